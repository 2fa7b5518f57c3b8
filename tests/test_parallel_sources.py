"""The bundled parallel robots against the sources their files cite.

The sources' numbers are typed in here with the citation next to them; nothing is read back from
a model file to build a reference.  Where a source prints a computed value (a pose from actuator
values, actuator values of a pose, the nominal strut length), the package's kinematics must give it
to the digits printed.  Also here: the certified interval search refuses a parallel robot with a
typed error naming why (its sensitivities come from Newton's method, which intervals cannot bound).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import tolsynth
from tolsynth.errors import InputError

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
# M. J. Nategh, M. M. Agheli, "A total solution to kinematic calibration of hexapod machine tools
# with a minimum number of measurement configurations and superior accuracies", Int. J. Machine
# Tools and Manufacture 49 (2009): a hexapod machine tool whose "top and base platforms have
# diameters of 250 and 650 mm".  Table 1, nominal kinematic parameters (mm): base joints u_i,
# platform joints s_i (z = 0), nominal strut length lo_i; Table 2, the simulated "real" machine's.
# As typed in T. Viso's hexapod-parallel-manipulator (calibration.m: u_nom, s_nom, lo_nom, u_real,
# s_real, lo_real), columns i = 1..6; the source's strut length is l_i = lo_i + dl_i.
NATEGH_U = [
    (305.4001, 111.1565, 0.0),
    (-56.4357, 320.0625, 0.0),
    (-248.9644, 208.9060, 0.0),
    (-248.9644, -208.9060, 0.0),
    (-56.4357, -320.0625, 0.0),
    (305.4001, -111.1565, 0.0),
]
NATEGH_S = [
    (92.1597, 84.4488, 0.0),
    (27.055, 122.037, 0.0),
    (-119.2146, 37.58822, 0.0),
    (-119.2146, -37.5882, 0.0),
    (27.055, -122.037, 0.0),
    (92.1597, -84.4488, 0.0),
]
NATEGH_LO = 604.8652
NATEGH_DIAMETERS = {"base": 650.0, "platform": 250.0}
NATEGH_U_REAL = [
    (305.2599, 115.0695, 2.6210),
    (-55.2814, 322.9819, 4.2181),
    (-244.7954, 208.0087, 3.9365),
    (-252.5755, -211.8783, -3.0128),
    (-53.9678, -320.6115, 4.3181),
    (302.4266, -109.4351, 3.3812),
]
NATEGH_S_REAL = [
    (96.6610, 81.7602, 1.0684),
    (22.2476, 125.2511, -0.5530),
    (-122.4519, 36.6453, 4.3547),
    (-120.6859, -34.4565, -4.9014),
    (24.7769, -125.0489, -4.8473),
    (91.3462, -80.9866, 0.2515),
]
NATEGH_LO_REAL = [604.4299, 607.2473, 600.4441, 605.9031, 604.5251, 600.0616]


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


def test_delta_arm_range_covers_the_examples_and_stays_clear_of_singularities(delta):
    """The file's arm range (-30 to 60 deg, its assumption) holds every arm angle of the source's
    worked examples, and over a 9^3 grid of it (NumPy: arm ends from the source's geometry, the
    links' unit directions as the rows of df/dx at the forward kinematics' platform position) every
    link closes to 1e-8 mm, df/dx has condition number <= 4.4 and the platform stays 740 to 1640 mm
    below the base: no pose of the box is near a singularity."""
    lo, hi = (np.degrees([getattr(j, k) for j in delta.spec.joints]) for k in ("lower", "upper"))
    assert np.allclose(lo, -30.0) and np.allclose(hi, 60.0)
    examples = np.array([a for _, a in WILLIAMS_IPK] + [a for a, _ in WILLIAMS_FPK])
    assert lo[0] <= examples.min() and examples.max() <= hi[0]
    w = WILLIAMS
    s3 = math.sqrt(3.0)
    wB, uP, wP = s3 / 6 * w["sB"], s3 / 3 * w["sP"], s3 / 6 * w["sP"]
    base = np.array([[0, -wB, 0], [s3 / 2 * wB, wB / 2, 0], [-s3 / 2 * wB, wB / 2, 0]])
    plat = np.array([[0, -uP, 0], [w["sP"] / 2, wP, 0], [-w["sP"] / 2, wP, 0]])
    out = base / np.linalg.norm(base, axis=1)[:, None]  # radially outward; theta > 0 turns it down
    down = np.array([0.0, 0.0, -1.0])
    g = np.radians(np.linspace(-30.0, 60.0, 9))
    conds, heights = [], []
    for th in np.array(np.meshgrid(g, g, g)).reshape(3, -1).T:
        p = delta.fk(th)[:3, 3]
        A = base + w["L"] * (np.cos(th)[:, None] * out + np.sin(th)[:, None] * down)
        d = p + plat - A
        assert np.abs(np.linalg.norm(d, axis=1) - w["l"]).max() <= 1e-8
        conds.append(np.linalg.cond(d / w["l"]))
        heights.append(p[2])
    assert max(conds) <= 4.4 and -1640.0 <= min(heights) and max(heights) <= -740.0, (max(conds), heights)


def test_hexapod_numbers_are_nategh_and_aghelis_table():
    """Leg i of the model is the table's column i (to 1e-9 mm); the table's joints lie on the
    source's 650 and 250 mm circles to its 4 printed decimals (1e-4 mm)."""
    m = tolsynth.load_model("stewart_gough")
    B, C = _leg_points(m)
    assert np.abs(B - np.array(NATEGH_U)).max() <= 1e-9
    assert np.abs(C - np.array(NATEGH_S)).max() <= 1e-9
    for pts, d in ((NATEGH_U, "base"), (NATEGH_S, "platform")):
        radii = np.linalg.norm(np.array(pts), axis=1)
        assert np.abs(radii - NATEGH_DIAMETERS[d] / 2).max() <= 1e-4, (d, radii)
    assert np.all(m.joints("home") == NATEGH_LO)


