"""The exact solver's cut set: (pose, direction) constraints ``P(|w . dr| <= R) >= p`` whose
directions follow the worst one while the interior-point method moves the tolerances.

A cut at a fixed direction ``w`` approximates the pose's constraint ``min_w P(w, u) >= p`` with a
gradient error proportional to the distance of ``w`` from the minimiser: an exchange of fixed cuts
closes on the optimum only linearly (a new cut per round, each a little nearer).  A *tracking* cut
instead stands for ``h(u) = min_w P(w, u)`` over directions near its own: at a local minimum
``w*(u)`` on the sphere, ``grad h = dP/du`` there (P is stationary in w) and
``hess h = P_uu - P_ut Hr^-1 P_tu`` (``Hr`` the Riemannian Hessian in w, ``t`` two tangent
coordinates).  Along a Newton step ``du`` of the tolerances the direction takes the joint Newton
step ``dt = -Hr^-1 (grad_t P + P_tu du)``, so the minimiser and the optimum converge together.
None of this enters the certificate: the branch and bound proves every direction afresh, and the
lower bound is valid for any set of directions.
"""

from __future__ import annotations

import math

import numpy as np

from tolsynth.solvers.exact_series import derivatives, probability

__all__ = ["Cuts", "sphere_model", "minimise_directions"]

#: derivatives' truncation tolerance for the cuts (the barrier's margins stay far above it)
CUT_EVAL_TOL = 1e-11
#: largest direction step (rad) of one Newton step on the sphere
MAX_TURN = 0.2
#: largest turn (rad) of a slide where P is not convex in w (the quadratic model is no guide there)
SADDLE_TURN = 0.05
#: each accepted slide uses this much of a cut's budget of 1 (the step shrinks with it)
SLIDE_BUDGET = 0.1


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _tangent(W: np.ndarray) -> np.ndarray:
    """An orthonormal tangent basis (m, 3, 2) at each unit row of W: the branch-free basis of Duff
    et al. (2017, "Building an orthonormal basis, revisited"), stable for every unit vector, in a
    few operations on columns (no cross products)."""
    x, y, z = W[:, 0], W[:, 1], W[:, 2]
    sg = np.where(z >= 0.0, 1.0, -1.0)
    a = -1.0 / (sg + z)
    b = x * y * a
    E = np.empty((W.shape[0], 3, 2))
    E[:, 0, 0] = 1.0 + sg * x * x * a
    E[:, 1, 0] = sg * b
    E[:, 2, 0] = -sg * x
    E[:, 0, 1] = b
    E[:, 1, 1] = sg + y * y * a
    E[:, 2, 1] = -y
    return E


def sphere_model(A3: np.ndarray, W: np.ndarray, G: np.ndarray, H: np.ndarray):
    """For rows ``c = |W_j . A3_j|`` with their derivatives in u (G (m, n), H (m, n, n)): the
    tangent basis E (m, 3, 2), the tangent gradient gt (m, 2) and Riemannian Hessian Hr (m, 2, 2) of
    P in w, and the mixed derivatives B = P_ut (m, n, 2).  ``d ln b_i / dw = a_i / y_i`` with
    ``y_i = w . a_i``; a term with y_i near 0 (P is even in it) is left out."""
    # batched matrix products throughout: einsum's parsing costs more than the arithmetic here
    y = np.matmul(W[:, None, :], A3)[:, 0, :]
    ay = np.abs(y)
    big = ay > 1e-9 * np.maximum(ay.max(axis=1, keepdims=True), 1e-300)
    inv = np.where(big, 1.0 / np.where(big, y, 1.0), 0.0)
    Mi = A3 * inv[:, None, :]  # (m, 3, n)
    MiT = Mi.transpose(0, 2, 1)
    gw = np.matmul(Mi, G[:, :, None])[:, :, 0]
    n = G.shape[1]
    Hg = H.copy()
    Hg[:, np.arange(n), np.arange(n)] -= G
    Hw = Mi @ Hg @ MiT
    E = _tangent(W)
    ET = E.transpose(0, 2, 1)
    gt = np.matmul(ET, gw[:, :, None])[:, :, 0]
    Hr = ET @ Hw @ E - np.sum(W * gw, axis=1)[:, None, None] * np.eye(2)[None]
    B = H @ (MiT @ E)
    return E, gt, Hr, B


