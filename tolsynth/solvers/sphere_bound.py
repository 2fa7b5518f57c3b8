"""A lower bound on the cost of the Gaussian sphere criterion, tighter than the per-component one.

With Gaussian errors the principal components ``w_j`` of ``dr`` (the variances ``lambda_j`` of
``V = A diag(eps^2 / c) A^T``) are independent, and the ball ``|dr| <= R`` lies inside the box
``|w_j| <= R``, so every design that meets the sphere meets

    sum_j h(lambda_j) >= ln p,    h(v) = ln P(|sqrt(v) Z| <= R) = ln erf(R / sqrt(2 v)),

and, each factor being at most 1, ``lambda_j <= v_p = (R / z(p))^2`` (the per-component
constraint: the box relaxation implies it).  ``h`` is concave where ``P(|w| <= R)`` is above about
0.894 (``v < 0.383 R^2``) and convex beyond; ``hh`` (``h`` up to the point whose tangent passes
through ``(v_p, h(v_p))``, that tangent after it) is its concave envelope on ``[0, v_p]``, so
``hh >= h``.  A symmetric concave function of the eigenvalues is a concave function of the matrix
(Lewis, "Convex analysis on the Hermitian matrices", SIAM J. Optim. 6(1), 1996), and ``V`` is
linear in ``s = eps^2``: ``phi(s) = sum_j hh(lambda_j(V(s)))`` is concave on the convex set
``lambda_max <= v_p``.  The relaxation ``phi(s) >= ln p`` therefore lies in the half-space of its
supporting hyperplane at any ``s*`` of that set, ``G . (s - s*) >= ln p - phi(s*)`` (``G`` the
gradient of ``phi``), and the cheapest point of the half-space within the bounds is a separable
problem with a one-dimensional dual (:meth:`ToleranceNLP.lagrangian_bound`): a rigorous lower
bound from any ``s*``.  At the relaxation's optimum (found here by SLSQP) the bound is that optimum.

The sphere problem itself is not convex in general (at p = 0.7 the equal-variance midpoint of two
one-axis designs that meet the sphere misses it), so no bound of this kind closes its gap.
"""

from __future__ import annotations

import math

import numpy as np

from tolsynth.probability.stats import z_of_p
from tolsynth.problem.nlp import ToleranceNLP

__all__ = ["box_bound", "half_space_bound", "log_box", "envelope_point"]

_SQPI = math.sqrt(math.pi)


def _h(v: np.ndarray, R: float) -> tuple[np.ndarray, np.ndarray]:
    """``h(v) = ln erf(R / sqrt(2 v))`` and ``h'(v)`` (0 and 0 at v = 0)."""
    from scipy.special import erfc  # scipy loads in about a second: only when a sphere bound is asked

    v = np.maximum(np.asarray(v, dtype=float), 1e-300)
    x = np.minimum(R / np.sqrt(2.0 * v), 40.0)  # beyond, erfc(x) and h' underflow to 0 (a planar arm's 0)
    E = 1.0 - erfc(x)
    dE = -(x / (v * _SQPI)) * np.exp(-x * x)  # d erf(x) / dv, dx/dv = -x / (2 v)
    return np.log1p(-erfc(x)), dE / E


def envelope_point(R: float, p: float) -> float:
    """Where the concave envelope of ``h`` on ``[0, v_p]`` leaves ``h`` for the tangent through
    ``(v_p, h(v_p))`` (``v_p`` itself where ``h`` is concave on the whole range).

    ``g(t) = h(t) + h'(t) (v_p - t) - h(v_p)`` is positive below that point and not above it
    (``g`` falls while ``h`` is concave, rises back to ``g(v_p) = 0`` while it is convex)."""
    vp = (R / z_of_p(p)) ** 2
    hp = float(_h(vp, R)[0])
    lo, hi = 0.0, vp
    for _ in range(200):
        t = 0.5 * (lo + hi)
        ht, dt = _h(t, R)
        if float(ht + dt * (vp - t)) - hp > 0.0:
            lo = t
        else:
            hi = t
        if hi - lo <= 1e-15 * vp:
            break
    return hi


def _hh(v: np.ndarray, R: float, tT: float) -> tuple[np.ndarray, np.ndarray]:
    """The concave envelope ``hh`` and its derivative (``h`` up to ``tT``, its tangent there after)."""
    hv, dv = _h(v, R)
    hT, dT = _h(tT, R)
    beyond = np.asarray(v) > tT
    return np.where(beyond, hT + dT * (np.asarray(v) - tT), hv), np.where(beyond, dT, dv)


