"""The probability map of the paper's Figure 3: ``P(|dr| <= R)`` over the reachable part of a plane.

:func:`probability_map` solves the inverse kinematics on a grid of a base-frame plane
(:mod:`tolsynth.kinematics.ik`) for a fixed hand orientation and evaluates the analytic (linear, Gaussian)
sphere probability there (:mod:`tolsynth.kinematics.batch_stats`); :func:`tolsynth.analysis.plot.plot_map` draws it.
Units: mm and rad in the API.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numpy as np

from tolsynth.checks import check_count, check_mapping, check_real, check_vector
from tolsynth.errors import InputError, OutOfRangeError, UnknownNameError
from tolsynth.kinematics.batch_stats import _evaluator, principal_std_batch
from tolsynth.kinematics.ik import PLANES, _GridIK, _ik_evaluator
from tolsynth.kinematics.joint_space import MODEL_REFERENCE, _limits, _reference
from tolsynth.kinematics.parallel_ik import ParallelGridIK
from tolsynth.model.parallel import is_parallel
from tolsynth.probability.stats import check_positive, p_ball_batch
from tolsynth.progress import make_bar
from tolsynth.tabular import Tabular, jsonable
from tolsynth.units import units_label

__all__ = ["ProbabilityMap", "probability_map", "PLANES"]


@dataclass(frozen=True)
class ProbabilityMap(Tabular):
    """``P(|dr| <= R)`` over the reachable part of a plane, for a fixed hand orientation.

    Attributes
    ----------
    u, v : ndarray (mm)
        Grid coordinates along the plane's horizontal and vertical axes (``X0`` and ``Z0`` for
        ``plane="xz"``).
    P : ndarray, shape (len(v), len(u))
        Probability; NaN where the point is not reachable with the hand orientation and the
        joint limits and constraints (the interference limit).
    sigma : ndarray, shape (len(v), len(u), 3)
        Principal standard deviations (mm), NaN outside.
    Q : ndarray, shape (n_joints, len(v), len(u))
        The inverse-kinematics solution used (rad), NaN outside.
    limit_margin : ndarray, shape (len(v), len(u))
        Smallest distance (rad) of that solution to a joint limit or joint constraint: >= 0 inside
        the reachable region, < 0 where the solution continued past a limit, -inf where no
        solution was found; its zero contour is the region's boundary.
    plane, offset, hand_axis
        The plane, its offset along the normal (mm) and the hand z axis imposed.
    fixed : dict
        Joints held (rad) and why.
    branch : str
        How the inverse-kinematics solution was chosen, and whether another one within the limits
        was found anywhere.
    worst : tuple
        ``(u, v, P)`` of the lowest probability on the map.
    reference_point : tuple or None
        ``(u, v)`` of the reference configuration's hand point, if it lies on the plane with the
        hand axis of the map; ``reference_P`` the probability there (that configuration's own
        joint values, with the limits it waives).  For ``xu_zhang_1988`` this is the paper's pose
        (925, 1225) mm, 0.33 deg past the interference limit: on the map's edge.
    """

    model: str
    u: np.ndarray
    v: np.ndarray
    P: np.ndarray
    sigma: np.ndarray
    Q: np.ndarray
    limit_margin: np.ndarray
    plane: str
    offset: float
    hand_axis: np.ndarray | None
    R: float
    distribution: str
    tolerances: dict
    tolerance_label: str
    fixed: dict
    free_joints: tuple
    joint_names: tuple
    branch: str
    n_alternative_solutions: int
    n_checked: int
    worst: tuple
    reference: str | None
    reference_point: tuple | None
    reference_P: float | None
    constraints: tuple
    elapsed_s: float
    units: dict = field(default_factory=lambda: {"u": "mm", "v": "mm", "sigma": "mm", "Q": "rad", "R": "mm"})
    #: each joint value's unit, "rad" or "mm" (a joint that slides); empty: all "rad"
    joint_units: tuple = ()
    #: the reading of P: the Gaussian (normal errors of the same variances), whatever the distribution
    probability: str = "gaussian"

    @property
    def reachable(self) -> np.ndarray:
        """Boolean mask of the reachable grid points (where ``P`` is finite)."""
        return np.isfinite(self.P)

    def to_dict(self) -> dict:
        """Plain dict for JSON (arrays as lists): every field, with NaN and infinities as None
        (``P`` and ``sigma`` NaN where a grid point is unreachable), so ``json.dumps(..., allow_nan=False)`` takes it."""
        return jsonable(self.__dict__, null=True)

    def plot(self, path=None, ax=None):
        """See :func:`tolsynth.analysis.plot.plot_map`."""
        from tolsynth.analysis.plot import plot_map

        return plot_map(self, path=path, ax=ax)


def _yaw_joint(mech, ref_q: np.ndarray, rng) -> int | None:
    """A joint that only turns the whole arm about the base Z axis (dp/dq = e_z x p, and the
    same for the hand axis), checked at random poses; None if there is none."""
    pos = _evaluator(mech, "position")
    lo, hi = _limits(mech)
    nq = len(lo)
    Q = lo[:, None] + (hi - lo)[:, None] * rng.random((nq, 5))
    h = 1e-6
    p0 = pos([Q, np.zeros(mech.n)])[0]
    for j in range(nq):
        Q2 = Q.copy()
        Q2[j] += h
        dp = (pos([Q2, np.zeros(mech.n)])[0] - p0) / h
        ez_x_p = np.vstack([-p0[1], p0[0], np.zeros(p0.shape[1])])
        if np.allclose(dp, ez_x_p, atol=1e-4 * (1 + np.abs(p0).max())):
            return j
    return None


def _motion_plane(mech, lo, hi, rng) -> tuple[str, float | None]:
    """The base-frame plane the hand point moves in and its offset, where it moves in one (the
    spread of one coordinate over 200 random joint values below 1e-9 of the others'); else
    ``("xz", None)``."""
    Q = lo[:, None] + (hi - lo)[:, None] * rng.random((len(lo), 200))
    P = _evaluator(mech, "position")([Q, np.zeros(mech.n)])[0]
    P = P[:, np.all(np.isfinite(P), axis=0)]  # a parallel robot's platform is not assembled everywhere
    if P.shape[1] < 3:
        return "xz", None
    spread = np.ptp(P, axis=1)
    normal = int(np.argmin(spread))
    if spread[normal] > 1e-9 * max(float(spread.max()), 1e-300):
        return "xz", None
    plane = next(name for name, (_, _, n) in PLANES.items() if n == normal)
    return plane, float(np.mean(P[normal]))


def probability_map(
    mechanism,
    tolerances="figure3",
    R: float = 0.2,
    distribution=None,
    n: int = 100,
    plane: str | None = None,
    offset: float | None = None,
    hand_axis: Sequence[float] | None = (0.0, 0.0, 1.0),
    fixed: Mapping[str, float] | None = None,
    extent: Sequence[float] | None = None,
    reference=MODEL_REFERENCE,
    seeds: int = 8,
    check_points: int = 200,
    progress: bool | None = None,
) -> ProbabilityMap:
    """``P(|dr| <= R)`` (Eq. 5, linear + Gaussian) over the reachable part of a plane (Figure 3).

    Inverse kinematics: for each grid point the joints are solved from the model's forward
    kinematics graph (hand point on the grid point, hand z axis along ``hand_axis``) by a
    batched Levenberg-Marquardt iteration, by continuation over the grid from the reference
    configuration (each point seeded with a solved neighbour's joints), with deterministic
    quasi-random seeds for points the continuation does not reach.  A point is *reachable* only
    if the solution lies inside every joint limit and joint constraint (for ``xu_zhang_1988`` the
    interference limit); revolute joints are first moved by multiples of 2 pi into their limits.
    The branch is therefore the one connected to the reference configuration; at
    ``check_points`` random reachable points all seeds are run again and the number of points
    with another valid solution is reported (0 means the solution is unique within the limits
    there).  Joints that change neither the hand point nor its axis are held at the reference
    value; for a plane containing ``Z0`` a joint that only turns the arm about ``Z0`` (the
    waist) is held at 0, so the plane is its ``theta = 0`` half.  The loops close on the branch
    declared in the model file.

    Parameters
    ----------
    mechanism : Mechanism
    tolerances : str, dict or array
        Default: the ``figure3`` set of the paper's Figure 3.
    R : float
        Radius (mm), > 0.
    distribution : str or dict, optional
        As :func:`tolsynth.synthesize` (default: the model file's, else uniform).
    n : int
        Grid points per axis (n x n), >= 5.
    plane : {"xz", "xy", "yz"} or None
        Base-frame plane; ``offset`` (mm) along its normal.  Default: for a mechanism whose hand
        point moves in one base-frame plane (a planar arm or a planar parallel robot, found at
        random joint values), that plane at its offset; else ``"xz"`` at offset 0.
    hand_axis : 3 floats or None
        Hand z axis imposed (base frame; normalised), None for none.  Default: vertical, up, as
        in the paper's worst pose.
    fixed : dict, optional
        Joint name -> value (rad) to hold fixed, replacing the automatic choice.
    extent : (umin, umax, vmin, vmax), optional
        Grid extent (mm); default: the reachable region's bounding box from a coarse pass.
    reference : str, array or None
        Configuration to start the continuation from and to mark: a configuration name, joint
        values (rad), or None (start from the joints' zeros, clipped into the limits, and mark
        nothing).  Default: the model's reference pose (a parallel robot's ``home``, else its
        ``worst`` if it has one, else none).
    seeds : int
        Quasi-random seeds for points not reached by continuation.
    check_points : int
        Reachable points at which uniqueness of the solution is checked.
    progress : bool or None
        A tqdm bar on stderr (None: on a terminal, shown once the run has taken 2 s).

    Returns
    -------
    ProbabilityMap
    """
    t0 = time.perf_counter()
    from tolsynth.kinematics.mechanism import as_mechanism
    from tolsynth.probability.distributions import resolve

    mechanism = as_mechanism(mechanism)
    R = check_positive(R, "R")

    distribution = resolve(distribution, mechanism)
    n = check_count(n, "n", 5, 2000)  # grid points per axis
    if offset is not None:
        offset = check_real(offset, "offset", "mm")
    seeds = check_count(seeds, "seeds", 1, 1000)
    check_points = check_count(check_points, "check_points", 0, 10**6)
    if fixed is not None:
        fixed = check_mapping(fixed, "fixed", "a dict joint name -> value (rad)")
    if extent is not None:
        extent = tuple(check_vector(extent, "extent", 4, "mm"))
    if plane is not None and (not isinstance(plane, str) or plane not in PLANES):
        raise OutOfRangeError("plane", f"got {plane!r}", "one of " + ", ".join(PLANES) + ", or None (the default)")
    eps = mechanism.tolerances(tolerances)
    label = tolerances if isinstance(tolerances, str) else "given"
    axis = None
    if hand_axis is not None:
        axis = check_vector(hand_axis, "hand_axis", 3)
        if np.linalg.norm(axis) == 0:
            raise InputError("hand_axis", f"got {hand_axis!r}", "3 finite numbers, not all 0, or None")
        axis = axis / np.linalg.norm(axis)
    names = list(mechanism.joint_names)
    nq = len(names)
    lo, hi = _limits(mechanism)
    ref_name, ref_q = _reference(mechanism, reference)
    if ref_q is None:
        ref_q = np.clip(np.zeros(nq), lo, hi)
    rng = np.random.default_rng(0)
    if plane is None:
        plane, moved = _motion_plane(mechanism, lo, hi, np.random.default_rng(1))
        offset = moved if offset is None else offset
    offset = 0.0 if offset is None else offset

    # joints held fixed
    held: dict[int, tuple[float, str]] = {}
    yaw_held = None  # the waist, held at 0 automatically for a plane through Z0
    if fixed is not None:
        for name, val in fixed.items():
            if name not in names:
                raise UnknownNameError("fixed", f"unknown joint {name!r}", "one of " + ", ".join(names))
            held[names.index(name)] = (check_real(val, f"fixed[{name}]", "rad"), "given")
    elif not is_parallel(mechanism.spec):  # a parallel robot's platform pose sets every actuator
        ev_all = _ik_evaluator(mechanism, tuple(range(nq)), axis is not None)
        Qr = lo[:, None] + (hi - lo)[:, None] * rng.random((nq, 6))
        _, J = ev_all([Qr, np.zeros(3), axis if axis is not None else np.zeros(3)])
        J = J.reshape(-1, nq, Qr.shape[1], order="F")
        for j in range(nq):
            if np.all(np.abs(J[:, j, :]) <= 1e-9):
                held[j] = (float(ref_q[j]), "moves neither the hand point nor its axis")
        if "z" in plane:
            yaw = _yaw_joint(mechanism, ref_q, rng)
            if yaw is not None and yaw not in held and lo[yaw] <= 0.0 <= hi[yaw]:
                held[yaw] = (0.0, "turns the arm about Z0; the map is at its zero")
                yaw_held = yaw
    given_extent = extent
    for attempt in (0, 1):
        free = tuple(j for j in range(nq) if j not in held)
        if not free:
            raise InputError("fixed", "every joint is held fixed", "at least one free joint")
        iu, iv, inorm = PLANES[plane]

        ik = (ParallelGridIK if is_parallel(mechanism.spec) else _GridIK)(
            mechanism, free, held, ref_q, axis, plane, offset, int(seeds)
        )
        if given_extent is not None:
            break
        # extent: reachable bounding box from a coarse pass
        pos = _evaluator(mechanism, "position")
        Qr = lo[:, None] + (hi - lo)[:, None] * rng.random((nq, 4000))
        for j, (v, _) in held.items():
            Qr[j] = v
        P = pos([Qr, np.zeros(mechanism.n)])[0]
        P = P[:, np.all(np.isfinite(P), axis=0)]  # a parallel robot's platform is not assembled everywhere
        reach = float(np.max(np.linalg.norm(P - P.mean(axis=1, keepdims=True), axis=0)))
        cu, cv = P[iu].mean(), P[iv].mean()
        span = 1.6 * reach
        m0 = 41
        uc = np.linspace(cu - span, cu + span, m0)
        vc = np.linspace(cv - span, cv + span, m0)
        okc = ik.solve(uc, vc)[1].reshape(m0, m0)
        if np.any(okc):
            du, dv = uc[1] - uc[0], vc[1] - vc[0]
            cols, rows = np.flatnonzero(okc.any(axis=0)), np.flatnonzero(okc.any(axis=1))
            # two coarse cells of margin: thin tips of the region can fall between coarse points
            extent = (uc[cols[0]] - 2 * du, uc[cols[-1]] + 2 * du, vc[rows[0]] - 2 * dv, vc[rows[-1]] + 2 * dv)
            break
        if attempt == 0 and yaw_held is not None:
            # an arm with a shoulder offset (a Puma) reaches a plane through Z0 only with the waist
            # turned: free it (the map then follows the continuation's waist angle)
            del held[yaw_held]
            yaw_held = None
            continue
        raise InputError(
            "plane",
            f"no reachable point found in the {plane} plane at offset {offset:g} mm with this hand axis",
            "a plane and hand axis the arm can reach",
        )
    if given_extent is not None:
        extent = tuple(float(e) for e in given_extent)
        if len(extent) != 4 or not (extent[0] < extent[1] and extent[2] < extent[3]):
            raise InputError("extent", f"got {extent!r}", "(umin, umax, vmin, vmax) in mm with min < max")
    u = np.linspace(extent[0], extent[1], n)
    v = np.linspace(extent[2], extent[3], n)

    bar = None
    if progress or (progress is None and sys.stderr.isatty()):  # auto: shown on runs longer than ~2 s
        bar = make_bar(n * n, "map (inverse kinematics)", "pt", 0.0 if progress else 2.0)
    try:
        Qs, ok, margin = ik.solve(u, v, bar)
    finally:
        if bar is not None:
            bar.close()
    T = ik.targets(*[a.ravel() for a in np.meshgrid(u, v)])

    sig = np.full((n * n, 3), np.nan)
    Pv = np.full(n * n, np.nan)
    if np.any(ok):
        s = principal_std_batch(mechanism, Qs[:, ok], eps, distribution)
        sig[ok] = s
        Pv[ok] = p_ball_batch(s**2, R)

    # uniqueness check at sampled reachable points: every seed again, any other valid solution?
    idx = np.flatnonzero(ok)
    chk = rng.choice(idx, size=min(int(check_points), idx.size), replace=False) if idx.size else idx
    alt = np.zeros(chk.size, bool)
    if chk.size:  # every seed at every checked point, in one batch
        nseed = len(ik.seed_set)
        Q, good, _ = ik.attempt(np.repeat(np.column_stack(ik.seed_set), chk.size, axis=1), np.tile(T[:, chk], nseed))
        diff = np.max(np.abs(Q[list(free)] - np.tile(Qs[list(free)][:, chk], nseed)), axis=0)
        alt = np.any((good & (diff > 1e-5)).reshape(nseed, chk.size), axis=0)
    n_alt = int(np.count_nonzero(alt))
    branch = getattr(ik, "branch_note", None) or (
        "continuation from the reference configuration"
        + (
            f"; loop branch {', '.join(f'{lp.name} {lp.branch:+d}' for lp in mechanism.spec.loops)} (model file)"
            if mechanism.spec.loops
            else ""
        )
        + (
            f"; unique within the limits at {chk.size} checked points"
            if n_alt == 0
            else f"; ANOTHER valid solution exists at {n_alt} of {chk.size} checked points"
        )
    )

    Pg = Pv.reshape(n, n)
    if np.any(ok):
        w = int(np.nanargmin(Pv))
        worst = (float(T[iu, w]), float(T[iv, w]), float(Pv[w]))
    else:
        worst = (math.nan, math.nan, math.nan)
    ref_point = None
    ref_P = None
    if ref_name is not None:
        ref_pose = ref_name if ref_name != "given" else ref_q
        Tref = np.asarray(mechanism.fk(ref_pose))
        pr = Tref[:3, 3]
        on_plane = abs(pr[inorm] - offset) < 1e-6 and (axis is None or np.allclose(Tref[:3, 2], axis, atol=1e-6))
        if on_plane:
            ref_point = (float(pr[iu]), float(pr[iv]))
            ref_P = float(mechanism.analyze(ref_pose, eps, distribution, R=R).p_sphere)
    pm = ProbabilityMap(
        model=mechanism.name,
        u=u,
        v=v,
        P=Pg,
        sigma=sig.reshape(n, n, 3),
        Q=Qs.reshape(nq, n, n),
        limit_margin=margin.reshape(n, n),
        plane=plane,
        offset=float(offset),
        hand_axis=axis,
        R=R,
        distribution=distribution,
        tolerances=dict(zip(mechanism.error_parameters, eps.tolist())),
        tolerance_label=label,
        fixed={names[j]: (val, why) for j, (val, why) in held.items()},
        free_joints=tuple(names[j] for j in free),
        joint_names=tuple(names),
        branch=branch,
        n_alternative_solutions=n_alt,
        n_checked=int(chk.size),
        worst=worst,
        reference=ref_name,
        reference_point=ref_point,
        reference_P=ref_P,
        constraints=tuple(
            f"{c.name}: {math.degrees(c.lower):g} <= "
            + " ".join(
                f"{'+' if coef > 0 else '-'} {'' if abs(coef) == 1 else f'{abs(coef):g}*'}{jn}"
                for jn, coef in c.terms.items()
            ).lstrip("+ ")
            + f" <= {math.degrees(c.upper):g} deg"
            for c in mechanism.spec.joint_constraints
        ),
        elapsed_s=time.perf_counter() - t0,
        joint_units=mechanism.joint_value_units,
    )
    pm.units["Q"] = units_label(mechanism.joint_value_units)  # a strut's length in mm
    return pm
