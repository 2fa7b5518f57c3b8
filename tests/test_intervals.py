"""Interval evaluation of CasADi graphs, the mean-value form and the branch and bound.

Soundness: for every operation, values that plain CasADi computes at points of a box lie inside
the interval computed for the box (random boxes, wide ones for the periodic functions, boxes that
touch or straddle 0 for the partial functions).  Tightness: a single operation's interval reaches
the extremes found at the points that attain them (end points, corners, critical points), so the
enclosures are not trivially wide.  The branch and bound is checked against closed forms and
against a dense grid refined by scipy's local maximisation.
"""

from __future__ import annotations

import math
import zlib

import casadi as ca
import numpy as np
import pytest

from tolsynth.analysis.branch_bound import maximize
from tolsynth.analysis.interval_box import BoxFunction
from tolsynth.analysis.intervals import IntervalFunction, MeanValueFunction
from tolsynth.errors import InputError

OPS = {v: k for k, v in vars(ca).items() if k.startswith("OP_") and isinstance(v, int)}
X, Y = ca.SX.sym("x"), ca.SX.sym("y")


def _op_codes(f):
    return {OPS[f.instruction_id(k)] for k in range(f.n_instructions())}


def _boxes(rng, n, centre, width, touch_zero=True, integers=False):
    """Random boxes: centres in [-centre, centre], widths log-uniform up to ``width``, some
    degenerate, some with an end point exactly at 0 (or straddling it), some at integers."""
    c = rng.uniform(-centre, centre, n)
    w = np.exp(rng.uniform(np.log(1e-10), np.log(width), n))
    lo, hi = c - w / 2, c + w / 2
    k = n // 10
    lo[:k] = hi[:k] = c[:k]  # points
    if touch_zero:
        lo[k : 2 * k] = 0.0
        hi[k : 2 * k] = w[k : 2 * k]
        lo[2 * k : 3 * k] = -w[2 * k : 3 * k]
        hi[2 * k : 3 * k] = 0.0
        lo[3 * k : 4 * k], hi[3 * k : 4 * k] = -w[3 * k : 4 * k] / 3, 2 * w[3 * k : 4 * k] / 3
    if integers:
        lo[4 * k : 5 * k] = np.round(lo[4 * k : 5 * k])
        hi[4 * k : 5 * k] = np.maximum(lo[4 * k : 5 * k], np.round(hi[4 * k : 5 * k]))
    return lo, hi


def _samples(rng, lo, hi, m, specials=()):
    """m points per box: both ends, random points, and the special points that fall inside."""
    t = rng.uniform(0, 1, (len(lo), m - 2))
    pts = [lo[:, None], hi[:, None], lo[:, None] + t * (hi - lo)[:, None]]
    for s in specials:
        pts.append(np.clip(s, lo, hi)[:, None])
    return np.concatenate(pts, axis=1)


def _periodic_points(lo, hi, phase, period, most=64):
    """The points phase + k * period inside each box (at most ``most`` per box)."""
    k0 = np.ceil((lo - phase) / period)
    out = [phase + (k0 + j) * period for j in range(most)]
    return [np.where(p <= hi, p, hi) for p in out]


def _casadi_values(f, *cols):
    """Plain CasADi at many points: cols are arrays of the same shape, one per scalar input."""
    shape = cols[0].shape
    flat = [c.reshape(1, -1) for c in cols]
    return np.array(f.map(flat[0].shape[1])(*flat)).reshape(shape)


def _check(lo, hi, reg, v, tight_ok=None, rtol=1e-12):
    """Soundness (every finite value inside), the regular flag (no undefined value where it is
    set) and, where ``tight_ok``, tightness (the interval reaches the sampled extremes)."""
    lo_ = np.where(np.isnan(lo), -np.inf, lo)[:, None]
    hi_ = np.where(np.isnan(hi), np.inf, hi)[:, None]
    fin = np.isfinite(v)
    outside = fin & ((v < lo_) | (v > hi_))
    assert not outside.any(), (lo_[outside.any(1)][:3], hi_[outside.any(1)][:3], v[outside.any(1)][:3])
    assert fin[reg].all(), "a box proven regular holds a point where CasADi returns inf or NaN"
    if tight_ok is not None:
        sel = tight_ok & reg & fin.all(axis=1)
        vmax, vmin = v[sel].max(axis=1), v[sel].min(axis=1)
        scale = 1.0 + np.maximum(np.abs(vmax), np.abs(vmin))
        assert np.all(hi_[sel, 0] - vmax <= rtol * scale), np.max((hi_[sel, 0] - vmax) / scale)
        assert np.all(vmin - lo_[sel, 0] <= rtol * scale), np.max((vmin - lo_[sel, 0]) / scale)
        assert sel.sum() > len(sel) // 4


