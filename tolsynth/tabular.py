"""The :class:`Tabular` mixin of every result type: ``to_frame()`` and the file writers.

The result types live in the lower layers, the table builders and the one table writer in
:mod:`tolsynth.io.tables`, which registers them here when the package is imported (importing any
``tolsynth`` module imports the package first), so a result never imports the layer above it.
"""

from __future__ import annotations

import math

import numpy as np

from tolsynth.errors import MissingDependencyError
from tolsynth.units import joint_values
from tolsynth.version import __version__

__all__ = ["Tabular", "register", "require_pandas", "jsonable", "make_frame", "spec_inputs", "synthesis_row"]

TABLES_INSTALL = 'pip install "tolsynth[tables]"'

_frame = None
_save = None


def register(frame, save) -> None:
    """Install the table builder ``frame(result)`` and the writer ``save(result, path, suffix)``."""
    global _frame, _save
    _frame, _save = frame, save


class Tabular:
    """Mixin of the result types: ``to_frame()`` and the writers (one implementation for all)."""

    __slots__ = ()

    def to_frame(self):
        """The result as a :class:`pandas.DataFrame`; inputs, summary, units and the package
        version in ``frame.attrs`` (see :mod:`tolsynth.io.tables`).  Needs pandas
        (``pip install "tolsynth[tables]"``)."""
        return _frame(self)

    def save(self, path) -> str:
        """Write :meth:`to_frame` to ``path`` (``.csv``, ``.json``, ``.parquet`` or ``.xlsx``) with every input."""
        return _save(self, path)

    def to_csv(self, path) -> str:
        """Write :meth:`to_frame` as CSV."""
        return _save(self, path, ".csv")

    def to_json(self, path) -> str:
        """Write :meth:`to_frame` as JSON (pandas' table orientation plus a ``"tolsynth"`` key)."""
        return _save(self, path, ".json")

    def to_parquet(self, path) -> str:
        """Write :meth:`to_frame` as Parquet (needs pyarrow), inputs in the file's metadata."""
        return _save(self, path, ".parquet")

    def to_excel(self, path) -> str:
        """Write :meth:`to_frame` as an Excel workbook (needs openpyxl), inputs in a second sheet."""
        return _save(self, path, ".xlsx")


def require_pandas(what: str = "a table"):
    """pandas, or a :class:`MissingDependencyError` naming the install command."""
    try:
        import pandas
    except ImportError:
        raise MissingDependencyError("pandas", what, TABLES_INSTALL) from None
    return pandas


def jsonable(obj, null: bool = False):
    """Plain JSON types: arrays to lists, NumPy scalars to Python, enums to strings, non-finite
    floats to the strings ``"nan"``, ``"inf"``, ``"-inf"`` (with ``null``: to None, JSON's null, as
    the results' ``to_dict()`` give them), so ``json.dumps(..., allow_nan=False)`` takes the result."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v, null) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v, null) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist(), null)
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None if null else str(v)
    if isinstance(obj, (str, int)) or obj is None:
        return str(obj) if isinstance(obj, str) and type(obj) is not str else obj
    if hasattr(obj, "to_dict"):
        return jsonable(obj.to_dict(), null)
    return str(obj)


def _cell(v):
    """A table cell for JSON: NaN and infinities as null (pandas reads null back as NaN)."""
    v = jsonable(v)
    return None if isinstance(v, str) and v in ("nan", "inf", "-inf") and not isinstance(v, bool) else v


def _version() -> str:
    return __version__


def make_frame(rows, kind: str, inputs: dict, summary: dict | None = None, units: dict | None = None, columns=None):
    """A DataFrame of ``rows`` (list of dicts, or dict of columns) with the standard ``attrs``."""
    pd = require_pandas(f"{kind}.to_frame()")
    frame = pd.DataFrame(rows, columns=columns)
    frame.attrs.update(
        tolsynth_version=_version(),
        kind=kind,
        inputs=jsonable(inputs),
        summary=jsonable(summary or {}),
        units=jsonable(units or {}),
    )
    return frame


def spec_inputs(spec) -> dict:
    """The resolved inputs held by a :class:`tolsynth.problem.specification.Specification`."""
    out = {
        "R_mm": spec.R,
        "p": spec.p,
        "distribution": spec.distribution,
        "criterion": spec.criterion,
        "Phi_rad": spec.Phi,
        "p_orientation": spec.p_orientation,
        "error_parameters": list(spec.names),
        "tolerance_units": dict(zip(spec.names, spec.units)),
        "alpha": dict(zip(spec.names, np.asarray(spec.alpha, dtype=float))),
        "k": dict(zip(spec.names, np.asarray(spec.k, dtype=float))),
        "bounds": {n: [float(lo), float(hi)] for n, lo, hi in zip(spec.names, spec.lower, spec.upper)},
        **joint_values(
            {label: np.asarray(q, dtype=float) for label, q in (spec.poses or {}).items()},
            getattr(spec, "joint_units", ()) or ("rad",),
            "poses",
        ),
    }
    costs = getattr(spec, "cost", None)
    if costs is not None and hasattr(costs, "models"):
        out["cost_models"] = dict(zip(spec.names, (m.describe() for m in costs.models)))
    return out


def _synthesis_inputs(res) -> dict:
    base = dict(getattr(res, "inputs", None) or {})
    out = {"model": base.pop("model", None), "solver": res.solver}
    if res.spec is not None:
        out.update(spec_inputs(res.spec))
    out.update(base)
    return out


def synthesis_summary(res) -> dict:
    return {
        "solver": res.solver,
        "probability": res.probability_kind,
        "status": str(res.status),
        "success": bool(res.success),
        "message": res.message,
        "cost": res.cost,
        "lower_bound": res.lower_bound,
        "gap": res.gap,
        "max_constraint": res.max_constraint if res.constraints else None,
        "iterations": res.iterations,
        "function_evaluations": res.function_evaluations,
        "wall_time_s": res.wall_time,
    }


def synthesis_row(res, prefix: str = "eps_") -> dict:
    """One flat row of a synthesis (the sweep's columns): status, cost, bound, gap, every tolerance."""
    row = synthesis_summary(res)
    for name, value in res.tolerances.items():
        row[prefix + name] = value
    return row
