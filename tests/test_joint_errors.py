"""Joint errors: servo errors and revolute-joint clearances as error parameters.

Independent references:

* a plain-NumPy forward kinematics with the joint errors written in by hand (the paper's robot
  with its parallelogram solved as a circle-circle intersection, and the Puma 560), which must
  agree with the CasADi graph at random poses and random errors;
* central differences of that NumPy kinematics for every joint-error column of the sensitivity;
* closed forms: a servo error of the base joint moves the hand by ``z x p`` per radian; a servo
  error of the Puma's joint 1 is the same column as its joint-offset error ``o1``;
* the nonlinear Monte Carlo: with only a fixed servo error on joint 1 the sampled position spread
  is the closed-form ``|z x p| eps / sqrt 3``; at a synthesis optimum with fixed joint errors the
  sampled principal spreads match the linear prediction built from the NumPy differences.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import tolsynth
from test_joint_units_display import SLIDE  # the one-slide URDF of the units tests
from test_kinematics import (
    PUMA_SYM,
    TOL_UNIT,
    XU_SYM,
    XU_UNITS,
    Rx,
    Rz,
    Tx,
    Tz,
    elbow_by_circles,
    fd_sensitivity,
    random_q,
)
from tolsynth import JointError
from tolsynth.errors import InfeasibleSpecificationError, InputError, ModelFileError, UnknownNameError

UNIT = {**TOL_UNIT, "um": 1e-3}


def Ty(b):
    T = np.eye(4)
    T[1, 3] = b
    return T


def Ry(t):
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def clearance(d: dict, joint: str, length_unit: float) -> np.ndarray:
    """Tx Ty Tz Rx Ry of a clearance at ``joint`` (translations in length_unit, tilts in mrad)."""
    g = lambda s: float(d.get(f"{joint}.{s}", 0.0))  # noqa: E731
    return (
        Tx(g("radial_x") * length_unit)
        @ Ty(g("radial_y") * length_unit)
        @ Tz(g("axial") * length_unit)
        @ Rx(g("tilt_x") * 1e-3)
        @ Ry(g("tilt_y") * 1e-3)
    )


def xu_fk_joints(q, d=None, servo_unit=1e-3, length_unit=1.0):
    """The paper's robot by hand, with servo errors (servo_unit rad per tolerance unit) on every
    actuated joint and clearances at every chain joint, in the bearing frame before Rz(theta)."""
    d = d or {}
    S = XU_SYM
    g = lambda k: float(d.get(k, 0.0)) * UNIT[XU_UNITS[k]]  # noqa: E731
    sv = lambda j: float(d.get(f"{j}.servo", 0.0)) * servo_unit  # noqa: E731
    th1, thp2, th2, th4, th5 = (
        q[0] + sv("theta1"),
        q[1] + sv("thetap2"),
        q[2] + sv("theta2"),
        q[3] + sv("theta4"),
        q[4] + sv("theta5"),
    )
    h2 = S["h2"] + g("h2")
    hp1 = S["hp1"] + g("h2")
    th3 = elbow_by_circles(th2, thp2, hp1, S["hp2"] + g("hp2"), S["hp3"] + g("hp3"), S["hp4"] + g("hp4"))
    C = lambda j: clearance(d, j, length_unit)  # noqa: E731
    T = Tz(S["s0"])
    T = T @ Tx(S["h0"]) @ Rx(S["alpha0"]) @ Tz(S["s1"] + g("s1")) @ C("theta1") @ Rz(th1 + S["o1"])
    T = T @ Tx(S["h1"]) @ Rx(S["alpha1"] + g("alpha1")) @ Tz(S["s2"]) @ C("theta2") @ Rz(th2)
    T = T @ Tx(h2) @ Rx(S["alpha2"]) @ Tz(S["s3"]) @ C("theta3") @ Rz(th3)
    T = T @ Tx(S["h3"] + g("h3")) @ Rx(S["alpha3"] + g("alpha3")) @ Tz(S["s4"]) @ C("theta4") @ Rz(th4)
    T = T @ Tx(S["h4"] + g("h4")) @ Rx(S["alpha4"] + g("alpha4")) @ Tz(S["a"] + g("a")) @ C("theta5") @ Rz(th5)
    return T


def puma_fk_joints(q, d=None, servo_unit=1e-3, length_unit=1.0):
    """Puma 560 by hand (standard D-H), servo errors and clearances before each Rz(q + o)."""
    d = d or {}
    S = PUMA_SYM
    L = lambda k: S[k] + float(d.get(k, 0.0))  # noqa: E731
    A = lambda k: S[k] + 1e-3 * float(d.get(k, 0.0))  # noqa: E731
    T = np.eye(4)
    for i in range(1, 7):
        j = f"q{i}"
        qi = q[i - 1] + float(d.get(f"{j}.servo", 0.0)) * servo_unit
        T = (
            T
            @ clearance(d, j, length_unit)
            @ Rz(qi + A(f"o{i}"))
            @ Tz(L(f"d{i}"))
            @ Tx(L(f"a{i}"))
            @ Rx(A(f"alpha{i}"))
        )
    return T


XU_JOINTS = ["theta1", "thetap2", "theta2", "theta4", "theta5"]
XU_CHAIN = ["theta1", "theta2", "theta3", "theta4", "theta5"]
PUMA_JOINTS = [f"q{i}" for i in range(1, 7)]


def _every_joint_error(actuated, chain, value=0.02, clear=0.01):
    """A fixed servo error on every actuated joint and a full clearance at every chain joint."""
    out = [JointError(j, "servo", value=value) for j in actuated]
    out += [JointError(j, "clearance", value=clear, axial=clear / 2, length=50.0) for j in chain]
    return out


CASES = {
    "xu_zhang_1988": (xu_fk_joints, XU_JOINTS, XU_CHAIN),
    "puma560": (puma_fk_joints, PUMA_JOINTS, PUMA_JOINTS),
}


@pytest.fixture(scope="module")
def with_joints():
    out = {}
    for name, (_, act, chain) in CASES.items():
        out[name] = tolsynth.load_model(name).with_joint_errors(_every_joint_error(act, chain))
    return out


@pytest.mark.parametrize("name", list(CASES))
def test_joint_errors_enter_the_graph_like_the_numpy_chain(name, with_joints):
    """CasADi fk with random link AND joint errors == the hand-written NumPy chain (1e-9 mm)."""
    fk, _, _ = CASES[name]
    m = with_joints[name]
    assert len(m.joint_error_parameters) == len(CASES[name][1]) + 5 * len(CASES[name][2])
    rng = np.random.default_rng(11)
    for _ in range(8):
        q = random_q(name, rng)
        d = {n: rng.uniform(-3, 3) for n in m.error_parameters}  # tolerance units (mm, mrad, 1e-2 rad)
        T = m.fk(q, d, check_limits=False)
        T_ref = fk(q, d)
        assert np.max(np.abs(T[:3, 3] - T_ref[:3, 3])) < 1e-9
        assert np.max(np.abs(T[:3, :3] - T_ref[:3, :3])) < 1e-12


@pytest.mark.parametrize("name", list(CASES))
def test_joint_error_sensitivities_match_central_differences(name, with_joints):
    """Every joint-error column of the algorithmic sensitivity == central differences of the
    NumPy chain (step 1e-3 tolerance units: 1 um, 1 urad), to 1e-6 relative."""
    fk, _, _ = CASES[name]
    m = with_joints[name]
    names = list(m.joint_error_parameters)
    cols = [m.index(n) for n in names]
    rng = np.random.default_rng(5)
    for _ in range(4):
        q = random_q(name, rng)
        S = m.sensitivity(q, check_limits=False)[:, cols]
        S_fd = fd_sensitivity(fk, q, names, [1e-3] * len(names))
        for rows in (slice(0, 3), slice(3, 6)):
            err = np.linalg.norm(S[rows] - S_fd[rows], axis=0)
            scale = np.maximum(np.linalg.norm(S_fd[rows], axis=0), 1e-6)
            assert np.all(err / scale < 1e-6), (rows, dict(zip(names, err / scale)))


def test_servo_of_the_base_joint_is_z_cross_p():
    """Closed form: a servo error d(theta1) turns the whole arm about the base z axis, so the hand
    moves by z x p per rad and turns by z; the Puma's servo on q1 is its offset o1's column."""
    m = tolsynth.load_model("xu_zhang_1988").with_joint_errors([JointError("theta1", "servo", value=0.1, unit="urad")])
    rng = np.random.default_rng(2)
    for _ in range(5):
        q = random_q("xu_zhang_1988", rng)
        p = m.fk(q, check_limits=False)[:3, 3]
        col = m.sensitivity(q, check_limits=False)[:, m.index("theta1.servo")] / 1e-6  # per rad
        np.testing.assert_allclose(col[:3], [-p[1], p[0], 0.0], atol=1e-9)
        np.testing.assert_allclose(col[3:], [0.0, 0.0, 1.0], atol=1e-12)
    puma = tolsynth.load_model("puma560").with_joint_errors([JointError("q1", "servo", bounds=(0.001, 50.0))])
    for cfg in ("qz", "qn", "qr"):
        S = puma.sensitivity(cfg)
        np.testing.assert_allclose(S[:, puma.index("q1.servo")], S[:, puma.index("o1")], atol=1e-12)


def test_servo_of_a_loop_joint_moves_the_loop():
    """The paper's theta'2 drives the parallelogram only: its servo error turns the forearm like
    the crank (nominal parallelogram: d theta3 = d theta'2), checked against the NumPy chain."""
    m = tolsynth.load_model("xu_zhang_1988").with_joint_errors([JointError("thetap2", "servo", value=0.3)])
    q = m.configurations["worst"]
    S = m.sensitivity("worst")[:, -1]
    S_fd = fd_sensitivity(xu_fk_joints, q, ["thetap2.servo"], [1e-3])[:, 0]
    np.testing.assert_allclose(S, S_fd, rtol=1e-7, atol=1e-12)
    assert np.linalg.norm(S[:3]) > 0.5  # mm per mrad: the forearm (800 mm) turns


def test_monte_carlo_spread_of_a_servo_error_alone():
    """Only a fixed servo error (uniform +-0.2 mrad) on joint 1: the nonlinear Monte Carlo's
    sampled spread is |z x p| eps / sqrt(3) along y and ~0 elsewhere (closed form); a normal one
    (3 sigma = 0.2 mrad) gives |z x p| eps / 3."""
    m = tolsynth.load_model("xu_zhang_1988").with_joint_errors([JointError("theta1", "servo", value=0.2)])
    eps = np.zeros(m.n)
    eps[m.index("theta1.servo")] = 0.2
    mc = tolsynth.monte_carlo(m, "worst", eps, R=0.1, n=200_000, seed=3)
    p = m.fk("worst")[:3, 3]
    sd = math.hypot(p[0], p[1]) * 0.2e-3 / math.sqrt(3)  # mm
    sd_mc = np.sqrt(np.diag(mc.covariance))
    assert abs(sd_mc[1] / sd - 1) < 4 * (1 / math.sqrt(2 * 200_000)) * 1.5  # sampling error of an sd
    assert sd_mc[0] < 1e-3 * sd and sd_mc[2] < 1e-12
    # P(|dy| <= R) for dy uniform on +-a: R/a exactly
    a = math.hypot(p[0], p[1]) * 0.2e-3
    i = int(np.argmax(np.abs(mc.principal_directions[1])))
    lo, hi = mc.p_components_ci[i]
    assert lo <= 0.1 / a <= hi
    # a normal servo error (3 sigma = 0.2 mrad): sd |z x p| eps / 3, P(|dy| <= R) = erf(R / (sd sqrt 2))
    mc = tolsynth.monte_carlo(m, "worst", eps, R=0.1, n=200_000, seed=4, distribution="normal")
    sd = math.hypot(p[0], p[1]) * 0.2e-3 / 3
    assert abs(np.sqrt(mc.covariance[1, 1]) / sd - 1) < 4 / math.sqrt(2 * 200_000)
    i = int(np.argmax(np.abs(mc.principal_directions[1])))
    lo, hi = mc.p_components_ci[i]
    assert lo <= math.erf(0.1 / (sd * math.sqrt(2))) <= hi


def test_synthesis_with_fixed_joint_errors_is_checked_by_monte_carlo():
    """The paper's Table 1 specification (R = 0.5 mm, p = 0.99, uniform, alpha 0.7) with a fixed
    encoder quantisation (q = 0.2 mrad: +-0.1 mrad) on every actuated joint and a clearance of
    5 um at the elbow: the link tolerances tighten (their cost rises), the specification is met,
    and the Monte Carlo's principal spreads are the linear prediction from the NumPy chain."""
    base = tolsynth.load_model("xu_zhang_1988")
    errs = [JointError(j, "servo", value=0.1) for j in XU_JOINTS]
    errs.append(JointError("theta3", "clearance", value=0.005, unit="mm", length=60.0))
    m = base.with_joint_errors(errs)
    r0 = tolsynth.synthesize(base, R=0.5, p=0.99, probability="gaussian")
    r = tolsynth.synthesize(m, R=0.5, p=0.99, validate=60_000, seed=1, probability="gaussian")
    assert r.success and r.gap < 1e-5 * r.cost
    for n in m.joint_error_parameters:  # locked at their values
        assert r.tolerances[n] == pytest.approx(m.fixed_joint_errors[n], rel=1e-12)
    assert r.cost > r0.cost * 1.01  # the fixed errors cost nothing: this is the links' cost
    eps_links = [r.tolerances[n] for n in base.error_parameters]
    assert r.cost == pytest.approx(sum(base.k[i] * e**-0.7 for i, e in enumerate(eps_links)), rel=1e-12)
    # the linear prediction from central differences of the NumPy chain
    q = m.configurations["worst"]
    names = list(m.error_parameters)
    steps = [1e-3] * len(names)
    S = fd_sensitivity(xu_fk_joints, q, names, steps)[:3]
    eps = np.array([r.tolerances[n] for n in names])
    V = S @ np.diag(eps**2 / 3) @ S.T
    sig = np.sqrt(np.sort(np.linalg.eigvalsh(V))[::-1])
    z = tolsynth.z_of_p(0.99)
    assert np.max(sig * z / 0.5) == pytest.approx(1.0, abs=1e-5)  # the binding component, independently
    mc = r.validation.montecarlo
    np.testing.assert_allclose(mc.principal_std[:2], sig[:2], rtol=0.015)
    assert np.all(r.validation.p_components_ci[:, 1] >= 0.985)  # near p = 0.99 (uniform vs Gaussian)


def test_fixed_joint_errors_alone_break_the_specification():
    """A coarse encoder (+-1 mrad on theta1 at 925 mm: |dy| up to 0.93 mm) cannot meet R = 0.5 mm
    at p = 0.99 whatever the links: InfeasibleSpecificationError naming the fixed joint error."""
    m = tolsynth.load_model("xu_zhang_1988").with_joint_errors([JointError("theta1", "servo", value=1.0)])
    with pytest.raises(InfeasibleSpecificationError, match=r"fixed joint errors \['theta1.servo'\]"):
        tolsynth.synthesize(m, R=0.5, p=0.99, probability="gaussian")
    # with a user lock as well, both are named and the joint error stays locked
    with pytest.raises(InfeasibleSpecificationError, match=r"theta1.servo.*fixed joint errors"):
        tolsynth.synthesize(m, R=0.5, p=0.99, locks={"h3": 0.05}, probability="gaussian")


def test_user_locks_and_costs_keep_the_fixed_joint_errors_fixed_and_free():
    """locks= and cost= for the links leave the fixed joint errors locked and at no cost: the
    reported cost is the links' own (k eps^-alpha summed by hand, or the Chase model's)."""
    from tolsynth.model.cost import Chase

    base = tolsynth.load_model("xu_zhang_1988")
    m = base.with_joint_errors([JointError("theta2", "servo", value=0.05)])
    r = tolsynth.synthesize(m, R=0.5, p=0.99, locks={"h3": 0.1}, probability="gaussian")
    assert r.success
    assert r.tolerances["h3"] == pytest.approx(0.1, rel=1e-12)
    assert r.tolerances["theta2.servo"] == pytest.approx(0.05, rel=1e-12)
    eps = np.array([r.tolerances[n] for n in base.error_parameters])
    assert r.cost == pytest.approx(float(np.sum(base.k * eps**-0.7)), rel=1e-12)
    for cost in (Chase(1.0, 0.4, 1.0), [Chase(1.0, 0.4, 1.0)] * m.n, {"h3": Chase(1.0, 0.4, 1.0)}):
        r = tolsynth.synthesize(m, R=0.5, p=0.99, cost=cost, probability="gaussian")
        eps = np.array([r.tolerances[n] for n in base.error_parameters])
        if isinstance(cost, dict):
            i = base.index("h3")
            expect = sum(base.k[j] * e**-0.7 for j, e in enumerate(eps) if j != i) + 1.0 + 0.4 / eps[i]
        else:
            expect = float(np.sum(1.0 + 0.4 / eps))
        assert r.cost == pytest.approx(expect, rel=1e-10)
        assert r.gap <= 1e-6 * r.cost


def test_designable_servo_is_a_design_variable():
    """Puma 560 with a designable servo error on q1 with the same unit, k and bounds as o1: the
    two columns are equal at every pose, so the convex problem's optimum gives both the same
    tolerance (symmetry).  With k 10x smaller for the servo, the stationarity of
    ``k1 e1^-a + k2 e2^-a`` on ``e1^2 + e2^2 = const`` (the covariance sees only that sum) gives
    ``e1 / e2 = (k1 / k2)^(1 / (a + 2))`` (closed form; a = 0.7)."""
    puma = tolsynth.load_model("puma560")
    o1 = puma.parameters[puma.index("o1")]
    m = puma.with_joint_errors([JointError("q1", "servo", bounds=(o1.lower, o1.upper), unit="mrad", k=o1.k)])
    r = tolsynth.synthesize(m, R=0.5, p=0.95, pose="qn", probability="gaussian")
    assert r.success
    assert r.tolerances["q1.servo"] == pytest.approx(r.tolerances["o1"], rel=1e-5)
    cheap = puma.with_joint_errors([JointError("q1", "servo", bounds=(o1.lower, o1.upper), k=o1.k / 10)])
    r2 = tolsynth.synthesize(cheap, R=0.5, p=0.95, pose="qn", probability="gaussian")
    ratio = r2.tolerances["q1.servo"] / r2.tolerances["o1"]
    assert ratio == pytest.approx(0.1 ** (1 / 2.7), rel=1e-4)
    # a cost model for the joint error (Chase: A + B eps^-k)
    r3 = tolsynth.synthesize(
        puma.with_joint_errors(
            [JointError("q1", "servo", bounds=(0.001, 50.0), cost={"model": "chase", "A": 1.0, "B": 0.5, "k": 1.0})]
        ),
        R=0.5,
        p=0.95,
        pose="qn",
        probability="gaussian",
    )
    assert r3.success and r3.tolerances["q1.servo"] > 0


def test_designable_clearance_on_puma():
    """A designable radial clearance at the Puma's elbow (q3): two design variables x and y (the
    same bounds and cost); the specification is met and a Monte Carlo agrees."""
    m = tolsynth.load_model("puma560").with_joint_errors(
        [JointError("q3", "clearance", bounds=(0.001, 0.5), unit="mm", k=2.0)]
    )
    assert m.error_parameters[-2:] == ("q3.radial_x", "q3.radial_y")
    r = tolsynth.synthesize(m, R=0.5, p=0.95, pose="qn", validate=40_000, seed=2, probability="gaussian")
    assert r.success and r.max_constraint <= 1 + 1e-6
    assert 0.001 < r.tolerances["q3.radial_x"] < 0.5
    assert np.all(r.validation.p_components_ci[:, 1] >= 0.94)


def test_clearance_model_numbers():
    """Tilt 2c/L in mrad, axial play in the clearance's unit, components named per joint."""
    m = tolsynth.load_model("puma560").with_joint_errors(
        [JointError("q2", "clearance", value=10.0, unit="um", axial=4.0, length=40_000.0)]
    )
    assert m.fixed_joint_errors == pytest.approx(
        {
            "q2.radial_x": 10.0,
            "q2.radial_y": 10.0,
            "q2.axial": 4.0,
            "q2.tilt_x": 2 * 10.0 / 40_000.0 * 1e3,
            "q2.tilt_y": 2 * 10.0 / 40_000.0 * 1e3,
        }
    )
    assert [m.units[m.index(n)] for n in m.joint_error_parameters] == ["um", "um", "um", "mrad", "mrad"]


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(joint="theta3", kind="servo", value=0.1), "joint_errors[0].joint"),  # passive: no servo
        (dict(joint="nope", kind="clearance", value=0.1), "joint_errors[0].joint"),
        (dict(joint="theta1", kind="backlash", value=0.1), "joint_errors[0].kind"),
        (dict(joint="theta1", kind="servo", value=0.1, unit="mm"), "joint_errors[0].unit"),
        (dict(joint="theta1", kind="clearance", value=0.1, unit="mrad"), "joint_errors[0].unit"),
        (dict(joint="theta1", kind="servo"), "joint_errors[0]"),
        (dict(joint="theta1", kind="servo", value=0.1, bounds=(0.1, 1)), "joint_errors[0]"),
        (dict(joint="theta1", kind="servo", value=-0.1), "joint_errors[0].value"),
        (dict(joint="theta1", kind="servo", bounds=(1.0, 0.5)), "joint_errors[0].bounds.upper"),
        (dict(joint="theta1", kind="servo", value=0.1, length=5.0), "joint_errors[0].length"),
        (dict(joint="theta1", kind="clearance", bounds=(0.001, 0.1), axial=0.01), "joint_errors[0].axial"),
        (dict(joint="theta1", kind="clearance", value=0.1, length=1.0), "joint_errors[0].length"),
        (
            dict(joint="theta1", kind="servo", value=0.1, cost={"model": "chase", "A": 1, "B": 1, "k": 1}),
            "joint_errors[0].cost",
        ),
        (dict(joint="theta1", kind="servo", value=0.1, k=2.0), "joint_errors[0].k"),  # given, not bought
        (dict(joint="theta1", kind="servo", bounds=(0.1, 1.0), k=0.0), "joint_errors[0].k"),
    ],
)
def test_bad_joint_errors_name_the_field(kwargs, field):
    m = tolsynth.load_model("xu_zhang_1988")
    with pytest.raises(InputError) as info:
        m.with_joint_errors([JointError(**kwargs)])
    assert info.value.field == field


