"""IPOPT (through CasADi) on the tolerance problem, with exact first and second derivatives.

Smooth formulation.  The principal sigma_j are eigenvalues, which are not differentiable where two
coincide, and at the optimum of the paper's example two are active at once.  So the accuracy
constraint is posed as the matrix inequality ``G(u) = I - (z/R)^2 V >= 0`` of
:mod:`tolsynth.problem`, written with a lower-triangular 3x3 factor ``L`` as the smooth equalities

    G(u) - L L^T = 0          (6 equations and 6 extra variables per block)

(every PSD matrix has such a Cholesky-type factor, zero pivots allowed).  The problem in (u, B) is smooth, IPOPT gets the exact
Hessian from CasADi, and the equality multipliers form the LMI multiplier matrix Z, whose
positive semi-definiteness, with the dual bound of :meth:`ToleranceNLP.dual_bound`, certifies the
global optimum of the convex problem in u.

For the sphere criterion (beyond the paper) each sphere block adds the smooth inequality
``P_b(u) >= p_b`` from :func:`tolsynth.problem.sphere_graph`.

Return codes are mapped to :class:`tolsynth.result.Status` here (``Solved_To_Acceptable_Level``
is *not* plain success).
"""

from __future__ import annotations

import time
from functools import lru_cache

import casadi as ca
import numpy as np

from ..problem import ToleranceNLP, nlp_graphs, sphere_graph
from ..result import Status
from .common import assemble

__all__ = ["solve_ipopt", "IPOPT_STATUS", "DEFAULT_OPTIONS"]

IPOPT_STATUS = {
    "Solve_Succeeded": Status.OPTIMAL,
    "Solved_To_Acceptable_Level": Status.OPTIMAL_INACCURATE,
    "Infeasible_Problem_Detected": Status.INFEASIBLE,
    "Maximum_Iterations_Exceeded": Status.ITERATION_LIMIT,
    "Maximum_CpuTime_Exceeded": Status.ITERATION_LIMIT,
    "Maximum_WallTime_Exceeded": Status.ITERATION_LIMIT,
    "Restoration_Failed": Status.NUMERICAL_ERROR,
    "Error_In_Step_Computation": Status.NUMERICAL_ERROR,
    "Search_Direction_Becomes_Too_Small": Status.NUMERICAL_ERROR,
    "Diverging_Iterates": Status.NUMERICAL_ERROR,
    "Invalid_Number_Detected": Status.NUMERICAL_ERROR,
}

DEFAULT_OPTIONS = {"tol": 1e-9, "constr_viol_tol": 1e-12, "max_iter": 500}

#: tried in turn until one ends in Solve_Succeeded (measured on Tables 1-3: the adaptive barrier
#: update alone converges on all 18 columns; the monotone update is the fallback)
ATTEMPTS = ({"mu_strategy": "adaptive"}, {"mu_strategy": "monotone"})

_TRIU = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
_TRIL = [(i, j) for i in range(3) for j in range(i + 1)]


@lru_cache(maxsize=32)
def _solver(n: int, m: int, tol: float, constr_viol_tol: float, max_iter: int, mu_strategy: str,
            m_sphere: int = 0, sphere_nodes: int = 0) -> ca.Function:
    g = nlp_graphs(n, m)
    n_ps = 1 + m_sphere + 3 * n * m_sphere if m_sphere else 0
    x = ca.SX.sym("x", n + 6 * m)
    p = ca.SX.sym("p", g.params + 2 * n + n_ps)
    u = x[:n]
    P, alpha, k = p[: g.params], p[g.params : g.params + n], p[g.params + n : g.params + 2 * n]
    G = g.lmi(u, P)
    cons = []
    for b in range(m):
        L = ca.SX.zeros(3, 3)
        for e, (i, j) in enumerate(_TRIL):
            L[i, j] = x[n + 6 * b + e]
        H = G[:, 3 * b : 3 * b + 3] - ca.mtimes(L, L.T)
        cons += [H[i, j] for i, j in _TRIU]
    if m_sphere:  # P(|dr| <= R_b) >= p_b, bounds given through lbg
        cons.append(sphere_graph(n, m_sphere, sphere_nodes)(u, p[g.params + 2 * n :]))
    nlp = {"x": x, "p": p, "f": g.cost(u, alpha, k), "g": ca.vertcat(*cons)}
    opts = {
        "print_time": False,
        # a trial point may overflow (Inf) on the way; IPOPT backtracks from it by itself, so the
        # evaluation warning is noise for the user (the outcome is in the return status)
        "show_eval_warnings": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.tol": tol,
        "ipopt.constr_viol_tol": constr_viol_tol,
        "ipopt.max_iter": max_iter,
        # never stop at the "acceptable" level silently: only Solve_Succeeded is success
        "ipopt.acceptable_iter": 0,
        "ipopt.hessian_approximation": "exact",
        "ipopt.mu_strategy": mu_strategy,
    }
    return ca.nlpsol("tolerance_ipopt", "ipopt", nlp, opts)


