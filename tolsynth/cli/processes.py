"""``tolsynth processes``: the cheapest manufacturing process per parameter and the tolerances
within it, with a proven optimum (:func:`tolsynth.synthesize_processes`), from the model file's
processes or a table file.

A table file (TOML or JSON) maps parameter names to lists of processes, each
``{name, cost, lower, upper}`` (``cost`` as in a model file, e.g. ``{model = "power", k = 1,
alpha = 0.7}``; ``lower``/``upper`` in the parameter's tolerance unit)::

    [[h3]]
    name = "turning"
    cost = { model = "power", k = 1.0, alpha = 0.7 }
    lower = 0.05
    upper = 0.5
"""

from __future__ import annotations

import json
import os
import sys

from tolsynth.cli.args import (
    add_table_out_argument,
    check_table_out,
    emit_json,
    inputs_record,
    length_mm,
    number,
    write_out,
)
from tolsynth.cli.designs import add_design_arguments, design_kwargs
from tolsynth.errors import InputError
from tolsynth.kinematics.mechanism import load_model

__all__ = ["register", "cmd_processes", "read_process_table"]

_SHAPE = "a TOML or JSON file: parameter name -> list of {name, cost, lower, upper}"


def read_process_table(path: str) -> dict:
    """The processes of a table file (module docstring); typed errors naming the file otherwise."""
    if not os.path.isfile(path):
        raise InputError("--table", f"{path!r} is not a file", _SHAPE)
    try:
        if path.lower().endswith(".json"):
            with open(path, encoding="utf-8") as fh:
                data = json.load(fh)
        else:
            try:
                import tomllib
            except ImportError:  # pragma: no cover - Python 3.10
                import tomli as tomllib
            with open(path, "rb") as fh:
                data = tomllib.load(fh)
    except (OSError, UnicodeDecodeError, ValueError) as exc:  # TOMLDecodeError and JSONDecodeError are ValueErrors
        raise InputError("--table", f"{path!r} cannot be read: {exc}", _SHAPE) from None
    if not isinstance(data, dict) or not data:
        raise InputError("--table", f"{path!r} holds no processes", _SHAPE)
    for key, items in data.items():
        if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
            raise InputError(f"--table[{key}]", f"got {items!r}", "a list of {name, cost, lower, upper}")
    return data


def cmd_processes(args) -> int:
    from tolsynth.synthesis.processes import synthesize_processes

    check_table_out(args)
    mech = load_model(args.model)
    if args.table is not None:
        procs = read_process_table(args.table)
    elif mech.processes:
        procs = None  # the model file's
    else:
        raise InputError("--table", f"not given, and model {mech.name} declares no processes",
                         "a process table file: " + _SHAPE)
    kw, record = design_kwargs(mech, args)
    dist = kw.pop("distribution")
    best = synthesize_processes(mech, args.R, args.p, procs, dist, max_nodes=args.max_nodes, **kw)
    record.update(R_mm=args.R, p=args.p, table=args.table, max_nodes=args.max_nodes)
    res = best.result
    if args.out:
        frame = res.to_frame()
        frame.insert(2, "process", [best.processes.get(n, "") for n in frame["parameter"]])
        summary = {k: v for k, v in best.to_dict().items() if k != "tolerances"}
        frame.attrs["summary"] = dict(frame.attrs["summary"], process_choice=summary)
        frame.attrs["kind"] = "ProcessChoice"
        write_out(frame, args, mech, **record)
    if args.json:
        d = best.to_dict()
        d.update(result=res.to_dict(), inputs=inputs_record(args, mech, **record))
        emit_json(d)
    else:
        print(f"{mech.name}: R = {args.R:g} mm, p = {args.p:g}, processes from "
              f"{args.table or 'the model file'}")
        print(best.summary())
    if not best.proven:
        print("tolsynth processes: the optimum is not proven (node limit or an uncertified solve)", file=sys.stderr)
        return 1
    return 0


def register(sub) -> None:
    """Add ``tolsynth processes`` to the sub-command parser."""
    p = sub.add_parser("processes", help="the cheapest process per parameter, with a proven optimum",
                       description="One manufacturing process per parameter and the tolerances within it at minimum "
                                   "total cost, by branch and bound (tolsynth.synthesize_processes); the processes "
                                   "from --table or from the model file.")
    add_design_arguments(p)
    p.add_argument("--R", type=length_mm("--R"), required=True, help="position accuracy radius, mm (suffixes: 500um)")
    p.add_argument("--p", type=number("--p", "0 < p < 1", lambda v: 0 < v < 1), required=True,
                   help="probability per principal component, 0 < p < 1")
    p.add_argument("--table", default=None, metavar="FILE",
                   help="process table, TOML or JSON: parameter -> list of {name, cost, lower, upper}; "
                        "default: the model file's processes")
    p.add_argument("--max-nodes", dest="max_nodes", type=number("--max-nodes", "a whole number >= 1",
                                                                lambda v: v >= 1, integer=True), default=10_000,
                   help="limit on the continuous solves of the search (then the optimum is not proven)")
    add_table_out_argument(p, "the chosen processes and tolerances")
    p.add_argument("--json", action="store_true", help="print one JSON object (inputs recorded) instead of the report")
    p.set_defaults(func=cmd_processes, task="the process choice")
