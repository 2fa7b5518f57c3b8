"""The bundled parallel robots against the sources their files cite.

The sources' numbers are typed in here with the citation next to them; nothing is read back from
a model file to build a reference.  Where a source prints a computed value (a pose from actuator
values, actuator values of a pose, strut lengths at home), the package's kinematics must give it
to the digits printed.  Also here: the certified interval search refuses a parallel robot with a
typed error naming why (its sensitivities come from Newton's method, which intervals cannot bound).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import tolsynth
from tolsynth.errors import InputError

INCH = 25.4  # mm

# ---------------------------------------------------------------------------------------------
# R. L. Williams II, "The Delta Parallel Robot: Kinematics Solutions", Internet Publication, Ohio
# University, 2016 (header "October 2016"; www.ohio.edu/people/williar4/html/pdf/DeltaKin.pdf).
# p. 6, table "for a specific commercial delta robot, the ABB FlexPicker IRB 360-1/1600" (mm):
#   sB = 567, sP = 76, L = 524, l = 1244, h = 131, wB = 164, uB = 327, wP = 22, uP = 44,
# with wB = sqrt(3)/6 sB, uB = sqrt(3)/3 sB, wP = sqrt(3)/6 sP, uP = sqrt(3)/3 sP, and the points
#   B1 = (0, -wB, 0), B2 = (sqrt(3)/2 wB, wB/2, 0), B3 = (-sqrt(3)/2 wB, wB/2, 0)  (base frame),
#   P1 = (0, -uP, 0), P2 = (sP/2, wP, 0), P3 = (-sP/2, wP, 0)                     (platform frame).
# p. 3: theta_i is zero with the upper leg horizontal.  Worked examples (m, deg):
#   p. 16, inverse: P = (0, 0, -0.9) -> theta = (-20.5, -20.5, -20.5);
#                   P = (0.3, 0.5, -1.1) -> theta = (47.5, -11.6, 21.4);
#   p. 19, forward: theta = (0, 0, 0) -> P = (0, 0, -1.065);
#                   theta = (10, 20, 30) -> P = (0.108, -0.180, -1.244).
WILLIAMS = {
    "sB": 567.0,
    "sP": 76.0,
    "L": 524.0,
    "l": 1244.0,
    "table_rounded": {"wB": 164.0, "uB": 327.0, "wP": 22.0, "uP": 44.0},
}
WILLIAMS_IPK = [((0.0, 0.0, -900.0), (-20.5, -20.5, -20.5)), ((300.0, 500.0, -1100.0), (47.5, -11.6, 21.4))]
WILLIAMS_FPK = [((0.0, 0.0, 0.0), (0.0, 0.0, -1065.0)), ((10.0, 20.0, 30.0), (108.0, -180.0, -1244.0))]

# ---------------------------------------------------------------------------------------------
# LinuxCNC, src/emc/kinematics/genhexkins.h (generalised hexapod, derived from R. Brian Register's
# work; the "mini tetra" configuration of EMC2's genhexkins.h), DEFAULT_BASE_i_{X,Y,Z} and
# DEFAULT_PLATFORM_i_{X,Y,Z}, struts 0..5 (inch); and
# configs/sim/axis/vismach/hexapod-sim/hexapod.ini: HOME = 0 0 20 0 0 0 (inch, deg), strut
# lengths there 29.7466 in (rounded).
LINUXCNC_BASE = [
    (-22.950, 13.250, 0.0),
    (22.950, 13.250, 0.0),
    (22.950, 13.250, 0.0),
    (0.000, -26.500, 0.0),
    (0.000, -26.500, 0.0),
    (-22.950, 13.250, 0.0),
]
LINUXCNC_PLATFORM = [
    (-1.000, 11.500, 0.0),
    (1.000, 11.500, 0.0),
    (10.459, -4.884, 0.0),
    (9.459, -6.616, 0.0),
    (-9.459, -6.616, 0.0),
    (-10.459, -4.884, 0.0),
]
LINUXCNC_HOME_Z, LINUXCNC_HOME_STRUT = 20.0, 29.7466  # inch


def _leg_points(m):
    """Base and platform anchors (mm) of each leg, from the model's nominal dimensions."""
    s = m.spec.symbols
    B = np.array([[s[leg.symbol(f)] for f in ("bx", "by", "bz")] for leg in m.spec.legs])
    C = np.array([[s[leg.symbol(f)] for f in ("px", "py", "pz")] for leg in m.spec.legs])
    return B, C


@pytest.fixture(scope="module")
def delta():
    return tolsynth.load_model("delta")


