"""The probabilistic error model of the paper's section 3 (Eqs. 2-9).

Each error ``delta_i`` is zero-mean inside ``(-eps_i, eps_i)``:

* ``"uniform"`` (single-piece production): ``V(delta_i) = eps_i**2 / 3``;
* ``"normal"`` (batch production, ``3 sigma = eps``): ``V(delta_i) = eps_i**2 / 9``.

The hand error is linear in the errors (the sensitivity matrix ``S``, 6 x n), so its covariance is
``S diag(V(delta)) S^T``; rotated to principal axes it is three independent zero-mean normals
(the paper's Gaussian reading of Eq. 4).  This module holds

* the CasADi graphs shared by the analysis and by both solvers: :data:`COVARIANCE` (the covariance
  from sensitivities and tolerances) and :func:`principal_variances_cubic` (the closed-form cubic of
  the paper's appendix, written as a CasADi expression);
* NumPy evaluations: principal standard deviations by the symmetric eigensolver, and the
  probabilities ``P(|w_j| <= R)`` (Eq. 6-7), ``P(dr <= R)`` in the sphere (Eq. 5) and in the cone
  (Eq. 8) by a quadrature with a stated error bound (not sampling), and the two-sided normal
  quantile ``z(p)``.
"""

from __future__ import annotations

import itertools
import math
from functools import lru_cache
from statistics import NormalDist

import casadi as ca
import numpy as np

from tolsynth.errors import OutOfRangeError

__all__ = [
    "VARIANCE_DIVISOR",
    "variance_divisor",
    "z_of_p",
    "covariance_graph",
    "covariance",
    "principal",
    "principal_variances_cubic",
    "principal_cubic_function",
    "p_components",
    "p_ball",
    "p_ball_batch",
    "p_cone",
]

#: V(delta) = eps**2 / divisor (the paper's two; tolsynth.probability.distributions has all the shapes)
VARIANCE_DIVISOR = {"uniform": 3.0, "normal": 9.0, "triangular": 6.0}


def variance_divisor(distribution, mechanism=None):
    """3 for uniform errors, 9 for normal errors with 3 sigma = eps, 6 triangular, ... (see
    :mod:`tolsynth.probability.distributions`); one value per error parameter of ``mechanism`` for a
    per-parameter distribution (a mapping ``name -> shape``)."""
    from tolsynth.probability.distributions import divisor_of

    return divisor_of(distribution, mechanism)


# the argument rules live in tolsynth.checks (one copy); re-exported here for older imports
from tolsynth.checks import check_half_angle, check_positive, check_probability, check_vector  # noqa: E402,F401


def _array(x, field: str) -> np.ndarray:
    """A float array of finite numbers, or a typed error."""
    from tolsynth.errors import InputError

    if isinstance(x, (str, bytes)) or x is None:
        raise InputError(field, f"expected numbers, got {x!r}", "an array of finite numbers")
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise InputError(field, f"expected numbers, got {x!r:.60}", "an array of finite numbers") from None
    if not np.all(np.isfinite(arr)):
        raise OutOfRangeError(field, "a non-finite value", "finite numbers")
    return arr


def z_of_p(p: float) -> float:
    """Two-sided standard normal quantile: ``P(|Z| <= z(p)) = p``.  z(0.99) = 2.5758."""
    p = check_probability(p)
    return NormalDist().inv_cdf(0.5 + 0.5 * p)


