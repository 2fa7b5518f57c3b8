"""The exact solver's interior-point steps where the tracking cuts' directions do not turn: the step
is then modelled with the cuts' Hessians at their fixed directions (checked against central
differences of the exact probability), and the puma560 designs whose path stalled on the Hessians
of ``min_w P`` instead are certified, their directions checked by the reference evaluator."""

import numpy as np
import pytest

import tolsynth
from tolsynth.probability.distributions import resolve, shapes_of
from tolsynth.probability.exact import direction_probability
from tolsynth.solvers.exact_cuts import Cuts
from tolsynth.solvers.exact_series import probability


def _puma_qn(dist):
    m = tolsynth.load_model("puma560")
    A = m.sensitivity(m.joints("qn"))[:3]
    return m, A, shapes_of(resolve(dist, m), m.error_parameters, m.index)


def test_fixed_hessians_against_central_differences():
    """At a direction off its minimum in w, the Hessians a step without turning is modelled with
    are those of g at the fixed direction (central differences of the series evaluated afresh, to
    1e-5 of their size), while the tracking Hessian (that of min_w P) differs from them."""
    m, A, shapes = _puma_qn("triangular")
    w = np.array([0.3, -0.5, 0.8])
    c = np.abs((w / np.linalg.norm(w)) @ A)
    # equal tolerances scaled (by bisection in ln eps) to P = 0.95 along w, the cut's margin 0.5
    lo, hi = -12.0, 2.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        P = probability(c[None] * np.exp(mid), shapes, 0.1, 1e-13)[0][0]
        lo, hi = (mid, hi) if P > 0.95 else (lo, mid)
    u = np.full(m.n, lo)
    cuts = Cuts(shapes, 1e-5)
    cuts.add(0, A, 0.1, 0.9, w, moving=True)
    g, _, H = cuts(u, 2)
    cuts.commit()
    Hf = cuts.fixed_hessians(u, H)[0]

    def gval(v):
        return (probability(c[None] * np.exp(v)[None], shapes, 0.1, 1e-13)[0][0] - 0.9) / 0.1

    h = 1e-3
    E = np.eye(m.n) * h
    F = np.array(
        [
            [
                (gval(u + E[i] + E[j]) - gval(u + E[i] - E[j]) - gval(u - E[i] + E[j]) + gval(u - E[i] - E[j]))
                / (4 * h * h)
            ]
            for i in range(m.n)
            for j in range(m.n)
        ]
    ).reshape(m.n, m.n)
    scale = np.abs(F).max()
    assert np.abs(Hf - F).max() <= 1e-5 * scale
    assert np.abs(H[0] - F).max() > 1e-3 * scale


@pytest.mark.parametrize("alpha", [0.5, 0.6])
def test_stalled_puma560_designs_are_certified(alpha):
    """puma560 at qn, R = 0.1 mm, p = 0.9, triangular errors: the two rows of a 216-row sweep whose
    interior-point path stopped at its iteration limit.  Certified (gap <= 1e-6 of the cost, bound
    below the cost); 4000 random directions by the reference evaluator meet p - 1e-7, and the
    binding direction is at p."""
    m, A, shapes = _puma_qn("triangular")
    r = tolsynth.synthesize(m, R=0.1, p=0.9, distribution="triangular", alpha=alpha, pose="qn", probability="exact")
    assert r.success and r.status.value == "optimal", r.message
    assert r.lower_bound <= r.cost and r.gap <= 1e-6 * r.cost
    sh = [s.name for s in shapes]
    D = np.random.default_rng(3).normal(size=(4000, 3))
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    assert direction_probability(D @ A * r.x, sh, 0.1).min() >= 0.9 - 1e-7
    w = r.constraints[0].directions[:, 0]
    assert abs(direction_probability(w @ A * r.x, sh, 0.1) - 0.9) <= 1e-6


@pytest.mark.parametrize(("R", "alpha"), [(0.6, 0.7), (0.3, 0.6)])
def test_turning_cuts_do_not_stall_the_path(R, alpha):
    """puma560 at qn, p = 0.9, triangular errors: rows of the R x p x alpha sweep where a tracking
    cut's turn towards its minimum in w took its margin to zero faster than the Newton step of u
    (solved without the turn) raised it, so every step was cut short and the path stopped at its
    iteration limit before a restart closed it (221 and 468 Newton steps; the sweep's other rows
    take 15-110).  Now at most 100 steps, certified, and 4000 random directions by the reference
    evaluator meet p - 1e-7."""
    m, A, shapes = _puma_qn("triangular")
    r = tolsynth.synthesize(m, R=R, p=0.9, distribution="triangular", alpha=alpha, pose="qn", probability="exact")
    assert r.success and r.status.value == "optimal", r.message
    assert r.gap <= 1e-6 * r.cost
    assert r.iterations <= 100, r.history
    sh = [s.name for s in shapes]
    D = np.random.default_rng(5).normal(size=(4000, 3))
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    assert direction_probability(D @ A * r.x, sh, R).min() >= 0.9 - 1e-7
