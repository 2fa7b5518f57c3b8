"""The acceptance table: the uniform columns of Tables 1-2 (xu_zhang_1988, R = 0.5 mm,
alpha 0.7, p = 0.7, 0.8, 0.9, 0.99) designed with the Gaussian reading (the paper's) and with the
exact probabilities, each checked by the nonlinear Monte Carlo along its binding direction
(the worst direction of the exact design; the same direction for the Gaussian one), 99 % Wilson
intervals.  Also the sphere criterion, and the times.

    python benchmarks/bench_exact.py [--n 400000] [--sphere]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import tolsynth
from tolsynth.probability.exact import direction_probability


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=400_000, help="Monte Carlo samples per design (default 400000)")
    ap.add_argument("--sphere", action="store_true", help="also the sphere criterion")
    args = ap.parse_args()
    m = tolsynth.load_model("xu_zhang_1988")
    A = m.sensitivity(m.joints("worst"))[:3]
    sh = ["uniform"] * m.n
    R = 0.5
    print(f"xu_zhang_1988, R = {R} mm, uniform errors, alpha 0.7; Monte Carlo n = {args.n}, 99 % intervals")
    print(f"{'p':>5} | {'Gaussian cost':>13} {'exact cost':>10} {'diff':>7} | "
          f"{'exact P along w*':>16} {'MC at exact design':>28} {'p in CI':>7} | {'Gaussian design: exact P':>24} "
          f"{'MC':>8} | {'t exact s':>9}")
    for p in (0.7, 0.8, 0.9, 0.99):
        g = tolsynth.synthesize(m, R=R, p=p)
        t0 = time.perf_counter()
        e = tolsynth.synthesize(m, R=R, p=p, probability="exact")
        te = time.perf_counter() - t0
        w = e.constraints[0].directions[:, 0]
        Pe = direction_probability(w @ A * e.x, sh, R)
        Pg = direction_probability(w @ A * g.x, sh, R)
        mce = tolsynth.monte_carlo(m, "worst", e.x, R=R, n=args.n, seed=1, directions=w[:, None], confidence=0.99)
        mcg = tolsynth.monte_carlo(m, "worst", g.x, R=R, n=args.n, seed=2, directions=w[:, None], confidence=0.99)
        lo, hi = mce.p_directions_ci[0]
        print(f"{p:5.2f} | {g.cost:13.4f} {e.cost:10.4f} {100 * (e.cost / g.cost - 1):+6.2f}% | "
              f"{Pe:16.7f} {mce.p_directions[0]:10.5f} [{lo:.5f}, {hi:.5f}] {str(bool(lo <= p <= hi)):>7} | "
              f"{Pg:24.5f} {mcg.p_directions[0]:8.5f} | {te:9.1f}")
    if args.sphere:
        print("\nsphere criterion P(|dr| <= R) >= p")
        for p in (0.7, 0.8, 0.9, 0.99):
            g = tolsynth.synthesize(m, R=R, p=p, criterion="sphere")
            t0 = time.perf_counter()
            e = tolsynth.synthesize(m, R=R, p=p, criterion="sphere", probability="exact")
            te = time.perf_counter() - t0
            mce = tolsynth.monte_carlo(m, "worst", e.x, R=R, n=args.n, seed=3, confidence=0.99)
            mcg = tolsynth.monte_carlo(m, "worst", g.x, R=R, n=args.n, seed=4, confidence=0.99)
            lo, hi = mce.p_sphere_ci
            print(f"{p:5.2f} | Gaussian {g.cost:10.4f} (MC {mcg.p_sphere:.5f}) | exact {e.cost:10.4f} "
                  f"({100 * (e.cost / g.cost - 1):+.2f}%), MC {mce.p_sphere:.5f} [{lo:.5f}, {hi:.5f}] "
                  f"p in CI {bool(lo <= p <= hi)} | {te:.1f} s")
    np.set_printoptions(precision=4)


if __name__ == "__main__":
    main()
