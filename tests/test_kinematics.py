"""Forward kinematics and sensitivities of the three bundled models, checked independently.

* A plain-NumPy forward kinematics, written out by hand for each model below (the paper's
  parallelogram solved as a circle-circle intersection, not as the package's atan2 + acos), must
  agree with the CasADi graph at random configurations and random parameter errors.
* Every column of the exact (algorithmic) sensitivity must agree with central differences of
  ``Mechanism.fk(q, deltas=...)`` (position rows, and the small rotation
  ``vee(skew((R(+h) - R(-h)) / 2h @ R0.T))`` for the orientation rows), and with central
  differences of the NumPy forward kinematics.

The NumPy chains ``xu_fk``, ``puma_fk``, ``planar_fk`` and ``fd_sensitivity`` are also used by
``test_cli_analyze.py``, ``test_errors.py`` and ``test_packaging.py``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import tolsynth

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover
    import tomli as tomllib

MODELS_DIR = Path(__file__).resolve().parent.parent / "models"


def _toml(name: str) -> dict:
    with open(MODELS_DIR / f"{name}.toml", "rb") as fh:
        return tomllib.load(fh)


# ---------------------------------------------------------------------------------------------
# elementary transforms
# ---------------------------------------------------------------------------------------------
def Tx(a):
    T = np.eye(4)
    T[0, 3] = a
    return T


def Tz(d):
    T = np.eye(4)
    T[2, 3] = d
    return T


def Rx(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def Rz(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def vee(W):
    """(phi_x, phi_y, phi_z) of the skew part of W."""
    A = 0.5 * (W - W.T)
    return np.array([A[2, 1], A[0, 2], A[1, 0]])


# tolerance units, by hand (the tests also check the model files declare exactly these)
TOL_UNIT = {"mm": 1.0, "1e-2 rad": 1e-2, "mrad": 1e-3}


# ---------------------------------------------------------------------------------------------
# the paper's robot (docs/reconstruction.md), by hand
# ---------------------------------------------------------------------------------------------
_XU = _toml("xu_zhang_1988")
XU_SYM = {k: (math.radians(v) if (k.startswith("alpha") or k == "o1") else float(v)) for k, v in _XU["symbols"].items()}
XU_UNITS = {  # error parameter -> tolerance unit, as the paper's section 5 states them
    "h2": "mm",
    "h3": "mm",
    "h4": "mm",
    "hp2": "mm",
    "hp3": "mm",
    "hp4": "mm",
    "s1": "mm",
    "a": "mm",
    "alpha1": "1e-2 rad",
    "alpha3": "1e-2 rad",
    "alpha4": "1e-2 rad",
}
XU_ORDER = ["h2", "h3", "h4", "hp2", "hp3", "hp4", "s1", "a", "alpha1", "alpha3", "alpha4"]


def _wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def elbow_by_circles(th2, thp2, hp1, hp2, hp3, hp4):
    """Forearm (lever) direction of the parallelogram by intersecting two circles.

    Shoulder S at the origin of the arm plane, angles from X1: elbow E = hp1 u(th2), crank tip
    C = hp2 u(thp2); the lever tip D lies on the circle (C, hp3) and on the circle (E, hp4).
    Of the two intersections take the one whose lever direction is nearest thp2 (the open
    parallelogram).  Returns the passive elbow angle theta3 = lever direction - th2.
    """
    E = hp1 * np.array([math.cos(th2), math.sin(th2)])
    C = hp2 * np.array([math.cos(thp2), math.sin(thp2)])
    v = E - C
    dist = float(np.hypot(*v))
    along = (hp3**2 - hp4**2 + dist**2) / (2 * dist)  # from C towards E, to the common chord
    half_chord = math.sqrt(hp3**2 - along**2)
    foot = C + along * v / dist
    perp = np.array([-v[1], v[0]]) / dist
    best = None
    for D in (foot + half_chord * perp, foot - half_chord * perp):
        lever = math.atan2(D[1] - E[1], D[0] - E[0])
        gap = abs(_wrap(lever - thp2))
        if best is None or gap < best[0]:
            best = (gap, lever)
    return best[1] - th2


def xu_fk(q, d=None):
    """Hand pose of the paper's robot; q = (theta1, theta'2, theta2, theta4, theta5) rad, d the
    deviations in tolerance units (mm; 1e-2 rad for the angles)."""
    d = d or {}
    S = XU_SYM
    g = lambda k: float(d.get(k, 0.0)) * TOL_UNIT[XU_UNITS[k]]  # noqa: E731
    th1, thp2, th2, th4, th5 = q
    h2 = S["h2"] + g("h2")
    hp1 = S["hp1"] + g("h2")  # one part: dh'1 = dh2
    th3 = elbow_by_circles(th2, thp2, hp1, S["hp2"] + g("hp2"), S["hp3"] + g("hp3"), S["hp4"] + g("hp4"))
    T = Tz(S["s0"])
    T = T @ Tx(S["h0"]) @ Rx(S["alpha0"]) @ Tz(S["s1"] + g("s1")) @ Rz(th1 + S["o1"])
    T = T @ Tx(S["h1"]) @ Rx(S["alpha1"] + g("alpha1")) @ Tz(S["s2"]) @ Rz(th2)
    T = T @ Tx(h2) @ Rx(S["alpha2"]) @ Tz(S["s3"]) @ Rz(th3)
    T = T @ Tx(S["h3"] + g("h3")) @ Rx(S["alpha3"] + g("alpha3")) @ Tz(S["s4"]) @ Rz(th4)
    T = T @ Tx(S["h4"] + g("h4")) @ Rx(S["alpha4"] + g("alpha4")) @ Tz(S["a"] + g("a")) @ Rz(th5)
    return T


# ---------------------------------------------------------------------------------------------
# Puma 560, standard D-H, by hand
# ---------------------------------------------------------------------------------------------
_PUMA = _toml("puma560")
PUMA_SYM = {k: (math.radians(v) if k.startswith(("alpha", "o")) else float(v)) for k, v in _PUMA["symbols"].items()}


def puma_fk(q, d=None):
    """Puma 560, six standard D-H links Rz(q + o) Tz(d) Tx(a) Rx(alpha); d: mm and mrad."""
    d = d or {}
    S = PUMA_SYM
    L = lambda k: S[k] + float(d.get(k, 0.0))  # noqa: E731  (mm)
    A = lambda k: S[k] + 1e-3 * float(d.get(k, 0.0))  # noqa: E731  (mrad)
    q1, q2, q3, q4, q5, q6 = q
    T = Rz(q1 + A("o1")) @ Tz(L("d1")) @ Tx(L("a1")) @ Rx(A("alpha1"))
    T = T @ Rz(q2 + A("o2")) @ Tz(L("d2")) @ Tx(L("a2")) @ Rx(A("alpha2"))
    T = T @ Rz(q3 + A("o3")) @ Tz(L("d3")) @ Tx(L("a3")) @ Rx(A("alpha3"))
    T = T @ Rz(q4 + A("o4")) @ Tz(L("d4")) @ Tx(L("a4")) @ Rx(A("alpha4"))
    T = T @ Rz(q5 + A("o5")) @ Tz(L("d5")) @ Tx(L("a5")) @ Rx(A("alpha5"))
    T = T @ Rz(q6 + A("o6")) @ Tz(L("d6")) @ Tx(L("a6")) @ Rx(A("alpha6"))
    return T


# ---------------------------------------------------------------------------------------------
# planar 2R, closed form
# ---------------------------------------------------------------------------------------------
_P2R = _toml("planar_2r")


def planar_fk(q, d=None):
    """Planar 2R in closed form: l1 = 500, l2 = 300 mm, offsets in mrad."""
    d = d or {}
    l1 = _P2R["symbols"]["l1"] + float(d.get("l1", 0.0))
    l2 = _P2R["symbols"]["l2"] + float(d.get("l2", 0.0))
    a1 = q[0] + 1e-3 * float(d.get("o1", 0.0))
    a12 = a1 + q[1] + 1e-3 * float(d.get("o2", 0.0))
    T = np.eye(4)
    T[:2, :2] = [[math.cos(a12), -math.sin(a12)], [math.sin(a12), math.cos(a12)]]
    T[0, 3] = l1 * math.cos(a1) + l2 * math.cos(a12)
    T[1, 3] = l1 * math.sin(a1) + l2 * math.sin(a12)
    return T


NUMPY_FK = {"xu_zhang_1988": xu_fk, "puma560": puma_fk, "planar_2r": planar_fk}


# ---------------------------------------------------------------------------------------------
# random configurations inside the limits (and the interference limit), read from the files
# ---------------------------------------------------------------------------------------------
def random_q(name: str, rng, margin_deg: float = 2.0) -> np.ndarray:
    data = _toml(name)
    names = [j["name"] for j in data["joints"]]
    while True:
        q = np.array([rng.uniform(j["limits"][0] + margin_deg, j["limits"][1] - margin_deg) for j in data["joints"]])
        ok = True
        for c in data.get("joint_constraints", []):
            v = sum(coef * q[names.index(jn)] for jn, coef in c["terms"].items())
            ok &= c["limits"][0] + margin_deg <= v <= c["limits"][1] - margin_deg
        if ok:
            return np.radians(q)


def fd_sensitivity(fk, q, names, steps) -> np.ndarray:
    """Central differences of fk(q, {name: +-h}): position rows and the small rotation rows."""
    R0 = fk(q, None)[:3, :3]
    cols = []
    for name, h in zip(names, steps):
        Tp, Tm = fk(q, {name: h}), fk(q, {name: -h})
        dp = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
        dphi = vee((Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ R0.T)
        cols.append(np.concatenate([dp, dphi]))
    return np.column_stack(cols)


def fd_steps(mech) -> list[float]:
    """1e-3 mm for lengths, 1e-5 rad for angles, expressed in each tolerance unit."""
    return [1e-3 if p.unit == "mm" else 1e-5 / TOL_UNIT[p.unit] for p in mech.parameters]


def column_errors(S, S_ref):
    """Per column: |error| / |reference| of the position part and of the rotation part."""
    out = []
    for block, floor in ((slice(0, 3), 1e-9), (slice(3, 6), 1e-12)):
        err = np.linalg.norm(S[block] - S_ref[block], axis=0)
        scale = np.linalg.norm(S_ref[block], axis=0)
        out.append((err, scale, floor))
    return out


MODELS = ["xu_zhang_1988", "puma560", "planar_2r"]


@pytest.fixture(scope="module")
def mechs():
    return {name: tolsynth.load_model(name) for name in MODELS}


# ---------------------------------------------------------------------------------------------
# the hand-written chains read the files the way the tests assume
# ---------------------------------------------------------------------------------------------
def test_model_files_declare_the_units_the_tests_assume(mechs):
    """mm and 1e-2 rad (xu_zhang_1988), mm and mrad (puma560, planar_2r); file angles in deg."""
    for name in MODELS:
        data = _toml(name)
        assert data["units"] == {"length": "mm", "angle": "deg"}
    xu = mechs["xu_zhang_1988"]
    assert list(xu.error_parameters) == XU_ORDER
    assert [p.unit for p in xu.parameters] == [XU_UNITS[n] for n in XU_ORDER]
    puma = mechs["puma560"]
    assert {p.name: p.unit for p in puma.parameters} == {
        f"{k}{i}": ("mm" if k in "ad" else "mrad") for i in range(1, 7) for k in ("a", "d", "alpha", "o")
    }
    assert {p.name: p.unit for p in mechs["planar_2r"].parameters} == {
        "l1": "mm",
        "l2": "mm",
        "o1": "mrad",
        "o2": "mrad",
    }


def test_numpy_parallelogram_is_a_parallelogram():
    """Sanity of the reference itself: with nominal dimensions the lever is parallel to the crank."""
    rng = np.random.default_rng(1)
    for _ in range(20):
        q = random_q("xu_zhang_1988", rng)
        th3 = elbow_by_circles(q[2], q[1], 600.0, 280.0, 600.0, 280.0)
        assert abs(_wrap(th3 - (q[1] - q[2]))) < 1e-12


def test_xu_worst_pose_by_numpy():
    """The NumPy chain alone puts the 'worst' pose at (925, 0, 1225) mm with the roll axis up."""
    cfg = _XU["configurations"]["worst"]
    q = np.radians([cfg[j["name"]] for j in _XU["joints"]])
    T = xu_fk(q)
    assert np.allclose(T[:3, 3], [925.0, 0.0, 1225.0], atol=1e-6)
    assert np.allclose(T[:3, 2], [0.0, 0.0, 1.0], atol=1e-9)


def test_puma_zero_pose_by_hand():
    """qz of the Puma 560: hand at (a2 + a3, -d3, d1 + d4) = (452.1, -150.05, 1103.63) mm,
    with d1 = 26.45 inch = 671.83 mm (Robotics Toolbox Puma560.py)."""
    T = puma_fk(np.zeros(6))
    assert np.allclose(T[:3, 3], [452.1, -150.05, 26.45 * 25.4 + 431.8], atol=1e-9)


# ---------------------------------------------------------------------------------------------
# CasADi forward kinematics vs NumPy
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", MODELS)
def test_fk_matches_numpy(mechs, name):
    m = mechs[name]
    fk_np = NUMPY_FK[name]
    rng = np.random.default_rng(7)
    worst_pos = worst_rot = 0.0
    for trial in range(12):
        q = random_q(name, rng)
        # nominal, then random errors of up to one tolerance unit (1 mm; 0.01 rad or 1 mrad)
        d = None if trial % 4 == 0 else {n: rng.uniform(-1.0, 1.0) for n in m.error_parameters}
        T = m.fk(q, deltas=d)
        T_ref = fk_np(q, d)
        worst_pos = max(worst_pos, np.max(np.abs(T[:3, 3] - T_ref[:3, 3])))
        worst_rot = max(worst_rot, np.max(np.abs(T[:3, :3] - T_ref[:3, :3])))
        assert np.array_equal(T[3], [0, 0, 0, 1])
    assert worst_pos < 1e-9, f"{name}: position differs by {worst_pos:.3e} mm"
    assert worst_rot < 1e-12, f"{name}: rotation differs by {worst_rot:.3e}"


@pytest.mark.parametrize("name", MODELS)
def test_fk_named_configurations_match_numpy(mechs, name):
    m = mechs[name]
    data = _toml(name)
    for cname, cfg in data["configurations"].items():
        q = np.radians([cfg[j["name"]] for j in data["joints"]])
        assert np.allclose(m.configurations[cname], q, rtol=0, atol=1e-15)
        assert np.max(np.abs(m.fk(cname) - NUMPY_FK[name](q))) < 1e-9


def test_xu_aliases_perturb_the_same_parameters(mechs):
    """x1..x11 are the paper's names: x1 moves h2 and h'1 together, x9 is alpha1 in 1e-2 rad."""
    m = mechs["xu_zhang_1988"]
    q = m.configurations["worst"]
    for i, name in enumerate(XU_ORDER):
        T = m.fk(q, deltas={f"x{i + 1}": 0.3})
        assert np.max(np.abs(T - xu_fk(q, {name: 0.3}))) < 1e-9


# ---------------------------------------------------------------------------------------------
# exact sensitivities vs central differences
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", MODELS)
def test_sensitivity_matches_central_differences_of_fk(mechs, name):
    m = mechs[name]
    rng = np.random.default_rng(11)
    steps = fd_steps(m)
    worst = 0.0
    configs = [random_q(name, rng) for _ in range(5)] + [m.configurations[c] for c in m.configurations]
    for q in configs:
        S = m.sensitivity(q)
        assert S.shape == (6, m.n)
        S_fd = fd_sensitivity(lambda qq, d: m.fk(qq, deltas=d), q, m.error_parameters, steps)
        for err, scale, floor in column_errors(S, S_fd):
            assert np.all(err <= 1e-6 * scale + floor), (name, np.degrees(q), err, scale)
            nz = scale > 0
            worst = max(worst, float(np.max(err[nz] / scale[nz], initial=0.0)))
    print(f"{name}: max column-wise relative FD error {worst:.2e}")


@pytest.mark.parametrize("name", MODELS)
def test_sensitivity_matches_central_differences_of_numpy_fk(mechs, name):
    """The same against the hand-written chains (no package code in the reference at all)."""
    m = mechs[name]
    rng = np.random.default_rng(12)
    for q in [random_q(name, rng) for _ in range(2)]:
        S = m.sensitivity(q)
        S_fd = fd_sensitivity(NUMPY_FK[name], q, m.error_parameters, fd_steps(m))
        for err, scale, floor in column_errors(S, S_fd):
            assert np.all(err <= 1e-6 * scale + floor), (name, err, scale)


def test_sensitivity_at_perturbed_parameters(mechs):
    """The graph is exact away from the nominal point too (loop no longer a parallelogram)."""
    m = mechs["xu_zhang_1988"]
    rng = np.random.default_rng(13)
    q = random_q("xu_zhang_1988", rng)
    d0 = {n: rng.uniform(-2, 2) for n in m.error_parameters}
    S = m.sensitivity(q, deltas=d0)

    def fk(qq, d):
        dd = dict(d0)
        for k, v in (d or {}).items():
            dd[k] += v
        return xu_fk(qq, dd)

    S_fd = fd_sensitivity(fk, q, m.error_parameters, fd_steps(m))
    for err, scale, floor in column_errors(S, S_fd):
        assert np.all(err <= 1e-6 * scale + floor)


def test_parallelogram_first_order_forearm_rotation(mechs):
    """First-order forearm rotation of the perturbed parallelogram (the loop dimensions only move
    the passive elbow, so their rotation columns lie along the shoulder axis z2).

    docs/reconstruction.md prints dtheta = [-dh'1 + dh'3 + (dh'2 - dh'4) cos g] / (h'2 sin g); with the
    angles counter-clockwise about z2 (the D-H sense, and the sense of the circle-intersection
    reference above) the same expression carries the opposite overall sign:
    dtheta = [dh'1 - dh'3 - (dh'2 - dh'4) cos g] / (h'2 sin g).  Only the sign convention differs."""
    m = mechs["xu_zhang_1988"]
    rng = np.random.default_rng(14)
    for _ in range(5):
        q = random_q("xu_zhang_1988", rng)
        gamma = q[1] - q[2]
        S = m.sensitivity(q)
        axis = (Tz(200.0) @ Rz(q[0] + math.pi) @ Rx(math.pi / 2) @ Rz(q[2]))[:3, 2]  # z2 in the base frame
        k = 1.0 / (280.0 * math.sin(gamma))
        expect = {"h2": k, "hp3": -k, "hp2": -k * math.cos(gamma), "hp4": k * math.cos(gamma)}
        for name, value in expect.items():
            col = S[3:, m.error_parameters.index(name)]
            assert abs(col @ axis - value) < 1e-9 * abs(value) + 1e-15
            assert np.linalg.norm(col - (col @ axis) * axis) < 1e-15
