"""The truncated normal's characteristic function and its two scaled derivatives, fast.

The exact probabilities evaluate ``phi(s) = E cos(sY)`` of every error shape at thousands of
arguments per row, and the exact solver also needs ``D1 = s phi'(s)`` and ``D2 = s dD1/ds``.  For
the uniform, normal and triangular shapes these are closed forms; the truncated normal's
(:func:`tolsynth.probability.distributions._cf_truncnormal`) is an integral taken by a 48-node rule,
and evaluating that rule (and its derivatives by automatic differentiation) took most of an exact
solve with mixed shapes.  This module evaluates the same formula from piecewise Chebyshev
interpolants built once per ``beta`` from that rule, and checks them against it when it builds
them (an interpolant that misses the rule by more than :data:`FIT_TOL` is refined, never used).

With ``x = beta/sqrt2``, ``y = s/(beta sqrt2)`` and ``c = 2 e^{-x^2} / (sqrt(pi) erf x)``,
``phi = e^{-y^2} + c I(y)`` where ``I(y) = int_0^y e^{t^2 - y^2} sin(2xt) dt``.

* ``y <= 5``: ``I`` interpolated in ``y``; its derivatives from the equation it satisfies,
  ``I' = sin(2xy) - 2y I`` (differentiating under the integral), so no interpolant is
  differentiated.
* ``y > 5``: ``I = (v/2) (sin(2xy) C(v) - cos(2xy) S(v))`` with ``v = 1/y`` and
  ``C, S = int_0^50 e^{-sigma + sigma^2 v^2 / 4} (cos, sin)(x sigma v) d sigma`` (the rule's
  boundary-layer form); ``C, S`` and their first two derivatives in ``v`` are smooth on
  ``[0, 1/5]``, each interpolated from its own integral, and the oscillation ``sin(2xy)`` is kept
  exact, so the accuracy does not fall as ``s`` grows.

``L = s d/ds = y d/dy`` acts on ``F(theta, v)`` with ``theta = 2xy`` as ``theta F_theta - v F_v``;
the formulas in :func:`cf3` are that operator applied once and twice.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from tolsynth.probability.distributions import _GL48, _TN_SIGMA, _TN_SPLIT

__all__ = ["cf3", "FIT_TOL"]

#: largest difference allowed between an interpolant and the 48-node rule it replaces (checked
#: at build time on points between the interpolation nodes)
FIT_TOL = 2e-14
# the rule's own switch between its two forms, its boundary-layer cut and its nodes: one copy
_SPLIT, _SIGMA, _GL = _TN_SPLIT, _TN_SIGMA, _GL48


class _Piecewise:
    """Chebyshev interpolants of several functions on equal pieces of ``[a, b]``."""

    def __init__(self, funcs, a: float, b: float, pieces: int, degree: int):
        self.a, self.h, self.pieces, self.degree = a, (b - a) / pieces, pieces, degree
        k = np.arange(degree + 1)
        nodes = np.cos(np.pi * (k + 0.5) / (degree + 1))  # Chebyshev points of the first kind
        lo = a + self.h * np.arange(pieces)[:, None]
        pts = lo + 0.5 * self.h * (nodes[None, :] + 1.0)
        vals = funcs(pts.ravel())  # (m, pieces * (degree + 1))
        vals = vals.reshape(len(vals), pieces, degree + 1)
        # discrete cosine transform at the first-kind points: exact interpolation
        T = np.cos(np.outer(k, np.pi * (k + 0.5) / (degree + 1)))
        coef = 2.0 / (degree + 1) * np.einsum("mpj,kj->mpk", vals, T)
        coef[..., 0] *= 0.5
        self.coef = np.ascontiguousarray(np.moveaxis(coef, 2, 0))  # (degree + 1, m, pieces)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Every function at ``x`` (inside ``[a, b]``): shape ``(m,) + x.shape``."""
        u = (x - self.a) / self.h
        j = np.clip(np.floor(u).astype(np.intp), 0, self.pieces - 1)
        t = 2.0 * (u - j) - 1.0
        c = self.coef[:, :, j]  # every point's piece's coefficients, gathered once
        b1 = np.zeros(c.shape[1:])
        b2 = np.zeros_like(b1)
        t2 = 2.0 * t
        for k in range(self.degree, 0, -1):  # Clenshaw
            b1, b2 = c[k] + t2 * b1 - b2, b1
        return c[0] + t * b1 - b2


def _small_I(y: np.ndarray, x: float) -> np.ndarray:
    """``I(y)`` by the 48-node rule on ``[0, y]`` (the rule of ``_cf_truncnormal`` below the split)."""
    xi, wi = _GL
    t = 0.5 * y[:, None] * (1.0 + xi[None, :])
    return np.sum((0.5 * wi) * y[:, None] * np.exp(t * t - (y * y)[:, None]) * np.sin(2.0 * x * t), axis=1)


