"""Best-first branch and bound: a certified maximum of a function over a box in R^d.

:func:`maximize` needs two vectorised callables: ``bound_fn(lo, hi)`` gives a rigorous upper
bound of the objective on each box of a batch (from :mod:`tolsynth.analysis.intervals`), and
``point_fn(x)`` the objective at points, whose best feasible value is the lower side.  The boxes
are kept in a heap by their bound; each round takes the most promising ones, halves them along
their widest (scaled) side, bounds the halves in one call, evaluates their centres and drops the
halves that cannot beat the best value by more than the tolerance.  The result's ``upper_bound``
is the largest bound still standing (open, dropped or at the resolution limit), so
``best_value <= max <= upper_bound`` holds whether or not the gap closed.

Constraints ``g(x) <= 0`` come as an interval function too: a box with some ``g`` proven positive
everywhere holds no feasible point and is dropped; a box not proven feasible stays, and its points
count only when they are proven feasible (``g`` bounded above by 0 on the point itself).

Example
-------
>>> import numpy as np
>>> f = lambda x: -((x - 0.3) ** 2).sum(axis=1)
>>> def bound(lo, hi):  # minus the squared distance from (0.3, 0.3) to the box
...     return -((np.clip(0.3, lo, hi) - 0.3) ** 2).sum(axis=1)
>>> r = maximize(bound, f, [-1.0, -1.0], [2.0, 3.0], tol=1e-9)
>>> bool(r.certified), abs(round(r.best_value, 6))
(True, 0.0)
"""

from __future__ import annotations

import heapq
import time
from dataclasses import dataclass

import numpy as np

from tolsynth.analysis.certify_parallel import run
from tolsynth.errors import InputError

__all__ = ["MaximizeResult", "maximize"]


@dataclass(frozen=True)
class MaximizeResult:
    """Outcome of :func:`maximize`.

    Attributes
    ----------
    upper_bound : float
        Proven upper bound of the objective over the feasible part of the box (``-inf`` when every
        part is proven infeasible).
    best_value : float
        Largest objective value at a proven-feasible point found (``-inf`` if none).
    best_x : numpy.ndarray or None
        That point.
    boxes_processed : int
        Boxes bounded (the root and every half).
    certified : bool
        ``upper_bound - best_value <= tol + rtol * |best_value|``, or every box proven infeasible.
    reason : str
        Why not certified ("" when certified).
    open_boxes : int
        Boxes still undecided at the end.
    elapsed : float
        Wall time (s).
    """

    upper_bound: float
    best_value: float
    best_x: np.ndarray | None
    boxes_processed: int
    certified: bool
    reason: str
    open_boxes: int
    elapsed: float

    @property
    def gap(self) -> float:
        return self.upper_bound - self.best_value


def _vector(v, field: str) -> np.ndarray:
    a = np.atleast_1d(np.asarray(v, dtype=float))
    if a.ndim != 1 or not np.all(np.isfinite(a)):
        raise InputError(field, f"expected a 1-D array of finite numbers, got {v!r}")
    return a


