"""Every bundled model against the source its file cites.

The sources' numbers are typed in here, with the citation next to them; nothing is read back from
the model file to build the reference.  Where an independent library exists (the Robotics Toolbox
for Python, ``roboticstoolbox-python``, in the ``test`` extra) the forward kinematics are compared
with it at random joint vectors inside the limits; every robot is also compared with a plain-NumPy
D-H chain written here.  A test that finds no model file for a bundled name fails
(``test_every_bundled_model_has_a_source_test``), so a new model needs its source test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import tolsynth

DEG = math.pi / 180
INCH = 25.4  # mm

# ---------------------------------------------------------------------------------------------
# the sources, typed in
# ---------------------------------------------------------------------------------------------
# Universal Robots, "DH Parameters for calculations of kinematics and dynamics" (universal-robots.com
# support article), table UR5 (CB3; also the CB3 service manual's "UR5 serie 3"), in m and rad:
#   a = (0, -0.425, -0.39225, 0, 0, 0), d = (0.089159, 0, 0, 0.10915, 0.09465, 0.0823),
#   alpha = (pi/2, 0, 0, pi/2, -pi/2, 0); joint ranges +-360 deg (UR5 CB3 datasheet).
UR5 = {
    "a": [0.0, -0.425, -0.39225, 0.0, 0.0, 0.0],
    "d": [0.089159, 0.0, 0.0, 0.10915, 0.09465, 0.0823],
    "alpha": [math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0],
    "limits": [(-2 * math.pi, 2 * math.pi)] * 6,
}
# Franka Emika, Franka Control Interface documentation, "Robot and interface specifications"
# (frankaemika.github.io/docs/control_parameters.html): Denavit-Hartenberg parameters (Craig's
# convention, m and rad) and "Limits for Panda" (rad).
PANDA = {
    "a": [0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088],
    "d": [0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.0],
    "alpha": [0.0, -math.pi / 2, math.pi / 2, math.pi / 2, -math.pi / 2, math.pi / 2, math.pi / 2],
    "flange_d": 0.107,
    "q_min": [-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973],
    "q_max": [2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973],
}
# P. Corke, B. Armstrong-Helouvry, "A search for consensus among model parameters reported for the
# PUMA 560 robot", ICRA 1994, as in the Robotics Toolbox for Python, models/DH/Puma560.py (m, rad):
#   base = 26.45 * inch "from mounting surface to shoulder axis" (= d1), a2 = 0.4318, a3 = 0.0203,
#   d3 = 0.15005, d4 = 0.4318, alpha = (pi/2, 0, -pi/2, pi/2, -pi/2, 0); joint limits (deg) from
#   Wang & Chen, IEEE Trans. RA 7(4) 1991, as in Puma560.py.
PUMA = {
    "a": [0.0, 0.4318, 0.0203, 0.0, 0.0, 0.0],
    "d": [26.45 * 0.0254, 0.0, 0.15005, 0.4318, 0.0, 0.0],
    "alpha": [math.pi / 2, 0.0, -math.pi / 2, math.pi / 2, -math.pi / 2, 0.0],
    "limits_deg": [(-160, 160), (-45, 225), (-225, 45), (-110, 170), (-100, 100), (-266, 266)],
}
# Xu Weiliang, Zhang Qixian (1988), section 5 (restated in docs/reconstruction.md): nominal parameters
# (mm, rad) "h'1 = h'3 = h2 = 600, h'2 = h'4 = 280, h5 = 800, s5 = a = 150, s0 = 200, s'i = 0,
# alpha'i = 0, s1..s4 = 0, alpha1 = pi/2, alpha2 = alpha3 = 0, alpha4 = pi/2"; ranges (deg); the
# interference limit 50..130 deg; k = 1 (lengths, mm) and 1.5 (angles, 1e-2 rad).
XU_NOMINAL = {
    "hp1": 600.0,
    "hp3": 600.0,
    "h2": 600.0,
    "hp2": 280.0,
    "hp4": 280.0,
    "h3": 800.0,
    "a": 150.0,
    "s0": 200.0,
    "s1": 0.0,
    "s2": 0.0,
    "s3": 0.0,
    "s4": 0.0,
    "alpha1": 90 * DEG,
    "alpha2": 0.0,
    "alpha3": 0.0,
    "alpha4": 90 * DEG,
}
XU_RANGES = {
    "theta1": (-150, 150),
    "thetap2": (140, 200),
    "theta2": (50, 130),
    "theta4": (-110, 110),
    "theta5": (-185, 185),
}
# the paper's Tables 1-3, optimal half-tolerances x1..x11 (mm and 1e-2 rad), as printed.
XU_TABLES = {
    # (table, R, p, alpha, distribution): x1..x11
    ("Table 1", 1.0, 0.99, 0.7, "uniform"): [
        0.109,
        0.474,
        0.273,
        0.103,
        0.067,
        0.087,
        0.337,
        0.268,
        0.035,
        0.132,
        0.124,
    ],
    ("Table 1", 1.0, 0.99, 0.7, "normal"): [
        0.182,
        0.839,
        0.446,
        0.190,
        0.122,
        0.160,
        0.596,
        0.419,
        0.065,
        0.169,
        0.195,
    ],
    ("Table 1", 0.5, 0.99, 0.7, "uniform"): [
        0.057,
        0.125,
        0.133,
        0.052,
        0.033,
        0.044,
        0.174,
        0.178,
        0.017,
        0.067,
        0.055,
    ],
    ("Table 1", 0.5, 0.99, 0.7, "normal"): [
        0.081,
        0.392,
        0.240,
        0.095,
        0.065,
        0.088,
        0.326,
        0.282,
        0.028,
        0.097,
        0.109,
    ],
    ("Table 1", 0.1, 0.99, 0.7, "uniform"): [
        0.013,
        0.017,
        0.030,
        0.011,
        0.006,
        0.008,
        0.036,
        0.023,
        0.003,
        0.012,
        0.012,
    ],
    ("Table 1", 0.1, 0.99, 0.7, "normal"): [
        0.019,
        0.063,
        0.014,
        0.018,
        0.012,
        0.016,
        0.056,
        0.017,
        0.006,
        0.024,
        0.025,
    ],
    ("Table 2", 0.5, 0.90, 0.7, "uniform"): [
        0.0765,
        0.326,
        0.219,
        0.0827,
        0.0573,
        0.0774,
        0.296,
        0.245,
        0.0261,
        0.0976,
        0.122,
    ],
    ("Table 2", 0.5, 0.90, 0.7, "normal"): [
        0.154,
        0.638,
        0.357,
        0.132,
        0.0918,
        0.119,
        0.484,
        0.333,
        0.0440,
        0.190,
        0.152,
    ],
    ("Table 2", 0.5, 0.80, 0.7, "uniform"): [
        0.121,
        0.462,
        0.266,
        0.0944,
        0.0626,
        0.0856,
        0.325,
        0.253,
        0.0346,
        0.151,
        0.109,
    ],
    ("Table 2", 0.5, 0.80, 0.7, "normal"): [
        0.189,
        0.816,
        0.469,
        0.175,
        0.122,
        0.161,
        0.718,
        0.511,
        0.055,
        0.208,
        0.245,
    ],
    ("Table 2", 0.5, 0.70, 0.7, "uniform"): [
        0.135,
        0.579,
        0.373,
        0.143,
        0.085,
        0.113,
        0.438,
        0.304,
        0.044,
        0.143,
        0.113,
    ],
    ("Table 2", 0.5, 0.70, 0.7, "normal"): [
        0.230,
        1.072,
        0.585,
        0.218,
        0.141,
        0.195,
        0.714,
        0.585,
        0.078,
        0.307,
        0.226,
    ],
    ("Table 3", 0.5, 0.99, 1.0, "uniform"): [
        0.057,
        0.209,
        0.138,
        0.053,
        0.035,
        0.044,
        0.158,
        0.111,
        0.018,
        0.041,
        0.050,
    ],
    ("Table 3", 0.5, 0.99, 1.0, "normal"): [
        0.104,
        0.391,
        0.214,
        0.085,
        0.057,
        0.076,
        0.295,
        0.201,
        0.028,
        0.103,
        0.077,
    ],
    ("Table 3", 0.5, 0.99, 0.8, "uniform"): [
        0.059,
        0.216,
        0.130,
        0.050,
        0.034,
        0.043,
        0.172,
        0.116,
        0.016,
        0.057,
        0.057,
    ],
    ("Table 3", 0.5, 0.99, 0.8, "normal"): [
        0.090,
        0.443,
        0.194,
        0.090,
        0.062,
        0.083,
        0.330,
        0.247,
        0.031,
        0.083,
        0.081,
    ],
    ("Table 3", 0.5, 0.99, 0.6, "uniform"): [
        0.045,
        0.272,
        0.132,
        0.050,
        0.036,
        0.049,
        0.177,
        0.151,
        0.018,
        0.082,
        0.072,
    ],
    ("Table 3", 0.5, 0.99, 0.6, "normal"): [
        0.096,
        0.399,
        0.256,
        0.088,
        0.057,
        0.073,
        0.274,
        0.222,
        0.031,
        0.103,
        0.103,
    ],
}
# planar_2r cites itself (tolsynth example model): l1 = 500 mm, l2 = 300 mm.
PLANAR = {"l1": 500.0, "l2": 300.0}

# the parallel robots' sources are typed in and checked in test_parallel_sources.py
# kr6r900sixx: typed in and checked against its URDF chain in test_certify_kr6.py
SOURCE_TESTED = {
    "ur5",
    "panda",
    "puma560",
    "xu_zhang_1988",
    "planar_2r",
    "stewart_gough",
    "delta",
    "planar_3rrr",
    "kr6r900sixx",
}


def test_every_bundled_model_has_a_source_test():
    assert set(tolsynth.bundled_models()) == SOURCE_TESTED


# ---------------------------------------------------------------------------------------------
# independent plain-NumPy D-H chains (metres and radians, as the sources)
# ---------------------------------------------------------------------------------------------
def _rz(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def _rx(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[1.0, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]])


def _t(x=0.0, y=0.0, z=0.0):
    T = np.eye(4)
    T[:3, 3] = (x, y, z)
    return T


def standard_dh(q, a, d, alpha):
    """Standard D-H: Rz(theta) Tz(d) Tx(a) Rx(alpha) per link."""
    T = np.eye(4)
    for qi, ai, di, al in zip(q, a, d, alpha):
        T = T @ _rz(qi) @ _t(z=di) @ _t(x=ai) @ _rx(al)
    return T


def modified_dh(q, a, d, alpha, tool=np.eye(4)):
    """Craig's modified D-H: Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i) per link."""
    T = np.eye(4)
    for qi, ai, di, al in zip(q, a, d, alpha):
        T = T @ _rx(al) @ _t(x=ai) @ _rz(qi) @ _t(z=di)
    return T @ tool


