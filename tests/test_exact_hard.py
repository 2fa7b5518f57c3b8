"""The exact evaluator on the inputs that used to fail or crawl: a dominant term, coefficients near
zero, thousands of terms, p from 0.5 to 1 - 1e-6, mixed shapes, planar errors; its batched API;
its independence of what ran before; its speed.  Every value is checked against a reference that
shares nothing with it (test_exact_refs.py: FFT convolution, SciPy quadrature, Olds' formula in
rational arithmetic, Monte Carlo intervals)."""

import math
import time

import numpy as np
import pytest

import tolsynth
from test_exact_refs import fft_probability, olds, two_term, unit_distribution, wilson
from tolsynth.errors import OutOfRangeError
from tolsynth.probability.distributions import shape, shapes_of
from tolsynth.probability.exact import (
    ExactProbabilityError,
    ball_probability,
    components_probability,
    cone_probability,
    direction_probability,
    direction_probability_batch,
    worst_direction,
)
from tolsynth.probability.exact_parts import cap_of, part_of, tn_cf

#: the mixed shapes of the paper's robot used below (a normal, a triangular, a truncated normal)
MIXED = {"*": "uniform", "h2": "normal", "alpha1": "triangular", "a": "truncnormal"}
PLANAR_MIXED = {"*": "uniform", "l1": "normal", "o1": "triangular", "o2": "truncnormal"}


def _model_rows(model, dist, p=0.9):
    m = tolsynth.load_model(model)
    eps = tolsynth.synthesize(m, 0.5, p, dist).x
    return m.sensitivity(m.joints("worst"))[:3], eps, shapes_of(dist, m.error_parameters, m.index)


# ------------------------------------------------------------------------- the parts themselves
@pytest.mark.parametrize(
    "part",
    [part_of(s) for s in ("uniform", "triangular", "normal", "truncnormal", "truncnormal(0.5)", "truncnormal(5)")]
    + [cap_of(0.5), cap_of(2.0), cap_of(5.0)],
    ids=lambda p: f"{p.kind}{p.beta:g}",
)
def test_envelopes_bound_the_characteristic_function_and_never_rise(part):
    """The envelopes the truncation bounds rest on: above |cf| on a fine grid up to s = 1e5 (cf in
    closed form: sinc, its square, the Gaussian, and the truncated normal through SciPy's Faddeeva
    function, its cap as (that - w sinc) / (1 - w) with w = 2 f(1) from SciPy) and non-increasing."""
    s = np.concatenate([np.linspace(0.0, 60.0, 60001), np.geomspace(60.0, 1e5, 200001)])
    env = part.env(s)
    assert np.all(np.diff(env) <= 1e-15)
    assert np.all(np.abs(_cf_reference(part, s)) <= env + 1e-13)


def _cf_reference(part, s):
    from scipy.special import wofz

    sinc = np.sinc(s / np.pi)
    if part.kind == "uniform":
        return sinc
    if part.kind == "triangular":
        return np.sinc(s / (2 * np.pi)) ** 2
    if part.kind == "normal":
        return np.exp(-s * s / 18.0)
    beta = part.beta
    x, y = beta / math.sqrt(2), s / (beta * math.sqrt(2))
    tn = (np.exp(-y * y) - np.exp(-x * x) * np.real(np.exp(-2j * x * y) * wofz(-y + 1j * x))) / math.erf(x)
    if part.kind == "truncnormal":
        return tn
    w = 2.0 * unit_distribution(f"truncnormal({beta:g})").pdf(1.0 - 1e-15)
    return (tn - w * sinc) / (1.0 - w)


@pytest.mark.parametrize("beta", [0.5, 1.0, 2.0, 3.0, 8.0])
def test_truncated_normal_table_against_the_faddeeva_function(beta):
    """The table and expansion of the truncated normal's characteristic function against its
    closed form through SciPy's Faddeeva function: ``phi(s) = (e^{-y^2} - e^{-x^2} Re(e^{-2ixy}
    w(-y + ix))) / erf(x)``, ``x = beta/sqrt2``, ``y = s/(beta sqrt2)``; and the Dawson bound used
    by the envelope."""
    from scipy.special import dawsn, wofz

    rng = np.random.default_rng(int(beta * 10))
    s = np.concatenate([rng.uniform(0, 60, 20000), rng.uniform(60, 3000, 20000), rng.uniform(3000, 1e6, 2000)])
    x, y = beta / math.sqrt(2), s / (beta * math.sqrt(2))
    ref = (np.exp(-y * y) - np.exp(-x * x) * np.real(np.exp(-2j * x * y) * wofz(-y + 1j * x))) / math.erf(x)
    assert np.max(np.abs(tn_cf(beta, s) - ref)) < 1.5e-12
    t = np.geomspace(1e-6, 1e6, 20001)
    assert np.all(dawsn(t) <= np.minimum(0.5411, 1.0 / t))


