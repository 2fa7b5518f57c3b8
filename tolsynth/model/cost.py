"""Cost-tolerance models, one per parameter and mixable in one mechanism.

Every model is a cost ``c(eps)`` of one tolerance ``eps > 0`` (in the parameter's tolerance unit),
non-increasing in ``eps``, and seen by the solvers as a function of ``u = ln eps``:

========================  ==========================  =================================================
model                     cost                        source
========================  ==========================  =================================================
:class:`PowerLaw`         ``k eps^-alpha``            Xu & Zhang 1988 (Eq. 11-12); Sutherland & Roth
                                                      1975; the "reciprocal power" of Chase &
                                                      Greenwood's survey (1988)
:class:`Chase`            ``A + B eps^-k``            Chase, Greenwood, Loosli & Hauglund 1990
                                                      (``k = 2``: Spotts 1973)
:class:`Exponential`      ``A exp(-B eps)``           Speckhart 1972
:class:`Tabulated`        shop data, PCHIP in         Fritsch & Carlson 1980 (monotone cubic
                          ``(ln eps, ln cost)``       interpolation); fitted curves as in Dong, Hu &
                                                      Xue 1994
========================  ==========================  =================================================

References
----------
* F. H. Speckhart, "Calculation of tolerance based on a minimum cost approach", J. Eng. Ind.
  94(2):447-453, 1972.
* M. F. Spotts, "Allocation of tolerances to minimize cost of assembly", J. Eng. Ind.
  95(3):762-764, 1973.
* G. H. Sutherland, B. Roth, "Mechanism design: accounting for manufacturing tolerances and costs
  in function generating problems", J. Eng. Ind. 97(1):283-286, 1975.
* K. W. Chase, W. H. Greenwood, "Design issues in mechanical tolerance analysis", Manufacturing
  Review 1(1):50-59, 1988 (survey of the cost-tolerance models).
* K. W. Chase, W. H. Greenwood, B. G. Loosli, L. F. Hauglund, "Least cost tolerance allocation for
  mechanical assemblies with automated process selection", Manufacturing Review 3(1):49-59, 1990.
* Z. Dong, W. Hu, D. Xue, "New production cost-tolerance models for tolerance synthesis",
  J. Eng. Ind. 116(2):199-206, 1994.
* F. N. Fritsch, R. E. Carlson, "Monotone piecewise cubic interpolation", SIAM J. Numer. Anal.
  17(2):238-246, 1980.

Convexity and the certificate
-----------------------------
The accuracy constraints are *linear* in ``y = eps^2`` (the covariance is ``sum_i y_i a_i a_i^T /
c``), and the map ``u -> y = e^{2u}`` is a smooth bijection of the box, so KKT points in ``u`` and
in ``y`` are the same.  The problem is therefore convex (every KKT point is the global optimum and
the Lagrangian dual bound closes the gap) whenever every cost is convex in ``y``; in terms of ``u``
that is ``c''(u) - 2 c'(u) >= 0``, which is *weaker* than convexity in ``u`` (``c'' >= 0``) because
``c' <= 0``.  Per model:

* power law and Chase: convex in ``u`` (hence in ``y``) everywhere;
* exponential: convex in ``u`` only where ``B eps >= 1``, but convex in ``y`` everywhere
  (``c'' - 2c' = A B eps e^{-B eps} (B eps + 1) > 0``): the certificate holds on any range (the
  exact reading's set is convex in ``eps``, not ``y``: there it is certified in ``eps``, see exact.py);
* tabulated: convex in ``y`` iff ``g'' + g'^2 - 2 g' >= 0`` for the log-log interpolant ``g``;
  checked exactly (a quartic per interval, its minimum from the roots of its derivative), see
  :meth:`Tabulated.convex_in_y`.  Where it fails the problem may have local optima: no certificate
  is claimed (the lower bound stays valid, see below, but need not meet the cost).

The dual bound's per-parameter minimisation ``min over [lu, uu] of c(u) + w e^{2u}`` (``w >= 0``)
is done by :meth:`CostModel.dual_min`: in closed form for the power law and Chase; by bisection on
the sign of the derivative where ``c`` is convex in ``y`` (the sum is then convex in ``y``, so the
derivative changes sign once; for the exponential model it does so on any range, since
``2 w eps - A B e^{-B eps}`` is increasing); and otherwise by a rigorous interval bound on a fine
grid (``c`` is non-increasing, so on ``[a, b]`` the function is ``>= c(b) + w e^{2a}``), which is a
valid lower bound whatever the shape.  The Lagrangian bound is valid for any positive semi-definite
multiplier (weak duality) provided this inner minimum is global, which these three methods are.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping

import casadi as ca
import numpy as np

from tolsynth.errors import InputError, OutOfRangeError

__all__ = [
    "CostModel",
    "PowerLaw",
    "Chase",
    "Exponential",
    "Tabulated",
    "Given",
    "cost_model",
    "MODELS",
]

#: bisection steps of the safeguarded 1-D minimisation (interval shrinks by 2^-64)
_BISECT = 64
#: grid points of the interval bound used where the cost is not convex in y
_GRID = 4097


def _positive(value, field_name: str, allow_zero: bool = False) -> float:
    from tolsynth.checks import HUGE, is_real

    if type(value) is float and 0.0 < value <= HUGE:  # the common case (NaN and inf fail here)
        return value
    if not is_real(value):
        raise InputError(field_name, f"expected a number, got {value!r}", "a finite positive number")
    v = float(value)
    ok = math.isfinite(v) and (v >= 0 if allow_zero else v > 0) and v <= HUGE
    if not ok:
        raise OutOfRangeError(field_name, f"got {v}", f"{'0 <=' if allow_zero else '0 <'} value <= {HUGE:g}")
    return v


class CostModel:
    """A cost-tolerance curve ``c(eps)``, seen by the solvers as ``c(u)``, ``u = ln eps``.

    Subclasses define :attr:`kind`, :meth:`theta` (the numbers, fed to the graph as a CasADi
    parameter so one graph serves every value), :meth:`_expr` (CasADi or NumPy, the same code),
    and :meth:`du` (``dc/du``, vectorised).
    """

    kind: str = ""
    source: str = ""

    # -- evaluation ----------------------------------------------------------------------------
    def theta(self) -> np.ndarray:
        raise NotImplementedError

    @property
    def signature(self) -> tuple:
        """What fixes the graph's structure (the kind and the length of ``theta``)."""
        return (self.kind, len(self.theta()))

    @staticmethod
    def _expr(u, th, lib):
        raise NotImplementedError

    def value(self, u) -> np.ndarray:
        """``c`` at ``u = ln eps`` (NumPy, vectorised)."""
        return self._expr(np.asarray(u, dtype=float), self.theta(), np)

    def cost(self, eps) -> np.ndarray:
        """``c`` at the tolerance ``eps`` (NumPy, vectorised)."""
        return self.value(np.log(np.asarray(eps, dtype=float)))

    def du(self, u) -> np.ndarray:
        """``dc/du`` (NumPy, vectorised, <= 0)."""
        raise NotImplementedError

    def d2u(self, u) -> np.ndarray:
        """``d2c/du2`` (NumPy, vectorised)."""
        raise NotImplementedError

    # -- convexity -----------------------------------------------------------------------------
    def convex_in_u(self, lo: float, hi: float) -> bool:
        """True if ``c`` is convex in ``u = ln eps`` on ``[lo, hi]`` (tolerance units)."""
        return True

    def convex_in_y(self, lo: float, hi: float) -> bool:
        """True if ``c`` is convex in ``y = eps^2`` on ``[lo, hi]``: what the certificate needs."""
        return True

    def check_range(self, lo: float, hi: float, field_name: str) -> None:
        """Raise if the model is not defined on ``[lo, hi]`` (only tabulated curves are limited)."""

    # -- the dual bound's 1-D minimisation ------------------------------------------------------
    def dual_min(self, w, lu: float, uu: float) -> tuple[np.ndarray, np.ndarray]:
        """``(min, argmin)`` over ``u`` in ``[lu, uu]`` of ``c(u) + w e^{2u}``, for each ``w >= 0``.

        The value is the exact minimum where ``c`` is convex in ``y`` (bisection on the sign of the
        derivative, which changes once), and a rigorous lower bound otherwise (interval bound on a
        grid of :data:`_GRID` points); either way a valid ingredient of a Lagrangian lower bound.
        """
        w = np.asarray(w, dtype=float)
        if self.convex_in_y(math.exp(lu), math.exp(uu)) or self._unimodal():
            a = np.full(w.shape, float(lu))
            b = np.full(w.shape, float(uu))
            for _ in range(_BISECT):
                m = 0.5 * (a + b)
                up = self.du(m) + 2.0 * w * np.exp(2.0 * m) > 0.0
                b = np.where(up, m, b)
                a = np.where(up, a, m)
            u = 0.5 * (a + b)
            cands = np.stack([u, np.full(w.shape, float(lu)), np.full(w.shape, float(uu))])
            vals = self.value(cands) + w * np.exp(2.0 * cands)
            j = np.argmin(vals, axis=0)
            return np.take_along_axis(vals, j[None], 0)[0], np.take_along_axis(cands, j[None], 0)[0]
        grid = np.linspace(lu, uu, _GRID)
        c = self.value(grid)
        we = w[..., None] * np.exp(2.0 * grid)
        lower = np.min(c[1:] + we[..., :-1], axis=-1)  # c non-increasing: c >= c(b), e^{2u} >= e^{2a}
        exact = c + we
        return np.minimum(lower, exact.min(axis=-1)), grid[np.argmin(exact, axis=-1)]

    def _unimodal(self) -> bool:
        """True if ``c(u) + w e^{2u}`` has a single minimum for every ``w >= 0`` on any range."""
        return False

    def to_dict(self) -> dict:
        raise NotImplementedError

    def describe(self) -> str:
        raise NotImplementedError


