"""The farthest point of an error zonotope from its centre, exactly, in three dimensions.

With every error anywhere in its band, the hand's error is ``sum_i s_i c_i`` (``c_i = eps_i a_i``,
``|s_i| <= 1``): a zonotope.  Its farthest point from the origin, ``h = max_s |sum_i s_i c_i|``, is
a vertex (``|.|`` is convex), and the vertex that maximises ``w . x`` has the sign pattern
``s_i = sign(w . c_i)``.  The patterns are therefore the cells of the arrangement of the great
circles ``{w : w . c_i = 0}`` on the unit sphere, and there are O(n^2) of them, not 2^n
(/work/shared/GUARANTEES.md section 5; Edelsbrunner, *Algorithms in Combinatorial Geometry*, 1987,
on arrangements).

Every cell of an arrangement of at least two distinct circles has a vertex, and every vertex is
``+-(c_i x c_j) / |c_i x c_j|`` for two circles through it.  Around a vertex ``w0`` the cells are the
sectors between the circles through it, read in its tangent plane: a circle k through ``w0``
splits the tangent plane along the line orthogonal to the projection of ``c_k``; the midpoints of
consecutive critical angles are one direction per sector.  So the exact maximum takes the patterns
of every sector around every vertex (four at a vertex where only two circles cross), evaluates
``|C s|`` for each and keeps the largest; an ascent step ``s <- sign(C^T C s)``, which never lowers
``|C s|``, guards the rounding of nearly concurrent circles.  Zero columns play no part; parallel
columns give the same circle, which the sector reading handles.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["candidate_patterns", "zonotope_max", "zonotope_patterns"]

#: a column is zero when its norm is below this fraction of the largest column's
ZERO = 1e-14
#: two unit columns are parallel when the norm of their cross product is below this
PARALLEL = 1e-12
#: a circle passes through a vertex when |w0 . u_k| is below this (unit vectors)
TIGHT = 1e-10
#: most ascent steps after the enumeration (each never lowers the value; usually none move)
ASCENT = 8


def _signs(x: np.ndarray) -> np.ndarray:
    return np.where(x >= 0.0, 1.0, -1.0)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` of two 3-vectors (np.cross's checks cost more than the product here)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _pair_cross(U: np.ndarray):
    """The cross products of every pair of columns of ``U`` (i < j), their norms and the pairs."""
    i, j = np.triu_indices(U.shape[1], 1)
    a, b = U[:, i], U[:, j]
    X = np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]], axis=1)
    return X, np.sqrt(np.einsum("ij,ij->i", X, X)), i, j


def _merge_parallel(U: np.ndarray, xn, i, j) -> tuple[np.ndarray, np.ndarray]:
    """Parallel columns give one circle: each column's group (a representative) and its sign
    relative to the representative (the worst case aligns a group: one generator)."""
    parent = np.arange(U.shape[1])

    def root(k):
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    for a, b in zip(i[xn <= PARALLEL].tolist(), j[xn <= PARALLEL].tolist()):
        ra, rb = root(a), root(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    rep = np.array([root(k) for k in range(U.shape[1])])
    sign = _signs(np.einsum("ij,ij->j", U, U[:, rep]))
    return rep, sign


def _sector_patterns(w0: np.ndarray, U: np.ndarray, tight: np.ndarray, base: np.ndarray) -> np.ndarray:
    """The sign patterns of the cells around the vertex ``w0``: ``base`` outside ``tight``, and
    inside it one pattern per sector of the tangent plane between the circles through ``w0``."""
    e1 = _cross(w0, np.eye(3)[int(np.argmin(np.abs(w0)))])
    e1 /= math.sqrt(e1 @ e1)
    e2 = _cross(w0, e1)
    idx = np.nonzero(tight)[0]
    P = np.stack([e1 @ U[:, idx], e2 @ U[:, idx]])  # 2 x t projections
    phi = np.arctan2(P[1], P[0])
    crit = np.sort(np.mod(np.concatenate([phi + 0.5 * math.pi, phi - 0.5 * math.pi]), 2 * math.pi))
    gaps = np.diff(np.concatenate([crit, [crit[0] + 2 * math.pi]]))
    mids = (crit + 0.5 * gaps)[gaps > 1e-13]
    T = np.stack([np.cos(mids), np.sin(mids)], axis=1)  # one direction per sector
    out = np.repeat(base[None, :], len(mids), axis=0)
    out[:, idx] = _signs(T @ P)
    return out


def candidate_patterns(C: np.ndarray, unique: bool = False) -> np.ndarray:
    """Every candidate sign pattern (rows, +-1) of the zonotope ``{C s : |s| <= 1}``, ``C`` 3 x n:
    those of the cells of the arrangement of great circles (module docstring), O(n^2) rows
    (``unique``: without repeats).  They depend on the columns' directions only, so one set
    serves every positive scaling of the columns (every tolerance vector)."""
    C = np.asarray(C, dtype=float)
    n = C.shape[1]
    norms = np.sqrt(np.einsum("ij,ij->j", C, C))
    big = float(norms.max()) if n else 0.0
    live = np.nonzero(norms > ZERO * big)[0] if big > 0 else np.zeros(0, dtype=int)
    if len(live) == 0:
        return np.ones((1, n))
    U = C[:, live] / norms[live]
    X, xn, i, j = _pair_cross(U)
    rep, sign = _merge_parallel(U, xn, i, j)
    reps, group = np.unique(rep, return_inverse=True)
    S = _distinct(U[:, reps])  # one generator per group of parallel columns
    out = np.ones((len(S), n))
    out[:, live] = S[:, group] * sign
    return np.unique(out, axis=0) if unique else out


def _distinct(U: np.ndarray) -> np.ndarray:
    """:func:`candidate_patterns` on unit columns no two of which are parallel."""
    X, xn, i, j = _pair_cross(U)
    keep = xn > PARALLEL
    if not keep.any():  # one column: the vertex is the column itself
        return np.ones((1, U.shape[1]))
    W = X[keep] / xn[keep, None]
    W = np.concatenate([W, -W])
    pi, pj = np.concatenate([i[keep], i[keep]]), np.concatenate([j[keep], j[keep]])
    D = W @ U
    tight = np.abs(D) <= TIGHT
    base = _signs(D)
    simple = tight.sum(axis=1) <= 2
    rows = []
    if simple.any():  # two circles cross: the four cells around the vertex
        B, a, b = base[simple], pi[simple], pj[simple]
        r = np.arange(len(B))
        for sa in (1.0, -1.0):
            for sb in (1.0, -1.0):
                S = B.copy()
                S[r, a], S[r, b] = sa, sb
                rows.append(S)
    if (~simple).any():  # several circles through one vertex: the sectors between them
        multi = np.nonzero(~simple)[0]
        _, first = np.unique(np.round(W[multi], 9), axis=0, return_index=True)
        rows += [_sector_patterns(W[v], U, tight[v], base[v]) for v in multi[first]]
    return np.concatenate(rows)


def zonotope_patterns(
    C: np.ndarray, top: int | None = None, patterns: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(values, patterns)``: the candidate patterns (``patterns`` if given, else
    :func:`candidate_patterns`) with ``|C s|``, distinct, largest first; the ``top`` largest."""
    C = np.asarray(C, dtype=float)
    S = candidate_patterns(C) if patterns is None else patterns
    V = S @ C.T
    vals = np.sqrt(np.einsum("ij,ij->i", V, V))
    order = np.argsort(-vals, kind="stable")
    out, seen = [], set()
    for k in order.tolist():
        key = S[k].tobytes()
        if key in seen:
            continue
        seen.add(key)
        out.append(k)
        if top is not None and len(out) >= top:
            break
    return vals[out], S[out]


