"""The model-file format (every table and its keys) and the strict reader of its fields.

Unknown keys, misspellings and wrong types are :class:`tolsynth.ModelFileError` naming the field;
the D-H and URDF imports read through the same :class:`_Reader`, so they report the same way.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from typing import Any

from tolsynth.checks import HUGE, TINY
from tolsynth.errors import ModelFileError, UnknownNameError
from tolsynth.units import ANGLE_UNITS, LENGTH_UNITS, allowed_units, to_base, unit_kind

__all__ = ["FORMAT", "DEFAULT_K", "DEFAULT_BOUNDS", "DEFAULT_TOLERANCE_UNITS"]


# --------------------------------------------------------------------------------------------
# the format: every table and its keys
# --------------------------------------------------------------------------------------------
#: Every table of the model-file format and its keys: ``True`` required, ``False`` optional.
#: A key that is not listed here is a ModelFileError ("did you mean ...?").  Adding a field to the
#: format is one line here, plus its parsing in ``_parse`` (or in the module that owns it).
#: Sections: "" is the top level; "configurations.*" lists the keys besides the joint names;
#: "tolerance_value" is the ``{ value, unit }`` form of a tolerance.
FORMAT: dict[str, dict[str, bool]] = {
    "": {
        "model": True,
        "units": True,
        "symbols": True,
        "chain": True,
        "joints": True,
        "loops": False,
        "joint_constraints": False,
        "configurations": True,
        "error_parameters": True,
        "tolerance_sets": False,
        "reference_results": False,
        "joint_errors": False,
    },
    "model": {"name": True, "title": False, "source": True, "assumptions": True, "notes": False},
    "units": {"length": True, "angle": True},
    "chain": {"convention": True, "links": True, "base": False, "tool": False},
    "joints": {"name": True, "limits": True},
    "loops": {
        "name": True,
        "kind": True,
        "passive_joint": True,
        "ground": True,
        "ground_angle": True,
        "crank": True,
        "crank_angle": True,
        "coupler": True,
        "lever": True,
        "branch": True,
    },
    "joint_constraints": {"name": True, "terms": True, "limits": True},
    "configurations.*": {"note": False, "waive": False},
    "error_parameters": {
        "name": True,
        "perturbs": True,
        "unit": True,
        "k": True,
        "bounds": True,
        "label": False,
        "alias": False,
        "cost": False,  # a cost model, {model = "chase", A = .., B = .., k = ..} (tolsynth.model.cost)
        "processes": False,  # [{name, cost, lower, upper}, ...] (tolsynth.synthesis.processes)
        "lock": False,  # a tolerance fixed at this value (tolerance unit)
        "distribution": False,  # this error's shape (tolsynth.probability.distributions), default uniform
    },
    "tolerance_value": {"value": True, "unit": True},
    # joint errors (tolsynth.model.joint_errors); value (fixed) or bounds (designable)
    "joint_errors": {
        "joint": True,
        "kind": True,
        "value": False,
        "bounds": False,
        "unit": False,
        "axial": False,
        "length": False,
        "k": False,
        "cost": False,
        "note": False,
    },
    # parallel robots (tolsynth.model.parallel): the top level of a [[leg]] file and its own tables
    "parallel": {
        "model": True,
        "units": True,
        "platform": True,
        "leg": True,
        "configurations": True,
        "errors": False,
        "tolerance_sets": False,
    },
    "platform": {"dof": True, "assembly": True, "tool": False},
    "leg": {
        "name": True,
        "joint": True,
        "actuation": True,  # "prismatic" (strut length) or "revolute" (arm + distal link)
        "limits": True,
        "base": True,
        "platform": True,
        "offset": False,
        "arm": False,  # revolute legs: arm and link lengths, the arm's axis and zero direction
        "link": False,
        "axis": False,
        "zero": False,
    },
    "leg_errors": {"select": False, "k": False, "bounds": False, "tolerance_units": False, "distribution": False},
    "reference_results": {
        "table": True,
        "R": True,
        "p": True,
        "alpha": True,
        "distribution": True,
        "tolerances": True,
    },
}


def _nearest(key: str, valid) -> str:
    """`` (did you mean `x`?)`` for the closest valid name, or an empty string."""
    match = difflib.get_close_matches(str(key), [str(v) for v in valid], n=1, cutoff=0.5)
    return f" (did you mean `{match[0]}`?)" if match else ""


def _type_name(value: Any) -> str:
    return {dict: "a table", list: "a list", str: "a string", bool: "a boolean"}.get(type(value), type(value).__name__)


# --------------------------------------------------------------------------------------------
# parsing
# --------------------------------------------------------------------------------------------
class _Reader:
    """Small helper that reads typed fields and raises ModelFileError naming the field."""

    def __init__(self, path: str):
        self.path = path
        self.angle_unit = "rad"  # the file's [units] angle, once read: named in the range messages

    # ---- physical ranges of angles (a unit mistake, degrees read as radians, shows here)
    def revolute_limits(self, lo: float, hi: float, where: str, weight: float = 1.0) -> None:
        """A revolute joint's limits (rad) within :data:`MAX_JOINT_TURNS` turns either way; a joint
        constraint's, a sum of joints with coefficients summing to ``weight`` in absolute value,
        within ``weight`` times that."""
        top = MAX_JOINT_TURNS * 2 * math.pi * weight
        if -top <= lo and hi <= top:
            return
        per = ANGLE_UNITS[self.angle_unit]
        what = "a revolute joint" if weight == 1.0 else f"a joint constraint whose coefficients sum to {weight:g}"
        in_deg = self.angle_unit == "deg"
        # a file in rad may hold degrees by mistake; one in degrees (or finer) has no such excuse
        hint = (
            ""
            if self.angle_unit in ("deg", "arcmin", "arcsec")
            else f" (degrees written with angle = {self.angle_unit!r}?)"
        )
        raise self.fail(
            where,
            f"[{lo / per:g}, {hi / per:g}] {self.angle_unit}"
            + ("" if in_deg else f" = [{math.degrees(lo):g}, {math.degrees(hi):g}] deg")
            + f" is beyond {MAX_JOINT_TURNS} turns; allowed: limits from {-top / per:g} to {top / per:g} "
            f"{self.angle_unit}"
            + ("" if in_deg else f" (+-{MAX_JOINT_TURNS * 360 * weight:g} deg)")
            + f" for {what}{hint}",
        )

    def angle_tolerance(self, value: float, unit: str, where: str) -> None:
        """An angle tolerance (or bound) in ``unit`` of at most one full turn."""
        top = 2 * math.pi / to_base(unit)
        if value <= top * (1 + 1e-12):
            return
        raise self.fail(
            where,
            f"{value:g} {unit} is more than a full turn; allowed: an angle tolerance up to {top:g} {unit} "
            "(2 pi rad, 360 deg)",
        )

    def fail(self, field_name: str, message: str) -> ModelFileError:
        return ModelFileError(self.path, field_name, message)

    # ---- tables and keys
    def keys(self, table: dict, where: str, valid, required=()) -> None:
        """Unknown keys and missing required keys of ``table`` are errors."""
        for key in table:
            if key not in valid:
                raise self.fail(
                    f"{where}.{key}" if where else str(key),
                    f"unknown key{_nearest(key, valid)} (allowed here: {', '.join(map(str, valid))})",
                )
        for key in required:
            if key not in table:
                raise self.fail(f"{where}.{key}" if where else key, "missing required field")

    def table(self, value: Any, where: str, section: str | None = None, extra=()) -> dict:
        """``value`` must be a table; with ``section``, its keys must be those of FORMAT[section]
        (plus ``extra``)."""
        if not isinstance(value, dict):
            raise self.fail(where or "(file)", f"expected a table, got {_type_name(value)}: {value!r:.60}")
        if section is not None:
            spec = FORMAT[section]
            self.keys(value, where, list(spec) + list(extra), [k for k, req in spec.items() if req])
        return value

    def tables(self, value: Any, where: str, section: str) -> list[dict]:
        """An array of tables (``[[section]]``), each with the keys of FORMAT[section]."""
        if not isinstance(value, list):
            raise self.fail(where, f"expected an array of tables [[{where}]], got {_type_name(value)}")
        return [self.table(item, f"{where}[{i}]", section) for i, item in enumerate(value)]

    def get(self, table: dict, key: str, where: str, kind=None, default: Any = ...):
        field_name = f"{where}.{key}" if where else key
        if key not in table:
            if default is ...:
                raise self.fail(field_name, "missing required field")
            return default
        value = table[key]
        if kind is float:
            return self.number(value, field_name)
        if kind is str:
            return self.name(value, field_name)
        if kind is int and (isinstance(value, bool) or not isinstance(value, int)):
            raise self.fail(field_name, f"expected an integer, got {_type_name(value)}: {value!r}")
        if kind is not None and not isinstance(value, kind):
            raise self.fail(field_name, f"expected {kind.__name__}, got {_type_name(value)}: {value!r:.60}")
        return value

    # ---- values
    def name(self, value: Any, where: str) -> str:
        """A non-empty string."""
        if not isinstance(value, str):
            raise self.fail(where, f"expected a string, got {_type_name(value)}: {value!r:.60}")
        if not value.strip():
            raise self.fail(where, "expected a non-empty string")
        return value

    def names(self, value: Any, where: str, allow_empty: bool = True) -> list[str]:
        """A list of distinct non-empty strings."""
        if not isinstance(value, list):
            raise self.fail(where, f"expected a list of strings, got {_type_name(value)}: {value!r:.60}")
        out = [self.name(v, f"{where}[{i}]") for i, v in enumerate(value)]
        if not allow_empty and not out:
            raise self.fail(where, "expected at least one name")
        dup = sorted({v for v in out if out.count(v) > 1})
        if dup:
            raise self.fail(where, f"{dup} given more than once")
        return out

    def number(self, value: Any, where: str, lower: float = -HUGE, upper: float = HUGE) -> float:
        """A finite number in ``[lower, upper]`` (the shared limits of :mod:`tolsynth.checks`)."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(where, f"expected a number, got {_type_name(value)}: {value!r:.60}")
        try:
            v = float(value)
        except OverflowError:  # an integer beyond double range
            v = math.inf
        if not (math.isfinite(v) and lower <= v <= upper):
            raise self.fail(where, f"expected a finite number from {lower:g} to {upper:g}, got {value!r}")
        return v

    def positive(self, value: Any, where: str) -> float:
        """A number from TINY to HUGE."""
        return self.number(value, where, TINY, HUGE)

    def unit(self, value: Any, where: str, kind: str | None = None) -> str:
        if not isinstance(value, str) or unit_kind(value) is None:
            raise self.fail(where, f"unknown unit {value!r}{_nearest(value, _UNIT_NAMES)} (known: {allowed_units()})")
        if kind is not None and unit_kind(value) != kind:
            raise self.fail(where, f"unit {value!r} is not a unit of {kind}")
        return value

    # ---- the sections every model file starts with
    def model_table(self, data: dict) -> tuple[str, str, str, list, str]:
        """``[model]``: name, title (default: the name), source, assumptions and notes."""
        meta = self.table(data["model"], "model", "model")
        name = self.get(meta, "name", "model", str)
        title = self.get(meta, "title", "model", str, default=name)
        source = self.get(meta, "source", "model", str)
        assumptions = self.get(meta, "assumptions", "model", list)
        for i, a in enumerate(assumptions):
            self.name(a, f"model.assumptions[{i}]")
        notes = meta.get("notes", "")
        if not isinstance(notes, str):
            raise self.fail("model.notes", f"expected a string, got {_type_name(notes)}")
        return name, title, source, assumptions, notes

    def unit_factors(self, data: dict) -> tuple[float, float]:
        """``[units]``: the factors that take the file's lengths to mm and its angles to rad."""
        units = self.table(data["units"], "units", "units")
        length_unit = self.unit(self.get(units, "length", "units"), "units.length", "length")
        angle_unit = self.unit(self.get(units, "angle", "units"), "units.angle", "angle")
        self.angle_unit = angle_unit
        return LENGTH_UNITS[length_unit], ANGLE_UNITS[angle_unit]

    def configuration_tables(self, data: dict, joint_names: list[str], what: str = "joint"):
        """Each ``[configurations.NAME]`` table as ``(NAME, its field, the table, the joint values
        in the file's units, the note)``: every joint given a number (``what`` names them in the
        message), the note a string."""
        for cname, raw in self.table(data["configurations"], "configurations").items():
            where = f"configurations.{cname}"
            self.table(raw, where, "configurations.*", extra=joint_names)
            missing = [j for j in joint_names if j not in raw]
            if missing:
                raise self.fail(where, f"missing {what} value(s) {missing}")
            values = [self.get(raw, j, where, float) for j in joint_names]
            note = raw.get("note", "")
            if not isinstance(note, str):
                raise self.fail(f"{where}.note", f"expected a string, got {_type_name(note)}")
            yield cname, where, raw, values, note

    def pair(self, value: Any, where: str) -> tuple[float, float]:
        if not isinstance(value, list) or len(value) != 2:
            raise self.fail(where, f"expected [lower, upper], got {value!r:.60}")
        lo, hi = (self.number(v, f"{where}[{i}]") for i, v in enumerate(value))
        if not lo < hi:
            raise self.fail(where, f"lower {lo} must be below upper {hi}")
        return lo, hi


