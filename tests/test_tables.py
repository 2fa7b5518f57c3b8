"""Results as tables: every result type written as CSV, JSON, Parquet and Excel and read
back with plain pandas (``read_csv``, ``read_excel`` with no arguments); the numbers must equal the result object's own attributes, and the file
must hold every input and the package version."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

import tolsynth
from tolsynth.errors import InputError, MissingDependencyError

pd = pytest.importorskip("pandas")
pytest.importorskip("pyarrow")

pytest.importorskip("openpyxl")

#: exact round trips; Excel keeps 16 significant digits (openpyxl writes "%.16g"): tested on its own
FORMATS = ["csv", "json", "parquet"]


def _read_plain(path):
    """Read back with pandas alone (the documented way), and the metadata by hand."""
    if path.suffix == ".csv":
        meta = json.loads(Path(str(path) + ".json").read_text())["tolsynth"]
        assert meta["tolsynth_version"] == tolsynth.__version__
        return pd.read_csv(path), meta
    if path.suffix == ".xlsx":
        rows = pd.read_excel(path, sheet_name="tolsynth")
        meta = {k: json.loads("".join(g.sort_values("part")["json"])) for k, g in rows.groupby("key")}
        assert meta["tolsynth_version"] == tolsynth.__version__
        return pd.read_excel(path), meta
    if path.suffix == ".json":
        meta = json.loads(path.read_text())["tolsynth"]
        assert meta["tolsynth_version"] == tolsynth.__version__
        return pd.read_json(path, orient="table", precise_float=True), meta
    frame = pd.read_parquet(path)
    assert frame.attrs["tolsynth_version"] == tolsynth.__version__
    return frame, frame.attrs


@pytest.fixture(scope="module")
def solved(xz):
    return tolsynth.synthesize(
        xz,
        R=0.5,
        p=0.99,
        distribution="normal",
        alpha={n: 0.5 if n == "h3" else 0.7 for n in xz.error_parameters},
        k={"a": 2.0},
        bounds={"h2": (0.05, 1.0)},
        options={"tol": 1e-10},
        probability="gaussian",
    )


@pytest.mark.parametrize("fmt", FORMATS)
def test_synthesis_round_trip(solved, tmp_path, fmt):
    path = tmp_path / f"res.{fmt}"
    assert solved.save(path) == str(path)
    frame, meta = _read_plain(path)
    assert list(frame["parameter"]) == list(solved.tolerances)
    np.testing.assert_array_equal(frame["tolerance"].to_numpy(), solved.x)  # exact, every format
    np.testing.assert_array_equal(frame["lower"].to_numpy(), solved.spec.lower)
    assert frame.set_index("parameter").loc["h2", "bound_active"] == solved.bounds_active.get("h2", "") or (
        pd.isna(frame.set_index("parameter").loc["h2", "bound_active"]) and "h2" not in solved.bounds_active
    )
    # the per-parameter cost column sums to the result's cost (an independent sum of k eps^-alpha)
    k = np.array([2.0 if n == "a" else k0 for n, k0 in zip(solved.tolerances, solved.spec.k)])
    alpha = np.array([0.5 if n == "h3" else 0.7 for n in solved.tolerances])
    assert np.sum(k * solved.x**-alpha) == pytest.approx(solved.cost, rel=1e-12)
    assert frame["cost"].sum() == pytest.approx(solved.cost, rel=1e-12)
    inputs, summary = meta["inputs"], meta["summary"]
    assert inputs["model"]["name"] == "xu_zhang_1988"
    assert (inputs["R_mm"], inputs["p"], inputs["distribution"], inputs["criterion"]) == (
        0.5,
        0.99,
        "normal",
        "components",
    )
    assert inputs["alpha"]["h3"] == 0.5 and inputs["alpha"]["h2"] == 0.7 and inputs["k"]["a"] == 2.0
    assert inputs["bounds"]["h2"] == [0.05, 1.0]
    assert inputs["solver"] == "auto" and inputs["options"] == {"tol": 1e-10}
    np.testing.assert_allclose(inputs["poses_rad"]["worst"], solved.spec.poses["worst"], rtol=0, atol=0)
    assert summary["cost"] == solved.cost and summary["gap"] == solved.gap and summary["status"] == "optimal"


@pytest.mark.parametrize("fmt", FORMATS)
def test_montecarlo_round_trip(xz, solved, tmp_path, fmt):
    r = tolsynth.monte_carlo(xz, "worst", solved.x, "normal", R=0.5, n=4000, seed=3)
    path = tmp_path / f"mc.{fmt}"
    getattr(r, f"to_{fmt}")(path)
    frame, meta = _read_plain(path)
    rows = frame.set_index("quantity")
    np.testing.assert_array_equal(rows.loc[[f"p_component_{j}" for j in (1, 2, 3)], "monte_carlo"], r.p_components)
    assert rows.loc["p_sphere", "monte_carlo"] == r.p_sphere
    np.testing.assert_array_equal(rows.loc["p_sphere", ["ci_low", "ci_high"]].to_numpy(dtype=float), r.p_sphere_ci)
    assert rows.loc["p_sphere", "analytic"] == r.p_sphere_analytic
    assert meta["inputs"]["n"] == 4000 and meta["inputs"]["seed"] == 3 and meta["inputs"]["R_mm"] == 0.5
    assert meta["inputs"]["tolerances"] == pytest.approx(r.tolerances, rel=0, abs=0)


@pytest.fixture(scope="module")
def compared_and_mapped(xz):
    return tolsynth.compare(xz, R=0.5, p=0.99), tolsynth.probability_map(xz, "figure3", R=0.2, n=6)


@pytest.mark.parametrize("fmt", FORMATS)
def test_comparison_and_map_round_trip(compared_and_mapped, tmp_path, fmt):
    c, pm = compared_and_mapped
    frame, meta = _read_plain(_saved(c, tmp_path / f"cmp.{fmt}"))
    np.testing.assert_array_equal(frame["ipopt"].to_numpy(), c.ipopt.x)
    np.testing.assert_array_equal(frame["sumt"].to_numpy(), c.sumt.x)
    assert meta["summary"]["sumt"]["cost"] == c.sumt.cost and meta["inputs"]["R_mm"] == 0.5
    frame, meta = _read_plain(_saved(pm, tmp_path / f"map.{fmt}"))
    np.testing.assert_array_equal(frame["P"].to_numpy(), pm.P.ravel())  # NaN where unreachable, both
    np.testing.assert_array_equal(frame["u"].to_numpy().reshape(pm.P.shape)[0], pm.u)
    assert meta["inputs"]["R_mm"] == 0.2 and meta["inputs"]["plane"] == "xz"


def _saved(result, path):
    result.save(path)
    return path


def test_validation_frame(xz, tmp_path):
    res = tolsynth.synthesize(xz, R=0.5, p=0.99, validate=3000, seed=2, probability="gaussian")
    v = res.validation
    frame, meta = _read_plain(_saved(v, tmp_path / "v.csv"))
    rows = frame.set_index("quantity")
    np.testing.assert_array_equal(rows.loc[[f"p_component_{j}" for j in (1, 2, 3)], "monte_carlo"], v.p_components)
    assert list(rows.loc[[f"p_component_{j}" for j in (1, 2, 3)], "met"]) == list(v.components_met)
    assert meta["inputs"]["p"] == 0.99 and meta["inputs"]["seed"] == 2 and meta["summary"]["met"] == v.met
    assert res.to_frame().attrs["summary"]["validation"]["n"] == 3000


def test_workspace_and_worst_pose_frames(xz, solved):
    w = tolsynth.synthesize_workspace(xz, 0.5, 0.99, max_rounds=2, probability="gaussian")
    f = w.to_frame()
    assert list(f["cost"]) == [r["cost"] for r in w.rounds]
    assert f.attrs["summary"]["converged"] == w.converged
    wp = tolsynth.worst_pose(xz, solved.x, grid=4)
    f = wp.to_frame()
    assert f.loc[0, "value"] == wp.value and f.loc[0, "x"] == wp.position[0]


def test_bad_paths_and_missing_pandas(solved, tmp_path, monkeypatch):
    with pytest.raises(InputError, match="unknown table format .xls"):
        solved.save(tmp_path / "r.xls")
    with pytest.raises(InputError, match="does not end in .csv"):
        solved.to_csv(tmp_path / "r.json")
    with pytest.raises(InputError, match="does not exist"):
        solved.save(tmp_path / "missing" / "r.csv")
    monkeypatch.setitem(sys.modules, "pandas", None)  # import pandas now raises ImportError
    with pytest.raises(MissingDependencyError, match=r'pip install "tolsynth\[tables\]"') as info:
        solved.to_frame()
    assert isinstance(info.value, ImportError) and info.value.package == "pandas"


def test_core_import_needs_no_pandas_or_dask():
    import subprocess

    code = "import sys, tolsynth, tolsynth.cli; bad = [m for m in ('pandas', 'pyarrow', 'dask', 'distributed') if m in sys.modules]; print(bad)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "[]"


@pytest.mark.parametrize("fmt", ["csv", "xlsx"])
def test_plain_pandas_reads_numeric_columns(solved, tmp_path, fmt):
    path = tmp_path / f"res.{fmt}"
    solved.save(path)
    frame = pd.read_csv(path) if fmt == "csv" else pd.read_excel(path)  # no arguments
    assert list(frame.columns[:3]) == ["parameter", "unit", "tolerance"]
    for col in ("tolerance", "lower", "upper", "k", "alpha", "cost", "bound_multiplier"):
        assert pd.api.types.is_numeric_dtype(frame[col]), col
    np.testing.assert_allclose(frame["tolerance"].to_numpy(), solved.x, rtol=0 if fmt == "csv" else 1e-15)
    assert frame["cost"].sum() == pytest.approx(solved.cost, rel=1e-14)


def test_excel_round_trip_of_other_results(xz, solved, compared_and_mapped, tmp_path):
    r = tolsynth.monte_carlo(xz, "worst", solved.x, "normal", R=0.5, n=4000, seed=3)
    rows = pd.read_excel(_saved_excel(r, tmp_path / "mc.xlsx")).set_index("quantity")
    np.testing.assert_allclose(
        rows.loc[[f"p_component_{j}" for j in (1, 2, 3)], "monte_carlo"], r.p_components, rtol=1e-15
    )
    c, pm = compared_and_mapped
    frame = pd.read_excel(_saved_excel(pm, tmp_path / "map.xlsx"))
    np.testing.assert_allclose(frame["P"].to_numpy(), pm.P.ravel(), rtol=1e-15, equal_nan=True)  # empty cells: NaN
    back = tolsynth.read_table(tmp_path / "map.xlsx")
    assert back.attrs["inputs"]["R_mm"] == 0.2 and back.attrs["kind"] == "ProbabilityMap"
    frame = pd.read_excel(_saved_excel(c, tmp_path / "cmp.xlsx"))
    np.testing.assert_allclose(frame["sumt"].to_numpy(), c.sumt.x, rtol=1e-15)


def _saved_excel(result, path):
    assert result.to_excel(path) == str(path)
    return path
    back = tolsynth.read_table(path)
    assert back.attrs["summary"]["cost"] == solved.cost
    assert back.attrs["inputs"]["model"]["name"] == "xu_zhang_1988"


def test_xlsx_metadata_longer_than_a_cell(tmp_path):
    frame = pd.DataFrame({"x": [1.0, 2.0], "n": [1, 2]})
    frame.attrs = {"kind": "test", "inputs": {"poses": [[float(i), 0.5] for i in range(5000)]}}
    path = tolsynth.write_table(frame, tmp_path / "long.xlsx")
    back = tolsynth.read_table(path)
    assert back.attrs["inputs"] == frame.attrs["inputs"]
    assert len(json.dumps(frame.attrs["inputs"])) > 32767  # more than one Excel cell
    np.testing.assert_array_equal(back["n"].to_numpy(), [1, 2])


@pytest.mark.parametrize("fmt", FORMATS)
def test_read_table_bad_files_raise_typed_errors(solved, tmp_path, fmt):
    path = tmp_path / f"t.{fmt}"
    with pytest.raises(InputError, match="does not exist"):
        tolsynth.read_table(path)
    path.write_bytes(b"")
    with pytest.raises(InputError, match="is empty"):
        tolsynth.read_table(path)
    for junk in (b"\xff\xfe\x00garbage\x80\x81" * 50, b"\x00" * 4096, b'{"tolsynth": '):
        path.write_bytes(junk)
        with pytest.raises(InputError, match=str(path.name)):
            tolsynth.read_table(path)
    if fmt == "csv":  # a sidecar that is not JSON, or that names other columns
        solved.save(path)
        Path(str(path) + ".json").write_text("{not json")
        with pytest.raises(InputError, match="metadata"):
            tolsynth.read_table(path)
        solved.save(path)
        path.write_text("a,b\n1,2\n")
        with pytest.raises(InputError, match="columns"):
            tolsynth.read_table(path)


def test_read_table_on_devices_and_folders(tmp_path):
    import os

    if os.path.exists("/dev/zero"):
        os.symlink("/dev/zero", tmp_path / "zero.csv")
        with pytest.raises(InputError, match="not a regular file"):
            tolsynth.read_table(tmp_path / "zero.csv")
    (tmp_path / "dir.csv").mkdir()
    with pytest.raises(InputError, match="not a regular file"):
        tolsynth.read_table(tmp_path / "dir.csv")


def test_csv_of_earlier_versions_still_reads(tmp_path):
    path = tmp_path / "old.csv"
    path.write_text(
        '# tolsynth 0.1.0 SynthesisResult\n# {"kind": "SynthesisResult", "summary": {"cost": 1.5}}\n'
        "parameter,tolerance\nh2,0.1\n"
    )
    back = tolsynth.read_table(path)
    assert back.attrs["summary"]["cost"] == 1.5 and back.attrs["tolsynth_version"] == "0.1.0"
    assert back["tolerance"].tolist() == [0.1]


def test_write_errors_are_typed(solved, tmp_path):
    import os

    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full")
    os.symlink("/dev/full", tmp_path / "t.csv.json")  # the sidecar's write fails: no space left
    with pytest.raises(InputError, match="cannot be written"):
        solved.save(tmp_path / "t.csv")
