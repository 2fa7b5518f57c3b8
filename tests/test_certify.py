"""The certified worst pose: facts proven on the graphs, sound bounds, tight results.

References are independent of the code under test: the sensitivity evaluated numerically at poses
(``Mechanism.sensitivity``) with NumPy's eigensolver, dense random searches refined by SciPy's
local optimisers, closed forms for the planar arm, and exact rational arithmetic checked against
floating point.
"""

from __future__ import annotations

import math
from fractions import Fraction

import casadi as ca
import numpy as np
import pytest

import tolsynth
from independent import dense_then_local, sigma_max
from tolsynth.analysis.certify import certify_worst_pose
from tolsynth.analysis.certify_bounds import (
    JointGraphs,
    PolygonSigmaBounds,
    SigmaBounds,
    arc_polygons,
    lambda_max_bound,
    largest_singular_bound,
    polytope_vertices,
)
from tolsynth.analysis.certify_structure import _PolyWalk, structure, trig_polynomial
from tolsynth.errors import InputError
from tolsynth.kinematics.joint_space import _limits
from tolsynth.probability.stats import z_of_p


@pytest.fixture(scope="module")
def models():
    return {n: tolsynth.load_model(n) for n in ("planar_2r", "xu_zhang_1988", "puma560", "ur5", "panda")}


# ------------------------------------------------------------------------------------------------
# facts proven on the graph, checked numerically
# ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "name, rotation", [("planar_2r", 0), ("xu_zhang_1988", 0), ("puma560", 0), ("ur5", 0), ("panda", None)]
)
def test_base_rotation_proof_matches_the_numbers(models, name, rotation):
    """Where the proof holds, turning the joint turns every column of A by Rz at random poses; panda
    has link-1 errors before its first joint (h1, alpha1), so its waist changes sigma and is not held."""
    m = models[name]
    st = structure(m)
    assert st.rotation == rotation
    rng = np.random.default_rng(1)
    lo, hi = _limits(m)
    eps = m.tolerances(next(iter(m.tolerance_sets)) if m.tolerance_sets else np.sqrt(m.bounds[0] * m.bounds[1]))
    Q = lo + (hi - lo) * rng.random((20, len(lo)))
    Q2 = Q.copy()
    Q2[:, 0] = lo[0] + (hi[0] - lo[0]) * rng.random(20)
    s1, s2 = sigma_max(m, Q, eps), sigma_max(m, Q2, eps)
    if rotation is not None:
        for q, q2 in zip(Q[:3], Q2[:3]):
            t = q2[0] - q[0]
            Rz = np.array([[math.cos(t), -math.sin(t), 0], [math.sin(t), math.cos(t), 0], [0, 0, 1]])
            A, A2 = m.sensitivity(q, check_limits=False)[:3], m.sensitivity(q2, check_limits=False)[:3]
            assert np.abs(Rz @ A - A2).max() <= 1e-9 * np.abs(A).max()
        assert np.abs(s1 - s2).max() <= 1e-10 * s1.max()
    else:
        assert np.abs(s1 - s2).max() > 1e-6 * s1.max()


def test_rotation_proof_refuses_an_error_before_the_first_joint():
    """A toleranced base offset along x (an error acting before joint 1) breaks the symmetry: no
    proof, and sigma does change with the first joint; without it the proof holds."""
    links = [{"a": 300.0, "limits": (-170, 170)}, {"a": 200.0, "limits": (-150, 150)}]
    off = tolsynth.Mechanism.from_dh(links=links, angle_unit="deg", base=[("Tx", 50.0, "bx")], name="offset2r")
    plain = tolsynth.Mechanism.from_dh(links=links, angle_unit="deg", name="plain2r")
    assert structure(off).rotation is None and structure(plain).rotation == 0
    eps = np.full(off.n, 0.05)
    q1, q2 = np.radians([[10.0, 60.0], [100.0, 60.0]])
    assert abs(sigma_max(off, q1, eps)[0] - sigma_max(off, q2, eps)[0]) > 1e-6


