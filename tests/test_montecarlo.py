"""Monte Carlo through the nonlinear kinematics (tolsynth.analysis.montecarlo), checked against an
independent sampler written here: plain NumPy forward kinematics of the reconstructed robot
(docs/reconstruction.md), including the parallelogram loop, with its own random numbers."""

from __future__ import annotations

import json
import math
import tracemalloc
from statistics import NormalDist

import casadi as ca
import numpy as np
import pytest

from tolsynth.analysis.montecarlo import NumpyEvaluator, monte_carlo, wilson_interval
from tolsynth.analysis.validation import validate
from tolsynth.errors import InputError, OutOfRangeError, UnknownNameError
from tolsynth.kinematics.mechanism import load_model

Z999 = NormalDist().inv_cdf(0.9995)  # two-sided 99.9 %

# ---------------------------------------------------------------------------------------------
# the independent sampler: the paper's numbers, modified D-H, parallelogram loop, nothing from tolsynth
# ---------------------------------------------------------------------------------------------
# joint values of the worst pose as docs/reconstruction.md gives them (theta1 = 180 deg there)
WORST_DEG = (180.0, 157.6451903, 107.97116143, 22.3548097, 0.0)
# Figure 3 half-tolerances (mm, rad), in the order h2(=h'1), h3, h4, h'2, h'3, h'4, s1, a, alpha1, alpha3, alpha4
FIG3 = np.array([0.06, 0.08, 0.01, 0.028, 0.06, 0.028, 0.01, 0.015, 0.0005, 0.0005, 0.0005])


def _mdh(h, alpha, s, theta):
    """Batched modified D-H transform Tx(h) Rx(alpha) Tz(s) Rz(theta), shape (B, 4, 4)."""
    B = np.broadcast(h, alpha, s, theta).shape[0]
    ct, st, ca_, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    T = np.zeros((B, 4, 4))
    T[:, 0, 0], T[:, 0, 1], T[:, 0, 3] = ct, -st, h
    T[:, 1, 0], T[:, 1, 1], T[:, 1, 2], T[:, 1, 3] = st * ca_, ct * ca_, -sa, -s * sa
    T[:, 2, 0], T[:, 2, 1], T[:, 2, 2], T[:, 2, 3] = st * sa, ct * sa, ca_, s * ca_
    T[:, 3, 3] = 1.0
    return T


def independent_positions(q_deg, d):
    """Hand positions (B, 3) mm for error samples d (B, 11) in mm and rad, and a closure flag."""
    B = d.shape[0]
    t1, tp2, t2, t4, t5 = np.radians(q_deg)
    h2 = 600.0 + d[:, 0]
    hp1 = 600.0 + d[:, 0]  # the same part
    h3 = 800.0 + d[:, 1]
    h4 = 0.0 + d[:, 2]
    hp2, hp3, hp4 = 280.0 + d[:, 3], 600.0 + d[:, 4], 280.0 + d[:, 5]
    s1, a = 0.0 + d[:, 6], 150.0 + d[:, 7]
    al1, al3, al4 = math.pi / 2 + d[:, 8], 0.0 + d[:, 9], math.pi / 2 + d[:, 10]
    # parallelogram: lever direction psi (from X1) with |E + hp4 u(psi) - C| = hp3, root next to theta'2
    E = np.stack([hp1 * math.cos(t2), hp1 * math.sin(t2)])
    C = np.stack([hp2 * math.cos(tp2), hp2 * math.sin(tp2)])
    dv = E - C
    dn = np.hypot(dv[0], dv[1])
    K = (hp3**2 - dn**2 - hp4**2) / (2 * hp4)
    closes = np.abs(K / dn) <= 1
    base = np.arctan2(dv[1], dv[0])
    roots = np.stack([base + np.arccos(np.clip(K / dn, -1, 1)), base - np.arccos(np.clip(K / dn, -1, 1))])
    off = np.abs((roots - tp2 + np.pi) % (2 * np.pi) - np.pi)
    psi = np.where(off[0] <= off[1], roots[0], roots[1])
    t3 = psi - t2
    z = np.zeros(B)
    T = np.tile(np.eye(4), (B, 1, 1))
    T[:, 2, 3] = 200.0  # s0
    T = T @ _mdh(z, z, s1, np.full(B, t1))
    T = T @ _mdh(z, al1, z, np.full(B, t2))
    T = T @ _mdh(h2, z, z, t3)
    T = T @ _mdh(h3, al3, z, np.full(B, t4))
    T = T @ _mdh(h4, al4, a, np.full(B, t5))
    return T[:, :3, 3], closes


