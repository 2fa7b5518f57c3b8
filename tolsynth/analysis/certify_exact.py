"""The certified smallest per-direction probability with the exact distribution of the linear model.

Along a unit direction ``u`` the hand error is ``u . dr = sum_i b_i Y_i`` with ``b_i = eps_i u . a_i(q)``
and ``Y_i`` independent on [-1, 1] with the parameters' shapes.  The search runs over the joints
and the direction together, ``x = (q, theta, phi)`` with ``u = (sin theta cos phi, sin theta
sin phi, cos theta)`` on the upper hemisphere (the probability is even in ``u``), and bounds
``P(x) = P(|u . dr| <= R)`` from below on each box with two facts of
``/work``'s GUARANTEES (sections 1 and 3):

* **monotone**: ``P`` falls as any ``|b_i|`` grows (symmetric unimodal ``Y_i``), so ``P`` at the
  interval upper bounds of ``|b_i|`` over the box is a lower bound (one evaluation; first order);
* **quasi-concave**: the set ``{b : P(|b . Y| <= R) >= t}`` is convex for every t (symmetric
  log-concave ``Y``: Lagoa, Li & Sznaier 2005), so over the affine image ``y(c) + J(c) d`` of the box
  (d in ``[-r, r]``) the smallest probability is at one of its ``2^(k+2)`` corners; the Taylor
  remainder ``E`` (interval Hessian or Jacobian, as :mod:`tolsynth.analysis.certify_bounds`) is
  taken up by monotonicity (``|b_i| + E_i`` at each corner).  The excess falls like the square of
  the box's width.

The larger of the two lower bounds counts; the corners are evaluated only on boxes the first bound
cannot settle.  Every probability comes from :func:`tolsynth.probability.exact.direction_probability_batch`
with its rigorous error bound subtracted.
"""

from __future__ import annotations

import itertools
import math

import casadi as ca
import numpy as np

from tolsynth.analysis.branch_bound import maximize
from tolsynth.analysis.certify_bounds import polytope_vertices
from tolsynth.analysis.interval_ops import round_up as _up
from tolsynth.analysis.intervals import IntervalFunction
from tolsynth.errors import OutOfRangeError
from tolsynth.probability.exact import direction_probability_batch

__all__ = ["ComponentBounds", "certify_components_exact", "EXACT_TOL"]

_U = 2.0**-53
#: error allowed in each exact probability evaluated by the search
EVAL_TOL = 1e-9
#: default absolute gap (probability) at which the search stops, certified
EXACT_TOL = 2e-7
#: the Hessian's graph is used when it has at most this many times the Jacobian's operations
HESSIAN_FACTOR = 4.0
#: the same with the compiled interval interpreter (evaluations cheaper than the boxes they save)
HESSIAN_FACTOR_COMPILED = 16.0


