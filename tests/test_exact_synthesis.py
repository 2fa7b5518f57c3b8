"""synthesize(..., probability="exact"): the certified exact design, against independent
computations: the reference evaluator of tolsynth.probability.exact on dense grids of directions, a
Monte Carlo of the linear error model with its confidence interval, cvxpy + Clarabel on the
all-normal case (where the exact problem is the Gaussian one), a brute-force grid of a
two-parameter problem, and the nonlinear Monte Carlo."""

import math
import re

import numpy as np
import pytest

import tolsynth
from tolsynth.analysis.verify import sample_size
from tolsynth.errors import InputError
from tolsynth.probability.distributions import Shape, resolve, shape, shapes_of
from tolsynth.probability.exact import ball_probability, direction_probability
from tolsynth.problem.result import Status

R = 0.5


def _wilson(k, n, z):
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return c - h, c + h


def _sphere_directions(m, seed=5):
    D = np.random.default_rng(seed).normal(size=(m, 3))
    return D / np.linalg.norm(D, axis=1, keepdims=True)


def _linear_mc(A, eps, shapes, w, n=400_000, seed=7):
    """P(|w . dr| <= R) of the linear model by sampling the errors (shapes' own samplers)."""
    rng = np.random.default_rng(seed)
    Y = np.column_stack([shape(s).sample(rng, n) for s in shapes])
    x = (Y * eps) @ (w @ A)
    return int(np.count_nonzero(np.abs(x) <= R)), n


def test_certified_exact_design_at_one_pose(xz):
    """p = 0.7, uniform: certified (gap <= 1e-6 of the cost, bound below the cost); 4000 random
    directions by the reference evaluator meet p - 1e-7; the binding direction is at p, and a Monte
    Carlo of the linear model along it contains p in its 99.9 % interval; the Gaussian design of the
    same column misses p along that direction by more than the interval."""
    r = tolsynth.synthesize(xz, R=R, p=0.7, probability="exact")
    assert r.success, r.message
    assert r.lower_bound <= r.cost and r.gap <= 1e-6 * r.cost
    assert "certified optimum" in r.message and "proven" in r.message
    A = xz.sensitivity(xz.joints("worst"))[:3]
    sh = ["uniform"] * xz.n
    D = _sphere_directions(4000)
    assert direction_probability(D @ A * r.x, sh, R).min() >= 0.7 - 1e-7
    w = r.constraints[0].directions[:, 0]
    assert abs(direction_probability(w @ A * r.x, sh, R) - 0.7) <= 1e-6
    lo, hi = _wilson(*_linear_mc(A, r.x, sh, w), 3.2905)
    assert lo <= 0.7 <= hi
    g = tolsynth.synthesize(xz, R=R, p=0.7, probability="gaussian")
    assert abs(direction_probability(w @ A * g.x, sh, R) - 0.7) > hi - lo


@pytest.mark.parametrize("model, p", [("ur5", 0.999), ("xu_zhang_1988", 0.9999)])
def test_certified_at_high_p(model, p):
    """At a high p the multipliers grow like 1 / (1 - p), and with them what the gradients' error
    bound costs the lower bound: still certified (gap <= 1e-6 of the cost; these two missed it by
    2.2 and 2.7 times); 4000 random directions by the reference evaluator meet p - 1e-7 and the
    binding direction is at p."""
    m = tolsynth.load_model(model)
    r = tolsynth.synthesize(m, R=R, p=p)
    assert r.success, r.message
    assert r.lower_bound <= r.cost and r.gap <= 1e-6 * r.cost
    A = m.sensitivity(m.joints("worst"))[:3]
    sh = [s.name for s in shapes_of(resolve(None, m), m.error_parameters, m.index)]
    D = _sphere_directions(4000)
    assert direction_probability(D @ A * r.x, sh, R).min() >= p - 1e-7
    w = r.constraints[0].directions[:, 0]
    assert abs(direction_probability(w @ A * r.x, sh, R) - p) <= 1e-7


