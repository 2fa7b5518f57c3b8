"""Closed forms for a direction with a few uniform (or triangular) terms, where the series would
need thousands of terms (the density of a sum of two or three uniforms is only once or twice
differentiable, so its Fourier coefficients decay slowly).

With ``X = sum_j beta_j V_j``, ``V_j`` uniform on [-1, 1] (a triangular error of half-width b is
two uniforms of half-width b/2), the distribution function is the spline

    F(x) = sum_{s in {-1,1}^m} (prod_j s_j) (x + s . beta)_+^m / (m! 2^m prod_j beta_j)

and ``P(|X| <= R) = F(R) - F(-R)``.  In ``v_j = ln beta_j``, with ``A_s = (x + s . beta)_+`` and
``G_j = sum_s sigma_s m A_s^(m-1) s_j beta_j / D`` (``D = m! 2^m prod beta``):
``dF/dv_j = G_j - F`` and ``d2F/dv_i dv_j = Q_ij + delta_ij G_i - G_i - G_j + F`` with
``Q_ij = sum_s sigma_s m (m-1) A_s^(m-2) s_i s_j beta_i beta_j / D``.  The terms cancel: the
rounding bound ``2^m m ulp max|term|`` is returned with the value, and the caller falls back to
the series where it is not small.
"""

from __future__ import annotations

import itertools
import math
from functools import lru_cache

import numpy as np

from tolsynth.solvers import exact_kernel

__all__ = ["closed_rows", "MAX_UNIFORMS"]

#: at most this many uniform pieces (2^m sign patterns)
MAX_UNIFORMS = 5


@lru_cache(maxsize=None)
def _signs(m: int) -> np.ndarray:
    return np.array(list(itertools.product((-1.0, 1.0), repeat=m)))  # (2^m, m)


def _pieces(b: np.ndarray, kinds: tuple) -> tuple[np.ndarray, np.ndarray] | None:
    """The uniform pieces of one row: half-widths and the parameter each belongs to; None if a
    non-zero term is not uniform or triangular, or there are too many pieces."""
    beta, owner = [], []
    for i in np.flatnonzero(b):
        if kinds[i] == "uniform":
            beta.append(b[i])
            owner.append(i)
        elif kinds[i] == "triangular":
            beta += [0.5 * b[i], 0.5 * b[i]]
            owner += [i, i]
        else:
            return None
        if len(beta) > MAX_UNIFORMS:
            return None
    if len(beta) < 2:
        return None
    return np.array(beta), np.array(owner)


def _spline(beta: np.ndarray, x: float, order: int):
    """F(x), its gradient (m,) and Hessian (m, m) in ln beta, and the rounding bound."""
    m = beta.size
    S = _signs(m)
    sigma = np.prod(S, axis=1)
    A = np.maximum(x + S @ beta, 0.0)
    D = math.factorial(m) * 2.0**m * float(np.prod(beta))
    terms = sigma * A**m / D
    F = float(terms.sum())
    rnd = 4.0 * m * 2.0**m * np.finfo(float).eps * float(np.max(np.abs(A**m) / D, initial=0.0))
    if order == 0:
        return F, None, None, rnd
    sb = S * beta[None, :]  # s_j beta_j
    w1 = sigma * m * A ** (m - 1) / D
    G = w1 @ sb
    grad = G - F
    if order == 1:
        return F, grad, None, rnd * m
    w2 = sigma * m * (m - 1) * np.where(A > 0, A ** max(m - 2, 0), 0.0) / D
    Q = (sb * w2[:, None]).T @ sb
    H = Q + np.diag(G) - G[:, None] - G[None, :] + F
    return F, grad, H, rnd * m * m


def closed_rows(b: np.ndarray, shapes: tuple, R, order: int = 0, tol: float = 1e-11):
    """For each row of ``b`` (M, n) that a closed form serves (a few uniform / triangular terms and
    a rounding bound below ``tol``): ``{row: (P, grad in u (n,), Hessian in u (n, n), error)}``."""
    out = exact_kernel.closed(shapes, b, R, order, tol)
    if out is not None:  # the same sums compiled
        return out
    kinds = tuple(s.kind for s in shapes)
    Rv = np.broadcast_to(np.asarray(R, dtype=float), (b.shape[0],))
    out = {}
    n = b.shape[1]
    for r in range(b.shape[0]):
        pc = _pieces(b[r], kinds)
        if pc is None:
            continue
        beta, owner = pc
        a = _spline(beta, Rv[r], order)
        c = _spline(beta, -Rv[r], order)
        err = a[3] + c[3]
        if err > tol:
            continue
        P = a[0] - c[0]
        grad = hess = None
        if order >= 1:  # pieces of one parameter move together: sum their derivatives
            E = np.zeros((n, beta.size))
            E[owner, np.arange(beta.size)] = 1.0
            grad = E @ (a[1] - c[1])
            if order >= 2:
                hess = E @ (a[2] - c[2]) @ E.T
        out[r] = (P, grad, hess, err)
    return out
