"""The default engine (``solver="auto"``): the compiled interior-point method of
:mod:`tolsynth.solvers.fast`, checked against references that share none of its code.

Independent references:
* cvxpy + Clarabel on the convex form in ``v = eps^2`` (one 3x3 LMI per block, the power-law cost);
* IPOPT through CasADi on the cut NLP in ``u = ln eps`` (``solver="ipopt"``);
* NumPy: every block's covariance rebuilt from the model's sensitivities, its eigenvalues against
  ``(R/z)^2`` (position) or ``(Phi/z)^2`` (orientation).
"""

from __future__ import annotations

import numpy as np
import pytest

import tolsynth
from convex_reference import clarabel, random_poses
from tolsynth.errors import InputError
from tolsynth.kinematics.joint_space import _limits
from tolsynth.model.cost import Chase
from tolsynth.probability.stats import z_of_p
from tolsynth.problem.nlp import ToleranceNLP
from tolsynth.problem.specification import make_specification
from tolsynth.solvers import fast
from tolsynth.solvers.fast_ipm import kernel, kernel_status

cp = pytest.importorskip("cvxpy")
pytestmark = pytest.mark.skipif(kernel() is None, reason=f"no compiled kernel: {kernel_status()['reason']}")

R, P, ALPHA = 0.5, 0.99, 0.7


def assert_feasible(mech, res, tol=1e-9):
    """Every block's largest principal sigma times z over R (or Phi), rebuilt by NumPy from the
    model's own sensitivities at the result's poses, at most 1 + tol."""
    spec = res.spec
    eps = res.x
    for label, q in spec.poses.items():
        S = mech.sensitivity(q, check_limits=False) * spec.col_scale
        for rows, limit, p in ((S[:3], spec.R, spec.p), (S[3:], spec.Phi, spec.p_orientation)):
            if limit is None:
                continue
            V = rows @ np.diag(eps**2 / spec.c) @ rows.T
            assert np.sqrt(np.linalg.eigvalsh(V).max()) * z_of_p(p) / limit <= 1 + tol, label


def check(mech, res, ref_ipopt=None, rtol=1e-6):
    assert res.solver == "ipm", res.message
    assert res.success and res.gap <= 1e-9 * res.cost, res.message
    assert_feasible(mech, res)
    ref = clarabel(res.spec)
    if ref is not None:
        assert res.cost == pytest.approx(ref, rel=rtol)
    if ref_ipopt is not None:
        assert ref_ipopt.success
        # IPOPT stops at its own gap (up to 1e-6): the method's certified cost is never above it by more
        assert res.cost <= ref_ipopt.cost * (1 + 1e-9) and res.cost >= ref_ipopt.lower_bound * (1 - 1e-9)


@pytest.mark.parametrize(
    "model,N",
    [
        ("xu_zhang_1988", 1),
        ("xu_zhang_1988", 10),
        ("puma560", 3),
        ("puma560", 10),
        pytest.param("panda", 10, marks=pytest.mark.slow),
        pytest.param("puma560", 30, marks=pytest.mark.slow),
        pytest.param("ur5", 10, marks=pytest.mark.slow),
    ],
)
@pytest.mark.parametrize("distribution", ["uniform", "normal"])
def test_random_pose_sets_agree_with_clarabel_and_ipopt(model, N, distribution):
    mech = tolsynth.load_model(model)
    poses = random_poses(mech, N, seed=100 * N + len(model))
    res = tolsynth.synthesize(mech, R, P, distribution, ALPHA, poses=poses, probability="gaussian")
    check(
        mech,
        res,
        tolsynth.synthesize(mech, R, P, distribution, ALPHA, poses=poses, solver="ipopt", probability="gaussian"),
    )


