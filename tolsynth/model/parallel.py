"""Parallel robots: Gough-Stewart hexapods, Delta robots and planar 3-RRR, from ``[[leg]]`` model files.

A parallel robot is a moving platform carried by legs.  Each leg joins an anchor on the base
(``base``, base frame) to an anchor on the platform (``platform``, platform frame) and is actuated
in one of two ways:

``prismatic``
    the leg's length is the actuator value plus an offset: ``|C - B| = q + offset`` (a hexapod strut);
``revolute``
    an arm of length ``arm`` turns about the unit ``axis`` through the base anchor; at the
    actuator angle ``q + offset`` it points along ``cos(phi) zero + sin(phi) (axis x zero)``; a
    distal link of length ``link`` with ball joints at both ends joins the arm's end ``A`` to the
    platform anchor: ``|C - A| = link`` (a Delta or 3-RRR leg).

``C = p + R c`` is the platform anchor in the base frame for the platform pose ``(p, R)``;
``R = Rz(rz) Ry(ry) Rx(rx)``.  The platform moves in the pose coordinates ``dof`` (a subset of
x, y, z, rx, ry, rz, as many as there are legs); the others stay 0.  The hand point is ``tool``
(platform frame).  Units of the file: ``[units]``; here mm and rad.

Every leg dimension is a *symbol* ``<leg>.<field>`` (``bx by bz px py pz offset`` and, for revolute
legs, ``arm link``), the entry point of an error parameter; ``[errors]`` selects which of them are
error parameters, with their cost factors, bounds and tolerance units (as a URDF chain's ``errors``
do).  The graphs (forward kinematics by Newton, the implicit-function-theorem sensitivities) are
:mod:`tolsynth.kinematics.parallel`'s.
"""

from __future__ import annotations

import fnmatch
import math
from dataclasses import dataclass
from typing import Any

from tolsynth.errors import InputError
from tolsynth.model.fields import (
    DEFAULT_K,
    DEFAULT_TOLERANCE_UNITS,
    _bounds_by_kind,
    _by_kind,
    _check_configurations,
    _nearest,
    _Reader,
    _tolerance_sets,
    _type_name,
    _unique,
)
from tolsynth.model.spec import Configuration, ErrorParameter, Joint, MechanismSpec
from tolsynth.units import to_base

__all__ = ["ParallelSpec", "Leg", "POSE_COORDINATES", "LEG_FIELDS", "FIELD_GROUPS", "is_parallel"]

#: the platform's pose coordinates, in the order of the pose vector (mm, mm, mm, rad, rad, rad)
POSE_COORDINATES = ("x", "y", "z", "rx", "ry", "rz")
#: the dimensions of a leg, each the symbol ``<leg>.<field>``, by actuation
LEG_FIELDS = {
    "prismatic": ("bx", "by", "bz", "px", "py", "pz", "offset"),
    "revolute": ("bx", "by", "bz", "px", "py", "pz", "offset", "arm", "link"),
}
#: names that select several fields of a leg in ``[errors].select`` and tolerance sets
FIELD_GROUPS = {
    "base": ("bx", "by", "bz"),
    "platform": ("px", "py", "pz"),
    "anchors": ("bx", "by", "bz", "px", "py", "pz"),
    "lengths": ("offset", "arm", "link"),
}
_LABELS = {
    "bx": "base anchor x",
    "by": "base anchor y",
    "bz": "base anchor z",
    "px": "platform anchor x",
    "py": "platform anchor y",
    "pz": "platform anchor z",
    "arm": "arm length",
    "link": "link length",
}
#: a revolute leg's axis and arm direction must be perpendicular to this (cosine of the angle)
_ORTHOGONAL = 1e-6


@dataclass(frozen=True)
class Leg:
    """One leg: its actuated joint, actuation and (revolute) the arm's axis and zero direction
    (unit vectors, base frame).  Its dimensions are the symbols :meth:`symbol` names."""

    name: str
    joint: str
    actuation: str  # "prismatic" or "revolute"
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    zero: tuple[float, float, float] = (1.0, 0.0, 0.0)

    @property
    def fields(self) -> tuple[str, ...]:
        return LEG_FIELDS[self.actuation]

    def symbol(self, fname: str) -> str:
        return f"{self.name}.{fname}"


