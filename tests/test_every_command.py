"""Every bundled model runs every command of the CLI.

A model without a reference pose (``puma560``) is given its first named configuration with
``--pose``; the others run on their defaults.  The numbers of each command are checked elsewhere;
here: exit status 0 and an answer about the model that was asked for (JSON output).  ``map`` on the
6- and 7-joint arms takes 20-40 s each (the reachable box), so it is a slow test.
"""

from __future__ import annotations

import contextlib
import io
import json

import pytest

import tolsynth
from tolsynth.cli import main
from tolsynth.kinematics.joint_space import model_reference

MODELS = tolsynth.bundled_models()


def _run(argv):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(argv + ["--json"])
    assert rc == 0, (argv, rc, err.getvalue())
    return json.loads(out.getvalue())


def _args(name):
    m = tolsynth.load_model(name)
    pose = [] if model_reference(m) else ["--pose", next(iter(m.configurations))]
    return m, next(iter(m.tolerance_sets)), pose


@pytest.mark.parametrize("name", MODELS)
def test_every_command_runs(name):
    m, tol, pose = _args(name)
    for argv in (
        ["analyze", "--model", name, "--tolerances", tol, "--R", "0.5", *pose],
        ["solve", "--model", name, "--R", "0.5", "--p", "0.99", *pose],
        ["montecarlo", "--model", name, "--tolerances", tol, "--R", "0.5", "--n", "2000", *pose],
        ["worst-pose", "--model", name, "--tolerances", tol, "--grid", "3"],
    ):
        out = _run(argv)
        assert out["inputs"]["model"]["name"] == name, argv


@pytest.mark.slow
@pytest.mark.parametrize("name", MODELS)
def test_map_runs(name):
    m, tol, _ = _args(name)
    # the 3-RRR moves in the xy plane, away from the default xz plane's y = 0
    plane = ["--plane", "xy"] if name == "planar_3rrr" else []
    out = _run(["map", "--model", name, "--tolerances", tol, "--R", "0.5", "--n", "6", *plane])
    assert out["inputs"]["model"]["name"] == name