def _in_mm(T):
    T = T.copy()
    T[:3, 3] *= 1000.0
    return T


def _random_q(lo, hi, n, seed):
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    return lo + (hi - lo) * rng.random((n, len(lo)))


def _assert_same_pose(T_pkg, T_ref, scale):
    """Position to 1e-9 relative to the arm's size, rotation to 1e-12."""
    assert np.max(np.abs(T_pkg[:3, 3] - T_ref[:3, 3])) <= 1e-9 * scale, (T_pkg[:3, 3], T_ref[:3, 3])
    assert np.max(np.abs(T_pkg[:3, :3] - T_ref[:3, :3])) <= 1e-12


def _limits(m):
    return [j.lower for j in m.spec.joints], [j.upper for j in m.spec.joints]


# ---------------------------------------------------------------------------------------------
# UR5
# ---------------------------------------------------------------------------------------------
def test_ur5_numbers_are_universal_robots_table():
    m = tolsynth.load_model("ur5")
    sym = m.spec.symbols
    for i in range(6):
        assert sym[f"a{i + 1}"] == pytest.approx(1000 * UR5["a"][i], abs=1e-12)
        assert sym[f"d{i + 1}"] == pytest.approx(1000 * UR5["d"][i], abs=1e-12)
        assert sym[f"alpha{i + 1}"] == pytest.approx(UR5["alpha"][i], abs=1e-15)
        assert sym[f"o{i + 1}"] == 0.0
        assert (m.spec.joints[i].lower, m.spec.joints[i].upper) == pytest.approx(UR5["limits"][i], abs=1e-15)
    assert m.spec.convention == "standard" and not m.spec.base and not m.spec.tool


