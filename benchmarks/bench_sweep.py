"""Sweep throughput: rows per second of tolsynth.sweep on each engine, in one run.

The grid: xu_zhang_1988 (11 parameters), R x p x alpha x distribution = --size values each of
R and p, two alphas, two distributions (default 6 x 6 x 2 x 2 = 144 solves by the default
solver).  Engines: this
process (serial), local processes (ProcessPoolExecutor, --workers), the default (client=None:
processes only if the grid pays for starting them), and a dask.distributed
LocalCluster with threads in this process (processes=False) and with --workers worker processes.
Prints the median over --repeat runs of rows/s (whole call: scheduling, pickling and start-up
included; the cluster's own start-up is not) and the ratio to serial.

Usage: python benchmarks/bench_sweep.py [--size 6] [--repeat 3] [--workers 2]
"""

import argparse
import logging
import os
import statistics
import time

import numpy as np

import tolsynth


def grid_of(size: int) -> dict:
    """The sweep's axes: ``size`` values each of R and p, two alphas, two distributions."""
    return dict(
        R=list(np.linspace(0.2, 1.0, size)),
        p=list(np.linspace(0.9, 0.995, size)),
        alpha=[0.5, 0.7],
        distribution=["uniform", "normal"],
    )


def throughput(m, grid: dict, client, repeat: int, **kw) -> tuple[float, float, int]:
    """Median over ``repeat`` runs of ``tolsynth.sweep`` on ``grid``: (rows/s, s, failed rows); the
    whole call is timed (scheduling, pickling and start-up included)."""
    n = int(np.prod([len(v) for v in grid.values()]))
    times, failed = [], 0
    for _ in range(repeat):
        t = time.perf_counter()
        df = tolsynth.sweep(m, **grid, client=client, progress=False, **{"probability": "gaussian", **kw})
        times.append(time.perf_counter() - t)
        failed = int((~df["success"]).sum())
    t = statistics.median(times)
    return n / t, t, failed


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=6)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 2)
    a = ap.parse_args()
    logging.getLogger("distributed").setLevel(logging.CRITICAL)  # no shutdown chatter in the table
    m = tolsynth.load_model("xu_zhang_1988")
    grid = grid_of(a.size)
    n = a.size * a.size * 4
    print(
        f"sweep of {n} solves (xu_zhang_1988, default solver, the paper's Gaussian criterion), median of {a.repeat} runs, {os.cpu_count()} CPUs, "
        f"load average {os.getloadavg()[0]:.1f} at the start"
    )
    print(f"{'engine':<42} {'rows/s':>8} {'s':>7} {'vs serial':>10} {'failed':>7}")

    def run(label, client, **kw):
        return (label, *throughput(m, grid, client, a.repeat, **kw))

    rows = [
        run("serial (this process)", "serial"),
        run(f"processes ({a.workers}, ProcessPoolExecutor)", "processes", workers=a.workers),
        run("auto (client=None, the default)", None, workers=a.workers),
    ]
    from distributed import Client, LocalCluster

    with (
        LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=None) as cl,
        Client(cl) as c,
    ):
        rows.append(run("dask LocalCluster (1 thread, in-process)", c))
    with (
        LocalCluster(n_workers=a.workers, threads_per_worker=1, processes=True, dashboard_address=None) as cl,
        Client(cl) as c,
    ):
        c.submit(lambda: None).result()
        rows.append(run(f"dask LocalCluster ({a.workers} worker processes)", c))
    base = rows[0][1]
    for label, rate, t, failed in rows:
        print(f"{label:<42} {rate:>8.1f} {t:>7.2f} {rate / base:>9.2f}x {failed:>7d}")


if __name__ == "__main__":
    main()