def test_hexapod_home_is_the_tables_nominal_length():
    """Every strut at the table's lo = 604.8652 mm puts the platform level (rotation within 1e-6 of
    the identity, from the six struts alone, by Newton) at z = 565.40 mm; back from the anchors, the
    six struts at that level pose all round to the printed 604.8652 (within 5e-5 mm): one length for
    six struts, which the table's coordinates give only if they are the symmetric design it states."""
    m = tolsynth.load_model("stewart_gough")
    T = m.fk("home")
    assert np.abs(T[:3, :3] - np.eye(3)).max() <= 1e-6
    assert np.abs(T[:2, 3]).max() <= 1e-3 and abs(T[2, 3] - 565.40) <= 1e-3, T[:3, 3]
    lengths = np.linalg.norm(np.array([0.0, 0.0, 565.40]) + np.array(NATEGH_S) - np.array(NATEGH_U), axis=1)
    assert np.abs(lengths - NATEGH_LO).max() <= 5e-5, lengths


def test_hexapod_strut_box_is_well_conditioned():
    """The file's strut box (600 to 640 mm, its assumption): at the 2^6 corners and 200 random strut
    vectors of it the platform assembles, its struts close to 1e-8 mm (NumPy, from the table's
    anchors), and df/dx (rows: the struts' unit directions u and (R s) x u / 125 mm) has condition
    number <= 12.1, with 6.744 at home (the rotation columns here are small rotations about the
    base axes, the package's are its rx, ry, rz: the two agree at the level home pose)."""
    m = tolsynth.load_model("stewart_gough")
    U, S = np.array(NATEGH_U), np.array(NATEGH_S)

    def cond(q):
        T = m.fk(q)
        c = S @ T[:3, :3].T
        d = T[:3, 3] + c - U
        assert np.abs(np.linalg.norm(d, axis=1) - q).max() <= 1e-8
        u = d / np.linalg.norm(d, axis=1)[:, None]
        return np.linalg.cond(np.c_[u, np.cross(c, u) / 125.0])

    assert abs(cond(m.joints("home")) - 6.744) <= 1e-3
    lo, hi = (np.array([getattr(j, k) for j in m.spec.joints]) for k in ("lower", "upper"))
    assert np.all(lo == 600.0) and np.all(hi == 640.0)
    corners = np.array(np.meshgrid(*[[600.0, 640.0]] * 6)).reshape(6, -1).T
    Q = np.r_[corners, lo + (hi - lo) * np.random.default_rng(5).uniform(0, 1, (200, 6))]
    conds = [cond(q) for q in Q]
    assert max(conds) <= 12.1, max(conds)