def test_ur5_fk_against_numpy_chain():
    m = tolsynth.load_model("ur5")
    for q in _random_q(*_limits(m), 50, seed=1):
        _assert_same_pose(m.fk(q), _in_mm(standard_dh(q, UR5["a"], UR5["d"], UR5["alpha"])), 1000.0)
    # zero pose, by hand: x = a2 + a3, y = -(d4 + d6), z = d1 - d5 (mm)
    assert np.allclose(m.fk("qz")[:3, 3], [-425 - 392.25, -(109.15 + 82.3), 89.159 - 94.65], atol=1e-9)


# ---------------------------------------------------------------------------------------------
# Panda
# ---------------------------------------------------------------------------------------------
def test_panda_numbers_are_frankas_table():
    m = tolsynth.load_model("panda")
    sym = m.spec.symbols
    for i in range(7):
        # this package's modified link is Tx(h) Rx(alpha) Tz(s) Rz(theta): h = a_(i-1), s = d_i
        assert sym[f"h{i + 1}"] == pytest.approx(1000 * PANDA["a"][i], abs=1e-12)
        assert sym[f"s{i + 1}"] == pytest.approx(1000 * PANDA["d"][i], abs=1e-12)
        assert sym[f"alpha{i + 1}"] == pytest.approx(PANDA["alpha"][i], abs=1e-15)
        assert sym[f"o{i + 1}"] == 0.0
        assert m.spec.joints[i].lower == PANDA["q_min"][i] and m.spec.joints[i].upper == PANDA["q_max"][i]
    assert m.spec.convention == "modified"
    assert m.spec.tool == (("Tz", "flange"),) and sym["flange"] == pytest.approx(1000 * PANDA["flange_d"], abs=1e-12)