def _positive(Hr: np.ndarray) -> np.ndarray:
    ev = np.linalg.eigvalsh(Hr)
    return ev[:, 0] > 1e-12 * np.maximum(np.abs(ev[:, 1]), 1e-300)


def minimise_directions(
    A3: np.ndarray, W0: np.ndarray, u: np.ndarray, shapes: tuple, R, steps: int = 20, tol: float = 1e-10
) -> tuple[np.ndarray, np.ndarray]:
    """Local minima of P over unit directions from each row of W0 (A3 (m, 3, n) the rows' blocks,
    R one per row or a number), all rows at once: Newton's method on the sphere (a short gradient
    step where the Riemannian Hessian is not positive definite), steps at most :data:`MAX_TURN`,
    halved where P does not fall.  Returns the directions and their P."""
    W = _unit(np.asarray(W0, dtype=float))
    m = W.shape[0]
    Rv = np.broadcast_to(np.asarray(R, dtype=float), (m,)).copy()
    A3 = np.asarray(A3, dtype=float)
    P, G, H, _, _ = derivatives(np.abs(np.einsum("mxn,mx->mn", A3, W)), u, shapes, Rv, tol=tol)
    scale = np.ones(m)
    live = np.ones(m, dtype=bool)
    for _ in range(steps):
        idx = np.flatnonzero(live)
        if not idx.size:
            break
        E, gt, Hr, _ = sphere_model(A3[idx], W[idx], G[idx], H[idx])
        pd = _positive(Hr)
        d = np.empty_like(gt)
        if pd.any():
            d[pd] = -np.linalg.solve(Hr[pd], gt[pd][:, :, None])[:, :, 0]
        ng = np.maximum(np.linalg.norm(gt, axis=1), 1e-300)
        d[~pd] = -gt[~pd] * (0.05 / ng[~pd])[:, None]
        nd = np.linalg.norm(d, axis=1)
        d *= (np.minimum(1.0, MAX_TURN / np.maximum(nd, 1e-300)) * scale[idx])[:, None]
        nd = np.linalg.norm(d, axis=1)
        done = nd < 1e-9
        live[idx[done]] = False
        idx, E, d, nd = idx[~done], E[~done], d[~done], nd[~done]
        if not idx.size:
            break
        Wt = _unit(W[idx] + np.einsum("mxa,ma->mx", E, d))
        Pt, Gt, Ht, _, _ = derivatives(np.abs(np.einsum("mxn,mx->mn", A3[idx], Wt)), u, shapes, Rv[idx], tol=tol)
        better = Pt < P[idx]
        acc = idx[better]
        W[acc], P[acc], G[acc], H[acc] = Wt[better], Pt[better], Gt[better], Ht[better]
        scale[acc] = 1.0
        rej = idx[~better]
        scale[rej] *= 0.5
        live[rej[nd[~better] < 1e-10]] = False
    return W, P