def independent_sampler(n, seed, chunk=250_000, R=0.2):
    rng = np.random.default_rng(seed)
    p0, _ = independent_positions(WORST_DEG, np.zeros((1, 11)))
    inside, s1, s2 = 0, np.zeros(3), np.zeros((3, 3))
    for a in range(0, n, chunk):
        b = min(chunk, n - a)
        d = rng.uniform(-1.0, 1.0, size=(b, 11)) * FIG3
        p, closes = independent_positions(WORST_DEG, d)
        assert closes.all()
        dr = p - p0
        inside += int(np.count_nonzero(np.einsum("bi,bi->b", dr, dr) <= R * R))
        s1 += dr.sum(axis=0)
        s2 += dr.T @ dr
    mean = s1 / n
    return inside / n, (s2 - n * np.outer(mean, mean)) / (n - 1), p0[0]


# ---------------------------------------------------------------------------------------------
# the NumPy interpreter of CasADi graphs
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("graph", ["position", "fk", "closure", "sensitivity"])
def test_evaluator_matches_casadi(xz, graph, rng):
    f = getattr(xz.graphs, graph)
    ev = NumpyEvaluator(f)
    B = 64
    Q = np.radians([0, 160, 100, 20, 10])[:, None] + rng.normal(0, 0.2, (5, B))
    D = rng.normal(0, 1, (11, B))
    rows, cols = f.size_out(0)
    ref = np.array(f.map(B)(Q, D)).reshape(rows, B, cols).transpose(0, 2, 1)
    got = ev.dense(0, ev([Q, D])[0])
    assert np.allclose(got, ref, rtol=1e-12, atol=1e-9)
    # joints fixed, errors batched (the Monte Carlo case): the fixed part is evaluated once
    ref1 = np.array(f.map(B)(np.repeat(Q[:, :1], B, 1), D)).reshape(rows, B, cols).transpose(0, 2, 1)
    assert np.allclose(ev.dense(0, ev([Q[:, 0], D])[0]), ref1, rtol=1e-12, atol=1e-9)


def test_evaluator_covers_operations(rng):
    x = ca.SX.sym("x", 3)
    exprs = [
        ca.atan2(x[0], x[1]),
        ca.if_else(x[0] > 0, x[1], 3.0),
        ca.fabs(x[0]) ** 2.5,
        ca.fmin(x[0], x[2]),
        ca.sqrt(ca.fabs(x[2])) / (1 + x[1] ** 2),
        ca.acos(ca.tanh(x[0])),
        ca.exp(-(x[1] ** 2)) * ca.log(2 + x[2]),
        ca.floor(x[0]) + ca.sign(x[1]) - ca.fmax(x[0], x[1]) * 2,
    ]
    f = ca.Function("f", [x], [ca.vertcat(*exprs)])
    X = rng.normal(0, 1, (3, 100))
    got = NumpyEvaluator(f)([X])[0]
    assert np.allclose(got, np.array(f.map(100)(X)), rtol=1e-12, atol=1e-12, equal_nan=True)


def test_evaluator_rejects_mx():
    x = ca.MX.sym("x")
    with pytest.raises(InputError, match="SX"):
        NumpyEvaluator(ca.Function("g", [x], [x * 2]))


# ---------------------------------------------------------------------------------------------
# Monte Carlo against the independent sampler (the acceptance check)
# ---------------------------------------------------------------------------------------------
def test_independent_sampler_reproduces_the_paper_pose():
    p0, closes = independent_positions(WORST_DEG, np.zeros((1, 11)))
    assert closes.all()
    assert np.allclose(p0[0], [925.0, 0.0, 1225.0], atol=1e-4)