def _crit(*pairs):
    return lambda lo, hi: [p for ph, per in pairs for p in _periodic_points(lo, hi, ph, per)]


ZERO = lambda lo, hi: [np.zeros_like(lo)]  # noqa: E731
NONE = lambda lo, hi: []  # noqa: E731

# name, expression, operation it must contain, box centre range, box width, special points, tight
UNARY = [
    ("neg", -X, "OP_NEG", 5, 10, NONE, True),
    ("twice", X + X, "OP_TWICE", 5, 10, NONE, True),
    ("mul_pos_const", 2.7 * X, "OP_MUL", 5, 10, NONE, True),
    ("mul_neg_const", -0.3 * X, "OP_MUL", 5, 10, NONE, True),
    ("sq", X * X, "OP_SQ", 5, 10, ZERO, True),
    ("fabs", ca.fabs(X), "OP_FABS", 5, 10, ZERO, True),
    ("sqrt", ca.sqrt(X), "OP_SQRT", 5, 10, NONE, True),
    ("inv", 1 / X, "OP_INV", 5, 10, NONE, True),
    ("exp", ca.exp(X), "OP_EXP", 30, 20, NONE, True),
    ("log", ca.log(X), "OP_LOG", 5, 10, NONE, True),
    ("sin", ca.sin(X), "OP_SIN", 60, 40, _crit((np.pi / 2, np.pi)), True),
    ("cos", ca.cos(X), "OP_COS", 60, 40, _crit((0.0, np.pi)), True),
    ("tan", ca.tan(X), "OP_TAN", 20, 4, NONE, True),
    ("asin", ca.asin(X), "OP_ASIN", 1.3, 1.5, NONE, True),
    ("acos", ca.acos(X), "OP_ACOS", 1.3, 1.5, NONE, True),
    ("atan", ca.atan(X), "OP_ATAN", 20, 30, NONE, True),
    ("sinh", ca.sinh(X), "OP_SINH", 10, 10, NONE, True),
    ("cosh", ca.cosh(X), "OP_COSH", 10, 10, ZERO, True),
    ("tanh", ca.tanh(X), "OP_TANH", 10, 10, NONE, True),
    ("asinh", ca.asinh(X), "OP_ASINH", 10, 10, NONE, True),
    ("acosh", ca.acosh(X), "OP_ACOSH", 5, 6, NONE, True),
    ("atanh", ca.atanh(X), "OP_ATANH", 1.3, 1.5, NONE, True),
    ("log1p", ca.log1p(X), "OP_LOG1P", 3, 4, NONE, True),
    ("expm1", ca.expm1(X), "OP_EXPM1", 10, 10, NONE, True),
    ("erf", ca.erf(X), "OP_ERF", 4, 4, NONE, True),
    ("floor", ca.floor(X), "OP_FLOOR", 5, 3, NONE, True),
    ("ceil", ca.ceil(X), "OP_CEIL", 5, 3, NONE, True),
    ("sign", ca.sign(X), "OP_SIGN", 2, 3, NONE, True),
    ("not", ca.logic_not(X), "OP_NOT", 1, 2, NONE, False),
    ("constpow_2.5", ca.constpow(X, 2.5), "OP_CONSTPOW", 5, 10, NONE, True),
    ("constpow_-1.5", ca.constpow(X, -1.5), "OP_CONSTPOW", 5, 10, NONE, True),
    # CasADi rewrites integer constant powers into products; pow(x, n) with a variable n that the
    # box fixes at an integer runs the integer branch (test_binary_operation_encloses_values[pow])
]


@pytest.mark.parametrize("name, expr, op, centre, width, specials, tight", UNARY, ids=[u[0] for u in UNARY])
def test_unary_operation_encloses_values(name, expr, op, centre, width, specials, tight):
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    f = ca.Function("f", [X], [expr])
    assert op in _op_codes(f)
    lo, hi = _boxes(rng, 600, centre, width, integers=name in ("floor", "ceil"))
    r = IntervalFunction(f)([lo[:, None]], [hi[:, None]])
    pts = _samples(rng, lo, hi, 31, specials(lo, hi))
    _check(
        r.lo[0][:, 0, 0], r.hi[0][:, 0, 0], r.regular, _casadi_values(f, pts), np.ones(len(lo), bool) if tight else None
    )