class _Search:
    """State of one run: the best point, the heap and the bounds of the boxes set aside (and what
    :func:`tolsynth.analysis.certify_parallel.run` needs to share it out)."""

    sense = 1.0  # a maximum

    def __init__(self, point_fn, constraint_fn, lo, hi, tol, rtol, scale):
        self.point_fn, self.constraint_fn = point_fn, constraint_fn
        self.lo, self.hi, self.tol, self.rtol, self.scale = lo, hi, tol, rtol, scale
        self.best, self.best_x = -np.inf, None
        self.heap: list = []
        self.seq = 0
        self.dropped = -np.inf  # largest bound of a box dropped as unable to beat the best
        self.target = None  # boxes bounded by it are dropped too (a decision)
        self.stuck = -np.inf  # largest bound of a box too small to split
        self.leaves = None  # when kept: (lo, hi, ub) of every box set aside, a cover of the feasible part
        self.processed = 0  # boxes bounded
        self.shared = None  # on several processes: the incumbent they share (certify_parallel.Shared)

    def incumbent(self) -> float:
        """The best value found, by any worker: the threshold every worker uses is the serial one."""
        return self.best if self.shared is None else max(self.best, self.shared.incumbent())

    def threshold(self) -> float:
        best = self.incumbent()
        if self.target is not None and not best > self.target:
            return self.target  # the decision: only boxes that may exceed the target matter
        return best + self.tol + self.rtol * abs(best) if np.isfinite(best) else -np.inf

    def feasible_points(self, x):
        if self.constraint_fn is None:
            return np.ones(len(x), dtype=bool)
        _, g_hi = self.constraint_fn(x, x)
        g_hi = np.asarray(g_hi, dtype=float).reshape(len(x), -1)
        return (g_hi <= 0.0).all(axis=1)  # NaN (no information) is not proof

    def values(self, x):
        if len(x) == 0:
            return np.zeros(0)
        v = np.asarray(self.point_fn(x), dtype=float).reshape(len(x))
        v = np.where(np.isnan(v), -np.inf, v)
        return np.where(self.feasible_points(x), v, -np.inf)

    def consider(self, x) -> bool:
        """Evaluate points; keep the best feasible one.  Returns whether the best improved."""
        v = self.values(x)
        if len(v) and v.max() > self.best:
            j = int(np.argmax(v))
            self.best, self.best_x = float(v[j]), x[j].copy()
            if self.shared is not None:
                self.shared.offer(self.best)
            return True
        return False

    def polish(self, steps: int) -> None:
        """Compass search from the best point: +-h along each axis, h quartered on no progress."""
        if self.best_x is None or steps <= 0:
            return
        d = len(self.lo)
        h = 0.01 * self.scale
        eye = np.eye(d)
        for _ in range(steps):
            cand = np.clip(np.concatenate([self.best_x + eye * h, self.best_x - eye * h]), self.lo, self.hi)
            if not self.consider(cand):
                h = h * 0.25
                if np.all(h < 1e-12 * self.scale):
                    break

    def push(self, lo, hi, ub, feasible, min_width, g_lo=None, g_hi=None, split=None):
        thr = self.threshold()
        widths = (hi - lo) / self.scale
        side = np.argmax(widths, axis=1)
        if split is not None:
            # the bound function's own measure of how much each side widens the bound
            ok = np.isfinite(split).all(axis=1) & (split.max(axis=1, initial=0.0) > 0.0) & (hi > lo).any(axis=1)
            side = np.where(ok, np.argmax(np.where(hi > lo, split, -1.0), axis=1), side)
        elif g_lo is not None:
            # a box proven feasible is halved where the gradient makes the bound loosest (its
            # smear); one across the constraints' boundary along its widest side, to settle it
            with np.errstate(invalid="ignore"):
                smear = np.maximum(np.abs(g_lo), np.abs(g_hi)) * (hi - lo)
            ok = feasible & np.isfinite(smear).all(axis=1) & (smear.max(axis=1, initial=0.0) > 0.0)
            side = np.where(ok, np.argmax(np.where(np.isfinite(smear), smear, 0.0), axis=1), side)
        for k in range(len(ub)):
            if ub[k] <= thr:
                self.dropped = max(self.dropped, float(ub[k]))
                self.keep_leaf(lo[k], hi[k], ub[k])
            elif widths[k].max() < min_width:
                self.stuck = max(self.stuck, float(ub[k]))
                self.keep_leaf(lo[k], hi[k], ub[k])
            else:
                self.seq += 1
                heapq.heappush(self.heap, (-float(ub[k]), self.seq, lo[k], hi[k], bool(feasible[k]), int(side[k])))

    def keep_leaf(self, lo, hi, ub) -> None:
        if self.leaves is not None:
            self.leaves.append((np.array(lo, dtype=float), np.array(hi, dtype=float), float(ub)))

    def upper(self) -> float:
        return max(self.open_bound(), self.dropped, self.stuck, self.best)

    bound = upper

    # -- what certify_parallel.run needs ------------------------------------------------------
    @staticmethod
    def key(entry) -> float:
        return -entry[0]

    def open_bound(self) -> float:
        return -self.heap[0][0] if self.heap else -np.inf

    def open_count(self) -> int:
        return len(self.heap) if self.heap and -self.heap[0][0] > self.threshold() else 0

    def settled(self, thr) -> bool:
        if -self.heap[0][0] <= thr:  # nothing left can beat the best by more than the tolerance
            self.dropped = max(self.dropped, -self.heap[0][0])
            return True
        return False

    def past(self, level) -> str:
        return f"a point above {level:.9g} found" if self.best > level else ""

    def to_worker(self, heap, shared) -> None:
        self.heap, self.shared, self.processed = heap, shared, 0
        self.dropped = self.stuck = -np.inf
        self.leaves = None if self.leaves is None else []

    def part(self) -> dict:
        return dict(
            best=self.best,
            x=self.best_x,
            dropped=self.dropped,
            stuck=self.stuck,
            n_boxes=self.processed,
            leaves=self.leaves,
        )

    def merge(self, p) -> None:
        if p["best"] > self.best:
            self.best, self.best_x = p["best"], p["x"]
        self.dropped, self.stuck = max(self.dropped, p["dropped"]), max(self.stuck, p["stuck"])
        self.processed += p["n_boxes"]
        if self.leaves is not None:
            self.leaves.extend(p["leaves"])