def zonotope_max(C: np.ndarray, patterns: np.ndarray | None = None) -> tuple[float, np.ndarray, np.ndarray]:
    """``(h, s, w)``: the farthest point's distance ``h = max |C s|`` over ``|s_i| <= 1``, its sign
    pattern ``s`` and its direction ``w = C s / h`` (any unit vector when h = 0); ``C`` 3 x n,
    ``patterns`` the candidates of its columns' directions if known (:func:`candidate_patterns`)."""
    C = np.asarray(C, dtype=float)
    S = candidate_patterns(C) if patterns is None else patterns
    V = S @ C.T
    vals = np.einsum("ij,ij->i", V, V)
    k = int(np.argmax(vals))
    s, best = S[k].copy(), float(vals[k])
    for _ in range(ASCENT):  # s <- sign(C^T v) maximises v . C s', so |C s'| >= |v|
        t = C.T @ (C @ s)
        s_new = np.where(t > 0, 1.0, np.where(t < 0, -1.0, s))
        val = float((C @ s_new) @ (C @ s_new))
        if val <= best or np.array_equal(s_new, s):
            break
        s, best = s_new, val
    h = math.sqrt(best)
    v = C @ s
    w = v / h if h > 0 else np.eye(C.shape[0])[0]
    return h, s, w
