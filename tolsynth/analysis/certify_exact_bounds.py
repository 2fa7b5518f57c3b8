"""Lower bounds of the exact per-direction probability over (joint box, direction patch) pairs.

Along a unit direction ``u`` the hand error is ``u . dr = sum_i b_i Y_i`` with ``b_i = eps_i u . a_i(q)``
and ``Y_i`` independent on [-1, 1] with the parameters' shapes.  For symmetric log-concave ``Y_i``
the set ``{b : P(|b . Y| <= R) >= t}`` is convex for every level t (Lagoa, Li & Sznaier 2005) and,
as ``P`` falls when any ``|b_i|`` grows (Anderson's theorem), it is closed downwards in ``|b|``:
``P`` is quasi-concave in ``b``, and stays so after any ``|b_i|`` is raised by a constant.

* A joint box (centre ``c``, half-widths ``r``) gives ``A(c + d) = A(c) + J(c) d + E`` with the
  remainder ``|E|`` from an interval bound of the second derivatives over the box, or of the third
  with the Hessian at the centre where that is tighter (:func:`taylor_enclosure`); the affine
  part's corners are the box's vertices, cut by the joint constraints.
* A direction patch is the cone over a square of a cube face (``u`` and ``-u`` give the same
  probability, so three faces suffice) with corner rays ``v_k``; with ``n`` a unit vector inside
  it, every direction of the patch is ``x / |x|`` for an ``x`` of the quadrilateral of the points
  ``v_k / (n . v_k)``, all on the plane ``n . x = 1`` and so outside the unit ball: ``b(x) =
  |x| b(x / |x|)`` is larger, and ``P`` there smaller.
* Over the product, ``b`` is bilinear in (joint corner, point of the quadrilateral) plus the
  remainder, so the smallest probability is at one of the pairs of vertices, with ``|b_i|``
  raised by the remainder's part ``eps_i sum_r |E_ri| max_k |v_kr| / (n . v_k)``.

The corners are settled cheaply first: at the interval hull of the joint corners (one evaluation
per patch corner), at the corner of largest variance (the likeliest to fail), then in groups by
their side of the centre along the joints that move ``A`` most, each group at its largest
``|b_i|`` (``|y + sum_j s_j g_j|`` over the signs of the free joints is at most ``|y + fixed part| +
sum_free |g_j|``, coordinate by coordinate), halving the failing groups joint by joint.  Every
probability is the compiled series (:func:`tolsynth.solvers.exact_series.probability`) with its
rigorous error bound subtracted.
"""

from __future__ import annotations

import math

import numpy as np

from tolsynth.analysis.certify_bounds import JointGraphs
from tolsynth.analysis.interval_ops import round_up as _up
from tolsynth.solvers.exact_series import probability

__all__ = ["ExactBounds", "start_patches", "children", "patch_normals"]

_U = 2.0**-53
#: error allowed in each exact probability the search evaluates
EVAL_TOL = 1e-10
#: the tolerances a row is evaluated to, in turn, until one settles it against the threshold: 87 %
#: of the paper robot's rows lie more than 1e-5 from it, and a row to 1e-5 costs 60 % of one to
#: 1e-7 (its exact proof: the series' time 10.5 -> 6.8 s, the same boxes and bound)
TOLS = (1e-5, 1e-7, EVAL_TOL)
#: patches per cube face side at the start
START_GRID = 2
#: joints whose sides group the corners of a box crossed by a joint constraint (2^levels groups)
GROUP_LEVELS = 3
#: a lifted direction's rounding is covered by raising every coefficient by this relative amount
_LIFT_SLACK = 1e-13
#: relative rounding allowed for the sums forming a coefficient bound (a few dozen roundings)
_SUM_SLACK = 1e-14

_E = np.eye(3)
_FRAMES = np.array([(_E[a], _E[(a + 1) % 3], _E[(a + 2) % 3]) for a in range(3)])  # face, (n, s, t), xyz
_STEPS = np.array([(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)])


def _rays(face, s0, t0, h):
    """Corner rays (n, 4, 3) of the patches (exact: dyadic face coordinates)."""
    F = _FRAMES[face]
    s = s0[:, None] + _STEPS[None, :, 0] * h[:, None]
    t = t0[:, None] + _STEPS[None, :, 1] * h[:, None]
    return F[:, None, 0] + s[..., None] * F[:, None, 1] + t[..., None] * F[:, None, 2]


