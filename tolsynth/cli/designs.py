"""Arguments shared by ``tolsynth pareto``, ``budget`` and ``processes``: the model, the
specification's fixed parts (distribution, alpha, poses, orientation, probability) and the
keyword arguments of the library call they become."""

from __future__ import annotations

import numpy as np

from tolsynth.cli.args import (
    POSE_HELP,
    add_dist_argument,
    add_model_argument,
    angle_rad,
    dist_for,
    parse_per_parameter,
    parse_poses,
    pose_label,
)
from tolsynth.errors import InputError

__all__ = ["add_design_arguments", "design_kwargs", "parse_range"]

#: the probabilities these commands accept (the library's default when not given)
PROBABILITIES = ("gaussian", "exact")


def add_design_arguments(p) -> None:
    """--model, --dist, --alpha, --pose (repeatable), --Phi, --probability."""
    add_model_argument(p)
    add_dist_argument(p)
    p.add_argument("--alpha", default=None,
                   help="cost exponent: VALUE for every parameter, name=VALUE or pattern=VALUE overrides; default: 0.7")
    p.add_argument("--pose", action="append", default=None,
                   help=POSE_HELP + "; repeat for several poses; default: the model's reference pose")
    p.add_argument("--Phi", type=angle_rad("--Phi"), default=None,
                   help="orientation accuracy half-angle, rad (or with a suffix: 2mrad); default: none")
    p.add_argument("--probability", choices=list(PROBABILITIES), default=None,
                   help="gaussian (the paper's) or exact (the exact probabilities of the linear error model); "
                        "default: the library's (tolsynth.synthesize)")


def design_kwargs(mech, args) -> tuple[dict, dict]:
    """``(keyword arguments of the library call, the resolved values to record)``."""
    dist = dist_for(args, mech)
    alpha = parse_per_parameter(mech, args.alpha, "--alpha", 0.7, "a number > 0 (the paper: 0.7)")
    poses = parse_poses(mech, args.pose)
    kw = dict(distribution=dist, alpha=0.7 if alpha is None else alpha, poses=poses)
    if args.Phi is not None:
        kw["Phi"] = args.Phi
    if args.probability is not None:
        kw["probability"] = args.probability
    record = dict(distribution=dist, alpha=kw["alpha"], poses=[pose_label(q) for q in poses], Phi_rad=args.Phi,
                  probability=args.probability)
    return kw, record


def parse_range(text: str, field: str, check, unit_parse) -> list[float]:
    """``START:STOP:N`` (N values, evenly spaced) or comma-separated values."""
    text = str(text).strip()
    if ":" in text:
        parts = text.split(":")
        if len(parts) != 3:
            raise InputError(field, f"{text!r}", "START:STOP:N (e.g. 0.2:2:10) or comma-separated values")
        start, stop = unit_parse(parts[0]), unit_parse(parts[1])
        try:
            n = int(parts[2])
        except ValueError:
            raise InputError(field, f"{text!r}: N = {parts[2]!r} is not a whole number",
                             "START:STOP:N with 2 <= N <= 1000") from None
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
            raise InputError(field, f"{v:g} in {text!r}", "values in range")
    return values
