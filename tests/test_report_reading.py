"""The design report judges the worst pose in the probability reading the design was made for: an
exact design by its exact per-direction probability, recomputed here in closed form (the
distribution of a sum of uniform errors), not by the Gaussian sigma z / R."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

import tolsynth

pytest.importorskip("matplotlib")


def _p_sum_of_uniforms(a, R):
    """P(|sum a_i Y_i| <= R), Y_i independent uniform on [-1, 1]: the CDF of a sum of uniforms on
    [-a_i, a_i] by inclusion-exclusion, sum_s prod(s) (x + s.a)_+^n / (n! prod 2 a_i)."""
    a = [x for x in a if x > 1e-12]
    n = len(a)

    def cdf(x):
        terms = [
            math.prod(s) * max(x + sum(si * ai for si, ai in zip(s, a)), 0.0) ** n
            for s in itertools.product((1, -1), repeat=n)
        ]
        return math.fsum(terms) / (math.factorial(n) * math.prod(2 * ai for ai in a))

    return cdf(R) - cdf(-R)


def _exact_margin(mech, q, eps, R, p):
    A = np.asarray(mech.sensitivity(q, check_limits=False))[:3]
    assert np.all(A[2] == 0)  # the planar arm: the worst direction lies in the plane
    P = min(
        _p_sum_of_uniforms(np.abs(np.array([math.cos(t), math.sin(t)]) @ A[:2]) * eps, R)
        for t in np.linspace(0.0, math.pi, 20001)
    )
    return (1.0 - P) / (1.0 - p)


def test_exact_design_judged_by_its_exact_probability():
    mech = tolsynth.load_model("planar_2r")
    rep = tolsynth.report(mech, R=0.5, p=0.99, mc_samples=0, map_n=0)
    assert rep.result.probability_kind == "exact"
    blocks = rep.blocks()
    start = blocks.index(("h", 3, "Worst pose"))
    table = next(b for b in blocks[start:] if b[0] == "table")
    row = next(r for r in table[2] if r[0].startswith("exact (1-P)/(1-p)"))
    eps = rep.result.x
    found = _exact_margin(mech, rep.worst.q, eps, 0.5, 0.99)
    reference = _exact_margin(mech, rep.worst.reference_q, eps, 0.5, 0.99)
    assert float(row[1]) == pytest.approx(found, abs=6e-5)
    assert float(row[2]) == pytest.approx(reference, abs=6e-5)
    # the reference pose is the one designed for: its worst direction is the active constraint; the
    # exact search finds where the single-pose design misses p (9.6 %), and the verdict says so
    assert reference == pytest.approx(1.0, abs=1e-4) and found > 1.09
    verdict = [b for b in blocks[start:] if b[0] in ("ok", "note") and "At the poses compared" in b[1]]
    assert len(verdict) == 1 and verdict[0][0] == "note" and "1.0957 > 1" in verdict[0][1], verdict
    text = " ".join(str(b) for b in blocks)
    assert "sigma z / R" not in text  # no Gaussian judgement of an exact design anywhere
