"""The command line's full reach: ``tolsynth models``, ``pareto``, ``budget`` and ``processes``
run what the API runs (the same numbers), with tables, ``--json`` and ``--out``; bad input is one
line and exit status 2."""

from __future__ import annotations

import json
import math

import pytest

import tolsynth
from tolsynth.cli import main

pd = pytest.importorskip("pandas")

PROCS = """
[[h3]]
name = "turning"
cost = { model = "power", k = 1.0, alpha = 0.7 }
lower = 0.05
upper = 0.5

[[h3]]
name = "grinding"
cost = { model = "power", k = 3.0, alpha = 0.7 }
lower = 0.005
upper = 0.05
"""


def _json(capsys, argv):
    assert main(argv + ["--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_models_lists_every_bundled_model_with_its_source(capsys, tmp_path):
    out = _json(capsys, ["models"])
    names = [m["name"] for m in out["models"]]
    assert names == tolsynth.bundled_models()
    for m in out["models"]:
        model = tolsynth.load_model(m["name"])
        assert m["title"] == model.title and m["error_parameters"] == model.n and m["source_line"]
    assert main(["models", "--out", str(tmp_path / "m.csv")]) == 0
    text = capsys.readouterr().out
    assert "xu_zhang_1988" in text and "source:" in text
    assert list(pd.read_csv(tmp_path / "m.csv")["name"]) == names


def test_pareto_matches_the_api(capsys, tmp_path):
    out = _json(
        capsys,
        [
            "pareto",
            "--model",
            "planar_2r",
            "--p",
            "0.99",
            "--R",
            "0.3:0.9:3",
            "--probability",
            "gaussian",
            "--dist",
            "uniform",
        ],
    )
    front = tolsynth.pareto_front(
        "planar_2r", R=[0.3, 0.6, 0.9], p=0.99, probability="gaussian", distribution="uniform"
    )
    assert [r["R"] for r in out["rows"]] == pytest.approx([0.3, 0.6, 0.9])
    assert [r["cost"] for r in out["rows"]] == pytest.approx([r["cost"] for r in front.rows], rel=1e-9)
    assert out["inputs"]["command"] == "pareto"
    path = tmp_path / "front.csv"
    assert (
        main(
            [
                "pareto",
                "--model",
                "planar_2r",
                "--R",
                "0.5",
                "--p",
                "0.9,0.99",
                "--probability",
                "gaussian",
                "--out",
                str(path),
            ]
        )
        == 0
    )
    frame = pd.read_csv(path)  # plain pandas
    assert list(frame["p"]) == [0.9, 0.99] and frame["cost"].is_monotonic_increasing
    assert tolsynth.read_table(path).attrs["summary"]["axis"] == "p"


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["--R", "0.5", "--p", "0.9"], "--R/--p"),
        (["--R", "0.9:0.3:3", "--p", "0.9"], "START < STOP"),
        (["--R", "0.3:0.9:1", "--p", "0.9"], "N"),
        (["--R", "0.3:0.9:x", "--p", "0.9"], "whole number"),
    ],
)
def test_pareto_bad_ranges(capsys, argv, needle):
    assert main(["pareto", "--model", "planar_2r"] + argv) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_budget_matches_the_api(capsys, tmp_path):
    out = _json(capsys, ["budget", "--model", "planar_2r", "--p", "0.99", "--cost", "12", "--probability", "gaussian"])
    api = tolsynth.best_accuracy("planar_2r", 12.0, p=0.99, probability="gaussian")
    assert out["budget"]["value"] == pytest.approx(api.value, rel=1e-9)
    assert out["budget"]["certified"] and out["cost"] <= 12.0
    path = tmp_path / "b.xlsx"
    pytest.importorskip("openpyxl")
    assert (
        main(
            [
                "budget",
                "--model",
                "planar_2r",
                "--R",
                "0.5",
                "--cost",
                "12",
                "--probability",
                "gaussian",
                "--out",
                str(path),
            ]
        )
        == 0
    )
    frame = pd.read_excel(path)
    assert frame["cost"].sum() <= 12.0 + 1e-9
    assert tolsynth.read_table(path).attrs["summary"]["budget"]["quantity"] == "p"
    assert main(["budget", "--model", "planar_2r", "--cost", "12"]) == 2
    assert "--p/--R" in capsys.readouterr().err


