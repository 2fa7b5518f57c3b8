"""Exact probabilities of the linear error model (tolsynth.probability.exact) and the error shapes
(tolsynth.probability.distributions), against closed forms, direct quadrature and Monte Carlo
intervals.  The hard inputs (dominant terms, coefficients near zero, thousands of terms, mixed
shapes, history independence, speed) are in test_exact_hard.py; the references in test_exact_refs.py."""

import math
from math import comb, factorial

import casadi as ca
import numpy as np
import pytest

from test_exact_refs import olds, wilson
from tolsynth.errors import InputError, OutOfRangeError
from tolsynth.probability import stats
from tolsynth.probability.distributions import divisors, shape, shapes_of
from tolsynth.probability.exact import (
    ExactProbabilityError,
    ball_probability,
    components_probability,
    cone_probability,
    direction_probability,
    worst_direction,
)

ALL = ["uniform", "normal", "triangular", "truncnormal", "truncnormal(3)", "truncnormal(0.5)"]


_mc_interval = wilson


# ------------------------------------------------------------------------------------------ shapes
@pytest.mark.parametrize("name", ALL)
def test_shape_variance_and_cf_match_samples(name):
    """Var(Y) and E cos(sY) of each shape against 400k samples (sampling error ~ 1/sqrt(n))."""
    sh = shape(name)
    rng = np.random.default_rng(7)
    y = sh.sample(rng, 400_000)
    assert np.all(np.abs(y) <= 1.0) or not sh.bounded
    assert abs(np.var(y) - sh.variance) < 5 * np.std(y**2) / math.sqrt(y.size)
    s = np.array([0.3, 1.0, 2.5, 6.0, 15.0])
    emp = np.cos(np.outer(s, y)).mean(axis=1)
    assert np.max(np.abs(emp - sh.cf(s))) < 6 / math.sqrt(y.size)
    # the envelope bounds |cf| everywhere on a fine grid
    t = np.linspace(0.0, 400.0, 40_001)
    assert np.all(np.abs(sh.cf(t)) <= sh.envelope(t) + 1e-12)


@pytest.mark.parametrize("beta", [0.5, 2.0, 5.0])
def test_truncnormal_cf_against_direct_quadrature(beta):
    """The closed form of the truncated normal's characteristic function (48-node rule in a
    boundary-layer variable) against a direct 200001-point Simpson quadrature of the density."""
    sh = shape(f"truncnormal({beta})")
    x = np.linspace(-1.0, 1.0, 200001)
    f = np.exp(-0.5 * (beta * x) ** 2)
    h = x[1] - x[0]
    wts = np.ones_like(x)
    wts[1:-1:2], wts[2:-1:2] = 4, 2
    f /= np.sum(wts * f) * h / 3
    s = np.array([0.0, 0.5, 3.0, 10.0, 60.0, 300.0, 2000.0])
    ref = np.array([np.sum(wts * f * np.cos(si * x)) * h / 3 for si in s])
    assert np.max(np.abs(sh.cf(s) - ref)) < 1e-8
    # the same formula as a CasADi expression
    S = ca.SX.sym("s")
    F = ca.Function("f", [S], [sh.cf(S, lib=ca)])
    assert np.max(np.abs(np.array([float(F(v)) for v in s]) - sh.cf(s))) < 1e-13


def test_variances_closed_forms_and_mixing():
    assert shape("uniform").divisor == pytest.approx(3.0)
    assert shape("normal").divisor == pytest.approx(9.0)
    assert shape("triangular").divisor == pytest.approx(6.0)
    # truncated at 3 sigma: nearly the normal's 9; at 2 sigma: 1/(4 * 0.7737...) (variance 0.7737 sigma^2)
    assert shape("truncnormal(3)").divisor == pytest.approx(9 / 0.97333, rel=1e-4)
    assert shape("truncnormal").divisor == pytest.approx(4 / 0.77377, rel=1e-4)
    names = ["a", "b", "c"]
    np.testing.assert_allclose(divisors({"*": "normal", "b": "triangular"}, names), [9, 6, 9])
    np.testing.assert_allclose(divisors("uniform", names), [3, 3, 3])
    with pytest.raises(OutOfRangeError, match="distribution"):
        shape("cauchy")
    with pytest.raises(OutOfRangeError, match="beta"):
        shape("truncnormal(20)")
    with pytest.raises(InputError, match=r"distribution\[d\]"):
        shapes_of({"d": "normal"}, names)
    with pytest.raises(OutOfRangeError, match=r"distribution\[b\]"):
        shapes_of({"b": "lognormal"}, names)


