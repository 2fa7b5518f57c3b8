"""Assembly of a :class:`~tolsynth.problem.result.SynthesisResult` from a solver's raw output (shared)."""

from __future__ import annotations

import math

import numpy as np

from tolsynth.problem.nlp import ToleranceNLP
from tolsynth.problem.result import ConstraintBlock, Status, SynthesisResult, optimality_gap
from tolsynth.solvers.sphere_bound import box_bound
from tolsynth.solvers.sphere_support import support_bound

__all__ = ["assemble"]

ACTIVE_TOL = 1e-6

#: ``success`` needs, whatever the solver's own status, the returned point to meet every constraint
#: by an independent check (largest ``sigma z / R`` by NumPy's eigensolver, or ``(1-P)/(1-p)``
#: by the error-controlled ``p_ball``) within FEAS_TOL ...
FEAS_TOL = 1e-6
#: ... and, for the convex (per-component) problem, a certificate gap within GAP_TOL of the cost
GAP_TOL = 1e-6
#: the solver's multipliers alone certify when their gap is within this fraction of GAP_TOL;
#: otherwise those recomputed from the point (ToleranceNLP.kkt_multipliers) are tried as well
KKT_SKIP = 1e-3


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
    mu_sphere: np.ndarray | None = None,
    lagrangian: tuple[np.ndarray, float] | None = None,
    relaxation_bound=None,
) -> SynthesisResult:
    """Constraint values, activity, multipliers and the dual-bound certificate at ``eps``.

    ``Z`` are the LMI multiplier matrices (Lagrangian ``f - sum tr(Z_b G_b)``, Z_b >= 0);
    ``bound_mult_u`` the multipliers of the bounds in u = ln(eps) (positive: upper bound active,
    negative: lower).  The multiplier of ``g_j = sigma_j z/R - 1 <= 0`` is ``2 d_j^T Z d_j`` with
    ``d_j`` the j-th principal direction (d(1 - (1+g)^2)/dg = -2 at g = 0).

    ``mu_sphere`` are the multipliers of ``P_b >= p_b`` (sphere criterion), reported for
    ``g = (1 - P)/(1 - p) <= 1`` as ``mu (1 - p)``.  With sphere blocks the lower bound is the
    best of three, the per-component problem at the same p (solved here by IPOPT), the box of the
    independent principal components (:mod:`.sphere_bound`) and the proven supporting half-space at
    the design (:mod:`.sphere_support`); a checked design's status is ``FEASIBLE``: the sphere
    problem is not known to be convex, and the bound is proven only to a tolerance.

    ``lagrangian``: ``(w, tr)`` of the solver's multipliers (:meth:`ToleranceNLP.dual_weights`),
    if it has them without ``Z`` (IPOPT's cut multipliers); default: from ``Z``.
    """
    spec = nlp.spec
    # exp(ln eps) may round one ulp past a bound (a lock)
    eps = np.minimum(np.maximum(np.asarray(eps, dtype=float), spec.lower), spec.upper)
    vals, dirs = nlp.block_values(eps)
    vals, dirs = vals.copy(), dirs.copy()  # the result's own (block_values remembers its answer)
    m = len(spec.blocks)
    Zs = np.asarray(Z, dtype=float).reshape(m, 3, 3)
    mults = 2.0 * (dirs * (Zs @ dirs)).sum(axis=1)  # 2 d_j^T Z d_j for every block and j
    active = vals >= 1.0 - ACTIVE_TOL
    blocks = [
        ConstraintBlock(
            label=block.label,
            pose=block.pose,
            kind=block.kind,
            values=vals[b],
            directions=dirs[b],
            active=active[b],
            multipliers=mults[b],
        )
        for b, block in enumerate(spec.blocks)
    ]
    if spec.sphere_blocks:
        sphere_vals = nlp.sphere_values(eps)
        mu_sphere = np.zeros(len(sphere_vals)) if mu_sphere is None else np.asarray(mu_sphere, dtype=float)
        for block, (vals, dirs, _), mu in zip(spec.sphere_blocks, sphere_vals, mu_sphere):
            blocks.append(
                ConstraintBlock(
                    label=block.label,
                    pose=block.pose,
                    kind="sphere",
                    values=vals,
                    directions=dirs,
                    active=vals >= 1.0 - ACTIVE_TOL,
                    multipliers=np.array([mu * (1.0 - block.p)]),
                )
            )
    at_lower = eps <= spec.lower * (1 + ACTIVE_TOL)
    at_upper = ~at_lower & (eps >= spec.upper * (1 - ACTIVE_TOL))
    bounds_active, bound_mult = {}, {}
    for i in (at_lower | at_upper).nonzero()[0]:
        name = spec.names[i]
        bounds_active[name] = "lower" if at_lower[i] else "upper"
        bound_mult[name] = float(bound_mult_u[i] / eps[i])  # d/d eps = (1/eps) d/du
    cost = nlp.cost(eps)
    if spec.sphere_blocks and relaxation_bound is None:  # a start for another method: no bound asked
        lower = -math.inf
    elif spec.sphere_blocks:  # relaxations, each containing the sphere's feasible set
        lower = max(relaxation_bound(nlp), box_bound(nlp, eps))
        if status is Status.OPTIMAL:  # the proven supporting half-space at the design (about 0.3-1 s)
            lower = max(lower, support_bound(nlp, eps))
    else:
        # both are valid lower bounds: the solver's own multipliers, and those recomputed from the
        # primal point by least squares on stationarity (sharper when the solver's are loose, so
        # tried unless the solver's already close the gap with room to spare)
        lower = nlp.lagrangian_bound(*lagrangian) if lagrangian is not None else nlp.dual_bound(Zs)
        if not cost - lower <= KKT_SKIP * GAP_TOL * abs(cost):
            lower = max(lower, nlp.dual_bound(nlp.kkt_multipliers(eps)))
    status, message = _verified(status, message, blocks, cost, lower, certified=not spec.sphere_blocks)
    if not spec.sphere_blocks and not spec.convex:
        # weak duality still holds (the dual bound's 1-D minima are global), so a closed gap still
        # certifies; an open one may be a local optimum, and _verified has withheld "optimal"
        bad = [nm for nm, ok in zip(spec.names, spec.costs.convex(spec.lower, spec.upper)) if not ok]
        message = f"{message}; the cost of {bad} is not convex in eps^2 on its range: " + (
            "certified only because the dual gap closed"
            if status is Status.OPTIMAL
            else "no certificate, possibly a local optimum (the lower bound is valid)"
        )
    return SynthesisResult(
        solver=solver,
        status=status,
        success=status is Status.OPTIMAL,
        message=message,
        tolerances=dict(zip(spec.names, eps.tolist())),
        units=dict(zip(spec.names, spec.units)),
        cost=cost,
        constraints=tuple(blocks),
        bounds_active=bounds_active,
        bound_multipliers=bound_mult,
        lower_bound=lower,
        gap=optimality_gap(cost, lower),
        iterations=int(iterations),
        function_evaluations=int(evaluations),
        wall_time=float(wall_time),
        spec=spec,
        history=history,
    )


