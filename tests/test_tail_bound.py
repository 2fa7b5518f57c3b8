"""The exact probability's lower bound from the standard deviation (tolsynth.probability.tail_bound):
its lemma proven with arb balls, its value against quadrature and Monte Carlo runs of the sums it
covers."""

import math

import numpy as np
import pytest

from tolsynth.probability.distributions import shape
from tolsynth.probability.tail_bound import covered, probability_lower, tail_upper

flint = pytest.importorskip("flint")


def _gauss_e3(c):
    """E (G - c)_+^3 for an arb ball c: (2 + c^2) phi(c) - c (3 + c^2) Q(c)."""
    phi = (-(c * c) / 2).exp() / (2 * flint.arb.pi()).sqrt()
    q = (c / flint.arb(2).sqrt()).erfc() / 2
    return (2 + c * c) * phi - c * (3 + c * c) * q


def test_the_uniform_lies_below_the_normal_of_its_variance_in_the_cubic_order():
    # E (G / sqrt 3 - h)_+^3 - (1 - h)^4 / 8 > 0 on every piece of [-1, 1]: a proof by arb balls
    flint.ctx.prec = 80
    s = flint.arb(3).sqrt()
    n = 4000

    def margin(h):
        return _gauss_e3(h * s) / (s * s * s) - (1 - h) ** 4 / 8

    for i in range(n):
        h = flint.arb(flint.arf(-1) + flint.arf(2 * i + 1) / n, flint.arf(1) / n)  # [-1 + 2i/n, -1 + 2(i+1)/n]
        assert margin(h).lower() > 0, i
    # the margin is smallest at the ends, both E (G - sqrt 3)_+^3 / 3^1.5 = 0.00239...
    for end in (-1, 1):
        assert float(margin(flint.arb(end)).mid()) == pytest.approx(0.0023912, abs=1e-6)
    # at 0: E G_+^3 / 3^1.5 - 1/8 = 2 / (sqrt(2 pi) 3^1.5) - 1/8
    assert float(margin(flint.arb(0)).mid()) == pytest.approx(2 / (math.sqrt(2 * math.pi) * 3**1.5) - 0.125, rel=1e-12)


def test_outside_the_support_the_order_holds_by_the_moments():
    # below -1, E (U - h)_+^3 = E (U - h)^3 = -h^3 - h (Monte Carlo here), the normal's E (G / sqrt 3 - h)^3,
    # which its positive part exceeds (arb); above 1 the uniform's is 0
    flint.ctx.prec = 80
    s = flint.arb(3).sqrt()
    rng = np.random.default_rng(0)
    for h in (-1.0, -1.5, -3.0):
        u = np.mean(np.maximum(rng.uniform(-1, 1, 2_000_000) - h, 0.0) ** 3)
        assert u == pytest.approx(-(h**3) - h, rel=2e-3)
        g = _gauss_e3(flint.arb(h) * s) / (s * s * s)
        assert g.lower() > -(h**3) - h
    assert _gauss_e3(flint.arb(1) * s).lower() > 0


def test_the_bound_against_the_normal_tail_and_its_known_thresholds():
    Q = lambda z: 0.5 * math.erfc(z / math.sqrt(2.0))  # noqa: E731
    for z in (1.0, 2.0, 2.576, 3.0, 4.0):
        t = tail_upper(z)
        assert 2 * Q(z) < t < 2 * (2 * math.e**3 / 9) * Q(z)  # above the normal tail, within Pinelis' constant
    # the z where it reaches 0.01, from an independent minimisation over h with scipy
    pytest.importorskip("scipy")
    from scipy.optimize import brentq, minimize_scalar
    from scipy.stats import norm

    e3 = lambda c: (2 + c * c) * norm.pdf(c) - c * (3 + c * c) * norm.sf(c)  # noqa: E731
    ref = lambda z: 2 * minimize_scalar(lambda h: e3(h) / (z - h) ** 3, bounds=(z - 6, z - 1e-6), method="bounded").fun  # noqa: E731
    z99 = brentq(lambda z: ref(z) - 0.01, 2.5, 3.5)
    assert z99 == pytest.approx(3.0242, abs=2e-3)
    assert tail_upper(z99 * (1 + 1e-6)) <= 0.01
    assert tail_upper(z99 * (1 - 1e-3)) > 0.01


@pytest.mark.parametrize(
    "names, b",
    [
        (["uniform"], [1.0]),
        (["uniform", "uniform"], [1.0, 1.0]),
        (["uniform"] * 6, [1.0, 0.8, 0.5, 0.3, 0.2, 0.1]),
        (["triangular", "uniform", "normal"], [0.7, 1.0, 0.2]),
    ],
)
def test_the_bound_holds_on_sums_it_covers(names, b):
    # Monte Carlo of sum b_i Y_i: the empirical tail stays below the bound at several R
    rng = np.random.default_rng(7)
    shapes = [shape(n) for n in names]
    assert covered(shapes)
    S = np.stack([s.sample(rng, 400_000) for s in shapes], axis=1) @ np.asarray(b)
    sd = math.sqrt(sum(bi**2 * s.variance for bi, s in zip(b, shapes)))
    for R in (1.0 * sd, 2.0 * sd, 2.6 * sd, 3.0 * sd):
        emp = np.mean(np.abs(S) <= R)
        lb = float(probability_lower(R, sd))
        assert emp >= lb - 4 * math.sqrt(max(emp * (1 - emp), 1e-6) / len(S)), (R / sd, emp, lb)


def test_the_truncated_normal_is_not_covered():
    assert not covered([shape("uniform"), shape("truncnormal")])
    assert covered([shape("uniform"), shape("normal"), shape("triangular")])


def test_degenerate_deviations():
    assert probability_lower(1.0, [0.0, np.inf, np.nan]).tolist() == [1.0, 0.0, 0.0]
    # ratios past the cap take its bound (about 1e-301), not an overflow's NaN
    assert probability_lower(1.0, [1e-300, 1e-2]).tolist() == pytest.approx([1.0, 1.0], abs=2e-15)
    assert 0.0 < tail_upper(1e300) == tail_upper(40.0) < 1e-290


def test_an_array_of_deviations_gets_each_its_own_bound():
    # a whole array of boxes at once is the bound of each at a time, in any order; and it falls
    # as the ratio grows, as Eaton's bound does
    s = np.array([0.5, 0.2, 0.9, 0.33, 0.41, 0.2])
    each = [float(probability_lower(1.0, v)) for v in s]
    assert probability_lower(1.0, s).tolist() == each
    assert probability_lower(1.0, s[::-1]).tolist() == each[::-1]
    z = np.linspace(0.5, 39.0, 300)
    t = [tail_upper(v) for v in z]
    assert all(a >= b for a, b in zip(t, t[1:]))
