"""The arguments of :func:`tolsynth.synthesize`, grouped: what the design must meet
(:class:`DesignSpec`) and how to solve it (:class:`SolverOptions`).

Both are frozen dataclasses whose fields carry the keyword names of ``synthesize``, so a study can
keep one specification and vary one field with :func:`dataclasses.replace`:

>>> import tolsynth
>>> spec = tolsynth.DesignSpec(R=0.5, p=0.99, distribution="uniform")
>>> res = tolsynth.synthesize("xu_zhang_1988", spec=spec, solver=tolsynth.SolverOptions("sumt"))  # doctest: +SKIP

The keywords keep working; a field given both in a group and as a keyword with a different value
is an :class:`~tolsynth.InputError` naming it, never a silent choice.
"""

from __future__ import annotations

import functools
import inspect
from dataclasses import dataclass, fields
from typing import Any

from tolsynth.errors import InputError
from tolsynth.problem.specification import ALPHA_DEFAULT

__all__ = ["DesignSpec", "SolverOptions", "merge_groups", "accepts_groups"]


@dataclass(frozen=True)
class DesignSpec:
    """What the design must meet and what it may cost; fields as in :func:`tolsynth.synthesize`."""

    R: float | None = None
    p: float | None = None
    distribution: Any = None
    alpha: Any = ALPHA_DEFAULT
    k: Any = None
    bounds: Any = None
    pose: Any = None  # None: the model's 'worst' pose, unless poses are given
    poses: Any = None
    Phi: float | None = None
    p_orientation: float | None = None
    criterion: str = "components"
    cost: Any = None
    locks: Any = None
    probability: str | None = None


@dataclass(frozen=True)
class SolverOptions:
    """How to solve: the solver, its options, a start, and the checks run at the optimum."""

    solver: str = "auto"
    options: dict | None = None
    x0: Any = None
    validate: int | None = None
    seed: int = 0
    verify: Any = None
    #: seconds the solve may take (None: tolsynth.checks.DEFAULT_TIME_LIMIT), then Status.TIME_LIMIT
    time_limit: float | None = None


def _same(a, b) -> bool:
    try:
        return bool(a == b) if not (hasattr(a, "__len__") or hasattr(b, "__len__")) else a is b or repr(a) == repr(b)
    except Exception:  # arrays and other values without a plain truth value
        return a is b


#: the fields that take a number with a unit ("500um"), and that unit: compared converted
QUANTITIES = {"R": "mm", "Phi": "rad"}


def _same_quantity(a, b, unit: str) -> bool:
    """True if ``a`` and ``b`` are the same number in ``unit`` once converted (``"500um"`` and
    0.5 mm; to 1e-12 relative, the rounding of the conversion); False for anything that does not
    convert (the keyword's own checks then name it)."""
    import math

    from tolsynth.checks import is_real
    from tolsynth.units import convert_quantity

    def value(x):
        if isinstance(x, str):
            return convert_quantity(x, unit)
        return float(x) if is_real(x) else None

    va, vb = value(a), value(b)
    return va is not None and vb is not None and math.isclose(va, vb, rel_tol=1e-12, abs_tol=0.0)


def merge_groups(given: dict, spec, solver_options) -> dict:
    """``given`` (the keywords the caller passed, and only those) with the groups' fields filled in.

    A keyword not passed takes the group's value; a field left at its default in the group counts
    as not given there (the keyword's value stands); a field set both ways to different values is
    an error naming it, also where the keyword's value happens to be its default; ``R`` and
    ``Phi`` are compared in mm and rad (``R="500um"`` and ``R=0.5`` are the same value).
    """
    out = dict(given)
    for group, cls, argname in ((spec, DesignSpec, "spec"), (solver_options, SolverOptions, "solver")):
        if group is None:
            continue
        if not isinstance(group, cls):
            raise InputError(argname, f"got {type(group).__name__}", f"a tolsynth.{cls.__name__}")
        for f in fields(cls):
            value = getattr(group, f.name)
            if f.name not in out:
                out[f.name] = value
                continue
            if _same(value, f.default):  # unset in the group: the keyword stands
                continue
            if _same(out[f.name], value) or (
                f.name in QUANTITIES and _same_quantity(out[f.name], value, QUANTITIES[f.name])
            ):
                out[f.name] = value
            else:
                raise InputError(
                    f.name, f"given as a keyword ({out[f.name]!r}) and in {argname} ({value!r})", "one of the two"
                )
    return out


def accepts_groups(fn):
    """``fn`` (:func:`tolsynth.synthesize`) taking ``spec=`` and ``solver=SolverOptions(...)``: the
    call is bound to ``fn``'s signature, so that the keywords the caller passed are known as passed
    (a keyword given at its default value still conflicts with a group's other value), merged
    with the groups by :func:`merge_groups`, and ``fn`` runs on the result."""
    signature = inspect.signature(fn)
    first = next(iter(signature.parameters))

    @functools.wraps(fn)
    def with_groups(*args, **kwargs):
        grouped = kwargs.get("spec") is not None or any(
            isinstance(a, SolverOptions) for a in (*args, kwargs.get("solver"))
        )
        if not grouped:
            return fn(*args, **kwargs)
        try:
            passed = dict(signature.bind(*args, **kwargs).arguments)  # only what the caller passed
        except TypeError:  # a call Python itself refuses: its own message, from fn
            return fn(*args, **kwargs)
        spec = passed.pop("spec", None)
        options = passed.pop("solver") if isinstance(passed.get("solver"), SolverOptions) else None
        head = passed.pop(first)
        return fn(head, **merge_groups(passed, spec, options))

    return with_groups