def test_workspace_check_of_an_exact_design_is_in_exact_probabilities(xz):
    """The sampled workspace check of an exact design (p = 0.99, uniform, made at the paper's
    pose) is in exact probabilities: at the pose it names, 4000 random directions by the reference
    evaluator find no smaller probability than the check's (to 1e-6) and one within 2 % of its miss
    probability; a Monte Carlo of the linear model along that direction contains the check's P in
    its 99.9 % interval and lies below p (the design is over its specification there)."""
    r = tolsynth.synthesize(xz, R=R, p=0.99, probability="exact")
    ws = r.workspace
    assert ws.exact and "exact probabilities" in ws.line() and ws.to_dict()["probabilities"] == "exact"
    P_check = 1.0 - 0.01 * ws.worst
    A = xz.sensitivity(ws.q, check_limits=False)[:3]
    sh = ["uniform"] * xz.n
    D = _sphere_directions(4000)
    P = direction_probability(D @ A * r.x, sh, R)
    assert P.min() >= P_check - 1e-6
    assert (1.0 - P.min()) >= 0.98 * (1.0 - P_check)
    lo, hi = _wilson(*_linear_mc(A, r.x, sh, D[int(np.argmin(P))]), 3.2905)
    assert lo - 2e-4 <= P_check <= hi + 2e-4 and hi < 0.99
    assert ws.exceeds


def test_workspace_check_screens_every_sampled_pose_in_exact_probabilities():
    """planar_2r's exact single-pose design misses p by about 9.6 % at poses the Gaussian ranking
    puts below its top five (the check used to say 'within'): every sampled pose is now screened in
    exact probabilities.  Against a brute-force grid of q2 (q1 only turns the error, so it changes
    no probability over directions) of 2000 random directions each by the reference evaluator, the
    check's value is within 2 % of the grid's largest and never above it by more than the grid's
    coarseness."""
    m = tolsynth.load_model("planar_2r")
    r = tolsynth.synthesize(m, R=R, p=0.99)
    ws = r.workspace
    assert ws.exceeds and ws.worst > 1.05 and "screened in exact probabilities" in ws.line()
    sh = [s.name for s in shapes_of(resolve(None, m), m.error_parameters, m.index)]
    D = _sphere_directions(2000)
    lo, hi = m.spec.joints[1].lower, m.spec.joints[1].upper
    worst = 0.0
    for q2 in np.linspace(lo, hi, 181):
        A = m.sensitivity(np.array([0.0, q2]), check_limits=False)[:3]
        worst = max(worst, (1.0 - direction_probability(D @ A * r.x, sh, R).min()) / 0.01)
    assert 0.98 * worst <= ws.worst <= worst * 1.02


def test_all_normal_errors_are_the_gaussian_problem_solved_by_cvxpy(xz):
    """All-normal errors: the exact problem is the Gaussian one (routed to its path), and cvxpy +
    Clarabel on the convex form (v = eps^2, an LMI per pose) finds the same cost."""
    cp = pytest.importorskip("cvxpy")
    e = tolsynth.synthesize(xz, R=R, p=0.99, distribution="normal", probability="exact")
    assert e.success and "every error is normal" in e.message
    from tolsynth.probability.stats import z_of_p

    A = xz.sensitivity(xz.joints("worst"))[:3]
    k, alpha = xz.k, 0.7
    lo, hi = xz.bounds
    v = cp.Variable(xz.n)
    S = A * (z_of_p(0.99) / (3.0 * R))  # sigma_i = eps_i / 3; z sigma_j <= R
    lmi = S @ cp.diag(v) @ S.T
    prob = cp.Problem(
        cp.Minimize(cp.sum(cp.multiply(k, cp.power(v, -alpha / 2, approx=False)))),
        [0.5 * (lmi + lmi.T) << np.eye(3), v >= lo**2, v <= hi**2],
    )
    prob.solve(solver="CLARABEL")
    assert e.cost == pytest.approx(prob.value, rel=1e-5)
    np.testing.assert_allclose(e.x, np.sqrt(v.value), rtol=1e-3)