_UNIT_NAMES = list(LENGTH_UNITS) + list(ANGLE_UNITS)
#: revolute joint limits beyond this many turns either way are a unit mistake (170 read as rad)
#: rather than a robot: wrist joints of a few turns are real, tens of turns are not
MAX_JOINT_TURNS = 4


def _tolerance_sets(r, raw_sets, eparams) -> dict[str, dict[str, float]]:
    """The ``[tolerance_sets]`` of a file: name -> {error parameter: tolerance in its unit}."""
    tolerance_sets = {}
    by_name = {p.name: p for p in eparams}
    by_name.update({p.alias: p for p in eparams if p.alias})
    for sname, raw in r.table(raw_sets, "tolerance_sets").items():
        where = f"tolerance_sets.{sname}"
        r.table(raw, where)
        values = {}
        for key, value in raw.items():
            if key not in by_name:
                raise r.fail(
                    f"{where}.{key}",
                    f"unknown error parameter{_nearest(key, by_name)} (known: {[p.name for p in eparams]})",
                )
            par = by_name[key]
            if par.name in values:
                raise r.fail(f"{where}.{key}", f"{par.name!r} is given twice (by its name and its alias)")
            if isinstance(value, dict):
                r.table(value, f"{where}.{key}", "tolerance_value")
                v = r.number(value["value"], f"{where}.{key}.value")
                u = r.unit(value["unit"], f"{where}.{key}.unit", par.kind)
                v = v * to_base(u) / par.scale
            else:
                v = r.number(value, f"{where}.{key}")
            if not 0 <= v <= HUGE:
                raise r.fail(f"{where}.{key}", f"a tolerance must be >= 0 (and at most {HUGE:g} {par.unit}), got {v}")
            if par.kind == "angle":
                r.angle_tolerance(v, par.unit, f"{where}.{key}")
            values[par.name] = v
        missing = [p.name for p in eparams if p.name not in values]
        if missing:
            raise r.fail(where, f"missing tolerance(s) for {missing}")
        tolerance_sets[sname] = values
    return tolerance_sets


