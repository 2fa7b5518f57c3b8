"""``tolsynth solve``: optimal tolerances for one specification."""

from __future__ import annotations

import sys

from ..errors import InputError
from ..mechanism import load_model
from .args import emit_json, parse_pose

__all__ = ["register"]


def _fmt(v) -> str:
    return "(" + ", ".join(f"{x:.1f}" for x in v) + ")"


def cmd_solve(args) -> int:
    from ..synthesis import compare, synthesize

    mech = load_model(args.model)
    pose = parse_pose(mech, args.pose)
    kw = dict(pose=pose, Phi=args.Phi, criterion=args.criterion)
    if args.everywhere:
        from ..synthesis import synthesize_workspace

        if args.solver == "both":
            raise InputError("--solver", "'both' does not combine with --everywhere", "ipopt or sumt")
        w = synthesize_workspace(mech, args.R, args.p, args.dist, args.alpha, solver=args.solver, **kw)
        if args.json:
            out = w.result.to_dict()
            out.update(converged=w.converged, rounds=w.rounds, poses=w.poses)
            emit_json(out)
        else:
            print(f"{mech.name}: R={args.R:g} mm, p={args.p:g}, alpha={args.alpha:g}, {args.dist} errors, every pose")
            for k, r in enumerate(w.rounds):
                print(f"  round {k}: {r['n_poses']} pose(s), cost {r['cost']:.6g}, worst sigma z/R over the "
                      f"workspace {r['worst_value']:.5f} at hand {_fmt(r['worst_position'])} mm")
            print(w.result.summary())
        if not w.success:
            print("tolsynth solve: no convergence over the workspace; the numbers above are not an optimum", file=sys.stderr)
            return 1
        return 0
    if args.solver == "both":
        c = compare(mech, args.R, args.p, args.dist, args.alpha, **kw)
        if args.json:
            emit_json(c.to_dict())
        else:
            print(f"{mech.name}: R={args.R:g} mm, p={args.p:g}, alpha={args.alpha:g}, {args.dist} errors, pose {args.pose}")
            print(c.table())
            print(f"IPOPT: {c.ipopt.message}\nSUMT:  {c.sumt.message}")
        ok = c.ipopt.success and c.sumt.success
    else:
        res = synthesize(mech, args.R, args.p, args.dist, args.alpha, solver=args.solver, **kw)
        if args.json:
            emit_json(res.to_dict())
        else:
            print(f"{mech.name}: R={args.R:g} mm, p={args.p:g}, alpha={args.alpha:g}, {args.dist} errors, pose {args.pose}")
            print(res.summary())
        ok = res.success
    if not ok:
        print("tolsynth solve: the solver did not converge; the numbers above are not an optimum", file=sys.stderr)
        return 1
    return 0


def register(sub) -> None:
    p = sub.add_parser("solve", help="optimal tolerances for one specification")
    p.add_argument("--model", required=True, help="bundled model name or path to a .toml file")
    p.add_argument("--R", type=float, required=True, help="position accuracy radius (mm)")
    p.add_argument("--p", type=float, required=True, help="probability per principal component, 0 < p < 1")
    p.add_argument("--dist", choices=["uniform", "normal"], default="uniform")
    p.add_argument("--alpha", type=float, default=0.7, help="cost exponent (default 0.7)")
    p.add_argument("--solver", choices=["ipopt", "sumt", "both"], default="ipopt")
    p.add_argument("--pose", default="worst", help="configuration name or joint angles in deg")
    p.add_argument("--Phi", type=float, default=None, help="orientation accuracy half-angle (rad), optional")
    p.add_argument("--criterion", choices=["components", "sphere"], default="components",
                   help="per principal component (the paper's Eq. 20) or the sphere P(|dr| <= R) >= p")
    p.add_argument("--everywhere", action="store_true",
                   help="impose the constraint at every reachable pose (exchange method with the worst-pose search)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_solve)
