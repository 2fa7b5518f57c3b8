"""ISO 286-1 standard tolerance grades: the width ``IT`` of each grade for a nominal size.

Source: ISO 286-1:2010, *Geometrical product specifications (GPS) -- ISO code system for
tolerances on linear sizes -- Part 1: Basis of tolerances, deviations and fits*, Table 1 (IT1 to
IT18, nominal sizes up to 3150 mm) and Table A.1 (IT01 and IT0, up to 500 mm); the same values as
ISO 286-1:1988 Tables 1 and 5.  The table below is the standard's: it is authoritative, and its
values are *rounded* from the standard tolerance factor

    i = 0.45 D^(1/3) + 0.001 D          (µm, D in mm, nominal sizes up to 500 mm)
    I = 0.004 D + 2.1                   (µm, over 500 mm)

with ``D`` the geometric mean of the size range's limits (the first range, up to 3 mm, takes
``D = sqrt(1 * 3)``), ``IT5 .. IT18 = 7, 10, 16, 25, 40, 64, 100, 160, 250, 400, 640, 1000,
1600, 2500`` times the factor (IT1 .. IT4 over 500 mm: 2, 2.7, 3.7, 5 times I; up to 500 mm IT1
is ``0.8 + 0.020 D`` and IT2 .. IT4 lie in geometric progression between IT1 and IT5).
:func:`factor` gives the formula for checks; :func:`it_width` reads the table.

A tolerance grade gives a zone of width IT; as a symmetric tolerance (the ``eps`` of a
parameter, ``+-eps``) that is ``eps = IT / 2`` (:func:`half_width`).  IT14 to IT18 are not
defined for nominal sizes up to 1 mm.
"""

from __future__ import annotations

import math

from tolsynth.errors import OutOfRangeError, UnknownNameError

__all__ = [
    "FACTOR_MULTIPLE",
    "GRADES",
    "IT_TABLE",
    "SIZE_STEPS",
    "factor",
    "grades_for",
    "half_width",
    "it_width",
    "size_range",
]

#: the grades, finest first
GRADES = ("IT01", "IT0") + tuple(f"IT{g}" for g in range(1, 19))

#: upper limits of the nominal size ranges, mm ("over the previous, up to and including this")
SIZE_STEPS = (3, 6, 10, 18, 30, 50, 80, 120, 180, 250, 315, 400, 500, 630, 800, 1000, 1250, 1600, 2000, 2500, 3150)

_UM = 1.0  # IT1 .. IT11 are printed in µm
_MM = 1000.0  # IT12 .. IT18 in mm

#: grade -> width per size range, µm (ISO 286-1:2010 Table 1; IT01 and IT0 from Table A.1, up to 500 mm)
IT_TABLE: dict[str, tuple[float, ...]] = {
    "IT01": (0.3, 0.4, 0.4, 0.5, 0.6, 0.6, 0.8, 1, 1.2, 2, 2.5, 3, 4),
    "IT0": (0.5, 0.6, 0.6, 0.8, 1, 1, 1.2, 1.5, 2, 3, 4, 5, 6),
    "IT1": (0.8, 1, 1, 1.2, 1.5, 1.5, 2, 2.5, 3.5, 4.5, 6, 7, 8, 9, 10, 11, 13, 15, 18, 22, 26),
    "IT2": (1.2, 1.5, 1.5, 2, 2.5, 2.5, 3, 4, 5, 7, 8, 9, 10, 11, 13, 15, 18, 21, 25, 30, 36),
    "IT3": (2, 2.5, 2.5, 3, 4, 4, 5, 6, 8, 10, 12, 13, 15, 16, 18, 21, 24, 29, 35, 41, 50),
    "IT4": (3, 4, 4, 5, 6, 7, 8, 10, 12, 14, 16, 18, 20, 22, 25, 28, 33, 39, 46, 55, 68),
    "IT5": (4, 5, 6, 8, 9, 11, 13, 15, 18, 20, 23, 25, 27, 32, 36, 40, 47, 55, 65, 78, 96),
    "IT6": (6, 8, 9, 11, 13, 16, 19, 22, 25, 29, 32, 36, 40, 44, 50, 56, 66, 78, 92, 110, 135),
    "IT7": (10, 12, 15, 18, 21, 25, 30, 35, 40, 46, 52, 57, 63, 70, 80, 90, 105, 125, 150, 175, 210),
    "IT8": (14, 18, 22, 27, 33, 39, 46, 54, 63, 72, 81, 89, 97, 110, 125, 140, 165, 195, 230, 280, 330),
    "IT9": (25, 30, 36, 43, 52, 62, 74, 87, 100, 115, 130, 140, 155, 175, 200, 230, 260, 310, 370, 440, 540),
    "IT10": (40, 48, 58, 70, 84, 100, 120, 140, 160, 185, 210, 230, 250, 280, 320, 360, 420, 500, 600, 700, 860),
    "IT11": (60, 75, 90, 110, 130, 160, 190, 220, 250, 290, 320, 360, 400, 440, 500, 560, 660, 780, 920, 1100, 1350),
}
_MM_ROWS = {
    "IT12": (
        0.1,
        0.12,
        0.15,
        0.18,
        0.21,
        0.25,
        0.3,
        0.35,
        0.4,
        0.46,
        0.52,
        0.57,
        0.63,
        0.7,
        0.8,
        0.9,
        1.05,
        1.25,
        1.5,
        1.75,
        2.1,
    ),
    "IT13": (
        0.14,
        0.18,
        0.22,
        0.27,
        0.33,
        0.39,
        0.46,
        0.54,
        0.63,
        0.72,
        0.81,
        0.89,
        0.97,
        1.1,
        1.25,
        1.4,
        1.65,
        1.95,
        2.3,
        2.8,
        3.3,
    ),
    "IT14": (
        0.25,
        0.3,
        0.36,
        0.43,
        0.52,
        0.62,
        0.74,
        0.87,
        1,
        1.15,
        1.3,
        1.4,
        1.55,
        1.75,
        2,
        2.3,
        2.6,
        3.1,
        3.7,
        4.4,
        5.4,
    ),
    "IT15": (0.4, 0.48, 0.58, 0.7, 0.84, 1, 1.2, 1.4, 1.6, 1.85, 2.1, 2.3, 2.5, 2.8, 3.2, 3.6, 4.2, 5, 6, 7, 8.6),
    "IT16": (0.6, 0.75, 0.9, 1.1, 1.3, 1.6, 1.9, 2.2, 2.5, 2.9, 3.2, 3.6, 4, 4.4, 5, 5.6, 6.6, 7.8, 9.2, 11, 13.5),
    "IT17": (1, 1.2, 1.5, 1.8, 2.1, 2.5, 3, 3.5, 4, 4.6, 5.2, 5.7, 6.3, 7, 8, 9, 10.5, 12.5, 15, 17.5, 21),
    "IT18": (1.4, 1.8, 2.2, 2.7, 3.3, 3.9, 4.6, 5.4, 6.3, 7.2, 8.1, 8.9, 9.7, 11, 12.5, 14, 16.5, 19.5, 23, 28, 33),
}
IT_TABLE.update({g: tuple(round(v * _MM, 6) for v in row) for g, row in _MM_ROWS.items()})

