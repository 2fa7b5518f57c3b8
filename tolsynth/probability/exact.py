"""Exact probabilities of the linear error model, with no Gaussian approximation.

The hand error is linear in the errors, ``dr = sum_i a_i eps_i Y_i`` (``a_i`` the sensitivity
column of parameter i, ``Y_i`` independent with the shapes of :mod:`tolsynth.probability.distributions`).
Every probability here comes with a bound on its error, and nothing is sampled.

**Along a direction** (``w = u . dr = sum_i b_i Y_i``, ``b_i = (u . a_i) eps_i``), each row of
coefficients is evaluated on its own by the cheapest method that meets the tolerance
(:mod:`.exact_rows`): closed forms (one term, only normal terms, a bounded sum that cannot reach
R); the vertex formula, an exact piecewise polynomial for a few uniform and triangular terms plus
a normal part or one truncated normal (:mod:`.exact_poly`), in exact rational arithmetic where
floating point would cancel (:mod:`.exact_rest`), also with a small rest of other terms through
their moments; the Fourier series of the periodised density with the least number of terms whose
rigorous tail bound meets the tolerance (:mod:`.exact_series`); a truncated normal written as a
mixture of a uniform and a continuous cap where its jumps make the series slow
(:mod:`.exact_parts`).  Terms too small to matter are dropped first, with a rigorous bound on
their effect.  So a dominant term, coefficients near zero, thousands of terms and p from 0.5 to
1 - 1e-6 meet the tolerance, and a row's value is a function of that row, R and the tolerance:
not of the other rows of a batch (beyond the last bits of NumPy's summation order), nor of
anything that ran before in the process (nothing is remembered between calls but constants and
the truncated normal's table, whose entries are the same whenever they are computed).

Limits: where no method reaches the tolerance within its term limits (in practice a sphere
kernel, or a row with several truncated normals of very different sizes among which a dominant
one meets R at its edge), the series' bound is reported as it is (``direction_probability``
raises :class:`ExactProbabilityError`, the batch and ``return_error`` report the bound); the
bounds of the vertex formula's rounding and of the truncated normal's table are careful
estimates (stated where they are made), the others rigorous.

**The sphere and the cone** (:mod:`.exact_sphere`): ``P(|dr| <= R)`` by the local Radon
inversion in three dimensions, ``P(|dr| <= R) = mean over unit v of [P(|v . dr| <= r) - 2 r g_v(r)]``
at ``r = R`` (``g_v`` the density of ``v . dr``), each direction's kernel from the same per-row
methods; for an error in a plane (a planar arm; the cone of the orientation, Eq. 8) the same
formula in the plane's polar form, ``(1/pi) int dphi int Q_phi(R cosh t) sech^2 t dt``, split at
the break points of each direction's distribution.

References: Gil-Pelaez (1951) for the inversion of a characteristic function; Abate & Whitt (1992)
"The Fourier-series method for inverting transforms of probability distributions" for the
periodisation argument; the vertex formula is the distribution of a sum of uniforms as a divided
difference (the box spline; e.g. Olds 1952 for unequal widths).
"""

from __future__ import annotations

import math

import numpy as np

from tolsynth.checks import check_positive
from tolsynth.errors import OutOfRangeError
from tolsynth.probability.distributions import Shape, shape
from tolsynth.probability.exact_inputs import (
    DEFAULT_TOL,
    ExactProbabilityError,
    check_count,
    check_matrix,
    check_rows,
    check_shapes,
    check_tol,
)
from tolsynth.probability.exact_parts import part_of
from tolsynth.probability.exact_rows import evaluate
from tolsynth.probability.exact_series import KMAX, NORMAL_REACH
from tolsynth.probability.exact_series import half_period as _half_period
from tolsynth.probability.exact_sphere import _hemisphere, ball_probability, cone_probability  # noqa: F401
from tolsynth.progress import check_deadline

__all__ = [
    "ExactProbabilityError",
    "direction_probability",
    "direction_probability_batch",
    "components_probability",
    "worst_direction",
    "ball_probability",
    "cone_probability",
    "series_terms",
    "half_period",
    "DEFAULT_TOL",
    "KMAX",
    "NORMAL_REACH",
]


