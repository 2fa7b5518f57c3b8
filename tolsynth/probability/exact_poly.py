"""Sums of a few uniform errors plus one smooth part by the vertex formula: exact piecewise
polynomials in floating point, one method of :mod:`tolsynth.probability.exact` (the exact-arithmetic
variants are in :mod:`.exact_rest`).

For ``w = sum_{i<=m} a_i U_i + V`` (``U_i`` uniform on [-1, 1], a triangular error of half-width
``b`` being two uniforms of half-width ``b/2``; ``V`` nothing, a normal part ``sigma Z``, or one
truncated normal or cap ``b T``), the distribution function is the m-th divided difference of
``G_m(y) = E (y + V)_+^m / m!`` over the vertices ``c_s = sum_i s_i a_i``, ``s`` in ``{-1, 1}^m``:

    P(w <= x) = sum_s (prod_i s_i) G_m(x + c_s) / prod_i (2 a_i),

so ``P(|w| <= R) = F(R) - F(-R)`` and the density ``f(R)`` (for the sphere's kernel
``P - 2 R f(R)``) is the same sum with ``G_(m-1)``.  Without V, ``G_m(y) = y_+^m / m!`` (the
B-spline of the box).  With a normal part, ``E (y + sigma Z)_+^m = sum_j C(m, j) y^(m-j) sigma^j
M_j(-y/sigma)`` with the partial moments ``M_j(c) = E[Z^j; Z > c]``: ``M_0 = erfc(c/sqrt 2)/2``,
``M_1 = phi(c)``, ``M_j = c^(j-1) phi(c) + (j-1) M_(j-2)``.  With a truncated normal ``b T``
(``sigma = 1/beta`` truncated at +-1), ``E (y + bT)_+^m = sum_j C(m, j) y^(m-j) (b/beta)^j
(M_j(beta t0) - M_j(beta)) / erf(beta/sqrt 2)``, ``t0 = clip(-y/b, -1, 1)``; its cap is
``(truncated normal - w uniform) / (1 - w)``, the uniform's term in closed form.  No truncation:
the only error is rounding.  The sum over the ``2^m`` vertices cancels badly when the half-widths
differ by orders of magnitude (a dominant error with a small one); the bound says so, and
:mod:`.exact_rest` then computes in exact arithmetic.

**Rounding bound**: ``eps / (m! prod 2a) * sum_s [(2m + 8) A_m(y_s) + m (m + 2) reach A_(m-1)(y_s)]``
over both ends (``reach = R + sum a`` plus the smooth part's), ``A_j`` the sum of the moduli of the
terms of ``G_j``: each term carries at most ``2m + 8`` relative rounding errors (powers, products,
erfc), and each vertex ``y_s`` an absolute error of ``(m + 2) eps reach``, which moves ``G_m`` by at
most its slope ``m G_(m-1)`` times that.
"""

from __future__ import annotations

import math

import numpy as np

from tolsynth.probability.stats import _special

__all__ = ["M_POLY", "Smooth", "vertex_float"]

#: at most this many uniforms (a triangular error counts two): 2^m vertices
M_POLY = 12
_EPS = np.finfo(float).eps


def _signs(m: int) -> tuple[np.ndarray, np.ndarray]:
    S = np.array([[1.0 if (v >> i) & 1 == 0 else -1.0 for i in range(m)] for v in range(1 << m)]).reshape(1 << m, m)
    return S, np.prod(S, axis=1) if m else np.ones(1)


def _moments_above(c: np.ndarray, j: int) -> list:
    """``M_q(c) = E[Z^q; Z > c]`` for q = 0..j (Z standard normal)."""
    phi = np.exp(-0.5 * c * c) / math.sqrt(2.0 * math.pi)
    out = [0.5 * _special("erfc", c / math.sqrt(2.0)), phi]
    for q in range(2, j + 1):
        out.append(c ** (q - 1) * phi + (q - 1) * out[q - 2])
    return out[: j + 1]


class Smooth:
    """The one non-polynomial part of a vertex row: none, a normal part (``scale`` = sigma), or one
    truncated normal or its cap (``scale`` = its coefficient b, ``beta``, ``w``); ``scale`` (M,)."""

    def __init__(self, kind: str, scale=None, beta: float = 0.0, w: float = 0.0):
        self.kind, self.beta, self.w = kind, beta, w
        self.scale = None if scale is None else np.asarray(scale, dtype=float)

    def reach(self) -> np.ndarray:
        return 12.0 * self.scale if self.kind == "normal" else (self.scale if self.kind != "none" else 0.0)

    def rows(self, idx) -> "Smooth":
        return Smooth(self.kind, None if self.scale is None else self.scale[idx], self.beta, self.w)


