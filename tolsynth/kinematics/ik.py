"""Inverse kinematics on the model's forward-kinematics graph, for grids of hand positions.

A batched Levenberg-Marquardt iteration on all grid points at once (residual and Jacobian from
the model's CasADi fk graph; each column independent of the others), with continuation over a
grid in a base-frame plane from a reference configuration and deterministic quasi-random seeds for
the points it misses (the seeds after the first run together).  Where a C compiler is found the
iteration runs compiled with CasADi's generated code of the same graph
(:mod:`tolsynth.kinematics.ik_compiled`, the columns split over threads); otherwise here in NumPy, the graph
evaluated by :class:`tolsynth.kinematics.numpy_eval.NumpyEvaluator` for large batches and by CasADi itself
for small ones.  Both give the same iterates up to rounding.  Used by
:mod:`tolsynth.analysis.workspace_map`.  Units: mm and rad.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from tolsynth.kinematics.batch_stats import _cache
from tolsynth.kinematics.ik_compiled import compile_lm
from tolsynth.kinematics.joint_space import _feasible, _limit_margin, _limits, _wrap
from tolsynth.kinematics.numpy_eval import NumpyEvaluator

__all__ = ["PLANES"]

PLANES = {"xz": (0, 2, 1), "xy": (0, 1, 2), "yz": (1, 2, 0)}  # (horizontal, vertical, normal) axis

_ORIENT_WEIGHT = 1000.0  # mm per unit of axis-direction error in the residual (1 mrad ~ 1 mm)


def _ik_evaluator(mech, free: tuple[int, ...], with_axis: bool) -> NumpyEvaluator:
    key = ("ik", free, with_axis)
    c = _cache(mech)
    if key not in c:
        nq = len(mech.joint_names)
        q = ca.SX.sym("q", nq)
        target = ca.SX.sym("target", 3)
        axis = ca.SX.sym("axis", 3)
        T = mech.graphs.fk(q, ca.DM.zeros(mech.n))
        r = T[:3, 3] - target
        if with_axis:
            r = ca.vertcat(r, _ORIENT_WEIGHT * (T[:3, 2] - axis))
        J = ca.densify(ca.jacobian(r, q[list(free)]))
        # common subexpressions merged (cse): the residual and its Jacobian share most of the fk
        # graph; about 13 % fewer operations per evaluation for xu_zhang_1988
        c[key] = NumpyEvaluator(
            ca.Function(
                "ik_residual", [q, target, axis], [ca.densify(r), J], ["q", "target", "axis"], ["r", "J"], {"cse": True}
            )
        )
    return c[key]


#: batches up to this size are evaluated by CasADi's virtual machine (a few us per column), larger
#: ones by the NumPy interpreter (about 0.6 ms per call plus 0.4 us per column for xu_zhang_1988)
SMALL_BATCH = 48


def _spd_solve(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Solve ``A x = b`` for a batch of small symmetric positive definite systems by Cholesky,
    vectorised over the batch: ``A`` (n, n, N), ``b`` (n, N).  Returns ``x`` and a flag (N,),
    False where the factorisation broke down (a pivot not > 0: ``x`` there is not usable)."""
    n, N = b.shape
    L = np.zeros_like(A)
    ok = np.ones(N, bool)
    with np.errstate(all="ignore"):
        for j in range(n):
            d = A[j, j] - sum(L[j, k] * L[j, k] for k in range(j))
            good = d > 0
            ok &= good
            L[j, j] = np.sqrt(np.where(good, d, 1.0))
            for i in range(j + 1, n):
                L[i, j] = (A[i, j] - sum(L[i, k] * L[j, k] for k in range(j))) / L[j, j]
        y = np.empty_like(b)
        for i in range(n):
            y[i] = (b[i] - sum(L[i, k] * y[k] for k in range(i))) / L[i, i]
        x = np.empty_like(b)
        for i in reversed(range(n)):
            x[i] = (y[i] - sum(L[k, i] * x[k] for k in range(i + 1, n))) / L[i, i]
    return x, ok & np.all(np.isfinite(x), axis=0)


