"""A parallel robot's inverse kinematics on a grid of a plane, in closed form (the map's solver).

The platform keeps the reference configuration's pose except for the hand point, which is put on
each grid point; the actuators follow from the closed-form inverse kinematics of
:mod:`tolsynth.kinematics.parallel` (each revolute leg on its home branch).  A point is reachable
when every leg reaches, the actuators lie inside their limits, and the forward kinematics (Newton
from the home pose) gives the hand point back: the pose belongs to the assembly mode that the error
model is evaluated on.  The class has the interface of the serial arms' grid solver
(:class:`tolsynth.kinematics.ik._GridIK`), so that :func:`tolsynth.probability_map` uses either.
Units: mm and rad.
"""

from __future__ import annotations

import numpy as np

from tolsynth.errors import InputError
from tolsynth.kinematics.batch_stats import _evaluator
from tolsynth.kinematics.ik import PLANES
from tolsynth.kinematics.joint_space import _feasible, _limit_margin
from tolsynth.kinematics.numpy_eval import NumpyEvaluator

__all__ = ["ParallelGridIK", "ROUND_TRIP_TOL"]

#: largest distance (mm) between a grid point and the forward kinematics of its actuators
ROUND_TRIP_TOL = 1e-6
#: largest difference (per component of the unit vector) between the requested hand axis and the
#: reference pose's, which the map keeps
AXIS_TOL = 1e-6


class ParallelGridIK:
    """Closed-form inverse kinematics of a parallel robot on a grid of a base-frame plane."""

    branch_note = (
        "closed-form inverse kinematics, each revolute leg on the home configuration's branch; "
        "forward kinematics (Newton from the home pose) checked at every point"
    )

    def __init__(self, mech, free, held, ref_q, axis, plane, offset, seeds):
        if held:
            raise InputError(
                "fixed", "a parallel robot's actuators cannot be held: the platform pose sets them all", "None"
            )
        g = mech.graphs
        self.mech = mech
        self.iu, self.iv, self.inorm = PLANES[plane]
        self.offset = offset
        self.ref_q = ref_q.copy()
        x_ref = np.asarray(g.pose(ref_q, np.zeros(mech.n)), dtype=float).ravel()
        if not np.all(np.isfinite(x_ref)):
            raise InputError(
                "reference",
                "the platform is not assembled at the reference configuration",
                "a configuration inside the workspace",
            )
        T_ref = np.asarray(g.fk(ref_q, np.zeros(mech.n)), dtype=float)
        # a micro-radian: a home pose solved from anchors printed to 0.1 um is level only to ~1e-7
        if axis is not None and not np.allclose(axis, T_ref[:3, 2], atol=AXIS_TOL):
            raise InputError(
                "hand_axis",
                f"{np.round(axis, 6).tolist()}: the map keeps the reference pose's platform orientation",
                f"{np.round(T_ref[:3, 2], 9).tolist()} or None",
            )
        self.x_ref, self.R_ref = x_ref, T_ref[:3, :3]
        self.lever = self.R_ref @ np.asarray(mech.spec.tool_point, dtype=float)  # platform origin -> hand
        self.seed_set = [self.ref_q]
        self.ik = NumpyEvaluator(g.ik)
        self.position = _evaluator(mech, "position")

    def targets(self, U, V) -> np.ndarray:
        T = np.empty((3, U.size))
        T[self.iu], T[self.iv], T[self.inorm] = U, V, self.offset
        return T

    def attempt(self, Q0, T):
        """Actuators for the hand points ``T`` (``Q0`` is not needed: the solution is in closed
        form), a reachable flag, and the limit margin (-inf where no leg solution exists)."""
        spec = self.mech.spec
        N = T.shape[1]
        X = np.repeat(self.x_ref[:, None], N, axis=1)
        reachable = np.ones(N, bool)
        for i, d in enumerate(spec.dof):  # the platform origin's coordinates that are pose dof
            if d in ("x", "y", "z"):
                X[i] = T["xyz".index(d)] - self.lever["xyz".index(d)]
        for k, d in enumerate("xyz"):  # a coordinate that is not a dof stays at the reference pose's
            if d not in spec.dof:
                p_ref = (self.x_ref[spec.dof.index(d)] if d in spec.dof else 0.0) + self.lever[k]
                reachable &= np.abs(T[k] - p_ref) <= ROUND_TRIP_TOL
        Q, C = self.ik([X, np.zeros(self.mech.n)])
        Q = np.asarray(Q, dtype=float).reshape(-1, N)
        C = np.asarray(C, dtype=float).reshape(-1, N)
        reachable &= np.all(np.abs(C) <= 1.0, axis=0) & np.all(np.isfinite(Q), axis=0)
        Q = np.where(reachable[None, :], Q, np.nan)
        margin = np.full(N, -np.inf)
        margin[reachable] = _limit_margin(self.mech, Q[:, reachable])
        ok = reachable.copy()
        ok[reachable] = _feasible(self.mech, Q[:, reachable])
        if np.any(ok):  # the forward kinematics must give the point back (same assembly mode)
            P = self.position([Q[:, ok], np.zeros(self.mech.n)])[0]
            back = np.all(np.abs(P - T[:, ok]) <= ROUND_TRIP_TOL, axis=0)
            ok[np.flatnonzero(ok)[~back]] = False
        return Q, ok, margin

    def solve(self, u, v, bar=None):
        """Actuators (nq, N), reachable flag (N,) and limit margin (N,) for the grid u x v (rows v)."""
        Ug, Vg = np.meshgrid(u, v)
        Q, ok, margin = self.attempt(None, self.targets(Ug.ravel(), Vg.ravel()))
        if bar is not None:
            bar.update(max(0, Ug.size - bar.n))
        return np.where(ok[None, :], Q, np.nan), ok, margin
