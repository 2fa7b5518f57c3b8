"""Fuzz suite (hypothesis): model-file mutations of every bundled model, bad and
extreme arguments of every public function, and command lines.

The invariant (``fuzz_cases.outcome``): a case either succeeds with finite, independently checked
numbers (every converged ``synthesize`` is checked independently: a covariance rebuilt with NumPy
for the paper's Gaussian criterion, a NumPy Monte Carlo along directions for the exact one), or
raises a ``TolsynthError`` naming the field.  Never an untyped exception, a hang (each case runs
under a 60 s alarm), a numerical warning from inside the package (turned into an error), a
traceback on the command line, or a silent acceptance of a defect that must be rejected.

Profiles: the default run is derandomized with a few examples per category (seconds); the ``ci``
profile (``@pytest.mark.slow``, run in CI with ``--runslow``) runs 6x as many, the ``long`` one
(``@pytest.mark.long``, ``--runlong``, before a release) 20x as many.
``HYPOTHESIS_PROFILE=long`` selects the long numbers for the default-marked tests too.
``tests/fuzz_counts.py`` counts the outcomes of the same cases per category.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fuzz_cases as fc

pytestmark = pytest.mark.filterwarnings("error:::tolsynth")

EXAMPLES = {"default": 20, "ci": 50, "long": 400}
if os.environ.get("HYPOTHESIS_PROFILE") == "long":
    EXAMPLES["default"] = EXAMPLES["long"]
PROFILES = [
    pytest.param("default"),
    pytest.param("ci", marks=pytest.mark.slow),
    pytest.param("long", marks=pytest.mark.long),
]


def _settings(profile: str, scale: float = 1.0):
    return settings(
        max_examples=max(1, int(EXAMPLES[profile] * scale)),
        derandomize=True,
        database=None,
        deadline=None,
        suppress_health_check=list(HealthCheck),
        print_blob=True,
    )


def _assert_good(cat: str) -> None:
    assert cat in fc.GOOD, f"{cat}: {fc.FAILURES[-1][1] if fc.FAILURES else ''}"


@pytest.mark.parametrize("profile", PROFILES)
@pytest.mark.parametrize("kind", fc.MUTATIONS)
def test_model_file_mutations(profile, kind, tmp_path):
    @_settings(profile)
    @given(fc.model_mutations(kinds=(kind,)))
    def run(case):
        model, _, blob, must_reject = case
        _assert_good(fc.outcome(lambda: fc.load_mutated(tmp_path, blob, must_reject)))

    run()


@pytest.mark.parametrize("profile", PROFILES)
@pytest.mark.parametrize("function", sorted(fc.API_CASES))
def test_api_arguments(profile, function):
    # these two functions' cases solve designs, about 0.5 s each: half the examples
    @_settings(profile, scale=0.5 if function in ("valid extremes", "synthesize (valid specs)") else 1.0)
    @given(st.data())
    def run(data):
        _assert_good(fc.outcome(fc.API_CASES[function](data.draw)))

    run()


@pytest.mark.parametrize("profile", PROFILES)
def test_cli_arguments(profile):
    @_settings(profile, scale=2)
    @given(fc.cli_argv())
    def run(argv):
        _assert_good(fc.outcome(lambda: fc.run_cli(argv)))

    run()


@pytest.mark.parametrize(
    "argv",
    [
        ["solve", "--model", "xu_zhang_1988", "--R", "nan", "--p", "0.99"],
        ["analyze", "--model", "planar_2r", "--pose", "worst", "--tolerances", "coarse,,,l1=inf"],
    ],
)
def test_cli_subprocess_no_traceback(argv):
    """The real entry point in a fresh interpreter: exit status 2 and one line, no traceback."""
    out = subprocess.run([sys.executable, "-m", "tolsynth", *argv], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr and "error" in out.stderr


def test_outcome_classifies():
    """The classifier itself: each category is recognised (so the suite can fail)."""
    import math

    import numpy as np

    from tolsynth.errors import InputError

    def warn():
        import warnings

        warnings.warn_explicit("x", RuntimeWarning, "tolsynth/stats.py", 1, module="tolsynth.probability.stats")

    def hang():
        while True:
            pass

    old, fc.CASE_SECONDS = fc.CASE_SECONDS, 0.2
    try:
        assert fc.outcome(hang) == "hang"
    finally:
        fc.CASE_SECONDS = old
    assert fc.outcome(lambda: None) == "ok"
    assert fc.outcome(lambda: (_ for _ in ()).throw(InputError("R", "bad"))) == "typed"
    assert fc.outcome(lambda: np.linalg.inv(np.zeros((2, 2)))) == "untyped"
    assert fc.outcome(warn) == "warning"
    assert fc.outcome(lambda: fc.finite(math.nan)) == "bad_numbers"
    assert fc.outcome(lambda: fc.probability(-1e-28)) == "bad_numbers"
