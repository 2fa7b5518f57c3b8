"""The Fourier series of the periodised density, with a per-row number of terms and a rigorous
truncation bound (one method of :mod:`tolsynth.probability.exact`).

For ``w = sum_i b_i Y_i`` (``b_i >= 0``), the density periodised with half-period
``L = R + B/2`` (``B`` the reach of ``w``: the sum of the bounded ``b_i`` plus ``NORMAL_REACH``
standard deviations of the normal part) is unchanged on ``[-R, R]``, so with ``T_k = prod_i
phi_i(k pi b_i / L)`` and ``x_k = k pi R / L``

    P(|w| <= R)          = R/L + sum_{k>=1} (2 / (k pi)) sin(x_k) T_k,
    P(|w| <= R) - 2R f(R) =       sum_{k>=1} (2 / (k pi)) (sin x_k - x_k cos x_k) T_k

exactly (the second is the kernel of the sphere's Radon formula, ``f`` the density of ``w``).

**Terms.**  Each row gets the least K of the ladder 16, 32, ..., 2^22 whose tail bound meets the
tolerance; the rows are then summed in groups of equal K, so a row's value depends on that row
alone (never on the other rows of a batch).  The summand's modulus is at most
``g(k) = weight(k) prod_i env_i(k pi b_i / L)`` with the envelopes of :mod:`.exact_parts`, a
non-increasing function of k; so the tail beyond ``K_j`` is at most
``sum_{i>=j} K_i g(K_i)`` over the ladder (``K_{i+1} - K_i = K_i`` terms, each at most
``g(K_i)``) plus the integral of ``g`` beyond the last rung, where every envelope is bounded by
its power law ``far / s^power`` (the factors not yet below 1 there are bounded by 1).

**Rounding** (added to the bound): each term carries a relative error of at most
``(8 n + 10) eps`` (the arguments ``k pi b / L`` to 3 ulps, ``|s phi'(s)| <= 2`` for every shape),
the phase ``x_k`` an absolute error of ``3 eps x_k`` (``6 eps |T_k|`` on P, ``6 pi eps k |T_k|`` on the
kernel); the sums are pairwise.  A truncated normal's characteristic function adds
:func:`~tolsynth.probability.exact_parts.cf_error` per factor and term.  The normal part cut at
``NORMAL_REACH`` sigma adds at most ``erfc(8.5/sqrt 2) < 2e-17`` to P and
``4 R phi(8.5) / sigma`` to the kernel.
"""

from __future__ import annotations

import math

import numpy as np

from tolsynth.probability.exact_parts import cf_error
from tolsynth.progress import check_deadline

__all__ = ["NORMAL_REACH", "KMAX", "half_period", "terms_needed", "series_sum", "products"]

#: standard deviations of the normal part beyond which its mass (< 2e-17) is neglected
NORMAL_REACH = 8.5
#: the largest number of series terms
KMAX = 1 << 22
#: the ladder of term counts: 16, 32, ..., 2^24 (the last rungs only bound the tail)
LADDER = 16 * 2 ** np.arange(0, 21)
_EPS = np.finfo(float).eps
#: phi(8.5), the standard normal density at the reach
_PHI_REACH = math.exp(-0.5 * NORMAL_REACH**2) / math.sqrt(2 * math.pi)
#: values per chunk of the (rows x terms) arrays
CHUNK = 1 << 21


def _normal_cols(parts) -> tuple[np.ndarray, np.ndarray]:
    bounded = np.array([p.bounded for p in parts], dtype=bool)
    return bounded, ~bounded


def half_period(b: np.ndarray, parts, R) -> np.ndarray:
    """``L = R + (sum of bounded b + 8.5 sigma_normal) / 2`` per row of ``b`` (M, n)."""
    bounded, normal = _normal_cols(parts)
    B = b[:, bounded].sum(axis=1) if bounded.any() else np.zeros(b.shape[0])
    if normal.any():
        B = B + NORMAL_REACH * np.sqrt(np.sum((b[:, normal] / 3.0) ** 2, axis=1))
    return R + 0.5 * B