def test_hexapod_error_parameters_read_the_sources_real_machine():
    """The source's Table 2 machine as an error vector (real minus nominal: anchors and lo): the
    forward kinematics at the nominal lengths (dl = 0) gives a pose at which the real anchors are
    the real lengths lo_i apart (NumPy, to 1e-8 mm): offsets and anchors mean what the source's
    parameters mean."""
    m = tolsynth.load_model("stewart_gough")
    d = np.zeros(m.n)
    for i in range(6):
        leg = f"L{i + 1}"
        for k, f in enumerate("xyz"):
            d[m.index(f"{leg}.b{f}")] = NATEGH_U_REAL[i][k] - NATEGH_U[i][k]
            d[m.index(f"{leg}.p{f}")] = NATEGH_S_REAL[i][k] - NATEGH_S[i][k]
        d[m.index(f"{leg}.offset")] = NATEGH_LO_REAL[i] - NATEGH_LO
    T = m.fk("home", d)
    legs = np.linalg.norm(T[:3, 3] + np.array(NATEGH_S_REAL) @ T[:3, :3].T - np.array(NATEGH_U_REAL), axis=1)
    assert np.abs(legs - NATEGH_LO_REAL).max() <= 1e-8, legs
    assert np.abs(T[:3, 3] - m.fk("home")[:3, 3]).max() > 1.0  # millimetre-sized errors move it


# ---------------------------------------------------------------------------------------------
# J. F. Garcia-Samartin, A. Barrientos, "Kinematic Modelling of a 3RRR Planar Parallel Robot Using
# Genetic Algorithms and Neural Networks", Machines 11(10) (2023) 952, as typed in the authors'
# repository github.com/Robcib-GIT/3RRR (commit 8926073): the defaults of src/robot3RRR.m (metres,
# radians) and the vertex formulas of src/Platform.m (equilateral platform, orientation phi):
#   O = [0 0; 0.595 0; 0.297 0.515], L = [0.2 0.2 0.1155] per leg (arm, link, vertex to centre),
#   T = [0.2 0.2 0.2], P = [0.3 0.2 0], q = [1.529 1.588 -2.604], sgn = [1 1 1];
#   L = T / cos(pi/6) / 2, B1 = P - L (cos(pi/6 + phi), sin(pi/6 + phi)), B2 = B1 + T (cos phi,
#   sin phi), B3 = B1 + T (cos(pi/3 + phi), sin(pi/3 + phi)); A = O + L1 (cos q, sin q).
GS = {
    "O": [(0.0, 0.0), (0.595, 0.0), (0.297, 0.515)],
    "arm": 0.2,
    "link": 0.2,
    "L_typed": 0.1155,
    "T": 0.2,
    "P": (0.3, 0.2, 0.0),
    "q": (1.529, 1.588, -2.604),
}


def _gs_vertices(x, y, phi):
    """The source's platform vertices (m) for the pose (x, y, phi)."""
    T, L = GS["T"], GS["T"] / math.cos(math.pi / 6) / 2
    b1 = np.array([x - L * math.cos(math.pi / 6 + phi), y - L * math.sin(math.pi / 6 + phi)])
    return np.array(
        [
            b1,
            b1 + T * np.array([math.cos(phi), math.sin(phi)]),
            b1 + T * np.array([math.cos(math.pi / 3 + phi), math.sin(math.pi / 3 + phi)]),
        ]
    )


def _gs_links(q, pose):
    """|A_i - B_i| (m) for actuators q (rad) and a pose (m, m, rad): the source's loop closure."""
    A = np.array(GS["O"]) + GS["arm"] * np.c_[np.cos(q), np.sin(q)]
    return np.linalg.norm(A - _gs_vertices(*pose), axis=1)


@pytest.fixture(scope="module")
def rrr():
    return tolsynth.load_model("planar_3rrr")


def test_3rrr_numbers_are_the_sources_robot(rrr):
    """Base joints are the source's O, arms and links its 0.2 m (to 1e-9 mm); the platform joints
    are its vertex formulas at P = 0, phi = 0 (to 1e-9 mm), 115.47 mm from the centre (the class's
    typed 0.1155 m to its 4 decimals); every actuator turns about Z0 from X0, as A = O + L1 (cos q,
    sin q)."""
    B, C = _leg_points(rrr)
    assert np.abs(B - np.c_[1000 * np.array(GS["O"]), np.zeros(3)]).max() <= 1e-9
    assert np.abs(C - np.c_[1000 * _gs_vertices(0.0, 0.0, 0.0), np.zeros(3)]).max() <= 1e-9
    assert np.abs(np.linalg.norm(C, axis=1) / 1000 - GS["L_typed"]).max() <= 5e-5
    s = rrr.spec.symbols
    for leg in rrr.spec.legs:
        assert s[leg.symbol("arm")] == 1000 * GS["arm"] and s[leg.symbol("link")] == 1000 * GS["link"]
        assert leg.axis == (0.0, 0.0, 1.0) and leg.zero == (1.0, 0.0, 0.0)


