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

from .errors import OutOfRangeError

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
    "p_cone",
]

#: V(delta) = eps**2 / divisor
VARIANCE_DIVISOR = {"uniform": 3.0, "normal": 9.0}


def variance_divisor(distribution: str) -> float:
    """3 for uniform errors, 9 for normal errors with 3 sigma = eps."""
    try:
        return VARIANCE_DIVISOR[distribution]
    except (KeyError, TypeError):
        raise OutOfRangeError(
            "distribution", f"unknown distribution {distribution!r}", "'uniform' or 'normal'"
        ) from None


def _is_real(x) -> bool:
    return not isinstance(x, (bool, np.bool_)) and isinstance(x, (int, float, np.integer, np.floating))


def check_probability(p: float, field: str = "p") -> float:
    """``p`` as a float, or OutOfRangeError unless 0 < p < 1."""
    if not _is_real(p) or not (0.0 < float(p) < 1.0):
        raise OutOfRangeError(field, f"got {p!r}", "0 < p < 1")
    return float(p)


def check_positive(x: float, field: str, unit: str = "mm") -> float:
    """``x`` as a float, or OutOfRangeError unless it is finite and > 0."""
    if not _is_real(x) or not (float(x) > 0.0) or not math.isfinite(float(x)):
        raise OutOfRangeError(field, f"got {x!r}", f"a finite number > 0 ({unit})")
    return float(x)


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
    units and ``c`` the variance divisor (3 uniform, 9 normal).  Used by the analysis, by IPOPT and
    by SUMT alike.
    """
    S = ca.SX.sym("S", 6, n)
    eps = ca.SX.sym("eps", n)
    c = ca.SX.sym("c")
    D = ca.diag(eps**2 / c)
    V = ca.mtimes([S, D, S.T])
    return ca.Function("covariance", [S, eps, c], [V[:3, :3], V[3:, 3:]], ["S", "eps", "c"], ["Vp", "Vo"])


def covariance(S: np.ndarray, eps: np.ndarray, distribution: str) -> tuple[np.ndarray, np.ndarray]:
    """Position and orientation covariance (mm^2, rad^2) of the hand error."""
    S = np.asarray(S, dtype=float)
    Vp, Vo = covariance_graph(S.shape[1])(S, np.asarray(eps, dtype=float), variance_divisor(distribution))
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
    return (A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1])
            - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
            + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0]))


def principal_variances_cubic(V) -> ca.SX:
    """Principal variances (descending) of a symmetric 3x3 ``V`` by the closed-form cubic.

    The paper's appendix writes the characteristic polynomial ``lam^3 + b1 lam^2 + b2 lam + b3``
    and its trigonometric roots with ``p = -b1^2/3 + b2`` (the DIGEST's fix).  Here ``p`` is
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
def _erf(x: np.ndarray) -> np.ndarray:
    """Vectorised error function (CasADi's, double precision; NumPy has none)."""
    x = np.asarray(x, dtype=float)
    flat = np.array(ca.erf(ca.DM(x.reshape(-1, 1)))).reshape(x.shape)
    return flat


def p_components(sigma, R: float) -> np.ndarray:
    """``P(|w_j| <= R)`` for independent zero-mean normals with standard deviations ``sigma``."""
    R = check_positive(R, "R")
    sigma = np.asarray(sigma, dtype=float)
    with np.errstate(divide="ignore"):
        x = np.where(sigma > 0, R / (np.sqrt(2.0) * np.where(sigma > 0, sigma, 1.0)), np.inf)
    return np.where(np.isinf(x), 1.0, _erf(np.where(np.isinf(x), 0.0, x)))


def _chi_cdf_radial(n: int, x: np.ndarray) -> np.ndarray:
    """P(|Z| <= x) for Z standard normal in n = 1, 2, 3 dimensions (chi distribution CDF)."""
    if n == 1:
        return _erf(x / math.sqrt(2.0))
    if n == 2:
        return -np.expm1(-0.5 * x * x)
    return _erf(x / math.sqrt(2.0)) - math.sqrt(2.0 / math.pi) * x * np.exp(-0.5 * x * x)


@lru_cache(maxsize=None)
def _gauss_legendre_01(n: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def p_ball(variances, R: float, tol: float = 1e-12, max_nodes: int = 4096, return_error: bool = False):
    """``P(|w| <= R)`` for ``w`` zero-mean normal with independent components of the given variances.

    This is Eq. 5 (the sphere) for three variances and the cone of Eq. 8 for two.  In whitened
    coordinates ``w = diag(sigma) r v`` (``r`` chi-distributed, ``v`` uniform on the unit sphere), so

        P = mean over unit v of  F_n( R / sqrt(sum_j lam_j v_j^2) ),

    with ``F_n`` the chi CDF in n dimensions.  The sphere average is a smooth integral, taken over
    one octant by Gauss-Legendre in ``v_1 = cos(theta)`` and the midpoint rule in the azimuth
    (periodic, so spectrally accurate); the node count doubles until two successive values agree
    to ``tol``.  Equal variances make the integrand constant, so the result is the closed form
    ``erf(x/sqrt2) - sqrt(2/pi) x exp(-x^2/2)`` to rounding.  Variances below ``1e-15 * max`` are
    treated as 0 (they are below the eigensolver's rounding) and the dimension drops accordingly.

    Returns the probability, and its error estimate if ``return_error``.  Raises ``RuntimeError``
    if ``max_nodes`` is reached without meeting ``tol`` (never returns an unconverged value).
    """
    R = check_positive(R, "R")
    lam = np.sort(np.asarray(variances, dtype=float).ravel())[::-1]
    if lam.size == 0 or lam[0] <= 0.0:
        return (1.0, 0.0) if return_error else 1.0
    if np.any(lam < -1e-12 * lam[0]):
        raise OutOfRangeError("variances", f"negative variance in {lam}", "variances >= 0")
    lam = lam[lam > 1e-15 * lam[0]]
    n = lam.size
    if n == 1:
        value, err = float(_chi_cdf_radial(1, np.array(R / math.sqrt(lam[0])))), 0.0
    else:
        value, err = None, math.inf
        nodes = 16
        while nodes <= max_nodes:
            new = _ball_quadrature(lam, R, nodes)
            if value is not None:
                err = abs(new - value)
                if err <= tol:
                    value = new
                    break
            value = new
            nodes *= 2
        else:
            raise RuntimeError(f"p_ball: no convergence to {tol} with {max_nodes} nodes (last change {err:.2e})")
    return (value, err) if return_error else value


def _ball_quadrature(lam: np.ndarray, R: float, nodes: int) -> float:
    n = lam.size
    phi = (np.arange(nodes) + 0.5) * (0.5 * math.pi / nodes)  # midpoint rule on [0, pi/2]
    if n == 2:
        q = lam[0] * np.cos(phi) ** 2 + lam[1] * np.sin(phi) ** 2
        return float(np.mean(_chi_cdf_radial(2, R / np.sqrt(q))))
    z, wz = _gauss_legendre_01(nodes)  # z = v_1 = cos(theta), uniform measure on the sphere
    perp = lam[1] * np.cos(phi) ** 2 + lam[2] * np.sin(phi) ** 2
    q = lam[0] * z[:, None] ** 2 + (1.0 - z[:, None] ** 2) * perp[None, :]
    f = _chi_cdf_radial(3, R / np.sqrt(q))
    return float(wz @ f.mean(axis=1))


def p_cone(Vo: np.ndarray, axis, Phi: float) -> float:
    """Probability that the hand axis stays inside a cone of half-angle ``Phi`` (rad), Eq. 8.

    ``Vo`` is the orientation covariance (rad^2, base frame) and ``axis`` the nominal hand axis
    (unit vector, base frame).  To first order the axis turns by the rotation components
    perpendicular to it, so the deviation angle is the length of a 2-D normal vector with the
    covariance of ``Vo`` projected on the plane normal to the axis.
    """
    Phi = check_positive(Phi, "Phi", "rad")
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    helper = np.eye(3)[int(np.argmin(np.abs(a)))]
    e1 = np.cross(a, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    E = np.column_stack([e1, e2])
    C = E.T @ np.asarray(Vo, dtype=float) @ E
    lam = np.linalg.eigvalsh(0.5 * (C + C.T))
    return p_ball(lam, Phi)