def test_monte_carlo_matches_independent_sampler(xz):
    n_mc, n_ind = 2_000_000, 1_000_000
    r = monte_carlo(xz, "worst", "figure3", "uniform", R=0.2, n=n_mc, seed=11)
    p_ind, cov_ind, p0 = independent_sampler(n_ind, seed=20261121)
    assert np.allclose(r.position, p0, atol=1e-6)
    # the two estimates differ by sampling noise only: 99.9 % interval of the difference
    se = math.sqrt(r.p_sphere * (1 - r.p_sphere) / n_mc + p_ind * (1 - p_ind) / n_ind)
    print(
        f"\nP(|dr| <= 0.2 mm), figure3, uniform, worst pose: tolsynth MC {r.p_sphere:.5f} "
        f"[{r.p_sphere_ci[0]:.5f}, {r.p_sphere_ci[1]:.5f}], independent {p_ind:.5f}, "
        f"analytic (linear, exact) {r.p_sphere_analytic:.5f}"
    )
    assert abs(r.p_sphere - p_ind) <= Z999 * se
    # and the independent value lies inside the Monte Carlo interval widened to 99.9 %
    lo, hi = wilson_interval(round(r.p_sphere * n_mc), n_mc, 0.999)
    assert (
        lo - Z999 * math.sqrt(p_ind * (1 - p_ind) / n_ind)
        <= p_ind
        <= hi + Z999 * math.sqrt(p_ind * (1 - p_ind) / n_ind)
    )
    # covariances agree to sampling noise (sd of a sample covariance <= sqrt(2 V_ii V_jj / n))
    noise = np.sqrt(2 * np.outer(np.diag(cov_ind), np.diag(cov_ind)) * (1 / n_mc + 1 / n_ind))
    assert np.all(np.abs(r.covariance - cov_ind) <= 5 * noise)
    # the linear model's exact sphere probability (the default reading) is the sampled one to the
    # nonlinearity's size; its Gaussian approximation is far off here (alpha1 alone sets the y
    # error, uniform), and a run in that reading says so rather than hiding it
    assert r.analytic == "exact" and abs(r.p_sphere_analytic - p_ind) <= 2e-3
    g = monte_carlo(xz, "worst", "figure3", "uniform", R=0.2, n=n_ind, seed=12, analytic="gaussian")
    assert g.p_sphere_analytic == pytest.approx(xz.analyze("worst", "figure3", "uniform", R=0.2).p_sphere)
    assert not g.p_sphere_analytic_in_ci
    assert g.p_sphere < g.p_sphere_analytic - 0.05
    assert r.kurtosis[0] < -1.0  # w1 = y: nearly one uniform source (excess kurtosis -1.2)
    assert r.n_loop_failures == 0


def test_normal_errors_agree_with_the_analytic_model(xz):
    """For normal errors the analytic model is exact up to the (tiny) nonlinearity."""
    r = monte_carlo(xz, "worst", "figure3", "normal", R=0.2, n=1_000_000, seed=5)
    assert r.p_sphere_analytic_in_ci
    assert np.all(r.p_components_analytic_in_ci)
    assert np.all(np.abs(r.kurtosis) < 5 * r.kurtosis_se)
    assert np.allclose(r.principal_std, r.principal_std_analytic, rtol=2e-3)


def test_same_seed_same_numbers_and_seeds_agree(xz):
    a = monte_carlo(xz, "worst", "figure3", R=0.2, n=300_000, seed=1)
    b = monte_carlo(xz, "worst", "figure3", R=0.2, n=300_000, seed=1)
    c = monte_carlo(xz, "worst", "figure3", R=0.2, n=300_000, seed=2)
    assert a.seed == 1 and c.seed == 2
    assert a.p_sphere == b.p_sphere
    assert np.array_equal(a.p_components, b.p_components)
    assert np.array_equal(a.covariance, b.covariance)
    assert a.p_sphere != c.p_sphere
    se = math.sqrt(2 * a.p_sphere * (1 - a.p_sphere) / a.n)
    assert abs(a.p_sphere - c.p_sphere) <= Z999 * se
    assert c.p_sphere_ci[0] <= a.p_sphere_ci[1] and a.p_sphere_ci[0] <= c.p_sphere_ci[1]
    for j in range(3):
        pj = a.p_components[j]
        assert abs(pj - c.p_components[j]) <= Z999 * math.sqrt(2 * pj * (1 - pj) / a.n) + 1e-12


