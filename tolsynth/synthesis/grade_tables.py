"""The grades each parameter may take, for :func:`tolsynth.synthesis.grades.round_to_grades`: a
user's grade table (names, patterns such as ``"o*"``, ``"*"``; values in the parameter's tolerance
unit or with a unit suffix) or ISO 286-1 grades at each length's nominal size (mm, or with a
suffix), with errors that name the inputs as the caller wrote them (:data:`API_NAMES` for the
Python arguments; the command line passes its options)."""

from __future__ import annotations

from typing import Mapping

import numpy as np

from tolsynth.checks import check_positive
from tolsynth.errors import InputError, OutOfRangeError, UnknownNameError
from tolsynth.model import iso286
from tolsynth.units import unit_kind

__all__ = ["API_NAMES", "grade_candidates"]


#: how the messages name the inputs (``{name}`` a parameter, ``{key}`` a table's key as written,
#: ``{label}`` a grade, ``{unit}`` a tolerance unit): the Python arguments here; the command line
#: passes the names of its options, so that an error names what its user typed
API_NAMES = {
    "sizes": "sizes",
    "size": "sizes[{name}]",
    "table": "table",
    "entry": "table[{key}]",
    "grade": "table[{key}][{label}]",
    "give_table": "a grade table for it: table={{'{name}': {{'A': 0.1, 'B': 0.2, ...}}}} in {unit} (its tolerance "
    "unit) or with a unit suffix ('0.1mrad'), or a pattern such as 'o*' or '*' for several parameters",
    "give_size": "its nominal size for the ISO 286 grade, in mm or with a length unit suffix: sizes={{'{name}': 50}}",
}


def _size(value, field: str) -> float:
    """A nominal size in mm (a string with a length unit converted), inside ISO 286-1's sizes."""
    v = check_positive(value, field, "mm")
    try:
        iso286.size_range(v, field)
    except OutOfRangeError as exc:
        got = f"got {value!r} ({v:g} mm)" if isinstance(value, str) else f"got {v:g} mm"
        raise OutOfRangeError(field, got, exc.allowed) from None
    return v


def _read_sizes(mechanism, sizes, names):
    """``sizes`` as None, one size in mm, or a dict parameter name -> size in mm."""
    if sizes is None:
        return None
    if isinstance(sizes, Mapping):
        out = {}
        for key, value in sizes.items():
            field = names["size"].format(name=key)
            try:
                canon = mechanism.error_parameters[mechanism.index(key)]
            except UnknownNameError as exc:
                raise UnknownNameError(field, f"{key!r} is not an error parameter", exc.allowed) from None
            par = mechanism.parameters[mechanism.index(canon)]
            if par.kind != "length":  # ISO 286 sizes are linear; an angle's grades come from the table alone
                lengths = [q.name for q in mechanism.parameters if q.kind == "length"]
                raise InputError(
                    field,
                    f"{canon} is an angle ({par.unit}): a nominal size applies to length parameters only "
                    "(an angle's grades come from its grade table)",
                    "a size for a length parameter: " + (", ".join(lengths) or "this model has none"),
                )
            out[canon] = _size(value, field)
        return out
    if isinstance(sizes, (str, int, float, np.integer, np.floating)) and not isinstance(sizes, bool):
        return _size(sizes, names["sizes"])
    raise InputError(
        names["sizes"],
        f"got {sizes!r}",
        "one nominal size for every length, or a dict parameter name -> size; in mm or with a length "
        "unit suffix ('300mm', '0.3m')",
    )


def _expand_patterns(mechanism, table, names) -> dict:
    """Parameter name (or ``"*"``) -> (the key as written, its entry); a pattern such as ``"o*"``
    names every parameter it matches, a later key overriding an earlier one."""
    import fnmatch

    if not isinstance(table, Mapping):
        raise InputError(
            names["table"], f"got {table!r}", "a dict parameter name or pattern (or '*') -> {grade label: tolerance}"
        )
    out = {}
    for key, value in table.items():
        if key != "*" and any(c in str(key) for c in "*?["):
            hits = [n for n in mechanism.error_parameters if fnmatch.fnmatchcase(n, str(key))]
            if not hits:
                raise InputError(
                    names["entry"].format(key=key),
                    f"pattern {key!r} matches no parameter",
                    ", ".join(mechanism.error_parameters),
                )
            out.update({h: (key, value) for h in hits})
        elif key == "*":
            out[key] = (key, value)
        else:
            try:
                canon = mechanism.error_parameters[mechanism.index(key)]
            except UnknownNameError as exc:
                raise UnknownNameError(
                    names["entry"].format(key=key), f"{key!r} is not an error parameter", exc.allowed
                ) from None
            out[canon] = (key, value)
    return out


