"""Parallel robots' model files read strictly, and the package's tools on parallel robots.

Each defect of a ``[[leg]]`` file is a ModelFileError naming its field.  The tools (synthesis with
its three criteria, the workspace exchange, the map, contributions, joint errors) are checked
against numbers computed here independently: the principal standard deviations from the
sensitivity matrix by NumPy, brute force over the actuator box, the closed-form IK of the map
against the forward kinematics.
"""

from __future__ import annotations

import numpy as np
import pytest

import tolsynth
from model_text import assert_defect_named
from model_text import drop_at as _drop
from model_text import set_at as _set
from tolsynth.errors import InputError, OutOfRangeError
from tolsynth.probability.stats import z_of_p


def _far_strut(d):
    """One strut far longer than the others can follow: a configuration that does not assemble."""
    for leg in d["leg"]:
        leg["limits"] = [600.0, 2000.0]
    d["configurations"]["far"] = {"q1": 1990.0, "q2": 700.0, "q3": 700.0, "q4": 700.0, "q5": 700.0, "q6": 700.0}


CASES = [
    ("delta", _set(["leg", 0, "lenght"], 1.0), "leg[0].lenght", "unknown key"),
    ("delta", _set(["leg", 1, "actuation"], "revolut"), "leg[1].actuation", "did you mean"),
    ("stewart_gough", _set(["leg", 0, "arm"], 100.0), "leg[0].arm", "only a revolute leg"),
    ("delta", _drop(["leg", 2, "link"]), "leg[2].link", "missing required field"),
    ("delta", _set(["leg", 0, "zero"], [1.0, 1.0, 0.0]), "leg[0].zero", "not perpendicular"),
    ("delta", _set(["leg", 0, "axis"], [0.0, 0.0, 0.0]), "leg[0].axis", "zero vector"),
    ("delta", _set(["leg", 0, "arm"], -524.0), "leg[0].arm", "finite number"),
    ("delta", _set(["leg", 0, "base"], [0.0, -164.0]), "leg[0].base", "expected [x, y, z]"),
    ("delta", _set(["leg", 1, "name"], "A1"), "leg", "leg name ['A1'] declared more than once"),
    ("delta", _set(["leg", 1, "name"], "A.1"), "leg[1].name", "letters, digits"),
    ("delta", _set(["platform", "dof"], ["x", "y", "z", "rz"]), "platform.dof", "as many as legs"),
    ("delta", _set(["platform", "dof"], ["x", "y", "zz"]), "platform.dof[2]", "unknown pose coordinate"),
    ("delta", _set(["platform", "assembly"], {"rz": 0.0}), "platform.assembly.rz", "not a pose coordinate"),
    ("stewart_gough", _set(["platform", "assembly"], {"z": 0.0}), "platform.assembly", "does not assemble"),
    ("delta", _drop(["configurations", "home"]), "configurations.home", "missing"),
    (
        "delta",
        _set(["configurations", "home", "theta1"], 95.0),
        "configurations.home.theta1",
        "outside the joint limits",
    ),
    ("stewart_gough", lambda d: _far_strut(d), "configurations.far", "cannot be assembled"),
    ("delta", _set(["errors", "select"], ["*.bx", "*.arms"]), "errors.select[1]", "selects no leg dimension"),
    ("delta", _set(["errors", "k"], {"lenght": 1.0}), "errors.k[lenght]", "did you mean"),
    ("delta", _set(["errors", "selekt"], ["*"]), "errors.selekt", "unknown key"),
    ("delta", _set(["tolerance_sets", "coarse", "*.anchor"], 0.1), "tolerance_sets.coarse.*.anchor", "selects no"),
    ("delta", _set(["tolerance_sets", "coarse", "A1.bx"], 0.1), "tolerance_sets.coarse.A1.bx", "already given"),
    ("delta", _drop(["tolerance_sets", "coarse", "*.link"]), "tolerance_sets.coarse", "missing tolerance"),
    ("delta", _set(["chain"], {}), "chain", "unknown key"),
]