def log_box(A: np.ndarray, s: np.ndarray, c: float, R: float, tT: float):
    """``phi(s) = sum_j hh(lambda_j)``, its gradient in ``s`` and the variances ``lambda``."""
    V = (A * (s / c)) @ A.T
    lam, vec = np.linalg.eigh(0.5 * (V + V.T))
    lam = np.maximum(lam, 0.0)
    hv, dv = _hh(lam, R, tT)
    G = (((vec.T @ A) ** 2) * dv[:, None]).sum(axis=0) / c  # d lambda_j / d s_i = (v_j . a_i)^2 / c
    return float(hv.sum()), G, lam


def box_bound(nlp: ToleranceNLP, eps_start) -> float:
    """A rigorous lower bound on the Gaussian sphere problem's cost (module docstring), from the box
    relaxation at every sphere block of ``nlp``; its other constraints are left out (a relaxation)."""
    from scipy.optimize import minimize

    spec = nlp.spec
    c = float(spec.c)
    blocks = []
    for b in spec.sphere_blocks:
        A, R, p = np.asarray(b.A, dtype=float), float(b.R), float(b.p)
        blocks.append((A, R, p, envelope_point(R, p), (R / z_of_p(p)) ** 2))
    lu, uu = nlp.lu, nlp.uu
    costs = nlp.costs

    def f(u):
        return float(np.sum(costs.costs(np.exp(u)))), costs.du(u)

    cons = []
    for A, R, p, tT, vp in blocks:
        lnp = math.log(p)
        cons.append(
            {
                "type": "ineq",
                "fun": lambda u, A=A, R=R, tT=tT, lnp=lnp: log_box(A, np.exp(2 * u), c, R, tT)[0] - lnp,
                "jac": lambda u, A=A, R=R, tT=tT: log_box(A, np.exp(2 * u), c, R, tT)[1] * 2 * np.exp(2 * u),
            }
        )
    u0 = np.clip(np.log(np.asarray(eps_start, dtype=float)), lu, uu)
    fixed = uu - lu <= 1e-12
    res = minimize(
        lambda u: f(u)[0],
        u0,
        jac=lambda u: f(u)[1],
        constraints=cons,
        bounds=[(a, b) if not fx else (a, a) for a, b, fx in zip(lu, uu, fixed)],
        method="SLSQP",
        options={"maxiter": 300, "ftol": 1e-13},
    )
    s = np.exp(2 * np.clip(res.x, lu, uu))
    # the supporting hyperplanes are valid where every variance is at most v_p: shrink s* into it
    t = min(min(vp / max(log_box(A, s, c, R, tT)[2].max(), 1e-300) for A, R, _, tT, vp in blocks), 1.0)
    s = s * t
    ws, rhs = [], []
    for A, R, p, tT, _ in blocks:
        ph, G, _ = log_box(A, s, c, R, tT)
        ws.append(-G)  # feasible designs: (-G) . s <= (-G) . s* + phi(s*) - ln p
        rhs.append(float(-G @ s) + ph - math.log(p))
    return half_space_bound(nlp, np.array(ws), np.array(rhs))


def half_space_bound(nlp: ToleranceNLP, W: np.ndarray, r: np.ndarray) -> float:
    """The cheapest cost within the bounds over the half-spaces ``W_b . eps^2 <= r_b`` (``W >= 0``),
    from below: the Lagrangian dual ``max over mu >= 0`` of the separable minimum
    (:meth:`ToleranceNLP.lagrangian_bound`), every value of which is a valid bound (weak duality)."""
    from scipy.optimize import minimize, minimize_scalar

    def dual(mu):
        return nlp.lagrangian_bound(mu @ W, float(mu @ r))

    if len(r) == 1:  # the dual is concave in mu: a bounded search over log mu
        best = minimize_scalar(lambda a: -dual(np.array([math.exp(a)])), bounds=(-40.0, 40.0), method="bounded")
        return max(float(-best.fun), dual(np.zeros(1)))
    best = minimize(lambda a: -dual(np.exp(a)), np.zeros(len(r)), method="Nelder-Mead")
    return max(float(-best.fun), dual(np.zeros(len(r))))
