"""Parallel robots (hexapod, Delta, planar 3-RRR): the kinematics against independent NumPy code.

The geometry is typed in here from the sources the model files cite (Nategh & Agheli's hexapod
machine tool, Williams' table of the ABB FlexPicker IRB 360, Garcia-Samartin & Barrientos' 3-RRR); the inverse
kinematics below is written from the anchors alone (a strut's length; a revolute leg's angle by the
tangent half-angle substitution, not the package's atan2/acos form).  Nothing is read back from
the model files to build a reference.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import tolsynth
from tolsynth.errors import LoopClosureError, OutOfRangeError

S3 = math.sqrt(3.0) / 2.0

# Nategh & Agheli, Int. J. Machine Tools and Manufacture 49 (2009), Table 1 (mm): base joints u_i,
# platform joints s_i, nominal strut length 604.8652 (as typed in T. Viso's hexapod-parallel-manipulator)
HEX_BASE = np.array(
    [
        [305.4001, 111.1565, 0],
        [-56.4357, 320.0625, 0],
        [-248.9644, 208.906, 0],
        [-248.9644, -208.906, 0],
        [-56.4357, -320.0625, 0],
        [305.4001, -111.1565, 0],
    ]
)
HEX_PLATFORM = np.array(
    [
        [92.1597, 84.4488, 0],
        [27.055, 122.037, 0],
        [-119.2146, 37.58822, 0],
        [-119.2146, -37.5882, 0],
        [27.055, -122.037, 0],
        [92.1597, -84.4488, 0],
    ]
)
HEX_LO = 604.8652
# Williams, "The Delta Parallel Robot: Kinematics Solutions" (2016), ABB FlexPicker IRB 360-1/1600 (mm):
# sB = 567, sP = 76, L = 524, l = 1244, and the source's formulas wB = sB sqrt(3)/6, uP = sP sqrt(3)/3,
# wP = sP sqrt(3)/6 (p. 6)
SB, SP, L_ARM, L_LINK = 567.0, 76.0, 524.0, 1244.0
WB, UP, WP = SB * math.sqrt(3) / 6, SP * math.sqrt(3) / 3, SP * math.sqrt(3) / 6
DELTA_BASE = np.array([[0, -WB, 0], [S3 * WB, WB / 2, 0], [-S3 * WB, WB / 2, 0]])
DELTA_PLATFORM = np.array([[0, -UP, 0], [SP / 2, WP, 0], [-SP / 2, WP, 0]])
DELTA_ZERO = np.array([[0, -1, 0], [S3, 0.5, 0], [-S3, 0.5, 0]])  # radially outward
DELTA_DOWN = np.array([0, 0, -1.0])  # theta > 0 turns the arm down
# Garcia-Samartin & Barrientos' 3-RRR (Machines 2023, the robot3RRR class of github.com/Robcib-GIT/3RRR),
# in mm: base joints O = [0 0; 0.595 0; 0.297 0.515] m, arms and links 0.2 m, an equilateral platform of
# side T = 0.2 m with vertices B1 = P - L (cos 30, sin 30), B2 = B1 + T (1, 0), B3 = B1 + T (cos 60,
# sin 60), L = T / cos(30 deg) / 2 (src/Platform.m, phi = 0)
RRR_BASE = np.array([[0.0, 0, 0], [595.0, 0, 0], [297.0, 515.0, 0]])
_T, _L = 200.0, 200.0 / math.cos(math.pi / 6) / 2
_B1 = -_L * np.array([math.cos(math.pi / 6), math.sin(math.pi / 6), 0.0])
RRR_PLATFORM = np.array([_B1, _B1 + [_T, 0, 0], _B1 + _T * np.array([0.5, S3, 0.0])])
RRR_HOME = (300.0, 200.0)  # the source's pose P = (0.3, 0.2) m, rz = 0
RRR_ZERO = np.tile([1.0, 0, 0], (3, 1))
RRR_UP = np.array([0, 1.0, 0])  # e = z x zero: angles about z from X0


def rot(rx, ry, rz):
    """Rz(rz) Ry(ry) Rx(rx)."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def revolute_ik(B, C, zero, e, arm, link, near):
    """The arm angle with |C - B - arm (cos t zero + sin t e)| = link: tangent half-angle roots of
    E cos t + F sin t + G = 0, the one nearest ``near`` (rad)."""
    w = C - B
    E, F, G = -2 * arm * (w @ zero), -2 * arm * (w @ e), w @ w + arm**2 - link**2
    disc = E * E + F * F - G * G
    assert disc >= 0, "unreachable"
    roots = [2 * math.atan((-F + s * math.sqrt(disc)) / (G - E)) for s in (1.0, -1.0)]
    return min(roots, key=lambda t: abs(math.remainder(t - near, 2 * math.pi)))


