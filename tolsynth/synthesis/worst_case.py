"""The worst-case (arithmetic) design beside the statistical one: :func:`synthesize_worst_case`,
which ``synthesize(..., probability="worst_case")`` calls.

Every error may sit anywhere in its band at once, and the hand must still land within R (and the
orientation within Phi) at every pose; no probability or distribution enters (the solver and its
certificate: :mod:`tolsynth.solvers.worst_case`).  The per-component and the sphere readings are
the same here: ``|w . dr| <= R`` for every unit w is ``|dr| <= R``.  With ``p`` given, the
statistical design at the same R and p is solved too and the result's summary states how much
more the worst case costs.

>>> import tolsynth
>>> res = tolsynth.synthesize("xu_zhang_1988", R=0.8, probability="worst_case")
>>> res.success  # doctest: +SKIP
True
"""

from __future__ import annotations

import math
from dataclasses import replace

from tolsynth.checks import TINY, check_vector
from tolsynth.errors import InputError, TolsynthError
from tolsynth.problem.specification import ALPHA_DEFAULT, make_specification
from tolsynth.solvers.worst_case import (
    DEFAULT_OPTIONS,
    WorstCaseResult,
    solve_worst_case,
)

__all__ = ["refuse_unread", "synthesize_worst_case"]

#: the placeholder probability the specification builder needs (the worst case reads no p)
_NO_P = 0.5


def refuse_unread(p, distribution, criterion, Phi, p_orientation) -> None:
    """The worst case's refusals of what it would ignore, as the command line's: the shape and the
    orientation probability are read only by the statistical design compared with (so only with
    p), and the worst case bounds every direction at once, so it has no sphere criterion."""
    if criterion != "components":
        raise InputError(
            "criterion",
            f"{criterion!r} with probability='worst_case'",
            "'components' (the worst case bounds |dr| itself: every direction at once)",
        )
    if p_orientation is not None and Phi is None:
        raise InputError("p_orientation", "given without Phi", "give Phi (rad) with it")
    for name, value in (("distribution", distribution), ("p_orientation", p_orientation)):
        if value is not None and p is None:
            raise InputError(
                name,
                f"{value!r} with probability='worst_case' and no p: only the statistical design compared "
                "with (given p) reads it",
                f"no {name}, or p with it",
            )


def synthesize_worst_case(
    mechanism,
    R,
    *,
    p=None,
    alpha=ALPHA_DEFAULT,
    solver="ipopt",
    k=None,
    bounds=None,
    pose="worst",
    poses=None,
    Phi=None,
    cost=None,
    x0=None,
    options=None,
    inputs=None,
    statistical=None,
) -> WorstCaseResult:
    """Cheapest tolerances whose worst case (every error at any point of its band) meets R (and Phi).

    ``mechanism`` is a loaded :class:`~tolsynth.kinematics.mechanism.Mechanism`; ``bounds`` and
    ``cost`` already hold the model's locks and cost models (as :func:`tolsynth.synthesize`
    resolves them).  ``statistical``, when given, is called with no argument and returns the
    statistical design at the same R and p; its cost goes into the result's ``statistical``.
    """
    if solver != "ipopt":
        raise InputError(
            "solver",
            f"{solver!r} with probability='worst_case'",
            "'ipopt' (the worst case is solved by its own exchange over sign patterns with IPOPT)",
        )
    if options is not None:
        from tolsynth.checks import check_options

        options = check_options(options, DEFAULT_OPTIONS)
    spec = make_specification(
        mechanism, R, _NO_P, "uniform", alpha, k, bounds, pose, poses, Phi, None, "components", cost
    )
    # no probability: z and the blocks' z / R scales are NaN, so that no Gaussian reading of this
    # specification (a multiplier, a bound) can pass for a number
    spec = replace(
        spec,
        p=None,
        z=math.nan,
        distribution="any (worst case)",
        p_orientation=None,
        blocks=tuple(replace(b, scale=math.nan) for b in spec.blocks),
    )
    eps0 = None if x0 is None else check_vector(mechanism.tolerances(x0, "x0"), "x0", lower=TINY)
    result = solve_worst_case(spec, eps0, options)
    stat = None
    if statistical is not None and p is not None:
        try:
            other = statistical()
            stat = {
                "probability": (other.inputs or {}).get("probability"),
                "p": float(p),
                "cost": float(other.cost),
                "success": bool(other.success),
                "tolerances": dict(other.tolerances),
            }
        except TolsynthError as exc:  # the statistical design is a comparison, not the answer
            stat = {
                "probability": None,
                "p": float(p),
                "cost": None,
                "success": False,
                "message": f"no statistical design: {exc}",
            }
    rec = dict(inputs or {})
    rec.update(probability="worst_case", p_compared=None if p is None else float(p))
    object.__setattr__(result, "inputs", rec)
    object.__setattr__(result, "statistical", stat)
    if result.feasible:
        from tolsynth.analysis.validation import WorkspaceCheck

        # the statistical results' sampled check, in the worst case's quantity; computed when read
        object.__setattr__(result, "workspace", WorkspaceCheck(mechanism, result))
    return result