def test_delta_numbers_are_williams_table(delta):
    """Anchors by the source's formulas from sB and sP (to 1e-9 mm), arms L and links l; the table's
    rounded wB, uB, wP, uP are those formulas to the millimetre; the arms turn about the base
    triangle's sides and point radially outward at theta = 0."""
    w = WILLIAMS
    s3 = math.sqrt(3.0)
    wB, uB, wP, uP = s3 / 6 * w["sB"], s3 / 3 * w["sB"], s3 / 6 * w["sP"], s3 / 3 * w["sP"]
    for name, value in {"wB": wB, "uB": uB, "wP": wP, "uP": uP}.items():
        assert abs(value - w["table_rounded"][name]) <= 0.5, name
    base = np.array([[0, -wB, 0], [s3 / 2 * wB, wB / 2, 0], [-s3 / 2 * wB, wB / 2, 0]])
    plat = np.array([[0, -uP, 0], [w["sP"] / 2, wP, 0], [-w["sP"] / 2, wP, 0]])
    B, C = _leg_points(delta)
    assert np.abs(B - base).max() <= 1e-9 and np.abs(C - plat).max() <= 1e-9
    s = delta.spec.symbols
    for leg, b in zip(delta.spec.legs, base):
        assert s[leg.symbol("arm")] == w["L"] and s[leg.symbol("link")] == w["l"]
        radial = b / np.linalg.norm(b)
        assert np.allclose(leg.zero, radial, atol=1e-12)
        assert abs(np.dot(leg.axis, radial)) <= 1e-12 and abs(leg.axis[2]) <= 1e-12


def test_delta_inverse_kinematics_reproduces_williams_examples(delta):
    """The closed-form inverse kinematics gives the source's angles to the 0.1 deg it prints."""
    zero = np.zeros(delta.n)
    for pose, printed in WILLIAMS_IPK:
        q, c = delta.graphs.ik(np.array(pose), zero)
        assert np.all(np.abs(np.asarray(c, dtype=float)) <= 1.0)
        assert np.abs(np.degrees(np.asarray(q, dtype=float).ravel()) - printed).max() <= 0.05, (pose, q)


def test_delta_forward_kinematics_reproduces_williams_examples(delta):
    """Newton's forward kinematics gives the source's platform positions.  The source prints metres
    to 3 decimals, rounded from MATLAB's 4-decimal display (its -1.065 m for the exact
    -1.064452 m is -1.0645 rounded again), so a printed value is within 0.5 + 0.05 mm."""
    for theta, printed in WILLIAMS_FPK:
        p = delta.fk(np.radians(theta))[:3, 3]
        assert np.abs(p - printed).max() <= 0.55, (theta, p)
    # and the home configuration is the source's inverse example pose, to the file's 1e-10 deg
    assert np.abs(delta.fk("home")[:3, 3] - [0.0, 0.0, -900.0]).max() <= 1e-6


def test_hexapod_numbers_are_linuxcnc_defaults():
    """Leg i of the model is the source's strut i - 1, every coordinate times 25.4 (to 1e-9 mm);
    the home pose is the ini's HOME and its strut lengths round to the ini's 29.7466 in."""
    m = tolsynth.load_model("stewart_gough")
    B, C = _leg_points(m)
    assert np.abs(B - np.array(LINUXCNC_BASE) * INCH).max() <= 1e-9
    assert np.abs(C - np.array(LINUXCNC_PLATFORM) * INCH).max() <= 1e-9
    T = m.fk("home")
    assert np.abs(T[:3, 3] - [0.0, 0.0, LINUXCNC_HOME_Z * INCH]).max() <= 1e-8
    lengths = np.linalg.norm(T[:3, 3] + C @ T[:3, :3].T - B, axis=1) / INCH
    assert np.abs(lengths - LINUXCNC_HOME_STRUT).max() <= 5e-4
    assert np.abs(m.joints("home") / INCH - LINUXCNC_HOME_STRUT).max() <= 5e-4


def test_planar_3rrr_is_the_files_own_definition():
    """The 3-RRR cites no published geometry: its file defines it (base joints on a 300 mm circle,
    platform joints on a 60 mm one, at 90, 210 and 330 deg; arms and links 200 mm); the model
    holds exactly that."""
    m = tolsynth.load_model("planar_3rrr")
    assert "not that paper's" in m.spec.source
    ang = np.radians([90.0, 210.0, 330.0])
    B, C = _leg_points(m)
    assert np.abs(B - np.c_[300 * np.cos(ang), 300 * np.sin(ang), np.zeros(3)]).max() <= 1e-9
    assert np.abs(C - np.c_[60 * np.cos(ang), 60 * np.sin(ang), np.zeros(3)]).max() <= 1e-9
    s = m.spec.symbols
    assert all(s[leg.symbol("arm")] == 200.0 and s[leg.symbol("link")] == 200.0 for leg in m.spec.legs)


# ---------------------------------------------------------------------------------------------
# the certified search on a parallel robot: a typed refusal, not a search that never closes
# ---------------------------------------------------------------------------------------------
def test_certified_search_refuses_a_parallel_robot_with_the_reason(delta):
    from tolsynth.analysis.certify import certify_worst_pose

    with pytest.raises(InputError, match="Newton's method") as info:
        certify_worst_pose(delta, "coarse", progress=False)
    assert info.value.field == "certify" and "certify=False" in str(info.value)
    with pytest.raises(InputError, match="parallel robot"):
        tolsynth.worst_pose(delta, "coarse", certify=True, grid=3, starts=1, progress=False)
    with pytest.raises(InputError, match="parallel robot"):
        tolsynth.synthesize_workspace(delta, R=0.3, p=0.99, pose="home", certify=True, max_rounds=2)