def test_dropped_columns_and_joints_have_no_effect(models):
    """puma560's wrist angle errors act on the wrist centre (its hand point): zero columns; xu_zhang's
    roll joint theta5 turns the hand about its own point: A does not depend on it."""
    pm = models["puma560"]
    st = structure(pm)
    dropped = [i for i in range(pm.n) if i not in st.columns]
    assert [pm.error_parameters[i] for i in dropped] == ["alpha4", "o4", "alpha5", "o5", "alpha6", "o6"]
    rng = np.random.default_rng(2)
    lo, hi = _limits(pm)
    for q in lo + (hi - lo) * rng.random((5, 6)):
        assert np.abs(pm.sensitivity(q, check_limits=False)[:3, dropped]).max() < 1e-12
    xz = models["xu_zhang_1988"]
    sx = structure(xz)
    assert 4 not in sx.joints and set(sx.periodic) == {0, 3}
    q = np.radians([10.0, 160.0, 90.0, 20.0, 0.0])
    q2 = q.copy()
    q2[4] = 1.3
    assert np.abs(xz.sensitivity(q, check_limits=False)[:3] - xz.sensitivity(q2, check_limits=False)[:3]).max() < 1e-12


def test_exact_reading_against_floating_point():
    """The exact polynomial reading of a small graph equals NumPy at random points, and keeps what
    floating point loses: CasADi folds (x * 0.1) * 3 into x * fl(0.3 + ulp), which is not x * 0.3."""
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [ca.vertcat((x[0] + 0.5 * x[1]) ** 2 - x[0] * x[1] / 4.0, x[0] * 0.1 * 3 - x[0] * 0.3)])
    pw = _PolyWalk(f)
    q = {pw.var(("q", 0)): 0, pw.var(("q", 1)): 1}
    rng = np.random.default_rng(3)
    for _ in range(5):
        v = rng.normal(size=2)
        num = sum(float(c) * np.prod([v[q[i]] ** e for i, e in mono]) for mono, c in pw.outputs[0].items())
        assert abs(num - ((v[0] + 0.5 * v[1]) ** 2 - v[0] * v[1] / 4.0)) < 1e-12
    ((mono, c),) = pw.outputs[1].items()  # one term left, exact and not zero
    assert c == Fraction(0.1 * 3) - Fraction(0.3) and c != 0


def test_trig_polynomial_reproduces_the_sensitivity(models):
    for name in ("planar_2r", "puma560", "panda"):
        m = models[name]
        st = structure(m)
        free = [j for j in st.joints if j != st.rotation]
        poly = trig_polynomial(st, free, st.rotation)
        B = PolygonSigmaBounds(poly, free, np.ones(len(st.columns)))
        Q = np.random.default_rng(4).uniform(-3, 3, (4, len(free)))
        for q, A in zip(Q, B.values(Q)):
            full = np.zeros(len(m.joint_names))
            full[free] = q
            ref = m.sensitivity(full, check_limits=False)[:3][:, list(st.columns)]
            assert np.abs(A - ref).max() <= 1e-12 * np.abs(ref).max()
    assert trig_polynomial(structure(models["xu_zhang_1988"]), [1, 2, 3], 0) is None  # the loop: no polynomial


# ------------------------------------------------------------------------------------------------
# sound bounds
# ------------------------------------------------------------------------------------------------
def test_rigorous_eigenvalue_bounds():
    rng = np.random.default_rng(5)
    M = rng.normal(size=(400, 3, 7))
    M[::7, 2] = M[::7, 1]  # rank-deficient ones
    M[::11] *= 1e-9
    sv = np.linalg.svd(M, compute_uv=False)[:, 0]
    ub = largest_singular_bound(M)
    assert np.all(ub >= sv) and np.max((ub - sv) / sv) < 1e-9
    G = M @ np.swapaxes(M, 1, 2)
    sym = np.stack([G[:, 0, 0], G[:, 1, 1], G[:, 2, 2], G[:, 0, 1], G[:, 0, 2], G[:, 1, 2]], axis=1)
    err = 1e-3 * np.abs(sym)
    lam = lambda_max_bound(G, err)
    assert np.all(
        lam
        >= np.linalg.eigvalsh(G)[:, -1] + np.sqrt((err[:, :3] ** 2).sum(1) + 2 * (err[:, 3:] ** 2).sum(1)) * (1 - 1e-12)
    )


