"""Benchmark: every solve workload, tolsynth against the lean cvxpy + Clarabel model, paired.

The reference is :class:`lean_cvxpy.LeanModel` (the model a competent cvxpy user writes: ``w =
eps^2 / (c (R/z)^2)``, one 3x3 LMI per pose, the effective cost factors and the bounds on w as
Parameters, the Problem built once).  Each workload runs both sides in the same process,
interleaved repeat by repeat (the order alternating), on the same specification; the table gives
the medians, their ratio (cvxpy / tolsynth: above 1 means tolsynth is faster) and the largest
relative difference of the optimal costs over the repeats.  Every timed tolsynth result must be
``success`` (certified) and every lean one optimal (Clarabel's "optimal_inaccurate" counted and
shown).  A difference above 1e-6 fails the row unless the lean cost lies above a tolsynth optimum
whose certified gap is within 1e-6 (Clarabel at its default tolerances stops up to about 1e-6
above the optimum on 30-pose sets; those pairs are counted as "lean above certified").

Workloads (R 0.5 mm, p 0.99, uniform, alpha 0.7 unless the step changes it):

* cold single-pose solve of the paper's robot (xu_zhang_1988, pose ``worst``): each repeat loads
  the model afresh (untimed; one copy per side, so neither reuses the other's sensitivities) and
  draws new cost factors k (x 0.8 to 1.25 per parameter: a specification no earlier solve had);
  timed: ``tolsynth.synthesize`` against building a LeanModel and solving it;
* one step of a sweep on the paper's robot, each step a value no earlier step had: k of one
  parameter (+1 % a step), alpha (+0.002), the upper bound of the loosest parameter (held at
  0.8 x its optimum, +0.2 % a step: active), a lock of one parameter (0.9 x its optimum, +0.2 %),
  R (+0.2 %), p (-0.0002).  tolsynth with its defaults, from scratch (nothing from the earlier
  steps: an answer never depends on what ran before it); the lean model built once and re-solved
  (alpha: rebuilt, cvxpy cannot take it as a Parameter);
* puma560 and panda (bundled models) at 10, 30 and 100 random poses inside the joint limits, a
  new pose set each repeat, cold (both sides' one-off set-up for a size done once, untimed);
* 1000 random poses: an R sweep step (+0.2 %) on a fixed set of 1000 poses, tolsynth from scratch
  (its default) and asked to warm-start from the step before (``options={"warm_start": True}``),
  the lean model built once (puma560; panda too without ``--quick``); without ``--quick`` also a
  k step on the same set, from scratch.

Run: ``python benchmarks/bench_solve.py [--quick]`` (``--quick``: fewer repeats, under about a
minute on 2 cores).  Needs cvxpy and clarabel (the ``bench`` extra).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from lean_cvxpy import LeanModel, random_poses

import tolsynth

R, P, DIST, ALPHA = 0.5, 0.99, "uniform", 0.7
TARGET = 3.0  # cvxpy time / tolsynth time asked of every workload
RTOL = 1e-6  # the same optimum: relative cost difference
#: readable names of ``SynthesisResult.solver`` (the engine solver="auto" chose)
ENGINES = {"ipm": "compiled interior point", "ipopt": "IPOPT", "sumt": "SUMT + Powell"}


def fmt_t(t: float) -> str:
    return f"{t * 1e3:.2f} ms" if t < 1 else f"{t:.2f} s"


class Row:
    """One workload's paired samples."""

    def __init__(self, label: str, target: str = f">= {TARGET:g}x"):
        self.label, self.target = label, target
        self.ts, self.lean, self.rel, self.its, self.lean_its = [], [], [], [], []
        self.engines = {}  # result.solver -> count: which engine the default solver="auto" ran
        self.failures, self.signed, self.retried, self.inaccurate = [], [], 0, 0
        self.above = 0  # pairs beyond 1e-6 where the lean cost lies above a certified tolsynth optimum

    def add(self, t_ts, r_ts, t_lean, r_lean):
        self.ts.append(t_ts)
        self.lean.append(t_lean)
        if not r_ts.success:
            self.failures.append(f"tolsynth: {r_ts.message}")
        if not r_lean.success:
            self.failures.append(f"lean: {r_lean.status}")
        self.signed.append((r_lean.cost - r_ts.cost) / abs(r_ts.cost))
        self.rel.append(abs(self.signed[-1]))
        if self.rel[-1] > RTOL:
            certified = r_ts.success and r_ts.gap <= RTOL * abs(r_ts.cost)
            if self.signed[-1] > 0 and certified:
                self.above += 1  # Clarabel stopped short of an optimum tolsynth proves: tolsynth is right
            else:
                self.failures.append(f"cost differs by {self.signed[-1]:.1e}")
        self.retried += r_lean.retried
        self.inaccurate += r_lean.status == "optimal_inaccurate"
        self.its.append(r_ts.iterations)
        self.engines[r_ts.solver] = self.engines.get(r_ts.solver, 0) + 1
        self.lean_its.append(r_lean.iterations)

    @property
    def t_ts(self):
        return statistics.median(self.ts)

    @property
    def t_lean(self):
        return statistics.median(self.lean)

    @property
    def ratio(self):
        return self.t_lean / self.t_ts

    def met(self) -> bool:
        ok = self.ratio >= TARGET and not self.failures
        if self.target.startswith("< 0.1 s"):
            ok = ok and self.t_ts < 0.1
        return ok

    def line(self) -> str:
        same = (
            f"{max(self.rel):.1e}"
            + (f" ({self.above} lean above certified)" if self.above else "")
            + (f" ({len(self.failures)} FAILED)" if self.failures else "")
        )
        return (
            f"| {self.label} | {fmt_t(self.t_ts)} | {fmt_t(self.t_lean)} | {self.ratio:.2f}x | {same} | "
            f"{self.target}: {'yes' if self.met() else 'no'} |"
        )

    def engine(self) -> str:
        """Which engine ran the tolsynth side: one name, or each with its count where they differ."""
        if len(self.engines) == 1:
            return ENGINES.get(next(iter(self.engines)), next(iter(self.engines)))
        return ", ".join(f"{ENGINES.get(k, k)} {n}x" for k, n in sorted(self.engines.items()))

    def detail(self) -> str:
        return (
            f"  {self.label}: tolsynth {fmt_t(self.t_ts)} ({self.engine()}; iterations median "
            f"{statistics.median(self.its):g}), "
            f"lean {fmt_t(self.t_lean)} (Clarabel iterations median {statistics.median(self.lean_its):g}), "
            f"{self.ratio:.2f}x over {len(self.ts)} pairs; cost (lean - tolsynth) / tolsynth from "
            f"{min(self.signed):.1e} to {max(self.signed):.1e}"
            + (f"; lean retried {self.retried}x" if self.retried else "")
            + (f"; lean 'optimal_inaccurate' {self.inaccurate}x" if self.inaccurate else "")
            + (f"; FAILURES: {self.failures[:3]}" if self.failures else "")
        )


