"""Cost models and locks inside synthesize: closed forms of the
one-direction problem through the real solvers, the paper's robot with mixed models against cvxpy
+ Clarabel in y = eps^2 (an independent convex solver), certificates and their absence, locks."""

import math

import numpy as np
import pytest

import tolsynth
from tolsynth.model.cost import Chase, Exponential, PowerLaw, Tabulated
from tolsynth.model.cost_set import CostSet
from tolsynth.problem.nlp import ToleranceNLP
from tolsynth.problem.specification import Block, Specification
from tolsynth.solvers.ipopt import solve_ipopt
from tolsynth.solvers.sumt import solve_sumt

A_ROW = np.array([1.0, 2.0, 0.5])
SCALE = 20.0  # z/R, 1/mm: scale^2 sum eps_i^2 a_i^2 / 3 <= 1


def _one_direction(models, lower=1e-4, upper=10.0):
    n = len(models)
    A = np.zeros((3, n))
    A[0] = A_ROW
    return Specification(
        names=tuple(f"e{i}" for i in range(n)),
        units=("mm",) * n,
        R=1.0,
        p=0.99,
        z=SCALE,
        distribution="uniform",
        c=3.0,
        alpha=np.full(n, 0.7),
        k=np.ones(n),
        lower=np.full(n, lower),
        upper=np.full(n, upper),
        blocks=(Block("x", "position", SCALE, A),),
        cost=CostSet(tuple(models)),
    )


def _multiplier(eps, models):
    """lam of sum a_i^2 eps_i^2 <= T from stationarity of the first parameter: -dc/dy = lam a^2."""
    m = models[0]
    dc_dy = float(m.du(math.log(eps[0]))) / (2 * eps[0] ** 2)
    return -dc_dy / A_ROW[0] ** 2


@pytest.mark.parametrize("solve", [solve_ipopt, solve_sumt], ids=["ipopt", "sumt"])
def test_one_direction_closed_forms_through_the_solvers(solve):
    T = 3.0 / SCALE**2
    power = [PowerLaw(1.0, 0.7), PowerLaw(3.0, 0.7), PowerLaw(0.5, 0.7)]
    res = solve(ToleranceNLP(_one_direction(power)))
    assert res.success
    eps = res.x
    ratio = (np.array([1.0, 3.0, 0.5]) / A_ROW**2) ** (1 / 2.7)  # eps_i ~ (k_i / a_i^2)^(1/(alpha+2))
    np.testing.assert_allclose(eps / eps[0], ratio / ratio[0], rtol=1e-5)
    assert np.sum(A_ROW**2 * eps**2) == pytest.approx(T, rel=1e-7)
    from scipy.special import lambertw

    ex = [Exponential(10.0, 30.0), Exponential(4.0, 20.0), Exponential(20.0, 50.0)]
    res = solve(ToleranceNLP(_one_direction(ex)))
    assert res.success
    lam = _multiplier(res.x, ex)
    closed = np.array([lambertw(m.A * m.B**2 / (2 * lam * a**2)).real / m.B for m, a in zip(ex, A_ROW)])
    np.testing.assert_allclose(res.x, closed, rtol=1e-5)
    assert np.sum(A_ROW**2 * res.x**2) == pytest.approx(T, rel=1e-7)
    # not convex in u on this range (B eps < 1), convex in y: the certificate still closes
    assert not ex[0].convex_in_u(1e-4, 10.0)
    assert res.gap <= 1e-6 * res.cost and "no certificate" not in res.message


@pytest.mark.filterwarnings("ignore:Power atom")
def test_paper_robot_mixed_models_against_cvxpy():
    cp = pytest.importorskip("cvxpy")
    mech = tolsynth.load_model("xu_zhang_1988")
    names = mech.error_parameters
    models = {}
    for i, nm in enumerate(names):
        models[nm] = [PowerLaw(1.0 + 0.1 * i, 0.7), Chase(2.0, 0.5 + 0.05 * i, 1.5), Exponential(8.0, 3.0 + i)][i % 3]
    res = tolsynth.synthesize(mech, R=0.5, p=0.99, cost=models, probability="gaussian")
    assert res.success and res.gap <= 1e-6 * res.cost
    spec = res.spec
    y = cp.Variable(len(names))
    terms = []
    for i, nm in enumerate(names):
        m = models[nm]
        if isinstance(m, PowerLaw):
            terms.append(m.k * cp.power(y[i], -m.alpha / 2))
        elif isinstance(m, Chase):
            terms.append(m.A + m.B * cp.power(y[i], -m.k / 2))
        else:
            terms.append(m.A * cp.exp(-m.B * cp.sqrt(y[i])))
    b = spec.blocks[0]
    V = sum(y[i] * np.outer(b.A[:, i], b.A[:, i]) / spec.c for i in range(len(names)))
    cons = [np.eye(3) - b.scale**2 * V >> 0, y >= spec.lower**2, y <= spec.upper**2]
    prob = cp.Problem(cp.Minimize(cp.sum(cp.hstack(terms))), cons)
    prob.solve(solver=cp.CLARABEL)
    assert prob.status == "optimal"
    assert res.cost == pytest.approx(prob.value, rel=1e-5)
    np.testing.assert_allclose(res.x, np.sqrt(y.value), rtol=2e-3)
    # the cost the result reports is the models' cost at its tolerances
    assert res.cost == pytest.approx(sum(models[nm].cost(res.tolerances[nm]) for nm in names), rel=1e-12)


