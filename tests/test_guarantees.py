"""The named findings, each pinned: a typed error naming the field, or a correct
number where there was a wrong one (checked against SciPy or a closed form)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import tolsynth
from tolsynth.errors import InputError, OutOfRangeError, TolsynthError


@pytest.fixture(scope="module")
def planar():
    return tolsynth.load_model("planar_2r")


@pytest.mark.parametrize(
    "call, field",
    [
        (lambda m: tolsynth.worst_pose(m, "coarse", step_tol=0), "step_tol"),
        (lambda m: tolsynth.worst_pose(m, "coarse", step_tol=-1e-3), "step_tol"),
        (lambda m: tolsynth.worst_pose(m, "coarse", step_tol=math.nan), "step_tol"),
        (lambda m: tolsynth.worst_pose(tolsynth.load_model("xu_zhang_1988"), "figure3", grid=200), "grid"),
        (lambda m: tolsynth.worst_pose(m, "coarse", grid=10**7), "grid"),
        (lambda m: tolsynth.monte_carlo(m, "worst", "coarse", R=0.5, n=math.nan), "n"),
        (lambda m: tolsynth.monte_carlo(m, "worst", "coarse", R=0.5, n=math.inf), "n"),
        (lambda m: tolsynth.synthesize(m, 0.5, 1 - 1.1e-16, probability="gaussian"), "p"),
        (lambda m: tolsynth.synthesize(m, 0.5, 0.99, x0=[0.0, 0.1, 0.1, 0.1], probability="gaussian"), "x0[0]"),
        (lambda m: tolsynth.synthesize(m, 0.5, 0.99, options={"tol": -1}, probability="gaussian"), "options['tol']"),
        (lambda m: tolsynth.synthesize(m, 0.5, 0.99, options={"tl": 1e-8}, probability="gaussian"), "options"),
        (lambda m: m.analyze("worst", np.full(4, 1e155), R=0.5), "tolerances[l1]"),
        (lambda m: tolsynth.synthesize_workspace(m, 0.5, 0.99, max_rounds=0, probability="gaussian"), "max_rounds"),
        (lambda m: tolsynth.compare(m, 0.5, 0.99, options="tol"), "options"),
        (lambda m: tolsynth.compare(m, 0.5, 0.99, options={"ipopt": "a"}), "options['ipopt']"),
        (lambda m: tolsynth.compare(m, 0.5, 0.99, options={"ipopt": {"warm_start": 1}}), "options['warm_start']"),
        (lambda m: m.tolerances({"l1": "a", "l2": 1, "o1": 1, "o2": 1}), "tolerances[l1]"),
        (lambda m: m.fk(["a", "b"]), "q[q1]"),  # the first joint that is not an angle
        (lambda m: m.index(["l1"]), "error parameter"),
    ],
)
def test_typed_error_names_field(planar, call, field):
    with pytest.raises(TolsynthError) as info:
        call(planar)
    assert isinstance(info.value, InputError)
    assert info.value.field == field and field in str(info.value)


def test_ipopt_options_dump_nothing(planar, capfd):
    with pytest.raises(OutOfRangeError):
        tolsynth.synthesize(planar, 0.5, 0.99, options={"tol": -1}, probability="gaussian")
    assert capfd.readouterr().out == ""


def test_p_sphere_at_tiny_radius_is_positive_and_right(planar):
    """At R = 1e-12 mm the closed form cancels (it gave -8e-28); the series gives the value of
    the small-ball limit P ~ R^3 / (3 sqrt(pi/2) prod(sigma)) ... checked here against SciPy's chi
    CDF for equal variances, and positive in general."""
    from scipy.stats import chi

    from tolsynth.probability.stats import p_ball

    for R in (1e-12, 1e-6, 0.3, 0.5, 0.7):
        assert p_ball([2.0, 2.0, 2.0], R) == pytest.approx(chi.cdf(R / math.sqrt(2.0), 3), rel=1e-12, abs=0)
    a = planar.analyze("elbow90", "coarse", R=1e-12)
    assert 0 < a.p_sphere < 1e-20


def test_no_overflow_warning_from_stats():
    """Huge arguments of the chi CDF (variance 1e-300 against R = 1e9) saturate at 1 silently."""
    from tolsynth.probability.stats import p_ball, p_components

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert p_ball([1e-30, 1e-300, 1e-300], 1e9) == 1.0
        assert np.all(p_components([1e-300, 1.0], 1e9) == 1.0)


# ---------------------------------------------------------------------------------------------
# no surprises: units, limits, option checks (each against an independent number or a typed error)
# ---------------------------------------------------------------------------------------------
def test_lengths_and_angles_take_unit_strings_everywhere(planar):
    """One rule for the API and the command line: ``R="500um"`` is 0.5 mm, ``Phi="2mrad"`` is
    0.002 rad (the same optimum as the numbers, to the solver's tolerance); an angle unit for R
    is a typed error quoting the length units."""
    a = tolsynth.synthesize(planar, 0.5, 0.99, pose="elbow90", probability="gaussian")
    b = tolsynth.synthesize(planar, "500um", 0.99, pose="elbow90", probability="gaussian")
    assert b.cost == pytest.approx(a.cost, rel=1e-8)
    an = planar.analyze("elbow90", "coarse", R="0.05cm", Phi="0.1deg")
    ref = planar.analyze("elbow90", "coarse", R=0.5, Phi=math.radians(0.1))
    assert an.p_sphere == pytest.approx(ref.p_sphere, rel=1e-12) and an.p_cone == pytest.approx(ref.p_cone, rel=1e-12)
    with pytest.raises(InputError) as info:
        tolsynth.synthesize(planar, "5deg", 0.99, pose="elbow90", probability="gaussian")
    assert info.value.field == "R" and "um" in str(info.value) and "length unit" in str(info.value)
    with pytest.raises(InputError) as info:
        tolsynth.synthesize(planar, "0.5 furlong", 0.99, pose="elbow90", probability="gaussian")
    assert info.value.field == "R"


@pytest.mark.parametrize(
    "call, field",
    [
        (
            lambda m: tolsynth.best_accuracy(m, 20.0, p=0.99, rtol=math.nan, pose="elbow90", probability="gaussian"),
            "rtol",
        ),
        (lambda m: tolsynth.best_accuracy(m, 20.0, p=0.99, rtol=-1.0, pose="elbow90", probability="gaussian"), "rtol"),
        (
            lambda m: tolsynth.best_accuracy(m, 20.0, p=0.99, max_solves=0, pose="elbow90", probability="gaussian"),
            "max_solves",
        ),
        (lambda m: tolsynth.best_accuracy(m, "20mm", p=0.99, pose="elbow90", probability="gaussian"), "budget"),
        (lambda m: tolsynth.sweep(m, [0.5], 0.99, pose="elbow90", progress="x", probability="gaussian"), "progress"),
        (
            lambda m: tolsynth.synthesize(m, 0.5, 0.99, pose="elbow90", time_limit=0, probability="gaussian"),
            "time_limit",
        ),
        (
            lambda m: tolsynth.synthesize(m, 0.5, 0.99, pose="elbow90", time_limit=math.nan, probability="gaussian"),
            "time_limit",
        ),
        (
            lambda m: tolsynth.synthesize(m, 0.5, 0.99, pose="elbow90", time_limit="1", probability="gaussian"),
            "time_limit",
        ),
        (
            lambda m: tolsynth.synthesize(m, 0.5, 0.99, pose="elbow90", probability="exact", options={"bogus": 1}),
            "options",
        ),
        (lambda m: tolsynth.synthesize(m, 0.5, 0.99, pose="elbow90", probability="exact", options="a"), "options"),
    ],
)
def test_bad_limits_are_typed_errors(planar, call, field):
    with pytest.raises(InputError) as info:
        call(planar)
    assert info.value.field == field and "allowed" in str(info.value)


def _processes():
    from tolsynth.model.cost import PowerLaw
    from tolsynth.synthesis.processes import Process

    return {
        "h3": [Process("turning", PowerLaw(1.0, 0.7), 0.05, 0.5), Process("grinding", PowerLaw(3.0, 0.7), 0.005, 0.05)],
        "a": [Process("turning", PowerLaw(1.0, 0.7), 0.05, 0.5), Process("lapping", PowerLaw(5.0, 0.7), 0.001, 0.05)],
    }


@pytest.mark.parametrize(
    "kw, field",
    [
        ({"max_nodes": 0}, "max_nodes"),
        ({"max_nodes": 1}, "max_nodes"),
        ({"rel_gap": -1.0}, "rel_gap"),
        ({"rel_gap": math.nan}, "rel_gap"),
    ],
)
def test_process_search_limits_are_checked(kw, field):
    """A search that cannot start (fewer than the root's two solves) or a meaningless gap is an
    error, never a 'proven' optimum."""
    with pytest.raises(InputError) as info:
        tolsynth.synthesize_processes("xu_zhang_1988", R=0.5, p=0.99, processes=_processes(), **kw)
    assert info.value.field == field


def test_process_search_proof_matches_brute_force():
    """Whatever the node limit, ``proven`` is claimed only for the brute-force optimum (every
    combination solved by enumerate_processes)."""
    from tolsynth.synthesis.processes import enumerate_processes

    brute = min(
        r.cost
        for _, r in enumerate_processes("xu_zhang_1988", 0.5, 0.99, _processes(), probability="gaussian")
        if r is not None and r.success
    )
    for limit in (2, 3, 10_000):
        best = tolsynth.synthesize_processes(
            "xu_zhang_1988", R=0.5, p=0.99, processes=_processes(), max_nodes=limit, probability="gaussian"
        )
        assert best.lower_bound <= brute * (1 + 1e-9)
        if best.proven:
            assert best.cost == pytest.approx(brute, rel=1e-6)


def test_time_limit_ends_a_solve_honestly(planar):
    """A limit too short for the solve: ``Status.TIME_LIMIT``, never success, and the call returns
    within a second or so of the limit; the same specification without it converges."""

    from tolsynth.problem.result import Status

    for solver in ("ipopt", "sumt"):
        res = tolsynth.synthesize(
            planar,
            0.5,
            0.99,
            pose="elbow90",
            solver=solver,
            time_limit=1e-3,
            options={"max_outer": 60} if solver == "sumt" else None,
            probability="gaussian",
        )
        assert res.status in (Status.TIME_LIMIT, Status.OPTIMAL)
        if solver == "sumt":  # its outer loop takes longer than 1 ms
            assert res.status is Status.TIME_LIMIT and not res.success and "time limit" in res.message
    res = tolsynth.synthesize(
        planar,
        0.5,
        0.99,
        pose="elbow90",
        solver=tolsynth.SolverOptions("sumt", time_limit=1e-3),
        probability="gaussian",
    )
    assert res.status is Status.TIME_LIMIT


def test_time_limit_inside_an_evaluation(planar, monkeypatch):
    """A solver stopped inside a long evaluation (the deadline checked there raises): the result is
    the start point with ``Status.TIME_LIMIT``, its constraint values those of that point (checked
    against Mechanism.analyze's principal sigma), never success; elapsed time near the limit."""
    import time

    from tolsynth.problem.result import Status
    from tolsynth.progress import check_deadline
    from tolsynth.synthesis import single

    def endless(nlp, eps0, options):
        while True:
            check_deadline("a slow evaluation")
            time.sleep(0.01)

    monkeypatch.setitem(single.SOLVERS, "ipopt", endless)
    t0 = time.perf_counter()
    x0 = [0.05, 0.05, 0.05, 0.05]
    res = tolsynth.synthesize(
        planar, 0.5, 0.99, pose="elbow90", time_limit=0.5, x0=x0, solver="ipopt", probability="gaussian"
    )
    assert 0.5 <= time.perf_counter() - t0 < 5.0
    assert res.status is Status.TIME_LIMIT and not res.success and "start point, not a design" in res.message
    assert res.x == pytest.approx(x0)
    a = planar.analyze("elbow90", x0, R=0.5)
    from statistics import NormalDist

    z = NormalDist().inv_cdf(0.995)
    assert res.constraints[0].values == pytest.approx(a.principal_std * z / 0.5, rel=1e-9)
    assert res.lower_bound <= res.cost


def test_default_time_limit_is_stated():
    from tolsynth.checks import DEFAULT_TIME_LIMIT, check_time_limit

    assert check_time_limit(None) == DEFAULT_TIME_LIMIT == 600.0
    assert tolsynth.SolverOptions().time_limit is None


def test_from_dh_angles_are_radians_unless_stated():
    """from_dh and load_urdf follow one rule (docs/units.md): rad unless angle_unit says otherwise.
    A table in degrees without the unit is refused (a twist of 90 is not 90 rad); with the unit it
    is the same robot as in radians (forward kinematics to 1e-12 mm)."""
    deg = [{"a": 500.0, "alpha": 90.0, "limits": (-170, 170)}, {"a": 300.0, "limits": (-150, 150)}]
    rad = [
        {"a": 500.0, "alpha": math.pi / 2, "limits": (math.radians(-170), math.radians(170))},
        {"a": 300.0, "limits": (math.radians(-150), math.radians(150))},
    ]
    with pytest.raises(InputError) as info:
        tolsynth.Mechanism.from_dh(deg)
    assert info.value.field == "angle_unit" and "angle_unit='deg'" in str(info.value)
    m_deg = tolsynth.Mechanism.from_dh(deg, angle_unit="deg", configurations={"c": [30.0, 90.0]})
    m_rad = tolsynth.Mechanism.from_dh(rad, configurations={"c": [math.radians(30.0), math.radians(90.0)]})
    assert np.abs(m_deg.fk("c") - m_rad.fk("c")).max() <= 1e-12
    # the hand of a planar 2R at (30, 90) deg with a1 = 500, a2 = 300, by hand (twist 90 about x1)
    c1, s1 = math.cos(math.radians(30)), math.sin(math.radians(30))
    assert m_rad.fk("c")[:3, 3] == pytest.approx([500 * c1, 500 * s1, 300.0], abs=1e-9)


def test_bundled_models_configurations_inside_their_limits():
    """Every bundled model's named configurations lie inside its joint limits (or waive them with
    a note): the reader now refuses any other at load."""
    for name in tolsynth.bundled_models():
        m = tolsynth.load_model(name)
        for cname in m.configurations:
            m.joints(cname)  # raises if outside (the same rule the reader applies)