def test_memory_is_independent_of_n(xz):
    monte_carlo(xz, "worst", "figure3", R=0.2, n=10_000, seed=0, batch=8192)  # warm caches
    peaks = []
    for n in (50_000, 800_000):
        tracemalloc.start()
        monte_carlo(xz, "worst", "figure3", R=0.2, n=n, seed=0, batch=8192)
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    assert peaks[1] < 1.25 * peaks[0] + 1e6  # 16 x the samples, same peak
    assert peaks[1] < 64e6  # a few tens of bytes per sample per batch, not per n


def test_covariance_approaches_the_linear_model(xz):
    """Same random numbers at every scale: what changes is the nonlinearity only."""
    eps = xz.tolerances("figure3")
    dev = {}
    for s in (100.0, 1.0, 0.01):
        r = monte_carlo(xz, "worst", eps * s, "uniform", R=0.2 * s, n=200_000, seed=5)
        dev[s] = np.linalg.norm(r.covariance - r.covariance_analytic) / np.linalg.norm(r.covariance_analytic)
    noise = 4 * math.sqrt(2 / 200_000)
    assert dev[0.01] < noise
    assert dev[100.0] > dev[0.01] + 1e-4  # visible nonlinearity at 100 x the Figure 3 tolerances
    assert abs(dev[1.0] - dev[0.01]) < 1e-5  # none left at the Figure 3 tolerances


def test_loop_failures_are_counted_not_dropped(xz):
    eps = xz.tolerances("figure3")
    eps[xz.index("hp3")] = 300.0  # coupler +-300 mm: the parallelogram often cannot close
    # (R = 50 mm: stats.p_ball is slow for R far below the largest sigma)
    r = monte_carlo(xz, "worst", eps, R=50.0, n=50_000, seed=4)
    assert 0 < r.n_loop_failures < r.n
    assert r.n == 50_000
    assert r.p_sphere <= (r.n - r.n_loop_failures) / r.n  # failures count as outside


def test_orientation_probabilities(xz):
    r = monte_carlo(xz, "worst", "figure3", "normal", R=0.2, n=400_000, seed=8, Phi=0.0005)
    lo, hi = r.p_cone_ci
    assert lo - 0.002 <= r.p_cone_analytic <= hi + 0.002
    assert np.allclose(r.p_orientation_components, r.p_orientation_components_analytic, atol=0.003)


def test_report_and_dict(xz):
    r = monte_carlo(xz, "worst", "figure3", R=0.2, n=20_000, seed=3, analytic="gaussian")
    text = r.report()
    assert "analytic outside CI" in text and "Wilson" in text and "kurtosis" in text
    d = r.to_dict()
    json.dumps(d)
    for key in (
        "p_sphere",
        "p_sphere_ci",
        "p_components",
        "covariance",
        "n",
        "seed",
        "p_sphere_analytic",
        "p_components_analytic",
        "covariance_analytic",
    ):
        assert key in d


# ---------------------------------------------------------------------------------------------
# validation of an optimum
# ---------------------------------------------------------------------------------------------
class _FakeResult:
    def __init__(self, tolerances):
        self.tolerances = tolerances
        self.R = 0.5
        self.p = 0.9
        self.distribution = "uniform"


def test_validate_accepts_dicts_and_result_objects(xz):
    tol = dict(zip(xz.error_parameters, xz.tolerances("figure3").tolist()))
    a = validate(xz, tol, R=0.5, p=0.9, n=100_000, seed=2)
    b = validate(xz, _FakeResult(tol), n=100_000, seed=2)
    assert np.array_equal(a.p_components, b.p_components) and a.p_sphere == b.p_sphere
    assert np.array_equal(a.components_met, a.p_components >= 0.9)
    assert a.montecarlo.n == 100_000
    json.dumps(a.to_dict())
    assert "validation" in a.report()