def test_panda_fk_against_numpy_chain():
    m = tolsynth.load_model("panda")
    flange = _t(z=PANDA["flange_d"])
    for q in _random_q(PANDA["q_min"], PANDA["q_max"], 50, seed=2):
        _assert_same_pose(m.fk(q), _in_mm(modified_dh(q, PANDA["a"], PANDA["d"], PANDA["alpha"], flange)), 1000.0)


# ---------------------------------------------------------------------------------------------
# Puma 560 (an earlier version of the file had d1 = 672.0, 0.17 mm off the source)
# ---------------------------------------------------------------------------------------------
def test_puma_numbers_are_the_toolbox_values():
    m = tolsynth.load_model("puma560")
    sym = m.spec.symbols
    for i in range(6):
        assert sym[f"a{i + 1}"] == pytest.approx(1000 * PUMA["a"][i], abs=1e-12)
        assert sym[f"d{i + 1}"] == pytest.approx(1000 * PUMA["d"][i], abs=1e-12), f"d{i + 1}"
        assert sym[f"alpha{i + 1}"] == pytest.approx(PUMA["alpha"][i], abs=1e-15)
        lo, hi = PUMA["limits_deg"][i]
        assert (m.spec.joints[i].lower, m.spec.joints[i].upper) == pytest.approx((lo * DEG, hi * DEG), abs=1e-15)
    assert sym["d1"] == pytest.approx(26.45 * INCH, abs=1e-12)  # 671.83 mm, not 672


def test_puma_fk_against_numpy_chain():
    m = tolsynth.load_model("puma560")
    lo, hi = np.array(PUMA["limits_deg"]).T * DEG
    for q in _random_q(lo, hi, 50, seed=3):
        _assert_same_pose(m.fk(q), _in_mm(standard_dh(q, PUMA["a"], PUMA["d"], PUMA["alpha"])), 1000.0)


# ---------------------------------------------------------------------------------------------
# the Robotics Toolbox for Python: an independent library (test extra)
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def rtb():
    return pytest.importorskip("roboticstoolbox")


