"""The exact design's speed and certificate, paired in one run against the lean cvxpy + Clarabel
model of the Gaussian problem (benchmarks/lean_cvxpy.py: a cold solve is building plus solving).

Rows (medians over ``--repeat`` runs, a new R each time so no solve repeats another):

* the paper's robot (xu_zhang_1988 at its worst pose), uniform and mixed shapes, p = 0.7, 0.9,
  0.99: the exact solve's time, its ratio to one cold cvxpy solve of the Gaussian problem
  (target <= 8x), its cost, gap and the certificate's status;
* ``verify=True`` at p = 0.99: the time it adds (target < 1 s);
* puma560 at 30 random poses (target < 5 s);
* the sphere criterion against the component one at p = 0.9 (target <= 10x);
* all-normal errors: the exact path's time against the Gaussian path's (the same problem).

CPU time (``time.process_time``) stands next to wall time: on a shared machine the wall time
mostly measures the other processes.

    python benchmarks/bench_exact.py [--repeat 3] [--only uniform|mixed|paper]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import tolsynth

sys.path.insert(0, str(Path(__file__).resolve().parent))

MIXED = {"*": "uniform", "h2": "normal", "s1": "triangular", "alpha3": "truncnormal"}


def _cold_cvxpy(m, R, p, distribution):
    """One cold lean cvxpy + Clarabel solve of the Gaussian problem (build + solve): (wall, CPU) s."""
    try:
        from lean_cvxpy import LeanModel
    except ImportError:  # the reference model is not there: no ratio
        return float("nan"), float("nan")
    t0, c0 = time.perf_counter(), time.process_time()
    LeanModel(m, poses=("worst",), distribution=distribution).solve(R, p)
    return time.perf_counter() - t0, time.process_time() - c0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="runs per row (default 3; medians)")
    ap.add_argument(
        "--only",
        choices=("uniform", "mixed", "paper"),
        help="only the paper's robot rows of these shapes (paper: both), nothing after them",
    )
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    m = tolsynth.load_model("xu_zhang_1988")
    tolsynth.synthesize(m, R=0.5, p=0.9, probability="gaussian")  # graphs built once, outside the timings
    from tolsynth.solvers import exact_kernel

    backend = "compiled C kernel" if exact_kernel.available() else "NumPy (no C compiler, or TOLSYNTH_NO_COMPILE)"
    print(f"xu_zhang_1988 at its worst pose; medians of {args.repeat} runs, a new R each time; series: {backend}\n")
    print(
        f"{'shapes':>8} {'p':>5} | {'exact s':>8} {'cpu s':>7} {'cvxpy s':>8} {'cpu s':>7} {'ratio':>6} "
        f"{'cpu ratio':>9} | {'cost':>10} {'gap/cost':>9} {'rounds':>6} {'status':>18}"
    )
    for name, dist in (("uniform", "uniform"), ("mixed", MIXED)):
        if args.only in ("uniform", "mixed") and name != args.only:
            continue
        for p in (0.7, 0.9, 0.99):
            te, ce, tc, cc, last = [], [], [], [], None
            for _ in range(args.repeat):
                R = 0.5 * (1 + 0.02 * rng.random())
                w, c = _cold_cvxpy(m, R, p, dist)
                tc.append(w)
                cc.append(c)
                t0, c0 = time.perf_counter(), time.process_time()
                last = tolsynth.synthesize(m, R=R, p=p, distribution=dist, probability="exact")
                te.append(time.perf_counter() - t0)
                ce.append(time.process_time() - c0)
            e, c, ec, cvc = (statistics.median(x) for x in (te, tc, ce, cc))
            print(
                f"{name:>8} {p:5.2f} | {e:8.3f} {ec:7.3f} {c:8.3f} {cvc:7.3f} {e / c:6.1f} {ec / cvc:9.1f} | "
                f"{last.cost:10.4f} {last.gap / last.cost:9.1e} {len(last.history):6d} {str(last.status):>18}",
                flush=True,
            )
    if args.only:
        return
    # verify=True at p = 0.99: the time it adds
    tv = []
    for _ in range(args.repeat):
        R = 0.5 * (1 + 0.02 * rng.random())
        t0 = time.perf_counter()
        tolsynth.synthesize(m, R=R, p=0.99, probability="exact")
        t1 = time.perf_counter()
        tolsynth.synthesize(m, R=R, p=0.99, probability="exact", verify=True, seed=1)
        tv.append((time.perf_counter() - t1) - (t1 - t0))
    print(f"\nverify=True at p = 0.99 adds {statistics.median(tv):.2f} s (median)")
    # puma560 at 30 random poses
    from lean_cvxpy import random_poses

    pm = tolsynth.load_model("puma560")
    qs = random_poses(pm, 30, rng)
    t0 = time.perf_counter()
    r = tolsynth.synthesize(pm, R=1.0, p=0.95, poses=qs, probability="exact")
    print(
        f"puma560, 30 random poses, p = 0.95: {time.perf_counter() - t0:.2f} s, {r.status}, "
        f"gap/cost {r.gap / r.cost:.1e}"
    )
    # sphere against components
    ts, tcmp = [], []
    for _ in range(args.repeat):
        R = 0.5 * (1 + 0.02 * rng.random())
        t0 = time.perf_counter()
        tolsynth.synthesize(m, R=R, p=0.9, probability="exact")
        t1 = time.perf_counter()
        s = tolsynth.synthesize(m, R=R, p=0.9, criterion="sphere", probability="exact")
        ts.append(time.perf_counter() - t1)
        tcmp.append(t1 - t0)
    print(
        f"sphere p = 0.9: {statistics.median(ts):.2f} s against components {statistics.median(tcmp):.2f} s "
        f"({statistics.median(ts) / statistics.median(tcmp):.1f}x); {s.status}, cost {s.cost:.4f}, "
        f"bound {s.lower_bound:.4f}"
    )
    # all-normal: the Gaussian path
    tn, tg = [], []
    for _ in range(args.repeat):
        R = 0.5 * (1 + 0.02 * rng.random())
        t0 = time.perf_counter()
        tolsynth.synthesize(m, R=R, p=0.99, distribution="normal", probability="exact")
        t1 = time.perf_counter()
        tolsynth.synthesize(m, R=R * 1.001, p=0.99, distribution="normal", probability="gaussian")
        tn.append(t1 - t0)
        tg.append(time.perf_counter() - t1)
    print(
        f"all-normal p = 0.99: exact path {1e3 * statistics.median(tn):.2f} ms, Gaussian path "
        f"{1e3 * statistics.median(tg):.2f} ms"
    )


if __name__ == "__main__":
    main()