def half_period(b: np.ndarray, shapes, R) -> np.ndarray:
    """``L = R + (B + 8.5 sigma_normal) / 2`` per row of coefficients ``b`` (M, n)."""
    return _half_period(np.abs(np.atleast_2d(b)), tuple(shape(s) for s in shapes), R)


def series_terms(b: np.ndarray, shapes: tuple[Shape, ...], L: np.ndarray, K: int, lib=np) -> np.ndarray:
    """``prod_i phi_i(k pi b_i / L)`` for k = 1..K per row (M, K) (NumPy)."""
    b = np.abs(np.atleast_2d(b))
    k = np.arange(1, K + 1, dtype=float)
    out = np.ones((b.shape[0], K))
    for i, s in enumerate(shapes):
        bi = b[:, i : i + 1]
        if np.all(bi == 0):
            continue
        out *= shape(s).cf(np.pi * k[None, :] * bi / np.asarray(L)[:, None])
    return out


def direction_probability_batch(B, shapes, R, tol: float = DEFAULT_TOL, kmax: int = KMAX, return_method: bool = False):
    """``P(|sum_i B[j, i] Y_i| <= R_j)`` for every row j of ``B`` (m, n) (mm), ``Y_i`` of the given
    shapes (one per column), and a rigorous bound on each error.

    ``R``: a number or one per row (mm).  Returns ``(P (m,), err (m,))`` (and the method of each
    row with ``return_method``: "none", "one", "normal", "inside", "vertex", "vertex-exact",
    "vertex-rest", "series", "split", "series-long").  Never raises for a bound above ``tol``: the
    caller reads ``err``, which exceeds ``tol`` only in the limits of the module docstring.  Each
    row's value depends on that row, its R and ``tol`` alone.

    Examples
    --------
    >>> from tolsynth import direction_probability_batch
    >>> P, err = direction_probability_batch([[1.0, 0.5], [1.0, 1.0]], ["uniform"] * 2, 0.8)
    >>> [round(float(x), 12) for x in P]  # trapezoid 1 - 0.7^2 / 2; triangle 1 - 1.2^2 / 4
    [0.755, 0.64]
    """
    b, _ = check_rows(B, "B")
    sh = check_shapes(shapes, b.shape[1])
    Rv = np.asarray(R, dtype=float)
    if Rv.ndim == 0:
        Rv = np.full(b.shape[0], check_positive(float(Rv), "R"))
    elif Rv.shape != (b.shape[0],) or not np.all(np.isfinite(Rv)) or np.any(Rv <= 0):
        raise OutOfRangeError("R", f"shape {Rv.shape} or a value <= 0", f"a number > 0 or {b.shape[0]} of them")
    P, err, method = evaluate(
        b, tuple(part_of(s) for s in sh), Rv, check_tol(tol), False, check_count(kmax, "kmax", 16)
    )
    P = np.clip(P, 0.0, 1.0)
    return (P, err, method) if return_method else (P, err)


def direction_probability(b, shapes, R: float, tol: float = DEFAULT_TOL, kmax: int = KMAX, return_error: bool = False):
    """``P(|sum_i b_i Y_i| <= R)`` for rows of coefficients ``b`` (mm; shape (n,) or (M, n)),
    ``Y_i`` of the given shapes (one per column), exactly (see the module docstring).

    Returns the probabilities (scalar for one row) and, with ``return_error``, the rigorous bound
    on the error.  Raises :class:`ExactProbabilityError` if a bound exceeds ``tol`` (unless
    ``return_error``, which then reports the larger bound).

    Examples
    --------
    >>> from tolsynth import direction_probability
    >>> round(direction_probability([1.0, 1e-9], ["uniform"] * 2, 0.3), 12)  # a dominant term
    0.3
    """
    R = check_positive(R, "R")
    b, one = check_rows(b)
    P, bound = direction_probability_batch(b, shapes, R, tol, kmax)
    if not return_error and np.any(bound > tol):
        raise ExactProbabilityError(
            f"exact probability: the error bound {bound.max():.2e} exceeds tol {tol:g} within {kmax} series terms"
        )
    if one:
        return (float(P[0]), float(bound[0])) if return_error else float(P[0])
    return (P, bound) if return_error else P


