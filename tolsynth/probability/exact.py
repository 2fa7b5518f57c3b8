"""Exact probabilities of the linear error model, with no Gaussian approximation.

The hand error is linear in the errors, ``dr = sum_i a_i eps_i Y_i`` (``a_i`` the sensitivity
column of parameter i, ``Y_i`` independent with the shapes of :mod:`tolsynth.probability.distributions`).
Its characteristic function is the product of the known factors ``phi_i``, so the probabilities
follow by inverting it, with a rigorous truncation bound; nothing is sampled.

**Along a direction** (``w = u . dr = sum_i b_i Y_i``, ``b_i = (u . a_i) eps_i``).  ``w`` lies in
``[-B, B]`` (``B = sum |b_i|`` over the bounded shapes, plus 8.5 standard deviations of the
normal part, beyond which its mass is below 2e-17).  Its density periodised with period ``2L``,
``L = R + B/2``, is unchanged on ``[-R, R]`` (the copies start beyond ``2L - R = R + B``), so

    P(|w| <= R) = R/L + sum_{k>=1} (2 / (k pi)) sin(k pi R / L) prod_i phi_i(k pi b_i / L)

exactly (the Fourier series of the periodised density, integrated over [-R, R]).  The series is
summed up to the K whose tail ``sum_{k>K} (2/(k pi)) prod_i env_i(k pi |b_i| / L)`` is below the
tolerance, with ``env_i >= |phi_i|`` non-increasing (:meth:`Shape.envelope`); the tail is bounded
by the integral of that non-increasing function, taken by upper Riemann sums.  So the error bound
is rigorous (up to rounding, about 1e-15).  Slow cases: one term dominating a direction (a
discontinuous density) needs K ~ 1/tol; the bound says so and :class:`ExactProbabilityError` is
raised beyond ``kmax``.

**The sphere** ``P(|dr| <= R)``.  In three dimensions the Radon inversion is local: with ``g_v``
the density of ``v . dr``, ``P(|dr| <= R) = mean over unit v of [P(|v . dr| <= R) - 2 R g_v(R)]``
(by ``f = -(1/8 pi^2) Laplacian int g_v(v . x) dv`` integrated over the ball; for a standard normal
it gives ``erf(R/sqrt2) - sqrt(2/pi) R e^{-R^2/2}``, the chi CDF).  Both terms come from the same
periodised series: per direction ``sum_k (2/(k pi)) (sin x_k - x_k cos x_k) prod_i phi_i(...)``,
``x_k = k pi R / L``; the mean over the hemisphere is Gauss-Legendre in ``v_z`` times the trapezoid
rule in the azimuth, doubled until two levels agree to the tolerance.  The integrand is only as
smooth in v as the density of ``v . dr`` (piecewise polynomial for uniform errors: C^(n-2) for n of
them), so the rule converges algebraically, about 2^-6 per doubling for 8 uniforms.

**The orientation cone** (Eq. 8): the 2-D vector of the rotation components perpendicular to the
hand axis, ``P(|t| <= Phi) = mean over theta of int_0^inf phi_theta(rho) Phi J_1(Phi rho) d rho``
(the 2-D inversion in polar frequency coordinates), by Gauss-Legendre panels up to a radius where
the rigorous tail bound ``int env * Phi * sqrt(2/(pi Phi rho))`` is below the tolerance.

References for the method: Gil-Pelaez (1951) for the inversion of a characteristic function;
Abate & Whitt (1992) "The Fourier-series method for inverting transforms of probability
distributions" for the periodisation (sampling) argument used here.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from tolsynth.checks import check_positive
from tolsynth.errors import OutOfRangeError, TolsynthError
from tolsynth.probability.distributions import Shape, shape

__all__ = [
    "ExactProbabilityError",
    "direction_probability",
    "components_probability",
    "worst_direction",
    "ball_probability",
    "cone_probability",
    "series_terms",
    "DEFAULT_TOL",
]

DEFAULT_TOL = 1e-9
#: largest number of series terms (beyond it the bound is reported, not met)
KMAX = 1 << 22
#: standard deviations of the normal part beyond which its mass (< 2e-17) is neglected
NORMAL_REACH = 8.5


class ExactProbabilityError(TolsynthError, ArithmeticError):
    """An exact probability could not be brought within its stated tolerance (``kmax`` terms)."""


def _shapes(shapes: Sequence, n: int) -> tuple[Shape, ...]:
    out = tuple(shape(s) for s in shapes)
    if len(out) != n:
        raise OutOfRangeError("shapes", f"{len(out)} shapes for {n} coefficients", "one shape per error parameter")
    return out


def half_period(b: np.ndarray, shapes: tuple[Shape, ...], R: float) -> np.ndarray:
    """``L = R + (B + 8.5 sigma_normal) / 2`` per row of coefficients ``b`` (M, n)."""
    b = np.abs(b)
    bounded = np.array([s.bounded for s in shapes])
    B = b[:, bounded].sum(axis=1) if bounded.any() else np.zeros(b.shape[0])
    if (~bounded).any():
        B = B + NORMAL_REACH * np.sqrt(np.sum((b[:, ~bounded] / 3.0) ** 2, axis=1))
    return R + 0.5 * B


def _envelope(b: np.ndarray, shapes: tuple[Shape, ...], t: np.ndarray) -> np.ndarray:
    """``prod_i env_i(t |b_i|)`` for rows b (M, n) at frequencies t (M, T)."""
    out = np.ones(t.shape)
    for i, s in enumerate(shapes):
        bi = np.abs(b[:, i : i + 1])
        if np.all(bi == 0):
            continue
        out = out * np.where(bi > 0, s.envelope(t * bi), 1.0)
    return out


def _tail_bound(b, shapes, L, K, weight) -> np.ndarray:
    """Rigorous bound on ``sum_{k>K} weight(k) prod env(k pi |b| / L)`` per row, by the integral of
    the non-increasing summand, upper Riemann sums on a geometric grid from K to 1e19 K, and the
    power-law remainder beyond."""
    r = 1.25
    grid = K * r ** np.arange(0, 200)  # up to ~2e19 K
    t = np.pi * grid[None, :] / L[:, None]
    g = weight(grid[None, :], L[:, None]) * _envelope(b, shapes, t)
    dx = np.diff(grid)
    total = np.sum(g[:, :-1] * dx[None, :], axis=1)
    return total + g[:, -1] * grid[-1]  # remainder: g(t) <= g(T) T / t^2 once one power-law factor decays


def _needed_terms(b, shapes, L, tol, weight, kmax) -> tuple[int, np.ndarray]:
    K = 32
    while True:
        bound = _tail_bound(b, shapes, L, K, weight)
        if np.all(bound <= tol) or K >= kmax:
            return K, bound
        K *= 2


def series_terms(b: np.ndarray, shapes: tuple[Shape, ...], L: np.ndarray, K: int, lib=np) -> np.ndarray:
    """``prod_i phi_i(k pi b_i / L)`` for k = 1..K per row (M, K) (NumPy)."""
    k = np.arange(1, K + 1, dtype=float)
    out = np.ones((b.shape[0], K))
    for i, s in enumerate(shapes):
        bi = np.abs(b[:, i : i + 1])
        if np.all(bi == 0):
            continue
        out *= s.cf(np.pi * k[None, :] * bi / L[:, None])
    return out


def _interval_weight(k, L):
    return 2.0 / (np.pi * k)


#: a bounded term below this fraction of its row's largest is dropped, its effect added to the bound
NEGLIGIBLE = 1e-13


def _negligible_dropped(b: np.ndarray, sh) -> tuple[np.ndarray, np.ndarray]:
    """``b`` with bounded terms below ``NEGLIGIBLE`` of the row's largest set to 0 (they would make a
    near-jump the series cannot resolve), and per row the rigorous bound on what that changes:
    shifting ``w`` by at most ``delta = sum of the dropped |b_i|`` moves ``P(|w| <= R)`` by at most
    ``2 delta`` times the density's maximum, which is at most ``peak_j / |b_j|`` for any one term j
    (a convolution never raises the maximum), the largest term's here."""
    bounded = np.array([s.bounded for s in sh])
    peak = np.array([s.peak for s in sh])
    big = b.max(axis=1, keepdims=True)
    small = bounded[None, :] & (b > 0) & (b <= NEGLIGIBLE * big)
    if not small.any():
        return b, np.zeros(b.shape[0])
    jmax = np.argmax(b, axis=1)
    delta = np.where(small, b, 0.0).sum(axis=1)
    bound = np.where(delta > 0, 2.0 * delta * peak[jmax] / np.maximum(big[:, 0], 1e-300), 0.0)
    return np.where(small, 0.0, b), bound


