"""The main job, ``tolsynth reproduce`` (18 columns of Tables 1-3, IPOPT and SUMT + Powell).

Prints, in one run:

* wall time of ``tolsynth reproduce`` as a subprocess (what a user waits for: import, graphs,
  36 IPOPT solves, 18 SUMT solves, the report), median of --repeat runs with the compiled-library
  cache warm, and one run with an empty cache (the first run after installing: it compiles);
* the same in-process (``tolsynth.synthesis.reproduce.reproduce()``), median of --repeat after one warm-up,
  with the time split into its IPOPT and SUMT solves;
* SUMT + Powell per column: the compiled Powell (:mod:`tolsynth.solvers.cpowell`, the default
  where a C compiler is found); the Python Powell on the same graph with the same options (the
  fallback without a compiler; ``TOLSYNTH_NO_COMPILE=1``); and "before": the Python Powell with
  the options of the earlier release (``line_rtol=1e-9``, no extrapolation: the path every run
  took before this benchmark was written), on --python-columns columns (they are slow); the
  ratios, the evaluations and the IPOPT agreement.

Usage: python benchmarks/bench_reproduce.py [--repeat 5] [--python-columns 3]
"""

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import tolsynth
from tolsynth import synthesize
from tolsynth.solvers import cpowell
from tolsynth.synthesis.reproduce import reproduce


def command():
    exe = shutil.which("tolsynth", path=os.path.dirname(sys.executable))
    return [exe, "reproduce"] if exe else [sys.executable, "-m", "tolsynth", "reproduce"]


def run_subprocess(env=None):
    t0 = time.perf_counter()
    proc = subprocess.run(command(), capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    if proc.returncode != 0 or "all solves converged: True" not in proc.stdout:
        raise SystemExit(f"tolsynth reproduce failed:\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")
    return wall


def sumt_column(mech, ref):
    t0 = time.perf_counter()
    su = synthesize(mech, ref.R, ref.p, ref.distribution, ref.alpha, solver="sumt", probability="gaussian")
    return time.perf_counter() - t0, su


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--python-columns", type=int, default=3)
    a = ap.parse_args()
    print(f"cores: {os.cpu_count()}, SUMT backend: ", end="")
    mech = tolsynth.load_model("xu_zhang_1988")
    refs = mech.spec.reference_results
    sumt_column(mech, refs[0])
    st = cpowell.backend_status()
    print(st["backend"], f"({st['reason']})" if st["reason"] else f"(cache: {cpowell.cache_dir()})")

    # -- subprocess ---------------------------------------------------------------------------
    with tempfile.TemporaryDirectory() as empty:
        cold = run_subprocess({**os.environ, "TOLSYNTH_CACHE_DIR": empty})
    warm = [run_subprocess() for _ in range(a.repeat)]
    print(
        f"\n`tolsynth reproduce` as a subprocess: median {statistics.median(warm):.2f} s "
        f"(min {min(warm):.2f}, max {max(warm):.2f}, {a.repeat} runs, compiled library cached); "
        f"first run, empty cache: {cold:.2f} s"
    )
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "import tolsynth.cli, tolsynth.synthesis.reproduce"], check=True)
    print(f"  of which starting Python and importing tolsynth: {time.perf_counter() - t0:.2f} s")

    # -- in-process ---------------------------------------------------------------------------
    reproduce()  # warm-up
    walls, ip_t, su_t = [], [], []
    for _ in range(a.repeat):
        t0 = time.perf_counter()
        reps = reproduce()
        walls.append(time.perf_counter() - t0)
        ip_t.append(sum(r.ipopt.wall_time for rep in reps for r in rep.readings.values()))
        su_t.append(sum(rep.printed_unit.sumt.wall_time for rep in reps))
    worst = max(rep.agreement()["cost_rel_diff"] for rep in reps)
    print(
        f"\nreproduce() in-process: median {statistics.median(walls):.3f} s over {a.repeat} runs; inside "
        f"the solvers (their own wall_time): IPOPT 36 solves {statistics.median(ip_t):.3f} s, "
        f"SUMT 18 solves {statistics.median(su_t):.3f} s; largest IPOPT-SUMT cost difference {worst:.1e}"
    )

    # -- SUMT per column: compiled vs Python Powell vs before --------------------------------
    print(
        "\nSUMT + Powell per column (synthesize end to end): compiled; Python Powell, same options; "
        "before (Python, line_rtol 1e-9, no extrapolation)"
    )
    print(
        f"  {'column':<52} {'compiled ms':>11} {'evals':>6} {'python ms':>9} {'before ms':>9} {'evals':>7} "
        f"{'py/comp':>7} {'before/comp':>11} {'|SUMT-IPOPT|/IPOPT':>18}"
    )
    r_py, r_before = [], []
    for i, ref in enumerate(refs):
        label = f"{ref.table}: R={ref.R:g} mm, p={ref.p:g}, alpha={ref.alpha:g}, {ref.distribution}"
        tc = statistics.median(sumt_column(mech, ref)[0] for _ in range(a.repeat))
        _, su = sumt_column(mech, ref)
        ip = synthesize(mech, ref.R, ref.p, ref.distribution, ref.alpha, solver="ipopt", probability="gaussian")
        row = f"  {label:<52} {tc * 1e3:>11.1f} {su.function_evaluations:>6}"
        if i < a.python_columns:
            os.environ["TOLSYNTH_NO_COMPILE"] = "1"
            try:
                tp, _ = sumt_column(mech, ref)
                t0 = time.perf_counter()
                sb = synthesize(
                    mech,
                    ref.R,
                    ref.p,
                    ref.distribution,
                    ref.alpha,
                    solver="sumt",
                    options={"line_rtol": 1e-9, "extrapolate": False},
                    probability="gaussian",
                )
                tb = time.perf_counter() - t0
            finally:
                del os.environ["TOLSYNTH_NO_COMPILE"]
            r_py.append(tp / tc)
            r_before.append(tb / tc)
            row += f" {tp * 1e3:>9.0f} {tb * 1e3:>9.0f} {sb.function_evaluations:>7} {tp / tc:>7.0f} {tb / tc:>11.0f}"
        else:
            row += f" {'':>9} {'':>9} {'':>7} {'':>7} {'':>11}"
        print(row + f" {abs(su.cost - ip.cost) / ip.cost:>18.1e}")
    if r_py:
        print(
            f"  speed-up over {len(r_py)} columns (median): {statistics.median(r_py):.0f}x over the Python Powell, "
            f"{statistics.median(r_before):.0f}x over before"
        )


if __name__ == "__main__":
    main()