@dataclass(frozen=True)
class PowerLaw(CostModel):
    """Reciprocal power ``k eps^-alpha`` (the paper's Eq. 11-12; Sutherland & Roth 1975).

    Convex in ``u`` everywhere.  Dual minimum in closed form:
    ``u* = ln(alpha k / (2 w)) / (2 + alpha)``, clipped to the box.
    """

    k: float
    alpha: float
    kind = "power"
    source = "Xu & Zhang 1988 Eq. 11-12; Sutherland & Roth 1975"

    def __post_init__(self):
        object.__setattr__(self, "k", _positive(self.k, "cost.k"))
        object.__setattr__(self, "alpha", _positive(self.alpha, "cost.alpha"))

    def theta(self):
        return np.array([self.k, self.alpha])

    @staticmethod
    def _expr(u, th, lib):
        return th[0] * lib.exp(-th[1] * u)

    def du(self, u):
        return _power_du(np.asarray(u, dtype=float), self.k, self.alpha)

    def d2u(self, u):
        return self.alpha**2 * self.k * np.exp(-self.alpha * np.asarray(u, dtype=float))

    def dual_min(self, w, lu, uu):
        return _power_dual_min(np.asarray(w, dtype=float), self.k, self.alpha, 0.0, lu, uu)

    def to_dict(self):
        return {"model": "power", "k": self.k, "alpha": self.alpha}

    def describe(self):
        return f"{self.k:g} eps^-{self.alpha:g}"