def _verified(status: Status, message: str, blocks, cost: float, lower: float, certified: bool):
    """An optimum is reported only if the point is feasible by an independent check and, for the
    convex problem, certified by a small gap; otherwise the status says why it is not."""
    if status is not Status.OPTIMAL:
        return status, message
    worst = max((float(b.values[0]) for b in blocks), default=0.0)
    if not math.isfinite(cost) or not worst <= 1.0 + FEAS_TOL:
        return Status.NUMERICAL_ERROR, (
            f"{message}; rejected: the point violates the specification "
            f"(largest constraint value {worst:.6g} > 1 + {FEAS_TOL:g})"
        )
    gap = cost - lower
    if certified and not gap <= GAP_TOL * abs(cost):
        return Status.OPTIMAL_INACCURATE, (
            f"{message}; not certified: dual gap {gap:.3g} ({gap / abs(cost):.2e} of the cost) > {GAP_TOL:g}"
        )
    if not certified:  # the sphere criterion: a checked design, its optimality not proven
        return Status.FEASIBLE, (
            f"{message}; the sphere criterion is met (checked by p_ball), optimality not proven: the problem "
            f"is not known to be convex, and the lower bound (the best of the per-component relaxation, the box "
            f"relaxation and the proven supporting half-space) leaves a gap of {gap:.4g} ({gap / abs(cost):.2%} of "
            "the cost)"
        )
    return status, message
