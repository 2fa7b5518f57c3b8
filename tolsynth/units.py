"""Units of length and angle, and their factors to the package's base units (mm and rad).

The package computes in millimetres and radians.  Tolerances are *stated* in each error
parameter's own tolerance unit (the paper: mm for lengths, 1e-2 rad for angles), and the cost
``k * eps**(-alpha)`` is evaluated on the number in that unit, as the paper does.
"""

from __future__ import annotations

import math

__all__ = ["LENGTH_UNITS", "ANGLE_UNITS", "unit_kind", "to_base", "BASE_UNIT"]

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
