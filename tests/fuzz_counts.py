"""Count the outcomes of the fuzz cases of ``tests/fuzz_cases.py``, per category.

    python tests/fuzz_counts.py [EXAMPLES_PER_CATEGORY] [--show]

Prints one row per category (model-file mutations by kind, API functions, CLI) with the number of
cases and how many ended ok, with a typed error, untyped, hung, leaked a warning, returned bad
numbers or silently accepted a defect.  Deterministic (hypothesis derandomized).  To count an
older version, put its source tree first on PYTHONPATH.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fuzz_cases as fc  # beside this file: run as a script, its folder is on sys.path

SETTINGS = dict(derandomize=True, database=None, deadline=None, suppress_health_check=list(HealthCheck))


def run(name, strategy, make, n):
    results = []
    fc.FAILURES.clear()

    @settings(max_examples=n, **SETTINGS)
    @given(strategy)
    def inner(x):
        results.append(fc.outcome(lambda: make(x)()))

    inner()
    if SHOW:
        for cat, text in sorted(set(fc.FAILURES)):
            print(f"  {name}: {cat}: {text}")
    return name, fc.counts(results)


def main(n: int = 100) -> None:
    import tolsynth

    print(f"tolsynth from {Path(tolsynth.__file__).parent}, {n} examples per category")
    tmp = Path(tempfile.mkdtemp())
    rows = []
    t0 = time.perf_counter()
    for kind in fc.MUTATIONS:
        rows.append(
            run(
                f"model file: {kind}",
                fc.model_mutations(kinds=(kind,)),
                lambda x: lambda: fc.load_mutated(tmp, x[2], x[3]),
                n,
            )
        )
    for name, case in fc.API_CASES.items():
        rows.append(run(f"API: {name}", st.data(), lambda data, case=case: case(data.draw), n))
    rows.append(run("CLI", fc.cli_argv(), lambda argv: lambda: fc.run_cli(argv), n))
    keys = list(rows[0][1])
    print(f"{'category':<34}" + "".join(f"{k:>12}" for k in ["cases"] + keys))
    total = {k: 0 for k in keys}
    for name, c in rows:
        print(f"{name:<34}" + f"{sum(c.values()):>12}" + "".join(f"{c[k]:>12}" for k in keys))
        for k in keys:
            total[k] += c[k]
    print(f"{'total':<34}" + f"{sum(total.values()):>12}" + "".join(f"{total[k]:>12}" for k in keys))
    print(f"wall time {time.perf_counter() - t0:.0f} s")


SHOW = "--show" in sys.argv  # print each distinct failure

if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a != "--show"]
    main(int(args[0]) if args else 100)