def _unique(r: _Reader, names: list, where: str, what: str) -> None:
    """Each name at most once."""
    dup = sorted({str(n) for n in names if names.count(n) > 1})
    if dup:
        raise r.fail(where, f"{what} {dup} declared more than once")


# --------------------------------------------------------------------------------------------
# defaults of the robots given in Python (a D-H table, a URDF)
# --------------------------------------------------------------------------------------------
#: cost factor by kind, as in Xu & Zhang 1988 (and the bundled models): lengths 1, angles 1.5
DEFAULT_K = {"length": 1.0, "angle": 1.5}
#: default tolerance bounds (Eq. 22) by kind, physical quantities in the default tolerance units
#: (mm and mrad); :func:`_bounds_by_kind` converts them into each parameter's own unit
DEFAULT_BOUNDS = {"length": (0.001, 5.0), "angle": (0.001, 50.0)}
DEFAULT_TOLERANCE_UNITS = {"length": "mm", "angle": "mrad"}


def _by_kind(arg: Any, argname: str, default: dict, selectable: dict[str, str]) -> dict[str, Any]:
    """``k``/``bounds``/``tolerance_units``: one value for all, or a mapping whose keys are
    ``"length"``, ``"angle"`` or error-parameter names; returns name -> value for every selected
    parameter (name -> kind in ``selectable``)."""
    out = {name: default[kind] for name, kind in selectable.items()}
    if arg is None:
        return out
    if not isinstance(arg, Mapping):
        return {name: arg for name in selectable}
    for key in arg:
        if key not in ("length", "angle") and key not in selectable:
            valid = ["length", "angle", *selectable]
            raise UnknownNameError(
                f"{argname}[{key}]",
                f"not 'length', 'angle' or a selected error parameter{_nearest(key, valid)}",
                "'length', 'angle' or one of " + ", ".join(selectable),
            )
    for name, kind in selectable.items():  # by kind first, then by name
        if kind in arg:
            out[name] = arg[kind]
    for name in selectable:
        if name in arg:
            out[name] = arg[name]
    return out


