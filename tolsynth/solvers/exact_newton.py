"""A primal-dual interior-point Newton method for the exact problem on a finite set of cuts:

    minimise f(u)  subject to  g_j(u) >= 0 (j = 1..m),  lu <= u <= uu,

with ``f`` the separable cost in ``u = ln eps`` and ``g_j = (P_j - p_j) / (1 - p_j)`` the normalised
margins of the direction cuts (:mod:`tolsynth.solvers.exact_series` gives their exact values,
gradients and Hessians).  The set of each cut is convex (Lagoa, Li & Sznaier 2005, see
:mod:`tolsynth.solvers.exact`) and ``f`` is convex, so Newton's method on the barrier's perturbed
KKT conditions, with a few cuts and a dozen variables, converges in a few dozen steps from the
Gaussian design, which is close.  Every iterate stays strictly feasible on the cuts (the line
search rejects a step that leaves them), so the last iterate is a feasible point of the cut problem
and its multipliers the ones the certificate starts from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Barrier", "BarrierResult", "cost_function"]

#: the barrier parameter ends at this fraction of the cost (the barrier's duality gap is
#: tau (m + 2 n), far below the certificate's 1e-6, and the margins stay far above the
#: evaluations' accuracy)
TAU_END = 1e-8
#: fraction-to-the-boundary rule for the bounds
FTB = 0.995
#: multipliers stay within this factor of tau / slack
KAPPA = 100.0
DEBUG = False
#: the barrier parameter falls once the Newton decrement squared of phi / tau is below this
DECREMENT = 1e-2


@dataclass
class BarrierResult:
    u: np.ndarray
    lam: np.ndarray  # multipliers of g_j >= 0
    z: np.ndarray  # bound multipliers in u (+ upper active, - lower active)
    iterations: int
    ok: bool
    message: str


class Barrier:
    """The cost ``(f, grad, hess diagonal)`` and the cuts ``(g, J, H)`` as callables of u."""

    def __init__(self, cost, cuts, lu: np.ndarray, uu: np.ndarray):
        self.cost, self.cuts = cost, cuts
        self.lu, self.uu = np.asarray(lu, dtype=float), np.asarray(uu, dtype=float)
        self.free = self.uu - self.lu > 1e-12

    def solve(
        self, u0: np.ndarray, lam0: np.ndarray | None = None, max_iter: int = 200, tau0: float | None = None
    ) -> BarrierResult:
        free, lu, uu = self.free, self.lu, self.uu
        u = np.array(u0, dtype=float)
        u[~free] = lu[~free]
        width = np.where(free, uu - lu, 1.0)
        u[free] = np.clip(u[free], lu[free] + 1e-9 * width[free], uu[free] - 1e-9 * width[free])
        commit = getattr(self.cuts, "commit", lambda: None)
        g, J, H = self.cuts(u, 2)
        commit()
        if g.size and not np.all(g > 0):
            return BarrierResult(u, np.zeros(g.size), np.zeros(u.size), 0, False, "start not strictly feasible")
        f, df, d2f = self.cost(u)
        scale = max(abs(f), 1e-300)
        tau = tau0 if tau0 is not None else 1e-1 * scale / max(1, g.size + free.sum())
        tau_end = TAU_END * scale / max(1, g.size + free.sum())
        sl, su = u - lu, uu - u
        lam = tau / g if g.size else np.zeros(0)
        if lam0 is not None and lam0.size == g.size:
            lam = _safeguard(np.asarray(lam0, dtype=float), tau, g)
        zl = np.where(free, tau / np.maximum(sl, 1e-300), 0.0)
        zu = np.where(free, tau / np.maximum(su, 1e-300), 0.0)
        plan, at = getattr(self.cuts, "plan", None), getattr(self.cuts, "at", None)
        slide = getattr(self.cuts, "slide", None)
        fixed = getattr(self.cuts, "fixed_hessians", None)
        path_model = getattr(self.cuts, "path_model", None)
        it = 0
        for it in range(1, max_iter + 1):
            model = path_model(u) if path_model is not None and g.size else None
            du, slope = self._step(u, df, d2f, g, J, H, lam, tau, zl, zu, sl, su, model)
            # cuts whose directions follow the worst one turn along the step: g's derivative along
            # the path gains their term (the joint Newton step; where that would take more than half
            # of the step's decrease, its part towards the minimum damped, or no turn at all).  The
            # step is solved with the turn in its linearised margins: without it a turn that takes a
            # cut's margin to zero is met by no move of u, and the line search cut every step short.
            turn = np.zeros(g.size)
            if plan is not None and g.size:
                turn = plan(u, du)

                def cost(t):
                    return -tau * float((t / g).sum())

                c1 = cost(turn)
                if slope + c1 > 0.5 * slope:
                    if model is not None:  # the step with the turn that follows the minimiser alone
                        du, slope = self._step(
                            u, df, d2f, g, J, H, lam, tau, zl, zu, sl, su, (0.0 * model[0], model[1])
                        )
                        c1 = cost(plan(u, du))
                    c0 = cost(plan(u, du, damp=0.0))
                    if slope + c0 > 0.5 * slope:
                        # the directions stay put, so the step is modelled with the cuts' own Hessians:
                        # those of min_w P (far larger where the minimum in w is far) stalled the path
                        Hf = fixed(u, H) if fixed is not None else H
                        du, slope = self._step(u, df, d2f, g, J, Hf, lam, tau, zl, zu, sl, su)
                        turn = plan(u, du, damp=0.0, follow=False)
                    else:
                        turn = plan(u, du, damp=(-0.5 * slope - c0) / (c1 - c0))
                        if slope + cost(turn) > 0.5 * slope:
                            turn = plan(u, du, damp=0.0)
            path_slope = slope - tau * float((turn / g).sum()) if g.size else slope
            Jdu = (J @ du + turn) if g.size else np.zeros(0)
            # the multipliers' Newton steps, and the fraction to the boundary on the bounds and on them
            dlam = (tau - lam * g - lam * Jdu) / g if g.size else np.zeros(0)
            dzl = np.where(free, (tau - zl * sl - zl * du) / np.maximum(sl, 1e-300), 0.0)
            dzu = np.where(free, (tau - zu * su + zu * du) / np.maximum(su, 1e-300), 0.0)
            a = 1.0
            for s, d in ((sl, du), (su, -du)):
                neg = free & (d < 0)
                if neg.any():
                    a = min(a, FTB * float(np.min(-s[neg] / d[neg])))
            ad = 1.0
            for v, d in ((lam, dlam), (zl, dzl), (zu, dzu)):
                neg = d < 0
                if neg.any():
                    ad = min(ad, FTB * float(np.min(-v[neg] / d[neg])))
            phi0 = self._phi(f, g, sl, su, tau)
            # the Newton decrement of phi / tau (self-concordant): small means on the central path
            if -slope <= DECREMENT * tau:
                # centred: the cuts whose directions are not at a minimum of P may slide first
                moved = slide(u) if slide is not None else None
                if moved is not None:
                    g, J, H = moved
                    lam = _safeguard(lam, tau, g)
                    continue
                if tau <= tau_end:
                    break
                tau = max(tau_end, min(0.1 * tau, tau**1.5 / math.sqrt(scale)))
                continue
            # backtracking on the barrier function, keeping every cut strictly feasible
            accepted = False
            full = None
            for trial in range(40):
                un = u + a * du
                if at is not None:
                    at(a)
                if trial == 0:  # the first trial is usually taken: its derivatives come with it
                    full = self.cuts(un, 2)
                    gn = full[0]
                else:
                    full = None
                    gn = self.cuts(un, 0)[0]
                if not gn.size or (np.all(gn > 0) and np.all(gn >= (1.0 - FTB) * g)):  # no cut approached too fast
                    fn, dfn, d2fn = self.cost(un)
                    sln, sun = un - lu, uu - un
                    phin = self._phi(fn, gn, sln, sun, tau)
                    if phin <= phi0 + 1e-4 * a * min(path_slope, 0.0) + 1e-15 * abs(phi0):
                        if full is None:  # the derivatives' own evaluation must agree that every cut holds
                            full = self.cuts(un, 2)
                            if not np.all(full[0] > 0):
                                full = None
                                a *= 0.5
                                continue
                        accepted = True
                        break
                a *= 0.5
            if DEBUG:
                print(f"    it {it} tau {tau:.1e} a {a:.1e} dec {-slope / tau:.2e} g {gn if accepted else None}")
            if not accepted:
                if at is not None:
                    at(0.0)
                return BarrierResult(
                    u,
                    lam,
                    zu - zl,
                    it,
                    tau <= 1e3 * tau_end,
                    f"line search failed at tau {tau:.1e} (Newton decrement {-slope / tau:.1e})",
                )
            u, f, df, d2f, sl, su = un, fn, dfn, d2fn, sln, sun
            g, J, H = full
            commit()
            lam = _safeguard(lam + ad * dlam, tau, g) if g.size else lam
            zl = np.where(free, _safeguard(zl + ad * dzl, tau, np.maximum(sl, 1e-300)), 0.0)
            zu = np.where(free, _safeguard(zu + ad * dzu, tau, np.maximum(su, 1e-300)), 0.0)
        else:
            return BarrierResult(u, lam, zu - zl, it, False, f"iteration limit at tau {tau:.1e}")
        return BarrierResult(u, lam, zu - zl, it, True, f"converged in {it} Newton steps")

    def _step(self, u, df, d2f, g, J, H, lam, tau, zl, zu, sl, su, turn=None) -> tuple[np.ndarray, float]:
        """The Newton step of the reduced system (multipliers eliminated) with the cuts' Hessians
        ``H``, and the barrier function's slope along it in u alone.  ``turn = (c, T)``: the cuts'
        margins change by ``J du + c + T du`` along the step (their directions turn), so the
        linearised complementarity ``lam (g + (J + T) du + c) + g dlam = tau`` is the path's."""
        free = self.free
        Jp, shift = (J, 0.0) if turn is None or not g.size else (J + turn[1], turn[0])
        W = np.diag(d2f) - (lam @ H.reshape(g.size, -1)).reshape(u.size, u.size) if g.size else np.diag(d2f)
        W = W + (Jp.T * (lam / g)) @ Jp if g.size else W
        W = W + np.diag(np.where(free, zl / np.maximum(sl, 1e-300) + zu / np.maximum(su, 1e-300), 0.0))
        rhs = (
            -df
            + (Jp.T @ ((tau - lam * shift) / g) if g.size else 0.0)
            + np.where(free, tau / np.maximum(sl, 1e-300) - tau / np.maximum(su, 1e-300), 0.0)
        )
        du = np.zeros_like(u)
        du[free] = _solve_pd(W[np.ix_(free, free)], rhs[free])
        Jdu = J @ du if g.size else np.zeros(0)
        slope = float(
            df @ du
            - tau * (Jdu / g).sum()
            - tau * np.sum(np.where(free, du / np.maximum(sl, 1e-300) - du / np.maximum(su, 1e-300), 0.0))
        )
        return du, slope

    def _phi(self, f, g, sl, su, tau) -> float:
        free = self.free
        return f - tau * (np.log(g).sum() + np.log(sl[free]).sum() + np.log(su[free]).sum())