@pytest.mark.parametrize(
    "p", [0.7, pytest.param(0.5, marks=pytest.mark.slow), pytest.param(0.99, marks=pytest.mark.slow)]
)
def test_midpoints_of_feasible_designs_stay_feasible(p):
    """The convexity the certificate rests on (Lagoa, Li & Sznaier 2005): along a fixed direction,
    designs on the boundary P = p have their arithmetic and geometric midpoints inside (the
    reference evaluator, mixed log-concave shapes)."""
    rng = np.random.default_rng(int(p * 100))
    sh = ["uniform", "uniform", "triangular", "truncnormal", "normal", "uniform"]
    c = rng.uniform(0.1, 1.0, size=6)

    def on_boundary(eps):  # scale eps until P = p (P falls as the scale grows)
        a, b = 1e-3, 1e3
        for _ in range(48):
            m = math.sqrt(a * b)
            if direction_probability(c * eps * m, sh, 1.0, tol=1e-10) >= p:
                a = m
            else:
                b = m
        return eps * a

    worst = math.inf
    for _ in range(6):
        e1, e2 = on_boundary(rng.uniform(0.05, 1.0, 6)), on_boundary(rng.uniform(0.05, 1.0, 6))
        for mid in (0.5 * (e1 + e2), np.sqrt(e1 * e2)):
            worst = min(worst, direction_probability(c * mid, sh, 1.0, tol=1e-10) - p)
    assert worst >= -1e-9


@pytest.mark.slow
def test_brute_force_grid_of_a_two_parameter_problem():
    """planar_2r with its angle errors locked: two free tolerances (l1, l2).  For a grid of l1 the
    largest feasible l2 is found by bisection, feasibility being the least exact P over 91
    directions of the plane (the reference evaluator, P even in each coefficient); the grid's
    cheapest design costs no less than the certified optimum, and within the grid's resolution."""
    m = tolsynth.load_model("planar_2r")
    locks = {"o1": 0.2, "o2": 0.4}
    r = tolsynth.synthesize(m, R=0.5, p=0.9, locks=locks, probability="exact")
    assert r.success, r.message
    A = m.sensitivity(m.joints("worst"))[:3]
    sh = ["uniform"] * m.n
    th = np.linspace(0.0, 0.5 * np.pi, 91)
    D = np.column_stack([np.cos(th), np.sin(th), np.zeros_like(th)])
    locked = np.array([0.0, 0.0, locks["o1"], locks["o2"]])

    def feasible(l1, l2):
        eps = locked + np.array([l1, l2, 0.0, 0.0])
        return direction_probability(D @ A * eps, sh, 0.5, tol=1e-10).min() >= 0.9

    cost = tolsynth.synthesize(m, R=0.5, p=0.9, locks=locks, probability="gaussian").spec.costs
    best = math.inf
    l1s = r.tolerances["l1"] * np.linspace(0.7, 1.3, 25)
    for l1 in l1s:
        a, b = 1e-3, 5.0
        if not feasible(l1, a):
            continue
        for _ in range(30):
            mid = 0.5 * (a + b)
            a, b = (mid, b) if feasible(l1, mid) else (a, mid)
        eps = locked + np.array([l1, a, 0.0, 0.0])
        best = min(best, cost.cost(eps))
    assert best >= r.cost * (1 - 1e-7)
    assert best <= r.cost * (1 + 2e-3)


def test_no_certificate_for_a_shape_that_is_not_log_concave(xz):
    """A shape outside the symmetric log-concave family (a bimodal density) has no convexity
    argument: the status would say so, never "optimal"."""
    from tolsynth.problem.specification import make_specification
    from tolsynth.solvers.exact import certifiable

    spec = make_specification(xz, R, 0.9, "uniform")
    ok, why = certifiable((shape("uniform"),) * (xz.n - 1) + (Shape("bimodal", "bimodal"),), spec)
    assert not ok and "not symmetric log-concave" in why and "no certificate" in why
    assert certifiable(spec.shapes, spec) == (True, "")


def test_bad_input():
    with pytest.raises(InputError, match="probability"):
        tolsynth.synthesize("xu_zhang_1988", R=R, p=0.9, probability="exactly")
    with pytest.raises(InputError, match="bogus"):
        tolsynth.synthesize("xu_zhang_1988", R=R, p=0.9, probability="exact", options={"bogus": 1})
    with pytest.raises(InputError, match="max_rounds"):
        tolsynth.synthesize("xu_zhang_1988", R=R, p=0.9, probability="exact", options={"max_rounds": "a"})
    with pytest.raises(InputError, match="options"):
        tolsynth.synthesize("xu_zhang_1988", R=R, p=0.9, probability="exact", options=[1])


