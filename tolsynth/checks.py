"""Shared validators of the numbers a caller gives (one copy of each rule).

Every public function checks its arguments with these before any work starts, so that bad input
raises a typed error (:mod:`tolsynth.errors`) naming the field and the allowed range, and extreme
input never reaches a formula that would overflow, divide by zero or loop forever.  The rules:

* a number is a real (``int``/``float``/NumPy scalar, not ``bool``), finite, and of magnitude at
  most :data:`HUGE` (1e9 of its unit: a kilometre in mm, far beyond any robot);
* a positive quantity (a radius, a tolerance bound, a cost factor, a step) is at least
  :data:`TINY` (1e-12 of its unit);
* a probability lies in ``[P_MIN, P_MAX]`` = [1e-12, 1 - 1e-12] (beyond, the normal quantile is
  not representable in double precision: ``z(1 - 1e-16)`` is infinite);
* a count is an integer (an integral float such as ``1e4`` is accepted) inside stated limits;
* a length or an angle may be a string with a unit suffix (``"500um"``, ``"2mrad"``), converted
  to the argument's unit (:mod:`tolsynth.units`: one rule for the API and the command line).

The model-file reader (:mod:`tolsynth.model.reader`) applies the same limits to the numbers in a file.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from tolsynth.errors import InputError, OutOfRangeError
from tolsynth.units import convert_quantity, suffixes, unit_kind

__all__ = [
    "HUGE",
    "TINY",
    "P_MIN",
    "P_MAX",
    "is_real",
    "check_real",
    "check_positive",
    "check_probability",
    "check_count",
    "check_seed",
    "check_vector",
    "check_progress",
    "check_time_limit",
    "check_writable_path",
    "DEFAULT_TIME_LIMIT",
]

#: largest magnitude of any number given, in its own unit (mm, rad, tolerance unit, ...)
HUGE = 1e9
#: smallest positive quantity, in its own unit
TINY = 1e-12
#: probabilities must lie in [P_MIN, P_MAX]
P_MIN = 1e-12
P_MAX = 1.0 - 1e-12


def is_real(x: Any) -> bool:
    """True for a real scalar (Python or NumPy int/float), False for bool, str, None, arrays..."""
    return not isinstance(x, (bool, np.bool_)) and isinstance(x, (int, float, np.integer, np.floating))


#: seconds a solve may take by default before it stops with Status.TIME_LIMIT: far beyond any
#: solve of the bundled models (milliseconds; an exact or workspace design, tens of seconds), so
#: it only ends a run that would otherwise not end
DEFAULT_TIME_LIMIT = 600.0


def _with_units(allowed: str, unit: str) -> str:
    kind = unit_kind(unit)
    return (
        f"{allowed}; or a string with a{'n' if kind == 'angle' else ''} {kind} unit ({suffixes(kind)})"
        if kind
        else allowed
    )


def _as_float(x: Any, field: str, allowed: str, unit: str = "") -> float:
    if isinstance(x, str) and unit_kind(unit):  # "500um": the same rule as the command line's
        v = convert_quantity(x, unit)
        if v is None:
            kind = unit_kind(unit)
            raise InputError(
                field,
                f"{x!r} is not a number with a{'n' if kind == 'angle' else ''} {kind} unit",
                _with_units(allowed, unit),
            )
        return v
    if not is_real(x):
        raise InputError(field, f"expected a number, got {x!r}", _with_units(allowed, unit))
    try:
        v = float(x)
    except OverflowError:  # a Python int beyond double range
        raise OutOfRangeError(field, f"got {x!r}", allowed) from None
    if not math.isfinite(v):
        raise OutOfRangeError(field, f"got {x!r}", allowed)
    return v


def check_real(
    x: Any, field: str, unit: str = "", lower: float = -HUGE, upper: float = HUGE, allowed: str | None = None
) -> float:
    """``x`` as a float, or a typed error unless it is a finite number in ``[lower, upper]``;
    ``allowed`` says what the argument takes in place of that range (where the caller knows more)."""
    if allowed is None:
        u = f" {unit}" if unit else ""
        allowed = f"a finite number >= {lower:g} and <= {upper:g}{u}"
    v = _as_float(x, field, allowed, unit)
    if not lower <= v <= upper:
        raise OutOfRangeError(field, f"got {x!r}", allowed)
    return v


def check_positive(x: Any, field: str, unit: str = "mm", upper: float = HUGE, lower: float = TINY) -> float:
    """``x`` as a float, or a typed error unless ``lower <= x <= upper`` (a positive quantity)."""
    if type(x) is float and x > 0 and lower <= x <= upper:  # the common case (NaN and inf fail here)
        return x
    allowed = f"a finite number > 0, from {lower:g} to {upper:g}" + (f" ({unit})" if unit else "")
    v = _as_float(x, field, allowed, unit)
    if not (v > 0 and lower <= v <= upper):
        raise OutOfRangeError(field, f"got {x!r}", allowed)
    return v


def check_half_angle(x: Any, field: str = "Phi") -> float:
    """A cone half-angle (rad), or a typed error unless ``0 < x <= pi``: a rotation turns the hand
    axis by at most pi, so a larger half-angle would allow every turn and change nothing."""
    return check_positive(x, field, "rad", upper=math.pi)


def check_probability(p: Any, field: str = "p") -> float:
    """``p`` as a float, or a typed error unless ``P_MIN <= p <= P_MAX`` (0 < p < 1 with the
    normal quantile representable)."""
    if type(p) is float and P_MIN <= p <= P_MAX:  # the common case (NaN fails here)
        return p
    allowed = f"0 < {field} < 1, from {P_MIN:g} to 1 - {1 - P_MAX:.0e}"
    v = _as_float(p, field, allowed)
    if not P_MIN <= v <= P_MAX:
        raise OutOfRangeError(field, f"got {p!r}", allowed)
    return v


def check_count(n: Any, field: str, lower: int = 1, upper: int = 10**12) -> int:
    """``n`` as an int, or a typed error unless it is an integer (or integral float) in
    ``[lower, upper]``."""
    allowed = f"an integer from {lower} to {upper}"
    if isinstance(n, (bool, np.bool_)) or not isinstance(n, (int, float, np.integer, np.floating)):
        raise InputError(field, f"expected an integer, got {n!r}", allowed)
    if isinstance(n, (float, np.floating)) and not (math.isfinite(n) and float(n).is_integer()):
        raise OutOfRangeError(field, f"got {n!r}", allowed)
    v = int(n)
    if not lower <= v <= upper:
        raise OutOfRangeError(field, f"got {n!r}", allowed)
    return v


def check_seed(seed: Any, field: str = "seed") -> int:
    """A seed for ``numpy.random.default_rng``: an integer >= 0 (not a float, not a bool)."""
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or int(seed) < 0:
        raise OutOfRangeError(field, f"got {seed!r}", "an integer >= 0 (recorded in the result)")
    return int(seed)


def check_vector(
    x: Any,
    field: str,
    size: int | None = None,
    unit: str = "",
    lower: float = -HUGE,
    upper: float = HUGE,
    names=None,
    units=None,
    allowed: str | None = None,
) -> np.ndarray:
    """A 1-D float array of finite numbers in ``[lower, upper]`` (of length ``size`` if given);
    an offending element is named ``field[names[i]]`` (or ``field[i]``).

    ``units`` (one per element; else ``unit`` for all) is each element's unit: an element of a
    list given as a string with a unit suffix (``["30deg", "90deg"]``) is converted to it, the
    units rule of :mod:`tolsynth.units`.  ``allowed`` says what the argument takes in place of
    the range (where the caller knows more)."""

    def _allowed() -> str:  # the message, built only for an error
        if allowed is not None:
            return allowed
        if units is not None and len(set(units)) > 1:
            u = " (" + ", ".join(units) + ")"
        else:
            u = f" {units[0] if units else unit}" if (units or unit) else ""
        return f"{size if size is not None else 'some'} finite numbers >= {lower:g} and <= {upper:g}{u}"

    if isinstance(x, (str, bytes)) or x is None:
        raise InputError(field, f"expected numbers, got {x!r}", _allowed())
    if isinstance(x, np.ndarray) and x.ndim == 1 and x.dtype.kind in "UO":
        x = x.tolist()
    if isinstance(x, (list, tuple)) and any(isinstance(v, str) for v in x):
        if units is not None and len(x) != len(units):
            raise InputError(field, f"expected {len(units)} values, got {len(x)}", _allowed())
        x = [
            _as_float(v, f"{field}[{names[i] if names is not None else i}]", _allowed(), units[i] if units else unit)
            if isinstance(v, str)
            else v
            for i, v in enumerate(x)
        ]
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise InputError(field, f"expected numbers, got {x!r}", _allowed()) from None
    if arr.ndim > 1 and arr.size == max(arr.shape):
        arr = arr.ravel()
    if arr.ndim != 1 or (size is not None and arr.shape != (size,)):
        raise InputError(
            field, f"expected {size if size is not None else 'a vector of'} values, got shape {arr.shape}", _allowed()
        )
    bad = ~(np.isfinite(arr) & (arr >= lower) & (arr <= upper))
    if bad.any():
        i = int(bad.nonzero()[0][0])
        raise OutOfRangeError(f"{field}[{names[i] if names is not None else i}]", f"got {float(arr[i])!r}", _allowed())
    return arr


def check_mapping(x: Any, field: str, allowed: str = "a dict", optional: bool = True) -> dict:
    """``x`` as a dict (``None`` -> ``{}`` when ``optional``), or InputError unless it is a mapping."""
    if x is None and optional:
        return {}
    if not isinstance(x, Mapping):
        raise InputError(field, f"expected a dict, got {type(x).__name__}: {x!r:.60}", allowed)
    return dict(x)


def check_options(options: Any, defaults: dict, field: str = "options") -> dict:
    """Solver options: a dict whose keys are those of ``defaults``; each value of the type of its
    default (a float default: a positive number; an int: a count >= 0; None: None or a positive
    number; a string: a string)."""
    options = check_mapping(options, field, "a dict with keys " + ", ".join(defaults))
    for key, value in options.items():
        if key not in defaults:
            import difflib

            near = difflib.get_close_matches(str(key), list(defaults), n=1)
            hint = f" (did you mean {near[0]!r}?)" if near else ""
            raise InputError(field, f"unknown option {key!r}{hint}", ", ".join(defaults))
        default = defaults[key]
        where = f"{field}[{key!r}]"
        if isinstance(default, bool):
            if not isinstance(value, (bool, np.bool_)):
                raise InputError(where, f"got {value!r}", "True or False")
        elif isinstance(default, int):
            check_count(value, where, lower=0, upper=10**9)
        elif isinstance(default, float) or (default is None and value is not None):
            check_positive(value, where, "", lower=1e-300)  # solver tolerances may be tiny
        elif isinstance(default, str) and not isinstance(value, str):
            raise InputError(where, f"got {value!r}", "a string")
    return options


def check_progress(progress: Any, field: str = "progress"):
    """A ``progress`` argument: None (a bar on a terminal, for runs over a couple of seconds), True,
    False, or a callable ``progress(done, total)``."""
    if progress is None or isinstance(progress, (bool, np.bool_)) or callable(progress):
        return progress
    raise InputError(field, f"got {progress!r}", "None (automatic), True, False, or a callable progress(done, total)")


def check_time_limit(limit: Any, field: str = "time_limit") -> float:
    """Seconds a run may take (a positive number; ``None``: :data:`DEFAULT_TIME_LIMIT`)."""
    if limit is None:
        return DEFAULT_TIME_LIMIT
    return check_positive(limit, field, "s", upper=1e7, lower=1e-3)


def check_writable_path(path: Any, field: str = "path") -> str:
    """A file path that can be written, checked before any work: not empty, a name the file
    system accepts, in an existing folder, not a folder itself, and openable for writing (tried:
    a file that did not exist is removed again; a place such as /proc fails here, not after the
    work).  A full device (``/dev/full``) still fails only when written."""
    import errno
    import os

    if not isinstance(path, (str, os.PathLike)):
        raise InputError(field, f"got {type(path).__name__}", "a file path (str or os.PathLike)")
    path = os.fspath(path)
    if not isinstance(path, str) or not path.strip():
        raise InputError(field, f"empty path {path!r}", "a file path")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise InputError(field, f"{path!r}: the folder {folder} does not exist", "a path in an existing folder")
    if os.path.isdir(path):
        raise InputError(field, f"{path!r} is a folder", "a file path")
    existed = os.path.exists(path)
    try:
        with open(path, "ab"):
            pass
    except OSError as exc:
        why = "the name is too long" if exc.errno == errno.ENAMETOOLONG else (exc.strerror or type(exc).__name__)
        raise InputError(
            field, f"{path!r} cannot be written: {why}", "a writable file path in an existing folder"
        ) from None
    if not existed:
        try:
            os.remove(path)
        except OSError:  # pragma: no cover - created but not removable: left empty
            pass
    return path
