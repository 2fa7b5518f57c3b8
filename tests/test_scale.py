"""The solver core at scale: every feasible problem solved, at any number of poses, by the default
engine (``solver="auto"``: the compiled interior-point method) and by IPOPT alike.

Independent references:
* cvxpy + Clarabel on the convex form in ``v = eps^2`` (cost ``k v^(-alpha/2)``, one 3x3 LMI
  ``sum_i v_i a_i a_i^T / c <= (R/z)^2 I`` per pose): an SDP solved by an interior-point conic
  solver that shares nothing with tolsynth's NLP;
* NumPy: the covariance rebuilt from the model's sensitivities at every pose and its eigenvalues
  tested against ``(R/z)^2``.

The default run covers 1-30 poses; 100 and 300 poses, and the full default-bounds grid, are slow.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

import tolsynth
from convex_reference import clarabel, random_poses
from tolsynth.probability.stats import z_of_p
from tolsynth.problem.specification import make_specification

cp = pytest.importorskip("cvxpy")


def clarabel_cost(mech, R, p, distribution, alpha, poses, **kw) -> float | None:
    """The optimal cost by cvxpy + Clarabel, or None where Clarabel does not report optimal."""
    return clarabel(make_specification(mech, R, p, distribution, alpha, poses=poses, **kw))


def assert_meets_spec(mech, res, R, p, distribution, poses, tol=1e-6):
    """NumPy check: the covariance at every pose, rebuilt from the sensitivities."""
    c = {"uniform": 3.0, "normal": 9.0}[distribution]
    eps = res.x
    limit = (R / z_of_p(p)) ** 2
    for q in poses:
        S = mech.sensitivity(q, check_limits=False)[:3]
        V = S @ np.diag(eps**2 / c) @ S.T
        assert np.linalg.eigvalsh(V).max() <= limit * (1 + tol) ** 2


def reference_pose(mech):
    return "worst" if "worst" in mech.configurations else list(mech.configurations)[-1]


SIZES = [(1, 2), (3, 2), (10, 2), (30, 1)]
#: the default engine and IPOPT (the general path and the cross-check)
SOLVERS = ["auto", "ipopt"]
SLOW_SIZES = [
    (100, 1),
    pytest.param(100, 3, marks=pytest.mark.long),
    pytest.param(300, 1, marks=pytest.mark.long),
]  # 300 poses: a minute a case


def _sweep(model, N, seeds):
    """Both solvers at each random pose set, against one Clarabel reference per set."""
    mech = tolsynth.load_model(model)
    for seed in range(seeds):
        rng = np.random.default_rng(1000 * N + seed)
        poses = random_poses(mech, N, rng)
        for dist in ("uniform", "normal"):
            ref = clarabel_cost(mech, 0.5, 0.99, dist, 0.7, poses)
            for solver in SOLVERS:
                res = tolsynth.synthesize(
                    mech,
                    R=0.5,
                    p=0.99,
                    distribution=dist,
                    alpha=0.7,
                    poses=poses,
                    solver=solver,
                    probability="gaussian",
                )
                assert res.success, (model, N, seed, dist, solver, res.status, res.message)
                assert res.gap <= 1e-6 * res.cost
                assert_meets_spec(mech, res, 0.5, 0.99, dist, poses)
                if ref is not None:
                    assert res.cost == pytest.approx(ref, rel=1e-6), (model, N, seed, dist, solver)


@pytest.mark.parametrize("model", ["xu_zhang_1988", "puma560"])
@pytest.mark.parametrize("N,seeds", SIZES)
def test_random_pose_sets_agree_with_clarabel(model, N, seeds):
    _sweep(model, N, seeds)


@pytest.mark.slow
@pytest.mark.parametrize("model", ["xu_zhang_1988", "puma560"])
@pytest.mark.parametrize("N,seeds", SLOW_SIZES)
def test_random_pose_sets_agree_with_clarabel_large(model, N, seeds):
    _sweep(model, N, seeds)


def _grid(models, Rs, ps, alphas, solver):
    for model in models:
        mech = tolsynth.load_model(model)
        pose = reference_pose(mech)
        for R, p, a, d in itertools.product(Rs, ps, alphas, ("uniform", "normal")):
            try:
                res = tolsynth.synthesize(
                    mech, R=R, p=p, distribution=d, alpha=a, pose=pose, solver=solver, probability="gaussian"
                )
            except tolsynth.InfeasibleSpecificationError:
                # infeasible only if even the lower bounds fail (checked independently)
                spec = make_specification(mech, R, p, d, a, pose=pose)
                S = spec.blocks[0].A
                V = S @ np.diag(spec.lower**2 / spec.c) @ S.T
                assert math.sqrt(np.linalg.eigvalsh(V).max()) * spec.z / R > 1
                continue
            assert res.success, (model, R, p, a, d, res.message)
            assert_meets_spec(mech, res, R, p, d, [mech.joints(pose, check_limits=False)])
            assert res.gap <= 1e-6 * res.cost


@pytest.mark.parametrize("solver", SOLVERS)
def test_default_bounds_grid_where_upper_bounds_become_active(solver):
    """R up to 10 mm, p 0.5..0.9999, alpha 0.3..3 on every bundled model (upper bounds active)."""
    _grid(tolsynth.bundled_models(), [0.5, 10.0], [0.5, 0.9999], [0.3, 3.0], solver)


@pytest.mark.long  # 24 s; test_default_bounds_grid_where_upper_bounds_become_active is its smaller grid
@pytest.mark.parametrize("solver", SOLVERS)
def test_default_bounds_grid_full(solver):
    _grid(
        tolsynth.bundled_models(), [0.05, 0.5, 2.0, 5.0, 10.0], [0.5, 0.9, 0.99, 0.9999], [0.3, 0.7, 1.0, 3.0], solver
    )


@pytest.mark.parametrize("solver", SOLVERS)
def test_upper_bound_active_case_from_the_issue(solver):
    """planar_2r, R = 5 mm, p = 0.5, alpha 0.7 ended at the iteration limit with the factor form."""
    mech = tolsynth.load_model("planar_2r")
    res = tolsynth.synthesize(
        mech, R=5, p=0.5, alpha=0.7, pose=reference_pose(mech), solver=solver, probability="gaussian"
    )
    assert res.success and res.bounds_active
    ref = clarabel_cost(mech, 5, 0.5, "uniform", 0.7, [reference_pose(mech)])
    assert res.cost == pytest.approx(ref, rel=1e-6)


@pytest.mark.parametrize("solver", SOLVERS)
def test_extreme_scales_are_solved_not_misreported(solver):
    """k = 1e-3, R = 1000 mm, alpha 3, bounds 1e-12..1e6: reported optimal with gap/cost 1.0 before."""
    mech = tolsynth.load_model("planar_2r")
    pose = reference_pose(mech)
    res = tolsynth.synthesize(
        mech, R=1000, p=0.5, alpha=3, k=0.001, bounds=(1e-12, 1e6), pose=pose, solver=solver, probability="gaussian"
    )
    assert res.success and res.gap <= 1e-6 * res.cost
    assert res.max_constraint == pytest.approx(1.0, abs=1e-6)  # no bound active: the constraint binds
    from scipy.optimize import minimize

    spec = make_specification(mech, 1000, 0.5, "uniform", 3, k=0.001, bounds=(1e-12, 1e6), pose=pose)
    A = spec.blocks[0].scale * spec.blocks[0].A

    def f(u):
        return float(np.sum(spec.k * np.exp(-spec.alpha * u)))

    def g(u):
        V = A @ np.diag(np.exp(2 * u) / spec.c) @ A.T
        return 1.0 - np.linalg.eigvalsh(V).max()

    best = minimize(
        f,
        np.log(res.x) - 0.1,
        constraints=[{"type": "ineq", "fun": g}],
        method="SLSQP",
        bounds=list(zip(np.log(spec.lower), np.log(spec.upper))),
        options={"ftol": 1e-14, "maxiter": 500},
    )
    assert res.cost <= f(best.x) * (1 + 1e-6)


@pytest.mark.parametrize("solver", SOLVERS)
def test_loose_options_never_report_a_false_optimum(solver):
    """tol = 1 and constr_viol_tol = 1 used to give success with sigma z / R = 1.31."""
    res = tolsynth.synthesize(
        "xu_zhang_1988", R=0.5, p=0.99, options={"tol": 1, "constr_viol_tol": 1}, solver=solver, probability="gaussian"
    )
    if res.success:
        assert res.max_constraint <= 1 + 1e-6 and res.gap <= 1e-6 * res.cost
    else:
        assert res.status in set(tolsynth.Status) - {tolsynth.Status.OPTIMAL}


def test_infeasible_specification_still_raises():
    with pytest.raises(tolsynth.InfeasibleSpecificationError):
        tolsynth.synthesize("xu_zhang_1988", R=1e-4, p=0.99, probability="gaussian")


def test_sumt_accepts_specifications_close_to_their_limit():
    """R between the smallest feasible R0 and sqrt(2) R0 raised 'x0: not strictly inside' in SUMT."""
    mech = tolsynth.load_model("planar_2r")
    pose = reference_pose(mech)
    spec = make_specification(mech, 1.0, 0.99, "uniform", 0.7, pose=pose)
    A = spec.blocks[0].A
    V = A @ np.diag(spec.lower**2 / spec.c) @ A.T
    R0 = math.sqrt(np.linalg.eigvalsh(V).max()) * spec.z  # the smallest feasible R
    R = 1.2 * R0
    ipopt = tolsynth.synthesize(mech, R=R, p=0.99, pose=pose, solver="ipopt", probability="gaussian")
    sumt = tolsynth.synthesize(mech, R=R, p=0.99, pose=pose, solver="sumt", probability="gaussian")
    assert ipopt.success
    assert sumt.cost == pytest.approx(ipopt.cost, rel=1e-5)