def test_sin_cos_span_several_periods():
    rng = np.random.default_rng(1)
    lo = rng.uniform(-100, 100, 200)
    hi = lo + rng.uniform(2 * np.pi, 30, 200)
    for fn in (ca.sin, ca.cos):
        r = IntervalFunction(ca.Function("f", [X], [fn(X)]))([lo[:, None]], [hi[:, None]])
        assert np.all(r.lo[0] <= -1.0) and np.all(r.hi[0] >= 1.0)
        assert np.all(r.lo[0] >= -1.0 - 1e-12) and np.all(r.hi[0] <= 1.0 + 1e-12)


def _binary_boxes(rng, n, centre, width):
    xl, xh = _boxes(rng, n, centre, width)
    yl, yh = _boxes(rng, n, centre, width)
    p = rng.permutation(n)  # mix the special kinds between the two arguments
    return xl, xh, yl[p], yh[p]


def _corners(rng, xl, xh, yl, yh, m, extra=()):
    tx, ty = rng.uniform(0, 1, (2, len(xl), m))
    xs = [xl, xl, xh, xh] + [np.clip(e[0], xl, xh) for e in extra]
    ys = [yl, yh, yl, yh] + [np.clip(e[1], yl, yh) for e in extra]
    px = np.concatenate([np.stack(xs, 1), xl[:, None] + tx * (xh - xl)[:, None]], axis=1)
    py = np.concatenate([np.stack(ys, 1), yl[:, None] + ty * (yh - yl)[:, None]], axis=1)
    return px, py


BINARY = [
    ("add", X + Y, "OP_ADD", True),
    ("sub", X - Y, "OP_SUB", True),
    ("mul", X * Y, "OP_MUL", True),
    ("div", X / Y, "OP_DIV", True),
    ("pow", ca.power(X, Y), "OP_POW", True),
    ("atan2", ca.atan2(Y, X), "OP_ATAN2", True),
    ("fmin", ca.fmin(X, Y), "OP_FMIN", True),
    ("fmax", ca.fmax(X, Y), "OP_FMAX", True),
    ("hypot", ca.hypot(X, Y), "OP_HYPOT", True),
    ("lt", X < Y, "OP_LT", False),
    ("le", X <= Y, "OP_LE", False),
    ("eq", X == Y, "OP_EQ", False),
    ("ne", X != Y, "OP_NE", False),
    ("and", ca.logic_and(X, Y), "OP_AND", False),
    ("or", ca.logic_or(X, Y), "OP_OR", False),
    ("if_else_zero", ca.SX.binary(ca.OP_IF_ELSE_ZERO, X, Y), "OP_IF_ELSE_ZERO", False),
    ("if_else", ca.if_else(X > Y, ca.sin(X), Y * Y), "OP_IF_ELSE_ZERO", False),
    ("copysign", ca.copysign(X, Y), "OP_COPYSIGN", False),
]


@pytest.mark.parametrize("name, expr, op, tight", BINARY, ids=[b[0] for b in BINARY])
def test_binary_operation_encloses_values(name, expr, op, tight):
    rng = np.random.default_rng(zlib.crc32(name.encode()))
    f = ca.Function("f", [X, Y], [expr])
    assert op in _op_codes(f)
    xl, xh, yl, yh = _binary_boxes(rng, 600, 4, 8)
    if name in ("eq", "ne", "and", "or"):  # make ties and zeros common
        xl, xh, yl, yh = np.round(xl), np.round(xh), np.round(yl), np.round(yh)
    if name == "pow":  # the integer-exponent branch: degenerate integer exponents on half the boxes
        yl[:300] = yh[:300] = np.round(yl[:300])
    r = IntervalFunction(f)([xl[:, None], yl[:, None]], [xh[:, None], yh[:, None]])
    zero = (np.zeros_like(xl), np.zeros_like(yl))
    px, py = _corners(rng, xl, xh, yl, yh, 40, extra=[zero])
    _check(
        r.lo[0][:, 0, 0],
        r.hi[0][:, 0, 0],
        r.regular,
        _casadi_values(f, px, py),
        np.ones(len(xl), bool) if tight else None,
    )