# ---------------------------------------------------------------------------------------------
# CasADi graphs: the one copy of the covariance formula
# ---------------------------------------------------------------------------------------------
@lru_cache(maxsize=None)
def covariance_graph(n: int) -> ca.Function:
    """``covariance(S, eps, c) -> (Vp, Vo)``: position (mm^2) and orientation (rad^2) covariances.

    ``S`` is the 6 x n sensitivity (per tolerance unit), ``eps`` the n half-widths in tolerance
    units and ``c`` the n variance divisors (3 uniform, 9 normal, ...; a scalar is broadcast).
    Used by the analysis, by IPOPT and by SUMT alike.
    """
    S = ca.SX.sym("S", 6, n)
    eps = ca.SX.sym("eps", n)
    c = ca.SX.sym("c", n)
    D = ca.diag(eps**2 / c)
    V = ca.mtimes([S, D, S.T])
    return ca.Function("covariance", [S, eps, c], [V[:3, :3], V[3:, 3:]], ["S", "eps", "c"], ["Vp", "Vo"])


def covariance(S: np.ndarray, eps: np.ndarray, distribution) -> tuple[np.ndarray, np.ndarray]:
    """Position and orientation covariance (mm^2, rad^2) of the hand error.  ``distribution``: a
    shape name, or the variance divisors, one per column of ``S``."""
    S = np.asarray(S, dtype=float)
    c = distribution if isinstance(distribution, np.ndarray) else variance_divisor(distribution)
    Vp, Vo = covariance_graph(S.shape[1])(S, np.asarray(eps, dtype=float), c)
    return np.array(Vp), np.array(Vo)


def principal(V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Principal standard deviations (descending) and directions (columns) of a covariance.

    By NumPy's symmetric eigensolver.  Eigenvalues below ``1e-15 * max`` (rounding noise of a
    positive semi-definite matrix, possibly slightly negative) are reported as exactly 0.
    """
    V = np.asarray(V, dtype=float)
    lam, vec = np.linalg.eigh(0.5 * (V + V.T))
    order = np.argsort(lam)[::-1]
    lam, vec = lam[order], vec[:, order]
    floor = 1e-15 * max(float(lam[0]), 0.0)
    lam = np.where(lam <= floor, 0.0, lam)
    return np.sqrt(lam), vec


def _det3(A):
    """3x3 determinant by cofactors (CasADi's MX ``det`` factorises and fails on singular input)."""
    return (
        A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1])
        - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
        + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0])
    )


def principal_variances_cubic(V) -> ca.SX:
    """Principal variances (descending) of a symmetric 3x3 ``V`` by the closed-form cubic.

    The paper's appendix writes the characteristic polynomial ``lam^3 + b1 lam^2 + b2 lam + b3``
    and its trigonometric roots with ``p = -b1^2/3 + b2`` (fixing the scan: docs/reconstruction.md).  Here ``p`` is
    evaluated as ``-tr(D^2)/2`` with ``D = V - tr(V)/3 I``, which is the same number without the
    cancellation, and ``q = -det(D)``; the roots are ``m + 2 s cos(phi - 2 pi k / 3)`` with
    ``s = sqrt(-p/3)`` and ``cos(3 phi) = -q / (2 s^3)``.

    Coinciding variances: the textbook ``3 phi = acos(-q / 2 s^3)`` loses half the digits there
    (``acos`` near +-1 turns a rounding error of 1e-16 into 1e-8), so ``3 phi`` is taken as
    ``atan2(sin 3phi, cos 3phi)`` with ``sin 3phi = sqrt(Delta / 27) / (2 s^3)``, where ``Delta``,
    the discriminant ``prod (lam_i - lam_j)^2``, is evaluated as a sum of squares (Cauchy-Binet
    on the Gram determinant of ``[vec I, vec D, vec D^2]``, Parlett 2002), which keeps its full
    relative accuracy down to 0.  Everything is scaled by ``s`` first.  Where all three variances
    coincide (``s = 0``) the roots are ``tr(V)/3``.  The derivatives stay finite where variances
    coincide.  Works on SX/MX symbols (a CasADi expression) and on numbers.
    """
    V = ca.SX(V) if isinstance(V, (np.ndarray, list)) else V
    m = ca.trace(V) / 3
    D = V - m * ca.DM.eye(3)
    s2 = ca.sumsqr(D) / 6  # = -p/3, p = -tr(D^2)/2 <= 0
    tiny = 1e-300 + 1e-28 * m**2
    spread = s2 > tiny
    s = ca.if_else(spread, ca.sqrt(ca.if_else(spread, s2, 1.0)), 0.0)  # no 0/0 in the derivative
    Dn = D / ca.if_else(spread, s, 1.0)  # scaled: sqrt(tr(Dn^2)/6) = 1
    Dn2 = ca.mtimes(Dn, Dn)
    # rows (i, j) of [vec I, vec Dn, vec Dn^2]; the symmetric off-diagonal pairs merged (weight sqrt 2)
    rows = []
    for i, j in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)):
        w = 1.0 if i == j else math.sqrt(2.0)
        rows.append(ca.horzcat(1.0 if i == j else 0.0, w * Dn[i, j], w * Dn2[i, j]))
    minors = [_det3(ca.vertcat(rows[a], rows[b], rows[c])) for a, b, c in itertools.combinations(range(6), 3)]
    disc = ca.sumsqr(ca.vertcat(*minors))  # = prod (mu_i - mu_j)^2 of the eigenvalues mu of Dn
    sin3 = ca.if_else(disc > 0, ca.sqrt(ca.if_else(disc > 0, disc, 1.0) / 27), 0.0)  # = 2 sin(3 phi)
    cos3 = _det3(Dn)  # = -q / s^3 = 2 cos(3 phi)
    phi = ca.if_else(spread, ca.atan2(sin3, cos3), 0.0) / 3
    two_pi_3 = 2 * math.pi / 3
    l1 = m + 2 * s * ca.cos(phi)
    l3 = m + 2 * s * ca.cos(phi + two_pi_3)
    l2 = 3 * m - l1 - l3
    return ca.vertcat(l1, l2, l3)