#: multiples of the tolerance factor (i up to 500 mm, I beyond) per grade
FACTOR_MULTIPLE = {
    "IT5": 7,
    "IT6": 10,
    "IT7": 16,
    "IT8": 25,
    "IT9": 40,
    "IT10": 64,
    "IT11": 100,
    "IT12": 160,
    "IT13": 250,
    "IT14": 400,
    "IT15": 640,
    "IT16": 1000,
    "IT17": 1600,
    "IT18": 2500,
}


def size_range(size: float, field: str = "size") -> int:
    """The index of the nominal size range holding ``size`` (mm): ``0 < size <= 3150``."""
    try:
        s = float(size)
    except (TypeError, ValueError):
        raise OutOfRangeError(field, f"got {size!r}", "a nominal size in mm, 0 < size <= 3150") from None
    if not (math.isfinite(s) and 0.0 < s <= SIZE_STEPS[-1]):
        raise OutOfRangeError(field, f"got {size!r} mm", "a nominal size in mm, 0 < size <= 3150 (ISO 286-1)")
    for k, top in enumerate(SIZE_STEPS):
        if s <= top:
            return k
    raise AssertionError("unreachable")  # pragma: no cover


def factor(size: float) -> float:
    """The standard tolerance factor (µm) of the size range holding ``size``: ``i`` up to 500 mm,
    ``I`` beyond (module docstring), from the geometric mean of the range's limits."""
    k = size_range(size)
    lo = 1.0 if k == 0 else float(SIZE_STEPS[k - 1])
    D = math.sqrt(lo * SIZE_STEPS[k])
    return 0.45 * D ** (1.0 / 3.0) + 0.001 * D if SIZE_STEPS[k] <= 500 else 0.004 * D + 2.1


def it_width(grade: str, size: float, field: str = "grade") -> float:
    """The width of ``grade`` (``"IT7"``, ``"IT01"``, ...) at the nominal ``size`` (mm), in mm."""
    if grade not in IT_TABLE:
        raise UnknownNameError(field, f"unknown grade {grade!r}", ", ".join(GRADES))
    k = size_range(size)
    row = IT_TABLE[grade]
    if k >= len(row):
        raise OutOfRangeError(
            field,
            f"{grade} at {size:g} mm",
            f"{grade} is defined up to {SIZE_STEPS[len(row) - 1]} mm (ISO 286-1 Table A.1)",
        )
    if float(size) <= 1.0 and grade in ("IT14", "IT15", "IT16", "IT17", "IT18"):
        raise OutOfRangeError(field, f"{grade} at {size:g} mm", "IT14 to IT18 apply to nominal sizes over 1 mm")
    return row[k] / 1000.0


def half_width(grade: str, size: float) -> float:
    """The symmetric tolerance ``eps`` (``+-eps``, mm) of ``grade`` at ``size``: half its width."""
    return 0.5 * it_width(grade, size)


def grades_for(size: float) -> dict[str, float]:
    """Every grade defined at the nominal ``size`` (mm) -> its half width (mm), finest first."""
    size_range(size)  # a size outside the table is an error, not an empty answer
    out = {}
    for g in GRADES:
        try:
            out[g] = half_width(g, size)
        except OutOfRangeError:  # IT01 and IT0 end at 500 mm; IT14 to IT18 start over 1 mm
            continue
    return out