@pytest.mark.parametrize("model, edit, field, fragment", CASES, ids=[c[2] for c in CASES])
def test_defect_names_field(tmp_path, model, edit, field, fragment):
    assert_defect_named(tmp_path, model, edit, field, fragment)


def test_error_selection_and_tolerance_patterns():
    """[errors] selects by pattern and group; a tolerance set's pattern keys reach every match."""
    m = tolsynth.load_model("planar_3rrr")
    assert m.n == 21 and not any(n.endswith(("bz", "pz")) for n in m.error_parameters)
    eps = dict(zip(m.error_parameters, m.tolerances("coarse")))
    assert eps["R2.py"] == 0.02 and eps["R3.offset"] == 0.2 and m.units[m.index("R3.offset")] == "mrad"
    h = tolsynth.load_model("stewart_gough")
    assert h.n == 42 and h.units == ("mm",) * 42


def _sigma(m, q, eps, c=3.0):
    """Largest principal standard deviation (mm) from the sensitivity matrix, by NumPy."""
    S = m.sensitivity(q)[:3]
    return float(np.sqrt(np.linalg.eigvalsh(S @ np.diag(eps**2 / c) @ S.T).max()))


@pytest.mark.parametrize("name", ["stewart_gough", "delta", "planar_3rrr"])
def test_synthesis_meets_the_specification(name):
    """Components: every principal sigma z / R <= 1 at the optimum (NumPy eigenvalues), certified."""
    m = tolsynth.load_model(name)
    res = tolsynth.synthesize(m, R=0.1, p=0.99, pose="home", probability="gaussian")
    assert res.success and res.gap <= 1e-6 * res.cost
    assert _sigma(m, "home", res.x) * z_of_p(0.99) / 0.1 <= 1 + 1e-6


def test_orientation_constraint_binds_on_the_hexapod():
    """A tight Phi makes the platform's rotation the active constraint and raises the cost; the
    rotation's principal sigma then meets Phi (NumPy, rows 3-5 of the sensitivity)."""
    m = tolsynth.load_model("stewart_gough")
    free = tolsynth.synthesize(m, R=0.1, p=0.99, pose="home", probability="gaussian")
    tight = tolsynth.synthesize(m, R=0.1, p=0.99, pose="home", Phi=3e-4, probability="gaussian")
    assert tight.success and tight.cost > 1.01 * free.cost
    So = m.sensitivity("home")[3:]
    sig_o = np.sqrt(np.linalg.eigvalsh(So @ np.diag(tight.x**2 / 3) @ So.T).max())
    assert sig_o * z_of_p(0.99) / 3e-4 <= 1 + 1e-6


def test_servo_errors_of_revolute_actuators_and_what_is_refused():
    """A servo error on a Delta arm acts as that arm's zero offset (same sensitivity column);
    clearances and strut servo errors are typed errors."""
    d = tolsynth.load_model("delta")
    d2 = d.with_joint_errors([tolsynth.JointError("theta2", "servo", value=0.1, unit="mrad")])
    S = d2.sensitivity("corner")
    assert np.allclose(S[:, -1], S[:, d.index("A2.offset")], rtol=0, atol=1e-12)
    h = tolsynth.load_model("stewart_gough")
    with pytest.raises(InputError, match="strut"):  # a strut's length error is its leg's offset
        h.with_joint_errors([tolsynth.JointError("q1", "servo", value=0.1, unit="mm")]).sensitivity("home")
    with pytest.raises(OutOfRangeError, match="not a unit of length"):  # a strut slides: no angle
        h.with_joint_errors([tolsynth.JointError("q1", "servo", value=0.1, unit="mrad")])
    with pytest.raises(InputError):
        h.with_joint_errors([tolsynth.JointError("q1", "clearance", value=0.01)])


