"""A robot from a Denavit-Hartenberg table in Python, without a model file.

:func:`from_dh` (also ``tolsynth.Mechanism.from_dh``) builds the same raw table a TOML model file
would hold and passes it through the model-file parser (:func:`tolsynth.model.reader._parse`), so there
is one copy of the validation: a bad value is the same :class:`~tolsynth.errors.ModelFileError`,
with the field renamed to the argument of ``from_dh`` that gave it (``links[1].a``, ``k[a2]``,
``configurations[home]``).  Only the shape of the arguments (which keys a link may have, which
names a pattern selects) is checked here.

>>> import tolsynth
>>> arm = tolsynth.Mechanism.from_dh(
...     links=[{"a": 500.0, "limits": (-170, 170)}, {"a": 300.0, "limits": (-150, 150)}],
...     name="two_link", configurations={"bent": [30.0, 90.0]}, angle_unit="deg")
>>> arm.fk("bent")[:3, 3].round(3)
array([283.013, 509.808,   0.   ])
>>> arm.error_parameters
('a1', 'd1', 'alpha1', 'o1', 'a2', 'd2', 'alpha2', 'o2')

Symbols are named by field and link number (1-based): ``a2`` is link 2's length ``a``, ``o2`` its
joint zero offset; base and tool transforms are ``base1, base2, ...`` and ``tool1, ...``.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tolsynth.errors import InputError, ModelFileError, UnknownNameError
from tolsynth.model.fields import DEFAULT_K, DEFAULT_TOLERANCE_UNITS, _bounds_by_kind, _by_kind, _nearest, _Reader
from tolsynth.model.reader import _parse
from tolsynth.model.spec import CONVENTIONS, ELEMENTARY

__all__ = ["dh_spec"]

#: per convention: the D-H fields of a link in the error-parameter order (lengths, then the twist),
#: and the other names a link may use for them (the Robotics Toolbox writes a and d for the
#: modified convention's h and s)
_FIELDS = {
    "standard": (("a", "length"), ("d", "length"), ("alpha", "angle")),
    "modified": (("h", "length"), ("s", "length"), ("alpha", "angle")),
}
_ALIASES = {"standard": {}, "modified": {"a": "h", "d": "s"}}
_LINK_KEYS = ("offset", "limits", "name")


def _plain(value: Any) -> Any:
    """NumPy scalars and arrays as plain Python values (the parser checks Python types)."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, tuple):
        return [_plain(v) for v in value]
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


