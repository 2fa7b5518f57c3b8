"""Benchmark: every speed figure, with its target and the alternatives, in one run.

Prints medians over repeats (same process, same machine, same moment) of

Every cvxpy figure is the lean cvxpy + Clarabel model of ``benchmarks/lean_cvxpy.py`` (the reference
of every speed ratio: variables ``w = eps^2 / (c (R/z)^2)``, one 3x3 LMI per pose, the effective
cost factors and bounds as Parameters, the Problem built once and re-solved).

1. one warm solve of the paper's column (xu_zhang_1988, R = 0.5 mm, p = 0.99, uniform,
   alpha = 0.7): ``tolsynth.synthesize`` end to end (the default engine, the compiled
   interior-point method; and its kernel's own time inside it), timed with the lean model's
   re-solve in four batches spread over the run (its start, after sections 2, 3 and 4: this VM's
   speed drifts within minutes) and reported as the median over all of them, against
   * the lean cvxpy + Clarabel model re-solved (cvxpy keeps its canonicalisation);
   * ``solver="ipopt"``, IPOPT's warm re-solve (the general path, ``options={"warm_start": True}``),
     end to end;
   * scipy SLSQP with exact gradients (cost gradient from tolsynth's CasADi cost graph, the three
     eigenvalue constraints ``1 - lambda_j(As diag(e^{2u}) As^T / c)`` with their analytic
     gradients from the CasADi sensitivities), from a built specification, ``ftol`` tightened until
     the cost is within ``--rtol`` of the certified optimum;
   * SUMT + Powell (tolsynth's compiled paper method, same graphs), end to end;
   and a sweep step (R 0.2 % apart each call) against the lean model's;
2. many poses: random feasible pose sets (uniform inside the joint limits and constraints), a new
   set per repeat (so no remembered working set helps), ``synthesize(poses=...)`` end to end,
   against the lean model built and solved on the same set; the growth exponent of tolsynth's time
   fitted (least squares in log-log) over 30..1000 poses;
3. ``tolsynth reproduce`` (18 columns, IPOPT and SUMT + Powell): in-process ``reproduce()`` and
   the command as a subprocess;
4. the 100 x 100 probability map (``tolsynth.analysis.workspace_map.probability_map``, Figure 3), with the
   compiled inverse kinematics on every core, on one thread, and by the NumPy iteration (what a
   machine without a C compiler runs);
5. ``worst_pose(criterion="probability")`` (figure3 tolerances, R = 0.2 mm).

Ends with a Markdown table of every figure against its target (the README's speed table is
``speed_table.py``'s, which reuses this script's SLSQP and timing helpers).
``--quick`` keeps the whole run to about half a minute; the default run takes about a minute here.

Run: ``python benchmarks/bench_synthesis.py [--quick]`` (needs the ``bench`` extra: cvxpy,
clarabel, scipy).  The per-workload comparison with the lean model (cold solves, every kind of
sweep step, 10-1000 poses) is ``benchmarks/bench_solve.py``.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import time

import casadi as ca
import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from lean_cvxpy import LeanModel  # noqa: E402

import tolsynth  # noqa: E402
from tolsynth.kinematics.joint_space import _feasible, _limits  # noqa: E402
from tolsynth.problem.nlp import ToleranceNLP, cost_graph  # noqa: E402
from tolsynth.problem.specification import make_specification  # noqa: E402

R, P, DIST, ALPHA = 0.5, 0.99, "uniform", 0.7
#: IPOPT's warm re-solve is asked for: by default IPOPT starts from scratch (about 90 iterations)
IPOPT_WARM = {"warm_start": True}


def sample_times(fn, repeats):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return times, out


def median_time(fn, repeats):
    times, out = sample_times(fn, repeats)
    return statistics.median(times), out


class WarmBatches:
    """The warm solve and Clarabel's cached re-solve timed in batches spread over the run (at its
    start and after each later section), each batch back to back: on a VM whose speed drifts by
    up to 1.7x within minutes, one 0.4 s window decides nothing.  The figures are the medians over
    every sample of all batches; each batch's own medians are printed beside them."""

    def __init__(self, warm_fn, cl_fn, rep_warm, rep_cl):
        self.warm_fn, self.cl_fn, self.rep_warm, self.rep_cl = warm_fn, cl_fn, rep_warm, rep_cl
        self.warm, self.cl, self.batches = [], [], []

    def batch(self, where):
        w, res = sample_times(self.warm_fn, self.rep_warm)
        c, _ = sample_times(self.cl_fn, self.rep_cl)
        self.warm += w
        self.cl += c
        self.batches.append((where, statistics.median(w), statistics.median(c)))
        return res

    @property
    def t_warm(self):
        return statistics.median(self.warm)

    @property
    def t_cl(self):
        return statistics.median(self.cl)

    def spread(self):
        return ", ".join(f"{where} {fmt_t(w)} (lean cvxpy {fmt_t(c)})" for where, w, c in self.batches)


