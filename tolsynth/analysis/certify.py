"""Certified worst pose: a proven bound of the error statistics over the whole joint space.

:func:`certify_worst_pose` runs a branch and bound (:func:`tolsynth.analysis.branch_bound.maximize`)
over the joint ranges, inside the joint constraints (the paper's interference limit) and, for
closed loops, the loop-closure condition ``closure(q, 0)^2 <= 1``.  What it returns is either a
proof -- no pose anywhere in the joint space is worse than ``upper_bound`` (the largest principal
standard deviation, mm) or ``probability_lower_bound`` (the smallest probability of one component
of the hand error, along any direction, to stay within ``R``) -- together with the best pose it
found, whose value lies within the search's tolerance of the bound; or, when the box limit or the
time limit stops it first, the bound reached so far and ``certified = False``.

Before splitting, facts proven on the graph shrink the search
(:mod:`tolsynth.analysis.certify_structure`): error parameters without effect are dropped, joints
without effect held, a joint that turns the error distribution rigidly about the base z axis held,
a joint range beyond one turn cut to one period where the joint enters only through sine and
cosine, and beyond half a turn to half a turn where that changes no column of ``A`` but its sign.
The bounds are those of :mod:`tolsynth.analysis.certify_bounds` (Gaussian reading: the
largest principal standard deviation) and :mod:`tolsynth.analysis.certify_exact` (the exact
per-direction probability).  Units: mm and rad.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from tolsynth.analysis.branch_bound import maximize
from tolsynth.analysis.certify_bounds import PolygonSigmaBounds, sigma_bounds
from tolsynth.analysis.certify_domain import domain as _domain
from tolsynth.analysis.certify_domain import full as _full
from tolsynth.analysis.certify_domain import sheared
from tolsynth.analysis.certify_parallel import worker_count
from tolsynth.analysis.certify_structure import structure
from tolsynth.analysis.interval_ops import round_down as _dn
from tolsynth.analysis.interval_ops import round_up as _up
from tolsynth.checks import check_count, check_positive, check_probability, check_real
from tolsynth.errors import InputError, OutOfRangeError
from tolsynth.progress import Progress, remaining
from tolsynth.tabular import jsonable

__all__ = ["Certificate", "certify_worst_pose", "check_limits", "LIMITS", "DEFAULT_RTOL", "DEFAULT_MAX_BOXES"]

#: relative gap between the certified bound and the best value found (sigma criterion)
DEFAULT_RTOL = 5e-4
#: boxes bounded before the search gives up (not certified, the bound so far reported)
DEFAULT_MAX_BOXES = 400_000


@dataclass(frozen=True)
class Certificate:
    """Outcome of :func:`certify_worst_pose`.

    Attributes
    ----------
    criterion : {"sigma", "components"}
        Largest principal standard deviation, or smallest per-direction probability.
    probability : {"gaussian", "exact"}
        How ``probability_lower_bound`` reads the error: the Gaussian approximation (it follows
        from the sigma bound; the default with ``criterion="sigma"``) or the exact distribution
        of the linear model (the default with ``criterion="components"``).
    certified : bool
        Without a ``target``: the bound is proven and the best pose found is within the tolerance
        of it.  With one: the target is proven (``upper_bound <= target``, or
        ``probability_lower_bound >= target`` for the exact criterion), nothing else; a pose found
        past the target, or a bound that stops short of it, leaves it False and ``reason`` says
        which (the pose and its value).
    upper_bound : float or None
        Proven upper bound of the largest principal standard deviation over the joint space (mm);
        None for the exact criterion.
    probability_lower_bound : float or None
        Proven lower bound of the smallest per-direction probability ``P(|u . dr| <= R)`` (with R).
    best_value : float
        The criterion at the best pose found (sigma in mm, or the probability).
    q : ndarray
        That pose (rad, every joint; held joints at their reference values).
    direction : ndarray or None
        For the exact criterion, the direction of the smallest probability there.
    boxes, open_boxes : int
        Boxes bounded, and left undecided at the end.
    reason : str
        Why not certified ("" when certified).
    target : float or None
        The decision asked (:func:`certify_worst_pose`'s ``target``: sigma_1 in mm, or the exact
        probability), None for the tightest bound.
    held : dict
        Joint name -> why it was held (it cannot change the criterion).
    half_turn : tuple of str
        Searched joints covered over half a turn only: half a turn of each changes no column of the
        sensitivity but its sign (proven), so the other half holds the same values.
    symmetries : tuple of (str, str)
        The symmetries that cut a searched joint to half its range, as (the map, the joint cut),
        e.g. ``("q4 + pi, -q5", "q4")``: a pose past the cut is the map's image of one inside, with
        the same columns of the sensitivity up to sign and a residual from the twists' rounded
        constants, added to ``upper_bound`` (about 1e-13 mm).  The Gaussian reading only: the exact
        search covers the whole range.
    searched : tuple of str
        The joints searched.
    dropped : tuple of str
        Error parameters without effect on the hand position.
    history : tuple of (int, float, float)
        After each round of the branch and bound: boxes bounded, the bound proven so far and the
        best value found (sigma_1 in mm for the Gaussian reading; for the exact per-component
        probability its proven lower bound and the lowest found): the gap closing.
    leaves : tuple of ndarray or None
        With ``keep_boxes=True``: ``(lo, hi, bound)``, the boxes of the searched joints (rad) the
        search set aside with the bound proven on each (shapes (m, k), (m, k), (m,)); with the
        boxes proven infeasible they cover the searched joint space, so the largest bound of
        the boxes meeting a region bounds the criterion there (a certified map).  That space is
        cut where ``half_turn`` and ``symmetries`` say (the rest is its image);
        :mod:`tolsynth.analysis.certify_map` covers the whole joint ranges.
    """

    model: str
    criterion: str
    probability: str
    R: float | None
    tolerances: dict
    certified: bool
    upper_bound: float | None
    probability_lower_bound: float | None
    best_value: float
    q: np.ndarray
    direction: np.ndarray | None
    boxes: int
    open_boxes: int
    elapsed_s: float
    reason: str
    rtol: float
    held: dict = field(default_factory=dict)
    half_turn: tuple = ()
    symmetries: tuple = ()
    searched: tuple = ()
    dropped: tuple = ()
    method: str = ""
    history: tuple = ()
    leaves: tuple | None = None
    target: float | None = None

    @property
    def gap(self) -> float:
        """Bound minus best value (sigma, mm), or best value minus bound (probability)."""
        if self.criterion == "sigma":
            return float(self.upper_bound - self.best_value)
        return float(self.best_value - self.probability_lower_bound)

    def to_dict(self) -> dict:
        """Plain dict for JSON (arrays as lists; a bound that did not close, inf or NaN, as None, so
        ``json.dumps(..., allow_nan=False)`` takes it); the boxes kept are left out (they can be large)."""
        return jsonable({k: v for k, v in self.__dict__.items() if k != "leaves"}, null=True)

    def summary(self) -> str:
        """One line per fact: the proof (or why not), the best pose, what was held and searched."""
        head = "certified" if self.certified else "NOT certified"
        lines = []
        if self.upper_bound is not None:
            lines.append(
                f"{head}: largest principal sigma <= {self.upper_bound:.6g} mm over the whole joint space; "
                f"{self.best_value if self.criterion == 'sigma' else self.upper_bound:.6g} mm reached"
            )
        if self.probability_lower_bound is not None:
            lines.append(
                f"{head}: every component P(|u.dr| <= {self.R:g} mm) >= {self.probability_lower_bound:.8f} "
                f"({self.probability}); lowest found {self.best_value:.8f}"
                if self.criterion == "components"
                else f"  (Gaussian per-component probability >= {self.probability_lower_bound:.8f})"
            )
        lines.append(
            f"  pose (deg) ({', '.join(f'{v:.3f}' for v in np.degrees(self.q))}), {self.boxes} boxes, "
            f"{self.elapsed_s:.1f} s" + ("" if self.certified else f"; {self.reason}")
        )
        if self.held:
            lines.append("  held: " + "; ".join(f"{k} ({v})" for k, v in self.held.items()))
        if self.half_turn:
            lines.append("  searched over half a turn (the other half the same, proven): " + ", ".join(self.half_turn))
        for sym, joint in self.symmetries:
            lines.append(f"  {joint} searched over half its range: the rest is the image of it under {sym} (proven)")
        if self.target is not None:
            goal = (
                f"sigma_1 <= {self.target:.9g} mm"
                if self.criterion == "sigma"
                else f"every component probability >= {self.target:.12g}"
            )
            lines.append(f"  target {goal} everywhere: " + ("proven" if self.certified else "NOT proven"))
        if self.dropped:
            lines.append("  no effect on the hand position: " + ", ".join(self.dropped))
        return "\n".join(lines)


#: the certified search's limits a caller may set, here and in the certified exchange's
#: ``certify_options`` (:func:`tolsynth.synthesize_workspace`)
LIMITS = ("rtol", "tol", "max_boxes", "time_limit", "workers")


def check_limits(field=lambda key: key, **limits) -> dict:
    """The limits of :data:`LIMITS` given, each checked by its one rule (None: the default, kept
    None), so that :func:`certify_worst_pose` and the callers that pass them on refuse the same
    values before any work; ``field(key)`` names an offending one.  ``time_limit`` is seconds
    > 0 (None: none; 0 is refused, not read as none); ``max_boxes`` and ``workers`` are counts
    >= 1, not bools."""
    out = {}
    for key, v in limits.items():
        f = field(key)
        if key not in LIMITS:
            raise InputError(f, f"unknown limit {key!r}", ", ".join(LIMITS))
        if v is None:
            out[key] = None
        elif key == "rtol":
            out[key] = check_positive(v, f, "relative", upper=0.5, lower=1e-12)
        elif key == "tol":
            out[key] = check_positive(v, f, "probability", upper=0.5)
        elif key == "max_boxes":
            out[key] = check_count(v, f, 1, 10**9)
        elif key == "time_limit":
            try:
                out[key] = check_positive(v, f, "s")
            except InputError as e:  # the same type, with None named among the allowed values
                raise type(e)(f, f"got {v!r}", "a number of seconds > 0, or None for no limit") from None
        else:
            out[key] = worker_count(v, f)
    return out


# ---------------------------------------------------------------------------------------------
def certify_worst_pose(
    mechanism,
    tolerances,
    distribution=None,
    criterion: str = "sigma",
    R: float | None = None,
    probability: str | None = None,
    *,
    rtol: float | None = None,
    tol: float | None = None,
    max_boxes: int = DEFAULT_MAX_BOXES,
    x0=None,
    base_q=None,
    progress=None,
    time_limit: float | None = None,
    target: float | None = None,
    stop_at: float | None = None,
    keep_boxes: bool = False,
    workers: int | None = None,
    search: bool = True,
) -> Certificate:
    """A proven bound of the worst accuracy over the whole joint space (module docstring).

    Parameters
    ----------
    mechanism : Mechanism
    tolerances : str, dict or array
        Tolerance set name or half-widths (tolerance units).
    distribution : str or dict, optional
        As :func:`tolsynth.synthesize` (default: the model file's, else uniform).
    criterion : {"sigma", "components"}
        Bound the largest principal standard deviation, or the smallest per-direction probability
        ``P(|u . dr| <= R)`` (needs ``R``).
    R : float, optional
        Radius (mm), > 0.  With ``criterion="sigma"`` it adds the Gaussian per-component
        probability bound.
    probability : {"gaussian", "exact"}
        The reading of the per-direction probability (exact: no Gaussian approximation,
        :mod:`tolsynth.probability.exact`; only with ``criterion="components"``).
    rtol : float, optional
        Relative gap at which the search stops, certified (sigma; default :data:`DEFAULT_RTOL`).
    tol : float, optional
        Absolute gap in probability (exact criterion; default 2e-7).
    max_boxes : int
        Boxes to bound before giving up, >= 1 (None: :data:`DEFAULT_MAX_BOXES`).
    x0 : array_like, optional
        Poses (rad, every joint) to evaluate first, e.g. the poses already known to be bad.
    base_q : array_like, optional
        Values of the held joints in the reported pose (default: the model's reference pose, else 0
        clipped to the limits).
    progress : None, bool or callable
        A progress bar on stderr (None: on a terminal, for runs over a couple of seconds).
    time_limit : float, optional
        Seconds, > 0 (None: no limit of its own); also any enclosing
        :func:`tolsynth.progress.time_limit` block.
    target : float, optional
        A decision: prove sigma_1 <= target (mm) everywhere (sigma), or the probability >= target
        (exact components), not the tightest bound.  ``certified`` then means the target is
        proven and nothing else: a pose found past it (sigma_1 above it, the probability below
        it) disproves it, and ``reason`` names that pose and its value.  Proven, the bound returned
        lies between the best value and the target.  The Certificate records it (``target``).
    stop_at : float, optional
        Stop as soon as a pose worse than this is found (sigma above it, probability below it).
    keep_boxes : bool
        Keep the boxes set aside and their bounds (``Certificate.leaves``), for a certified map.
    workers : int, optional
        Processes for a search that outlasts its first half second (default: the machine's cores,
        at most 8; 1: one process throughout).  The certificate means the same whatever the count;
        its numbers may differ within the search's tolerance.
    search : bool
        Exact reading: before the branch and bound, the sampled search for the pose of lowest
        probability from the seeds ``x0`` (its incumbent); False where the caller has just run it
        and gives its result as the last of ``x0`` (the certified exchange: its full sampled search
        precedes every proof), the incumbent then taken there.  Speed only.

    Returns
    -------
    Certificate

    Examples
    --------
    >>> import tolsynth
    >>> from tolsynth.analysis.certify import certify_worst_pose
    >>> c = certify_worst_pose(tolsynth.load_model("planar_2r"), "coarse", progress=False)
    >>> bool(c.certified), bool(c.best_value <= c.upper_bound <= c.best_value * (1 + 1e-3))
    (True, True)
    """
    t0 = time.perf_counter()
    from tolsynth.kinematics.joint_space import MODEL_REFERENCE, _reference
    from tolsynth.kinematics.mechanism import as_mechanism
    from tolsynth.probability.distributions import resolve
    from tolsynth.probability.stats import variance_divisor

    mech = as_mechanism(mechanism)
    if criterion not in ("sigma", "components"):
        raise OutOfRangeError("criterion", f"got {criterion!r}", "'sigma' or 'components'")
    if probability is None:  # the exact reading where one is read, as a design reads it
        probability = "exact" if criterion == "components" else "gaussian"
    if probability not in ("gaussian", "exact"):
        raise OutOfRangeError("probability", f"got {probability!r}", "'gaussian' or 'exact'")
    if R is not None:
        R = check_positive(R, "R")
    elif criterion == "components":
        raise InputError("R", "the per-component probability needs a radius", "a finite number > 0 (mm)")
    if probability == "exact" and criterion != "components":
        raise InputError(
            "probability",
            "'exact' is a reading of the per-component probability",
            "criterion='components' with probability='exact', or probability='gaussian'",
        )
    if criterion == "components" and probability == "gaussian" and (target is not None or stop_at is not None):
        raise InputError(
            "target" if target is not None else "stop_at",
            "given with the Gaussian per-component probability",
            "criterion='sigma' with a target in mm",
        )
    if target is not None:
        target = check_positive(target, "target", "mm") if criterion == "sigma" else check_probability(target, "target")
    if stop_at is not None:
        stop_at = check_real(stop_at, "stop_at")
    lim = check_limits(rtol=rtol, tol=tol, max_boxes=max_boxes, time_limit=time_limit, workers=workers)
    rtol = DEFAULT_RTOL if lim["rtol"] is None else lim["rtol"]
    tol, time_limit = lim["tol"], lim["time_limit"]
    max_boxes = DEFAULT_MAX_BOXES if lim["max_boxes"] is None else lim["max_boxes"]
    workers = worker_count(lim["workers"])
    distribution = resolve(distribution, mech)
    eps = mech.tolerances(tolerances)
    st = structure(mech)
    nq = len(mech.joint_names)
    names = list(mech.joint_names)
    if base_q is None:
        _, ref = _reference(mech, MODEL_REFERENCE)
        base_q = ref if ref is not None else np.zeros(nq)
    base_q = np.asarray(base_q, dtype=float)
    # a symmetry's residual is bounded for sigma_1 (Domain.symmetry_excess); the exact search has no
    # such term, so it covers the whole range itself
    gaussian = criterion == "sigma" or probability == "gaussian"
    dom = _domain(mech, st, base_q, symmetries=gaussian)
    cols = list(st.columns)
    seeds = None
    if x0 is not None:
        X0 = np.atleast_2d(np.asarray(x0, dtype=float))
        if X0.shape[1] != nq:
            raise InputError("x0", f"shape {X0.shape}", f"poses of {nq} joint values (rad)")
        seeds = dom.fold(X0[:, dom.free])
    deadline = time.monotonic() + (math.inf if time_limit is None else time_limit)

    def stop():
        if remaining() <= 0 or time.monotonic() > deadline:
            return "time limit reached"
        return ""

    bar = Progress(progress, max_boxes, f"certified worst pose ({mech.name})", "box")
    done = [0]
    history = []
    sign = 1.0 if criterion == "sigma" or probability == "gaussian" else -1.0  # the exact search maximises -P

    def callback(n, ub, best):
        bar.update(n, n - done[0])
        done[0] = n
        history.append((int(n), sign * float(ub), sign * float(best)))

    c = np.broadcast_to(np.asarray(variance_divisor(distribution, mech), dtype=float), (mech.n,))
    direction = None
    leaves = [] if keep_boxes else None
    try:
        if gaussian:
            sdom = dom
            w = (eps**2 / c)[cols]
            excess = dom.symmetry_excess(w)  # sigma_1 past a cut is at most excess above its value inside
            bounds, method = sigma_bounds(st, sdom, nq, w)
            if leaves is None and not isinstance(bounds, PolygonSigmaBounds):
                # a joint constraint as a coordinate (kept boxes are reported in joints)
                sdom = sheared(mech, dom)
                if sdom is not dom:
                    bounds, method = sigma_bounds(st, sdom, nq, w)
            polygons = isinstance(bounds, PolygonSigmaBounds)
            r = maximize(
                (lambda L, H, level=None: _with_split(bounds.bound(L, H, level)))
                if polygons
                else (lambda L, H: _with_split(bounds.bound(L, H))),
                bounds.point,
                sdom.lo,
                sdom.hi,
                tol=0.0,
                rtol=rtol,
                max_boxes=max_boxes,
                constraint_fn=sdom.constraint_fn,
                x0=None if seeds is None else sdom.coords(seeds),
                callback=callback,
                stop=stop,
                batch=512,
                target=None if target is None else target - excess,
                stop_above=stop_at,
                leaves=leaves,
                workers=workers,
                level_aware=polygons,
            )
            if not np.isfinite(r.best_value):
                raise OutOfRangeError(
                    "joint limits",
                    "no pose satisfies every joint limit and constraint",
                    "a non-empty feasible joint space",
                )
            ub = float(_up(r.upper_bound + excess)) if excess else float(r.upper_bound)
            q = _full(sdom, r.best_x, nq)
            best = float(r.best_value)
            p_lb = None
            if R is not None:
                p_lb = _dn(math.erf(R / (math.sqrt(2.0) * ub)) - 1e-15) if ub > 0 else 1.0
            if criterion == "components":
                best = math.erf(R / (math.sqrt(2.0) * best)) if best > 0 else 1.0
            cert = dict(
                certified=r.certified,
                upper_bound=ub,
                probability_lower_bound=p_lb,
                best_value=best,
                boxes=r.boxes_processed,
                open_boxes=r.open_boxes,
                reason=r.reason,
            )
        else:
            from tolsynth.analysis.certify_exact import certify_components_exact

            out = certify_components_exact(
                mech,
                st,
                dom,
                eps,
                distribution,
                R,
                tol=tol,
                max_boxes=max_boxes,
                seeds=seeds,
                callback=callback,
                stop=stop,
                target=target,
                stop_at=stop_at,
                leaves=leaves,
                workers=workers,
                search=search,
            )
            q = _full(dom, out["x"], nq)
            direction = out["direction"]
            method = out["method"]
            cert = {
                k: out[k]
                for k in ("certified", "probability_lower_bound", "best_value", "boxes", "open_boxes", "reason")
            }
            cert["upper_bound"] = None
    finally:
        bar.close()
    if target is not None:
        _decide(cert, target, criterion == "sigma", mech.format_joints(q))
    return Certificate(
        model=mech.name,
        criterion=criterion,
        probability=probability,
        R=R,
        tolerances=dict(zip(mech.error_parameters, eps.tolist())),
        q=q,
        direction=direction,
        elapsed_s=time.perf_counter() - t0,
        rtol=rtol,
        held={names[j]: f"{math.degrees(v):g} deg, {dom.why[j]}" for j, v in dom.held.items()},
        searched=tuple(names[j] for j in dom.free),
        half_turn=tuple(names[j] for j in dom.halved),
        symmetries=tuple((sym.describe(names), names[dom.free[i]]) for sym, i in dom.cuts),
        dropped=tuple(mech.error_parameters[i] for i in range(mech.n) if i not in st.columns),
        method=method,
        history=tuple(history),
        leaves=_leaves(leaves, len(dom.free), sign),
        target=target,
        **cert,
    )


def _decide(cert: dict, target: float, sigma: bool, pose: str) -> None:
    """With a target the search answers a decision, and ``certified`` says whether the target is
    proven: the branch and bound's own flag says only that its search ended decided or within its
    tolerance of the maximum, which a pose past the target also ends with."""
    best = cert["best_value"]
    if sigma:
        proven, past = cert["upper_bound"] <= target, best > target
        found, bound = f"sigma_1 = {best:.9g} mm > {target:.9g} mm", f"{cert['upper_bound']:.9g} mm"
    else:
        proven, past = cert["probability_lower_bound"] >= target, best < target
        found, bound = f"P = {best:.12g} < {target:.12g}", f"P >= {cert['probability_lower_bound']:.12g}"
    if proven:
        cert.update(certified=True, reason="")
    elif past:
        cert.update(certified=False, reason=f"the target is exceeded: {found} at the pose {pose}")
    else:
        cert.update(
            certified=False,
            reason=f"the target is not proven: the bound reached is {bound}, and no pose past the target was found"
            + (
                f" ({cert['reason']})"
                if cert["reason"]
                else f" (the search closed its tolerance first; a smaller {'rtol' if sigma else 'tol'} may decide it)"
            ),
        )


def _leaves(leaves, k, sign):
    """The boxes kept, over the searched joints only, with the bound in the criterion's own sense."""
    if leaves is None:
        return None
    if not leaves:
        return np.zeros((0, k)), np.zeros((0, k)), np.zeros(0)
    lo = np.array([b[0][:k] for b in leaves])
    hi = np.array([b[1][:k] for b in leaves])
    return lo, hi, sign * np.array([b[2] for b in leaves])


def _with_split(res):
    ub, split = res
    return ub, None, None, split
