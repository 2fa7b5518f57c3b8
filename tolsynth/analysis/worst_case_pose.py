"""The pose of largest worst-case error at given tolerances: :func:`worst_case_pose`.

The worst case at a pose is the farthest point of the error zonotope ``{sum_i s_i eps_i a_i(q) :
|s_i| <= 1}`` (:func:`tolsynth.solvers.worst_case_zonotope.zonotope_max`), relative to R, and
with Phi the orientation's relative to Phi; the search maximises the larger of the two over the
joint space with the grid and compass search of :func:`tolsynth.analysis.worst_pose`.  The
workspace exchange of a worst-case design (:func:`tolsynth.synthesize_workspace` with
``probability="worst_case"``) runs it after each solve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tolsynth.kinematics.joint_space import _feasible, _limits, grid_and_compass, hold_fixed, scaled_joints
from tolsynth.solvers.worst_case_zonotope import zonotope_max

__all__ = ["WorstCasePose", "worst_case_at", "worst_case_pose"]

#: grid points of the coarse search: each pose costs an exact zonotope maximum (about 1 ms on a
#: six-joint arm), not a batched covariance
GRID_POINTS = 2000


@dataclass(frozen=True)
class WorstCasePose:
    """``q`` (rad) and ``position`` (mm) of the pose found; ``value`` the largest worst-case
    ``|dr| / R`` (and ``|dphi| / Phi``) there; ``held_joints`` the joints held (they change no
    worst case)."""

    q: np.ndarray
    position: np.ndarray
    value: float
    held_joints: dict


def worst_case_at(mechanism, q, eps, R: float, Phi: float | None = None) -> float:
    """``max(h_pos / R, h_ori / Phi)`` at joints ``q`` (rad): the worst case over every error in
    its band (NaN where a parallel robot's platform does not assemble)."""
    S = np.asarray(mechanism.sensitivity(q, check_limits=False), dtype=float)
    if not np.all(np.isfinite(S)):
        return float("nan")
    value = zonotope_max(S[:3] * eps)[0] / R
    if Phi is not None:
        value = max(value, zonotope_max(S[3:6] * eps)[0] / Phi)
    return float(value)


def worst_case_pose(
    mechanism,
    eps,
    R: float,
    Phi: float | None = None,
    *,
    grid: int | None = None,
    fixed: dict | None = None,
    starts: int = 4,
    step_tol: float = 1e-7,
    max_grid_points: int = GRID_POINTS,
    seed: int = 0,
    reference=None,
) -> WorstCasePose:
    """The pose of largest :func:`worst_case_at` found by a grid and compass search over the joint
    space (inside every joint limit and constraint); joints that change no worst case (checked at
    random poses) and ``fixed`` ones are held.  Arguments as :func:`tolsynth.worst_pose`'s;
    ``eps`` in tolerance units, ``R`` mm, ``Phi`` rad."""
    from tolsynth.analysis.pose_search import MAX_GRID_POINTS
    from tolsynth.kinematics.joint_space import _reference

    eps = np.asarray(eps, dtype=float)
    lo, hi = _limits(mechanism)
    nq = len(lo)
    rng = np.random.default_rng(seed)
    _, ref_q = _reference(mechanism, reference)
    base_q = ref_q if ref_q is not None else np.clip(np.zeros(nq), lo, hi)

    def values(Q: np.ndarray) -> np.ndarray:
        return np.array([worst_case_at(mechanism, Q[:, i], eps, R, Phi) for i in range(Q.shape[1])])

    # a joint that turns the whole zonotope (a waist), or about whose axis the rest of it is
    # symmetric, changes no worst case: holding it shrinks the grid
    held: dict[int, float] = {}
    Q = lo[:, None] + (hi - lo)[:, None] * rng.random((nq, 6))
    base = values(Q)
    for j in range(nq):
        Q2 = Q.copy()
        Q2[j] = lo[j] + (hi[j] - lo[j]) * rng.random(Q.shape[1])
        v2 = values(Q2)
        if np.all(np.isfinite(base)) and np.all(np.abs(v2 - base) <= 1e-9 * np.max(base) + 1e-15):
            held[j] = float(np.clip(base_q[j], lo[j], hi[j]))
    hold_fixed(mechanism, dict(fixed or {}), lo, hi, held)
    free = [j for j in range(nq) if j not in held]

    def evaluate(U: np.ndarray, tol: float = 0.0) -> np.ndarray:
        Q = scaled_joints(U, held, free, lo, hi)
        ok = _feasible(mechanism, Q) & np.all((U >= 0) & (U <= 1), axis=0)
        val = np.full(U.shape[1], -np.inf)
        if np.any(ok):
            val[ok] = values(Q[:, ok])
            val[~np.isfinite(val)] = -np.inf
        return val

    best_u, _, _, _ = grid_and_compass(
        mechanism, evaluate, free, lo, hi, grid, max_grid_points, starts, step_tol, MAX_GRID_POINTS, 0.0
    )
    q = scaled_joints(best_u[:, None], held, free, lo, hi)[:, 0]
    names = list(mechanism.joint_names)
    return WorstCasePose(
        q=q,
        position=np.asarray(mechanism.fk(q, check_limits=False))[:3, 3],
        value=worst_case_at(mechanism, q, eps, R, Phi),
        held_joints={names[j]: v for j, v in held.items()},
    )
