"""The certified smallest per-direction probability with the exact distribution of the linear model.

Along a unit direction ``u`` the hand error is ``u . dr = sum_i b_i Y_i`` with ``b_i = eps_i u . a_i(q)``
and ``Y_i`` independent on [-1, 1] with the parameters' shapes.  For symmetric log-concave
``Y_i`` the set ``{b : P(|b . Y| <= R) >= t}`` is convex for every level t (Lagoa, Li & Sznaier
2005) and, as ``P`` falls when any ``|b_i|`` grows (Anderson's theorem), it is closed downwards in
``|b|``: ``P`` is quasi-concave in ``b``, and stays so after any ``|b_i|`` is raised by a constant.
``b`` is linear in ``u`` and, to second order, affine in the joints, so the search runs over **joint
boxes**, each carrying the **direction patches** not yet proven on it:

* a joint box (centre ``c``, half-widths ``r``) gives ``A(c + d) = A(c) + J(c) d + E`` with the
  remainder ``|E|`` from an interval bound of the second derivatives (or the interval Jacobian)
  over the box (:mod:`tolsynth.analysis.certify_bounds` computes the same enclosure for
  ``sigma_1``), the affine part's corners ``d`` at the vertices of the box (cut by the joint
  constraints);
* a direction patch is the cone over a square of a cube face (``u`` and ``-u`` give the same
  probability, so three faces suffice) with corner rays ``v_k``; with ``n`` a unit vector inside
  it, every direction of the patch is ``x / |x|`` for an ``x`` of the quadrilateral of the points
  ``v_k / (n . v_k)``, all on the plane ``n . x = 1`` and so outside the unit ball: ``b(x) =
  |x| b(x / |x|)`` is larger, and ``P`` there smaller;
* over the product, ``b`` is bilinear in (joint corner, point of the quadrilateral) plus the
  remainder, so the smallest probability is at one of the pairs of vertices, with ``|b_i|``
  raised by the remainder's part ``eps_i sum_r |E_ri| max_k |v_kr| / (n . v_k)``.  One evaluation per
  direction vertex first, at the largest ``|b_i|`` over the joint corners (monotone), then every
  pair where that does not settle it.

The bound's excess is second order both ways: the remainder (the joint box's width squared) and
the lift ``1 / (n . v) - 1`` (the patch's width squared).  A patch is split while its lift is the
larger part, the joint box where the remainder is: only patches near the worst direction of the
poses near the worst pose are ever split fine.  Every probability comes from the compiled series
(:func:`tolsynth.solvers.exact_series.probability`) with its rigorous error bound subtracted.
"""

from __future__ import annotations

import heapq
import itertools
import math

import casadi as ca
import numpy as np

from tolsynth.analysis.certify_bounds import polytope_vertices
from tolsynth.analysis.interval_ops import round_up as _up
from tolsynth.analysis.intervals import IntervalFunction
from tolsynth.errors import OutOfRangeError
from tolsynth.solvers.exact_series import probability

__all__ = ["ExactBounds", "certify_components_exact", "EXACT_TOL", "taylor_enclosure"]

_U = 2.0**-53
#: error allowed in each exact probability the search evaluates
EVAL_TOL = 1e-10
#: the first, cheaper tolerance: most rows are settled against the threshold by it
LOOSE_TOL = 1e-7
#: default absolute gap (probability) at which the search stops, certified
EXACT_TOL = 2e-7
#: the Hessian's graph is used when it has at most this many times the Jacobian's operations
HESSIAN_FACTOR = 4.0
#: the same with the compiled interval interpreter (evaluations cheaper than the boxes they save)
HESSIAN_FACTOR_COMPILED = 16.0
#: the third derivatives' graph is used when it has at most this many times the Hessian's operations
THIRD_FACTOR = 4.0
#: patches per cube face side at the start
START_GRID = 2
#: joint boxes taken from the heap per round
BATCH = 32
#: rounds of patch refinement per joint box before the box itself is split
PATCH_ROUNDS = 8
#: joints whose sides group the corners in the bound's first passes (at most 2^levels groups)
GROUP_LEVELS = 3
#: joint sides halved together: those with at least this share of the largest one's remainder
SPLIT_SHARE = 0.6
#: a lifted direction's rounding is covered by raising every coefficient by this relative amount
_LIFT_SLACK = 1e-13

