"""The probabilistic error model (paper section 3), checked against independent references.

* covariance (uniform eps^2/3, normal eps^2/9): an explicit sum over the parameters, and a Monte
  Carlo sample of the linear error model ``S @ delta`` drawn from the actual distributions;
* principal standard deviations: NumPy's ``eigh`` and the closed-form cubic against matrices
  built from known eigenvalues (including coincident and zero ones) and against each other;
  the cubic's derivatives against first-order perturbation theory (d lam = v^T dV v);
* ``p_ball``: the chi closed forms (3-D, 2-D, 1-D), ``scipy.stats.chi2``, a SciPy ``dblquad`` of
  the Gaussian density in Cartesian coordinates, and a large seeded Gaussian sample;
* ``p_components`` and ``z_of_p`` against ``scipy.stats.norm``;
* ``p_cone`` against a Monte Carlo of the actual axis deviation angle (the axis rotated by a
  sampled rotation vector, the angle measured).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from scipy import integrate, special, stats

import tolsynth
from tolsynth.probability.stats import (
    covariance,
    p_ball,
    p_components,
    p_cone,
    principal,
    principal_cubic_function,
    principal_variances_cubic,
    z_of_p,
)


# ---------------------------------------------------------------------------------------------
# references
# ---------------------------------------------------------------------------------------------
def ball_probability_scipy(variances, R, epsabs=1e-14):
    """P(w1^2 + w2^2 + w3^2 <= R^2), w_j ~ N(0, lam_j) independent, as a SciPy double integral.

    Cartesian slicing: P = int phi(z1) int phi(z2) [2 Phi(r(z1, z2)/sig3) - 1] dz2 dz1 over the
    ball, with the substitutions z1 = a sin t, z2 = b(t) sin u that make the integrand smooth.
    Works for 2 or 3 positive variances (2: the inner integral is the probability itself)."""
    lam = sorted((float(v) for v in variances if v > 0), reverse=True)
    if len(lam) == 2:
        l1, l2 = lam
        a = R / math.sqrt(l1)

        def f(t):
            return (
                math.exp(-0.5 * (a * math.sin(t)) ** 2)
                * a
                * math.cos(t)
                / math.sqrt(2 * math.pi)
                * special.erf(R * math.cos(t) / math.sqrt(2 * l2))
            )

        value, _ = integrate.quad(f, -math.pi / 2, math.pi / 2, epsabs=1e-14, epsrel=1e-13, limit=200)
        return value
    l1, l2, l3 = lam
    a = R / math.sqrt(l1)

    def f(u, t):
        b = R * math.cos(t) / math.sqrt(l2)
        return (
            math.exp(-0.5 * (a * math.sin(t)) ** 2)
            * a
            * math.cos(t)
            / math.sqrt(2 * math.pi)
            * math.exp(-0.5 * (b * math.sin(u)) ** 2)
            * b
            * math.cos(u)
            / math.sqrt(2 * math.pi)
            * special.erf(R * math.cos(t) * math.cos(u) / math.sqrt(2 * l3))
        )

    value, _ = integrate.dblquad(f, -math.pi / 2, math.pi / 2, -math.pi / 2, math.pi / 2, epsabs=epsabs, epsrel=1e-13)
    return value


def p_sphere_closed_form(x):
    return special.erf(x / math.sqrt(2)) - math.sqrt(2 / math.pi) * x * math.exp(-x * x / 2)


def random_rotation(rng):
    Q, Rr = np.linalg.qr(rng.normal(size=(3, 3)))
    return Q * np.sign(np.diag(Rr))


def rodrigues(phi):
    """Rotation matrices exp([phi]x) for an (N, 3) array of rotation vectors."""
    th = np.linalg.norm(phi, axis=1)[:, None, None]
    K = np.zeros((phi.shape[0], 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -phi[:, 2], phi[:, 1], -phi[:, 0]
    K -= np.transpose(K, (0, 2, 1))
    safe = np.where(th > 0, th, 1.0)
    return np.eye(3) + np.sin(safe) / safe * K + (1 - np.cos(safe)) / safe**2 * (K @ K)


# ---------------------------------------------------------------------------------------------
# covariance
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def worst_case(xz):
    return xz.sensitivity("worst"), xz.tolerances("figure3")


@pytest.mark.parametrize("dist, divisor", [("uniform", 3.0), ("normal", 9.0)])
def test_covariance_is_the_explicit_sum(worst_case, dist, divisor):
    S, eps = worst_case
    Vp, Vo = covariance(S, eps, dist)
    ref = sum(np.outer(S[:, i], S[:, i]) * eps[i] ** 2 / divisor for i in range(S.shape[1]))
    assert np.allclose(Vp, ref[:3, :3], rtol=1e-13, atol=1e-16 * np.abs(ref[:3, :3]).max())
    assert np.allclose(Vo, ref[3:, 3:], rtol=1e-13, atol=1e-16 * np.abs(ref[3:, 3:]).max())


@pytest.mark.parametrize("dist", ["uniform", "normal"])
def test_covariance_matches_monte_carlo_of_the_linear_model(worst_case, dist):
    """delta_i ~ U(-eps_i, eps_i), or N(0, (eps_i/3)^2); the sample covariance of S @ delta
    agrees with the model's covariance within 5 standard errors, entry by entry."""
    S, eps = worst_case
    rng = np.random.default_rng(2024 if dist == "uniform" else 2025)
    N = 300_000
    if dist == "uniform":
        delta = rng.uniform(-1.0, 1.0, size=(N, eps.size)) * eps
    else:
        delta = rng.normal(0.0, 1.0, size=(N, eps.size)) * (eps / 3.0)
    err = delta @ S.T  # N x 6
    Vp, Vo = covariance(S, eps, dist)
    V = np.zeros((6, 6))
    V[:3, :3], V[3:, 3:] = Vp, Vo
    for i in range(6):
        for j in range(6):
            if (i < 3) != (j < 3):
                continue
            prod = err[:, i] * err[:, j]
            se = prod.std() / math.sqrt(N)
            assert abs(prod.mean() - V[i, j]) <= 5 * se + 1e-300, (dist, i, j, prod.mean(), V[i, j], se)