# ------------------------------------------------------------------- a dominant term, tiny ones
CASES = [
    ("uniform", "uniform"),
    ("truncnormal", "uniform"),
    ("uniform", "truncnormal"),
    ("triangular", "normal"),
    ("truncnormal", "truncnormal"),
    ("normal", "uniform"),
    ("truncnormal(0.5)", "triangular"),
]


@pytest.mark.parametrize("n1,n2", CASES)
@pytest.mark.parametrize("ratio", [1.0, 1e-3, 1e-6, 1e-9])
def test_two_terms_against_quadrature(n1, n2, ratio):
    """``P(|Y1 + ratio Y2| <= R)`` for R inside, at and beyond the dominant term's edge, against
    SciPy quadrature of the convolution: within the reported bound, which meets 1e-10."""
    for R in (0.3, 0.999, 1.0, 1.4):
        ref, _ = two_term(1.0, n1, ratio, n2, R)
        P, err = direction_probability([1.0, ratio], [n1, n2], R, tol=1e-10, return_error=True)
        assert err <= 1e-10
        assert abs(P - ref) <= err + 2e-12, (R, P, ref, err)


@pytest.mark.parametrize(
    "n1,n2,ratio",
    [
        ("uniform", "uniform", 0.5),
        ("truncnormal", "uniform", 1e-3),
        ("triangular", "normal", 0.2),
        ("uniform", "truncnormal", 0.7),
    ],
)
def test_sphere_kernel_against_quadrature(n1, n2, ratio):
    """The sphere's kernel ``P - 2 R f(R)`` of a direction against quadrature of P and of the density."""
    from tolsynth.probability.exact_rows import evaluate

    for R in (0.3, 0.9, 1.2):
        P, D = two_term(1.0, n1, ratio, n2, R)
        Q, err, _ = evaluate(np.array([[1.0, ratio]]), (part_of(n1), part_of(n2)), R, 1e-9, kernel=True)
        assert err[0] <= 1e-9 and abs(Q[0] - (P - 2 * R * D)) <= err[0] + 1e-11


@pytest.mark.parametrize("small", [1e-4, 1e-7, 1e-12])
def test_a_dominant_term_among_many_near_zero(small):
    """Eight terms, three of them dominant, the rest ``small`` of them, mixed shapes; R inside, at
    and beyond a break point: against the FFT convolution (the small terms included)."""
    names = ["uniform", "triangular", "truncnormal", "uniform", "normal", "truncnormal", "triangular", "uniform"]
    b = np.array([1.0, 0.5, 0.3] + [small * (1 + k) for k in range(5)])
    for R in (0.4, 1.2, 1.8, 2.2):
        P, err = direction_probability(b, names, R, tol=1e-10, return_error=True)
        ref = (
            fft_probability(list(b[:3]), names[:3], R, 2e-3)
            if small < 1e-6
            else fft_probability(list(b), names, R, min(2e-3, small))
        )
        assert err <= 1e-10
        assert abs(P - ref) <= 1e-8 if small >= 1e-6 else abs(P - ref) <= 1e-9 + 20 * small


