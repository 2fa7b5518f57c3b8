"""``tolsynth map`` (the paper's Figure 3) and ``tolsynth worst-pose``."""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from ..mechanism import load_model
from ..pose_search import worst_pose
from ..workspace_map import PLANES, ProbabilityMap, probability_map
from .args import emit_json, parse_tolerances

__all__ = ["register"]


def _cmd_map(args) -> int:
    mech = load_model(args.model)
    eps = parse_tolerances(mech, args.tolerances)
    label = args.tolerances
    extent = None
    if args.extent:
        try:
            extent = [float(x) for x in args.extent.split(",")]
        except ValueError:
            raise InputError("--extent", f"{args.extent!r}", "umin,umax,vmin,vmax in mm") from None
    axis = None if args.hand_axis == "free" else [float(x) for x in args.hand_axis.split(",")]
    pm = probability_map(mech, eps, R=args.R, distribution=args.dist, n=args.n, plane=args.plane,
                         offset=args.offset, hand_axis=axis, extent=extent,
                         progress=False if args.quiet else None)
    pm = ProbabilityMap(**{**pm.__dict__, "tolerance_label": label})
    if args.out:
        import matplotlib

        matplotlib.use("Agg")
        from ..plot import plot_map

        plot_map(pm, path=args.out)
    if args.json:
        out = {k: v for k, v in pm.to_dict().items() if k not in ("Q", "sigma")}
        out["out"] = args.out
        emit_json(out)
    else:
        rch = pm.reachable
        print(f"map          {mech.name}, plane {pm.plane}, {args.n} x {args.n} points, {int(rch.sum())} reachable")
        print(f"extent       {pm.u[0]:.1f} .. {pm.u[-1]:.1f} x {pm.v[0]:.1f} .. {pm.v[-1]:.1f} mm")
        print(f"P(dr<=R)     {np.nanmin(pm.P):.4f} .. {np.nanmax(pm.P):.4f}  (R = {pm.R:g} mm, {pm.distribution})")
        print(f"lowest P     {pm.worst[2]:.4f} at ({pm.worst[0]:.1f}, {pm.worst[1]:.1f}) mm")
        print(f"branch       {pm.branch}")
        print("held         " + "; ".join(f"{k} = {math.degrees(v):g} deg ({w})" for k, (v, w) in pm.fixed.items()))
        print(f"time         {pm.elapsed_s:.2f} s")
        if args.out:
            print(f"figure       {args.out}")
    return 0


def _cmd_worst(args) -> int:
    mech = load_model(args.model)
    eps = parse_tolerances(mech, args.tolerances)
    w = worst_pose(mech, eps, criterion=args.criterion, R=args.R, distribution=args.dist, grid=args.grid,
                   reference=args.reference if args.reference != "none" else None)
    if args.json:
        emit_json(w.to_dict())
    else:
        print(w.report(mech.joint_names))
    return 0


def register(sub) -> None:
    """Add ``tolsynth map`` and ``tolsynth worst-pose`` to the sub-command parser."""
    p = sub.add_parser("map", help="P(dr <= R) over the reachable part of a plane (the paper's Figure 3)")
    p.add_argument("--model", required=True, help="bundled model name or path to a .toml file")
    p.add_argument("--tolerances", default="figure3", help="SET | name=value,... | SET,name=value,...")
    p.add_argument("--dist", choices=["uniform", "normal"], default="uniform")
    p.add_argument("--R", type=float, default=0.2, help="radius of the accuracy sphere (mm)")
    p.add_argument("--n", type=int, default=100, help="grid points per axis")
    p.add_argument("--plane", choices=sorted(PLANES), default="xz")
    p.add_argument("--offset", type=float, default=0.0, help="offset of the plane along its normal (mm)")
    p.add_argument("--hand-axis", default="0,0,1", help="hand z axis in the base frame, or 'free'")
    p.add_argument("--extent", default=None, help="umin,umax,vmin,vmax (mm); default: the reachable box")
    p.add_argument("--out", default=None, help="figure file (.png, .pdf, ...)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_map)

    p = sub.add_parser("worst-pose", help="search the joint space for the pose of worst accuracy")
    p.add_argument("--model", required=True, help="bundled model name or path to a .toml file")
    p.add_argument("--tolerances", default="figure3", help="SET | name=value,... | SET,name=value,...")
    p.add_argument("--dist", choices=["uniform", "normal"], default="uniform")
    p.add_argument("--criterion", choices=["sigma", "probability"], default="sigma")
    p.add_argument("--R", type=float, default=None, help="radius (mm); needed for --criterion probability")
    p.add_argument("--grid", type=int, default=None, help="grid points per searched joint")
    p.add_argument("--reference", default="worst", help="configuration to report beside the result, or 'none'")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_worst)
