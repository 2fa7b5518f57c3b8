"""Exact probabilities in the sphere and in a disk (the cone of the orientation), for
:mod:`tolsynth.probability.exact`.

**The sphere** ``P(|dr| <= R)`` for ``dr = M Y`` in 3-D (``M = A diag(eps)``).  The Radon inversion
in three dimensions is local: with ``g_v`` the density of ``v . dr``,
``P(|dr| <= R) = mean over unit v of Q_v(R)``, ``Q_v(r) = P(|v . dr| <= r) - 2 r g_v(r)`` (by
``f = -(1/8 pi^2) Laplacian int g_v(v . x) dv`` integrated over the ball; for a standard normal it
gives the chi CDF ``erf(R/sqrt2) - sqrt(2/pi) R e^{-R^2/2}``).  Each ``Q_v`` comes from the per-row
methods (:mod:`.exact_rows`); the mean over the hemisphere is Gauss-Legendre in ``v_z`` times the
midpoint rule in the azimuth, doubled until two levels agree to the tolerance.  The rule converges
algebraically where the integrand is only piecewise smooth in v.

**A planar error** (``M`` of rank 2, e.g. a planar arm, whose ``z`` row is zero; and the disk of
the cone).  Along ``v = (sin(theta) e_phi, cos(theta))`` every coefficient scales with
``sin(theta)``, so ``Q_v(R) = Q_phi(R / sin(theta))``, and the substitution
``r = R cosh(t) = R / sin(theta)`` gives

    P(|t| <= R) = (1/pi) int_0^pi dphi int_0^inf Q_phi(R cosh t) sech^2(t) dt,

``Q_phi = 1`` beyond the reach of ``e_phi . t``.  The inner integral is split where ``Q_phi`` may
be non-smooth (``R cosh t`` equal to a sum of the largest bounded terms' half-widths with signs:
the smaller ones' kinks are smoothed by the convolution with the rest) and
taken by 12- and 24-node Gauss-Legendre on each piece (their difference is the error estimate);
the azimuth by the midpoint rule, doubled until two levels agree.  A 3-D error within
``delta = sum_i |u_3 . M_i|`` of a plane (``u_3`` its normal) changes the sphere's probability by
at most ``pi delta^2`` times the planar density's maximum, which is at most
``peak_i peak_j / |det(c_i, c_j)|`` for any two of its terms (a convolution never raises it).
"""

from __future__ import annotations

import math

import numpy as np

from tolsynth.checks import check_half_angle, check_positive
from tolsynth.probability.exact_inputs import ExactProbabilityError, check_count, check_matrix, check_tol
from tolsynth.probability.exact_parts import part_of
from tolsynth.probability.exact_rows import evaluate
from tolsynth.probability.exact_series import KMAX
from tolsynth.progress import check_deadline

__all__ = ["ball_probability", "cone_probability", "planar_part", "azimuths", "radial_nodes"]

#: a matrix whose third singular value is below this fraction of the first is treated as planar
PLANAR = 1e-12
#: the azimuths of the planar rule start at this many
AZIMUTHS = 16
#: the radial integral is split at the signed sums of this many largest half-widths: beyond four
#: terms their kinks are smoothed by the convolution with the rest (the planar 3-RRR's 21 terms:
#: the same probability to 1e-14 with one edge as with ten, in 1 s instead of 140 s)
EDGES = 4
_GL = {n: np.polynomial.legendre.leggauss(n) for n in (12, 24)}


def _hemisphere(nodes: int) -> tuple[np.ndarray, np.ndarray]:
    x, w = np.polynomial.legendre.leggauss(nodes)
    z, wz = 0.5 * (x + 1.0), 0.5 * w
    phi = 2 * math.pi * np.arange(2 * nodes) / (2 * nodes)
    s = np.sqrt(1.0 - z**2)
    dirs = np.stack(
        [np.outer(s, np.cos(phi)).ravel(), np.outer(s, np.sin(phi)).ravel(), np.repeat(z, 2 * nodes)], axis=1
    )
    return dirs, np.repeat(wz, 2 * nodes) / (2 * nodes)


def _edges(b: np.ndarray, parts) -> list[float]:
    """The half-widths whose signed sums are the break points of a row's distribution."""
    out = []
    for x, p in zip(b, parts):
        if x > 0 and p.bounded:
            out += [0.5 * x, 0.5 * x] if p.kind == "triangular" else [x]
    return sorted(out, reverse=True)[:EDGES]


