"""The model's default design pose is one rule for every door: without a pose, ``tolsynth solve``,
:func:`tolsynth.synthesize`, :func:`tolsynth.sweep` and ``tolsynth sweep`` design at the same pose,
the one docs/model_format.md names: the model's ``worst`` configuration (read here from the model
file with tomllib), else the worst-pose search's pose (largest principal sigma at the geometric
middle of the tolerance bounds, found here by calling :func:`tolsynth.worst_pose` directly)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.10
    import tomli as tomllib

import tolsynth
from tolsynth.cli import main

SPEC = dict(R=0.5, p=0.99)


def _cli_solve(capsys, model: str) -> dict:
    rc = main(["solve", "--model", model, "--R", "0.5", "--p", "0.99", "--json"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err[-2000:]
    return json.loads(cap.out)


def _search_pose(m) -> np.ndarray:
    """The documented rule for a model without a ``worst`` configuration, computed here."""
    lo, hi = (np.asarray(b, dtype=float) for b in m.bounds)
    return np.asarray(tolsynth.worst_pose(m, np.sqrt(lo * hi), criterion="sigma", reference=None).q, dtype=float)


def _file_configurations(m) -> dict:
    with open(m.spec.path, "rb") as f:
        return tomllib.load(f).get("configurations", {})


@pytest.mark.parametrize("name", ["delta", "stewart_gough", "puma560"])
def test_cli_and_api_design_at_the_same_documented_pose(capsys, name):
    m = tolsynth.load_model(name)
    assert "worst" not in _file_configurations(m)
    q = _search_pose(m)
    out = _cli_solve(capsys, name)
    res = tolsynth.synthesize(m, **SPEC)
    assert out["cost"] == pytest.approx(res.cost, rel=1e-9)
    recorded = next(v for k, v in out["inputs"].items() if k.startswith("poses_"))  # the unit in the key
    np.testing.assert_allclose(recorded[0], q, atol=1e-12)
    np.testing.assert_allclose(list(res.spec.poses.values())[0], q, atol=1e-12)
    assert "worst-pose search" in out["default_pose"]
    # and the design is the one made at that pose when it is given explicitly
    assert tolsynth.synthesize(m, **SPEC, pose=q).cost == pytest.approx(res.cost, rel=1e-9)


def test_a_worst_configuration_is_the_design_pose_of_a_parallel_robot_too(capsys, tmp_path):
    """A parallel robot's ``home`` (the pose its maps compare with) does not displace its
    ``worst`` configuration as the design pose: the Delta's file with one added."""
    src = tolsynth.load_model("delta").spec.path
    text = open(src, encoding="utf-8").read()
    text += '\n[configurations.worst]\nnote = "a test pose"\ntheta1 = -2.5\ntheta2 = 0.5\ntheta3 = 31.0\n'
    path = tmp_path / "delta_worst.toml"
    path.write_text(text, encoding="utf-8")
    m = tolsynth.load_model(str(path))
    worst = _file_configurations(m)["worst"]
    q = np.radians([worst[j] for j in m.joint_names])  # the file's angles are deg
    out = _cli_solve(capsys, str(path))
    res = tolsynth.synthesize(m, **SPEC)
    assert out["inputs"]["poses_rad"] == ["worst"] and "default_pose" not in out
    np.testing.assert_allclose(res.spec.poses["worst"], q, atol=1e-12)
    assert out["cost"] == pytest.approx(res.cost, rel=1e-9)


@pytest.mark.parametrize("name", ["delta", "puma560"])
def test_sweep_without_a_pose_designs_at_the_default_pose(name):
    pytest.importorskip("pandas")
    m = tolsynth.load_model(name)
    q = _search_pose(m)
    df = tolsynth.sweep(m, R=[0.5], p=[0.99], client="serial", progress=False)
    assert list(df["status"]) == ["optimal"], df["error"].tolist()
    assert df["cost"][0] == pytest.approx(tolsynth.synthesize(m, **SPEC, pose=q).cost, rel=1e-9)
    assert "worst-pose search" in df.attrs["inputs"]["default_pose"]