@pytest.mark.parametrize(
    "name, expr", [(u[0], u[1]) for u in UNARY] + [(b[0], b[1]) for b in BINARY], ids=[u[0] for u in UNARY + BINARY]
)
def test_compiled_interpreter_matches_the_numpy_extensions(name, expr):
    """The compiled interpreter runs each extension's own arithmetic: the same end points to the
    bit (NaN where NumPy has NaN) and the same regular boxes, on the soundness tests' boxes and on
    a kinematic graph of every joint; graphs with an operation it lacks stay on NumPy."""
    f = ca.Function("f", [X, Y], [expr])
    F = IntervalFunction(f)
    if F._compiled is None:
        assert _op_codes(f) & {
            "OP_TAN",
            "OP_POW",
            "OP_CONSTPOW",
            "OP_SINH",
            "OP_COSH",
            "OP_TANH",
            "OP_ASINH",
            "OP_ACOSH",
            "OP_ATANH",
            "OP_LOG1P",
            "OP_EXPM1",
            "OP_ERF",
        }
        return
    if not F.compiled:
        pytest.skip("no C compiler (or TOLSYNTH_NO_COMPILE set)")
    rng = np.random.default_rng(zlib.crc32(name.encode()) + 1)
    xl, xh, yl, yh = _binary_boxes(rng, 3000, 4, 8)
    XL, XH = np.stack([xl, yl], axis=1), np.stack([xh, yh], axis=1)
    a, b = F.evaluate(XL, XH), F.evaluate_numpy(XL, XH)
    for u, v in zip(a, b):
        assert _same(u, v, name in LIBRARY)


#: operations whose values come from a library function: the C library's in the compiled
#: interpreter, NumPy's own in the extensions, which on AVX-512 machines are SIMD versions that
#: round differently by up to an ulp (exp: on 4.6 % of arguments); each is widened by 8 ulp
#: (interval_ops._REL), so the end points are compared to 16 ulp, the rest bit for bit
LIBRARY = {"exp", "log", "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh"}
LIBRARY |= {"asinh", "acosh", "atanh", "log1p", "expm1", "erf", "pow", "hypot"}


def _same(u, v, library: bool, rtol: float = 2.0**-48, scale: float = 0.0) -> bool:
    """Bit for bit, or with a library function to ``rtol`` (plus ``rtol * scale`` absolute, for a
    graph whose terms cancel), the NaNs and the flags exactly."""
    u, v = np.asarray(u), np.asarray(v)
    if not library or u.dtype == bool:
        return np.array_equal(u, v, equal_nan=True)
    with np.errstate(invalid="ignore"):  # infinite end points: equal ones are close
        close = np.allclose(u, v, rtol=rtol, atol=max(2.0**-1000, rtol * scale), equal_nan=True)
    return bool(np.array_equal(np.isnan(u), np.isnan(v)) and close)


def test_compiled_interpreter_matches_numpy_on_a_model_graph():
    from tolsynth.analysis.certify_bounds import JointGraphs
    from tolsynth.analysis.certify_structure import structure
    from tolsynth.kinematics.mechanism import load_model

    mech = load_model("xu_zhang_1988")  # a closed loop: sqrt, acos, atan2, divisions
    g = JointGraphs(structure(mech), 5, [1, 2, 3], {0: 0.0, 4: 0.0})
    if not g.centre.compiled:
        pytest.skip("no C compiler (or TOLSYNTH_NO_COMPILE set)")
    rng = np.random.default_rng(5)
    c = rng.uniform(-3, 3, (500, 3))
    w = np.exp(rng.uniform(np.log(1e-9), np.log(2.0), (500, 3)))
    for F in (g.centre, g.box):
        a, b = F.evaluate(c - w, c + w), F.evaluate_numpy(c - w, c + w)
        assert 0.2 < a[2].mean() < 1.0  # both regular and irregular boxes
        # acos and atan2 among its operations, their last-bit differences carried through sums that
        # cancel: compared to 1e-12 of the largest end point (a wrong formula is off by far more)
        scale = max(float(np.nanmax(np.abs(u))) for u in a[:2])
        for u, v in zip(a, b):
            assert _same(u, v, True, 1e-12, scale)