class ComponentBounds:
    """Lower bounds of the exact per-direction probability on boxes of ``(q_free, theta, phi)``.

    Parameters
    ----------
    st : Structure
    nq : int
    free : sequence of int
    held : dict
        Values of the other joints (rad).
    eps : ndarray
        Tolerances of every error parameter (tolerance units).
    shapes : tuple
        The shape of every error parameter (:func:`tolsynth.probability.distributions.shapes_of`).
    R : float
    """

    def __init__(self, st, nq: int, free, held: dict, eps, shapes, R: float, linear=()):
        cols = list(st.columns)
        self.free = tuple(free)
        self.k = len(self.free)
        self.d = self.k + 2
        self.m = len(cols)
        self.eps = np.asarray(eps, dtype=float)[cols]
        self.shapes = tuple(shapes[i] for i in cols)
        self.R = float(R)
        x = ca.SX.sym("x", self.d)
        q = [ca.SX(float(held.get(j, 0.0))) for j in range(nq)]
        for i, j in enumerate(self.free):
            q[j] = x[i]
        th, ph = x[self.k], x[self.k + 1]
        u = ca.vertcat(ca.sin(th) * ca.cos(ph), ca.sin(th) * ca.sin(ph), ca.cos(th))
        A = st.A.call([ca.vertcat(*q)])[0][:, cols]
        y = ca.densify(ca.mtimes(A.T, u))
        J = ca.densify(ca.jacobian(y, x))
        self.point_fn = ca.Function("y", [x], [y])
        self.centre = IntervalFunction(ca.Function("yJ", [x], [y, J]))
        H = ca.densify(ca.vertcat(*[ca.vec(ca.hessian(y[i], x)[0]) for i in range(self.m)]))
        hess = IntervalFunction(ca.Function("yH", [x], [y, H]))
        factor = HESSIAN_FACTOR_COMPILED if hess.compiled else HESSIAN_FACTOR
        self.use_hessian = hess.n_operations <= factor * self.centre.n_operations
        self.box = hess if self.use_hessian else self.centre
        self.corners = np.array(list(itertools.product([-1.0, 1.0], repeat=self.d)))
        self.threshold = np.inf  # boxes whose cheap bound is above this need no corners (kept current)
        self.linear = tuple(linear)  # joint constraints (a, lo, hi) over the searched joints

    def coefficients(self, X: np.ndarray) -> np.ndarray:
        """``|u . a_i| eps_i`` at points X (n, d), shape (n, m)."""
        X = np.atleast_2d(X)
        y = np.array(self.point_fn.map(len(X))(X.T)).T.reshape(len(X), self.m)
        return np.abs(y) * self.eps

    def _lower(self, B: np.ndarray) -> np.ndarray:
        """Rigorous lower bounds of P at rows of coefficient upper bounds ``B`` (n, m)."""
        if len(B) == 0:
            return np.zeros(0)
        P, err = direction_probability_batch(B, self.shapes, self.R, EVAL_TOL)
        return np.maximum(P - err - 4.0 * _U, 0.0)

    def point(self, X: np.ndarray) -> np.ndarray:
        """``P`` at points (floating-point coefficients: the best value found, not a bound)."""
        X = np.atleast_2d(X)
        if len(X) == 0:
            return np.zeros(0)
        P, _ = direction_probability_batch(self.coefficients(X), self.shapes, self.R, EVAL_TOL)
        return P

    def bound(self, L: np.ndarray, H: np.ndarray):
        """``(lb, split)``: lower bounds (n,) of P on the boxes and per-coordinate split weights."""
        nb, d, m = len(L), self.d, self.m
        C = np.minimum(np.maximum(0.5 * (L + H), L), H)
        r = np.maximum(_up(H - C), _up(C - L))
        with np.errstate(all="ignore"):
            BL, BH, breg = self.box.evaluate(L, H)
            ylo, yhi = BL[:, :m], BH[:, :m]
            nat_ok = np.isfinite(ylo).all(axis=1) & np.isfinite(yhi).all(axis=1)
            mag = np.where(nat_ok[:, None], np.maximum(np.abs(ylo), np.abs(yhi)), 0.0)
            lb = np.where(nat_ok, self._lower(_up(mag * self.eps)), 0.0)
            CL, CH, creg = self.centre.evaluate(C, C)
            ym = 0.5 * (CL[:, :m] + CH[:, :m])
            Jl, Jh = CL[:, m:].reshape(nb, d, m), CH[:, m:].reshape(nb, d, m)
            Jm = 0.5 * (Jl + Jh)
            lin = np.einsum("bkn,bk->bn", np.maximum(Jh - Jm, Jm - Jl) + 4.0 * (d + 2) * _U * np.abs(Jm), r)
            E = np.maximum(CH[:, :m] - ym, ym - CL[:, :m]) + lin + 4.0 * _U * np.abs(ym)
            if self.use_hessian:
                Ha = np.maximum(np.abs(BL[:, m:]), np.abs(BH[:, m:])).reshape(nb, m, d, d)
                share = 0.5 * np.einsum("bnjk,bj,bk->bnk", Ha, r, r)
            else:
                dev = np.maximum(np.abs(BL[:, m:].reshape(nb, d, m) - Jm), np.abs(BH[:, m:].reshape(nb, d, m) - Jm))
                share = np.einsum("bkn,bk->bnk", dev, r)
            E = _up(E + share.sum(axis=2) * (1.0 + 4.0 * (d + 2) * _U))
            ok = breg & creg & np.isfinite(E).all(axis=1) & np.isfinite(ym).all(axis=1)
            split = np.sqrt(np.einsum("bnk,n->bk", share**2, self.eps**2))
            todo = np.flatnonzero(ok & (lb < self.threshold))
            if len(todo):
                k = self.k
                Dq, use = polytope_vertices(C[todo, :k], r[todo, :k], self.linear)
                du = np.array(list(itertools.product([-1.0, 1.0], repeat=2)))
                D = np.concatenate(
                    [np.repeat(Dq, 4, axis=1), np.tile(du[None] * r[todo, None, k:], (1, Dq.shape[1], 1))], axis=2
                )
                use = np.repeat(use, 4, axis=1)
                Et = E[todo] + (1e-12 * np.einsum("bkn,bk->bn", np.abs(Jm[todo]), r[todo]) if self.linear else 0.0)
                Y = ym[todo, None, :] + np.einsum("bkn,bck->bcn", Jm[todo], D)
                Bc = _up((np.abs(Y) + Et[:, None, :]) * self.eps)
                Pc = np.full(use.shape, np.inf)
                Pc[use] = self._lower(Bc[use])
                lb[todo] = np.maximum(lb[todo], np.minimum(Pc.min(axis=1), 1.0))
        # a box where the graph is not proven regular (a closed loop near its limits) becomes so
        # only by narrowing its joints: halve the widest joint, never a direction angle, there
        widths = np.concatenate([H[:, : self.k] - L[:, : self.k], np.zeros((nb, 2))], axis=1)
        return lb, np.where(ok[:, None], split, widths)


