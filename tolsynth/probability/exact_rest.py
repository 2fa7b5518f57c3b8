"""The vertex formula in exact arithmetic, and with a small rest: one method of
:mod:`tolsynth.probability.exact` for a dominant term and coefficients near zero.

Split a row into X, the largest terms (uniform and triangular: a vertex formula with half-widths
``a``, exact in rational arithmetic), and the rest S (any few small terms: uniforms, triangulars
and one smooth part, a normal part or one truncated normal or cap).  Then

    P(|X + S| <= R) = sum_s (prod_i s_i) [H_m(R + c_s) - H_m(-R + c_s)] / (m! prod 2a),
    H_m(y) = E (y + S)_+^m,

and for a vertex end y beyond S's reach (``|S| <= reach`` up to a normal tail), ``H_m(y)`` is the
polynomial ``E (y + S)^m = sum_q C(m, q) y^(m-q) E S^q`` (``y >= reach``) or 0 (``y <= -reach``).
The far ends are summed exactly (Python integers over a power-of-two denominator, the moments of
S multiplying exact sums), so the cancellation of a sum over vertices that differ in the 10th
digit costs nothing; the few ends within S's reach take ``H_m`` from the vertex formula of S
itself, at S's own scale (:mod:`.exact_poly`), in floating point with its rounding bound.  A normal
part's tail beyond 12 sigma adds at most ``sigma^m 2 T^(m-1) phi(T)`` per far end (``T = 12``,
valid while ``T^2 >= 2m``).  The density at R (the sphere's kernel) is the same sum over the upper
ends with ``H_(m-1)``.  Moments: ``E Y^(2k)`` of each unit shape (uniform ``1/(2k+1)``,
triangular ``2/((2k+1)(2k+2))``, normal ``(2k-1)!! / 9^k``, truncated normal by parts,
``m_2k = ((2k-1) m_(2k-2) - 2 f(1)) / beta^2``), combined over independent terms binomially.

With S empty and no normal part this is the vertex formula in exact arithmetic (no rounding but
the final one); with S a normal part alone, the vertex formula with a normal part.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

from tolsynth.probability.exact_parts import part_of
from tolsynth.probability.exact_poly import _G, M_POLY, Smooth, _signs
from tolsynth.probability.exact_series import products, terms_needed

__all__ = ["vertex_exact", "vertex_rest"]

_EPS = np.finfo(float).eps
_T = 12.0
_PHI_T = math.exp(-0.5 * _T * _T) / math.sqrt(2.0 * math.pi)
_NORMAL = part_of("normal")
#: the series of a rest without a vertex formula stops at this many terms (its bound reported)
REST_TERMS = 1 << 16


def _ints(values) -> tuple[list[int], int]:
    """Floats as integers over one common power-of-two denominator."""
    ratios = [float(v).as_integer_ratio() for v in values]
    den = max(d for _, d in ratios)
    return [n * (den // d) for n, d in ratios], den


def _vertices(ai: list[int]) -> tuple[list[int], list[int]]:
    cs, sg = [0], [1]
    for x in ai:
        cs = [c + x for c in cs] + [c - x for c in cs]
        sg = sg + [-s for s in sg]
    return cs, sg


def _unit_moments(p, K: int) -> np.ndarray:
    """``E Y^(2k)``, k = 0..K, of one unit part."""
    k = np.arange(K + 1)
    if p.kind == "uniform":
        return 1.0 / (2 * k + 1)
    if p.kind == "triangular":
        return 2.0 / ((2 * k + 1) * (2 * k + 2))
    if p.kind == "normal":
        return np.array([math.prod(range(1, 2 * j, 2)) / 9.0**j for j in k], dtype=float)
    beta = p.beta
    f1 = p.peak_tn * math.exp(-0.5 * beta * beta)
    mt = [1.0]
    for j in range(1, K + 1):  # integration by parts against f' = -beta^2 y f
        mt.append(((2 * j - 1) * mt[-1] - 2.0 * f1) / (beta * beta))
    mt = np.array(mt)
    if p.kind == "truncnormal":
        return mt
    return (mt - p.w / (2 * k + 1)) / (1.0 - p.w)


def _moments(b, parts, K: int) -> np.ndarray:
    """``E S^q``, q = 0..2K (odd ones 0), of ``S = sum b_i Y_i`` (independent, symmetric)."""
    mu = np.zeros(K + 1)
    mu[0] = 1.0
    binom = np.array([[math.comb(2 * j, 2 * i) for i in range(K + 1)] for j in range(K + 1)], dtype=float)
    for x, p in zip(b, parts):
        if x <= 0:
            continue
        own = _unit_moments(p, K) * x ** (2.0 * np.arange(K + 1))
        mu = np.array([np.sum(binom[j, : j + 1] * mu[: j + 1] * own[j::-1]) for j in range(K + 1)])
    out = np.zeros(2 * K + 1)
    out[::2] = mu
    return out


class _Rest:
    """The small rest S: uniform half-widths ``a``, a smooth part, its moments and reach."""

    def __init__(self, a: list[float], sm, mu: np.ndarray, reach: float, sigma: float, b=(), parts=()):
        self.a, self.sm, self.mu, self.reach, self.sigma = a, sm, mu, reach, sigma
        self.b, self.parts = np.asarray(b, dtype=float), tuple(parts)

    def stoploss(self, y: np.ndarray, j: int, tol: float) -> tuple[np.ndarray, np.ndarray]:
        """``E (y + S)_+^j`` at the ends y (k,) and a bound on each one's error."""
        if self.sm is None:
            return self._series(np.asarray(y, dtype=float), j, tol)
        y = np.asarray(y, dtype=float)[None, :]
        if not self.a:
            G, A = _G(y, self.sm, j)
            _, A1 = _G(y, self.sm, j - 1)
            return G[0], (_EPS * ((2 * j + 8) * A + j * (j + 2) * (np.abs(y) + self.reach) * A1))[0]
        ms = len(self.a)
        S, sg = _signs(ms)
        c = S @ np.array(self.a)
        M = j + ms
        yy = y[0][:, None] + c[None, :]
        G, A = _G(yy, self.sm, M)
        _, A1 = _G(yy, self.sm, M - 1)
        scale = math.factorial(j) / (math.factorial(M) * float(np.prod(2.0 * np.array(self.a))))
        val = (G @ sg) * scale
        err = (
            _EPS
            * scale
            * (
                np.sum((2 * M + 8) * A, axis=1)
                + M * (M + 2) * (np.abs(y[0]) + 2 * self.reach)[:, None].ravel() * np.sum(A1, axis=1)
            )
        )
        return val, err

    def _series(self, y: np.ndarray, j: int, tol: float) -> tuple[np.ndarray, np.ndarray]:
        """S without a vertex formula of its own (two smooth parts): its density periodised with
        half-period ``L = reach`` (the support fits), ``F(t) = 1/2 + t/(2L) + sum_k phi_k
        sin(k pi t / L) / (k pi)`` on ``[-L, L]``, so ``H_0(y) = F(y)`` and
        ``H_1(y) = int_{-y}^{L} (1 - F) = L/4 + y/2 + y^2/(4L) - (L/pi^2) sum_k phi_k (cos(k pi y/L) - (-1)^k) / k^2``;
        the tails are at most the P series' (:mod:`.exact_series`; its weight ``2/(k pi)`` is at least
        ``1/(k pi)``, and ``(L/pi) 2/(k pi)`` at least ``2L/(k pi)^2``), times ``L/pi`` for j = 1."""
        if j > 1:
            return np.full(y.shape, math.nan), np.full(y.shape, math.inf)
        L = np.array([self.reach])
        b = self.b[None, :]
        factor = L[0] / math.pi if j == 1 else 1.0
        K, tail = terms_needed(b, self.parts, np.zeros(1), L, np.array([tol / factor]), False, REST_TERMS)
        Kr = int(K[0]) if K[0] > 0 else REST_TERMS
        k = np.arange(1, Kr + 1, dtype=float)
        T = products(b, self.parts, L, k)[0]
        x = np.pi * k[None, :] * y[:, None] / L[0]
        if j == 0:
            val = 0.5 + y / (2 * L[0]) + np.sin(x) @ (T / (k * np.pi))
        else:
            val = (
                L[0] / 4
                + y / 2
                + y * y / (4 * L[0])
                - L[0] / np.pi**2 * ((np.cos(x) - (-1.0) ** k[None, :]) @ (T / k**2))
            )
        err = tail[0] * factor + 16 * _EPS * (1.0 + L[0]) * math.log2(Kr + 1)
        return val, np.full(y.shape, err)