def _solve_ik(
    ev: NumpyEvaluator,
    free: tuple[int, ...],
    Q0: np.ndarray,
    targets: np.ndarray,
    axis: np.ndarray,
    tol: float = 1e-7,
    max_iter: int = 60,
) -> tuple[np.ndarray, np.ndarray]:
    """Levenberg-Marquardt on all columns at once, each column independent of the others (the
    iteration keeps compact arrays of the columns still running).  Returns joints (nq, N) and a
    converged flag (residual norm below ``tol``: mm, and 1e-3 * tol in the axis direction)."""
    N = Q0.shape[1]
    if N == 0:
        return Q0.copy(), np.zeros(0, bool)
    lm = compile_lm(ev.function)
    if lm is not None:  # the same iteration, compiled with the same graph
        return lm.solve(free, Q0, targets, axis, tol, max_iter)
    Q = Q0.copy()
    fr = list(free)
    nf = len(fr)

    # entries the same in every column -- the held joints (never moved here) and a target
    # coordinate constant over the batch (the plane's offset) -- are bound as fixed: what depends
    # only on them (the held joints' sines and cosines) is evaluated once, not per column
    vq = np.ones(Q.shape[0], bool)
    vq[fr] = False
    vq &= ~np.all(Q == Q[:, :1], axis=1)
    vq[fr] = True
    vt = ~np.all(targets == targets[:, :1], axis=1)
    prog = ev.bind([Q[:, 0], targets[:, 0], axis], [vq, vt, np.zeros(3, bool)])

    iq, it = np.flatnonzero(vq), np.flatnonzero(vt)
    nv = iq.size
    fpos = np.searchsorted(iq, fr)  # rows of the free joints among the program's rows

    def residual(X):
        """r (nr, n) and J (nf, nr, n) at the program's rows X: varying joints, then targets."""
        n = X.shape[1]
        if n <= SMALL_BATCH:  # CasADi's own evaluation of the same graph, mapped over the columns
            maps = ev.__dict__.setdefault("_maps", {})
            if n not in maps:
                maps[n] = ev.function.map(n)
            Qa = np.repeat(Q[:, :1], n, axis=1)
            Ta = np.repeat(targets[:, :1], n, axis=1)
            Qa[iq], Ta[it] = X[:nv], X[nv:]
            r, J = (np.asarray(x) for x in maps[n](Qa, Ta, axis))
            return r, J.reshape(r.shape[0], n, nf).transpose(2, 0, 1)  # J_b side by side
        r, J = prog(X)
        return r, J.reshape(nf, r.shape[0], -1)  # J[k, :, b]: column k of the dense (nr x nf) J

    X = np.vstack([Q[iq], targets[it]])
    r, J = residual(X)
    cost = np.einsum("rb,rb->b", r, r)
    cost = np.where(np.isfinite(cost), cost, np.inf)
    conv = cost <= tol * tol
    # the columns still running (a non-finite residual, a loop that does not close, never moves)
    w = np.flatnonzero(~conv & np.isfinite(cost))
    Xw, rw, Jw, cw = X[:, w], r[:, w], J[:, :, w], cost[w]
    mu = np.full(w.size, 1e-3)
    for _ in range(max_iter):
        if w.size == 0:
            break
        A = np.empty((nf, nf, w.size))
        g = np.empty((nf, w.size))
        for k in range(nf):
            g[k] = np.einsum("rb,rb->b", Jw[k], rw)
            for l in range(k + 1):
                A[k, l] = A[l, k] = np.einsum("rb,rb->b", Jw[k], Jw[l])
        # a non-finite Jacobian (a loop at its limit; it shows in the diagonal of J^T J): every
        # step from there is non-finite and rejected, so the column can never move
        trace = A[0, 0].copy()
        for k in range(1, nf):
            trace += A[k, k]
        moving = np.isfinite(trace)
        for k in range(nf):
            A[k, k] += mu * (A[k, k] + 1e-9)  # damped (A is the damped matrix from here)
        with np.errstate(all="ignore"):
            step, solved = _spd_solve(A, -g)
        for c in np.flatnonzero(~solved & moving):  # breakdown (a singular system): least squares
            step[:, c] = np.linalg.lstsq(A[:, :, c], -g[:, c], rcond=None)[0]
        Xn = Xw.copy()
        Xn[fpos] += step
        rn, Jn = residual(Xn)
        cn = np.einsum("rb,rb->b", rn, rn)
        acc = moving & np.isfinite(cn) & (cn < cw)
        np.copyto(Xw, Xn, where=acc)
        np.copyto(rw, rn, where=acc)
        np.copyto(Jw, Jn, where=acc)
        small_gain = acc & (cw - cn <= 1e-14 * cw)
        cw = np.where(acc, cn, cw)
        mu = np.where(acc, np.maximum(mu / 3.0, 1e-12), mu * 4.0)
        big_step = np.abs(step[0])
        for k in range(1, nf):
            np.maximum(big_step, np.abs(step[k]), out=big_step)
        keep = moving & (cw > tol * tol) & ~((mu > 1e8) | small_gain | (big_step < 1e-13))
        if not keep.all():  # finished columns out of the working set
            done = ~keep
            Q[np.ix_(iq, w[done])] = Xw[:nv, done]
            conv[w[done]] = cw[done] <= tol * tol
            w, Xw, rw, Jw, cw, mu = w[keep], Xw[:, keep], rw[:, keep], Jw[:, :, keep], cw[keep], mu[keep]
    Q[np.ix_(iq, w)] = Xw[:nv]  # the iteration limit reached
    return Q, conv