def _safeguard(v: np.ndarray, tau: float, slack: np.ndarray) -> np.ndarray:
    """A multiplier kept within a factor :data:`KAPPA` of its central-path value ``tau / slack``."""
    c = tau / slack
    return np.minimum(np.maximum(v, c / KAPPA), c * KAPPA)


def _solve_pd(W: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``W^-1 r`` by Cholesky, with a growing multiple of the identity where W is not positive
    definite (the cuts' curvature off their tangent spaces can make it indefinite)."""
    if W.size == 0:
        return np.zeros(0)
    W = 0.5 * (W + W.T)
    d = np.abs(np.diag(W)).max() or 1.0
    shift = 0.0
    for _ in range(30):
        try:
            C = np.linalg.cholesky(W + shift * np.eye(W.shape[0]))
            return np.linalg.solve(C.T, np.linalg.solve(C, r))
        except np.linalg.LinAlgError:
            shift = max(2.0 * shift, 1e-10 * d)
    return np.linalg.lstsq(W, r, rcond=None)[0]


def cost_function(nlp):
    """``u -> (f, grad, Hessian diagonal)`` of the problem's separable cost."""
    costs = nlp.costs
    pl = costs.power_law()
    if pl is not None:
        k, a = pl

        def f(u):
            e = k * np.exp(-a * u)
            return math.fsum(e.tolist()), -a * e, a * a * e

        return f

    def f(u):
        return (nlp.cost(np.exp(u), u), costs.du(u), np.array([float(m.d2u(x)) for m, x in zip(costs.models, u)]))

    return f