def paired(row: Row, reps: int, setup, ts_fn, lean_fn) -> Row:
    """``reps`` pairs: ``args = setup(i)`` untimed, then ``ts_fn(*args)`` and ``lean_fn(*args)``
    timed, the order alternating (a drift of the machine's speed hits both sides alike)."""
    for i in range(reps):
        args = setup(i)
        out = {}
        for side in ("ts", "lean") if i % 2 == 0 else ("lean", "ts"):
            fn = ts_fn if side == "ts" else lean_fn
            t0 = time.perf_counter()
            res = fn(*args)
            out[side] = (time.perf_counter() - t0, res)
        row.add(*out["ts"], *out["lean"])
    print(row.detail(), flush=True)
    return row


def cold_single(reps: int, rng) -> Row:
    name = "xu_zhang_1988"
    k0 = tolsynth.load_model(name).k

    def setup(i):
        return tolsynth.load_model(name), tolsynth.load_model(name), k0 * rng.uniform(0.8, 1.25, len(k0))

    def ts(m_ts, m_lean, k):
        return tolsynth.synthesize(m_ts, R, P, DIST, ALPHA, k=k, probability="gaussian")

    def lean(m_ts, m_lean, k):
        return LeanModel(m_lean, ["worst"], DIST, ALPHA).solve(R, P, k=k)

    warm = setup(-1)
    ts(*warm), lean(*warm)  # imports, compiled libraries, cvxpy's first-use costs: untimed
    return paired(Row("cold single-pose solve, paper's robot (new model, new k)"), reps, setup, ts, lean)


def sweeps(reps: int) -> list[Row]:
    m = tolsynth.load_model("xu_zhang_1988")
    lm = LeanModel(tolsynth.load_model("xu_zhang_1988"), ["worst"], DIST, ALPHA)
    base = tolsynth.synthesize(m, R, P, DIST, ALPHA, probability="gaussian")
    lm.solve(R, P)
    names, eps = m.error_parameters, base.x
    lo, _ = m.bounds
    j = int(np.argmax(eps))  # the loosest tolerance: its upper bound below its optimum is active
    rows = []

    def run(label, ts_kw, lean_kw):
        ts = lambda kw: tolsynth.synthesize(
            m,
            kw.get("R", R),
            kw.get("p", P),
            DIST,
            kw.get("alpha", ALPHA),
            probability="gaussian",  # the lean model's problem
            **{k: v for k, v in kw.items() if k not in ("R", "p", "alpha")},
        )
        lean = lambda kw: lm.solve(
            kw.get("R", R), kw.get("p", P), **{k: v for k, v in kw.items() if k not in ("R", "p")}
        )
        ts(ts_kw(0)), lean(lean_kw(0))  # the sweep's first point, untimed
        row = paired(
            Row(label), reps, lambda i: (ts_kw(i + 1), lean_kw(i + 1)), lambda a, b: ts(a), lambda a, b: lean(b)
        )
        rows.append(row)

    def k_step(i):
        k = m.k
        k[0] *= 1 + 0.01 * i
        return {"k": k}

    run(f"sweep step, from scratch (the default): k of {names[0]} (+1 %)", k_step, k_step)
    lm.solve(R, P)
    run(
        "sweep step, from scratch (the default): alpha (+0.002; lean rebuilds)",
        lambda i: {"alpha": ALPHA + 0.002 * i},
        lambda i: {"alpha": ALPHA + 0.002 * i},
    )
    lm.solve(R, P, alpha=ALPHA)
    up = lambda i: 0.8 * eps[j] * (1 + 0.002 * i)
    run(
        f"sweep step, from scratch (the default): upper bound of {names[j]} (active, +0.2 %)",
        lambda i: {"bounds": {names[j]: (lo[j], up(i))}},
        lambda i: {"upper": {names[j]: up(i)}},
    )
    lk = lambda i: {"locks": {names[0]: 0.9 * eps[0] * (1 + 0.002 * i)}}
    run(f"sweep step, from scratch (the default): lock of {names[0]} (+0.2 %)", lk, lk)
    rs = lambda i: {"R": R * (1 + 0.002 * i)}
    run("sweep step, from scratch (the default): R (+0.2 %)", rs, rs)
    ps = lambda i: {"p": P - 0.0002 * i}
    run("sweep step, from scratch (the default): p (-0.0002)", ps, ps)
    return rows


