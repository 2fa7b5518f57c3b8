"""Contributor report, checked against sensitivities by central finite
differences of the forward kinematics (not the CasADi sensitivity the report uses) and against
finite differences of the error-controlled sphere probability stats.p_ball."""

import math

import numpy as np
import pytest

import tolsynth
from tolsynth.probability.stats import p_ball, principal


@pytest.fixture(scope="module")
def mech():
    return tolsynth.load_model("xu_zhang_1988")


@pytest.fixture(scope="module")
def optimum(mech):
    return tolsynth.synthesize(mech, R=0.5, p=0.99, distribution="uniform", alpha=0.7, probability="gaussian")


def _fd_position_sensitivity(mech, q, h=1e-6):
    n = mech.n
    cols = []
    for i in range(n):
        d = np.zeros(n)
        d[i] = h
        plus = mech.fk(q, d, check_limits=False)[:3, 3]
        minus = mech.fk(q, -d, check_limits=False)[:3, 3]
        cols.append((plus - minus) / (2 * h))
    return np.column_stack(cols)


def test_principal_variance_shares_against_finite_difference_sensitivities(mech, optimum):
    rep = tolsynth.contributions(optimum)
    assert rep.poses and rep.shares.shape == (len(rep.poses), mech.n, 3)
    np.testing.assert_allclose(rep.shares.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(rep.total_share.sum(axis=1), 1.0, atol=1e-12)
    q = optimum.spec.poses[rep.poses[0]]
    A = _fd_position_sensitivity(mech, q)
    eps = optimum.x
    y = eps**2 / 3.0
    V = (A * y) @ A.T
    sig, d = principal(V)
    np.testing.assert_allclose(rep.sigma[0], sig, rtol=1e-6)
    # share_ij sigma_j^2 = eps_i^2 (a_i . d_j)^2 / c with the FD a_i; where principal sigmas
    # coincide (two are active at the optimum) only the sum over that eigenspace is defined
    clusters = [[0]]
    for j in (1, 2):
        (clusters[-1].append(j) if abs(sig[j] - sig[clusters[-1][0]]) <= 1e-5 * sig[0] else clusters.append([j]))
    assert [len(c) for c in clusters] == [2, 1]  # the paper's optimum: sigma1 = sigma2 = R / z
    for cl in clusters:
        ref = sum(y * (d[:, j] @ A) ** 2 for j in cl)
        got = sum(rep.shares[0, :, j] * rep.sigma[0, j] ** 2 for j in cl)
        assert np.max(np.abs(got - ref)) < 1e-6 * np.max(ref)
    # at the paper's optimum the two largest principal sigmas are at the limit R / z
    assert rep.sigma[0, 0] == pytest.approx(0.5 / tolsynth.z_of_p(0.99), rel=1e-6)


def test_sphere_loss_shares_against_finite_differences_of_p_ball(mech, optimum):
    rep = tolsynth.contributions(optimum)
    A = optimum.spec.blocks[0].A
    eps = optimum.x

    def loss(e):
        lam = np.linalg.eigvalsh((A * e**2 / 3.0) @ A.T)
        return 1.0 - p_ball(np.clip(lam, 0, None), 0.5)

    h = 1e-5
    el = np.array(
        [
            (loss(eps * np.exp(h * np.eye(mech.n)[i])) - loss(eps * np.exp(-h * np.eye(mech.n)[i]))) / (2 * h)
            for i in range(mech.n)
        ]
    )
    np.testing.assert_allclose(rep.sphere_share[0], el / el.sum(), atol=1e-6)
    assert rep.P_sphere[0] == pytest.approx(1.0 - loss(eps), abs=1e-9)


def test_mechanism_input_table_and_plot(mech):
    pytest.importorskip("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    tol = {name: 0.1 for name in mech.error_parameters}
    rep = tolsynth.contributions(mech, tol, poses=["worst", mech.joints("home")], R=0.5)
    assert len(rep.poses) == 2 and len(rep.rows()) == 2 * mech.n
    assert set(rep.ranking(0)) == set(mech.error_parameters)
    text = rep.format()
    assert "1-P %" in text and mech.error_parameters[0] in text
    ax = rep.plot(1)
    assert len(ax.patches) == 4 * mech.n
    with pytest.raises(tolsynth.InputError, match="tolerances"):
        tolsynth.contributions(mech)
    with pytest.raises(tolsynth.OutOfRangeError, match="R"):
        tolsynth.contributions(mech, tol, R=-1.0)
    assert math.isclose(float(rep.shares[0, :, 2].sum()), 1.0)


def test_cli_contributions_and_lock(capsys):
    import json

    from tolsynth.cli import main

    assert (
        main(
            [
                "solve",
                "--model",
                "xu_zhang_1988",
                "--R",
                "0.5",
                "--p",
                "0.99",
                "--lock",
                "h3=0.2",
                "--contributions",
                "--json",
            ]
        )
        == 0
    )
    out = json.loads(capsys.readouterr().out)
    assert out["tolerances"]["h3"] == 0.2 and out["inputs"]["locks"] == {"h3": 0.2}
    rows = out["contributions"]["rows"]
    assert len(rows) == 11 and abs(sum(r["share_sigma1"] for r in rows) - 1) < 1e-12
    assert main(["solve", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.99", "--lock", "h3=5"]) == 2
    assert "locked tolerances ['h3']" in capsys.readouterr().err
    assert main(["solve", "--model", "xu_zhang_1988", "--R", "0.5", "--p", "0.99", "--lock", "h3"]) == 2


def test_mechanism_input_defaults_to_the_design_pose_and_bad_types_are_typed():
    delta = tolsynth.load_model("delta")  # no 'worst' configuration: the design pose is searched for
    res = tolsynth.synthesize(delta, R=0.5, p=0.99)
    (q,) = res.spec.poses.values()
    c = tolsynth.contributions(delta, res.tolerances)
    # the principal sigmas by hand at the pose synthesize designed at: V = A diag(eps^2 / 3) A^T
    A = delta.sensitivity(q, check_limits=False)[:3]
    V = (A * (res.x**2 / 3.0)) @ A.T
    np.testing.assert_allclose(np.sort(c.sigma[0]), np.sqrt(np.clip(np.linalg.eigvalsh(V), 0, None)), rtol=1e-9)
    with pytest.raises(tolsynth.InputError, match=r"^source: got dict .*contributions\(mechanism, tolerances\)"):
        tolsynth.contributions(res.tolerances, mechanism=delta)
    with pytest.raises(tolsynth.InputError, match=r"^mechanism: got str"):
        tolsynth.contributions(res, mechanism="delta", poses=[q])
