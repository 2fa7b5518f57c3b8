"""A robot from a URDF file: :func:`load_urdf`, and model files whose chain is a URDF.

The URDF is read with `yourdfpy <https://github.com/clemense/yourdfpy>`_ (the optional extra
``tolsynth[urdf]``), a maintained parser of the URDF schema that does not need the meshes.  The
serial chain from ``base_link`` to ``tip_link`` becomes a mechanism of convention ``"urdf"``:

* each movable joint (``revolute``, ``continuous``, ``prismatic``) is a link
  ``origin . A . J(q) . A^T`` where ``origin = Trans(x, y, z) . Rz(yaw) . Ry(pitch) . Rx(roll)``
  is the joint's ``<origin>`` (URDF's fixed-axis roll-pitch-yaw), ``A`` the constant rotation
  that turns z onto the joint's ``<axis>`` and ``J`` = Rz(q) (revolute: q in rad) or Tz(q)
  (prismatic: q in mm).  The CasADi graph is exact (tolsynth.kinematics.graphs, no finite differences);
* fixed joints are folded in: a fixed joint's origin is prepended to the next movable joint's
  origin, and the fixed joints after the last movable joint are the tool transform; their xyz and
  rpy are error parameters like any other origin's;
* joint limits are the file's (revolute: rad; prismatic: m -> mm); a ``continuous`` joint gets
  [-pi, pi] (every orientation once); any other type on the chain (floating, planar) and a mimic
  joint raise :class:`~tolsynth.errors.UnsupportedJointError` naming the joint.

Error parameters, one per number of each origin on the chain, named ``<joint>.<field>``:

``<joint>.x``, ``.y``, ``.z``
    the origin's translation, lengths (tolerance unit mm, k 1, bounds 0.001-5 mm by default);
``<joint>.roll``, ``.pitch``, ``.yaw``
    the origin's rpy angles themselves (tolerance unit mrad, k 1.5, bounds 0.001-50 mrad);
``<joint>.tilt1``, ``.tilt2``
    movable joints only: small rotations of the joint axis about the two directions
    perpendicular to it (``A . Rx(tilt1) . Ry(tilt2)``), angles as above.

``errors`` selects them by name or shell pattern; ``.xyz``, ``.rpy`` and ``.axis`` stand for the
three (two) fields of a group: ``["*.xyz", "elbow_joint.rpy", "*.axis"]``.  The default
``["*.xyz", "*.rpy"]`` leaves the axis tilts out.  Each pattern must select something.  An origin
at pitch = +-90 deg (UR arms' shoulder and wrist 1) has roll and yaw errors that turn about the
same axis (gimbal lock): both are kept as the file writes them; the synthesis prices both.

A model file may point at a URDF instead of writing the chain (see ``URDF_FORMAT``)::

    [model]
    name = "ur5_urdf"
    source = "ur5_robot.urdf from example-robot-data"
    assumptions = ["..."]
    [units]
    length = "mm"            # prismatic joints' values in [configurations]
    angle = "deg"            # revolute joints' values in [configurations]
    [chain]
    urdf = "ur5_robot.urdf"  # relative to this file
    base_link = "base_link"
    tip_link = "tool0"
    errors = ["*.xyz", "*.rpy"]
    k = { length = 1.0, angle = 1.5 }
    bounds = { length = [0.001, 5.0], angle = [0.001, 50.0] }
    tolerance_units = { length = "mm", angle = "mrad" }
    [configurations.worst]
    shoulder_pan_joint = 0.0
    ...
    [tolerance_sets.fine]
    "elbow_joint.z" = 0.02    # dotted names are quoted in TOML
"""

from __future__ import annotations

import fnmatch
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tolsynth.checks import is_real
from tolsynth.errors import InputError, MissingDependencyError, ModelFileError, UnsupportedJointError
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
)
from tolsynth.model.spec import Configuration, ErrorParameter, Joint, Link, MechanismSpec
from tolsynth.model.urdf_xml import _axis_angles, _chain, _origins, _rpy_matrix
from tolsynth.units import to_base

__all__ = ["urdf_spec", "URDF_FORMAT", "URDF_INSTALL", "ORIGIN_FIELDS", "AXIS_FIELDS", "GROUPS"]

