"""The joint space a certified search covers: the searched joints, their box and the joint
constraints inside it, in the search's coordinates.

By default the coordinates are the searched joints.  :func:`sheared` takes a joint constraint on
two joints as a coordinate in place of one of them (``s_r = a . x``), so the constraint's planes
become faces of the boxes: the worst poses of a design made at a sampled set of poses lie along
such a constraint (the paper robot's interference limit), and boxes crossed by a plane need their
own polytope points where a box with the plane as a face needs none.  The replaced joint's limits
become the constraint rows instead, crossing the boxes only where they meet.  Units: rad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from tolsynth.analysis.certify_symmetry import KEEP, MIRROR, MIRROR_TURN, TURN
from tolsynth.analysis.interval_ops import round_down as _dn
from tolsynth.analysis.interval_ops import round_up as _up
from tolsynth.analysis.intervals import IntervalFunction
from tolsynth.kinematics.joint_space import _feasible, _limits

__all__ = ["Domain", "domain", "constraints", "full", "sheared"]


@dataclass
class Domain:
    free: list
    held: dict  # joint -> value (rad) in the reported pose
    why: dict  # joint -> reason
    lo: np.ndarray  # the box of the coordinates
    hi: np.ndarray
    constraint_fn: object
    linear: tuple  # (a, lower, upper) of each linear constraint, a over the coordinates
    M: np.ndarray | None = None  # the searched joints are M @ coordinates; None: the coordinates themselves
    halved: tuple = ()  # joints searched over half a turn of a wider range (Structure.half_turn)
    periods: dict = None  # searched joint's index -> its period (2 pi, or pi when halved) where its range was cut
    # the symmetries that cut joints to half their range, in the order the fold applies them: each
    # (Structure's Symmetry, searched index of the joint cut); every later one keeps the joints cut before
    cuts: tuple = ()

    def fold(self, Q: np.ndarray) -> np.ndarray:
        """Searched joints Q (n, k) moved into the box by the symmetries that cut it: a pose past a
        symmetry's cut by the symmetry (each cut in turn), each cut joint by whole periods: the
        same sensitivities up to sign (and the symmetries' residuals), so a seed keeps its value
        instead of being clipped."""
        Q = np.array(Q, dtype=float)
        for sym, i in self.cuts:
            op = sym.ops[self.free[i]]
            if i in (self.periods or {}):  # a whole period: the half kept, or its mirror image
                Q[:, i] = self.lo[i] + np.mod(Q[:, i] - self.lo[i], 2 * math.pi)
            # past the cut: above it, or for a range symmetric about 0 cut to [0, hi], below it
            past = Q[:, i] < self.lo[i] if op == MIRROR and i not in (self.periods or {}) else Q[:, i] > self.hi[i]
            for o, j in enumerate(self.free):
                op_o = sym.ops[j]
                if op_o == TURN:
                    Q[past, o] += -math.pi if o == i else math.pi
                elif op_o == MIRROR:
                    Q[past, o] = -Q[past, o]
                elif op_o == MIRROR_TURN:
                    Q[past, o] = math.pi - Q[past, o]
        for i, period in (self.periods or {}).items():
            Q[:, i] = self.lo[i] + np.mod(Q[:, i] - self.lo[i], period)
        return np.minimum(np.maximum(Q, self.lo), self.hi)  # a rounding past the end

    def symmetry_excess(self, w: np.ndarray) -> float:
        """What the cutting symmetries' residuals can add to sigma_1 beyond the box (mm), with ``w``
        the kept columns' variance weights: each one at most ``||Delta W^1/2||_2 <=
        ||Delta W^1/2||_F``, summed over the cuts a pose may pass, rounded up."""
        total = 0.0
        for sym, _ in self.cuts:
            r = np.asarray(sym.residual, dtype=float)
            total = _up(
                total + _up(math.sqrt(_up(float(np.sum(_up(r * r) * np.asarray(w, dtype=float)) * (1 + 1e-12)))))
            )
        return float(total)

    def joints(self, X: np.ndarray) -> np.ndarray:
        """Searched joints (n, k) at coordinates X (n, k)."""
        X = np.asarray(X, dtype=float)
        return X if self.M is None else X @ self.M.T

    def coords(self, Q: np.ndarray) -> np.ndarray:
        """Coordinates (n, k) of searched joints Q (n, k)."""
        Q = np.asarray(Q, dtype=float)
        return Q if self.M is None else np.linalg.solve(self.M, Q.T).T


def domain(mech, st, base_q: np.ndarray, half_turns: bool = True, symmetries: bool | None = None) -> Domain:
    """The searched joints, their box and constraints.  ``half_turns``: a joint whose half turn
    changes nothing searched (``st.half_turn``) is searched over half a turn; False for a map,
    which shows the whole range.  ``symmetries`` (default: as ``half_turns``): joints are cut to
    half their range where a symmetry of ``A`` (``st.symmetries``) maps the rest into the box
    (:func:`_symmetry_cuts`)."""
    lo_q, hi_q = _limits(mech)
    nq = len(lo_q)
    names = list(mech.joint_names)
    constrained = {names.index(jn) for c in mech.spec.joint_constraints for jn in c.terms}
    free = [j for j in range(nq) if (j in st.joints and j != st.rotation) or j in constrained]
    why = {}
    for j in range(nq):
        if j == st.rotation and j not in constrained:
            why[j] = "turns the error distribution rigidly about the base z axis"
        elif j not in free:
            why[j] = "the hand position's sensitivity does not depend on it"
    held = {j: float(np.clip(base_q[j], lo_q[j], hi_q[j])) for j in range(nq) if j not in free}
    lo, hi = lo_q[free].copy(), hi_q[free].copy()
    halved, periods = [], {}
    for i, j in enumerate(free):
        if j in st.periodic and j not in constrained and hi[i] - lo[i] > 2 * math.pi:
            hi[i] = lo[i] + 2 * math.pi  # one period: the joint enters only through sin and cos
            periods[i] = 2 * math.pi
        if half_turns and j in st.half_turn and j not in constrained and hi[i] - lo[i] > math.pi:
            hi[i] = lo[i] + math.pi  # every pose past it is one inside turned by half a turn
            halved.append(j)
            periods[i] = math.pi
    cuts = ()
    if half_turns if symmetries is None else symmetries:
        cuts = _symmetry_cuts(st, free, constrained, lo, hi, periods)
    linear = tuple(_rows(mech, free))
    return Domain(
        free,
        held,
        why,
        lo,
        hi,
        constraints(mech, free, held, linear),
        linear,
        None,
        tuple(halved),
        periods,
        cuts,
    )


def _symmetry_cuts(st, free, constrained, lo, hi, periods) -> tuple:
    """Cut joints to half their range by symmetries of ``A`` (``lo``, ``hi`` in place), greedily by
    the range removed: a joint the symmetry turns by half a turn, spanning more than half a turn
    and at most a whole one, to ``[lo, lo + pi]``; a joint it mirrors, of a range symmetric about
    0, to ``[0, hi]``, or over a whole period, to the half congruent to ``[0, pi]`` or ``[pi, 2 pi]``.
    A pose past the cut is the symmetry's image of one inside when every other joint the symmetry
    moves stays in its range: held (its value changes nothing), over a whole period or half a turn,
    or, mirrored, of a range symmetric about 0 (about pi / 2 for ``pi - q``).  A later cut keeps
    every joint cut before it, and no joint of a joint constraint moves.  Returns the cuts as
    ``(symmetry, searched index)`` in the order the fold applies them."""
    cuts: list = []
    done: set = set()
    while True:
        best, gain = None, 1e-9
        for sym in st.symmetries:
            ops = sym.ops
            if any(ops[j] for j in constrained) or any(ops[free[i]] for i in done):
                continue
            for i, j in enumerate(free):
                new = _half(ops[j], lo[i], hi[i], periods.get(i))
                if new is None or (hi[i] - lo[i]) - (new[1] - new[0]) <= gain:
                    continue
                if all(_stays(ops[jo], lo[o], hi[o], periods.get(o)) for o, jo in enumerate(free) if o != i):
                    best, gain = (sym, i, new), (hi[i] - lo[i]) - (new[1] - new[0])
        if best is None:
            return tuple(cuts)
        sym, i, (lo[i], hi[i]) = best
        cuts.append((sym, i))
        done.add(i)


def _half(op, lo, hi, period):
    """The half of a joint's range ``[lo, hi]`` a symmetry's ``op`` maps the rest onto, or None."""
    if op == TURN and math.pi < hi - lo <= 2 * math.pi and period != math.pi:
        return lo, lo + math.pi
    if op == MIRROR and period == 2 * math.pi:
        c = 2 * math.pi * math.ceil(lo / (2 * math.pi))  # a multiple of 2 pi in [lo, lo + 2 pi]
        return (c, c + math.pi) if c - lo <= math.pi else (c - math.pi, c)
    if op == MIRROR and period is None and lo == -hi and hi > 0:
        return 0.0, hi
    return None


def _stays(op, lo, hi, period) -> bool:
    """Whether a joint moved by ``op`` stays in ``[lo, hi]`` up to its period (``period``: the
    joint's period where its range was cut to it, else None)."""
    if op == KEEP or period is not None:
        return True
    return (op == MIRROR and lo == -hi) or (op == MIRROR_TURN and lo + hi == math.pi)


def _rows(mech, free):
    names = list(mech.joint_names)
    for c in mech.spec.joint_constraints:
        a = np.zeros(len(free))
        for jn, coef in c.terms.items():
            a[free.index(names.index(jn))] = coef
        yield a, c.lower, c.upper


def constraints(mech, free, held, rows, M=None):
    """``g(x) <= 0`` on boxes of the coordinates: the linear rows ``(a, lower, upper)`` (two each)
    and, for closed loops, ``c^2 - 1`` of every loop's closure argument at zero error.  On points
    the package's own feasibility test decides (the one Mechanism.joints applies)."""
    names = list(mech.joint_names)
    rows = list(rows)
    clos = None
    graphs = mech.graphs
    if getattr(graphs, "closure", None) is not None and graphs.closure.numel_out(0) > 0:
        x = ca.SX.sym("x", len(free))
        joints = x if M is None else ca.mtimes(ca.DM(M), x)
        q = [ca.SX(float(held.get(j, 0.0))) for j in range(len(names))]
        for i, j in enumerate(free):
            q[j] = joints[i]
        cl = graphs.closure
        cl = cl if cl.is_a("SXFunction") else cl.expand()
        c = cl.call([ca.vertcat(*q), ca.DM.zeros(cl.nnz_in(1))])[0]
        clos = IntervalFunction(ca.Function("closure_margin", [x], [ca.densify(c * c - 1.0)]))
    if not rows and clos is None:
        return None
    nq = len(names)

    def fn(L, H):
        parts_lo, parts_hi = [], []
        for a, lower, upper in rows:
            terms_lo = np.where(a > 0, a * L, a * H)
            terms_hi = np.where(a > 0, a * H, a * L)
            slack = 4.0 * len(a) * 2.0**-53 * np.abs(np.concatenate([terms_lo, terms_hi], axis=1)).sum(axis=1)
            v_lo, v_hi = _dn(terms_lo.sum(axis=1) - slack), _up(terms_hi.sum(axis=1) + slack)
            parts_lo += [v_lo - upper, lower - v_hi]
            parts_hi += [v_hi - upper, lower - v_lo]
        g_lo = np.array(parts_lo).T if parts_lo else np.zeros((len(L), 0))
        g_hi = np.array(parts_hi).T if parts_hi else np.zeros((len(L), 0))
        if clos is not None:
            cl_lo, cl_hi, _ = clos.evaluate(L, H)
            g_lo, g_hi = np.hstack([g_lo, cl_lo]), np.hstack([g_hi, cl_hi])
        point = np.all(L == H, axis=1)
        if point.any():  # a point: the package's own test of the limits and joint constraints
            Q = np.empty((nq, int(point.sum())))
            for j, v in held.items():
                Q[j] = v
            X = L[point] if M is None else L[point] @ M.T
            for i, j in enumerate(free):
                Q[j] = X[:, i]
            ok = _feasible(mech, Q)
            g_hi[point, : 2 * len(rows)] = np.where(ok, 0.0, 1.0)[:, None]
        return g_lo, g_hi

    return fn


def full(dom: Domain, x: np.ndarray, nq: int) -> np.ndarray:
    """The whole joint vector at coordinates ``x`` (k,)."""
    q = np.empty(nq)
    for j, v in dom.held.items():
        q[j] = v
    xj = dom.joints(np.asarray(x, dtype=float)[None])[0]
    for i, j in enumerate(dom.free):
        q[j] = xj[i]
    return q


def sheared(mech, dom: Domain) -> Domain:
    """``dom`` with its first joint constraint on two joints with coefficients +-1 taken as a
    coordinate (the module docstring), or ``dom`` itself where there is none.  The joint it replaces
    is the one of the narrower range (on the paper's robot the exact proof then needs 5 095 boxes,
    with the other 7 443).  The map is exact: ``x_r = a_r (s_r - a_o x_o)`` with ``a_r, a_o`` in
    {-1, 1}."""
    if dom.M is not None:
        return dom
    for n, (a, lower, upper) in enumerate(dom.linear):
        support = np.flatnonzero(a)
        if len(support) != 2 or not np.all(np.abs(a[support]) == 1.0):
            continue
        width = dom.hi[support] - dom.lo[support]
        r, o = (support[1], support[0]) if width[1] < width[0] else (support[0], support[1])
        k = len(dom.free)
        M = np.eye(k)
        M[r, r] = a[r]
        M[r, o] = -a[r] * a[o]
        # the band's value over the box: the coordinate's range is the band cut to it
        reach_lo = a[o] * (dom.lo[o] if a[o] > 0 else dom.hi[o]) + a[r] * (dom.lo[r] if a[r] > 0 else dom.hi[r])
        reach_hi = a[o] * (dom.hi[o] if a[o] > 0 else dom.lo[o]) + a[r] * (dom.hi[r] if a[r] > 0 else dom.lo[r])
        lo, hi = dom.lo.copy(), dom.hi.copy()
        lo[r], hi[r] = max(lower, _dn(reach_lo)), min(upper, _up(reach_hi))
        if not lo[r] <= hi[r]:
            return dom  # nothing feasible: the plain domain says so
        rows = [(M[r].copy(), dom.lo[r], dom.hi[r])]  # the replaced joint's limits
        rows += [(b @ M, bl, bu) for m, (b, bl, bu) in enumerate(dom.linear) if m != n]
        return Domain(
            dom.free,
            dom.held,
            dom.why,
            lo,
            hi,
            constraints(mech, dom.free, dom.held, rows, M),
            tuple(rows),
            M,
            dom.halved,
            dom.periods,
            dom.cuts,
        )
    return dom