def test_validate_needs_R_and_p(xz):
    with pytest.raises(InputError, match="R"):
        validate(xz, "figure3", p=0.9, n=10)
    with pytest.raises(OutOfRangeError, match="p"):
        validate(xz, "figure3", R=0.5, p=1.5, n=10)


# ---------------------------------------------------------------------------------------------
# errors, intervals, command line
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"n": 0}, "n"),
        ({"n": -5}, "n"),
        ({"n": 2.5}, "n"),
        ({"R": 0.0}, "R"),
        ({"R": -1.0}, "R"),
        ({"seed": -1}, "seed"),
        ({"distribution": "lognormal"}, "distribution"),
        ({"batch": 0}, "batch"),
    ],
)
def test_bad_input_names_the_field(xz, kwargs, field):
    args = dict(q="worst", tolerances="figure3", R=0.2, n=100, seed=0)
    args.update(kwargs)
    with pytest.raises(OutOfRangeError) as exc:
        monte_carlo(xz, **args)
    assert exc.value.field == field
    assert exc.value.allowed


def test_unknown_tolerance_set(xz):
    with pytest.raises(UnknownNameError, match="figure3"):
        monte_carlo(xz, "worst", "nope", R=0.2, n=10)


def test_wilson_interval_against_scipy():
    stats = pytest.importorskip("scipy.stats")
    for k, n in ((0, 50), (3, 50), (25, 50), (50, 50), (123456, 1_000_000)):
        ci = stats.binomtest(k, n).proportion_ci(0.95, method="wilson")
        assert np.allclose(wilson_interval(k, n, 0.95), [ci.low, ci.high], atol=1e-12)


def test_cli_montecarlo_json(capsys):
    from tolsynth.cli import main

    rc = main(
        [
            "montecarlo",
            "--model",
            "xu_zhang_1988",
            "--tolerances",
            "figure3",
            "--dist",
            "uniform",
            "--R",
            "0.2",
            "--n",
            "50000",
            "--seed",
            "3",
            "--json",
        ]
    )
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    for key in (
        "p_sphere",
        "p_sphere_ci",
        "p_components",
        "covariance",
        "n",
        "seed",
        "p_sphere_analytic",
        "p_components_analytic",
        "covariance_analytic",
        "n_loop_failures",
        "kurtosis",
    ):
        assert key in out
    assert out["n"] == 50000 and out["seed"] == 3
    rc = main(["montecarlo", "--model", "xu_zhang_1988", "--tolerances", "figure3", "--R", "0.2", "--n", "0"])
    assert rc == 2
    assert "n:" in capsys.readouterr().err


def test_planar_arm_has_no_error_normal_to_its_plane():
    """The planar 2R's z error is identically 0: no kurtosis to judge there (NaN, shown as '-' and
    'no error along it', not 'nan not Gaussian'); in the plane, at the stretched pose, w1 = y is
    the sum of two uniform angular terms, whose excess kurtosis has the closed form
    -1.2 (a^4 + b^4) / (a^2 + b^2)^2 (a, b their half-widths' lever arms)."""
    import tolsynth

    m = tolsynth.load_model("planar_2r")
    eps = m.tolerances("coarse")
    r = monte_carlo(m, "stretched", "coarse", "uniform", R=0.5, n=400_000, seed=2, progress=False)
    assert r.principal_std[2] == 0.0 and np.isnan(r.kurtosis[2])
    line = [ln for ln in r.report().splitlines() if ln.startswith("w3")][0]
    assert "no error along it" in line and "nan" not in line
    i1, i2 = m.error_parameters.index("o1"), m.error_parameters.index("o2")
    a, b = 800.0 * eps[i1] * 1e-3, 300.0 * eps[i2] * 1e-3  # mrad -> rad: y = 800 o1 + 300 o2 (mm)
    j = int(np.argmax(np.abs(r.principal_directions[1])))  # the principal direction along y
    assert abs(r.principal_directions[1, j]) > 0.999
    assert r.kurtosis[j] == pytest.approx(-1.2 * (a**4 + b**4) / (a**2 + b**2) ** 2, abs=5 * r.kurtosis_se)


