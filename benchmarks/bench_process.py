"""Process choice: branch and bound against brute-force enumeration, and the
proven optimum against rounding the continuous relaxation to a process.

Prints, per case: combinations, continuous solves by B&B, wall times (median of --repeat runs),
the proven optimum and the rounded cost.  Brute force runs only where it has <= --brute
combinations.  Usage: python benchmarks/bench_process.py [--repeat 3] [--brute 100]
"""

import argparse
import statistics
import time

import tolsynth
from tolsynth.model.cost import Chase, Exponential, PowerLaw
from tolsynth.synthesis.processes import Process, enumerate_processes, synthesize_processes


def planar():
    lengths = [
        Process("turning", Chase(1.0, 0.4, 1.0), 0.1, 1.0),
        Process("grinding", Chase(3.0, 0.3, 1.0), 0.02, 0.06),
        Process("lapping", Exponential(12.0, 20.0), 0.002, 0.015),
    ]
    angles = [Process("standard", PowerLaw(1.5, 0.7), 0.5, 5.0), Process("precision", PowerLaw(6.0, 0.7), 0.05, 0.4)]
    return "planar_2r", {"l1": lengths, "l2": lengths, "o1": angles, "o2": angles}


def robot():
    m = tolsynth.load_model("xu_zhang_1988")
    half = {3: 0.0065, 5: 0.0125, 7: 0.0285, 11: 0.18}  # ISO 286-1 IT grades, 315-400 mm, halved
    lengths = [
        Process("turning", Chase(1.0, 0.02, 1.0), half[7], half[11]),
        Process("grinding", Chase(2.0, 0.01, 1.0), half[5], half[7]),
        Process("lapping", Chase(4.0, 0.004, 1.0), half[3], half[5]),
    ]
    angles = [
        Process("standard", Chase(1.0, 0.05, 1.0), 0.05, 1.0),
        Process("precision", Chase(3.0, 0.02, 1.0), 0.005, 0.05),
    ]
    return "xu_zhang_1988", {nm: (lengths if u == "mm" else angles) for nm, u in zip(m.error_parameters, m.units)}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--brute", type=int, default=100)
    a = ap.parse_args()
    print(
        f"{'case':<22} {'R':>5} {'combos':>7} {'B&B solves':>10} {'B&B s':>7} {'brute s':>8} {'ratio':>6} "
        f"{'optimum':>10} {'rounded':>10} {'excess':>7}"
    )
    for make, Rs in ((planar, (0.5, 0.2, 0.1)), (robot, (0.5, 0.2))):
        model, procs = make()
        for R in Rs:
            times, best = [], None
            for _ in range(a.repeat):
                t0 = time.perf_counter()
                best = synthesize_processes(model, R, 0.99, procs, probability="gaussian")
                times.append(time.perf_counter() - t0)
            tb = statistics.median(times)
            tbf = float("nan")
            if best.combinations <= a.brute:
                bt = []
                for _ in range(a.repeat):
                    t0 = time.perf_counter()
                    allr = enumerate_processes(model, R, 0.99, procs)
                    bt.append(time.perf_counter() - t0)
                tbf = statistics.median(bt)
                ref = min(r.cost for _, r in allr if r is not None and r.success)
                assert abs(ref - best.cost) <= 1e-7 * ref
            rc = best.rounded["cost"]
            print(
                f"{model:<22} {R:>5g} {best.combinations:>7d} {best.nodes:>10d} {tb:>7.2f} {tbf:>8.2f} "
                f"{tbf / tb:>6.2f} {best.cost:>10.5f} {rc:>10.5f} {100 * (rc / best.cost - 1):>6.1f}%"
            )


if __name__ == "__main__":
    main()