def test_a_joint_error_declared_twice():
    m = tolsynth.load_model("xu_zhang_1988")
    with pytest.raises(InputError, match="declared twice"):
        m.with_joint_errors([JointError("theta1", "servo", value=0.1), JointError("theta1", "servo", value=0.2)])
    with pytest.raises(InputError, match="list of tolsynth.JointError"):
        m.with_joint_errors(JointError("theta1", "servo", value=0.1))


# ---------------------------------------------------------------------------------------------
# model files
# ---------------------------------------------------------------------------------------------
JOINT_TABLES = """
[[joint_errors]]
joint = "theta1"
kind = "servo"
value = 0.1
unit = "mrad"
note = "encoder of 2^14 counts per motor turn behind a 100:1 gear: q = 2 pi / 1.6e6 rad ~ 0.004 mrad; +-0.1 mrad with the gear's lost motion"

[[joint_errors]]
joint = "theta3"
kind = "clearance"
value = 5.0
unit = "um"
axial = 2.0
length = 60000.0

[[joint_errors]]
joint = "theta2"
kind = "servo"
bounds = [0.001, 5.0]
cost = { model = "power", k = 1.0, alpha = 0.7 }
"""


def _xu_text():
    from test_kinematics import MODELS_DIR

    return (MODELS_DIR / "xu_zhang_1988.toml").read_text()