# ---------------------------------------------------------------------------------------------
# principal standard deviations: eigh and the closed-form cubic
# ---------------------------------------------------------------------------------------------
KNOWN_SPECTRA = [
    (3.0, 2.0, 1.0),  # distinct
    (2.0, 1.0, 1.0),  # two equal (the smaller pair)
    (2.0, 2.0, 1.0),  # two equal (the larger pair)
    (4.0, 4.0, 4.0),  # all three equal
    (2.0, 1.0, 0.0),  # one zero
    (5.0, 5.0, 0.0),  # two equal and a zero
    (1.0, 0.0, 0.0),  # rank one
    (2.0, 1.0 + 1e-9, 1.0),  # nearly coincident
    (9.1e-2, 3.8e-2, 2.5e-3),  # mm^2, the paper's scale
    (2.4e-7, 5.7e-8, 8.3e-9),  # rad^2, an orientation covariance
]


def _check_spectrum(lam_got, lam_true, what):
    """Std to 1e-10 relative where the variance is not (nearly) zero; a zero variance to 1e-13 of
    the largest (its square root is rounding noise of any method, ~1e-8 of the largest std)."""
    lam_got = np.asarray(lam_got, dtype=float)
    lam_true = np.asarray(lam_true, dtype=float)
    top = lam_true.max()
    for got, true in zip(lam_got, lam_true):
        if true > 1e-6 * top:
            rel = abs(math.sqrt(max(got, 0.0)) - math.sqrt(true)) / math.sqrt(true)
            assert rel <= 1e-10, (what, lam_got, lam_true, rel)
        else:
            assert abs(got - true) <= 1e-13 * top, (what, lam_got, lam_true)