URDF_INSTALL = 'pip install "tolsynth[urdf]"'
#: an origin's fields: (name, elementary transform, kind), in the order the transforms are applied
ORIGIN_FIELDS = (
    ("x", "Tx", "length"),
    ("y", "Ty", "length"),
    ("z", "Tz", "length"),
    ("yaw", "Rz", "angle"),
    ("pitch", "Ry", "angle"),
    ("roll", "Rx", "angle"),
)
#: a movable joint's axis tilts (after the rotation that turns z onto the axis)
AXIS_FIELDS = (("tilt1", "Rx", "angle"), ("tilt2", "Ry", "angle"))
#: the error-parameter order of one joint, and the group suffixes a pattern may use
_ERROR_ORDER = ("x", "y", "z", "roll", "pitch", "yaw", "tilt1", "tilt2")
GROUPS = {"xyz": ("x", "y", "z"), "rpy": ("roll", "pitch", "yaw"), "axis": ("tilt1", "tilt2")}
DEFAULT_ERRORS = ("*.xyz", "*.rpy")
_MOVABLE = ("revolute", "continuous", "prismatic")

#: the keys of a model file whose chain is a URDF: True required, False optional
URDF_FORMAT: dict[str, dict[str, bool]] = {
    "": {"model": True, "units": True, "chain": True, "configurations": False, "tolerance_sets": False},
    "chain": {
        "urdf": True,
        "base_link": True,
        "tip_link": True,
        "errors": False,
        "k": False,
        "bounds": False,
        "tolerance_units": False,
    },
}
#: top-level tables of a D-H model file that a URDF chain replaces or does not support
_NOT_WITH_URDF = {
    "symbols": "the symbols come from the URDF's joint origins",
    "joints": "the joints and their limits come from the URDF",
    "error_parameters": "the error parameters are chain.errors (patterns over <joint>.x/y/z/roll/pitch/yaw/tilt1/tilt2)",
    "loops": "closed loops are not supported with a URDF chain",
    "joint_constraints": "joint constraints are not supported with a URDF chain",
    "joint_errors": "joint errors are not supported with a URDF chain",
    "reference_results": "reference results are not supported with a URDF chain",
}


def _yourdfpy():
    try:
        import yourdfpy
    except ImportError:
        raise MissingDependencyError("yourdfpy", "URDF import (tolsynth.load_urdf)", URDF_INSTALL) from None
    return yourdfpy