def _large_CS(v: np.ndarray, x: float) -> np.ndarray:
    """``C, S`` and their first two derivatives in ``v``, each by the 48-node rule on [0, 50]."""
    xi, wi = _GL
    sg = 0.5 * _SIGMA * (1.0 + xi)[None, :]
    w = 0.5 * _SIGMA * wi[None, :]
    v = v[:, None]
    E = np.exp(-sg + sg * sg * v * v / 4.0)
    Ev = E * sg * sg * v / 2.0
    Evv = E * (sg * sg / 2.0 + sg**4 * v * v / 4.0)
    a = x * sg
    c, s = np.cos(a * v), np.sin(a * v)
    rows = (
        E * c,
        E * s,
        Ev * c - E * a * s,
        Ev * s + E * a * c,
        Evv * c - 2.0 * Ev * a * s - E * a * a * c,
        Evv * s + 2.0 * Ev * a * c - E * a * a * s,
    )
    return np.array([np.sum(w * r, axis=1) for r in rows])


def _fit(funcs, a, b, pieces, degree, scale):
    """An interpolant within FIT_TOL * scale of ``funcs`` at points between its nodes."""
    probe = np.linspace(a, b, 2001)[:-1] + 0.37 * (b - a) / 2000
    want = funcs(probe)
    for deg in (degree, 2 * degree, 4 * degree):
        fit = _Piecewise(funcs, a, b, pieces, deg)
        err = np.max(np.abs(fit(probe) - want) / scale[:, None])
        if err <= FIT_TOL:
            return fit
    raise ArithmeticError(f"truncated-normal interpolant missed its rule by {err:.1e} > {FIT_TOL:g}")


@lru_cache(maxsize=None)
def _tables(beta: float):
    x = beta / math.sqrt(2.0)
    small = _fit(lambda y: _small_I(y, x)[None, :], 0.0, _SPLIT, 80, 10, np.ones(1))
    scale = np.maximum(np.max(np.abs(_large_CS(np.linspace(0.0, 1.0 / _SPLIT, 64), x)), axis=1), 1e-300)
    # C, S; their first and their second derivatives apart: a value needs only the first pair
    large = tuple(
        _fit(lambda v, k=k: _large_CS(v, x)[k : k + 2], 0.0, 1.0 / _SPLIT, 16, 10, scale[k : k + 2]) for k in (0, 2, 4)
    )
    c = 2.0 * math.exp(-x * x) / (math.sqrt(math.pi) * math.erf(x))
    return x, c, small, large


def cf3(s, beta: float, order: int = 0):
    """``phi(s)``, and for ``order >= 1`` ``D1 = s phi'(s)``, for ``order 2`` ``D2 = s dD1/ds``, of the
    normal with ``sigma = 1/beta`` truncated at +-1, for ``s >= 0`` (``None`` for orders not asked)."""
    s = np.abs(np.asarray(s, dtype=float))
    x, c, small, large = _tables(float(beta))
    y = s / (beta * math.sqrt(2.0))
    g = np.exp(-y * y)
    lo = y <= _SPLIT
    I = np.empty_like(y)
    LI = np.empty_like(y) if order >= 1 else None
    LLI = np.empty_like(y) if order >= 2 else None
    if lo.any():
        ys = y[lo]
        Is = small(ys)[0]
        I[lo] = Is
        if order >= 1:
            th = 2.0 * x * ys
            I1 = np.sin(th) - 2.0 * ys * Is
            LI[lo] = ys * I1
            if order >= 2:
                I2 = 2.0 * x * np.cos(th) - 2.0 * Is - 2.0 * ys * I1
                LLI[lo] = ys * I1 + ys * ys * I2
    hi = ~lo
    if hi.any():
        yl = y[hi]
        v = 1.0 / yl
        C, S = large[0](v)
        th = 2.0 * x * yl
        sn, cs = np.sin(th), np.cos(th)
        P = sn * C - cs * S
        I[hi] = 0.5 * v * P
        if order >= 1:
            C1, S1 = large[1](v)
            Pt = cs * C + sn * S  # dP/dtheta
            Pv = sn * C1 - cs * S1
            Q = -P + th * Pt - v * Pv
            LI[hi] = 0.5 * v * Q
            if order >= 2:
                C2, S2 = large[2](v)
                Ptv = cs * C1 + sn * S1
                Pvv = sn * C2 - cs * S2
                LQ = 2.0 * v * Pv - th * th * P - 2.0 * th * v * Ptv + v * v * Pvv
                LLI[hi] = 0.5 * v * (-Q + LQ)
    phi = g + c * I
    if order == 0:
        return phi, None, None
    y2 = y * y
    D1 = -2.0 * y2 * g + c * LI
    if order == 1:
        return phi, D1, None
    return phi, D1, (4.0 * y2 * y2 - 4.0 * y2) * g + c * LLI


@lru_cache(maxsize=None)
def packed(beta: float) -> np.ndarray:
    """The interpolants of :func:`cf3` at ``beta`` as one flat array, for a compiled evaluator of
    the same formulas: ``[beta, x, c, split, offset of each of the 4 interpolants]`` and then each
    interpolant as ``[a, h, pieces, degree, functions, coefficients (degree + 1, functions,
    pieces) in C order]`` (the small-argument ``I``, then ``C, S`` and their first and second
    derivatives)."""
    x, c, small, large = _tables(float(beta))
    blocks, offsets, at = [], [], 8
    for fit in (small,) + tuple(large):
        blk = np.concatenate([[fit.a, fit.h, fit.pieces, fit.degree, fit.coef.shape[1]], fit.coef.ravel()])
        offsets.append(at)
        blocks.append(blk)
        at += blk.size
    out = np.concatenate([[beta, x, c, _SPLIT], offsets, *blocks])
    out.setflags(write=False)
    return out
