"""The certified search on the command line, run as a user runs it (a child process): exit
statuses, the JSON fields of the proof, and the numbers checked against the sensitivity evaluated
at the reported poses (``Mechanism.sensitivity`` with NumPy's eigensolver) and random poses."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

import tolsynth
from independent import sigma_max
from tolsynth.kinematics.joint_space import _feasible, _limits
from tolsynth.probability.stats import z_of_p

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


#: a solve of the planar 2R, the start of the usage errors' command lines
SOLVE_2R = ("solve", "--model", "planar_2r", "--R", "0.1", "--p", "0.99")


def _run(*argv: str) -> tuple[int, dict | None, str]:
    proc = subprocess.run(
        [sys.executable, "-m", "tolsynth", *argv], capture_output=True, text=True, cwd=ROOT, timeout=900
    )
    try:
        out = json.loads(proc.stdout)
    except json.JSONDecodeError:
        out = None
    return proc.returncode, out, proc.stderr


@pytest.mark.parametrize("workers", [None, "1", "2"])
def test_worst_pose_certify_json_holds_its_proof(workers):
    rc, out, _ = _run(
        "worst-pose", "--model", "planar_2r", "--certify", "--json", *(["--workers", workers] if workers else [])
    )
    assert rc == 0
    m = tolsynth.load_model("planar_2r")
    sig = sigma_max(m, np.array(out["q"]), np.array(list(out["tolerances"].values())))[0]
    assert out["certified"] is True and out["boxes"] > 0
    assert sig == pytest.approx(out["value"], rel=1e-9)
    assert out["value"] <= out["upper_bound"] <= out["value"] * (1 + 5e-4)
    assert out["certificate"]["certified"] is True and "leaves" not in out["certificate"]


def test_worst_pose_certify_components_gives_a_probability_bound():
    rc, out, _ = _run(
        "worst-pose",
        "--model",
        "planar_2r",
        "--certify",
        "--criterion",
        "components",
        "--R",
        "0.1",
        "--probability",
        "gaussian",
        "--json",
    )
    assert rc == 0 and out["certified"] is True
    m = tolsynth.load_model("planar_2r")
    sig = sigma_max(m, np.array(out["q"]), np.array(list(out["tolerances"].values())))[0]
    p_there = math.erf(0.1 / (math.sqrt(2.0) * sig))
    assert out["probability_lower_bound"] <= p_there == pytest.approx(out["value"], rel=1e-9)
    assert out["probability_lower_bound"] == pytest.approx(
        math.erf(0.1 / (math.sqrt(2.0) * out["upper_bound"])), abs=1e-14
    )


@pytest.mark.parametrize(
    "argv, says",
    [
        (["worst-pose", "--model", "planar_2r", "--certify", "--criterion", "probability", "--R", "0.1"], "components"),
        (["solve", "--model", "planar_2r", "--R", "0.1", "--p", "0.99", "--certify"], "--everywhere"),
        (["solve", "--model", "planar_2r", "--R", "0.1", "--p", "0.99", "--max-rounds", "3"], "--everywhere"),
        (
            [
                "solve",
                "--model",
                "planar_2r",
                "--R",
                "0.1",
                "--p",
                "0.99",
                "--everywhere",
                "--certify",
                "--criterion",
                "sphere",
            ],
            "components",
        ),
        (["worst-pose", "--model", "planar_2r", "--certify-time-limit", "3"], "--certify"),
        (["worst-pose", "--model", "planar_2r", "--certify", "--certify-time-limit", "0"], "seconds > 0"),
        (["worst-pose", "--model", "planar_2r", "--workers", "2"], "--certify"),
        (["worst-pose", "--model", "planar_2r", "--certify", "--workers", "0"], "integer >= 1"),
        (["solve", "--model", "planar_2r", "--R", "0.1", "--p", "0.99", "--everywhere", "--workers", "2"], "--certify"),
        (["solve", "--model", "planar_2r", "--R", "0.1", "--p", "0.99", "--workers", "2"], "--everywhere"),
        ([*SOLVE_2R, "--everywhere", "--margin", "3e-3"], "--certify"),
        ([*SOLVE_2R, "--everywhere", "--certify", "--margin", "1"], "from 0 to 0.5"),
        ([*SOLVE_2R, "--everywhere", "--through-sigma"], "--certify --through-sigma"),
        ([*SOLVE_2R, "--probability", "gaussian", "--everywhere", "--certify", "--through-sigma"], "exact reading"),
    ],
    ids=[
        "sphere-probability",
        "certify-alone",
        "max-rounds-alone",
        "sphere-everywhere",
        "time-alone",
        "time-zero",
        "workers-alone",
        "workers-zero",
        "workers-without-certify",
        "workers-without-everywhere",
        "margin-without-certify",
        "margin-too-large",
        "through-sigma-without-certify",
        "through-sigma-gaussian",
    ],
)
def test_certify_usage_errors_exit_2_naming_the_choice(argv, says, capsys):
    # in this process (the command's own entry point; a child process per case took 2 s each, and
    # tests/test_cli_exits.py runs the real command line's exits)
    from tolsynth.cli import main

    try:
        rc = main(list(argv))
    except SystemExit as exc:  # argparse's own usage errors end the command this way
        rc = exc.code
    err = capsys.readouterr().err
    assert rc == 2 and says in err and "Traceback" not in err


@pytest.mark.slow  # 4-12 s: a child process, 1.5 s of search, 2000 poses
def test_time_limit_is_not_proven_with_the_bound_so_far():
    """The Puma 560 is not certified in 1.5 s: exit status 1, the reason, and a bound that holds
    (above sigma_1 at the reported pose, evaluated here, and at 2000 random poses)."""
    rc, out, err = _run("worst-pose", "--model", "puma560", "--certify", "--certify-time-limit", "1.5", "--json")
    assert rc == 1 and "not certified (time limit reached)" in err
    assert out["certified"] is False and out["certificate"]["reason"] == "time limit reached"
    m = tolsynth.load_model("puma560")
    eps = np.array(list(out["tolerances"].values()))
    assert m.distribution == "uniform"  # variance eps^2 / 3, as sigma_max takes it
    assert sigma_max(m, np.array(out["q"]), eps)[0] == pytest.approx(out["value"], rel=1e-9)
    lo, hi = _limits(m)
    Q = lo + (hi - lo) * np.random.default_rng(3).random((2000, len(lo)))
    assert sigma_max(m, Q, eps).max() <= out["upper_bound"] and out["value"] < out["upper_bound"]


@pytest.mark.slow
def test_round_limit_is_not_converged_with_the_bound_so_far():
    """Two rounds on the paper's robot cannot meet the specification: exit status 1, converged and
    certified false, the reason, and the bound so far above the worst value found (which is
    sigma z / R at the pose reported, checked here)."""
    rc, out, err = _run(
        "solve",
        "--model",
        "xu_zhang_1988",
        "--R",
        "0.5",
        "--p",
        "0.99",
        "--dist",
        "uniform",
        "--alpha",
        "0.7",
        "--probability",
        "gaussian",
        "--everywhere",
        "--certify",
        "--max-rounds",
        "2",
        "--json",
    )
    assert rc == 1 and "no convergence" in err
    assert out["converged"] is False and out["certified"] is False and "round limit (2)" in out["reason"]
    assert len(out["rounds"]) == 2 and out["rounds"][-1]["boxes"] > 0
    m = tolsynth.load_model("xu_zhang_1988")
    eps = np.array([out["tolerances"][n] for n in m.error_parameters])
    worst = sigma_max(m, np.array(out["rounds"][-1]["worst_q"]), eps)[0] * z_of_p(0.99) / 0.5
    assert worst == pytest.approx(out["worst_value"], rel=1e-9)
    assert out["worst_value"] <= out["upper_bound"] and out["upper_bound"] > 1.001


@pytest.mark.slow  # 3-15 s: five solves and a tenth of a second of certified search
def test_everywhere_certify_time_limit_is_not_converged():
    """A certified search stopped by --certify-time-limit: exit status 1, not converged, the reason,
    and a bound (possibly infinite, never below) above the worst value found, which is sigma z / R
    at the reported pose (checked here).  The limit is far below the proof's time (about a second,
    6 000 boxes, on two idle cores)."""
    argv = ["solve", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.99", "--dist", "uniform", "--alpha", "0.7"]
    rc, out, err = _run(
        *argv, "--probability", "gaussian", "--everywhere", "--certify", "--certify-time-limit", "0.1", "--json"
    )
    assert rc == 1 and "time limit reached" in err
    assert out["converged"] is False and out["certified"] is False and "time limit reached" in out["reason"]
    m = tolsynth.load_model("xu_zhang_1988")
    eps = np.array([out["tolerances"][n] for n in m.error_parameters])
    worst = sigma_max(m, np.array(out["rounds"][-1]["worst_q"]), eps)[0] * z_of_p(0.99) / 0.5
    assert worst == pytest.approx(out["worst_value"], rel=1e-9) and out["worst_value"] <= float(out["upper_bound"])
    rc, _, err = _run(*argv, "--everywhere", "--certify-time-limit", "1")
    assert rc == 2 and "--certify-time-limit" in err


@pytest.mark.slow
def test_everywhere_certified_on_the_paper_robot():
    """The certified exchange proves z sigma_1 / R <= 1 + tol over the continuous joint space; no
    random feasible pose (3000, NumPy eigenvalues) exceeds the bound."""
    rc, out, _ = _run(
        "solve",
        "--model",
        "xu_zhang_1988",
        "--R",
        "0.5",
        "--p",
        "0.99",
        "--dist",
        "uniform",
        "--alpha",
        "0.7",
        "--probability",
        "gaussian",
        "--everywhere",
        "--certify",
        "--json",
    )
    assert rc == 0
    assert out["converged"] is True and out["certified"] is True and out["reason"] == ""
    assert out["upper_bound"] <= 1.001 and out["rounds"][-1]["boxes"] > 0
    m = tolsynth.load_model("xu_zhang_1988")
    eps = np.array([out["tolerances"][n] for n in m.error_parameters])
    lo, hi = _limits(m)
    Q = lo + (hi - lo) * np.random.default_rng(15).random((20000, len(lo)))
    Q = Q[_feasible(m, Q.T)]
    A = np.stack([m.sensitivity(q, check_limits=False)[:3] for q in Q[:3000]])
    V = np.einsum("nij,j,nkj->nik", A, eps**2 / 3.0, A)
    ratio = np.sqrt(np.linalg.eigvalsh(V)[:, -1]) * z_of_p(0.99) / 0.5
    assert ratio.max() <= out["upper_bound"]


@pytest.mark.slow  # 5 s: a child process
def test_everywhere_certified_with_a_margin_reports_the_bound_at_R():
    """``--margin``: certified at R, the design's cost the optimum at R / (1 + margin) and the
    lower bound the optimum at R at the same poses, both by cvxpy + Clarabel."""
    pytest.importorskip("cvxpy")
    from convex_reference import clarabel
    from tolsynth.problem.specification import make_specification

    argv = ["solve", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.99", "--probability", "gaussian"]
    rc, out, _ = _run(*argv, "--everywhere", "--certify", "--margin", "3e-3", "--json")
    assert rc == 0 and out["certified"] is True and out["margin"] == 3e-3 and out["upper_bound"] <= 1.001
    m = tolsynth.load_model("xu_zhang_1988")
    poses = [np.array(q) for q in out["poses"]]
    at_R = clarabel(make_specification(m, 0.5, 0.99, "uniform", 0.7, poses=poses))
    at_Rd = clarabel(make_specification(m, 0.5 / 1.003, 0.99, "uniform", 0.7, poses=poses))
    assert out["lower_bound"] == pytest.approx(at_R, rel=1e-6)
    assert out["cost"] == pytest.approx(at_Rd, rel=1e-6)
    assert out["gap"] == pytest.approx(at_Rd - at_R, rel=1e-3)


@pytest.mark.slow  # 4-12 s: a child process, a certified exchange of the paper's robot
def test_everywhere_exact_reading_proven_through_sigma():
    """``--through-sigma``: the exact reading's design proven through sigma_1; the design is the
    Gaussian reading's optimum at z' = 3.0272 at its poses, the lower bound the exact reading's
    there; the first by cvxpy + Clarabel."""
    pytest.importorskip("cvxpy")
    from convex_reference import clarabel
    from tolsynth.problem.specification import make_specification

    argv = ["solve", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.99", "--everywhere", "--certify"]
    rc, out, _ = _run(*argv, "--through-sigma", "--json")
    assert rc == 0 and out["certified"] is True and out["probability_lower_bound"] >= 0.99 - 1e-6
    assert out["through"] == pytest.approx(3.0272, abs=1e-3) and out["upper_bound"] is None
    m = tolsynth.load_model("xu_zhang_1988")
    poses = [np.array(q) for q in out["poses"]]
    pg = math.erf(out["through"] / math.sqrt(2.0))
    assert out["cost"] == pytest.approx(clarabel(make_specification(m, 0.5, pg, "uniform", 0.7, poses=poses)), rel=1e-6)
    assert out["lower_bound"] < out["cost"] and out["gap"] == pytest.approx(out["cost"] - out["lower_bound"], rel=1e-9)


@pytest.mark.slow  # 4 s
def test_everywhere_with_a_margin_says_which_radius_a_value_is_relative_to(capsys):
    """In text: the rounds and the value found afterwards are relative to R' = R / (1 + margin) (the
    round's printed value is sigma z / R' at its hand position, checked with NumPy eigenvalues), and
    a value past R' is called a violation of R', not of the specification, which is proven at R."""
    from independent import sigma_max
    from tolsynth.cli import main
    from tolsynth.probability.stats import z_of_p

    argv = ["solve", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.99", "--probability", "gaussian"]
    assert main([*argv, "--everywhere", "--certify", "--margin", "3e-3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert main([*argv, "--everywhere", "--certify", "--margin", "3e-3"]) == 0
    text = capsys.readouterr().out
    assert "of R', the radius designed for; the proof below is at R)" in text
    m = tolsynth.load_model("xu_zhang_1988")
    eps = np.array(list(out["tolerances"].values()))
    last = out["rounds"][-1]  # the final design's round, whose worst pose the proof found
    value = sigma_max(m, np.array([last["worst_q"]]), eps)[0] * z_of_p(0.99) * 1.003 / 0.5
    k = len(out["rounds"]) - 1
    assert f"round {k}: {last['n_poses']} pose(s), cost {last['cost']:.6g}, worst sigma z/R at R' = R/(1+0.003)" in text
    assert f"workspace {value:.5f} at hand" in text


def test_sampled_exchange_round_limit_says_why_with_progress():
    """Without certify too: a round limit reached is not converged, the reason says so and by how
    much the last design misses (its worst value, sigma z / R at the reported pose, checked), exit
    status 1 naming the reason; a progress callable hears of every round."""
    m = tolsynth.load_model("xu_zhang_1988")
    calls = []
    w = tolsynth.synthesize_workspace(
        m,
        0.5,
        0.99,
        "uniform",
        0.7,
        probability="gaussian",
        max_rounds=2,
        progress=lambda done, total: calls.append((done, total)),
    )
    assert not w.converged and w.certified is None and calls == [(1, 2), (2, 2)]
    worst = sigma_max(m, w.rounds[-1]["worst_q"], w.result.x)[0] * z_of_p(0.99) / 0.5
    assert worst == pytest.approx(w.worst_value, rel=1e-9)
    assert (
        w.reason
        == f"round limit (2) reached; the last design misses the specification by {worst - 1:.3g} at a pose found"
    )
    rc, out, err = _run(
        "solve",
        "--model",
        "xu_zhang_1988",
        "--R",
        "0.5",
        "--p",
        "0.99",
        "--dist",
        "uniform",
        "--alpha",
        "0.7",
        "--probability",
        "gaussian",
        "--everywhere",
        "--max-rounds",
        "2",
        "--json",
    )
    assert rc == 1 and "round limit (2) reached" in err
    assert out["converged"] is False and out["reason"] == w.reason


def test_cli_errors_and_reasons_name_the_flags_not_certify_options(capsys):
    from tolsynth.cli import main

    base = ["solve", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--everywhere", "--probability", "gaussian"]
    assert main([*base, "--certify", "--through-sigma"]) == 2
    err = capsys.readouterr().err
    assert "error: --through-sigma: given with the gaussian reading" in err and "certify_options" not in err
    # a certified search stopped at once: the reason suggests the design margin by its flag
    assert main([*base, "--certify", "--certify-time-limit", "0.001"]) == 1
    captured = capsys.readouterr()
    assert "a design margin (--margin, e.g. 3 tol) gives the proof room" in captured.err
    assert "certify_options" not in captured.out + captured.err