def test_map_points_invert_the_forward_kinematics():
    """The map's closed-form IK: at every reachable point the forward kinematics of its actuators
    is the grid point with the home orientation, and P there is the analysis' sphere probability."""
    m = tolsynth.load_model("delta")
    pm = tolsynth.probability_map(m, "coarse", R=0.3, n=12, progress=False)
    idx = np.argwhere(np.isfinite(pm.P))
    assert idx.shape[0] > 20
    for a, b in idx[:: max(1, idx.shape[0] // 8)]:
        q = pm.Q[:, a, b]
        T = m.fk(q)
        assert np.allclose(T[:3, 3], [pm.u[b], 0.0, pm.v[a]], atol=1e-8)
        assert abs(m.analyze(q, "coarse", R=0.3).p_sphere - pm.P[a, b]) <= 1e-9


@pytest.mark.slow
def test_workspace_design_holds_over_the_actuator_box():
    """synthesize_workspace on the Delta: at its tolerances, sigma z / R <= 1 + tol at every point
    of a brute-force grid over the actuator box (NumPy eigenvalues per pose)."""
    m = tolsynth.load_model("delta")
    ws = tolsynth.synthesize_workspace(m, R=0.1, p=0.99, pose="home", tol=1e-3, probability="gaussian")
    assert ws.success
    lo, hi = (np.array([getattr(j, k) for j in m.spec.joints]) for k in ("lower", "upper"))
    g = np.linspace(0, 1, 7)
    worst = max(
        _sigma(m, lo + (hi - lo) * np.array(u), ws.result.x) for u in np.array(np.meshgrid(g, g, g)).reshape(3, -1).T
    )
    assert worst * z_of_p(0.99) / 0.1 <= 1 + 2e-3


def test_workspace_design_without_a_worst_configuration():
    """The 3-RRR has no ``worst`` configuration: synthesize_workspace with its default start (the
    model's reference pose, else the search's worst pose) runs, and the design meets sigma z / R <=
    1 + tol on a brute-force grid over the actuator box (NumPy eigenvalues per pose, reachable ones)."""
    m = tolsynth.load_model("planar_3rrr")
    assert "worst" not in m.configurations
    ws = tolsynth.synthesize_workspace(m, R=0.1, p=0.99, tol=1e-3, probability="gaussian")
    assert ws.success
    lo, hi = (np.array([getattr(j, k) for j in m.spec.joints]) for k in ("lower", "upper"))
    g = np.linspace(0, 1, 9)
    worst, reached = 0.0, 0
    for u in np.array(np.meshgrid(g, g, g)).reshape(3, -1).T:
        q = lo + (hi - lo) * u
        try:
            worst = max(worst, _sigma(m, q, ws.result.x))
            reached += 1
        except tolsynth.TolsynthError:  # outside the reachable set
            continue
    assert reached > 50
    assert worst * z_of_p(0.99) / 0.1 <= 1 + 2e-3


def test_contributions_of_anchors_and_leg_offsets():
    """Each parameter's share of the total variance tr V at the optimum is its term
    eps_i^2 |a_i|^2 / 3 over the sum (NumPy from the sensitivity matrix); anchors and leg offsets
    together make all of it."""
    m = tolsynth.load_model("stewart_gough")
    res = tolsynth.synthesize(m, R=0.1, p=0.99, pose="home", probability="gaussian")
    c = tolsynth.contributions(res)
    A = m.sensitivity("home")[:3]
    terms = res.x**2 * (A**2).sum(axis=0) / 3
    assert np.allclose(c.total_share[0], terms / terms.sum(), rtol=0, atol=1e-12)
    offsets = [i for i, n in enumerate(m.error_parameters) if n.endswith(".offset")]
    assert len(offsets) == 6 and 0 < c.total_share[0][offsets].sum() < 1


@pytest.mark.slow
def test_exact_probability_design_on_the_delta():
    """probability="exact" on the Delta (few dominant uniform errors: the Gaussian reading is off
    by 0.015 in P at R = 0.3 mm): certified, and Monte Carlo through Newton's forward kinematics
    finds P(|w_j| <= R) >= p along the principal directions, within its confidence interval."""
    m = tolsynth.load_model("delta")
    res = tolsynth.synthesize(m, R=0.3, p=0.99, pose="home", probability="exact")
    assert res.success and res.gap <= 1e-5 * res.cost
    mc = tolsynth.monte_carlo(m, "home", res.x, R=0.3, n=200_000, seed=5, progress=False)
    assert np.all(mc.p_components_ci[:, 1] >= 0.99), mc.p_components_ci


@pytest.mark.parametrize("name", ["stewart_gough", "delta", "planar_3rrr"])
def test_exact_probability_designs_are_certified(name):
    """probability="exact" (uniform errors) on each parallel robot: a certified optimum, and plain
    NumPy Monte Carlo of the linear model at its tolerances finds P(|v . dr| <= R) >= p along each
    principal direction v (within 4 standard errors of 200 000 samples).  The hexapod's 42-error
    solve runs on IPOPT: the compiled interior-point method stops at its iteration limit there."""
    m = tolsynth.load_model(name)
    extra = {"solver": "ipopt"} if name == "stewart_gough" else {}
    res = tolsynth.synthesize(m, R=0.1, p=0.99, pose="home", probability="exact", **extra)
    assert res.success and res.gap <= 1e-5 * res.cost, res.message
    A = m.sensitivity("home")[:3]
    rng = np.random.default_rng(11)
    n = 200_000
    w = rng.uniform(-1.0, 1.0, (n, m.n)) * res.x @ A.T
    _, V = np.linalg.eigh(A @ np.diag(res.x**2 / 3) @ A.T)
    for v in V.T:
        if np.linalg.norm(A.T @ v) > 1e-12:  # a direction the errors move (the 3-RRR's z does not)
            P = np.mean(np.abs(w @ v) <= 0.1)
            assert P >= 0.99 - 4 * np.sqrt(0.99 * 0.01 / n), (name, P)


@pytest.mark.slow  # 4-15 s: the default run stays under 4 minutes
def test_exact_probability_design_on_the_hexapod_with_the_default_solver():
    """The 42-error hexapod's exact design (its barrier path stalls once and is re-centred): certified,
    the cost IPOPT's Gaussian start leads to as well, and p met along each principal direction by
    NumPy Monte Carlo of the linear model (200 000 samples, 4 standard errors)."""
    m = tolsynth.load_model("stewart_gough")
    res = tolsynth.synthesize(m, R=0.1, p=0.99, pose="home", probability="exact")
    assert res.success, res.message
    other = tolsynth.synthesize(m, R=0.1, p=0.99, pose="home", probability="exact", solver="ipopt")
    assert other.success and res.cost == pytest.approx(other.cost, rel=1e-6)
    A = m.sensitivity("home")[:3]
    w = np.random.default_rng(14).uniform(-1.0, 1.0, (200_000, m.n)) * res.x @ A.T
    for v in np.linalg.eigh(A @ np.diag(res.x**2 / 3) @ A.T)[1].T:
        assert np.mean(np.abs(w @ v) <= 0.1) >= 0.99 - 4 * np.sqrt(0.99 * 0.01 / 200_000)


@pytest.mark.slow
def test_exact_workspace_design_on_the_delta():
    """synthesize_workspace with exact probabilities over the Delta's arm box: converged, finite
    tolerances, and at the last worst pose NumPy Monte Carlo of the linear model meets p along each
    principal direction (200 000 samples, 4 standard errors)."""
    m = tolsynth.load_model("delta")
    ws = tolsynth.synthesize_workspace(m, R=0.1, p=0.99, pose="home", probability="exact")
    assert ws.success and np.all(np.isfinite(ws.result.x)) and np.all(ws.result.x > 0)
    A = m.sensitivity(ws.rounds[-1]["worst_q"])[:3]
    w = np.random.default_rng(12).uniform(-1.0, 1.0, (200_000, m.n)) * ws.result.x @ A.T
    for v in np.linalg.eigh(A @ np.diag(ws.result.x**2 / 3) @ A.T)[1].T:
        assert np.mean(np.abs(w @ v) <= 0.1) >= 0.99 - 4 * np.sqrt(0.99 * 0.01 / 200_000)


def test_hexapod_map_keeps_a_home_pose_level_to_its_anchors_rounding():
    """The hexapod's home pose is level only to ~3e-8 rad (its anchors are printed to 0.1 um): the
    map's default vertical hand axis is accepted, each reachable point's struts give the grid point
    back through the forward kinematics (1e-8 mm) with the platform level to 1e-6, and an axis
    tilted by 1e-3 is refused with the reference axis named."""
    m = tolsynth.load_model("stewart_gough")
    tilt = np.abs(m.fk("home")[:3, 2] - [0.0, 0.0, 1.0]).max()
    assert 1e-9 < tilt < 1e-6
    pm = tolsynth.probability_map(m, "coarse", R=0.5, n=9, plane="xz", progress=False)
    idx = np.argwhere(np.isfinite(pm.P))
    assert idx.shape[0] >= 5
    for a, b in idx:
        T = m.fk(pm.Q[:, a, b])
        assert np.allclose(T[:3, 3], [pm.u[b], 0.0, pm.v[a]], atol=1e-8)
        assert np.abs(T[:3, 2] - [0.0, 0.0, 1.0]).max() <= 1e-6
    with pytest.raises(InputError, match="reference pose's platform orientation"):
        tolsynth.probability_map(m, "coarse", R=0.5, n=9, plane="xz", hand_axis=(0.0, 1e-3, 1.0), progress=False)


def test_repeated_exact_solve_on_the_hexapod_gives_the_same_certified_design():
    """Results do not depend on what ran before: the same exact design twice in one process (IPOPT;
    the second's Gaussian start comes from IPOPT's remembered cuts, and its barrier path differs)."""
    m = tolsynth.load_model("stewart_gough")
    spec = dict(R=0.15, p=0.98, pose="home", probability="exact", solver="ipopt")
    first, second = (tolsynth.synthesize(m, **spec) for _ in range(2))
    assert first.success and second.success and abs(first.cost - second.cost) <= 1e-6 * first.cost


@pytest.mark.slow
@pytest.mark.parametrize("name", ["stewart_gough", "delta", "planar_3rrr"])
def test_sphere_designs_with_exact_probabilities_meet_p(name):
    """criterion="sphere" with exact probabilities: the design (a local optimum: the sphere's
    optimality is not proven, so its status is "feasible") keeps P(|dr| <= R) >= p by NumPy Monte
    Carlo of the linear model (200 000 uniform samples, 4 standard errors)."""
    m = tolsynth.load_model(name)
    extra = {"solver": "ipopt"} if name == "stewart_gough" else {}
    res = tolsynth.synthesize(m, R=0.1, p=0.99, pose="home", criterion="sphere", probability="exact", **extra)
    assert res.status.value in ("feasible", "optimal") and np.all(np.isfinite(res.x)), res.message
    A = m.sensitivity("home")[:3]
    w = np.random.default_rng(13).uniform(-1.0, 1.0, (200_000, m.n)) * res.x @ A.T
    P = np.mean(np.linalg.norm(w, axis=1) <= 0.1)
    assert P >= 0.99 - 4 * np.sqrt(0.99 * 0.01 / 200_000), (name, P)


def test_a_leg_axis_is_a_direction(tmp_path):
    """The format reads a revolute leg's axis as a direction: a longer vector along it gives the same
    robot (hand position and sensitivity at the home pose to 1e-12), a zero vector is refused."""
    from model_text import edited, load_dict

    ref = tolsynth.load_model("delta")
    long = load_dict(tmp_path, edited("delta", _set(["leg", 1, "axis"], [-1.5, 3 * 0.8660254037844386, 0.0])))
    q = ref.configurations["home"]
    assert np.allclose(long.fk(q), ref.fk(q), rtol=0, atol=1e-12)
    assert np.allclose(long.sensitivity(q), ref.sensitivity(q), rtol=0, atol=1e-12)
    assert_defect_named(tmp_path, "delta", _set(["leg", 1, "axis"], [0.0, 0.0, 0.0]), "leg[1].axis", "zero vector")
