"""The choice of method per row of coefficients, for :mod:`tolsynth.probability.exact`.

A row ``b`` (``b_i >= 0``, one part per column) asks for ``P(|w| <= R)`` or the sphere kernel
``P - 2 R f(R)`` of ``w = sum_i b_i Y_i``, to an absolute tolerance.  Each row is handled on its
own (so its value never depends on the other rows of a batch, nor on anything that ran before):

1. **Small terms dropped, with a rigorous bound.**  For independent symmetric ``S`` (the dropped
   terms) and the kept sum ``X`` with density ``f``, ``psi(s) = P(|X + s| <= R)`` has
   ``psi'(0) = 0`` and ``|psi'(s)| <= 2 min(sup f, Lip(f) |s|)``, so dropping S moves P by at most
   ``min(2 sup f E|S|, Lip(f) E S^2)``; ``sup f <= min_i peak_i / b_i`` and
   ``Lip(f) <= min(lip_i / b_i^2, peak_i tv_j / (b_i b_j))`` over kept terms ``i != j``
   (``(f_i * f_j)' = f_i * f_j'``).  The density at R moves by at most ``Lip(f) E|S|``.  The
   smallest terms go while the bound stays below a quarter of the tolerance.
2. **Closed forms**: no term left (1), one term (its own distribution function), only normal
   terms (erf), or a bounded sum that cannot reach R (1, the normal part's tail in the bound).
3. **The cheaper exact method** of the two that apply: the vertex formula (:mod:`.exact_poly`:
   uniform and triangular terms plus one smooth part, a normal part or one truncated normal,
   exact up to rounding, ``2^m`` vertices; in exact arithmetic, :mod:`.exact_rest`, where its
   rounding bound is too large) or the Fourier series (:mod:`.exact_series`, with the least number
   of terms whose rigorous tail bound meets the tolerance, at most ``2^16`` here, ``2^12`` when a
   truncated normal could be split instead); each the other's fallback.
4. **The vertex formula with a small rest** (:mod:`.exact_rest`): the largest terms exactly, the
   others through their moments, or at their own scale where they reach a break point.
5. **A truncated normal split** where nothing above applies (its density's jumps make the series
   slow): ``Y = w U + (1 - w) C`` as a mixture (:mod:`.exact_parts`), both rows evaluated again,
   the results and bounds averaged with weights ``w`` and ``1 - w`` (up to four truncated normals
   a row, 16 sub-rows).
6. Otherwise the series with up to ``kmax`` terms (about ``2^18`` where even that cannot meet the
   tolerance), its bound reported as it is.

Each row's value is a function of that row, its R and its tolerance: the methods, their term
counts and their groupings are chosen from the row alone (the rows of a batch differ only in the
last bits NumPy's summation order leaves, below 1e-15), and nothing is remembered between calls
but constants and the truncated normal's table, whose entries are the same whenever computed.
"""

from __future__ import annotations

import math

import numpy as np

from tolsynth.probability.exact_parts import UNIFORM, cap_of
from tolsynth.probability.exact_poly import M_POLY, Smooth, vertex_float
from tolsynth.probability.exact_rest import vertex_exact, vertex_rest
from tolsynth.probability.exact_series import KMAX, half_period, series_sum, terms_needed
from tolsynth.probability.stats import _special

__all__ = ["evaluate", "FAST_TERMS"]

#: the series is used up to this many terms before the other methods are tried
FAST_TERMS = 1 << 16
#: with a truncated normal, a split is tried before a series longer than this
SPLIT_TERMS = 1 << 12
#: a row is split only while it has at most this many truncated normals (2^4 sub-rows)
MAX_SPLIT = 4
#: where no method meets the tolerance, the series stops near this many terms (its bound reported)
LONG_TERMS = 1 << 18
_SQRT2 = math.sqrt(2.0)
#: method codes (one per row, for profiles and tests)
METHODS = ("none", "one", "normal", "inside", "vertex", "vertex-exact", "series", "split", "series-long")


def _attr(parts, name) -> np.ndarray:
    return np.array([getattr(p, name) for p in parts], dtype=float)


