"""The exact probability along one direction, its gradient and Hessian in ``u = ln eps``, on
batches of rows: what the exact solver and its certificate evaluate thousands of times.

A row is one (pose, direction) cut: ``c_i = |w . a_i|`` and ``b_i = c_i e^{u_i}``, and
``P(u) = P(|sum_i b_i Y_i| <= R)``.  As in :mod:`tolsynth.probability.exact`, the density of the sum
periodised with half-period ``L >= R + B/2`` (``B`` the reach of the bounded terms plus 8.5 sigma of
the normal ones) is unchanged on ``[-R, R]``, so with ``tau_k = k pi / L``

    P = R/L + sum_k (2/(k pi)) sin(k pi R / L) prod_i phi_i(tau_k b_i)

exactly, for any such ``L``.  P does not depend on ``L``; so with ``L`` fixed slightly above its
least value the series differentiates term by term (``d/du_i`` of ``phi_i(tau b_i)`` is
``D1_i = t phi_i'(t)`` at ``t = tau b_i``, and ``d^2/du_i^2`` is ``D2_i = t d/dt (t phi_i'(t))``).

Truncation: every bounded shape's envelope is a power, ``|phi_i(s)| <= min(1, m_i / s)^d_i``
(:meth:`Shape.envelope`: uniform ``m = 1, d = 1``, triangular ``m = 2, d = 2``, truncated normal
``m = 2 f(0), d = 1``), so for ``k >= K`` the product is at most ``prod_{c_j < K} (c_j / k)`` over
the power factors with ``c_j = m_j L / (pi b_j)`` below K, times the normal factors at K (they
decrease in k); summing ``(2/pi) C k^-(q+1)`` over ``k > K`` is at most ``(2/pi) C K^-q / q``.  Each
row gets its own K from that bound (rows are grouped by K), so one row with a dominant term no
longer makes every row of a batch long.  The gradient's tail is the same bound without the
factor of the parameter differentiated, times ``sup |t phi_i'(t)|``.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from tolsynth.probability.distributions import Shape
from tolsynth.probability.truncnormal import cf3 as truncnormal_cf3
from tolsynth.solvers import exact_kernel

__all__ = ["Rows", "probability", "derivatives", "NORMAL_REACH"]

#: standard deviations of the normal part beyond which its mass (< 2e-17) is neglected
NORMAL_REACH = 8.5
#: ``L`` is this factor above its least value, so that the series stays exact near the point
#: (what term-by-term differentiation needs)
L_MARGIN = 1.0 + 1e-3
#: the K of a row: powers of two from 16 to 2^22
_KS = 2.0 ** np.arange(4, 23)


@lru_cache(maxsize=None)
def _power_factors(shp: Shape) -> tuple[float, ...]:
    """The factors ``m`` of ``env(s) <= prod min(1, m / s)`` of a bounded shape, read off its
    envelope's far decay ``env(s) s^d`` (one copy of each envelope: :meth:`Shape.envelope`)."""
    d = shp.decay
    S = 1e6
    c = float(shp.envelope(np.array(S))) * S**d
    return (c ** (1.0 / d),) * d


@lru_cache(maxsize=None)
def _far_factor(shp: Shape) -> tuple[float, float]:
    """``(a, c)`` with ``|phi(s)| <= a / s + c / s^2`` for s > 0, so that for ``s >= s0`` the power
    factor ``m`` may be ``min(m, a + c / s0)``.  Only the truncated normal gains: its density
    ``f(y) = f(0) e^{-beta^2 y^2 / 2}`` on [-1, 1], integrated by parts twice,
    ``phi(s) = 2 f(1) sin(s) / s - (2 f'(1) cos(s) - int f'' cos(sy) dy) / s^2``, so
    ``a = 2 f(1)`` and ``c = 2 |f'(1)| + int |f''|``, where ``|f'(1)| = beta^2 f(1)`` and
    ``int |f''|`` is twice the variation of ``f' = -beta^2 y f`` on [0, 1] (falling to its least
    value ``-beta f(0) e^{-1/2}`` at ``y = 1/beta`` when ``beta > 1``, then rising to ``f'(1)``);
    its envelope's ``m = 2 f(0)`` is then some seven times too large at ``beta = 2``."""
    if shp.kind != "truncnormal":
        m = _power_factors(shp)[0] if shp.bounded else 0.0
        return m, 0.0
    b = shp.beta
    f1 = shp.peak * math.exp(-0.5 * b * b)
    d1 = b * b * f1  # |f'(1)|
    tv = 2.0 * b * shp.peak * math.exp(-0.5) - d1 if b > 1.0 else d1  # variation of f' on [0, 1]
    return 2.0 * f1, 2.0 * d1 + 2.0 * tv


