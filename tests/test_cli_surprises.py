"""The first day without surprises: the command line and the defaults a new user meets, each
checked against the API or against a number computed here (NumPy eigenvalues, closed forms)."""

from __future__ import annotations

import io
import json
import math
import sys
import warnings

import numpy as np
import pytest

import tolsynth
from tolsynth.cli import build_parser, main
from tolsynth.errors import WorkspaceWarning

BASE = ["solve", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--pose", "elbow90"]


def _json(capsys, argv):
    assert main(argv) == 0, capsys.readouterr().err
    return json.loads(capsys.readouterr().out)


# ---------------------------------------------------------------------------------------------
# --lock: units, duplicates, bounds; never dropped with --solver both or --everywhere
# ---------------------------------------------------------------------------------------------
def test_lock_takes_a_unit_suffix(capsys):
    out = _json(capsys, BASE + ["--lock", "l1=50um", "--json"])
    assert out["tolerances"]["l1"] == pytest.approx(0.05, rel=1e-12)
    api = tolsynth.synthesize("planar_2r", 0.5, 0.99, pose="elbow90", locks={"l1": "50um"})  # both exact
    assert out["cost"] == pytest.approx(api.cost, rel=1e-8) and api.tolerances["l1"] == pytest.approx(0.05, rel=1e-12)


@pytest.mark.parametrize(
    "locks, fragment",
    [
        (["l1=0.05", "l1=0.06"], "--lock l1: given twice"),
        (["l1=1e-5"], "locks[l1]: 1e-05 mm is outside the parameter's bounds"),
        (["o1=50um"], "--lock o1: '50um' is not a tolerance"),
        (["x9=0.1"], "x9"),
        (["l1"], "NAME=VALUE"),
    ],
)
def test_bad_locks_are_one_line_errors(capsys, locks, fragment):
    argv = list(BASE)
    for item in locks:
        argv += ["--lock", item]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert fragment in err and err.count("\n") == 1, err


def test_lock_and_contributions_with_both_solvers(capsys):
    """--solver both applies the lock to both solvers and reports both contributions (they were
    dropped silently): each solver's l1 is the lock, and each report's shares sum to 1 per
    principal variance (a property of the contributor report, checked on the JSON)."""
    out = _json(capsys, BASE + ["--solver", "both", "--lock", "l1=0.05", "--contributions", "--json"])
    for s in ("ipopt", "sumt"):
        assert out[s]["tolerances"]["l1"] == pytest.approx(0.05, rel=1e-9)
        assert set(out["contributions"]) == {"ipopt", "sumt"}


def test_lock_and_contributions_with_everywhere(capsys):
    out = _json(
        capsys,
        [
            "solve",
            "--model",
            "planar_2r",
            "--R",
            "0.5",
            "--p",
            "0.99",
            "--everywhere",
            "--lock",
            "l1=0.05",
            "--contributions",
            "--json",
        ],
    )
    assert out["tolerances"]["l1"] == pytest.approx(0.05, rel=1e-9)
    assert "contributions" in out


# ---------------------------------------------------------------------------------------------
# defaults that work for every model, and say what they chose
# ---------------------------------------------------------------------------------------------
def _no_worst():
    """A from_dh robot without a 'worst' configuration (planar 2R, the bundled model's table)."""
    return tolsynth.Mechanism.from_dh(
        [{"a": 500.0, "limits": (-170, 170)}, {"a": 300.0, "limits": (-150, 150)}],
        angle_unit="deg",
        name="two_link",
        configurations={"bent": [30.0, 90.0]},
    )


def test_default_pose_for_a_model_without_worst():
    """pose="worst" (the default) on a robot with no such configuration: the worst-pose search's
    pose, said in the result; the design meets the specification there (sigma z/R <= 1 by NumPy)."""
    m = _no_worst()
    res = tolsynth.synthesize(m, 0.5, 0.99, probability="gaussian")
    assert res.success and "worst-pose search" in res.inputs["default_pose"] and "pose:" in res.summary()
    q = np.array(list(res.spec.poses.values())[0])
    S = m.sensitivity(q)[:3]
    lam = np.linalg.eigvalsh(S @ np.diag(res.x**2 / 3.0) @ S.T)
    assert math.sqrt(lam.max()) * tolsynth.z_of_p(0.99) / 0.5 == pytest.approx(1.0, abs=1e-6)
    again = tolsynth.synthesize(m, 0.5, 0.99, probability="gaussian")  # the same pose again (deterministic, remembered)
    assert np.array_equal(np.array(list(again.spec.poses.values())[0]), q)


@pytest.mark.parametrize("command", ["worst-pose", "map"])
def test_map_and_worst_pose_default_tolerances_for_every_model(capsys, command):
    """panda has no figure3 set: the default is its first set, and the output says so; the same
    set given explicitly gives the same numbers."""
    extra = ["--n", "8", "--quiet"] if command == "map" else ["--grid", "3"]
    argv = [command, "--model", "panda", *extra]
    assert main(argv) == 0, capsys.readouterr().err
    text = capsys.readouterr().out
    first = next(iter(tolsynth.load_model("panda").tolerance_sets))
    assert f"tolerances   {first} (the model's first tolerance set" in text
    a = _json(capsys, argv + ["--json"])
    b = _json(capsys, argv + ["--json", "--tolerances", first])
    key = "value" if command == "worst-pose" else "worst"
    assert a[key] == b[key]


# ---------------------------------------------------------------------------------------------
# validate=N at every pose; the workspace check; the HTML repr
# ---------------------------------------------------------------------------------------------
def test_validate_checks_every_pose():
    """Two poses: both are run (per_pose), and the one reported is the one with the lowest
    P(|w_j| <= R), whose analytic value is the erf of its sigma (closed form)."""
    res = tolsynth.synthesize(
        "planar_2r", 0.5, 0.99, poses=["elbow90", "worst"], validate=20_000, seed=1, probability="gaussian"
    )
    v = res.validation
    assert len(v.per_pose) == 2 and {p.pose for p in v.per_pose} == {"elbow90", "worst"}
    assert min(float(np.min(p.p_components)) for p in v.per_pose) == float(np.min(v.p_components))
    a = tolsynth.load_model("planar_2r").analyze(v.pose, res.x, R=0.5)
    ana = [math.erf(0.5 / (math.sqrt(2) * s)) if s > 0 else 1.0 for s in a.principal_std]
    assert np.allclose(v.p_components_analytic, ana, rtol=1e-9, atol=1e-12)
    assert "the worst of 2 poses" in v.report() and len(v.to_dict()["per_pose"]) == 2


def test_workspace_check_of_a_single_pose_design():
    """The paper's design at its one pose is over the specification elsewhere: the sampled check
    says by how much and where, warns pointing to synthesize_workspace, and its number at that
    pose is sigma_1 z / R from Mechanism.analyze (NumPy's eigensolver)."""
    m = tolsynth.load_model("xu_zhang_1988")
    res = tolsynth.synthesize(m, 0.5, 0.99, probability="gaussian")
    with pytest.warns(WorkspaceWarning, match="synthesize_workspace"):
        line = res.workspace.line()
    ws = res.workspace
    assert ws.exceeds and ws.worst > 1.05 and ws.n_poses > 200
    a = m.analyze(ws.q, res.x, R=0.5, check_limits=False)
    assert ws.worst == pytest.approx(a.principal_std[0] * tolsynth.z_of_p(0.99) / 0.5, rel=1e-9)
    assert "% over the specification" in line and line in res.summary()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert res.workspace.worst == ws.worst  # computed once: the same answer, no second warning


def test_workspace_check_of_an_everywhere_design_finds_nothing():
    w = tolsynth.synthesize_workspace("planar_2r", 0.5, 0.99, probability="gaussian")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert w.result.workspace.worst <= 1 + 1e-3
        assert "within the specification" in w.result.workspace.line()


def test_results_show_as_html_in_notebooks():
    res = tolsynth.synthesize("planar_2r", 0.5, 0.99, pose="elbow90", probability="gaussian")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        html = res._repr_html_()
    assert html.startswith("<div>") and "<table>" in html
    for name, v in res.tolerances.items():
        assert f"<td>{name}</td><td>{v:.6g}</td>" in html


# ---------------------------------------------------------------------------------------------
# help texts and progress
# ---------------------------------------------------------------------------------------------
def test_help_texts_say_each_default_once_and_the_truth():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    for name, sp in sub.choices.items():
        for action in sp._actions:
            text = sp._get_formatter()._expand_help(action) if action.help else ""
            assert text.lower().count("default") <= 1, (name, action.option_strings, text)
    sweep_help = " ".join(sub.choices["sweep"].format_help().split())
    assert "uniform, normal, triangular, truncnormal" in sweep_help
    reproduce_help = " ".join(sub.choices["reproduce"].format_help().split())
    assert "1.5 s" not in reproduce_help and "milliseconds" in reproduce_help


def test_working_reports_long_runs_only():
    import time

    from tolsynth.progress import Working

    buf = io.StringIO()
    with Working("tolsynth solve: a long run", delay=0.05, every=0.1, file=buf, show=True):
        time.sleep(0.35)
    lines = buf.getvalue().splitlines()
    assert lines[0].startswith("tolsynth solve: a long run, 0 s") and lines[-1].startswith(
        "tolsynth solve: a long run: done in"
    )
    buf = io.StringIO()
    with Working("short", delay=0.5, file=buf, show=True):
        pass
    assert buf.getvalue() == ""


def test_progress_shows_in_a_notebook(monkeypatch):
    from tolsynth.progress import interactive

    class NotATerminal(io.StringIO):
        def isatty(self):
            return False

    monkeypatch.setattr(sys, "stderr", NotATerminal())
    monkeypatch.delitem(sys.modules, "ipykernel", raising=False)
    assert interactive() is False
    monkeypatch.setitem(sys.modules, "ipykernel", type(sys)("ipykernel"))
    assert interactive() is True


def test_summary_runs_no_workspace_search_and_shows_it_once_computed():
    """summary() and to_dict() are pure: they run no sampled workspace check (no warning, nothing
    computed) and say how to get it; once it is read, both show it, with its own numbers."""
    res = tolsynth.synthesize("xu_zhang_1988", 0.5, 0.99, probability="gaussian")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        text = res.summary()
        d = res.to_dict()
    assert not res.workspace.computed and d["workspace_check"] is None
    assert "workspace check: not computed (result.workspace.line() samples 300 poses" in text
    with pytest.warns(WorkspaceWarning):
        line = res.workspace.line()
    assert line in res.summary()
    d = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    assert d["workspace_check"]["worst"] == res.workspace.worst > 1.05 and d["workspace_check"]["line"] == line
    assert res.to_frame().attrs["summary"]["workspace_check"]["worst"] == res.workspace.worst


def test_command_line_solve_still_shows_the_workspace_check(capsys):
    """The command line computes the check for what it prints: the line in the summary, and the
    warning on stderr for a design over its specification elsewhere (sigma z / R from
    Mechanism.analyze at the pose it names)."""
    assert main(["solve", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.99", "--probability", "gaussian"]) == 0
    cap = capsys.readouterr()
    line = next(s for s in cap.out.splitlines() if s.startswith("workspace check ("))
    assert "% over the specification" in line and "warning: workspace check (" in cap.err
    m = tolsynth.load_model("xu_zhang_1988")
    res = tolsynth.synthesize(m, 0.5, 0.99, probability="gaussian")
    with pytest.warns(WorkspaceWarning):
        ws = res.workspace
        a = m.analyze(ws.q, res.x, R=0.5, check_limits=False)
    assert f"{a.principal_std[0] * tolsynth.z_of_p(0.99) / 0.5:.4f}" in line