def test_worst_pose_reports_strut_limits_in_mm():
    """A hexapod's active strut limits are lengths: shown in mm, not as angles."""
    m = tolsynth.load_model("stewart_gough")
    w = tolsynth.worst_pose(m, "coarse", grid=2, starts=1)
    assert w.active and all(a.endswith(" mm)") for a in w.active), w.active


def test_cli_certify_on_a_parallel_robot_exits_2_with_the_reason(capsys):
    """worst-pose --certify: bad input (exit 2) and a one-line reason, not a search without end."""
    from tolsynth.cli import main

    assert main(["worst-pose", "--model", "planar_3rrr", "--tolerances", "coarse", "--certify"]) == 2
    err = capsys.readouterr().err
    assert "certify" in err and "parallel robot" in err and "Traceback" not in err


# ---------------------------------------------------------------------------------------------
# P. Dietmaier, "The Stewart-Gough platform of general geometry can have 40 real postures", in
# Advances in Robot Kinematics: Analysis and Control, Springer 1998 (doi 10.1007/978-94-015-9064-8_1):
# a general 6-6 platform (base points X_i, platform points x_i, leg lengths L_i; no units), as typed
# in E. Martyushev's fkSGP (genSGP, sgpType 100) with one of its real postures (R, t).  Read as metres.
DIETMAIER_X = [
    (0, 0, 0),
    (1.107915, 0, 0),
    (0.549094, 0.756063, 0),
    (0.735077, -0.223935, 0.525991),
    (0.514188, -0.526063, -0.368418),
    (0.590473, 0.094733, -0.205018),
]
DIETMAIER_x = [
    (0, 0, 0),
    (0.542805, 0, 0),
    (0.956919, -0.528915, 0),
    (0.665885, -0.353482, 1.402538),
    (0.478359, 1.158742, 0.107672),
    (-0.137087, -0.235121, 0.353913),
]
DIETMAIER_L = [1, 0.645275, 1.086284, 1.503439, 1.281933, 0.771071]
DIETMAIER_R = [
    [-0.040450357031281, -0.932229494397471, 0.359599691867884],
    [0.983337493748685, 0.026695523074364, 0.179818582009314],
    [-0.177231887661606, 0.360881585597300, 0.915616371179918],
]
DIETMAIER_t = [0.955868038233880, -0.046995628998516, -0.290013283037649]


def _dietmaier(tmp_path, start):
    """Dietmaier's platform as a model file (mm), the home configuration its leg lengths, Newton
    started from ``start`` (x, y, z mm; rx, ry, rz deg)."""
    from model_text import model_dict, toml_text

    d = model_dict("stewart_gough")
    for i, leg in enumerate(d["leg"]):
        leg["base"] = [1000.0 * v for v in DIETMAIER_X[i]]
        leg["platform"] = [1000.0 * v for v in DIETMAIER_x[i]]
        leg["limits"] = [1000.0 * DIETMAIER_L[i] - 100.0, 1000.0 * DIETMAIER_L[i] + 100.0]
    d["configurations"] = {"home": {f"q{i + 1}": 1000.0 * v for i, v in enumerate(DIETMAIER_L)}}
    del d["tolerance_sets"]
    d["platform"]["assembly"] = dict(zip(("x", "y", "z", "rx", "ry", "rz"), start))
    path = tmp_path / "dietmaier.toml"
    path.write_text(toml_text(d))
    return tolsynth.load_model(path)


def test_general_platform_reaches_dietmaiers_posture_and_another_from_elsewhere(tmp_path):
    """A general 6-6 platform with non-planar anchors: from a start 83 mm and up to 7.4 deg per angle away, Newton's
    forward kinematics lands on the source's posture (to 1e-8 mm and 1e-11 in R: the posture's 15
    printed digits close the legs to 4e-13 m, and df/dx has condition number 160 there); from a
    start farther away, on another of its 40 postures, whose legs still have the source's lengths."""
    R, t = np.array(DIETMAIER_R), 1000.0 * np.array(DIETMAIER_t)
    B, C = 1000.0 * np.array(DIETMAIER_X, float), 1000.0 * np.array(DIETMAIER_x, float)
    m = _dietmaier(tmp_path, (900.0, 0.0, -250.0, 15.0, 5.0, 85.0))
    T = m.fk("home")
    assert np.abs(T[:3, 3] - t).max() <= 1e-8 and np.abs(T[:3, :3] - R).max() <= 1e-11
    other = _dietmaier(tmp_path, (1000.0, 0.0, -200.0, 0.0, 0.0, 90.0)).fk("home")
    assert np.abs(other[:3, 3] - t).max() > 100.0  # a different assembly mode
    legs = np.linalg.norm(other[:3, 3] + C @ other[:3, :3].T - B, axis=1)
    assert np.abs(legs - 1000.0 * np.array(DIETMAIER_L)).max() <= 1e-9