def _breaks(b, parts, R, reach) -> np.ndarray:
    """The t in (0, acosh(reach/R)) where ``Q(R cosh t)`` may be non-smooth, and that end."""
    e = _edges(b, parts)
    T = math.acosh(reach / R) if reach > R else 0.0
    if not e or T == 0.0:
        return np.array([0.0, T])
    sums = np.array([0.0])
    for x in e:
        sums = np.concatenate([sums + x, sums - x])
    r = np.unique(np.abs(sums))
    r = r[(r > R) & (r < reach)]
    return np.unique(np.concatenate([[0.0], np.arccosh(r / R), [T]]))


def azimuths(naz: int) -> np.ndarray:
    """The planar rule's ``naz`` unit directions in the plane (the midpoint rule on [0, pi)), (naz, 2)."""
    phi = (np.arange(naz) + 0.5) * math.pi / naz
    return np.column_stack([np.cos(phi), np.sin(phi)])


def radial_nodes(B, parts, R, nodes: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The radial rule of each azimuth row of ``B`` (naz, n): ``nodes``-point Gauss-Legendre on
    each piece of ``t`` between the break points.  Returns ``(row, radius R cosh t, weight)`` with
    the weights of ``sech^2 t dt`` divided by naz, so that ``P = 1 - sum w (1 - Q_row(radius))``
    (``Q = 1`` beyond the last node)."""
    naz = B.shape[0]
    bounded = np.array([p.bounded for p in parts])
    sig = np.sqrt(np.sum((B[:, ~bounded] / 3.0) ** 2, axis=1)) if (~bounded).any() else np.zeros(naz)
    reach = B[:, bounded].sum(axis=1) + 12.0 * sig
    x, w = _GL[nodes]
    rows, radii, weights = [], [], []
    for j in range(naz):
        t = _breaks(B[j], parts, R, reach[j])
        a, h = t[:-1], np.diff(t)
        a, h = a[h > 0], h[h > 0]  # an azimuth that cannot leave the disk adds nothing
        tt = (a[:, None] + 0.5 * h[:, None] * (x[None, :] + 1.0)).ravel()
        weights.append((0.5 * h[:, None] * w[None, :]).ravel() / np.cosh(tt) ** 2 / naz)
        radii.append(R * np.cosh(tt))
        rows.append(np.repeat(j, tt.size))
    return np.concatenate(rows), np.concatenate(radii), np.concatenate(weights)


def _disk_level(C, parts, R, naz, tol):
    """One level of the planar rule with ``naz`` azimuths: (value, error estimate)."""
    B = np.abs(azimuths(naz) @ C)  # (naz, n)
    lo, hi = radial_nodes(B, parts, R, 12), radial_nodes(B, parts, R, 24)
    idx, radii = np.concatenate([lo[0], hi[0]]), np.concatenate([lo[1], hi[1]])
    Q, e, _ = evaluate(B[idx], parts, radii, 0.05 * tol, True)
    m = lo[0].size
    deficit_lo = np.bincount(lo[0], lo[2] * (1.0 - Q[:m]), naz)
    deficit_hi = np.bincount(hi[0], hi[2] * (1.0 - Q[m:]), naz)
    rounding = np.bincount(hi[0], hi[2] * e[m:], naz)
    tails = 1e-30  # Q = 1 - (a normal tail beyond 12 sigma) past the reach
    return 1.0 - float(deficit_hi.sum()), float(np.sum(np.abs(deficit_hi - deficit_lo) + rounding)) + tails


def _disk(C, parts, R, tol, max_az):
    """``P(|C Y| <= R)`` for 2-D coefficients C (2, n): (value, error estimate) (module docstring)."""
    prev, naz = None, AZIMUTHS
    while True:
        check_deadline("the exact probability in a disk")
        val, inner = _disk_level(C, parts, R, naz, tol)
        if prev is not None:
            err = abs(val - prev) + inner
            if err <= tol or 2 * naz > max_az:
                return min(max(val, 0.0), 1.0), err
        prev, naz = val, 2 * naz


def planar_part(M, parts, tol: float):
    """``(C (2, n), U (3, 2), extra)`` when M (3, n) lies within ``PLANAR`` of a plane (columns of
    U) and the sphere's probability of ``C Y = U^T M Y`` is within ``extra <= 0.1 tol`` of that of
    ``M Y`` (module docstring), else None."""
    U, s, _ = np.linalg.svd(M, full_matrices=True)
    if s[0] == 0.0 or s[2] > PLANAR * s[0]:
        return None
    C, delta = U[:, :2].T @ M, float(np.sum(np.abs(U[:, 2] @ M)))
    extra = math.pi * delta**2 * _planar_density_bound(C, parts) if delta > 0 else 0.0
    return (C, U[:, :2], extra) if extra <= 0.1 * tol else None


def _planar_density_bound(C, parts) -> float:
    """The planar density's maximum is at most ``peak_i peak_j / |det(c_i, c_j)|`` for any pair."""
    best = math.inf
    n = C.shape[1]
    for i in range(n):
        for j in range(i + 1, n):
            det = abs(C[0, i] * C[1, j] - C[1, i] * C[0, j])
            if det > 0:
                best = min(best, parts[i].peak * parts[j].peak / det)
    return best


def ball_probability(
    A, eps, shapes, R: float, tol: float = 1e-7, max_nodes: int = 128, kmax: int = KMAX, return_error: bool = False
):
    """Exact ``P(|dr| <= R)`` for ``dr = A diag(eps) Y`` in 3-D (``A`` 3 x n, mm per tolerance unit):
    Eq. 5 without the Gaussian approximation (see the module docstring).

    The hemisphere quadrature doubles its nodes from 16 (the planar rule its azimuths, up to
    ``2 max_nodes``) until two levels agree to ``tol``; the error estimate is that change plus the
    per-direction error bounds.  Raises :class:`ExactProbabilityError` if ``max_nodes`` cannot meet
    ``tol`` (unless ``return_error``).
    """
    R = check_positive(R, "R")
    A, eps, sh = check_matrix(A, eps, shapes, 3, "A")
    tol = check_tol(tol)
    kmax = check_count(kmax, "kmax", 16)
    max_nodes = check_count(max_nodes, "max_nodes", 16)
    parts = tuple(part_of(s) for s in sh)
    M = A * eps
    plane = planar_part(M, parts, tol)
    if plane is not None:
        C, _, extra = plane
        P, err = _disk(C, parts, R, tol - extra, 2 * max_nodes)
        return _result(P, err + extra, tol, return_error, "sphere")
    prev, nodes = None, 16
    while True:
        check_deadline("the exact probability in the sphere")
        dirs, w = _hemisphere(nodes)
        Q, e, _ = evaluate(np.abs(dirs @ M), parts, R, 0.1 * tol, True, kmax)
        val, tail = float(np.sum(w * Q)), float(np.sum(w * e))
        if prev is not None:
            err = abs(val - prev) + tail
            if err <= tol or 2 * nodes > max_nodes:
                return _result(min(max(val, 0.0), 1.0), err, tol, return_error, "sphere")
        prev, nodes = val, 2 * nodes


def _result(P, err, tol, return_error, what):
    if err > tol and not return_error:
        raise ExactProbabilityError(f"exact {what} probability: error estimate {err:.1e} > tol {tol:g}")
    return (P, err) if return_error else P


def cone_probability(C, eps, shapes, Phi: float, tol: float = 1e-7, max_nodes: int = 256, return_error: bool = False):
    """Exact ``P(|t| <= Phi)`` for the 2-D vector ``t = C diag(eps) Y`` (``C`` 2 x n, rad per
    tolerance unit: the rotation components perpendicular to the hand axis): Eq. 8 without the
    Gaussian approximation, by the planar rule of the module docstring (up to ``max_nodes``
    azimuths).  Raises :class:`ExactProbabilityError` if the estimate exceeds ``tol`` (unless
    ``return_error``)."""
    Phi = check_half_angle(Phi)
    C, eps, sh = check_matrix(C, eps, shapes, 2, "C")
    tol = check_tol(tol)
    max_nodes = check_count(max_nodes, "max_nodes", 16)
    parts = tuple(part_of(s) for s in sh)
    P, err = _disk(C * eps, parts, Phi, tol, max_nodes)
    return _result(P, err, tol, return_error, "cone")
