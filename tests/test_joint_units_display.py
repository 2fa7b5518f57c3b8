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
