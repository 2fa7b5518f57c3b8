"""python-flint's arb balls against CasADi's own evaluation and against the package's intervals.

The arb walk of a graph (:mod:`tolsynth.analysis.interval_arb`) is checked against plain CasADi at
points (the same function, read independently), its box enclosures against CasADi's values at
random points of the box and against closed-form ranges; the package's enclosures
(:class:`tolsynth.analysis.intervals.IntervalFunction`) are then checked against arb: both hold
the exact value at every point, so they meet on every box, and arb's thin point balls at the
corners and random points fall inside the package's enclosure.
"""

from __future__ import annotations

import dataclasses
import math
import sys

import casadi as ca
import numpy as np
import pytest

import tolsynth
from tolsynth.analysis.certify_structure import structure
from tolsynth.analysis.intervals import IntervalFunction
from tolsynth.errors import InputError, MissingDependencyError, OutOfRangeError

flint = pytest.importorskip("flint")

from tolsynth.analysis import interval_arb  # noqa: E402  (after the skip: it needs python-flint)
from tolsynth.analysis.interval_arb import (  # noqa: E402
    ArbFunction,
    arb_enclosure,
    check_certificate_enclosures,
    check_enclosures,
)

MODELS = ["planar_2r", "xu_zhang_1988", "puma560"]
ULP = 2.0**-52


def _joint_boxes(name, n, seed):
    """The sensitivity graph A(q) of a bundled model and n random boxes inside its joint limits,
    0.002 to 0.2 rad wide."""
    m = tolsynth.load_model(name)
    lo = np.array([j.lower for j in m.spec.joints])
    hi = np.array([j.upper for j in m.spec.joints])
    rng = np.random.default_rng(seed)
    c = lo + rng.random((n, len(lo))) * (hi - lo)
    r = rng.uniform(0.001, 0.1, (n, len(lo)))
    return structure(m).A, np.maximum(c - r, lo), np.minimum(c + r, hi), rng


def _inside(rng, L, H, m):
    """m random points in each box, shape (n, m, n_x)."""
    return L[:, None, :] + rng.random((len(L), m, L.shape[1])) * (H - L)[:, None, :]


def _ball_bounds(balls):
    arb = flint.arb
    return (
        np.array([interval_arb._down(b, arb) for b in balls]),
        np.array([interval_arb._upward(b, arb) for b in balls]),
    )


@pytest.mark.parametrize("name", MODELS)
def test_arb_encloses_the_sensitivity_at_random_points(name):
    A, L, H, rng = _joint_boxes(name, 12, seed=1)
    F = ArbFunction(A)
    AL, AH = F(L, H)
    assert np.all(np.isfinite(AL)) and np.all(np.isfinite(AH))
    P = _inside(rng, L, H, 6)
    for k in range(len(L)):
        V = np.array(A.map(P.shape[1])(P[k].T)).reshape(3, -1, P.shape[1], order="F")  # (3, n, m)
        V = V.transpose(2, 1, 0).reshape(P.shape[1], -1)  # (m, dense column-major)
        # CasADi computes in doubles: a few ulp of the output's scale off the exact value
        tol = 64 * ULP * (1.0 + np.abs(V).max())
        assert np.all(V >= AL[k] - tol) and np.all(V <= AH[k] + tol)
        with flint.ctx.workprec(F.prec):
            for p, v in zip(P[k], V):
                lo, hi = _ball_bounds(F.balls([flint.arb(float(c)) for c in p]))
                # the arb walk reads the same function as CasADi: its thin ball (the two doubles
                # around it) sits on CasADi's value
                assert np.all(np.abs(0.5 * (lo + hi) - v) <= tol) and np.all(hi - lo <= 4 * ULP * np.abs(v) + 1e-300)
                # the exact value lies in both the point ball and the box ball: they meet
                assert np.all(hi >= AL[k]) and np.all(lo <= AH[k])