def _halton(n: int, dim: int) -> np.ndarray:
    primes = [2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37][:dim]
    out = np.empty((n, dim))
    for d, b in enumerate(primes):
        for i in range(n):
            f, r, k = 1.0, 0.0, i + 1
            while k > 0:
                f /= b
                r += f * (k % b)
                k //= b
            out[i, d] = r
    return out


class _GridIK:
    """Inverse kinematics on a grid of a plane: Levenberg-Marquardt on the fk graph, continuation
    over the grid from the reference configuration, quasi-random seeds for what it misses."""

    #: seeds run together on the points left after the first (None: all; 1: one at a time)
    seed_batch: int | None = None

    def __init__(self, mech, free, held, ref_q, axis, plane, offset, seeds):
        self.mech = mech
        self.free = free
        self.axis_in = axis if axis is not None else np.zeros(3)
        self.ev = _ik_evaluator(mech, free, axis is not None)
        self.iu, self.iv, self.inorm = PLANES[plane]
        self.offset = offset
        self.ref_q = ref_q.copy()
        for j, (v, _) in held.items():
            self.ref_q[j] = v
        lo, hi = _limits(mech)
        seed_set = [cq.copy() for cq in mech.configurations.values()]  # named configurations,
        for hrow in _halton(max(seeds, 0), len(free)):  # then Halton points inside the limits
            s = ref_q.copy()
            for i, j in enumerate(free):
                s[j] = lo[j] + (hi[j] - lo[j]) * hrow[i]
            seed_set.append(s)
        for s in seed_set:
            for j, (v, _) in held.items():
                s[j] = v
        self.seed_set = seed_set

    def targets(self, U, V) -> np.ndarray:
        T = np.empty((3, U.size))
        T[self.iu], T[self.iv], T[self.inorm] = U, V, self.offset
        return T

    def attempt(self, Q0, T):
        """Solve from Q0; returns wrapped joints, valid (converged and inside every limit), and
        the limit margin of converged solutions (-inf where not converged)."""
        Q, conv = _solve_ik(self.ev, self.free, Q0, T, self.axis_in)
        Q = _wrap(self.mech, Q)
        margin = np.where(conv, _limit_margin(self.mech, Q), -np.inf)
        return Q, conv & _feasible(self.mech, Q), margin

    def solve(self, u, v, bar=None):
        """Joints (nq, N), reachable flag (N,) and limit margin (N,) for the grid u x v (rows v)."""
        nu, nv = u.size, v.size
        Ug, Vg = np.meshgrid(u, v)
        T = self.targets(Ug.ravel(), Vg.ravel())
        N = T.shape[1]
        nq = len(self.ref_q)
        Qs = np.full((nq, N), np.nan)
        ok = np.zeros(N, bool)
        margin = np.full(N, -np.inf)
        tried = np.zeros(N, bool)

        def take(idx, Q, good, mg):
            better = mg > margin[idx]
            margin[idx[better]] = mg[better]
            Qs[:, idx[good]] = Q[:, good]
            ok[idx[good]] = True

        # start: the grid point nearest the reference hand point, from the reference joints
        p_ref = np.asarray(self.mech.graphs.position(self.ref_q, np.zeros(self.mech.n))).ravel()
        start = int(np.argmin((T[self.iu] - p_ref[self.iu]) ** 2 + (T[self.iv] - p_ref[self.iv]) ** 2))
        # every start at once (columns are independent), taken in order up to the first valid one
        starts = [self.ref_q] + self.seed_set
        Qa, good, mg = self.attempt(np.column_stack(starts), np.repeat(T[:, [start]], len(starts), axis=1))
        for i in range(len(starts)):
            take(np.array([start]), Qa[:, [i]], good[[i]], mg[[i]])
            if ok[start]:
                break
        tried[start] = True
        flat = np.arange(N).reshape(nv, nu)
        last = np.full(N, -1)  # the neighbour a point was last seeded from

        def continuation():
            # sweeps: unsolved points next to solved ones, seeded with a solved neighbour's joints
            while True:
                grid_ok = ok.reshape(nv, nu)
                src = np.full((nv, nu), -1)
                for dv, du in ((0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (-1, -1), (1, -1), (-1, 1)):
                    vs, vd = slice(max(dv, 0), nv + min(dv, 0)), slice(max(-dv, 0), nv + min(-dv, 0))
                    us, ud = slice(max(du, 0), nu + min(du, 0)), slice(max(-du, 0), nu + min(-du, 0))
                    cand = np.where(grid_ok[vs, us], flat[vs, us], -1)
                    dst = src[vd, ud]
                    src[vd, ud] = np.where(dst < 0, cand, dst)
                src = src.ravel()
                front = np.flatnonzero((src >= 0) & ~ok & ~tried)
                if front.size == 0:
                    return
                tried[front] = True
                last[front] = src[front]
                take(front, *self.attempt(Qs[:, src[front]], T[:, front]))
                if bar is not None:
                    bar.update(front.size)

        continuation()
        # points not reached: quasi-random seeds in turn, each followed by continuation if it found
        # a point.  The first seed runs alone (it usually reaches the region, and continuation
        # fills it); the others run at once on the points left (the columns are independent, so
        # each point's result from a seed is the one it would get alone), taken in turn.
        pending = list(self.seed_set)
        while pending:
            rest = np.flatnonzero(~ok)
            if rest.size == 0:
                break
            first = len(pending) == len(self.seed_set)
            batch = pending[:1] if first else pending[: self.seed_batch or len(pending)]
            pending = pending[len(batch) :]
            Qa, good, mg = self.attempt(
                np.repeat(np.column_stack(batch), rest.size, axis=1), np.tile(T[:, rest], len(batch))
            )
            for i in range(len(batch)):
                left = np.flatnonzero(~ok[rest])
                if left.size == 0:
                    break
                cols = i * rest.size + left
                before = int(ok.sum())
                take(rest[left], Qa[:, cols], good[cols], mg[cols])
                if ok.sum() > before:
                    tried[:] = ok
                    continuation()
        if bar is not None:
            bar.update(max(0, N - bar.n))
        return Qs, ok, margin