def _power_du(u, k, alpha):
    """``d/du k e^{-alpha u}`` (one copy; ``k``, ``alpha`` scalars or one per element of ``u``)."""
    return -alpha * k * np.exp(-alpha * u)


def _power_dual_min(w, k, alpha, A, lu, uu, consts=None):
    """Closed form of ``min A + k e^{-alpha u} + w e^{2u}`` over ``[lu, uu]`` (one copy): the
    stationary point ``u* = ln(alpha k / (2 w)) / (2 + alpha)`` clipped to the box.  ``consts``:
    ``(ln(alpha k / 2), 1 / (2 + alpha))`` if the caller keeps them."""
    la, inv = consts if consts is not None else (np.log(0.5 * alpha * k), 1.0 / (2.0 + alpha))
    # w <= 0: the minimum is at the upper bound (the log of the floored w is finite, then replaced)
    u = np.where(w > 0, (la - np.log(np.maximum(w, 1e-300))) * inv, uu)
    u = np.minimum(np.maximum(u, lu), uu)
    f = k * np.exp(-alpha * u) + w * np.exp(2.0 * u)
    return (f + A if A else f), u


@dataclass(frozen=True)
class Chase(CostModel):
    """Chase's reciprocal power with a fixed part, ``A + B eps^-k`` (Chase et al. 1990; ``k = 2``
    is Spotts 1973's reciprocal square).

    Convex in ``u`` everywhere; dual minimum in closed form (as the power law, plus ``A``).
    """

    A: float
    B: float
    k: float
    kind = "chase"
    source = "Chase, Greenwood, Loosli & Hauglund 1990; Spotts 1973 (k = 2)"

    def __post_init__(self):
        object.__setattr__(self, "A", _positive(self.A, "cost.A", allow_zero=True))
        object.__setattr__(self, "B", _positive(self.B, "cost.B"))
        object.__setattr__(self, "k", _positive(self.k, "cost.k"))

    def theta(self):
        return np.array([self.A, self.B, self.k])

    @staticmethod
    def _expr(u, th, lib):
        return th[0] + th[1] * lib.exp(-th[2] * u)

    def du(self, u):
        return -self.k * self.B * np.exp(-self.k * np.asarray(u, dtype=float))

    def d2u(self, u):
        return self.k**2 * self.B * np.exp(-self.k * np.asarray(u, dtype=float))

    def dual_min(self, w, lu, uu):
        return _power_dual_min(np.asarray(w, dtype=float), self.B, self.k, self.A, lu, uu)

    def to_dict(self):
        return {"model": "chase", "A": self.A, "B": self.B, "k": self.k}

    def describe(self):
        return f"{self.A:g} + {self.B:g} eps^-{self.k:g}"


