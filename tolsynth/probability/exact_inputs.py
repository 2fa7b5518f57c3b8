"""The checks of what a caller gives the exact evaluator (typed errors naming the field), and its
error class; shared by :mod:`tolsynth.probability.exact` and :mod:`.exact_sphere`."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from tolsynth.checks import check_positive
from tolsynth.errors import InputError, OutOfRangeError, TolsynthError
from tolsynth.probability.distributions import Shape, shape

__all__ = ["ExactProbabilityError", "DEFAULT_TOL"]

DEFAULT_TOL = 1e-9


class ExactProbabilityError(TolsynthError, ArithmeticError):
    """An exact probability could not be brought within its stated tolerance."""


def check_shapes(shapes: Sequence, n: int) -> tuple[Shape, ...]:
    """One :class:`Shape` per coefficient (typed errors naming ``shapes`` or the bad name)."""
    if isinstance(shapes, (str, Shape)) or not hasattr(shapes, "__iter__"):
        raise InputError("shapes", f"{shapes!r}", "a sequence of shape names, one per coefficient")
    out = tuple(shape(s) for s in shapes)
    if len(out) != n:
        raise OutOfRangeError("shapes", f"{len(out)} shapes for {n} coefficients", "one shape per error parameter")
    return out


def check_tol(tol, field: str = "tol") -> float:
    tol = check_positive(tol, field)
    if not tol < 1.0:
        raise OutOfRangeError(field, f"{tol!r}", "a number in (0, 1)")
    return tol


def check_count(value, field: str, least: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
        raise OutOfRangeError(field, f"{value!r}", f"an integer >= {least}")
    return int(value)


def _floats(x, field: str, what: str) -> np.ndarray:
    try:
        return np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise InputError(field, f"not numbers: {str(x)[:60]}", what) from None


def check_rows(b, field: str = "b") -> tuple[np.ndarray, bool]:
    """Coefficient rows as ``|b|`` (M, n), and whether one row (n,) was given."""
    arr = _floats(b, field, "an array of coefficients (mm)")
    if arr.ndim not in (1, 2) or arr.shape[-1] == 0:
        raise OutOfRangeError(field, f"shape {arr.shape}", "one row (n,) or rows (m, n) of coefficients, n >= 1")
    if not np.all(np.isfinite(arr)):
        raise OutOfRangeError(field, "a non-finite coefficient", "finite numbers")
    return np.atleast_2d(np.abs(arr)), arr.ndim == 1


def check_matrix(M, eps, shapes, rows: int, field: str):
    """``M`` (``rows`` x n) and ``eps`` (n,) as float arrays and the n shapes; typed errors naming
    ``field`` or ``eps``."""
    M = _floats(M, field, f"a {rows} x n matrix")
    if M.ndim != 2 or M.shape[0] != rows or M.shape[1] == 0:
        raise OutOfRangeError(field, f"shape {M.shape}", f"{rows} x n rows, n >= 1")
    if not np.all(np.isfinite(M)):
        raise OutOfRangeError(field, "a non-finite entry", "finite numbers")
    eps = _floats(eps, "eps", "tolerances")
    if eps.shape != (M.shape[1],) or not np.all(np.isfinite(eps)) or np.any(eps < 0):
        raise OutOfRangeError(
            "eps", f"shape {eps.shape} or a negative or non-finite value", f"{M.shape[1]} tolerances >= 0"
        )
    return M, eps, check_shapes(shapes, M.shape[1])
