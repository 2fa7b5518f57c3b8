"""Mechanism declarations: reading and validating the model files under ``models/``.

A model file is TOML and is *data*: the chain, loops, joints, configurations, error parameters and
tolerance sets of one mechanism, with its source and assumptions.  This module turns one into a
:class:`MechanismSpec` (plain, validated numbers in mm and rad), and :func:`load_model` wraps that
in a :class:`tolsynth.mechanism.Mechanism`, which owns the CasADi graphs.

The format is documented in ``README.md`` ("Model file format") and in the header of each model
file; ``models/planar_2r.toml`` is the smallest complete example.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

from .errors import ModelFileError, UnknownNameError
from .units import ANGLE_UNITS, LENGTH_UNITS, allowed_units, to_base, unit_kind

__all__ = [
    "MechanismSpec",
    "Link",
    "Joint",
    "FourBarLoop",
    "JointConstraint",
    "Configuration",
    "ErrorParameter",
    "ReferenceResult",
    "bundled_models",
    "model_path",
    "read_model_file",
]

CONVENTIONS = {
    # name: (fields in the order they are applied, description)
    "modified": (("h", "alpha", "s", "theta"), "Tx(h) . Rx(alpha) . Tz(s) . Rz(theta)"),
    "standard": (("theta", "d", "a", "alpha"), "Rz(theta) . Tz(d) . Tx(a) . Rx(alpha)"),
}
_LENGTH_FIELDS = {"h", "s", "d", "a"}
_ANGLE_FIELDS = {"alpha", "theta_offset"}
ELEMENTARY = {"Tx": "length", "Ty": "length", "Tz": "length", "Rx": "angle", "Ry": "angle", "Rz": "angle"}


@dataclass(frozen=True)
class Link:
    """One D-H link.  Every dimension is a *symbol name*; ``theta`` names a joint."""

    dims: dict[str, str]  # field -> symbol name (h/alpha/s or d/a/alpha)
    theta: str  # joint name (actuated or passive)
    theta_offset: str | None  # symbol name, or None


@dataclass(frozen=True)
class Joint:
    name: str
    lower: float  # rad
    upper: float  # rad


@dataclass(frozen=True)
class FourBarLoop:
    """Planar four-bar that sets a passive joint (see ``tolsynth.kinematics.four_bar_output``).

    In the plane of the loop, with the common pivot O at the origin: the ground link O->E of length
    ``ground`` lies at angle ``ground_angle``; the crank O->C of length ``crank`` at ``crank_angle``;
    the coupler C->D has length ``coupler``; the lever E->D of length ``lever`` is rigid with the
    next link.  The passive joint is the lever's angle measured from the ground link.
    """

    name: str
    passive_joint: str
    ground: str
    ground_angle: str
    crank: str
    crank_angle: str
    coupler: str
    lever: str
    branch: int  # +1 or -1


@dataclass(frozen=True)
class JointConstraint:
    name: str
    terms: dict[str, float]  # joint name -> coefficient
    lower: float  # rad
    upper: float  # rad


@dataclass(frozen=True)
class Configuration:
    name: str
    q: tuple[float, ...]  # rad, in the order of the actuated joints
    note: str = ""
    waive: tuple[str, ...] = ()  # joint or joint-constraint limits this named pose may violate


@dataclass(frozen=True)
class ErrorParameter:
    name: str
    perturbs: tuple[str, ...]
    unit: str
    scale: float  # one tolerance unit in base units (mm or rad)
    k: float
    lower: float  # default bounds, in the tolerance unit
    upper: float
    label: str = ""
    alias: str | None = None
    kind: str = "length"


@dataclass(frozen=True)
class ReferenceResult:
    """A published optimum (the paper's Tables 1-3): specification and printed tolerances."""

    table: str
    R: float  # mm
    p: float
    alpha: float
    distribution: str
    tolerances: tuple[float, ...]  # in the error parameters' units, in their order


@dataclass(frozen=True)
class MechanismSpec:
    """A validated mechanism declaration: every number in mm or rad."""

    name: str
    title: str
    source: str
    assumptions: tuple[str, ...]
    path: str
    convention: str
    base: tuple[tuple[str, str], ...]  # (elementary transform, symbol)
    tool: tuple[tuple[str, str], ...]
    links: tuple[Link, ...]
    symbols: dict[str, float]  # nominal value in mm or rad
    symbol_kinds: dict[str, str]
    joints: tuple[Joint, ...]
    loops: tuple[FourBarLoop, ...]
    joint_constraints: tuple[JointConstraint, ...]
    configurations: dict[str, Configuration]
    error_parameters: tuple[ErrorParameter, ...]
    tolerance_sets: dict[str, dict[str, float]]
    reference_results: tuple[ReferenceResult, ...] = field(default_factory=tuple)
    notes: str = ""

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)


