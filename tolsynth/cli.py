"""Command line: ``tolsynth analyze | solve | reproduce | montecarlo | map``.

Every sub-command prints a readable report, or one JSON object with ``--json``.  Bad input exits
with status 2 and a one-line message naming the field and the allowed range.
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np

from .errors import InputError, TolsynthError
from .mechanism import Mechanism, load_model

__all__ = ["main", "build_parser", "add_pose_arguments", "parse_pose", "parse_tolerances", "emit_json"]


# ---------------------------------------------------------------------------------------------
# argument helpers shared by the sub-commands
# ---------------------------------------------------------------------------------------------
def parse_pose(mech: Mechanism, text: str):
    """A configuration name, or comma-separated joint values in degrees."""
    if text in mech.configurations:
        return text
    try:
        values = [math.radians(float(v)) for v in text.split(",")]
    except ValueError:
        raise InputError(
            "--pose", f"{text!r} is neither a configuration nor joint values",
            "one of " + ", ".join(mech.configurations) + f", or {len(mech.joint_names)} comma-separated angles in deg",
        ) from None
    return np.array(values)


def parse_tolerances(mech: Mechanism, text: str) -> np.ndarray:
    """``SET``, ``name=value,...`` (every parameter) or ``SET,name=value,...`` (overrides)."""
    parts = [p.strip() for p in text.split(",") if p.strip()]
    base: dict[str, float] = {}
    overrides: dict[str, float] = {}
    for part in parts:
        if "=" in part:
            name, _, value = part.partition("=")
            key = mech.error_parameters[mech.index(name.strip())]  # UnknownNameError for a bad name
            try:
                overrides[key] = float(value)
            except ValueError:
                raise InputError("--tolerances", f"{part!r}: {value!r} is not a number", "name=value") from None
        else:
            if base:
                raise InputError("--tolerances", "more than one tolerance set named", "one SET, then name=value overrides")
            base = dict(zip(mech.error_parameters, mech.tolerances(part)))
    base.update(overrides)
    return mech.tolerances(base)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else str(v)
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def emit_json(obj) -> None:
    print(json.dumps(_jsonable(obj), indent=2))


def _fmt_vec(v, fmt="{:.6g}") -> str:
    return "(" + ", ".join(fmt.format(x) for x in np.asarray(v).ravel()) + ")"


# ---------------------------------------------------------------------------------------------
# analyze
# ---------------------------------------------------------------------------------------------
def cmd_analyze(args) -> int:
    mech = load_model(args.model)
    q = parse_pose(mech, args.pose)
    eps = parse_tolerances(mech, args.tolerances)
    a = mech.analyze(q, eps, args.dist, R=args.R, Phi=args.Phi)
    if args.json:
        out = {
            "model": mech.name,
            "pose": args.pose,
            "q_rad": a.q,
            "distribution": args.dist,
            "tolerances": a.tolerances,
            "units": {"position": "mm", "covariance": "mm^2", "principal_std": "mm", "R": "mm",
                      "sensitivity": "rows mm, mm, mm, rad, rad, rad per tolerance unit",
                      "tolerances": dict(zip(mech.error_parameters, mech.units))},
            "position": a.position,
            "sensitivity": a.sensitivity,
            "covariance": a.covariance,
            "principal_std": a.principal_std,
            "principal_directions": a.principal_directions,
            "principal_std_cubic": a.principal_std_cubic,
            "R": a.R,
            "p_components": a.p_components,
            "p_sphere": a.p_sphere,
        }
        if args.Phi is not None:
            out.update(Phi=a.Phi, orientation_covariance=a.orientation_covariance,
                       orientation_principal_std=a.orientation_principal_std,
                       p_orientation_components=a.p_orientation_components, p_cone=a.p_cone)
        emit_json(out)
        return 0
    print(f"model        {mech.name}: {mech.title}")
    print(f"pose         {args.pose}  q = {_fmt_vec(np.degrees(a.q), '{:.4f}')} deg")
    print(f"errors       {args.dist} ({'eps^2/3' if args.dist == 'uniform' else 'eps^2/9, 3 sigma = eps'})")
    print("tolerances   " + ", ".join(f"{n}={v:g} {u}" for (n, v), u in zip(a.tolerances.items(), mech.units)))
    print(f"hand         {_fmt_vec(a.position, '{:.4f}')} mm")
    print("covariance   (mm^2)")
    for row in a.covariance:
        print("             " + "  ".join(f"{x:+.6e}" for x in row))
    print(f"principal    sigma = {_fmt_vec(a.principal_std)} mm")
    for j in range(3):
        print(f"  direction {j + 1} {_fmt_vec(a.principal_directions[:, j], '{:+.4f}')}")
    print(f"R            {args.R:g} mm")
    print("P(|w_j|<=R)  " + _fmt_vec(a.p_components, "{:.6f}"))
    print(f"P(dr<=R)     {a.p_sphere:.6f}  (sphere, Eq. 5)")
    if args.Phi is not None:
        print(f"Phi          {args.Phi:g} rad; orientation sigma = {_fmt_vec(a.orientation_principal_std)} rad")
        print("P(|phi_j|<=Phi) " + _fmt_vec(a.p_orientation_components, "{:.6f}"))
        print(f"P(cone)      {a.p_cone:.6f}  (hand z axis inside the cone, Eq. 8)")
    return 0


# ---------------------------------------------------------------------------------------------
# parser
# ---------------------------------------------------------------------------------------------
def add_pose_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments of a one-pose analysis: model, pose, tolerances, distribution, R, Phi."""
    p.add_argument("--model", required=True, help="bundled model name or path to a .toml file")
    p.add_argument("--pose", default="worst", help="configuration name or joint angles in deg, comma-separated")
    p.add_argument("--tolerances", required=True, help="SET | name=value,... | SET,name=value,...")
    p.add_argument("--dist", choices=["uniform", "normal"], default="uniform")
    p.add_argument("--R", type=float, required=True, help="radius of the accuracy sphere (mm)")
    p.add_argument("--Phi", type=float, default=None, help="orientation cone half-angle (rad)")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tolsynth", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("analyze", help="linearised, Gaussian error analysis of one pose")
    add_pose_arguments(p)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_analyze)

    # the other sub-commands live beside the code they drive; each module has register(sub)
    from . import cli_commands

    for register in cli_commands.REGISTER:
        register(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except TolsynthError as exc:
        print(f"tolsynth {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