def _sigma_normal(b, parts) -> np.ndarray:
    _, normal = _normal_cols(parts)
    if not normal.any():
        return np.zeros(b.shape[0])
    return np.sqrt(np.sum((b[:, normal] / 3.0) ** 2, axis=1))


def groups(parts) -> list:
    """The columns of each distinct part: ``[(part, column indices)]`` (one NumPy call per group)."""
    out: dict = {}
    for i, p in enumerate(parts):
        out.setdefault(p, []).append(i)
    return [(p, np.array(idx)) for p, idx in out.items()]


def _envelope(b, parts, t) -> np.ndarray:
    """``prod_i env_i(t b_i)`` for rows b (M, n) at frequencies t (M, T)."""
    out = np.ones(t.shape)
    for p, idx in groups(parts):
        bi = b[:, idx]  # (M, g)
        live = bi > 0
        if not live.any():
            continue
        e = p.env(t[:, :, None] * bi[:, None, :])
        out *= np.prod(np.where(live[:, None, :], e, 1.0), axis=2)
    return out


def terms_needed(
    b: np.ndarray, parts, R, L: np.ndarray, tol: np.ndarray, kernel: bool = False, kmax: int = KMAX
) -> tuple[np.ndarray, np.ndarray]:
    """Per row: the least ladder K (<= ``kmax``) whose tail bound is at most ``tol``, and that bound
    (``K = 0`` and the bound at ``kmax`` where none is).  ``kernel``: the sphere kernel's weight
    ``(2 / (k pi)) (1 + k pi R / L)`` instead of ``2 / (k pi)``."""
    M = b.shape[0]
    R = np.broadcast_to(np.asarray(R, dtype=float), (M,))
    Kl = LADDER.astype(float)
    t = np.pi * Kl[None, :] / L[:, None]
    env = _envelope(b, parts, t)
    if kernel:
        weight = 2.0 / (np.pi * Kl[None, :]) + 2.0 * R[:, None] / L[:, None]
    else:
        weight = 2.0 / (np.pi * Kl[None, :]) * np.ones((M, 1))
    g = weight * env
    # beyond the last rung X: power laws of the factors already below 1 at X
    X = Kl[-1]
    logC = np.zeros(M)
    q = np.zeros(M)
    for i, p in enumerate(parts):
        bi = b[:, i]
        live = bi > 0
        if not live.any():
            continue
        s = np.pi * X * np.where(live, bi, 1.0) / L
        if p.power == 0:  # normal: its value at X bounds it beyond
            logC += np.where(live, -s * s / 18.0, 0.0)
            continue
        with np.errstate(divide="ignore"):
            lf = math.log(p.far) - p.power * np.log(s)
        use = live & (lf < 0.0)
        logC += np.where(use, lf, 0.0)
        q += np.where(use, p.power, 0.0)
    C = np.exp(logC)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if kernel:
            W = 2.0 / (np.pi * X) + 2.0 * R / L
            rem = np.where(q > 1.0, W * C * X / (q - 1.0), np.inf)
        else:
            rem = np.where(q > 0.0, 2.0 / np.pi * C / q, np.inf)
        rem = np.where(C == 0.0, 0.0, rem)
    seg = Kl[None, :] * g  # terms K_i+1 .. 2 K_i, each at most g(K_i)
    tail = np.cumsum(seg[:, ::-1], axis=1)[:, ::-1] + rem[:, None]
    # the normal part cut at its reach
    sig = _sigma_normal(b, parts)
    with np.errstate(divide="ignore", invalid="ignore"):
        cut = np.where(sig > 0, 2e-17 + (4.0 * R * _PHI_REACH / np.where(sig > 0, sig, 1.0) if kernel else 0.0), 0.0)
    tail = tail + cut[:, None]
    usable = LADDER <= kmax
    ok = (tail <= tol[:, None]) & usable[None, :]
    first = np.where(ok.any(axis=1), np.argmax(ok, axis=1), -1)
    last = int(np.flatnonzero(usable)[-1])
    K = np.where(first >= 0, LADDER[np.maximum(first, 0)], 0)
    bound = np.where(first >= 0, tail[np.arange(M), np.maximum(first, 0)], tail[:, last])
    return K.astype(np.int64), bound