def _bounds(bound_fn, lo, hi):
    """Upper bounds (NaN read as +inf) and, when bound_fn gives them, gradient bounds and split
    weights."""
    r = bound_fn(lo, hi)
    g_lo = g_hi = split = None
    if isinstance(r, tuple):
        r, g_lo, g_hi, *rest = r
        if g_lo is not None:
            g_lo = np.asarray(g_lo, dtype=float).reshape(lo.shape)
            g_hi = np.asarray(g_hi, dtype=float).reshape(lo.shape)
        if rest and rest[0] is not None:
            split = np.asarray(rest[0], dtype=float).reshape(lo.shape)
    ub = np.asarray(r, dtype=float).reshape(len(lo))
    return np.where(np.isnan(ub), np.inf, ub), g_lo, g_hi, split


def _monotone_faces(lo, hi, g_lo, g_hi, usable):
    """Where the objective provably rises (falls) along a side of a box whose points are all
    feasible, its maximum lies on the upper (lower) face: the box shrinks to that face."""
    up = (g_lo > 0.0) & usable[:, None] & (hi > lo)
    down = (g_hi < 0.0) & usable[:, None] & (hi > lo)
    rows = np.flatnonzero((up | down).any(axis=1))
    return np.where(up, hi, lo), np.where(down, lo, hi), rows


def _infeasible(constraint_fn, lo, hi):
    """Per box: proven infeasible (some g > 0 everywhere), proven feasible (every g <= 0)."""
    g_lo, g_hi = constraint_fn(lo, hi)
    g_lo = np.asarray(g_lo, dtype=float).reshape(len(lo), -1)
    g_hi = np.asarray(g_hi, dtype=float).reshape(len(lo), -1)
    return (g_lo > 0.0).any(axis=1), (g_hi <= 0.0).all(axis=1)