@lru_cache(maxsize=None)
def principal_cubic_function() -> ca.Function:
    """CasADi Function ``principal_cubic(V) -> lam`` (3 principal variances, descending)."""
    V = ca.SX.sym("V", 3, 3)
    Vs = 0.5 * (V + V.T)
    return ca.Function("principal_cubic", [V], [principal_variances_cubic(Vs)], ["V"], ["lam"])


# ---------------------------------------------------------------------------------------------
# probabilities
# ---------------------------------------------------------------------------------------------
def _special(name: str, x) -> np.ndarray:
    """``scipy.special.<name>`` (erf, erfc) when SciPy is installed (it is not a run-time
    dependency; about 10x faster), else the standard library's ``math.<name>`` element by element;
    both agree to 3e-16."""
    x = np.asarray(x, dtype=float)
    try:
        import scipy.special
    except ImportError:  # pragma: no cover - exercised where SciPy is absent
        return _MATH_UFUNCS[name](x).astype(float)
    return getattr(scipy.special, name)(x)


_MATH_UFUNCS = {name: np.frompyfunc(getattr(math, name), 1, 1) for name in ("erf", "erfc")}


def _erf(x: np.ndarray) -> np.ndarray:
    """Vectorised error function, double precision (NumPy has none): :func:`_special`."""
    return _special("erf", x)


def p_components(sigma, R: float) -> np.ndarray:
    """``P(|w_j| <= R)`` for independent zero-mean normals with standard deviations ``sigma``."""
    R = check_positive(R, "R")
    sigma = _array(sigma, "sigma")
    if np.any(sigma < 0):
        raise OutOfRangeError("sigma", "a negative standard deviation", "finite numbers >= 0")
    with np.errstate(divide="ignore", over="ignore"):  # R / tiny sigma -> inf -> probability 1
        x = np.where(sigma > 0, R / (np.sqrt(2.0) * np.where(sigma > 0, sigma, 1.0)), np.inf)
    return np.where(np.isinf(x), 1.0, _erf(np.where(np.isinf(x), 0.0, x)))