def test_processes_from_a_table_file(capsys, tmp_path):
    table = tmp_path / "procs.toml"
    table.write_text(PROCS)
    out = _json(
        capsys,
        [
            "processes",
            "--model",
            "xu_zhang_1988",
            "--R",
            "0.5",
            "--p",
            "0.99",
            "--table",
            str(table),
            "--probability",
            "gaussian",
        ],
    )
    from tolsynth.model.cost import PowerLaw

    procs = {
        "h3": [
            tolsynth.Process("turning", PowerLaw(1.0, 0.7), 0.05, 0.5),
            tolsynth.Process("grinding", PowerLaw(3.0, 0.7), 0.005, 0.05),
        ]
    }
    api = tolsynth.synthesize_processes("xu_zhang_1988", 0.5, 0.99, procs, probability="gaussian")
    assert out["processes"] == api.processes and out["proven"]
    assert out["cost"] == pytest.approx(api.cost, rel=1e-9)
    path = tmp_path / "pc.csv"
    assert (
        main(
            [
                "processes",
                "--model",
                "xu_zhang_1988",
                "--R",
                "0.5",
                "--p",
                "0.99",
                "--table",
                str(table),
                "--probability",
                "gaussian",
                "--out",
                str(path),
            ]
        )
        == 0
    )
    frame = pd.read_csv(path).set_index("parameter")
    assert frame.loc["h3", "process"] == api.processes["h3"]
    # no table and no processes in the model file; a table that is not TOML
    assert main(["processes", "--model", "planar_2r", "--R", "0.5", "--p", "0.9"]) == 2
    assert "--table" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text("[[h3]\nname=")
    assert main(["processes", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.9", "--table", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "cannot be read" in err and "Traceback" not in err


@pytest.mark.parametrize(
    "name", [pytest.param(n, marks=[] if n == "planar_2r" else pytest.mark.slow) for n in tolsynth.bundled_models()]
)
def test_every_bundled_model_with_the_default_probability(capsys, name):
    from tolsynth.kinematics.joint_space import model_reference

    m = tolsynth.load_model(name)
    pose = [] if model_reference(m) else ["--pose", next(iter(m.configurations))]
    out = _json(capsys, ["pareto", "--model", name, "--R", "0.5,1", "--p", "0.99", *pose])
    assert all(r["success"] for r in out["rows"]) and out["inputs"]["model"]["name"] == name
    budget = out["rows"][1]["cost"] * 1.01  # a little above the R = 1 design's cost: it buys R <= 1
    out = _json(capsys, ["budget", "--model", name, "--p", "0.99", "--cost", f"{budget:.12g}", "--rtol", "1e-3", *pose])
    assert out["budget"]["certified"] and out["budget"]["value"] <= 1.0 + 1e-9


def test_solve_worst_case_without_p(capsys):
    """``solve --probability worst_case`` needs no --p: the design's hand error over every corner of
    the error box (2^11 sign patterns, brute force on the sensitivity matrix) reaches R = 0.8 and no
    further; with --p the statistical design's cost is beside it (the worst case about 69 % dearer)."""
    import itertools

    import numpy as np

    out = _json(capsys, ["solve", "--model", "xu_zhang_1988", "--R", "0.8", "--probability", "worst_case"])
    assert out["success"] and out["inputs"]["probability"] == "worst_case"
    m = tolsynth.load_model("xu_zhang_1988")
    A = np.asarray(m.sensitivity("worst"))[:3]
    eps = np.array([out["tolerances"][n] for n in m.error_parameters])
    worst = max(np.linalg.norm(A @ (np.array(s) * eps)) for s in itertools.product((-1.0, 1.0), repeat=len(eps)))
    assert worst == pytest.approx(0.8, rel=1e-6)
    both = _json(
        capsys, ["solve", "--model", "xu_zhang_1988", "--R", "0.8", "--p", "0.99", "--probability", "worst_case"]
    )
    assert both["cost"] == pytest.approx(out["cost"], rel=1e-9)
    assert 1.6 < both["cost"] / both["statistical"]["cost"] < 1.8
    for bad in (["--solver", "both"], ["--everywhere", "--p", "0.99"], ["--criterion", "sphere"]):
        assert main(["solve", "--model", "planar_2r", "--R", "0.5", "--probability", "worst_case", *bad]) == 2
    assert main(["solve", "--model", "planar_2r", "--R", "0.5"]) == 2  # a statistical design needs --p
    assert "--p" in capsys.readouterr().err


@pytest.mark.slow  # 4-15 s: the default run stays under 4 minutes
def test_grades_command(capsys, tmp_path):
    """``tolsynth grades``: lengths rounded to ISO 286 grades at 300 mm, whose half widths are the
    standard's table typed here (250-315 mm: IT11 320 um, IT12 520 um, IT10 210 um, IT13 810 um),
    angles to a grade file; the --out CSV reads back with pandas.read_csv and no arguments."""
    iso_half = {"IT10": 0.105, "IT11": 0.16, "IT12": 0.26, "IT13": 0.405}
    grades = tmp_path / "g.toml"
    grades.write_text('["o*"]\nA = 0.1\nB = 0.2\nC = 0.5\nD = 1.0\n', encoding="utf-8")
    out = _json(
        capsys,
        [
            "grades",
            "--model",
            "planar_2r",
            "--R",
            "0.5",
            "--p",
            "0.99",
            "--sizes",
            "l1=300,l2=0.3m",
            "--grades",
            str(grades),
        ],
    )
    assert out["proven"] and out["cost"] >= out["continuous_cost"]
    for n in ("l1", "l2"):
        assert out["tolerances"][n] == pytest.approx(iso_half[out["grades"][n]], rel=1e-12)
    for n in ("o1", "o2"):
        assert out["tolerances"][n] == {"A": 0.1, "B": 0.2, "C": 0.5, "D": 1.0}[out["grades"][n]]
    csv = tmp_path / "g.csv"
    assert (
        main(
            [
                "grades",
                "--model",
                "planar_2r",
                "--R",
                "0.5",
                "--p",
                "0.99",
                "--sizes",
                "300",
                "--grades",
                str(grades),
                "--out",
                str(csv),
            ]
        )
        == 0
    )
    frame = pd.read_csv(csv).set_index("parameter")
    assert frame.loc["l1", "grade"] == out["grades"]["l1"] and frame.loc["o2", "tolerance"] == out["tolerances"]["o2"]
    capsys.readouterr()
    for bad in (["--sizes", "l1=abc"], ["--sizes", "l1=3,l1=4"], ["--grades", str(tmp_path / "none.toml")]):
        assert main(["grades", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", *bad]) == 2


def test_grades_errors_name_the_options(capsys, tmp_path):
    """Bad grades input on the command line names --sizes and --grades (what was typed), never the
    library's sizes= or table=, and is refused before the solve."""
    base = ["grades", "--model", "planar_2r", "--R", "0.5", "--p", "0.99"]
    good = tmp_path / "g.toml"
    good.write_text('["o*"]\nA = 0.1\n', encoding="utf-8")
    bad = tmp_path / "bad.toml"
    bad.write_text('["o*"]\nA = "0.1mm"\n', encoding="utf-8")
    one = tmp_path / "one.toml"
    one.write_text('["o1"]\nA = 0.1\n', encoding="utf-8")
    cases = [
        (["--sizes", "l1=5000", "--grades", str(good)], "--sizes l1: got 5000 mm"),
        (["--sizes", "5m", "--grades", str(good)], "--sizes: got 5000 mm"),
        (["--sizes", "l1=300"], "error: --grades: o1 is an angle (mrad) and ISO 286 grades are for linear sizes"),
        (["--grades", str(bad)], f"--grades {bad}: [o*] A: '0.1mm' is not a number with an angle unit"),
        (["--grades", str(one)], f"--grades {one}: [o2]: o2 is an angle"),
    ]
    for extra, needle in cases:
        assert main(base + extra) == 2, extra
        err = capsys.readouterr().err
        assert needle in err, (extra, err)
        assert "size:" not in err and "table[" not in err and "table=" not in err, err
        assert "Traceback" not in err and err.count("\n") == 1
    assert main(base + ["--sizes", "l1=300"]) == 2
    assert '--grades FILE, a TOML file with a table ["o1"]' in capsys.readouterr().err


def test_grades_file_with_unit_suffixes(capsys, tmp_path):
    """A grade file's suffixed values are converted to the angles' unit, mrad, by hand here:
    "200urad" = 0.2 mrad, "0.0573deg" = 0.0573 pi / 180 rad = 1.000070 mrad."""
    grades = tmp_path / "g.toml"
    grades.write_text('["o*"]\nA = "200urad"\nB = "0.0573deg"\n', encoding="utf-8")
    out = _json(
        capsys,
        ["grades", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--probability", "gaussian"]
        + ["--sizes", "0.3m", "--grades", str(grades)],
    )
    want = {"A": 0.2, "B": 0.0573 * math.pi / 180 * 1000}
    for n in ("o1", "o2"):
        assert out["tolerances"][n] == pytest.approx(want[out["grades"][n]], rel=1e-12)
    assert out["sizes"] == {"l1": 300.0, "l2": 300.0}