def test_model_file_joint_errors(tmp_path):
    path = tmp_path / "xu_joints.toml"
    path.write_text(_xu_text() + JOINT_TABLES)
    m = tolsynth.load_model(path)
    api = tolsynth.load_model("xu_zhang_1988").with_joint_errors(
        [
            JointError("theta1", "servo", value=0.1, unit="mrad"),
            JointError("theta3", "clearance", value=5.0, unit="um", axial=2.0, length=60000.0),
            JointError("theta2", "servo", bounds=(0.001, 5.0), cost={"model": "power", "k": 1.0, "alpha": 0.7}),
        ]
    )
    assert m.error_parameters == api.error_parameters
    assert m.fixed_joint_errors == api.fixed_joint_errors
    assert m.spec.reference_results == ()  # the paper's optima are for the links alone
    assert m.tolerance_sets == {}  # a designable joint error has no value for the sets
    np.testing.assert_array_equal(m.sensitivity("worst"), api.sensitivity("worst"))
    r = tolsynth.synthesize(m, R=0.5, p=0.99, probability="gaussian")
    assert r.success and r.tolerances["theta1.servo"] == pytest.approx(0.1)
    assert 0.001 < r.tolerances["theta2.servo"] < 5.0


def test_model_file_tolerance_sets_get_the_fixed_values(tmp_path):
    path = tmp_path / "xu_fixed.toml"
    path.write_text(_xu_text() + JOINT_TABLES.split('[[joint_errors]]\njoint = "theta2"')[0])
    m = tolsynth.load_model(path)
    eps = m.tolerances("figure3")
    assert eps[m.index("theta1.servo")] == 0.1 and eps[m.index("theta3.tilt_x")] == pytest.approx(2 * 5 / 60000 * 1e3)