def _dh(theta, d, a, alpha):
    ct, st, ca_, sa = ca.cos(theta), ca.sin(theta), math.cos(alpha), math.sin(alpha)
    return ca.vertcat(
        ca.horzcat(ct, -st * ca_, st * sa, a * ct),
        ca.horzcat(st, ct * ca_, -ct * sa, a * st),
        ca.horzcat(0, sa, ca_, d),
        ca.horzcat(0, 0, 0, 1),
    )


def _six_joint_arm(a6=0.0):
    """Position of a Puma 560-like arm (standard D-H, m): a 6-input graph built here."""
    q = ca.SX.sym("q", 6)
    a = [0, 0.4318, 0.0203, 0, 0, a6]
    d = [0, 0, 0.15005, 0.4318, 0, 0.1]
    alpha = [np.pi / 2, 0, -np.pi / 2, np.pi / 2, -np.pi / 2, 0]
    T = ca.SX.eye(4)
    for i in range(6):
        T = T @ _dh(q[i], d[i], a[i], alpha[i])
    return q, T[:3, 3]


def test_composite_graph_and_mean_value_form_enclose_values():
    rng = np.random.default_rng(7)
    q, p = _six_joint_arm()
    f = ca.Function("p", [q], [p, ca.sumsqr(p)])
    nat, mv = IntervalFunction(f), MeanValueFunction(f)
    n = 300
    c = rng.uniform(-3, 3, (n, 6))
    w = np.exp(rng.uniform(np.log(1e-6), np.log(2.0), (n, 1))) * rng.uniform(0, 1, (n, 6))
    lo, hi = c - w, c + w
    t = rng.uniform(0, 1, (n, 40, 6))
    pts = lo[:, None, :] + t * (hi - lo)[:, None, :]
    vals = np.array(f.map(n * 40)(pts.reshape(-1, 6).T)[0]).T.reshape(n, 40, 3)
    vals_r = np.array(f.map(n * 40)(pts.reshape(-1, 6).T)[1]).reshape(n, 40)
    for F in (nat, mv):
        r = F([lo], [hi])
        for j in range(3):
            _check(r.lo[0][:, j, 0], r.hi[0][:, j, 0], r.regular, vals[:, :, j])
        _check(r.lo[1][:, 0, 0], r.hi[1][:, 0, 0], r.regular, vals_r)


@pytest.mark.parametrize("model", ["xu_zhang_1988", "panda"])
def test_bundled_sensitivity_graphs_enclose_values(model):
    """The package's own graphs (the paper's robot has a four-bar loop: sqrt, acos, atan2, division)
    over joint boxes and small error intervals, both forms, against plain CasADi at points."""
    import tolsynth

    mech = tolsynth.load_model(model)
    S = mech.graphs.sensitivity
    nq, ne = S.nnz_in(0), S.nnz_in(1)
    lim_lo = np.array([j.lower for j in mech.spec.joints])
    lim_hi = np.array([j.upper for j in mech.spec.joints])
    rng = np.random.default_rng(5)
    n, m = 60, 20
    c = rng.uniform(lim_lo, lim_hi, (n, nq))
    w = rng.uniform(0, 0.2, (n, nq))
    ql, qh = c - w, c + w
    dl, dh = -rng.uniform(0, 1e-3, (n, ne)), rng.uniform(0, 1e-3, (n, ne))
    t = rng.uniform(0, 1, (2, n, m, 1))
    qp = ql[:, None, :] + t[0] * (qh - ql)[:, None, :]
    dp = dl[:, None, :] + t[1] * (dh - dl)[:, None, :]
    vals = np.array(S(qp.reshape(-1, nq).T, dp.reshape(-1, ne).T))  # 6 x (n m ne), CasADi maps
    vals = vals.reshape(6, n, m, ne).transpose(1, 2, 0, 3).reshape(n, m, 6 * ne)
    for F in (IntervalFunction(S), MeanValueFunction(S, wrt=[0])):
        r = F([ql, dl], [qh, dh])
        lo = r.lo[0].reshape(n, 6 * ne)
        hi = r.hi[0].reshape(n, 6 * ne)
        assert r.regular.mean() > 0.5
        for j in range(6 * ne):
            _check(lo[:, j], hi[:, j], r.regular, vals[:, :, j])


