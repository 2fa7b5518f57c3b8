"""A manufacturing process for one parameter: a cost model and the tolerance range it can hold.

Model files name processes per parameter; :func:`tolsynth.synthesize_processes` picks the
cheapest one per parameter.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

from tolsynth.checks import check_positive
from tolsynth.errors import InputError
from tolsynth.model.cost import CostModel, cost_model

__all__ = ["Process"]


@dataclass(frozen=True)
class Process:
    """A manufacturing process for one parameter: its cost model and the tolerances it can hold
    (``lower <= eps <= upper``, the parameter's tolerance unit)."""

    name: str
    cost: CostModel
    lower: float
    upper: float

    def __post_init__(self):
        object.__setattr__(self, "cost", cost_model(self.cost))
        for key in ("lower", "upper"):  # a process alone prices no parameter: no unit to read "50um" in
            if isinstance(getattr(self, key), str):
                raise InputError(
                    f"process {self.name!r}.{key}",
                    f"{getattr(self, key)!r}: a Process alone has no parameter's tolerance unit to convert to",
                    "a number in the parameter's tolerance unit, or the process as a dict in processes={name: [...]}",
                )
        lo = check_positive(self.lower, f"process {self.name!r}.lower", "")
        hi = check_positive(self.upper, f"process {self.name!r}.upper", "")
        if hi < lo:
            raise InputError(f"process {self.name!r}", f"lower {lo} > upper {hi}", "lower <= upper")
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)
        self.cost.check_range(lo, hi, f"process {self.name!r}")

    @classmethod
    def make(cls, spec, unit: str | None = None) -> "Process":
        """A :class:`Process` from itself or a dict ``{name, cost, lower, upper}`` (typed errors
        otherwise); ``unit``: the parameter's tolerance unit, into which a dict's ``lower``,
        ``upper`` and tabulated cost tolerances written with a unit suffix (``"50um"``) are read."""
        if isinstance(spec, Process):
            return spec
        if isinstance(spec, Mapping):
            extra = set(spec) - {"name", "cost", "lower", "upper"}
            if extra:
                raise InputError("process", f"unknown keys {sorted(extra)}", "name, cost, lower, upper")
            try:
                name, cost, lo, hi = str(spec["name"]), spec["cost"], spec["lower"], spec["upper"]
            except KeyError as e:
                raise InputError("process", f"missing {e.args[0]!r}", "name, cost, lower, upper") from None
            if unit is not None:
                lo, hi = (
                    check_positive(v, f"process {name!r}.{key}", unit) if isinstance(v, str) else v
                    for key, v in (("lower", lo), ("upper", hi))
                )
            return cls(name, cost_model(cost, unit), lo, hi)
        raise InputError("process", f"got {spec!r}", "a Process or a dict {name, cost, lower, upper}")
