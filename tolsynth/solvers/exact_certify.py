"""The exact solver's certificate: every direction proven to meet p, and a rigorous lower bound.

**Every direction** (:func:`cover`).  At one pose, ``P(w) = P(|w . dr| <= R)`` with
``w . dr = x . Y``, ``x = M^T w`` (``M = A diag(eps)``).  The directions are covered by patches of
the cube's faces (``w`` and ``-w`` give the same P, so three faces suffice), each patch the cone
over four unit vertices ``v_k``; ``d = min_k c . v_k`` for a unit ``c`` inside it.  Every unit
``w`` of the patch is ``sum_k mu_k v_k / |sum_k mu_k v_k|`` with ``mu`` in the simplex, and
``|sum mu v| >= d``.  Two lower bounds on P over the patch follow, each an ordinary probability:

* *monotone*: ``|w . a_i| <= max_k |v_k . a_i| / d``, and P does not increase when any
  ``|x_i|`` grows (for independent symmetric unimodal errors: condition on the others and use
  Anderson's theorem in one dimension), so P over the patch is at least P at those coefficients;
* *gauge*: for symmetric log-concave errors the set ``K = {w in R^3 : P(w) >= q}`` is convex for
  every level q (the preimage under ``x = M^T w`` of the convex set of Lagoa, Li & Sznaier 2005)
  and symmetric, so its gauge ``N`` is a norm and ``N(w) <= max_k N(v_k) / d``; hence
  ``min_k P(|v_k . dr| <= R d)`` bounds P over the patch.  Its loss is second order in the
  patch's size (``1 - d``), which is what lets the search close on a minimum that sits exactly at p.

A patch whose bound (the larger, less the evaluator's error bound) is below ``p - tol`` is split
in four; a patch centre whose own P is below ``p - cut_tol`` is a violated direction (a new cut
for the exchange), and one below ``p - tol`` ends the search: no cover can exist.

**Lower bound** (:func:`half_space_bound`).  In ``u = ln eps`` the feasible set of each cut is
convex (the image under ``ln`` of a convex set that is closed downwards: the geometric mean of two
points lies below their arithmetic mean).  At the solution ``u*`` each active cut's set lies in
its supporting half-space ``h . (u - u') <= 0``, ``h = -grad P(u') >= 0``, taken at the point
``u' = u* + s`` (every tolerance scaled by ``e^s``) where P is at p or just below it (proven with
the evaluator's error bound): the set of level ``P(u') <= p`` contains the cut's own and is
supported there.  The gradient comes from the series with its own truncation bound ``e``; the
half-space is widened by ``sum_i e_i max |u_i - u'_i|`` over the box.  The cheapest point of the box in those
half-spaces is separable: ``L(lam) = sum_i min_u [c_i(u) + w_i u] - sum_j lam_j c_j``,
``w = sum_j lam_j h_j``, a valid bound for every ``lam >= 0`` (weak duality), maximised by Newton's
method from the interior-point multipliers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tolsynth.solvers.exact_series import derivatives, probability
from tolsynth.solvers.worst_case import _linear_min, convex_in_eps

__all__ = ["cover", "Cover", "half_space_bound", "LOG_CONCAVE"]

#: shapes with a symmetric log-concave density (the convexity and the gauge bound need it)
LOG_CONCAVE = frozenset({"uniform", "normal", "triangular", "truncnormal"})
#: the cube's faces split G x G at the start
START_GRID = 4
#: series tolerance of the patch evaluations: loose first, tight where the bound is near p
EVAL_TOL = 1e-10
LOOSE_TOL = 1e-6
#: the tighter tolerances a patch evaluation takes in turn while it is not clear of the level
MID_TOLS = (1e-8, EVAL_TOL)
#: truncation tolerance of the gradients that tilt the lower bound's half-spaces, at first
GRAD_TOL = 1e-9
#: the tightest it is taken to, where the multipliers (about 1 / (1 - p)) need more
MIN_GRAD_TOL = 1e-14
#: the share of the cost the gradients' error may widen the half-spaces by (the certificate's gap
#: is 1e-6 of it)
WIDEN_SHARE = 1e-7
#: a patch smaller than this (1 - d) that still fails is reported as not certified
MIN_SIZE = 1e-15
#: grid points' face coordinates as integers in units of 2^-_GRID_BITS (exact for the dyadic splits)
_GRID_BITS = 28


@dataclass
class Cover:
    """The outcome of :func:`cover` at one pose."""

    certified: bool  # every direction proven to have P >= p - tol
    proven: float  # the least lower bound over the final cover (P >= proven everywhere)
    violations: list  # [(w (3,), P)] directions found with P < p - cut_tol, worst first
    patches: int  # patches examined
    evaluations: int  # probability evaluations
    #: the search stopped at ``max_patches`` before it closed: nothing is proven (``proven`` is -inf)
    limit: bool = False


def _frames():
    e = np.eye(3)
    return [(e[a], e[(a + 1) % 3], e[(a + 2) % 3]) for a in range(3)]


_FRAMES = np.array(_frames())  # (3 faces, 3 vectors, 3)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _lower(rows: np.ndarray, shapes: tuple, R: float, q: float, first: int = 0) -> tuple[np.ndarray, float]:
    """``P - error`` per row: to a loose tolerance (or the ``first`` of :data:`MID_TOLS`), then
    tighter only where the last value is not clear of ``q`` (rows with a few dominant terms need
    many series terms at the tightest); and the fraction of rows the second tolerance took."""
    tols = (LOOSE_TOL,) + MID_TOLS
    P, e = probability(rows, shapes, R, tols[first])
    out = P - e
    last = tols[first]
    second = 1.0 if first else 0.0
    for tol in tols[first + 1 :]:
        near = np.flatnonzero(np.abs(out - q) < 2 * last)
        if not near.size:
            break
        if tol == tols[1]:
            second = near.size / max(rows.shape[0], 1)
        P2, e2 = probability(rows[near], shapes, R, tol)
        out[near] = P2 - e2
        last = tol
    return out, second


def cover(
    M: np.ndarray,
    shapes: tuple,
    R: float,
    p: float,
    tol: float = 1e-7,
    cut_tol: float = 1e-8,
    max_patches: int = 200_000,
    gauge: bool = True,
) -> Cover:
    """Branch and bound over direction patches (see the module docstring): is ``P(|w . dr| <= R)
    >= p - tol`` proven for every unit w, with ``dr = M Y`` (M 3 x n)?

    Neighbouring patches share corners, and a split keeps its parent's: each grid point's gauge
    value ``P(|v . dr| <= R d)`` is kept with its ``d``, and serves every patch whose own ``d`` is
    at least that (P grows with the radius); a point is evaluated again only where its value is
    short of the level and the patch's ``d`` is larger.  The monotone bound is tried while it
    still proves patches.  A pose symmetric under a reflection (:func:`_mirror`) has half of the
    directions covered, its rows raised by the columns' departure from the symmetry."""
    q = p - tol
    g = np.linspace(-1.0, 1.0, START_GRID + 1)
    S0, T0 = np.meshgrid(g[:-1], g[:-1], indexing="ij")
    face = np.repeat(np.arange(3), S0.size)
    s0 = np.tile(S0.ravel(), 3)
    t0 = np.tile(T0.ravel(), 3)
    h = np.full(face.size, 2.0 / START_GRID)
    axis, slack = _mirror(M)
    if axis is not None:  # the half with the axis' coordinate >= 0 on each face
        keep = np.where((face + 2) % 3 == axis, t0 >= 0, s0 >= 0)
        face, s0, t0, h = face[keep], s0[keep], t0[keep], h[keep]
    proven = math.inf
    violations: list = []
    patches = evaluations = 0
    # grid points evaluated so far (face and coordinates packed in one integer), sorted, with the
    # d of their evaluation and the lower bound on P(|v . dr| <= R d) found there
    kk, kd_, kv_ = np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0)
    mono_on = True
    tight = 0.0
    while face.size:
        patches += face.size
        if patches > max_patches:
            return Cover(False, -math.inf, violations, patches, evaluations, limit=True)
        F = _FRAMES[face]  # (N, 3, 3)
        cs, ct, corners = [], [], []
        for ds, dt in ((0, 0), (1, 0), (0, 1), (1, 1)):
            cs.append(s0 + ds * h)
            ct.append(t0 + dt * h)
            corners.append(_unit(F[:, 0] + cs[-1][:, None] * F[:, 1] + ct[-1][:, None] * F[:, 2]))
        V = np.stack(corners, axis=1)  # (N, 4, 3)
        c = _unit(V.sum(axis=1))
        d = np.min(np.einsum("nkx,nx->nk", V, c), axis=1)  # (N,)
        X = np.abs(V @ M) + slack  # (N, 4, n): |v_k . a_i| eps_i (raised by the mirror's slack)
        bound = np.full(face.size, -math.inf)
        if mono_on:
            bound = _lower(X.max(axis=1) / d[:, None], shapes, R, q)[0]
            evaluations += face.size
            mono_on = np.count_nonzero(bound >= q) >= 0.2 * face.size
        fail = bound < q
        if gauge and fail.any():
            idx = np.flatnonzero(fail)
            keys = (
                (face[idx, None] << 60)
                | (np.rint((np.stack(cs, 1)[idx] + 1.0) * 2.0**_GRID_BITS).astype(np.int64) << 30)
                | np.rint((np.stack(ct, 1)[idx] + 1.0) * 2.0**_GRID_BITS).astype(np.int64)
            )  # (m, 4)
            dj = np.repeat(d[idx, None], 4, axis=1)
            pos = np.minimum(np.searchsorted(kk, keys), max(kk.size - 1, 0))
            found = (kk[pos] == keys) if kk.size else np.zeros(keys.shape, dtype=bool)
            kd = np.where(found, kd_[pos] if kk.size else 0.0, math.inf)
            kv = np.where(found, kv_[pos] if kk.size else 0.0, -math.inf)
            # a kept value serves a patch whose d is at least its own; it is taken again only where
            # it is short of the level and this patch's d is larger
            serves = kd <= dj
            need = ~(serves & ((kv >= q) | (kd >= dj)))
            val = np.where(serves, kv, -math.inf)
            if need.any():
                uk, first, inv = np.unique(keys[need], return_index=True, return_inverse=True)
                dd = np.full(uk.size, math.inf)
                np.minimum.at(dd, inv, dj[need])
                r = np.flatnonzero(need.ravel())[first]
                # where most of the last level's values needed the second tolerance, start there
                vals, tight = _lower(X[idx[r // 4], r % 4] / dd[:, None], shapes, R, q, int(tight > 0.5))
                evaluations += uk.size
                val[need] = np.maximum(val[need], np.where(dd[inv] <= dj[need], vals[inv], -math.inf))
                # keep the value at the larger d (deeper patches have larger d)
                kpos = np.minimum(np.searchsorted(kk, uk), max(kk.size - 1, 0))
                kfound = (kk[kpos] == uk) if kk.size else np.zeros(uk.size, dtype=bool)
                better = kfound & (dd >= kd_[kpos] if kk.size else False)
                kd_[kpos[better]], kv_[kpos[better]] = dd[better], vals[better]
                kk, kd_, kv_ = (np.concatenate([a, b[~kfound]]) for a, b in ((kk, uk), (kd_, dd), (kv_, vals)))
                order = np.argsort(kk, kind="stable")
                kk, kd_, kv_ = kk[order], kd_[order], kv_[order]
            bound[idx] = np.maximum(bound[idx], val.min(axis=1))
            fail = bound < q
        proven = min(proven, float(np.min(bound[~fail], initial=math.inf)))
        if not fail.any():
            break
        idx = np.flatnonzero(fail)
        Pc, ec = probability(np.abs(c[idx] @ M), shapes, R, LOOSE_TOL)
        evaluations += idx.size
        short = Pc + ec < p - cut_tol
        for j in np.flatnonzero(short):
            violations.append((c[idx[j]], float(Pc[j])))
        bad = Pc + ec < q  # below what the certificate asks: no cover can exist
        if bad.any():
            violations.sort(key=lambda v: v[1])
            return Cover(False, min(proven, float(np.min(Pc[bad]))), violations, patches, evaluations)
        tiny = ((1.0 - d[idx]) < MIN_SIZE) | (h[idx] < 2.0 ** (2 - _GRID_BITS))
        if tiny.any():
            return Cover(False, min(proven, float(np.min(bound[idx[tiny]]))), violations, patches, evaluations)
        # split each failing patch in four
        hh = 0.5 * h[idx]
        face = np.repeat(face[idx], 4)
        s0 = np.concatenate([s0[idx], s0[idx] + hh, s0[idx], s0[idx] + hh]).reshape(4, -1).T.ravel()
        t0 = np.concatenate([t0[idx], t0[idx], t0[idx] + hh, t0[idx] + hh]).reshape(4, -1).T.ravel()
        h = np.repeat(hh, 4)
    violations.sort(key=lambda v: v[1])
    return Cover(True, proven, violations, patches, evaluations)


def _mirror(M: np.ndarray) -> tuple[int | None, np.ndarray | float]:
    """A coordinate axis k whose reflection S (w_k -> -w_k) leaves every row ``|w . m_i|`` the same
    up to rounding: each column lies in the mirror plane or along the axis.  Then
    ``|S w . m_i| <= |w . m_i| + delta_i`` with ``delta_i = 2 min(|m_ik|, |m_i without k|)``, and as P
    does not increase when a coefficient grows, a bound on rows raised by delta holds at w and at
    S w alike.  Returns (k, delta) for the first such axis (delta at most 1e-12 of the largest
    entry), else (None, 0)."""
    scale = float(np.abs(M).max(initial=0.0))
    for k in range(3):
        rest = np.linalg.norm(np.delete(M, k, axis=0), axis=0)
        delta = 2.0 * np.minimum(np.abs(M[k]), rest)
        if scale > 0 and float(delta.max(initial=0.0)) <= 1e-12 * scale:
            return k, delta
    return None, 0.0


def _sphere_derivatives(M: np.ndarray, shapes: tuple, R: float, w: np.ndarray):
    """P at unit ``w`` and its gradient and Hessian in ``w`` (R^3): with ``y_i = w . m_i`` and the
    series' derivatives in ``u_i = ln b_i`` (``G_i = b_i dP/db_i``, ``H``), ``grad = sum_i (G_i / y_i) m_i``
    and ``hess = M diag(1/y) (H - diag G) diag(1/y) M^T``; a term with ``y_i`` near 0 (whose own
    derivative vanishes there: P is even in each ``y_i``) is left out."""
    y = w @ M
    big = np.abs(y) > 1e-9 * max(float(np.abs(y).max()), 1e-300)
    inv = np.where(big, 1.0 / np.where(big, y, 1.0), 0.0)
    P, G, H, _, _ = derivatives(np.abs(y)[None, :], np.zeros(y.size), shapes, R, tol=EVAL_TOL)
    Mi = M * inv[None, :]
    grad = Mi @ G[0]
    hess = Mi @ (H[0] - np.diag(G[0])) @ Mi.T
    return float(P[0]), grad, hess


def refine_direction(
    M: np.ndarray, shapes: tuple, R: float, w: np.ndarray, steps: int = 30
) -> tuple[np.ndarray, float]:
    """A local minimum of P over unit directions near ``w``: Newton's method on the sphere (the
    Riemannian Hessian ``E^T hess E - (w . grad) I`` in a tangent basis E; a gradient step where
    it is not positive definite), steps at most 0.2 rad, halved until P falls."""
    w = _unit(np.asarray(w, dtype=float))
    P, grad, hess = _sphere_derivatives(M, shapes, R, w)
    for _ in range(steps):
        e1 = np.cross(w, np.eye(3)[int(np.argmin(np.abs(w)))])
        e1 /= np.linalg.norm(e1)
        E = np.column_stack([e1, np.cross(w, e1)])
        g = E.T @ grad
        Hr = E.T @ hess @ E - float(w @ grad) * np.eye(2)
        ev = np.linalg.eigvalsh(Hr)
        if ev[0] > 1e-12 * max(abs(ev[1]), 1e-300):
            d = -np.linalg.solve(Hr, g)
        else:
            d = -g * (0.05 / max(float(np.linalg.norm(g)), 1e-300))
        nd = float(np.linalg.norm(d))
        if nd > 0.2:
            d *= 0.2 / nd
            nd = 0.2
        if nd < 1e-9:
            break
        a = 1.0
        while a * nd >= 1e-10:
            wt = _unit(w + a * (E @ d))
            Pt, gt, ht = _sphere_derivatives(M, shapes, R, wt)
            if Pt < P:
                break
            a *= 0.5
        else:
            break
        w, P, grad, hess = wt, Pt, gt, ht
    return w, P


# ---------------------------------------------------------------------------------------------
# the lower bound
# ---------------------------------------------------------------------------------------------
def _one_dim_min(costs, w: np.ndarray, lu: np.ndarray, uu: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per parameter ``min over [lu_i, uu_i] of c_i(u) + w_i u`` (w >= 0): the value (a rigorous
    lower bound where the cost is not convex in u), the argmin, and ``1 / c_i''`` at an interior
    argmin (0 at a bound: the dual's Hessian)."""
    pl = costs.power_law()
    if pl is not None:
        k, a = pl
        with np.errstate(divide="ignore"):
            u = np.where(w > 0, np.log(np.maximum(a * k, 1e-300) / np.maximum(w, 1e-300)) / a, uu)
        inside = (u > lu) & (u < uu)
        u = np.clip(u, lu, uu)
        val = k * np.exp(-a * u) + w * u
        curv = np.where(inside, 1.0 / (a * a * k * np.exp(-a * u)), 0.0)
        return val, u, curv
    vals, us, curvs = np.empty(lu.size), np.empty(lu.size), np.zeros(lu.size)
    groups: dict = {}  # the parameters of one model object are minimised together, vectorised
    for i, m in enumerate(costs.models):
        groups.setdefault(id(m), (m, []))[1].append(i)
    for m, idx in groups.values():
        idx = np.asarray(idx)
        a, b, wi = lu[idx], uu[idx], w[idx]
        fixed = b - a <= 1e-12
        convex = np.array([f or m.convex_in_u(math.exp(x), math.exp(y)) for f, x, y in zip(fixed, a, b)])
        val, u, curv = _convex_min(m, wi, a, b)
        val = np.where(fixed, m.value(a) + wi * a, val)
        u = np.where(fixed, a, u)
        curv = np.where(fixed, 0.0, curv)
        for j in np.flatnonzero(~convex):  # a rigorous lower bound on a grid: c non-increasing, w u increasing
            grid = np.linspace(a[j], b[j], 2001)
            cv = m.value(grid)
            exact = cv + wi[j] * grid
            val[j] = min(float(np.min(cv[1:] + wi[j] * grid[:-1])), float(exact.min()))
            u[j], curv[j] = float(grid[np.argmin(exact)]), 0.0
        vals[idx], us[idx], curvs[idx] = val, u, curv
    return vals, us, curvs


def _eps_coordinates(costs, lu, uu) -> np.ndarray:
    """Per parameter: True where the cost is convex in eps but not in ``u = ln eps`` on its box."""
    if costs.power_law() is not None:
        return np.zeros(lu.size, dtype=bool)
    return np.array(
        [
            b - a > 1e-12 and not m.convex_in_u(math.exp(a), math.exp(b)) and convex_in_eps(m, math.exp(a), math.exp(b))
            for m, a, b in zip(costs.models, lu, uu)
        ]
    )


def _mixed_min(costs, w, lu, uu, lin) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_one_dim_min`, with ``min over [e^lu_i, e^uu_i] of c_i(eps) + w_i eps`` where ``lin``:
    the values, the minimisers in each parameter's coordinate, and ``1 / c_i''`` in it."""
    val, z, curv = _one_dim_min(costs, w, lu, uu)
    for i in np.flatnonzero(lin):
        m = costs.models[i]
        val[i], u = _linear_min(m, float(w[i]), float(lu[i]), float(uu[i]))
        z[i] = math.exp(u)
        c2 = float(m.d2u(np.array([u]))[0] - m.du(np.array([u]))[0])  # eps^2 d2c/deps2
        curv[i] = z[i] ** 2 / c2 if lu[i] < u < uu[i] and c2 > 0 else 0.0
    return val, z, curv


def _convex_min(m, w, a, b) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``min over [a, b] of c(u) + w u`` for one cost model convex in u, every element at once.
    The derivative increases: where it has one sign over the range the minimum is at an end;
    elsewhere Newton's method runs inside the bracket that its sign keeps (bisection where a step
    leaves it).  The interior value is a rigorous lower bound: by convexity the minimum is at
    least ``f(u) + f'(u) (x - u)`` with ``x`` the far end of the bracket on the minimiser's side."""
    ga, gb = m.du(a) + w, m.du(b) + w
    lo, hi = a.copy(), b.copy()
    u = np.where(gb <= 0, b, np.where(ga >= 0, a, 0.5 * (lo + hi)))
    live = (ga < 0) & (gb > 0)
    g = np.where(gb <= 0, gb, np.where(ga >= 0, ga, 0.0))
    for _ in range(60):
        if not live.any():
            break
        g = np.where(live, m.du(u) + w, g)
        lo = np.where(live & (g < 0), u, lo)
        hi = np.where(live & (g > 0), u, hi)
        # converged where the bound's slack |f'| (hi - lo) is at rounding level of the value
        live &= (g != 0) & (np.abs(g) * (hi - lo) > 1e-15 * (1.0 + np.abs(m.value(u) + w * u)))
        h = m.d2u(u)
        with np.errstate(divide="ignore", invalid="ignore"):
            newton = u - g / h
        inside = (h > 0) & (newton > lo) & (newton < hi)
        u = np.where(live, np.where(inside, newton, 0.5 * (lo + hi)), u)
    g = m.du(u) + w
    val = m.value(u) + w * u + np.where(g < 0, g * (hi - u), -g * (u - lo))
    c2 = m.d2u(u)
    interior = (u > a) & (u < b) & (c2 > 0)
    curv = np.where(interior, 1.0 / np.where(c2 > 0, c2, 1.0), 0.0)
    return val, u, curv


def half_space_bound(costs, lu, uu, u_star, c_rows, R_rows, p_rows, shapes, lam0) -> tuple[float, np.ndarray]:
    """The rigorous lower bound of the module docstring from the cuts ``c_rows`` (m, n) active at
    ``u_star`` (with their R and p), maximised over the multipliers from ``lam0``; returns
    ``(bound, lam)``."""
    lu, uu, u_star = (np.asarray(x, dtype=float) for x in (lu, uu, u_star))
    c_rows = np.atleast_2d(c_rows)
    m = c_rows.shape[0]
    if m == 0:
        val, _, _ = _one_dim_min(costs, np.zeros(lu.size), lu, uu)
        return math.fsum(val.tolist()), np.zeros(0)
    # each cut's half-space is taken where P = p (or just below): every tolerance scaled up by e^s
    P0, G0, _, _, _ = derivatives(c_rows, u_star, shapes, R_rows, tol=1e-12, hessian=False)
    slope = np.maximum(-G0.sum(axis=1), 1e-12)  # -dP/ds
    # no farther than the box reaches (a cut that stays above p there gives no half-space)
    reach_s = float(np.max(uu - u_star)) + 1.0
    s = np.minimum(np.maximum(P0 - p_rows, 0.0) / slope, reach_s)
    for _ in range(8):
        Ps, es_ = probability(c_rows * np.exp(u_star + s[:, None]), shapes, R_rows, 1e-11)
        over = Ps + es_ - p_rows
        if np.all(over <= 0):
            break
        s = np.minimum(s + np.maximum(over, 0.0) / slope * 1.5 + 1e-15, reach_s)
    else:
        Ps, es_ = probability(c_rows * np.exp(u_star + s[:, None]), shapes, R_rows, 1e-11)
    # the gradient to GRAD_TOL first (a tighter one needs up to 2^18 series terms a row on some
    # rows); its error bound widens the half-spaces by lam . delta, which the multipliers of a high p
    # (about 1 / (1 - p)) carry past the certificate's gap: then to the tolerance that keeps the
    # widening below WIDEN_SHARE of the cost
    # a cost convex in eps but not in u takes eps itself as its half-spaces' coordinate: the cut's set
    # is convex in any mix of eps and ln eps (convex in eps and closed downwards), and the dual's
    # one-dimensional minimum is then global and meets the cost at a KKT point
    lin = _eps_coordinates(costs, lu, uu)
    Us = u_star + s[:, None]
    Es = np.exp(Us)
    to_z = np.where(lin, 1.0 / Es, 1.0)  # d/dz = d/du / eps in an eps coordinate
    Zs = np.where(lin, Es, Us)
    reach = np.where(
        lin,
        np.maximum(np.abs(np.exp(lu) - Es), np.abs(np.exp(uu) - Es)),
        np.maximum(np.abs(lu - Us), np.abs(uu - Us)),
    )
    total = costs.total(u_star)
    if total is None:
        total = math.fsum(float(m.value(x)) for m, x in zip(costs.models, u_star))
    lam_abs = np.abs(np.asarray(lam0, dtype=float))
    tol = GRAD_TOL
    for _ in range(2):
        _, G, _, _, eG = derivatives(
            c_rows * np.exp(s)[:, None], u_star, shapes, R_rows, tol=tol, hessian=False, rigorous=True
        )
        delta = (eG * to_z * reach).sum(axis=1)
        widening, budget = float(lam_abs @ delta), WIDEN_SHARE * abs(total)
        if widening <= budget or tol <= MIN_GRAD_TOL:
            break
        tol = max(tol * 0.5 * budget / widening, MIN_GRAD_TOL)
    P, eP = Ps, es_
    hs = np.maximum(-G, 0.0) * to_z  # the true gradient is <= 0: clipping only moves the estimate closer
    cj = (hs * Zs).sum(axis=1) + delta
    if not np.all(P + eP <= p_rows):  # still above p after the search: that cut gives no half-space
        keep = P + eP <= p_rows
        hs, cj = hs[keep], cj[keep]
        lam0 = np.asarray(lam0, dtype=float)[keep]
        m = int(keep.sum())
        if m == 0:
            val, _, _ = _one_dim_min(costs, np.zeros(lu.size), lu, uu)
            return math.fsum(val.tolist()), np.zeros(0)

    def dual(lam):
        w = lam @ hs
        val, z, curv = _mixed_min(costs, w, lu, uu, lin)
        return math.fsum(val.tolist()) - float(lam @ cj), hs @ z - cj, -(hs * curv[None, :]) @ hs.T

    # any multipliers give a valid bound: the ascent stops once the bound is within 1e-8 of the
    # cost at u_star, far inside the certificate's 1e-6, or, while more than 1e-4 of it is missing
    # (no certificate in reach: the relaxation's own optimum lies lower, with a cost not convex in
    # u), once a step gains less than a thousandth of that (the last steps crept on for hundreds of
    # evaluations of milliseconds each)
    enough = total - 1e-8 * abs(total)
    lam = np.maximum(np.asarray(lam0, dtype=float), 0.0)
    best, grad, Hd = dual(lam)
    best_lam = lam
    for _ in range(40):  # projected Newton on the concave dual, gradient ascent where Newton stalls
        if best >= enough:
            break
        step = -np.linalg.lstsq(Hd - 1e-14 * np.abs(np.diag(Hd)).max() * np.eye(m), grad, rcond=None)[0]
        improved = False
        for direction in (step, grad * (np.abs(lam).max() + 1.0) / (np.abs(grad).max() + 1e-300)):
            if not np.all(np.isfinite(direction)):
                continue
            a = 1.0
            for _ in range(40):
                trial = np.maximum(lam + a * direction, 0.0)
                v, gr, Hn = dual(trial)
                if v > best:
                    improved = True
                    break
                a *= 0.5
            if improved:
                break
        if not improved:
            break
        gain = v - best
        lam, best, grad, Hd, best_lam = trial, v, gr, Hn, trial
        missing = enough - best
        if gain <= 1e-15 * abs(best) or (missing > 1e-4 * abs(total) and gain <= 1e-3 * missing):
            break
    return best, best_lam