@dataclass(frozen=True)
class Exponential(CostModel):
    """Speckhart's exponential ``A exp(-B eps)`` (Speckhart 1972).

    Convex in ``u`` only where ``B eps >= 1`` (``c''(u) = A B eps e^{-B eps} (B eps - 1)``), but
    convex in ``y = eps^2`` everywhere, which is what the certificate needs (module docstring).
    The cost stays finite (``-> A``) as ``eps -> 0``, so the lower bounds of the box matter.
    """

    A: float
    B: float
    kind = "exponential"
    source = "Speckhart 1972"

    def __post_init__(self):
        object.__setattr__(self, "A", _positive(self.A, "cost.A"))
        object.__setattr__(self, "B", _positive(self.B, "cost.B"))

    def theta(self):
        return np.array([self.A, self.B])

    @staticmethod
    def _expr(u, th, lib):
        return th[0] * lib.exp(-th[1] * lib.exp(u))

    def du(self, u):
        e = np.exp(np.asarray(u, dtype=float))
        return -self.A * self.B * e * np.exp(-self.B * e)

    def d2u(self, u):
        e = np.exp(np.asarray(u, dtype=float))
        return self.A * self.B * e * np.exp(-self.B * e) * (self.B * e - 1.0)

    def convex_in_u(self, lo, hi):
        return self.B * lo >= 1.0

    def _unimodal(self):
        return True  # sign of the derivative = sign of 2 w eps - A B e^{-B eps}, increasing in eps

    def to_dict(self):
        return {"model": "exponential", "A": self.A, "B": self.B}

    def describe(self):
        return f"{self.A:g} exp(-{self.B:g} eps)"