@dataclass(frozen=True)
class ParallelSpec(MechanismSpec):
    """A parallel robot: legs between a base and a platform (see the module docstring).

    ``assembly``: a platform pose near the ``home`` configuration's (one value per ``dof``
    coordinate, mm and rad), the start of the Newton iteration that finds it; it selects the
    assembly mode.  ``tool_point``: the hand point in the platform frame (mm)."""

    legs: tuple[Leg, ...] = ()
    dof: tuple[str, ...] = ()
    #: the configuration the worst-pose searches and maps compare with by default (not the design
    #: pose, which is the same rule for every model: tolsynth.analysis.design_pose)
    reference: str = "home"
    assembly: tuple[float, ...] = ()
    tool_point: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def length_joints(self) -> tuple[str, ...]:
        """Joints whose values are lengths (mm): those of the prismatic legs."""
        return tuple(leg.joint for leg in self.legs if leg.actuation == "prismatic")


def is_parallel(spec) -> bool:
    """True for a parallel robot's specification."""
    return isinstance(spec, ParallelSpec)


def _point(r: _Reader, value: Any, where: str, factor: float) -> tuple[float, float, float]:
    if not isinstance(value, list) or len(value) != 3:
        raise r.fail(where, f"expected [x, y, z], got {_type_name(value)}: {value!r:.60}")
    return tuple(r.number(v, f"{where}[{i}]") * factor for i, v in enumerate(value))  # type: ignore[return-value]


def _unit_vector(r: _Reader, value: Any, where: str) -> tuple[float, float, float]:
    v = _point(r, value, where, 1.0)
    norm = math.sqrt(sum(c * c for c in v))
    if not norm > 0:
        raise r.fail(where, "a zero vector (a direction is needed)")
    return tuple(c / norm for c in v)  # type: ignore[return-value]


def _parse_legs(r: _Reader, data: dict, lf: float, af: float):
    """The ``[[leg]]`` tables: legs, joints, nominal symbols (mm, rad) and their kinds."""
    legs, joints, symbols, kinds = [], [], {}, {}
    raw_legs = r.tables(data["leg"], "leg", "leg")
    for i, raw in enumerate(raw_legs):
        where = f"leg[{i}]"
        name = r.get(raw, "name", where, str)
        if not all(ch.isalnum() or ch == "_" for ch in name):
            raise r.fail(
                f"{where}.name", f"{name!r}: letters, digits and '_' only (it starts the symbols '{name}.bx', ...)"
            )
        actuation = r.get(raw, "actuation", where, str)
        if actuation not in LEG_FIELDS:
            raise r.fail(
                f"{where}.actuation",
                f"unknown actuation {actuation!r}{_nearest(actuation, LEG_FIELDS)} (known: {', '.join(LEG_FIELDS)})",
            )
        if actuation == "prismatic":
            for key in ("arm", "link", "axis", "zero"):
                if key in raw:
                    raise r.fail(f"{where}.{key}", "only a revolute leg has an arm (this leg is prismatic)")
        jf = lf if actuation == "prismatic" else af
        lo, hi = r.pair(r.get(raw, "limits", where), f"{where}.limits")
        if actuation != "prismatic":
            r.revolute_limits(lo * jf, hi * jf, f"{where}.limits")
        joint = r.get(raw, "joint", where, str)
        joints.append(Joint(joint, lo * jf, hi * jf))
        b = _point(r, r.get(raw, "base", where), f"{where}.base", lf)
        c = _point(r, r.get(raw, "platform", where), f"{where}.platform", lf)
        values = dict(zip(("bx", "by", "bz"), b)) | dict(zip(("px", "py", "pz"), c))
        values["offset"] = r.number(raw.get("offset", 0.0), f"{where}.offset") * jf
        kinds.update({f"{name}.{f}": "length" for f in ("bx", "by", "bz", "px", "py", "pz")})
        kinds[f"{name}.offset"] = "length" if actuation == "prismatic" else "angle"
        axis, zero = (0.0, 0.0, 1.0), (1.0, 0.0, 0.0)
        if actuation == "revolute":
            for key in ("arm", "link"):
                values[key] = r.positive(r.get(raw, key, where), f"{where}.{key}") * lf
                kinds[f"{name}.{key}"] = "length"
            axis = _unit_vector(r, r.get(raw, "axis", where), f"{where}.axis")
            zero = _unit_vector(r, r.get(raw, "zero", where), f"{where}.zero")
            dot = sum(a * z for a, z in zip(axis, zero))
            if abs(dot) > _ORTHOGONAL:
                raise r.fail(
                    f"{where}.zero",
                    f"not perpendicular to the axis (cosine {dot:.3g}): the arm turns in the plane normal to its axis",
                )
        legs.append(Leg(name, joint, actuation, axis, zero))
        symbols.update({f"{name}.{f}": v for f, v in values.items()})
    _unique(r, [leg.name for leg in legs], "leg", "leg name")
    _unique(r, [j.name for j in joints], "leg", "joint name")
    return legs, joints, symbols, kinds


