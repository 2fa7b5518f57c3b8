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
        lo = check_positive(self.lower, f"process {self.name!r}.lower")
        hi = check_positive(self.upper, f"process {self.name!r}.upper")
        if hi < lo:
            raise InputError(f"process {self.name!r}", f"lower {lo} > upper {hi}", "lower <= upper")
        object.__setattr__(self, "lower", lo)
        object.__setattr__(self, "upper", hi)
        self.cost.check_range(lo, hi, f"process {self.name!r}")

    @classmethod
    def make(cls, spec) -> "Process":
        """A :class:`Process` from itself or a dict ``{name, cost, lower, upper}`` (typed errors otherwise)."""
        if isinstance(spec, Process):
            return spec
        if isinstance(spec, Mapping):
            extra = set(spec) - {"name", "cost", "lower", "upper"}
            if extra:
                raise InputError("process", f"unknown keys {sorted(extra)}", "name, cost, lower, upper")
            try:
                return cls(str(spec["name"]), spec["cost"], spec["lower"], spec["upper"])
            except KeyError as e:
                raise InputError("process", f"missing {e.args[0]!r}", "name, cost, lower, upper") from None
        raise InputError("process", f"got {spec!r}", "a Process or a dict {name, cost, lower, upper}")