def _G(y: np.ndarray, sm: Smooth, j: int) -> tuple[np.ndarray, np.ndarray]:
    """``E (y + V)_+^j`` for the smooth part V (none: ``y_+^j``) and the sum of its terms' moduli;
    y (M, V), the scales broadcast per row."""
    if j < 0:
        return np.zeros_like(y), np.zeros_like(y)
    if sm.kind == "none":
        v = np.maximum(y, 0.0) ** j if j else (y > 0).astype(float)
        return v, v
    sc = sm.scale[:, None]
    val = np.zeros_like(y)
    ab = np.zeros_like(y)
    if sm.kind == "normal":
        Mq = _moments_above(-y / sc, j)
        for q in range(j + 1):
            t = math.comb(j, q) * y ** (j - q) * sc**q * Mq[q]
            val += t
            ab += np.abs(t)
        return val, ab
    # a truncated normal b T on [-b, b]: z = beta t between beta t0 and beta, t0 = clip(-y/b, -1, 1)
    beta = sm.beta
    Z = math.erf(beta / math.sqrt(2.0))
    lo = beta * np.clip(-y / sc, -1.0, 1.0)
    Mlo = _moments_above(lo, j)
    Mhi = _moments_above(np.array(beta), j)
    for q in range(j + 1):
        t = math.comb(j, q) * y ** (j - q) * (sc / beta) ** q * (Mlo[q] - Mhi[q]) / Z
        val += t
        ab += np.abs(t)
    if sm.kind == "tn":
        return val, ab
    # the cap: (truncated normal - w uniform) / (1 - w); the uniform's E (y + bU)_+^j in closed form
    u = (np.maximum(y + sc, 0.0) ** (j + 1) - np.maximum(y - sc, 0.0) ** (j + 1)) / (2.0 * sc * (j + 1))
    ua = (np.maximum(y + sc, 0.0) ** (j + 1) + np.maximum(y - sc, 0.0) ** (j + 1)) / (2.0 * sc * (j + 1))
    return (val - sm.w * u) / (1.0 - sm.w), (ab + sm.w * ua) / (1.0 - sm.w)


def vertex_float(a: np.ndarray, sm: Smooth, R: np.ndarray, kernel: bool = False):
    """Rows of half-widths ``a`` (M, m) with a smooth part ``sm``: ``(P, errP, Q, errQ)`` with
    ``Q = P - 2 R f(R)`` (``None`` unless ``kernel``); the errors are the rounding bounds."""
    M, m = a.shape
    S, sg = _signs(m)
    c = a @ S.T  # (M, V)
    reach = R + a.sum(axis=1) + sm.reach()
    N = math.factorial(m) * np.prod(2.0 * a, axis=1)
    yR = R[:, None] + c
    yL = -R[:, None] + c
    GR, AR = _G(yR, sm, m)
    GL, AL = _G(yL, sm, m)
    GR1, AR1 = _G(yR, sm, m - 1)
    _, AL1 = _G(yL, sm, m - 1)
    P = (GR - GL) @ sg / N
    errP = (
        _EPS / N * (np.sum((2 * m + 8) * (AR + AL), axis=1) + m * (m + 2) * reach * np.sum(AR1 + AL1, axis=1))
        + 4 * _EPS
    )
    if not kernel:
        return P, errP, None, None
    Nd = N / m
    g = GR1 @ sg / Nd
    _, AR2 = _G(yR, sm, m - 2)
    errg = _EPS / Nd * (np.sum((2 * m + 8) * AR1, axis=1) + max(m - 1, 0) * (m + 2) * reach * np.sum(AR2, axis=1))
    return P, errP, P - 2.0 * R * g, errP + 2.0 * R * errg


def _ints(values) -> tuple[list[int], int]:
    """Floats as integers over one common power-of-two denominator."""
    ratios = [float(v).as_integer_ratio() for v in values]
    den = max(d for _, d in ratios)
    return [n * (den // d) for n, d in ratios], den