def urdf_spec(
    path: str | os.PathLike,
    base_link: str,
    tip_link: str,
    *,
    errors: str | Sequence[str] = DEFAULT_ERRORS,
    k: float | Mapping[str, float] | None = None,
    bounds: Sequence[float] | Mapping[str, Sequence[float]] | None = None,
    tolerance_units: str | Mapping[str, str] | None = None,
    configurations: Mapping[str, Any] | None = None,
    tolerance_sets: Mapping[str, Mapping[str, Any]] | None = None,
    length_unit: str = "mm",
    angle_unit: str | None = None,
    name: str | None = None,
    title: str | None = None,
    source: str | None = None,
    assumptions: Sequence[str] = (),
):
    """The model of the serial chain ``base_link -> tip_link`` of a URDF, for :func:`tolsynth.load_urdf`.

    Parameters
    ----------
    path : path of the ``.urdf`` file (meshes are not needed).
    base_link, tip_link : str
        Link names; ``tip_link`` must descend from ``base_link``.  The hand point is the origin of
        ``tip_link``'s frame, expressed in ``base_link``'s frame (mm).
    errors : str or list of str
        Error parameters by name or shell pattern over ``<joint>.<field>`` (module docstring);
        ``.xyz``, ``.rpy`` and ``.axis`` expand to their fields.  ``"all"`` selects every field
        including the axis tilts.  Default ``["*.xyz", "*.rpy"]``.
    k, bounds, tolerance_units
        Cost factor, default bounds (in the tolerance unit) and tolerance unit: one value for all
        or a dict keyed by ``"length"``, ``"angle"`` or parameter names (as in
        :func:`tolsynth.Mechanism.from_dh`).  Defaults: mm and mrad, k 1 and 1.5, bounds
        0.001-5 mm and 0.001-50 mrad, converted into the tolerance unit chosen (um: 1-5000).
    configurations : dict, optional
        Name -> joint values: a list in joint order or a dict joint name -> value (with optional
        ``note``); revolute joints in ``angle_unit``, prismatic in ``length_unit``.  Each must lie
        inside the joint limits (a configuration outside them is an error naming it).
        A configuration ``"zero"`` (every joint at 0, or at the middle of its range when 0 is
        outside it) is added unless given.
    tolerance_sets : dict, optional
        Name -> {parameter: tolerance in its unit}.
    length_unit, angle_unit : str
        Units of the numbers given here (the configurations), as a model file's ``[units]``:
        default mm and rad, the package's units (docs/units.md).  The URDF itself is read in its
        own units (m, rad).  Without ``angle_unit``, a configuration angle beyond 2 pi is an error
        (degrees meant?): say ``angle_unit="deg"``, or ``"rad"`` to confirm.
    name, title, source, assumptions : str
        Recorded on the mechanism; by default the robot's name and the file.

    Raises
    ------
    MissingDependencyError
        yourdfpy is not installed (``pip install "tolsynth[urdf]"``).
    ModelFileError
        An unreadable URDF, an unknown link, a pattern that selects nothing, a bad bound...; the
        field is the argument (``base_link``, ``errors[1]``, ``k[length]``).
    UnsupportedJointError
        A floating, planar or mimic joint on the chain (names the joint).
    """
    _check_arguments(path, errors, configurations, tolerance_sets, assumptions, name, title, source)
    angle_given = angle_unit is not None
    angle_unit = "rad" if angle_unit is None else angle_unit
    chain: dict[str, Any] = {"urdf": os.fspath(Path(path).resolve()), "base_link": base_link, "tip_link": tip_link}
    chain["errors"] = [errors] if isinstance(errors, str) else list(errors)
    for key, value in (("k", k), ("bounds", bounds), ("tolerance_units", tolerance_units)):
        if value is not None:
            chain[key] = dict(value) if isinstance(value, Mapping) else value
    raw_conf: dict[str, Any] = {}
    for cname, value in (configurations or {}).items():
        raw_conf[cname] = dict(value) if isinstance(value, Mapping) else {"__list__": list(value)}
    data = {
        "model": {"name": name, "title": title, "source": source, "assumptions": list(assumptions)},
        "units": {"length": length_unit, "angle": angle_unit},
        "chain": chain,
        "configurations": raw_conf,
        "tolerance_sets": {s: dict(v) for s, v in (tolerance_sets or {}).items()},
        "angle_unit_given": angle_given,
    }
    r = _Reader(os.fspath(path))
    try:
        spec = _parse_urdf_model(data, r, python=True)
    except UnsupportedJointError:
        raise
    except ModelFileError as err:  # name the argument, not the model-file key
        field = err.field[len("chain.") :] if err.field.startswith("chain.") else err.field
        raise ModelFileError(err.path, field, str(err).split(": ", 2)[-1]) from None
    return spec


def _check_arguments(path, errors, configurations, tolerance_sets, assumptions, name, title, source) -> None:
    """The shape of load_urdf's arguments (their values are checked by the model-file reader)."""
    if not isinstance(path, (str, os.PathLike)):
        raise InputError(
            "path", f"got {type(path).__name__}: {path!r:.60}", "the path of a .urdf file (str or os.PathLike)"
        )
    if not isinstance(errors, str) and (
        isinstance(errors, (bytes, Mapping))
        or not isinstance(errors, Sequence)
        or not all(isinstance(e, str) for e in errors)
    ):
        raise InputError(
            "errors", f"got {errors!r:.60}", "a pattern or a list of patterns such as ['*.xyz', '*.rpy'] or 'all'"
        )
    for argname, value in (("configurations", configurations), ("tolerance_sets", tolerance_sets)):
        if value is not None and not isinstance(value, Mapping):
            raise InputError(
                argname,
                f"expected a dict, got {type(value).__name__}: {value!r:.60}",
                "a dict name -> "
                + (
                    "joint values (a list in joint order, or a dict joint -> value)"
                    if argname == "configurations"
                    else "{parameter: tolerance}"
                ),
            )
    for cname, value in (configurations or {}).items():
        ok = isinstance(value, Mapping) or (
            isinstance(value, (Sequence, np.ndarray))
            and not isinstance(value, (str, bytes))
            and all(is_real(v) for v in np.asarray(value, dtype=object).ravel())
        )
        if not ok:
            raise InputError(
                f"configurations[{cname}]",
                f"got {value!r:.60}",
                "a list of joint values in joint order, or a dict joint name -> value",
            )
    for sname, value in (tolerance_sets or {}).items():
        if not isinstance(value, Mapping):
            raise InputError(f"tolerance_sets[{sname}]", f"got {value!r:.60}", "a dict parameter name -> tolerance")
    if (
        isinstance(assumptions, (str, bytes))
        or not isinstance(assumptions, Sequence)
        or not all(isinstance(a, str) for a in assumptions)
    ):
        raise InputError("assumptions", f"got {assumptions!r:.60}", "a list of strings")
    for argname, value in (("name", name), ("title", title), ("source", source)):
        if value is not None and not isinstance(value, str):
            raise InputError(argname, f"got {value!r:.60}", "a string")


