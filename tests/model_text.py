"""Helpers of the model-file tests: a bundled model as a dict, a dict back to TOML text, and the
small edits the strict-reading tests make to a model's dict before loading it again.

The writer is deliberately small (inline tables and arrays only, which TOML allows anywhere) so
that the tests need no TOML-writing package; it writes what the fuzz tests produce, including
NaN, infinities and empty tables.
"""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

MODELS_DIR = Path(__file__).resolve().parent.parent / "models"


def model_dict(name: str) -> dict:
    """The bundled model file ``name`` parsed into plain Python values."""
    with open(MODELS_DIR / f"{name}.toml", "rb") as fh:
        return tomllib.load(fh)


def _key(k) -> str:
    return json.dumps(str(k))


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, (list, tuple)):
        return "[ " + ", ".join(_value(x) for x in v) + " ]"
    raise TypeError(f"no TOML for {type(v).__name__}")


def toml_text(data: dict) -> str:
    """TOML text whose parse is ``data`` (top-level keys as ``key = value`` lines)."""
    return "".join(f"{_key(k)} = {_value(v)}\n" for k, v in data.items())


def load_dict(tmp_path, data: dict, name: str = "m.toml"):
    """``data`` written as a model file under ``tmp_path`` and loaded by the package."""
    import tolsynth

    path = tmp_path / name
    path.write_text(toml_text(data))
    return tolsynth.load_model(path)


def edited(model: str, fn) -> dict:
    """The bundled model's dict with ``fn`` applied to a deep copy of it."""
    data = copy.deepcopy(model_dict(model))
    fn(data)
    return data


def _parent(data: dict, path):
    for key in path[:-1]:
        data = data[key]
    return data


def set_at(path, value):
    """An edit that sets ``data[path[0]][path[1]]...`` to ``value``."""

    def fn(data):
        _parent(data, path)[path[-1]] = value

    return fn


def drop_at(path):
    """An edit that deletes ``data[path[0]][path[1]]...``."""

    def fn(data):
        del _parent(data, path)[path[-1]]

    return fn


def assert_defect_named(tmp_path, model: str, edit, field: str, fragment: str):
    """The model with ``edit`` applied, loaded, raises ModelFileError naming ``field`` (its
    message holding ``fragment``); returns the error."""
    import pytest

    from tolsynth.errors import ModelFileError

    with pytest.raises(ModelFileError) as info:
        load_dict(tmp_path, edited(model, edit))
    assert info.value.field == field, str(info.value)
    assert fragment in str(info.value)
    return info.value