def test_wilson_interval_reaches_the_ends_exactly():
    """Every sample inside: the interval's upper end is 1 (the Wilson bound's closed form at k = n),
    so an analytic probability of exactly 1 lies inside it; none inside: the lower end is 0."""
    for n in (7, 2000, 123457):
        assert wilson_interval(n, n, 0.95)[1] == 1.0
        assert wilson_interval(0, n, 0.95)[0] == 0.0


def test_a_certain_component_is_not_flagged_outside_its_interval():
    """stewart_gough's third component at R 0.3 mm: every sample inside and P = 1 analytically
    (the analytic model's own value, read from analyze), so no 'outside CI' flag."""
    m = load_model("stewart_gough")
    mc = monte_carlo(m, "home", "coarse", R=0.3, n=2000, seed=1)
    a = m.analyze("home", "coarse", R=0.3)
    j = int(np.argmax(a.p_components))
    assert a.p_components[j] == 1.0 and mc.p_components[j] == 1.0
    assert mc.p_components_analytic_in_ci[j]


def test_to_dict_is_json_without_nan():
    """A planar arm has no error along z: its third kurtosis is NaN (0/0). to_dict gives None there,
    the other entries as the arrays hold them, and strict JSON (no NaN tokens) takes the dict."""
    mc = monte_carlo(load_model("planar_2r"), "elbow90", "coarse", R=0.5, n=2000, seed=1)
    assert np.isnan(mc.kurtosis[2]) and np.all(np.isfinite(mc.kurtosis[:2]))
    d = json.loads(json.dumps(mc.to_dict(), allow_nan=False))
    assert d["kurtosis"][2] is None and d["kurtosis"][:2] == mc.kurtosis[:2].tolist()
    assert d["p_sphere"] == mc.p_sphere and d["n"] == 2000


def test_validate_compares_an_exact_design_with_the_exact_linear_model(capsys):
    """An exact design's analytic column is the linear model's exact probabilities (tests/
    independent.py's FFT along the Monte Carlo's own directions; the sphere by a 4e6-sample linear
    Monte Carlo), labelled so; the command line's montecarlo shows the same by default and the
    Gaussian values of Mechanism.analyze with --probability gaussian."""
    import tolsynth
    from tests.independent import fft_at_edge
    from tolsynth.cli import main

    m = load_model("planar_2r")
    r = tolsynth.synthesize(m, R=0.5, p=0.99)
    v = validate(m, r, n=20_000, seed=1)
    mc = v.montecarlo
    A = np.asarray(m.sensitivity(m.joints("worst")))[:3]
    ref = fft_at_edge((mc.principal_directions.T @ A) * r.x, 0.5, 1 << 14)
    np.testing.assert_allclose(v.p_components_analytic, ref, atol=2e-6)
    assert v.p_components_analytic[0] >= 0.99 - 1e-6  # the design meets p in its own reading ...
    gauss = m.analyze(mc.q, r.x, R=0.5).p_components
    assert gauss[0] < 0.99 - 1e-4  # ... where the Gaussian reading would show it below p
    rng = np.random.default_rng(3)
    dr = A @ (r.x[:, None] * rng.uniform(-1, 1, (4, 4_000_000)))
    inside = np.mean(np.einsum("ib,ib->b", dr, dr) <= 0.25)
    assert v.p_sphere_analytic == pytest.approx(inside, abs=5e-4)
    assert mc.analytic == "exact" and "exact linear 0.99" in v.report()

    tol = ",".join(f"{k}={x!r}" for k, x in r.tolerances.items())
    args = ["montecarlo", "--model", "planar_2r", "--pose", "worst", "--tolerances", tol, "--R", "0.5"]
    assert main([*args, "--n", "20000", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(out["p_components_analytic"], ref, atol=2e-6)
    assert main([*args, "--n", "20000", "--json", "--probability", "gaussian"]) == 0
    out = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(out["p_components_analytic"], gauss, rtol=1e-12)
    assert out["analytic"] == "gaussian"
