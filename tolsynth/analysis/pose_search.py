"""The worst-error pose search: the configuration of worst accuracy at given tolerances.

:func:`worst_pose` searches the joint ranges, inside the joint constraints (the interference
limit of the paper's robot), for the configuration of worst accuracy: the largest principal
standard deviation (``criterion="sigma"``) or the lowest sphere probability ``P(|dr| <= R)``
(``criterion="probability"``), by a coarse grid and then a local generating-set (pattern)
search, on the batched analytic statistics of :mod:`tolsynth.kinematics.batch_stats`.  Units: mm and rad.

>>> import tolsynth
>>> m = tolsynth.load_model("xu_zhang_1988")
>>> w = tolsynth.worst_pose(m, "figure3", criterion="sigma")
>>> bool(w.value >= w.reference_value)
True
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from tolsynth.checks import check_count, check_mapping, check_positive, check_progress, check_real, check_seed
from tolsynth.errors import InputError, OutOfRangeError
from tolsynth.kinematics.batch_stats import _criterion_batch, principal_std_batch
from tolsynth.kinematics.joint_space import (
    MODEL_REFERENCE,
    _feasible,
    _limits,
    _reference,
    grid_and_compass,
    hold_fixed,
    scaled_joints,
)
from tolsynth.probability.stats import p_ball
from tolsynth.tabular import Tabular, jsonable
from tolsynth.units import units_label

__all__ = ["WorstPose", "worst_pose"]

#: largest number of grid points of the coarse search (memory ~ 100 bytes per point and joint)
MAX_GRID_POINTS = 10**6


def _invariant_joints(mech, eps, distribution, rng) -> list[int]:
    """Joints that do not change the principal standard deviations (checked at random poses)."""
    lo, hi = _limits(mech)
    nq = len(lo)
    Q = lo[:, None] + (hi - lo)[:, None] * rng.random((nq, 6))
    base = principal_std_batch(mech, Q, eps, distribution)
    out = []
    for j in range(nq):
        Q2 = Q.copy()
        Q2[j] = lo[j] + (hi[j] - lo[j]) * rng.random(Q.shape[1])
        s2 = principal_std_batch(mech, Q2, eps, distribution)
        if np.all(np.abs(s2 - base) <= 1e-9 * np.max(base) + 1e-15):
            out.append(j)
    return out


@dataclass(frozen=True)
class WorstPose(Tabular):
    """The configuration of worst accuracy found, next to a reference configuration.

    Attributes
    ----------
    criterion : {"sigma", "probability"}
        Largest principal standard deviation (mm; larger is worse) or ``P(|dr| <= R)``
        (Eq. 5; lower is worse), both of the linear, Gaussian model.
    q, position : ndarray
        Joint values (rad) and hand position (mm) of the worst pose found.  Inside every joint
        limit and joint constraint.
    value : float
        Criterion there (sigma in mm, or the probability).
    principal_std : ndarray (mm)
    p_sphere : float or None
        ``P(|dr| <= R)`` there (with ``R``), Gaussian.
    probability : {"gaussian", "exact"}
        The reading of :attr:`value` where it is a probability: Gaussian for the sphere, as asked
        for the components.
    reference, reference_q, reference_position, reference_value, reference_principal_std,
    reference_p_sphere
        The same at the reference configuration (None without one; for ``xu_zhang_1988`` by
        default its ``worst``: the paper's pose
        (925, 0, 1225) mm, which lies 0.33 deg past the interference limit).
    held_joints : dict
        Joints held fixed (rad) because they do not change the error statistics (found
        numerically), plus any ``fixed`` by the caller.
    active : list of str
        Limits and constraints active (within 1e-6 rad) at the worst pose.
    n_grid, n_evaluations : int
        Feasible grid points and total poses evaluated.
    method : str
    certified, upper_bound, probability_lower_bound, boxes, certificate
        With ``certify=True``: whether the branch and bound proved its bound, the proven upper
        bound of the largest principal sigma (mm) over the whole joint space, the proven lower
        bound of the smallest per-component probability (with R), the boxes it bounded, and the
        :class:`~tolsynth.analysis.certify.Certificate` itself (None without ``certify``).
    """

    model: str
    criterion: str
    distribution: str
    R: float | None
    tolerances: dict
    q: np.ndarray
    position: np.ndarray
    value: float
    principal_std: np.ndarray
    p_sphere: float | None
    reference: str | None
    reference_q: np.ndarray | None
    reference_position: np.ndarray | None
    reference_value: float | None
    reference_principal_std: np.ndarray | None
    reference_p_sphere: float | None
    held_joints: dict
    active: list
    n_grid: int
    n_evaluations: int
    elapsed_s: float
    method: str
    certified: bool | None = None
    upper_bound: float | None = None
    probability_lower_bound: float | None = None
    boxes: int | None = None
    certificate: object = None
    #: each joint value's unit, "rad" or "mm" (a joint that slides); empty: all "rad"
    joint_units: tuple = ()
    probability: str = "gaussian"

    def to_dict(self) -> dict:
        """Plain dict for JSON (arrays as lists, inf and NaN as None, the certificate's own dict)."""
        return jsonable(self.__dict__, null=True)

    def report(self, joint_names: Sequence[str] | None = None, joint_units: Sequence[str] | None = None) -> str:
        """Readable table: the worst pose found beside the reference (joints in deg, or in mm where
        ``joint_units`` says so, as :attr:`tolsynth.Mechanism.joint_units` does; hand in mm)."""
        unit = {
            "sigma": "mm (largest principal sigma)",
            "probability": "(Gaussian P(|dr|<={R:g} mm))",
            "components": "(smallest {p} P(|u.dr|<={R:g} mm))",
        }[self.criterion].format(R=self.R, p={"gaussian": "Gaussian"}.get(self.probability, self.probability))
        names = joint_names or [f"q{i + 1}" for i in range(len(self.q))]
        units = tuple(joint_units or ["deg"] * len(self.q))
        lines = [f"worst pose   criterion {self.criterion} {unit}, {self.distribution} errors; {self.method}"]
        has_ref = self.reference is not None  # without one, no column of dashes
        fmt = lambda v: "(" + ", ".join(f"{x:.3f}" for x in v) + ")"  # noqa: E731
        shown = lambda q: [x if u == "mm" else math.degrees(x) for x, u in zip(q, units)]  # noqa: E731

        def row(label: str, found: str, ref: str | None) -> None:
            lines.append(f"{label:22}{found:>42}" + (f"  {'-' if ref is None else ref:>38}" if has_ref else ""))

        row("", "found", f"reference ({self.reference})")
        row(
            "joints (" + units_label(units) + ")",
            fmt(shown(self.q)),
            None if self.reference_q is None else fmt(shown(self.reference_q)),
        )
        row("hand (mm)", fmt(self.position), None if self.reference_position is None else fmt(self.reference_position))
        row("criterion", f"{self.value:.6f}", None if self.reference_value is None else f"{self.reference_value:.6f}")
        row(
            "principal sigma (mm)",
            fmt(self.principal_std),
            None if self.reference_principal_std is None else fmt(self.reference_principal_std),
        )
        if self.p_sphere is not None:
            row(
                "P(|dr|<=R), Gaussian",
                f"{self.p_sphere:.6f}",
                None if self.reference_p_sphere is None else f"{self.reference_p_sphere:.6f}",
            )
        if self.certificate is not None:
            lines.append("certificate  " + self.certificate.summary().replace("\n", "\n             "))
        lines.append("joint order  " + ", ".join(names))
        lines.append(
            "held         " + (", ".join(f"{k} = {math.degrees(v):g} deg" for k, v in self.held_joints.items()) or "-")
        )
        lines.append("active       " + (", ".join(self.active) or "none (interior)"))
        return "\n".join(lines)


#: error allowed in P(|dr| <= R) (criterion "probability") on the coarse grid, which only picks the
#: starts, and in the pattern search's polls; the value reported is evaluated to 1e-12
GRID_P_TOL = 1e-7
SEARCH_P_TOL = 1e-10


def worst_pose(
    mechanism,
    tolerances,
    criterion: str = "sigma",
    R: float | None = None,
    distribution=None,
    grid: int | None = None,
    reference=MODEL_REFERENCE,
    fixed: Mapping[str, float] | None = None,
    starts: int = 4,
    step_tol: float = 1e-7,
    max_grid_points: int = 20000,
    seed: int = 0,
    *,
    certify: bool = False,
    probability: str | None = None,
    rtol: float | None = None,
    max_boxes: int | None = None,
    progress=None,
    time_limit: float | None = None,
    workers: int | None = None,
) -> WorstPose:
    """Search the joint space for the pose of worst accuracy at given tolerances.

    Method: (1) joints that do not change the error statistics are found numerically (at random
    poses) and held at the reference value -- for ``xu_zhang_1988`` the waist ``theta1`` (it turns
    the whole error ellipsoid) and the roll ``theta5`` (the hand point lies on its axis); (2) a
    coarse grid over the remaining joints, inside every joint limit and joint constraint;
    (3) from the ``starts`` best, mutually separated grid points, a generating-set search
    (compass search with complete polling; step halved on failure down to ``step_tol`` of each
    joint's range, doubled after a run of successes) whose directions include the tangents of the
    linear joint constraints, with infeasible polls rejected.  Derivative-free on purpose: the
    largest principal sigma is not differentiable where two principal variances cross, the sphere
    probability is a quadrature, and the worst pose typically lies on limits and the interference
    constraint, where a tangent polling set is all that is needed.  (4) With the exact
    per-component probability (``criterion="components"``, ``probability="exact"``): the pose of
    largest sigma need not be the pose of lowest exact probability, so the exact search
    (:func:`tolsynth.analysis.exact_pose_search.worst_exact_pose`) goes on from it, over joints and
    directions together.

    Parameters
    ----------
    mechanism : Mechanism
    tolerances : str, dict or array
        Tolerance set name or half-widths (tolerance units).
    criterion : {"sigma", "probability", "components"}
        Maximise the largest principal sigma (mm), or minimise ``P(|dr| <= R)`` (needs ``R``), or
        minimise the smallest per-component probability ``P(|u . dr| <= R)`` over directions u
        (needs ``R``; Gaussian: the pose of largest sigma).
    R : float, optional
        Radius (mm), > 0; required for ``"probability"``, reported otherwise if given.
    distribution : str or dict, optional
        As :func:`tolsynth.synthesize` (default: the model file's, else uniform).
    grid : int, optional
        Grid points per searched joint (default: as many as keep the grid under
        ``max_grid_points``).
    reference : str, array or None
        Configuration reported beside the result: a configuration name, joint values (rad), or
        None for none.  Default: the model's reference pose (a parallel robot's ``home``, else its
        ``worst`` configuration if it has one, else none;
        :func:`tolsynth.kinematics.joint_space.model_reference`).
    fixed : dict, optional
        Joint name -> value (rad) to hold in addition to the invariant joints.
    starts : int
        Local searches started from the best grid points.
    step_tol : float
        Final step, as a fraction of each joint's range.
    seed : int
        Seed of the random poses used to detect invariant joints.
    certify : bool
        Also prove a bound over the whole continuous joint space (joint limits and constraints
        included) by branch and bound (:func:`tolsynth.analysis.certify.certify_worst_pose`):
        ``certified``, ``upper_bound`` (sigma, mm), ``probability_lower_bound`` (with ``R``) and
        ``boxes`` are set, and the pose reported is the best the search found (the sampled one if
        better).  For ``criterion="sigma"`` or ``"components"``; the sphere probability is not
        certified.
    probability : {"exact", "gaussian"}, optional
        Reading of the per-component probability (``criterion="components"``): the exact
        probabilities of the linear error model (the default there, as :func:`tolsynth.synthesize`
        reads them), or the paper's Gaussian reading.
    rtol, max_boxes, progress, time_limit
        Of the certified search (relative gap, box limit >= 1, progress bar, seconds > 0; None:
        the defaults, 400 000 boxes and no time limit): a limit reached leaves ``certified`` False
        with the bound reached, which holds, only looser.  ``rtol``, ``max_boxes``,
        ``time_limit`` and ``workers`` without ``certify=True`` raise an ``InputError``, and so
        does a ``progress`` that asks for reports (True or a callable): the sampled search
        reports none.
    workers : int, optional
        Processes of the certified search (default: the cores this process may use; 1: one).

    Returns
    -------
    WorstPose

    Examples
    --------
    >>> import tolsynth
    >>> m = tolsynth.load_model("xu_zhang_1988")
    >>> w = tolsynth.worst_pose(m, "figure3", criterion="probability", R=0.2)
    >>> bool(w.p_sphere <= w.reference_p_sphere)
    True
    """
    t0 = time.perf_counter()
    from tolsynth.kinematics.mechanism import as_mechanism

    mechanism = as_mechanism(mechanism)
    if criterion not in ("sigma", "probability", "components"):
        raise OutOfRangeError("criterion", f"got {criterion!r}", "'sigma', 'probability' or 'components'")
    if probability is None:  # the exact reading where one is read, as a design reads it
        probability = "exact" if criterion == "components" else "gaussian"
    if probability not in ("gaussian", "exact"):
        raise OutOfRangeError("probability", f"got {probability!r}", "'gaussian' or 'exact'")
    if probability == "exact" and criterion != "components":  # it would be ignored: say so
        raise InputError(
            "probability",
            f"'exact' given with criterion {criterion!r}, which this search reads in the Gaussian model "
            "(sigma_1, or P(|dr| <= R) from the principal variances)",
            "criterion='components' with probability='exact' (the per-direction probability), or "
            "probability 'gaussian' / None with criterion 'sigma' or 'probability'",
        )
    if certify and criterion == "probability":
        # a proven bound of the sphere probability needs enclosures of all three principal
        # variances and of a quadrature's error; the per-component probability needs sigma_1 alone
        raise InputError(
            "certify",
            "the sphere probability P(|dr| <= R) has no certified search; the smallest "
            "per-component probability P(|u.dr| <= R) has one (criterion 'components')",
            "criterion 'components' (probability_lower_bound, with R) or 'sigma' (upper_bound, mm) with certify=True",
        )
    limits = dict(rtol=rtol, max_boxes=max_boxes, time_limit=time_limit, workers=workers)
    if certify:
        from tolsynth.analysis.certify import check_limits

        check_limits(**limits)  # before the sampled search, not after it
    else:  # the certified search's limits would be ignored: say so
        given = [key for key, v in limits.items() if v is not None]
        if given:
            raise InputError(given[0], "only used with certify=True", f"certify=True with {given[0]}, or no {given[0]}")
        # the sampled search reports no progress: a bar asked for (True, a callable) would not come
        if check_progress(progress) is not None and progress is not False:
            raise InputError(
                "progress",
                f"got {progress!r}: only the certified search (certify=True) reports progress",
                "certify=True with progress, or progress None / False",
            )
    from tolsynth.probability.distributions import resolve

    distribution = resolve(distribution, mechanism)
    if R is not None:
        R = check_positive(R, "R")
    elif criterion in ("probability", "components"):
        raise InputError("R", f"criterion {criterion!r} needs a radius", "a finite number > 0 (mm)")
    starts = check_count(starts, "starts", 1, 1000)
    step_tol = check_positive(step_tol, "step_tol", "fraction of each joint's range", upper=1.0)
    max_grid_points = check_count(max_grid_points, "max_grid_points", 1, MAX_GRID_POINTS)
    grid = None if grid is None else check_count(grid, "grid", 2, MAX_GRID_POINTS)
    seed = check_seed(seed)
    fixed = {
        name: check_real(v, f"fixed[{name}]", "rad")
        for name, v in check_mapping(fixed, "fixed", "a dict joint name -> value (rad)").items()
    }
    eps = mechanism.tolerances(tolerances)
    ref_name, ref_q = _reference(mechanism, reference)
    lo, hi = _limits(mechanism)
    nq = len(lo)
    names = list(mechanism.joint_names)
    rng = np.random.default_rng(seed)

    search_criterion = "sigma" if criterion == "components" else criterion  # the Gaussian ranking
    held: dict[int, float] = {}
    base_q = ref_q if ref_q is not None else np.clip(np.zeros(nq), lo, hi)
    for j in _invariant_joints(mechanism, eps, distribution, rng):
        held[j] = float(np.clip(base_q[j], lo[j], hi[j]))
    hold_fixed(mechanism, fixed or {}, lo, hi, held)
    free = [j for j in range(nq) if j not in held]
    k = len(free)
    n_eval = 0

    def full(U: np.ndarray) -> np.ndarray:  # scaled (k, N) -> joints (nq, N)
        return scaled_joints(U, held, free, lo, hi)

    def evaluate(U: np.ndarray, tol: float = SEARCH_P_TOL) -> np.ndarray:
        nonlocal n_eval
        Q = full(U)
        ok = _feasible(mechanism, Q) & np.all((U >= 0) & (U <= 1), axis=0)
        val = np.full(U.shape[1], -np.inf)
        if np.any(ok):
            val[ok] = _criterion_batch(mechanism, Q[:, ok], eps, distribution, search_criterion, R, tol)[0]
            val[~np.isfinite(val)] = -np.inf  # a parallel robot's platform not assembled there
            n_eval += int(np.count_nonzero(ok))
        return val

    # (2) coarse grid, (3) local generating-set search from the best separated grid points
    best_u, g, n_grid, n_starts = grid_and_compass(
        mechanism, evaluate, free, lo, hi, grid, max_grid_points, starts, step_tol, MAX_GRID_POINTS, GRID_P_TOL
    )
    q = full(best_u[:, None])[:, 0]
    exact_search = ""
    if criterion == "components" and probability == "exact":
        from tolsynth.analysis.exact_pose_search import worst_exact_pose

        e = worst_exact_pose(
            mechanism, eps, R, None, distribution, x0=[q], fixed=fixed, seed=seed, step_tol=max(step_tol, 1e-6)
        )
        n_eval += e.n_evaluations
        exact_search = f"; then the exact search over joints and directions ({e.method})"
        if e.probability < _value_at(mechanism, q, eps, distribution, R, criterion, probability):
            q = np.asarray(e.q, dtype=float)
    cert = None
    if certify:
        from tolsynth.analysis.certify import certify_worst_pose

        cert = certify_worst_pose(
            mechanism,
            eps,
            distribution,
            "components" if criterion == "components" else "sigma",
            R,
            probability,
            rtol=rtol,
            max_boxes=max_boxes,
            x0=[q],
            base_q=base_q,
            progress=progress,
            time_limit=time_limit,
            workers=workers,
        )
        better = (
            cert.best_value > _value_at(mechanism, q, eps, distribution, R, criterion, probability)
            if criterion == "sigma"
            else cert.best_value < _value_at(mechanism, q, eps, distribution, R, criterion, probability)
        )
        if better:
            q = cert.q
    value, sig, P = _criterion_batch(mechanism, q[:, None], eps, distribution, search_criterion, R)
    p_sph = float(p_ball(sig[0] ** 2, R)) if R is not None else None
    position = np.asarray(mechanism.fk(q, check_limits=True))[:3, 3]

    active = []
    tol_a = 1e-6
    units = mechanism.joint_units  # a parallel robot's struts are lengths (mm)
    for j in range(nq):
        if j in held:
            continue
        shown = (lambda v: f"{v:g} mm") if units[j] == "mm" else (lambda v: f"{math.degrees(v):g} deg")
        if abs(q[j] - lo[j]) <= tol_a:
            active.append(f"{names[j]} lower ({shown(lo[j])})")
        if abs(q[j] - hi[j]) <= tol_a:
            active.append(f"{names[j]} upper ({shown(hi[j])})")
    for c in mechanism.spec.joint_constraints:
        v = sum(coef * q[names.index(jn)] for jn, coef in c.terms.items())
        if abs(v - c.lower) <= tol_a:
            active.append(f"{c.name} lower ({math.degrees(c.lower):g} deg)")
        if abs(v - c.upper) <= tol_a:
            active.append(f"{c.name} upper ({math.degrees(c.upper):g} deg)")

    ref = dict(
        reference_q=None,
        reference_position=None,
        reference_value=None,
        reference_principal_std=None,
        reference_p_sphere=None,
    )
    if ref_q is not None:
        rv, rs, rp = _criterion_batch(mechanism, ref_q[:, None], eps, distribution, search_criterion, R)
        ref.update(
            reference_q=ref_q,
            reference_position=np.asarray(mechanism.fk(ref_name if ref_name != "given" else ref_q))[:3, 3],
            reference_value=float(rs[0, 0])
            if criterion == "sigma"
            else float(rp[0])
            if criterion == "probability"
            else _value_at(mechanism, ref_q, eps, distribution, R, criterion, probability),
            reference_principal_std=rs[0],
            reference_p_sphere=float(p_ball(rs[0] ** 2, R)) if R is not None else None,
        )
    return WorstPose(
        model=mechanism.name,
        criterion=criterion,
        distribution=distribution,
        R=R,
        tolerances=dict(zip(mechanism.error_parameters, eps.tolist())),
        q=q,
        position=position,
        value=float(sig[0, 0])
        if criterion == "sigma"
        else float(P[0])
        if criterion == "probability"
        else _value_at(mechanism, q, eps, distribution, R, criterion, probability),
        principal_std=sig[0],
        p_sphere=p_sph,
        reference=ref_name,
        held_joints={names[j]: v for j, v in held.items()},
        active=active,
        n_grid=n_grid,
        n_evaluations=n_eval,
        elapsed_s=time.perf_counter() - t0,
        method=f"grid {g}^{k} over {', '.join(names[j] for j in free) or '-'}, then pattern search from {n_starts} starts"
        + exact_search
        + (f"; certified search: {cert.method}" if cert is not None else ""),
        certified=None if cert is None else cert.certified,
        upper_bound=None if cert is None else cert.upper_bound,
        probability_lower_bound=None if cert is None else cert.probability_lower_bound,
        boxes=None if cert is None else cert.boxes,
        certificate=cert,
        joint_units=mechanism.joint_value_units,
        probability=probability if criterion == "components" else "gaussian",
        **ref,
    )


def _value_at(mech, q, eps, distribution, R, criterion, probability) -> float:
    """The criterion at one pose: sigma_1 (mm), or the smallest per-component probability (Gaussian:
    from sigma_1; exact: along the worst direction of a lattice and local search)."""
    sig = principal_std_batch(mech, q[:, None], eps, distribution)[0, 0]
    if criterion == "sigma":
        return float(sig)
    if probability == "gaussian":
        return math.erf(R / (math.sqrt(2.0) * sig)) if sig > 0 else 1.0
    from tolsynth.probability.distributions import shapes_of
    from tolsynth.probability.exact import worst_direction

    A = mech.sensitivity(q, check_limits=False)[:3]
    return worst_direction(A, eps, shapes_of(distribution, mech.error_parameters, mech.index), R)[1]