_E = np.eye(3)
_FRAMES = np.array([(_E[a], _E[(a + 1) % 3], _E[(a + 2) % 3]) for a in range(3)])  # face, (n, s, t), xyz
_STEPS = np.array([(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)])


class JointEnclosure:
    """Interval functions of ``A`` over boxes of the searched joints (the other joints held)."""

    def __init__(self, st, nq: int, free, held: dict):
        cols = list(st.columns)
        self.m = len(cols)
        self.k = len(free)
        x = ca.SX.sym("x", self.k)
        q = [ca.SX(float(held.get(j, 0.0))) for j in range(nq)]
        for i, j in enumerate(free):
            q[j] = x[i]
        A = st.A.call([ca.vertcat(*q)])[0][:, cols]
        a = ca.densify(ca.vec(A))  # column-major: the three rows of column 0, then column 1, ...
        self.na = a.numel()
        self.point_fn = ca.Function("A", [x], [a])
        self.centre = IntervalFunction(ca.Function("aJ", [x], [a, ca.densify(ca.jacobian(a, x))]))
        H = ca.densify(ca.vertcat(*[ca.vec(ca.hessian(a[i], x)[0]) for i in range(self.na)]))
        hess = IntervalFunction(ca.Function("aH", [x], [a, H]))
        factor = HESSIAN_FACTOR_COMPILED if hess.compiled else HESSIAN_FACTOR
        self.use_hessian = hess.n_operations <= factor * self.centre.n_operations
        self.hess = hess
        self.box = hess if self.use_hessian else self.centre
        # third derivatives over the box with the Hessian at the centre: a third-order remainder,
        # where the interval Hessian over a wider box is much wider than the Hessian itself
        self.third = None
        if self.use_hessian:
            T = ca.jacobian(ca.vec(ca.jacobian(ca.vec(ca.jacobian(a, x)), x)), x)
            third = IntervalFunction(ca.Function("aT", [x], [a, ca.densify(ca.vec(T))]))
            if third.n_operations <= THIRD_FACTOR * hess.n_operations:
                self.third = third

    def values(self, X: np.ndarray) -> np.ndarray:
        """``A`` at points X (n, k), shape (n, 3, m) (floating point)."""
        X = np.atleast_2d(X)
        a = np.array(self.point_fn.map(len(X))(X.T)).T.reshape(len(X), self.m, 3)
        return a.transpose(0, 2, 1)


