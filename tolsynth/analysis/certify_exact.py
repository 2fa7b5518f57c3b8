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

Where every shape is uniform, triangular or normal, a joint box is first bounded as a whole from
its bound of ``sigma_1`` (arc polygons for serial chains, :func:`tolsynth.analysis.certify_bounds.sigma_bounds`):
every direction's deviation is at most ``sigma_1``, and :mod:`tolsynth.probability.tail_bound`
turns that into a probability.  It needs ``R / sigma_1`` about 3 at p = 0.99, so it settles the
wide boxes far from the binding poses, which the vertex pairs cannot; the pairs settle those near.
"""

from __future__ import annotations

import heapq
import itertools
import math
import time

import numpy as np

from tolsynth.analysis.certify_bounds import PolygonSigmaBounds, joint_graphs, sigma_bounds, taylor_enclosure
from tolsynth.analysis.certify_domain import full, sheared
from tolsynth.analysis.certify_exact_bounds import ExactBounds, children, patch_normals, start_patches
from tolsynth.analysis.certify_parallel import Background, run
from tolsynth.analysis.exact_pose_search import worst_exact_pose
from tolsynth.errors import OutOfRangeError
from tolsynth.probability.tail_bound import covered, probability_lower, z_for

__all__ = ["certify_components_exact", "EXACT_TOL"]

#: default absolute gap (probability) at which the search stops, certified
EXACT_TOL = 2e-7
#: joint boxes taken from the heap per round
BATCH = 32
#: rounds of patch refinement per joint box before the box itself is split
PATCH_ROUNDS = 8
#: joint sides halved together: those with at least this share of the largest one's remainder
SPLIT_SHARE = 0.6


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


class _Search:
    """One certified search (:func:`certify_components_exact`), and what
    :func:`tolsynth.analysis.certify_parallel.run` needs to share it out."""

    sense = -1.0  # a minimum

    def __init__(self, bounds: ExactBounds, lo, hi, constraint_fn, tol, target, kept, sigma=None):
        self.b = bounds
        self.sigma = sigma  # bounds of sigma_1 on joint boxes, where the shapes allow the tail bound
        self.lo, self.hi = lo, hi
        self.scale = np.where(hi > lo, hi - lo, 1.0)
        self.constraint_fn = constraint_fn
        self.tol, self.target = tol, target
        self.best, self.best_x, self.best_u = math.inf, None, None
        self.dropped = math.inf  # least bound of a joint box set aside, every direction proven
        self.stuck = math.inf  # least bound of a box too small to split
        self.w = np.repeat(bounds.eps**2, 3)  # column-major entries of A: each column's weight
        self.heap: list = []
        self.seq = 0
        self.processed = 0
        self.kept = kept  # when kept: (lo, hi, -bound) of every joint box set aside
        self.shared = None  # on several processes: the incumbent they share (certify_parallel.Shared)

    def incumbent(self) -> float:
        """The best value found, by any worker: the threshold every worker uses is the serial one."""
        return self.best if self.shared is None else min(self.best, self.shared.incumbent())

    def threshold(self) -> float:
        t = self.incumbent() - self.tol
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
            if self.shared is not None:
                self.shared.offer(self.best)
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
        enc = taylor_enclosure(self.b.enc, L, H, self.b.linear)
        bi = np.repeat(np.arange(nb), [len(b.face) for b in boxes])
        face, s0, t0, h, fall = (
            np.concatenate([getattr(b, a) for b in boxes]) for a in ("face", "s0", "t0", "h", "plb")
        )
        proven = np.array([b.proven for b in boxes])
        if self.sigma is not None:
            # every direction of a joint box at once, from sigma_1's bound (tail_bound): it settles
            # the boxes far from the binding poses, which the vertex pairs cannot while they are wide
            plb = self.sigma_lower(L, H, thr)
            whole = plb >= thr
            proven[whole] = np.minimum(proven[whole], plb[whole])
            fall = np.maximum(fall, plb[bi])
            rest = ~whole[bi]
            bi, face, s0, t0, h, fall = (x[rest] for x in (bi, face, s0, t0, h, fall))
        kept = []
        for _ in range(PATCH_ROUNDS):
            if bi.size == 0:
                break
            lb, lift, rel = self.b.pairs(enc, bi, face.astype(int), s0, t0, h, thr)
            lb = np.maximum(lb, np.minimum(fall, thr))  # a parent's bound holds on its parts
            done = lb >= thr
            np.minimum.at(proven, bi[done], lb[done])
            refine = ~done & (lift > rel) & (h > 2.0**-40)
            stay = ~done & ~refine
            kept.append((bi[stay], face[stay], s0[stay], t0[stay], h[stay], lb[stay]))
            fall = np.repeat(lb[refine], 4)
            bi = np.repeat(bi[refine], 4)
            face, s0, t0, h = children(face[refine].astype(int), s0[refine], t0[refine], h[refine])
        kept.append((bi, face, s0, t0, h, fall))  # split, not yet bounded: their parents' bounds
        kb, kf, ks, kt, kh, kl = (np.concatenate(parts) for parts in zip(*kept))
        order = np.argsort(kb, kind="stable")
        kb, kf, ks, kt, kh, kl = (a[order] for a in (kb, kf, ks, kt, kh, kl))
        cuts = np.searchsorted(kb, np.arange(nb + 1))
        weights = np.sqrt(np.einsum("bnk,n->bk", enc.share**2, self.w))
        for i, b in enumerate(boxes):
            a, z = cuts[i], cuts[i + 1]
            b.face, b.s0, b.t0, b.h, b.plb = kf[a:z].astype(int), ks[a:z], kt[a:z], kh[a:z], kl[a:z]
            b.proven = float(proven[i])
            b.lb = float(kl[a:z].min()) if z > a else math.inf
            if z > a:
                j = a + int(np.argmin(kl[a:z]))
                b.worst = patch_normals(kf[j : j + 1].astype(int), ks[j : j + 1], kt[j : j + 1], kh[j : j + 1])[0]
            wide = (b.H - b.L) > 0
            if enc.ok[i] and np.isfinite(weights[i]).all() and weights[i][wide].max(initial=0.0) > 0:
                wi = np.where(wide, weights[i], -1.0)
                # every side with a fair part of the remainder at once: halving one side at a time
                # bounds every intermediate box again
                b.side = tuple(np.flatnonzero(wi >= SPLIT_SHARE * wi.max()))
            else:
                b.side = (int(np.argmax(b.H - b.L)),)

    def sigma_lower(self, L, H, thr) -> np.ndarray:
        """Lower bounds of the probability on joint boxes from the bounds of sigma_1 on them
        (:func:`tolsynth.probability.tail_bound.probability_lower`); the polygons refine a box
        toward the deviation at which the threshold would be proven."""
        if isinstance(self.sigma, PolygonSigmaBounds):
            z = z_for(1.0 - thr)  # 0 where any deviation would do (a threshold of 0 or below)
            ub = self.sigma.bound(L, H, self.b.R / z if z > 0.0 else math.inf)[0]
        else:
            ub = self.sigma.bound(L, H)[0]
        return probability_lower(self.b.R, ub)

    def set_aside(self, b, bound) -> None:
        if self.kept is not None:
            self.kept.append((b.L.copy(), b.H.copy(), -float(bound)))

    def push(self, boxes) -> None:
        thr = self.threshold()
        for b in boxes:
            bound = min(b.lb, b.proven)
            if b.lb >= thr:  # every direction proven at the threshold
                self.dropped = min(self.dropped, bound)
                self.set_aside(b, bound)
            elif np.all((b.H - b.L) < 1e-12 * self.scale):
                self.stuck = min(self.stuck, bound)
                self.set_aside(b, bound)
            else:
                self.seq += 1
                heapq.heappush(self.heap, (b.lb, self.seq, b))

    def step(self, thr) -> None:
        """One round: the lowest-bound joint boxes split, their parts' patches bounded."""
        take = []
        while self.heap and len(take) < BATCH and self.heap[0][0] < thr:
            take.append(heapq.heappop(self.heap)[2])
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
            bad, feas = _infeasible(self.constraint_fn, KL[rest], KH[rest])
            for i, bd, fs in zip(rest, bad, feas):
                if not bd:
                    kids[i].feasible = bool(fs)
                    todo.append(kids[i])
        self.processed += len(kids)
        if todo:
            self.evaluate(todo)
            live = [c for c in todo if c.worst is not None]
            if live and self.consider(np.array([0.5 * (c.L + c.H) for c in live]), np.array([c.worst for c in live])):
                self.polish(rounds=1, steps=12)
            self.push(todo)

    # -- what certify_parallel.run needs ------------------------------------------------------
    @staticmethod
    def key(entry) -> float:
        return entry[0]

    def open_bound(self) -> float:
        return min((min(b.lb, b.proven) for _, _, b in self.heap), default=math.inf)

    def bound(self) -> float:
        return min(self.open_bound(), self.dropped, self.stuck, self.best)

    def open_count(self) -> int:
        return len(self.heap) if self.heap and self.heap[0][0] < self.threshold() else 0

    def settled(self, thr) -> bool:
        return self.heap[0][0] >= thr

    def past(self, level) -> str:
        return f"a pose below {level:.9g} found" if self.best < level else ""

    def to_worker(self, heap, shared) -> None:
        self.heap, self.shared, self.processed = heap, shared, 0
        self.dropped = self.stuck = math.inf
        self.kept = None if self.kept is None else []

    def part(self) -> dict:
        return dict(
            best=self.best,
            x=self.best_x,
            u=self.best_u,
            dropped=self.dropped,
            stuck=self.stuck,
            n_boxes=self.processed,
            kept=self.kept,
        )

    def merge(self, p) -> None:
        if p["best"] < self.best:
            self.best, self.best_x, self.best_u = p["best"], p["x"], p["u"]
        self.dropped, self.stuck = min(self.dropped, p["dropped"]), min(self.stuck, p["stuck"])
        self.processed += p["n_boxes"]
        if self.kept is not None:
            self.kept.extend(p["kept"])


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
    workers=1,
    search=True,
) -> dict:
    """The search of the module docstring on the domain of :func:`tolsynth.analysis.certify.certify_worst_pose`:
    best first over joint boxes (lowest bound first), a box's patches inherited by its halves; past
    the first :data:`~tolsynth.analysis.certify_parallel.SERIAL_SECONDS` on ``workers`` processes."""
    from tolsynth.probability.distributions import shapes_of

    shapes = shapes_of(distribution, mech.error_parameters, mech.index)
    cols = list(st.columns)
    tol = EXACT_TOL if tol is None else float(tol)
    nq = len(mech.joint_names)
    held = dict(dom.held)
    if st.rotation is not None and st.rotation in held:
        held[st.rotation] = 0.0  # the proven rotation: any value gives the same probabilities
    if leaves is None:  # a joint constraint as a coordinate (kept boxes are reported in joints)
        dom = sheared(mech, dom)
        seeds = None if seeds is None else dom.coords(np.atleast_2d(seeds))
    enc = joint_graphs(st, nq, dom.free, held, third=True, M=dom.M)
    bounds = ExactBounds(enc, np.asarray(eps, dtype=float)[cols], tuple(shapes[i] for i in cols), R, dom.linear)
    lo, hi = np.asarray(dom.lo, dtype=float), np.asarray(dom.hi, dtype=float)
    sigma = None
    if covered(bounds.shapes):
        sigma, _ = sigma_bounds(st, dom, nq, np.asarray(eps, dtype=float)[cols] ** 2 * bounds.var)
    s = _Search(bounds, lo, hi, dom.constraint_fn, tol, target, [] if leaves is not None else None, sigma)
    starts = [0.5 * (lo + hi)] + ([] if seeds is None else list(np.clip(np.atleast_2d(seeds), lo, hi)))
    if not search and seeds is not None:
        starts = starts[-1:]  # the caller's sampled search ended at its last seed

    def sampled():
        if not search:  # the caller has just run it from the same seeds
            return None
        # the sampled search for the pose of lowest exact probability (joints and direction together,
        # ending on the joint constraints where the minimum lies there: a compass search from a box
        # centre stops short of a corner of the domain, and the bound cannot close on it)
        w = worst_exact_pose(mech, eps, R, distribution=distribution, x0=[full(dom, x, nq) for x in starts])
        return np.asarray(w.q, dtype=float)[list(dom.free)], np.asarray(w.direction, dtype=float)

    # it does not depend on the starts' directions and their polish: on a second core, alongside them
    with Background(sampled, enabled=search and int(workers) > 1) as job:
        for x in starts:
            s.consider(np.asarray(x)[None], s.direction(np.asarray(x))[None])
        s.polish()
        found = job.result()
    if found is not None:
        s.consider(dom.coords(found[0][None]), found[1][None])
    face0 = start_patches()
    root = _Box(lo.copy(), hi.copy(), *face0, np.zeros(len(face0[0])), 0.0, math.inf, False)
    bad, feas = _infeasible(dom.constraint_fn, root.L[None], root.H[None])
    s.processed = 1
    t0 = time.perf_counter()
    if not bad[0]:
        root.feasible = bool(feas[0])
        s.evaluate([root])
        s.push([root])
    stopped = run(
        s,
        workers=workers,
        max_boxes=max_boxes,
        stop=stop,
        level=stop_at,
        callback=None if callback is None else (lambda n, lb, best: callback(n, -lb, -best)),
        start=t0,
    )
    lower = s.bound()
    n_open, processed = s.open_count(), s.processed
    for _, _, b in s.heap:
        s.set_aside(b, min(b.lb, b.proven))
    if leaves is not None:
        leaves.extend(s.kept)
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
        x=dom.joints(s.best_x[None])[0],
        direction=s.best_u,
        certified=bool(certified),
        probability_lower_bound=max(0.0, float(lower)),
        best_value=float(s.best),
        boxes=processed,
        open_boxes=n_open,
        reason=reason,
        method="exact probabilities at the vertex pairs of joint boxes and lifted direction patches"
        + ("; whole joint boxes from their bound of sigma_1 (Eaton's tail bound)" if sigma is not None else ""),
    )