@pytest.mark.parametrize("spectrum", KNOWN_SPECTRA)
def test_principal_std_known_spectra(spectrum):
    """Rotated diag(lam): eigh and the cubic both recover lam, and agree with each other."""
    rng = np.random.default_rng(abs(hash(spectrum)) % 2**32)
    cubic = principal_cubic_function()
    lam_true = np.array(spectrum)
    for _ in range(40):
        Q = random_rotation(rng)
        V = Q @ np.diag(lam_true) @ Q.T
        sig, vec = principal(V)
        lam_cubic = np.array(cubic(V)).ravel()
        _check_spectrum(sig**2, lam_true, "eigh")
        _check_spectrum(lam_cubic, lam_true, "cubic")
        _check_spectrum(lam_cubic, sig**2, "cubic vs eigh")
        # directions: orthonormal eigenvectors; for distinct variances the known axes (up to sign)
        assert np.allclose(vec.T @ vec, np.eye(3), atol=1e-12)
        assert np.allclose(V @ vec, vec * sig**2, atol=1e-12 * lam_true.max())
        if len(set(spectrum)) == 3 and min(np.diff(sorted(spectrum))) > 1e-6:
            assert np.allclose(np.abs(np.sum(vec * Q, axis=0)), 1.0, atol=1e-9)


def test_principal_std_random_spd():
    """Random SPD matrices: A A^T (cubic vs eigh), and Q diag(lam) Q^T with random known lam over
    seven decades (both vs lam).  Reports the largest std difference relative to that std."""
    rng = np.random.default_rng(99)
    cubic = principal_cubic_function()
    worst = 0.0
    for k in range(600):
        if k % 2:
            A = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-5, 2)
            V, lam_true = A @ A.T, None
        else:
            lam_true = np.sort(10.0 ** rng.uniform(-9, -2, 3))[::-1]
            Q = random_rotation(rng)
            V = Q @ np.diag(lam_true) @ Q.T
        sig = principal(V)[0]
        lam_c = np.array(cubic(V)).ravel()
        _check_spectrum(lam_c, sig**2, "cubic vs eigh")
        if lam_true is not None:
            _check_spectrum(sig**2, lam_true, "eigh")
            _check_spectrum(lam_c, lam_true, "cubic")
        big = sig**2 > 1e-6 * sig[0] ** 2
        worst = max(worst, float(np.max(np.abs(np.sqrt(lam_c[big]) - sig[big]) / sig[big])))
    print(f"random SPD: cubic vs eigh, max relative std difference {worst:.2e}")


def test_cubic_is_a_casadi_expression_with_the_right_derivative():
    """On symbols, the cubic's Jacobian is d lam_j / dV = v_j v_j^T (first-order perturbation of a
    simple eigenvalue of a symmetric matrix), and stays finite where variances coincide."""
    Vs = ca.SX.sym("V", 3, 3)
    lam = principal_variances_cubic(0.5 * (Vs + Vs.T))
    assert isinstance(lam, ca.SX) and lam.shape == (3, 1)
    jac = ca.Function("dlam_dV", [Vs], [ca.jacobian(lam, ca.vec(Vs))])
    rng = np.random.default_rng(5)
    for _ in range(20):
        Q = random_rotation(rng)
        lam_true = np.sort(rng.uniform(0.1, 3.0, 3))[::-1]
        V = Q @ np.diag(lam_true) @ Q.T
        J = np.array(jac(V))
        for j in range(3):
            expect = np.outer(Q[:, j], Q[:, j]).ravel(order="F")
            assert np.allclose(J[j], expect, atol=1e-9)
    coincident = [(2.0, 1.0, 1.0), (2.0, 2.0, 1.0), (1.0, 1.0, 1.0), (1.0, 0.0, 0.0)]
    matrices = [np.diag(sp) for sp in coincident]  # exactly coincident (exactly isotropic: s = 0)
    for sp in coincident:
        Q = random_rotation(rng)
        matrices.append(Q @ np.diag(sp) @ Q.T)  # coincident up to rounding
    for V in matrices:
        J = np.array(jac(V))
        assert np.all(np.isfinite(J)), V
        # the sum of the three is the trace, whose derivative is the identity, whatever coincides
        assert np.allclose(J.sum(axis=0), np.eye(3).ravel(), atol=1e-9)


