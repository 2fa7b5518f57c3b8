"""What ``tolsynth pareto``, ``budget``, ``processes`` and ``grades`` share: the model, the
specification's fixed parts (distribution, alpha, poses, orientation, probability) and the
keyword arguments of the library call they become; their output options, the table files they
read, and how each of them ends (the table, the JSON object or the report, and the exit status;
``worst-pose`` ends the same way)."""

from __future__ import annotations

import json
import os
import sys

import numpy as np

from tolsynth.cli.args import (
    DEFAULT_POSE_HELP,
    POSE_HELP,
    add_dist_argument,
    add_model_argument,
    add_table_out_argument,
    dist_for,
    emit_json,
    half_angle_rad,
    inputs_record,
    length_mm,
    number,
    parse_poses,
    pose_label,
    write_out,
)
from tolsynth.cli.params import parse_per_parameter
from tolsynth.errors import InputError
from tolsynth.problem.specification import ALPHA_DEFAULT

__all__ = [
    "design_command",
    "add_design_arguments",
    "add_R_p_arguments",
    "add_max_nodes_argument",
    "add_output_arguments",
    "design_kwargs",
    "parse_range",
    "read_table_file",
    "finish",
]

#: the probabilities these commands accept (the library's default when not given)
PROBABILITIES = ("gaussian", "exact")


def add_design_arguments(p) -> None:
    """--model, --dist, --alpha, --pose (repeatable), --Phi, --probability."""
    add_model_argument(p)
    add_dist_argument(p)
    p.add_argument(
        "--alpha",
        default=None,
        help="cost exponent: VALUE for every parameter, name=VALUE or pattern=VALUE overrides; default: 0.7",
    )
    p.add_argument(
        "--pose",
        action="append",
        default=None,
        help=f"{POSE_HELP}; repeat for several poses; {DEFAULT_POSE_HELP}",
    )
    p.add_argument(
        "--Phi",
        type=half_angle_rad("--Phi"),
        default=None,
        help="orientation accuracy half-angle, rad (or with a suffix: 2mrad); default: none",
    )
    p.add_argument(
        "--probability",
        choices=list(PROBABILITIES),
        default=None,
        help="exact (the default: the exact probabilities of the linear error model) or gaussian (the "
        "paper's: each principal component read as normal)",
    )


def design_command(sub, name: str, help: str, description: str, R_and_p: bool = True):
    """A sub-command's parser with the design arguments (and --R, --p, both required, unless the
    command reads them its own way)."""
    p = sub.add_parser(name, help=help, description=description)
    add_design_arguments(p)
    if R_and_p:
        add_R_p_arguments(p)
    return p


def add_R_p_arguments(p) -> None:
    """--R and --p, both required: the specification a design meets."""
    p.add_argument("--R", type=length_mm("--R"), required=True, help="position accuracy radius, mm (suffixes: 500um)")
    p.add_argument(
        "--p",
        type=number("--p", "0 < p < 1", lambda v: 0 < v < 1),
        required=True,
        help="probability per principal component, 0 < p < 1",
    )


def add_max_nodes_argument(p, default: int, what: str) -> None:
    """--max-nodes: the limit of a proven search (past it the choice is not proven optimal)."""
    p.add_argument(
        "--max-nodes",
        dest="max_nodes",
        type=number("--max-nodes", "a whole number >= 1", lambda v: v >= 1, integer=True),
        default=default,
        help=f"limit on {what} (then the optimum is not proven)",
    )


def add_output_arguments(p, table: str, printed: str = "the report") -> None:
    """--out (a table of ``table``) and --json (one JSON object instead of ``printed``)."""
    add_table_out_argument(p, table)
    p.add_argument("--json", action="store_true", help=f"print one JSON object (inputs recorded) instead of {printed}")


def read_table_file(path: str, field: str, shape: str, what: str = "table") -> dict:
    """The one table (a mapping) of a TOML or JSON file (by its suffix); a typed error naming the
    file and ``shape`` when it is missing, unreadable or empty."""
    if not os.path.isfile(path):
        raise InputError(field, f"{path!r} is not a file", shape)
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
    except (OSError, UnicodeDecodeError, ValueError) as exc:  # TOML and JSON decode errors are ValueErrors
        raise InputError(field, f"{path!r} cannot be read: {exc}", shape) from None
    if not isinstance(data, dict) or not data:
        raise InputError(field, f"{path!r} holds no {what}", shape)
    return data


def finish(args, mech, record: dict, *, frame, data, text, ok: bool, failure: str) -> int:
    """How a design command ends: ``frame()`` to --out, then ``data()`` as one JSON object with the
    inputs recorded (--json) or the readable ``text()``; exit status 1 with ``failure`` on stderr
    when ``ok`` is false, since a number that is not a proven optimum must not pass for one.  The
    three are called only when their output is asked for (a report may run checks of its own)."""
    if args.out:
        write_out(frame(), args, mech, **record)
    if args.json:
        emit_json(dict(data(), inputs=inputs_record(args, mech, **record)))
    else:
        print(text())
    if not ok:
        print(f"tolsynth {args.command}: {failure}", file=sys.stderr)
        return 1
    return 0


def design_kwargs(mech, args) -> tuple[dict, dict]:
    """``(keyword arguments of the library call, the resolved values to record)``."""
    from tolsynth.synthesis.single import DEFAULT_PROBABILITY

    dist = dist_for(args, mech)
    alpha = parse_per_parameter(mech, args.alpha, "--alpha", ALPHA_DEFAULT, "a number > 0 (the paper: 0.7)")
    poses = parse_poses(mech, args.pose)
    kw = dict(distribution=dist, alpha=ALPHA_DEFAULT if alpha is None else alpha, poses=poses)
    if args.Phi is not None:
        kw["Phi"] = args.Phi
    if args.probability is not None:
        kw["probability"] = args.probability
    record = dict(
        distribution=dist,
        alpha=kw["alpha"],
        poses=[pose_label(q) for q in poses],
        Phi_rad=args.Phi,
        probability=args.probability or DEFAULT_PROBABILITY,
    )
    return kw, record


def parse_range(text: str, field: str, check, unit_parse, allowed: str) -> list[float]:
    """``START:STOP:N`` (N values, evenly spaced) or comma-separated values, each passing ``check``
    (``allowed`` says which values do, with their unit)."""
    text = str(text).strip()
    if ":" in text:
        parts = text.split(":")
        if len(parts) != 3:
            raise InputError(field, f"{text!r}", "START:STOP:N (e.g. 0.2:2:10) or comma-separated values")
        start, stop = unit_parse(parts[0]), unit_parse(parts[1])
        try:
            n = int(parts[2])
        except ValueError:
            raise InputError(
                field, f"{text!r}: N = {parts[2]!r} is not a whole number", "START:STOP:N with 2 <= N <= 1000"
            ) from None
        if not 2 <= n <= 1000:
            raise InputError(field, f"{text!r}: N = {n}", "START:STOP:N with 2 <= N <= 1000")
        if not start < stop:
            raise InputError(field, f"{text!r}: START >= STOP", "START < STOP")
        values = np.linspace(start, stop, n).tolist()
    else:
        values = [unit_parse(t) for t in text.split(",") if t.strip()]
        if not values:
            raise InputError(field, "empty", "START:STOP:N or comma-separated values")
    for v in values:
        if not check(v):
            raise InputError(field, f"{v:g} in {text!r}", allowed)
    return values