def test_mean_value_form_is_tighter_on_small_boxes():
    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    expr = ca.sin(x) * ca.cos(y) - x * y + ca.exp(x * y) / (2 + ca.cos(x - y))
    f = ca.Function("f", [ca.vertcat(x, y)], [expr])
    rng = np.random.default_rng(3)
    c = rng.uniform(-1.5, 1.5, (200, 2))
    lo, hi = c - 1e-3, c + 1e-3
    nat, mv = IntervalFunction(f)([lo], [hi]), MeanValueFunction(f)([lo], [hi])
    wn = (nat.hi[0] - nat.lo[0]).ravel()
    wm = (mv.hi[0] - mv.lo[0]).ravel()
    assert np.all(wm <= wn) and np.median(wm / wn) < 0.5
    t = rng.uniform(0, 1, (200, 50, 2))
    pts = lo[:, None, :] + t * (hi - lo)[:, None, :]
    v = np.array(f.map(200 * 50)(pts.reshape(-1, 2).T)).reshape(200, 50)
    _check(mv.lo[0].ravel(), mv.hi[0].ravel(), mv.regular, v)
    # the true range is |grad| * 2 * half-width wide, up to second-order terms (h^2 = 1e-6); the
    # form's excess is second order too
    grad = np.array(ca.Function("g", [f.sx_in(0)], [ca.gradient(f(f.sx_in(0)), f.sx_in(0))]).map(200)(c.T)).T
    true_w = np.abs(grad).sum(axis=1) * 2e-3
    assert np.all(wm <= true_w + 1e-4) and np.median(wm / true_w) < 1.02


def test_irregular_boxes_are_flagged_and_repeat_calls_agree():
    f = ca.Function("f", [X, Y], [X / Y + ca.sqrt(X)])
    F = IntervalFunction(f)
    r = F(
        [np.array([[1.0], [1.0], [-1.0]]), np.array([[1.0], [-1.0], [1.0]])],
        [np.array([[2.0], [2.0], [2.0]]), np.array([[2.0], [1.0], [2.0]])],
    )
    assert r.regular.tolist() == [True, False, False]
    assert np.isinf(r.hi[0][1, 0, 0]) and np.isinf(r.lo[0][1, 0, 0])
    a = F([np.full((700, 1), 0.5), np.full((700, 1), 1.0)], [np.full((700, 1), 0.7), np.full((700, 1), 2.0)])
    F([np.full((3, 1), 9.0), np.full((3, 1), -5.0)], [np.full((3, 1), 9.5), np.full((3, 1), 5.0)])
    b = F([np.full((700, 1), 0.5), np.full((700, 1), 1.0)], [np.full((700, 1), 0.7), np.full((700, 1), 2.0)])
    assert np.array_equal(a.lo[0], b.lo[0]) and np.array_equal(a.hi[0], b.hi[0])


def test_bad_input_raises_typed_errors():
    with pytest.raises(InputError, match="fmod"):
        IntervalFunction(ca.Function("f", [X, Y], [ca.fmod(X, Y)]))
    F = IntervalFunction(ca.Function("f", [X], [ca.sin(X)]))
    with pytest.raises(InputError, match="lo"):
        F([np.array([[2.0]])], [np.array([[1.0]])])
    with pytest.raises(InputError, match="finite"):
        F([np.array([[np.nan]])], [np.array([[1.0]])])
    with pytest.raises(InputError, match="tol"):
        maximize(lambda a, b: a[:, 0], lambda x: x[:, 0], [0.0], [1.0], tol=-1.0)
    with pytest.raises(InputError, match="fixed"):
        BoxFunction(ca.Function("f", [X, Y], [X * Y]), fixed=[])
    with pytest.raises(InputError, match="order"):
        BoxFunction(ca.Function("f", [X], [X]), order=3)


# ---------------------------------------------------------------- branch and bound
def _bb_fns(f, order=2):
    B = BoxFunction(f, order=order)
    return B.upper, B.point


@pytest.mark.parametrize("order", [0, 1, 2])
def test_maximum_of_sin_cos_on_boxes(order):
    z = ca.SX.sym("z", 2)
    f = ca.Function("f", [z], [ca.sin(z[0]) * ca.cos(z[1])])
    bound, point = _bb_fns(f, order)
    # sin falls on [2, 3] and cos on [0.5, 1.2], both positive: the maximum is at the corner
    r = maximize(bound, point, [2.0, 0.5], [3.0, 1.2], tol=1e-9)
    exact = math.sin(2.0) * math.cos(0.5)
    assert r.certified and r.best_value <= exact + 1e-15 and exact <= r.upper_bound <= exact + 1e-9
    # interior maximum 1 at (pi/2, 0)
    r = maximize(bound, point, [0.3, -2.0], [2.9, 0.4], tol=1e-8)
    assert r.certified and 1.0 <= r.upper_bound <= 1.0 + 1e-8 and r.best_value >= 1.0 - 1e-8
    assert np.allclose(r.best_x, [np.pi / 2, 0.0], atol=1e-3)