def dh_spec(
    links: Sequence[Mapping[str, Any]],
    convention: str = "standard",
    *,
    name: str = "dh_robot",
    title: str | None = None,
    length_unit: str = "mm",
    angle_unit: str | None = None,
    base: Sequence[tuple[str, float]] = (),
    tool: Sequence[tuple[str, float]] = (),
    errors: str | Sequence[str] = "all",
    k: float | Mapping[str, float] | None = None,
    bounds: Sequence[float] | Mapping[str, Sequence[float]] | None = None,
    tolerance_units: str | Mapping[str, str] | None = None,
    configurations: Mapping[str, Any] | None = None,
    tolerance_sets: Mapping[str, Mapping[str, Any]] | None = None,
    source: str = "tolsynth.Mechanism.from_dh (a D-H table given in Python)",
    assumptions: Sequence[str] = (),
):
    """The model of a D-H table (serial, revolute joints), for :func:`tolsynth.Mechanism.from_dh`.

    Parameters
    ----------
    links : list of dict
        One dict per link, base to hand.  ``convention="standard"``: ``d``, ``a``, ``alpha``
        (each link is ``Rz(theta) . Tz(d) . Tx(a) . Rx(alpha)``); ``"modified"`` (Craig):
        ``h`` (or ``a``), ``alpha``, ``s`` (or ``d``) for ``Tx(h) . Rx(alpha) . Tz(s) . Rz(theta)``.
        A field left out is 0.  Also ``limits = (lower, upper)`` of the joint (required), ``offset``
        (the joint's zero offset, added to theta; default 0) and ``name`` of the joint (default
        ``q1``, ``q2``, ...).  Lengths in ``length_unit``, angles in ``angle_unit``.
    convention : "standard" or "modified"
    name, title, source, assumptions : str
        Recorded as a model file's ``[model]`` table; a generated line on the convention, the
        hand point and the error parameters is appended to ``assumptions``.
    length_unit, angle_unit : str
        Units of the numbers given here (D-H values, base/tool, limits, configurations): ``"mm"``,
        ``"m"``, ... and ``"deg"``, ``"rad"``, ...; default mm and rad, the package's units (one
        rule for the API, the model builders and the command line: docs/units.md).  Without
        ``angle_unit``, an angle beyond 2 pi (a twist of 90, limits of 170) reads like degrees
        and is an error asking for ``angle_unit="deg"`` (or ``"rad"`` to confirm) instead of
        being taken as that many radians.
    base, tool : list of (transform, value) or (transform, value, name)
        Elementary transforms before the first and after the last link, e.g.
        ``[("Tz", 107.0, "flange")]``; transforms ``Tx Ty Tz Rx Ry Rz``.  Their symbols are the
        names given, else ``base1, ...``, ``tool1, ...``.
    errors : "all" or list of str
        The error parameters: ``"all"`` (every D-H length, twist and joint offset, and every base
        and tool value), or symbol names and shell patterns (``["a*", "d*", "o2"]``) each of which
        must select at least one symbol.  Each perturbs its own symbol.
    k, bounds, tolerance_units
        Cost factor (> 0), default tolerance bounds ``(lower, upper)`` and tolerance unit of the
        error parameters: one value for all, or a dict with keys ``"length"``, ``"angle"`` and/or
        parameter names (a name wins over its kind).  Defaults: k 1 (lengths) and 1.5 (angles);
        units mm and mrad; bounds 0.001-5 mm and 0.001-50 mrad, physical quantities converted into
        the tolerance unit chosen (um: 1-5000 um; deg: 5.73e-5 to 2.865 deg).  Bounds given are
        in the tolerance unit.
    configurations : dict, optional
        Name -> joint values (a list in joint order, in ``angle_unit``) or a dict of joint name ->
        value with optional ``note`` and ``waive`` (as in a model file).
    tolerance_sets : dict, optional
        Name -> {parameter: half-width in its tolerance unit}, as in a model file.

    Raises
    ------
    InputError, UnknownNameError
        A malformed argument: a link that is not a dict, a key a link cannot have, a pattern of
        ``errors`` that selects nothing, an unknown key of ``k``/``bounds``/``tolerance_units``.
    ModelFileError
        A bad or missing value (a link without limits), found by the model-file parser; its field names the argument
        (``links[1].a``, ``links[0].limits``, ``k[a2]``, ``configurations[home]``).
    """
    angle_given = angle_unit is not None
    angle_unit = "rad" if angle_unit is None else angle_unit
    if not isinstance(convention, str) or convention not in CONVENTIONS:
        raise InputError(
            "convention",
            f"unknown convention {convention!r}{_nearest(str(convention), CONVENTIONS)}",
            " or ".join(CONVENTIONS),
        )
    if isinstance(links, (str, bytes, Mapping)) or not isinstance(links, Sequence) or not links:
        raise InputError("links", "expected a non-empty list of dicts, one per link", "a list of dicts")
    fields = _FIELDS[convention]
    aliases = _ALIASES[convention]
    allowed = [f for f, _ in fields] + list(aliases) + list(_LINK_KEYS)

    symbols: dict[str, Any] = {}
    kinds: dict[str, str] = {}
    origin: dict[str, str] = {}  # raw-table field -> from_dh argument, for the error messages
    chain_links, joints = [], []
    for i, link in enumerate(links):
        where = f"links[{i}]"
        if not isinstance(link, Mapping):
            raise InputError(
                where, f"expected a dict of D-H fields, got {type(link).__name__}", "a dict with " + ", ".join(allowed)
            )
        values: dict[str, Any] = {}
        for key, value in link.items():
            if key not in allowed:
                raise UnknownNameError(
                    f"{where}.{key}",
                    f"not a field of a {convention} D-H link{_nearest(str(key), allowed)}",
                    ", ".join(allowed),
                )
            field = aliases.get(key, key)
            if field in values:
                raise InputError(
                    f"{where}.{key}",
                    f"{field!r} given twice (as {field!r} and by its alias)",
                    "one of " + " or ".join([field] + [a for a, f in aliases.items() if f == field]),
                )
            values[field] = (key, value)
        n = i + 1
        joint = _plain(values["name"][1]) if "name" in values else f"q{n}"
        raw_link: dict[str, Any] = {"theta": joint}
        for field, kind in fields:
            sym = f"{field}{n}"
            key, value = values.get(field, (field, 0.0))
            symbols[sym], kinds[sym] = _plain(value), kind
            origin[f"symbols.{sym}"] = f"{where}.{key}"
            raw_link[field] = sym
        sym = f"o{n}"
        symbols[sym], kinds[sym] = _plain(values.get("offset", ("offset", 0.0))[1]), "angle"
        origin[f"symbols.{sym}"] = f"{where}.offset"
        raw_link["theta_offset"] = sym
        chain_links.append(raw_link)
        # limits left out: the model-file parser's own ModelFileError (renamed links[i].limits below)
        joints.append({"name": joint, **({"limits": _plain(values["limits"][1])} if "limits" in values else {})})
        origin[f"joints[{i}]"] = where
        origin[f"chain.links[{i}]"] = where

    raw_chain: dict[str, Any] = {"convention": convention, "links": chain_links}
    for part, items in (("base", base), ("tool", tool)):
        if isinstance(items, (str, bytes, Mapping)) or not isinstance(items, Sequence):
            raise InputError(part, "expected a list of (transform, value) pairs", "e.g. [('Tz', 100.0)]")
        out = []
        for j, item in enumerate(items):
            if (
                isinstance(item, (str, bytes))
                or not isinstance(item, Sequence)
                or len(item) not in (2, 3)
                or item[0] not in ELEMENTARY
            ):
                raise InputError(
                    f"{part}[{j}]",
                    f"expected (transform, value) or (transform, value, name), got {item!r:.60}",
                    "transform one of " + ", ".join(ELEMENTARY),
                )
            sym = item[2] if len(item) == 3 else f"{part}{j + 1}"
            if not isinstance(sym, str) or not sym.strip():
                raise InputError(
                    f"{part}[{j}]", f"the name must be a non-empty string, got {sym!r:.60}", "a symbol name"
                )
            if sym in symbols:
                raise InputError(f"{part}[{j}]", f"name {sym!r} is already a symbol", "a name not used by the links")
            symbols[sym], kinds[sym] = _plain(item[1]), ELEMENTARY[item[0]]
            origin[f"symbols.{sym}"] = f"{part}[{j}]"
            out.append({item[0]: sym})
        if out:
            raw_chain[part] = out
    base_syms = [next(iter(t.values())) for t in raw_chain.get("base", [])]

    # ---- error parameters: a selection of the symbols ----------------------------------------
    if isinstance(errors, str):
        errors = [errors]
    if isinstance(errors, (bytes, Mapping)) or not isinstance(errors, Sequence) or not errors:
        raise InputError(
            "errors", "expected 'all' or a non-empty list of symbol names/patterns", "'all' or e.g. ['a*', 'd*', 'o2']"
        )
    order = base_syms + [s for s in symbols if s not in base_syms]  # base, links, tool
    selected: list[str] = []
    for j, pattern in enumerate(errors):
        if not isinstance(pattern, str):
            raise InputError(
                f"errors[{j}]", f"expected a string, got {type(pattern).__name__}", "a symbol name or pattern"
            )
        hits = order if pattern == "all" else [s for s in order if fnmatch.fnmatchcase(s, pattern)]
        if not hits:
            raise UnknownNameError(
                f"errors[{j}]",
                f"{pattern!r} selects no symbol{_nearest(pattern, order)}",
                "'all' or names/patterns of " + ", ".join(order),
            )
        selected += [s for s in hits if s not in selected]
    selected = [s for s in order if s in selected]  # link order, whatever the pattern order
    sel_kinds = {s: kinds[s] for s in selected}
    k_of = _by_kind(_plain(k), "k", DEFAULT_K, sel_kinds)
    units_of = _by_kind(tolerance_units, "tolerance_units", DEFAULT_TOLERANCE_UNITS, sel_kinds)
    if bounds is None or isinstance(bounds, Mapping):
        bounds_of = _bounds_by_kind(bounds, "bounds", units_of, sel_kinds)
    else:
        bounds_of = {s: bounds for s in selected}
    raw_errors = []
    for i, sym in enumerate(selected):
        raw_errors.append(
            {"name": sym, "perturbs": [sym], "unit": units_of[sym], "k": k_of[sym], "bounds": _plain(bounds_of[sym])}
        )
        for key, arg in (("unit", "tolerance_units"), ("k", "k"), ("bounds", "bounds")):
            origin[f"error_parameters[{i}].{key}"] = f"{arg}[{sym}]"
        origin[f"error_parameters[{i}]"] = f"errors ({sym})"

    # ---- configurations ----------------------------------------------------------------------
    joint_names = [jt["name"] for jt in joints]
    raw_configs: dict[str, Any] = {}
    for cname, value in (configurations or {}).items():
        origin[f"configurations.{cname}"] = f"configurations[{cname}]"
        value = _plain(value)
        if isinstance(value, Mapping):
            raw_configs[cname] = {key: _plain(v) for key, v in value.items()}
        elif isinstance(value, list) and len(value) == len(joint_names):
            raw_configs[cname] = dict(zip(joint_names, value))
        else:
            raise InputError(
                f"configurations[{cname}]",
                f"expected {len(joint_names)} joint values, got {value!r:.60}",
                f"a list of {len(joint_names)} values in {angle_unit} or a dict joint -> value",
            )

    if not angle_given:
        _degrees_guard(symbols, kinds, joints, raw_configs, joint_names)
    lines = [
        f"{convention.capitalize()} D-H chain {CONVENTIONS[convention][1]} for each of the {len(links)} links"
        + (", with a base transform" if base else "")
        + (", with a tool transform" if tool else "")
        + "; hand point = origin of the last frame"
        + (" after the tool" if tool else "")
        + ".",
        f"Error parameters: {', '.join(selected)}; each perturbs its own symbol.",
    ]
    data = {
        "model": {
            "name": name,
            "title": title if title is not None else name,
            "source": source,
            "assumptions": [*assumptions, *lines],
        },
        "units": {"length": length_unit, "angle": angle_unit},
        "symbols": symbols,
        "chain": raw_chain,
        "joints": joints,
        "configurations": raw_configs,
        "error_parameters": raw_errors,
    }
    if tolerance_sets is not None:
        data["tolerance_sets"] = {s: {p: _plain(v) for p, v in values.items()} for s, values in tolerance_sets.items()}
        for s in tolerance_sets:
            origin[f"tolerance_sets.{s}"] = f"tolerance_sets[{s}]"
    reader = _Reader(f"from_dh({name})")
    try:
        spec = _parse(data, reader)
    except ModelFileError as err:
        raise ModelFileError(reader.path, _rename(err.field, origin), _message(err)) from None
    return spec