def _bounds_by_kind(arg: Any, argname: str, units: dict[str, Any], selectable: dict[str, str]) -> dict[str, Any]:
    """``bounds`` as :func:`_by_kind` reads it, given bounds in the tolerance unit as they are, and
    the defaults :data:`DEFAULT_BOUNDS` (0.001-5 mm, 0.001-50 mrad) converted into each parameter's
    tolerance unit (``units``: name -> unit), so that choosing um or deg keeps the same physical
    range instead of reading 5 as 5 um.  A unit that is not one of the parameter's kind keeps the
    numbers: the reader refuses that unit with its own message."""
    unset = object()
    given = _by_kind(arg, argname, {"length": unset, "angle": unset}, selectable)
    out = {}
    for name, kind in selectable.items():
        if given[name] is not unset:
            out[name] = given[name]
            continue
        lo, hi = DEFAULT_BOUNDS[kind]
        unit = units.get(name)
        if isinstance(unit, str) and unit_kind(unit) == kind:
            f = to_base(DEFAULT_TOLERANCE_UNITS[kind]) / to_base(unit)
            lo, hi = lo * f, hi * f
        out[name] = (lo, hi)
    return out


#: joint limits are inclusive; this slack only absorbs the rounding of deg -> rad conversions and
#: of the constraint sums (a pose written exactly on a limit in degrees is inside)
LIMIT_SLACK = 1e-12