@pytest.mark.slow
@pytest.mark.parametrize("p", [0.7, 0.99])
@pytest.mark.parametrize("dist", ["uniform", "mixed"])
def test_certified_across_p_and_shapes(xz, p, dist):
    """The paper's robot at p = 0.7 and 0.99, uniform and mixed shapes: certified, and 2000 random
    directions meet p - 1e-7 by the reference evaluator."""
    d = (
        "uniform"
        if dist == "uniform"
        else {"*": "uniform", "h2": "normal", "s1": "triangular", "alpha3": "truncnormal"}
    )
    r = tolsynth.synthesize(xz, R=R, p=p, distribution=d, probability="exact")
    assert r.success and r.gap <= 1e-6 * r.cost, r.message
    A = xz.sensitivity(xz.joints("worst"))[:3]
    sh = r.spec.shapes
    assert direction_probability(_sphere_directions(2000) @ A * r.x, sh, R).min() >= p - 1e-7


def _ball_mc(A, eps, shapes, n=400_000, seed=11):
    """P(|dr| <= R) of the linear model by sampling the errors (shapes' own samplers)."""
    rng = np.random.default_rng(seed)
    Y = np.column_stack([shape(s).sample(rng, n) for s in shapes])
    return int(np.count_nonzero(np.linalg.norm((Y * eps) @ A.T, axis=1) <= R)), n


@pytest.mark.slow
def test_exact_sphere(xz):
    """P(|dr| <= R) >= p exactly: the error-controlled ball probability at the result is p, a Monte
    Carlo of the linear model and the nonlinear Monte Carlo contain p in their intervals; the status
    says the design is met but not proven optimal, and the lower bound is the certified exact
    per-component optimum (the sphere lies in every slab), below the cost."""
    r = tolsynth.synthesize(xz, R=R, p=0.9, criterion="sphere", probability="exact")
    assert r.status is Status.FEASIBLE and r.feasible and not r.success, r.message
    assert "optimality not proven" in r.message
    A = xz.sensitivity(xz.joints("worst"))[:3]
    sh = ["uniform"] * xz.n
    P = ball_probability(A, r.x, sh, R, tol=1e-6)
    assert abs(P - 0.9) <= 2e-6
    lo, hi = _wilson(*_ball_mc(A, r.x, sh), 3.2905)
    assert lo <= 0.9 <= hi
    mc = tolsynth.monte_carlo(xz, "worst", r.x, R=R, n=200_000, seed=2, confidence=0.99)
    assert mc.p_sphere_ci[0] <= 0.9 <= mc.p_sphere_ci[1]
    comp = tolsynth.synthesize(xz, R=R, p=0.9, probability="exact")
    assert comp.success
    assert r.lower_bound == pytest.approx(comp.lower_bound, rel=1e-9) and r.lower_bound < r.cost
    assert r.gap == pytest.approx(r.cost - comp.lower_bound, rel=1e-9)
    g = tolsynth.synthesize(xz, R=R, p=0.9, criterion="sphere", probability="gaussian")
    assert ball_probability(A, g.x, sh, R, tol=1e-6) > 0.9 + 5e-3


@pytest.mark.slow
def test_gaussian_sphere_is_met_not_proven_and_its_bound_within_half_a_percent(xz):
    """The Gaussian sphere criterion (p = 0.95, where ln erf is concave on every component's range):
    status FEASIBLE; the sphere probability of the Gaussian model at the design is p by a Monte Carlo
    of that model (99.9 % interval); the per-component optimum (cvxpy + Clarabel) is below the box
    relaxation's optimum found independently (SLSQP in v = eps^2 with finite differences, from the
    per-component optimum: the cheapest tolerances whose three principal components each stay
    within R with joint probability p), which the lower bound reaches or passes (the proven
    supporting half-space), within 0.5 % of the cost."""
    from scipy.optimize import minimize
    from scipy.special import erf

    from convex_reference import clarabel

    p = 0.95
    r = tolsynth.synthesize(xz, R=R, p=p, distribution="uniform", criterion="sphere", probability="gaussian")
    assert r.status is Status.FEASIBLE and r.feasible and not r.success, r.message
    A = xz.sensitivity(xz.joints("worst"))[:3]
    V = (A * r.x**2 / 3.0) @ A.T  # uniform errors read as normal with eps^2 / 3
    X = np.random.default_rng(3).multivariate_normal(np.zeros(3), V, size=400_000)
    lo, hi = _wilson(int(np.count_nonzero(np.linalg.norm(X, axis=1) <= R)), len(X), 3.2905)
    assert lo <= p <= hi
    spec = r.spec.relaxed()
    comp = clarabel(spec)
    assert comp is not None and comp < r.lower_bound < r.cost
    lower, upper = xz.bounds
    k, alpha = np.asarray(xz.k, dtype=float), 0.7

    def box(v):
        lam = np.linalg.eigvalsh((A * v / 3.0) @ A.T).clip(1e-300)
        return float(np.sum(np.log(erf(R / np.sqrt(2 * lam))))) - math.log(p)

    v0 = tolsynth.synthesize(xz, R=R, p=p, distribution="uniform", probability="gaussian").x ** 2
    scale = v0.copy()
    res = minimize(
        lambda y: float(np.sum(k * (y * scale) ** (-alpha / 2))),
        np.full(xz.n, 0.7),
        constraints=[{"type": "ineq", "fun": lambda y: box(y * scale)}],
        bounds=list(zip(lower**2 / scale, upper**2 / scale)),
        method="SLSQP",
        options={"ftol": 1e-14, "maxiter": 1000},
    )
    assert res.success and box(res.x * scale) >= -1e-9
    assert comp < res.fun < r.cost and 0.05 < (r.cost - res.fun) / r.cost  # the box relaxation alone: 8.9 %
    assert res.fun * (1 - 1e-6) <= r.lower_bound < r.cost
    assert r.gap == pytest.approx(r.cost - r.lower_bound, rel=1e-12) and r.gap < 5e-3 * r.cost


