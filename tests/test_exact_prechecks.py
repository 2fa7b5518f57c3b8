"""The exact reading's pre-checks (locks alone, every tolerance at its lower bound): a Gaussian
``sigma_1 z > R`` does not refuse a specification the exact probabilities meet, and a refusal
quotes the exact probability, checked against closed forms and tests/independent.py's FFT."""

from __future__ import annotations

import re

import numpy as np
import pytest

import tolsynth
from tests.independent import independent_worst
from tolsynth.errors import InfeasibleSpecificationError

BOUNDS = {"l1": (0.25, 5.0), "l2": (0.25, 5.0), "o1": (0.05, 50.0), "o2": (0.05, 50.0)}


@pytest.fixture(scope="module")
def arm():
    m = tolsynth.load_model("planar_2r")
    return m, np.asarray(m.sensitivity(m.joints("worst")))[:3]


def _meets(A, eps, R, p):
    P, _ = independent_worst(A * eps, R, plane=True)
    assert P >= p - 2e-5, P


def test_a_lock_the_gaussian_reading_refuses_is_solved_exactly(arm):
    m, A = arm
    # the Gaussian reading refuses it: 0.35 / sqrt(3) * z(0.99) / 0.5 = 1.04 > 1 ...
    with pytest.raises(InfeasibleSpecificationError, match="locked tolerances"):
        tolsynth.synthesize(m, R=0.5, p=0.99, locks={"l1": 0.35}, probability="gaussian")
    # ... but a single uniform +-0.35 term against R = 0.5 has P = min(1, R / b) = 1
    assert np.linalg.norm(A[:, 0]) * 0.35 < 0.5
    r = tolsynth.synthesize(m, R=0.5, p=0.99, locks={"l1": 0.35})
    assert r.success and r.tolerances["l1"] == 0.35
    _meets(A, r.x, 0.5, 0.99)


def test_lower_bounds_the_gaussian_reading_refuses_are_solved_exactly(arm):
    m, A = arm
    with pytest.raises(InfeasibleSpecificationError, match="sigma\\*z/R = 1.05"):
        tolsynth.synthesize(m, R=0.5, p=0.99, bounds=BOUNDS, probability="gaussian")
    lower = np.array([b[0] for b in BOUNDS.values()])
    P0, _ = independent_worst(A * lower, 0.5, plane=True)
    assert P0 > 0.9999  # the exact reading is met with room at the lower bounds
    r = tolsynth.synthesize(m, R=0.5, p=0.99, bounds=BOUNDS)
    assert r.success
    _meets(A, r.x, 0.5, 0.99)


def test_a_lock_too_large_even_alone_is_refused_with_the_exact_value(arm):
    m, A = arm
    b = np.linalg.norm(A[:, 0]) * 0.6  # the lock's term along its own direction, the worst one
    with pytest.raises(InfeasibleSpecificationError, match="locked tolerances \\['l1'\\]") as info:
        tolsynth.synthesize(m, R=0.5, p=0.99, locks={"l1": 0.6})
    P = float(re.search(r"exact P\(\|u \. dr\| <= R\) = ([0-9.e-]+)", str(info.value)).group(1))
    assert P == pytest.approx(0.5 / b, rel=1e-5)  # closed form: one uniform term, P = R / b
    assert info.value.value == pytest.approx((1 - 0.5 / b) / 0.01, rel=1e-4)


def test_lower_bounds_too_large_are_refused_with_the_exact_value(arm):
    m, A = arm
    bounds = {**BOUNDS, "l1": (0.45, 5.0), "l2": (0.45, 5.0)}
    lower = np.array([b[0] for b in bounds.values()])
    P_ref, _ = independent_worst(A * lower, 0.5, plane=True)
    assert P_ref < 0.98
    with pytest.raises(InfeasibleSpecificationError, match="lower bound: exact P") as info:
        tolsynth.synthesize(m, R=0.5, p=0.99, bounds=bounds)
    P = float(re.search(r"exact P\(\|u \. dr\| <= R\) = ([0-9.e-]+)", str(info.value)).group(1))
    assert P == pytest.approx(P_ref, abs=1e-4)


def test_sweep_rows_in_the_exact_reading():
    pytest.importorskip("pandas")
    df = tolsynth.sweep("planar_2r", R=[0.5, 1e-7], p=0.99, bounds=BOUNDS, progress=False)
    assert list(df["status"]) == ["optimal", "error"]
    assert list(df["probability"]) == ["exact", "exact"]  # the error row names its reading too
    assert "exact P" in df["error"][1]


def test_lock_refusal_quotes_the_exact_value():
    m = tolsynth.load_model("planar_2r")
    with pytest.raises(tolsynth.InfeasibleSpecificationError) as e:
        tolsynth.synthesize(m, R=0.5, p=0.99, pose="elbow90", locks={"l1": 0.52})
    # the one error left, dl1 uniform on +-0.52 mm along link 1: P = 0.5 / 0.52, value = (1 - P) / (1 - p)
    value = (1 - 0.5 / 0.52) / (1 - 0.99)
    assert e.value.value == pytest.approx(value, rel=1e-9)
    assert f"P(|u . dr| <= R) = {0.5 / 0.52:.6g} < p = 0.99" in str(e.value)
    assert f"value (1 - P)/(1 - p) = {value:.4g} > 1" in str(e.value)
