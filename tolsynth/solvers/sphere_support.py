"""A lower bound on the Gaussian sphere criterion's cost from a proven supporting hyperplane.

With Gaussian errors ``P(|dr| <= R)`` depends on the variances ``lambda`` of the principal
components alone, ``F(lambda) = P(sum_j lambda_j Z_j^2 <= R^2)``, which falls as any ``lambda_j``
grows (Anderson's theorem).  Take weights ``g_1 >= g_2 >= g_3 >= 0`` (here ``-d ln F / d lambda`` at
the design's variances, sorted) and ``K(V) = sum_j g_j lambda_[j](V)`` (eigenvalues in descending
order): a positive combination of Ky Fan sums, convex and positively homogeneous in ``V``, and
``V`` is linear in ``s = eps^2``.  If ``c`` bounds ``sum_j g_j lambda_j`` over every sorted
``lambda`` with ``F(lambda) >= p``, every design that meets the sphere has ``K(V(s)) <= c``, and so
``G . s <= K(V(s)) <= c`` with ``G`` the gradient of ``K`` at any point (the subgradient inequality
and Euler's relation ``K(s*) = G . s*``): a half-space, whose cheapest point within the bounds is
the separable problem of :func:`.sphere_bound.half_space_bound`.

``c`` is proven by a branch and bound over the rays ``lambda = r (1, u, w)``, ``1 >= u >= w >= 0``:
along a ray F falls with r, so each ray leaves the set at one ``r(u, w)``, bracketed by the
error-controlled :func:`tolsynth.probability.stats.p_ball_batch` (its upper end has ``P + error <
p``); ``r`` falls as u or w grows, so over a cell ``[u0, u1] x [w0, w1]`` the weighted sum is at
most ``r_up(u0, w0) (g_1 + g_2 u1 + g_3 w1)``.  Cells whose bound is within ``rtol`` of the best
value found are closed, the others split in four.  Where the design's variances maximise the
weighted sum over the set (its tangent plane supports the set: found at p = 0.9 and 0.99 on the
paper's robot, not at p = 0.5 or 0.7, where the set is not convex), the bound is the design's cost
to within about ``rtol`` times the cost's elasticity.
"""

from __future__ import annotations

import math

import numpy as np

from tolsynth.probability.stats import p_ball, p_ball_batch, z_of_p
from tolsynth.problem.nlp import ToleranceNLP
from tolsynth.solvers.sphere_bound import half_space_bound

__all__ = ["support_bound", "weighted_maximum"]

#: the branch and bound closes a cell within this fraction of the best weighted sum found (the
#: bound then falls short of the cost by about a third of it: 1e-3 costs ten times the rays)
RTOL = 1e-2
#: and stops (its bound is then the largest open cell's) after this many rays
MAX_RAYS = 20_000


def _rays(U, W, R: float, p: float, r0, r1, tol: float = 1e-9):
    """Per ray ``lambda = r (1, u, w)``: ``(r_in, r_out)`` with ``P(r_in ...) >= p`` by the
    evaluator and ``P(r_out ...) + error < p`` (so no r beyond r_out meets p), to ``tol`` relative;
    regula falsi (Illinois) on ln r from the brackets ``[r0, r1]`` (arrays)."""
    n = U.size
    a, b = np.log(np.broadcast_to(r0, (n,))).copy(), np.log(np.broadcast_to(r1, (n,))).copy()
    fa, fb = np.full(n, 1.0 - p), np.full(n, -1e-3 * (1.0 - p))
    side = np.zeros(n)
    for _ in range(60):
        act = b - a > tol
        if not act.any():
            break
        i = np.flatnonzero(act)
        with np.errstate(divide="ignore", invalid="ignore"):  # equal ends: the midpoint instead
            x = (a[i] * fb[i] - b[i] * fa[i]) / (fb[i] - fa[i])
        x = np.where((x > a[i]) & (x < b[i]), x, 0.5 * (a[i] + b[i]))
        r = np.exp(x)
        P, err = p_ball_batch(np.column_stack([r, r * U[i], r * W[i]]), R, tol=1e-9, return_error=True)
        out = P + err < p
        j, k = i[out], i[~out]
        b[j], fb[j] = x[out], P[out] - p
        fa[j] = np.where(side[j] == 1, 0.5 * fa[j], fa[j])
        a[k], fa[k] = x[~out], P[~out] - p
        fb[k] = np.where(side[k] == -1, 0.5 * fb[k], fb[k])
        side[j], side[k] = 1, -1
    return np.exp(a), np.exp(b)


