"""synthesize(..., probability="exact") and verify=, against the exact
probabilities recomputed independently (tolsynth.probability.exact, rigorous bounds), closed forms (all-normal
errors: the exact design is the Gaussian one), the nonlinear Monte Carlo, and SUMT + Powell."""

import math

import numpy as np
import pytest

import tolsynth
from tolsynth.analysis.verify import sample_size
from tolsynth.errors import InputError
from tolsynth.probability.exact import ball_probability, direction_probability

R = 0.5


def _wilson(k, n, z):
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return c - h, c + h


def _binding_direction_mc(m, r, n=200_000, seed=11):
    """Nonlinear Monte Carlo along the result's binding (worst) direction at its pose."""
    label, q = next(iter(r.spec.poses.items()))
    w = r.constraints[0].directions[:, 0]
    mc = tolsynth.monte_carlo(m, q, r.x, None, R=R, n=n, seed=seed, directions=w[:, None], confidence=0.99,
                              check_limits=False)
    return mc.p_directions[0], mc.p_directions_ci[0]


def test_exact_components_at_one_pose(xz):
    """p = 0.9, uniform (Table 2): every direction meets p by the exact probability recomputed
    outside the solver (2000 random directions + the binding one), the binding one is at p to 1e-6,
    and the nonlinear Monte Carlo along it contains p in its 99 % interval."""
    r = tolsynth.synthesize(xz, R=R, p=0.9, probability="exact")
    assert r.success, r.message
    A = xz.sensitivity(xz.joints("worst"))[:3]
    sh = ["uniform"] * xz.n
    rng = np.random.default_rng(5)
    D = rng.normal(size=(2000, 3))
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    assert direction_probability(D @ A * r.x, sh, R).min() >= 0.9 - 1e-7
    w = r.constraints[0].directions[:, 0]
    assert abs(direction_probability(w @ A * r.x, sh, R) - 0.9) <= 1e-6
    P, (lo, hi) = _binding_direction_mc(xz, r)
    assert lo <= 0.9 <= hi
    # the Gaussian design of the same column is off along that direction by more than the interval
    g = tolsynth.synthesize(xz, R=R, p=0.9)
    Pg = direction_probability(w @ A * g.x, sh, R)
    assert r.cost != pytest.approx(g.cost, rel=1e-3)
    assert r.lower_bound <= r.cost
    assert "no convexity certificate" in r.message
    assert abs(Pg - 0.9) > 1e-4  # the Gaussian design misses p along it (0.8995 here)


def test_all_normal_errors_give_the_gaussian_design(xz):
    """For normal errors the exact probabilities are the Gaussian ones: the two designs coincide."""
    g = tolsynth.synthesize(xz, R=R, p=0.99, distribution="normal")
    e = tolsynth.synthesize(xz, R=R, p=0.99, distribution="normal", probability="exact")
    assert e.success
    assert e.cost == pytest.approx(g.cost, rel=1e-6)
    np.testing.assert_allclose(e.x, g.x, rtol=1e-4)


@pytest.mark.slow
def test_exact_sphere(xz):
    """P(|dr| <= R) >= p exactly: the exact ball probability at the result is p (to its 1e-6
    accuracy), the Monte Carlo interval contains p, and the Gaussian design's exact P is not p."""
    r = tolsynth.synthesize(xz, R=R, p=0.9, criterion="sphere", probability="exact")
    assert r.success, r.message
    A = xz.sensitivity(xz.joints("worst"))[:3]
    P = ball_probability(A, r.x, ["uniform"] * xz.n, R, tol=1e-6)
    assert abs(P - 0.9) <= 2e-6
    mc = tolsynth.monte_carlo(xz, "worst", r.x, R=R, n=200_000, seed=2, confidence=0.99)
    assert mc.p_sphere_ci[0] <= 0.9 <= mc.p_sphere_ci[1]
    g = tolsynth.synthesize(xz, R=R, p=0.9, criterion="sphere")
    assert ball_probability(A, g.x, ["uniform"] * xz.n, R, tol=1e-6) > 0.9 + 5e-3


@pytest.mark.slow
def test_exact_at_several_poses(xz):
    qs = [xz.joints("worst"), xz.joints("home")]
    r = tolsynth.synthesize(xz, R=R, p=0.8, poses=qs, probability="exact")
    assert r.success, r.message
    for q in qs:
        A = xz.sensitivity(q, check_limits=False)[:3]
        from tolsynth.probability.exact import worst_direction

        assert worst_direction(A, r.x, ["uniform"] * xz.n, R)[1] >= 0.8 - 1e-7


