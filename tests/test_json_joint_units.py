"""Joint values in JSON carry their unit in their key (docs/units.md): the sampled workspace check's
pose and the poses recorded among a solve's inputs, checked against the kinds of joint the model
file itself declares (read by tomllib: a strut that slides is in mm, a joint that turns in rad)."""

import contextlib
import io
import json

import numpy as np
import pytest

from model_text import model_dict
from tolsynth.cli import main


def _unit(model: str) -> str:
    data = model_dict(model)
    if "leg" in data:  # a parallel robot: its actuators
        units = {"mm" if leg["actuation"] == "prismatic" else "rad" for leg in data["leg"]}
    else:
        units = {"mm" if j.get("type") == "prismatic" else "rad" for j in data["joints"]}
    assert len(units) == 1
    return units.pop()


@pytest.mark.parametrize("model, pose", [("stewart_gough", "home"), ("xu_zhang_1988", "worst")])
def test_solve_json_keys_name_the_joint_unit(model, pose):
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["solve", "--model", model, "--R", "0.5", "--p", "0.99", "--pose", pose, "--json"]) == 0
    out = json.loads(buf.getvalue())
    unit = _unit(model)
    check = out["workspace_check"]
    assert "q" not in check and "q" not in out["inputs"] and "poses" not in out["inputs"]
    q = np.array(check[f"q_{unit}"])
    data = model_dict(model)
    # inside the file's own limits: a stroke in mm, or joint limits typed in degrees
    limits = np.array(
        [leg["limits"] for leg in data["leg"]] if unit == "mm" else np.radians([j["limits"] for j in data["joints"]])
    )
    assert q.shape == (len(limits),) and np.all((limits[:, 0] - 1e-9 <= q) & (q <= limits[:, 1] + 1e-9))
    assert out["inputs"][f"poses_{unit}"] == [pose]
