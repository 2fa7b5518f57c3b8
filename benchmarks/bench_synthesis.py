"""Benchmark: one column of the paper (R = 0.5 mm, p = 0.99, uniform, alpha = 0.7), three solvers.

* IPOPT through CasADi with exact derivatives (tolsynth's default), graph already built;
* SUMT + Powell, the paper's method (tolsynth's built-in, same graphs);
* scipy's SLSQP with finite-difference gradients on the paper's per-eigenvalue constraints
  ``sigma_j z / R <= 1`` (NumPy eigvalsh), what an engineer would otherwise reach for.

Each must reach the same cost accuracy: within ``--rtol`` (default 1e-5) of the certified optimum
(IPOPT's, whose dual bound closes the gap); SLSQP's constraint violation is printed too (with the
non-smooth eigenvalue constraints and FD gradients it stops about 1e-6 inside the infeasible side).  Prints the median wall time of each over repeats and
the ratios.  Run: ``python benchmarks/bench_synthesis.py``.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np

import tolsynth
from tolsynth.stats import z_of_p


def slsqp(mech, R, p, alpha, ftol):
    from scipy.optimize import minimize

    S = mech.sensitivity("worst")[:3]
    k = mech.k
    lo, hi = mech.bounds
    z = z_of_p(p)

    def cost(x):
        return float(np.sum(k * x**-alpha))

    def cons(x):
        V = (S * (x**2 / 3.0)) @ S.T
        return 1.0 - np.sqrt(np.clip(np.linalg.eigvalsh(V), 0, None)) * z / R

    x0 = np.full(len(k), 0.01)
    res = minimize(cost, x0, method="SLSQP", bounds=list(zip(lo, hi)),
                   constraints=[{"type": "ineq", "fun": cons}], options={"ftol": ftol, "maxiter": 1000})
    return res


def median_time(fn, repeats):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=0, help="repeats per solver (default: 50 / 5 / 20)")
    ap.add_argument("--rtol", type=float, default=1e-5, help="required relative cost accuracy")
    args = ap.parse_args()
    R, p, alpha = 0.5, 0.99, 0.7
    mech = tolsynth.load_model("xu_zhang_1988")

    t0 = time.perf_counter()
    first = tolsynth.synthesize(mech, R, p, "uniform", alpha)  # builds and caches the graphs
    build = time.perf_counter() - t0
    ref = first.cost
    assert first.success and first.gap <= 1e-9 * ref, "reference optimum not certified"
    print(f"reference optimum (IPOPT, certified): cost {ref:.10g}, dual bound {first.lower_bound:.10g}")
    print(f"first call incl. graph construction: {build * 1e3:.1f} ms\n")

    rows = []
    # IPOPT: synthesize() end to end (sensitivities, checks, solve) and the solver alone
    t_ip, r_ip = median_time(lambda: tolsynth.synthesize(mech, R, p, "uniform", alpha), args.repeats or 50)
    rows.append(("IPOPT (exact derivatives), synthesize() end to end", t_ip, r_ip.cost, r_ip.iterations, r_ip.function_evaluations))
    rows.append(("IPOPT, time inside the solver only", r_ip.wall_time, r_ip.cost, r_ip.iterations, r_ip.function_evaluations))
    t_su, r_su = median_time(lambda: tolsynth.synthesize(mech, R, p, "uniform", alpha, solver="sumt"), args.repeats or 5)
    rows.append(("SUMT + Powell (built in)", t_su, r_su.cost, r_su.iterations, r_su.function_evaluations))
    # SLSQP: tighten ftol until the cost accuracy is reached
    for ftol in (1e-6, 1e-8, 1e-10, 1e-12):
        res = slsqp(mech, R, p, alpha, ftol)
        if abs(res.fun - ref) / ref <= args.rtol:
            break
    t_sl, r_sl = median_time(lambda: slsqp(mech, R, p, alpha, ftol), args.repeats or 20)
    rows.append((f"scipy SLSQP, FD gradients (ftol {ftol:g})", t_sl, float(r_sl.fun), int(r_sl.nit), int(r_sl.nfev)))

    print(f"{'solver':<52} {'median ms':>10} {'cost rel.err':>12} {'iter':>6} {'evals':>7}")
    for name, t, cost, nit, nfev in rows:
        print(f"{name:<52} {t * 1e3:>10.2f} {abs(cost - ref) / ref:>12.1e} {nit:>6d} {nfev:>7d}")
    print()
    print(f"SUMT + Powell / IPOPT (end to end): {t_su / t_ip:8.1f}x")
    print(f"SLSQP (FD)    / IPOPT (end to end): {t_sl / t_ip:8.1f}x")
    acc_ok = abs(r_sl.fun - ref) / ref <= args.rtol
    S = mech.sensitivity("worst")[:3]
    V = (S * (r_sl.x**2 / 3.0)) @ S.T
    viol = math.sqrt(np.linalg.eigvalsh(V).max()) * z_of_p(p) / R - 1
    print(f"SLSQP reached the cost accuracy {args.rtol:g}: {acc_ok} (success flag {r_sl.success}: {r_sl.message}); "
          f"largest sigma z/R - 1 = {viol:.1e}")
    print(f"IPOPT: {r_ip.max_constraint - 1:.1e} (largest sigma z/R - 1); one solve inside IPOPT {r_ip.wall_time * 1e3:.2f} ms")


if __name__ == "__main__":
    main()