def chi3_cdf(x, erf=None, exp=np.exp):
    """P(|Z| <= x) for Z standard normal in 3 dimensions: ``erf(x/sqrt2) - sqrt(2/pi) x e^(-x^2/2)``.

    On NumPy arrays by default; pass ``erf=casadi.erf, exp=casadi.exp`` for a CasADi expression
    (the sphere constraint of :mod:`tolsynth.problem.nlp` uses that: one copy of the formula).
    """
    erf = _erf if erf is None else erf
    return erf(x / math.sqrt(2.0)) - math.sqrt(2.0 / math.pi) * x * exp(-0.5 * x * x)


#: the chi CDFs in 1-3 dimensions equal 1 to double precision beyond this argument
CHI_SATURATION = 40.0


def _chi_cdf_radial(n: int, x: np.ndarray) -> np.ndarray:
    """P(|Z| <= x) for Z standard normal in n = 1, 2 dimensions (chi distribution CDF).

    Arguments beyond CHI_SATURATION are evaluated there (where the CDF is 1 to double precision),
    so that ``x * x`` cannot overflow.  (3-D: :func:`chi3_cdf`; the sphere quadrature uses
    :func:`_ball3_kernel`.)"""
    x = np.minimum(x, CHI_SATURATION)
    if n == 1:
        return _erf(x / math.sqrt(2.0))
    return -np.expm1(-0.5 * x * x)