def test_arc_polygons_hold_their_arcs():
    rng = np.random.default_rng(6)
    a = rng.uniform(-7, 7, 300)
    b = a + np.concatenate([rng.uniform(0, 0.1, 100), rng.uniform(0, 1.5, 100), rng.uniform(0, 7, 100)])
    P, rad = arc_polygons(a, b)
    t = a[:, None] + (b - a)[:, None] * np.linspace(0, 1, 200)[None]
    pts = np.stack([np.cos(t), np.sin(t)], axis=2)
    for k in range(len(a)):  # every arc point inside the polygon (convex, counter-clockwise or a rectangle)
        hull = P[k]
        c = hull.mean(axis=0)
        order = np.argsort(np.arctan2(hull[:, 1] - c[1], hull[:, 0] - c[0]))
        hull = hull[order]
        for i in range(4):
            e = hull[(i + 1) % 4] - hull[i]
            cross = e[0] * (pts[k, :, 1] - hull[i, 1]) - e[1] * (pts[k, :, 0] - hull[i, 0])
            assert np.all(cross >= -1e-12)


def test_polytope_vertices_cover_the_feasible_part():
    rng = np.random.default_rng(7)
    linear = ((np.array([1.0, -1.0, 0.0]), 0.2, 0.9),)
    C = rng.uniform(-1, 1, (50, 3))
    r = rng.uniform(0.05, 0.6, (50, 3))
    D, use = polytope_vertices(C, r, linear)
    w = rng.normal(size=3)
    X = C[:, None] + r[:, None] * rng.uniform(-1, 1, (50, 2000, 3))
    g = X[..., 0] - X[..., 1]
    feas = (g >= 0.2) & (g <= 0.9)
    for k in range(50):  # a linear function's maximum over the feasible part is at a listed point
        if feas[k].any():
            assert np.max(((C[k] + D[k]) @ w)[use[k]]) >= np.max(X[k][feas[k]] @ w) - 1e-12


@pytest.mark.parametrize(
    "name, polygon", [("xu_zhang_1988", False), ("puma560", True), ("puma560", False), ("panda", True)]
)
def test_sigma_bounds_are_sound_on_random_boxes(models, name, polygon):
    m = models[name]
    st = structure(m)
    nq = len(m.joint_names)
    free = [j for j in st.joints if j != st.rotation]
    held = {j: 0.0 for j in range(nq) if j not in free}
    eps = m.tolerances("figure3" if name == "xu_zhang_1988" else "fine")
    w = (eps**2 / 3.0)[list(st.columns)]
    if polygon:
        B = PolygonSigmaBounds(trig_polynomial(st, free, st.rotation), free, w)
    else:
        B = SigmaBounds(JointGraphs(st, nq, free, held), w)
    lo, hi = _limits(m)
    rng = np.random.default_rng(8)
    n = 12
    for h in (0.5, 0.05, 0.005):
        C = lo[free] + (hi[free] - lo[free]) * rng.random((n, len(free)))
        L, H = C - h, C + h
        ub, _ = B.bound(L, H)
        X = L[:, None] + (H - L)[:, None] * rng.random((n, 60, len(free)))
        Q = np.zeros((n * 60, nq))
        for j, v in held.items():
            Q[:, j] = v
        Q[:, free] = X.reshape(-1, len(free))
        ref = sigma_max(m, Q, eps).reshape(n, 60).max(axis=1)
        assert np.all(ub >= ref * (1 - 1e-12))
        if h == 0.005:
            assert np.max((ub - ref) / ref) < 0.03  # and tight on small boxes (excess ~ width^2)


