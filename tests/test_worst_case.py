"""The worst-case (arithmetic) stack-up: the exact zonotope maximum against brute force over all
2^n sign patterns, and the certified design against cvxpy + Clarabel with every sign pattern
enumerated as a second-order cone."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import tolsynth
from tolsynth.errors import InfeasibleSpecificationError, InputError
from tolsynth.solvers.worst_case_zonotope import zonotope_max, zonotope_patterns

cp = pytest.importorskip("cvxpy")


def brute_force(C):
    """max |C s| over all 2^n sign patterns."""
    S = np.array(list(itertools.product([-1.0, 1.0], repeat=C.shape[1])))
    V = S @ C.T
    return float(np.sqrt(np.max(np.einsum("ij,ij->i", V, V))))


def _case(rng, kind, n):
    C = rng.normal(size=(3, n))
    if kind == "planar":  # every column in one plane: every circle through the same two poles
        C[2] = 0.0
    elif kind == "parallel" and n > 1:
        C[:, 1] = -2.5 * C[:, 0]
    elif kind == "zero":
        C[:, 0] = 0.0
    elif kind == "coplanar" and n > 2:  # three circles through one vertex
        C[:, 2] = C[:, 0] + C[:, 1]
    elif kind == "scaled":
        C *= np.logspace(-6, 3, n)
    return C


@pytest.mark.parametrize("kind", ["generic", "planar", "parallel", "zero", "coplanar", "scaled"])
def test_zonotope_maximum_equals_brute_force(kind):
    rng = np.random.default_rng(abs(hash(kind)) % 2**32)
    for n in range(1, 13):
        for _ in range(4):
            C = _case(rng, kind, n)
            h, s, w = zonotope_max(C)
            b = brute_force(C)
            assert h == pytest.approx(b, rel=1e-12, abs=1e-300)
            assert np.linalg.norm(C @ s) == pytest.approx(h, rel=1e-12, abs=1e-300)
            if h > 0:
                assert np.linalg.norm(w) == pytest.approx(1.0)


def test_pattern_count_grows_as_n_squared_not_2_to_the_n():
    rng = np.random.default_rng(3)
    n = 40
    C = rng.normal(size=(3, n))
    vals, S = zonotope_patterns(C)
    assert len(S) <= 4 * n * (n - 1)  # four cells around each of the n(n-1) vertices
    # the arrangement of n generic great circles has n(n-1) + 2 cells: all of them found
    assert len(S) == n * (n - 1) + 2
    # 2^40 patterns cannot be checked; the ascent from random patterns never beats the maximum
    h = vals[0]
    for _ in range(200):
        s = np.sign(rng.normal(size=n))
        for _ in range(50):
            s = np.where(C.T @ (C @ s) >= 0, 1.0, -1.0)
        assert np.linalg.norm(C @ s) <= h * (1 + 1e-12)


def _cvxpy_cost(model, e):
    from tolsynth.model.cost import Chase, Exponential, PowerLaw

    if isinstance(model, PowerLaw):
        return model.k * cp.power(e, -model.alpha, approx=False)
    if isinstance(model, Chase):
        return model.A + model.B * cp.power(e, -model.k, approx=False)
    assert isinstance(model, Exponential)
    return model.A * cp.exp(-model.B * e)


def _cvxpy_worst_case(spec):
    """The same problem with every sign pattern of every block as a second-order cone."""
    n = spec.n
    eps = cp.Variable(n)
    cons = [eps >= spec.lower, eps <= spec.upper]
    for b in spec.blocks:
        limit = spec.R if b.kind == "position" else spec.Phi
        for s in itertools.product([-1.0, 1.0], repeat=n):
            cons.append(cp.norm(b.A @ cp.multiply(np.array(s), eps)) <= limit)
    cost = sum(_cvxpy_cost(model, eps[i]) for i, model in enumerate(spec.costs.models))
    prob = cp.Problem(cp.Minimize(cost), cons)
    prob.solve(solver="CLARABEL", tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10)
    assert prob.status == "optimal"
    return prob.value, eps.value


@pytest.mark.parametrize(
    "model,kw",
    [
        ("planar_2r", {"R": 0.5}),
        ("planar_2r", {"R": 0.5, "Phi": 0.0006}),  # the orientation block active as well
        ("planar_2r", {"R": 0.3, "poses": [[0.3, 1.2], [1.0, -2.0], [2.5, 0.4]]}),
        ("planar_2r", {"R": 0.5, "cost": "mixed"}),  # Chase's and the exponential model beside the power law
        pytest.param("xu_zhang_1988", {"R": 0.8}, marks=pytest.mark.slow),  # 11 parameters: 2048 cones, ~20 s
    ],
)
def test_design_matches_cvxpy_with_every_sign_pattern(model, kw):
    if kw.get("cost") == "mixed":
        from tolsynth.model.cost import Chase, Exponential

        kw = dict(kw, cost={"l1": Chase(0.5, 2.0, 1.0), "o1": Exponential(5.0, 2.0)})
    res = tolsynth.synthesize(model, probability="worst_case", **kw)
    assert res.success, res.message
    ref, eps_ref = _cvxpy_worst_case(res.spec)
    assert res.cost == pytest.approx(ref, rel=1e-6)
    np.testing.assert_allclose(res.x, eps_ref, rtol=1e-4)
    # the certificate brackets the independent optimum
    assert res.lower_bound <= ref * (1 + 1e-8)
    assert res.gap <= 1e-6 * res.cost
    # the returned point meets the worst case, checked over all 2^n patterns
    for b in res.spec.blocks:
        limit = res.spec.R if b.kind == "position" else res.spec.Phi
        assert brute_force(b.A * res.x) <= limit * (1 + 1e-6)


def test_paper_robot_worst_case_costs_about_69_percent_more_than_gaussian():
    res = tolsynth.synthesize("xu_zhang_1988", R=0.8, p=0.99, probability="worst_case")
    gauss = tolsynth.synthesize("xu_zhang_1988", R=0.8, p=0.99, probability="gaussian")
    assert res.success and gauss.success
    assert res.cost / gauss.cost == pytest.approx(1.685, abs=0.01)
    st = res.statistical
    assert st["p"] == 0.99 and st["cost"] is not None
    assert "worst case costs" in res.summary()
    again = tolsynth.synthesize("xu_zhang_1988", R=0.8, p=0.99, probability=st["probability"])
    assert st["cost"] == pytest.approx(again.cost, rel=1e-9)
    assert res.cost_ratio == pytest.approx(res.cost / again.cost, rel=1e-9)


def test_worst_case_design_meets_any_uniform_probability():
    # every error inside its band: a Monte Carlo of the linear model never leaves the ball
    res = tolsynth.synthesize("xu_zhang_1988", R=0.8, probability="worst_case")
    A = res.spec.blocks[0].A
    rng = np.random.default_rng(0)
    U = rng.uniform(-1, 1, size=(200_000, res.spec.n))
    d = np.linalg.norm((U * res.x) @ A.T, axis=1)
    assert d.max() <= 0.8 * (1 + 1e-9)
    assert res.statistical is None and "statistical" not in res.summary()


def test_every_bundled_model_default_pose():
    for name in tolsynth.bundled_models():
        m = tolsynth.load_model(name)
        pose = "worst" if "worst" in m.configurations else next(iter(m.configurations))
        res = tolsynth.synthesize(m, R=0.5, probability="worst_case", pose=pose)
        assert res.success, (name, res.message)
        assert res.gap <= 1e-6 * res.cost


@pytest.mark.slow  # 4-15 s: the default run stays under 4 minutes
def test_default_pose_on_a_model_without_a_worst_configuration():
    """The 3-RRR has no 'worst' configuration: the worst-case solve takes the pose the statistical
    solve takes by default (the pose search's), and its design meets R there over every sign
    pattern (brute force)."""
    m = tolsynth.load_model("planar_3rrr")
    assert "worst" not in m.configurations
    res = tolsynth.synthesize(m, R=0.5, probability="worst_case")
    stat = tolsynth.synthesize(m, R=0.5, p=0.99, probability="gaussian")
    assert res.success and res.gap <= 1e-6 * res.cost
    np.testing.assert_array_equal(res.spec.blocks[0].A, stat.spec.blocks[0].A)
    assert brute_force(res.spec.blocks[0].A * res.x) <= 0.5 * (1 + 1e-6)


def test_bad_inputs_are_typed():
    with pytest.raises(InputError, match="solver"):
        tolsynth.synthesize("planar_2r", R=0.5, probability="worst_case", solver="sumt")
    with pytest.raises(InputError, match="validate"):
        tolsynth.synthesize("planar_2r", R=0.5, p=0.9, probability="worst_case", validate=100)
    with pytest.raises(InputError, match="R"):
        tolsynth.synthesize("planar_2r", probability="worst_case")
    with pytest.raises(InputError):
        tolsynth.synthesize("planar_2r", R=0.5, probability="worst_case", options={"bogus": 1})
    with pytest.raises(InfeasibleSpecificationError, match="worst case"):
        tolsynth.synthesize("planar_2r", R=1e-4, probability="worst_case")
    for bad in ({"time_limit": "a"}, {"max_rounds": 0}, {"tol": -1.0}, {"cuts_per_round": 1.5}):
        with pytest.raises(InputError, match=list(bad)[0]):
            tolsynth.synthesize("planar_2r", R=0.5, probability="worst_case", options=bad)
    res = tolsynth.synthesize("planar_2r", R=0.5, probability="worst_case", options={"time_limit": 1e-9})
    assert not res.success and "time limit" in res.message  # out of time: never an optimum


def test_time_limit_reaches_the_worst_case_solve():
    """synthesize(time_limit=) bounds the worst-case solve as options['time_limit'] does: a limit
    far below the solve's time stops it honestly (not success, the message says so), measured by
    a clock outside the package; the same call without it succeeds; bad or doubled limits are typed."""
    import time

    free = tolsynth.synthesize("planar_2r", R=0.5, probability="worst_case")
    assert free.success
    t0 = time.perf_counter()
    res = tolsynth.synthesize("planar_2r", R=0.5, probability="worst_case", time_limit=1e-3)
    assert time.perf_counter() - t0 < 30.0
    assert not res.success and str(res.status) == "time_limit" and "time limit (0.001 s)" in res.message
    for bad in (-1.0, "a", 0.0):
        with pytest.raises(InputError, match="time_limit"):
            tolsynth.synthesize("planar_2r", R=0.5, probability="worst_case", time_limit=bad)
    with pytest.raises(InputError, match="time_limit"):
        tolsynth.synthesize("planar_2r", R=0.5, probability="worst_case", time_limit=5.0, options={"time_limit": 5.0})


def test_table_of_a_worst_case_design():
    pytest.importorskip("pandas")
    res = tolsynth.synthesize("planar_2r", R=0.5, p=0.9, probability="worst_case")
    frame = res.to_frame()
    assert list(frame["parameter"]) == list(res.tolerances)
    assert frame.attrs["inputs"]["probability"] == "worst_case"
    assert frame.attrs["summary"]["statistical"]["p"] == 0.9


def test_many_poses_with_orientation_on_a_six_joint_arm():
    from tolsynth.kinematics.joint_space import _limits

    m = tolsynth.load_model("puma560")
    lo, hi = _limits(m)
    lo, hi = np.maximum(lo, -3.0), np.minimum(hi, 3.0)
    rng = np.random.default_rng(0)
    poses = [lo + (hi - lo) * rng.uniform(0.05, 0.95, len(lo)) for _ in range(12)]
    res = tolsynth.synthesize(m, R=0.5, Phi=0.002, poses=poses, probability="worst_case")
    assert res.success, res.message
    assert res.gap <= 1e-6 * res.cost and len(res.constraints) == 24
    assert any(b.values[0] >= 1 - 1e-6 for b in res.constraints)  # the specification binds somewhere
    # no sign pattern beats the reported maximum: 2000 random patterns, each pushed up by ascent
    for b, c in zip(res.spec.blocks, res.constraints):
        C = b.A * res.x
        limit = res.spec.R if b.kind == "position" else res.spec.Phi
        for _ in range(100):
            s = np.sign(rng.normal(size=m.n))
            for _ in range(30):
                s = np.where(C.T @ (C @ s) >= 0, 1.0, -1.0)
            assert np.linalg.norm(C @ s) <= c.values[0] * limit * (1 + 1e-12)


def test_cli_refuses_a_shape_the_worst_case_would_ignore(capsys):
    """Without --p the worst case reads no error shape: --dist is refused (exit 2, one line naming
    it); with --p the statistical design beside it uses the shape, so it is accepted there."""
    from tolsynth.cli import main

    base = ["solve", "--model", "planar_2r", "--pose", "elbow90", "--R", "0.8", "--probability", "worst_case"]
    assert main(base + ["--dist", "normal"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--dist" in err[0] and "worst_case" in err[0], err
    assert main(base + ["--dist", "normal", "--p", "0.99"]) == 0
    assert "normal errors" in capsys.readouterr().out
