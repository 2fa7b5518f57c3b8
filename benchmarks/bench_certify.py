"""The certified search's speed on the bundled serial arms: the design of the sampled exchange
(R 0.5 mm, p 0.99, the Gaussian reading, uniform errors), then the certified decision the
certified exchange runs on it, ``z sigma_1 / R <= 1 + tol`` everywhere, within a time limit.

Per model (medians over ``--repeat`` runs of the certified search): boxes bounded, CPU seconds,
boxes per CPU second, the bound reached and the worst value found (both as ``z sigma_1 / R``),
certified or not.  ``--target`` sets the decision's goal (default ``1 + tol``, tol 1e-3): the
proof's cost is set by the room between the design's true maximum and the goal, so a sweep of
targets shows how it grows as the room closes.  ``--pieces`` sets the most tangent pieces a box
is bounded again with (tolsynth.analysis.certify_polygon.POLYGON_PIECES; default: as many as keep
a box's tuples within POLYGON_TUPLES).  ``--exchange`` also times the full certified
exchange, ``synthesize_workspace(..., certify=True)``, with ``--margin`` its design margin
(``certify_options["margin"]``: designs at ``R / (1 + margin)``, the proof at R).

CPU time (``time.process_time``) stands next to wall time: on a shared machine the wall time
mostly measures the other processes.

    python benchmarks/bench_certify.py [--models xu_zhang_1988 puma560 ur5 panda] [--repeat 1]
        [--time-limit 120] [--target 1.001 1.01] [--pieces 4] [--exchange [--margin 3e-3]]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import tolsynth
import tolsynth.analysis.certify_polygon as certify_polygon
from tolsynth.analysis.certify import certify_worst_pose
from tolsynth.probability.stats import z_of_p

R, P = 0.5, 0.99


def design(name: str):
    """The sampled exchange's design and its imposed poses (30 rounds at most)."""
    m = tolsynth.load_model(name)
    t = time.process_time()
    ws = tolsynth.synthesize_workspace(m, R, P, probability="gaussian", progress=False, max_rounds=30)
    print(
        f"{name}: sampled exchange {'converged' if ws.converged else 'NOT converged'} in {len(ws.rounds)} rounds, "
        f"worst found {ws.rounds[-1]['worst_value']:.6f}, {time.process_time() - t:.1f} s CPU",
        flush=True,
    )
    return m, ws.result.x, np.array(ws.poses)


def search(m, eps, poses, target: float, time_limit: float) -> dict:
    z = z_of_p(P)
    t, w = time.process_time(), time.perf_counter()
    c = certify_worst_pose(
        m, eps, None, "sigma", R, "gaussian", x0=poses, progress=False, target=target * R / z, time_limit=time_limit
    )
    return {
        "boxes": c.boxes,
        "cpu": time.process_time() - t,
        "wall": time.perf_counter() - w,
        "bound": c.upper_bound * z / R,
        "best": c.best_value * z / R,
        "certified": c.certified,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", nargs="+", default=["xu_zhang_1988", "puma560", "ur5", "panda"])
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--time-limit", type=float, default=120.0)
    ap.add_argument("--tol", type=float, default=1e-3)
    ap.add_argument("--target", type=float, nargs="+", default=None)
    ap.add_argument("--pieces", type=int, default=None)
    ap.add_argument("--exchange", action="store_true")
    ap.add_argument("--margin", type=float, default=0.0)
    args = ap.parse_args()
    if args.pieces is not None:
        certify_polygon.POLYGON_PIECES = args.pieces
    print(f"arc polygons: {certify_polygon.POLYGON_PIECES or 'automatic'} tangent pieces per arc")
    targets = args.target or [1.0 + args.tol]
    print(
        f"{'model':14} {'target':>8} {'boxes':>8} {'CPU s':>7} {'wall s':>7} {'box/s':>6} {'bound':>9} {'best':>9}  certified"
    )
    for name in args.models:
        m, eps, poses = design(name)
        for target in targets:
            runs = [search(m, eps, poses, target, args.time_limit) for _ in range(args.repeat)]
            med = {k: statistics.median(r[k] for r in runs) for k in ("boxes", "cpu", "wall", "bound", "best")}
            print(
                f"{name:14} {target:8.4f} {med['boxes']:8.0f} {med['cpu']:7.1f} {med['wall']:7.1f} "
                f"{med['boxes'] / max(med['cpu'], 1e-9):6.0f} {med['bound']:9.6f} {med['best']:9.6f}  "
                f"{sum(r['certified'] for r in runs)}/{len(runs)}",
                flush=True,
            )
        if args.exchange:
            t, w = time.process_time(), time.perf_counter()
            ws = tolsynth.synthesize_workspace(
                m,
                R,
                P,
                probability="gaussian",
                tol=args.tol,
                certify=True,
                certify_options={"time_limit": args.time_limit, "margin": args.margin},
                progress=False,
                max_rounds=30,
            )
            boxes = sum(r["boxes"] for r in ws.rounds)
            print(
                f"{name:14} certified exchange: {'certified' if ws.certified else 'NOT certified'}, "
                f"bound {ws.upper_bound}, {len(ws.rounds)} rounds, {boxes} boxes, "
                f"{time.process_time() - t:.1f} s CPU, {time.perf_counter() - w:.1f} s wall; cost "
                f"{ws.result.cost:.6f}, lower bound {ws.lower_bound:.6f}; {ws.reason}",
                flush=True,
            )


if __name__ == "__main__":
    main()