@pytest.mark.parametrize(
    "table, field, text",
    [
        ('joint = "theta1"\nkind = "servo"\nvalu = 0.1', "joint_errors[0].valu", "did you mean `value`"),
        ('joint = "theta9"\nkind = "servo"\nvalue = 0.1', "joint_errors[0].joint", "not an actuated joint"),
        ('joint = "theta1"\nkind = "servo"\nvalue = -1', "joint_errors[0].value", "expected a finite number"),
        ('joint = "theta1"\nkind = "servo"\nvalue = 0.1\nunit = "furlong"', "joint_errors[0].unit", "unknown unit"),
        ('kind = "servo"\nvalue = 0.1', "joint_errors[0].joint", "missing required field"),
    ],
)
def test_model_file_bad_joint_errors(tmp_path, table, field, text):
    path = tmp_path / "bad.toml"
    path.write_text(_xu_text() + "\n[[joint_errors]]\n" + table + "\n")
    with pytest.raises(ModelFileError) as info:
        tolsynth.load_model(path)
    assert field in str(info.value) and text in str(info.value)


def test_unknown_joint_is_an_unknown_name():
    with pytest.raises(UnknownNameError):
        tolsynth.load_model("puma560").with_joint_errors([JointError("q7", "servo", value=0.1)])