def maximize(
    bound_fn,
    point_fn,
    lo,
    hi,
    tol: float,
    max_boxes: int = 200_000,
    constraint_fn=None,
    *,
    rtol: float = 0.0,
    scale=None,
    batch: int = 256,
    x0=None,
    local_steps: int = 40,
    min_width: float = 1e-12,
    callback=None,
    stop=None,
    target: float | None = None,
    stop_above: float | None = None,
    leaves: list | None = None,
    workers: int = 1,
    level_aware: bool = False,
) -> MaximizeResult:
    """Certified maximum of an objective over the box ``lo <= x <= hi`` (and ``g(x) <= 0``).

    Parameters
    ----------
    bound_fn : callable
        ``bound_fn(lo, hi) -> ub``: ``lo, hi`` of shape (n, d), ``ub`` of shape (n,), a rigorous
        upper bound of the objective on each box (NaN is read as ``+inf``).  It may return
        ``(ub, g_lo, g_hi)`` with rigorous bounds (n, d) of the gradient on each box (NaN: none;
        :meth:`tolsynth.analysis.intervals.BoxFunction.upper` does): boxes are then halved where
        the gradient widens the bound most, and a box proven feasible shrinks to its upper (lower)
        face along a side where the objective provably rises (falls).
    point_fn : callable
        ``point_fn(x) -> values``: ``x`` of shape (n, d), the objective at each point (NaN: none).
    lo, hi : array_like
        The box, shape (d,), finite, ``lo <= hi``.
    tol : float
        Absolute tolerance: boxes whose bound is within ``tol`` (plus ``rtol * |best|``) of the best
        value are dropped, and the result is certified when the final gap is within it.
    max_boxes : int
        Boxes to bound (about: a round may pass it); past it the result is returned with
        ``certified=False`` unless the gap has already closed.
    constraint_fn : callable, optional
        ``constraint_fn(lo, hi) -> (g_lo, g_hi)``, each of shape (n, m): interval bounds of the
        constraints ``g(x) <= 0`` on each box (on points, called with ``lo == hi``).
    rtol : float
        Relative part of the tolerance.
    scale : array_like, optional
        Per-coordinate scale used to choose the side to halve (default: the box's widths).
    batch : int
        Boxes taken from the heap per round (their halves are bounded in one call).
    x0 : array_like, optional
        Points (k, d) or (d,) to evaluate first: a good start prunes sooner.
    local_steps : int
        Compass-search steps from each new best point (0: none).
    min_width : float
        Boxes narrower than this (relative to ``scale``) on every side are not split further.
    callback : callable, optional
        ``callback(boxes_processed, upper_bound, best_value)`` after every round.
    stop : callable, optional
        ``stop() -> str``: checked after every round; a non-empty string ends the search, not
        certified unless the gap has closed, with that string as the reason (a time limit).
    target : float, optional
        A decision instead of the maximum: while no point above ``target`` is known, boxes that
        cannot exceed it are dropped (and only those), and the result is certified when
        ``upper_bound <= target`` (the maximum proven below the target, by a bound that need not
        be within ``tol`` of it); once a point above it is found, the search goes on to the
        maximum within the tolerance.
    stop_above : float, optional
        End the search as soon as a feasible point exceeds this value (not certified; the point is
        the answer to the decision).
    leaves : list, optional
        When given, ``(lo, hi, upper_bound)`` of every box the search set aside (dropped, too small
        to split, or left open) is appended: together with the boxes proven infeasible they cover
        the box, so the largest of their bounds over a region bounds the objective there (a
        certified map).
    workers : int
        Processes: past :data:`~tolsynth.analysis.certify_parallel.SERIAL_SECONDS` of serial search
        the open boxes are dealt to this many workers sharing the best value
        (:mod:`tolsynth.analysis.certify_parallel`); 1: serial throughout.
    level_aware : bool
        ``bound_fn(lo, hi, level)`` is called with the value its boxes must be proven below to be
        set aside (when there is one), so that it may spend more work on the boxes that work can
        decide.  Speed only: any rigorous bound is as valid.

    Returns
    -------
    MaximizeResult
    """
    t0 = time.perf_counter()
    lo, hi = _vector(lo, "lo"), _vector(hi, "hi")
    if lo.shape != hi.shape or np.any(lo > hi):
        raise InputError("lo, hi", "the box needs lo <= hi, of one length", f"lo {lo}, hi {hi}")
    if not (np.isfinite(tol) and tol >= 0.0) or not (np.isfinite(rtol) and rtol >= 0.0):
        raise InputError("tol", f"tol={tol}, rtol={rtol}", "finite numbers >= 0")
    if int(max_boxes) < 1 or int(batch) < 1:
        raise InputError("max_boxes", f"max_boxes={max_boxes}, batch={batch}", "integers >= 1")
    d = len(lo)
    width = hi - lo
    scale = np.where(width > 0, width, 1.0) if scale is None else _vector(scale, "scale")
    if scale.shape != lo.shape or np.any(scale <= 0):
        raise InputError("scale", f"{scale}", f"{d} positive numbers")
    s = _Search(point_fn, constraint_fn, lo, hi, float(tol), float(rtol), scale)
    s.target = None if target is None else float(target)
    s.leaves = None if leaves is None else []

    L, H = lo[None, :], hi[None, :]
    feasible = np.array([constraint_fn is None])
    s.processed = 1
    if constraint_fn is not None:
        bad, feasible = _infeasible(constraint_fn, L, H)
        if bad[0]:
            return MaximizeResult(-np.inf, -np.inf, None, 1, True, "", 0, time.perf_counter() - t0)
    seeds = [0.5 * (lo + hi)]
    if x0 is not None:
        seeds.append(np.clip(np.atleast_2d(np.asarray(x0, dtype=float)).reshape(-1, d), lo, hi))
    if s.consider(np.vstack(seeds)):
        s.polish(local_steps)
    ub, g_lo, g_hi, split = _bounds(bound_fn, L, H)
    s.push(L, H, ub, feasible, min_width, g_lo, g_hi, split)

    def step(thr):
        """One round: the most promising boxes halved, their halves bounded and kept or set aside."""
        take = []
        while s.heap and len(take) < batch and -s.heap[0][0] > thr:
            take.append(heapq.heappop(s.heap))
        P_ub = np.array([-t[0] for t in take])
        P_lo = np.array([t[2] for t in take])
        P_hi = np.array([t[3] for t in take])
        P_feas = np.array([t[4] for t in take])
        k = np.array([t[5] for t in take])  # the side chosen when the box was pushed
        rows = np.arange(len(take))
        mid = 0.5 * (P_lo[rows, k] + P_hi[rows, k])
        A_hi, B_lo = P_hi.copy(), P_lo.copy()
        A_hi[rows, k] = mid
        B_lo[rows, k] = mid
        C_lo, C_hi = np.concatenate([P_lo, B_lo]), np.concatenate([A_hi, P_hi])
        C_feas = np.concatenate([P_feas, P_feas])
        fn = (lambda lo, hi: bound_fn(lo, hi, float(thr))) if level_aware and np.isfinite(thr) else bound_fn
        ub, g_lo, g_hi, split = _bounds(fn, C_lo, C_hi)
        ub = np.minimum(ub, np.concatenate([P_ub, P_ub]))  # a parent's bound holds on its halves
        s.processed += len(C_lo)
        keep = np.ones(len(C_lo), dtype=bool)
        if constraint_fn is not None and not C_feas.all():
            todo = np.flatnonzero(~C_feas)
            bad, ok = _infeasible(constraint_fn, C_lo[todo], C_hi[todo])
            keep[todo[bad]] = False
            C_feas[todo[ok]] = True
        if g_lo is not None:
            C_lo, C_hi, red = _monotone_faces(C_lo, C_hi, g_lo, g_hi, keep & C_feas)
            if len(red):  # bound the shrunken boxes again: a thinner box has a tighter bound
                ub2, g_lo[red], g_hi[red], split2 = _bounds(fn, C_lo[red], C_hi[red])
                if split is not None and split2 is not None:
                    split[red] = split2
                ub[red] = np.minimum(ub[red], ub2)
                s.processed += len(red)
        if s.consider(0.5 * (C_lo[keep] + C_hi[keep])):
            s.polish(local_steps)
        s.push(
            C_lo[keep],
            C_hi[keep],
            ub[keep],
            C_feas[keep],
            min_width,
            None if g_lo is None else g_lo[keep],
            None if g_hi is None else g_hi[keep],
            None if split is None else split[keep],
        )

    s.step = step
    stopped = run(s, workers=workers, max_boxes=max_boxes, stop=stop, level=stop_above, callback=callback, start=t0)
    processed = s.processed
    upper = s.upper()
    n_open = s.open_count()
    for t in s.heap:
        s.keep_leaf(t[2], t[3], -t[0])
    if leaves is not None:
        leaves.extend(s.leaves)
    slack = s.tol + s.rtol * abs(s.best) if np.isfinite(s.best) else 0.0
    if upper == -np.inf:
        certified, reason = True, ""  # every box proven infeasible
    elif not np.isfinite(s.best):
        certified, reason = False, "no feasible point found"
    else:
        certified = upper - s.best <= slack or (s.target is not None and upper <= s.target)
        reason = ""
        if not certified:
            reason = (
                stopped
                or (f"box limit reached ({processed} boxes, {n_open} open)" if n_open else "")
                or f"boxes at the resolution limit (min_width={min_width}) still bound above the best"
            )
    return MaximizeResult(
        float(upper), float(s.best), s.best_x, processed, bool(certified), reason, n_open, time.perf_counter() - t0
    )