def _check_configurations(r: _Reader, configurations: dict, joints, constraints=(), length_joints=()) -> None:
    """Every named configuration inside the joint limits and the joint constraints (those it
    waives excepted): a model whose own poses cannot be used fails when it is read, naming the
    configuration, not later at its first use."""
    names = [j.name for j in joints]
    for cname, cfg in configurations.items():
        waive = set(getattr(cfg, "waive", ()) or ())
        for j, v in zip(joints, cfg.q):
            if j.name in waive or j.lower - LIMIT_SLACK <= v <= j.upper + LIMIT_SLACK:
                continue
            if j.name in length_joints:
                what = f"{v:.6g} mm is outside the joint limits {j.lower:g} to {j.upper:g} mm"
            else:
                what = (
                    f"{math.degrees(v):.6g} deg is outside the joint limits {math.degrees(j.lower):g} to "
                    f"{math.degrees(j.upper):g} deg"
                )
            raise r.fail(
                f"configurations.{cname}.{j.name}", what + " (or waive the limit with 'waive' and say why in 'note')"
            )
        for c in constraints:
            if c.name in waive:
                continue
            v = sum(coef * cfg.q[names.index(jn)] for jn, coef in c.terms.items())
            if not c.lower - LIMIT_SLACK <= v <= c.upper + LIMIT_SLACK:
                raise r.fail(
                    f"configurations.{cname}",
                    f"{math.degrees(v):.6g} deg breaks joint constraint {c.name!r} "
                    f"({math.degrees(c.lower):g} to {math.degrees(c.upper):g} deg; "
                    "or waive it with 'waive' and say why in 'note')",
                )
