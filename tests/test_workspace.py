"""Worst-pose search and the workspace probability map (tolsynth.worst_pose, tolsynth.probability_map).

The map's reachable region is checked against a closed-form inverse kinematics of the
reconstructed robot written here (planar two-link arm to the wrist centre, law of cosines), and
the batched statistics against the package's one-pose analysis."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import tolsynth
from tolsynth import probability_map, worst_pose
from tolsynth.errors import InputError, OutOfRangeError, UnknownNameError
from tolsynth.kinematics.batch_stats import principal_std_batch
from tolsynth.probability.stats import p_ball_batch


# ---------------------------------------------------------------------------------------------
# closed-form inverse kinematics of xu_zhang_1988 with the hand roll axis vertical (up), theta1 = 0
# ---------------------------------------------------------------------------------------------
def closed_form_ik(x, z):
    """Joints (theta1, theta'2, theta2, theta4, theta5) in rad and the smallest distance to a
    limit (rad, < 0 outside; -inf out of reach) for the hand point (x, 0, z) mm.

    Wrist centre W = hand - 150 mm * Z0; shoulder S = (0, 200) mm; upper arm 600 mm at elevation
    e2 = 180 deg - theta2, forearm 800 mm at elevation e2 - gamma with the elbow angle
    gamma = theta'2 - theta2 (the parallelogram), hand vertical when theta4 = e2 - gamma.
    """
    dx, dz = x, z - 150.0 - 200.0
    c = (dx * dx + dz * dz - 600.0**2 - 800.0**2) / (2 * 600.0 * 800.0)
    if abs(c) > 1:
        return None, -math.inf
    g = math.acos(c)  # the elbow branch with gamma > 0: the other one violates 50 <= gamma <= 130 deg
    e2 = math.atan2(dz, dx) + math.atan2(800.0 * math.sin(g), 600.0 + 800.0 * math.cos(g))
    t2 = math.pi - e2
    tp2 = t2 + g
    t4 = e2 - g
    r = math.radians
    margin = min(
        t2 - r(50),
        r(130) - t2,
        tp2 - r(140),
        r(200) - tp2,
        (g - r(50)) / math.sqrt(2),
        (r(130) - g) / math.sqrt(2),
        t4 + r(110),
        r(110) - t4,
    )
    return np.array([0.0, tp2, t2, t4, 0.0]), margin


def test_closed_form_reproduces_the_paper_pose(xz):
    q, margin = closed_form_ik(925.0, 1225.0)
    assert np.allclose(q, xz.configurations["worst"], atol=1e-8)
    assert -0.01 < margin < 0  # 0.33 deg past the interference limit


# ---------------------------------------------------------------------------------------------
# batched statistics
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("N", [12, 300])  # CasADi's evaluation (small batches), the NumPy interpreter
def test_principal_std_batch_matches_analyze(xz, rng, N):
    from tolsynth.kinematics.batch_stats import SMALL_BATCH

    assert (N <= SMALL_BATCH) == (N == 12)
    lo = np.array([j.lower for j in xz.spec.joints])
    hi = np.array([j.upper for j in xz.spec.joints])
    Q = lo[:, None] + (hi - lo)[:, None] * rng.random((5, N))
    got = principal_std_batch(xz, Q, "figure3", "normal")
    for k in range(0, Q.shape[1], max(1, N // 12)):
        a = xz.analyze(Q[:, k], "figure3", "normal", check_limits=False)
        assert np.allclose(got[k], a.principal_std, rtol=1e-10, atol=1e-14)


# ---------------------------------------------------------------------------------------------
# worst pose
# ---------------------------------------------------------------------------------------------
def _feasible_random(xz, rng, n):
    lo = np.array([j.lower for j in xz.spec.joints])
    hi = np.array([j.upper for j in xz.spec.joints])
    Q = lo[:, None] + (hi - lo)[:, None] * rng.random((5, n))
    g = Q[1] - Q[2]
    return Q[:, (g >= math.radians(50)) & (g <= math.radians(130))]


def test_worst_pose_sigma_beats_the_paper_and_respects_limits(xz, rng):
    w = worst_pose(xz, "figure3", criterion="sigma", R=0.2)
    xz.joints(w.q)  # raises if a limit or the interference constraint is violated
    assert w.reference == "worst"
    assert np.allclose(w.reference_position, [925.0, 0.0, 1225.0], atol=1e-6)
    assert w.value >= w.reference_value  # at least as bad as the paper's pose
    assert w.value == pytest.approx(xz.analyze(w.q, "figure3").principal_std[0], rel=1e-10)
    assert w.reference_value == pytest.approx(xz.analyze("worst", "figure3").principal_std[0], rel=1e-10)
    assert set(w.held_joints) == {"theta1", "theta5"}  # found numerically: they do not matter
    # no random feasible pose is worse than the one found
    Q = _feasible_random(xz, rng, 20000)
    assert principal_std_batch(xz, Q, "figure3")[:, 0].max() <= w.value * (1 + 1e-9)
    assert any("interference" in a for a in w.active)
    text = w.report(xz.joint_names)
    assert "reference (worst)" in text and "925.000" in text
    json.dumps(w.to_dict())
    # without a reference pose the table has the found column only (no column of dashes and nan)
    bare = worst_pose(xz, "figure3", criterion="sigma", R=0.2, reference=None)
    assert bare.value == pytest.approx(w.value, rel=1e-9)
    text = bare.report(xz.joint_names)
    assert "reference" not in text and "nan" not in text and " -\n" not in text
    assert all(len(line) <= 22 + 42 for line in text.splitlines()[1:6]), text


def test_worst_pose_search_does_not_creep_along_a_ridge(monkeypatch):
    """The pattern search on puma560's exact single-pose design at step_tol 1e-7: a step only ever
    halved crept along a ridge of tiny gains for millions of polls (minutes); a run of successes now
    doubles it.  It ends within 200 000 evaluations (the guard raises past them), at a sigma_1 that
    NumPy's eigenvalues of the sensitivity give again, at least the coarse search's and no random
    feasible pose's exceeds."""
    import tolsynth.analysis.pose_search as ps

    m = tolsynth.load_model("puma560")
    eps = tolsynth.synthesize(m, R=0.5, p=0.99).x
    calls = [0]
    inner = ps._criterion_batch

    def guarded(mech, Q, *a, **k):
        calls[0] += Q.shape[1]
        if calls[0] > 200_000:
            raise RuntimeError("the pattern search crept on past 200 000 evaluations")
        return inner(mech, Q, *a, **k)

    monkeypatch.setattr(ps, "_criterion_batch", guarded)
    w = worst_pose(m, eps, step_tol=1e-7)
    monkeypatch.setattr(ps, "_criterion_batch", inner)
    A = m.sensitivity(w.q)[:3] * eps
    assert w.value == pytest.approx(math.sqrt(np.linalg.eigvalsh(A @ A.T / 3.0).max()), rel=1e-9)
    assert w.value >= worst_pose(m, eps, step_tol=1e-4).value * (1 - 1e-12)
    lo = np.array([j.lower for j in m.spec.joints])
    hi = np.array([j.upper for j in m.spec.joints])
    Q = lo[:, None] + (hi - lo)[:, None] * np.random.default_rng(3).random((len(lo), 5000))  # no constraints
    assert principal_std_batch(m, Q, eps)[:, 0].max() <= w.value * (1 + 1e-9)


def test_worst_pose_probability(xz, rng):
    w = worst_pose(xz, "figure3", criterion="probability", R=0.2, grid=12, starts=2)
    xz.joints(w.q)
    assert w.p_sphere <= w.reference_p_sphere
    assert w.value == pytest.approx(xz.analyze(w.q, "figure3", R=0.2).p_sphere, abs=1e-9)
    Q = _feasible_random(xz, rng, 3000)
    sig = principal_std_batch(xz, Q, "figure3")
    assert p_ball_batch(sig**2, 0.2).min() >= w.value - 1e-9


def test_worst_pose_errors(xz):
    with pytest.raises(OutOfRangeError, match="criterion"):
        worst_pose(xz, "figure3", criterion="largest")
    with pytest.raises(InputError, match="R"):
        worst_pose(xz, "figure3", criterion="probability")
    with pytest.raises(UnknownNameError):
        worst_pose(xz, "nope")
    with pytest.raises(UnknownNameError):
        worst_pose(xz, "figure3", fixed={"theta9": 0.0})


# ---------------------------------------------------------------------------------------------
# the map (Figure 3)
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def fig3map():
    xz = tolsynth.load_model("xu_zhang_1988")
    return xz, probability_map(xz, "figure3", R=0.2, distribution="uniform", n=40, progress=False)


def test_map_is_nan_exactly_outside_the_reachable_region(fig3map):
    xz, pm = fig3map
    checked_in = checked_out = 0
    for j, z in enumerate(pm.v):
        for i, x in enumerate(pm.u):
            q, margin = closed_form_ik(x, z)
            if margin > 0.01:  # clearly inside: reachable, and the same joints
                assert np.isfinite(pm.P[j, i]), (x, z)
                assert np.allclose(pm.Q[:, j, i], q, atol=1e-6)
                checked_in += 1
            elif margin < -0.01:  # clearly outside (past a limit, or out of reach)
                assert np.isnan(pm.P[j, i]), (x, z)
                assert np.all(np.isnan(pm.Q[:, j, i]))
                checked_out += 1
    assert checked_in > 300 and checked_out > 500
    assert pm.fixed["theta1"][0] == 0.0 and pm.fixed["theta5"][0] == 0.0
    assert pm.n_alternative_solutions == 0


@pytest.mark.parametrize(
    "x, z, reachable",
    [
        (925.0, 1200.0, True),
        (800.0, 800.0, True),
        (300.0, 600.0, False),
        (1300.0, 900.0, False),
        (600.0, 1550.0, False),
    ],
)
def test_map_points_checked_one_by_one(xz, x, z, reachable):
    pm = probability_map(xz, "figure3", R=0.2, n=5, extent=(x - 1, x + 1, z - 1, z + 1), progress=False)
    q, margin = closed_form_ik(x, z)
    assert (margin >= 0) == reachable
    assert bool(np.isfinite(pm.P[2, 2])) == reachable
    if reachable:
        assert pm.P[2, 2] == pytest.approx(xz.analyze(q, "figure3", "uniform", R=0.2).p_sphere, abs=1e-9)


def test_map_values_and_marks(fig3map):
    xz, pm = fig3map
    P = pm.P[np.isfinite(pm.P)]
    assert 0 < P.min() < P.max() < 1
    assert pm.worst[2] == pytest.approx(P.min())
    assert pm.reference_point == pytest.approx((925.0, 1225.0), abs=1e-6)
    assert pm.reference_P == pytest.approx(xz.analyze("worst", "figure3", R=0.2).p_sphere)
    # the paper's pose lies on the region's edge: some neighbours are reachable, some are not
    i = np.searchsorted(pm.u, 925.0)
    j = np.searchsorted(pm.v, 1225.0)
    block = np.isfinite(pm.P[j - 2 : j + 2, i - 2 : i + 2])
    assert block.any() and not block.all()


def test_map_figure(fig3map, tmp_path):
    pytest.importorskip("matplotlib")
    _, pm = fig3map
    out = tmp_path / "fig3.png"
    fig = pm.plot(out)
    assert out.stat().st_size > 20_000
    texts = " ".join(t.get_text() for t in fig.texts)
    assert "vertical" in texts and "interference" in texts and "branch" in texts
    ax = fig.axes[0]
    assert "mm" in ax.get_xlabel() and "mm" in ax.get_ylabel()


def test_map_errors(xz):
    with pytest.raises(OutOfRangeError, match="R"):
        probability_map(xz, R=0.0)
    with pytest.raises(OutOfRangeError, match="plane"):
        probability_map(xz, plane="xw")
    with pytest.raises(OutOfRangeError, match="n"):
        probability_map(xz, n=2)
    with pytest.raises(UnknownNameError, match="tolerance"):
        probability_map(xz, "nope")
    with pytest.raises(InputError, match="hand_axis"):
        probability_map(xz, hand_axis=(0, 0, 0))


def test_cli_map_and_worst_pose(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    from tolsynth.cli import main

    out = tmp_path / "map.png"
    rc = main(
        [
            "map",
            "--model",
            "xu_zhang_1988",
            "--tolerances",
            "figure3",
            "--dist",
            "uniform",
            "--R",
            "0.2",
            "--out",
            str(out),
            "--n",
            "30",
            "--json",
            "--quiet",
        ]
    )
    assert rc == 0 and out.exists()
    data = json.loads(capsys.readouterr().out)
    assert data["out"] == str(out) and len(data["P"]) == 30
    rc = main(["worst-pose", "--model", "xu_zhang_1988", "--tolerances", "figure3", "--R", "0.2", "--json"])
    assert rc == 0
    data = json.loads(capsys.readouterr().out)
    assert data["value"] >= data["reference_value"]
    rc = main(["map", "--model", "xu_zhang_1988", "--R", "-1", "--quiet"])
    assert rc == 2 and "R:" in capsys.readouterr().err


def test_full_resolution_map(xz):
    """The benchmark's map: reachable exactly where the closed form is (away from the edge), the
    same joints there, and P equal to the one-pose analysis at the closed-form joints."""
    pm = probability_map(xz, "figure3", R=0.2, n=100, progress=False)
    inside = 0
    for j in range(0, 100, 7):
        for i in range(0, 100, 7):
            q, margin = closed_form_ik(pm.u[i], pm.v[j])
            if abs(margin) > 0.005:
                assert np.isfinite(pm.P[j, i]) == (margin > 0)
            if margin > 0.005:
                inside += 1
                assert np.allclose(pm.Q[:, j, i], q, atol=1e-6)
                if inside % 4 == 0:
                    ref = xz.analyze(q, "figure3", R=0.2).p_sphere
                    assert pm.P[j, i] == pytest.approx(ref, abs=1e-9)
    assert inside > 50
    assert int(pm.reachable.sum()) == 3799  # the figure of the benchmark


# ---------------------------------------------------------------------------------------------
# the map's inverse kinematics internals
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("n", [1, 2, 3, 6])
def test_batched_cholesky_solve_against_numpy(n, rng):
    from tolsynth.kinematics.ik import _spd_solve

    M = rng.normal(size=(40, n, n))
    A = M @ M.transpose(0, 2, 1) + 1e-3 * np.eye(n)
    b = rng.normal(size=(40, n))
    x, ok = _spd_solve(A.transpose(1, 2, 0).copy(), b.T.copy())
    assert ok.all()
    assert np.allclose(x.T, np.linalg.solve(A, b[:, :, None])[:, :, 0], rtol=1e-9, atol=1e-12)
    A[3] = -np.eye(n)  # not positive definite: flagged
    A[5, 0, 0] = np.nan
    x, ok = _spd_solve(A.transpose(1, 2, 0).copy(), b.T.copy())
    assert not ok[3] and not ok[5] and ok[[0, 1, 2, 4]].all()


def test_ik_small_batches_by_casadi_as_large_by_numpy(xz, monkeypatch):
    """The IK's two evaluations of its residual graph (CasADi's VM for small batches, the NumPy
    interpreter for large ones) give the same solutions, which are the closed-form joints."""
    import tolsynth.kinematics.ik as ik

    pts = [(925.0, 1200.0), (800.0, 800.0), (700.0, 1300.0), (1000.0, 1000.0)]
    T = np.array([[x, 0.0, z] for x, z in pts]).T
    ev = ik._ik_evaluator(xz, (1, 2, 3), True)
    Q0 = np.repeat(xz.configurations["home"][:, None], len(pts), axis=1)
    axis = np.array([0.0, 0.0, 1.0])
    Qs, cs = ik._solve_ik(ev, (1, 2, 3), Q0, T, axis)
    monkeypatch.setattr(ik, "SMALL_BATCH", 0)
    Ql, cl = ik._solve_ik(ev, (1, 2, 3), Q0, T, axis)
    assert cs.all() and cl.all()
    assert np.allclose(Qs, Ql, rtol=0, atol=1e-9)
    for k, (x, z) in enumerate(pts):
        q, margin = closed_form_ik(x, z)
        assert np.allclose(ik._wrap(xz, Qs[:, [k]])[:, 0], q, atol=1e-6)


@pytest.mark.parametrize("model, kw", [("xu_zhang_1988", {"hand_axis": None}), ("planar_2r", {"plane": "xy"})])
def test_map_seeds_together_as_one_at_a_time(model, kw, monkeypatch):
    """The seeds run together on the points left give what they give one at a time (the map's
    earlier loop): same reachable set, joints, margins and alternative-solution count."""
    from tolsynth.kinematics.ik import _GridIK

    m = tolsynth.load_model(model)
    tol = "figure3" if model == "xu_zhang_1988" else "coarse"
    together = probability_map(m, tol, R=0.2, n=11, progress=False, **kw)
    monkeypatch.setattr(_GridIK, "seed_batch", 1)
    alone = probability_map(m, tol, R=0.2, n=11, progress=False, **kw)
    assert np.array_equal(together.reachable, alone.reachable) and together.reachable.any()
    assert together.n_alternative_solutions == alone.n_alternative_solutions
    assert np.allclose(together.Q, alone.Q, equal_nan=True, rtol=0, atol=1e-12)
    assert np.allclose(together.limit_margin, alone.limit_margin, equal_nan=True, rtol=0, atol=1e-12)
    assert np.allclose(together.P, alone.P, equal_nan=True, rtol=0, atol=1e-13)


# ---------------------------------------------------------------------------------------------
# synthesize_workspace: rounds, certificate and the largest value found
# afterwards, checked through a hand-written NumPy chain (central differences) at its own worst
# pose and at independently sampled poses
# ---------------------------------------------------------------------------------------------
def _chain_value(fk, mech, eps, q, R, p):
    """Largest sigma z / R at q from the hand-written NumPy kinematics (central differences)."""
    from test_kinematics import fd_sensitivity, fd_steps
    from tolsynth.probability.stats import z_of_p

    S = fd_sensitivity(fk, q, mech.error_parameters, fd_steps(mech))[:3]
    V = (S * (np.asarray(eps) ** 2 / 3.0)) @ S.T  # uniform: eps^2 / 3
    return math.sqrt(np.linalg.eigvalsh(V).max()) * z_of_p(p) / R


def _check_workspace_result(w, mech, fk, name, n_samples, R=0.5, p=0.99):
    from test_kinematics import random_q

    assert w.success and len(w.rounds) >= 2
    # the certificate: a lower bound below the cost with a small gap (the last solve's)
    assert w.lower_bound <= w.result.cost and w.gap == pytest.approx(w.result.cost - w.lower_bound, abs=1e-12)
    assert 0.0 <= w.gap <= 1e-6 * w.result.cost
    # the reported worst value is what the NumPy chain gives at the reported worst pose ...
    q_worst = np.asarray(w.rounds[-1]["worst_q"], dtype=float)
    assert _chain_value(fk, mech, w.result.x, q_worst, R, p) == pytest.approx(w.worst_value, rel=1e-6)
    # ... no independently sampled pose is worse, and the violation is within the exchange's tol
    rng = np.random.default_rng(8)
    sampled = max(_chain_value(fk, mech, w.result.x, random_q(name, rng), R, p) for _ in range(n_samples))
    assert sampled <= w.worst_value * (1 + 1e-6)
    assert w.max_violation == pytest.approx(max(0.0, w.worst_value - 1.0)) and w.max_violation <= 1e-3
    # every round's cost at least the first (poses are only added) and the summary reports it all
    assert all(r["cost"] >= w.rounds[0]["cost"] * (1 - 1e-9) for r in w.rounds)
    text = w.summary()
    assert f"{len(w.rounds)} round(s)" in text and "lower bound" in text and f"{w.gap:.2e}" in text
    assert f"{w.worst_value:.6f}" in text


@pytest.mark.slow  # 4-15 s: the default run stays under 4 minutes
def test_synthesize_workspace_reports_rounds_certificate_and_violation(xz, capsys):
    from test_kinematics import xu_fk

    w = tolsynth.synthesize_workspace(xz, 0.5, 0.99, "uniform", 0.7, probability="gaussian")
    _check_workspace_result(w, xz, xu_fk, "xu_zhang_1988", 400)
    # the command line prints the certificate and the largest value found afterwards
    from tolsynth.cli import main

    rc = main(
        [
            "solve",
            "--model",
            "xu_zhang_1988",
            "--R",
            "0.5",
            "--p",
            "0.99",
            "--dist",
            "uniform",
            "--everywhere",
            "--probability",
            "gaussian",
            "--json",
        ]
    )
    assert rc == 0
    data = json.loads(capsys.readouterr().out)
    # (a re-solve: the same optimum to the solver's tolerance, not bit for bit; the worst value is
    # a compass search's maximum of the largest sigma, which has a kink where two principal sigmas
    # meet, so two searches from optima 1e-10 apart may end 2e-7 apart: the final step is 1e-7 of
    # each joint's range, and the error at a kink is first order in it)
    assert data["worst_value"] == pytest.approx(w.worst_value, rel=1e-6)
    assert data["lower_bound"] == pytest.approx(w.lower_bound, rel=1e-7) and data["gap"] <= 1e-6 * data["cost"]
    rc = main(["solve", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.99", "--dist", "uniform", "--everywhere"])
    out = capsys.readouterr().out
    assert rc == 0 and "certificate: lower bound" in out and "largest value found anywhere" in out


@pytest.mark.slow
def test_synthesize_workspace_on_puma560():
    from test_kinematics import puma_fk

    puma = tolsynth.load_model("puma560")
    w = tolsynth.synthesize_workspace(puma, 0.5, 0.99, "uniform", 0.7, pose="qn", probability="gaussian")
    _check_workspace_result(w, puma, puma_fk, "puma560", 300)


def test_exact_workspace_design_labels_its_values_and_its_verdicts_agree():
    """An exact design for every pose of the planar arm (uniform errors): the table labels
    worst_value by the design's reading, and the value is that reading, the exact (1 - P)/(1 - p)
    along the worst direction, recomputed by FFT convolution (tests/independent.py); the summary's
    verdict on a value just above 1 names the exchange's tol, as the sampled check's line does, and
    to_dict is strict JSON with the same numbers."""
    from independent import independent_worst

    m = tolsynth.load_model("planar_2r")
    w = tolsynth.synthesize_workspace(m, R=0.5, p=0.99)
    quantity = "exact (1 - P)/(1 - p) along the worst direction"
    assert w.worst_quantity == quantity and w.to_frame().attrs["units"]["worst_value"] == quantity
    last = w.rounds[-1]
    A = np.asarray(m.sensitivity(last["worst_q"], check_limits=False))[:3]
    P, _ = independent_worst(A * w.result.x, 0.5, plane=True)
    v = w.worst_value
    assert v == pytest.approx((1 - P) / (1 - 0.99), abs=1e-4)
    assert w.converged and 1 < v <= 1 + 1e-3  # met to the exchange's tol, not within 1 itself
    line = next(s for s in w.summary().splitlines() if s.startswith("afterwards"))
    assert f"{v:.6f}: {v - 1:.2e} over 1, within the tolerance tol=0.001 of the specification" in line
    check = w.result.workspace.line()  # the sampled check, 300 poses: its own value just above 1 too
    assert 1 < w.result.workspace.worst <= 1 + 1e-3 and "within the tolerance 0.001 of the specification" in check
    d = json.loads(json.dumps(w.to_dict(), allow_nan=False))
    assert d["worst_value"] == v and d["tol"] == 1e-3 and d["worst_quantity"] == quantity
    assert d["result"]["cost"] == w.result.cost and d["result"]["tolerances"] == w.result.tolerances
    assert d["poses"] == [np.asarray(q, dtype=float).tolist() for q in w.poses] and len(d["rounds"]) == len(w.rounds)
    g = tolsynth.synthesize_workspace(m, R=0.5, p=0.99, probability="gaussian")
    assert g.to_frame().attrs["units"]["worst_value"] == "sigma z / R"


def test_binding_poses_with_an_orientation_limit_pair_each_block_with_its_pose(xz):
    """With Phi each imposed pose has a position and an orientation block.  The binding poses are
    those where z sigma_1 / R or z sigma_1 / Phi is at 1, by NumPy eigenvalues of S diag(eps^2/3)
    S^T at each pose (uniform errors); the orientation limit binds somewhere, so the case tests it."""
    from scipy.stats import norm

    w = tolsynth.synthesize_workspace(xz, 0.5, 0.99, "uniform", 0.7, Phi=0.002, probability="gaussian")
    assert w.converged and len(w.poses) > 2
    z, eps = norm.ppf(0.995), w.result.x
    values = []
    for q in w.poses:
        S = np.asarray(xz.sensitivity(q, check_limits=False))
        V = S @ np.diag(eps**2 / 3) @ S.T
        values.append(
            [
                z * math.sqrt(np.linalg.eigvalsh(V[:3, :3])[-1]) / 0.5,
                z * math.sqrt(np.linalg.eigvalsh(V[3:, 3:])[-1]) / 0.002,
            ]
        )
    values = np.array(values)
    assert np.any(values[:, 1] >= 1 - 1e-6)  # the orientation binds somewhere
    expected = [i for i in range(len(w.poses)) if values[i].max() >= 1 - 1e-6]
    got = [next(i for i, q in enumerate(w.poses) if q is b) for b in w.binding_poses]
    assert got == expected and len(expected) < len(w.poses)