def random_poses(mech, N, rng):
    """N joint vectors (rad) drawn uniformly inside the joint limits and joint constraints."""
    lo, hi = _limits(mech)
    out = []
    while len(out) < N:
        Q = lo[:, None] + (hi - lo)[:, None] * rng.random((len(lo), 4 * N))
        out += [Q[:, j] for j in np.nonzero(_feasible(mech, Q))[0]]
    return out[:N]


# -- scipy SLSQP with exact gradients -----------------------------------------------------------
class SLSQPExact:
    """SLSQP in u = ln eps on the paper's per-eigenvalue constraints, exact gradients."""

    def __init__(self, spec):
        nlp = ToleranceNLP(spec)
        self.nlp = nlp
        cg = cost_graph(spec.n, nlp.costs.signature)
        u = ca.SX.sym("u", spec.n)
        th = ca.SX.sym("th", cg.size1_in(1))
        f = cg(u, th)
        self.fg = ca.Function("fg", [u, th], [f, ca.gradient(f, u)])
        self.As = nlp.As  # (m, 3, n), from the CasADi sensitivity graph
        self.c = spec.c

    def solve(self, ftol):
        from scipy.optimize import minimize

        nlp, As, c = self.nlp, self.As, self.c
        theta = nlp.theta

        def fun(u):
            f, g = self.fg(u, theta)
            return float(f), np.array(g).ravel()

        def eig(u):
            w = np.exp(2 * u) / c
            V = np.einsum("bin,n,bjn->bij", As, w, As)
            lam, E = np.linalg.eigh(V)
            return lam, E, w

        def cons(u):
            return (1.0 - eig(u)[0]).ravel()

        def cons_jac(u):
            lam, E, w = eig(u)
            proj = np.einsum("bij,bin->bjn", E, As)  # e_j . as_i, (m, 3, n)
            return (-2.0 * w * proj**2).reshape(-1, len(u))

        u0 = np.log(nlp.start_point())
        return minimize(
            fun,
            u0,
            jac=True,
            method="SLSQP",
            bounds=list(zip(nlp.lu, nlp.uu)),
            constraints=[{"type": "ineq", "fun": cons, "jac": cons_jac}],
            options={"ftol": ftol, "maxiter": 1000},
        )