def components_probability(A, eps, shapes, R: float, tol: float = DEFAULT_TOL):
    """Exact ``P(|w_j| <= R)`` along the three principal directions of the covariance of
    ``dr = A diag(eps) Y`` (``A`` 3 x n, mm per tolerance unit): the paper's Eq. 6-7 without the
    Gaussian approximation.  Returns ``(P (3,), directions (3, 3) columns)`` descending in sigma."""
    A, eps, sh = check_matrix(A, eps, shapes, 3, "A")
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


def _frames(U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to each row of U (and to each other)."""
    h = np.eye(3)[np.argmin(np.abs(U), axis=1)]
    e1 = np.cross(U, h)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(U, e1)


def worst_direction(A, eps, shapes, R: float, tol: float = DEFAULT_TOL, start=None, grid: int = 400, local: int = 3):
    """The unit direction u of smallest exact ``P(|u^T dr| <= R)`` (and that probability).

    Candidates: the principal directions, the bisectors of each pair, ``start`` (if given) and a
    Fibonacci lattice of ``grid`` directions on the hemisphere (``P`` is even in u; the landscape
    of a non-Gaussian error can have several local minima); then a pattern search on the sphere
    from each of the ``local`` best (steps halved from 0.05 rad, 0.2 without a lattice, to 1e-6
    rad; all starts advance together, each step one batch), keeping the lowest.  Every value is
    the evaluator's (to ``max(tol, 1e-9)`` in the search, to ``tol`` at the end), so the answer
    depends on the inputs alone.  Returns ``(u (3,), P)``.
    """
    R = check_positive(R, "R")
    A, eps, sh = check_matrix(A, eps, shapes, 3, "A")
    tol = check_tol(tol)
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
        if s0.shape != (3,) or not np.all(np.isfinite(s0)) or not np.linalg.norm(s0) > 0:
            raise OutOfRangeError("start", f"{start!r}", "a non-zero 3-vector")
        cands.append(s0 / np.linalg.norm(s0))
    C = np.vstack([np.array(cands), _fibonacci_hemisphere(int(grid))]) if grid else np.array(cands)
    search_tol = max(tol, 1e-9)
    parts = tuple(part_of(s) for s in sh)
    M = A * eps

    def probs(U):
        return evaluate(np.abs(U @ M), parts, R, search_tol)[0]

    P = probs(C)
    order = np.argsort(P, kind="stable")
    starts = []
    for j in order:  # the best few, at least 0.1 rad apart (up to sign)
        if all(abs(float(C[j] @ C[k])) < math.cos(0.1) for k in starts):
            starts.append(j)
        if len(starts) >= local:
            break
    U = C[starts].copy()
    PU = P[starts].copy()
    step = np.full(len(starts), 0.05 if grid else 0.2)
    while np.any(step > 1e-6):
        check_deadline("the worst direction")
        act = np.flatnonzero(step > 1e-6)
        e1, e2 = _frames(U[act])
        h = step[act, None]
        T = np.stack([U[act] + h * e1, U[act] - h * e1, U[act] + h * e2, U[act] - h * e2], axis=1)
        T /= np.linalg.norm(T, axis=2, keepdims=True)
        PT = probs(T.reshape(-1, 3)).reshape(-1, 4)
        k = np.argmin(PT, axis=1)
        best = PT[np.arange(act.size), k]
        better = best < PU[act]
        U[act[better]] = T[np.flatnonzero(better), k[better]]
        PU[act[better]] = best[better]
        step[act[~better]] *= 0.5
    Pf = direction_probability(U @ M, sh, R, tol)  # to the asked tolerance at the end
    j = int(np.argmin(Pf))
    return U[j], float(Pf[j])