def _drop(b, parts, R, tol, kernel):
    """``b`` with the droppable terms set to 0, and the bound on what that changes (module doc)."""
    M, n = b.shape
    var, peak, tv, lip = (_attr(parts, k) for k in ("var", "peak", "tv", "lip"))
    sd2 = b * b * var[None, :]
    order = np.argsort(-sd2, axis=1, kind="stable")
    bs = np.take_along_axis(b, order, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        pk = np.where(bs > 0, peak[order] / bs, np.inf)
        tvb = np.where(bs > 0, tv[order] / bs, np.inf)
        lb = np.where(bs > 0, lip[order] / (bs * bs), np.inf)
    s2 = np.take_along_axis(sd2, order, axis=1)
    rest = np.concatenate([np.cumsum(s2[:, ::-1], axis=1)[:, ::-1], np.zeros((M, 1))], axis=1)[:, 1:]
    supf = np.minimum.accumulate(pk, axis=1)
    tvm = np.minimum.accumulate(tvb, axis=1)
    pair = np.full((M, n), np.inf)
    if n > 1:
        with np.errstate(invalid="ignore"):
            pair[:, 1:] = np.minimum(supf[:, :-1] * tvb[:, 1:], tvm[:, :-1] * pk[:, 1:])
        pair = np.nan_to_num(pair, nan=np.inf)
    lipk = np.minimum(np.minimum.accumulate(lb, axis=1), np.minimum.accumulate(pair, axis=1))
    with np.errstate(invalid="ignore", over="ignore"):
        root = np.sqrt(rest)
        bP = np.where(rest > 0, np.minimum(2.0 * supf * root, lipk * rest), 0.0)
        bD = np.where(rest > 0, lipk * root, 0.0)
    _local(b, parts, R, order, rest, bP, bD)
    with np.errstate(invalid="ignore", over="ignore"):
        bound = bP + 2.0 * np.asarray(R)[..., None] * bD if kernel else bP
    bound = np.nan_to_num(bound, nan=np.inf)
    ok = bound <= 0.25 * tol[:, None]
    keep = np.argmax(ok, axis=1) + 1  # bound(n kept) = 0, so some entry is true
    dropped = np.arange(n)[None, :] >= keep[:, None]
    out = b.copy()
    rows = np.repeat(np.arange(M), n).reshape(M, n)
    out[rows[dropped], order[dropped]] = 0.0
    return out, bound[np.arange(M), keep - 1]


def _local(b, parts, R, order, rest, bP, bD):
    """The largest term kept alone, the others dropped: where R is farther from its break points
    than the others reach, its density is smooth around R, so P moves by at most
    ``slope_in / b^2 E S^2`` and the density at R by ``curve_in / (2 b^3) E S^2`` (Taylor to the
    second order against a symmetric S); a normal part of S counts to 12 sigma, its tail beyond
    (below 1e-30) added.  Updates the first column of ``bP`` and ``bD`` in place."""
    M, n = b.shape
    if n < 2:
        return
    first = order[:, 0]
    bj = b[np.arange(M), first]
    bounded = np.array([p.bounded for p in parts])
    normal2 = (b[:, ~bounded] / 3.0) ** 2 if (~bounded).any() else np.zeros((M, 1))
    reach = (
        b[:, bounded].sum(axis=1)
        - np.where(bounded[first], bj, 0.0)
        + 12.0 * np.sqrt(normal2.sum(axis=1) - np.where(~bounded[first], (bj / 3.0) ** 2, 0.0).clip(0.0))
    )
    Rv = np.broadcast_to(np.asarray(R, dtype=float), (M,))
    for j in np.unique(first):
        sel = np.flatnonzero((first == j) & (bj > 0))
        p = parts[j]
        gap = np.full(sel.size, np.inf)
        for e in p.edges:
            gap = np.minimum(gap, np.abs(Rv[sel] - e * bj[sel]))
        ok = sel[gap > reach[sel] * (1.0 + 1e-9)]
        if not ok.size:
            continue
        x = bj[ok]
        bP[ok, 0] = np.minimum(bP[ok, 0], p.slope_in / (x * x) * rest[ok, 0] + 1e-30)
        bD[ok, 0] = np.minimum(bD[ok, 0], 0.5 * p.curve_in / (x * x * x) * rest[ok, 0] + 1e-30)


def _erf(x):
    return _special("erf", x)


def evaluate(b: np.ndarray, parts: tuple, R, tol, kernel: bool = False, kmax: int = KMAX):
    """Per row of ``b`` (M, n), ``b >= 0``: ``P(|w| <= R)`` (or with ``kernel`` the sphere kernel
    ``P - 2 R f(R)``), a bound on its error, and the method used.  ``R`` and ``tol``: numbers or
    one per row."""
    b = np.asarray(b, dtype=float)
    M, n = b.shape
    R = np.array(np.broadcast_to(np.asarray(R, dtype=float), (M,)))
    tol = np.array(np.broadcast_to(np.asarray(tol, dtype=float), (M,)))
    val = np.zeros(M)
    err = np.zeros(M)
    method = np.empty(M, dtype=object)
    if M == 0:
        return val, err, method
    b, dropped = _drop(b, parts, R, tol, kernel)
    err += dropped
    tol_left = tol - dropped
    bounded = np.array([p.bounded for p in parts], dtype=bool)
    live = b > 0
    nk = live.sum(axis=1)
    sigma = np.sqrt(np.sum((b[:, ~bounded] / 3.0) ** 2, axis=1)) if (~bounded).any() else np.zeros(M)
    B = b[:, bounded].sum(axis=1) if bounded.any() else np.zeros(M)
    todo = np.ones(M, dtype=bool)

    # -- closed forms --------------------------------------------------------------------------
    none = nk == 0
    val[none], method[none] = 1.0, "none"
    todo &= ~none
    one = todo & (nk == 1)
    if one.any():
        j = np.argmax(live, axis=1)
        for col in np.unique(j[one]):
            r = np.flatnonzero(one & (j == col))
            x = R[r] / b[r, col]
            P = parts[col].within(x)
            val[r] = P - 2.0 * R[r] * parts[col].density(x) / b[r, col] if kernel else P
        method[one] = "one"
        err[one] += 4e-16
        todo &= ~one
    normal = todo & ~np.any(live[:, bounded], axis=1)
    if normal.any():
        r = np.flatnonzero(normal)
        z = R[r] / sigma[r]
        P = _erf(z / _SQRT2)
        val[r] = P - 2.0 * z * np.exp(-0.5 * z * z) / math.sqrt(2 * math.pi) if kernel else P
        err[r] += 4e-16
        method[normal] = "normal"
        todo &= ~normal
    gap = R - B
    inside = todo & (gap >= 0)
    if inside.any():
        r = np.flatnonzero(inside)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            z = np.where(sigma[r] > 0, gap[r] / np.where(sigma[r] > 0, sigma[r], 1.0), np.inf)
            tail = np.where(np.isinf(z), 0.0, _special("erfc", np.where(np.isinf(z), 0.0, z) / _SQRT2))
            if kernel:
                tail = tail + np.where(
                    np.isinf(z),
                    0.0,
                    2.0
                    * R[r]
                    * np.exp(-0.5 * np.minimum(z, 1e3) ** 2)
                    / (math.sqrt(2 * math.pi) * np.where(sigma[r] > 0, sigma[r], 1.0)),
                )
        good = tail <= 0.5 * tol_left[r]
        rg = r[good]
        val[rg], err[rg], method[rg] = 1.0, err[rg] + tail[good], "inside"
        todo[rg] = False
    rows = np.flatnonzero(todo)
    if rows.size:
        _hard(b, parts, R, tol_left, kernel, kmax, sigma, rows, val, err, method)
    return val, err, method


def _widths(b, parts, m: int) -> np.ndarray:
    """The uniforms' half-widths of rows with m of them (a triangular is two of half its width),
    largest first, (rows, m)."""
    cols = [b[:, i] for i, p in enumerate(parts) if p.kind == "uniform"]
    cols += [0.5 * b[:, i] for i, p in enumerate(parts) if p.kind == "triangular" for _ in range(2)]
    W = np.column_stack(cols) if cols else np.zeros((b.shape[0], 0))
    return -np.sort(-W, axis=1)[:, :m]


def _smooth_keys(live, kinds) -> np.ndarray:
    """Per row, the non-polynomial part a vertex row may carry: -1 none, -2 a normal part (any
    number of normal terms), the column of its one truncated normal or cap (and no normal), or -3
    (not a vertex row)."""
    normal = np.array([k == "normal" for k in kinds], dtype=bool)
    quad = np.array([k in ("truncnormal", "cap") for k in kinds], dtype=bool)
    nq = live[:, quad].sum(axis=1) if quad.any() else np.zeros(live.shape[0], dtype=int)
    has_normal = live[:, normal].any(axis=1) if normal.any() else np.zeros(live.shape[0], dtype=bool)
    col = np.argmax(live & quad[None, :], axis=1)
    key = np.where(nq == 0, np.where(has_normal, -2, -1), -3)
    return np.where((nq == 1) & ~has_normal, col, key)


def _hard(b, parts, R, tol, kernel, kmax, sigma, rows, val, err, method):
    """Rows with two or more terms that reach R: the cheaper of the vertex formula and the series,
    the other where the first misses the tolerance, then the vertex formula with a small rest,
    a split, or the long series."""
    bb = b[rows]
    live = bb > 0
    kinds = [p.kind for p in parts]
    two = np.array([2 if k == "triangular" else 1 if k == "uniform" else 0 for k in kinds])
    m = live.astype(int) @ two
    key = _smooth_keys(live, kinds)
    poly_ok = (key != -3) & (m <= M_POLY) & (m >= 1)
    Rr, sr = R[rows], sigma[rows]
    L = half_period(bb, parts, Rr)
    K, tail = terms_needed(bb, parts, Rr, L, 0.9 * tol[rows], kernel, min(kmax, FAST_TERMS))
    cost_series = np.where(K > 0, K * (live @ np.array([p.cost for p in parts]) + 4.0), np.inf)
    # the vertex formula's rounding, roughly: 2^(m+1) terms of size reach^m / (m! prod 2a)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        logw = np.log(np.where(live, bb, 1.0)) @ two - live[:, two == 2].sum(axis=1) * 2 * math.log(2.0)
        reach = Rr + bb @ (two > 0) + 12.0 * sr + bb @ np.array([k in ("truncnormal", "cap") for k in kinds])
        lognorm = np.array([math.lgamma(x + 1) for x in m]) + m * math.log(2.0) + logw
        amp = np.exp(np.minimum((m + 1) * math.log(2.0) + m * np.log(reach) - lognorm + 2 * np.log(m + 2.0), 700.0))
    slow = np.finfo(float).eps * amp > 0.5 * tol[rows]
    smooth = key != -1
    exact_ok = (key == -1) | (key == -2)
    cost_vertex = (
        (2.0 ** np.minimum(m, 60))
        * (m + 4)
        * np.where(smooth, 12.0, 2.0)
        * np.where(slow, np.where(exact_ok, np.where(smooth, 3000.0, 300.0), np.inf), 1.0)
    )
    cost_vertex = np.where(poly_ok, cost_vertex, np.inf)
    tn = np.array([k == "truncnormal" for k in kinds], dtype=bool)
    has_tn = np.any(live[:, tn], axis=1) if tn.any() else np.zeros(rows.size, dtype=bool)
    deferred = has_tn & (K > SPLIT_TERMS)  # a split is likely cheaper than a long series
    cost_first = np.where(deferred, np.inf, cost_series)
    done = np.zeros(rows.size, dtype=bool)
    for stage in range(2):
        vertex_first = cost_vertex <= cost_first
        use_vertex = ~done & np.isfinite(cost_vertex) & (vertex_first if stage == 0 else ~vertex_first)
        use_series = ~done & np.isfinite(cost_first) & (~vertex_first if stage == 0 else vertex_first)
        idx = np.flatnonzero(use_vertex)
        if idx.size:
            v, e, meth = _vertex(bb[idx], parts, Rr[idx], tol[rows[idx]], kernel, sr[idx], m[idx], key[idx], slow[idx])
            ok = e <= tol[rows[idx]]
            r = rows[idx[ok]]
            val[r], err[r], method[r] = v[ok], err[r] + e[ok], meth[ok]
            done[idx[ok]] = True
        idx = np.flatnonzero(use_series)
        if idx.size:
            _series_rows(bb, parts, Rr, L, K, tail, kernel, rows, idx, val, err, method, "series")
            done[idx] = True
    for i in np.flatnonzero(~done):
        out = vertex_rest(bb[i], parts, float(Rr[i]), kernel, float(tol[rows[i]]))
        if out is not None and out[1] <= tol[rows[i]]:
            val[rows[i]], err[rows[i]], method[rows[i]] = out[0], err[rows[i]] + out[1], "vertex-rest"
            done[i] = True
    n_tn = live[:, tn].sum(axis=1) if tn.any() else np.zeros(rows.size, dtype=int)
    split = np.flatnonzero(~done & has_tn & (n_tn <= MAX_SPLIT))
    if split.size:
        base = err[rows[split]].copy()
        _split(bb, parts, R, tol, kernel, kmax, rows, split, val, err, method)
        missed = split[(err[rows[split]] - base > tol[rows[split]]) & np.isfinite(cost_series[split])]
        if missed.size:  # the split fell short: the series it was preferred to
            err[rows[missed]] = base[np.searchsorted(split, missed)]
            _series_rows(bb, parts, Rr, L, K, tail, kernel, rows, missed, val, err, method, "series")
        done[split] = True
    idx = np.flatnonzero(~done & np.isfinite(cost_series))
    if idx.size:
        _series_rows(bb, parts, Rr, L, K, tail, kernel, rows, idx, val, err, method, "series")
        done[idx] = True
    long = np.flatnonzero(~done)
    if long.size:
        r = rows[long]
        Kl, tl = terms_needed(bb[long], parts, Rr[long], L[long], 0.9 * tol[r], kernel, kmax)
        miss = Kl == 0
        if miss.any():  # out of reach: the fewest terms within twice the bound at LONG_TERMS
            cap = min(kmax, LONG_TERMS)
            _, tc = terms_needed(
                bb[long[miss]], parts, Rr[long[miss]], L[long[miss]], np.zeros(miss.sum()), kernel, cap
            )
            Km, tm = terms_needed(bb[long[miss]], parts, Rr[long[miss]], L[long[miss]], 2.0 * tc, kernel, cap)
            Kl[miss], tl[miss] = Km, tm
        _series_rows(bb, parts, Rr, L, Kl, tl, kernel, rows, long, val, err, method, "series-long", local=True)


def _series_rows(bb, parts, Rr, L, K, tail, kernel, rows, idx, val, err, method, name, local=False):
    """The series on rows ``idx`` of the hard set (``local``: K and tail given for idx only)."""
    Kr, tr = (K, tail) if local else (K[idx], tail[idx])
    v, rnd = series_sum(bb[idx], parts, Rr[idx], L[idx], Kr, kernel)
    r = rows[idx]
    val[r], err[r], method[r] = v, err[r] + tr + rnd, name


def _vertex(bb, parts, R, tol, kernel, sigma, m, key, slow):
    """The vertex formula on rows (grouped by m and by their smooth part): floating point unless
    its rounding is expected too large, exact arithmetic (no smooth part, or a normal one) where
    the floating-point bound misses."""
    val = np.zeros(bb.shape[0])
    err = np.full(bb.shape[0], np.inf)
    meth = np.empty(bb.shape[0], dtype=object)
    for mg in np.unique(m):
        for kg in np.unique(key[m == mg]):
            sel = np.flatnonzero((m == mg) & (key == kg))
            a = _widths(bb[sel], parts, int(mg))
            if kg == -1:
                sm = Smooth("none")
            elif kg == -2:
                sm = Smooth("normal", sigma[sel])
            else:
                c = int(kg)
                p = parts[c]
                sm = Smooth("tn" if p.kind == "truncnormal" else "cap", bb[sel, c], p.beta, p.w)
            fl = ~slow[sel]
            if fl.any():
                P, eP, Q, eQ = vertex_float(
                    a[fl], sm.rows(np.flatnonzero(fl)) if sm.scale is not None else sm, R[sel[fl]], kernel
                )
                val[sel[fl]], err[sel[fl]] = (Q, eQ) if kernel else (P, eP)
                meth[sel[fl]] = "vertex"
            if kg >= 0:  # no exact arithmetic with a truncated normal
                continue
            for k in np.flatnonzero(err[sel] > 0.5 * tol[sel]):
                i = sel[k]
                P1, eP1, Q1, eQ1 = vertex_exact(a[k], float(sigma[i]), float(R[i]), kernel)
                v1, e1 = (Q1, eQ1) if kernel else (P1, eP1)
                if e1 < err[i]:
                    val[i], err[i], meth[i] = v1, e1, "vertex-exact"
    return val, err, meth


def _split(bb, parts, R, tol, kernel, kmax, rows, split, val, err, method):
    """The largest truncated-normal term of each row as a mixture of a uniform and its cap."""
    tn = [i for i, p in enumerate(parts) if p.kind == "truncnormal"]
    sub = bb[split][:, tn]
    col = np.array(tn)[np.argmax(sub, axis=1)]
    for c in np.unique(col):
        sel = split[col == c]
        r = rows[sel]
        w = parts[c].w
        pu = parts[:c] + (UNIFORM,) + parts[c + 1 :]
        pc = parts[:c] + (cap_of(parts[c].beta),) + parts[c + 1 :]
        vu, eu, _ = evaluate(bb[sel], pu, R[r], tol[r], kernel, kmax)
        vc, ec, _ = evaluate(bb[sel], pc, R[r], tol[r], kernel, kmax)
        val[r] = w * vu + (1.0 - w) * vc
        err[r] += w * eu + (1.0 - w) * ec
        method[r] = "split"