def _parse_platform(r: _Reader, data: dict, n_legs: int, lf: float, af: float):
    plat = r.table(data["platform"], "platform", "platform")
    dof = r.names(r.get(plat, "dof", "platform", list), "platform.dof", allow_empty=False)
    for i, d in enumerate(dof):
        if d not in POSE_COORDINATES:
            raise r.fail(
                f"platform.dof[{i}]",
                f"unknown pose coordinate {d!r}{_nearest(d, POSE_COORDINATES)} (known: {', '.join(POSE_COORDINATES)})",
            )
    dof = tuple(d for d in POSE_COORDINATES if d in dof)  # the pose vector's order
    if len(dof) != n_legs:
        raise r.fail(
            "platform.dof",
            f"{len(dof)} pose coordinates {list(dof)} for {n_legs} legs: each leg sets one, "
            "so there must be as many as legs",
        )
    start = r.table(r.get(plat, "assembly", "platform"), "platform.assembly")
    for key in start:
        if key not in dof:
            raise r.fail(
                f"platform.assembly.{key}",
                f"not a pose coordinate of the platform{_nearest(key, dof)} (dof: {list(dof)})",
            )
    assembly = tuple(r.number(start.get(d, 0.0), f"platform.assembly.{d}") * (lf if len(d) == 1 else af) for d in dof)
    tool = _point(r, plat.get("tool", [0.0, 0.0, 0.0]), "platform.tool", lf)
    return dof, assembly, tool


def _select(r: _Reader, pattern: str, where: str, names: list[str]) -> list[str]:
    """Leg dimensions matched by one ``<leg>.<field>`` pattern (fnmatch; a group name such as
    ``*.anchors`` stands for its fields), in the legs' order; none is an error naming ``where``."""
    head, _, group = pattern.rpartition(".")
    expanded = [f"{head}.{f}" for f in FIELD_GROUPS[group]] if head and group in FIELD_GROUPS else [pattern]
    hit = [n for n in names if any(fnmatch.fnmatchcase(n, e) for e in expanded)]
    if not hit:
        raise r.fail(
            where,
            f"{pattern!r} selects no leg dimension{_nearest(pattern, names)} (names are <leg>.<field> "
            f"with fields {', '.join(LEG_FIELDS['revolute'])}; groups .{', .'.join(FIELD_GROUPS)})",
        )
    return hit


