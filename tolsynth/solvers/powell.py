"""Powell's direction-set method (Powell 1964), written here: the paper's inner minimiser.

Derivative-free: each iteration minimises along n directions in turn (bracketing by golden-ratio
expansion, then Brent's parabolic / golden-section line search), then replaces the direction of
largest decrease by the overall displacement when Powell's test says the new direction is worth it
(the rule of Numerical Recipes' ``powell``, which keeps the set from collapsing).  The function may
return ``+inf`` outside its domain (the interior penalty does): such points are never accepted, they
only bound the line search.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

__all__ = ["powell", "PowellResult", "brent"]

GOLD = 1.618033988749895
CGOLD = 0.3819660112501051  # 2 - GOLD


@dataclass
class PowellResult:
    x: np.ndarray
    fun: float
    nit: int
    nfev: int
    converged: bool
    message: str
    directions: np.ndarray
    history: list = field(default_factory=list)  # f after each iteration


def _bracket(phi: Callable[[float], float], f0: float, h: float, max_expand: int = 200):
    """Return (a, b, c, fa, fb, fc) with a < b < c (or c < b < a) and fb <= min(fa, fc)."""
    a, fa = 0.0, f0
    b, fb = h, phi(h)
    if not fb < fa:
        c, fc = -h, phi(-h)
        if not fc < fa:
            return -h, 0.0, h, fc, f0, fb  # 0 is already the lowest of the three
        b, fb = c, fc  # go the other way
    for _ in range(max_expand):
        c = b + GOLD * (b - a)
        fc = phi(c)
        if fc >= fb:  # includes +inf
            return a, b, c, fa, fb, fc
        a, fa, b, fb = b, fb, c, fc
    return a, b, c, fa, fb, fc  # unbounded descent: the caller's maxfev ends it


def brent(phi, a, b, c, fb, rtol=1e-9, atol=1e-14, maxiter=200):
    """Brent's minimisation of ``phi`` on the bracket (a, c) with interior point b, phi(b) = fb.

    Returns (x, fx).  Parabolic steps only through finite points; otherwise golden sections.
    """
    lo, hi = (a, c) if a < c else (c, a)
    x = w = v = b
    fx = fw = fv = fb
    d = e = 0.0
    for _ in range(maxiter):
        xm = 0.5 * (lo + hi)
        tol1 = rtol * abs(x) + atol
        tol2 = 2.0 * tol1
        if abs(x - xm) <= tol2 - 0.5 * (hi - lo):
            break
        use_golden = True
        if abs(e) > tol1 and math.isfinite(fw) and math.isfinite(fv):
            r = (x - w) * (fx - fv)
            q = (x - v) * (fx - fw)
            p = (x - v) * q - (x - w) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            etemp = e
            e = d
            if not (abs(p) >= abs(0.5 * q * etemp) or p <= q * (lo - x) or p >= q * (hi - x)):
                d = p / q
                u = x + d
                if u - lo < tol2 or hi - u < tol2:
                    d = tol1 if xm - x >= 0 else -tol1
                use_golden = False
        if use_golden:
            e = (lo - x) if x >= xm else (hi - x)
            d = CGOLD * e
        u = x + (d if abs(d) >= tol1 else (tol1 if d >= 0 else -tol1))
        fu = phi(u)
        if fu <= fx:
            if u >= x:
                lo = x
            else:
                hi = x
            v, w, x = w, x, u
            fv, fw, fx = fw, fx, fu
        else:
            if u < x:
                lo = u
            else:
                hi = u
            if fu <= fw or w == x:
                v, w = w, u
                fv, fw = fw, fu
            elif fu <= fv or v == x or v == w:
                v, fv = u, fu
    return x, fx


def powell(
    f: Callable[[np.ndarray], float],
    x0,
    *,
    directions: np.ndarray | None = None,
    step: float = 0.1,
    ftol: float = 1e-13,
    line_rtol: float = 1e-9,
    maxiter: int = 5000,
    maxfev: int = 2_000_000,
) -> PowellResult:
    """Minimise ``f`` from ``x0`` by Powell's direction-set method.

    Converged when one full sweep lowers f by no more than ``ftol * (|f_start| + |f|) / 2``.
    ``directions`` (rows) may carry the set over from a previous, related minimisation (SUMT does).
    """
    x = np.array(x0, dtype=float)
    n = x.size
    D = np.eye(n) if directions is None else np.array(directions, dtype=float)
    nfev = 0

    def fc(z):
        nonlocal nfev
        nfev += 1
        return float(f(z))

    fx = fc(x)
    if not math.isfinite(fx):
        return PowellResult(x, fx, 0, nfev, False, "start point outside the domain (f is not finite)", D)
    steps = np.full(n + 1, step)
    history = [fx]

    def linemin(x, fx, d, h):
        scale = np.linalg.norm(d)
        if scale == 0.0:
            return x, fx, 0.0
        dn = d / scale

        def phi(t):
            return fc(x + t * dn)

        a, b, c, fa, fb, fcc = _bracket(phi, fx, h)
        t, ft = brent(phi, a, b, c, fb, rtol=line_rtol)
        if ft < fx:
            return x + t * dn, ft, t
        return x, fx, 0.0

    for it in range(1, maxiter + 1):
        f_start, x_start = fx, x.copy()
        big, ibig = 0.0, 0
        for i in range(n):
            f_prev = fx
            x, fx, t = linemin(x, fx, D[i], steps[i])
            if t != 0.0:
                steps[i] = max(abs(t), 1e-8)
            if f_prev - fx > big:
                big, ibig = f_prev - fx, i
        history.append(fx)
        if 2.0 * (f_start - fx) <= ftol * (abs(f_start) + abs(fx)) + 1e-300:
            return PowellResult(x, fx, it, nfev, True, "converged: a sweep no longer lowers f", D, history)
        if nfev >= maxfev:
            return PowellResult(x, fx, it, nfev, False, f"stopped: {nfev} evaluations (maxfev)", D, history)
        d_new = x - x_start
        fe = fc(x + d_new)
        if fe < f_start:
            tt = 2.0 * (f_start - 2.0 * fx + fe) * (f_start - fx - big) ** 2 - big * (f_start - fe) ** 2
            if tt < 0.0:
                x, fx, t = linemin(x, fx, d_new, max(np.linalg.norm(d_new), 1e-8))
                D[ibig] = D[n - 1]
                D[n - 1] = d_new / max(np.linalg.norm(d_new), 1e-300)
    return PowellResult(x, fx, maxiter, nfev, False, f"stopped: {maxiter} iterations (maxiter)", D, history)