def _table_for(table: dict, par, names):
    """The grades ``table`` (expanded) gives ``par``, label -> tolerance in its tolerance unit, or None."""
    hit = table.get(par.name, table.get("*"))
    if hit is None:
        return None
    key, entry = hit
    if not isinstance(entry, Mapping) or not entry:
        raise InputError(
            names["entry"].format(key=key),
            f"got {entry!r}",
            f"a non-empty dict grade label -> tolerance, in {par.unit} (the tolerance unit of {par.name}) or "
            "with a unit suffix",
        )
    # a string with a unit suffix ("0.1deg") is converted to the parameter's unit (docs/units.md)
    return {
        str(label): check_positive(value, names["grade"].format(key=key, label=label), par.unit)
        for label, value in entry.items()
    }


def grade_candidates(mechanism, sizes=None, table=None, *, names=None) -> dict[str, dict[str, float]]:
    """Parameter -> {grade label: tolerance in its tolerance unit}, finest first: the user's
    ``table`` where it names the parameter (by name, pattern such as ``"o*"``, or ``"*"``), else
    ISO 286-1 at ``sizes[name]`` (mm; default: the nominal value of the dimension the parameter
    perturbs).  Sizes and table values may be strings with a unit suffix (``"0.3m"``,
    ``"0.1deg"``), converted to mm and to the parameter's tolerance unit.  ``names``: how errors
    name the inputs (default :data:`API_NAMES`, the Python arguments)."""
    return _candidates(mechanism, sizes, table, names or API_NAMES)[0]


def _candidates(mechanism, sizes, table, names):
    """:func:`grade_candidates` and, per parameter, where its grades come from (for messages)."""
    sizes = _read_sizes(mechanism, sizes, names)
    table = _expand_patterns(mechanism, table, names) if table is not None else {}
    out, sources = {}, {}
    for par in mechanism.parameters:
        own = _table_for(table, par, names)
        if own is not None:
            out[par.name] = dict(sorted(own.items(), key=lambda kv: kv[1]))
            sources[par.name] = "the grade table"
            continue
        if par.kind != "length":
            raise InputError(
                names["entry"].format(key=par.name),
                f"{par.name} is an angle ({par.unit}) and ISO 286 grades are for linear sizes",
                names["give_table"].format(name=par.name, unit=par.unit),
            )
        size = _size_of(mechanism, par, sizes, names)
        # ISO gives mm; the parameter's tolerance unit is par.scale mm
        out[par.name] = {g: v / par.scale for g, v in iso286.grades_for(size).items()}
        sources[par.name] = f"ISO 286 at {size:g} mm"
    return out, sources


def _size_of(mechanism, par, sizes, names=API_NAMES) -> float:
    """The nominal size (mm) of a length ``par``: given in ``sizes`` (read by :func:`_read_sizes`),
    else the largest nominal value of the dimensions it perturbs."""
    if isinstance(sizes, float):
        return sizes
    if isinstance(sizes, Mapping) and par.name in sizes:
        return sizes[par.name]
    field = names["size"].format(name=par.name)
    nominal = [abs(mechanism.spec.symbols.get(s, 0.0)) for s in par.perturbs]
    nominal = [v for v in nominal if v > 0]
    if not nominal:
        raise InputError(
            field,
            f"{par.name} perturbs a dimension of nominal size 0 ({', '.join(par.perturbs) or 'a joint'})",
            names["give_size"].format(name=par.name),
        )
    size = max(nominal)
    if size > iso286.SIZE_STEPS[-1]:
        raise OutOfRangeError(
            field,
            f"{par.name}'s nominal size (its dimension's value) is {size:g} mm, beyond ISO 286-1's "
            f"{iso286.SIZE_STEPS[-1]} mm",
            names["give_size"].format(name=par.name),
        )
    return size


def _no_grade_message(name, unit, bounds, grades, source) -> str:
    """Why no grade of ``name`` is offered, and what would help: grades of a table of one's own
    inside the bounds (in the tolerance unit: a table written in another unit misses them), or
    for ISO 286 grades wider bounds or a table of one's own."""
    lo, hi = bounds
    vals = list(grades.values())
    span = f"{min(vals):g} to {max(vals):g} {unit}" if len(set(vals)) > 1 else f"{vals[0]:g} {unit}"
    head = f"no grade of {name} lies within its bounds [{lo:g}, {hi:g}] {unit}"
    if source == "the grade table":
        suffix = "'0.1mrad', '0.01deg'" if unit_kind(unit) == "angle" else "'5um', '0.005mm'"
        return (
            f"{head}: its grade table gives {span}; a bare number is in {unit}, the tolerance unit of {name} "
            f"(or write a unit suffix: {suffix}); give grades inside the bounds, or widen the bounds"
        )
    where = f" ({source}: {span})" if source else ""
    return f"{head}{where}: widen the bounds, or give {name} grades of your own in a grade table"