def fmt_t(t):
    return f"{t * 1e3:.2f} ms" if t < 1 else f"{t:.2f} s"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats and sizes: about a minute")
    ap.add_argument("--rtol", type=float, default=1e-6, help="cost accuracy asked of SLSQP (default 1e-6)")
    args = ap.parse_args()
    quick = args.quick
    rep_warm = 100 if quick else 400
    rep_alt = 20 if quick else 100
    rep_pose = 2 if quick else 3
    rep_big = 1 if quick else 3
    table = []  # (figure, target, measured, alternatives, met)
    print(
        f"cores: {os.cpu_count()}, python {sys.version.split()[0]}, casadi {ca.__version__}, numpy {np.__version__}"
        f"{', --quick' if quick else ''}"
    )
    m = tolsynth.load_model("xu_zhang_1988")

    # == 1. one warm solve =====================================================================
    first = tolsynth.synthesize(m, R, P, DIST, ALPHA, probability="gaussian")
    ref = first.cost
    assert first.success and first.gap <= 1e-9 * ref, "reference optimum not certified"
    for _ in range(5):
        tolsynth.synthesize(m, R, P, DIST, ALPHA, probability="gaussian")
    spec = make_specification(m, R, P, DIST, ALPHA)
    lean = LeanModel(tolsynth.load_model("xu_zhang_1988"), ["worst"], DIST, ALPHA)
    lean.solve(R, P)  # first solve: canonicalisation (cached from here on)
    wb = WarmBatches(
        lambda: tolsynth.synthesize(m, R, P, DIST, ALPHA, probability="gaussian"),
        lambda: lean.solve(R, P),
        rep_warm,
        rep_alt,
    )
    res = wb.batch("start")
    t_e2e = wb.t_warm
    inside = statistics.median(
        tolsynth.synthesize(m, R, P, DIST, ALPHA, probability="gaussian").wall_time for _ in range(rep_alt)
    )
    # the compiled kernel alone (one ctypes call: the whole interior-point solve), timed around
    # each of its calls
    from tolsynth.solvers.fast_ipm import IPMKernel

    kernel_calls = []
    call = IPMKernel.solve

    def timed_call(self, *a, **kw):
        t0 = time.perf_counter()
        out = call(self, *a, **kw)
        kernel_calls.append(time.perf_counter() - t0)
        return out

    IPMKernel.solve = timed_call
    try:
        for _ in range(rep_alt):
            tolsynth.synthesize(m, R, P, DIST, ALPHA, probability="gaussian")
    finally:
        IPMKernel.solve = call
    t_call = statistics.median(kernel_calls)
    t_spec, _ = median_time(lambda: make_specification(m, R, P, DIST, ALPHA), rep_alt)
    t_cl, lres = wb.t_cl, lean.solve(R, P)
    cl_inside = lres.solve_time
    cl_err = abs(lres.cost - ref) / ref
    tolsynth.synthesize(m, R, P, DIST, ALPHA, solver="ipopt", probability="gaussian", options=IPOPT_WARM)
    t_ip, r_ip = median_time(
        lambda: tolsynth.synthesize(m, R, P, DIST, ALPHA, solver="ipopt", probability="gaussian", options=IPOPT_WARM),
        rep_alt,
    )
    sl = SLSQPExact(spec)
    for ftol in (1e-6, 1e-8, 1e-10, 1e-12, 1e-14):
        r_sl = sl.solve(ftol)
        if abs(r_sl.fun - ref) / ref <= args.rtol:
            break
    t_sl, r_sl = median_time(lambda: sl.solve(ftol), rep_alt)
    sl_err = abs(r_sl.fun - ref) / ref
    lam = np.linalg.eigvalsh(np.einsum("bin,n,bjn->bij", sl.As, np.exp(2 * r_sl.x) / sl.c, sl.As))
    sl_viol = float(np.sqrt(lam.max()) - 1)
    t_su, r_su = median_time(
        lambda: tolsynth.synthesize(m, R, P, DIST, ALPHA, solver="sumt", probability="gaussian"), max(5, rep_alt // 4)
    )
    print(
        f"\n1. one warm solve, paper's column (R {R} mm, p {P}, {DIST}, alpha {ALPHA}); optimum {ref:.10g}, "
        f"gap {first.gap:.1e}"
    )
    print(f"  {'solver':<66} {'median':>10} {'cost rel.err':>12}  ratio to tolsynth")
    print(
        f"  {'tolsynth.synthesize (default: interior point), end to end, first batch':<66} {fmt_t(t_e2e):>10} "
        f"{abs(res.cost - ref) / ref:>12.1e}  1 ({res.message})"
    )
    print(f"  {'  of which the solver (result.wall_time: kernel + checks)':<66} {fmt_t(inside):>10}")
    print(f"  {'  of which the compiled kernel itself (one ctypes call)':<66} {fmt_t(t_call):>10}")
    print(f"  {'  of which make_specification (checks, sensitivities)':<66} {fmt_t(t_spec):>10}")
    print(
        f"  {'lean cvxpy + Clarabel, the Problem re-solved, end to end':<66} {fmt_t(t_cl):>10} {cl_err:>12.1e}"
        f"  {t_cl / t_e2e:.2f}x"
    )
    print(f"  {'  of which inside Clarabel (solver_stats.solve_time)':<66} {fmt_t(cl_inside):>10}")
    label_ip = "solver='ipopt' (the exchange method, warm re-solve), end to end"
    print(
        f"  {label_ip:<66} {fmt_t(t_ip):>10} "
        f"{abs(r_ip.cost - ref) / ref:>12.1e}  {t_ip / t_e2e:.2f}x ({r_ip.iterations} IPOPT iterations)"
    )
    print(
        f"  {f'scipy SLSQP, exact gradients, ftol {ftol:g}, from a built spec':<66} {fmt_t(t_sl):>10} {sl_err:>12.1e}"
        f"  {t_sl / t_e2e:.2f}x (largest sigma z/R - 1 = {sl_viol:.1e}, {r_sl.nit} iterations)"
    )
    print(
        f"  {'SUMT + Powell (compiled), end to end':<66} {fmt_t(t_su):>10} {abs(r_su.cost - ref) / ref:>12.1e}"
        f"  {t_su / t_e2e:.2f}x"
    )
    # a sweep's step: each solve at another R (0.2 % apart): a new specification every call
    Rs = [R * (1 + 0.002 * k) for k in range(10)]
    step = {"k": 0}

    def neighbour_ts():
        step["k"] += 1
        return tolsynth.synthesize(m, Rs[step["k"] % 10], P, DIST, ALPHA, probability="gaussian")

    def neighbour_cl():
        step["k"] += 1
        return lean.solve(Rs[step["k"] % 10], P)

    for _ in range(10):
        neighbour_ts()
    t_nb, r_nb = median_time(neighbour_ts, rep_warm)
    its = [neighbour_ts().iterations for _ in range(20)]
    t_nbcl, _ = median_time(neighbour_cl, rep_alt)
    ok_nb = r_nb.success and r_nb.gap <= 1e-6 * r_nb.cost
    print(
        f"  {'tolsynth.synthesize, R changed 0.2 % per call (a sweep step)':<66} {fmt_t(t_nb):>10} {'':>12}"
        f"  {t_nb / t_e2e:.2f}x the same-spec re-solve; iterations median {statistics.median(its):g}; "
        f"certified {ok_nb}"
    )
    print(
        f"  {'lean cvxpy + Clarabel, the same R steps':<66} {fmt_t(t_nbcl):>10} {'':>12}"
        f"  {t_nbcl / t_nb:.2f}x tolsynth's step"
    )

    def warm_row():  # filled in at the end, from every batch
        t_w, t_c = wb.t_warm, wb.t_cl
        met = t_w <= 1e-3 and t_c / t_w >= 3 and t_sl > t_w
        return (
            "one warm solve, end to end",
            "<= 1 ms, >= 3x faster than the lean cvxpy model, ahead of SLSQP",
            f"{fmt_t(t_w)}: median of {len(wb.warm)} solves in {len(wb.batches)} batches over the run (the "
            f"compiled kernel itself {fmt_t(t_call)}, {res.iterations} iterations)",
            f"lean cvxpy + Clarabel {fmt_t(t_c)} ({t_c / t_w:.2f}x); IPOPT warm {fmt_t(t_ip)} ({t_ip / t_w:.2f}x); "
            f"SLSQP exact grad. {fmt_t(t_sl)} ({t_sl / t_w:.2f}x); SUMT + Powell {fmt_t(t_su)} "
            f"({t_su / t_w:.2f}x)",
            met,
        )

    table.append(None)  # the warm-solve row, filled in at the end
    table.append(
        (
            "a sweep step: a solve at another R (0.2 % apart)",
            ">= 3x faster than the lean cvxpy model",
            f"{fmt_t(t_nb)} (iterations median {statistics.median(its):g})",
            f"lean cvxpy + Clarabel, same steps {fmt_t(t_nbcl)} ({t_nbcl / t_nb:.2f}x)",
            t_nbcl / t_nb >= 3,
        )
    )

    # == 2. many poses =========================================================================
    sizes = [1, 10, 30, 100, 300, 1000]
    cl_max = 100 if quick else 300
    print(
        "\n2. random feasible pose sets on xu_zhang_1988, a new set per repeat; end to end, against the "
        "lean cvxpy model built and solved (cost difference '-': Clarabel did not report optimal)"
    )
    print(f"  {'poses':>6} {'tolsynth':>10} {'lean cvxpy':>10} {'ratio':>7} {'|cost diff|/cost':>16}  tolsynth message")
    rng = np.random.default_rng(2024)
    # untimed: the first solves of a size (the kernel's first use, cvxpy's imports)
    for N in (30, 300):
        ps = random_poses(m, N, np.random.default_rng(N))
        tolsynth.synthesize(m, R, P, DIST, ALPHA, poses=ps, probability="gaussian")
        LeanModel(m, ps, DIST, ALPHA).solve(R, P)
    t_of = {}
    for N in sizes:
        reps = rep_big if N >= 300 else rep_pose
        times, cl_times, diffs, msg = [], [], [], ""
        for _ in range(reps):
            poses = random_poses(m, N, rng)
            t0 = time.perf_counter()
            r = tolsynth.synthesize(m, R, P, DIST, ALPHA, poses=poses, probability="gaussian")
            times.append(time.perf_counter() - t0)
            assert r.success, r.message
            msg = r.message
            if N <= cl_max or (N == 1000 and not quick and not cl_times and len(times) == 1):
                t0 = time.perf_counter()
                c = LeanModel(m, poses, DIST, ALPHA).solve(R, P)
                cl_times.append(time.perf_counter() - t0)
                if c.success:
                    diffs.append(abs(c.cost - r.cost) / r.cost)
        t_of[N] = statistics.median(times)
        tc = statistics.median(cl_times) if cl_times else float("nan")
        ratio = f"{tc / t_of[N]:.1f}x" if cl_times else "-"
        diff = f"{max(diffs):.1e}" if diffs else "-"
        print(f"  {N:>6} {fmt_t(t_of[N]):>10} {fmt_t(tc) if cl_times else '-':>10} {ratio:>7} {diff:>16}  {msg}")
        if N == cl_max:
            t_cl_top = tc
        if N == 1000:
            t_cl1000 = tc if cl_times else None
    fit = [N for N in sizes if N >= 30]
    slope = float(np.polyfit(np.log(fit), np.log([t_of[N] for N in fit]), 1)[0])
    print(f"  growth exponent of tolsynth's time over {fit[0]}..{fit[-1]} poses: {slope:.2f}")
    alt = (
        f"lean cvxpy + Clarabel {fmt_t(t_cl1000)} ({t_cl1000 / t_of[1000]:.1f}x)"
        if t_cl1000
        else f"lean cvxpy at {cl_max} poses: {t_cl_top / t_of[cl_max]:.1f}x (1000 poses: run without --quick)"
    )
    table.append(
        (
            "1000 poses, cold",
            "< 2 s, linear growth",
            f"{fmt_t(t_of[1000])}, growth exponent {slope:.2f} (30..1000)",
            alt,
            t_of[1000] < 2 and slope <= 1.15,
        )
    )

    wb.batch("after the pose sets")

    # == 3. tolsynth reproduce ==================================================================
    from tolsynth.synthesis.reproduce import reproduce

    reproduce()  # warm-up (compiled libraries, graphs)
    t_rep, reps = median_time(reproduce, rep_big)
    worst = max(rep.agreement()["cost_rel_diff"] for rep in reps)
    exe = shutil.which("tolsynth", path=os.path.dirname(sys.executable))
    cmd = [exe, "reproduce"] if exe else [sys.executable, "-m", "tolsynth", "reproduce"]

    def run_cmd():
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0 or "all solves converged: True" not in proc.stdout:
            raise SystemExit(f"tolsynth reproduce failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")

    t_cmd, _ = median_time(run_cmd, rep_big)
    print(
        f"\n3. tolsynth reproduce (18 columns, IPOPT and SUMT + Powell): in-process {fmt_t(t_rep)}, "
        f"as the command {fmt_t(t_cmd)}; largest IPOPT-SUMT cost difference {worst:.1e}"
    )
    table.append(
        (
            "`tolsynth reproduce`, 18 columns, both solvers",
            "< 3 s on 2 cores",
            f"{fmt_t(t_cmd)} as the command ({fmt_t(t_rep)} in-process)",
            f"IPOPT-SUMT cost agreement {worst:.1e}",
            t_cmd < 3,
        )
    )

    wb.batch("after reproduce")

    # == 4. map, 5. worst pose ===================================================================
    from tolsynth.analysis.pose_search import worst_pose
    from tolsynth.analysis.workspace_map import probability_map
    from tolsynth.kinematics import ik_compiled

    def one_map():
        return probability_map(m, "figure3", R=0.2, n=100, progress=False)

    probability_map(m, "figure3", R=0.2, n=20, progress=False)  # compiles (or loads) the IK library
    backend = ik_compiled.backend_status()
    t_map, pm = median_time(one_map, rep_big)
    threads = ik_compiled._workers() if backend["backend"] == "compiled" else 1
    alts = []
    if backend["backend"] == "compiled":  # the same map on one thread, and by the NumPy iteration
        saved = ik_compiled.THREADS
        ik_compiled.THREADS = 1
        try:
            t_one, pm1 = median_time(one_map, rep_big)
        finally:
            ik_compiled.THREADS = saved
        os.environ["TOLSYNTH_NO_COMPILE"] = "1"
        try:
            t_np, pmn = median_time(one_map, 1)
        finally:
            del os.environ["TOLSYNTH_NO_COMPILE"]
        same = (
            np.array_equal(pm.reachable, pm1.reachable)
            and np.array_equal(pm.reachable, pmn.reachable)
            and float(np.nanmax(np.abs(pm.P - pmn.P))) <= 1e-9
        )
        alts = [f"one thread {fmt_t(t_one)}", f"NumPy iteration (no C compiler) {fmt_t(t_np)} ({t_np / t_map:.1f}x)"]
        print(
            f"\n4. the 100 x 100 probability map (figure3, R 0.2 mm): {fmt_t(t_map)} "
            f"({int(np.sum(pm.reachable))} reachable points; compiled IK on {threads} threads); on one thread "
            f"{fmt_t(t_one)}; by the NumPy iteration {fmt_t(t_np)}; the same map from all three: {same}"
        )
    else:
        print(
            f"\n4. the 100 x 100 probability map (figure3, R 0.2 mm): {fmt_t(t_map)} "
            f"({int(np.sum(pm.reachable))} reachable points; NumPy IK: {backend['reason']})"
        )
    table.append(
        (
            "100 x 100 map",
            "< 1 s",
            f"{fmt_t(t_map)} (IK {backend['backend']}, {threads} thread(s))",
            "; ".join(alts),
            t_map < 1,
        )
    )
    worst_pose(m, "figure3", criterion="probability", R=0.2)
    t_wp, wp = median_time(lambda: worst_pose(m, "figure3", criterion="probability", R=0.2), rep_big + 1)
    print(f"5. worst_pose(criterion='probability') (figure3, R 0.2 mm): {fmt_t(t_wp)}, P = {wp.value:.5f}")
    table.append(('`worst_pose(criterion="probability")`', "< 0.5 s", fmt_t(t_wp), "", t_wp < 0.5))

    wb.batch("at the end")
    table[table.index(None)] = warm_row()
    print(
        f"\n1'. the warm solve over the whole run: {fmt_t(wb.t_warm)} (lean cvxpy {fmt_t(wb.t_cl)}, "
        f"{wb.t_cl / wb.t_warm:.2f}x); batch medians: {wb.spread()}"
    )

    print(f"\nSummary ({os.cpu_count()} cores; medians in this run):\n")
    print("| figure | target | measured | alternatives, same run (their time / tolsynth's) | target met |")
    print("|---|---|---|---|---|")
    for fig, target, meas, alt, ok in table:
        print(f"| {fig} | {target} | {meas} | {alt} | {'-' if ok is None else 'yes' if ok else 'no'} |")


if __name__ == "__main__":
    main()
