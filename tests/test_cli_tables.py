"""The command line's tables: ``--out FILE.csv|.json|.parquet|.xlsx`` on solve,
montecarlo, map (``--data``), worst-pose and sweep, read back with pandas against the API's numbers;
an unknown suffix is refused before any work; ``tolsynth sweep`` from arguments and from a TOML file;
every ``--json`` records its inputs."""

from __future__ import annotations

import json

import numpy as np
import pytest

import tolsynth
from tolsynth.cli import main

pd = pytest.importorskip("pandas")
pytest.importorskip("pyarrow")


def test_solve_out_matches_api(tmp_path, capsys):
    path = tmp_path / "t.json"
    assert (
        main(["solve", "--model", "planar_2r", "--R", "0.5", "--p", "0.9", "--dist", "normal", "--out", str(path)]) == 0
    )
    frame = pd.read_json(path, orient="table", precise_float=True)
    ref = tolsynth.synthesize("planar_2r", 0.5, 0.9, "normal", probability="gaussian")
    np.testing.assert_allclose(frame["tolerance"].to_numpy(), ref.x, rtol=1e-9)
    meta = json.loads(path.read_text())["tolsynth"]
    assert meta["inputs"]["R_mm"] == 0.5 and meta["inputs"]["distribution"] == "normal"
    cl = meta["inputs"]["command_line"]
    assert cl["command"] == "solve" and cl["tolsynth_version"] == tolsynth.__version__
    assert cl["arguments"]["out"] == str(path)


@pytest.mark.parametrize("suffix", ["csv", "xlsx"])
def test_solve_out_read_by_plain_pandas(tmp_path, capsys, suffix):
    pytest.importorskip("openpyxl")
    path = tmp_path / f"t.{suffix}"
    assert main(["solve", "--model", "planar_2r", "--R", "0.5", "--p", "0.9", "--out", str(path)]) == 0
    frame = pd.read_csv(path) if suffix == "csv" else pd.read_excel(path)  # no arguments
    assert list(frame["parameter"]) == list(tolsynth.load_model("planar_2r").error_parameters)
    assert pd.api.types.is_float_dtype(frame["tolerance"]) and pd.api.types.is_float_dtype(frame["cost"])
    back = tolsynth.read_table(path)
    assert back.attrs["inputs"]["command_line"]["command"] == "solve"
    assert back.attrs["summary"]["cost"] == pytest.approx(frame["cost"].sum(), rel=1e-12)


@pytest.mark.parametrize(
    "argv",
    [
        ["solve", "--model", "planar_2r", "--R", "0.5", "--p", "0.9"],
        ["montecarlo", "--model", "planar_2r", "--tolerances", "coarse", "--R", "0.5", "--n", "1000"],
        ["worst-pose", "--model", "planar_2r", "--tolerances", "coarse", "--grid", "5"],
        ["sweep", "--model", "planar_2r", "--R", "0.5", "--p", "0.9"],
    ],
)
def test_unknown_suffix_refused_before_work(argv, capsys, tmp_path, monkeypatch):
    import importlib

    def boom(*a, **k):  # loading the model is the first piece of work: it must not happen
        raise AssertionError("work started before the --out check")

    for name in ("solve", "montecarlo", "workspace", "sweep"):  # each command's own reference
        monkeypatch.setattr(importlib.import_module(f"tolsynth.cli.{name}"), "load_model", boom)
    assert main(argv + ["--out", str(tmp_path / "t.xls")]) == 2
    err = capsys.readouterr().err
    assert "--out" in err and ".xlsx" in err and ".parquet" in err and "Traceback" not in err


