"""Joint-space helpers shared by the pose search and the workspace map: joint limits, joint
constraints (the interference limit), wrapping of revolute joints, the distance to the limits,
and the resolution of a reference configuration.  Units: rad.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import UnknownNameError

__all__: list[str] = []  # internal helpers of tolsynth.pose_search and tolsynth.workspace_map


def _limits(mech) -> tuple[np.ndarray, np.ndarray]:
    return np.array([j.lower for j in mech.spec.joints]), np.array([j.upper for j in mech.spec.joints])


def _feasible(mech, Q: np.ndarray) -> np.ndarray:
    """Joint limits and joint constraints, evaluated exactly as :meth:`Mechanism.joints` does."""
    lo, hi = _limits(mech)
    ok = np.all((Q >= lo[:, None]) & (Q <= hi[:, None]), axis=0)
    names = list(mech.joint_names)
    for c in mech.spec.joint_constraints:
        v = 0
        for jn, coef in c.terms.items():
            v = v + coef * Q[names.index(jn)]
        ok &= (c.lower <= v) & (v <= c.upper)
    return ok


def _wrap(mech, Q: np.ndarray) -> np.ndarray:
    """Move each revolute joint value by a multiple of 2 pi into its limits where possible."""
    lo, hi = _limits(mech)
    Q = Q.copy()
    for j in range(Q.shape[0]):
        v = Q[j]
        k = np.ceil((lo[j] - v) / (2 * math.pi))  # smallest shift that reaches the lower limit
        w = v + 2 * math.pi * k
        Q[j] = np.where(w <= hi[j], w, v)
    return Q


def _reference(mech, reference) -> tuple[str | None, np.ndarray | None]:
    if reference is None:
        return None, None
    if isinstance(reference, str):
        if reference not in mech.configurations:
            raise UnknownNameError("reference", f"unknown configuration {reference!r}",
                                   "one of " + ", ".join(mech.configurations))
        return reference, mech.joints(reference)
    return "given", mech.joints(reference)


def _limit_margin(mech, Q: np.ndarray) -> np.ndarray:
    """Smallest distance (rad) to a joint limit or joint constraint; negative outside."""
    lo, hi = _limits(mech)
    m = np.min(np.minimum(Q - lo[:, None], hi[:, None] - Q), axis=0)
    names = list(mech.joint_names)
    for c in mech.spec.joint_constraints:
        v = 0
        for jn, coef in c.terms.items():
            v = v + coef * Q[names.index(jn)]
        norm = math.sqrt(sum(coef * coef for coef in c.terms.values()))
        m = np.minimum(m, np.minimum(v - c.lower, c.upper - v) / norm)
    return m