def taylor_enclosure(g: JointEnclosure, L: np.ndarray, H: np.ndarray, linear=()):
    """``A`` over each box ``L <= x <= H`` (n, k): ``(Y, use, E, ok, share)`` with ``A(x)`` in the convex
    hull of the corner matrices ``Y[b, c]`` (column-major vectors, (n, C, 3 m); only where ``use``)
    plus ``[-E, E]`` entrywise (n, 3 m) for every x of the box that meets the linear constraints;
    ``ok`` False where the graph is not proven regular on the box (a closed loop near its limits);
    ``share`` (n, 3 m, k): each coordinate's part of the remainder (where to halve); ``bits`` (n, C,
    levels): each corner's side of the centre along the joints that move A most, the most first."""
    na, k = g.na, g.k
    nb = len(L)
    C = np.minimum(np.maximum(0.5 * (L + H), L), H)
    r = np.maximum(_up(H - C), _up(C - L))
    with np.errstate(all="ignore"):
        BL, BH, breg = g.box.evaluate(L, H)
        CL, CH, creg = g.centre.evaluate(C, C)
        am = 0.5 * (CL[:, :na] + CH[:, :na])
        Jl, Jh = CL[:, na:].reshape(nb, k, na), CH[:, na:].reshape(nb, k, na)
        Jm = 0.5 * (Jl + Jh)
        # the centre's own enclosure widths and the rounding of am + Jm d, then the remainder
        lin = np.einsum("bkn,bk->bn", np.maximum(Jh - Jm, Jm - Jl) + 4.0 * (k + 2) * _U * np.abs(Jm), r)
        E = np.maximum(CH[:, :na] - am, am - CL[:, :na]) + lin + 4.0 * _U * np.abs(am)
        if g.use_hessian:
            Ha = np.maximum(np.abs(BL[:, na:]), np.abs(BH[:, na:])).reshape(nb, na, k, k)
            share = 0.5 * np.einsum("bnjk,bj,bk->bnk", Ha, r, r)
            if g.third is not None:
                # |d^T H(c) d| / 2 + |T(B)| r^3 / 6, coordinate by coordinate, where it is smaller
                HcL, HcH, _ = g.hess.evaluate(C, C)
                Hc = np.maximum(np.abs(HcL[:, na:]), np.abs(HcH[:, na:])).reshape(nb, na, k, k)
                TL, TH, treg = g.third.evaluate(L, H)
                # vec of the (na k) x k Jacobian of vec(J): entry (n + na (j + k l)) -> T[n, j, l, ...]
                Ta = np.maximum(np.abs(TL[:, na:]), np.abs(TH[:, na:])).reshape(nb, k, k, k, na)
                s3 = 0.5 * np.einsum("bnjk,bj,bk->bnk", Hc, r, r) + np.einsum("blkjn,bj,bk,bl->bnl", Ta, r, r, r) / 6.0
                better = treg[:, None] & np.isfinite(s3).all(axis=2) & (s3.sum(axis=2) < share.sum(axis=2))
                share = np.where(better[:, :, None], s3, share)
        else:
            dev = np.maximum(np.abs(BL[:, na:].reshape(nb, k, na) - Jm), np.abs(BH[:, na:].reshape(nb, k, na) - Jm))
            share = np.einsum("bkn,bk->bnk", dev, r)
        E = _up(E + share.sum(axis=2) * (1.0 + 4.0 * (k + 2) * _U))
        D, use = polytope_vertices(C, r, linear)
        # the constraint crossings are computed: their rounding moves the image by at most this
        E = E + 1e-12 * np.einsum("bkn,bk->bn", np.abs(Jm), r) if linear else E
        Y = am[:, None, :] + np.einsum("bkn,bck->bcn", Jm, D)
        ok = breg & creg & np.isfinite(E).all(axis=1) & np.isfinite(Y).all(axis=(1, 2))
    # the corners grouped for the bound's first passes: by their side of the centre along the
    # joints that move A most, the most first
    spread = np.linalg.norm(Jm, axis=2) * r  # (n, k)
    order = np.argsort(-spread, axis=1)[:, :GROUP_LEVELS]
    bits = np.take_along_axis(D, order[:, None, :], axis=2) >= 0.0  # (n, C, levels)
    return np.where(ok[:, None, None], Y, 0.0), use, np.where(ok[:, None], E, 0.0), ok, share, bits


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
    enc : JointEnclosure
    eps : ndarray
        Tolerances of the kept columns (tolerance units).
    shapes : tuple
        The shape of every kept column.
    R : float
    linear : tuple
        Joint constraints ``(a, lo, hi)`` over the searched joints.
    """

    def __init__(self, enc: JointEnclosure, eps, shapes, R: float, linear=()):
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
        leave R (P = 1); else the series to a loose tolerance, and to :data:`EVAL_TOL` where that
        leaves the row within its error of ``thr``."""
        out = np.ones(len(B))
        if len(B) == 0:
            return out
        todo = np.flatnonzero(~(self.bounded & (B.sum(axis=1) * (1.0 + 4 * self.m * _U) <= self.R)))
        if todo.size:
            P, err = probability(B[todo], self.shapes, self.R, LOOSE_TOL)
            low = P - err - 4.0 * _U
            near = np.flatnonzero((low < thr) & (P + err + 4.0 * _U >= thr))
            if near.size:
                P2, err2 = probability(B[todo[near]], self.shapes, self.R, EVAL_TOL)
                low[near] = P2 - err2 - 4.0 * _U
            out[todo] = np.maximum(low, 0.0)
            self.evaluations += todo.size + near.size
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
        for t in range(1, bits.shape[2] + 1):
            code = (bits[:, :, :t] * (1 << np.arange(t))).sum(axis=2)  # (p, C)
            G = 1 << t
            onehot = (code[:, :, None] == np.arange(G)) & ~done[:, :, None] & alive[:, None, None]  # (p, C, G)
            has = onehot.any(axis=1)  # (p, G)
            if not has.any():
                break
            pi, gi = np.nonzero(has)
            mag = np.where(onehot[pi, :, gi][:, :, None, None], Bc[pi], 0.0).max(axis=1)  # (n, K, m)
            val = self.lower(mag.reshape(-1, m), thr).reshape(-1, K).min(axis=1)
            ok = val >= thr
            np.minimum.at(low, pi[ok], val[ok])
            settled = np.zeros((p, G), dtype=bool)
            settled[pi[ok], gi[ok]] = True
            done |= np.take_along_axis(settled, code, axis=1) & use
            single = onehot.sum(axis=1)[pi, gi] == 1
            alive[pi[~ok & single]] = False  # one corner below the threshold: the pair fails
        rest = ~done & alive[:, None]
        if rest.any():
            pi, ci = np.nonzero(rest)
            val = self.lower(Bc[pi, ci].reshape(-1, m), thr).reshape(-1, K).min(axis=1)
            np.minimum.at(low, pi, val)
            bad = np.zeros(p, dtype=bool)
            bad[pi[val < thr]] = True
            alive &= ~bad
        return np.where(alive, np.minimum(low, 1.0), lb)

    @staticmethod
    def _hull(Y, use):
        """Midpoint and half-width (n, 3 m) of the interval hull of each box's used corner matrices."""
        big = np.where(use[:, :, None], Y, -np.inf).max(axis=1)
        small = np.where(use[:, :, None], Y, np.inf).min(axis=1)
        ok = np.isfinite(big) & np.isfinite(small)
        mid = np.where(ok, 0.5 * (big + small), 0.0)
        return mid, np.where(ok, _up(np.maximum(big - mid, mid - small)), 0.0)

    def pairs(self, enc_box, bi, face, s0, t0, h, thr):
        """Lower bounds (n,) on the pairs (joint box ``bi``, patch), the lift excess and the
        remainder's relative size of each (where to refine), and the patches' inner unit vectors."""
        Y, use, E, ok, bits = enc_box
        m = self.m
        V = _rays(face, s0, t0, h)
        n, scale = _lift(V)
        nrm = np.linalg.norm(V, axis=2)
        lift = (nrm * scale).max(axis=1) - 1.0
        reach = (np.abs(V) * scale[..., None]).max(axis=1)  # (p, 3): the largest |x_r| on the patch
        e = np.einsum("pmr,pr->pm", E[bi].reshape(len(bi), m, 3), reach)
        # first the interval hull of the joint corners (one matrix product a vertex), then the corners
        Ym, Yr = self._hull(Y, use)
        Ymb, Yrb = Ym[bi].reshape(len(bi), m, 3), Yr[bi].reshape(len(bi), m, 3)
        Vs = V * scale[..., None]
        Z0 = np.einsum("pmr,pkr->pkm", Ymb, Vs)
        spread = np.einsum("pmr,pkr->pkm", Yrb + 1e-14 * np.abs(Ymb), np.abs(Vs))
        mag = _up((np.abs(Z0) * (1.0 + _LIFT_SLACK) + spread + e[:, None, :]) * self.eps)
        lb = self.lower(mag.reshape(-1, m), thr).reshape(-1, 4).min(axis=1)
        todo = np.flatnonzero(ok[bi] & (lb < thr))
        if todo.size:
            bt = bi[todo]
            Yb = Y[bt].reshape(todo.size, Y.shape[1], m, 3)  # (p, C, m, 3)
            Vt = Vs[todo]
            Z = np.abs(np.einsum("pcmr,pkr->pckm", Yb, Vt))
            rnd = 1e-14 * np.einsum("pmr,pkr->pkm", np.abs(Ymb[todo]) + Yrb[todo], np.abs(Vt))
            Bc = _up((Z * (1.0 + _LIFT_SLACK) + (rnd + e[todo][:, None, :])[:, None]) * self.eps)
            lb[todo] = self._vertex_pairs(Bc, use[bt], bits[bt], lb[todo], thr)
        lb = np.where(ok[bi], lb, 0.0)
        centre = np.abs(Z0).max(axis=1)  # (p, m) a typical coefficient vector
        rel = np.linalg.norm(e * self.eps, axis=1) / np.maximum(np.linalg.norm(centre * self.eps, axis=1), 1e-300)
        return lb, lift, np.where(ok[bi], rel, np.inf), n