@pytest.mark.slow  # 4-15 s: the default run stays under 4 minutes
def test_supporting_half_space_bounds_a_dense_grid_of_rays(xz):
    """The proven maximum of the weighted variances over the sphere's set (Gaussian, p = 0.9, the
    design's weights): at least the design's own weighted sum (the design is in the set, P = p)
    and every value on a dense 48 x 48 grid of rays (each ray's exit found by 60 bisection steps of
    p_ball), at most the value found times 1 + rtol; at p = 0.9 the design's tangent supports the
    set (found and design's value agree to the rays' 1e-5), as the bound's tightness needs."""
    from tolsynth.probability.stats import p_ball_batch, z_of_p
    from tolsynth.solvers.sphere_support import RTOL, _weights, weighted_maximum

    p = 0.9
    r = tolsynth.synthesize(xz, R=R, p=p, distribution="uniform", criterion="sphere", probability="gaussian")
    A = xz.sensitivity(xz.joints("worst"))[:3]
    lam = np.sort(np.linalg.eigvalsh((A * r.x**2 / 3.0) @ A.T))[::-1]
    g = _weights(lam, R)
    g = g / g[0]
    proven, found = weighted_maximum(g, R, p)
    own = float(g @ lam)
    assert found == pytest.approx(own, rel=2e-5) and own <= proven <= found * (1 + RTOL)  # (rays to 1e-5)
    e = np.linspace(0, 1, 48)
    U, W = (a.ravel() for a in np.meshgrid(e, e, indexing="ij"))
    U, W = U[W <= U], W[W <= U]
    lo, hi = np.zeros(U.size), np.full(U.size, (R / z_of_p(p)) ** 2)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        ok = p_ball_batch(np.column_stack([mid, mid * U, mid * W]), R) >= p
        lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
    assert np.max(lo * (g[0] + g[1] * U + g[2] * W)) <= proven