def test_cubic_on_mx_symbols():
    """The expression evaluates on MX graphs too (the solvers may build either kind), including
    a singular deviator (the middle variance equal to the mean) and coincident variances."""
    Vm = ca.MX.sym("V", 3, 3)
    f = ca.Function("cubic_mx", [Vm], [principal_variances_cubic(0.5 * (Vm + Vm.T))])
    rng = np.random.default_rng(8)
    for spectrum in [(3.0, 2.0, 1.0), (2.0, 1.0, 1.0), (4.0, 4.0, 4.0), (2.0, 1.0, 0.0)]:
        Q = random_rotation(rng)
        _check_spectrum(np.array(f(Q @ np.diag(spectrum) @ Q.T)).ravel(), spectrum, "MX")
        _check_spectrum(np.array(f(np.diag(spectrum))).ravel(), spectrum, "MX diagonal")


# ---------------------------------------------------------------------------------------------
# P(dr <= R) in the sphere
# ---------------------------------------------------------------------------------------------
X_VALUES = [0.1, 0.3, 0.5, 1.0, 1.5, 2.0, 2.5758, 3.0, 4.0, 5.0, 8.0]


@pytest.mark.parametrize("sigma", [0.05, 1.0, 37.0])
def test_p_ball_equal_variances_closed_form(sigma):
    worst = 0.0
    for x in X_VALUES:
        P = p_ball([sigma**2] * 3, x * sigma)
        worst = max(worst, abs(P - p_sphere_closed_form(x)))
        assert abs(P - p_sphere_closed_form(x)) <= 1e-10, (x, P)
        assert abs(P - stats.chi2.cdf(x * x, 3)) <= 1e-10, (x, P)
    print(f"sphere, equal variances, sigma={sigma}: max |P - closed form| {worst:.1e}")


def test_p_ball_two_and_one_dimensional_limits():
    """One zero variance: the 2-D disc, 1 - exp(-x^2/2); two zero: erf(x/sqrt2)."""
    for x in X_VALUES:
        assert abs(p_ball([4.0, 4.0, 0.0], 2.0 * x) - (1 - math.exp(-x * x / 2))) <= 1e-12
        assert abs(p_ball([4.0, 0.0, 0.0], 2.0 * x) - special.erf(x / math.sqrt(2))) <= 1e-12
        assert abs(p_ball([4.0, 4.0], 2.0 * x) - stats.chi2.cdf(x * x, 2)) <= 1e-12


UNEQUAL = [
    ((1.0, 0.5, 0.1), 1.0),
    ((4.0, 1.0, 0.25), 0.5),
    ((4.0, 1.0, 0.25), 3.0),
    ((0.04, 0.01, 1e-4), 0.2),
    ((0.091, 0.038, 0.0025), 0.2),  # the paper's scale
    ((1.0, 1e-2, 1e-4), 0.05),  # strongly unequal
    ((1.0, 0.9, 0.8), 8.0),  # far tail
]


@pytest.mark.parametrize("lam, R", UNEQUAL)
def test_p_ball_unequal_variances_vs_scipy_integral(lam, R):
    P, err = p_ball(lam, R, return_error=True)
    ref = ball_probability_scipy(lam, R)
    assert abs(P - ref) <= 1e-10, (lam, R, P, ref)
    assert err <= 1e-12


@pytest.mark.parametrize("lam, R", [((1.0, 0.3), 0.7), ((9.0, 1e-2), 0.5), ((2.0, 1.0), 4.0)])
def test_p_ball_unequal_2d_vs_scipy_integral(lam, R):
    assert abs(p_ball(list(lam) + [0.0], R) - ball_probability_scipy(lam, R)) <= 1e-11


@pytest.mark.parametrize("lam, R", [((1.0, 0.5, 0.1), 1.0), ((0.091, 0.038, 0.0025), 0.2), ((4.0, 1.0, 0.0), 1.5)])
def test_p_ball_unequal_variances_vs_gaussian_sample(lam, R):
    """2e6 seeded Gaussian points: within 4 standard errors (about 1.4e-3 at P = 0.5)."""
    rng = np.random.default_rng(314159)
    N = 2_000_000
    w = rng.standard_normal((N, 3)) * np.sqrt(lam)
    hits = np.count_nonzero(np.einsum("ij,ij->i", w, w) <= R * R)
    p_mc = hits / N
    P = p_ball(lam, R)
    se = math.sqrt(P * (1 - P) / N)
    assert abs(P - p_mc) <= 4 * se, (lam, R, P, p_mc, se)


