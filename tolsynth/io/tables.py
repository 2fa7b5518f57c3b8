"""Results as tables: pandas DataFrames and CSV / JSON / Parquet files that record their inputs.

One helper for every result type.  Each result class inherits :class:`Tabular`, whose
``to_frame()`` builds a :class:`pandas.DataFrame` (the table builders below, one per result type)
and whose ``to_csv`` / ``to_json`` / ``to_parquet`` / ``save`` write it with :func:`write_table`.
Every frame carries ``frame.attrs``:

``tolsynth_version``
    the package version that computed it;
``kind``
    the result type (``"SynthesisResult"``, ``"MonteCarloResult"``, ...);
``inputs``
    every input of the run (model, R, p, distribution, alpha, k, bounds, poses, criterion,
    solver, options, ... in mm, rad and each parameter's tolerance unit);
``summary``
    the scalar results (status, cost, lower bound, gap, times, ...);
``units``
    the unit of each column that has one.

The rows of each type's frame:

- ``SynthesisResult``: one per parameter: ``parameter, unit, tolerance, lower, upper, k, alpha``
  (of the cost model the solve used, a process's or ``cost=``'s included; NaN where it is not the
  power law ``k eps^-alpha``), ``cost_model`` (that model, e.g. ``5 eps^-0.7``), ``cost`` (that
  parameter's share of the cost), ``bound_active`` ("lower" / "upper" / ""),
  ``bound_multiplier``; the constraint blocks in ``attrs["summary"]["constraints"]``;
- ``Comparison``: one per parameter: ``ipopt, sumt, rel_diff, ipopt_bound, sumt_bound``;
- ``WorkspaceSynthesis``: one per exchange round (cost, worst value, worst pose and hand point);
- ``MonteCarloResult``: one per probability (``monte_carlo, ci_low, ci_high, analytic, diff,
  analytic_in_ci``), then the principal standard deviations and the mean error;
- ``ProbabilityMap``: one per grid point (``u, v, P, reachable, sigma1..3, limit_margin, q_<joint>``);
- ``WorstPose``: the worst pose and the reference pose;
- ``ValidationResult``: the Monte Carlo rows plus ``p_asked``, ``met``, ``short`` per component.

The files keep them: CSV as a plain table (``pandas.read_csv(path)``, no arguments) with the
metadata in a sidecar JSON beside it (``t.csv`` -> ``t.csv.json``), JSON as pandas' table
orientation with a ``"tolsynth"`` key (``pandas.read_json(path, orient="table",
precise_float=True)``), Parquet in the file's metadata (``pandas.read_parquet``), Excel as the
sheet ``table`` with the metadata in the sheet ``tolsynth`` (``pandas.read_excel(path)`` reads the
table, numeric columns as numbers).  :func:`read_table` reads any of them back with its
``attrs``, and raises a typed error on a missing, empty or corrupted file.

pandas (and pyarrow for Parquet) are the optional extra ``tables``
(``pip install "tolsynth[tables]"``), openpyxl for Excel the extra ``xlsx``; without them these methods raise
:class:`tolsynth.MissingDependencyError` with the install command.  The core path does not
import pandas.
"""

from __future__ import annotations

import json
import os
import zipfile

from tolsynth import tabular
from tolsynth.errors import InputError, MissingDependencyError
from tolsynth.io.frames import _build
from tolsynth.tabular import (
    TABLES_INSTALL,
    Tabular,
    _cell,
    _version,
    jsonable,
    make_frame,
    require_pandas,
    spec_inputs,
    synthesis_row,
)

__all__ = [
    "TABLE_SUFFIXES",
    "Tabular",
    "check_table_path",
    "jsonable",
    "make_frame",
    "read_table",
    "require_pandas",
    "spec_inputs",
    "synthesis_row",
    "write_table",
]

#: file suffix -> format written by :func:`write_table`
TABLE_SUFFIXES = {".csv": "csv", ".json": "json", ".parquet": "parquet", ".xlsx": "xlsx"}
#: the install command of the Excel writer and reader
XLSX_INSTALL = 'pip install "tolsynth[xlsx]"'
#: the sidecar of a CSV table: its metadata (``t.csv`` -> ``t.csv.json``), so that the CSV itself
#: is plain and ``pandas.read_csv(path)`` reads it with no arguments
SIDECAR = ".json"
#: the sheets of an Excel table: the frame, and the metadata as (key, part, JSON) rows
SHEET, META_SHEET = "table", "tolsynth"
#: Excel holds at most 32767 characters in a cell: longer JSON goes over several rows
_CELL = 32000


# ---------------------------------------------------------------------------------------------
# optional dependencies and paths
# ---------------------------------------------------------------------------------------------


def _require_pyarrow(what: str) -> None:
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        raise MissingDependencyError("pyarrow", what, TABLES_INSTALL) from None