def _planar_2r(a1=1.0, a2=0.6):
    q = ca.SX.sym("q", 2)
    a = ca.SX.sym("a", 2)
    p = ca.vertcat(a[0] * ca.cos(q[0]) + a[1] * ca.cos(q[0] + q[1]), a[0] * ca.sin(q[0]) + a[1] * ca.sin(q[0] + q[1]))
    return q, a, p, ca.substitute(p, a, ca.DM([a1, a2]))


def test_planar_2r_reach_with_a_binding_joint_constraint():
    a1, a2 = 1.0, 0.6
    q, _, _, p = _planar_2r(a1, a2)
    f = ca.Function("r", [q], [ca.norm_2(p)])
    bound, point = _bb_fns(f)
    cons = BoxFunction(ca.Function("g", [q], [0.8 - q[0] - q[1]]), order=0)  # q1 + q2 >= 0.8
    r = maximize(bound, point, [0.0, 0.0], [0.3, 2.0], tol=1e-9, constraint_fn=cons)
    exact = math.sqrt(a1**2 + a2**2 + 2 * a1 * a2 * math.cos(0.5))  # q2 = 0.8 - 0.3
    assert r.certified and exact - 1e-9 <= r.best_value <= exact + 1e-12
    assert exact <= r.upper_bound <= exact + 1e-9
    assert r.best_x[0] + r.best_x[1] >= 0.8


def test_sigma_of_planar_2r_against_a_dense_grid():
    """Largest standard deviation of the tip position, from link-length and joint-angle errors:
    sigma_1 = sqrt(lambda_max(J diag(t^2) J^T)), a function of q2 only; the reference is a dense
    grid of q2 refined by scipy, with the eigenvalues from numpy."""
    from scipy.optimize import minimize_scalar

    a1, a2, t = 1.0, 0.6, np.array([0.05, 0.05, 0.01, 0.02])  # mm-scale link, rad-scale joint
    q, a, p_sym, _ = _planar_2r()
    J = ca.substitute(ca.jacobian(p_sym, ca.vertcat(a, q)), a, ca.DM([a1, a2]))
    C = J @ ca.diag(t**2) @ J.T
    lam = 0.5 * (C[0, 0] + C[1, 1]) + ca.sqrt(0.25 * (C[0, 0] - C[1, 1]) ** 2 + C[0, 1] ** 2)
    f = ca.Function("sigma", [q], [ca.sqrt(lam)])
    bound, point = _bb_fns(f)
    r = maximize(bound, point, [-1.0, 0.3], [1.0, 2.6], tol=1e-9)

    def sigma(q2):
        q2 = np.atleast_1d(q2)
        s12, c12, one, zero = np.sin(q2), np.cos(q2), np.ones_like(q2), np.zeros_like(q2)  # q1 = 0
        Jn = np.stack(
            [np.stack([one, c12, -a2 * s12, -a2 * s12], -1), np.stack([zero, s12, a1 + a2 * c12, a2 * c12], -1)], -2
        )
        return np.sqrt(np.linalg.eigvalsh(Jn @ np.diag(t**2) @ Jn.transpose(0, 2, 1))[:, -1])

    grid = np.linspace(0.3, 2.6, 200001)
    vals = sigma(grid)
    k = int(np.argmax(vals))
    res = minimize_scalar(
        lambda v: -sigma(v)[0],
        bounds=(grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]),
        method="bounded",
        options={"xatol": 1e-12},
    )
    ref = max(vals[k], -res.fun)
    assert r.certified
    assert ref <= r.upper_bound + 1e-12 and r.upper_bound - ref <= 1e-8
    assert abs(r.best_value - ref) <= 1e-8


def test_constrained_maximum_and_infeasible_box():
    z = ca.SX.sym("z", 2)
    bound, point = _bb_fns(ca.Function("f", [z], [z[0] * z[1]]))
    cons = BoxFunction(ca.Function("g", [z], [z[0] ** 2 + z[1] ** 2 - 1]), order=0)
    r = maximize(bound, point, [0.0, 0.0], [2.0, 2.0], tol=1e-6, constraint_fn=cons)
    assert r.certified and 0.5 - 1e-6 <= r.best_value <= 0.5 and 0.5 <= r.upper_bound <= 0.5 + 1e-6
    r = maximize(bound, point, [2.0, 2.0], [3.0, 3.0], tol=1e-7, constraint_fn=cons)
    assert r.certified and r.upper_bound == -np.inf and r.best_x is None