@lru_cache(maxsize=None)
def _d1_sup(shp: Shape) -> float:
    """``sup_t |t phi'(t)|``: uniform ``|cos t - sinc t| <= 2``; triangular ``2 |s| |cos h - s| <= 4``;
    normal ``(t^2/9) e^{-t^2/18} <= 2/e``; truncated normal ``|E[tY sin tY]| <= 1 + 4 f(0)``
    (integration by parts against the density ``f``, which is unimodal on [-1, 1])."""
    return {"uniform": 2.0, "triangular": 4.0, "normal": 2.0 / math.e}.get(shp.kind, 1.0 + 4.0 * shp.peak)


def _cf3(shp: Shape, t: np.ndarray, order: int):
    """``phi(t)`` and, for ``order >= 1``, ``D1 = t phi'(t)``, for ``order 2`` ``D2 = t dD1/dt``."""
    if shp.kind == "uniform":
        small = np.abs(t) < 1e-4
        safe = np.where(small, 1.0, t)
        phi = np.where(small, 1.0 - t * t / 6.0, np.sin(safe) / safe)
        if order == 0:
            return phi, None, None
        c = np.cos(t)
        d1 = np.where(small, -t * t / 3.0, c - phi)
        d2 = np.where(small, -2.0 * t * t / 3.0, -t * np.sin(t) - d1) if order > 1 else None
        return phi, d1, d2
    if shp.kind == "normal":
        phi = np.exp(-t * t / 18.0)
        if order == 0:
            return phi, None, None
        a = t * t / 9.0
        return phi, -a * phi, (a * a - 2.0 * a) * phi if order > 1 else None
    if shp.kind == "triangular":
        h = 0.5 * t
        small = np.abs(h) < 1e-4
        safe = np.where(small, 1.0, h)
        s = np.where(small, 1.0 - h * h / 6.0, np.sin(safe) / safe)
        phi = s * s
        if order == 0:
            return phi, None, None
        e = np.where(small, -h * h / 3.0, np.cos(h) - s)  # h s'(h)
        d1 = 2.0 * s * e
        if order == 1:
            return phi, d1, None
        he = np.where(small, -2.0 * h * h / 3.0, -h * np.sin(h) - e)  # h d/dh (h s')
        return phi, d1, 2.0 * e * e + 2.0 * s * he
    return truncnormal_cf3(t, shp.beta, order)


