"""Mechanism declarations: reading and validating the model files under ``models/``.

A model file is TOML and is *data*: the chain, loops, joints, configurations, error parameters and
tolerance sets of one mechanism, with its source and assumptions.  This module turns one into a
:class:`MechanismSpec` (plain, validated numbers in mm and rad), and :func:`load_model` wraps that
in a :class:`tolsynth.kinematics.mechanism.Mechanism`, which owns the CasADi graphs.

The format is documented in ``docs/model_format.md`` and in the header of each model
file; ``models/planar_2r.toml`` is the smallest complete example.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path
from typing import Any

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib  # type: ignore[no-redef]

from tolsynth.checks import P_MAX, P_MIN, TINY
from tolsynth.errors import UnknownNameError
from tolsynth.model.fields import _check_configurations, _nearest, _Reader, _tolerance_sets, _type_name, _unique
from tolsynth.model.parallel import _parse_parallel_model
from tolsynth.model.spec import (
    _LENGTH_FIELDS,
    CONVENTIONS,
    ELEMENTARY,
    Configuration,
    ErrorParameter,
    FourBarLoop,
    Joint,
    JointConstraint,
    Link,
    MechanismSpec,
    ReferenceResult,
)
from tolsynth.model.urdf import _parse_urdf_model
from tolsynth.units import to_base

__all__ = ["bundled_models", "model_path", "read_model_file"]


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
    return sorted(p.name[: -len(".toml")] for p in _models_dir().iterdir() if p.name.endswith(".toml"))


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


def read_model_file(path: str | os.PathLike) -> MechanismSpec:
    """Read and validate one model file.  Raises :class:`ModelFileError` on any defect."""
    path = Path(path)
    r = _Reader(str(path))
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as exc:
        raise r.fail("(file)", f"not valid TOML: {exc}") from None
    except UnicodeDecodeError as exc:
        raise r.fail("(file)", f"not UTF-8 text (TOML is UTF-8): {exc.reason} at byte {exc.start}") from None
    except RecursionError:
        raise r.fail("(file)", "nested too deeply") from None
    except OSError as exc:
        raise r.fail("(file)", f"cannot be read: {exc.strerror or exc}") from None
    return _parse(data, r)


def _parse(data: dict, r: _Reader) -> MechanismSpec:
    if isinstance(data, dict) and isinstance(data.get("chain"), dict) and "urdf" in data["chain"]:
        return _parse_urdf_model(data, r)
    if isinstance(data, dict) and "leg" in data:  # a parallel robot
        return _parse_parallel_model(data, r)
    r.table(data, "", "")
    name, title, source, assumptions, notes = r.model_table(data)
    lf, af = r.unit_factors(data)

    # ---- chain ------------------------------------------------------------------------------
    chain = r.table(data["chain"], "chain", "chain")
    convention = r.get(chain, "convention", "chain", str)
    if convention not in CONVENTIONS:
        raise r.fail(
            "chain.convention",
            f"unknown convention {convention!r}{_nearest(convention, CONVENTIONS)} (known: {', '.join(CONVENTIONS)})",
        )
    fields, _ = CONVENTIONS[convention]
    raw_symbols = r.table(data["symbols"], "symbols")
    symbol_kinds: dict[str, str] = {}

    def use_symbol(sym: Any, kind: str, where: str) -> str:
        if not isinstance(sym, str):
            raise r.fail(where, f"expected a symbol name (a key of [symbols]), got {_type_name(sym)}: {sym!r:.60}")
        if sym not in raw_symbols:
            raise r.fail(where, f"symbol {sym!r} is not declared in [symbols]{_nearest(sym, raw_symbols)}")
        previous = symbol_kinds.setdefault(sym, kind)
        if previous != kind:
            raise r.fail(where, f"symbol {sym!r} is used both as a {previous} and as a {kind}")
        return sym

    def elementary(items: Any, where: str) -> tuple[tuple[str, str], ...]:
        if not isinstance(items, list):
            raise r.fail(where, 'expected a list of one-key tables like { Tz = "s0" }')
        out = []
        for i, item in enumerate(items):
            if not isinstance(item, dict) or len(item) != 1:
                raise r.fail(f"{where}[{i}]", 'expected a one-key table like { Tz = "s0" }')
            ((op, sym),) = item.items()
            if op not in ELEMENTARY:
                raise r.fail(
                    f"{where}[{i}].{op}",
                    f"unknown transform{_nearest(op, ELEMENTARY)} (known: {', '.join(ELEMENTARY)})",
                )
            out.append((op, use_symbol(sym, ELEMENTARY[op], f"{where}[{i}].{op}")))
        return tuple(out)

    base = elementary(chain.get("base", []), "chain.base")
    tool = elementary(chain.get("tool", []), "chain.tool")
    raw_links = r.get(chain, "links", "chain", list)
    if not raw_links:
        raise r.fail("chain.links", "a chain needs at least one link")
    links = []
    link_keys = list(fields) + ["theta_offset", "name"]
    for i, raw in enumerate(raw_links):
        where = f"chain.links[{i}]"
        r.table(raw, where)
        for key in raw:
            if key not in link_keys:
                raise r.fail(
                    f"{where}.{key}",
                    f"field {key!r} does not belong to the {convention} D-H convention{_nearest(key, link_keys)} "
                    f"(its fields: {', '.join(fields)}, theta_offset, name)",
                )
        dims = {}
        for fname in fields:
            if fname == "theta":
                continue
            kind = "length" if fname in _LENGTH_FIELDS else "angle"
            dims[fname] = use_symbol(r.get(raw, fname, where), kind, f"{where}.{fname}")
        theta = r.get(raw, "theta", where, str)
        if "name" in raw:
            r.name(raw["name"], f"{where}.name")
        offset = raw.get("theta_offset")
        if offset is not None:
            offset = use_symbol(offset, "angle", f"{where}.theta_offset")
        links.append(Link(dims=dims, theta=theta, theta_offset=offset))

    # ---- joints -----------------------------------------------------------------------------
    joints = []
    raw_joints = r.tables(data["joints"], "joints", "joints")
    if not raw_joints:
        raise r.fail("joints", "at least one actuated joint is needed")
    for i, raw in enumerate(raw_joints):
        where = f"joints[{i}]"
        jname = r.get(raw, "name", where, str)
        lo, hi = r.pair(r.get(raw, "limits", where), f"{where}.limits")
        r.revolute_limits(lo * af, hi * af, f"{where}.limits")  # a link's theta: every joint here turns
        joints.append(Joint(jname, lo * af, hi * af))
    joint_names = [j.name for j in joints]
    _unique(r, joint_names, "joints", "joint name")

    # ---- loops ------------------------------------------------------------------------------
    loops = []
    for i, raw in enumerate(r.tables(data.get("loops", []), "loops", "loops")):
        where = f"loops[{i}]"
        kind = r.get(raw, "kind", where, str)
        if kind != "four_bar":
            raise r.fail(f"{where}.kind", f"unknown loop kind {kind!r}{_nearest(kind, ['four_bar'])} (known: four_bar)")
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
                raise r.fail(
                    f"{where}.{key}",
                    f"{getattr(loop, key)!r} is not an actuated joint "
                    f"{_nearest(getattr(loop, key), joint_names)}(joints: {joint_names})",
                )
        if loop.crank_angle == loop.ground_angle:
            raise r.fail(
                f"{where}.crank_angle",
                f"is the same joint as ground_angle ({loop.ground_angle!r}): the loop would not move",
            )
        if loop.passive_joint in joint_names:
            raise r.fail(f"{where}.passive_joint", f"{loop.passive_joint!r} is declared as an actuated joint")
        loops.append(loop)
    _unique(r, [lp.name for lp in loops], "loops", "loop name")
    passive = [lp.passive_joint for lp in loops]
    _unique(r, passive, "loops", "passive joint (one loop per passive joint)")
    for i, link in enumerate(links):
        if link.theta not in joint_names and link.theta not in passive:
            raise r.fail(
                f"chain.links[{i}].theta",
                f"{link.theta!r} is neither an actuated joint {joint_names} nor a loop's passive joint {passive}"
                + _nearest(link.theta, joint_names + passive),
            )
    _unique(r, [link.theta for link in links], "chain.links", "joint turned by a link (theta)")

    # ---- symbols: all used, all numbers -----------------------------------------------------
    symbols: dict[str, float] = {}
    for sym, value in raw_symbols.items():
        if sym not in symbol_kinds:
            raise r.fail(f"symbols.{sym}", "declared but not used by the chain or a loop")
        symbols[sym] = r.number(value, f"symbols.{sym}") * (lf if symbol_kinds[sym] == "length" else af)
    for loop in loops:
        for key in ("ground", "crank", "coupler", "lever"):
            if symbols[getattr(loop, key)] <= 0:
                raise r.fail(f"loops.{loop.name}.{key}", "a loop link length must be > 0")

    # ---- joint constraints ------------------------------------------------------------------
    jcons = []
    for i, raw in enumerate(r.tables(data.get("joint_constraints", []), "joint_constraints", "joint_constraints")):
        where = f"joint_constraints[{i}]"
        terms = r.table(r.get(raw, "terms", where), f"{where}.terms")
        if not terms:
            raise r.fail(f"{where}.terms", "names no joint")
        for jn, coef in terms.items():
            if jn not in joint_names:
                raise r.fail(
                    f"{where}.terms.{jn}", f"not an actuated joint{_nearest(jn, joint_names)} (joints: {joint_names})"
                )
            if r.number(coef, f"{where}.terms.{jn}") == 0:
                raise r.fail(f"{where}.terms.{jn}", "a coefficient of 0 (leave the joint out)")
        lo, hi = r.pair(r.get(raw, "limits", where), f"{where}.limits")
        r.revolute_limits(lo * af, hi * af, f"{where}.limits", sum(abs(float(v)) for v in terms.values()))
        jcons.append(
            JointConstraint(r.get(raw, "name", where, str), {k: float(v) for k, v in terms.items()}, lo * af, hi * af)
        )
    _unique(
        r, joint_names + [c.name for c in jcons], "joint_constraints", "name (joints and joint constraints share names)"
    )

    # ---- configurations ---------------------------------------------------------------------
    configurations = {}
    limit_names = set(joint_names) | {c.name for c in jcons}
    for cname, where, raw, values, note in r.configuration_tables(data, joint_names):
        q = tuple(v * af for v in values)
        waive = r.names(raw.get("waive", []), f"{where}.waive")
        for w in waive:
            if w not in limit_names:
                raise r.fail(f"{where}.waive", f"{w!r} names no joint or joint constraint{_nearest(w, limit_names)}")
        if waive and not note.strip():
            raise r.fail(f"{where}.note", "a configuration that waives a limit must say why in 'note'")
        configurations[cname] = Configuration(cname, q, note, tuple(waive))
    _check_configurations(r, configurations, joints, jcons)

    # ---- error parameters -------------------------------------------------------------------
    eparams = []
    seen: set[str] = set()
    raw_params = r.tables(data["error_parameters"], "error_parameters", "error_parameters")
    for i, raw in enumerate(raw_params):
        where = f"error_parameters[{i}]"
        pname = r.get(raw, "name", where, str)
        alias = r.get(raw, "alias", where, str, default=None)
        label = r.get(raw, "label", where, str, default=pname)
        for key, n in (("name", pname), ("alias", alias)):
            if n is not None and n in seen:
                raise r.fail(f"{where}.{key}", f"name {n!r} is used twice")
            if n is not None:
                seen.add(n)
        perturbs = r.names(r.get(raw, "perturbs", where), f"{where}.perturbs", allow_empty=False)
        kinds = set()
        for j, sym in enumerate(perturbs):
            if sym not in symbols:
                raise r.fail(f"{where}.perturbs[{j}]", f"{sym!r} is not a declared symbol{_nearest(sym, symbols)}")
            kinds.add(symbol_kinds[sym])
        if len(kinds) != 1:
            raise r.fail(f"{where}.perturbs", "mixes lengths and angles")
        kind = kinds.pop()
        unit = r.unit(r.get(raw, "unit", where), f"{where}.unit", kind)
        k = r.positive(raw["k"], f"{where}.k")
        lo, hi = r.pair(r.get(raw, "bounds", where), f"{where}.bounds")
        if lo < TINY:
            raise r.fail(f"{where}.bounds", f"lower bound must be > 0 (cost eps**-alpha), at least {TINY:g}, got {lo}")
        if kind == "angle":
            r.angle_tolerance(hi, unit, f"{where}.bounds")
        cost, procs, lock = _designer_fields(r, raw, where)
        if lock is not None and not lo <= lock <= hi:  # a lock is a tolerance: it must be one the bounds allow
            raise r.fail(f"{where}.lock", f"{lock:g} {unit} is outside the bounds; allowed: {lo:g} to {hi:g} {unit}")
        dist = r.get(raw, "distribution", where, default=None)
        if dist is not None:
            if not isinstance(dist, str):
                raise r.fail(f"{where}.distribution", f"expected a string, got {_type_name(dist)}")
            from tolsynth.errors import OutOfRangeError as _OOR
            from tolsynth.probability.distributions import shape

            try:
                dist = shape(dist).name
            except _OOR as exc:
                raise r.fail(f"{where}.distribution", f"got {dist!r}; allowed: {exc.allowed}") from None
        eparams.append(
            ErrorParameter(
                name=pname,
                perturbs=tuple(perturbs),
                unit=unit,
                scale=to_base(unit),
                k=k,
                lower=lo,
                upper=hi,
                label=label,
                alias=alias,
                kind=kind,
                cost=cost,
                processes=procs,
                lock=lock,
                distribution=dist,
            )
        )
    if not eparams:
        raise r.fail("error_parameters", "at least one error parameter is needed")

    # ---- tolerance sets ---------------------------------------------------------------------
    tolerance_sets = _tolerance_sets(r, data.get("tolerance_sets", {}), eparams)

    # ---- reference results ------------------------------------------------------------------
    refs = []
    for i, raw in enumerate(r.tables(data.get("reference_results", []), "reference_results", "reference_results")):
        where = f"reference_results[{i}]"
        tol = r.get(raw, "tolerances", where, list)
        if len(tol) != len(eparams):
            raise r.fail(f"{where}.tolerances", f"expected {len(eparams)} values, got {len(tol)}")
        tolerances = tuple(r.positive(t, f"{where}.tolerances[{j}]") for j, t in enumerate(tol))
        dist = r.get(raw, "distribution", where, str)
        if dist not in ("uniform", "normal"):
            raise r.fail(f"{where}.distribution", f"expected 'uniform' or 'normal', got {dist!r}")
        refs.append(
            ReferenceResult(
                table=r.get(raw, "table", where, str),
                R=r.positive(raw["R"], f"{where}.R"),
                p=r.number(raw["p"], f"{where}.p", P_MIN, P_MAX),
                alpha=r.positive(raw["alpha"], f"{where}.alpha"),
                distribution=dist,
                tolerances=tolerances,
            )
        )

    spec = MechanismSpec(
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
    if "joint_errors" in data:
        spec = _joint_errors(r, data["joint_errors"], spec)
    return spec


def _joint_errors(r, raw, spec):
    """Append the ``[[joint_errors]]`` of a file as error parameters (tolsynth.model.joint_errors).

    The file's tolerance sets name the link parameters only and get each fixed joint error's
    value; its reference results (for the link errors alone) are dropped."""
    from tolsynth.errors import InputError
    from tolsynth.model.joint_errors import _parse_file_entries, add_joint_errors

    entries = _parse_file_entries(r, r.tables(raw, "joint_errors", "joint_errors"), spec)
    try:
        return add_joint_errors(spec, entries)
    except InputError as err:
        raise r.fail(err.field, str(err)) from None


def _designer_fields(r, raw: dict, where: str):
    """The optional cost model, processes and lock of one error parameter."""
    from tolsynth.errors import InputError
    from tolsynth.model.cost import cost_model
    from tolsynth.model.process import Process

    cost = procs = lock = None
    try:
        if "cost" in raw:
            cost = cost_model(r.get(raw, "cost", where, dict))
        if "processes" in raw:
            items = r.get(raw, "processes", where, list)
            if not items:
                raise r.fail(f"{where}.processes", "empty list")
            procs = tuple(Process.make(item) for item in items)
        if "lock" in raw:
            lock = r.positive(raw["lock"], f"{where}.lock")
    except InputError as err:
        raise r.fail(where, str(err)) from None
    return cost, procs or (), lock