def _ends_sum(Ri, den, ai, rest: _Rest, j: int, lower: bool, tol: float) -> tuple[float, float]:
    """``sum_s s [H_j(R + c_s) - (lower) H_j(-R + c_s)] / (j! prod 2a)`` and its error bound."""
    cs, sg = _vertices(ai)
    m = len(ai)
    norm = math.factorial(j) * 2**m * math.prod(ai)  # j! prod(2a) den^m
    thr = rest.reach * (1.0 + 1e-12)
    far = {}  # q -> exact sum of s y^(j-q) over the far upper ends (times den^(j-q))
    near_y, near_s = [], []
    n_far = 0
    ends = [(Ri + c, s) for s, c in zip(sg, cs)]
    if lower:
        ends += [(c - Ri, -s) for s, c in zip(sg, cs)]
    for Y, s in ends:
        y = Y / den
        if y >= thr:
            n_far += 1
            for q in range(0, j + 1, 2):
                far[q] = far.get(q, 0) + s * Y ** (j - q)
        elif y > -thr:
            near_y.append(y)
            near_s.append(s)
        else:
            n_far += 1
    # exact far part: C(j, q) mu_q sum s y^(j-q) / (j! prod 2a); y^(j-q) = Y^(j-q) / den^(j-q)
    val = 0.0
    err = 0.0
    for q, B in far.items():
        part = Fraction(B * den ** (m - j + q), norm)  # sum s y^(j-q) / (j! prod 2a)
        val += float(part) * math.comb(j, q) * rest.mu[q] if q else 0.0
        if q:
            err += 4 * _EPS * abs(float(part)) * math.comb(j, q) * rest.mu[q]
    exact0 = Fraction(far.get(0, 0) * den ** (m - j), norm)
    normf = math.factorial(j) * float(np.prod(2.0 * np.array([x / den for x in ai])))
    if near_y:
        H, eH = rest.stoploss(np.array(near_y), j, 0.25 * tol * normf / len(near_y))
        val += float(np.sum(H * np.array(near_s))) / normf
        err += float(np.sum(eH)) / normf
    if rest.sigma > 0:
        err += n_far * rest.sigma**j * 2 * _T ** max(j - 1, 0) * _PHI_T / normf
    return float(exact0) + val, err + 2 * _EPS * (abs(val) + 1.0)