class Rows:
    """Shape-dependent constants of one tuple of shapes (remembered per tuple)."""

    def __init__(self, shapes: tuple):
        self.shapes = tuple(shapes)
        self.bounded = np.array([s.bounded for s in self.shapes])
        self.normal = ~self.bounded
        # power factors: column index and multiplier, one entry per factor
        idx, mult, far = [], [], []
        for i, s in enumerate(self.shapes):
            if s.bounded:
                for m in _power_factors(s):
                    idx.append(i)
                    mult.append(m)
                    far.append(_far_factor(s))
        self.f_idx = np.array(idx, dtype=int)
        self.f_mult = np.array(mult, dtype=float)
        # far from the origin a factor may be smaller: m(s0) = min(m, a + c / s0) for s >= s0
        self.f_far = np.array([a for a, _ in far], dtype=float)
        self.f_far2 = np.array([c for _, c in far], dtype=float)
        self.d1_sup = np.array([_d1_sup(s) for s in self.shapes])
        # identical shapes evaluate as one block of columns
        groups: dict = {}
        for i, s in enumerate(self.shapes):
            groups.setdefault(s, []).append(i)
        self.groups = [(s, np.array(ix)) for s, ix in groups.items()]

    def half_period(self, b: np.ndarray, R) -> np.ndarray:
        """``L`` per row (margin :data:`L_MARGIN` above ``R + B/2``)."""
        B = b[:, self.bounded].sum(axis=1) if self.bounded.any() else np.zeros(b.shape[0])
        if self.normal.any():
            B = B + NORMAL_REACH * np.sqrt(np.sum((b[:, self.normal] / 3.0) ** 2, axis=1))
        return R + 0.5 * B * L_MARGIN

    def tail(
        self, b: np.ndarray, L: np.ndarray, K: np.ndarray, drop: int | None = None, candidates: bool = False
    ) -> np.ndarray:
        """Rigorous bound on ``sum_{k>K} (2/(k pi)) prod_i env_i(k pi b_i / L)`` per row: K one per
        row (-> (M,)), or with ``candidates`` the same T values for every row (-> (M, T));
        ``drop``: without the factors of that column (the gradient's tail)."""
        K = np.asarray(K, dtype=float)
        if not candidates:
            out = exact_kernel.tail(self, b, L, np.broadcast_to(K, (b.shape[0],)), drop)
            if out is not None:
                return out
        Kc = K[None, :] if candidates else K[:, None]  # (1, T) or (M, 1)
        if self.f_idx.size:
            bf = b[:, self.f_idx]
            if drop is not None:
                bf = np.where(self.f_idx[None, :] == drop, 0.0, bf)
            with np.errstate(divide="ignore", invalid="ignore"):
                # the factor at the arguments s >= s0 = K pi b / L of the tail's terms
                s0 = Kc[:, None, :] * np.pi * np.maximum(bf, 1e-300)[:, :, None] / L[:, None, None]  # (M, F, T)
                m = np.minimum(self.f_mult[None, :, None], self.f_far[None, :, None] + self.f_far2[None, :, None] / s0)
                c = np.where(
                    (bf > 0)[:, :, None], m * L[:, None, None] / (np.pi * np.maximum(bf, 1e-300))[:, :, None], np.inf
                )
            below = c < Kc[:, None, :]  # (M, F, T)
            q = below.sum(axis=1)  # (M, T)
            logC = np.where(below, np.log(c), 0.0).sum(axis=1)
        else:
            q = np.zeros((b.shape[0], Kc.shape[1]))
            logC = np.zeros_like(q)
        if self.normal.any():  # the normal factors at K (they decrease in k)
            sn = b[:, self.normal]
            if drop is not None and self.normal[drop]:
                sn = np.where(np.flatnonzero(self.normal)[None, :] == drop, 0.0, sn)
            a = np.sum(sn**2, axis=1)[:, None] * (np.pi / L[:, None]) ** 2 / 18.0  # exp(-a k^2)
        else:
            a = np.zeros((b.shape[0], 1))
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            power = np.where(
                q > 0, (2.0 / np.pi) * np.exp(logC - q * np.log(Kc) - a * Kc**2) / np.maximum(q, 1), np.inf
            )
            # no power factor below K: the normal part alone, int_K (2/(pi x)) e^{-a x^2} <= e^{-a K^2} / (pi a K^2)
            gauss = np.where(a > 0, np.exp(-a * Kc**2) / (np.pi * a * Kc**2), np.inf)
        out = np.minimum(power, gauss)
        return out if candidates else out[:, 0]

    def terms(self, b: np.ndarray, L: np.ndarray, tol: float, kmax: float = 2.0**16) -> np.ndarray:
        """The K of each row: the least power of two whose tail bound is below ``tol`` (at most kmax)."""
        Ks = _KS[_KS <= kmax]
        K = exact_kernel.terms(self, b, L, Ks, tol)
        if K is not None:
            return K
        ok = self.tail(b, L, Ks, candidates=True) <= tol
        j = np.where(ok.any(axis=1), ok.argmax(axis=1), len(Ks) - 1)
        return Ks[j].astype(int)


