"""The command line reaches what the API reaches, checked against the API and
against conversions done by hand: unit suffixes, wildcards, per-parameter alpha / k / bounds,
several poses, p_orientation, --version, help texts and defaults, JSON inputs, the side-by-side
table of --solver both, and plain progress lines without tqdm (point 6)."""

from __future__ import annotations

import io
import json
import math

import numpy as np
import pytest

import tolsynth
from tolsynth.cli import build_parser, main
from tolsynth.progress import LineProgress


def _json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def _analyze_tol(capsys, text):
    out = _json(capsys, ["analyze", "--model", "xu_zhang_1988", "--tolerances", text, "--R", "0.2", "--json"])
    return out["tolerances"]


def test_tolerance_units_wildcards_and_overrides(capsys, xz):
    fig3 = dict(zip(xz.error_parameters, xz.tolerances("figure3")))
    t = _analyze_tol(capsys, "figure3,h2=5um,alpha1=2mrad,alpha3=0.1deg")
    assert t["h2"] == pytest.approx(0.005, rel=1e-12)  # mm
    assert t["alpha1"] == pytest.approx(0.2, rel=1e-12)  # 2 mrad in the model's 1e-2 rad
    assert t["alpha3"] == pytest.approx(math.radians(0.1) / 1e-2, rel=1e-12)
    assert t["h3"] == fig3["h3"]
    t = _analyze_tol(capsys, "*=0.02")  # every parameter, each in its own tolerance unit
    assert all(v == 0.02 for v in t.values())
    t = _analyze_tol(capsys, "*=0.02mm,*=1mrad,h2=0.03")  # suffixed patterns set their unit's kind only
    assert t["h2"] == 0.03 and t["a"] == 0.02 and t["alpha4"] == pytest.approx(0.1, rel=1e-12)
    t = _analyze_tol(capsys, "figure3,hp*=0.04")
    assert [t[n] for n in ("hp2", "hp3", "hp4")] == [0.04] * 3 and t["h2"] == fig3["h2"]


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("figure3,h2=0.1,h2=0.2", "h2 given twice"),
        ("figure3,,,", "empty item 2"),
        ("figure3,h2=2mrad", "h2 is a length"),
        ("figure3,x*=1", "matches no error parameter"),
        ("*=0.02mm", "no tolerance for alpha1"),
        ("figure3,h2=1parsec", "unknown unit 'parsec'"),
        ("figure3,figure3", "two tolerance sets"),
    ],
)
def test_bad_tolerances_are_typed_errors(capsys, text, fragment):
    assert main(["analyze", "--model", "xu_zhang_1988", "--tolerances", text, "--R", "0.2"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tolsynth analyze: error: --tolerances") and fragment in err, err


def test_lengths_and_angles_take_suffixes(capsys):
    base = ["analyze", "--model", "xu_zhang_1988", "--tolerances", "figure3", "--json"]
    a = _json(capsys, base + ["--R", "0.2", "--Phi", "0.01"])
    b = _json(capsys, base + ["--R", "200um", "--Phi", "10mrad"])
    assert a["R"] == b["R"] == 0.2 and a["Phi"] == pytest.approx(b["Phi"], rel=1e-15)
    assert a["p_sphere"] == b["p_sphere"] and a["p_cone"] == b["p_cone"]
    q = _json(capsys, base + ["--R", "0.2", "--pose", "0,180,130,0,0"])["q_rad"]
    r = _json(capsys, base + ["--R", "0.2", "--pose", f"0,{math.pi}rad,130deg,0,0"])["q_rad"]
    assert np.allclose(q, r, rtol=0, atol=1e-15)
    assert main(base + ["--R", "0.2", "--pose", "0,180,130,0,2mm"]) == 2
    err = capsys.readouterr().err
    assert "--pose" in err and "mm is not an angle unit" in err and "a number in deg" in err, err


def test_solve_reaches_alpha_k_bounds_poses_and_p_orientation(capsys):
    m = tolsynth.load_model("planar_2r")
    alpha = np.array([0.7, 0.5, 0.7, 0.9])
    k = np.array(m.k, dtype=float)
    k[0] = 3.0
    lo, hi = (np.array(b, dtype=float) for b in m.bounds)
    hi[0] = 0.2  # l1 <= 0.2 mm: below its optimum (0.223 mm), so the bound is active
    api = tolsynth.synthesize(
        m,
        0.5,
        0.99,
        "uniform",
        alpha,
        k=k,
        bounds=(lo, hi),
        poses=["stretched", "elbow90"],
        Phi=0.005,
        p_orientation=0.95,
        probability="gaussian",
    )
    assert api.success and api.bounds_active == {"l1": "upper"}
    argv = [
        "solve",
        "--model",
        "planar_2r",
        "--R",
        "0.5",
        "--p",
        "0.99",
        "--alpha",
        "0.7,l2=0.5,o2=0.9",
        "--k",
        "l1=3",
        "--bounds",
        "l1=:200um",
        "--pose",
        "stretched",
        "--pose",
        "elbow90",
        "--Phi",
        "5mrad",
        "--p-orientation",
        "0.95",
        "--probability",
        "gaussian",
    ]
    out = _json(capsys, argv + ["--json"])
    assert out["cost"] == pytest.approx(api.cost, rel=1e-9)
    assert out["bounds_active"] == {"l1": "upper"}
    inp = out["inputs"]
    assert inp["tolsynth_version"] == tolsynth.__version__ and inp["model"]["name"] == "planar_2r"
    assert inp["alpha"] == alpha.tolist() and inp["k"] == k.tolist() and inp["poses_rad"] == ["stretched", "elbow90"]
    assert (
        inp["bounds"][1] == pytest.approx(hi.tolist(), rel=1e-15)
        and inp["p_orientation"] == 0.95
        and inp["Phi_rad"] == 0.005
    )
    # --solver both: everything a single solve shows, side by side
    assert main(argv + ["--solver", "both"]) == 0
    text = capsys.readouterr().out
    for fragment in (
        "dual lower bound",
        "gap (cost - bound)",
        "mm [upper]",
        "mrad",
        f"{api.cost:.8g}",
        "position at pose 'elbow90' [1]",
        "orientation at pose 'stretched' [1]",
        "SUMT + Powell",
    ):
        assert fragment in text, fragment
    assert text.count("mm [upper]") == 2  # the marker in both columns


def test_solver_defaults_to_auto_with_ipopt_and_sumt_on_request(capsys):
    """The command line's default engine is the API's (auto: the compiled interior-point method where
    a compiler is found), on solve, report and sweep; --solver ipopt and sumt still run those
    algorithms, and all three reach the same optimum."""
    import argparse

    from tolsynth.solvers.fast_ipm import kernel_status

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    for name in ("solve", "report"):
        action = next(a for a in sub.choices[name]._actions if "--solver" in a.option_strings)
        assert action.default == "auto" and {"auto", "ipopt", "sumt"} <= set(action.choices), name
    sweep_help = next(a for a in sub.choices["sweep"]._actions if "--solver" in a.option_strings).help
    assert "default: auto" in sweep_help
    # the paper's criterion, where the compiled interior-point method applies
    base = ["solve", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.99", "--json", "--probability", "gaussian"]
    runs = {s: _json(capsys, base + ([] if s == "auto" else ["--solver", s])) for s in ("auto", "ipopt", "sumt")}
    assert runs["auto"]["inputs"]["solver"] == "auto"
    assert runs["auto"]["solver"] == ("ipm" if kernel_status()["backend"] == "compiled" else "ipopt")
    assert runs["ipopt"]["solver"] == "ipopt" and runs["sumt"]["solver"] == "sumt"
    for s in ("ipopt", "sumt"):  # other algorithms, the same optimum
        assert runs["auto"]["cost"] == pytest.approx(runs[s]["cost"], rel=1e-6), s


def test_solve_rejects_p_orientation_without_phi(capsys):
    assert main(["solve", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--p-orientation", "0.9"]) == 2
    assert "--p-orientation" in capsys.readouterr().err


@pytest.mark.parametrize(
    "extra, fragment",
    [
        (["--everywhere"], "given with --everywhere"),
        (["--solver", "both"], "given with --solver both"),
    ],
)
def test_solve_rejects_verify_where_it_would_be_ignored(capsys, extra, fragment):
    """--verify closes the loop of one solve; with --everywhere or both solvers it would silently do
    nothing, so it is a typed error naming the option."""
    assert main(["solve", "--model", "planar_2r", "--R", "0.5", "--p", "0.9", "--verify", "auto"] + extra) == 2
    err = capsys.readouterr().err
    assert "--verify" in err and fragment in err and "Traceback" not in err


def test_solve_and_report_share_the_specification_options():
    """One definition of the specification's options: solve and report offer the same ones."""
    import argparse

    from tolsynth.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    opts = {name: {o for a in sub.choices[name]._actions for o in a.option_strings} for name in ("solve", "report")}
    shared = {
        "--model",
        "--R",
        "--p",
        "--dist",
        "--alpha",
        "--k",
        "--bounds",
        "--solver",
        "--pose",
        "--Phi",
        "--p-orientation",
        "--criterion",
        "--probability",
        "--verify",
        "--lock",
    }
    assert shared <= opts["solve"] and shared <= opts["report"]


def test_version_and_help(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0 and capsys.readouterr().out.strip() == f"tolsynth {tolsynth.__version__}"
    parser = build_parser()
    top = parser.format_help()
    assert "`" not in top
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    for name in ("analyze", "solve", "reproduce", "montecarlo", "map", "worst-pose"):
        assert name in top and name in sub.choices
    for name, p in sub.choices.items():
        text = p.format_help()
        for action in p._actions:
            if not action.option_strings or action.dest == "help":
                continue
            assert action.help, f"{name} {action.option_strings[0]} has no help text"
            if action.default not in (None, False):
                assert f"(default: {action.default})" in " ".join(text.split()), (name, action.dest)


def test_every_json_output_records_inputs_and_version(capsys):
    runs = [
        ["analyze", "--model", "planar_2r", "--tolerances", "coarse", "--R", "0.5"],
        ["solve", "--model", "planar_2r", "--R", "0.5", "--p", "0.9"],
        ["montecarlo", "--model", "planar_2r", "--tolerances", "coarse", "--R", "0.5", "--n", "1000"],
        ["worst-pose", "--model", "planar_2r", "--tolerances", "coarse", "--grid", "5"],
    ]
    for argv in runs:
        out = _json(capsys, argv + ["--json"])
        inp = out["inputs"]
        assert inp["tolsynth_version"] == tolsynth.__version__ and inp["command"] == argv[0]
        assert inp["model"]["name"] == "planar_2r" and inp["model"]["file"].endswith("planar_2r.toml")
        assert inp["arguments"]["model"] == "planar_2r"


def test_line_progress_without_tqdm():
    buf = io.StringIO()
    bar = LineProgress(200, "map (inverse kinematics)", "pt", delay=0.0, every=0.0, file=buf)
    bar.update(50)
    bar.update(150)
    bar.close()
    lines = buf.getvalue().splitlines()
    assert lines[0].startswith("map (inverse kinematics): 50/200 pt (25%)")
    assert lines[-1].startswith("map (inverse kinematics): 200/200 pt, done in")
    quiet = io.StringIO()
    bar = LineProgress(10, "short", "pt", delay=60.0, file=quiet)  # a run shorter than the delay
    bar.update(10)
    bar.close()
    assert quiet.getvalue() == ""


def test_make_bar_falls_back_to_lines(monkeypatch):
    import sys

    from tolsynth.progress import make_bar

    monkeypatch.setitem(sys.modules, "tqdm", None)
    assert isinstance(make_bar(10, "x", "pt", 2.0), LineProgress)