# ------------------------------------------------------------------------------ along a direction
def test_one_uniform_and_a_trapezoid():
    P, err = direction_probability([1.0], ["uniform"], 0.5, tol=1e-6, return_error=True)
    assert abs(P - 0.5) <= 1e-6 and err <= 1e-6
    # two uniforms of half-widths 1 and 0.5: a trapezoid; P(|w| <= 0.8) = 1 - (1.5 - 0.8)^2 / 2
    P = direction_probability([1.0, 0.5], ["uniform"] * 2, 0.8, tol=1e-7)
    assert abs(P - (1 - 0.7**2 / 2)) <= 1e-7
    # inside the flat part: R / b1
    assert abs(direction_probability([1.0, 0.5], ["uniform"] * 2, 0.3, tol=1e-7) - 0.3) <= 1e-7


@pytest.mark.parametrize("n,R", [(3, 0.4), (6, 1.3), (12, 2.0)])
def test_irwin_hall(n, R):
    """n equal uniforms on [-1, 1]: S = 2 IH_n - n, P(|S| <= R) from the Irwin-Hall CDF."""

    def F(x):
        return sum((-1) ** k * comb(n, k) * (x - k) ** n for k in range(int(math.floor(x)) + 1)) / factorial(n)

    ref = F((n + R) / 2) - F((n - R) / 2)
    P, err = direction_probability(np.ones(n), ["uniform"] * n, R, return_error=True)
    assert err <= 1e-9
    assert abs(P - ref) <= 1e-9


@pytest.mark.parametrize(
    "n,p,value", [(3, 0.99, 0.996820), (10, 0.99, 0.991454), (30, 0.99, 0.990462), (2, 0.9, 0.892093)]
)
def test_equal_uniform_terms_at_the_gaussian_radius(n, p, value):
    """The values docs/certified.md quotes for the Gaussian reading against the exact one: n equal
    uniform terms, R = z sigma with the Gaussian's z (SciPy) and the sum's own sigma; the Irwin-Hall
    CDF in exact rational arithmetic, and the evaluator to 1e-9 of it.  Above p at p = 0.99, below
    it at p = 0.9."""
    from fractions import Fraction

    from scipy.stats import norm

    R = norm.ppf((1 + p) / 2) * math.sqrt(n / 3)

    def F(x):  # Irwin-Hall CDF of n uniforms on [0, 1]
        return sum((-1) ** k * comb(n, k) * (x - k) ** n for k in range(int(math.floor(x)) + 1)) / factorial(n)

    ref = float(F((n + Fraction(R)) / 2) - F((n - Fraction(R)) / 2))
    assert abs(ref - value) <= 5e-7
    assert (ref > p) == (p == 0.99)
    assert abs(direction_probability(np.ones(n), ["uniform"] * n, R, tol=1e-12) - ref) <= 1e-9


def test_normals_give_the_gaussian_values():
    b = np.array([1.0, 2.0, 0.5])
    s = math.sqrt(np.sum((b / 3) ** 2))
    assert abs(direction_probability(b, ["normal"] * 3, 1.0) - math.erf(1 / (s * math.sqrt(2)))) <= 1e-12


def test_mixed_direction_against_monte_carlo(rng):
    names = ["uniform", "normal", "triangular", "truncnormal", "uniform", "truncnormal(3)"]
    b = np.array([0.8, 0.5, 0.6, 0.4, 0.2, 0.3])
    R = 0.9
    P = direction_probability(b, names, R)
    n = 2_000_000
    Y = np.column_stack([shape(s).sample(rng, n) for s in names])
    lo, hi = _mc_interval(np.count_nonzero(np.abs(Y @ b) <= R), n)
    assert lo <= P <= hi