@lru_cache(maxsize=64)
def _rows_of(shapes: tuple) -> Rows:
    return Rows(shapes)


_last_rows: tuple = (None, None)  # the last tuple asked for (by identity) and its Rows, one object


def rows_of(shapes) -> Rows:
    """The :class:`Rows` of a tuple of shapes; the same tuple object as the last call is served
    without hashing its shapes again (a solve passes one tuple hundreds of times)."""
    global _last_rows
    last = _last_rows  # read once: another thread may replace it, never half of it
    if shapes is last[0] and type(shapes) is tuple:
        return last[1]
    rw = _rows_of(tuple(shapes))
    _last_rows = (shapes, rw)
    return rw


def split_small(b: np.ndarray, rw: "Rows", budget: float) -> tuple[np.ndarray, np.ndarray]:
    """``b`` with its smallest terms set to 0 where that changes P by at most ``budget``, and the
    rigorous bound per row.  The dropped part ``e`` is symmetric and independent of the kept sum X,
    whose density f is Lipschitz with ``|f'| <= (2 f_1(0) / b_1) (f_2(0) / b_2)`` (the total
    variation of the largest term's density times the peak of the next one's), so
    ``|P(|X + e| <= R) - P(|X| <= R)| <= Var(e) sup|f'|`` (Taylor to second order at +-R, the
    first-order term vanishing with E e = 0).  Rows whose structure makes some terms tiny (a
    planar sub-chain seen along its normal) then need a few dozen series terms, not thousands."""
    M, n = b.shape
    if n < 3 or budget <= 0:
        return b, np.zeros(M)
    return _split(b, rw, budget)[:2]


def _split(b, rw, budget):
    out = exact_kernel.split(rw, b, budget)
    if out is not None:
        return out
    M, n = b.shape
    var = np.array([s.variance for s in rw.shapes])
    peak = np.array([s.peak for s in rw.shapes])
    order = np.argsort(b, axis=1)  # ascending
    bs = np.take_along_axis(b, order, axis=1)
    b1, b2 = bs[:, -1], bs[:, -2]
    p1 = np.take_along_axis(peak[None, :].repeat(M, 0), order, axis=1)
    with np.errstate(divide="ignore"):
        S = 2.0 * p1[:, -1] * p1[:, -2] / np.maximum(b1 * b2, 1e-300)
    cv = np.cumsum(bs**2 * np.take_along_axis(var[None, :].repeat(M, 0), order, axis=1), axis=1)
    ok = cv[:, : n - 2] * S[:, None] <= budget  # dropping the j+1 smallest keeps at least two terms
    count = ok.sum(axis=1)  # cumsum is increasing: ok is a prefix
    drop = np.arange(n)[None, :] < count[:, None]
    out = b.copy()
    np.put_along_axis(out, order, np.where(drop, 0.0, bs), axis=1)
    var_e = np.where(count > 0, np.take_along_axis(cv, np.maximum(count - 1, 0)[:, None], axis=1)[:, 0], 0.0)
    # the gradient's bound: a dropped term's own derivative is at most 2 b^2 Var(Y) sup|f'|; a kept
    # one's moves by at most 2 b_j Var(e) sup|f''|, sup|f''| from the three largest kept terms
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        S3 = 4.0 * p1[:, -1] * p1[:, -2] * p1[:, -3] / np.maximum(b1 * b2 * bs[:, -3], 1e-300) if n >= 3 else np.inf
    gdrop = 2.0 * b**2 * var[None, :] * S[:, None]
    gkeep = 2.0 * b * (var_e * S3)[:, None]
    gerr = np.where(out == 0, np.where(b > 0, gdrop, 0.0), gkeep)
    return out, var_e * S, gerr


