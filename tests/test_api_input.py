"""What synthesize and ``tolsynth solve`` make of their inputs: options that mean nothing under
the exact reading, the label of what actually solved, pose against poses, the groups' unset
fields, and the seed."""

from __future__ import annotations

import numpy as np
import pytest

import tolsynth
from tolsynth.cli import main
from tolsynth.errors import InputError, OutOfRangeError

SPEC = dict(R=0.5, p=0.99, distribution="uniform")


# --- warm_start and --solver both under the exact reading


def test_solve_both_with_exact_probabilities_is_refused_naming_the_flags(capsys):
    rc = main(
        ["solve", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.99", "--solver", "both"]
        + ["--probability", "exact"]
    )
    err = capsys.readouterr().err
    assert rc == 2
    assert "--solver both" in err and "--probability gaussian" in err and "--probability exact" in err
    assert "warm_start" not in err and "Traceback" not in err  # nothing the user did not type


@pytest.mark.parametrize("solver", ["auto", "ipopt", "sumt"])
def test_warm_start_under_exact_is_refused_with_its_reason(xz, solver):
    with pytest.raises(InputError) as exc:
        tolsynth.synthesize(xz, **SPEC, solver=solver, options={"warm_start": False})
    assert exc.value.field == "options['warm_start']"
    assert "keeps nothing between solves" in str(exc.value) and "probability='gaussian'" in str(exc.value)
    with pytest.raises(InputError, match="keeps nothing between solves"):
        tolsynth.synthesize(xz, **SPEC, criterion="sphere", options={"warm_start": False})


def test_warm_start_false_solves_from_scratch_under_the_gaussian_reading(xz):
    """The guide's claim, where it holds: the same optimum as the paper's Table 1 value (84.41889)."""
    res = tolsynth.synthesize(xz, **SPEC, solver="ipopt", probability="gaussian", options={"warm_start": False})
    assert res.success and res.cost == pytest.approx(84.41889, rel=1e-6)
    with pytest.raises(InputError, match="SUMT \\+ Powell keeps nothing"):
        tolsynth.synthesize(xz, **SPEC, solver="sumt", probability="gaussian", options={"warm_start": False})


# --- the result says what solved


def test_exact_result_names_the_exact_method_and_its_start(xz):
    runs = {s: tolsynth.synthesize(xz, **SPEC, solver=s) for s in ("auto", "ipopt", "sumt")}
    gaussian_sumt = tolsynth.synthesize(xz, **SPEC, solver="sumt", probability="gaussian")
    # one method ran three times: the same Newton steps and evaluations, none of them SUMT's own run
    assert len({(r.iterations, r.function_evaluations) for r in runs.values()}) == 1
    assert runs["sumt"].iterations != gaussian_sumt.iterations
    for name, res in runs.items():
        assert res.success and res.solver.startswith("exact interior point"), (name, res.solver)
        assert res.summary().splitlines()[0].startswith(res.solver + ": optimal")
        assert res.inputs["solver"] == name  # what was asked stays recorded as asked
    assert "SUMT + Powell" in runs["sumt"].solver and "IPOPT" in runs["ipopt"].solver
    # all-normal errors: the exact problem is the Gaussian one, and the named solver does solve it
    normal = tolsynth.synthesize(xz, R=0.5, p=0.99, distribution="normal", solver="sumt")
    assert normal.solver == "sumt"


def test_cli_solve_labels_the_exact_run_honestly(capsys):
    rc = main(["solve", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.99", "--solver", "sumt"])
    out = capsys.readouterr().out
    assert rc == 0
    assert "exact interior point (started from the Gaussian optimum of SUMT + Powell): optimal" in out
    assert not any(line.startswith("sumt:") for line in out.splitlines())


# --- pose against poses


def test_pose_and_poses_together_are_an_error(xz):
    with pytest.raises(InputError) as exc:
        tolsynth.synthesize(xz, R=0.5, p=0.99, pose="worst", poses=["home"])
    assert exc.value.field == "pose" and "poses" in str(exc.value)
    with pytest.raises(InputError, match="not both"):
        tolsynth.synthesize(xz, spec=tolsynth.DesignSpec(R=0.5, p=0.99, pose="worst", poses=["home"]))
    with pytest.raises(InputError, match="not both"):
        tolsynth.synthesize(xz, spec=tolsynth.DesignSpec(R=0.5, p=0.99, poses=["home"]), pose="worst")


# --- the groups' unset fields


def test_unset_spec_fields_do_not_count_as_given(xz):
    at_home = tolsynth.synthesize(xz, **SPEC, pose="home", probability="gaussian")
    worst = tolsynth.synthesize(xz, **SPEC, probability="gaussian")
    assert abs(at_home.cost - worst.cost) > 1e-3 * worst.cost  # the pose matters, so the tests below see it
    a = tolsynth.synthesize(
        xz, spec=tolsynth.DesignSpec(pose="home", distribution="uniform"), R=0.5, p=0.99, probability="gaussian"
    )
    b = tolsynth.synthesize(xz, spec=tolsynth.DesignSpec(**SPEC, probability="gaussian"), pose="home")
    assert list(a.spec.poses) == list(b.spec.poses) == ["home"]
    assert a.cost == pytest.approx(at_home.cost, rel=1e-9) and b.cost == pytest.approx(at_home.cost, rel=1e-9)
    with pytest.raises(InputError, match="given as a keyword \\(0.6\\) and in spec \\(0.5\\)"):
        tolsynth.synthesize(xz, spec=tolsynth.DesignSpec(R=0.5, p=0.99), R=0.6)
    with pytest.raises(InputError, match="pose"):
        tolsynth.synthesize(xz, spec=tolsynth.DesignSpec(R=0.5, p=0.99, pose="home"), pose="worst")


def test_a_keyword_passed_at_its_default_value_still_conflicts_with_a_group(xz):
    # alpha=0.7 and criterion="components" are the keywords' defaults, passed explicitly here
    with pytest.raises(InputError, match=r"^alpha: given as a keyword \(0.7\) and in spec \(0.5\)"):
        tolsynth.synthesize(xz, spec=tolsynth.DesignSpec(R=0.5, p=0.99, alpha=0.5), alpha=0.7)
    with pytest.raises(InputError, match=r"^criterion: given as a keyword \('components'\) and in spec"):
        tolsynth.synthesize(xz, spec=tolsynth.DesignSpec(R=0.5, p=0.99, criterion="sphere"), criterion="components")
    with pytest.raises(InputError, match=r"^seed: given as a keyword \(0\) and in solver \(3\)"):
        tolsynth.synthesize(xz, 0.5, 0.99, solver=tolsynth.SolverOptions(seed=3), seed=0)
    # calls that agree keep their result: alpha 0.5 from the group alone, and given both ways
    plain = tolsynth.synthesize(xz, R=0.5, p=0.99, alpha=0.5, probability="gaussian")
    grouped = tolsynth.synthesize(xz, spec=tolsynth.DesignSpec(R=0.5, p=0.99, alpha=0.5), probability="gaussian")
    both = tolsynth.synthesize(xz, 0.5, 0.99, None, 0.5, spec=tolsynth.DesignSpec(alpha=0.5, probability="gaussian"))
    assert grouped.cost == plain.cost and both.cost == plain.cost


# --- the seed


@pytest.mark.parametrize("seed", ["x", 1.5, [1, 2], -1, True])
@pytest.mark.parametrize("validate", [None, 1000])
def test_bad_seed_is_the_same_typed_error_as_monte_carlo(xz, seed, validate):
    with pytest.raises(OutOfRangeError) as mc:
        tolsynth.monte_carlo(xz, "worst", "figure3", "uniform", R=0.2, n=100, seed=seed)
    with pytest.raises(OutOfRangeError) as syn:
        tolsynth.synthesize(xz, **SPEC, validate=validate, seed=seed)
    assert syn.value.field == mc.value.field == "seed" and str(syn.value) == str(mc.value)


def test_compare_refuses_the_exact_reading():
    """compare is IPOPT against SUMT + Powell on the paper's Gaussian reading: under the exact one
    both would be the same exact interior-point run, so it is refused, naming the field (not an
    internal option the user never gave); its default still compares the two solvers, which agree
    on Table 1's design to 1e-6."""
    m = tolsynth.load_model("xu_zhang_1988")
    with pytest.raises(InputError, match=r"probability: got 'exact'.*same run") as e:
        tolsynth.compare(m, 0.5, 0.99, probability="exact")
    assert "warm_start" not in str(e.value)
    c = tolsynth.compare(m, 0.5, 0.99)
    assert c.ipopt.success and c.sumt.success and c.cost_rel_diff <= 1e-6
    assert c.ipopt.cost == pytest.approx(84.41889, abs=1e-5)


@pytest.mark.parametrize("Phi", [4.0, 1e8, float("nan"), 0.0])
def test_a_cone_half_angle_above_pi_is_refused_everywhere(Phi):
    """A rotation turns the hand axis by at most pi, so a half-angle above it would allow every turn
    and change nothing: synthesize, analyze, p_cone and the exact cone probability refuse it (and
    0 and NaN), naming Phi and (0, pi]."""
    import math

    from tolsynth.probability.exact_sphere import cone_probability
    from tolsynth.probability.stats import p_cone

    m = tolsynth.load_model("xu_zhang_1988")
    q = m.joints("worst")
    calls = [
        lambda: tolsynth.synthesize(m, R=0.5, p=0.99, Phi=Phi, probability="gaussian"),
        lambda: m.analyze(q, m.tolerances("figure3"), Phi=Phi),
        lambda: p_cone(np.eye(3) * 1e-6, [0.0, 0.0, 1.0], Phi),
        lambda: cone_probability(np.ones((2, 3)), np.full(3, 1e-3), ["uniform"] * 3, Phi),
    ]
    for call in calls:
        with pytest.raises(OutOfRangeError, match=r"Phi: got .*to 3\.14159.*\(rad\)"):
            call()
    # pi itself is the widest cone: every orientation error of a rotation lies inside it
    assert p_cone(np.eye(3) * 1e-6, [0.0, 0.0, 1.0], math.pi) == pytest.approx(1.0)


@pytest.mark.parametrize("criterion, R", [("sigma", None), ("probability", 0.5)])
def test_worst_pose_refuses_the_exact_reading_it_would_ignore(criterion, R):
    """The sigma and sphere searches read the Gaussian model: probability='exact' there used to be
    accepted and ignored; now it names the field and the criterion that reads it. 'gaussian' and
    the default give the same pose, whose sigma_1 matches the sensitivity's own eigenvalue."""
    m = tolsynth.load_model("planar_2r")
    with pytest.raises(InputError, match=r"probability: 'exact' given with criterion"):
        tolsynth.worst_pose(m, "coarse", criterion=criterion, R=R, probability="exact")
    a = tolsynth.worst_pose(m, "coarse", criterion="sigma", probability="gaussian")
    b = tolsynth.worst_pose(m, "coarse", criterion="sigma")
    assert a.value == b.value
    A = m.sensitivity(a.q)[:3] * m.tolerances("coarse")
    assert a.value == pytest.approx(np.sqrt(np.linalg.eigvalsh(A @ A.T / 3.0).max()), rel=1e-9)


def test_solve_header_keeps_the_digits_of_p_and_lock_lists_its_kind(capsys):
    """p near 1 is shown with the digits that keep 1 - p (not 'p=1'); a --lock value of the wrong
    kind lists the suffixes of the parameter's own kind (length for h2, angle for alpha1)."""
    main(["solve", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.999999999999", "--probability", "gaussian"])
    assert "p=0.999999999999," in capsys.readouterr().out.splitlines()[0]
    assert main(["solve", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.99", "--lock", "h2=0.01deg"]) == 2
    err = capsys.readouterr().err
    assert "length unit suffix (mm, um" in err and "deg" not in err.split("suffix")[1]
    assert main(["solve", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.99", "--lock", "alpha1=5um"]) == 2
    err = capsys.readouterr().err
    assert "angle unit suffix (rad, mrad" in err and "um" not in err.split("suffix")[1]


# --- x0: read by the solvers that start from it, refused where the compiled method solves


def test_x0_is_refused_where_the_compiled_method_solves_and_read_by_ipopt():
    """The compiled interior-point method has its own start, so an x0 given to solver 'auto' on a
    problem it takes would be ignored: refused naming x0 and the solvers that read it.  IPOPT reads
    it: from a far start it reaches the same optimum within its tolerance, by another path."""
    m = tolsynth.load_model("planar_2r")
    spec = dict(R=0.5, p=0.99, pose="elbow90", probability="gaussian")
    far = [4.9, 0.002, 40.0, 0.002]
    for kw in ({}, {"probability": "exact"}):
        with pytest.raises(InputError) as info:
            tolsynth.synthesize(m, **{**spec, **kw}, x0=far)
        assert info.value.field == "x0" and "'ipopt'" in info.value.allowed and "'sumt'" in info.value.allowed
    cold = tolsynth.synthesize(m, **spec, solver="ipopt")
    started = tolsynth.synthesize(m, **spec, solver="ipopt", x0=far)
    assert started.inputs["x0"] == far and not np.array_equal(started.x, cold.x)  # another path
    assert started.cost == pytest.approx(cold.cost, rel=1e-7)
    sphere = tolsynth.synthesize(m, **{**spec, "criterion": "sphere"}, x0=far)  # 'auto' runs IPOPT here
    assert sphere.solver == "ipopt"


@pytest.mark.parametrize("solver, passed", [(None, False), ("ipopt", True)])
def test_pareto_and_budget_pass_the_previous_optimum_only_to_a_solver_that_reads_it(monkeypatch, solver, passed):
    """Each step of pareto_front and best_accuracy after a success hands x0 on only where it is read."""
    import tolsynth.synthesis.single as single

    seen = []
    real = single.synthesize

    def spy(*args, **kwargs):
        seen.append(kwargs.get("x0") is not None)
        return real(*args, **kwargs)

    monkeypatch.setattr(single, "synthesize", spy)
    m = tolsynth.load_model("planar_2r")
    kw = dict(pose="elbow90", probability="gaussian", **({} if solver is None else {"solver": solver}))
    tolsynth.pareto_front(m, R=[0.3, 0.5], p=0.99, **kw)
    tolsynth.best_accuracy(m, budget=12.0, p=0.99, max_solves=6, **kw)
    assert len(seen) > 4 and any(seen) is passed