def _cholesky_start(Gb: np.ndarray) -> np.ndarray:
    """Factor L of G at the start; for a start outside the constraint (G indefinite, a user's x0)
    the factor of G's projection on the PSD cone, so IPOPT starts from the user's tolerances."""
    lam, vec = np.linalg.eigh(0.5 * (Gb + Gb.T))
    Gp = (vec * np.maximum(lam, 1e-12)) @ vec.T
    L = np.linalg.cholesky(0.5 * (Gp + Gp.T))
    return np.array([L[i, j] for i, j in _TRIL])


def solve_ipopt(nlp: ToleranceNLP, eps0: np.ndarray | None = None, **options):
    """Solve with IPOPT from ``eps0`` (default: the interior start).  Options: tol,
    constr_viol_tol, max_iter (IPOPT's own)."""
    opts = {**DEFAULT_OPTIONS, **options}
    unknown = set(opts) - set(DEFAULT_OPTIONS)
    if unknown:
        from ..errors import InputError

        raise InputError("options", f"unknown IPOPT option(s) {sorted(unknown)}", ", ".join(DEFAULT_OPTIONS))
    spec = nlp.spec
    n, m, ms = spec.n, len(spec.blocks), len(spec.sphere_blocks)
    eps0 = nlp.interior_start() if eps0 is None else np.asarray(eps0, dtype=float)
    x0 = np.concatenate([np.log(eps0)] + [_cholesky_start(Gb) for Gb in nlp.G(eps0)])
    lbx = np.concatenate([nlp.lu, np.full(6 * m, -np.inf)])
    ubx = np.concatenate([nlp.uu, np.full(6 * m, np.inf)])
    pval = np.concatenate([nlp.P, spec.alpha, spec.k] + ([nlp.Ps] if ms else []))
    lbg = np.concatenate([np.zeros(6 * m), nlp.p_sphere])
    ubg = np.concatenate([np.zeros(6 * m), np.full(ms, np.inf)])
    wall, iters, nfev, tried = 0.0, 0, 0, []
    for attempt in ATTEMPTS:
        solver = _solver(n, m, float(opts["tol"]), float(opts["constr_viol_tol"]), int(opts["max_iter"]),
                         attempt["mu_strategy"], ms, nlp.sphere_nodes if ms else 0)
        t0 = time.perf_counter()
        sol = solver(x0=x0, p=pval, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        wall += time.perf_counter() - t0
        stats = solver.stats()
        code = stats.get("return_status", "unknown")
        status = IPOPT_STATUS.get(code, Status.SOLVER_ERROR)
        iters += int(stats.get("iter_count", 0))
        nfev += int(stats.get("n_call_nlp_f", 0)) + int(stats.get("n_call_nlp_g", 0))
        tried.append(f"{attempt['mu_strategy']}: {code}")
        if status is Status.OPTIMAL:
            break
    code = "; ".join(tried) if len(tried) > 1 else code
    x = np.array(sol["x"]).ravel()
    lam_g = np.array(sol["lam_g"]).ravel()
    lam_x = np.array(sol["lam_x"]).ravel()
    Z = []
    for b in range(m):
        L = np.zeros((3, 3))
        for e, (i, j) in enumerate(_TRIU):
            v = lam_g[6 * b + e]
            if i == j:
                L[i, i] = v
            else:
                L[i, j] = L[j, i] = v / 2.0
        Z.append(-L)  # CasADi's Lagrangian is f + lam^T g; the LMI form is f - tr(Z G)
    # P_b >= p_b active at its lower bound: CasADi's lam is <= 0 there; f - mu (P - p) with mu >= 0
    mu_sphere = -lam_g[6 * m :]
    it = stats.get("iterations", {})
    history = [
        {"iteration": i, "objective": float(o), "inf_pr": float(ip), "inf_du": float(idu)}
        for i, (o, ip, idu) in enumerate(zip(it.get("obj", []), it.get("inf_pr", []), it.get("inf_du", [])))
    ]
    return assemble(
        "ipopt",
        nlp,
        np.exp(x[:n]),
        Z,
        lam_x[:n],
        status,
        code,
        iters,
        nfev,
        wall,
        history,
        mu_sphere=mu_sphere,
    )