def test_exact_component_bounds_are_sound_and_quasi_concave():
    """Lower bounds of the exact per-direction probability on random (joint box, direction patch)
    pairs stay below the probability at sampled joint values and directions of the patch (computed
    here from the model's own sensitivity and an FFT convolution, not the package's series); and
    the fact behind the vertices: P along a segment of coefficient vectors is never below both
    ends (quasi-concavity, GUARANTEES section 1)."""
    from independent import fft_probabilities
    from tolsynth.analysis.certify_bounds import taylor_enclosure
    from tolsynth.analysis.certify_exact_bounds import ExactBounds
    from tolsynth.probability.distributions import shapes_of
    from tolsynth.probability.exact import direction_probability_batch

    m = tolsynth.load_model("xu_zhang_1988")
    st = structure(m)
    cols = list(st.columns)
    eps = m.tolerances("figure3")
    shapes = shapes_of("uniform", m.error_parameters, m.index)
    enc = JointGraphs(st, 5, [1, 2, 3], {0: 0.0, 4: 0.0}, third=True)
    B = ExactBounds(enc, eps[cols], tuple(shapes[i] for i in cols), 0.7)
    rng = np.random.default_rng(9)
    lo = np.radians([140.0, 50.0, -110.0])
    hi = np.radians([200.0, 130.0, 110.0])
    faces = rng.integers(0, 3, 8)
    for h, ph in ((0.3, 0.5), (0.02, 0.0625)):
        C = lo + (hi - lo) * rng.random((8, 3))
        box = taylor_enclosure(enc, C - h, C + h)
        s0 = rng.integers(0, int(2 / ph), 8) * ph - 1.0
        t0 = rng.integers(0, int(2 / ph), 8) * ph - 1.0
        lb, *_ = B.pairs(box, np.arange(8), faces, s0, t0, np.full(8, ph), 2.0)
        for i in range(8):
            X = (C[i] - h) + 2 * h * rng.random((6, 3))
            F = np.eye(3)[[faces[i], (faces[i] + 1) % 3, (faces[i] + 2) % 3]]
            st_ = rng.random((6, 2)) * ph + [s0[i], t0[i]]
            U = F[0] + st_[:, :1] * F[1] + st_[:, 1:] * F[2]
            U /= np.linalg.norm(U, axis=1, keepdims=True)
            rows = []
            for x, u in zip(X, U):
                A = m.sensitivity(np.concatenate([[0.0], x, [0.0]]), check_limits=False)[:3]
                rows.append(np.abs(u @ A) * eps)
            assert lb[i] <= fft_probabilities(rows, 0.7, 1 << 14).min() + 5e-5
        if h == 0.02:
            assert np.median(lb) > 0.5  # small boxes are not bounded trivially
    # boxes crossed by the interference limit 50 <= theta'2 - theta2 <= 130 deg: the feasible
    # part's own corners, checked at feasible points only
    lin = ((np.array([1.0, -1.0, 0.0]), math.radians(50.0), math.radians(130.0)),)
    B = ExactBounds(enc, eps[cols], tuple(shapes[i] for i in cols), 0.7, lin)
    C = np.radians(np.array([[150.0, 100.0 - 30.0 * i, 20.0 * i - 60.0] for i in range(6)]))
    C[:, 1] = C[:, 0] - np.radians([50.0, 130.0, 50.0, 130.0, 50.0, 130.0])  # on a limit
    box = taylor_enclosure(enc, C - 0.03, C + 0.03, lin)
    assert box.cross.all()
    lb, *_ = B.pairs(
        box, np.arange(6), np.zeros(6, dtype=int), np.full(6, -0.5), np.full(6, -0.5), np.full(6, 1.0), 2.0
    )
    for i in range(6):
        X = (C[i] - 0.03) + 0.06 * rng.random((40, 3))
        X = X[(X[:, 0] - X[:, 1] >= math.radians(50.0)) & (X[:, 0] - X[:, 1] <= math.radians(130.0))][:6]
        st_ = rng.random((len(X), 2)) - 0.5
        U = np.array([1.0, 0.0, 0.0]) + st_[:, :1] * np.array([0.0, 1.0, 0.0]) + st_[:, 1:] * np.array([0.0, 0.0, 1.0])
        U /= np.linalg.norm(U, axis=1, keepdims=True)
        rows = [
            np.abs(u @ m.sensitivity(np.concatenate([[0.0], x, [0.0]]), check_limits=False)[:3]) * eps
            for x, u in zip(X, U)
        ]
        assert len(rows) and lb[i] <= fft_probabilities(rows, 0.7, 1 << 14).min() + 5e-5
    assert lb.min() > 0.0
    a, b = rng.uniform(-0.2, 0.2, (2, 200, 11))
    t = rng.random((200, 1))
    Pa, _ = direction_probability_batch(a, ["uniform"] * 11, 0.6)
    Pb, _ = direction_probability_batch(b, ["uniform"] * 11, 0.6)
    Pt, _ = direction_probability_batch(t * a + (1 - t) * b, ["uniform"] * 11, 0.6)
    assert np.all(Pt >= np.minimum(Pa, Pb) - 1e-9)


