"""Reproduction of the paper's Tables 1-3: all 18 columns, IPOPT and SUMT against the print.

For every column (R, p, alpha; uniform and normal) of the model's ``reference_results``:

* the printed tolerances, and what they give in this model: their cost and their largest
  ``sigma z / R`` (<= 1 means they meet the specification at the worst pose);
* the optimum by IPOPT and by SUMT + Powell, their costs and their agreement;
* both readings of the printed angle unit (docs/reconstruction.md): "1e-2 rad" as printed, and
  "deg", in which the paper's angular numbers are degrees and the cost is evaluated on them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tolsynth.kinematics.mechanism import Mechanism, load_model
from tolsynth.problem.nlp import ToleranceNLP
from tolsynth.problem.result import SynthesisResult
from tolsynth.problem.specification import make_specification
from tolsynth.synthesis.single import synthesize

__all__ = ["reproduce", "ColumnReport", "Reading", "format_report"]


@dataclass(frozen=True)
class Reading:
    """One reading of the printed angle unit for one column."""

    angle_unit: str
    printed: dict[str, float]  # the printed numbers, in this reading's units
    printed_cost: float
    printed_max_constraint: float  # largest sigma z / R of the printed tolerances in this model
    ipopt: SynthesisResult
    sumt: SynthesisResult | None = None

    @property
    def ratio(self) -> dict[str, float]:
        """IPOPT optimum / printed value, per parameter."""
        return {k: self.ipopt.tolerances[k] / v for k, v in self.printed.items()}


@dataclass(frozen=True)
class ColumnReport:
    table: str
    R: float
    p: float
    alpha: float
    distribution: str
    readings: dict[str, Reading] = field(default_factory=dict)

    @property
    def label(self) -> str:
        return f"{self.table}: R={self.R:g} mm, p={self.p:g}, alpha={self.alpha:g}, {self.distribution}"

    @property
    def printed_unit(self) -> Reading:
        return next(iter(self.readings.values()))

    def agreement(self) -> dict[str, float]:
        """IPOPT vs SUMT in the printed-unit reading: relative cost and largest tolerance difference."""
        r = self.printed_unit
        if r.sumt is None:
            return {}
        return {
            "cost_rel_diff": abs(r.sumt.cost - r.ipopt.cost) / r.ipopt.cost,
            "max_tolerance_rel_diff": max(abs(r.sumt.tolerances[k] - v) / v for k, v in r.ipopt.tolerances.items()),
        }

    def to_dict(self) -> dict:
        out = {
            "table": self.table,
            "R": self.R,
            "p": self.p,
            "alpha": self.alpha,
            "distribution": self.distribution,
            "agreement": self.agreement(),
            "readings": {},
        }
        for key, r in self.readings.items():
            out["readings"][key] = {
                "angle_unit": r.angle_unit,
                "printed": r.printed,
                "printed_cost": r.printed_cost,
                "printed_max_constraint": r.printed_max_constraint,
                "ipopt": r.ipopt.to_dict(),
                "sumt": r.sumt.to_dict() if r.sumt is not None else None,
                "ratio_ipopt_to_printed": r.ratio,
            }
        return out


def _printed_eval(mech: Mechanism, ref, printed: np.ndarray):
    spec = make_specification(mech, ref.R, ref.p, ref.distribution, ref.alpha)
    nlp = ToleranceNLP(spec)
    return nlp.cost(printed), float(nlp.constraint_values(printed)[0][0][0])


def reproduce(
    model: str | Mechanism = "xu_zhang_1988", sumt: bool = True, progress: bool = False, degree_reading: bool = True
) -> list[ColumnReport]:
    """Solve every published column of the model (its ``reference_results``).

    Parameters
    ----------
    model : name, path or Mechanism
    sumt : bool
        Also solve with SUMT + Powell in the printed-unit reading (some 15 ms a column with a C
        compiler, :mod:`tolsynth.solvers.cpowell`; some 0.5 s without).
    progress : bool
        Show a progress bar on stderr (if the optional tqdm is installed).
    degree_reading : bool
        Also read the printed angular numbers as degrees (and optimise with degree numbers in the
        cost).
    """
    mech = model if isinstance(model, Mechanism) else load_model(model)
    refs = mech.spec.reference_results
    angle_params = [p.name for p in mech.parameters if p.kind == "angle"]
    readings = {"printed": mech}
    if degree_reading and angle_params:
        readings["deg"] = mech.with_units({n: "deg" for n in angle_params})
    bar = None
    if progress:  # a tqdm bar, or plain lines without the optional tqdm
        from tolsynth.progress import make_bar

        bar = make_bar(len(refs), "Tables 1-3", "column", 0.5)
    reports = []
    for ref in refs:
        col = {}
        for key, m in readings.items():
            printed = np.array(ref.tolerances, dtype=float)
            cost, gmax = _printed_eval(m, ref, printed)
            ip = synthesize(m, ref.R, ref.p, ref.distribution, ref.alpha, solver="ipopt", probability="gaussian")
            su = (
                synthesize(m, ref.R, ref.p, ref.distribution, ref.alpha, solver="sumt", probability="gaussian")
                if (sumt and key == "printed")
                else None
            )
            unit = m.units[m.index(angle_params[0])] if angle_params else "-"
            col[key] = Reading(unit, dict(zip(m.error_parameters, printed.tolist())), cost, gmax, ip, su)
        reports.append(ColumnReport(ref.table, ref.R, ref.p, ref.alpha, ref.distribution, col))
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return reports


def _cell(value, spec: str) -> str:
    """A number in its column, or a dash where it was not computed (SUMT skipped, no degree reading)."""
    return format(value, spec) if value is not None else "-".rjust(len(format(0.0, spec)))


def format_report(reports: list[ColumnReport], mech: Mechanism | None = None) -> str:
    """Readable text: one block per column, then a summary table."""
    lines = []
    for rep in reports:
        pr = rep.printed_unit
        deg = rep.readings.get("deg")
        lines.append("")
        lines.append(rep.label)
        head = f"  {'param':>7} {'unit':>9} {'printed':>9} {'IPOPT':>9} {'SUMT':>9} {'IP/pr':>6}"
        if deg is not None:
            head += f"   | deg reading: {'IPOPT':>9} {'IP/pr':>6}"
        lines.append(head)
        for name, value in pr.printed.items():
            row = (
                f"  {name:>7} {pr.ipopt.units[name]:>9} {value:>9.4g} {pr.ipopt.tolerances[name]:>9.4g} "
                f"{_cell(pr.sumt and pr.sumt.tolerances[name], '>9.4g')} {pr.ratio[name]:>6.2f}"
            )
            if deg is not None:
                row += f"   | {deg.ipopt.units[name]:>12} {deg.ipopt.tolerances[name]:>9.4g} {deg.ratio[name]:>6.2f}"
            lines.append(row)
        row = (
            f"  {'cost':>7} {'':>9} {pr.printed_cost:>9.4g} {pr.ipopt.cost:>9.4g} "
            f"{_cell(pr.sumt and pr.sumt.cost, '>9.4g')} {pr.ipopt.cost / pr.printed_cost:>6.2f}"
        )
        if deg is not None:
            row += f"   | {'':>12} {deg.ipopt.cost:>9.4g} {deg.ipopt.cost / deg.printed_cost:>6.2f}"
        lines.append(row)
        row = (
            f"  {'max sz/R':>7} {'':>9} {pr.printed_max_constraint:>9.4f} {pr.ipopt.max_constraint:>9.4f} "
            f"{_cell(pr.sumt and pr.sumt.max_constraint, '>9.4f')}"
        )
        if deg is not None:
            row += f"   | printed as deg: max sz/R {deg.printed_max_constraint:.4f}"
        lines.append(row)
    lines.append("")
    lines.append(
        "Summary (cost in the paper's units; 'max sz/R' of the printed tolerances in this model, <= 1 meets the spec)"
    )
    lines.append(
        f"  {'column':<52} {'printed':>8} {'IPOPT':>8} {'SUMT':>8} {'cost diff':>9} {'tol diff':>9} "
        f"{'pr sz/R':>8} {'deg sz/R':>8} {'IPOPT ms':>8} {'SUMT ms':>8}"
    )
    for rep in reports:
        pr, deg, ag = rep.printed_unit, rep.readings.get("deg"), rep.agreement()
        lines.append(
            f"  {rep.label:<52} {pr.printed_cost:>8.4g} {pr.ipopt.cost:>8.4g} "
            f"{_cell(pr.sumt and pr.sumt.cost, '>8.4g')} {_cell(ag.get('cost_rel_diff'), '>9.1e')} "
            f"{_cell(ag.get('max_tolerance_rel_diff'), '>9.1e')} {pr.printed_max_constraint:>8.3f} "
            f"{_cell(deg and deg.printed_max_constraint, '>8.3f')} {pr.ipopt.wall_time * 1e3:>8.1f} "
            f"{_cell(pr.sumt and pr.sumt.wall_time * 1e3, '>8.0f')}"
        )
    ok = all(
        r.printed_unit.ipopt.success and (r.printed_unit.sumt is None or r.printed_unit.sumt.success) for r in reports
    )
    lines.append(f"  all solves converged: {ok}")
    return "\n".join(lines)
