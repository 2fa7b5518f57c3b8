"""``tolsynth processes``: the cheapest manufacturing process per parameter and the tolerances
within it, with a proven optimum (:func:`tolsynth.synthesize_processes`), from the model file's
processes or a table file.

A table file (TOML or JSON) maps parameter names to lists of processes, each
``{name, cost, lower, upper}``: ``cost`` is a cost-model table as in a model file (not a number),
e.g. ``{model = "power", k = 1, alpha = 0.7}`` for ``k eps^-alpha`` (models: power, chase,
exponential, tabulated; docs/model_format.md); ``lower``/``upper`` (and a tabulated cost's
``eps``) in the parameter's tolerance unit, or strings with a unit suffix (``"50um"``)::

    [[h3]]
    name = "turning"
    cost = { model = "power", k = 1.0, alpha = 0.7 }
    lower = 0.05
    upper = 0.5
"""

from __future__ import annotations

from tolsynth.cli.args import check_table_out, fmt_p
from tolsynth.cli.designs import (
    add_max_nodes_argument,
    add_output_arguments,
    design_command,
    design_kwargs,
    finish,
    read_table_file,
)
from tolsynth.errors import InputError
from tolsynth.kinematics.mechanism import load_model

__all__ = ["register", "cmd_processes", "read_process_table"]

_SHAPE = (
    "a TOML or JSON file: parameter name -> list of {name, cost, lower, upper}, cost a cost-model "
    'table such as { model = "power", k = 1.0, alpha = 0.7 }'
)


def read_process_table(path: str, mech=None) -> dict:
    """The processes of a table file (module docstring); typed errors naming the file (and, with
    the model ``mech``, the parameter and process of a bad entry) otherwise."""
    from tolsynth.synthesis.processes import located, normalise_processes

    data = read_table_file(path, "--table", _SHAPE, "processes")
    for key, items in data.items():
        if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
            raise InputError(f"--table {path}: [{key}]", f"got {items!r}", "a list of {name, cost, lower, upper}")
    if mech is not None:
        try:
            normalise_processes(mech, data)
        except InputError as exc:
            raise located(exc, f"--table {path}") from None
    return data


def cmd_processes(args) -> int:
    from tolsynth.synthesis.processes import synthesize_processes

    check_table_out(args)
    mech = load_model(args.model)
    if args.table is not None:
        procs = read_process_table(args.table, mech)
    elif mech.processes:
        procs = None  # the model file's
    else:
        raise InputError(
            "--table", f"not given, and model {mech.name} declares no processes", "a process table file: " + _SHAPE
        )
    kw, record = design_kwargs(mech, args)
    dist = kw.pop("distribution")
    best = synthesize_processes(mech, args.R, args.p, procs, dist, max_nodes=args.max_nodes, **kw)
    record.update(R_mm=args.R, p=args.p, table=args.table, max_nodes=args.max_nodes)
    res = best.result

    def frame():
        table = res.to_frame()
        table.insert(2, "process", [best.processes.get(n, "") for n in table["parameter"]])
        summary = {k: v for k, v in best.to_dict().items() if k != "tolerances"}
        table.attrs["summary"] = dict(table.attrs["summary"], process_choice=summary)
        table.attrs["kind"] = "ProcessChoice"
        return table

    return finish(
        args,
        mech,
        record,
        frame=frame,
        data=lambda: dict(best.to_dict(), result=res.to_dict()),
        text=lambda: (
            f"{mech.name}: R = {args.R:g} mm, p = {fmt_p(args.p)}, processes from "
            f"{args.table or 'the model file'}\n{best.summary()}"
        ),
        ok=best.proven,
        failure="the optimum is not proven (node limit or an uncertified solve)",
    )


def register(sub) -> None:
    """Add ``tolsynth processes`` to the sub-command parser."""
    p = design_command(
        sub,
        "processes",
        "the cheapest process per parameter, with a proven optimum",
        "One manufacturing process per parameter and the tolerances within it at minimum "
        "total cost, by branch and bound (tolsynth.synthesize_processes); the processes "
        "from --table or from the model file.",
    )
    p.add_argument(
        "--table",
        default=None,
        metavar="FILE",
        help="process table, TOML or JSON: parameter -> list of {name, cost, lower, upper}, with cost a "
        'cost-model table, e.g. cost = { model = "power", k = 1.0, alpha = 0.7 } for k eps^-alpha (models: '
        "power, chase, exponential, tabulated; as in a model file), lower and upper in the parameter's "
        "tolerance unit; default: the model file's processes",
    )
    add_max_nodes_argument(p, 10_000, "the continuous solves of the search")
    add_output_arguments(p, "the chosen processes and tolerances")
    p.set_defaults(func=cmd_processes, task="the process choice")