# ------------------------------------------------------------------------------------------------
# certified maxima against closed forms and independent searches
# ------------------------------------------------------------------------------------------------
def test_planar_2r_against_the_closed_form(models):
    """sigma_1 of the planar arm depends on q2 only (the waist turns it rigidly); the reference is the
    2 x 2 eigenvalue in closed form on a 200 001-point grid of q2, refined by SciPy."""
    from scipy.optimize import minimize_scalar

    m = models["planar_2r"]
    eps = m.tolerances("coarse")
    c = certify_worst_pose(m, eps, "uniform", progress=False, rtol=1e-6)
    lo, hi = _limits(m)

    def sigma(q2):
        q2 = np.atleast_1d(q2)
        A = np.array([m.sensitivity([0.0, v], check_limits=False)[:2] for v in q2])  # planar rows x, y
        V = np.einsum("nij,j,nkj->nik", A, eps**2 / 3.0, A)
        tr, det = V[:, 0, 0] + V[:, 1, 1], V[:, 0, 0] * V[:, 1, 1] - V[:, 0, 1] ** 2
        return np.sqrt(tr / 2 + np.sqrt(np.maximum(tr**2 / 4 - det, 0.0)))

    grid = np.linspace(lo[1], hi[1], 2001)
    vals = sigma(grid)
    k = int(np.argmax(vals))
    res = minimize_scalar(
        lambda v: -sigma(v)[0],
        bounds=(grid[max(k - 1, 0)], grid[min(k + 1, 2000)]),
        method="bounded",
        options={"xatol": 1e-12},
    )
    ref = max(vals.max(), -res.fun)
    assert c.certified and ref <= c.upper_bound and c.upper_bound - ref <= 1e-6 * ref
    assert abs(c.best_value - ref) <= 1e-6 * ref


@pytest.mark.slow  # 10-17 s
def test_paper_robot_certified_against_a_dense_search(models):
    m = models["xu_zhang_1988"]
    eps = m.tolerances("figure3")
    c = certify_worst_pose(m, eps, "uniform", progress=False, rtol=1e-4)
    ref = dense_then_local(m, eps, 20000, 10, fixed={0: 0.0, 4: 0.0})
    assert c.certified
    assert ref <= c.upper_bound and (c.upper_bound - ref) / ref <= 1e-4 + 1e-9
    assert c.held.keys() == {"theta1", "theta5"}


@pytest.mark.long  # minutes per arm (20000 boxes)
@pytest.mark.parametrize("name", ["puma560", "ur5", "panda"])
def test_six_joint_arms_bound_a_dense_search(models, name):
    """A box budget: the bound holds whether or not the gap closed, above an independent search."""
    m = models[name]
    eps = m.tolerances("fine")
    c = certify_worst_pose(m, eps, "uniform", progress=False, max_boxes=20000)
    ref = dense_then_local(m, eps, 20000, 11)
    assert ref <= c.upper_bound
    assert c.best_value <= ref * (1 + 1e-9) or c.best_value >= ref * (1 - 1e-3)