class _Box:
    __slots__ = ("L", "H", "face", "s0", "t0", "h", "plb", "lb", "proven", "feasible", "side", "worst")

    def __init__(self, L, H, face, s0, t0, h, plb, lb, proven, feasible):
        self.L, self.H = L, H
        self.face, self.s0, self.t0, self.h, self.plb, self.lb = face, s0, t0, h, plb, lb
        self.proven, self.feasible = proven, feasible
        self.side, self.worst = (0,), None


def _infeasible(constraint_fn, L, H):
    if constraint_fn is None:
        return np.zeros(len(L), dtype=bool), np.ones(len(L), dtype=bool)
    g_lo, g_hi = constraint_fn(L, H)
    g_lo = np.asarray(g_lo, dtype=float).reshape(len(L), -1)
    g_hi = np.asarray(g_hi, dtype=float).reshape(len(L), -1)
    return (g_lo > 0.0).any(axis=1), (g_hi <= 0.0).all(axis=1)


def _start_patches():
    g = np.arange(START_GRID) * (2.0 / START_GRID) - 1.0
    S, T = np.meshgrid(g, g, indexing="ij")
    face = np.repeat(np.arange(3), S.size)
    return face, np.tile(S.ravel(), 3), np.tile(T.ravel(), 3), np.full(face.size, 2.0 / START_GRID)