def _parse_errors(r: _Reader, data: dict, symbols: dict, kinds: dict) -> list[ErrorParameter]:
    errs = r.table(data.get("errors", {}), "errors", "leg_errors")
    names = list(symbols)
    raw = errs.get("select", ["*"])
    patterns = r.names([raw] if isinstance(raw, str) else raw, "errors.select", allow_empty=False)
    chosen = {n for i, pat in enumerate(patterns) for n in _select(r, pat, f"errors.select[{i}]", names)}
    sel = {n: kinds[n] for n in names if n in chosen}
    try:
        ks = _by_kind(errs.get("k"), "errors.k", DEFAULT_K, sel)
        us = _by_kind(errs.get("tolerance_units"), "errors.tolerance_units", DEFAULT_TOLERANCE_UNITS, sel)
        bs = _bounds_by_kind(errs.get("bounds"), "errors.bounds", us, sel)
        ds = _by_kind(errs.get("distribution"), "errors.distribution", {"length": None, "angle": None}, sel)
    except InputError as err:
        raise r.fail(err.field, str(err).split(": ", 1)[-1]) from None
    out = []
    for n, kind in sel.items():
        unit = r.unit(us[n], f"errors.tolerance_units[{n}]", kind)
        b = bs[n]
        lo, hi = r.pair(list(b) if isinstance(b, (list, tuple)) else b, f"errors.bounds[{n}]")
        if lo <= 0:
            raise r.fail(f"errors.bounds[{n}]", f"the lower bound must be > 0 (cost eps**-alpha), got {lo}")
        if kind == "angle":
            r.angle_tolerance(hi, unit, f"errors.bounds[{n}]")
        dist = ds[n]
        if dist is not None:
            from tolsynth.errors import OutOfRangeError
            from tolsynth.probability.distributions import shape

            try:
                dist = shape(r.name(dist, f"errors.distribution[{n}]")).name
            except OutOfRangeError as exc:
                raise r.fail(f"errors.distribution[{n}]", f"got {dist!r}; allowed: {exc.allowed}") from None
        leg, _, fname = n.partition(".")
        label = f"{leg} {_LABELS.get(fname, 'leg-length offset' if kind == 'length' else 'arm zero offset')}"
        out.append(
            ErrorParameter(
                name=n,
                perturbs=(n,),
                unit=unit,
                scale=to_base(unit),
                k=r.positive(ks[n], f"errors.k[{n}]"),
                lower=lo,
                upper=hi,
                label=label,
                kind=kind,
                distribution=dist,
            )
        )
    return out


def _expand_tolerance_sets(r: _Reader, raw_sets: Any, eparams: list[ErrorParameter]) -> dict:
    """Tolerance-set keys that are patterns (``"*.anchors" = 0.02``) become one key per parameter
    they match; a parameter matched twice is an error naming both keys."""
    names = [p.name for p in eparams]
    out = {}
    for sname, raw in r.table(raw_sets, "tolerance_sets").items():
        where = f"tolerance_sets.{sname}"
        r.table(raw, where)
        values: dict[str, Any] = {}
        origin: dict[str, str] = {}
        for key, value in raw.items():
            hit = [key] if key in names else _select(r, key, f"{where}.{key}", names)
            for n in hit:
                if n in origin:
                    raise r.fail(f"{where}.{key}", f"{n!r} is already given by {origin[n]!r}")
                values[n], origin[n] = value, key
        out[sname] = values
    return _tolerance_sets(r, out, eparams)


def _parse_parallel_model(data: dict, r: _Reader) -> ParallelSpec:
    """A ``[[leg]]`` model file as a :class:`ParallelSpec` (strict: every defect names its field)."""
    r.table(data, "", "parallel")
    name, title, source, assumptions, notes = r.model_table(data)
    lf, af = r.unit_factors(data)

    legs, joints, symbols, kinds = _parse_legs(r, data, lf, af)
    dof, assembly, tool = _parse_platform(r, data, len(legs), lf, af)
    eparams = _parse_errors(r, data, symbols, kinds)

    joint_names = [j.name for j in joints]
    factor = {leg.joint: (lf if leg.actuation == "prismatic" else af) for leg in legs}
    configurations = {}
    for cname, where, raw, values, note in r.configuration_tables(data, joint_names, "actuator"):
        if raw.get("waive"):
            raise r.fail(f"{where}.waive", "a parallel robot's configurations waive no limit")
        configurations[cname] = Configuration(cname, tuple(v * factor[j] for j, v in zip(joint_names, values)), note)
    if "home" not in configurations:
        raise r.fail("configurations.home", "missing: the configuration the assembly pose starts from")
    lengths = tuple(leg.joint for leg in legs if leg.actuation == "prismatic")
    _check_configurations(r, configurations, joints, length_joints=lengths)
    return ParallelSpec(
        name=name,
        title=title,
        source=source,
        assumptions=tuple(assumptions),
        path=r.path,
        convention="parallel",
        base=(),
        tool=(),
        links=(),
        symbols=symbols,
        symbol_kinds=kinds,
        joints=tuple(joints),
        loops=(),
        joint_constraints=(),
        configurations=configurations,
        error_parameters=tuple(eparams),
        tolerance_sets=_expand_tolerance_sets(r, data.get("tolerance_sets", {}), eparams),
        notes=notes,
        legs=tuple(legs),
        dof=dof,
        assembly=assembly,
        tool_point=tool,
    )