@pytest.mark.slow  # 10-17 s
def test_interference_corner_found_where_the_sampled_exchange_missed_it(models):
    """The sampled exchange's design on the paper's robot: the certified search proves its largest
    sigma z / R, above what the sampled search saw, at a pose on the interference limit."""
    m = models["xu_zhang_1988"]
    R, p = 0.5, 0.99
    w = tolsynth.synthesize_workspace(m, R, p, "uniform", 0.7, probability="gaussian")
    z = z_of_p(p)
    # one process: with workers the pose found depends on their timing (its value does not, to the
    # search's tolerance), and a pose a few microradians off the limit meets that tolerance too
    c = certify_worst_pose(m, w.result.x, "uniform", progress=False, rtol=1e-5, workers=1)
    found = c.best_value * z / R
    assert found > w.worst_value + 1e-4  # the sampled search stopped short of it
    assert c.upper_bound * z / R - found <= 2e-5
    gamma = c.q[1] - c.q[2]
    assert min(abs(gamma - math.radians(50)), abs(gamma - math.radians(130))) < 1e-6  # on the interference limit
    assert found == pytest.approx(sigma_max(m, c.q, w.result.x)[0] * z / R, rel=1e-12)


def test_bad_inputs_raise_typed_errors(models):
    m = models["planar_2r"]
    with pytest.raises(InputError):
        certify_worst_pose(m, "coarse", criterion="sphere")
    with pytest.raises(InputError):
        certify_worst_pose(m, "coarse", criterion="components")  # no R
    with pytest.raises(InputError):
        certify_worst_pose(m, "coarse", probability="exact")  # exact needs components
    with pytest.raises(InputError):
        tolsynth.worst_pose(m, "coarse", criterion="probability", R=0.1, certify=True)
    with pytest.raises(InputError):
        tolsynth.synthesize_workspace(m, 0.1, 0.99, certify=True, criterion="sphere")


# ------------------------------------------------------------------------------------------------
# the boxes kept, the bound closing, the certified map
# ------------------------------------------------------------------------------------------------
def test_maximize_keeps_a_cover_of_the_box_with_sound_bounds():
    """The boxes set aside tile the box (their volumes add up to it, none overlap a random point
    twice) and each one's bound is above the function at random points inside it."""
    from tolsynth.analysis.branch_bound import maximize

    f = lambda x: np.sin(3 * x[:, 0]) * np.cos(2 * x[:, 1]) + 0.1 * x[:, 0]  # noqa: E731

    def bound(lo, hi):  # a Lipschitz bound from the centre: |grad f| <= 3 + 2 + 0.1 in each part
        return f(0.5 * (lo + hi)) + 0.5 * (3.1 * (hi - lo)[:, 0] + 2.0 * (hi - lo)[:, 1])

    leaves = []
    r = maximize(bound, f, [-1.0, -2.0], [2.0, 1.0], tol=1e-3, leaves=leaves)
    assert r.certified
    lo = np.array([b[0] for b in leaves])
    hi = np.array([b[1] for b in leaves])
    ub = np.array([b[2] for b in leaves])
    assert np.prod(hi - lo, axis=1).sum() == pytest.approx(9.0, rel=1e-12)
    X = np.random.default_rng(12).uniform([-1.0, -2.0], [2.0, 1.0], (3000, 2))
    inside = (X[:, None] >= lo[None]).all(axis=2) & (X[:, None] <= hi[None]).all(axis=2)
    assert np.all(inside.sum(axis=1) == 1)  # interior points: in exactly one box
    assert np.all(f(X) <= ub[np.argmax(inside, axis=1)] + 1e-15)
    assert ub.max() == pytest.approx(r.upper_bound)