def _children(face, s0, t0, h):
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


class _Search:
    """One certified search (:func:`certify_components_exact`)."""

    def __init__(self, bounds: ExactBounds, lo, hi, constraint_fn, tol, target):
        self.b = bounds
        self.lo, self.hi = lo, hi
        self.constraint_fn = constraint_fn
        self.tol, self.target = tol, target
        self.best, self.best_x, self.best_u = math.inf, None, None
        self.dropped = math.inf  # least bound of a joint box set aside, every direction proven
        self.stuck = math.inf  # least bound of a box too small to split
        self.w = np.repeat(bounds.eps**2, 3)  # column-major entries of A: each column's weight

    def threshold(self) -> float:
        t = self.best - self.tol
        return t if self.target is None else min(float(self.target), t)

    # -- points ----------------------------------------------------------------------------------
    def consider(self, X, U) -> bool:
        if len(X) == 0:
            return False
        if self.constraint_fn is not None:
            _, g_hi = self.constraint_fn(X, X)
            feas = (np.asarray(g_hi, dtype=float).reshape(len(X), -1) <= 0.0).all(axis=1)
            X, U = X[feas], U[feas]
            if len(X) == 0:
                return False
        P = self.b.point(X, U)
        j = int(np.argmin(P))
        if P[j] < self.best:
            self.best, self.best_x, self.best_u = float(P[j]), X[j].copy(), U[j].copy()
            return True
        return False

    def direction(self, x, start=None):
        from tolsynth.probability.exact import worst_direction

        A = self.b.enc.values(x[None])[0]
        u, _ = worst_direction(
            A,
            self.b.eps,
            self.b.shapes,
            self.b.R,
            tol=1e-9,
            start=start,
            grid=0 if start is not None else 200,
            local=1 if start is not None else 2,
        )
        return u

    def polish(self, rounds: int = 2, steps: int = 24) -> None:
        """Compass search over the joints from the best point (direction held), then the direction
        re-minimised there."""
        if self.best_x is None:
            return
        k = len(self.lo)
        scale = np.where(self.hi > self.lo, self.hi - self.lo, 1.0)
        for _ in range(rounds):
            h = 0.01 * scale
            for _ in range(steps):
                X = np.clip(
                    np.concatenate([self.best_x + np.eye(k) * h, self.best_x - np.eye(k) * h]), self.lo, self.hi
                )
                if not self.consider(X, np.repeat(self.best_u[None], 2 * k, axis=0)):
                    h = 0.25 * h
                    if np.all(h < 1e-9 * scale):
                        break
            u = self.direction(self.best_x, self.best_u)
            if not self.consider(self.best_x[None], u[None]):
                break

    # -- boxes -----------------------------------------------------------------------------------
    def evaluate(self, boxes: list) -> None:
        """Bound the direction patches of new joint boxes: patches proven at the threshold go; one
        failing because of its lift (more than the joint box's remainder) is split in four and its
        quarters bounded in the next round; the others are kept, for the box's halves."""
        thr = self.threshold()
        nb = len(boxes)
        L = np.array([b.L for b in boxes])
        H = np.array([b.H for b in boxes])
        Y, use, E, ok, share, bits = taylor_enclosure(self.b.enc, L, H, self.b.linear)
        enc_box = (Y, use, E, ok, bits)
        bi = np.repeat(np.arange(nb), [len(b.face) for b in boxes])
        face, s0, t0, h, fall = (
            np.concatenate([getattr(b, a) for b in boxes]) for a in ("face", "s0", "t0", "h", "plb")
        )
        proven = np.array([b.proven for b in boxes])
        kept = []
        for _ in range(PATCH_ROUNDS):
            if bi.size == 0:
                break
            lb, lift, rel, _n = self.b.pairs(enc_box, bi, face.astype(int), s0, t0, h, thr)
            lb = np.maximum(lb, np.minimum(fall, thr))  # a parent's bound holds on its parts
            done = lb >= thr
            np.minimum.at(proven, bi[done], lb[done])
            refine = ~done & (lift > rel) & (h > 2.0**-40)
            stay = ~done & ~refine
            kept.append((bi[stay], face[stay], s0[stay], t0[stay], h[stay], lb[stay]))
            fall = np.repeat(lb[refine], 4)
            bi = np.repeat(bi[refine], 4)
            face, s0, t0, h = _children(face[refine].astype(int), s0[refine], t0[refine], h[refine])
        kept.append((bi, face, s0, t0, h, fall))  # split, not yet bounded: their parents' bounds
        kb, kf, ks, kt, kh, kl = (np.concatenate(parts) for parts in zip(*kept))
        order = np.argsort(kb, kind="stable")
        kb, kf, ks, kt, kh, kl = (a[order] for a in (kb, kf, ks, kt, kh, kl))
        cuts = np.searchsorted(kb, np.arange(nb + 1))
        weights = np.sqrt(np.einsum("bnk,n->bk", share**2, self.w))
        for i, b in enumerate(boxes):
            a, z = cuts[i], cuts[i + 1]
            b.face, b.s0, b.t0, b.h, b.plb = kf[a:z].astype(int), ks[a:z], kt[a:z], kh[a:z], kl[a:z]
            b.proven = float(proven[i])
            b.lb = float(kl[a:z].min()) if z > a else math.inf
            if z > a:
                j = a + int(np.argmin(kl[a:z]))
                b.worst = _lift(_rays(kf[j : j + 1].astype(int), ks[j : j + 1], kt[j : j + 1], kh[j : j + 1]))[0][0]
            wide = (b.H - b.L) > 0
            if ok[i] and np.isfinite(weights[i]).all() and weights[i][wide].max(initial=0.0) > 0:
                wi = np.where(wide, weights[i], -1.0)
                # every side with a fair part of the remainder at once: halving one side at a time
                # bounds every intermediate box again
                b.side = tuple(np.flatnonzero(wi >= SPLIT_SHARE * wi.max()))
            else:
                b.side = (int(np.argmax(b.H - b.L)),)