@pytest.mark.parametrize("name", MODELS)
def test_package_enclosures_meet_arb_and_hold_arbs_point_values(name):
    A, L, H, rng = _joint_boxes(name, 12, seed=2)
    F = ArbFunction(A)
    AL, AH = F(L, H)
    PL, PH, regular = IntervalFunction(A).evaluate(L, H)
    assert regular.all() and np.all(np.isfinite(PL)) and np.all(np.isfinite(PH))
    assert np.all(AL <= PH) and np.all(PL <= AH)  # both hold f(box), which is not empty
    n = L.shape[1]
    corners = np.array([[(b >> i) & 1 for i in range(n)] for b in range(2**n)], dtype=bool)
    P = _inside(rng, L, H, 4)
    with flint.ctx.workprec(F.prec):
        for k in range(len(L)):
            pts = np.concatenate([np.where(corners, H[k], L[k]), P[k]])
            for p in pts:
                lo, hi = _ball_bounds(F.balls([flint.arb(float(c)) for c in p]))
                assert np.all(hi >= PL[k]) and np.all(lo <= PH[k]), (k, p)
    # neither is trivially wide: within a factor 2 of each other on every varying output
    wa, wp = AH - AL, PH - PL
    vary = wa > 1e-9 * (1 + np.abs(AL))
    assert np.all(wp[vary] <= 2 * wa[vary]) and np.all(wa[vary] <= 2 * wp[vary])


def test_closed_form_ranges():
    x = ca.SX.sym("x")
    # x sin x increases on [0, pi/2]: its range on [0.1, 0.3] is [0.1 sin 0.1, 0.3 sin 0.3]
    f = ca.Function("f", [x], [ca.sin(x) * x])
    lo, hi = arb_enclosure(f, [0.1], [0.3])
    rlo, rhi = 0.1 * math.sin(0.1), 0.3 * math.sin(0.3)  # within two ulp of the exact values
    assert lo[0] <= rlo * (1 + 4 * ULP) and hi[0] >= rhi * (1 - 4 * ULP)
    # the upper end is tight up to the box's own widening (a ball's radius carries 30 bits, rounded
    # up: measured 6e-10); the ball product loosens the lower end (measured -0.0096 against 0.00998)
    assert hi[0] <= rhi + 1e-8 and lo[0] >= rlo - 0.025
    pl, ph, _ = IntervalFunction(f).evaluate(np.array([[0.1]]), np.array([[0.3]]))
    assert pl[0, 0] <= rlo * (1 + 4 * ULP) and ph[0, 0] >= rhi * (1 - 4 * ULP) and ph[0, 0] <= rhi + 1e-8
    # square root of [4, 9] and of [-1, 4] (the part inside its domain, [0, 4]); arc cosine of
    # [-1, 0.5], where arb's own acos gives no information (the ball reaches below -1); tight up to
    # the boxes' widening (measured up to 9e-9)
    g = ca.Function("g", [x], [ca.vertcat(ca.sqrt(x), ca.acos(x / 9))])
    lo, hi = arb_enclosure(g, [[4.0], [-1.0], [-9.0]], [[9.0], [4.0], [4.5]])
    for (k, j), (a, b) in {(0, 0): (2.0, 3.0), (1, 0): (0.0, 2.0), (2, 1): (math.pi / 3, math.pi)}.items():
        assert lo[k, j] <= a * (1 + 4 * ULP) and hi[k, j] >= b * (1 - 4 * ULP)
        assert lo[k, j] >= a - 3e-8 and hi[k, j] <= b + 3e-8


def _every_operation():
    x, y = ca.SX.sym("x"), ca.SX.sym("y")
    e = [x + y, x - y, x * y, x / y, x**y, ca.constpow(x, 2.5), x * x, ca.atan2(x, y)]
    # integer powers of a base of either sign (CasADi expands constant ones into products)
    e += [(x - 0.45) ** ca.floor(y), (x - 0.45) ** (ca.floor(y) + 1)]
    e += [ca.fmin(x, y), ca.fmax(x, y), ca.hypot(x, y), x < 0.45, x <= 0.45, x == 0.5, x != 0.5]
    e += [ca.logic_and(x > 0.3, y > 2), ca.logic_or(x > 0.6, y > 2), ca.SX.binary(ca.OP_IF_ELSE_ZERO, x > 0.45, y)]
    e += [ca.copysign(x, y - 2), -x, x + x, ca.fabs(x - 0.45), 1 / x, ca.sqrt(x), ca.exp(x), ca.log(x)]
    e += [ca.sin(4 * y), ca.cos(4 * y), ca.tan(x), ca.asin(x), ca.acos(x), ca.atan(y), ca.sinh(x), ca.cosh(x)]
    e += [ca.tanh(x), ca.asinh(x), ca.acosh(1 + y), ca.atanh(x), ca.log1p(x), ca.expm1(x), ca.erf(x)]
    e += [ca.floor(4 * x), ca.ceil(4 * x), ca.sign(x - 0.45), ca.logic_not(x > 0.45)]
    return ca.Function("ops", [x, y], [ca.vertcat(*e)])


