"""``tolsynth analyze``: the JSON report against an independent computation, and bad input.

Reference: the hand-written NumPy chain of ``test_kinematics.py`` (position), its central
differences (sensitivity), the covariance ``sum_i a_i a_i^T eps_i^2 / 3`` in NumPy with the
Figure 3 tolerances typed from the paper (docs/reconstruction.md), ``numpy.linalg.eigvalsh`` (principal std),
``scipy.stats.norm`` (components) and the SciPy double integral of ``test_stats.py`` (sphere).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from test_kinematics import XU_ORDER, fd_sensitivity, xu_fk
from test_stats import ball_probability_scipy
from tolsynth.cli import main

ARGS = [
    "analyze",
    "--model",
    "xu_zhang_1988",
    "--pose",
    "worst",
    "--tolerances",
    "figure3",
    "--dist",
    "uniform",
    "--R",
    "0.2",
    "--json",
]
KEYS = {"position", "sensitivity", "covariance", "principal_std", "p_components", "p_sphere"}

# Figure 3 (the paper's section 5, docs/reconstruction.md), in mm and rad, and the worst pose of the model file (deg)
FIGURE3 = {
    "h2": 0.06,
    "hp2": 0.028,
    "hp3": 0.06,
    "hp4": 0.028,
    "h3": 0.08,
    "h4": 0.01,
    "s1": 0.01,
    "a": 0.015,
    "alpha1": 0.0005,
    "alpha3": 0.0005,
    "alpha4": 0.0005,
}
WORST_DEG = [0.0, 157.6451903, 107.97116143, 22.3548097, 0.0]


@pytest.fixture(scope="module")
def reference():
    """Everything the report should contain, computed without the package."""
    q = np.radians(WORST_DEG)
    T = xu_fk(q)
    # sensitivity per tolerance unit (mm; 1e-2 rad), by central differences of the NumPy chain
    steps = [1e-3] * len(XU_ORDER)  # 1e-3 mm, and 1e-3 x 1e-2 rad
    S = fd_sensitivity(xu_fk, q, XU_ORDER, steps)
    eps_unit = np.array([FIGURE3[n] / (0.01 if n.startswith("alpha") else 1.0) for n in XU_ORDER])
    cov = sum(np.outer(S[:3, i], S[:3, i]) * eps_unit[i] ** 2 / 3.0 for i in range(len(XU_ORDER)))
    lam = np.sort(np.linalg.eigvalsh(cov))[::-1]
    sig = np.sqrt(lam)
    R = 0.2
    return {
        "position": T[:3, 3],
        "sensitivity": S,
        "covariance": cov,
        "principal_std": sig,
        "p_components": 2 * stats.norm.cdf(R / sig) - 1,
        "p_sphere": ball_probability_scipy(lam, R),
    }


def _check_report(out, ref):
    assert KEYS <= set(out)
    assert np.allclose(out["position"], ref["position"], rtol=0, atol=1e-9)
    S = np.array(out["sensitivity"])
    assert S.shape == (6, 11)
    for rows, floor in ((slice(0, 3), 1e-9), (slice(3, 6), 1e-12)):
        err = np.linalg.norm(S[rows] - ref["sensitivity"][rows], axis=0)
        assert np.all(err <= 1e-6 * np.linalg.norm(ref["sensitivity"][rows], axis=0) + floor)
    cov = np.array(out["covariance"])
    assert np.allclose(cov, ref["covariance"], rtol=1e-6, atol=1e-9 * np.abs(ref["covariance"]).max())
    assert np.allclose(out["principal_std"], ref["principal_std"], rtol=1e-6, atol=0)
    assert np.allclose(out["p_components"], ref["p_components"], rtol=0, atol=1e-7)
    assert abs(out["p_sphere"] - ref["p_sphere"]) <= 1e-7


def test_analyze_json_in_process(capsys, reference):
    assert main(ARGS) == 0
    captured = capsys.readouterr()
    out = json.loads(captured.out)  # exactly one JSON object, nothing else on stdout
    assert isinstance(out, dict)
    _check_report(out, reference)
    assert out["R"] == 0.2 and out["distribution"] == "uniform"


def test_analyze_json_normal_is_a_third_of_uniform_variance(capsys, reference):
    """--dist normal: eps^2/9 instead of eps^2/3, so the covariance is exactly a third."""
    assert main(_with({"--dist": "normal"})) == 0
    out = json.loads(capsys.readouterr().out)
    assert np.allclose(
        out["covariance"], reference["covariance"] / 3.0, rtol=1e-6, atol=1e-9 * np.abs(reference["covariance"]).max()
    )
    sig = reference["principal_std"] / math.sqrt(3.0)
    assert abs(out["p_sphere"] - ball_probability_scipy(sig**2, 0.2)) <= 1e-7


def test_analyze_text_report(capsys, reference):
    assert main(ARGS[:-1]) == 0
    text = capsys.readouterr().out
    assert "925.0000" in text and "1225.0000" in text
    p_line = next(line for line in text.splitlines() if line.startswith("P(|dr|<=R)"))
    assert p_line.endswith("(sphere, Eq. 5, Gaussian)")
    assert abs(float(p_line.split()[1]) - reference["p_sphere"]) <= 1e-6


def test_analyze_tolerance_overrides(capsys, reference):
    """SET,name=value: one override by alias, the rest from the set (variance adds linearly)."""
    assert main(ARGS[:6] + ["figure3,x2=0.5"] + ARGS[7:]) == 0
    out = json.loads(capsys.readouterr().out)
    S = reference["sensitivity"]
    j = XU_ORDER.index("h3")
    extra = np.outer(S[:3, j], S[:3, j]) * (0.5**2 - 0.08**2) / 3.0
    assert np.allclose(out["covariance"], reference["covariance"] + extra, rtol=1e-6, atol=1e-12)


def test_analyze_installed_entry_point(tmp_path, reference):
    """The console script of the environment running the tests, from another directory."""
    exe = Path(sys.executable).parent / ("tolsynth.exe" if sys.platform == "win32" else "tolsynth")
    assert exe.exists(), f"no tolsynth entry point beside {sys.executable}"
    run = subprocess.run([str(exe), *ARGS], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    _check_report(json.loads(run.stdout), reference)
    bad = subprocess.run([str(exe), *_with({"--R": "0"})], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2
    assert "R" in bad.stderr and "> 0" in bad.stderr and bad.stdout == ""


BAD = [
    # (changed arguments, fragments of the message)
    ({"--model": "no_such_robot"}, ["model", "no_such_robot"]),
    ({"--R": "0"}, ["R", "> 0"]),
    ({"--R": "-0.5"}, ["R", "> 0"]),
    ({"--tolerances": "figure3,h2=-0.1"}, ["tolerances[h2]", ">= 0"]),
    ({"--tolerances": "figure3,h9=0.1"}, ["--tolerances", "unknown error parameter", "h9"]),
    ({"--tolerances": "figure3,h2=abc"}, ["--tolerances", "abc"]),
    ({"--tolerances": "figure7"}, ["tolerances", "figure7"]),
    ({"--pose": "banana"}, ["--pose", "banana"]),
    ({"--pose": "0,210,90,0,0"}, ["q[thetap2]", "140 to 200 deg"]),
    ({"--pose": "0,145,100,0,0"}, ["interference", "50 to 130 deg"]),
    ({"--pose": "0,170,90"}, ["q", "5"]),
]


def _with(changes):
    args = list(ARGS)
    for key, value in changes.items():
        args[args.index(key) + 1] = value
    return args


@pytest.mark.parametrize("changes, fragments", BAD, ids=[next(iter(b[0].values())) for b in BAD])
def test_bad_input_exits_2_naming_the_field(capsys, changes, fragments):
    assert main(_with(changes)) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith("tolsynth analyze: error:")
    for fragment in fragments:
        assert fragment in captured.err, (fragment, captured.err)


@pytest.mark.parametrize(
    "args, fragment",
    [
        (_with({"--dist": "lognormal"}), "--dist"),
        ([a for a in ARGS if a not in ("--R", "0.2")], "--R"),
        (_with({"--R": "small"}), "--R"),
    ],
)
def test_argparse_errors_exit_2(capsys, args, fragment):
    with pytest.raises(SystemExit) as info:
        main(args)
    assert info.value.code == 2
    assert fragment in capsys.readouterr().err


def test_pose_in_degrees_on_the_interference_limit(capsys):
    """A pose given in degrees exactly on the 50 deg interference limit is accepted (inclusive
    limits), and its hand point is that of those joints (nothing moved or clipped)."""
    assert main(_with({"--pose": "0,180,130,0,0"})) == 0
    out = json.loads(capsys.readouterr().out)
    assert np.allclose(out["position"], xu_fk(np.radians([0, 180, 130, 0, 0]))[:3, 3], atol=1e-9)