def test_box_relaxation_envelope_and_the_sphere_is_not_convex():
    """The box relaxation's pieces against independent numbers: h(v) = ln erf(R / sqrt(2 v)) (SciPy)
    turns from concave to convex once, where P = erf(...) is about 0.894; at p = 0.7 the envelope
    is h up to its tangent point, above h and concave on [0, v_p] (second differences), and equal to
    h at v_p.  And why no bound of this kind closes the sphere's gap: with Gaussian errors at p = 0.7
    two one-axis designs meet the sphere (P = p) while their midpoint, two equal variances, misses
    it (stats.p_ball against the closed form 1 - exp(-R^2 / (2 lam)))."""
    from scipy.special import erf, erfc

    from tolsynth.probability.stats import p_ball, z_of_p
    from tolsynth.solvers.sphere_bound import _hh, envelope_point

    r = 0.5
    v = np.linspace(0.01, 2.0, 200_001) * r * r
    h = np.log1p(-erfc(r / np.sqrt(2 * v)))  # (log1p: no rounding noise where P is near 1)
    d2 = np.diff(h, 2)
    turn = np.flatnonzero(np.diff(np.sign(d2)) != 0)
    assert len(turn) == 1 and erf(r / np.sqrt(2 * v[turn[0] + 1])) == pytest.approx(0.894, abs=1e-3)
    vp = (r / z_of_p(0.7)) ** 2
    tT = envelope_point(r, 0.7)
    assert 0 < tT < vp
    x = np.linspace(0, vp, 20_001)
    hh, _ = _hh(x, r, tT)
    hx = np.log1p(-erfc(r / np.sqrt(2 * np.maximum(x, 1e-300))))
    assert np.all(hh >= hx - 1e-12) and np.max(np.diff(hh, 2)) <= 1e-12
    assert hh[-1] == pytest.approx(hx[-1], abs=1e-9) and envelope_point(r, 0.95) == pytest.approx(
        (r / z_of_p(0.95)) ** 2
    )
    one = p_ball(np.array([vp, 0.0, 0.0]), r)
    mid = p_ball(np.array([vp / 2, vp / 2, 0.0]), r)
    assert one == pytest.approx(0.7, abs=1e-9)
    assert mid == pytest.approx(1 - np.exp(-(r**2) / vp), abs=1e-9) and mid < 0.66


@pytest.mark.slow
def test_exact_at_several_poses(xz):
    qs = [xz.joints("worst"), xz.joints("home")]
    r = tolsynth.synthesize(xz, R=R, p=0.8, poses=qs, probability="exact")
    assert r.success, r.message
    D = _sphere_directions(2000)
    for q in qs:
        A = xz.sensitivity(q, check_limits=False)[:3]
        assert direction_probability(D @ A * r.x, ["uniform"] * xz.n, R).min() >= 0.8 - 1e-7


@pytest.mark.slow
def test_puma560_random_poses_certified():
    """puma560 at 30 random poses: certified, each pose's directions checked on a grid."""
    m = tolsynth.load_model("puma560")
    rng = np.random.default_rng(3)
    lo = np.array([j.lower for j in m.spec.joints])
    hi = np.array([j.upper for j in m.spec.joints])
    qs = [lo + (hi - lo) * rng.random(lo.size) for _ in range(30)]
    r = tolsynth.synthesize(m, R=1.0, p=0.95, poses=qs, probability="exact")
    assert r.success and r.gap <= 1e-6 * r.cost, r.message
    D = _sphere_directions(500)
    for q in qs[:10]:
        A = m.sensitivity(q, check_limits=False)[:3]
        assert direction_probability(D @ A * r.x, r.spec.shapes, 1.0).min() >= 0.95 - 1e-7


@pytest.mark.slow
def test_verify_closes_the_loop(xz):
    """The Gaussian Table 1 design (p = 0.99) is verified in one round; the exact p = 0.9 design,
    whose probability is exactly p, gets a raised target until the 99 % lower bound reaches p."""
    r = tolsynth.synthesize(xz, R=R, p=0.99, probability="gaussian", verify=True, seed=3)
    v = r.verification
    assert v.verified and len(v.rounds) == 1 and v.ci[0] >= 0.99
    assert v.n == sample_size(0.99) == math.ceil(2.5758293**2 * 0.99 * 0.01 / 0.001**2)
    e = tolsynth.synthesize(xz, R=R, p=0.9, probability="exact", verify=30_000, seed=3)
    v = e.verification
    assert v.verified and v.ci[0] >= 0.9 and v.p_target > 0.9
    assert e.cost > tolsynth.synthesize(xz, R=R, p=0.9, probability="exact").cost
    lo, hi = _wilson(round(v.achieved * v.n), v.n, 2.5758293)
    assert v.ci[0] == pytest.approx(lo, abs=1e-6) and v.ci[1] == pytest.approx(hi, abs=1e-6)


@pytest.mark.slow
def test_sumt_start_reaches_the_same_design(xz):
    """solver="sumt" starts the exact search from SUMT's Gaussian design: the same certified optimum."""
    a = tolsynth.synthesize(xz, R=R, p=0.9, probability="exact")
    b = tolsynth.synthesize(xz, R=R, p=0.9, probability="exact", solver="sumt")
    assert a.success and b.success
    assert b.cost == pytest.approx(a.cost, rel=1e-6)