def _require_openpyxl(what: str) -> None:
    try:
        import openpyxl  # noqa: F401
    except ImportError:
        raise MissingDependencyError("openpyxl", what, XLSX_INSTALL) from None


def table_format(path, field: str = "path") -> str:
    """``"csv"``, ``"json"``, ``"parquet"`` or ``"xlsx"`` from the file's suffix; InputError otherwise."""
    if not isinstance(path, (str, os.PathLike)):
        raise InputError(field, f"got {type(path).__name__}", "a file path ending in " + ", ".join(TABLE_SUFFIXES))
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext not in TABLE_SUFFIXES:
        raise InputError(
            field,
            f"{os.fspath(path)!r}: unknown table format {ext or '(no suffix)'}",
            "a file name ending in " + ", ".join(TABLE_SUFFIXES),
        )
    return TABLE_SUFFIXES[ext]


def _require_format(fmt: str, what: str) -> None:
    require_pandas(what)
    if fmt == "parquet":
        _require_pyarrow(what)
    elif fmt == "xlsx":
        _require_openpyxl(what)


def check_table_path(path, field: str = "path") -> str:
    """Before any work: a known suffix, pandas (pyarrow for Parquet, openpyxl for Excel) installed,
    the folder exists and is writable.  Returns the format."""
    fmt = table_format(path, field)
    _require_format(fmt, f"writing {os.fspath(path)}")
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise InputError(field, f"{path!r}: the folder {folder} does not exist", "a path in an existing folder")
    if os.path.isdir(path) or not os.access(folder, os.W_OK) or (os.path.exists(path) and not os.access(path, os.W_OK)):
        raise InputError(field, f"{path!r} cannot be written", "a writable file path")
    return fmt


# ---------------------------------------------------------------------------------------------
# writing and reading
# ---------------------------------------------------------------------------------------------


def write_table(frame, path, field: str = "path") -> str:
    """Write ``frame`` (with its ``attrs``) to ``path``; the format from the suffix
    (``.csv``, ``.json``, ``.parquet``, ``.xlsx``).  Returns the path written.

    CSV: the plain table, its metadata in the sidecar ``path + ".json"``; JSON: pandas' table
    orientation with a ``"tolsynth"`` key; Parquet: the file's own metadata; Excel: the sheet
    ``table`` and the metadata in the sheet ``tolsynth``."""
    fmt = check_table_path(path, field)
    path = os.fspath(path)
    meta = jsonable(dict(frame.attrs))
    meta.setdefault("tolsynth_version", _version())
    try:
        _write(frame, path, fmt, meta)
    except OSError as exc:  # a full disk, a read-only sidecar, a path the system refuses
        where = exc.filename if exc.filename is not None else path
        raise InputError(
            field, f"{where!r} cannot be written: {exc.strerror or type(exc).__name__}", "a writable file path"
        ) from None
    return path


def _write(frame, path: str, fmt: str, meta: dict) -> None:
    if fmt == "csv":
        frame.to_csv(path, index=False)
        side = {"tolsynth": meta, "columns": [str(c) for c in frame.columns]}
        with open(path + SIDECAR, "w", encoding="utf-8") as fh:
            json.dump(side, fh, indent=1, allow_nan=False)
    elif fmt == "json":
        from pandas.io.json import build_table_schema

        # pandas' own writer rounds to 15 digits; records through json keep every float exactly
        data = [{str(k): _cell(v) for k, v in rec.items()} for rec in frame.to_dict(orient="records")]
        doc = {"schema": build_table_schema(frame, index=False), "data": data, "tolsynth": meta}
        with open(path, "w", encoding="utf-8") as fh:
            json.dump(doc, fh, indent=1, allow_nan=False)
    elif fmt == "xlsx":
        _write_xlsx(frame, path, meta)
    else:
        out = frame.copy()
        out.attrs = meta
        out.to_parquet(path, index=False)