def numpy_ik(name, pose, near):
    """Actuators (mm or rad) of a platform pose (x, y, z, rx, ry, rz), from the typed-in anchors."""
    p, R = np.asarray(pose[:3], float), rot(*pose[3:])
    if name == "stewart_gough":
        return np.linalg.norm(p + HEX_PLATFORM @ R.T - HEX_BASE, axis=1)
    if name == "delta":
        B, P, Z, E, arm, link = DELTA_BASE, DELTA_PLATFORM, DELTA_ZERO, [DELTA_DOWN] * 3, L_ARM, L_LINK
    else:
        B, P, Z, E, arm, link = RRR_BASE, RRR_PLATFORM, RRR_ZERO, [RRR_UP] * 3, 200.0, 200.0
    out = []
    for i in range(3):
        t = revolute_ik(B[i], p + R @ P[i], Z[i], np.asarray(E[i]), arm, link, near[i])
        out.append(near[i] + math.remainder(t - near[i], 2 * math.pi))
    return np.array(out)


#: platform poses sampled around each model's home pose: centre and half-ranges (mm, rad)
POSES = {
    "stewart_gough": ([0, 0, 600.0, 0, 0, 0], [20, 20, 25, 0.03, 0.03, 0.04]),
    "delta": ([0, 0, -900.0, 0, 0, 0], [300, 300, 150, 0, 0, 0]),
    "planar_3rrr": ([295.0, 190.0, 0, 0, 0, 0.03], [6, 6, 0, 0, 0, 0.04]),
}
MODELS = list(POSES)


@pytest.fixture(scope="module")
def models():
    return {name: tolsynth.load_model(name) for name in MODELS}


def _sample(name, m, rng, k):
    """Poses and their NumPy-IK actuators, inside the actuator limits."""
    centre, half = (np.array(v, float) for v in POSES[name])
    home = m.configurations["home"]
    lo, hi = (np.array([getattr(j, a) for j in m.spec.joints]) for a in ("lower", "upper"))
    out = []
    while len(out) < k:
        x = centre + half * rng.uniform(-1, 1, 6)
        q = numpy_ik(name, x, home)
        if np.all((lo <= q) & (q <= hi)):
            out.append((x, q))
    return out


@pytest.mark.parametrize("name", MODELS)
def test_fk_inverts_an_independent_ik(models, name):
    """Forward kinematics (Newton on the graph) of the NumPy IK's actuators gives the pose back
    to 1e-9 mm and 1e-9 in the rotation matrix; the graph's closed-form IK gives the actuators."""
    m = models[name]
    zero = np.zeros(m.n)
    for x, q in _sample(name, m, np.random.default_rng(1), 25):
        T = m.fk(q)
        assert np.max(np.abs(T[:3, 3] - x[:3])) <= 1e-9, (name, x)
        assert np.max(np.abs(T[:3, :3] - rot(*x[3:]))) <= 1e-9, (name, x)
        dof = [("x", "y", "z", "rx", "ry", "rz").index(d) for d in m.spec.dof]
        q_graph = np.asarray(m.graphs.ik(x[dof], zero)[0]).ravel()
        assert np.max(np.abs(q_graph - q)) <= 1e-9, (name, q_graph - q)