def _kernel(k: np.ndarray, R, L: np.ndarray, ball: bool = False) -> np.ndarray:
    """The series' weights: ``(2/(k pi)) sin x_k`` for ``P(|w| <= R)``, or the sphere kernel
    ``(2/(k pi)) (sin x_k - x_k cos x_k)`` of :mod:`tolsynth.probability.exact` (``x_k = k pi R / L``)."""
    x = np.pi * k[None, :] * (R / L)[:, None]
    if ball:
        return 2.0 / (np.pi * k)[None, :] * (np.sin(x) - x * np.cos(x))
    return 2.0 / (np.pi * k)[None, :] * np.sin(x)


def _products(b: np.ndarray, L: np.ndarray, K: int, rw: "Rows") -> np.ndarray:
    """``prod_i phi_i(k pi b_i / L)`` for k = 1..K per row (m, K).  ``sin(k theta)`` comes from the
    powers of ``e^{i theta}`` (a running product: one complex multiplication per term instead of a
    sine, rounding error about k ulp), the normal columns from one exponential per k."""
    m, n = b.shape
    k = np.arange(1, K + 1, dtype=float)
    out = np.ones((m, K))
    theta = np.pi * b / L[:, None]  # (m, n)
    for shp, ix in rw.groups:
        th = theta[:, ix]
        if shp.kind == "normal":
            out *= np.exp(-np.sum(th**2, axis=1)[:, None] * (k * k)[None, :] / 18.0)
            continue
        if shp.kind not in ("uniform", "triangular"):
            out *= np.prod(truncnormal_cf3(k[None, :, None] * th[:, None, :], shp.beta)[0], axis=2)
            continue
        half = 0.5 if shp.kind == "triangular" else 1.0
        th = half * th
        live = th > 0  # a zero coefficient is a factor 1
        z = np.exp(1j * np.where(live, th, 0.0))
        S = np.cumprod(np.broadcast_to(z[:, None, :], (m, K, th.shape[1])), axis=1).imag
        S = np.where(live[:, None, :], S, 1.0)
        q = live.sum(axis=1)  # (m,)
        den = np.prod(np.where(live, th, 1.0), axis=1)[:, None] * k[None, :] ** q[:, None]
        f = np.prod(S, axis=2) / den
        out *= f * f if half == 0.5 else f
    return out


#: rows needing at least this many series terms try the closed form of a few uniform terms
CLOSED_FROM = 512
#: rounding allowance added to every truncation bound (the running products drift by ~k ulp per
#: factor; K n ulp stays far below it for K n < 1e4)
ROUNDING = 1e-12
#: what the compiled evaluation takes of this module's constants
_CONSTS = (L_MARGIN, NORMAL_REACH, CLOSED_FROM, ROUNDING)