@pytest.mark.parametrize("small", [1e-3, 1e-5, 1e-9, 1e-13])
@pytest.mark.parametrize("R", [0.3, 1.0 - 1e-6, 1.0, 1.0 + 1e-9, 1.2])
def test_a_dominating_uniform_is_exact(small, R):
    """One uniform dominating a direction (a second uniform ``small`` of it) makes a near-jump in
    the density that a Fourier series cannot resolve; the vertex formula in exact arithmetic
    can: against Olds' formula in rational arithmetic, to 1e-12, inside the flat part, at the
    kink and beyond."""
    P, err = direction_probability([1.0, small], ["uniform"] * 2, R, tol=1e-10, return_error=True)
    assert err <= 1e-10
    assert abs(P - float(olds([1.0, small], R))) <= 1e-12


@pytest.mark.parametrize("name", ["uniform", "normal", "triangular", "truncnormal", "truncnormal(3)"])
def test_a_single_term_or_none_is_its_own_cdf(rng, name):
    """A direction with one error alone (a planar arm's normal has none): no series, the shape's
    CDF, against Monte Carlo; no term at all is probability 1; a bounded term 1e-15 of the largest
    is dropped with its rigorous effect in the bound."""
    b, R = np.array([0.0, 0.7, 0.0]), 0.45
    P, err = direction_probability(b, ["uniform", name, "normal"], R, return_error=True)
    n = 1_000_000
    lo, hi = _mc_interval(np.count_nonzero(np.abs(0.7 * shape(name).sample(rng, n)) <= R), n)
    assert err <= 1e-15 and lo <= P <= hi
    assert direction_probability(np.zeros(3), [name] * 3, R, return_error=True) == (1.0, 0.0)
    P2, err2 = direction_probability([0.7, 0.7e-15], [name, "uniform"], R, return_error=True)
    assert abs(P2 - P) <= err2 <= 1e-14


def test_planar_arm_exact_design_has_a_certain_normal_direction():
    """planar_2r: the hand never leaves its plane (z row of the sensitivity 0), so along z the
    exact probability is 1; the exact design meets p by Monte Carlo in the plane."""
    import tolsynth

    r = tolsynth.synthesize("planar_2r", 0.5, 0.9, probability="exact")
    assert r.success and r.inputs["probability"] == "exact"
    g = tolsynth.synthesize("planar_2r", 0.5, 0.9)
    assert abs(r.cost / g.cost - 1) < 0.1  # the same design problem, another reading of p
    mc = tolsynth.monte_carlo(
        "planar_2r",
        list(r.spec.poses.values())[0],
        r.x,
        R=0.5,
        n=200_000,
        seed=3,
        directions=r.constraints[0].directions[:, :1],
        check_limits=False,
    )
    lo, hi = mc.p_directions_ci[0]
    assert lo <= 0.9 + 1e-3 and hi >= 0.9 - 1e-3, (lo, hi)


def test_components_and_worst_direction(rng):
    A = rng.normal(size=(3, 8))
    eps = rng.uniform(0.5, 1.0, 8)
    sh = ["uniform"] * 8
    P, E = components_probability(A, eps, sh, 1.0)
    # each principal component's probability against a direct Monte Carlo along it
    n = 1_000_000
    Y = rng.uniform(-1, 1, (n, 8)) * eps
    W = (Y @ A.T) @ E
    for j in range(3):
        lo, hi = _mc_interval(np.count_nonzero(np.abs(W[:, j]) <= 1.0), n)
        assert lo <= P[j] <= hi
    u, pu = worst_direction(A, eps, sh, 1.0)
    assert pu <= P.min() + 1e-12
    # no direction among 2000 random ones is worse
    D = rng.normal(size=(2000, 3))
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    assert pu <= direction_probability(D @ A * eps, sh, 1.0).min() + 1e-9


# ---------------------------------------------------------------------------------- sphere, cone
def test_ball_all_normal_equals_the_gaussian_formula(rng):
    A = rng.normal(size=(3, 8))
    eps = rng.uniform(0.5, 1.0, 8)
    lam = np.linalg.eigvalsh((A * eps**2 / 9) @ A.T)
    P, err = ball_probability(A, eps, ["normal"] * 8, 1.0, return_error=True)
    assert err <= 1e-7
    assert abs(P - stats.p_ball(lam, 1.0)) <= 1e-7


