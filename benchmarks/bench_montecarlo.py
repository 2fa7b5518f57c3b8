"""Benchmark of the Monte Carlo, the worst-pose search and the Figure 3 map.

Run:  python benchmarks/bench_montecarlo.py [--quick]

Everything runs on ONE core: the BLAS/OpenMP thread counts are set to 1 before NumPy is imported
and the process is pinned to one CPU where the OS allows it.  Each timing is the median of
``--repeats`` runs.  Printed:

* Monte Carlo samples per second for ``xu_zhang_1988`` (figure3 tolerances, uniform, worst pose):
  ``tolsynth.monte_carlo`` end to end (random numbers, nonlinear kinematics, statistics), and the
  kinematics alone by the NumPy interpreter of the CasADi graph, next to the alternatives on the
  same ``position`` Function: CasADi ``map`` (serial; from NumPy arrays and from DM), the same
  ``map`` compiled by CasADi's JIT (gcc, if present), and one CasADi call per sample; with the
  ratio to ``monte_carlo``;
* peak traced memory (tracemalloc) against n, to show that it is flat;
* the time of a 100 x 100 map and of the worst-pose search.
"""

from __future__ import annotations

import os

for _var in (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "BLIS_NUM_THREADS",
):
    os.environ[_var] = "1"
try:
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    PINNED = True
except (AttributeError, OSError):  # pragma: no cover - not Linux
    PINNED = False

import argparse  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402

import casadi as ca  # noqa: E402
import numpy as np  # noqa: E402

import tolsynth  # noqa: E402
from tolsynth import probability_map, worst_pose  # noqa: E402
from tolsynth.analysis.montecarlo import DEFAULT_BATCH, NumpyEvaluator, monte_carlo  # noqa: E402


def median_time(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller n, fewer repeats")
    ap.add_argument("--repeats", type=int, default=None)
    args = ap.parse_args()
    repeats = args.repeats or (3 if args.quick else 5)
    n_mc = 1_000_000 if args.quick else 4_000_000
    B = DEFAULT_BATCH

    m = tolsynth.load_model("xu_zhang_1988")
    q = m.joints("worst")
    eps = m.tolerances("figure3")
    f = m.graphs.position
    print(
        f"tolsynth {tolsynth.__version__}, casadi {ca.__version__}, numpy {np.__version__}; "
        f"one core ({'pinned' if PINNED else 'not pinned'}, thread counts 1); median of {repeats}"
    )
    print(
        f"model xu_zhang_1988, tolerances figure3, uniform, pose 'worst'; position graph: "
        f"{f.n_instructions()} instructions; batch {B}"
    )
    print()

    rng = np.random.default_rng(0)
    D = rng.uniform(-1, 1, (m.n, B)) * eps[:, None]
    Q = np.repeat(q[:, None], B, axis=1)
    rows = []  # (name, samples/s, note)

    monte_carlo(m, q, eps, R=0.2, n=B, seed=0)  # warm up (graph construction, caches)
    t = median_time(lambda: monte_carlo(m, q, eps, R=0.2, n=n_mc, seed=1), repeats)
    rate_mc = n_mc / t
    rows.append(("tolsynth.monte_carlo (end to end)", rate_mc, f"n = {n_mc:,}: draws + nonlinear fk + statistics"))

    ev = NumpyEvaluator(f)
    prog = ev.bind([q, np.zeros(m.n)], [np.zeros(len(q), bool), eps > 0])
    Dact = D[eps > 0]
    reps = max(1, 200_000 // B) * 10
    t = median_time(lambda: [prog(Dact) for _ in range(reps)], repeats)
    rows.append(("NumPy interpreter of the graph (fk only)", reps * B / t, "joint-only part evaluated once"))

    fm = f.map(B, "serial")
    t = median_time(lambda: fm(Q, D), repeats)
    rows.append(("casadi map serial, NumPy in/out", B / t, "includes NumPy<->DM conversion"))
    Qd, Dd = ca.DM(Q), ca.DM(D)
    t = median_time(lambda: fm(Qd, Dd), repeats)
    rows.append(("casadi map serial, DM in/out", B / t, "SX virtual machine"))

    if shutil.which("gcc") or shutil.which("cc"):
        try:
            t0 = time.perf_counter()
            fj = ca.Function(
                "position_jit",
                f.sx_in(),
                f.call(f.sx_in()),
                {"jit": True, "compiler": "shell", "jit_options": {"flags": ["-O3"]}},
            )
            fjm = fj.map(B, "serial")
            fjm(Qd, Dd)
            compile_s = time.perf_counter() - t0
            t = median_time(lambda: fjm(Qd, Dd), repeats)
            rows.append(("casadi map, JIT-compiled (gcc -O3), DM in/out", B / t, f"+ {compile_s:.2f} s compile"))
            t = median_time(lambda: fjm(Q, D), repeats)
            rows.append(("casadi map, JIT-compiled, NumPy in/out", B / t, "includes NumPy<->DM conversion"))
        except Exception as exc:  # noqa: BLE001 - report and go on
            rows.append(("casadi map, JIT-compiled", float("nan"), f"failed: {exc}".splitlines()[0][:60]))
    else:
        rows.append(("casadi map, JIT-compiled", float("nan"), "no C compiler"))

    k = 5000
    t = median_time(lambda: [f(q, D[:, i]) for i in range(k)], repeats)
    rows.append(("casadi Function call per sample", k / t, ""))

    print(f"{'Monte Carlo throughput':50}{'samples/s':>14}{'vs monte_carlo':>16}  note")
    for name, rate, note in rows:
        ratio = rate / rate_mc if np.isfinite(rate) else float("nan")
        print(f"{name:50}{rate:14,.0f}{ratio:15.2f}x  {note}")
    print(f"requirement >= 1e6 samples/s: {'met' if rate_mc >= 1e6 else 'NOT met'} ({rate_mc / 1e6:.2f} M/s)")
    print()

    print(f"{'peak traced memory vs n (tracemalloc)':50}{'n':>14}{'peak MB':>12}")
    ns = (100_000, 1_000_000) if args.quick else (100_000, 1_000_000, 10_000_000)
    for n in ns:
        tracemalloc.start()
        monte_carlo(m, q, eps, R=0.2, n=n, seed=0)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        print(f"{'monte_carlo, batch ' + str(B):50}{n:14,}{peak / 1e6:12.2f}")
    print()

    probability_map(m, "figure3", R=0.2, n=20, progress=False)  # warm up
    t = median_time(lambda: probability_map(m, "figure3", R=0.2, n=100, progress=False), max(1, repeats // 2))
    pm = probability_map(m, "figure3", R=0.2, n=100, progress=False)
    print(
        f"{'100 x 100 map (figure3, R = 0.2 mm, uniform)':50}{t:10.2f} s  "
        f"({int(np.isfinite(pm.P).sum())} reachable points, IK + statistics)"
    )
    t = median_time(lambda: worst_pose(m, "figure3", criterion="sigma"), repeats)
    print(f"{'worst-pose search, criterion sigma':50}{t:10.2f} s")
    t = median_time(lambda: worst_pose(m, "figure3", criterion="probability", R=0.2), max(1, repeats // 2))
    print(f"{'worst-pose search, criterion probability':50}{t:10.2f} s")


if __name__ == "__main__":
    main()