@pytest.mark.slow
def test_workspace_exact(xz):
    w = tolsynth.synthesize_workspace(xz, R, 0.99, probability="exact")
    assert w.converged and w.result.success
    assert w.rounds[-1]["worst_value"] <= 1 + 1e-3
    g = tolsynth.synthesize_workspace(xz, R, 0.99, probability="gaussian")
    assert w.result.cost < g.result.cost  # uniform errors at p = 0.99: the exact design is cheaper


@pytest.mark.slow
def test_command_line_exact(xz):
    """tolsynth solve --probability exact --json: its tolerances meet p along 2000 directions by
    the reference evaluator, and the binding one is at p."""
    import json
    import subprocess
    import sys

    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "tolsynth",
            "solve",
            "--model",
            "xu_zhang_1988",
            "--R",
            "0.5",
            "--p",
            "0.8",
            "--probability",
            "exact",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0, out.stderr
    d = json.loads(out.stdout)
    assert d["inputs"]["probability"] == "exact"
    eps = np.array([d["tolerances"][n] for n in xz.error_parameters])
    A = xz.sensitivity(xz.joints("worst"))[:3]
    P = direction_probability(_sphere_directions(2000) @ A * eps, ["uniform"] * xz.n, R)
    assert P.min() >= 0.8 - 1e-7 and P.min() <= 0.8 + 1e-3


def test_command_line_sphere_prints_the_design_and_says_it_is_not_proven(capsys):
    """tolsynth solve --criterion sphere (Gaussian, planar_2r): exit status 0, the tolerances
    printed, and a last line on stderr giving the status feasible and the gap (before it, the
    workspace check's warning: the design is for one pose); the printed tolerances meet the sphere,
    by SciPy's quadrature of the 2-D normal's disk probability (mean over the azimuth of
    1 - exp(-R^2 / 2 q))."""
    from scipy import integrate

    from tolsynth.cli import main

    m = tolsynth.load_model("planar_2r")
    argv = ["solve", "--model", "planar_2r", "--pose", "elbow90", "--R", "0.2", "--p", "0.9", "--dist", "uniform"]
    rc = main(argv + ["--criterion", "sphere", "--probability", "gaussian"])
    cap = capsys.readouterr()
    assert rc == 0, cap.err
    last = cap.err.strip().splitlines()[-1]
    assert last.startswith("tolsynth solve: status feasible") and "optimality is not proven" in last
    assert "feasible" in cap.out.splitlines()[1]
    printed = dict(re.findall(r"^\s+(\w+) = (\S+) ", cap.out, flags=re.M))
    eps = np.array([float(printed[n]) for n in m.error_parameters])
    S = m.sensitivity(m.joints("elbow90"))[:3]
    lam = np.linalg.eigvalsh((S * eps**2 / 3.0) @ S.T)[1:]  # the planar error's two variances
    P = (
        integrate.quad(
            lambda t: 1 - math.exp(-(0.2**2) / (2 * (lam[0] * math.sin(t) ** 2 + lam[1] * math.cos(t) ** 2))),
            0,
            math.pi,
        )[0]
        / math.pi
    )
    assert P == pytest.approx(0.9, abs=2e-5)  # (the printed tolerances have six digits)


@pytest.mark.parametrize(
    "criterion,options,limit",
    [
        ("components", {"max_iter": 3}, "max_iter=3"),
        ("components", {"max_patches": 1}, "max_patches=1"),
        ("sphere", {"max_iter": 3}, "max_iter=3"),
    ],
)
def test_a_limit_reached_has_the_status_of_a_limit(criterion, options, limit):
    """An option's limit stops the exact solve short: the status is the documented word for a
    limit (Status.ITERATION_LIMIT, "iteration_limit"), not a numerical error, and the message names
    the option, with no -inf for a bound that was never proven."""
    m = tolsynth.load_model("planar_2r")
    r = tolsynth.synthesize(m, R=R, p=0.99, pose="elbow90", criterion=criterion, options=options)
    assert str(r.status) == "iteration_limit" and not r.success and not r.feasible
    assert limit in r.message and "-inf" not in r.message and "nan" not in r.message
    # without the limit the same problem is certified: only the limit stood in the way
    full = tolsynth.synthesize(m, R=R, p=0.99, pose="elbow90", criterion=criterion)
    assert full.status in (Status.OPTIMAL, Status.FEASIBLE)