def weighted_maximum(g, R: float, p: float, rtol: float = RTOL, max_rays: int = MAX_RAYS) -> tuple[float, float]:
    """``(proven, found)``: an upper bound on ``sum_j g_j lambda_j`` over sorted variances with
    ``P(sum_j lambda_j Z_j^2 <= R^2) >= p`` (``g`` descending, >= 0), and the largest value found
    at a point of the set (module docstring)."""
    from scipy.stats import chi2  # scipy.stats loads in over half a second: only when asked

    g = np.asarray(g, dtype=float)
    vp = (R / z_of_p(p)) ** 2  # lambda_1 <= v_p: the ball lies in the slab of the first component
    r0, r1 = R * R / float(chi2.ppf(p, 3)), vp * (1 + 1e-9)  # (1, u, w) <= (1, 1, 1): r0 meets p
    k = 16
    e = np.linspace(0.0, 1.0, k + 1)
    u0, w0 = (a.ravel() for a in np.meshgrid(e[:-1], e[:-1], indexing="ij"))
    h = np.full(u0.size, 1.0 / k)
    keep = w0 <= u0 + h  # cells that meet the sorted triangle w <= u
    u0, w0, h = u0[keep], w0[keep], h[keep]
    best, closed, rays = 0.0, 0.0, 0
    hi = np.full(u0.size, r1)
    while u0.size:
        r_in, r_out = _rays(u0, w0, R, p, r0, hi, 1e-3 * rtol)
        rays += u0.size
        best = max(best, float(np.max(r_in * (g[0] + g[1] * u0 + g[2] * np.minimum(w0, u0)))))
        ub = r_out * (g[0] + g[1] * np.minimum(u0 + h, 1.0) + g[2] * np.minimum(np.minimum(w0, u0) + h, 1.0))
        done = ub <= best * (1 + rtol)
        closed = max(closed, float(np.max(ub[done], initial=0.0)))
        if rays >= max_rays:
            return max(closed, float(np.max(ub, initial=0.0))), best
        u0, w0, h, hi = u0[~done], w0[~done], h[~done] / 2, r_out[~done]
        u0 = np.concatenate([u0, u0 + h, u0, u0 + h])
        w0 = np.concatenate([w0, w0, w0 + h, w0 + h])
        h, hi = np.tile(h, 4), np.tile(hi, 4)  # a child's corner is above its parent's: its ray leaves sooner
        keep = (w0 <= u0 + h) & (u0 < 1.0) & (w0 < 1.0)
        u0, w0, h, hi = u0[keep], w0[keep], h[keep], hi[keep]
    return closed, best  # every cell closed: none holds a larger value


def _weights(lam: np.ndarray, R: float) -> np.ndarray:
    """``-d ln P / d lambda_j`` at the variances (central differences of p_ball), sorted
    descending and >= 0: any such weights give a valid bound; these make it tight."""
    g = np.zeros(3)
    for j in range(3):
        d = np.zeros(3)
        d[j] = 1e-5 * lam[0]
        g[j] = -(math.log(p_ball(lam + d, R)) - math.log(p_ball(np.maximum(lam - d, 0.0), R))) / (2 * d[j])
    return np.sort(np.maximum(g, 0.0))[::-1]


def support_bound(nlp: ToleranceNLP, eps, rtol: float = RTOL) -> float:
    """A rigorous lower bound on the Gaussian sphere problem's cost from the proven supporting
    half-space at ``eps`` of every sphere block (module docstring); other constraints left out."""
    spec = nlp.spec
    s = np.asarray(eps, dtype=float) ** 2
    rows, rhs = [], []
    for b in spec.sphere_blocks:
        A, R, p = np.asarray(b.A, dtype=float), float(b.R), float(b.p)
        V = (A * (s / spec.c)) @ A.T
        lam, vec = np.linalg.eigh(0.5 * (V + V.T))
        lam, vec = np.maximum(lam[::-1], 0.0), vec[:, ::-1]
        g = _weights(lam, R)
        if not (np.all(np.isfinite(g)) and g[0] > 0):  # P is 1 to rounding here: leave the block out
            continue
        c, _ = weighted_maximum(g / g[0], R, p, rtol)
        rows.append((((vec.T @ A) ** 2) * (g / g[0])[:, None]).sum(axis=0) / spec.c)  # G = grad K at s
        rhs.append(c)
    return half_space_bound(nlp, np.array(rows), np.array(rhs)) if rows else -math.inf