def certify_components_exact(
    mech,
    st,
    dom,
    eps,
    distribution,
    R,
    *,
    tol=None,
    max_boxes,
    seeds=None,
    callback=None,
    stop=None,
    target=None,
    stop_at=None,
    leaves=None,
) -> dict:
    """The search of the module docstring on the domain of :func:`tolsynth.analysis.certify.certify_worst_pose`:
    best first over joint boxes (lowest bound first), a box's patches inherited by its halves."""
    from tolsynth.probability.distributions import shapes_of

    shapes = shapes_of(distribution, mech.error_parameters, mech.index)
    cols = list(st.columns)
    tol = EXACT_TOL if tol is None else float(tol)
    nq = len(mech.joint_names)
    held = dict(dom.held)
    if st.rotation is not None and st.rotation in held:
        held[st.rotation] = 0.0  # the proven rotation: any value gives the same probabilities
    enc = JointEnclosure(st, nq, dom.free, held)
    bounds = ExactBounds(enc, np.asarray(eps, dtype=float)[cols], tuple(shapes[i] for i in cols), R, dom.linear)
    lo, hi = np.asarray(dom.lo, dtype=float), np.asarray(dom.hi, dtype=float)
    s = _Search(bounds, lo, hi, dom.constraint_fn, tol, target)
    starts = [0.5 * (lo + hi)] + ([] if seeds is None else list(np.clip(np.atleast_2d(seeds), lo, hi)))
    for x in starts:
        s.consider(np.asarray(x)[None], s.direction(np.asarray(x))[None])
    s.polish()
    scale = np.where(hi > lo, hi - lo, 1.0)
    face0 = _start_patches()
    root = _Box(lo.copy(), hi.copy(), *face0, np.zeros(len(face0[0])), 0.0, math.inf, False)
    heap: list = []
    seq = 0
    kept = [] if leaves is not None else None

    def set_aside(b, bound):
        if kept is not None:
            kept.append((b.L.copy(), b.H.copy(), -float(bound)))

    def push(boxes):
        nonlocal seq
        thr = s.threshold()
        for b in boxes:
            bound = min(b.lb, b.proven)
            if b.lb >= thr:  # every direction proven at the threshold
                s.dropped = min(s.dropped, bound)
                set_aside(b, bound)
            elif np.all((b.H - b.L) < 1e-12 * scale):
                s.stuck = min(s.stuck, bound)
                set_aside(b, bound)
            else:
                seq += 1
                heapq.heappush(heap, (b.lb, seq, b))

    bad, feas = _infeasible(dom.constraint_fn, root.L[None], root.H[None])
    processed = 1
    stopped = ""
    if not bad[0]:
        root.feasible = bool(feas[0])
        s.evaluate([root])
        push([root])
    while heap and processed < max_boxes:
        if stop_at is not None and s.best < stop_at:
            stopped = f"a pose below {stop_at:.9g} found"
            break
        if stop is not None:
            stopped = stop() or ""
            if stopped:
                break
        thr = s.threshold()
        if heap[0][0] >= thr:
            break
        take = []
        while heap and len(take) < BATCH and heap[0][0] < thr:
            take.append(heapq.heappop(heap)[2])
        kids = []
        for b in take:
            sides = list(b.side)
            mid = 0.5 * (b.L[sides] + b.H[sides])
            for upper in itertools.product((False, True), repeat=len(sides)):
                L, H = b.L.copy(), b.H.copy()
                up = np.array(upper)
                L[sides] = np.where(up, mid, b.L[sides])
                H[sides] = np.where(up, b.H[sides], mid)
                kids.append(_Box(L, H, b.face, b.s0, b.t0, b.h, b.plb, b.lb, b.proven, b.feasible))
        KL = np.array([c.L for c in kids])
        KH = np.array([c.H for c in kids])
        todo = [c for c in kids if c.feasible]
        rest = [i for i, c in enumerate(kids) if not c.feasible]
        if rest:
            bad, feas = _infeasible(dom.constraint_fn, KL[rest], KH[rest])
            for i, bd, fs in zip(rest, bad, feas):
                if not bd:
                    kids[i].feasible = bool(fs)
                    todo.append(kids[i])
        processed += len(kids)
        if todo:
            s.evaluate(todo)
            live = [c for c in todo if c.worst is not None]
            if live and s.consider(np.array([0.5 * (c.L + c.H) for c in live]), np.array([c.worst for c in live])):
                s.polish(rounds=1, steps=12)
            push(todo)
        if callback is not None:
            callback(processed, -_lower_bound(s, heap), -s.best)
    lower = _lower_bound(s, heap)
    n_open = len(heap) if heap and heap[0][0] < s.threshold() else 0
    for _, _, b in heap:
        set_aside(b, min(b.lb, b.proven))
    if leaves is not None:
        leaves.extend(kept)
    if s.best_x is None:
        raise OutOfRangeError(
            "joint limits", "no pose satisfies every joint limit and constraint", "a non-empty feasible joint space"
        )
    certified = (target is not None and lower >= target) or s.best - lower <= tol
    reason = ""
    if not certified:
        reason = (
            stopped
            or (f"box limit reached ({processed} boxes, {n_open} open)" if n_open else "")
            or "boxes at the resolution limit still bound below the best"
        )
    return dict(
        x=s.best_x,
        direction=s.best_u,
        certified=bool(certified),
        probability_lower_bound=max(0.0, float(lower)),
        best_value=float(s.best),
        boxes=processed,
        open_boxes=n_open,
        reason=reason,
        method="exact probabilities at the vertex pairs of joint boxes and lifted direction patches",
    )


def _lower_bound(s: _Search, heap) -> float:
    top = min((min(b.lb, b.proven) for _, _, b in heap), default=math.inf)
    return min(top, s.dropped, s.stuck, s.best)