def _rtb_compare(robot, m, seed, n=50):
    """FK of a toolbox robot (m) against the bundled model (mm) at random q inside the limits."""
    worst = 0.0
    for q in _random_q(*_limits(m), n, seed):
        T_ref = _in_mm(np.array(robot.fkine(q).A))
        T = m.fk(q)
        worst = max(worst, float(np.max(np.abs(T[:3, 3] - T_ref[:3, 3]))) / 1000.0)
        _assert_same_pose(T, T_ref, 1000.0)
    return worst


def test_puma_fk_against_robotics_toolbox(rtb):
    """The toolbox's own Puma560 model, unchanged (its base height 26.45 inch is d1 here)."""
    robot = rtb.models.DH.Puma560()
    assert robot.links[0].d == pytest.approx(26.45 * 0.0254, abs=1e-15)
    assert np.allclose(np.array(robot.base.A), np.eye(4)) and np.allclose(np.array(robot.tool.A), np.eye(4))
    _rtb_compare(robot, tolsynth.load_model("puma560"), seed=4)


def test_panda_fk_against_robotics_toolbox(rtb):
    """The toolbox's Panda without its gripper tool (it folds the flange into d7)."""
    from spatialmath import SE3

    robot = rtb.models.DH.Panda()
    assert robot.links[6].d == pytest.approx(PANDA["flange_d"])
    robot.tool = SE3()  # the toolbox adds Franka's hand (103 mm, -45 deg); the model stops at the flange
    _rtb_compare(robot, tolsynth.load_model("panda"), seed=5)


def test_ur5_fk_against_robotics_toolbox(rtb):
    """A toolbox DHRobot from UR's table.  The toolbox's own UR5.py cites the same page but
    writes d1 = 0.089459 m (0.3 mm more); every other value of it is UR's, checked here."""
    robot = rtb.DHRobot(
        [rtb.RevoluteDH(a=a, d=d, alpha=al) for a, d, al in zip(UR5["a"], UR5["d"], UR5["alpha"])],
        name="UR5 (UR's table)",
    )
    _rtb_compare(robot, tolsynth.load_model("ur5"), seed=6)
    shipped = rtb.models.DH.UR5()
    for i, link in enumerate(shipped.links):
        assert link.a == pytest.approx(UR5["a"][i]) and link.alpha == pytest.approx(UR5["alpha"][i])
        if i > 0:
            assert link.d == pytest.approx(UR5["d"][i])


# ---------------------------------------------------------------------------------------------
# Xu & Zhang 1988 (docs/reconstruction.md) and planar_2r
# ---------------------------------------------------------------------------------------------
def test_xu_nominal_parameters_ranges_and_costs_as_printed():
    m = tolsynth.load_model("xu_zhang_1988")
    sym = m.spec.symbols
    for name, value in XU_NOMINAL.items():
        assert sym[name] == pytest.approx(value, abs=1e-12), name
    for j in m.spec.joints:
        assert (j.lower / DEG, j.upper / DEG) == pytest.approx(XU_RANGES[j.name], abs=1e-9)
    (c,) = m.spec.joint_constraints
    assert (c.lower / DEG, c.upper / DEG) == pytest.approx((50.0, 130.0))
    assert m.k.tolist() == [1.0] * 8 + [1.5] * 3
    assert list(m.units) == ["mm"] * 8 + ["1e-2 rad"] * 3


def test_xu_reference_results_are_the_printed_tables():
    m = tolsynth.load_model("xu_zhang_1988")
    got = {(r.table, r.R, r.p, r.alpha, r.distribution): list(r.tolerances) for r in m.spec.reference_results}
    assert got == XU_TABLES


def test_planar_2r_numbers_and_fk():
    m = tolsynth.load_model("planar_2r")
    assert {k: m.spec.symbols[k] for k in PLANAR} == PLANAR
    lo, hi = _limits(m)
    for q in _random_q(lo, hi, 20, seed=7):
        x = PLANAR["l1"] * math.cos(q[0]) + PLANAR["l2"] * math.cos(q[0] + q[1])
        y = PLANAR["l1"] * math.sin(q[0]) + PLANAR["l2"] * math.sin(q[0] + q[1])
        assert np.allclose(m.fk(q)[:3, 3], [x, y, 0.0], atol=1e-9)