def _angle_unit_guard(configurations: dict, motions: dict, joint_names: list) -> None:
    """Without an explicit ``angle_unit`` the numbers are radians; one beyond 2 pi reads like a
    degree, which would otherwise be taken silently as that many radians."""
    for cname, cfg in configurations.items():
        for jn, v in zip(joint_names, cfg.q):
            if motions[jn] == "revolute" and abs(v) > 2 * math.pi * (1 + 1e-9):
                raise InputError(
                    "angle_unit",
                    f"not given, and configurations[{cname}][{jn}] = {v:g} is beyond 2 pi rad (degrees meant?)",
                    "angle_unit='deg' for values in degrees, or angle_unit='rad' to read them as radians",
                )


def _parse_urdf_model(data: dict, r: _Reader, python: bool = False) -> MechanismSpec:
    """A model file (or :func:`load_urdf`'s arguments) whose ``[chain]`` names a URDF."""
    angle_given = data.pop("angle_unit_given", True) if python else True
    for key in data:
        if key in _NOT_WITH_URDF:
            raise r.fail(key, f"not allowed with chain.urdf: {_NOT_WITH_URDF[key]}")
    spec_keys = URDF_FORMAT[""]
    for key in data:
        if key not in spec_keys:
            near = _nearest(key, list(spec_keys) + list(_NOT_WITH_URDF))
            raise r.fail(str(key), f"unknown key{near} (allowed with chain.urdf: {', '.join(spec_keys)})")
    r.keys(data, "", list(spec_keys), [k for k, req in spec_keys.items() if req])
    chain = r.table(data["chain"], "chain", extra=())
    r.keys(chain, "chain", list(URDF_FORMAT["chain"]), [k for k, req in URDF_FORMAT["chain"].items() if req])
    lf, af = r.unit_factors(data)

    # ---- the file ---------------------------------------------------------------------------
    file = r.name(chain["urdf"], "chain.urdf")
    if not python:
        file = os.fspath(Path(r.path).parent / file)
    if not Path(file).is_file():
        raise r.fail("chain.urdf", f"no URDF file at {file!r}")
    yourdfpy = _yourdfpy()
    rr = _Reader(file)  # defects of the URDF itself name the URDF file
    try:
        raw_origins = _origins(file, rr)  # the tree checked before yourdfpy reads it
        urdf = yourdfpy.URDF.load(
            file,
            build_scene_graph=False,
            build_collision_scene_graph=False,
            load_meshes=False,
            load_collision_meshes=False,
        )
    except ModelFileError:
        raise
    except Exception as exc:  # yourdfpy/lxml raise many kinds on a malformed file
        raise rr.fail("(file)", f"not a readable URDF: {type(exc).__name__}: {exc}") from None
    joints_urdf = _chain(urdf.robot, chain["base_link"], chain["tip_link"], r, "chain")

    # ---- the chain: symbols, links, joints --------------------------------------------------
    symbols: dict[str, float] = {}
    kinds: dict[str, str] = {}
    selectable: dict[str, str] = {}  # error-parameter candidates -> kind, in chain order
    labels: dict[str, str] = {}
    links: list[Link] = []
    joints: list[Joint] = []
    motions: dict[str, str] = {}
    pending: list[tuple[str, str]] = []  # origins of fixed joints not yet folded into a link
    for joint in joints_urdf:
        jn = joint.name
        if joint.type not in _MOVABLE + ("fixed",):
            raise UnsupportedJointError(
                file,
                jn,
                joint.type,
                f"type {joint.type!r} is not supported on the chain (supported: fixed, {', '.join(_MOVABLE)})",
            )
        if joint.mimic is not None and joint.type != "fixed":
            raise UnsupportedJointError(
                file, jn, joint.type, "a mimic joint is not supported (its value follows another joint)"
            )
        xyz, rpy, raw_axis = raw_origins[jn]
        composed = _rpy_matrix(xyz, rpy)
        reference = np.asarray(joint.origin if joint.origin is not None else np.eye(4), float)
        if not np.allclose(composed, reference, rtol=0, atol=1e-9):  # the file's numbers are yourdfpy's
            raise rr.fail(f"joint {jn!r}", "origin read differently by yourdfpy and by tolsynth")
        values = dict(zip(("x", "y", "z"), (v * 1000.0 for v in xyz)))
        values.update(roll=rpy[0], pitch=rpy[1], yaw=rpy[2])
        origin = []
        for fname, op, kind in ORIGIN_FIELDS:
            sym = f"{jn}.{fname}"
            symbols[sym], kinds[sym] = values[fname], kind
            origin.append((op, sym))
        for fname in _ERROR_ORDER[:6]:
            selectable[f"{jn}.{fname}"] = kinds[f"{jn}.{fname}"]
            labels[f"{jn}.{fname}"] = f"{jn} origin {fname}"
        pending.extend(origin)
        if joint.type == "fixed":
            continue
        axis = np.asarray(raw_axis, float)
        big = float(np.max(np.abs(axis)))
        norm = big * float(np.linalg.norm(axis / big)) if big > 0 else 0.0  # no overflow at 1e308
        if not (math.isfinite(norm) and norm > 1e-12):
            raise rr.fail(f"joint {jn!r}", f"axis {list(raw_axis)} has no direction")
        phi, theta = _axis_angles(axis / big / (norm / big))
        axis_ops = []
        for fname, value in (("axis_phi", phi), ("axis_theta", theta)):
            sym = f"{jn}.{fname}"
            symbols[sym], kinds[sym] = value, "angle"
            axis_ops.append(("Rz" if fname == "axis_phi" else "Ry", sym))
        for fname, op, kind in AXIS_FIELDS:
            sym = f"{jn}.{fname}"
            symbols[sym], kinds[sym] = 0.0, kind
            axis_ops.append((op, sym))
            selectable[sym] = kind
            labels[sym] = f"{jn} axis {fname}"
        motion = "prismatic" if joint.type == "prismatic" else "revolute"
        links.append(
            Link(dims={}, theta=jn, theta_offset=None, origin=tuple(pending), axis=tuple(axis_ops), motion=motion)
        )
        pending = []
        motions[jn] = motion
        if joint.type == "continuous":
            lo, hi = -math.pi, math.pi
        else:
            lim = joint.limit
            if lim is None or lim.lower is None or lim.upper is None:
                raise rr.fail(f"joint {jn!r}", f"a {joint.type} joint needs <limit lower=.. upper=..>")
            lo, hi = float(lim.lower), float(lim.upper)
            if motion == "prismatic":
                lo, hi = lo * 1000.0, hi * 1000.0
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise rr.fail(f"joint {jn!r}", f"limits lower {lim.lower} must be below upper {lim.upper}")
            if motion != "prismatic":
                rr.revolute_limits(lo, hi, f"joint {jn!r} limits")
        joints.append(Joint(jn, lo, hi))
    if not joints:
        raise r.fail(
            "chain.tip_link", f"the chain {chain['base_link']!r} -> {chain['tip_link']!r} has no movable joint"
        )
    tool = tuple(pending)
    joint_names = [j.name for j in joints]

    # ---- error parameters -------------------------------------------------------------------
    patterns = chain.get("errors", list(DEFAULT_ERRORS))
    if isinstance(patterns, str):
        patterns = [patterns]
    patterns = r.names(patterns, "chain.errors", allow_empty=False)
    chosen: set[str] = set()
    for i, pat in enumerate(patterns):
        if pat == "all":
            hit = set(selectable)
        else:
            head, _, group = pat.rpartition(".")
            expanded = [f"{head}.{f}" for f in GROUPS[group]] if head and group in GROUPS else [pat]
            hit = {n for n in selectable for e in expanded if fnmatch.fnmatchcase(n, e)}
        if not hit:
            raise r.fail(
                f"chain.errors[{i}]",
                f"{pat!r} selects no error parameter{_nearest(pat, selectable)} "
                "(names are <joint>.x/y/z/roll/pitch/yaw/tilt1/tilt2; groups .xyz .rpy .axis)",
            )
        chosen |= hit
    order = [n for n in selectable if n in chosen]  # chain order, per joint x y z roll pitch yaw tilt1 tilt2
    sel = {n: selectable[n] for n in order}
    try:
        ks = _by_kind(chain.get("k"), "chain.k", DEFAULT_K, sel)
        us = _by_kind(chain.get("tolerance_units"), "chain.tolerance_units", DEFAULT_TOLERANCE_UNITS, sel)
        bs = _bounds_by_kind(chain.get("bounds"), "chain.bounds", us, sel)
    except InputError as err:
        raise r.fail(err.field, str(err).split(": ", 1)[-1]) from None
    eparams = []
    for n, kind in sel.items():
        unit = r.unit(us[n], f"chain.tolerance_units[{n}]", kind)
        b = bs[n]
        lo, hi = r.pair(list(b) if isinstance(b, (list, tuple)) else b, f"chain.bounds[{n}]")
        if lo <= 0:
            raise r.fail(f"chain.bounds[{n}]", f"the lower bound must be > 0 (cost eps**-alpha), got {lo}")
        if kind == "angle":
            r.angle_tolerance(hi, unit, f"chain.bounds[{n}]")
        eparams.append(
            ErrorParameter(
                name=n,
                perturbs=(n,),
                unit=unit,
                scale=to_base(unit),
                k=r.positive(ks[n], f"chain.k[{n}]"),
                lower=lo,
                upper=hi,
                label=labels[n],
                kind=kind,
            )
        )

    # ---- configurations ---------------------------------------------------------------------
    configurations: dict[str, Configuration] = {}
    raw_conf = r.table(data.get("configurations", {}), "configurations")
    for cname, raw in raw_conf.items():
        where = f"configurations.{cname}"
        r.table(raw, where)
        note = raw.get("note", "")
        if not isinstance(note, str):
            raise r.fail(f"{where}.note", f"expected a string, got {_type_name(note)}")
        if "__list__" in raw:  # load_urdf: a list in joint order
            values = raw["__list__"]
            if len(values) != len(joint_names):
                raise r.fail(where, f"expected {len(joint_names)} joint values {joint_names}, got {len(values)}")
            raw = dict(zip(joint_names, values))
        for key in raw:
            if key not in joint_names and key != "note":
                raise r.fail(
                    f"{where}.{key}", f"not a joint of the chain{_nearest(key, joint_names)} (joints: {joint_names})"
                )
        missing = [j for j in joint_names if j not in raw]
        if missing:
            raise r.fail(where, f"missing joint value(s) {missing}")
        q = tuple(r.number(raw[j], f"{where}.{j}") * (lf if motions[j] == "prismatic" else af) for j in joint_names)
        configurations[cname] = Configuration(cname, q, note)
    if not angle_given:
        _angle_unit_guard(configurations, motions, joint_names)
    _check_configurations(r, configurations, joints)
    if "zero" not in configurations:
        q0 = tuple(0.0 if j.lower <= 0.0 <= j.upper else 0.5 * (j.lower + j.upper) for j in joints)
        configurations["zero"] = Configuration(
            "zero", q0, "every joint at 0 (at mid-range where 0 is outside its limits)"
        )

    # ---- model ------------------------------------------------------------------------------
    meta = r.table(data["model"], "model", "model")
    robot = urdf.robot.name or Path(file).stem
    name = meta.get("name") or robot
    r.name(name, "model.name")
    chain_text = f"{chain['base_link']} -> {chain['tip_link']}"
    source = meta.get("source") or f"URDF file {Path(file).name} (robot {robot!r}), chain {chain_text}"
    r.name(source, "model.source")
    title = meta.get("title") or f"{robot} from its URDF ({chain_text})"
    assumptions = list(meta.get("assumptions") or [])
    for i, a in enumerate(assumptions):
        r.name(a, f"model.assumptions[{i}]")
    assumptions.append(
        f"Chain {chain_text} of {Path(file).name}: {len(joints)} movable joints ({', '.join(joint_names)}), each "
        "origin Trans(xyz) . Rz(yaw) . Ry(pitch) . Rx(roll) then the motion about/along its axis; fixed joints folded "
        f"into the next origin (or the tool); hand point = origin of {chain['tip_link']!r} in {chain['base_link']!r}'s frame; "
        f"{len(eparams)} error parameters ({', '.join(patterns)})."
    )
    spec = MechanismSpec(
        name=name,
        title=title,
        source=source,
        assumptions=tuple(assumptions),
        path=r.path,
        convention="urdf",
        base=(),
        tool=tool,
        links=tuple(links),
        symbols=symbols,
        symbol_kinds=kinds,
        joints=tuple(joints),
        loops=(),
        joint_constraints=(),
        configurations=configurations,
        error_parameters=tuple(eparams),
        tolerance_sets={},
        notes=str(meta.get("notes", "")),
    )
    sets = _tolerance_sets(r, data.get("tolerance_sets", {}), eparams)
    from dataclasses import replace

    return replace(spec, tolerance_sets=sets)