def _value(aX: list[float], rest: _Rest, R: float, kernel: bool, tol: float = 1e-10):
    (Ri, *ai), den = _ints([R, *aX])
    m = len(ai)
    P, eP = _ends_sum(Ri, den, ai, rest, m, True, tol)
    if not kernel:
        return P, eP, None, None
    g, eg = _ends_sum(Ri, den, ai, rest, m - 1, False, tol / (2.0 * R))
    return P, eP, P - 2.0 * R * g, eP + 2.0 * R * eg


def vertex_exact(a, sigma: float, R: float, kernel: bool = False):
    """The vertex formula of one row (half-widths ``a``, normal part ``sigma``) in exact arithmetic
    (a normal part: its ends within 12 sigma of 0 in floating point): ``(P, errP, Q, errQ)``."""
    a = [float(x) for x in a]
    if sigma > 0:
        mu = _moments([3.0 * sigma], [_NORMAL], len(a) // 2 + 1)
        rest = _Rest([], Smooth("normal", [sigma]), mu, _T * sigma, sigma)
    else:
        rest = _Rest([], Smooth("none"), np.eye(1, len(a) + 2).ravel(), 0.0, 0.0)
    return _value(a, rest, float(R), kernel)


def vertex_rest(b: np.ndarray, parts, R: float, kernel: bool = False, tol: float = 1e-10):
    """A row as its largest polynomial terms X and a small rest S (module docstring): for X = the
    top 1, 2, ... terms (by standard deviation) while they are uniform or triangular, the first
    value whose bound meets ``tol``, trying first the splits where S reaches no break point of X or
    has a vertex formula of its own (at most one smooth part), then those where S needs its series;
    ``(value, error)`` or ``None``."""
    sd = np.array([x * math.sqrt(p.var) for x, p in zip(b, parts)])
    order = [int(i) for i in np.argsort(-sd, kind="stable") if b[i] > 0]
    splits = []
    for j in range(1, len(order)):
        X, S = order[:j], order[j:]
        if not all(parts[i].polynomial for i in X):
            break
        aX = [w for i in X for w in ([b[i]] if parts[i].kind == "uniform" else [0.5 * b[i]] * 2)]
        aS = [w for i in S if parts[i].polynomial for w in ([b[i]] if parts[i].kind == "uniform" else [0.5 * b[i]] * 2)]
        if len(aX) > M_POLY or len(aS) > M_POLY:
            break
        quad = [i for i in S if parts[i].kind in ("truncnormal", "cap")]
        normal = [i for i in S if parts[i].kind == "normal"]
        sigma = math.sqrt(sum((b[i] / 3.0) ** 2 for i in normal))
        if len(quad) > 1 or (quad and normal):  # no vertex formula of S: its series where it reaches
            sm, reach_sm = None, sum(b[i] for i in quad) + _T * sigma
        elif quad:
            p = parts[quad[0]]
            sm = Smooth("tn" if p.kind == "truncnormal" else "cap", [b[quad[0]]], p.beta, p.w)
            reach_sm = b[quad[0]]
        elif normal:
            sm, reach_sm = Smooth("normal", [sigma]), _T * sigma
        else:
            sm, reach_sm = Smooth("none"), 0.0
        reach = sum(aS) + reach_sm
        sgn, _ = _signs(len(aX))
        c = sgn @ np.array(aX)
        gap = float(np.min(np.minimum(np.abs(R + c), np.abs(R - c))))
        splits.append((sm is None and gap <= reach * (1.0 + 1e-9), aX, aS, sm, reach, sigma, S))
    best = None
    for needs_series in (False, True):
        for flag, aX, aS, sm, reach, sigma, S in splits:
            if flag != needs_series:
                continue
            mu = _moments(b[S], [parts[i] for i in S], len(aX) // 2 + 1)
            rest = _Rest(aS, sm, mu, reach, sigma, b[S], [parts[i] for i in S])
            P, eP, Q, eQ = _value(aX, rest, float(R), kernel, tol)
            out = (Q, eQ) if kernel else (P, eP)
            if best is None or out[1] < best[1]:
                best = out
            if out[1] <= tol:
                return out
    return best
