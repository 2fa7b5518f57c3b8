"""Assembly of a :class:`~tolsynth.result.SynthesisResult` from a solver's raw output (shared)."""

from __future__ import annotations

import numpy as np

from ..problem import ToleranceNLP
from ..result import ConstraintBlock, Status, SynthesisResult

__all__ = ["assemble"]

ACTIVE_TOL = 1e-6


def assemble(
    solver: str,
    nlp: ToleranceNLP,
    eps: np.ndarray,
    Z: list[np.ndarray],
    bound_mult_u: np.ndarray,
    status: Status,
    message: str,
    iterations: int,
    evaluations: int,
    wall_time: float,
    history: list,
) -> SynthesisResult:
    """Constraint values, activity, multipliers and the dual-bound certificate at ``eps``.

    ``Z`` are the LMI multiplier matrices (Lagrangian ``f - sum tr(Z_b G_b)``, Z_b >= 0);
    ``bound_mult_u`` the multipliers of the bounds in u = ln(eps) (positive: upper bound active,
    negative: lower).  The multiplier of ``g_j = sigma_j z/R - 1 <= 0`` is ``2 d_j^T Z d_j`` with
    ``d_j`` the j-th principal direction (d(1 - (1+g)^2)/dg = -2 at g = 0).
    """
    spec = nlp.spec
    blocks = []
    for block, (vals, dirs), Zb in zip(spec.blocks, nlp.constraint_values(eps), Z):
        mult = np.array([2.0 * float(dirs[:, j] @ Zb @ dirs[:, j]) for j in range(3)])
        blocks.append(
            ConstraintBlock(
                label=block.label,
                pose=block.pose,
                kind=block.kind,
                values=vals,
                directions=dirs,
                active=vals >= 1.0 - ACTIVE_TOL,
                multipliers=mult,
            )
        )
    bounds_active, bound_mult = {}, {}
    for i, name in enumerate(spec.names):
        if eps[i] <= spec.lower[i] * (1 + ACTIVE_TOL):
            bounds_active[name] = "lower"
        elif eps[i] >= spec.upper[i] * (1 - ACTIVE_TOL):
            bounds_active[name] = "upper"
        if name in bounds_active:
            bound_mult[name] = float(bound_mult_u[i] / eps[i])  # d/d eps = (1/eps) d/du
    cost = nlp.cost(eps)
    # both are valid lower bounds: the solver's own multipliers, and those recomputed from the
    # primal point by least squares on stationarity (sharper when the solver's are loose)
    lower = max(nlp.dual_bound(Z), nlp.dual_bound(nlp.kkt_multipliers(eps)))
    return SynthesisResult(
        solver=solver,
        status=status,
        success=status is Status.OPTIMAL,
        message=message,
        tolerances=dict(zip(spec.names, (float(e) for e in eps))),
        units=dict(zip(spec.names, spec.units)),
        cost=cost,
        constraints=tuple(blocks),
        bounds_active=bounds_active,
        bound_multipliers=bound_mult,
        lower_bound=lower,
        gap=cost - lower,
        iterations=int(iterations),
        function_evaluations=int(evaluations),
        wall_time=float(wall_time),
        spec=spec,
        history=history,
    )