def test_sweep_command_without_a_pose(capsys, tmp_path):
    pd = pytest.importorskip("pandas")
    out = tmp_path / "delta.csv"
    rc = main(["sweep", "--model", "delta", "--R", "0.5", "--p", "0.99", "--workers", "1", "--out", str(out)])
    cap = capsys.readouterr()
    assert rc == 0, cap.err[-2000:]
    cost = pd.read_csv(out)["cost"][0]
    m = tolsynth.load_model("delta")
    assert math.isclose(cost, tolsynth.synthesize(m, **SPEC, pose=_search_pose(m)).cost, rel_tol=1e-9)


def test_validate_plain_tolerances_checks_the_design_pose():
    """validate() of plain tolerances on a model without a 'worst' configuration runs at the design
    pose (the worst-pose search's, computed here) instead of failing on the missing name; its
    probabilities are monte_carlo's at that pose with the same seed."""
    m = tolsynth.load_model("delta")
    q = _search_pose(m)
    v = tolsynth.validate(m, "coarse", R=0.5, p=0.99, n=20_000, seed=1)
    assert np.allclose(v.montecarlo.q, q, rtol=0, atol=1e-12)
    mc = tolsynth.monte_carlo(m, q, "coarse", R=0.5, n=20_000, seed=1)
    assert np.array_equal(v.p_components, mc.p_components)


def _file_pose(m, name: str) -> np.ndarray:
    """A configuration's joint values read from the model file (degrees there), in rad."""
    cfg = _file_configurations(m)[name]
    return np.radians([float(cfg[j]) for j in m.joint_names])


def test_validate_of_a_result_checks_the_pose_it_was_designed_at():
    """A result designed at ``elbow90`` is validated at ``elbow90``, not at the model's ``worst``
    configuration: the Monte Carlo's joint values are the model file's, and its probabilities are
    monte_carlo's at that pose with the same seed; an explicit pose still wins."""
    m = tolsynth.load_model("planar_2r")
    q = _file_pose(m, "elbow90")
    assert not np.allclose(q, _file_pose(m, "worst"))
    res = tolsynth.synthesize(m, **SPEC, pose="elbow90")
    v = tolsynth.validate(m, res, n=20_000, seed=1)
    assert v.to_dict()["pose"] == "elbow90"
    np.testing.assert_allclose(v.montecarlo.q, q, rtol=0, atol=1e-12)
    mc = tolsynth.monte_carlo(m, q, res.tolerances, "uniform", R=0.5, n=20_000, seed=1)
    assert np.array_equal(v.p_components, mc.p_components)
    explicit = tolsynth.validate(m, res, n=20_000, seed=1, pose="stretched")
    np.testing.assert_allclose(explicit.montecarlo.q, _file_pose(m, "stretched"), rtol=0, atol=1e-12)


def test_validate_of_a_several_pose_result_checks_each_pose():
    """A result designed at two poses is validated at both (seeds seed, seed + 1), in the model
    file's joint values; plain tolerances are checked at the model's ``worst`` configuration."""
    m = tolsynth.load_model("planar_2r")
    res = tolsynth.synthesize(m, **SPEC, poses=["elbow90", [0.2, 1.0]])
    v = tolsynth.validate(m, res, n=5_000, seed=4)
    assert len(v.per_pose) == 2
    np.testing.assert_allclose(v.per_pose[0].montecarlo.q, _file_pose(m, "elbow90"), rtol=0, atol=1e-12)
    np.testing.assert_allclose(v.per_pose[1].montecarlo.q, [0.2, 1.0], rtol=0, atol=1e-12)
    assert v.per_pose[1].seed == 5
    plain = tolsynth.validate(m, res.tolerances, R=0.5, p=0.99, n=5_000, seed=4)
    np.testing.assert_allclose(plain.montecarlo.q, _file_pose(m, "worst"), rtol=0, atol=1e-12)
