"""Per-parameter values on the command line: tolerances, bounds, k and alpha, each a list of
``name=VALUE`` items (patterns such as ``h*=0.01`` allowed) in the parameter's own unit or with a
unit suffix; errors name the option and the parameter."""

from __future__ import annotations

import fnmatch
import math

import numpy as np

from tolsynth.cli.args import _WILDCARD, _split_quantity, split_items
from tolsynth.errors import InputError, UnknownNameError
from tolsynth.kinematics.mechanism import Mechanism
from tolsynth.units import QUANTITY as _QTY
from tolsynth.units import suffixes as _suffixes
from tolsynth.units import to_base, unit_kind

__all__ = ["parse_tolerances", "parse_per_parameter", "parse_bounds"]


# ---------------------------------------------------------------------------------------------
# per-parameter values: tolerances, bounds, k, alpha
# ---------------------------------------------------------------------------------------------
def _param_kind(mech: Mechanism, i: int) -> str | None:
    return unit_kind(mech.units[i])


def _tolerance_value(mech: Mechanism, field: str):
    """A tolerance: bare number in the parameter's tolerance unit, or a length / angle suffix."""

    def parse(text: str, where: str):
        allowed = (
            "a number in each parameter's tolerance unit, or with a unit suffix "
            f"(lengths: {_suffixes('length')}; angles: {_suffixes('angle')})"
        )
        value, suffix = _split_quantity(text, f"{field}[{where}]" if where else field, allowed)
        kind = unit_kind(suffix) if suffix else None

        def convert(i: int) -> float:
            return value if suffix is None else value * to_base(suffix) / to_base(mech.units[i])

        return kind, convert

    return parse


def _apply_items(
    mech: Mechanism, text: str, field: str, base: np.ndarray, parse_value, set_lookup=None, bare_allowed: bool = True
) -> list:
    """Resolve ``SET``, ``VALUE``, ``pattern=VALUE`` and ``name=VALUE`` items onto ``base``.

    Order of precedence, whatever the order written: the set (tolerances only), then a bare value
    for every parameter, then patterns (``*``, ``?``, ``[..]``, in the order given), then exact
    names.  A value with a unit suffix applied by a pattern sets only the parameters of that
    unit's kind (``*=0.02mm`` every length, ``*=1mrad`` every angle).  Duplicates are errors.
    """
    names = list(mech.error_parameters)
    out = list(base)
    seen_exact: dict[str, str] = {}
    seen_pattern: set = set()
    set_name = None
    bare = None
    patterns = []
    exact = []
    for item in split_items(text, field):
        if "=" in item:
            key, _, val = (s.strip() for s in item.partition("="))
            if not key or not val:
                raise InputError(field, f"{item!r}", "name=value with both sides given")
            kind, conv = parse_value(val, key)
            if _WILDCARD.search(key):
                if (key, kind) in seen_pattern:
                    raise InputError(field, f"pattern {key!r} given twice", "each name or pattern once")
                seen_pattern.add((key, kind))
                hits = [
                    i
                    for i, n in enumerate(names)
                    if fnmatch.fnmatchcase(n, key) and (kind is None or _param_kind(mech, i) == kind)
                ]
                if not hits:
                    raise UnknownNameError(
                        field,
                        f"pattern {key!r} matches no{' ' + kind if kind else ''} error parameter",
                        "patterns over " + ", ".join(names),
                    )
                patterns.append((hits, conv))
            else:
                i = mech.index(key, field)  # UnknownNameError naming the option
                canon = names[i]
                if canon in seen_exact:
                    raise InputError(
                        field, f"{canon} given twice ({seen_exact[canon]!r} and {item!r})", "each name or pattern once"
                    )
                seen_exact[canon] = item
                if kind is not None and _param_kind(mech, i) != kind:
                    raise InputError(
                        field,
                        f"{item!r}: {canon} is a{'n' if _param_kind(mech, i) == 'angle' else ''} "
                        f"{_param_kind(mech, i)} (tolerance unit {mech.units[i]})",
                        f"a {_param_kind(mech, i)} unit or a bare number in {mech.units[i]}",
                    )
                exact.append((i, conv))
        elif set_lookup is not None and not _QTY.match(item):
            if set_name is not None:
                raise InputError(
                    field, f"two tolerance sets named ({set_name!r}, {item!r})", "one SET, then name=value overrides"
                )
            set_name = item
            out = list(set_lookup(item))
        elif bare_allowed:
            if bare is not None:
                raise InputError(
                    field,
                    f"two values for every parameter ({bare[0]!r}, {item!r})",
                    "one bare value, then name=value overrides",
                )
            kind, conv = parse_value(item, "")
            if kind is not None:  # a suffixed bare value: every parameter of that kind
                hits = [i for i in range(len(names)) if _param_kind(mech, i) == kind]
            else:
                hits = list(range(len(names)))
            bare = (item, hits, conv)
        else:
            raise InputError(field, f"{item!r}", "name=value items")
    if set_name is not None and bare is not None:
        raise InputError(
            field,
            f"both a set ({set_name!r}) and a value for every parameter ({bare[0]!r})",
            "a SET or a value, then name=value overrides",
        )
    if bare is not None:
        for i in bare[1]:
            out[i] = bare[2](i)
    for hits, conv in patterns:
        for i in hits:
            out[i] = conv(i)
    for i, conv in exact:
        out[i] = conv(i)
    return out