def test_p_ball_order_and_independence_of_scale():
    """The variances may come in any order, and P depends on R/sigma only."""
    lam = np.array([0.3, 2.0, 0.7])
    ref = ball_probability_scipy(lam, 1.1)
    for perm in ([0, 1, 2], [2, 0, 1], [1, 2, 0]):
        assert abs(p_ball(lam[perm], 1.1) - ref) <= 1e-10
    assert abs(p_ball(lam * 1e-6, 1.1e-3) - ref) <= 1e-10


@pytest.mark.parametrize("lam, R", [((1.0, 1e-4, 1e-8), 1e-3), ((1.0, 1e-6, 1e-12), 1e-4)])
def test_p_ball_very_unequal_variances_vs_scipy_integral(lam, R):
    """Variance ratios down to 1e-12: the graded panels keep this to milliseconds."""
    assert abs(p_ball(lam, R) - ball_probability_scipy(lam, R)) <= 1e-11


@pytest.mark.parametrize("l3", [1e-10, 1e-8, 1e-6])
def test_p_ball_thin_third_variance_vs_perturbation_series(l3):
    """(1, 1, l3), l3 -> 0: P = 1 - e^(-R^2/2) - l3 * e^(-R^2/2) / 2 + O(l3^2) (the chi-square(2)
    density at R^2 times E[w3^2]).  SciPy's dblquad loses ~4e-11 here, so the series is the check."""
    R = 0.5
    series = 1 - math.exp(-R * R / 2) - l3 * 0.5 * math.exp(-R * R / 2)
    assert abs(p_ball((1.0, 1.0, l3), R) - series) <= 1e-12 + 10 * l3**2


@pytest.mark.parametrize(
    "lam, R",
    [
        ((1.0, 0.5, 0.1), 1e-3),  # R far inside every sigma: P ~ R^3 (the series of the kernel)
        ((1.0, 1.0, 1.0), 1e-4),
        ((1.0, 1e-2, 1e-6), 1e-2),  # a flat ellipsoid: R beyond sigma3, far inside sigma1, sigma2
        ((4.0, 1.0, 1e-8), 1e-3),
        ((1.0, 0.3, 0.29), 0.05),
    ],
)
def test_p_ball_small_probabilities_keep_relative_accuracy(lam, R):
    """Probabilities of 1e-13 .. 5e-4: relative agreement with a SciPy dblquad run with a purely
    relative tolerance (the 1-D kernel is evaluated without cancellation)."""
    ref = ball_probability_scipy(lam, R, epsabs=0.0)
    assert abs(p_ball(lam, R) - ref) <= 1e-10 * ref, (lam, R, ref)


def test_p_ball_batch_random_rows_vs_scipy_integral():
    """Random variances over 4 decades and radii over 3: the batch against SciPy's dblquad."""
    rng = np.random.default_rng(20261123)
    lam = np.exp(rng.uniform(-8, 1, (8, 3)))
    for R in (5e-3, 0.2, 3.0):
        got = tolsynth.probability.stats.p_ball_batch(lam, R)
        for row, P in zip(lam, got):
            assert abs(P - ball_probability_scipy(row, R)) <= 1e-10, (row, R, P)


def test_p_ball_batch_rows_vs_scipy_integral(rng):
    """One batch mixing 3-D rows of different panel counts, 2-D, 1-D and all-zero rows."""
    rows = [np.exp(rng.normal(-3, 2.0, 3)) for _ in range(6)]
    rows += [(0.04, 0.01, 0.0), (0.02, 0.0, 0.0), (0.0, 0.0, 0.0), (1.0, 1e-5, 1e-9)]
    got = tolsynth.probability.stats.p_ball_batch(np.array(rows), 0.2)
    for lam, P in zip(rows, got):
        lam = sorted((v for v in lam if v > 0), reverse=True)
        if not lam:
            ref = 1.0
        elif len(lam) == 1:
            ref = float(special.erf(0.2 / math.sqrt(2 * lam[0])))
        else:
            ref = ball_probability_scipy(lam, 0.2)
        assert abs(P - ref) <= 1e-10, (lam, P, ref)