def test_home_poses_are_the_sources():
    """Nategh & Agheli's hexapod: every strut at the table's 604.8652 mm, the platform level at
    565.40 mm (NumPy: the six struts of that pose are 604.8652 to 5e-5 mm); Williams' Delta example
    pose (0, 0, -900) mm; the 3-RRR at the source's pose (300, 200) mm, not turned."""
    hexapod = tolsynth.load_model("stewart_gough")
    assert np.all(hexapod.configurations["home"] == HEX_LO)
    assert np.abs(numpy_ik("stewart_gough", [0, 0, 565.40, 0, 0, 0], None) - HEX_LO).max() <= 5e-5
    T = hexapod.fk("home")
    assert np.allclose(T[:3, 3], [0, 0, 565.40], atol=1e-3) and np.allclose(T[:3, :3], np.eye(3), atol=1e-6)
    delta = tolsynth.load_model("delta")
    assert np.allclose(delta.fk("home")[:3, 3], [0, 0, -900], atol=1e-8)  # file's angles to 1e-10 deg
    q_w = numpy_ik("delta", [0, 0, -900, 0, 0, 0], [-0.3, -0.3, -0.3])
    assert np.allclose(np.degrees(q_w), -20.5, atol=0.05)  # Williams p. 16 prints -20.5 deg
    T = tolsynth.load_model("planar_3rrr").fk("home")
    assert np.allclose(T[:3, 3], [*RRR_HOME, 0], atol=1e-8) and np.allclose(T[:3, :3], np.eye(3), atol=1e-10)


@pytest.mark.parametrize("name, pose", [(n, c) for n in MODELS for c in ("home", None)])
def test_sensitivity_is_the_central_difference_of_fk(models, name, pose):
    """The implicit-function-theorem sensitivities against central differences of the forward
    kinematics (Newton to convergence at each perturbed error vector)."""
    m = models[name]
    q = m.joints(pose) if pose else next(iter(_sample(name, m, np.random.default_rng(7), 1)))[1]
    S = m.sensitivity(q)
    h = 1e-3  # tolerance units (um or urad): truncation ~h^2, rounding ~1e-13/h
    for j in range(m.n):
        d = np.zeros(m.n)
        d[j] = h
        Tp, Tm = m.fk(q, d), m.fk(q, -d)
        dp = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
        W = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ Tp[:3, :3].T
        dphi = np.array([W[2, 1], W[0, 2], W[1, 0]])
        scale = 1.0 + np.abs(S[:, j]).max()
        assert np.abs(dp - S[:3, j]).max() <= 1e-6 * scale, (name, m.error_parameters[j])
        assert np.abs(dphi - S[3:, j]).max() <= 1e-6 * scale, (name, m.error_parameters[j])


def test_sensitivity_rows_of_constrained_platforms(models):
    """The Delta's platform does not turn; the 3-RRR's stays in its plane."""
    assert np.abs(models["delta"].sensitivity("corner")[3:]).max() == 0
    S = models["planar_3rrr"].sensitivity("shifted")
    assert np.abs(S[[2, 3, 4]]).max() == 0 and np.abs(S[5]).max() > 0


def test_unassembled_and_out_of_range_poses_are_typed_errors(models):
    m = models["stewart_gough"]
    with pytest.raises(OutOfRangeError, match=r"q\[q1\]: 2000.0000 mm is outside"):
        m.fk([2000.0] * 6)
    with pytest.raises(LoopClosureError, match="cannot be assembled"):
        m.fk([2000.0, 700, 700, 700, 700, 700], check_limits=False)  # one strut far too long
    with pytest.raises(LoopClosureError):
        m.sensitivity([2000.0, 700, 700, 700, 700, 700], check_limits=False)