class Cuts:
    """The cut set: per cut its block's rows ``A`` (3 x n per tolerance unit), R, p, block index,
    direction ``w`` and whether the direction tracks a local minimum of P.  Called as
    ``cuts(u, order)`` it gives ``g = (P - p) / (1 - p)`` per cut and (order 2) the Jacobian and
    Hessians in u (the tracking cuts' Hessians those of ``min_w P``); :meth:`plan` and :meth:`at`
    let the interior-point line search move the tracking directions with the tolerances."""

    def __init__(self, shapes, same_cut: float):
        self.shapes = tuple(shapes)
        self.same_cut = same_cut
        self.A: list = []
        self.R: list = []
        self.p: list = []
        self.block: list = []
        self.w: list = []
        self.moving: list = []
        self._model = None  # (u_ref, E, Hr^-1, gt, B) of the tracking cuts at the last order-2 evaluation
        self._dt = None  # the tracking cuts' tangent steps for a whole Newton step
        self._a = 0.0
        self._pending = None  # the directions, model and g of the last order-2 evaluation
        self._g = None
        self._slide = np.zeros(0)  # per cut: the fraction of a full slide step it takes next
        self._stacked = None

    def __len__(self) -> int:
        return len(self.w)

    def add(
        self,
        blk_index: int,
        A: np.ndarray,
        R: float,
        p: float,
        w: np.ndarray,
        moving: bool = False,
        slides: bool = False,
    ) -> bool:
        """Add the cut unless its pose has one within ``same_cut`` rad (up to sign) or one with the
        same row ``|w . a_i|`` (a mirror direction of a symmetric pose); True if added.  A moving
        cut tracks a local minimum of P where P is convex in w; one that ``slides`` also descends
        (:meth:`slide`) where it is not."""
        w = np.asarray(w, dtype=float) / np.linalg.norm(w)
        c = np.abs(w @ A)
        cmax = max(float(c.max()), 1e-300)
        for b, v, Ak in zip(self.block, self.w, self.A):
            if b != blk_index:
                continue
            if abs(float(v @ w)) > math.cos(self.same_cut) or np.max(np.abs(np.abs(v @ Ak) - c)) <= 1e-12 * cmax:
                return False
        self.A.append(np.asarray(A, dtype=float))
        self.R.append(float(R))
        self.p.append(float(p))
        self.block.append(blk_index)
        self.w.append(w)
        self.moving.append(bool(moving))
        self._slide = np.append(self._slide, 1.0 if slides else 0.0)
        self._model = self._dt = self._pending = self._g = None
        self._stacked = None
        return True

    def _stack(self):
        """The cuts' blocks (m, 3, n), R, p and the tracking cuts' indices as arrays (kept until
        a cut is added: every evaluation needs them)."""
        if self._stacked is None:
            self._stacked = (
                np.array(self.A),
                np.array(self.R),
                np.array(self.p),
                np.flatnonzero(self.moving),
            )
            for x in self._stacked:
                x.setflags(write=False)
        return self._stacked

    def rows(self, W=None) -> np.ndarray:
        W = np.array(self.w) if W is None else W
        return np.abs(np.matmul(W[:, None, :], self._stack()[0])[:, 0, :])

    def arrays(self):
        return self.rows(), self._stack()[1], self._stack()[2]

    # ---------------------------------------------------------------------- tracking directions
    def _directions(self) -> np.ndarray:
        """The directions at the current step fraction of the planned step."""
        W = np.array(self.w)
        if self._dt is None or self._a == 0.0:
            return W
        mv = self._stack()[3]
        E = self._model[1]
        W[mv] = _unit(W[mv] + self._a * np.matmul(E, self._dt[:, :, None])[:, :, 0])
        return W

    def plan(self, u: np.ndarray, du: np.ndarray, damp: float = 1.0, follow: bool = True) -> np.ndarray:
        """Fix the tracking directions' path for the Newton step ``du`` from ``u`` and return each
        cut's derivative of g along it due to the turning (zero for fixed cuts): the joint Newton
        step, its part that follows the minimiser's shift (unless ``follow`` is off) plus ``damp``
        times its Newton step towards the minimum at ``u``.  No turn where P is not at a local
        minimum in w (the quadratic model is no guide there)."""
        self._a = 0.0
        self._dt = None
        extra = np.zeros(len(self.w))
        if self._model is None or not np.array_equal(self._model[0], u):
            return extra
        _, E, Hinv, gt, B, pd, _ = self._model
        dt = -damp * np.matmul(Hinv, gt[:, :, None])[:, :, 0]
        if follow:
            dt = dt - np.matmul(Hinv, np.matmul(du, B)[:, :, None])[:, :, 0]
        dt[~pd] = 0.0
        nd = np.linalg.norm(dt, axis=1)
        dt *= np.minimum(1.0, MAX_TURN / np.maximum(nd, 1e-300))[:, None]
        mv = self._stack()[3]
        extra[mv] = np.sum(gt * dt, axis=1) / (1.0 - self._stack()[2][mv])
        self._dt = dt
        return extra

    def path_model(self, u: np.ndarray):
        """The tracking cuts' turn along a Newton step ``du`` from ``u``, before the cap of
        :data:`MAX_TURN`, as ``damp * c + T @ du`` per cut (zero for fixed cuts and where P is not
        at a local minimum in w): ``c`` the turn towards the minimum at ``u``, ``T`` the part that
        follows the minimiser's shift.  None without a model at ``u``."""
        if self._model is None or not np.array_equal(self._model[0], u):
            return None
        _, _, Hinv, gt, B, pd, _ = self._model
        mv = self._stack()[3]
        s = 1.0 / (1.0 - self._stack()[2][mv])
        Hg = np.matmul(Hinv, gt[:, :, None])[:, :, 0]
        Hg[~pd] = 0.0
        c = np.zeros(len(self.w))
        T = np.zeros((len(self.w), B.shape[1]))
        c[mv] = -np.sum(gt * Hg, axis=1) * s
        T[mv] = -np.matmul(B, Hg[:, :, None])[:, :, 0] * s[:, None]
        return c, T

    def fixed_hessians(self, u: np.ndarray, H: np.ndarray) -> np.ndarray:
        """The Hessians ``H`` of the last order-2 evaluation at ``u`` with the tracking cuts' own
        ones at their fixed directions (``P_uu``, not those of ``min_w P``): what a step whose
        directions do not turn must be modelled with."""
        if self._model is None or not np.array_equal(self._model[0], u):
            return H
        _, _, Hinv, _, B, _, _ = self._model
        mv = self._stack()[3]
        out = np.array(H, dtype=float)
        out[mv] += (B @ Hinv @ B.transpose(0, 2, 1)) / (1.0 - self._stack()[2][mv])[:, None, None]
        return out

    def at(self, a: float) -> None:
        """The fraction of the planned step that the next evaluations stand at."""
        self._a = float(a)

    def commit(self) -> None:
        """Make the last order-2 evaluation's directions (and their model) the current ones."""
        if self._pending is not None:
            self.w, self._model, self._g = self._pending
            self._pending = None
            self._dt, self._a = None, 0.0

    def __call__(self, u, order):
        """``g = (P - p)/(1 - p)`` per cut, and (order 2) its Jacobian and Hessians in u; an order-2
        evaluation's directions become the current ones at :meth:`commit`."""
        n = np.size(u)
        if not self.w:
            return np.zeros(0), np.zeros((0, n)), np.zeros((0, n, n))
        W = self._directions()
        if order == 0:
            _, R, p, _ = self._stack()
            P, _ = probability(self.rows(W) * np.exp(u)[None, :], self.shapes, R, CUT_EVAL_TOL)
            return (P - p) / (1.0 - p), None, None
        g, J, Hh, model = self._full(u, W)
        self._pending = (list(W), model, g)
        return g, J, Hh

    def _full(self, u, W):
        C = self.rows(W)
        A3, R, p, mv = self._stack()
        s = 1.0 / (1.0 - p)
        P, G, H, _, _ = derivatives(C, u, self.shapes, R, tol=CUT_EVAL_TOL)
        Hh = H.copy()
        model = None
        if mv.size:
            E, gt, Hr, B = sphere_model(A3[mv], W[mv], G[mv], H[mv])
            pd = _positive(Hr)
            Hinv = np.zeros_like(Hr)
            if pd.any():
                Hinv[pd] = np.linalg.inv(Hr[pd])
            Hh[mv] = H[mv] - B @ Hinv @ B.transpose(0, 2, 1)
            model = (np.array(u, dtype=float), E, Hinv, gt, B, pd, Hr)
        return (P - p) * s, G * s[:, None], Hh * s[:, None, None], model

    def slide(self, u):
        """Between Newton steps, the tracking directions where P is not convex in w (a flat
        valley, a saddle) take a short descent step on the sphere, kept where P falls and the
        margin keeps at least half of itself; returns the cuts' new ``(g, J, H)`` or None."""
        if self._model is None or self._g is None or not np.array_equal(self._model[0], u):
            return None
        _, E, _, gt, _, pd, Hr = self._model
        mv = self._stack()[3]
        go = ~pd & (np.linalg.norm(gt, axis=1) > 1e-9) & (self._slide[mv] > 1e-3)
        if not go.any():
            return None
        ev, V = np.linalg.eigh(Hr[go])
        ev = np.maximum(np.abs(ev), 1e-3 * np.maximum(np.abs(ev).max(axis=1, keepdims=True), 1e-300))
        dt = -np.einsum("mab,mb,mcb,mc->ma", V, 1.0 / ev, V, gt[go])
        nd = np.linalg.norm(dt, axis=1)
        k = mv[go]
        dt *= (np.minimum(1.0, SADDLE_TURN / np.maximum(nd, 1e-300)) * self._slide[k])[:, None]
        W = np.array(self.w)
        W[k] = _unit(W[k] + np.einsum("mxa,ma->mx", E[go], dt))
        g, J, Hh, model = self._full(u, W)
        ok = (g[k] < self._g[k]) & (g[k] >= 0.5 * self._g[k])
        # a slide that keeps P falling may go on (a few times per solve); one that does not, shorter
        self._slide[k] = np.where(ok, np.maximum(self._slide[k] - SLIDE_BUDGET, 0.0), 0.5 * self._slide[k])
        if not ok.all():
            return None
        self.w, self._model, self._g = list(W), model, g
        return g, J, Hh