def test_tabulated_cost_and_a_non_convex_one_claims_no_certificate():
    mech = tolsynth.load_model("xu_zhang_1988")
    convex = Tabulated([0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5], [30.0, 16.0, 9.0, 4.5, 3.0, 2.2, 1.6])
    lengths = [nm for nm, u in zip(mech.error_parameters, mech.units) if u == "mm"]
    bounds = {nm: (0.005, 0.5) for nm in lengths}
    res = tolsynth.synthesize(
        mech, R=0.5, p=0.99, cost={nm: convex for nm in lengths}, bounds=bounds, probability="gaussian"
    )
    assert res.success and res.gap <= 1e-6 * res.cost and "no certificate" not in res.message
    kinked = Tabulated([0.005, 0.02, 0.03, 0.1, 0.5], [30.0, 10.0, 9.9, 3.0, 2.0])
    assert not kinked.convex_in_y(0.005, 0.5)
    res = tolsynth.synthesize(mech, R=0.5, p=0.99, cost={lengths[0]: kinked}, bounds=bounds, probability="gaussian")
    assert "no certificate" in res.message and lengths[0] in res.message
    assert res.lower_bound <= res.cost + 1e-9  # still a valid bound
    with pytest.raises(tolsynth.OutOfRangeError, match="leaves the table"):
        tolsynth.synthesize(
            mech, R=0.5, p=0.99, cost={lengths[0]: kinked}, bounds={lengths[0]: (0.001, 0.5)}, probability="gaussian"
        )


def test_locks():
    mech = tolsynth.load_model("xu_zhang_1988")
    free = tolsynth.synthesize(mech, R=0.5, p=0.99, probability="gaussian")
    # locking a parameter at its optimal value changes nothing
    nm = "h3"
    same = tolsynth.synthesize(mech, R=0.5, p=0.99, locks={nm: free.tolerances[nm]}, probability="gaussian")
    assert same.success and same.cost == pytest.approx(free.cost, rel=1e-7)
    np.testing.assert_allclose(same.x, free.x, rtol=1e-4)
    # a tighter lock: the others are re-optimised, the total costs more, the lock holds exactly
    tight = tolsynth.synthesize(mech, R=0.5, p=0.99, locks={nm: 0.5 * free.tolerances[nm]}, probability="gaussian")
    assert tight.success and tight.tolerances[nm] == 0.5 * free.tolerances[nm]
    assert tight.cost > free.cost and tight.gap <= 1e-6 * tight.cost
    assert tight.max_constraint <= 1 + 1e-7
    # locks that alone break the specification: a clear error naming them
    with pytest.raises(tolsynth.InfeasibleSpecificationError, match="locked tolerances") as info:
        tolsynth.synthesize(mech, R=0.5, p=0.99, locks={"h3": 0.2, "alpha1": 5.0}, probability="gaussian")
    assert "'h3'" in str(info.value) and "'alpha1'" in str(info.value)
    with pytest.raises(tolsynth.UnknownNameError):
        tolsynth.synthesize(mech, R=0.5, p=0.99, locks={"zz": 0.1}, probability="gaussian")
    with pytest.raises(tolsynth.OutOfRangeError, match="locks"):
        tolsynth.synthesize(mech, R=0.5, p=0.99, locks={"h3": -0.1}, probability="gaussian")


@pytest.mark.parametrize("field", ["k", "alpha"])
def test_k_or_alpha_named_for_a_parameter_with_a_cost_model_is_refused(field):
    m = tolsynth.load_model("xu_zhang_1988")
    value = {"k": 50.0, "alpha": 0.2}[field]
    with pytest.raises(tolsynth.InputError, match=rf"^{field}\[h3\]: .*cost model \(Chase\) sets its cost") as e:
        tolsynth.synthesize(m, R=0.5, p=0.99, cost={"h3": Chase(1, 0.4, 1)}, **{field: {"h3": value}})
    assert e.value.field == f"{field}[h3]"
    # named for a parameter priced by the power law, it is read as before
    res = tolsynth.synthesize(m, R=0.5, p=0.99, cost={"h3": Chase(1, 0.4, 1)}, **{field: {"h2": value}})
    assert res.success
    # one alpha for all prices the power-law parameters only, and is not refused
    res = tolsynth.synthesize(m, R=0.5, p=0.99, cost={"h3": Chase(1, 0.4, 1)}, alpha=0.3)
    i = m.error_parameters.index("h3")
    # the cost by hand: Chase A + B eps^-k for h3, k_j eps_j^-0.3 for every other parameter
    by_hand = 1 + 0.4 * res.x[i] ** -1 + sum(m.k[j] * res.x[j] ** -0.3 for j in range(m.n) if j != i)
    assert res.cost == pytest.approx(by_hand, rel=1e-12)