@lru_cache(maxsize=None)
def _gauss_legendre_01(n: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def _graded_nodes(c: np.ndarray, n_panels: int, nodes: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [0, 1], in panels with edges 0, c, 10c, 100c, ..., 1
    (one panel [0, 1] when ``n_panels`` is 1).

    ``c`` (one per row, in (0, 1]) is the smallest feature scale of that row's integrand: the
    panels resolve features from c to 1 with the same number of nodes each.  Returns arrays of
    shape (rows, n_panels * nodes).
    """
    x, w = _gauss_legendre_01(nodes)
    k = np.arange(n_panels - 1)
    inner = np.minimum(c[:, None] * 10.0 ** k[None, :], 1.0) if n_panels > 1 else np.zeros((c.size, 0))
    edges = np.concatenate([np.zeros((c.size, 1)), inner, np.ones((c.size, 1))], axis=1)
    a, b = edges[:, :-1, None], edges[:, 1:, None]
    return (a + (b - a) * x).reshape(c.size, -1), ((b - a) * w).reshape(c.size, -1)


def _scales(lam: np.ndarray, R: float) -> np.ndarray:
    """Smallest feature scale (in (0, 1]) of the azimuthal integrand of each row.

    The integrand changes where ``q = lam1 sin^2 + lam2 cos^2`` leaves ``lam2``, at
    ``sqrt(lam2/lam1)``; in 3-D the factor ``erf(a sqrt(kappa))`` can turn a times faster there
    (``a = R / sqrt(2 lam3)``; only where it matters, ``a`` below 6: beyond, ``e^(-a^2)`` hides it).
    """
    c = 0.1 * np.sqrt(lam[:, 1] / lam[:, 0])
    if lam.shape[1] == 3:
        with np.errstate(over="ignore"):  # a = inf is clipped like any a >= 6
            a = R / np.sqrt(2.0 * lam[:, 2])
        c = c / np.clip(a, 1.0, 6.0)
    return np.minimum(1.0, c)


def _n_panels(c: np.ndarray) -> np.ndarray:
    """One panel down to a scale of 0.01, then one more per decade."""
    return np.where(c >= 0.01, 1, 1 + np.ceil(np.log10(0.01 / c)).astype(int))


def _erfc(x: np.ndarray) -> np.ndarray:
    """Vectorised complementary error function: :func:`_special`."""
    return _special("erfc", x)


def _series_coefficients(terms: int) -> np.ndarray:
    """``C[N, n]`` (N = 1..terms, n = 0..N-1) of the small-``a`` series of :func:`_ball3_kernel`:
    ``h = 2/sqrt(pi) sum_N (-1)^N a^(2N+1) sum_n C[N, n] kappa^n (1 - kappa)^(N - n)``, every
    ``C`` negative (no cancellation inside the sum)."""
    C = np.zeros((terms + 1, terms + 1))
    for N in range(1, terms + 1):
        for n in range(N):
            C[N, n] = (2 * n - 2 * N) / ((2 * N + 1) * (2 * n + 1) * math.factorial(n) * math.factorial(N - n))
    return C


_SERIES_TERMS = 12
_SERIES_C = _series_coefficients(_SERIES_TERMS)
#: the kernel by its series below this a (the closed form cancels there: P ~ a^3)
_SERIES_A = 0.25


def _ball3_kernel(a: np.ndarray, c: np.ndarray, kappa: np.ndarray, one_minus_kappa: np.ndarray) -> np.ndarray:
    """``h(a, kappa) = erf(a) - e^(-c) erf(a sqrt(kappa)) / sqrt(kappa)``, ``c = a^2 (1 - kappa)``,
    kappa in [0, 1), without cancellation: by the series in ``a`` for small ``a``, and for
    ``kappa >= 1/2`` as ``(1 - 1/s) - erfc(a) + erfc(a s)/s - expm1(-c) erf(a s)/s``
    (``s = sqrt(kappa)``, ``1 - 1/s = -(1 - kappa) / (s (1 + s))``), which keeps the relative
    accuracy of small probabilities of flat ellipsoids.  ``a`` may be clipped (at 1e8) and ``c``
    saturated (at 800, where ``e^(-c)`` is 0): the value does not change.  Arrays broadcast."""
    a, c, kappa, omk = np.broadcast_arrays(a, c, kappa, one_minus_kappa)
    out = np.empty(a.shape)
    small = a < _SERIES_A
    if np.any(small):
        aa, kk, om = a[small], kappa[small], omk[small]
        total = np.zeros(aa.shape)
        a2 = aa * aa
        apow = aa.copy()
        for N in range(1, _SERIES_TERMS + 1):
            apow = apow * a2
            inner = np.zeros(aa.shape)
            for n in range(N):
                inner = inner + _SERIES_C[N, n] * kk**n * om ** (N - n)
            total = total + (-1) ** N * apow * inner
        out[small] = 2.0 / math.sqrt(math.pi) * total
    big = ~small
    if np.any(big):
        aa, cc, kk, om = a[big], c[big], kappa[big], omk[big]
        s = np.sqrt(kk)
        y = aa * s
        # E = erf(y)/s = a erf(y)/y, by the series of erf(y)/y for small y (s may be 0)
        tiny = y < 1e-3
        ys = np.where(tiny, 1.0, y)
        G = np.where(tiny, 2.0 / math.sqrt(math.pi) * (1.0 - y * y / 3.0 + y**4 / 10.0), _erf(ys) / ys)
        E = aa * G
        direct = _erf(aa) - np.exp(-cc) * E
        with np.errstate(divide="ignore", invalid="ignore"):
            split = (-om / (s * (1.0 + s)) - _erfc(aa) + _erfc(y) / s) - np.expm1(-cc) * E
        out[big] = np.where(kk >= 0.5, split, direct)
    return out


def _ball_quadrature(lam: np.ndarray, R: float, nodes: int, pt: int) -> np.ndarray:
    """One quadrature of P(|w| <= R) for rows of 2 or 3 positive, descending variances.

    One azimuthal integral in both cases: ``psi`` turns in the plane of the two largest
    variances, ``q = lam1 sin^2 psi + lam2 cos^2 psi`` (feature at ``sqrt(lam2/lam1)`` near 0),
    ``t = psi / (pi/2)``.  2-D: ``P = mean over psi of 1 - e^(-R^2 / 2q)``.  3-D: condition on the
    third (smallest) whitened component ``z``; the 2-D probability of the rest, in closed form
    per direction, integrated over ``z`` in closed form too (a Gaussian integral, because
    ``q >= lam3``) gives ``P = mean over psi of h(a, kappa)``, ``a = R / sqrt(2 lam3)``,
    ``kappa = 1 - lam3 / q`` (:func:`_ball3_kernel`)."""
    c = _scales(lam, R)
    t, wt = _graded_nodes(c, pt, nodes)
    psi = 0.5 * math.pi * t
    s2, c2 = np.sin(psi) ** 2, np.cos(psi) ** 2
    q = lam[:, :1] * s2 + lam[:, 1:2] * c2
    if lam.shape[1] == 2:
        return np.sum(wt * _chi_cdf_radial(2, R / np.sqrt(q)), axis=1)
    l3 = lam[:, 2:3]
    q_minus = (lam[:, :1] - l3) * s2 + (lam[:, 1:2] - l3) * c2  # q - lam3 without cancellation
    with np.errstate(over="ignore"):  # huge R / sigma: clipped where nothing changes any more
        a = np.minimum(R / np.sqrt(2.0 * l3), 1e8)
        x = np.minimum(R / np.sqrt(q), CHI_SATURATION)
    return np.sum(wt * _ball3_kernel(a, 0.5 * x * x, q_minus / q, l3 / q), axis=1)


def _ball_rows(
    lam: np.ndarray,
    R: float,
    tol: float,
    max_nodes: int,
    out: np.ndarray,
    err: np.ndarray,
    rows: np.ndarray,
    budget: int = 4_000_000,
) -> None:
    """Converge the rows ``rows`` of ``lam`` (all of one dimension), grouped by panel counts and
    chunked so that no quadrature grid exceeds ``budget`` points."""
    pt = _n_panels(_scales(lam[rows], R))
    for key in sorted(set(pt.tolist())):
        group = rows[pt == key]
        prev, nodes = None, 8
        while group.size:
            chunk = max(1, budget // (key * nodes))
            val = np.concatenate(
                [_ball_quadrature(lam[group[a : a + chunk]], R, nodes, key) for a in range(0, group.size, chunk)]
            )
            if prev is not None:
                delta = np.abs(val - prev)
                done = delta <= tol
                # a quadrature of a CDF can overshoot [0, 1] by rounding (1 + 2e-15 seen): a
                # probability is reported inside [0, 1], the error estimate keeps the overshoot
                out[group[done]] = np.clip(val[done], 0.0, 1.0)
                err[group[done]] = np.maximum(delta[done], np.abs(val[done] - out[group[done]]))
                if not np.all(done) and nodes >= max_nodes:
                    raise RuntimeError(
                        f"p_ball: no convergence to {tol} with {max_nodes} nodes per panel "
                        f"(largest change {delta[~done].max():.2e})"
                    )
                group, val = group[~done], val[~done]
            prev, nodes = val, nodes * 2


def p_ball_batch(variances, R: float, tol: float = 1e-12, max_nodes: int = 512, return_error: bool = False):
    """``P(|w| <= R)`` for many zero-mean normal vectors with independent components.

    ``variances`` has shape (N, k), k <= 3 (mm^2, or rad^2 for the cone); returns shape (N,).
    This is Eq. 5 (the sphere) for three variances and Eq. 8 (the cone) for two.  Both are one
    integral over the azimuth ``psi`` in the plane of the two largest variances (whitened
    coordinates, ``q(psi) = lam1 sin^2 psi + lam2 cos^2 psi``):

        2-D:  P = mean over psi of  1 - exp(-R^2 / 2q)
        3-D:  P = mean over psi of  erf(a) - exp(-R^2 / 2q) erf(a sqrt(kappa)) / sqrt(kappa),
              a = R / sqrt(2 lam3),  kappa = 1 - lam3 / q

    (3-D: the disc probability of the two largest components, in closed form per direction,
    integrated in closed form over the smallest one, a Gaussian integral since ``q >= lam3``;
    evaluated without cancellation by :func:`_ball3_kernel`, so small probabilities keep their
    relative accuracy).  Gauss-Legendre in ``psi``, on panels graded geometrically from the
    smallest scale of the integrand (about ``0.1 sqrt(lam2 / lam1)``, so very unequal variances
    cost a few panels, not a finer grid).  The node count per panel doubles until two successive
    values agree to ``tol`` in every row.  Equal variances make the integrand constant, so the
    result is then the closed form ``erf(x/sqrt2) - sqrt(2/pi) x exp(-x^2/2)`` to rounding.
    Variances below ``1e-15 * max`` of their row are below an eigensolver's rounding and are
    taken as 0; the dimension drops accordingly (1-D: ``erf``).

    Raises ``RuntimeError`` if ``max_nodes`` per panel is reached without meeting ``tol``: an
    unconverged value is never returned.
    """
    R = check_positive(R, "R")
    lam = np.sort(np.atleast_2d(_array(variances, "variances")), axis=1)[:, ::-1]
    if lam.ndim != 2 or not 1 <= lam.shape[1] <= 3:
        raise OutOfRangeError("variances", f"shape {np.shape(variances)}", "(N, k) with 1 <= k <= 3")
    top = np.maximum(lam[:, :1], 0.0)
    if np.any(lam < -1e-12 * top) or not np.all(np.isfinite(lam)):
        raise OutOfRangeError("variances", "negative or non-finite variance", "finite variances >= 0")
    lam = np.where(lam > 1e-15 * top, lam, 0.0)
    dims = np.count_nonzero(lam > 0, axis=1)
    out = np.ones(lam.shape[0])
    err = np.zeros(lam.shape[0])
    one = dims == 1
    out[one] = _chi_cdf_radial(1, R / np.sqrt(lam[one, 0]))
    for k in (2, 3):
        rows = np.flatnonzero(dims == k)
        if rows.size:
            _ball_rows(lam[:, :k], R, tol, max_nodes, out, err, rows)
    return (out, err) if return_error else out


def p_ball(variances, R: float, tol: float = 1e-12, max_nodes: int = 512, return_error: bool = False):
    """``P(|w| <= R)`` for one zero-mean normal vector with independent components of the given
    variances (mm^2 and mm, or rad^2 and rad); see :func:`p_ball_batch` for the method.

    Returns the probability, and its error estimate (change at the last doubling) if
    ``return_error``.
    """
    value, err = p_ball_batch(_array(variances, "variances").ravel()[None, :], R, tol, max_nodes, True)
    return (float(value[0]), float(err[0])) if return_error else float(value[0])


def p_cone(Vo: np.ndarray, axis, Phi: float) -> float:
    """Probability that the hand axis stays inside a cone of half-angle ``Phi`` (rad), Eq. 8.

    ``Vo`` is the orientation covariance (rad^2, base frame) and ``axis`` the nominal hand axis
    (unit vector, base frame).  To first order the axis turns by the rotation components
    perpendicular to it, so the deviation angle is the length of a 2-D normal vector with the
    covariance of ``Vo`` projected on the plane normal to the axis.
    """
    Phi = check_half_angle(Phi)
    a = check_vector(axis, "axis", 3)
    if not np.linalg.norm(a) > 0:
        raise OutOfRangeError("axis", "the zero vector", "a nonzero 3-vector")
    a = a / np.linalg.norm(a)
    Vo = _array(Vo, "Vo")
    if Vo.shape != (3, 3):
        raise OutOfRangeError("Vo", f"shape {Vo.shape}", "a 3 x 3 covariance (rad^2)")
    helper = np.eye(3)[int(np.argmin(np.abs(a)))]
    e1 = np.cross(a, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    E = np.column_stack([e1, e2])
    C = E.T @ Vo @ E
    lam = np.linalg.eigvalsh(0.5 * (C + C.T))
    return p_ball(lam, Phi)