def test_3rrr_reproduces_the_sources_pose_and_actuator_angles(rrr):
    """The source prints q = (1.529, 1.588, -2.604) rad with P = (0.3, 0.2, 0).  The closed-form
    inverse kinematics at that pose gives (1.528480, 1.588324, -2.604251) rad: q2 and q3 round to
    the printed values, q1 is 5.2e-4 rad from its printed 1.529 (which rounds 1.52848 up by one
    unit); the printed angles close the source's legs (NumPy, its formulas) to 0.11 mm of the
    200 mm links, and Newton's forward kinematics of them lands 0.3 mm and 0.07 deg from the printed
    pose.  The file's home is that pose to 1e-6 mm."""
    x = np.array([1000 * GS["P"][0], 1000 * GS["P"][1], GS["P"][2]])
    q, c = rrr.graphs.ik(x, np.zeros(rrr.n))
    q = np.asarray(q, dtype=float).ravel()
    assert np.all(np.abs(np.asarray(c, dtype=float)) <= 1.0)
    printed = np.array(GS["q"])
    assert np.abs(q[1:] - printed[1:]).max() <= 5e-4 and abs(q[0] - printed[0]) <= 6e-4, q
    # the independent closure: the package's actuators close the source's legs exactly
    assert np.abs(_gs_links(q, GS["P"]) - GS["link"]).max() <= 1e-12
    assert np.abs(_gs_links(printed, GS["P"]) - GS["link"]).max() <= 1.1e-4
    T = rrr.fk(printed)
    assert np.abs(T[:2, 3] - x[:2]).max() <= 0.3 and abs(math.atan2(T[1, 0], T[0, 0])) <= math.radians(0.07)
    assert np.abs(rrr.fk("home")[:2, 3] - x[:2]).max() <= 1e-6
    assert np.abs(rrr.joints("home") - q).max() <= 1e-11


def test_3rrr_range_holds_the_sources_angles_and_stays_well_conditioned(rrr):
    """The file's actuator ranges (its assumption) hold the source's printed angles; over a 7^3 grid
    of them the platform assembles, its legs close to 1e-8 mm (NumPy, the source's formulas) and
    df/dx (rows: the links' unit directions u and (R c) x u / 115.47 mm, the platform's radius)
    has condition number <= 6.1, with 4.578 at home: no pose of the box is near a singularity."""
    lo, hi = (np.degrees([getattr(j, k) for j in rrr.spec.joints]) for k in ("lower", "upper"))
    assert np.allclose(lo, [83.0, 90.5, -155.0]) and np.allclose(hi, [88.0, 96.0, -144.0])
    printed = np.degrees(GS["q"])
    assert np.all(lo <= printed) and np.all(printed <= hi)
    O, radius = 1000 * np.array(GS["O"]), 1000 * GS["T"] / math.sqrt(3)

    def cond(q):
        T = rrr.fk(q)
        x, y, phi = T[0, 3], T[1, 3], math.atan2(T[1, 0], T[0, 0])
        assert np.abs(_gs_links(q, (x / 1000, y / 1000, phi)) - GS["link"]).max() <= 1e-11
        Bv = 1000 * _gs_vertices(x / 1000, y / 1000, phi)
        A = O + 1000 * GS["arm"] * np.c_[np.cos(q), np.sin(q)]
        u = (Bv - A) / np.linalg.norm(Bv - A, axis=1)[:, None]
        c = Bv - [x, y]
        return np.linalg.cond(np.c_[u, (c[:, 0] * u[:, 1] - c[:, 1] * u[:, 0]) / radius])

    assert abs(cond(rrr.joints("home")) - 4.578) <= 1e-3
    grid = np.array(np.meshgrid(*[np.radians(np.linspace(a, b, 7)) for a, b in zip(lo, hi)])).reshape(3, -1).T
    conds = [cond(q) for q in grid]
    assert max(conds) <= 6.1, max(conds)


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


def test_certified_exchange_refuses_a_parallel_robot_before_any_round():
    """The hexapod's six joints would draw the exact proof's warning after a round of solves; the
    refusal comes first (the warning, made an error here, never fires), and no solve runs."""
    import warnings

    from tolsynth.errors import CertificationWarning
    from tolsynth.synthesis import workspace

    hexapod = tolsynth.load_model("stewart_gough")
    with warnings.catch_warnings(), pytest.MonkeyPatch.context() as mp:
        warnings.simplefilter("error", CertificationWarning)
        mp.setattr(workspace, "synthesize", lambda *a, **k: pytest.fail("a solve ran before the refusal"))
        with pytest.raises(InputError, match="parallel robot"):
            tolsynth.synthesize_workspace(hexapod, R=0.5, p=0.99, certify=True, max_rounds=2, progress=False)


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
