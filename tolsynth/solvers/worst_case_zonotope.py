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

__all__ = ["zonotope_max", "zonotope_patterns"]

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


def _sector_patterns(w0: np.ndarray, U: np.ndarray, tight: np.ndarray, base: np.ndarray) -> np.ndarray:
    """The sign patterns of the cells around the vertex ``w0``: ``base`` outside ``tight``, and
    inside it one pattern per sector of the tangent plane between the circles through ``w0``."""
    h = np.eye(3)[int(np.argmin(np.abs(w0)))]
    e1 = np.cross(w0, h)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(w0, e1)
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


def _candidates(C: np.ndarray) -> tuple[np.ndarray, list]:
    """Values ``|C s|^2`` of every candidate pattern and a way to rebuild each pattern: rows of
    ``(base, columns set, their signs)`` kept compact (the four cells around a simple vertex
    differ from the vertex's own signs in two entries only)."""
    n = C.shape[1]
    norms = np.linalg.norm(C, axis=0)
    big = float(norms.max()) if n else 0.0
    live = np.nonzero(norms > ZERO * big)[0] if big > 0 else np.zeros(0, dtype=int)
    if len(live) == 0:
        return np.zeros(1), lambda k: np.ones(n)
    Cl = C[:, live]
    U = Cl / norms[live]
    i, j = np.triu_indices(len(live), 1)
    X = np.cross(U[:, i].T, U[:, j].T)
    xn = np.linalg.norm(X, axis=1)
    keep = xn > PARALLEL
    groups = []  # (values, function index -> pattern on the live columns)
    if not keep.any():  # every column on one line: the vertex is the columns aligned
        s = _signs(U[:, 0] @ U)
        v = Cl @ s
        groups.append((np.array([v @ v]), lambda k, s=s: s))
    else:
        W = X[keep] / xn[keep, None]
        W = np.concatenate([W, -W])
        pi, pj = np.concatenate([i[keep], i[keep]]), np.concatenate([j[keep], j[keep]])
        D = W @ U
        tight = np.abs(D) <= TIGHT
        base = _signs(D)
        simple = tight.sum(axis=1) <= 2
        if simple.any():  # two circles cross: the four cells around the vertex
            B, a, b = base[simple], pi[simple], pj[simple]
            V0 = B @ Cl.T - B[np.arange(len(B)), a, None] * Cl[:, a].T - B[np.arange(len(B)), b, None] * Cl[:, b].T
            combos = ((1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0))
            V = np.stack([V0 + sa * Cl[:, a].T + sb * Cl[:, b].T for sa, sb in combos], axis=1)  # m x 4 x 3
            vals = np.einsum("mkd,mkd->mk", V, V).ravel()

            def simple_pattern(k, B=B, a=a, b=b):
                m, c = divmod(int(k), 4)
                s = B[m].copy()
                s[a[m]], s[b[m]] = combos[c]
                return s

            groups.append((vals, simple_pattern))
        if (~simple).any():  # several circles through one vertex: the sectors between them
            multi = np.nonzero(~simple)[0]
            _, first = np.unique(np.round(W[multi], 9), axis=0, return_index=True)
            S = np.concatenate([_sector_patterns(W[v], U, tight[v], base[v]) for v in multi[first]])
            V = S @ Cl.T
            groups.append((np.einsum("ij,ij->i", V, V), lambda k, S=S: S[int(k)].copy()))
    vals = np.concatenate([g[0] for g in groups])
    offsets = np.cumsum([0] + [len(g[0]) for g in groups])

    def pattern(k):
        gi = int(np.searchsorted(offsets, k, side="right")) - 1
        s = np.ones(n)
        s[live] = groups[gi][1](k - offsets[gi])
        return s

    return vals, pattern


def zonotope_patterns(C: np.ndarray, top: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(values, patterns)``: candidate sign patterns (rows, +-1) of the zonotope ``{C s : |s| <= 1}``,
    ``C`` 3 x n, those of the cells of the arrangement of great circles (module docstring; O(n^2)
    of them), with ``|C s|``; the ``top`` largest distinct ones, largest first (None: all)."""
    C = np.asarray(C, dtype=float)
    vals, pattern = _candidates(C)
    order = np.argsort(-vals, kind="stable")
    out, seen = [], set()
    for k in order:
        s = pattern(k)
        key = s.tobytes()
        if key in seen:
            continue
        seen.add(key)
        out.append(s)
        if top is not None and len(out) >= top:
            break
    S = np.array(out)
    V = S @ C.T
    return np.sqrt(np.einsum("ij,ij->i", V, V)), S


def zonotope_max(C: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """``(h, s, w)``: the farthest point's distance ``h = max |C s|`` over ``|s_i| <= 1``, its sign
    pattern ``s`` and its direction ``w = C s / h`` (any unit vector when h = 0); ``C`` 3 x n."""
    C = np.asarray(C, dtype=float)
    vals, pattern = _candidates(C)
    k = int(np.argmax(vals))
    s = pattern(k)
    best = float((C @ s) @ (C @ s))
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