# ---------------------------------------------------------------------------------------------
# components, quantile, cone
# ---------------------------------------------------------------------------------------------
def test_p_components_vs_scipy_norm():
    sigma = np.array([0.3, 0.1, 0.02, 0.0])
    for R in (0.01, 0.2, 1.0):
        P = p_components(sigma, R)
        expect = [2 * stats.norm.cdf(R / s) - 1 if s > 0 else 1.0 for s in sigma]
        assert np.allclose(P, expect, rtol=0, atol=1e-14)


def test_z_of_p_vs_scipy_and_the_paper():
    for p in (0.5, 0.7, 0.8, 0.9, 0.95, 0.99, 0.999, 1e-6, 1 - 1e-9):
        assert abs(z_of_p(p) - stats.norm.ppf(0.5 + p / 2)) <= 1e-9 * max(1.0, stats.norm.ppf(0.5 + p / 2))
    # the values printed in the paper (its section 4), to their 4 decimals
    for p, printed in ((0.99, 2.5758), (0.90, 1.6449), (0.80, 1.2816), (0.70, 1.0364)):
        assert abs(z_of_p(p) - printed) < 5e-5
        # and it is a two-sided quantile: P(|Z| <= z) = p
        assert abs(p_components([1.0], z_of_p(p))[0] - p) < 1e-12


def _cone_monte_carlo(Vo, axis, Phi, N, rng):
    phi = rng.multivariate_normal(np.zeros(3), Vo, size=N, method="eigh")
    moved = rodrigues(phi) @ axis
    angle = np.arctan2(np.linalg.norm(np.cross(moved, axis), axis=1), moved @ axis)
    return np.count_nonzero(angle <= Phi) / N


def test_p_cone_vs_monte_carlo_of_the_axis_angle(xz):
    """The hand axis rotated by sampled small rotations: the fraction whose angle to the nominal
    axis stays within Phi, vs p_cone (N = 4e5, 4 standard errors)."""
    rng = np.random.default_rng(2718)
    N = 400_000
    a = xz.analyze("worst", "figure3", "uniform", Phi=5e-4)
    axis = xz.fk("worst")[:3, 2]
    cases = [(a.orientation_covariance, axis, 5e-4), (a.orientation_covariance, axis, 2e-4)]
    for _ in range(2):  # random anisotropic covariances, random axes
        A = rng.normal(size=(3, 3)) * 1e-3
        u = rng.normal(size=3)
        cases.append((A @ A.T, u / np.linalg.norm(u), 1.2e-3))
    for Vo, ax, Phi in cases:
        P = p_cone(Vo, ax, Phi)
        p_mc = _cone_monte_carlo(Vo, ax, Phi, N, rng)
        se = math.sqrt(max(P * (1 - P), 1e-12) / N)
        assert abs(P - p_mc) <= 4 * se + 1e-9, (P, p_mc, se)
    assert a.p_cone == pytest.approx(p_cone(cases[0][0], axis, 5e-4), abs=1e-15)


def test_erf_and_erfc_without_scipy_match_scipy(monkeypatch):
    """The SciPy-free fallback of stats._special (the C library's erf / erfc, element by element)
    against SciPy's own implementation (Cephes), computed before SciPy is hidden."""
    import sys

    special = pytest.importorskip("scipy.special")
    import tolsynth.probability.stats as st

    x = np.linspace(-6.0, 6.0, 241)
    ref_erf, ref_erfc = special.erf(x), special.erfc(x)
    monkeypatch.setitem(sys.modules, "scipy", None)
    monkeypatch.setitem(sys.modules, "scipy.special", None)
    got_erf, got_erfc = st._erf(x), st._erfc(x)
    assert got_erf.dtype == float and got_erfc.dtype == float
    np.testing.assert_allclose(got_erf, ref_erf, rtol=1e-15, atol=1e-16)
    np.testing.assert_allclose(got_erfc, ref_erfc, rtol=1e-14, atol=0)  # relative: erfc(6) ~ 2e-17