@pytest.mark.slow  # about 4 s: the default run stays under 4 minutes
def test_ball_and_cone_uniform_against_monte_carlo(rng):
    A = rng.normal(size=(3, 8))
    eps = rng.uniform(0.5, 1.0, 8)
    P = ball_probability(A, eps, ["uniform"] * 8, 1.6, tol=1e-6)
    n = 2_000_000
    Y = rng.uniform(-1, 1, (n, 8)) * eps
    d = Y @ A.T
    lo, hi = _mc_interval(np.count_nonzero(np.linalg.norm(d, axis=1) <= 1.6), n)
    assert lo <= P <= hi
    gauss = stats.p_ball(np.linalg.eigvalsh((A * eps**2 / 3) @ A.T), 1.6)
    assert gauss - P > 5 * (hi - lo)  # the Gaussian reading is off here (0.673 vs 0.653)
    C = A[:2]
    Pc = cone_probability(C, eps, ["uniform"] * 8, 1.5, tol=1e-6)
    lo, hi = _mc_interval(np.count_nonzero(np.linalg.norm(d[:, :2], axis=1) <= 1.5), n)
    assert lo <= Pc <= hi
    # the all-normal cone is the 2-D Gaussian value
    Pn = cone_probability(C, eps, ["normal"] * 8, 1.0)
    assert abs(Pn - stats.p_ball(np.linalg.eigvalsh((C * eps**2 / 9) @ C.T), 1.0)) <= 1e-7


def test_bad_input_is_typed():
    """Every bad argument gets a typed error naming its field; a tolerance out of reach raises
    ExactProbabilityError unless the bound is asked for."""
    with pytest.raises(OutOfRangeError, match="R"):
        direction_probability([1.0], ["uniform"], -1.0)
    with pytest.raises(OutOfRangeError, match="shapes"):
        direction_probability([1.0, 2.0], ["uniform"], 1.0)
    with pytest.raises(InputError, match="shapes"):
        direction_probability([1.0, 2.0], "uniform", 1.0)
    with pytest.raises(OutOfRangeError, match="distribution"):
        direction_probability([1.0], ["lognormal"], 1.0)
    with pytest.raises(OutOfRangeError, match="b"):
        direction_probability([1.0, float("nan")], ["uniform"] * 2, 1.0)
    with pytest.raises(InputError, match="b"):
        direction_probability(["a", "b"], ["uniform"] * 2, 1.0)
    with pytest.raises(OutOfRangeError, match="tol"):
        direction_probability([1.0], ["uniform"], 1.0, tol=0.0)
    with pytest.raises(OutOfRangeError, match="kmax"):
        direction_probability([1.0], ["uniform"], 1.0, kmax=2.5)
    with pytest.raises(OutOfRangeError, match="A"):
        ball_probability(np.ones((2, 3)), np.ones(3), ["uniform"] * 3, 1.0)
    with pytest.raises(OutOfRangeError, match="eps"):
        ball_probability(np.ones((3, 3)), -np.ones(3), ["uniform"] * 3, 1.0)
    with pytest.raises(OutOfRangeError, match="max_nodes"):
        ball_probability(np.ones((3, 3)), np.ones(3), ["uniform"] * 3, 1.0, max_nodes=4)
    with pytest.raises(OutOfRangeError, match="Phi"):
        cone_probability(np.ones((2, 3)), np.ones(3), ["uniform"] * 3, 0.0)
    with pytest.raises(OutOfRangeError, match="start"):
        worst_direction(np.eye(3), np.ones(3), ["uniform"] * 3, 1.0, start=[0.0, 0.0, 0.0])
    A = np.random.default_rng(3).normal(size=(3, 6))
    with pytest.raises(ExactProbabilityError, match="sphere"):
        ball_probability(A, np.ones(6), ["uniform"] * 6, 1.0, tol=1e-12, max_nodes=16)
    P, err = ball_probability(A, np.ones(6), ["uniform"] * 6, 1.0, tol=1e-12, max_nodes=16, return_error=True)
    assert err > 1e-12 and 0.0 < P < 1.0