def test_command_line_reads_joint_errors_from_the_file(tmp_path, capsys):
    """`tolsynth solve --model file` with [[joint_errors]]: the fixed errors are printed at their
    values, and `analyze` with the file's tolerance set includes them (its P per component is the
    one from the NumPy chain's differences)."""
    from tolsynth.cli import main
    from tolsynth.probability.stats import covariance, p_components, principal

    path = tmp_path / "xu_fixed.toml"
    path.write_text(_xu_text() + JOINT_TABLES.split('[[joint_errors]]\njoint = "theta2"')[0])
    assert main(["solve", "--model", str(path), "--R", "0.5", "--p", "0.99", "--json"]) == 0
    import json

    out = json.loads(capsys.readouterr().out)
    text = json.dumps(out)
    assert "theta1.servo" in text and "theta3.tilt_x" in text
    assert main(["analyze", "--model", str(path), "--tolerances", "figure3", "--R", "0.5", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    m = tolsynth.load_model(path)
    q = m.configurations["worst"]
    S = fd_sensitivity(xu_fk_joints_file, q, list(m.error_parameters), [1e-3] * m.n)
    sig, _ = principal(covariance(S, m.tolerances("figure3"), "uniform")[0])
    np.testing.assert_allclose(got["p_components"], p_components(sig, 0.5), atol=1e-7)


def xu_fk_joints_file(q, d=None):
    """The NumPy chain for the file above: clearance lengths in um."""
    return xu_fk_joints(q, d, length_unit=1e-3)


def test_with_units_converts_the_fixed_values():
    """A fixed servo error of 0.1 mrad is 100 urad after with_units; the optimum is the same."""
    m = tolsynth.load_model("xu_zhang_1988").with_joint_errors([JointError("theta1", "servo", value=0.1)])
    mu = m.with_units({"theta1.servo": "urad"})
    assert mu.fixed_joint_errors == pytest.approx({"theta1.servo": 100.0})
    assert mu.bounds[0][-1] == pytest.approx(100.0) and mu.units[-1] == "urad"
    r, ru = (tolsynth.synthesize(x, R=0.5, p=0.99, probability="gaussian") for x in (m, mu))
    assert ru.tolerances["theta1.servo"] == pytest.approx(100.0)
    assert ru.tolerances["h3"] == pytest.approx(r.tolerances["h3"], rel=1e-6)


def test_given_cost_model():
    """tolsynth.model.cost.Given: 0 everywhere, derivative 0, dual minimum w e^{2 lu} at lu (the
    closed form of min over [lu, uu] of 0 + w e^{2u}), round trip through its dict."""
    from tolsynth.model.cost import Given, cost_model
    from tolsynth.model.cost_set import cost_set

    g = Given()
    assert np.all(g.cost(np.array([1e-6, 1.0, 1e6])) == 0.0) and np.all(g.du(np.array([-3.0, 2.0])) == 0.0)
    w = np.array([0.0, 0.5, 7.0])
    val, u = g.dual_min(w, math.log(0.2), math.log(3.0))
    np.testing.assert_allclose(val, w * 0.04, rtol=1e-15)
    np.testing.assert_allclose(u, math.log(0.2))
    assert cost_model(g.to_dict()) == g
    cs = cost_set([g, cost_model({"model": "power", "k": 2.0, "alpha": 0.5})], ["a", "b"])
    u0 = np.log([0.3, 0.25])
    assert float(cs.expr(u0)) == pytest.approx(2.0 * 0.25**-0.5, rel=1e-15)


def test_sumt_solves_with_fixed_joint_errors_and_locks():
    """The paper's SUMT + Powell with locked tolerances (fixed joint errors, a user lock): the same
    optimum as IPOPT (cost 1e-7, tolerances 1e-4), the locked values exact, and the locked
    parameters' multipliers those of IPOPT (1e-3)."""
    m = tolsynth.load_model("xu_zhang_1988").with_joint_errors(
        [JointError(j, "servo", value=0.15) for j in XU_JOINTS]
        + [JointError("theta2", "clearance", bounds=(0.0005, 0.1))]
    )
    c = tolsynth.compare(m, R=0.5, p=0.99, locks={"h3": 0.2})
    i, s = c.ipopt, c.sumt
    assert i.success and s.success
    assert c.cost_rel_diff < 1e-7
    assert max(c.tolerance_rel_diff.values()) < 1e-4
    for n in list(m.joint_error_parameters[:5]) + ["h3"]:
        assert s.tolerances[n] == i.tolerances[n]  # exactly the locked value
        assert s.bound_multipliers[n] == pytest.approx(i.bound_multipliers[n], rel=1e-3, abs=1e-6)


def test_summary_marks_fixed_tolerances():
    m = tolsynth.load_model("xu_zhang_1988").with_joint_errors([JointError("theta1", "servo", value=0.1)])
    text = tolsynth.synthesize(m, R=0.5, p=0.99, locks={"h3": 0.2}, probability="gaussian").summary()
    assert "theta1.servo = 0.1 mrad  [fixed]" in text and "h3 = 0.2 mm  [fixed]" in text


def test_result_tables_record_the_joint_errors(tmp_path):
    pytest.importorskip("pandas")
    m = tolsynth.load_model("xu_zhang_1988").with_joint_errors(
        [JointError("theta1", "servo", value=0.1), JointError("theta2", "clearance", bounds=(0.001, 0.1))]
    )
    r = tolsynth.synthesize(m, R=0.5, p=0.99, probability="gaussian")
    r.to_json(tmp_path / "r.json")
    inputs = tolsynth.read_table(tmp_path / "r.json").attrs["inputs"]
    assert inputs["joint_errors"]["theta1.servo"] == {"joint": "theta1", "transform": "q", "unit": "mrad", "fixed": 0.1}
    assert inputs["joint_errors"]["theta2.radial_y"] == {
        "joint": "theta2",
        "transform": "Ty",
        "unit": "mm",
        "fixed": None,
    }
    assert tolsynth.synthesize("xu_zhang_1988", R=0.5, p=0.99, probability="gaussian").inputs["joint_errors"] is None


def test_a_cost_for_a_fixed_joint_error_is_refused():
    m = tolsynth.load_model("xu_zhang_1988").with_joint_errors([JointError("theta1", "servo", value=0.1)])
    with pytest.raises(InputError) as info:
        tolsynth.synthesize(
            m, R=0.5, p=0.99, cost={"theta1.servo": {"model": "power", "k": 1.0, "alpha": 0.7}}, probability="gaussian"
        )
    assert info.value.field == "cost[theta1.servo]"


def test_servo_error_of_a_slide_is_a_length(tmp_path):
    """A URDF prismatic joint moves the hand by its value along x (closed form x = 400 + q2 mm at
    q1 = 0): its servo error is a length in mm with sensitivity (1, 0, 0) mm per mm; an angle unit
    for it is refused, and so is a clearance (a revolute joint's model)."""
    from tolsynth.errors import OutOfRangeError, UnknownNameError

    path = tmp_path / "slide.urdf"
    path.write_text(SLIDE)
    m = tolsynth.load_urdf(path, "base", "tip")
    m2 = m.with_joint_errors([tolsynth.JointError("j2", "servo", value=0.01)])
    assert m2.units[-1] == "mm"
    np.testing.assert_allclose(m2.sensitivity(np.array([0.0, 50.0]))[:3, -1], [1.0, 0.0, 0.0], atol=1e-12)
    with pytest.raises(OutOfRangeError, match="not a unit of length"):
        m.with_joint_errors([tolsynth.JointError("j2", "servo", value=0.01, unit="mrad")])
    with pytest.raises(UnknownNameError, match=r"it slides \(a prismatic joint\).*allowed: one of j1\)"):
        m.with_joint_errors([tolsynth.JointError("j2", "clearance", value=0.01)])


@pytest.mark.parametrize(
    "model, joint, allowed",
    [
        ("stewart_gough", "q1", "no joint error (each strut's length error is its leg's offset parameter)"),
        ("delta", "theta1", "kind 'servo' on a revolute actuator"),
    ],
)
def test_clearance_on_a_parallel_robot_says_why_no_joint_qualifies(model, joint, allowed):
    from tolsynth.errors import UnknownNameError

    m = tolsynth.load_model(model)
    with pytest.raises(UnknownNameError) as err:
        m.with_joint_errors([tolsynth.JointError(joint, "clearance", value=0.01)])
    text = str(err.value)
    assert "legs end in ball joints" in text and f"(allowed: {allowed})" in text and "one of )" not in text