def _degrees_guard(symbols, kinds, joints, raw_configs, joint_names) -> None:
    """Without an explicit ``angle_unit`` the angles are radians; one beyond 2 pi (a twist of 90,
    limits of 170) reads like a degree and would otherwise be taken silently as radians."""
    import math

    def big(v) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool) and abs(v) > 2 * math.pi * (1 + 1e-9)

    found = [f"{s} = {v:g}" for s, v in symbols.items() if kinds[s] == "angle" and big(v)]
    for jt in joints:
        lim = jt.get("limits")
        if isinstance(lim, list) and any(big(v) for v in lim):
            found.append(f"{jt['name']} limits {tuple(lim)}")
    for cname, raw in raw_configs.items():
        found += [f"configurations[{cname}][{j}] = {raw[j]:g}" for j in joint_names if j in raw and big(raw[j])]
    if found:
        raise InputError(
            "angle_unit",
            f"not given, and {found[0]} is beyond 2 pi rad (degrees meant?)",
            "angle_unit='deg' for a table in degrees, or angle_unit='rad' to read these numbers as radians",
        )


def _rename(field: str, origin: dict[str, str]) -> str:
    """The raw-table field of a parser error as the from_dh argument that gave it: the longest
    known prefix is replaced (``joints[0].limits`` -> ``links[0].limits``)."""
    best = ""
    for prefix in origin:
        if (field == prefix or field.startswith(prefix + ".") or field.startswith(prefix + "[")) and len(prefix) > len(
            best
        ):
            best = prefix
    return origin[best] + field[len(best) :] if best else field


def _message(err: ModelFileError) -> str:
    """The parser's message without its ``path: field:`` prefix."""
    text = str(err)
    prefix = f"{err.path}: {err.field}: "
    return text[len(prefix) :] if text.startswith(prefix) else text
