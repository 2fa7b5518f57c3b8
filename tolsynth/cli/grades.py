"""``tolsynth grades``: the optimal tolerances rounded to standard grades (ISO 286 IT grades for
lengths at their nominal sizes, a user's own grade table for angles), the cheapest combination
that still meets the specification, with a proven optimum (:func:`tolsynth.round_to_grades`).

``--sizes`` gives each length's nominal size: one length for every parameter (``300`` or
``0.3m``), ``name=SIZE,...`` (patterns allowed by the library), or a TOML/JSON file mapping names to
sizes in mm.  ``--grades FILE`` (TOML or JSON) is a grade table: parameter name or pattern ->
{grade label: tolerance in the parameter's tolerance unit}::

    ["o*"]
    A = 0.1
    B = 0.2
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
    quantity,
    write_out,
)
from tolsynth.cli.designs import add_design_arguments, design_kwargs
from tolsynth.errors import InputError
from tolsynth.kinematics.mechanism import load_model

__all__ = ["register", "cmd_grades", "parse_sizes"]

_SIZES = "SIZE (mm, or with a suffix) for every length, name=SIZE,... or a TOML/JSON file name -> mm"


def _read_mapping(path: str, field: str, shape: str) -> dict:
    """A TOML or JSON file holding one table; typed errors naming the file otherwise."""
    try:
        if path.lower().endswith(".json"):
            with open(path, encoding="utf-8") as fh:
                data = json.load(fh)
        else:
            import tomllib

            with open(path, "rb") as fh:
                data = tomllib.load(fh)
    except (OSError, UnicodeDecodeError, ValueError) as exc:  # TOML and JSON decode errors are ValueErrors
        raise InputError(field, f"{path!r} cannot be read: {exc}", shape) from None
    if not isinstance(data, dict) or not data:
        raise InputError(field, f"{path!r} holds no table", shape)
    return data


def parse_sizes(text):
    """``--sizes``: None, one length (mm), a dict name -> mm from ``name=SIZE,...`` or from a file."""
    if text is None:
        return None
    text = str(text).strip()
    if os.path.isfile(text):
        data = _read_mapping(text, "--sizes", _SIZES)
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


def cmd_grades(args) -> int:
    from tolsynth.synthesis.grades import round_to_grades
    from tolsynth.synthesis.single import synthesize

    check_table_out(args)
    mech = load_model(args.model)
    sizes = parse_sizes(args.sizes)
    table = None
    if args.grades is not None:
        shape = "a TOML or JSON file: parameter name or pattern -> {grade label: tolerance}"
        if not os.path.isfile(args.grades):
            raise InputError("--grades", f"{args.grades!r} is not a file", shape)
        table = _read_mapping(args.grades, "--grades", shape)
    kw, record = design_kwargs(mech, args)
    res = synthesize(mech, args.R, args.p, **kw)
    if not res.success:
        print(res.summary())
        print("tolsynth grades: the continuous design did not converge; nothing to round", file=sys.stderr)
        return 1
    g = round_to_grades(mech, res, sizes=sizes, table=table, max_nodes=args.max_nodes)
    record.update(R_mm=args.R, p=args.p, sizes=sizes, grades_file=args.grades, max_nodes=args.max_nodes)
    if args.out:
        write_out(g.to_frame(), args, mech, **record)
    if args.json:
        d = g.to_dict()
        d.update(continuous=res.to_dict(), inputs=inputs_record(args, mech, **record))
        emit_json(d)
    else:
        print(f"{mech.name}: R = {args.R:g} mm, p = {args.p:g}; the continuous optimum costs {res.cost:.8g}")
        print(g.summary())
    if not g.proven:
        print("tolsynth grades: the grade choice is not proven optimal (node limit)", file=sys.stderr)
        return 1
    return 0


def register(sub) -> None:
    """Add ``tolsynth grades`` to the sub-command parser."""
    p = sub.add_parser("grades", help="optimal tolerances rounded to standard grades, with a proven optimum",
                       description="The continuous optimum rounded to ISO 286 IT grades (lengths, at their nominal "
                                   "sizes) or to a grade table of your own (angles): the cheapest combination that "
                                   "still meets the specification (tolsynth.round_to_grades).")
    add_design_arguments(p)
    p.add_argument("--R", type=length_mm("--R"), required=True, help="position accuracy radius, mm (suffixes: 500um)")
    p.add_argument("--p", type=number("--p", "0 < p < 1", lambda v: 0 < v < 1), required=True,
                   help="probability per principal component, 0 < p < 1")
    p.add_argument("--sizes", default=None,
                   help=f"nominal sizes of the lengths: {_SIZES}; default: each dimension's nominal value")
    p.add_argument("--grades", default=None, metavar="FILE",
                   help="grade table, TOML or JSON: parameter or pattern -> {label: tolerance in its unit}; "
                        "needed for angles (ISO 286 has none); default: ISO 286 only")
    p.add_argument("--max-nodes", dest="max_nodes", type=number("--max-nodes", "a whole number >= 1",
                                                                lambda v: v >= 1, integer=True), default=5000,
                   help="limit on the search's solves and checks (then the optimum is not proven)")
    add_table_out_argument(p, "the chosen grades and tolerances")
    p.add_argument("--json", action="store_true", help="print one JSON object (inputs recorded) instead of the report")
    p.set_defaults(func=cmd_grades, task="the grade choice")
