"""Independent references the solver tests share: random poses inside a model's joint limits and
constraints, and the optimal cost of a specification's convex form by cvxpy + Clarabel.

The convex form is in ``v = eps^2``: cost ``sum k v^(-alpha/2)``, one 3x3 LMI
``sum_i v_i a_i a_i^T / c <= I`` per block (the rows already scaled by z/R): an SDP solved by an
interior-point conic solver that shares nothing with tolsynth's NLP.
"""

from __future__ import annotations

import warnings

import numpy as np

from tolsynth.kinematics.joint_space import _feasible, _limits


def random_poses(mech, N: int, seed) -> list[np.ndarray]:
    """N joint vectors (rad) drawn uniformly inside the joint limits and joint constraints; ``seed``
    a seed or a NumPy generator (drawn from, as it is)."""
    rng = np.random.default_rng(seed)
    lo, hi = _limits(mech)
    out: list[np.ndarray] = []
    while len(out) < N:
        Q = lo[:, None] + (hi - lo)[:, None] * rng.random((len(lo), 4 * N))
        out += [Q[:, j] for j in np.nonzero(_feasible(mech, Q))[0]]
    return out[:N]


def clarabel(spec) -> float | None:
    """The optimal cost of the specification's convex form by cvxpy + Clarabel (None where Clarabel
    does not report optimal, or cvxpy is not installed)."""
    try:
        import cvxpy as cp
    except ImportError:  # pragma: no cover - the tests that need it skip first
        return None
    n = spec.n
    v = cp.Variable(n)
    cons = [v >= spec.lower**2, v <= spec.upper**2]
    for b in spec.blocks:
        As = b.scale * b.A
        M = sum(v[i] * np.outer(As[:, i], As[:, i]) / spec.c for i in range(n))
        cons.append(np.eye(3) - (M + M.T) / 2 >> 0)
    cost = sum(spec.k[i] * cp.power(v[i], -spec.alpha[i] / 2, approx=False) for i in range(n))
    prob = cp.Problem(cp.Minimize(cost), cons)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # cvxpy warns where Clarabel is inaccurate: reported as None
            prob.solve(solver="CLARABEL")
    except cp.error.SolverError:
        return None
    return float(prob.value) if prob.status == "optimal" else None
