"""The result of :func:`tolsynth.synthesis.workspace.synthesize_workspace`: the design, the poses
imposed, the exchange's rounds and, with ``certify=True``, the proof over the whole joint space."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tolsynth.problem.result import SynthesisResult, optimality_gap
from tolsynth.tabular import Tabular, jsonable

__all__ = ["WorkspaceSynthesis"]


@dataclass(frozen=True)
class WorkspaceSynthesis(Tabular):
    """Result of :func:`synthesize_workspace`: the constraint imposed over the whole workspace.

    Attributes
    ----------
    result : SynthesisResult
        The optimum at the final set of poses.
    poses : list of ndarray
        The poses (rad) whose constraints were imposed, the starting pose first.
    rounds : list of dict
        Per round: ``n_poses``, ``cost``, ``worst_value`` (the largest value found over the
        workspace at that round's optimum, in the design's reading, :attr:`worst_quantity`: sigma
        z / R; the sphere's (1 - P)/(1 - p); the exact (1 - P)/(1 - p) along the worst direction or in
        the sphere; or the worst case's largest ``|dr| / R`` over every error in its band), ``worst_q`` (rad), ``worst_position`` (mm).
    converged : bool
        True when the worst pose found meets the specification to ``tol``, ``worst_value <= 1 +
        tol`` (with ``certify``: when the proven bound does).
    tol : float or None
        The exchange's tolerance ``synthesize_workspace(tol=...)``: a worst value up to ``1 + tol``
        counts as meeting the specification.
    certified : bool or None
        With ``certify=True``: the specification is proven to hold at every pose of the joint
        space, to ``tol`` (Gaussian: ``upper_bound <= 1 + tol``; exact: ``probability_lower_bound
        >= p - 1e-6``).  None without ``certify``.
    upper_bound : float or None
        Gaussian reading: the proven bound of ``max z sigma_1 / R`` over the joint space, at the
        last solve's tolerances.
    probability_lower_bound : float or None
        The proven lower bound of the smallest per-component probability over the joint space
        (exact or Gaussian reading, as solved).
    certificate : Certificate or None
        The last certified search (:class:`tolsynth.analysis.certify.Certificate`).
    reason : str
        Why not converged ("" when converged).
    margin : float
        The design margin of a certified exchange (``certify_options["margin"]``): the designs were
        solved at ``R / (1 + margin)``, the proof made at ``R``.  0 without one.
    bound_at_R : float or None
        With a margin: the dual bound of a solve at ``R`` itself at the final poses, a lower bound
        on the cost of any tolerances meeting the specification everywhere (:attr:`lower_bound`).
        Proven through sigma_1: the same from the exact reading's solve.
    through : float or None
        The exact reading proven through sigma_1 (``certify_options={"through": "sigma"}``): the
        ``z`` of the Gaussian reading the design was made and proven for.  None otherwise.
    """

    result: SynthesisResult
    poses: list
    rounds: list
    converged: bool
    certified: bool | None = None
    upper_bound: float | None = None
    probability_lower_bound: float | None = None
    certificate: object = None
    reason: str = ""
    margin: float = 0.0
    bound_at_R: float | None = None
    through: float | None = None
    #: each joint value's unit, "rad" or "mm" (a joint that slides); empty: all "rad"
    joint_units: tuple = ()
    tol: float | None = None

    @property
    def success(self) -> bool:
        """The exchange converged and its last solve is optimal."""
        return self.converged and self.result.success

    @property
    def lower_bound(self) -> float:
        """Certified lower bound on the cost of *any* tolerances meeting the specification at every
        pose: the dual bound of the last solve, whose poses are a subset of the workspace (a
        relaxation), so it bounds the semi-infinite problem too.  With a design margin, the same
        bound from a solve at ``R`` itself (the last solve's is at ``R / (1 + margin)``)."""
        return self.bound_at_R if self.bound_at_R is not None else self.result.lower_bound

    @property
    def gap(self) -> float:
        """``cost - lower_bound``: the last solve's own gap, and with a design margin also what the
        margin cost."""
        return self.result.gap if self.bound_at_R is None else optimality_gap(self.result.cost, self.bound_at_R)

    @property
    def worst_quantity(self) -> str:
        """What ``worst_value`` measures, in the design's reading (each <= 1 meets the specification)."""
        res = self.result
        if res is not None and (res.inputs or {}).get("probability") == "worst_case":
            orientation = any(b.kind.startswith("orientation") for b in res.constraints)
            return "worst-case " + ("max(|dr| / R, |dphi| / Phi)" if orientation else "|dr| / R")
        sphere = any(b.kind.startswith("sphere") for b in res.constraints) if res is not None else False
        if res is not None and res.probability_kind == "exact":
            return "exact (1 - P)/(1 - p) " + ("in the sphere" if sphere else "along the worst direction")
        return "(1 - P)/(1 - p) in the sphere" if sphere else "sigma z / R"

    @property
    def worst_value(self) -> float:
        """The largest value found anywhere in the workspace by the search run *after* the last
        solve, at its tolerances, in the design's reading (:attr:`worst_quantity`); NaN if that
        solve failed."""
        return float(self.rounds[-1]["worst_value"]) if self.rounds else float("nan")

    @property
    def binding_poses(self) -> list:
        """The imposed poses (rad) with a constraint active at the last solve (at its limit, or with
        a multiplier above 1e-6 of the largest), position or orientation: each block is matched to
        its pose by its label, since with Phi a pose has two blocks.  (An interior-point solver
        leaves multipliers of about 1e-9 on inactive constraints: not "non-zero".)"""
        if self.result is None or not self.result.constraints:
            return []
        index = {label: i for i, label in enumerate(self.result.spec.poses)}  # the order of self.poses
        top = max(float(np.max(np.abs(b.multipliers))) for b in self.result.constraints)
        binding = {
            index[b.pose]
            for b in self.result.constraints
            if np.any(b.active) or np.any(np.asarray(b.multipliers, dtype=float) > 1e-6 * top)
        }
        return [q for i, q in enumerate(self.poses) if i in binding]

    @property
    def max_violation(self) -> float:
        """``max(0, worst_value - 1)``: how far the returned tolerances miss the specification at the
        worst pose the search found (0 where they meet it everywhere it looked)."""
        return max(0.0, self.worst_value - 1.0) if self.rounds else float("nan")

    def cost_line(self) -> str:
        """The cost with what is proven of it: the exchange's lower bound and gap, then the last
        solve's own dual bound, labelled as holding at its poses only."""
        res = self.result
        return (
            f"cost {res.cost:.8g}  (lower bound {self.lower_bound:.8g} over every pose, gap {self.gap:.2e}; "
            f"the last solve's dual bound at its {len(self.poses)} pose(s) {res.lower_bound:.8g})"
        )

    def certificate_line(self) -> str:
        """The certified search's proven bound over the whole joint space, or why there is none."""
        if self.certified is None:
            return "no certified search (certify=False): the worst pose is sampled"
        if self.upper_bound is not None:
            what = f"max z sigma_1 / R <= {self.upper_bound:.6f}"
        elif self.probability_lower_bound is not None:
            what = f"every component probability >= {self.probability_lower_bound:.8f}"
        else:
            what = "no bound"
        state = "the specification is proven to hold" if self.certified else "NOT proven: " + self.reason
        if self.through:
            state += (
                f"; through sigma_1 and Eaton's tail bound (designed for z sigma_1 <= R with z = {self.through:.4f}), "
                f"the cost is within {self.gap / self.result.cost:.2%} of the cheapest design that meets p at the "
                "poses imposed"
            )
        elif self.margin:
            state += (
                f"; designed with a margin of {self.margin:g} on R, the cost is within "
                f"{self.gap / self.result.cost:.2%} of the cheapest design that meets R everywhere"
            )
        return f"certificate over the whole joint space: {what} ({state})"

    def verdict(self) -> str:
        """Whether :attr:`worst_value` meets the specification, or meets it only to ``tol`` (a value
        up to ``1 + tol`` is taken as met by the exchange)."""
        v = self.worst_value
        if not v > 1.0:
            return "within the specification"
        if self.tol is not None and v <= 1.0 + self.tol:
            return f"{v - 1:.2e} over 1, within the tolerance tol={self.tol:g} of the specification"
        return f"over the specification by {v - 1:.2e}"

    def to_dict(self) -> dict:
        """Plain dict for JSON: the exchange's outcome, its rounds, the poses (rad) and the last
        solve's :meth:`SynthesisResult.to_dict` under ``"result"``; NaN and infinities as None."""
        cert = self.certificate
        return jsonable(
            {
                "success": self.success,
                "converged": self.converged,
                "reason": self.reason,
                "tol": self.tol,
                "cost": self.result.cost if self.result is not None else None,
                "lower_bound": self.lower_bound,
                "gap": self.gap,
                "worst_quantity": self.worst_quantity,
                "worst_value": self.worst_value,
                "max_violation": self.max_violation,
                "certified": self.certified,
                "upper_bound": self.upper_bound,
                "probability_lower_bound": self.probability_lower_bound,
                "margin": self.margin,
                "bound_at_R": self.bound_at_R,
                "through": self.through,
                "joint_units": list(self.joint_units) or ["rad"],
                "poses": self.poses,
                "rounds": self.rounds,
                "certificate": cert.to_dict() if cert is not None else None,
                "result": self.result.to_dict() if self.result is not None else None,
            },
            null=True,
        )

    def summary(self) -> str:
        """Readable summary: the exchange's rounds, the certificate, the largest value found after
        the last solve, and the last solve's own summary."""
        lines = [
            f"workspace exchange: {'converged' if self.converged else 'NOT converged'} after "
            f"{len(self.rounds)} round(s), {len(self.poses)} pose(s) imposed"
            + (f"; designed at R' = R/(1+{self.margin:g}), the values below relative to R'" if self.margin else "")
        ]
        for k, r in enumerate(self.rounds):
            pos = ", ".join(f"{v:.1f}" for v in np.asarray(r["worst_position"], dtype=float))
            lines.append(
                f"  round {k}: {r['n_poses']} pose(s), cost {r['cost']:.8g}, worst over the "
                f"workspace {r['worst_value']:.6f} at hand ({pos}) mm"
            )
        lines.append(
            f"certificate: cost {self.result.cost:.8g}, lower bound {self.lower_bound:.8g} "
            f"(valid at every pose), gap {self.gap:.2e}"
        )
        if self.rounds:
            lines.append(
                f"afterwards: largest {self.worst_quantity} found by the worst-pose search {self.worst_value:.6f}: {self.verdict()}"
            )
        else:
            lines.append("afterwards: no worst-pose search (no round finished)")
        if self.certified is not None:
            lines.append(self.certificate_line())
        lines.append(self.result.summary(cost_line=self.cost_line()))
        return "\n".join(lines)