def parse_tolerances(mech: Mechanism, text: str, field: str = "--tolerances") -> np.ndarray:
    """``SET``, ``VALUE``, ``name=VALUE,...`` or ``SET,name=VALUE,...``; patterns such as ``*=0.02``.

    Bare numbers are in each parameter's tolerance unit; a suffix converts (``h2=5um``,
    ``alpha1=2mrad``).  Without a set or a value for every parameter, every parameter must be named.
    """
    n = mech.n
    vals = _apply_items(
        mech, text, field, [math.nan] * n, _tolerance_value(mech, field), set_lookup=lambda s: mech.tolerances(s)
    )
    missing = [mech.error_parameters[i] for i in range(n) if not math.isfinite(vals[i])]
    if missing:
        raise InputError(
            field,
            "no tolerance for " + ", ".join(missing),
            "a SET, a value for every parameter (VALUE or *=VALUE), or every name=VALUE",
        )
    return mech.tolerances(dict(zip(mech.error_parameters, vals)))


def _plain_value(field: str, what: str):
    def parse(text: str, where: str):
        try:
            v = float(text)
        except ValueError:
            raise InputError(f"{field}[{where}]" if where else field, f"{text!r} is not a number", what) from None
        if not math.isfinite(v):
            raise InputError(f"{field}[{where}]" if where else field, f"got {text}", what)
        return None, (lambda i: v)

    return parse


def parse_per_parameter(mech: Mechanism, text: str | None, field: str, default, what: str) -> np.ndarray | None:
    """``--k`` / ``--alpha``: ``VALUE`` for every parameter, ``name=VALUE`` / ``pattern=VALUE`` overrides."""
    if text is None:
        return None
    base = np.broadcast_to(np.asarray(default, dtype=float), (mech.n,)).tolist()
    return np.array(_apply_items(mech, text, field, base, _plain_value(field, what)), dtype=float)


def parse_bounds(mech: Mechanism, text: str | None, field: str = "--bounds"):
    """``LOW:HIGH`` for every parameter, ``name=LOW:HIGH`` / ``pattern=LOW:HIGH`` overrides; a side
    left empty keeps the model's bound; units as for the tolerances.  Returns ``(lower, upper)``."""
    if text is None:
        return None
    lo0, hi0 = (np.asarray(b, dtype=float) for b in mech.bounds)
    tol = _tolerance_value(mech, field)
    allowed = "LOW:HIGH in each parameter's tolerance unit (or with a unit suffix); a side may be empty"

    def parse(val: str, where: str):
        if val.count(":") != 1:
            raise InputError(f"{field}[{where}]" if where else field, f"{val!r}", allowed)
        a, b = (s.strip() for s in val.split(":"))
        ka, ca_ = tol(a, where) if a else (None, None)
        kb, cb = tol(b, where) if b else (None, None)
        if ka and kb and ka != kb:
            raise InputError(f"{field}[{where}]" if where else field, f"{val!r} mixes a length and an angle", allowed)
        return ka or kb, (lambda i: (ca_(i) if ca_ else None, cb(i) if cb else None))

    pairs = _apply_items(mech, text, field, [(None, None)] * mech.n, parse)
    lo = np.array([p[0] if p[0] is not None else lo0[i] for i, p in enumerate(pairs)])
    hi = np.array([p[1] if p[1] is not None else hi0[i] for i, p in enumerate(pairs)])
    for i, name in enumerate(mech.error_parameters):  # more than a turn: a unit mistake, not a tolerance
        turn = 2 * math.pi / to_base(mech.units[i])
        if _param_kind(mech, i) == "angle" and hi[i] > turn * (1 + 1e-12):
            raise InputError(
                f"{field}[{name}]",
                f"upper bound {hi[i]:g} {mech.units[i]} is more than a full turn",
                f"an angle tolerance up to {turn:g} {mech.units[i]} (2 pi rad, 360 deg)",
            )
    return lo, hi
