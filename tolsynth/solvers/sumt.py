"""SUMT with an interior penalty, each unconstrained minimisation by Powell's method: the paper's
own solver, kept to cross-check IPOPT and the published tables.

The penalty function (one CasADi graph, built from the same cost and LMI graphs IPOPT reads, and
evaluated here for *values only*):

    P(u; r) = f(u) + r * [ w_acc * sum_b -ln det G_b(u)
                           + w_bnd * sum_i ( -ln(u_i - ln lower_i) - ln(ln upper_i - u_i) ) ]

``-ln det G_b`` is the interior penalty of the accuracy constraints of block b: with
``g_j = sigma_j z/R - 1`` it equals ``-sum_j ln(-g_j) - sum_j ln(2 + g_j)``, so it blows up exactly
at the paper's constraint boundary ``g_j = 0``, but stays smooth where principal sigma coincide
(a symmetric function of the eigenvalues), which a per-eigenvalue penalty does not.  As in the
paper, the accuracy constraints carry the larger weight (``w_acc`` = 1 against ``w_bnd`` = 0.01).
Outside the interior (a leading minor of some G_b <= 0, or a bound crossed) P is +inf.  For the
sphere criterion each sphere block adds ``-w_acc ln(P_b(u) - p_b)`` from the shared sphere graph.

The outer loop lowers ``r`` by ``reduction`` from ``r0`` until the barrier's duality-gap bound
``r * (3 m w_acc + 2 n w_bnd)`` is below ``gap_tol * f``; each minimisation starts from the
previous minimiser with the previous Powell directions.
"""

from __future__ import annotations

import math
import time
from functools import lru_cache

import casadi as ca
import numpy as np

from ..errors import InputError
from ..problem import ToleranceNLP, nlp_graphs, sphere_graph
from ..result import Status
from .common import assemble
from .powell import powell

__all__ = ["solve_sumt", "DEFAULT_OPTIONS", "penalty_graph"]

DEFAULT_OPTIONS = {
    "r0": None,  # default: 0.1 * f(start) / (barrier parameter)
    "reduction": 0.1,
    "w_acc": 1.0,
    "w_bnd": 0.01,
    "gap_tol": 1e-8,
    "max_outer": 40,
    "ftol": 1e-13,
    "maxiter": 5000,
    "maxfev": 2_000_000,
}


@lru_cache(maxsize=None)
def penalty_graph(n: int, m: int, m_sphere: int = 0, sphere_nodes: int = 0,
                  cost_signature: tuple | None = None) -> ca.Function:
    """``penalty(u, P, theta, lu, uu, r, w_acc, w_bnd, Ps, ps) -> (penalty, f)`` for n
    parameters, m LMI blocks and m_sphere sphere blocks (``-ln(P_b - p_b)`` each)."""
    g = nlp_graphs(n, m, cost_signature)
    u = ca.SX.sym("u", n)
    P = ca.SX.sym("P", g.params)
    theta = ca.SX.sym("theta", g.cost.size1_in(1))
    lu, uu = ca.SX.sym("lu", n), ca.SX.sym("uu", n)
    r, w_acc, w_bnd = ca.SX.sym("r"), ca.SX.sym("w_acc"), ca.SX.sym("w_bnd")
    f = g.cost(u, theta)
    G = g.lmi(u, P)
    inside = ca.logic_and(ca.mmin(u - lu) > 0, ca.mmin(uu - u) > 0)
    barrier_acc = 0
    for b in range(m):
        Gb = G[:, 3 * b : 3 * b + 3]
        m1 = Gb[0, 0]
        m2 = Gb[0, 0] * Gb[1, 1] - Gb[0, 1] * Gb[1, 0]
        m3 = ca.det(Gb)
        inside = ca.logic_and(inside, ca.logic_and(m1 > 0, ca.logic_and(m2 > 0, m3 > 0)))
        barrier_acc = barrier_acc - ca.log(ca.fmax(m3, 1e-300))
    Ps = ca.SX.sym("Ps", 1 + m_sphere + 3 * n * m_sphere if m_sphere else 0)
    ps = ca.SX.sym("ps", m_sphere)
    if m_sphere:
        margin = sphere_graph(n, m_sphere, sphere_nodes)(u, Ps) - ps
        inside = ca.logic_and(inside, ca.mmin(margin) > 0)
        barrier_acc = barrier_acc - ca.sum1(ca.log(ca.fmax(margin, 1e-300)))
    barrier_bnd = -ca.sum1(ca.log(ca.fmax(u - lu, 1e-300)) + ca.log(ca.fmax(uu - u, 1e-300)))
    value = ca.if_else(inside, f + r * (w_acc * barrier_acc + w_bnd * barrier_bnd), ca.inf)
    return ca.Function(
        "sumt_penalty",
        [u, P, theta, lu, uu, r, w_acc, w_bnd, Ps, ps],
        [value, f],
        ["u", "P", "theta", "lu", "uu", "r", "w_acc", "w_bnd", "Ps", "ps"],
        ["penalty", "f"],
    )