def _write_xlsx(frame, path: str, meta: dict) -> None:
    pd = require_pandas(f"writing {path}")
    rows = []
    for key, value in meta.items():
        text = json.dumps(value, allow_nan=False)
        for part in range(0, max(len(text), 1), _CELL):
            rows.append({"key": key, "part": part // _CELL, "json": text[part : part + _CELL]})
    out = frame.copy()
    for col in out.columns:  # Excel has no cell for a list or dict: JSON text instead
        if out[col].dtype == object and out[col].map(lambda v: isinstance(v, (list, dict, tuple))).any():
            out[col] = out[col].map(lambda v: json.dumps(jsonable(v)) if isinstance(v, (list, dict, tuple)) else v)
    with pd.ExcelWriter(path, engine="openpyxl") as xl:
        out.to_excel(xl, sheet_name=SHEET, index=False)
        pd.DataFrame(rows, columns=["key", "part", "json"]).to_excel(xl, sheet_name=META_SHEET, index=False)


def _bad(path: str, why: str):
    return InputError(
        "path",
        f"{path!r}: {why}",
        "a table written by tolsynth.write_table (.csv with its .csv.json, .json, .parquet or .xlsx)",
    )


def read_table(path):
    """Read a table written by :func:`write_table` back, with its ``attrs`` (inputs, summary,
    version, units).

    A missing, empty, unreadable or corrupted file (or one that is not a regular file, such as
    ``/dev/zero``) raises :class:`~tolsynth.InputError` naming the path.  A CSV without its sidecar
    is read as a plain table (empty ``attrs``); one written with the two ``#`` lines of earlier
    versions is read too."""
    fmt = table_format(path)
    path = os.fspath(path)
    _require_format(fmt, f"reading {path}")
    if not os.path.exists(path):
        raise _bad(path, "does not exist")
    if not os.path.isfile(path):
        raise _bad(path, "is not a regular file")
    if os.path.getsize(path) == 0:
        raise _bad(path, "is empty")
    try:
        frame, meta = _READERS[fmt](path)
    except InputError:
        raise
    except (
        OSError,
        UnicodeDecodeError,
        ValueError,
        KeyError,
        IndexError,
        TypeError,
        AttributeError,
        json.JSONDecodeError,
        zipfile.BadZipFile,
    ) as exc:  # pandas' parser errors are ValueErrors
        raise _bad(path, f"cannot be read as a {fmt} table ({type(exc).__name__}: {exc})") from None
    if len(frame.columns) == 0:
        raise _bad(path, "holds no columns")
    if not isinstance(meta, dict):
        raise _bad(path, "its metadata is not a JSON object")
    frame.attrs = meta
    return frame


def _read_csv(path: str):
    import pandas as pd

    with open(path, "rb") as fh:
        if b"\x00" in fh.read(1 << 16):
            raise _bad(path, "holds NUL bytes: not a text table")
    with open(path, encoding="utf-8") as fh:
        first = fh.readline()
        second = fh.readline() if first.startswith("# tolsynth") else ""
    if first.startswith("# tolsynth") and second.startswith("# "):  # the comment lines of earlier versions
        meta = json.loads(second[2:])
        meta["tolsynth_version"] = first.split()[2] if len(first.split()) > 2 else None
        return pd.read_csv(path, skiprows=2), meta
    frame = pd.read_csv(path)
    side = path + SIDECAR
    if not os.path.isfile(side):
        if len(frame) == 0:
            raise _bad(path, f"holds no rows, and no metadata {side!r} beside it")
        return frame, {}
    try:
        with open(side, encoding="utf-8") as fh:
            doc = json.load(fh)
        meta, columns = doc["tolsynth"], doc.get("columns")
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError) as exc:
        raise _bad(path, f"its metadata {side!r} cannot be read ({type(exc).__name__}: {exc})") from None
    if columns is not None and [str(c) for c in frame.columns] != list(columns):
        raise _bad(
            path, f"its columns {list(map(str, frame.columns))} are not those its metadata {side!r} records ({columns})"
        )
    return frame, meta


def _read_json(path: str):
    import io

    import pandas as pd

    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    doc = json.loads(text)
    if not isinstance(doc, dict) or "schema" not in doc or "data" not in doc:
        raise _bad(path, "is JSON but not a table (no 'schema' and 'data')")
    return pd.read_json(io.StringIO(text), orient="table", precise_float=True), doc.get("tolsynth", {})


def _read_parquet(path: str):
    import pandas as pd

    try:
        frame = pd.read_parquet(path)
    except Exception as exc:  # pyarrow's own error types (ArrowInvalid, ...), not all ValueErrors
        if isinstance(exc, (KeyboardInterrupt, MemoryError)):
            raise
        raise _bad(path, f"cannot be read as a parquet table ({type(exc).__name__}: {exc})") from None
    return frame, dict(frame.attrs)


def _read_xlsx(path: str):
    import pandas as pd

    sheets = pd.read_excel(path, sheet_name=None, engine="openpyxl")
    if SHEET not in sheets:
        raise _bad(path, f"has no sheet {SHEET!r} (sheets: {list(sheets)})")
    meta = {}
    if META_SHEET in sheets:
        rows = sheets[META_SHEET].sort_values(["key", "part"], kind="stable")
        for key, group in rows.groupby("key", sort=False):
            meta[str(key)] = json.loads("".join(str(t) for t in group["json"]))
    return sheets[SHEET], meta


_READERS = {"csv": _read_csv, "json": _read_json, "parquet": _read_parquet, "xlsx": _read_xlsx}


def _save(result, path, suffix: str | None = None) -> str:
    if suffix is not None and table_format(path) != TABLE_SUFFIXES[suffix]:
        raise InputError("path", f"{os.fspath(path)!r} does not end in {suffix}", f"a file name ending in {suffix}")
    check_table_path(path)
    return write_table(result.to_frame(), path)


tabular.register(_build, _save)