def test_box_limit_is_reported_not_certified():
    z = ca.SX.sym("z", 2)
    f = ca.Function("f", [z], [ca.sin(5 * z[0]) * ca.cos(7 * z[1]) + 0.1 * z[0]])
    bound, point = _bb_fns(f, order=0)
    seen = []
    r = maximize(
        bound,
        point,
        [-3.0, -3.0],
        [3.0, 3.0],
        tol=1e-12,
        max_boxes=50,
        local_steps=0,
        batch=8,
        callback=lambda n, ub, best: seen.append((n, ub, best)),
    )
    assert not r.certified and "box limit" in r.reason and r.open_boxes > 0
    assert len(seen) >= 3 and all(ub >= best for _, ub, best in seen) and seen[-1][0] == r.boxes_processed
    zs = np.linspace(-3, 3, 601)
    Z0, Z1 = np.meshgrid(zs, zs)
    dense = np.max(np.sin(5 * Z0) * np.cos(7 * Z1) + 0.1 * Z0)
    assert r.upper_bound >= dense and r.best_value <= r.upper_bound


def _dense_then_local(f, lo, hi, n, seed, starts=5):
    """Reference maximum: n random points, the best few refined by L-BFGS-B (scipy)."""
    from scipy.optimize import minimize

    x = ca.SX.sym("x", f.nnz_in(0))
    grad = ca.Function("g", [x], [ca.gradient(f(x), x)])
    X0 = np.random.default_rng(seed).uniform(lo, hi, (n, len(lo)))
    v = np.array(f(X0.T)).ravel()
    best = v.max()
    for x0 in X0[np.argsort(v)[-starts:]]:
        res = minimize(
            lambda z: -float(f(z)),
            x0,
            jac=lambda z: -np.array(grad(z)).ravel(),
            bounds=list(zip(lo, hi)),
            method="L-BFGS-B",
            options={"ftol": 1e-15, "gtol": 1e-12},
        )
        best = max(best, -res.fun)
    return best


def test_six_joint_tool_coordinate_against_dense_search():
    """A coordinate of a 6-joint arm's tool point over a joint box (an interior maximum in some
    joints, at the limits in others), certified, against 20 000 random poses refined by L-BFGS-B."""
    q, p = _six_joint_arm(a6=0.05)
    f = ca.Function("px", [q], [p[0] + 0.5 * p[2]])
    lo = np.array([-0.4, -0.9, -0.5, -1.0, -1.2, -0.5])
    hi = lo + np.array([0.8, 0.8, 0.9, 1.2, 1.0, 1.0])
    bound, point = _bb_fns(f)
    r = maximize(bound, point, lo, hi, tol=1e-9)
    ref = _dense_then_local(f, lo, hi, 20000, 11)
    assert r.certified
    assert ref <= r.upper_bound + 1e-12 and r.upper_bound - ref <= 1e-8


@pytest.mark.slow
def test_six_joint_reach_against_dense_search():
    """Squared distance of the tool point from the base, which the first joint leaves unchanged
    (it is fixed as a parameter, as a caller must do with such a symmetry: otherwise every pose
    along it is a maximiser to cover with small boxes), certified with the second-order form."""
    q, p = _six_joint_arm(a6=0.05)
    q5, q1 = ca.SX.sym("q5", 5), ca.SX.sym("q1")
    f = ca.Function("r2", [q5, q1], [ca.substitute(ca.sumsqr(p), q, ca.vertcat(q1, q5))])
    lo = np.array([-0.9, -0.5, -1.0, -1.2, -0.5])
    hi = lo + np.array([0.8, 0.9, 1.2, 1.0, 1.0])
    B = BoxFunction(f, [np.array([0.3])])
    r = maximize(B.upper, B.point, lo, hi, tol=1e-9)
    f5 = ca.Function("r2_5", [q5], [f(q5, 0.3)])
    ref = _dense_then_local(f5, lo, hi, 20000, 12)
    assert r.certified
    assert ref <= r.upper_bound + 1e-12 and r.upper_bound - ref <= 1e-8