def test_the_input_that_made_the_old_evaluator_raise():
    """The paper's robot along y (three angle terms and rounding noise of 1e-16 from the other
    columns) at an R where the old evaluator stopped its series on the tail bound alone and then
    raised on tail + dropped-term bound ("tail bound 1.00e-10 exceeds tol 1e-10 after 2048 terms"),
    while the next float of R passed: such knife edges made a solve fail or not depending on the
    design the warm-started runs before it left.  Now: a value within 1e-10, equal to Olds' formula
    in rational arithmetic."""
    b = [
        9.350782719455504e-18,
        4.986023021342734e-17,
        2.6947488179485835e-17,
        2.5358484119842838e-18,
        2.8387329663433656e-18,
        2.5358484119842838e-18,
        0.0,
        2.519605716512743e-33,
        0.4010276964244558,
        0.2387763762606198,
        0.24366218611324772,
    ]
    for R in (0.7980079978169268, 0.7980079978169269):
        P, err = direction_probability(b, ["uniform"] * 11, R, tol=1e-10, return_error=True)
        assert err <= 1e-10
        assert abs(P - float(olds([x for x in b if x > 0], R))) <= 1e-12


# ----------------------------------------------------------------------- many terms, all of p
@pytest.mark.parametrize("n", [1000, pytest.param(3000, marks=pytest.mark.slow)])
def test_thousands_of_terms_against_fft(n):
    """n terms in three groups (uniform, triangular, truncated normal), R from the median to
    P = 1 - 1e-6: against the FFT convolution (each group's transform raised to its size)."""
    k = n // 3
    b = np.concatenate([np.full(k, 0.01), np.full(k, 0.02), np.full(n - 2 * k, 0.015)])
    names = ["uniform"] * k + ["triangular"] * k + ["truncnormal"] * (n - 2 * k)
    sd = math.sqrt(k * (0.01**2 / 3 + 0.02**2 / 6) + (n - 2 * k) * 0.015**2 * shape("truncnormal").variance)
    for z in (0.6745, 1.645, 2.576, 3.89, 4.89):  # P about 0.5, 0.9, 0.99, 0.9999, 0.999999
        R = z * sd
        t0 = time.perf_counter()
        P, err = direction_probability(b, names, R, tol=1e-9, return_error=True)
        assert time.perf_counter() - t0 < 10.0
        ref = _grouped_fft([(0.01, "uniform", k), (0.02, "triangular", k), (0.015, "truncnormal", n - 2 * k)], R, 1e-4)
        assert err <= 1e-9
        assert abs(P - ref) <= 5e-9, (z, P, ref)  # the FFT's own error: 2e-9 at the median


def _grouped_fft(groups, R, h):
    """FFT reference for groups of equal terms (b, shape, count): each group's transform raised to
    its count, on grids of step h and h/2, Richardson-extrapolated."""
    return (4.0 * _fft_groups(groups, R, 0.5 * h) - _fft_groups(groups, R, h)) / 3.0