def test_paper_column_and_every_kind_of_change():
    """The paper's column, then a change of each sweep parameter: k of one parameter, alpha (one
    per parameter), an active upper bound, a lock, R, p, the distribution and mixed shapes."""
    m = tolsynth.load_model("xu_zhang_1988")
    base = tolsynth.synthesize(m, R, P, "uniform", ALPHA, probability="gaussian")
    check(m, base, tolsynth.synthesize(m, R, P, "uniform", ALPHA, solver="ipopt", probability="gaussian"))
    names, eps = m.error_parameters, base.x
    j = int(np.argmax(eps))
    lo, _ = m.bounds
    cases = [
        dict(k={names[0]: 1.3 * m.k[0]}),
        dict(alpha=np.linspace(0.3, 3.0, m.n)),
        dict(bounds={names[j]: (lo[j], 0.8 * eps[j])}),
        dict(locks={names[0]: 0.9 * eps[0]}),
        dict(R=0.3),
        dict(p=0.95),
        dict(distribution="normal"),
        dict(distribution={"*": "uniform", names[0]: "normal", names[-1]: "triangular"}),
    ]
    for kw in cases:
        args = dict(R=R, p=P, distribution="uniform", alpha=ALPHA, probability="gaussian")
        args.update(kw)
        res = tolsynth.synthesize(m, **args)
        check(m, res, tolsynth.synthesize(m, **args, solver="ipopt"))
        if "bounds" in kw:
            assert res.bounds_active == {names[j]: "upper"}
            ip = tolsynth.synthesize(m, **args, solver="ipopt")
            # the bound's multiplier from the barrier against IPOPT's
            assert res.bound_multipliers[names[j]] == pytest.approx(ip.bound_multipliers[names[j]], rel=1e-4)


def test_orientation_blocks_and_the_second_mode():
    """Position and orientation blocks (Phi), alpha 3: here the first mode (y the Lagrangian's
    minimiser) stalls and the second (y an iterate of its own) solves it; both kernel modes, run
    directly, agree where both converge."""
    m = tolsynth.load_model("panda")
    res = tolsynth.synthesize(
        m, 0.3641602761279353, 0.99, "uniform", 3.0, pose="ready", Phi=0.0061938619557347745, probability="gaussian"
    )
    check(m, res)
    spec = make_specification(m, 0.5, 0.99, "uniform", 0.7, pose="ready", Phi=0.01)
    out = []
    for modes in ((False,), (True,)):
        saved = fast.MODES
        fast.MODES = modes
        try:
            r, why = fast.solve_fast(ToleranceNLP(spec))
        finally:
            fast.MODES = saved
        assert why is None, why
        out.append(r)
    assert out[0].cost == pytest.approx(out[1].cost, rel=1e-9)
    np.testing.assert_allclose(out[0].x, out[1].x, rtol=1e-4)
    check(m, out[0])


def test_extreme_scales_and_upper_bounds_active():
    """k = 1e-3, R = 1000 mm, alpha 3, bounds 1e-12..1e6 (cost scales far from 1); and R so large
    that every tolerance sits at its upper bound (no block active: the multipliers are 0)."""
    mech = tolsynth.load_model("planar_2r")
    res = tolsynth.synthesize(
        mech, R=1000, p=0.5, alpha=3, k=0.001, bounds=(1e-12, 1e6), pose="worst", probability="gaussian"
    )
    check(mech, res)
    top = tolsynth.synthesize(mech, R=1e4, p=0.5, alpha=0.7, pose="worst", probability="gaussian")
    assert top.solver == "ipm" and top.success
    np.testing.assert_array_equal(top.x, mech.bounds[1])
    assert set(top.bounds_active.values()) == {"upper"}
    # every tolerance locked: nothing to choose; the cost is k eps^-alpha at the locks
    locked = tolsynth.synthesize(
        mech,
        R=5.0,
        p=0.9,
        alpha=0.7,
        pose="worst",
        locks={n: 0.01 for n in mech.error_parameters},
        probability="gaussian",
    )
    assert locked.solver == "ipm" and locked.success and locked.gap == pytest.approx(0.0, abs=1e-12)
    assert locked.cost == pytest.approx(float(np.sum(mech.k * 0.01**-0.7)), rel=1e-12)