# --------------------------------------------------------------------------------------------
# locating model files
# --------------------------------------------------------------------------------------------
def _models_dir():
    """The bundled model files: the package ``tolsynth.models`` once installed (editable or not);
    the top-level ``models/`` folder when the source tree's ``tolsynth/`` shadows the install
    (running from a checkout's root)."""
    try:
        return resources.files("tolsynth.models")
    except ModuleNotFoundError:
        checkout = Path(__file__).resolve().parent.parent / "models"
        if checkout.is_dir():
            return checkout
        raise


def bundled_models() -> list[str]:
    """Names of the models shipped with the package."""
    return sorted(
        p.name[: -len(".toml")] for p in _models_dir().iterdir() if p.name.endswith(".toml")
    )


def model_path(name_or_path: str | os.PathLike) -> Path:
    """Resolve a bundled model name or a path to a ``.toml`` file."""
    text = os.fspath(name_or_path)
    candidate = Path(text)
    if candidate.suffix == ".toml" or os.sep in text or "/" in text:
        if not candidate.is_file():
            raise UnknownNameError("model", f"no model file at {text!r}", "an existing .toml file")
        return candidate
    resource = _models_dir().joinpath(f"{text}.toml")
    if not resource.is_file():
        raise UnknownNameError(
            "model", f"unknown model {text!r}", "one of " + ", ".join(bundled_models()) + " or a path"
        )
    return Path(str(resource))


# --------------------------------------------------------------------------------------------
# parsing
# --------------------------------------------------------------------------------------------
class _Reader:
    """Small helper that reads typed fields and raises ModelFileError naming the field."""

    def __init__(self, path: str):
        self.path = path

    def fail(self, field_name: str, message: str) -> ModelFileError:
        return ModelFileError(self.path, field_name, message)

    def get(self, table: dict, key: str, where: str, kind=None, default: Any = ...):
        if key not in table:
            if default is ...:
                raise self.fail(f"{where}.{key}", "missing required field")
            return default
        value = table[key]
        if kind is float:
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise self.fail(f"{where}.{key}", f"expected a number, got {value!r}")
            if not math.isfinite(value):
                raise self.fail(f"{where}.{key}", f"expected a finite number, got {value!r}")
            return float(value)
        if kind is not None and not isinstance(value, kind):
            raise self.fail(f"{where}.{key}", f"expected {kind.__name__}, got {value!r}")
        return value

    def unit(self, value: Any, where: str, kind: str | None = None) -> str:
        if not isinstance(value, str) or unit_kind(value) is None:
            raise self.fail(where, f"unknown unit {value!r} (known: {allowed_units()})")
        if kind is not None and unit_kind(value) != kind:
            raise self.fail(where, f"unit {value!r} is not a unit of {kind}")
        return value

    def pair(self, value: Any, where: str) -> tuple[float, float]:
        if (
            not isinstance(value, list)
            or len(value) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
        ):
            raise self.fail(where, f"expected [lower, upper], got {value!r}")
        lo, hi = float(value[0]), float(value[1])
        if not lo < hi:
            raise self.fail(where, f"lower {lo} must be below upper {hi}")
        return lo, hi


def read_model_file(path: str | os.PathLike) -> MechanismSpec:
    """Read and validate one model file.  Raises :class:`ModelFileError` on any defect."""
    path = Path(path)
    r = _Reader(str(path))
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise r.fail("(file)", f"not valid TOML: {exc}") from None
    return _parse(data, r)