def _pchip_slopes(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Fritsch-Carlson slopes of the monotone cubic interpolant (the rule SciPy's PCHIP uses)."""
    h = np.diff(x)
    delta = np.diff(y) / h
    if len(x) == 2:
        return np.array([delta[0], delta[0]])
    d = np.zeros_like(x)
    w1 = 2 * h[1:] + h[:-1]
    w2 = h[1:] + 2 * h[:-1]
    same = (delta[:-1] * delta[1:]) > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        hm = (w1 + w2) / (w1 / delta[:-1] + w2 / delta[1:])
    d[1:-1] = np.where(same, hm, 0.0)

    def edge(h0, h1, d0, d1):
        s = ((2 * h0 + h1) * d0 - h0 * d1) / (h0 + h1)
        if np.sign(s) != np.sign(d0):
            return 0.0
        if np.sign(d0) != np.sign(d1) and abs(s) > abs(3 * d0):
            return 3 * d0
        return s

    d[0] = edge(h[0], h[1], delta[0], delta[1])
    d[-1] = edge(h[-1], h[-2], delta[-1], delta[-2])
    return d


@dataclass(frozen=True)
class Tabulated(CostModel):
    """A cost curve from shop data: PCHIP (Fritsch & Carlson 1980) through ``(ln eps_j, ln c_j)``.

    The interpolant is monotone (so the cost never rises with a looser tolerance) and C1 (IPOPT's
    Hessian jumps at the knots, which it tolerates).  It is defined on ``[eps_1, eps_last]`` only:
    a tolerance range outside the table is an error, never an extrapolation.  Convexity in ``y``
    (the certificate's condition) is checked exactly by :meth:`convex_in_y`; where it fails the
    result claims no certificate.

    Parameters
    ----------
    eps : sequence of float
        Tolerances, strictly increasing, > 0 (the parameter's tolerance unit).
    costs : sequence of float
        Costs at those tolerances, > 0 and non-increasing.
    """

    eps: tuple
    costs: tuple
    kind = "tabulated"
    source = "shop data; PCHIP in log-log (Fritsch & Carlson 1980)"
    _x: np.ndarray = field(init=False, repr=False, compare=False)
    _coef: np.ndarray = field(init=False, repr=False, compare=False)
    _convexity: dict = field(init=False, repr=False, compare=False, default_factory=dict)

    def __post_init__(self):
        try:
            e = np.asarray(self.eps, dtype=float).ravel()
            c = np.asarray(self.costs, dtype=float).ravel()
        except (TypeError, ValueError):
            raise InputError(
                "cost.eps/cost.costs", "not numbers", "two equal-length lists of positive numbers"
            ) from None
        if e.size < 2 or e.size != c.size:
            raise InputError(
                "cost.eps/cost.costs", f"got {e.size} tolerances and {c.size} costs", "two lists of equal length >= 2"
            )
        for i, (a, b) in enumerate(zip(e, c)):
            _positive(float(a), f"cost.eps[{i}]")
            _positive(float(b), f"cost.costs[{i}]")
        if np.any(np.diff(e) <= 0):
            raise InputError("cost.eps", "not strictly increasing", "strictly increasing tolerances")
        if np.any(np.diff(c) > 0):
            raise InputError("cost.costs", "rises with a looser tolerance", "costs non-increasing in eps")
        object.__setattr__(self, "eps", tuple(float(v) for v in e))
        object.__setattr__(self, "costs", tuple(float(v) for v in c))
        x, y = np.log(e), np.log(c)
        d = _pchip_slopes(x, y)
        h = np.diff(x)
        delta = np.diff(y) / h
        c2 = (3 * delta - 2 * d[:-1] - d[1:]) / h
        c3 = (d[:-1] + d[1:] - 2 * delta) / h**2
        object.__setattr__(self, "_x", x)
        object.__setattr__(self, "_coef", np.stack([y[:-1], d[:-1], c2, c3], axis=1))  # per interval

    def theta(self):
        return np.concatenate([self._x, self._coef.ravel()])

    @property
    def signature(self):
        return (self.kind, len(self._x))

    def _g(self, u, order=0):
        u = np.asarray(u, dtype=float)
        j = np.clip(np.searchsorted(self._x, u, side="right") - 1, 0, len(self._x) - 2)
        s = u - self._x[j]
        c = self._coef[j]
        a0, a1, a2, a3 = c[..., 0], c[..., 1], c[..., 2], c[..., 3]
        if order == 0:
            return a0 + s * (a1 + s * (a2 + s * a3))
        if order == 1:
            return a1 + s * (2 * a2 + 3 * s * a3)
        return 2 * a2 + 6 * s * a3

    def value(self, u):
        return np.exp(self._g(u))

    def du(self, u):
        return self.value(u) * self._g(u, 1)

    def d2u(self, u):
        g1 = self._g(u, 1)
        return self.value(u) * (self._g(u, 2) + g1**2)

    @staticmethod
    def _graph(u, th, nk):
        """CasADi: the piecewise cubic selected by comparisons with the knots (parameters)."""
        x = th[:nk]
        coef = th[nk:]
        g = None
        for j in range(nk - 1):
            s = u - x[j]
            a0, a1, a2, a3 = (coef[4 * j + r] for r in range(4))
            piece = a0 + s * (a1 + s * (a2 + s * a3))
            g = piece if g is None else ca.if_else(u >= x[j], piece, g)
        return ca.exp(g)

    def check_range(self, lo, hi, field_name):
        if lo < self.eps[0] * (1 - 1e-12) or hi > self.eps[-1] * (1 + 1e-12):
            raise OutOfRangeError(
                field_name,
                f"tolerance range [{lo:g}, {hi:g}] leaves the table",
                f"within the tabulated [{self.eps[0]:g}, {self.eps[-1]:g}]",
            )

    def _quartic_min(self, lo, hi, with_y: bool) -> float:
        """Exact minimum over ``[ln lo, ln hi]`` of ``g'' + g'^2 - 2 g'`` (``with_y``) or of
        ``g'' + g'^2`` (convexity of ``c = e^g`` in y, resp. in u); memoised per range."""
        key = (float(lo), float(hi), with_y)
        if key in self._convexity:
            return self._convexity[key]
        from numpy.polynomial import polynomial as P

        lu, uu = math.log(lo), math.log(hi)
        best = math.inf
        for j in range(len(self._x) - 1):
            a, b = max(lu, self._x[j]), min(uu, self._x[j + 1])
            if a > b:
                continue
            _, a1, a2, a3 = self._coef[j]
            g1 = np.array([a1, 2 * a2, 3 * a3])  # ascending powers of s = u - x_j
            q = P.polyadd(P.polyadd(P.polyder(g1), P.polymul(g1, g1)), -2 * g1 if with_y else [0.0])
            s0, s1 = a - self._x[j], b - self._x[j]
            pts = [s0, s1] + [r.real for r in P.polyroots(P.polyder(q)) if abs(r.imag) < 1e-12 and s0 < r.real < s1]
            best = min(best, float(np.min(P.polyval(np.array(pts), q))))
        self._convexity[key] = best
        return best

    def convex_in_u(self, lo, hi):
        return self._quartic_min(lo, hi, with_y=False) >= -1e-12

    def convex_in_y(self, lo, hi):
        return self._quartic_min(lo, hi, with_y=True) >= -1e-12

    def to_dict(self):
        return {"model": "tabulated", "eps": list(self.eps), "costs": list(self.costs)}

    def describe(self):
        return f"table of {len(self.eps)} points on [{self.eps[0]:g}, {self.eps[-1]:g}]"


@dataclass(frozen=True)
class Given(CostModel):
    """No cost: a tolerance that is *given*, not bought (a fixed joint error, see
    :mod:`tolsynth.model.joint_errors`: an encoder's resolution, a bearing's clearance).  Its parameter
    is locked (``lower = upper``), so it never moves; it adds exactly 0 to the objective, so the
    cost reported (and a budget) is that of the tolerances being chosen."""

    kind = "given"
    source = "a given error, not a design variable"

    def theta(self):
        return np.zeros(0)

    @staticmethod
    def _expr(u, th, lib):
        return 0.0 * u

    def du(self, u):
        return np.zeros_like(np.asarray(u, dtype=float))

    def d2u(self, u):
        return np.zeros_like(np.asarray(u, dtype=float))

    def dual_min(self, w, lu, uu):
        w = np.asarray(w, dtype=float)
        u = np.full(w.shape, float(lu))
        return w * np.exp(2.0 * u), u

    def to_dict(self):
        return {"model": "given"}

    def describe(self):
        return "given (no cost)"


#: model name (as in model files and ``cost_model``) -> class and its fields
MODELS = {
    "power": (PowerLaw, ("k", "alpha")),
    "chase": (Chase, ("A", "B", "k")),
    "exponential": (Exponential, ("A", "B")),
    "tabulated": (Tabulated, ("eps", "costs")),
    "given": (Given, ()),
}


def _read_units(spec: dict, name: str, unit: str | None) -> None:
    """In place: a tabulated curve's tolerances with a unit suffix (``"20um"``) converted to ``unit``
    (the parameter's); a suffix elsewhere (plain numbers) or with no unit is refused, not misread."""
    from tolsynth.checks import check_positive
    from tolsynth.units import split_quantity

    for key, value in spec.items():
        listed = isinstance(value, (list, tuple))
        items = list(value) if listed else [value]
        for i, v in enumerate(items):
            if isinstance(v, str) and (split_quantity(v) or (0, None))[1] is not None:
                where = f"cost.{key}" + (f"[{i}]" if listed else "")
                if (name, key) != ("tabulated", "eps"):
                    raise InputError(where, f"{v!r} has a unit, but {key} is a plain number", "a number without a unit")
                if unit is None:
                    raise InputError(where, f"{v!r}: no tolerance unit to convert to", "numbers, or cost={name: model}")
                items[i] = check_positive(v, where, unit)
        spec[key] = items if listed else value


def cost_model(spec, unit: str | None = None) -> CostModel:
    """A :class:`CostModel` from itself or a dict ``{"model": name, **fields}`` (``unit``: :func:`_read_units`)."""
    if isinstance(spec, CostModel):
        return spec
    if not isinstance(spec, Mapping):
        raise InputError(
            "cost", f"got {spec!r}", "a CostModel or a dict {'model': 'power'|'chase'|'exponential'|'tabulated', ...}"
        )
    spec = dict(spec)
    name = spec.pop("model", None)
    if name not in MODELS:
        raise InputError("cost.model", f"unknown cost model {name!r}", ", ".join(MODELS))
    cls, fields = MODELS[name]
    missing = [f for f in fields if f not in spec]
    extra = [f for f in spec if f not in fields]
    if missing or extra:
        raise InputError(
            f"cost ({name})",
            f"missing {missing}" if missing else f"unknown fields {extra}",
            f"exactly the fields {list(fields)}",
        )
    _read_units(spec, name, unit)
    return cls(**spec)