def _fft_groups(groups, R, h):
    W = sum(b * c for b, _, c in groups) + 2 * h
    # the sum of many terms concentrates: the grid needs only 40 standard deviations
    sd = math.sqrt(
        sum(
            c * b * b * (1 / 3 if nm == "uniform" else 1 / 6 if nm == "triangular" else shape(nm).variance)
            for b, nm, c in groups
        )
    )
    W = min(W, 40 * sd)
    N = 1 << int(math.ceil(math.log2(2 * W / h + 8)))
    j = np.arange(N)
    j = np.where(j < N // 2, j, j - N)
    spec = np.ones(N // 2 + 1, dtype=complex)
    for b, nm, c in groups:
        d = unit_distribution(nm)
        cells = d.cdf((j + 0.5) * h / b) - d.cdf((j - 0.5) * h / b)
        spec *= np.fft.rfft(cells) ** c
    pmf = np.fft.irfft(spec, N)
    k = np.abs(j * h)
    edge = (k > R - 0.5 * h) & (k < R + 0.5 * h)
    return float(pmf[k <= R - 0.5 * h].sum() + np.sum(pmf[edge] * (R - (k[edge] - 0.5 * h)) / h))


@pytest.mark.parametrize("p", [0.5, 0.9, 0.99, 0.9999, 0.999999])
def test_the_papers_robot_with_mixed_shapes_for_every_p(p):
    """Along the principal directions of the paper's robot at its Gaussian design for p, with a
    normal, a triangular and a truncated normal among the uniforms: against the FFT convolution."""
    A, eps, sh = _model_rows("xu_zhang_1988", MIXED, p)
    names = [s.name for s in sh]
    V = (A * eps**2 / np.array([s.divisor for s in sh])) @ A.T
    E = np.linalg.eigh(V)[1]
    for w in E.T:
        b = np.abs(w @ A * eps)
        P, err = direction_probability(b, sh, 0.5, tol=1e-10, return_error=True)
        ref = fft_probability(
            list(b[b > 1e-12]), [nm for nm, x in zip(names, b) if x > 1e-12], 0.5, float(b.max()) / 32000
        )
        assert err <= 1e-10 and abs(P - ref) <= 3e-10


# ---------------------------------------------------------------------------------- batched API
def test_batch_api_per_row_R_and_bounds(rng):
    """``direction_probability_batch``: one value and one bound per row, R per row, the methods
    named; each row equal to the single-row call, whatever the other rows (to 1e-14)."""
    A, eps, sh = _model_rows("xu_zhang_1988", MIXED)
    D = rng.normal(size=(200, 3))
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    B = D @ A * eps
    B[:10, :6] *= 1e-8  # near-zero coefficients
    B[10:20, 1:] *= 1e-5  # a dominant term
    R = rng.uniform(0.05, 1.5, 200)
    P, err, how = direction_probability_batch(B, sh, R, tol=1e-10, return_method=True)
    assert P.shape == err.shape == how.shape == (200,) and np.all(err <= 1e-10)
    assert set(how) <= {"none", "one", "normal", "inside", "vertex", "vertex-exact", "vertex-rest", "series", "split"}
    single = np.array([direction_probability(B[i], sh, R[i], tol=1e-10) for i in range(0, 200, 7)])
    assert np.max(np.abs(single - P[::7])) <= 1e-14
    perm = rng.permutation(200)
    P2, _ = direction_probability_batch(B[perm], sh, R[perm], tol=1e-10)
    assert np.max(np.abs(P2 - P[perm])) <= 1e-14
    # against Monte Carlo along a few rows
    Y = np.column_stack([s.sample(rng, 400_000) for s in sh])
    for i in (0, 15, 50):
        lo, hi = wilson(np.count_nonzero(np.abs(Y @ B[i]) <= R[i]), Y.shape[0])
        assert lo <= P[i] <= hi
    with pytest.raises(OutOfRangeError, match="R"):
        direction_probability_batch(B, sh, R[:5])
    with pytest.raises(OutOfRangeError, match="B"):
        direction_probability_batch(np.ones((2, 2, 2)), sh, 1.0)


def test_a_bound_out_of_reach_is_reported_not_hidden():
    """With the series capped at 16 terms and five truncated normals (no vertex formula, too many
    to split), the bound exceeds the tolerance: the batch reports it, the single call raises."""
    b = np.array([1.0, 0.9, 0.8, 0.7, 0.6])
    P, err = direction_probability_batch(b, ["truncnormal"] * 5, 1.0, tol=1e-12, kmax=16)
    assert err[0] > 1e-12 and 0.0 < P[0] < 1.0
    with pytest.raises(ExactProbabilityError):
        direction_probability(b, ["truncnormal"] * 5, 1.0, tol=1e-12, kmax=16)


# ---------------------------------------------------------------------------- the sphere, planar
def test_planar_sphere_and_cone_against_monte_carlo(rng):
    """planar_2r (its error has no z component) with mixed shapes: the sphere's probability by the
    planar rule, and the cone of three uniforms, against 2M-sample Monte Carlo."""
    A, eps, sh = _model_rows("planar_2r", PLANAR_MIXED, 0.5)
    P, err = ball_probability(A, eps, sh, 0.5, tol=1e-6, return_error=True)
    n = 2_000_000
    Y = np.column_stack([s.sample(rng, n) for s in sh]) * eps
    lo, hi = wilson(np.count_nonzero(np.linalg.norm(Y @ A.T, axis=1) <= 0.5), n)
    assert err <= 1e-6 and lo <= P <= hi
    C = np.array([[1.0, 0.3, -0.4], [0.2, 1.0, 0.5]])
    Pc = cone_probability(C, np.array([1.0, 0.8, 0.6]), ["uniform"] * 3, 0.9, tol=1e-7)
    Yc = rng.uniform(-1, 1, (n, 3)) * np.array([1.0, 0.8, 0.6])
    lo, hi = wilson(np.count_nonzero(np.linalg.norm(Yc @ C.T, axis=1) <= 0.9), n)
    assert lo <= Pc <= hi


@pytest.mark.slow  # 4-15 s: the default run stays under 4 minutes
def test_planar_rule_with_many_terms_against_monte_carlo(rng):
    """The 3-RRR's 21 uniform terms (its error planar): the rule splits its radial integral only at
    the signed sums of the four largest half-widths (the smaller ones' kinks are smoothed by the
    convolution with the rest, and the Gauss-Legendre pair's difference sees what is left), against
    2M-sample Monte Carlo of the same linear model, at two radii."""
    m = tolsynth.load_model("planar_3rrr")
    A, eps = m.sensitivity("home")[:3], m.tolerances("coarse")
    n = 2_000_000
    Y = rng.uniform(-1.0, 1.0, (n, A.shape[1])) * eps
    r = np.linalg.norm(Y @ A.T, axis=1)
    for R in (0.03, 0.05):
        P, err = ball_probability(A, eps, ["uniform"] * A.shape[1], R, tol=1e-6, return_error=True)
        lo, hi = wilson(np.count_nonzero(r <= R), n)
        assert err <= 1e-6 and lo <= P <= hi, (R, P, lo, hi)


def test_planar_rule_agrees_with_the_hemisphere_rule(rng):
    """A full-rank error with many terms, and the same error squeezed into a plane by a third row
    1e-3 of the others: the hemisphere rule on the near-planar error, the planar rule on the
    planar one, within the effect of that third row (at most its reach squared times the density)."""
    A = rng.normal(size=(3, 9))
    A[2] = 0.0
    eps = rng.uniform(0.5, 1.0, 9)
    sh = ["uniform", "normal", "triangular"] * 3
    P0, e0 = ball_probability(A, eps, sh, 1.5, tol=1e-7, return_error=True)
    A1 = A.copy()
    A1[2] = 1e-3 * rng.normal(size=9)
    P1, e1 = ball_probability(A1, eps, sh, 1.5, tol=1e-6, max_nodes=256, return_error=True)
    assert e0 <= 1e-7 and abs(P0 - P1) <= 1e-4


# ------------------------------------------------------------------------- history independence
def _snapshot(A, eps, sh, rows):
    P, e = direction_probability_batch(rows, sh, 0.5, tol=1e-10)
    Pc, _ = components_probability(A, eps, sh, 0.5, tol=1e-10)
    u, Pw = worst_direction(A, eps, sh, 0.5, tol=1e-10, grid=60)
    Pb = ball_probability(A, eps, sh, 0.5, tol=1e-6, return_error=True)[0]
    return np.concatenate([P, Pc, [Pw, Pb], u])


def _other_work(rng):
    """Evaluations of other kinds: new truncated-normal betas (their tables grow), long series,
    splits, the planar rule, a Gaussian solve."""
    for beta in (0.5, 5.0, 8.0):
        b = np.concatenate([[1.0], rng.uniform(1e-8, 1e-3, 4)])
        direction_probability_batch(b, [f"truncnormal({beta})"] * 5, 0.7, tol=1e-10)
    direction_probability_batch(rng.uniform(0, 1, (50, 30)), ["uniform", "truncnormal"] * 15, 2.0, tol=1e-11)
    A, eps, sh = _model_rows("planar_2r", PLANAR_MIXED, 0.5)
    ball_probability(A, eps, sh, 0.5, tol=1e-6)
    tolsynth.synthesize("xu_zhang_1988", 0.4, 0.95, MIXED)


def test_values_do_not_depend_on_what_ran_before(rng):
    """A specification's exact values (rows, principal directions, the worst direction, the sphere)
    before and after other evaluations and solves in the same process: the same to 1e-12."""
    A, eps, sh = _model_rows("xu_zhang_1988", MIXED)
    D = rng.normal(size=(40, 3))
    rows = D @ A * eps
    rows[:5, 3:] *= 1e-9
    before = _snapshot(A, eps, sh, rows)
    _other_work(rng)
    after = _snapshot(A, eps, sh, rows)
    assert np.max(np.abs(after - before)) <= 1e-12


@pytest.mark.slow
def test_values_do_not_depend_on_exact_solves_before(rng):
    """As above, with exact solves (per component and in the sphere) in between."""
    A, eps, sh = _model_rows("xu_zhang_1988", MIXED)
    rows = rng.normal(size=(20, 3)) @ A * eps
    before = _snapshot(A, eps, sh, rows)
    for crit in ("components", "sphere"):
        tolsynth.synthesize("xu_zhang_1988", 0.4, 0.95, MIXED, probability="exact", criterion=crit)
    after = _snapshot(A, eps, sh, rows)
    assert np.max(np.abs(after - before)) <= 1e-12


# ------------------------------------------------------------------------------------- speed
@pytest.mark.parametrize(
    "model,dist,p", [("xu_zhang_1988", MIXED, 0.9), ("xu_zhang_1988", MIXED, 0.5), ("planar_2r", PLANAR_MIXED, 0.5)]
)
def test_the_evaluations_of_the_slow_solves_are_fast(model, dist, p):
    """What an exact solve of these specifications evaluates (they ran for minutes): the principal
    directions, the worst direction, 400 directions and the sphere, each within seconds (the sum
    about a second on an idle machine; the limits allow for a shared one)."""
    A, eps, sh = _model_rows(model, dist, p)
    D = np.random.default_rng(1).normal(size=(400, 3))
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    for f in (
        lambda: direction_probability_batch(D @ A * eps, sh, 0.5, tol=1e-10),
        lambda: components_probability(A, eps, sh, 0.5, tol=1e-10),
        lambda: worst_direction(A, eps, sh, 0.5, tol=1e-10),
        lambda: ball_probability(A, eps, sh, 0.5, tol=1e-6, return_error=True),
    ):
        t0 = time.perf_counter()
        out = f()
        assert time.perf_counter() - t0 < 8.0
        assert out is not None


# ------------------------------------------------------------------ the solver's compiled series
def _series_rows(rng):
    """Rows of the four shapes (two truncated normals) with zero coefficients, a row of three
    terms (thousands of series terms) and one of uniform and triangular terms only (a closed
    form), and R per row with P inside (0.6, 0.999)."""
    sh = tuple(shape(k) for k in ["normal", "uniform", "triangular", "truncnormal", "uniform", "truncnormal(0.5)"])
    c = rng.uniform(0.05, 0.2, (12, len(sh)))
    c[:, 1:][rng.random((12, len(sh) - 1)) < 0.3] = 0.0
    c[0] = [0.0, 0.4, 0.0, 0.3, 0.25, 0.0]
    c[1] = [0.0, 0.4, 0.3, 0.0, 0.25, 0.0]
    return c, sh, np.sqrt(np.sum(c * c, axis=1))


def test_the_compiled_series_against_the_reference_and_central_differences(rng, monkeypatch):
    """The solver's series (compiled where a compiler is found) against the reference evaluator for
    P, central differences of P for the gradient and of the gradient for the Hessian, and the
    NumPy path (TOLSYNTH_NO_COMPILE) to rounding."""
    from tolsynth.solvers import exact_kernel
    from tolsynth.solvers.exact_closed import closed_rows
    from tolsynth.solvers.exact_series import _split, derivatives, probability, rows_of

    c, sh, R = _series_rows(rng)
    u = rng.normal(size=c.shape[1]) * 0.1
    b = c * np.exp(u)
    P, err = probability(b, sh, R, 1e-11)
    ref = direction_probability_batch(b, sh, R, tol=1e-12)[0]
    assert np.all((P > 0.6) & (P < 0.999)) and np.all(np.abs(P - ref) <= err + 1e-12)
    P2, G, H, _, _ = derivatives(c, u, sh, R, tol=1e-12)
    assert np.max(np.abs(P2 - ref)) < 1e-11
    h = 1e-5
    for i in range(c.shape[1]):
        e = np.zeros(c.shape[1])
        e[i] = h
        Pp, Gp, _, _, _ = derivatives(c, u + e, sh, R, tol=1e-12)
        Pm, Gm, _, _, _ = derivatives(c, u - e, sh, R, tol=1e-12)
        assert np.allclose(G[:, i], (Pp - Pm) / (2 * h), atol=1e-8)
        assert np.allclose(H[:, :, i], (Gp - Gm) / (2 * h), atol=1e-7)
    assert np.array_equal(H, H.transpose(0, 2, 1))
    if not exact_kernel.available():
        pytest.skip("no C compiler: the NumPy path ran above")
    _, _, _, _, eg = derivatives(c, u, sh, R, tol=1e-9, hessian=False, rigorous=True)
    Pb, Gb, Hb, _, _ = derivatives(c, u, sh, 2 * R, tol=1e-10, ball=True)
    cut = _split(b, rows_of(sh), 0.1)  # a budget that drops terms
    closed = closed_rows(b, sh, R, 2, 1e-11)
    assert 1 in closed and np.count_nonzero(cut[0] == 0) > np.count_nonzero(b == 0)
    monkeypatch.setenv("TOLSYNTH_NO_COMPILE", "1")
    assert not exact_kernel.available()
    Pn, en = probability(b, sh, R, 1e-11)
    P2n, Gn, Hn, _, _ = derivatives(c, u, sh, R, tol=1e-12)
    _, _, _, _, egn = derivatives(c, u, sh, R, tol=1e-9, hessian=False, rigorous=True)
    Pbn, Gbn, Hbn, _, _ = derivatives(c, u, sh, 2 * R, tol=1e-10, ball=True)
    # the Hessian's D2 = -t sin t - D1 multiplies the sines' rounding (rotations in C) by t
    for x, y, tol in (
        (P, Pn, 1e-13),
        (P2, P2n, 1e-13),
        (G, Gn, 1e-13),
        (H, Hn, 1e-11),
        (Pb, Pbn, 1e-13),
        (Gb, Gbn, 1e-13),
        (Hb / np.abs(Hbn).max(), Hbn / np.abs(Hbn).max(), 1e-11),
    ):
        assert np.max(np.abs(x - y)) < tol
    assert np.allclose(err, en, rtol=1e-12, atol=0) and np.allclose(eg, egn, rtol=1e-12, atol=0)
    assert all(np.array_equal(x, y) for x, y in zip(cut, _split(b, rows_of(sh), 0.1)))
    closed_n = closed_rows(b, sh, R, 2, 1e-11)
    assert closed.keys() == closed_n.keys()
    for r in closed:
        assert all(np.max(np.abs(np.asarray(x) - y)) < 1e-13 for x, y in zip(closed[r], closed_n[r]))


def test_the_compiled_uniform_series_against_fft_and_the_numpy_path(rng, monkeypatch):
    """Rows of eleven uniform terms (the paper robot's rows; the compiled kernel sums them by its
    own loop when P alone is asked) to 1e-5, 1e-7 and 1e-10, from 16 to more than 64 series terms
    and one row with a term small enough for sinc's small-argument form: against FFT convolution
    of the densities (R on a cell edge), and the NumPy path (TOLSYNTH_NO_COMPILE) to rounding."""
    from independent import fft_at_edge
    from tolsynth.solvers import exact_kernel
    from tolsynth.solvers.exact_series import probability, rows_of

    sh = (shape("uniform"),) * 11
    b = rng.uniform(0.02, 0.2, (40, 11))
    b[30:] = rng.uniform(0.005, 0.03, (10, 11))
    b[30:, :2] = [0.45, 0.4]  # two dominant terms: hundreds of series terms at 1e-10
    b[39, 5] = 1e-5
    R = 0.5
    ref = fft_at_edge(b, R, 1 << 16)  # error ~ 1e-8
    rw = rows_of(sh)
    L = rw.half_period(b, R)
    assert rw.terms(b, L, 1e-5).min() == 16 and rw.terms(b, L, 1e-10).max() > 64
    assert np.all((ref > 0.5) & (ref < 0.9999))
    out = []
    for tol in (1e-5, 1e-7, 1e-10):
        P, err = probability(b, sh, R, tol)
        assert np.all(err <= tol) and np.all(np.abs(P - ref) <= err + 2e-8)
        out.append((P, err))
    if not exact_kernel.available():
        pytest.skip("no C compiler: the NumPy path ran above")
    monkeypatch.setenv("TOLSYNTH_NO_COMPILE", "1")
    assert not exact_kernel.available()
    for tol, (P, err) in zip((1e-5, 1e-7, 1e-10), out):
        Pn, en = probability(b, sh, R, tol)
        assert np.max(np.abs(P - Pn)) < 1e-13 and np.allclose(err, en, rtol=1e-12, atol=0)