def _direction_angles(B: ComponentBounds, x: np.ndarray) -> np.ndarray:
    """(theta, phi) of the worst direction at the pose x (a local search: only a seed)."""
    from tolsynth.probability.exact import worst_direction

    u, _ = worst_direction(_signed_columns(B, x), B.eps, B.shapes, B.R, tol=1e-8, grid=200, local=2)
    u = u if u[2] >= 0 else -u
    return np.array([math.acos(min(1.0, max(-1.0, u[2]))), math.atan2(u[1], u[0])])


def _signed_columns(B: ComponentBounds, x: np.ndarray) -> np.ndarray:
    """The kept columns of A (3, m) at the pose x, from y = A^T u at the three axes."""
    rows = []
    for th, ph in ((math.pi / 2, 0.0), (math.pi / 2, math.pi / 2), (0.0, 0.0)):
        rows.append(np.array(B.point_fn(np.concatenate([x, [th, ph]]))).ravel())
    return np.array(rows)


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
    """The search of the module docstring on the domain of :func:`tolsynth.analysis.certify.certify_worst_pose`."""
    from tolsynth.probability.distributions import shapes_of

    shapes = shapes_of(distribution, mech.error_parameters, mech.index)
    tol = EXACT_TOL if tol is None else float(tol)
    nq = len(mech.joint_names)
    held = dict(dom.held)
    if st.rotation is not None and st.rotation in held:
        held[st.rotation] = 0.0  # the proven rotation: any value gives the same probabilities
    B = ComponentBounds(st, nq, dom.free, held, eps, shapes, R, dom.linear)
    lo = np.concatenate([dom.lo, [0.0, -math.pi]])
    hi = np.concatenate([dom.hi, [math.pi / 2, math.pi]])
    k = len(dom.free)
    cfn = None
    if dom.constraint_fn is not None:

        def cfn(L, H):
            return dom.constraint_fn(L[:, :k], H[:, :k])

    x0 = None
    if seeds is not None and len(seeds):
        x0 = np.array([np.concatenate([s, _direction_angles(B, s)]) for s in np.atleast_2d(seeds)])

    def bound(L, H):
        lb, split = B.bound(L, H)
        return -lb, None, None, split

    def cb(n, ub, best):
        B.threshold = -best - tol if target is None else min(-best - tol, float(target))
        if callback is not None:
            callback(n, ub, best)

    r = maximize(
        bound,
        lambda X: -B.point(X),
        lo,
        hi,
        tol=tol,
        max_boxes=max_boxes,
        constraint_fn=cfn,
        x0=x0,
        callback=cb,
        stop=stop,
        batch=128,
        target=None if target is None else -float(target),
        stop_above=None if stop_at is None else -float(stop_at),
        leaves=leaves,
    )
    if not np.isfinite(r.best_value):
        raise OutOfRangeError(
            "joint limits", "no pose satisfies every joint limit and constraint", "a non-empty feasible joint space"
        )
    th, ph = r.best_x[k], r.best_x[k + 1]
    return dict(
        x=r.best_x[:k],
        direction=np.array([math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)]),
        certified=r.certified,
        probability_lower_bound=max(0.0, -float(r.upper_bound)),
        best_value=-float(r.best_value),
        boxes=r.boxes_processed,
        open_boxes=r.open_boxes,
        reason=r.reason,
        method="exact probabilities at quasi-concave corners of (joints, direction) boxes",
    )
