"""Cost models: values, derivatives, CasADi graph, convexity flags and the dual
bound's 1-D minimisation, each against something independent (SciPy's PCHIP and bounded scalar
minimiser, central finite differences, dense grids, closed forms with Lambert W)."""

import math

import casadi as ca
import numpy as np
import pytest

from tolsynth.errors import InputError, OutOfRangeError
from tolsynth.model.cost import Chase, Exponential, PowerLaw, Tabulated, cost_model
from tolsynth.model.cost_set import CostSet, cost_set

scipy = pytest.importorskip("scipy")
from scipy.interpolate import PchipInterpolator  # noqa: E402
from scipy.optimize import brentq, minimize_scalar  # noqa: E402
from scipy.special import lambertw  # noqa: E402

#: turning-like shop data (tolerance mm, relative cost), convex in log-log
TABLE = Tabulated([0.005, 0.01, 0.02, 0.05, 0.1, 0.2], [30.0, 16.0, 9.0, 4.5, 3.0, 2.2])
#: a curve with a kink: steep, flat, steep (not convex in y)
KINKED = Tabulated([0.01, 0.02, 0.03, 0.06, 0.1], [20.0, 10.0, 9.9, 3.0, 2.0])

MODELS = [PowerLaw(2.0, 0.7), Chase(1.0, 0.5, 1.3), Exponential(10.0, 8.0), Exponential(5.0, 40.0), TABLE, KINKED]
LO, HI = 0.01, 0.1


def test_tabulated_matches_scipy_pchip():
    x, y = np.log(TABLE.eps), np.log(TABLE.costs)
    ref = PchipInterpolator(x, y)
    u = np.linspace(x[0], x[-1], 301)
    np.testing.assert_allclose(TABLE.value(u), np.exp(ref(u)), rtol=1e-12)
    np.testing.assert_allclose(TABLE.du(u), np.exp(ref(u)) * ref(u, 1), rtol=1e-10, atol=1e-10)
    # monotone: never rises with a looser tolerance
    assert np.all(np.diff(KINKED.value(np.linspace(math.log(0.01), math.log(0.1), 500))) <= 1e-12)


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.kind)
def test_derivatives_and_graph_against_finite_differences(model):
    lo, hi = (0.006, 0.19) if isinstance(model, Tabulated) and model is TABLE else (LO * 1.01, HI * 0.99)
    u = np.linspace(math.log(lo), math.log(hi), 37)
    h = 1e-6
    fd1 = (model.value(u + h) - model.value(u - h)) / (2 * h)
    np.testing.assert_allclose(model.du(u), fd1, rtol=1e-6, atol=1e-7)
    h = 1e-4
    fd2 = (model.value(u + h) - 2 * model.value(u) + model.value(u - h)) / h**2
    if isinstance(model, Tabulated):  # C1 only: compare away from the knots
        away = np.min(np.abs(u[:, None] - np.log(model.eps)[None]), axis=1) > 2 * h
        u, fd2 = u[away], fd2[away]
    np.testing.assert_allclose(model.d2u(u), fd2, rtol=1e-4, atol=1e-4)
    cs = CostSet((model,))
    U = ca.SX.sym("u", 1)
    grad = ca.Function("g", [U], [ca.gradient(cs.expr(U), U)])
    for x in u[::6]:
        assert float(cs.graph(x, cs.theta)) == pytest.approx(float(model.value(x)), rel=1e-12)
        assert float(grad(x)) == pytest.approx(float(model.du(x)), rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.kind)
def test_convexity_flags_against_sampled_second_derivatives(model):
    u = np.linspace(math.log(LO), math.log(HI), 2001)
    q_u = model.d2u(u)
    q_y = model.d2u(u) - 2 * model.du(u)
    assert model.convex_in_u(LO, HI) == bool(np.all(q_u >= -1e-9 * np.abs(q_u).max()))
    assert model.convex_in_y(LO, HI) == bool(np.all(q_y >= -1e-9 * np.abs(q_y).max()))


def test_convexity_per_model_as_documented():
    e = Exponential(10.0, 8.0)
    assert not e.convex_in_u(0.01, 0.1) and e.convex_in_u(0.2, 1.0)  # B eps >= 1 from 0.125 on
    assert e.convex_in_y(0.001, 10.0)
    assert TABLE.convex_in_y(0.005, 0.2)
    assert not KINKED.convex_in_y(0.01, 0.1)


@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.kind)
@pytest.mark.parametrize("w", [0.0, 1.0, 300.0, 3e4, 1e7])
def test_dual_min_is_the_global_minimum(model, w):
    lu, uu = math.log(LO), math.log(HI)
    val, ustar = model.dual_min(np.array([w]), lu, uu)
    grid = np.linspace(lu, uu, 200001)
    brute = np.min(model.value(grid) + w * np.exp(2 * grid))
    ref = minimize_scalar(
        lambda x: float(model.value(x)) + w * math.exp(2 * x),
        bounds=(lu, uu),
        method="bounded",
        options={"xatol": 1e-12},
    )
    best = min(brute, ref.fun)
    assert val[0] <= best + 1e-9 * max(1.0, abs(best))  # a valid lower bound, always
    assert lu - 1e-12 <= ustar[0] <= uu + 1e-12
    if model.convex_in_y(LO, HI):  # exact where the certificate is claimed
        assert val[0] == pytest.approx(best, rel=1e-9, abs=1e-12)
    else:  # rigorous interval bound: within the grid's resolution
        assert val[0] >= best - 1e-2 * best


def test_dual_min_vectorised_and_locked():
    w = np.array([0.0, 5.0, 500.0])
    for model in MODELS:
        vals, us = model.dual_min(w, math.log(0.05), math.log(0.05))  # a locked tolerance
        np.testing.assert_allclose(us, math.log(0.05))
        np.testing.assert_allclose(vals, model.cost(0.05) + w * 0.05**2, rtol=1e-12)