def products(b: np.ndarray, parts, L: np.ndarray, k: np.ndarray, split: bool = False):
    """``T_k = prod_i phi_i(k pi b_i / L)`` per row (rows, len(k)); the normal factors as one.
    With ``split``: also the product of the exact factors alone and a bound on the error of T_k
    from the truncated normals' tabulated factors (``sum_i d_i prod_{j != i} (|phi_j| + d_j)`` over
    them, times the exact factors' product; ``d`` from :func:`~.exact_parts.cf_error`)."""
    tau = np.pi * k[None, :] / L[:, None]
    out = np.ones(tau.shape)
    bounded, normal = _normal_cols(parts)
    if normal.any():
        s2 = np.sum(b[:, normal] ** 2, axis=1)
        if np.any(s2 > 0):
            out *= np.exp(-(tau**2) * s2[:, None] / 18.0)
    quad = []
    for p, idx in groups(parts):
        if not p.bounded:
            continue
        bi = b[:, idx]
        if not np.any(bi > 0):
            continue
        if p.kind in ("truncnormal", "cap"):
            quad += list(idx)
            continue
        # cf(0) = 1 for the columns of zeros
        out *= np.prod(p.cf(tau[:, :, None] * bi[:, None, :]), axis=2)
    if not quad:
        return (out, np.zeros(out.shape)) if split else out
    exact = out.copy()
    phis, errs = [], []
    for i in quad:
        p = parts[i]
        bi = b[:, i : i + 1]
        f = p.cf(tau * bi)
        out *= f
        if split:
            phis.append(np.abs(f))
            errs.append(np.where(bi > 0, cf_error(tau * bi, p.beta), 0.0) / (1.0 - p.w if p.kind == "cap" else 1.0))
    if not split:
        return out
    whole = np.ones(out.shape)
    for f, d in zip(phis, errs):
        whole *= f + d
    D = sum(d * whole / (f + d + 1e-300) for f, d in zip(phis, errs))
    return out, np.abs(exact) * D


def series_sum(b: np.ndarray, parts, R, L: np.ndarray, K: np.ndarray, kernel: bool = False):
    """The K-term series per row (K from :func:`terms_needed`; rows summed in groups of equal K)
    and its rounding bound: ``(value, rounding)``, each (M,)."""
    M, n = b.shape
    R = np.broadcast_to(np.asarray(R, dtype=float), (M,))
    val = np.zeros(M)
    rnd = np.zeros(M)
    for Kg in np.unique(K):
        if Kg <= 0:
            continue
        rows = np.flatnonzero(K == Kg)
        k = np.arange(1, Kg + 1, dtype=float)
        step = max(1, CHUNK // int(Kg * max(n, 1)))
        for a in range(0, rows.size, step):
            check_deadline("an exact probability")
            r = rows[a : a + step]
            T, D = products(b[r], parts, L[r], k, split=True)
            x = np.pi * k[None, :] * (R[r] / L[r])[:, None]
            w = 2.0 / (np.pi * k)[None, :]
            absT = np.abs(T)
            if kernel:
                c = w * (np.sin(x) - x * np.cos(x))
                val[r] = np.sum(c * T, axis=1)
                rnd[r] = _EPS * (
                    (8 * n + 10) * np.sum(np.abs(c) * absT, axis=1) + 6 * np.pi * np.sum(k[None, :] * absT, axis=1)
                )
                cw = np.abs(c)
            else:
                c = w * np.sin(x)
                val[r] = R[r] / L[r] + np.sum(c * T, axis=1)
                rnd[r] = _EPS * ((8 * n + 10) * np.sum(w * absT, axis=1) + 6 * np.sum(absT, axis=1) + 4)
                cw = w
            rnd[r] += np.sum(cw * D, axis=1)  # the truncated normals' tabulated factors
    return val, rnd