def test_map_data_and_montecarlo_out(tmp_path, capsys):
    data = tmp_path / "map.csv"
    assert (
        main(
            [
                "map",
                "--model",
                "planar_2r",
                "--tolerances",
                "coarse",
                "--plane",
                "xy",
                "--n",
                "6",
                "--quiet",
                "--data",
                str(data),
            ]
        )
        == 0
    )
    frame = pd.read_csv(data)  # a plain CSV: its metadata in map.csv.json beside it
    pm = tolsynth.probability_map(tolsynth.load_model("planar_2r"), "coarse", plane="xy", n=6, R=0.2, progress=False)
    np.testing.assert_allclose(frame["P"].to_numpy(), pm.P.ravel(), rtol=1e-12, equal_nan=True)
    out = tmp_path / "mc.parquet"
    assert (
        main(
            [
                "montecarlo",
                "--model",
                "planar_2r",
                "--tolerances",
                "coarse",
                "--R",
                "0.5",
                "--n",
                "2000",
                "--seed",
                "4",
                "--quiet",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    frame = pd.read_parquet(out)
    mc = tolsynth.monte_carlo(
        tolsynth.load_model("planar_2r"), "worst", "coarse", R=0.5, n=2000, seed=4, progress=False
    )
    assert frame.set_index("quantity").loc["p_sphere", "monte_carlo"] == mc.p_sphere
    assert frame.attrs["inputs"]["command_line"]["arguments"]["seed"] == 4


def test_sweep_cli_from_toml_and_arguments(tmp_path, capsys):
    grid = tmp_path / "grid.toml"
    grid.write_text('model = "planar_2r"\nR = [0.3, "500um"]\np = [0.9, 0.99]\ndistribution = ["uniform", "normal"]\n')
    out = tmp_path / "sweep.parquet"
    # the command line's --p replaces the file's
    assert main(["sweep", "--grid", str(grid), "--p", "0.95", "--workers", "1", "--quiet", "--out", str(out)]) == 0
    frame = pd.read_parquet(out)
    assert len(frame) == 4 and sorted(set(frame["R"])) == [0.3, 0.5] and set(frame["p"]) == {0.95}
    for _, row in frame.iterrows():
        ref = tolsynth.synthesize("planar_2r", row["R"], row["p"], row["distribution"])  # both exact
        assert row["cost"] == pytest.approx(ref.cost, rel=1e-8)
    assert frame.attrs["inputs"]["command_line"]["grid"]["p"] == [0.95]
    capsys.readouterr()
    # --json: every row and the inputs; a failing row gives exit 1 and keeps the others
    assert (
        main(["sweep", "--model", "planar_2r", "--R", "0.5,1e-9", "--p", "0.9", "--workers", "1", "--quiet", "--json"])
        == 1
    )
    captured = capsys.readouterr()
    out = json.loads(captured.out)
    assert [r["status"] for r in out["rows"]] == ["optimal", "error"]
    assert out["inputs"]["command"] == "sweep" and out["inputs"]["tolsynth_version"] == tolsynth.__version__
    assert "1 of 2 solves did not succeed" in captured.err


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("R = [0.5]\np = [0.9]\nbeta = 1\n", "unknown key"),
        ("R = [0.5]\np = [0.9]\nalph = 1\n", "did you mean 'alpha'"),
        ("R = [true]\np = [0.9]\n", "R"),
        ('R = [0.5]\np = ["x"]\n', "p"),
        ("R = 0.5\np = 0.9\n[x]\n", "unknown key"),
        ("R = [0.5\n", "cannot be read as TOML"),
    ],
)
def test_sweep_grid_file_errors(tmp_path, capsys, text, fragment):
    grid = tmp_path / "grid.toml"
    grid.write_text(text)
    assert main(["sweep", "--model", "planar_2r", "--grid", str(grid), "--workers", "1"]) == 2
    err = capsys.readouterr().err
    assert fragment in err and "Traceback" not in err


def test_every_json_records_inputs(capsys):
    for argv in (
        ["reproduce", "--no-sumt"],
        ["map", "--model", "planar_2r", "--tolerances", "coarse", "--plane", "xy", "--n", "6", "--quiet"],
        ["sweep", "--model", "planar_2r", "--R", "0.5", "--p", "0.9", "--workers", "1", "--quiet"],
    ):
        assert main(argv + ["--json"]) == 0
        inp = json.loads(capsys.readouterr().out)["inputs"]
        assert inp["tolsynth_version"] == tolsynth.__version__ and inp["command"] == argv[0]
        assert inp["model"]["name"] in ("planar_2r", "xu_zhang_1988")
