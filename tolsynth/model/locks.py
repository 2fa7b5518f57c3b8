"""Locked tolerances: some parameters fixed at given values, e.g. by a supplier.

A lock is the bound ``lower = upper = value``; the others are optimised around it (IPOPT treats a
fixed variable as a parameter; the dual bound's box is a point there).  Before solving,
:func:`check_locks` asks whether the locked tolerances *alone* (every other tolerance at zero,
which no choice of the others can beat: the covariance grows with every tolerance) already break
the specification, and if so raises :class:`~tolsynth.errors.InfeasibleSpecificationError` naming
them.  Under the exact reading the Gaussian values only pick the blocks to examine; the refusal
needs the exact probability's proof (an exact P also only falls as any tolerance grows).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from tolsynth.errors import InfeasibleSpecificationError, InputError, OutOfRangeError

__all__ = ["apply_locks", "check_locks"]

#: stands for a tolerance of zero (u = ln eps must stay finite): eps^2 = 1e-200 adds nothing
_ZERO = 1e-100


def _locked(mechanism, locks) -> dict[str, float]:
    from tolsynth.checks import check_positive

    if not isinstance(locks, Mapping):
        raise InputError("locks", f"got {locks!r}", "a dict parameter name -> tolerance")
    out = {}
    for name, value in locks.items():
        i = mechanism.index(name, f"locks[{name}]")  # UnknownNameError naming the field
        unit = mechanism.units[i]
        out[mechanism.error_parameters[i]] = check_positive(value, f"locks[{name}]", unit)
    return out


def apply_locks(mechanism, bounds, locks) -> dict:
    """The bounds of :func:`tolsynth.synthesize` with every locked parameter at ``(v, v)``, as a
    dict name -> (lower, upper) for every parameter."""
    locked = _locked(mechanism, locks)
    names = mechanism.error_parameters
    lo, hi = (np.array(b, dtype=float) for b in mechanism.bounds)
    if isinstance(bounds, Mapping):
        out = {nm: (float(a), float(b)) for nm, a, b in zip(names, lo, hi)}
        for key, pair in bounds.items():
            out[names[mechanism.index(key, f"bounds[{key}]")]] = pair
    elif bounds is None:
        out = {nm: (float(a), float(b)) for nm, a, b in zip(names, lo, hi)}
    else:
        try:
            lo, hi = (np.asarray(b, dtype=float) * np.ones(len(names)) for b in bounds)
        except (TypeError, ValueError):
            raise InputError("bounds", f"got {bounds!r}", "(lower, upper) or a dict name -> (lower, upper)") from None
        out = {nm: (float(a), float(b)) for nm, a, b in zip(names, lo, hi)}
    for nm, v in locked.items():
        a, b = out[nm]
        # a lock is a tolerance some process holds: outside the parameter's range it is a typo
        # or a unit slip (a lock below the lower bound once cost 3243 silently)
        if not float(a) * (1 - 1e-12) <= v <= float(b) * (1 + 1e-12):
            unit = mechanism.units[mechanism.index(nm)]
            raise OutOfRangeError(
                f"locks[{nm}]",
                f"{v:g} {unit} is outside the parameter's bounds",
                f"{float(a):g} to {float(b):g} {unit} (its bounds; widen them with bounds= to lock outside)",
            )
        out[nm] = (v, v)
    return out


def check_locks(nlp, joint_errors=(), refute=None) -> None:
    """Raise :class:`InfeasibleSpecificationError` naming the locked parameters (those with
    ``lower == upper``) if they alone (every other tolerance at zero) violate a constraint of the
    problem ``nlp``.  ``joint_errors`` names the parameters that are joint errors
    (:mod:`tolsynth.model.joint_errors`): the message calls those the fixed joint errors.

    ``refute`` (the exact reading's, :func:`tolsynth.solvers.exact_refute.exact_refuter`): a block
    the Gaussian values break is refused only if ``refute(block index, eps)`` proves it, with the
    exact value in the message; the Gaussian value alone is no proof for bounded errors."""
    spec = nlp.spec
    locked = [nm for nm, a, b in zip(spec.names, spec.lower, spec.upper) if a == b]
    eps = np.where(np.isin(np.array(spec.names), locked), spec.lower, _ZERO)
    labels = [b.label for b in spec.blocks] + [b.label for b in spec.sphere_blocks]
    joint = [nm for nm in locked if nm in tuple(joint_errors)]
    what = f"the locked tolerances {locked}"
    if joint and len(joint) == len(locked):
        what = f"the fixed joint errors {joint}"
    elif joint:
        what += f" (fixed joint errors: {joint})"
    for i, (label, vals) in enumerate(zip(labels, nlp.all_values(eps))):
        if vals[0] <= 1.0:
            continue
        if refute is None:
            value, text = float(vals[0]), f"constraint value {vals[0]:.6g} > 1"
        else:
            proof = refute(i, eps)
            if proof is None:  # the Gaussian reading's failure, not the exact one's
                continue
            value, text = proof
        raise InfeasibleSpecificationError(
            label,
            float(value),
            f"infeasible specification: {what} alone break the {label} "
            f"({text} with every other tolerance at zero).  Loosen R/Phi "
            f"or p, or tighten the locked tolerances (or the fixed joint errors).",
        )