def many_poses(name: str, sizes, reps: dict, rng) -> list[Row]:
    m_ts, m_lean = tolsynth.load_model(name), tolsynth.load_model(name)
    rows = []
    for N in sizes:

        def setup(i, N=N):
            return (random_poses(m_ts, N, rng),)

        ts = lambda poses: tolsynth.synthesize(m_ts, R, P, DIST, ALPHA, poses=poses, probability="gaussian")
        lean = lambda poses: LeanModel(m_lean, poses, DIST, ALPHA).solve(R, P)
        warm = setup(-1)
        ts(*warm), lean(*warm)  # one-off set-up of this size (tolsynth's NLP graphs per cut count)
        rows.append(paired(Row(f"{name}, {N} random poses, cold"), reps[N], setup, ts, lean))
    return rows


def warm_1000(name: str, reps: int, rng, k_step: bool) -> list[Row]:
    m = tolsynth.load_model(name)
    poses = random_poses(m, 1000, rng)
    lm = LeanModel(tolsynth.load_model(name), poses, DIST, ALPHA)
    (
        tolsynth.synthesize(m, R, P, DIST, ALPHA, poses=poses, probability="gaussian"),
        lm.solve(R, P),
    )  # built, canonicalised: untimed
    rows = []
    rs = lambda i: R * (1 + 0.002 * (i + 1))
    for how, options in (("from scratch (the default)", None), ("asked to warm-start", {"warm_start": True})):
        rows.append(
            paired(
                Row(f"{name}, 1000 random poses, R step (+0.2 %), {how}", "< 0.1 s and >= 3x"),
                reps,
                lambda i: (rs(i),),
                lambda r, options=options: tolsynth.synthesize(
                    m, r, P, DIST, ALPHA, poses=poses, probability="gaussian", options=options
                ),
                lambda r: lm.solve(r, P),
            )
        )
    if k_step:

        def ks(i):
            k = m.k
            k[0] *= 1 + 0.01 * (i + 1)
            return (k,)

        rows.append(
            paired(
                Row(f"{name}, 1000 random poses, k step (+1 %), from scratch (the default)", "< 0.1 s and >= 3x"),
                reps,
                ks,
                lambda k: tolsynth.synthesize(m, R, P, DIST, ALPHA, poses=poses, k=k, probability="gaussian"),
                lambda k: lm.solve(R, P, k=k),
            )
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats: under about a minute")
    args = ap.parse_args()
    quick = args.quick
    import casadi
    import cvxpy

    print(
        f"cores: {os.cpu_count()}, python {sys.version.split()[0]}, numpy {np.__version__}, casadi "
        f"{casadi.__version__}, cvxpy {cvxpy.__version__}{', --quick' if quick else ''}",
        flush=True,
    )
    t_start = time.perf_counter()
    rng = np.random.default_rng(22)
    rows = [cold_single(6 if quick else 30, rng)]
    rows += sweeps(8 if quick else 40)
    reps = {10: 3, 30: 3, 100: 2} if quick else {10: 9, 30: 7, 100: 5}
    for name in ("puma560", "panda"):
        rows += many_poses(name, (10, 30, 100), reps, rng)
    for name in ("puma560",) if quick else ("puma560", "panda"):
        rows += warm_1000(name, 3 if quick else 7, rng, k_step=not quick)

    print(
        f"\nSummary ({os.cpu_count()} cores, paired medians in one run of {time.perf_counter() - t_start:.0f} s; "
        f"ratio = lean cvxpy time / tolsynth time, above 1: tolsynth faster):\n"
    )
    print(
        "| workload | tolsynth median | lean cvxpy median | ratio (cvxpy/tolsynth) | same optimum (rel diff) | target (>= 3x) |"
    )
    print("|---|---|---|---|---|---|")
    for row in rows:
        print(row.line())


if __name__ == "__main__":
    main()