@pytest.mark.parametrize("all_blocks,N", [(8, 24), pytest.param(None, fast.ALL_BLOCKS + 72, marks=pytest.mark.slow)])
def test_many_blocks_working_set_cold_and_warm_agree(all_blocks, N, monkeypatch):
    """Above ALL_BLOCKS blocks the method works on a set of blocks (those near the worst at the
    start; with a warm start asked for, the active ones of the last solve of the same poses): a
    warm second solve starts from the first's active set and reaches the same certified optimum;
    the first, repeated after another problem ran, is the same again (results do not depend on
    what ran before).  By default with the threshold lowered to 8 blocks (the same code on a
    smaller problem)."""
    if all_blocks is not None:
        monkeypatch.setattr(fast, "ALL_BLOCKS", all_blocks)
    mech = tolsynth.load_model("puma560")
    poses = random_poses(mech, N, seed=5)
    cold = tolsynth.synthesize(mech, R, P, "uniform", ALPHA, poses=poses, probability="gaussian")
    assert cold.solver == "ipm" and cold.success and cold.gap <= 1e-9 * cold.cost, cold.message
    assert_feasible(mech, cold)
    warm = tolsynth.synthesize(
        mech, R, P, "uniform", ALPHA, poses=poses, options={"warm_start": True}, probability="gaussian"
    )
    assert warm.success and "1 round(s)" in warm.message, warm.message
    assert warm.cost == pytest.approx(cold.cost, rel=1e-9)
    np.testing.assert_allclose(warm.x, cold.x, rtol=1e-5)
    tolsynth.synthesize(mech, 0.7, 0.9, "normal", 1.0, poses=poses[: N // 2], probability="gaussian")
    again = tolsynth.synthesize(mech, R, P, "uniform", ALPHA, poses=poses, probability="gaussian")
    assert again.cost == cold.cost
    ref = clarabel(cold.spec)
    if ref is not None:
        assert cold.cost == pytest.approx(ref, rel=1e-6)


def test_falls_back_to_ipopt_where_it_does_not_apply(monkeypatch):
    """The sphere criterion and another cost model are not the method's class; without a compiled
    kernel IPOPT solves, says why, and finds the method's optimum."""
    m = tolsynth.load_model("xu_zhang_1988")
    sphere = make_specification(m, R, P, "uniform", ALPHA, criterion="sphere")
    assert fast.applies(ToleranceNLP(sphere)) == "the sphere criterion"
    chase = make_specification(m, R, P, "uniform", ALPHA, cost={"h2": Chase(A=1.0, B=2.0, k=1.5)})
    assert fast.applies(ToleranceNLP(chase)) == "a cost model other than the power law"
    res = tolsynth.synthesize(
        m, R, P, "uniform", ALPHA, cost={"h2": Chase(A=1.0, B=2.0, k=1.5)}, probability="gaussian"
    )
    assert res.solver == "ipopt" and "power law" in res.message and res.success
    fast_res = tolsynth.synthesize(m, R, P, "uniform", ALPHA, probability="gaussian")
    monkeypatch.setenv("TOLSYNTH_NO_COMPILE", "1")
    res = tolsynth.synthesize(m, R, P, "uniform", ALPHA, probability="gaussian")
    assert res.solver == "ipopt" and "TOLSYNTH_NO_COMPILE" in res.message and res.success
    assert fast_res.solver == "ipm" and fast_res.cost == pytest.approx(res.cost, rel=1e-6)


def test_other_probabilities_keep_their_solvers(monkeypatch):
    """solver='auto' is handed on to the exact probabilities (whose Gaussian start, and whole solve
    when every error is normal, it runs) and the worst case solves on as it always did."""
    from tolsynth.solvers import exact

    seen = []

    def spy(nlp, shapes, solver, *args, **kwargs):
        seen.append(solver)
        raise RuntimeError("stop here")

    monkeypatch.setattr(exact, "solve_exact", spy)
    with pytest.raises(RuntimeError, match="stop here"):
        tolsynth.synthesize("planar_2r", 5.0, 0.9, "uniform", 0.7, pose="worst", probability="exact")
    assert seen == ["auto"]
    wc = tolsynth.synthesize("planar_2r", 5.0, alpha=0.7, pose="worst", probability="worst_case")
    assert wc.success


def test_options():
    m = tolsynth.load_model("xu_zhang_1988")
    with pytest.raises(InputError):
        tolsynth.synthesize(m, R, P, "uniform", ALPHA, options={"no_such_option": 1}, probability="gaussian")
    # too few iterations for the method: IPOPT answers, certified
    res = tolsynth.synthesize(
        m, R, P, "uniform", ALPHA, options={"max_iter": 3, "warm_start": False}, probability="gaussian"
    )
    assert res.solver == "ipopt" and "interior-point method" in res.message
    tight = tolsynth.synthesize(m, R, P, "uniform", ALPHA, options={"tol": 1e-12}, probability="gaussian")
    assert tight.solver == "ipm" and tight.gap <= 1e-10 * tight.cost


def test_history_and_counts():
    m = tolsynth.load_model("xu_zhang_1988")
    res = tolsynth.synthesize(m, R, P, "uniform", ALPHA, options={"warm_start": False}, probability="gaussian")
    assert 5 <= res.iterations <= 60 and res.function_evaluations >= res.iterations
    assert res.history and res.history[-1]["inf_pr"] <= 1e-9
    assert res.history[-1]["objective"] == res.cost


def test_long_pose_lists_are_remembered_by_value():
    """A sweep re-solves the same poses: their checked joints and sensitivities are remembered per
    mechanism by the poses' values (read-only arrays, the same rows as a fresh evaluation); a
    changed pose is evaluated afresh, and a pose outside the limits still raises."""
    mech = tolsynth.load_model("puma560")
    poses = random_poses(mech, 12, seed=9)
    a = make_specification(mech, R, P, "uniform", ALPHA, poses=poses)
    b = make_specification(mech, 0.7, 0.9, "normal", ALPHA, poses=[q.copy() for q in poses])
    for ba, bb, q in zip(a.blocks, b.blocks, poses):
        assert ba.A is bb.A and not ba.A.flags.writeable
        np.testing.assert_array_equal(ba.A, mech.sensitivity(q)[:3])
    moved = [q.copy() for q in poses]
    moved[3][0] += 0.1
    c = make_specification(mech, R, P, "uniform", ALPHA, poses=moved)
    np.testing.assert_array_equal(c.blocks[3].A, mech.sensitivity(moved[3])[:3])
    assert not np.array_equal(c.blocks[3].A, a.blocks[3].A)
    lo, _ = _limits(mech)
    bad = [q.copy() for q in poses]
    bad[5][0] = lo[0] - 0.5
    with pytest.raises(tolsynth.OutOfRangeError):
        make_specification(mech, R, P, "uniform", ALPHA, poses=bad)


def test_sweep_steps_start_warm_and_reach_the_cold_optimum():
    """A step of a sweep (k, alpha, a bound, a lock, R, p: a few per mille to a per cent) asked to
    warm-start starts from the last solve of the same blocks: fewer iterations than the default
    cold start, the same certified optimum (1e-9) as the cold start and as IPOPT (1e-6)."""
    m = tolsynth.load_model("xu_zhang_1988")
    base = tolsynth.synthesize(m, R, P, "uniform", ALPHA, probability="gaussian")
    names, eps = m.error_parameters, base.x
    lo, _ = m.bounds
    j = int(np.argmax(eps))
    steps = [
        ({}, dict(k={names[0]: 1.01 * m.k[0]})),
        ({}, dict(alpha=ALPHA + 0.002)),
        (dict(bounds={names[j]: (lo[j], 0.8 * eps[j])}), dict(bounds={names[j]: (lo[j], 0.802 * eps[j])})),
        (dict(locks={names[0]: 0.9 * eps[0]}), dict(locks={names[0]: 0.902 * eps[0]})),
        ({}, dict(R=R * 1.002)),
        ({}, dict(p=P - 0.0002)),
    ]
    for before, kw in steps:
        args = dict(R=R, p=P, distribution="uniform", alpha=ALPHA, probability="gaussian")
        tolsynth.synthesize(m, **args, **before)  # the sweep's previous step
        args.update(kw)
        warm = tolsynth.synthesize(m, **args, options={"warm_start": True})
        cold = tolsynth.synthesize(m, **args)
        assert warm.history[0]["mode"] == "warm minimiser" and cold.history[0]["mode"] == "minimiser", kw
        assert warm.success and cold.success
        assert warm.iterations < cold.iterations, (kw, warm.iterations, cold.iterations)
        assert warm.cost == pytest.approx(cold.cost, rel=1e-9)
        np.testing.assert_allclose(warm.x, cold.x, rtol=1e-5)
        assert warm.cost == pytest.approx(tolsynth.synthesize(m, **args, solver="ipopt").cost, rel=1e-6)
    # far from the remembered problem (alpha 0.7 -> 3): no warm start (it would cost iterations)
    far = tolsynth.synthesize(m, R, P, "uniform", 3.0, probability="gaussian", options={"warm_start": True})
    assert far.history[0]["mode"] == "minimiser" and far.success


def test_the_same_problem_again_takes_no_iteration():
    """A re-solve of the very same specification asked to warm-start starts at the remembered
    optimum unshifted: no iteration, the same certified answer as the (cold) first solve."""
    m = tolsynth.load_model("xu_zhang_1988")
    first = tolsynth.synthesize(m, R, P, "uniform", ALPHA, probability="gaussian")
    again = tolsynth.synthesize(m, R, P, "uniform", ALPHA, probability="gaussian", options={"warm_start": True})
    assert first.iterations > 0
    assert again.iterations == 0 and again.success and again.cost == first.cost
