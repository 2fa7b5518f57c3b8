"""``tolsynth grades``: the optimal tolerances rounded to standard grades (ISO 286 IT grades for
lengths at their nominal sizes, a user's own grade table for angles), the cheapest combination
that still meets the specification, with a proven optimum (:func:`tolsynth.round_to_grades`).

``--sizes`` gives each length's nominal size: one length for every parameter (``300`` or
``0.3m``), ``name=SIZE,...`` (patterns allowed by the library), or a TOML/JSON file mapping names to
sizes in mm.  ``--grades FILE`` (TOML or JSON) is a grade table: parameter name or pattern ->
{grade label: tolerance in the parameter's tolerance unit, or a string with a unit suffix}::

    ["o*"]
    A = 0.1
    B = "0.2mrad"
"""

from __future__ import annotations

import os
import sys

from tolsynth.cli.args import check_table_out, fmt_p, quantity
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

__all__ = ["register", "cmd_grades", "parse_sizes", "option_names"]

_SIZES = "SIZE (mm, or with a suffix) for every length, name=SIZE,... or a TOML/JSON file name -> mm"


def parse_sizes(text):
    """``--sizes``: None, one length (mm), a dict name -> mm from ``name=SIZE,...`` or from a file."""
    if text is None:
        return None
    text = str(text).strip()
    if os.path.isfile(text):
        data = read_table_file(text, "--sizes", _SIZES)
        return {str(k): quantity(str(v), f"--sizes {k}", "length", "mm") for k, v in data.items()}
    if "=" not in text:
        return quantity(text, "--sizes", "length", "mm")
    out = {}
    for item in (s.strip() for s in text.split(",") if s.strip()):
        name, sep, value = (s.strip() for s in item.partition("="))
        if not sep or not name or not value:
            raise InputError("--sizes", f"got {item!r}", _SIZES)
        if name in out:
            raise InputError(f"--sizes {name}", "given twice", "each parameter once")
        out[name] = quantity(value, f"--sizes {name}", "length", "mm")
    return out


def option_names(grades_file: str | None) -> dict:
    """How :func:`tolsynth.synthesis.grades.grade_candidates` names the inputs in its errors: the
    options ``--sizes`` and ``--grades FILE`` (its tables ``["o*"]`` and their grades) where the
    library names its arguments ``sizes`` and ``table``."""
    where = f"--grades {grades_file}" if grades_file else "--grades"
    return {
        "sizes": "--sizes",
        "size": "--sizes {name}",
        "table": where,
        "entry": where + ": [{key}]" if grades_file else where,
        "grade": where + ": [{key}] {label}",
        "give_table": '--grades FILE, a TOML file with a table ["{name}"] (or a pattern such as ["o*"] or ["*"]) '
        "and its grades one a line, A = 0.1, B = 0.2, ..., in {unit} (its tolerance unit) or with a unit suffix "
        '(A = "0.1mrad")',
        "give_size": "its nominal size: --sizes {name}=SIZE, in mm or with a length unit suffix",
    }


def cmd_grades(args) -> int:
    from tolsynth.synthesis.grades import grade_candidates, round_to_grades
    from tolsynth.synthesis.single import synthesize

    check_table_out(args)
    mech = load_model(args.model)
    sizes = parse_sizes(args.sizes)
    table = None
    if args.grades is not None:
        table = read_table_file(
            args.grades, "--grades", "a TOML or JSON file: parameter name or pattern -> {grade label: tolerance}"
        )
    # the grades read before the solve, their errors naming the options typed
    grade_candidates(mech, sizes, table, names=option_names(args.grades))
    kw, record = design_kwargs(mech, args)
    res = synthesize(mech, args.R, args.p, **kw)
    if not res.success:
        print(res.summary())
        print("tolsynth grades: the continuous design did not converge; nothing to round", file=sys.stderr)
        return 1
    g = round_to_grades(mech, res, sizes=sizes, table=table, max_nodes=args.max_nodes)
    record.update(R_mm=args.R, p=args.p, sizes=sizes, grades_file=args.grades, max_nodes=args.max_nodes)
    return finish(
        args,
        mech,
        record,
        frame=g.to_frame,
        data=lambda: dict(g.to_dict(), continuous=res.to_dict()),
        text=lambda: (
            f"{mech.name}: R = {args.R:g} mm, p = {fmt_p(args.p)}; the continuous optimum costs "
            f"{res.cost:.8g}\n{g.summary()}"
        ),
        ok=g.proven,
        failure="the grade choice is not proven optimal (node limit)",
    )


def register(sub) -> None:
    """Add ``tolsynth grades`` to the sub-command parser."""
    p = design_command(
        sub,
        "grades",
        "optimal tolerances rounded to standard grades, with a proven optimum",
        "The continuous optimum rounded to ISO 286 IT grades (lengths, at their nominal "
        "sizes) or to a grade table of your own (angles): the cheapest combination that "
        "still meets the specification (tolsynth.round_to_grades).",
    )
    p.add_argument(
        "--sizes", default=None, help=f"nominal sizes of the lengths: {_SIZES}; default: each dimension's nominal value"
    )
    p.add_argument(
        "--grades",
        default=None,
        metavar="FILE",
        help="grade table, TOML or JSON: parameter or pattern -> {label: tolerance in its unit, or with a "
        'unit suffix such as "0.1mrad"}; '
        "needed for angles (ISO 286 has none); default: ISO 286 only",
    )
    add_max_nodes_argument(p, 5000, "the search's solves and checks")
    add_output_arguments(p, "the chosen grades and tolerances")
    p.set_defaults(func=cmd_grades, task="the grade choice")