def test_every_operation_holds_casadis_values():
    f = _every_operation()
    used = {f.instruction_id(k) for k in range(f.n_instructions())}
    missing = set(interval_arb._table()[1]) - used
    assert not missing, [interval_arb.OP_NAMES[o] for o in missing]
    rng = np.random.default_rng(3)
    n = 40
    c = np.column_stack([rng.uniform(0.2, 0.7, n), rng.uniform(1.5, 2.5, n)])
    w = np.exp(rng.uniform(np.log(1e-6), np.log(0.2), (n, 2)))
    L, H = c - w, c + w
    L[:4], H[:4] = c[:4], c[:4]  # points
    AL, AH = arb_enclosure(f, L, H)
    assert np.all(np.isfinite(AL)) and np.all(np.isfinite(AH))
    P = _inside(rng, L, H, 8)
    for k in range(n):
        V = np.array(f.map(P.shape[1])(P[k, :, 0], P[k, :, 1])).T  # (m, outputs)
        tol = 64 * ULP * (1.0 + np.abs(V))
        assert np.all(V >= AL[k] - tol) and np.all(V <= AH[k] + tol), k


def test_check_enclosures_passes_the_package_and_flags_a_faulty_enclosure(monkeypatch):
    A, L, H, _ = _joint_boxes("xu_zhang_1988", 10, seed=4)
    res = check_enclosures(A, L, H, samples=3)
    assert res.ok and res.boxes == 10 and res.points == 10 * (1 + 3)  # five inputs: no corners
    assert 0.5 < res.width_ratio_median <= 1.0 + 1e-9 and res.package_unbounded == res.arb_unbounded == 0
    assert "agree on 10 boxes" in res.summary()

    class Shifted(IntervalFunction):
        """Enclosures moved up by more than half their width: wrong on purpose."""

        def evaluate(self, XL, XH):
            lo, hi, reg = super().evaluate(XL, XH)
            d = 0.6 * (hi - lo) + 1e-9
            return lo + d, hi + d, reg

    monkeypatch.setattr(interval_arb, "IntervalFunction", Shifted)
    bad = check_enclosures(A, L, H, samples=3)
    assert not bad.ok and bad.missed and not bad.arb_missed and "DISAGREE" in bad.summary()


def test_check_certificate_enclosures():
    m = tolsynth.load_model("xu_zhang_1988")
    tol = np.full(m.graphs.sensitivity.nnz_in(1), 0.01)
    cert = tolsynth.certify_worst_pose(m, tol, keep_boxes=True)
    assert cert.method == "second-order Taylor corners"  # the bound evaluates A, J and H on boxes
    res = check_certificate_enclosures(m, cert, boxes=2, samples=1)
    # three searched joints: the centre, 8 corners and a random point in each box
    assert res.ok and res.boxes == 2 and res.points == 2 * 10
    with pytest.raises(InputError, match="keep_boxes=True"):
        check_certificate_enclosures(m, dataclasses.replace(cert, leaves=None))
    with pytest.raises(InputError, match="not planar_2r"):
        check_certificate_enclosures(tolsynth.load_model("planar_2r"), cert)


def test_typed_errors(monkeypatch):
    x = ca.SX.sym("x")
    f = ca.Function("f", [x], [ca.sin(x)])
    with pytest.raises(InputError, match="lower bound exceeds"):
        arb_enclosure(f, [1.0], [0.0])
    with pytest.raises(InputError, match=r"\(1,\) or \(n_boxes, 1\)"):
        arb_enclosure(f, [0.0, 1.0], [1.0, 2.0])
    with pytest.raises(OutOfRangeError, match="prec"):
        arb_enclosure(f, [0.0], [1.0], prec=20)
    with pytest.raises(InputError, match="erfinv"):
        ArbFunction(ca.Function("g", [x], [ca.erfinv(x)]))
    monkeypatch.setitem(sys.modules, "flint", None)  # as if python-flint were not installed
    with pytest.raises(MissingDependencyError, match=r"tolsynth\[interval\]"):
        arb_enclosure(f, [0.0], [1.0])
