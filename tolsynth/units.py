"""Units of length and angle, their factors to the package's base units (mm and rad), and the
one reader of a number written with a unit (``"500um"``, ``"2mrad"``, ``"0.1deg"``).

The package computes in millimetres and radians.  The rule, the same in the Python API, the
model builders and the command line (docs/units.md):

* a bare number is in the unit its argument states: mm for lengths (``R``, offsets), rad for
  angles (``Phi``, joint values; a joint that slides in mm), each error parameter's own tolerance
  unit for tolerances, locks and bounds (the paper: mm for lengths, 1e-2 rad for angles);
* a string with a unit suffix (``"500um"``, ``"0.5 mm"``, ``"2mrad"``, ``"0.1deg"``) is accepted
  wherever such a number is, and converted to the argument's unit;
* the model builders (:func:`tolsynth.Mechanism.from_dh`, :func:`tolsynth.load_urdf`) read the
  numbers of their tables in ``length_unit`` / ``angle_unit`` (default mm and rad, as a model
  file's ``[units]`` table states them).

The cost ``k * eps**(-alpha)`` is evaluated on the number in the tolerance unit, as the paper does.
"""

from __future__ import annotations

import math
import re

__all__ = [
    "LENGTH_UNITS",
    "ANGLE_UNITS",
    "unit_kind",
    "to_base",
    "BASE_UNIT",
    "SUFFIXES",
    "QUANTITY",
    "split_quantity",
    "convert_quantity",
    "suffixes",
    "joint_values",
    "units_label",
]

#: factor from the unit to mm
LENGTH_UNITS: dict[str, float] = {
    "mm": 1.0,
    "um": 1e-3,
    "cm": 10.0,
    "m": 1000.0,
}
#: factor from the unit to rad
ANGLE_UNITS: dict[str, float] = {
    "rad": 1.0,
    "1e-2 rad": 1e-2,
    "mrad": 1e-3,
    "urad": 1e-6,
    "deg": math.pi / 180.0,
    "arcmin": math.pi / (180.0 * 60.0),
    "arcsec": math.pi / (180.0 * 3600.0),
}
BASE_UNIT = {"length": "mm", "angle": "rad"}

#: unit suffixes accepted after a number (the model files' units, less the spaced "1e-2 rad")
SUFFIXES = {u: u for u in list(LENGTH_UNITS) + list(ANGLE_UNITS) if " " not in u}
SUFFIXES.update({"µm": "um", "μm": "um", "°": "deg"})
#: a number and an optional suffix (known or not: the caller says which is wrong)
QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(\S*)\s*$")


def unit_kind(unit: str) -> str | None:
    """Return ``"length"``, ``"angle"`` or ``None`` for an unknown unit."""
    if unit in LENGTH_UNITS:
        return "length"
    if unit in ANGLE_UNITS:
        return "angle"
    return None


def to_base(unit: str) -> float:
    """Factor that converts a value in ``unit`` to mm (lengths) or rad (angles)."""
    if unit in LENGTH_UNITS:
        return LENGTH_UNITS[unit]
    if unit in ANGLE_UNITS:
        return ANGLE_UNITS[unit]
    raise KeyError(unit)


def allowed_units() -> str:
    return ", ".join(list(LENGTH_UNITS) + list(ANGLE_UNITS))


def suffixes(kind: str) -> str:
    """The suffixes of one kind (``"length"`` or ``"angle"``), for messages."""
    table = LENGTH_UNITS if kind == "length" else ANGLE_UNITS
    return ", ".join(u for u in table if " " not in u)


def split_quantity(text: str) -> tuple[float, str | None] | None:
    """``"500um"`` -> ``(500.0, "um")``, ``"0.5"`` -> ``(0.5, None)``; None if ``text`` is not a
    finite number with an optional known suffix (the caller raises its own typed error)."""
    m = QUANTITY.match(str(text))
    if not m:
        return None
    value = float(m.group(1))
    suffix = m.group(2)
    if not math.isfinite(value) or (suffix and suffix not in SUFFIXES):
        return None
    return value, (SUFFIXES[suffix] if suffix else None)


def convert_quantity(text: str, unit: str) -> float | None:
    """A string such as ``"500um"`` in ``unit`` (a bare number is taken to be in ``unit``), or None
    if it is not a number, has an unknown suffix, or a suffix of the other kind."""
    parsed = split_quantity(text)
    if parsed is None:
        return None
    value, suffix = parsed
    if suffix is None:
        return value
    if unit_kind(suffix) != unit_kind(unit):
        return None
    return value * to_base(suffix) / to_base(unit)


def joint_values(q, units, key: str = "q") -> dict:
    """Joint values (a pose, or poses by name) for a JSON record or a table's inputs, the key
    naming their unit: ``{"q_rad": q}`` (every joint turns), ``{"q_mm": q}`` (every joint slides: a
    parallel robot's struts), or ``{"q": q, "joint_units": [...]}`` where the kinds mix."""
    units = tuple(units)
    if len(set(units)) <= 1:
        return {f"{key}_{units[0] if units else 'rad'}": q}
    return {key: q, "joint_units": list(units)}


def units_label(units) -> str:
    """One label for the units of a set of joints: ``"rad"``, ``"mm"`` or ``"mm/rad"`` where
    they mix (``"deg"`` and ``"mm"`` alike for the units shown)."""
    return "/".join(sorted(set(units))) or "rad"