def _rrr_turned(phi, near):
    """The 3-RRR's actuators with the platform centre at the source's pose and turned by ``phi``
    (rad), each leg followed on its branch from ``near`` (the actuators at rz = 0) in steps of at
    most 0.01 rad."""
    q = np.asarray(near, float)
    for t in np.linspace(0.0, phi, int(abs(phi) / 0.01) + 2)[1:]:
        q = numpy_ik("planar_3rrr", [*RRR_HOME, 0, 0, 0, t], q)
    return q


def _rrr_singular_angle(near):
    """A platform rotation (centre fixed at the source's pose) at which the 3-RRR's three links meet
    in one point: the 3 x 3 Jacobian of its closure (NumPy, by the links' directions) is singular."""

    def det(phi):
        q = _rrr_turned(phi, near)
        rows = []
        for i in range(3):
            A = RRR_BASE[i] + 200 * np.array([math.cos(q[i]), math.sin(q[i]), 0])
            c = rot(0, 0, phi) @ RRR_PLATFORM[i]
            u = (np.array([*RRR_HOME, 0]) + c - A) / np.linalg.norm(np.array([*RRR_HOME, 0]) + c - A)
            rows.append([u[0], u[1], c[0] * u[1] - c[1] * u[0]])  # d|C - A| / d(x, y, phi)
        return np.linalg.det(rows)

    grid = np.linspace(-1.2, 1.2, 49)
    vals = [det(p) for p in grid]
    k = next(i for i in range(len(grid) - 1) if vals[i] * vals[i + 1] < 0 and abs(grid[i]) > 0.05)
    a, b = grid[k], grid[k + 1]
    for _ in range(50):
        c = 0.5 * (a + b)
        a, b = (a, c) if det(a) * det(c) <= 0 else (c, b)
    return 0.5 * (a + b)


def test_singular_pose_is_a_typed_error_and_conditioning_grows(models):
    """Turning the 3-RRR's platform about its centre at the source's pose: the links meet in one
    point at about -0.58 rad (NumPy); the package's condition number grows on the way there and the
    singular pose itself is a typed error."""
    m = models["planar_3rrr"]
    near = m.joints("home")
    phi_s = _rrr_singular_angle(near)
    assert -0.6 < phi_s < -0.55, phi_s
    conds = []
    for frac in (0.5, 0.9, 0.99):
        q = _rrr_turned(frac * phi_s, near)
        conds.append(m.graphs.conditioning(q, np.zeros(m.n)))
    assert conds[0] < conds[1] < conds[2] and conds[2] > 20 * conds[0], conds
    q_s = _rrr_turned(phi_s, near)
    with pytest.raises(LoopClosureError):
        m.sensitivity(q_s, check_limits=False)
    with pytest.raises(LoopClosureError):
        tolsynth.monte_carlo(m, q_s, "coarse", R=0.1, n=100, check_limits=False, progress=False)


@pytest.mark.parametrize("name, R", [("delta", 0.3), ("stewart_gough", 0.05), ("planar_3rrr", 0.03)])
def test_monte_carlo_through_the_nonlinear_fk_matches_the_exact_probability(models, name, R):
    """P(|dr| <= R) by Monte Carlo through Newton's forward kinematics against the exact
    probability of the linear model (FFT-free series of tolsynth.probability.exact)."""
    from tolsynth.probability.distributions import shapes_of
    from tolsynth.probability.exact import ball_probability

    m = models[name]
    mc = tolsynth.monte_carlo(m, "home", "coarse", R=R, n=100_000, seed=3, progress=False)
    assert mc.n_loop_failures == 0
    eps = m.tolerances("coarse")
    p_exact = ball_probability(m.sensitivity("home")[:3], eps, shapes_of("uniform", m.error_parameters, m.index), R)
    lo, hi = mc.p_sphere_ci
    assert lo - 2e-3 <= p_exact <= hi + 2e-3, (name, mc.p_sphere, p_exact)