def _one_term(row: np.ndarray, sh, R: float) -> float:
    """``P(|b Y| <= R)`` for a row with at most one non-zero term: the shape's own CDF (closed
    forms: uniform ``x``, triangular ``1 - (1 - x)^2``, normal ``erf(3 x / sqrt 2)``, normal
    truncated at 1 with sigma ``1/beta``: ``erf(beta x / sqrt 2) / erf(beta / sqrt 2)``, with
    ``x = R / |b|``); 1 for no term."""
    nz = np.flatnonzero(row)
    if nz.size == 0:
        return 1.0
    s = sh[nz[0]]
    x = R / abs(row[nz[0]])
    if s.kind == "normal":
        return math.erf(3.0 * x / math.sqrt(2.0))
    if x >= 1.0:
        return 1.0
    if s.kind == "uniform":
        return x
    if s.kind == "triangular":
        return 1.0 - (1.0 - x) ** 2
    return math.erf(s.beta * x / math.sqrt(2.0)) / math.erf(s.beta / math.sqrt(2.0))


def direction_probability(b, shapes, R: float, tol: float = DEFAULT_TOL, kmax: int = KMAX,
                          return_error: bool = False):
    """``P(|sum_i b_i Y_i| <= R)`` for rows of coefficients ``b`` (mm; shape (n,) or (M, n)),
    ``Y_i`` of the given shapes (one per column), exactly (see the module docstring).

    Returns the probabilities (scalar for one row) and, with ``return_error``, the rigorous bound
    on the truncation error.  Raises :class:`ExactProbabilityError` if ``kmax`` terms cannot meet
    ``tol`` (unless ``return_error``, which then reports the larger bound).
    """
    R = check_positive(R, "R")
    b = np.asarray(b, dtype=float)
    one = b.ndim == 1
    b = np.atleast_2d(np.abs(b))
    if not np.all(np.isfinite(b)):
        raise OutOfRangeError("b", "a non-finite coefficient", "finite numbers")
    sh = _shapes(shapes, b.shape[1])
    b, dropped = _negligible_dropped(b, sh)
    P = np.empty(b.shape[0])
    bound = dropped.copy()
    single = np.count_nonzero(b, axis=1) <= 1  # no term, or one: its own CDF (a jump defeats the series)
    if np.any(single):
        P[single] = [_one_term(row, sh, R) for row in b[single]]
    rest = np.flatnonzero(~single)
    K = 0
    if rest.size:
        br = b[rest]
        L = half_period(br, sh, R)
        K, tail = _needed_terms(br, sh, L, tol, _interval_weight, kmax)
        bound[rest] += tail
        if not return_error and np.any(bound > tol):
            raise ExactProbabilityError(
                f"exact probability: the series tail bound {bound.max():.2e} exceeds tol {tol:g} after {K} terms "
                "(one error dominates this direction: its density has a jump)")
        k = np.arange(1, K + 1, dtype=float)
        chunk = max(1, 4_000_000 // max(1, K * b.shape[1]))
        for a in range(0, rest.size, chunk):
            rows = slice(a, a + chunk)
            terms = series_terms(br[rows], sh, L[rows], K)
            coef = 2.0 / (np.pi * k)[None, :] * np.sin(np.pi * k[None, :] * R / L[rows, None])
            P[rest[rows]] = R / L[rows] + np.sum(coef * terms, axis=1)
    P = np.clip(P, 0.0, 1.0)
    if one:
        return (float(P[0]), float(bound[0])) if return_error else float(P[0])
    return (P, bound) if return_error else P


def _series_P(b: np.ndarray, sh, R: float, K: int) -> np.ndarray:
    """The K-term series of :func:`direction_probability` for rows b, without the tail bound
    (the pattern search of :func:`worst_direction` reuses a K found rigorous nearby)."""
    b = np.abs(np.atleast_2d(b))
    L = half_period(b, sh, R)
    k = np.arange(1, K + 1, dtype=float)
    coef = 2.0 / (np.pi * k)[None, :] * np.sin(np.pi * k[None, :] * R / L[:, None])
    return R / L + np.sum(coef * series_terms(b, sh, L, K), axis=1)


def components_probability(A, eps, shapes, R: float, tol: float = DEFAULT_TOL):
    """Exact ``P(|w_j| <= R)`` along the three principal directions of the covariance of
    ``dr = A diag(eps) Y`` (``A`` 3 x n, mm per tolerance unit): the paper's Eq. 6-7 without the
    Gaussian approximation.  Returns ``(P (3,), directions (3, 3) columns)`` descending in sigma."""
    A, eps, sh = _matrix_inputs(A, eps, shapes, 3, "A")
    var = np.array([s.variance for s in sh])
    V = (A * (eps**2 * var)) @ A.T
    lam, vec = np.linalg.eigh(0.5 * (V + V.T))
    vec = vec[:, ::-1]
    P = direction_probability(vec.T @ A * eps, sh, R, tol)
    return np.atleast_1d(P), vec


def _fibonacci_hemisphere(m: int) -> np.ndarray:
    """m nearly uniform unit vectors on the upper hemisphere (a Fibonacci lattice), (m, 3)."""
    i = np.arange(m) + 0.5
    z = 1.0 - i / m  # (0, 1]
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    s = np.sqrt(1.0 - z * z)
    return np.column_stack([s * np.cos(phi), s * np.sin(phi), z])


def worst_direction(A, eps, shapes, R: float, tol: float = DEFAULT_TOL, start=None, grid: int = 400,
                    local: int = 3):
    """The unit direction u of smallest exact ``P(|u^T dr| <= R)`` (and that probability).

    Candidates: the principal directions, the bisectors of each pair, ``start`` (if given) and a
    Fibonacci lattice of ``grid`` directions on the hemisphere (``P`` is even in u; the landscape
    of a non-Gaussian error can have several local minima); then a pattern search on the sphere
    from each of the ``local`` best (steps halved from 0.2 rad to 1e-7 rad), keeping the lowest.
    Along a principal direction of a Gaussian this is the paper's component; for other shapes
    the worst direction moves off it.  Returns ``(u (3,), P)``.
    """
    A = np.asarray(A, dtype=float)
    eps = np.asarray(eps, dtype=float)
    sh = _shapes(shapes, A.shape[1])
    var = np.array([s.variance for s in sh])
    V = (A * (eps**2 * var)) @ A.T
    lam, vec = np.linalg.eigh(0.5 * (V + V.T))
    E = vec[:, ::-1]
    cands = [E[:, 0], E[:, 1], E[:, 2]]
    for i in range(3):
        for j in range(i + 1, 3):
            cands += [(E[:, i] + E[:, j]) / math.sqrt(2), (E[:, i] - E[:, j]) / math.sqrt(2)]
    if start is not None:
        s0 = np.asarray(start, dtype=float)
        cands.append(s0 / np.linalg.norm(s0))
    C = np.vstack([np.array(cands), _fibonacci_hemisphere(grid)]) if grid else np.array(cands)
    # screening to 1e-6 (a direction where one error dominates needs ~1/tol terms); rigorous at the end
    P = direction_probability(C @ A * eps, sh, R, max(tol, 1e-6), kmax=1 << 14, return_error=True)[0]

    order = np.argsort(P)
    starts = []
    for j in order:  # the best few, at least 0.1 rad apart (up to sign)
        if all(abs(float(C[j] @ C[k])) < math.cos(0.1) for k in starts):
            starts.append(j)
        if len(starts) >= local:
            break
    best_u, best_p = None, math.inf
    for j in starts:
        u, pu = C[j], float(P[j])
        bj = np.abs(np.atleast_2d(u @ A * eps))
        K = 2 * _needed_terms(bj, sh, half_period(bj, sh, R), max(tol, 1e-9), _interval_weight, 1 << 16)[0]
        step = 0.05 if grid else 0.2
        while step > 1e-7:
            h = np.eye(3)[int(np.argmin(np.abs(u)))]
            e1 = np.cross(u, h)
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(u, e1)
            trial = np.array([u + step * e1, u - step * e1, u + step * e2, u - step * e2])
            trial /= np.linalg.norm(trial, axis=1, keepdims=True)
            pt = _series_P(trial @ A * eps, sh, R, K)
            k = int(np.argmin(pt))
            if pt[k] < pu:
                u, pu = trial[k], float(pt[k])
            else:
                step *= 0.5
        pu = direction_probability(u @ A * eps, sh, R, tol)  # rigorous at the end
        if pu < best_p:
            best_u, best_p = u, pu
    return best_u, best_p


def _hemisphere(nodes: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(nodes)
    z, wz = 0.5 * (x + 1.0), 0.5 * w
    phi = 2 * math.pi * np.arange(2 * nodes) / (2 * nodes)
    s = np.sqrt(1.0 - z**2)
    dirs = np.stack([np.outer(s, np.cos(phi)).ravel(), np.outer(s, np.sin(phi)).ravel(), np.repeat(z, 2 * nodes)], axis=1)
    return dirs, np.repeat(wz, 2 * nodes) / (2 * nodes)


def _ball_weight(R):
    def weight(k, L):
        return 2.0 / (np.pi * k) * (1.0 + np.pi * k * R / L)
    return weight


def _ball_level(A, eps, sh, R, nodes, tol, kmax):
    dirs, w = _hemisphere(nodes)
    b = np.abs(dirs @ A * eps)
    L = half_period(b, sh, R)
    K, bound = _needed_terms(b, sh, L, tol, _ball_weight(R), kmax)
    k = np.arange(1, K + 1, dtype=float)
    total = 0.0
    chunk = max(1, 4_000_000 // max(1, K * b.shape[1]))
    for a in range(0, b.shape[0], chunk):
        rows = slice(a, a + chunk)
        x = np.pi * k[None, :] * R / L[rows, None]
        coef = 2.0 / (np.pi * k)[None, :] * (np.sin(x) - x * np.cos(x))
        total += float(np.sum(w[rows] * np.sum(coef * series_terms(b[rows], sh, L[rows], K), axis=1)))
    return total, float(np.sum(w * bound))


def _matrix_inputs(M, eps, shapes, rows: int, field: str):
    """``M`` (``rows`` x n) and ``eps`` as float arrays and the n shapes; a typed error naming
    ``field`` for another shape of ``M``."""
    M = np.asarray(M, dtype=float)
    if M.ndim != 2 or M.shape[0] != rows:
        raise OutOfRangeError(field, f"shape {M.shape}", f"{rows} x n rows")
    return M, np.asarray(eps, dtype=float), _shapes(shapes, M.shape[1])


def ball_probability(A, eps, shapes, R: float, tol: float = 1e-7, max_nodes: int = 128,
                     kmax: int = KMAX, return_error: bool = False):
    """Exact ``P(|dr| <= R)`` for ``dr = A diag(eps) Y`` in 3-D (``A`` 3 x n, mm per tolerance unit):
    Eq. 5 without the Gaussian approximation (see the module docstring).

    The hemisphere quadrature doubles its nodes from 16 until two levels agree to ``tol``; the
    error estimate is that change plus the series' tail bound.  Raises
    :class:`ExactProbabilityError` if ``max_nodes`` or ``kmax`` cannot meet ``tol``.
    """
    R = check_positive(R, "R")
    A, eps, sh = _matrix_inputs(A, eps, shapes, 3, "A")
    prev, nodes = None, 16
    while True:
        val, tail = _ball_level(A, eps, sh, R, nodes, 0.1 * tol, kmax)
        if prev is not None:
            change = abs(val - prev)
            err = change + tail
            if err <= tol or nodes >= max_nodes:
                if err > tol and not return_error:
                    raise ExactProbabilityError(
                        f"exact sphere probability: error estimate {err:.1e} > tol {tol:g} with {nodes} nodes")
                P = min(max(val, 0.0), 1.0)
                return (P, err) if return_error else P
        prev, nodes = val, 2 * nodes


def _j1(x: np.ndarray) -> np.ndarray:
    """Bessel J_1 (SciPy's when installed; else ``(1/pi) int_0^pi cos(t - x sin t) dt`` by the
    trapezoid rule, exponentially accurate for a periodic analytic integrand with > x + 40 nodes)."""
    try:
        from scipy.special import j1
    except ImportError:  # pragma: no cover - exercised where SciPy is absent
        x = np.asarray(x, dtype=float)
        nodes = int(np.max(x, initial=0.0)) + 48
        t = (np.arange(nodes) + 0.5) * np.pi / nodes
        return np.mean(np.cos(t[None, :] - x.reshape(-1, 1) * np.sin(t)[None, :]), axis=1).reshape(x.shape)
    return j1(x)


def cone_probability(C, eps, shapes, Phi: float, tol: float = 1e-7, max_nodes: int = 256,
                     return_error: bool = False):
    """Exact ``P(|t| <= Phi)`` for the 2-D vector ``t = C diag(eps) Y`` (``C`` 2 x n, rad per
    tolerance unit: the rotation components perpendicular to the hand axis): Eq. 8 without the
    Gaussian approximation, by the polar inversion of the module docstring.  Default tolerance
    1e-7 (the Bessel kernel decays only like rho^-1/2, so the radial integral is long)."""
    Phi = check_positive(Phi, "Phi", "rad")
    C, eps, sh = _matrix_inputs(C, eps, shapes, 2, "C")
    prev, nt = None, 16
    while True:
        theta = (np.arange(nt) + 0.5) * np.pi / nt  # midpoint rule on a periodic integrand
        dirs = np.stack([np.cos(theta), np.sin(theta)], axis=1)
        b = np.abs(dirs @ C * eps)  # (nt, n)
        # radius where the tail int_T^inf env(rho) Phi sqrt(2/(pi Phi rho)) d rho < tol/10
        sig = np.sqrt(np.sum((b**2) * np.array([s.variance for s in sh]), axis=1)) + 1e-300
        T = 8.0 / sig.min()
        while True:
            grid = T * 1.25 ** np.arange(200)
            env = _envelope(b, sh, grid[None, :] * np.ones((b.shape[0], 1)))
            g = env * Phi * np.sqrt(2.0 / (np.pi * Phi * grid[None, :]))
            tail = np.sum(g[:, :-1] * np.diff(grid)[None, :], axis=1) + g[:, -1] * grid[-1] * 2.0
            if np.all(tail <= 0.1 * tol) or T > 1e9 / Phi:
                break
            T *= 2.0
        # Gauss-Legendre panels of width ~ pi / max(Phi, max b) on [0, T]
        width = np.pi / max(Phi, float(b.max(initial=0.0)), 1e-300)
        panels = int(min(200_000, math.ceil(T / width)))
        x, wq = np.polynomial.legendre.leggauss(16)
        edges = np.linspace(0.0, T, panels + 1)
        rho = (0.5 * (edges[:-1, None] + edges[1:, None]) + 0.5 * np.diff(edges)[:, None] * x[None, :]).ravel()
        wr = (0.5 * np.diff(edges)[:, None] * wq[None, :]).ravel()
        kern = Phi * _j1(Phi * rho) * wr
        vals = np.empty(nt)
        for j in range(nt):
            f = np.ones_like(rho)
            for i, s in enumerate(sh):
                if b[j, i] > 0:
                    f = f * s.cf(rho * b[j, i])
            vals[j] = float(np.sum(f * kern))
        val = float(np.mean(vals))
        if prev is not None:
            err = abs(val - prev) + float(np.max(tail))
            if err <= tol or nt >= max_nodes:
                if err > tol and not return_error:
                    raise ExactProbabilityError(f"exact cone probability: error estimate {err:.1e} > tol {tol:g}")
                P = min(max(val, 0.0), 1.0)
                return (P, err) if return_error else P
        prev, nt = val, 2 * nt