def probability(b, shapes: tuple, R, tol: float = 1e-10):
    """``P(|sum_i b_i Y_i| <= R)`` for rows ``b`` (M, n) (``R`` a number or one per row), and the
    rigorous error bound per row (truncation plus a rounding allowance); rows grouped by their own
    number of terms."""
    rw = rows_of(shapes)
    b = np.abs(np.atleast_2d(np.asarray(b, dtype=float)))
    M = b.shape[0]
    Rv = np.broadcast_to(np.asarray(R, dtype=float), (M,))
    out = exact_kernel.evaluate(rw, b, Rv, tol, 0, _KS[_KS <= 2.0**16], _CONSTS)
    if out is not None:  # every row in one call of the compiled kernel
        P, _, _, err, b = out
        return _slow_rows(P, err, b, shapes, Rv, tol)
    b, dropped = split_small(b, rw, 0.25 * tol)
    L = rw.half_period(b, Rv)
    K = rw.terms(b, L, tol)
    P = np.empty(M)
    closed = {}
    long = np.flatnonzero(K >= CLOSED_FROM)
    if long.size:  # a few uniform terms: their spline, not thousands of series terms
        from tolsynth.solvers.exact_closed import closed_rows

        closed = {long[r]: v for r, v in closed_rows(b[long], shapes, Rv[long], 0, tol).items()}
        if closed:
            K = K.copy()
            K[list(closed)] = 0
    done = False
    if K.any():  # every row in one call of the compiled kernel, where it can be had
        r = np.flatnonzero(K > 0)
        out = exact_kernel.series(b[r], Rv[r], L[r], K[r], rw, 0)
        if out is not None:
            P[r], done = out[0], True
    for Kg in np.unique(K[K > 0]) if not done else ():
        rows = np.flatnonzero(K == Kg)
        k = np.arange(1, Kg + 1, dtype=float)
        step = max(1, 1_000_000 // (Kg * b.shape[1]))
        for a in range(0, rows.size, step):
            r = rows[a : a + step]
            kern = _kernel(k, Rv[r], L[r])
            P[r] = Rv[r] / L[r] + np.sum(kern * _products(b[r], L[r], int(Kg), rw), axis=1)
    err = rw.tail(b, L, np.maximum(K, 1)) + ROUNDING + dropped
    for r, (Pr, _, _, er) in closed.items():
        P[r], err[r] = Pr, er + ROUNDING + dropped[r]
    return _slow_rows(P, err, b, shapes, Rv, tol)


def _slow_rows(P, err, b, shapes, Rv, tol):
    """Rows whose bound is above ``tol`` from the reference evaluator; P clipped to [0, 1]."""
    slow = np.flatnonzero(err > tol + ROUNDING)
    if slow.size:  # one term dominates (a near-jump): the reference evaluator's closed forms
        from tolsynth.probability import exact as ref

        batch = getattr(ref, "direction_probability_batch", None)
        if batch is not None:  # one call: its rows are independent, and its per-call overhead is most of a row's cost
            P[slow], err[slow] = batch(b[slow], shapes, Rv[slow], tol=tol)
        else:
            for r in slow:
                P[r], err[r] = ref.direction_probability(b[r], shapes, float(Rv[r]), tol=tol, return_error=True)
    return np.clip(P, 0.0, 1.0), err


def _series_block(b, R, L, K: int, rw: "Rows", hessian: bool, ball: bool):
    """P, gradient and Hessian in u of rows ``b`` (m, n) that share their number of terms K."""
    m, n = b.shape
    k = np.arange(1, K + 1, dtype=float)
    tau = np.pi * k[None, :] / L[:, None]  # (m, K)
    phi = np.empty((m, K, n))
    d1 = np.empty((m, K, n))
    d2 = np.empty((m, K, n)) if hessian else None
    for shp, ix in rw.groups:
        f0, f1, f2 = _cf3(shp, tau[:, :, None] * b[:, None, ix], 2 if hessian else 1)
        phi[:, :, ix], d1[:, :, ix] = f0, f1
        if hessian:
            d2[:, :, ix] = f2
    s = _kernel(k, R, L, ball)  # (m, K)
    # products without one factor, by prefix and suffix products (no division by phi)
    pre = np.ones((m, K, n + 1))
    np.cumprod(phi, axis=2, out=pre[:, :, 1:])
    suf = np.ones((m, K, n + 1))
    suf[:, :, :-1] = np.cumprod(phi[:, :, ::-1], axis=2)[:, :, ::-1]
    others = pre[:, :, :-1] * suf[:, :, 1:]  # (m, K, n)
    P = (0.0 if ball else R / L) + np.einsum("mk,mk->m", s, pre[:, :, -1])
    sd1 = s[:, :, None] * d1 * others
    G = sd1.sum(axis=1)
    H = None
    if hessian:
        # without two factors: others / phi_j where phi_j is not tiny, else the product directly
        safe = np.where(np.abs(phi) > 1e-150, phi, 1e-150)
        Hm = np.matmul(sd1.transpose(0, 2, 1), d1 / safe)  # (m, n, n)
        diag = (s[:, :, None] * d2 * others).sum(axis=1)
        Hm[:, np.arange(n), np.arange(n)] = diag
        H = 0.5 * (Hm + Hm.transpose(0, 2, 1))
    return P, G, H


def derivatives(
    c, u, shapes: tuple, R, tol: float = 1e-12, hessian: bool = True, rigorous: bool = False, ball: bool = False
):
    """P, its gradient in ``u`` and (``hessian``) its Hessian for rows ``b = c e^u`` (c (M, n)).

    Returns ``(P, G (M, n), H (M, n, n) or None, errP (M,), errG (M, n) or None)``; ``errG`` (with
    ``rigorous``) bounds the gradient's truncation error per entry."""
    rw = rows_of(shapes)
    c = np.abs(np.atleast_2d(np.asarray(c, dtype=float)))
    M, n = c.shape
    b = c * np.exp(np.asarray(u, dtype=float))[None, :]
    if not rigorous and not ball:
        out = exact_kernel.evaluate(
            rw,
            b,
            np.broadcast_to(np.asarray(R, dtype=float), (M,)),
            tol,
            2 if hessian else 1,
            _KS[_KS <= 2.0**16],
            _CONSTS,
        )
        if out is not None:  # every row in one call of the compiled kernel
            return np.clip(out[0], 0.0, 1.0), out[1], out[2], out[3], None
    # the dropped terms' own derivatives are second order in them: 0 here, bounded in gerr
    if n >= 3 and not ball:
        b0 = b
        b, dropped, gerr = _split(b, rw, 0.25 * tol)
        if rigorous:  # where the gradient's bound for the dropped terms is not small, keep them all
            loose = gerr.max(axis=1) > tol
            b = np.where(loose[:, None], b0, b)
            dropped = np.where(loose, 0.0, dropped)
            gerr = np.where(loose[:, None], 0.0, gerr)
    else:
        dropped, gerr = np.zeros(M), np.zeros((M, n))
    Rv = np.broadcast_to(np.asarray(R, dtype=float), (M,))
    L = rw.half_period(b, Rv)
    if rigorous:  # the gradient's tail lacks one factor: K from the row without its largest term
        bk = b.copy()
        bk[np.arange(M), np.argmax(b, axis=1)] = 0.0
        K = rw.terms(bk, L, tol, kmax=2.0**18)
    else:
        K = rw.terms(b, L, tol)
    P = np.empty(M)
    G = np.empty((M, n))
    H = np.empty((M, n, n)) if hessian else None
    closed = {}
    long = np.flatnonzero(K >= CLOSED_FROM) if not ball else np.zeros(0, dtype=int)
    if long.size:
        from tolsynth.solvers.exact_closed import closed_rows

        closed = {long[r]: v for r, v in closed_rows(b[long], shapes, Rv[long], 2 if hessian else 1, tol).items()}
    for r, (Pr, Gr, Hr, _) in closed.items():
        P[r], G[r] = Pr, Gr
        if hessian:
            H[r] = Hr
    series = np.ones(M, dtype=bool)
    series[list(closed)] = False
    done = False
    if series.any():  # every row in one call of the compiled kernel, where it can be had
        r = np.flatnonzero(series)
        out = exact_kernel.series(b[r], Rv[r], L[r], K[r], rw, 2 if hessian else 1, ball)
        if out is not None:
            P[r], G[r], done = out[0], out[1], True
            if hessian:
                H[r] = out[2]
    for Kg in np.unique(K[series]) if not done else ():
        rows = np.flatnonzero(series & (K == Kg))
        step = max(1, 400_000 // (int(Kg) * n))  # rows per batch: a few MB of work arrays
        for a in range(0, rows.size, step):
            r = rows[a : a + step]
            P[r], G[r], Hr = _series_block(b[r], Rv[r], L[r], int(Kg), rw, hessian, ball)
            if hessian:
                H[r] = Hr
    errP = rw.tail(b, L, K) + ROUNDING + dropped
    if ball:  # the kernel's weight is (2/(k pi)) (1 + k pi R / L): one power of k more
        errP = errP * (1.0 + np.pi * K * Rv / L) * 2.0
    errG = None
    if rigorous:
        errG = np.stack([rw.tail(b, L, K, drop=i) * rw.d1_sup[i] for i in range(n)], axis=1) + gerr + ROUNDING
    for r, (_, _, _, er) in closed.items():
        errP[r] = er + ROUNDING + dropped[r]
        if rigorous:
            errG[r] = er * n + gerr[r] + ROUNDING
    return (P if ball else np.clip(P, 0.0, 1.0)), G, H, errP, errG