def _one_direction(models, a, T, lo=1e-4, hi=10.0):
    """min sum c_i(eps_i) s.t. sum a_i^2 eps_i^2 <= T by the dual: max over lam >= 0 of
    sum_i dual_min_i(lam a_i^2) - lam T (concave in lam; its argmin u gives the primal)."""
    cs = CostSet(tuple(models))
    lu, uu = np.full(len(models), math.log(lo)), np.full(len(models), math.log(hi))

    def dphi(lam):
        _, u = cs.dual_min(lam * np.asarray(a) ** 2, lu, uu)
        return float(np.sum(np.asarray(a) ** 2 * np.exp(2 * u))) - T

    lam = brentq(dphi, 1e-12, 1e12, xtol=1e-14, rtol=1e-14)
    _, u = cs.dual_min(lam * np.asarray(a) ** 2, lu, uu)
    return np.exp(u), lam


def test_one_direction_closed_forms():
    """One accuracy direction: power law / Chase give eps_i proportional to (B_i/a_i^2)^(1/(k+2));
    the exponential model eps_i = W(A_i B_i^2 / (2 lam a_i^2)) / B_i (Lambert W)."""
    a = np.array([1.0, 2.0, 0.5])
    T = 0.01
    eps, _ = _one_direction([PowerLaw(1.0, 0.7), PowerLaw(3.0, 0.7), PowerLaw(0.5, 0.7)], a, T)
    ratio = (np.array([1.0, 3.0, 0.5]) / a**2) ** (1 / 2.7)
    np.testing.assert_allclose(eps / eps[0], ratio / ratio[0], rtol=1e-7)
    assert np.sum(a**2 * eps**2) == pytest.approx(T, rel=1e-9)
    eps, _ = _one_direction([Chase(5.0, 1.0, 1.5), Chase(0.0, 2.0, 1.5), Chase(9.0, 0.3, 1.5)], a, T)
    ratio = (np.array([1.0, 2.0, 0.3]) / a**2) ** (1 / 3.5)
    np.testing.assert_allclose(eps / eps[0], ratio / ratio[0], rtol=1e-7)
    ex = [Exponential(10.0, 30.0), Exponential(4.0, 20.0), Exponential(20.0, 50.0)]
    eps, lam = _one_direction(ex, a, T)
    closed = np.array([lambertw(m.A * m.B**2 / (2 * lam * ai**2)).real / m.B for m, ai in zip(ex, a)])
    np.testing.assert_allclose(eps, closed, rtol=1e-7)


def test_one_direction_against_scipy_slsqp():
    """The mixed case against an independent constrained solver (SLSQP in eps)."""
    from scipy.optimize import minimize

    models = [PowerLaw(1.0, 0.7), Chase(2.0, 0.5, 1.2), Exponential(10.0, 30.0), TABLE]
    a = np.array([1.0, 2.0, 0.5, 3.0])
    T = 0.004
    lo, hi = 0.005, 0.2
    eps, _ = _one_direction(models, a, T, lo, hi)
    cs = CostSet(tuple(models))
    ref = minimize(
        lambda u: cs.cost(np.exp(u)),
        np.full(4, math.log(0.01)),
        method="SLSQP",
        bounds=[(math.log(lo), math.log(hi))] * 4,
        constraints=[{"type": "ineq", "fun": lambda u: 1.0 - np.sum(a**2 * np.exp(2 * u)) / T}],
        options={"ftol": 1e-12, "maxiter": 500},
    )
    assert ref.success, ref.message
    assert cs.cost(eps) == pytest.approx(ref.fun, rel=1e-6)
    np.testing.assert_allclose(eps, np.exp(ref.x), rtol=1e-3)


def test_cost_set_from_user_input():
    names = ["a", "b", "c"]
    cs = cost_set(None, names, k=np.array([1.0, 2.0, 3.0]), alpha=np.full(3, 0.7))
    assert cs.power_law()[0].tolist() == [1.0, 2.0, 3.0]
    cs = cost_set({"b": {"model": "chase", "A": 1, "B": 2, "k": 2}}, names, k=np.ones(3), alpha=np.full(3, 0.7))
    assert [m.kind for m in cs.models] == ["power", "chase", "power"] and cs.power_law() is None
    cs = cost_set({"model": "exponential", "A": 3, "B": 4}, names)
    assert all(m == Exponential(3, 4) for m in cs.models)
    assert cost_model({"model": "tabulated", "eps": [0.1, 0.2], "costs": [2, 1]}).cost(0.15) == pytest.approx(
        math.exp(np.interp(math.log(0.15), np.log([0.1, 0.2]), np.log([2, 1])))
    )
    with pytest.raises(InputError, match="cost.model"):
        cost_model({"model": "cubic"})
    with pytest.raises(InputError, match="unknown fields"):
        cost_model({"model": "power", "k": 1, "alpha": 1, "beta": 2})
    with pytest.raises(OutOfRangeError, match="cost.alpha"):
        PowerLaw(1.0, -0.5)
    with pytest.raises(InputError, match="rises"):
        Tabulated([0.1, 0.2], [1.0, 2.0])
    with pytest.raises(OutOfRangeError, match="leaves the table"):
        TABLE.check_range(0.001, 0.1, "bounds[x]")
    with pytest.raises(InputError, match="expected 3 models"):
        cost_set([PowerLaw(1, 1)], names)
    with pytest.raises(InputError, match="no parameter"):
        cost_set({"zz": PowerLaw(1, 1)}, names, k=np.ones(3), alpha=np.ones(3))
