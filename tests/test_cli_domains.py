"""Values outside their domain refused, options that would be ignored refused, one-sample Monte
Carlo reported honestly, messages that name the option, its range and its unit, and table columns
that say their unit.  Each number checked here comes from a closed form or an independent
computation (a full turn is 2 pi rad, a cone's half-angle at most pi)."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import tolsynth
from model_text import edited, load_dict, set_at
from tolsynth.cli import main
from tolsynth.errors import ModelFileError, OutOfRangeError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _error(capsys, argv) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    return err


# ---------------------------------------------------------------------------------------------
# worst-pose --probability: only the per-component criterion reads it
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("criterion", [[], ["--criterion", "sigma"], ["--criterion", "probability", "--R", "0.2"]])
def test_worst_pose_refuses_probability_it_would_ignore(capsys, criterion):
    err = _error(capsys, ["worst-pose", "--model", "planar_2r", "--probability", "gaussian", *criterion])
    assert "--probability: only used with --criterion components" in err, err
    assert "--criterion components --probability gaussian" in err


def test_worst_pose_takes_probability_with_components(capsys):
    """With the per-component criterion the Gaussian reading is P(|u.dr| <= R) = erf(R / (sqrt 2 sigma_1))
    at the worst pose, sigma_1 being the largest principal sigma there (the sigma criterion's value)."""
    argv = ["worst-pose", "--model", "planar_2r", "--json", "--R", "0.5"]
    assert main(argv + ["--criterion", "components", "--probability", "gaussian"]) == 0
    import json

    comp = json.loads(capsys.readouterr().out)
    sigma1 = comp["principal_std"][0]
    assert comp["value"] == pytest.approx(math.erf(0.5 / (math.sqrt(2) * sigma1)), rel=1e-9)


# ---------------------------------------------------------------------------------------------
# montecarlo --n 1: the mean is the one sample's error; no interval, no spread
# ---------------------------------------------------------------------------------------------
def test_montecarlo_one_sample_has_a_mean_and_says_why_no_interval(capsys):
    argv = ["montecarlo", "--model", "xu_zhang_1988", "--tolerances", "figure3", "--R", "0.2", "--n", "1"]
    assert main(argv + ["--seed", "5"]) == 0
    out = capsys.readouterr().out
    line = next(row for row in out.splitlines() if row.startswith("mean error"))
    assert "nan" not in out.lower(), out
    assert "need n >= 2" in line, line


def test_montecarlo_one_sample_mean_is_the_sample_error():
    """One sample: the mean error is that sample's error, which lies within the first-order
    worst case sum_i |J_i| eps_i (J per tolerance unit) plus a small second-order margin; its
    interval and the covariance need two samples (NaN)."""
    m = tolsynth.load_model("xu_zhang_1988")
    r = tolsynth.monte_carlo(m, "worst", "figure3", R=0.2, n=1, seed=5)
    eps = m.tolerances("figure3")
    J = np.asarray(m.sensitivity("worst"))[:3]
    worst_case = np.abs(J) @ eps
    assert np.all(np.isfinite(r.mean)) and np.any(r.mean != 0)
    assert np.all(np.abs(r.mean) <= 1.01 * worst_case + 1e-9), (r.mean, worst_case)
    assert np.all(np.isnan(r.mean_ci)) and np.all(np.isnan(r.covariance))
    two = tolsynth.monte_carlo(m, "worst", "figure3", R=0.2, n=2, seed=5)
    assert np.all(np.isfinite(two.mean_ci))


# ---------------------------------------------------------------------------------------------
# domains: a cone half-angle is at most pi; model files in the wrong angle unit
# ---------------------------------------------------------------------------------------------
POSE_ARGS = ["--model", "xu_zhang_1988", "--tolerances", "figure3", "--R", "0.2"]


@pytest.mark.parametrize("phi", ["10", "1e8", "3.2", "181deg", "0", "-0.1"])
@pytest.mark.parametrize(
    "argv",
    [
        ["analyze", *POSE_ARGS],
        ["montecarlo", *POSE_ARGS, "--n", "100"],
        ["solve", "--model", "xu_zhang_1988", "--R", "0.2", "--p", "0.99"],
    ],
    ids=["analyze", "montecarlo", "solve"],
)
def test_phi_above_pi_is_refused(capsys, argv, phi):
    with pytest.raises(SystemExit) as info:
        main([*argv, f"--Phi={phi}"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "--Phi" in err and "<= pi rad (180 deg)" in err, err


def test_phi_up_to_pi_is_taken(capsys):
    """pi itself (180 deg) is a valid half-angle: every orientation component's probability is then
    P(|phi_j| <= pi), about 1 for milliradian errors."""
    assert main(["analyze", *POSE_ARGS, "--Phi", "180deg"]) == 0
    assert "Phi          3.14159 rad" in capsys.readouterr().out


def test_montecarlo_api_refuses_phi_above_pi():
    with pytest.raises(OutOfRangeError, match="Phi"):
        tolsynth.monte_carlo("xu_zhang_1988", "worst", "figure3", R=0.2, n=10, Phi=math.pi + 0.01)


def test_joint_limits_in_degrees_read_as_radians_fail_at_load(tmp_path):
    """planar_2r's limits [-170, 170] read as rad are 27 turns either way: the field and the range
    (4 turns = 8 pi rad = 25.1327 rad) are named."""
    with pytest.raises(ModelFileError) as info:
        load_dict(tmp_path, edited("planar_2r", set_at(["units", "angle"], "rad")))
    assert info.value.field == "joints[0].limits"
    text = str(info.value)
    assert str(tmp_path / "m.toml") in text
    assert f"{-8 * math.pi:g} to {8 * math.pi:g} rad" in text and "[-170, 170] rad" in text


def test_four_turns_of_joint_limits_still_load(tmp_path):
    """A wrist of +-720 deg (two turns each way) is a real robot's, and loads."""
    d = edited("planar_2r", set_at(["joints", 1, "limits"], [-720.0, 720.0]))
    assert load_dict(tmp_path, d).spec.joints[1].upper == pytest.approx(4 * math.pi)


def test_angle_tolerance_bounds_beyond_a_turn_fail_at_load(tmp_path):
    def big(d):
        d["error_parameters"][2].update(unit="rad", bounds=[0.001, 5000.0])

    with pytest.raises(ModelFileError) as info:
        load_dict(tmp_path, edited("planar_2r", big))
    assert info.value.field == "error_parameters[2].bounds"
    assert f"up to {2 * math.pi:g} rad" in str(info.value)


def test_angle_tolerance_set_beyond_a_turn_fails_at_load(tmp_path):
    def big(d):
        d["tolerance_sets"]["coarse"]["o1"] = {"value": 7.0, "unit": "rad"}

    with pytest.raises(ModelFileError) as info:
        load_dict(tmp_path, edited("planar_2r", big))
    assert info.value.field == "tolerance_sets.coarse.o1"
    assert f"up to {2000 * math.pi:g} mrad" in str(info.value)


def test_servo_error_beyond_a_turn_is_refused():
    puma = tolsynth.load_model("puma560")
    with pytest.raises(OutOfRangeError, match=r"joint_errors\[0\]\.bounds\.upper"):
        puma.with_joint_errors([tolsynth.JointError("q1", "servo", bounds=(0.001, 7.0), unit="rad")])


def test_cli_bounds_beyond_a_turn_are_refused(capsys):
    err = _error(capsys, ["solve", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--bounds", "o1=1:5000rad"])
    assert "--bounds[o1]" in err and f"up to {2000 * math.pi:g} mrad" in err, err


def test_every_bundled_model_still_loads():
    for name in tolsynth.bundled_models():
        tolsynth.load_model(name)


# ---------------------------------------------------------------------------------------------
# messages: the range with its unit, the option's own name, enough digits of p
# ---------------------------------------------------------------------------------------------
def test_pareto_range_message_names_the_range(capsys):
    err = _error(capsys, ["pareto", "--model", "planar_2r", "--R", "0.3,-1", "--p", "0.99", "--pose", "elbow90"])
    assert "--R: -1 in '0.3,-1'" in err and "radii > 0 (mm" in err, err


@pytest.mark.parametrize("value", ["nonsense", "serial", "processes"])
def test_sweep_scheduler_is_named_as_the_option(capsys, value):
    err = _error(capsys, ["sweep", "--model", "planar_2r", "--R", "0.5", "--p", "0.9", "--scheduler", value])
    assert "--scheduler:" in err and "client" not in err and "tcp://host:8786" in err, err


@pytest.mark.parametrize(
    "p, shown", [(0.99, "0.99"), (0.999999999999, "0.999999999999"), (0.9, "0.9"), (1 - 1e-9, "0.999999999")]
)
def test_probabilities_keep_their_shortfall(p, shown):
    from tolsynth.cli.args import fmt_p

    assert fmt_p(p) == shown
    assert 1 - float(fmt_p(p)) == pytest.approx(1 - p, rel=1e-6)


def test_sweep_table_shows_p_near_one(capsys):
    argv = ["sweep", "--model", "planar_2r", "--R", "0.5", "--p", "0.999999999999", "--pose", "elbow90"]
    main(argv + ["--workers", "1", "--quiet"])
    assert "0.999999999999" in capsys.readouterr().out


# ---------------------------------------------------------------------------------------------
# table columns say their unit
# ---------------------------------------------------------------------------------------------
def test_worst_pose_csv_names_the_joint_unit(tmp_path, capsys):
    pd = pytest.importorskip("pandas")
    path = tmp_path / "w.csv"
    assert main(["worst-pose", "--model", "xu_zhang_1988", "--out", str(path)]) == 0
    capsys.readouterr()
    df = pd.read_csv(path)
    cols = [c for c in df.columns if c.startswith("q")]
    assert cols == [f"q{j}_rad" for j in range(1, 6)]
    w = tolsynth.worst_pose("xu_zhang_1988", "figure3")
    # the row holds the API's joint values (rad): the same pose's hand position by forward kinematics
    q = df.loc[df["pose"] == "worst", cols].to_numpy()[0]
    np.testing.assert_allclose(q, w.q, atol=1e-9)
    m = tolsynth.load_model("xu_zhang_1988")
    np.testing.assert_allclose(np.asarray(m.fk(q))[:3, 3], df.loc[df["pose"] == "worst", ["x", "y", "z"]].to_numpy()[0])


def test_map_csv_names_the_joint_unit(tmp_path, capsys):
    pd = pytest.importorskip("pandas")
    path = tmp_path / "m.csv"
    assert main(["map", "--model", "planar_2r", "--n", "6", "--quiet", "--data", str(path)]) == 0
    capsys.readouterr()
    assert [c for c in pd.read_csv(path).columns if c.startswith("q_")] == ["q_q1_rad", "q_q2_rad"]


# ---------------------------------------------------------------------------------------------
# Ctrl-C on a sweep's worker processes: one line, from the parent
# ---------------------------------------------------------------------------------------------
def test_pool_workers_are_recognised():
    from tolsynth.interrupts import worker_of_a_pool

    forkserver = ["python", "-B", "-c", "from multiprocessing.forkserver import main; main(11, 12, ['__main__'])"]
    spawn = ["python", "-c", "from multiprocessing.spawn import spawn_main; spawn_main(tracker_fd=5, pipe_handle=7)"]
    assert worker_of_a_pool(forkserver) and worker_of_a_pool(spawn)
    assert not worker_of_a_pool(["python", "-m", "tolsynth", "sweep"]) and not worker_of_a_pool(["tolsynth"])
    assert not worker_of_a_pool(["python", "-c", "import tolsynth"])


def _command() -> list[str]:
    import shutil
    import sysconfig

    for folder in (sysconfig.get_path("scripts"), os.path.dirname(sys.executable)):
        found = shutil.which("tolsynth", path=folder)
        if found:  # the installed script: its workers copy its argv, as a user's do
            return [found]
    return [sys.executable, "-m", "tolsynth"]


SWEEP = [
    "sweep",
    "--model",
    "puma560",
    "--pose",
    "qn",
    "--R",
    "0.1,0.2,0.3,0.4,0.5,0.6,0.7,0.8",
    "--p",
    "0.9,0.99,0.999",
    "--alpha",
    "0.5,0.6,0.7",
    "--dist",
    "uniform,normal,triangular",
    "--workers",
    "2",
    "--quiet",
]


@pytest.mark.parametrize("after", [2.5, 5.0])
def test_ctrl_c_on_a_sweep_with_workers_is_one_line(after):
    """Ctrl-C at a terminal reaches the whole process group (the workers too): exit 130, one line."""
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.Popen(
        _command() + SWEEP,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env=env,
        start_new_session=True,  # its own process group, as a terminal's foreground job
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        time.sleep(after)
        assert proc.poll() is None, "the sweep finished before the signal; give it more rows"
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:  # pragma: no cover
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    lines = [line for line in err.splitlines() if line.strip()]
    assert proc.returncode == 130, err
    assert len(lines) == 1 and lines[0].startswith("tolsynth sweep: interrupted (Ctrl-C)"), err
    assert err == lines[0] + "\n", repr(err)  # not a terminal: no blank line before it


def test_joint_constraint_limits_beyond_the_joints_turns_fail_at_load(tmp_path):
    """The paper's interference limit theta'2 - theta2 sums two joints of at most 4 turns each, so
    its limits lie within +-2 * 4 * 360 = 2880 deg; 7000 deg is a unit mistake, named at load."""
    path = ["joint_constraints", 0, "limits"]
    with pytest.raises(ModelFileError) as info:
        load_dict(tmp_path, edited("xu_zhang_1988", set_at(path, [50.0, 7000.0])))
    assert info.value.field == "joint_constraints[0].limits"
    text = str(info.value)
    assert "from -2880 to 2880 deg" in text and "coefficients sum to 2" in text
    # the file is in degrees: no "degrees written with angle = 'deg'?" hint, no deg = deg echo
    assert "degrees written" not in text and "= [" not in text, text
    wide = load_dict(tmp_path, edited("xu_zhang_1988", set_at(path, [-2880.0, 2880.0])))
    assert wide.spec.joint_constraints[0].upper == pytest.approx(16 * math.pi)


def test_a_lock_outside_its_bounds_fails_at_load(tmp_path):
    """planar_2r's l1 takes tolerances of 0.001-5 mm (its bounds in the file): a lock of 7 mm is
    refused when the file is read, naming the file's field, not at the first solve; 5 mm loads."""
    with pytest.raises(ModelFileError) as info:
        load_dict(tmp_path, edited("planar_2r", set_at(["error_parameters", 0, "lock"], 7.0)))
    assert info.value.field == "error_parameters[0].lock"
    assert "7 mm" in str(info.value) and "0.001 to 5 mm" in str(info.value)
    ok = load_dict(tmp_path, edited("planar_2r", set_at(["error_parameters", 0, "lock"], 5.0)))
    assert ok.spec.error_parameters[0].lock == 5.0