def test_verify_closes_the_loop(xz):
    """The Gaussian Table 1 design (p = 0.99) is verified in one round; the exact p = 0.9 design,
    whose probability is exactly p, gets a raised target until the 99 % lower bound reaches p."""
    r = tolsynth.synthesize(xz, R=R, p=0.99, verify=True, seed=3)
    v = r.verification
    assert v.verified and len(v.rounds) == 1 and v.ci[0] >= 0.99
    assert v.n == sample_size(0.99) == math.ceil(2.5758293**2 * 0.99 * 0.01 / 0.001**2)
    e = tolsynth.synthesize(xz, R=R, p=0.9, probability="exact", verify=30_000, seed=3)
    v = e.verification
    assert v.verified and v.ci[0] >= 0.9 and v.p_target > 0.9
    assert e.cost > tolsynth.synthesize(xz, R=R, p=0.9, probability="exact").cost
    # the interval is the Wilson score interval of the reported estimate
    lo, hi = _wilson(round(v.achieved * v.n), v.n, 2.5758293)
    assert v.ci[0] == pytest.approx(lo, abs=1e-6) and v.ci[1] == pytest.approx(hi, abs=1e-6)
    assert "verified" in v.report()


def test_bad_input():
    with pytest.raises(InputError, match="probability"):
        tolsynth.synthesize("xu_zhang_1988", R=R, p=0.9, probability="exactly")


@pytest.mark.slow
def test_sumt_reads_the_same_graphs(xz):
    """SUMT + Powell on the same exact-probability graphs finds IPOPT's design (p = 0.9)."""
    a = tolsynth.synthesize(xz, R=R, p=0.9, probability="exact")
    b = tolsynth.synthesize(xz, R=R, p=0.9, probability="exact", solver="sumt")
    assert a.success and b.success
    assert b.cost == pytest.approx(a.cost, rel=1e-6)
    np.testing.assert_allclose(b.x, a.x, rtol=1e-4)


@pytest.mark.slow
@pytest.mark.parametrize("p", [0.7, 0.8, 0.9, 0.99])
def test_acceptance_uniform_columns_of_tables_1_2(xz, p):
    """The acceptance: the nonlinear Monte Carlo at the exact optimum contains p in its
    99 % interval along the binding direction (R = 0.5 mm, uniform, alpha 0.7)."""
    r = tolsynth.synthesize(xz, R=R, p=p, probability="exact")
    assert r.success, r.message
    P, (lo, hi) = _binding_direction_mc(xz, r, n=400_000)
    assert lo <= p <= hi


@pytest.mark.slow
def test_workspace_exact(xz):
    w = tolsynth.synthesize_workspace(xz, R, 0.99, probability="exact")
    assert w.converged and w.result.success
    assert w.rounds[-1]["worst_value"] <= 1 + 1e-3
    g = tolsynth.synthesize_workspace(xz, R, 0.99)
    assert w.result.cost < g.result.cost  # uniform errors at p = 0.99: the exact design is cheaper


def test_command_line_exact_and_verify(xz):
    """tolsynth solve --probability exact --json: its tolerances meet p along every direction by the
    exact probability recomputed here; a bad --verify exits 2 without a traceback."""
    import json
    import subprocess
    import sys

    from tolsynth.probability.exact import worst_direction

    out = subprocess.run([sys.executable, "-m", "tolsynth", "solve", "--model", "xu_zhang_1988", "--R", "0.5",
                          "--p", "0.8", "--probability", "exact", "--json"], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    d = json.loads(out.stdout)
    assert d["inputs"]["probability"] == "exact"
    eps = np.array([d["tolerances"][n] for n in xz.error_parameters])
    A = xz.sensitivity(xz.joints("worst"))[:3]
    assert abs(worst_direction(A, eps, ["uniform"] * xz.n, R)[1] - 0.8) <= 1e-6
    bad = subprocess.run([sys.executable, "-m", "tolsynth", "solve", "--model", "xu_zhang_1988", "--R", "0.5",
                          "--p", "0.8", "--verify", "12"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "Traceback" not in bad.stderr and "--verify" in bad.stderr
