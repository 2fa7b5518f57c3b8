"""One result type for every solver, and the status vocabulary.

Each solver module owns the table from its own return codes to :class:`Status`; only
``Status.OPTIMAL`` counts as ``success``.  A result whose ``success`` is False carries the solver's
last iterate for inspection, but is never to be read as an optimum.  ``Status.FEASIBLE`` is the one
non-success whose design is usable: it meets the specification by an independent check, but no
certificate proves it optimal (the sphere criterion, a problem not known to be convex);
:attr:`SynthesisResult.feasible` is True for it and for ``OPTIMAL``.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tolsynth.tabular import Tabular

__all__ = ["Status", "ConstraintBlock", "SynthesisResult", "optimality_gap"]

#: a gap below zero by at most this fraction of the cost is rounding: the cost and its lower bound
#: are computed separately and meet at the optimum to about 1e-12 of the cost (the solvers stop at
#: about 1e-11), far inside this; success needs the gap within 1e-6 of the cost
GAP_ROUNDING = 1e-9


def optimality_gap(cost: float, lower: float) -> float:
    """``cost - lower`` as stored and shown everywhere: 0 where it is below zero only by rounding
    (within :data:`GAP_ROUNDING` of the cost), since a bound cannot truly exceed the optimum; a
    larger negative gap is kept as it is, a defect to see rather than hide (NaN stays NaN)."""
    gap = float(cost) - float(lower)
    if -GAP_ROUNDING * max(abs(float(cost)), 1.0) <= gap < 0.0:
        return 0.0
    return gap


class Status(str, enum.Enum):
    """Why the solver stopped, in one vocabulary for all solvers."""

    OPTIMAL = "optimal"  # converged to the requested tolerances
    OPTIMAL_INACCURATE = "optimal_inaccurate"  # stopped at a looser, "acceptable" level
    #: meets the specification (checked independently), optimality not proven: the problem is not
    #: known to be convex, and its lower bound (reported with its gap) need not be tight
    FEASIBLE = "feasible"
    INFEASIBLE = "infeasible"  # the solver concluded that no feasible point exists
    ITERATION_LIMIT = "iteration_limit"  # stopped by an iteration / evaluation limit
    NUMERICAL_ERROR = "numerical_error"  # stopped by a numerical difficulty
    TIME_LIMIT = "time_limit"  # stopped by the time limit (synthesize(..., time_limit=...))
    SOLVER_ERROR = "solver_error"  # any other failure

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class ConstraintBlock:
    """The accuracy constraints of one pose and kind, at the returned tolerances.

    ``values`` are the paper's ``sigma_j * z(p) / R`` (``/ Phi`` for orientation), descending, each
    required <= 1 (for the sphere criterion, kind ``"sphere"``: the one value ``(1 - P)/(1 - p)``,
    P = P(|dr| <= R) by :func:`tolsynth.probability.stats.p_ball`); ``directions`` the principal directions (columns, base frame); ``active`` which
    values are at 1 (within 1e-6); ``multipliers`` the Lagrange multipliers of the constraints
    ``g_j = sigma_j z / R - 1 <= 0`` (cost units per unit of g).
    """

    label: str
    pose: str
    kind: str
    values: np.ndarray
    directions: np.ndarray
    active: np.ndarray
    multipliers: np.ndarray


@dataclass(frozen=True)
class SynthesisResult(Tabular):
    """Optimal tolerances from :func:`tolsynth.synthesize` (any solver).

    Attributes
    ----------
    tolerances : dict
        Name -> half-width ``eps_i`` in the parameter's tolerance unit (``units``).
    cost : float
        ``sum k_i eps_i**-alpha_i`` in the paper's cost units.
    success, status, message
        ``success`` is True only for ``Status.OPTIMAL``; ``message`` is the solver's own reason.
        ``Status.FEASIBLE`` (``success`` False, :attr:`feasible` True): the design meets the
        specification, but its optimality is not proven (the gap says by how much it may miss).
    constraints : tuple of ConstraintBlock
        ``sigma_j z / R`` per pose and kind, with activity and multipliers.
    bounds_active : dict
        Name -> "lower" / "upper" for parameters at a bound (within 1e-6 relative).
    bound_multipliers : dict
        Name -> multiplier of the active bound (cost units per tolerance unit).
    lower_bound, gap : float
        Lagrangian (dual) lower bound on the optimal cost from the constraint multipliers, and
        ``cost - lower_bound``; the problem is convex, so a small gap certifies global optimality.
        (Sphere criterion: the optimum of a relaxation whose feasible set contains the sphere's,
        a valid bound but not a tight one; the status is then ``FEASIBLE``, not ``OPTIMAL``.)
    iterations, function_evaluations : int
        For IPOPT: iterations and NLP function evaluations; for SUMT: Powell iterations summed
        over the outer loop, and penalty-function evaluations.
    wall_time : float
        Seconds in the solver (graph construction excluded).
    history : list of dict
        Per iteration (IPOPT: objective and infeasibility; SUMT: outer iterations with their
        inner Powell histories).
    inputs : dict or None
        What :func:`tolsynth.synthesize` was given beyond the specification (model, solver
        options, locks, start); :meth:`to_frame` and the writers record it with ``spec``'s values.
    """

    solver: str
    status: Status
    success: bool
    message: str
    tolerances: dict[str, float]
    units: dict[str, str]
    cost: float
    constraints: tuple[ConstraintBlock, ...]
    bounds_active: dict[str, str]
    bound_multipliers: dict[str, float]
    lower_bound: float
    gap: float
    iterations: int
    function_evaluations: int
    wall_time: float
    spec: Any = field(repr=False)
    history: list = field(default_factory=list, repr=False)
    validation: Any = field(default=None, repr=False)
    inputs: dict | None = field(default=None, repr=False)
    #: ``synthesize(..., verify=...)``: the closed loop's :class:`tolsynth.analysis.verify.Verification`
    verification: Any = field(default=None, repr=False)
    #: how the design does over the workspace, a quick sampled check computed when first read
    #: (:class:`tolsynth.analysis.validation.WorkspaceCheck`: ``result.workspace.line()``, ``.worst``);
    #: :meth:`summary`, :meth:`to_dict` and ``to_frame()`` show it once computed and never compute it.
    #: None where synthesize attached none
    workspace: Any = field(default=None, repr=False, compare=False)

    @property
    def x(self) -> np.ndarray:
        """Tolerances as a vector in the model's parameter order."""
        return np.array(list(self.tolerances.values()))

    @property
    def feasible(self) -> bool:
        """True if the design meets the specification by an independent check: ``OPTIMAL`` (and
        proven optimal) or ``FEASIBLE`` (optimality not proven)."""
        return self.status in (Status.OPTIMAL, Status.FEASIBLE)

    @property
    def probability_kind(self) -> str:
        """The probabilities the design meets: ``"gaussian"`` (the paper's), ``"exact"`` or
        ``"worst_case"`` (as asked of :func:`tolsynth.synthesize`, else read from the constraints)."""
        asked = (self.inputs or {}).get("probability")
        return asked or ("exact" if any(b.kind.endswith("(exact)") for b in self.constraints) else "gaussian")

    @property
    def max_constraint(self) -> float:
        """Largest ``sigma_j z / R`` over all blocks (<= 1 means the specification is met)."""
        return float(max(b.values[0] for b in self.constraints))

    def summary(self, cost_line: str | None = None) -> str:
        """Readable summary: status, cost, bound and gap, tolerances with units and bound markers, constraint values and multipliers.
        ``cost_line`` replaces the cost, bound and gap line (a workspace exchange's bound is its own)."""
        lines = [
            f"{self.solver}: {self.status} ({self.message})",
            cost_line or f"cost {self.cost:.8g}  (dual bound {self.lower_bound:.8g}, gap {self.gap:.2e})",
            f"iterations {self.iterations}, evaluations {self.function_evaluations}, {self.wall_time * 1e3:.1f} ms",
            f"probabilities: {self.probability_kind}",
        ]
        spec = self.spec
        fixed = {
            n
            for n, a, b in zip(getattr(spec, "names", ()), getattr(spec, "lower", ()), getattr(spec, "upper", ()))
            if a == b
        }  # locked (tolsynth.model.locks) or a fixed joint error
        for name, value in self.tolerances.items():
            flag = f"  [{self.bounds_active[name]} bound]" if name in self.bounds_active else ""
            flag = "  [fixed]" if name in fixed else flag
            lines.append(f"  {name:>8} = {value:.6g} {self.units[name]}{flag}")
        for b in self.constraints:
            vals = ", ".join(f"{v:.6f}" for v in b.values)
            mult = ", ".join(f"{m:.4g}" for m in b.multipliers)
            if b.kind.endswith("(exact)"):  # tolsynth.solvers.exact: exact P, worst direction first
                what = (
                    "exact (1-P)/(1-p) in the sphere"
                    if b.kind.startswith("sphere")
                    else "exact (1-P)/(1-p) along the worst direction, then the principal axes"
                )
                lines.append(f"  {b.label}: {what} = ({vals})")
                continue
            what = "(1-P)/(1-p)" if b.kind == "sphere" else "sigma z/limit"
            lines.append(f"  {b.label}: {what} = ({vals}); multipliers ({mult})")
        if self.inputs and self.inputs.get("default_pose"):
            lines.append(f"pose: {self.inputs['default_pose']}")
        lines += self._workspace_lines()
        return "\n".join(lines)

    def _workspace_lines(self) -> list[str]:
        """The sampled workspace check's line for a summary: shown once computed, so that a summary
        runs no search (about a second); none where no check is attached."""
        if self.workspace is None:
            return []
        if self.workspace.computed:
            return [self.workspace.line()]
        return [
            f"workspace check: not computed (result.workspace.line() samples {self.workspace.n} poses; "
            "tolsynth.synthesize_workspace designs for every pose)"
        ]

    def _repr_html_(self) -> str:
        """The summary as an HTML block (Jupyter shows it in place of the dataclass repr)."""
        import html

        head = f"<b>{html.escape(self.solver)}: {html.escape(str(self.status))}</b> (success: {self.success})"
        rows = "".join(
            f"<tr><td>{html.escape(n)}</td><td>{v:.6g}</td><td>{html.escape(self.units[n])}</td></tr>"
            for n, v in self.tolerances.items()
        )
        return (
            f"<div>{head}<br>cost {self.cost:.8g}, dual bound {self.lower_bound:.8g}, gap {self.gap:.2e}"
            f"<table><tr><th>parameter</th><th>tolerance</th><th>unit</th></tr>{rows}</table>"
            f"<pre>{html.escape(self.summary())}</pre></div>"
        )

    def to_dict(self) -> dict:
        """Plain dict for JSON (probability kind, tolerances, units, cost, bound, gap, constraints,
        bounds, counts, time; ``workspace_check``: the sampled workspace check's dict once it has
        been computed, else None)."""
        ws = self.workspace
        return {
            "solver": self.solver,
            "probability": self.probability_kind,
            "status": str(self.status),
            "success": self.success,
            "message": self.message,
            "tolerances": self.tolerances,
            "units": self.units,
            "cost": self.cost,
            "lower_bound": self.lower_bound,
            "gap": self.gap,
            "constraints": [
                {
                    "label": b.label,
                    "values": b.values.tolist(),
                    "active": b.active.tolist(),
                    "multipliers": b.multipliers.tolist(),
                }
                for b in self.constraints
            ],
            "bounds_active": self.bounds_active,
            "bound_multipliers": self.bound_multipliers,
            "iterations": self.iterations,
            "function_evaluations": self.function_evaluations,
            "wall_time": self.wall_time,
            "workspace_check": ws.to_dict() if ws is not None and ws.computed else None,
        }
