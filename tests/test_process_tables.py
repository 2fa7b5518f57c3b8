"""``tolsynth processes`` with a table file: the table written shows the cost model each process
actually used (its k and alpha, checked against the cost recomputed in closed form from the
tolerance), and a bad entry is named by file, parameter and process."""

from __future__ import annotations

import pytest

import tolsynth
from tolsynth.cli import main
from tolsynth.errors import InputError

pd = pytest.importorskip("pandas")

TABLE = """
[[h2]]
name = "turning"
cost = { model = "power", k = 5.0, alpha = 0.7 }
lower = 0.01
upper = 0.5

[[alpha1]]
name = "milling"
cost = { model = "power", k = 10.0, alpha = 0.6 }
lower = 0.01
upper = 5
"""

BASE = ["processes", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.99", "--probability", "gaussian"]


def test_table_shows_the_process_cost_model(tmp_path, capsys):
    table = tmp_path / "proc.toml"
    table.write_text(TABLE)
    out = tmp_path / "pr.csv"
    assert main(BASE + ["--table", str(table), "--out", str(out)]) == 0
    frame = pd.read_csv(out).set_index("parameter")
    for name, k, alpha in (("h2", 5.0, 0.7), ("alpha1", 10.0, 0.6)):
        row = frame.loc[name]
        assert (row["k"], row["alpha"]) == (k, alpha)
        assert row["cost"] == pytest.approx(k * row["tolerance"] ** -alpha, rel=1e-12)
        assert row["cost_model"] == f"{k:g} eps^-{alpha:g}"
    # a parameter without a process keeps the model file's k = 1 (lengths) eps^-0.7
    assert frame.loc["h3", "k"] == 1.0
    assert frame.loc["h3", "cost"] == pytest.approx(frame.loc["h3", "tolerance"] ** -0.7, rel=1e-12)


def test_bad_cost_names_file_parameter_and_process(tmp_path, capsys):
    table = tmp_path / "bad_cost.toml"
    table.write_text(TABLE.replace('{ model = "power", k = 5.0, alpha = 0.7 }', "20.0"))
    assert main(BASE + ["--table", str(table)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    for part in (str(table), "parameter h2", "process 'turning'", "cost: got 20.0"):
        assert part in err, (part, err)
    # an unknown parameter is named with the file too
    table.write_text(TABLE.replace("[[h2]]", "[[h9]]"))
    assert main(BASE + ["--table", str(table)]) == 2
    err = capsys.readouterr().err
    assert str(table) in err and "h9" in err and "unknown error parameter" in err


def test_api_error_names_parameter_and_process():
    procs = {"h2": [{"name": "turning", "cost": 20.0, "lower": 0.01, "upper": 0.5}]}
    with pytest.raises(InputError) as info:
        tolsynth.synthesize_processes("xu_zhang_1988", 0.5, 0.99, procs, probability="gaussian")
    assert "parameter h2, process 'turning'" in str(info.value) and info.value.field.endswith("cost")


def test_help_says_cost_is_a_cost_model_table(capsys):
    with pytest.raises(SystemExit):
        main(["processes", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert 'cost a cost-model table, e.g. cost = { model = "power", k = 1.0, alpha = 0.7 }' in text


def test_printed_report_lists_every_parameter(tmp_path, capsys):
    """The printed report shows each parameter's tolerance, those without a process too ('model
    cost'), and the printed values are the CSV's, every parameter of the model once."""
    table = tmp_path / "proc.toml"
    table.write_text(TABLE)
    out = tmp_path / "pr.csv"
    assert main(BASE + ["--table", str(table), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    frame = pd.read_csv(out).set_index("parameter")
    m = tolsynth.load_model("xu_zhang_1988")
    for name in m.error_parameters:
        line = next(ln for ln in text.splitlines() if ln.strip().startswith(f"{name}:"))
        eps = float(line.split("eps = ")[1].split()[0])
        assert eps == pytest.approx(frame.loc[name, "tolerance"], rel=1e-5)
        assert ("model cost" in line) == (name not in ("h2", "alpha1")), line
