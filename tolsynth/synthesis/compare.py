"""IPOPT and SUMT + Powell on the same specification, side by side: the paper's cross-check."""

from __future__ import annotations

from dataclasses import dataclass

from tolsynth.checks import check_mapping, check_options
from tolsynth.errors import InputError
from tolsynth.problem.result import SynthesisResult
from tolsynth.problem.specification import ALPHA_DEFAULT
from tolsynth.synthesis.single import synthesize
from tolsynth.tabular import Tabular

__all__ = ["Comparison", "compare"]


@dataclass(frozen=True)
class Comparison(Tabular):
    """IPOPT and SUMT on the same specification, side by side."""

    ipopt: SynthesisResult
    sumt: SynthesisResult

    @property
    def cost_rel_diff(self) -> float:
        """``|cost_SUMT - cost_IPOPT| / |cost_IPOPT|``."""
        return abs(self.sumt.cost - self.ipopt.cost) / abs(self.ipopt.cost)

    @property
    def tolerance_rel_diff(self) -> dict[str, float]:
        """Name -> ``|eps_SUMT - eps_IPOPT| / |eps_IPOPT|``."""
        return {k: abs(self.sumt.tolerances[k] - v) / abs(v) for k, v in self.ipopt.tolerances.items()}

    @property
    def time_ratio(self) -> float:
        """SUMT wall time / IPOPT wall time."""
        return self.sumt.wall_time / self.ipopt.wall_time

    def table(self) -> str:
        """Short readable table: status, cost and tolerances of both solvers with relative differences."""
        i, s = self.ipopt, self.sumt
        rows = [
            f"{'':>10} {'IPOPT':>14} {'SUMT+Powell':>14} {'rel.diff':>10}",
            f"{'status':>10} {str(i.status):>14} {str(s.status):>14}",
            f"{'cost':>10} {i.cost:>14.8g} {s.cost:>14.8g} {self.cost_rel_diff:>10.2e}",
        ]
        for name, d in self.tolerance_rel_diff.items():
            rows.append(f"{name:>10} {i.tolerances[name]:>14.6g} {s.tolerances[name]:>14.6g} {d:>10.2e}")
        rows += [
            f"{'iter':>10} {i.iterations:>14d} {s.iterations:>14d}",
            f"{'evals':>10} {i.function_evaluations:>14d} {s.function_evaluations:>14d}",
            f"{'time ms':>10} {i.wall_time * 1e3:>14.2f} {s.wall_time * 1e3:>14.2f} {self.time_ratio:>9.1f}x",
        ]
        return "\n".join(rows)

    def to_dict(self) -> dict:
        """Plain dict for JSON: both results and their relative differences."""
        return {
            "ipopt": self.ipopt.to_dict(),
            "sumt": self.sumt.to_dict(),
            "cost_rel_diff": self.cost_rel_diff,
            "tolerance_rel_diff": self.tolerance_rel_diff,
            "time_ratio": self.time_ratio,
        }


def compare(mechanism, R: float, p: float, distribution=None, alpha=ALPHA_DEFAULT, **kwargs) -> Comparison:
    """Solve the same specification with IPOPT and with SUMT + Powell; see :class:`Comparison`.

    Keyword arguments are those of :func:`synthesize` (``options`` may be a dict with keys
    ``"ipopt"`` and ``"sumt"``).  Both solvers start from scratch: IPOPT without the cuts and
    optimum an earlier solve of the same blocks left (``options={"ipopt": {"warm_start": True}}``
    allows them), so its iterations, evaluations and time compare the algorithms.  The comparison
    reads the paper's Gaussian criterion unless ``probability`` says otherwise: it is the paper's
    cross-check of the two solvers, not a design.
    """
    kwargs.setdefault("probability", "gaussian")
    if kwargs["probability"] != "gaussian":  # both columns would be one and the same exact solve
        raise InputError(
            "probability",
            f"got {kwargs['probability']!r}: under the exact reading IPOPT and SUMT + Powell only find the "
            "Gaussian optimum the exact interior-point method starts from, so both columns would be the same run",
            "'gaussian' (the default of compare, the paper's reading)",
        )
    options = check_mapping(kwargs.pop("options", None), "options", "a dict with keys 'ipopt' and 'sumt'")
    check_options(options, {"ipopt": {}, "sumt": {}})
    kwargs.pop("solver", None)
    ipopt = check_mapping(options.get("ipopt"), "options['ipopt']", "a dict of IPOPT options")
    given = {"ipopt": {"warm_start": False, **ipopt}, "sumt": options.get("sumt")}
    res = {
        s: synthesize(mechanism, R, p, distribution, alpha, solver=s, options=given[s], **kwargs)
        for s in ("ipopt", "sumt")
    }
    return Comparison(res["ipopt"], res["sumt"])