def solve_sumt(nlp: ToleranceNLP, eps0: np.ndarray | None = None, **options):
    """Solve with SUMT + Powell from ``eps0`` (default: the interior start).

    Options (see DEFAULT_OPTIONS): r0, reduction (0 < . < 1), w_acc, w_bnd (weights of the
    accuracy and bound penalties), gap_tol (relative duality-gap target), max_outer, and the Powell
    options ftol, maxiter, maxfev (per inner minimisation).
    """
    unknown = set(options) - set(DEFAULT_OPTIONS)
    if unknown:
        raise InputError("options", f"unknown SUMT option(s) {sorted(unknown)}", ", ".join(DEFAULT_OPTIONS))
    o = {**DEFAULT_OPTIONS, **options}
    if not 0 < o["reduction"] < 1:
        raise InputError("options.reduction", f"got {o['reduction']}", "0 < reduction < 1")
    spec = nlp.spec
    fixed = [nm for nm, a, b in zip(spec.names, spec.lower, spec.upper) if not a < b]
    if fixed:
        raise InputError("bounds", f"SUMT needs lower < upper (an interior), not for {fixed}", "lower < upper")
    n, m, ms = spec.n, len(spec.blocks), len(spec.sphere_blocks)
    F = penalty_graph(n, m, ms, nlp.sphere_nodes if ms else 0, nlp.costs.signature)
    eps0 = nlp.interior_start() if eps0 is None else np.asarray(eps0, dtype=float)
    u = np.log(eps0)
    nu = (3 * m + ms) * o["w_acc"] + 2 * n * o["w_bnd"]  # barrier parameter: gap <= r * nu

    # the shared penalty graph with this problem's numbers fixed: two inputs per call instead of
    # nine (CasADi's per-call overhead dominates an evaluation of this small graph)
    us, rs = ca.SX.sym("u", n), ca.SX.sym("r")
    Fp = ca.Function(
        "sumt_penalty_fixed", [us, rs],
        [F(us, nlp.P, nlp.theta, nlp.lu, nlp.uu, rs, o["w_acc"], o["w_bnd"],
           nlp.Ps if ms else ca.DM(0, 1), nlp.p_sphere)[0]],
    )

    def penalty(r):
        return lambda z: float(Fp(z, r))

    f0 = nlp.cost(eps0)
    if not math.isfinite(penalty(1.0)(u)):
        raise InputError("x0", "the start point is not strictly inside the constraints", "strictly feasible tolerances")
    r = o["r0"] if o["r0"] is not None else 0.1 * f0 / nu
    t0 = time.perf_counter()
    history, directions = [], None
    nit = nfev = 0
    status, message = Status.ITERATION_LIMIT, f"stopped after {o['max_outer']} outer iterations"
    for outer in range(1, o["max_outer"] + 1):
        # inner accuracy: no finer than a hundredth of this r's own gap bound (the usual SUMT
        # practice), and never coarser than needed at the end
        ftol = o["ftol"]
        res = powell(penalty(r), u, directions=directions, ftol=ftol, line_rtol=1e-9,
                     maxiter=o["maxiter"], maxfev=o["maxfev"])
        nit += res.nit
        nfev += res.nfev
        u, directions = res.x, res.directions
        f = nlp.cost(np.exp(u))
        gmax = max(float(v[0]) for v in nlp.all_values(np.exp(u)))
        history.append(
            {"outer": outer, "r": r, "penalty": res.fun, "cost": f, "max_constraint": gmax,
             "inner_iterations": res.nit, "inner_evaluations": res.nfev, "inner_history": res.history,
             "inner_converged": res.converged}
        )
        if not res.converged:
            status, message = Status.ITERATION_LIMIT, f"Powell, outer iteration {outer}: {res.message}"
            break
        if r * nu <= o["gap_tol"] * abs(f):
            status, message = Status.OPTIMAL, (
                f"converged: barrier gap bound r*nu = {r * nu:.2e} <= {o['gap_tol']:g} * cost after {outer} outer iterations"
            )
            break
        r *= o["reduction"]
    wall = time.perf_counter() - t0
    eps = np.exp(u)
    # multipliers implied by the barrier: Z_b = r w_acc G_b^-1; bounds r w_bnd / distance
    Z = [r * o["w_acc"] * np.linalg.inv(Gb) for Gb in nlp.G(eps)]
    bound_mult = r * o["w_bnd"] * (1.0 / (nlp.uu - u) - 1.0 / (u - nlp.lu))
    mu_sphere = r * o["w_acc"] / (nlp.sphere_quadrature(eps) - nlp.p_sphere) if ms else None
    return assemble("sumt", nlp, eps, Z, bound_mult, status, message, nit, nfev, wall, history,
                    mu_sphere=mu_sphere)
