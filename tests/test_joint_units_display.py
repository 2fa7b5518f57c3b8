"""Pose values in the Monte Carlo and validation reports of a parallel robot: each strut (a
prismatic actuator) in mm as the model file writes it, never read as an angle in degrees; checked
against the numbers of the TOML file itself (tomllib), not against the package's formatter."""

from __future__ import annotations

import re
from pathlib import Path

import tomllib

import tolsynth

MODELS = Path(tolsynth.__file__).resolve().parent.parent / "models"


def _struts(config: str) -> list[float]:
    doc = tomllib.loads((MODELS / "stewart_gough.toml").read_text(encoding="utf-8"))
    return [float(doc["configurations"][config][f"q{i}"]) for i in range(1, 7)]


def _numbers(text: str) -> list[float]:
    return [float(x) for x in re.findall(r"[-+]?\d+\.\d+", text)]


def test_montecarlo_and_validation_reports_show_struts_in_mm():
    mech = tolsynth.load_model("stewart_gough")
    q = _struts("tilted")
    mc = tolsynth.monte_carlo(mech, q, "coarse", R=0.5, n=2000, seed=1)
    line = next(ln for ln in mc.report().splitlines() if ln.startswith("pose"))
    shown = _numbers(line.split("hand")[0])
    assert "mm" in line.split("hand")[0] and "deg" not in line
    assert len(shown) == 6 and all(abs(a - b) <= 1e-3 for a, b in zip(shown, q)), line
    # a validation over two poses names both, struts in mm
    res = tolsynth.synthesize(mech, R=0.5, p=0.9, poses=["home", "tilted"], probability="gaussian")
    val = tolsynth.validate(mech, res, R=0.5, p=0.9, pose=[_struts("home"), q], n=2000, seed=2)
    text = val.report()
    pose_lines = [ln for ln in text.splitlines() if ln.strip().startswith("pose (")]
    assert len(pose_lines) == 2 and "deg" not in text, text
    for ln, ref in zip(pose_lines, (_struts("home"), q)):
        shown = _numbers(ln.split(":")[0])
        assert len(shown) == 6 and all(abs(a - b) <= 1e-3 for a, b in zip(shown, ref)), ln


def test_tables_and_json_label_struts_in_mm(capsys):
    """Every leg of the model file is prismatic (read with tomllib), so every joint column of the
    tables and the JSON pose are lengths: labelled mm, holding the file's numbers."""
    doc = tomllib.loads((MODELS / "stewart_gough.toml").read_text(encoding="utf-8"))
    assert {leg["actuation"] for leg in doc["leg"]} == {"prismatic"}
    mech = tolsynth.load_model("stewart_gough")
    w = tolsynth.worst_pose(mech, "coarse")
    units = w.to_frame().attrs["units"]
    assert [units[f"q{j}"] for j in range(1, 7)] == ["mm"] * 6
    mc = tolsynth.monte_carlo(mech, _struts("tilted"), "coarse", R=0.5, n=500, seed=1)
    inputs = mc.to_frame().attrs["inputs"]
    assert "q_rad" not in inputs and inputs["q_mm"] == _struts("tilted")
    assert mc.units["q"] == "mm"
    res = tolsynth.synthesize(mech, R=0.5, p=0.9, pose="home", probability="gaussian")
    poses = res.to_frame().attrs["inputs"]
    assert "poses_rad" not in poses and poses["poses_mm"]["home"] == _struts("home")
    import json

    from tolsynth.cli import main

    assert (
        main(
            [
                "analyze",
                "--model",
                "stewart_gough",
                "--pose",
                "tilted",
                "--tolerances",
                "coarse",
                "--R",
                "0.5",
                "--json",
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert "q_rad" not in out and out["q_mm"] == _struts("tilted")


SLIDE = """<robot name="slide"><link name="base"/><link name="l1"/><link name="l2"/><link name="tip"/>
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
  <origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
<joint name="j2" type="prismatic"><parent link="l1"/><child link="l2"/>
  <origin xyz="0.4 0 0" rpy="0 0 0"/><axis xyz="1 0 0"/><limit lower="0" upper="0.2" effort="1" velocity="1"/></joint>
<joint name="f" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0 0 -0.05" rpy="0 0 0"/></joint>
</robot>"""


def test_a_urdf_slide_is_a_length_everywhere(tmp_path):
    """A prismatic URDF joint moves the hand by its value in mm along its axis (closed form:
    x = 400 + q2 at q1 = 0), and is shown, labelled and kept as a length, never as degrees."""
    import numpy as np

    from tolsynth.kinematics.joint_space import _wrap

    path = tmp_path / "slide.urdf"
    path.write_text(SLIDE)
    mech = tolsynth.load_urdf(path, "base", "tip")
    assert abs(mech.fk([0.0, 50.0])[0, 3] - 450.0) <= 1e-9
    assert mech.joint_units == ("deg", "mm") and mech.joint_value_units == ("rad", "mm")
    assert mech.format_joints([0.3, 50.0]) == "(17.189 deg, 50.000 mm)"
    w = tolsynth.worst_pose(mech, {n: 0.01 for n in mech.error_parameters})
    units = w.to_frame().attrs["units"]
    assert (units["q1"], units["q2"]) == ("rad", "mm")
    # bringing a revolute value into its limits moves it by 2 pi; a slide keeps its value
    Q = _wrap(mech, np.array([[4.0], [150.0]]))
    assert np.allclose(Q[:, 0], [4.0 - 2 * np.pi, 150.0])