def _lift(V):
    """Per patch the unit ``n`` inside it and the factors ``1 / (n . v_k)`` (n, 4), raised to cover
    their rounding and ``|n| != 1``: the lifted corners lie on a plane outside the unit ball."""
    U = V / np.linalg.norm(V, axis=2, keepdims=True)
    n = U.sum(axis=1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return n, (1.0 + _LIFT_SLACK) / np.einsum("pkx,px->pk", V, n)


class ExactBounds:
    """Lower bounds of the exact per-direction probability over (joint box, direction patch) pairs.

    Parameters
    ----------
    enc : JointGraphs
    eps : ndarray
        Tolerances of the kept columns (tolerance units).
    shapes : tuple
        The shape of every kept column.
    R : float
    linear : tuple
        Joint constraints ``(a, lo, hi)`` over the searched joints.
    """

    def __init__(self, enc: JointGraphs, eps, shapes, R: float, linear=()):
        self.enc = enc
        self.m = enc.m
        self.eps = np.asarray(eps, dtype=float)
        self.shapes = tuple(shapes)
        self.R = float(R)
        self.linear = tuple(linear)
        self.bounded = all(s.name != "normal" for s in self.shapes)
        self.var = np.array([s.variance for s in self.shapes])
        self.evaluations = 0

    def lower(self, B: np.ndarray, thr: float = -math.inf) -> np.ndarray:
        """Rigorous lower bounds of P at rows of coefficients ``B`` (n, m) (upper bounds of ``|b|``),
        to the precision that settles each against ``thr``: a sum of bounded errors that cannot
        leave R (P = 1); else the series to each tolerance of :data:`TOLS` in turn while that leaves
        the row within its error of ``thr``."""
        out = np.ones(len(B))
        if len(B) == 0:
            return out
        todo = np.flatnonzero(~(self.bounded & (B.sum(axis=1) * (1.0 + 4 * self.m * _U) <= self.R)))
        if todo.size:
            rows = todo
            low = np.empty(todo.size)
            at = np.arange(todo.size)
            for tol in TOLS:  # each row to the first precision that settles it against thr
                P, err = probability(B[rows], self.shapes, self.R, tol)
                low[at] = P - err - 4.0 * _U
                self.evaluations += rows.size
                near = (low[at] < thr) & (P + err + 4.0 * _U >= thr)
                rows, at = rows[near], at[near]
                if rows.size == 0:
                    break
            out[todo] = np.maximum(low, 0.0)
        return out

    def point(self, X: np.ndarray, U: np.ndarray) -> np.ndarray:
        """P at joint points X (n, k) along unit directions U (n, 3) (floating point: a value found,
        not a bound)."""
        A = self.enc.values(X)
        B = np.abs(np.einsum("nrm,nr->nm", A, U)) * self.eps
        P, _ = probability(B, self.shapes, self.R, EVAL_TOL)
        return P

    def _vertex_pairs(self, Bc, use, bits, lb, thr):
        """The pairs' bound from every (joint corner, direction vertex), settled group by group: the
        corners on one side of the centre along the joint moving A most, then along the next, ...,
        each group bounded at its largest ``|b_i|`` (monotone: one evaluation a direction vertex
        proves all of its corners), and only the corners of groups that fail one by one.  A pair
        found to fail keeps its bound ``lb`` (valid, looser), which only orders the search."""
        p, C, K, m = Bc.shape
        done = ~use.copy()  # (p, C) corners settled (or not used)
        low = np.full(p, np.inf)
        # first the corner of largest variance at each direction vertex: the likeliest to fail
        score = np.where(use[:, :, None], np.einsum("pckm,m->pck", Bc**2, self.var), -np.inf)
        top = np.argmax(score, axis=1)  # (p, K)
        first = np.take_along_axis(Bc, top[:, None, :, None], axis=1)[:, 0]  # (p, K, m)
        val = self.lower(first.reshape(-1, m), thr).reshape(p, K)
        alive = (val >= thr).all(axis=1)
        low = np.minimum(low, val.min(axis=1))
        pair = np.repeat(np.arange(p), C)
        for t in range(1, bits.shape[2] + 1):
            G = 1 << t
            live = ~done & alive[:, None]
            if not live.any():
                break
            # the groups of each pair contiguous (settled corners last): one maximum per run
            code = np.where(live, (bits[:, :, :t] * (1 << np.arange(t))).sum(axis=2), G)
            order = np.argsort(code, axis=1, kind="stable")
            flat = np.take_along_axis(code, order, axis=1).ravel()
            new = np.ones(p * C, dtype=bool)
            new[1:] = (flat[1:] != flat[:-1]) | (pair[1:] != pair[:-1])
            starts = np.flatnonzero(new)
            Bs = np.take_along_axis(Bc, order[:, :, None, None], axis=1).reshape(p * C, K, m)
            mags = np.maximum.reduceat(Bs, starts, axis=0)
            sp, sc = pair[starts], flat[starts]
            size = np.diff(np.append(starts, p * C))
            keep = sc < G
            mags, sp, sc, size = mags[keep], sp[keep], sc[keep], size[keep]
            val = self.lower(mags.reshape(-1, m), thr).reshape(-1, K).min(axis=1)
            ok = val >= thr
            np.minimum.at(low, sp[ok], val[ok])
            settled = np.zeros((p, G + 1), dtype=bool)
            settled[sp[ok], sc[ok]] = True
            done |= np.take_along_axis(settled, code, axis=1)
            alive[sp[~ok & (size == 1)]] = False  # one corner below the threshold: the pair fails
        rest = ~done & alive[:, None]
        if rest.any():
            pi, ci = np.nonzero(rest)
            val = self.lower(Bc[pi, ci].reshape(-1, m), thr).reshape(-1, K).min(axis=1)
            np.minimum.at(low, pi, val)
            bad = np.zeros(p, dtype=bool)
            bad[pi[val < thr]] = True
            alive &= ~bad
        return np.where(alive, np.minimum(low, 1.0), lb)

    def _tree(self, y0, G, order, base, lb, thr):
        """Non-crossed boxes: the pairs' bound over every joint corner from the centre's image
        ``y0`` (p, 4, m) and each joint's ``G_j = r_j J_j^T x`` (p, 4, k, m): first the corner of
        largest variance, then groups with the sides of the most moving joints fixed, halved where
        they fail (a group at ``|y0 + fixed part| + sum_free |G_j|``, its largest ``|b_i|``)."""
        p, K, k, m = G.shape
        aG = np.abs(G)
        w = self.var * self.eps**2
        sign = np.where(np.matmul(G, (y0 * w)[..., None])[..., 0] >= 0.0, 1.0, -1.0)
        first = np.abs(y0 + np.matmul(sign[:, :, None, :], G)[:, :, 0, :]) + base
        val = self.lower(self._rows(first), thr).reshape(p, K).min(axis=1)
        alive = val >= thr
        low = np.where(alive, val, np.inf)
        gp = np.flatnonzero(alive)
        S, F = y0[gp], aG[gp].sum(axis=2)
        for t in range(k):
            if gp.size == 0:
                break
            j = order[gp, t]
            Gj = G[gp, :, j, :]
            gp = np.repeat(gp, 2)
            S = np.repeat(S, 2, axis=0) + np.tile(np.array([1.0, -1.0]), len(Gj))[:, None, None] * np.repeat(
                Gj, 2, axis=0
            )
            F = np.maximum(np.repeat(F - np.abs(Gj), 2, axis=0), 0.0)
            keep = alive[gp]
            gp, S, F = gp[keep], S[keep], F[keep]
            val = self.lower(self._rows(np.abs(S) + F + base[gp]), thr).reshape(-1, K).min(axis=1)
            ok = val >= thr
            np.minimum.at(low, gp[ok], val[ok])
            if t == k - 1:
                alive[gp[~ok]] = False  # a single corner below the threshold: the pair fails
            gp, S, F = gp[~ok], S[~ok], F[~ok]
        return np.where(alive, np.minimum(low, 1.0), lb)

    def _rows(self, X):
        """Coefficient bounds ``(..., m)`` as rows, raised to cover the lift's rounding, in units."""
        return _up(X * (1.0 + _LIFT_SLACK) * self.eps).reshape(-1, self.m)

    def pairs(self, enc, bi, face, s0, t0, h, thr):
        """Lower bounds (n,) on the pairs (joint box ``bi`` of the :class:`Enclosure`, patch), the lift
        excess and the remainder's relative size of each (where to refine)."""
        m, k, p = self.m, self.enc.k, len(bi)
        V = _rays(face, s0, t0, h)
        _, scale = _lift(V)
        lift = (np.linalg.norm(V, axis=2) * scale).max(axis=1) - 1.0
        Vs = V * scale[..., None]  # the lifted corners (p, 4, 3)
        reach = np.abs(Vs).max(axis=1)  # (p, 3): the largest |x_r| on the quadrilateral
        e = np.einsum("pmr,pr->pm", enc.E[bi].reshape(p, m, 3), reach)
        am = enc.am[bi].reshape(p, m, 3)
        Jr = (enc.Jm[bi] * enc.r[bi][:, :, None]).reshape(p, k, m, 3)
        # products as matmul (einsum's loops took four to six times as long)
        y0 = np.matmul(Vs, am.transpose(0, 2, 1))  # (p, 4, m)
        G = np.ascontiguousarray(
            np.matmul(Jr.reshape(p, k * m, 3), Vs.transpose(0, 2, 1)).reshape(p, k, m, 4).transpose(0, 3, 1, 2)
        )  # (p, 4, k, m)
        # every sum below is of these terms: their rounding is a small multiple of their absolute sum
        size = np.matmul(np.abs(Vs), (np.abs(am) + np.abs(Jr).sum(axis=1)).transpose(0, 2, 1))
        base = e[:, None, :] + _SUM_SLACK * size
        lb = self.lower(self._rows(np.abs(y0) + np.abs(G).sum(axis=2) + base), thr).reshape(p, 4).min(axis=1)
        todo = enc.ok[bi] & (lb < thr)
        plain = np.flatnonzero(todo & ~enc.cross[bi])
        if plain.size:
            lb[plain] = self._tree(y0[plain], G[plain], enc.order[bi[plain]], base[plain], lb[plain], thr)
        crossed = np.flatnonzero(todo & enc.cross[bi])
        if crossed.size:  # the feasible part's own corners
            bt = bi[crossed]
            Yb = enc.Y[bt].reshape(crossed.size, enc.Y.shape[1], m, 3)
            nc = Yb.shape[1]
            Z = np.matmul(Yb.reshape(crossed.size, nc * m, 3), Vs[crossed].transpose(0, 2, 1))
            Z = np.abs(Z.reshape(crossed.size, nc, m, 4).transpose(0, 1, 3, 2)) + base[crossed][:, None]
            Bc = _up(Z * (1.0 + _LIFT_SLACK) * self.eps)
            bits = enc.bits[bt][:, :, :GROUP_LEVELS]
            lb[crossed] = self._vertex_pairs(Bc, enc.use[bt], bits, lb[crossed], thr)
        lb = np.where(enc.ok[bi], lb, 0.0)
        centre = np.abs(y0).max(axis=1)  # (p, m) a typical coefficient vector
        rel = np.linalg.norm(e * self.eps, axis=1) / np.maximum(np.linalg.norm(centre * self.eps, axis=1), 1e-300)
        return lb, lift, np.where(enc.ok[bi], rel, np.inf)


def patch_normals(face, s0, t0, h):
    """The unit vector inside each patch that its lift uses (n, 3)."""
    return _lift(_rays(face, s0, t0, h))[0]


def start_patches():
    g = np.arange(START_GRID) * (2.0 / START_GRID) - 1.0
    S, T = np.meshgrid(g, g, indexing="ij")
    face = np.repeat(np.arange(3), S.size)
    return face, np.tile(S.ravel(), 3), np.tile(T.ravel(), 3), np.full(face.size, 2.0 / START_GRID)


def children(face, s0, t0, h):
    """Each patch's four quarters (exact: halving a dyadic square)."""
    hh = 0.5 * h
    ds = np.array([0.0, 1.0, 0.0, 1.0])
    dt = np.array([0.0, 0.0, 1.0, 1.0])
    return (
        np.repeat(face, 4),
        (s0[:, None] + ds * hh[:, None]).ravel(),
        (t0[:, None] + dt * hh[:, None]).ravel(),
        np.repeat(hh, 4),
    )