def _parse(data: dict, r: _Reader) -> MechanismSpec:
    meta = r.get(data, "model", "(top level)", dict)
    name = r.get(meta, "name", "model", str)
    title = r.get(meta, "title", "model", str, default=name)
    source = r.get(meta, "source", "model", str)
    assumptions = r.get(meta, "assumptions", "model", list)
    if not all(isinstance(a, str) for a in assumptions):
        raise r.fail("model.assumptions", "expected a list of strings")
    notes = r.get(meta, "notes", "model", str, default="")

    units = r.get(data, "units", "(top level)", dict)
    length_unit = r.unit(r.get(units, "length", "units"), "units.length", "length")
    angle_unit = r.unit(r.get(units, "angle", "units"), "units.angle", "angle")
    lf, af = LENGTH_UNITS[length_unit], ANGLE_UNITS[angle_unit]

    # ---- chain ------------------------------------------------------------------------------
    chain = r.get(data, "chain", "(top level)", dict)
    convention = r.get(chain, "convention", "chain", str)
    if convention not in CONVENTIONS:
        raise r.fail("chain.convention", f"unknown convention {convention!r} (known: {', '.join(CONVENTIONS)})")
    fields, _ = CONVENTIONS[convention]
    raw_symbols = r.get(data, "symbols", "(top level)", dict)
    symbol_kinds: dict[str, str] = {}

    def use_symbol(sym: Any, kind: str, where: str) -> str:
        if not isinstance(sym, str):
            raise r.fail(where, f"expected a symbol name (a key of [symbols]), got {sym!r}")
        if sym not in raw_symbols:
            raise r.fail(where, f"symbol {sym!r} is not declared in [symbols]")
        previous = symbol_kinds.setdefault(sym, kind)
        if previous != kind:
            raise r.fail(where, f"symbol {sym!r} is used both as a {previous} and as a {kind}")
        return sym

    def elementary(items: Any, where: str) -> tuple[tuple[str, str], ...]:
        if not isinstance(items, list):
            raise r.fail(where, "expected a list of one-key tables like { Tz = \"s0\" }")
        out = []
        for i, item in enumerate(items):
            if not isinstance(item, dict) or len(item) != 1:
                raise r.fail(f"{where}[{i}]", "expected a one-key table like { Tz = \"s0\" }")
            (op, sym), = item.items()
            if op not in ELEMENTARY:
                raise r.fail(f"{where}[{i}]", f"unknown transform {op!r} (known: {', '.join(ELEMENTARY)})")
            out.append((op, use_symbol(sym, ELEMENTARY[op], f"{where}[{i}].{op}")))
        return tuple(out)

    base = elementary(chain.get("base", []), "chain.base")
    tool = elementary(chain.get("tool", []), "chain.tool")
    raw_links = r.get(chain, "links", "chain", list)
    if not raw_links:
        raise r.fail("chain.links", "a chain needs at least one link")
    links = []
    allowed_keys = set(fields) | {"theta_offset", "name"}
    for i, raw in enumerate(raw_links):
        where = f"chain.links[{i}]"
        if not isinstance(raw, dict):
            raise r.fail(where, "expected a table")
        extra = set(raw) - allowed_keys
        if extra:
            raise r.fail(
                where,
                f"field(s) {sorted(extra)} do not belong to the {convention} D-H convention "
                f"(its fields: {', '.join(fields)}, theta_offset)",
            )
        dims = {}
        for fname in fields:
            if fname == "theta":
                continue
            kind = "length" if fname in _LENGTH_FIELDS else "angle"
            dims[fname] = use_symbol(r.get(raw, fname, where), kind, f"{where}.{fname}")
        theta = r.get(raw, "theta", where, str)
        offset = raw.get("theta_offset")
        if offset is not None:
            offset = use_symbol(offset, "angle", f"{where}.theta_offset")
        links.append(Link(dims=dims, theta=theta, theta_offset=offset))

    # ---- joints -----------------------------------------------------------------------------
    joints = []
    for i, raw in enumerate(r.get(data, "joints", "(top level)", list)):
        where = f"joints[{i}]"
        jname = r.get(raw, "name", where, str)
        lo, hi = r.pair(r.get(raw, "limits", where), f"{where}.limits")
        joints.append(Joint(jname, lo * af, hi * af))
    joint_names = [j.name for j in joints]
    if len(set(joint_names)) != len(joint_names):
        raise r.fail("joints", "joint names must be unique")

    # ---- loops ------------------------------------------------------------------------------
    loops = []
    for i, raw in enumerate(data.get("loops", [])):
        where = f"loops[{i}]"
        kind = r.get(raw, "kind", where, str)
        if kind != "four_bar":
            raise r.fail(f"{where}.kind", f"unknown loop kind {kind!r} (known: four_bar)")
        branch = r.get(raw, "branch", where, int)
        if branch not in (1, -1):
            raise r.fail(f"{where}.branch", f"expected +1 or -1, got {branch}")
        loop = FourBarLoop(
            name=r.get(raw, "name", where, str),
            passive_joint=r.get(raw, "passive_joint", where, str),
            ground=use_symbol(r.get(raw, "ground", where), "length", f"{where}.ground"),
            ground_angle=r.get(raw, "ground_angle", where, str),
            crank=use_symbol(r.get(raw, "crank", where), "length", f"{where}.crank"),
            crank_angle=r.get(raw, "crank_angle", where, str),
            coupler=use_symbol(r.get(raw, "coupler", where), "length", f"{where}.coupler"),
            lever=use_symbol(r.get(raw, "lever", where), "length", f"{where}.lever"),
            branch=branch,
        )
        for key in ("ground_angle", "crank_angle"):
            if getattr(loop, key) not in joint_names:
                raise r.fail(f"{where}.{key}", f"{getattr(loop, key)!r} is not an actuated joint (joints: {joint_names})")
        if loop.passive_joint in joint_names:
            raise r.fail(f"{where}.passive_joint", f"{loop.passive_joint!r} is declared as an actuated joint")
        loops.append(loop)
    passive = [lp.passive_joint for lp in loops]
    for i, link in enumerate(links):
        if link.theta not in joint_names and link.theta not in passive:
            raise r.fail(
                f"chain.links[{i}].theta",
                f"{link.theta!r} is neither an actuated joint {joint_names} nor a loop's passive joint {passive}",
            )

    # ---- symbols: all used, all numbers -----------------------------------------------------
    symbols: dict[str, float] = {}
    for sym, value in raw_symbols.items():
        if sym not in symbol_kinds:
            raise r.fail(f"symbols.{sym}", "declared but not used by the chain or a loop")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise r.fail(f"symbols.{sym}", f"expected a finite number, got {value!r}")
        symbols[sym] = float(value) * (lf if symbol_kinds[sym] == "length" else af)
    for loop in loops:
        for key in ("ground", "crank", "coupler", "lever"):
            if symbols[getattr(loop, key)] <= 0:
                raise r.fail(f"loops.{loop.name}.{key}", "a loop link length must be > 0")

    # ---- joint constraints ------------------------------------------------------------------
    jcons = []
    for i, raw in enumerate(data.get("joint_constraints", [])):
        where = f"joint_constraints[{i}]"
        terms = r.get(raw, "terms", where, dict)
        for jn, coef in terms.items():
            if jn not in joint_names:
                raise r.fail(f"{where}.terms.{jn}", f"not an actuated joint (joints: {joint_names})")
            if isinstance(coef, bool) or not isinstance(coef, (int, float)):
                raise r.fail(f"{where}.terms.{jn}", f"expected a number, got {coef!r}")
        lo, hi = r.pair(r.get(raw, "limits", where), f"{where}.limits")
        jcons.append(JointConstraint(r.get(raw, "name", where, str), {k: float(v) for k, v in terms.items()}, lo * af, hi * af))

    # ---- configurations ---------------------------------------------------------------------
    configurations = {}
    for cname, raw in r.get(data, "configurations", "(top level)", dict).items():
        where = f"configurations.{cname}"
        if not isinstance(raw, dict):
            raise r.fail(where, "expected a table of joint values")
        missing = [j for j in joint_names if j not in raw]
        if missing:
            raise r.fail(where, f"missing joint value(s) {missing}")
        extra = set(raw) - set(joint_names) - {"note", "waive"}
        if extra:
            raise r.fail(where, f"unknown joint(s) {sorted(extra)} (joints: {joint_names})")
        q = tuple(r.get(raw, j, where, float) * af for j in joint_names)
        waive = r.get(raw, "waive", where, list, default=[])
        limit_names = set(joint_names) | {c.name for c in jcons}
        for w in waive:
            if w not in limit_names:
                raise r.fail(f"{where}.waive", f"{w!r} names no joint or joint constraint")
        if waive and not raw.get("note"):
            raise r.fail(f"{where}.note", "a configuration that waives a limit must say why in 'note'")
        configurations[cname] = Configuration(cname, q, raw.get("note", ""), tuple(waive))

    # ---- error parameters -------------------------------------------------------------------
    eparams = []
    seen: set[str] = set()
    for i, raw in enumerate(r.get(data, "error_parameters", "(top level)", list)):
        where = f"error_parameters[{i}]"
        pname = r.get(raw, "name", where, str)
        alias = raw.get("alias")
        for n in (pname, alias):
            if n is not None and n in seen:
                raise r.fail(f"{where}.name", f"name {n!r} is used twice")
            if n is not None:
                seen.add(n)
        perturbs = r.get(raw, "perturbs", where, list)
        if not perturbs:
            raise r.fail(f"{where}.perturbs", "names no symbol")
        kinds = set()
        for j, sym in enumerate(perturbs):
            if sym not in symbols:
                raise r.fail(f"{where}.perturbs[{j}]", f"{sym!r} is not a declared symbol")
            kinds.add(symbol_kinds[sym])
        if len(kinds) != 1:
            raise r.fail(f"{where}.perturbs", "mixes lengths and angles")
        kind = kinds.pop()
        unit = r.unit(r.get(raw, "unit", where), f"{where}.unit", kind)
        k = r.get(raw, "k", where, float)
        if k <= 0:
            raise r.fail(f"{where}.k", f"cost factor must be > 0, got {k}")
        lo, hi = r.pair(r.get(raw, "bounds", where), f"{where}.bounds")
        if lo <= 0:
            raise r.fail(f"{where}.bounds", f"lower bound must be > 0 (cost eps**-alpha), got {lo}")
        eparams.append(
            ErrorParameter(
                name=pname,
                perturbs=tuple(perturbs),
                unit=unit,
                scale=to_base(unit),
                k=k,
                lower=lo,
                upper=hi,
                label=raw.get("label", pname),
                alias=alias,
                kind=kind,
            )
        )
    if not eparams:
        raise r.fail("error_parameters", "at least one error parameter is needed")
    by_name = {p.name: p for p in eparams}
    by_name.update({p.alias: p for p in eparams if p.alias})

    # ---- tolerance sets ---------------------------------------------------------------------
    tolerance_sets = {}
    for sname, raw in data.get("tolerance_sets", {}).items():
        where = f"tolerance_sets.{sname}"
        values = {}
        for key, value in raw.items():
            if key not in by_name:
                raise r.fail(f"{where}.{key}", f"unknown error parameter (known: {[p.name for p in eparams]})")
            par = by_name[key]
            if isinstance(value, dict):
                v = r.get(value, "value", f"{where}.{key}", float)
                u = r.unit(r.get(value, "unit", f"{where}.{key}"), f"{where}.{key}.unit", par.kind)
                v = v * to_base(u) / par.scale
            else:
                v = r.get(raw, key, where, float)
            if v < 0:
                raise r.fail(f"{where}.{key}", f"a tolerance must be >= 0, got {v}")
            values[par.name] = v
        missing = [p.name for p in eparams if p.name not in values]
        if missing:
            raise r.fail(where, f"missing tolerance(s) for {missing}")
        tolerance_sets[sname] = values

    # ---- reference results ------------------------------------------------------------------
    refs = []
    for i, raw in enumerate(data.get("reference_results", [])):
        where = f"reference_results[{i}]"
        tol = r.get(raw, "tolerances", where, list)
        if len(tol) != len(eparams):
            raise r.fail(f"{where}.tolerances", f"expected {len(eparams)} values, got {len(tol)}")
        dist = r.get(raw, "distribution", where, str)
        if dist not in ("uniform", "normal"):
            raise r.fail(f"{where}.distribution", f"expected 'uniform' or 'normal', got {dist!r}")
        refs.append(
            ReferenceResult(
                table=r.get(raw, "table", where, str),
                R=r.get(raw, "R", where, float),
                p=r.get(raw, "p", where, float),
                alpha=r.get(raw, "alpha", where, float),
                distribution=dist,
                tolerances=tuple(float(t) for t in tol),
            )
        )

    return MechanismSpec(
        name=name,
        title=title,
        source=source,
        assumptions=tuple(assumptions),
        path=r.path,
        convention=convention,
        base=base,
        tool=tool,
        links=tuple(links),
        symbols=symbols,
        symbol_kinds=symbol_kinds,
        joints=tuple(joints),
        loops=tuple(loops),
        joint_constraints=tuple(jcons),
        configurations=configurations,
        error_parameters=tuple(eparams),
        tolerance_sets=tolerance_sets,
        reference_results=tuple(refs),
        notes=notes,
    )