def test_certificate_keeps_its_boxes_and_the_gap_closing(models):
    """Paper's robot, figure3: random feasible poses lie in a box kept whose bound is above their
    sigma_1 (numeric sensitivity, NumPy); the history's bound falls and its best value rises to the
    certificate's own numbers."""
    from tolsynth.kinematics.joint_space import _feasible

    m = models["xu_zhang_1988"]
    eps = m.tolerances("figure3")
    c = certify_worst_pose(m, eps, "uniform", progress=False, keep_boxes=True)
    lo, hi, ub = c.leaves
    names = list(m.joint_names)
    free = [names.index(n) for n in c.searched]
    lq, hq = _limits(m)
    rng = np.random.default_rng(13)
    Q = lq + (hq - lq) * rng.random((400, len(names)))
    Q[:, [0, 4]] = 0.0
    Q = Q[_feasible(m, Q.T)][:150]
    X = Q[:, free]
    inside = (X[:, None] >= lo[None] - 1e-12).all(axis=2) & (X[:, None] <= hi[None] + 1e-12).all(axis=2)
    assert inside.any(axis=1).all()
    bound_at = np.where(inside, ub[None], -np.inf).max(axis=1)
    assert np.all(sigma_max(m, Q, eps) <= bound_at * (1 + 1e-12))
    H = np.array(c.history)
    assert np.all(np.diff(H[:, 2]) >= 0) and np.all(np.diff(H[np.isfinite(H[:, 1]), 1]) <= 1e-15)
    assert H[-1, 1] == pytest.approx(c.upper_bound) and H[-1, 2] == pytest.approx(c.best_value)
    assert "leaves" not in c.to_dict()


def test_certified_map_bounds_random_poses_in_each_cell(models):
    """Every cell's bound is above sigma_1 (numeric sensitivity, NumPy) at random feasible poses of
    the cell, theta4 anywhere; the cells the interference band leaves empty are NaN."""
    from tolsynth.analysis.certify_map import certified_map
    from tolsynth.kinematics.joint_space import _feasible

    m = models["xu_zhang_1988"]
    eps = m.tolerances("figure3")
    cm = certified_map(m, eps, "uniform", joints=("theta2", "thetap2"), n=6, slices=8)
    names = list(m.joint_names)
    lq, hq = _limits(m)
    rng = np.random.default_rng(14)
    Q = lq + (hq - lq) * rng.random((3000, len(names)))
    Q[:, [0, 4]] = 0.0
    Q = Q[_feasible(m, Q.T)][:400]
    ka = np.clip(np.searchsorted(cm.edges[0], Q[:, names.index("theta2")]) - 1, 0, 5)
    kb = np.clip(np.searchsorted(cm.edges[1], Q[:, names.index("thetap2")]) - 1, 0, 5)
    assert np.all(sigma_max(m, Q, eps) <= cm.upper[kb, ka] * (1 + 1e-12))
    assert np.isnan(cm.upper).any() and np.all(np.isnan(cm.sampled)[np.isnan(cm.upper)])
    assert np.nanmax(cm.upper) >= certify_worst_pose(m, eps, "uniform", progress=False).best_value
    with pytest.raises(tolsynth.errors.UnknownNameError):
        certified_map(m, eps, joints=("theta1", "theta2"))  # theta1 is held: it cannot change sigma_1


def test_worst_pose_components_certified_with_a_probability_bound(models):
    """criterion 'components' (the smallest per-component probability, Gaussian reading): the
    certified lower bound is erf(R / (sqrt 2 sigma_ub)) and lies below the probability at the
    pose found; the sphere probability says which criterion is certified."""
    m = models["xu_zhang_1988"]
    R = 0.5
    w = tolsynth.worst_pose(
        m, "figure3", criterion="components", R=R, certify=True, progress=False, probability="gaussian"
    )
    assert w.certified and w.boxes > 0
    assert w.probability_lower_bound == pytest.approx(math.erf(R / (math.sqrt(2) * w.upper_bound)), abs=1e-14)
    sig = sigma_max(m, w.q, m.tolerances("figure3"))[0]
    assert w.probability_lower_bound <= math.erf(R / (math.sqrt(2) * sig)) == pytest.approx(w.value, rel=1e-9)
    with pytest.raises(InputError, match="components"):
        tolsynth.worst_pose(m, "figure3", criterion="probability", R=R, certify=True)
