"""The error shapes as the exact evaluator reads them: one :class:`Part` per shape, with what the
methods of :mod:`tolsynth.probability.exact` need of it.

A part is a unit variable ``Y`` (``|Y| <= 1``, or the normal with ``3 sigma = 1``) of one of the
shapes of :mod:`tolsynth.probability.distributions`, plus one that exists only here: the *cap* of a
truncated normal.  A truncated normal's density ``f`` jumps by ``f(1)`` at +-1, which makes its
characteristic function decay like ``1/s`` only; written as a mixture

    f = w * (uniform on [-1, 1]) + (1 - w) * cap,     w = 2 f(1),

the cap ``(f - f(1)) / (1 - w)`` is continuous (zero at +-1), so its characteristic function decays
like ``1/s^2``, and the uniform component is a polynomial piece the vertex formula
(:mod:`.exact_poly`) handles exactly.

Per part: the characteristic function ``cf`` (``E cos sY``; the shapes' own formulas), a
non-increasing envelope ``env >= |cf|`` for rigorous truncation bounds, the variance, the peak
(maximum) of the density, its total variation ``tv`` and Lipschitz constant ``lip`` (``inf`` with a
jump), the far decay ``c / s^power`` of the envelope, and ``P(|Y| <= x)`` and the density in
closed form.

Envelopes (each a minimum of non-increasing bounds, so non-increasing; all hold for every s >= 0):

* uniform ``sin s / s``: ``exp(-s^2/6)`` for ``s <= 2`` (``log(sin s / s) <= -s^2/6`` on
  ``(0, pi)``, from its product formula), ``1/s`` beyond (``exp(-2/3) > 1/2``, so non-increasing);
* triangular ``(sin(s/2) / (s/2))^2``: the same, squared at ``s/2``: ``exp(-s^2/12)`` for ``s <= 4``,
  ``4/s^2`` beyond;
* normal: ``exp(-s^2/18)`` itself;
* truncated normal (``sigma = 1/beta``, density ``f(y) = f(0) exp(-beta^2 y^2 / 2)`` on [-1, 1]):
  the minimum of ``1``, ``2 f(0) / s`` (integration by parts: ``|cf| <= TV(f) / s``),
  ``2 f(1) / s + V / s^2`` (twice by parts; ``V = 2 |f'(1)| + TV(f')`` on (-1, 1), which is
  ``4 beta f(1/beta)`` for ``beta > 1`` and ``4 beta^2 f(1)`` otherwise) and
  ``exp(-y^2) + c min(0.5411, 1/y)`` with ``y = s / (beta sqrt 2)`` and
  ``c = 2 exp(-beta^2/2) / (sqrt(pi) erf(beta/sqrt 2))`` (the closed form of the characteristic
  function, :func:`~tolsynth.probability.distributions._cf_truncnormal`, with its integral bounded
  by Dawson's function, whose maximum is 0.54104 and which stays below ``1/y``);
* cap: the minimum of ``1``, ``tv / s``, ``V / ((1 - w) s^2)`` and
  ``(env_truncnormal + w env_uniform) / (1 - w)``.

The truncated normal's characteristic function is a 48-node rule whose difference from the
Faddeeva-function form (SciPy's ``wofz``) is below ``3e-13`` everywhere and below ``4e-10 / s``
(measured for beta = 0.5 ... 8 on s up to 1e7, and checked in the tests); :func:`cf_error` bounds
it by ``min(5e-13, 1e-9 / s)`` per value, and the series adds that to its error bound.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from tolsynth.probability.distributions import Shape, shape
from tolsynth.probability.stats import _erf

__all__ = ["Part", "part_of", "cap_of", "UNIFORM", "cf_error"]

#: Dawson's function ``int_0^y exp(t^2 - y^2) dt`` never exceeds this
DAWSON_MAX = 0.5411
_SQRT2 = math.sqrt(2.0)
_SQRT2PI = math.sqrt(2.0 * math.pi)


@dataclass(frozen=True)
class Part:
    """One unit error part: ``kind`` in uniform, triangular, normal, truncnormal, cap (of a
    truncated normal), ``beta`` for the last two (``sigma = 1 / beta`` before truncation)."""

    kind: str
    beta: float = 0.0
    var: float = field(default=0.0, compare=False)
    peak: float = field(default=0.0, compare=False)
    tv: float = field(default=0.0, compare=False)
    lip: float = field(default=0.0, compare=False)
    far: float = field(default=1.0, compare=False)  # env(s) <= far / s^power for every s
    power: int = field(default=0, compare=False)
    w: float = field(default=0.0, compare=False)  # truncated normal: its uniform weight 2 f(1)
    V: float = field(default=0.0, compare=False)  # truncated normal and cap: the 1/s^2 constant
    cost: float = field(default=1.0, compare=False)  # relative cost of one cf value
    # away from its break points ``edges`` (unit positions where the density jumps or kinks), the
    # density's slope and curvature are at most ``slope_in`` and ``curve_in``
    edges: tuple = field(default=(), compare=False)
    slope_in: float = field(default=0.0, compare=False)
    curve_in: float = field(default=0.0, compare=False)

    @property
    def bounded(self) -> bool:
        return self.kind != "normal"

    @property
    def polynomial(self) -> bool:
        """A piecewise-polynomial density the vertex formula takes (uniform, triangular)."""
        return self.kind in ("uniform", "triangular")

    # -- characteristic function and envelope ---------------------------------------------------
    def cf(self, s: np.ndarray) -> np.ndarray:
        """``E cos(sY)`` for ``s >= 0`` (a truncated normal's from :func:`tn_cf`)."""
        if self.kind == "cap":
            return (tn_cf(self.beta, s) - self.w * shape("uniform").cf(s)) / (1.0 - self.w)
        if self.kind == "truncnormal":
            return tn_cf(self.beta, s)
        return self.shape.cf(s)

    @property
    def shape(self) -> Shape:
        if self.kind == "truncnormal":
            return shape(f"truncnormal({self.beta:g})")
        return shape(self.kind)

    def env(self, s: np.ndarray) -> np.ndarray:
        """A non-increasing upper bound on ``|cf(s)|`` (see the module docstring)."""
        s = np.asarray(s, dtype=float)
        with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
            if self.kind == "uniform":
                return np.where(s <= 2.0, np.exp(-s * s / 6.0), 1.0 / s)
            if self.kind == "triangular":
                return np.where(s <= 4.0, np.exp(-s * s / 12.0), 4.0 / (s * s))
            if self.kind == "normal":
                return np.exp(-s * s / 18.0)
            tn = _tn_env(self.beta, s)
            if self.kind == "truncnormal":
                return tn
            uni = np.where(s <= 2.0, np.exp(-s * s / 6.0), 1.0 / s)
            out = np.minimum(np.minimum(1.0, self.tv / s), self.V / (s * s))
            return np.minimum(out, (tn + self.w * uni) / (1.0 - self.w))

    # -- closed forms of one term -----------------------------------------------------------------
    def within(self, x: np.ndarray) -> np.ndarray:
        """``P(|Y| <= x)`` for ``x >= 0``."""
        x = np.asarray(x, dtype=float)
        xc = np.minimum(x, 1.0)
        if self.kind == "uniform":
            return xc
        if self.kind == "triangular":
            return 1.0 - (1.0 - xc) ** 2
        if self.kind == "normal":
            return _erf(3.0 * x / _SQRT2)
        tn = np.where(x >= 1.0, 1.0, _erf(self.beta * xc / _SQRT2) / math.erf(self.beta / _SQRT2))
        if self.kind == "truncnormal":
            return tn
        return np.clip((tn - self.w * xc) / (1.0 - self.w), 0.0, 1.0)

    def density(self, x: np.ndarray) -> np.ndarray:
        """The density of Y at ``x >= 0`` (0 on and beyond a jump at 1)."""
        x = np.asarray(x, dtype=float)
        inside = x < 1.0
        if self.kind == "uniform":
            return np.where(inside, 0.5, 0.0)
        if self.kind == "triangular":
            return np.maximum(1.0 - x, 0.0)
        if self.kind == "normal":
            return 3.0 / _SQRT2PI * np.exp(-4.5 * x * x)
        f = np.where(inside, self.peak_tn * np.exp(-0.5 * (self.beta * x) ** 2), 0.0)
        if self.kind == "truncnormal":
            return f
        return np.where(inside, (f - 0.5 * self.w) / (1.0 - self.w), 0.0)

    @property
    def peak_tn(self) -> float:
        """The truncated normal's density at 0 (also for its cap)."""
        return shape(f"truncnormal({self.beta:g})").peak


def cf_error(s: np.ndarray, beta: float) -> np.ndarray:
    """A bound on the error of one value of :func:`tn_cf` at s.  From the table (below
    :func:`asymptotic_start`): 7.1e-14 of interpolation plus three times the 48-node rule's error,
    which is below 4e-13 everywhere (measured against the Faddeeva function) and at rounding level
    for ``y = s / (beta sqrt 2) <= 1``: there the 48-node Gauss-Legendre remainder on ``[0, y]``,
    ``y^97 (48!)^4 / (97 (96!)^3) max |f^(96)|``, with Cauchy's ``max |f^(96)| <= 96! e^((y+1)^2 + 2x)``
    for the entire integrand ``f(t) = e^(t^2 - y^2) sin(2xt)`` (``x = beta / sqrt 2 <= 5.7``), is
    below 1e-50.  So 1e-13 for ``s <= beta sqrt 2``, 1.3e-12 beyond.  From the expansion: 2.1e-14."""
    s = np.asarray(s, dtype=float)
    table = np.where(s <= beta * math.sqrt(2.0), 1e-13, 1.3e-12)
    return np.where(s < asymptotic_start(beta), table, 2.1e-14)


#: the table of a truncated normal's characteristic function: step and block length
TABLE_STEP = 1.0 / 32.0
TABLE_BLOCK = 4096
_TABLES: dict = {}
#: the expansion of :func:`tn_cf` takes this many terms, its remainder bound at most ASYMPTOTIC_ERROR
ASYMPTOTIC_TERMS = 8
ASYMPTOTIC_ERROR = 2e-14


@lru_cache(maxsize=None)
def _derivatives_at_one(beta: float) -> tuple[tuple[float, ...], float]:
    """``f^(n)(1)`` for n < 8 of the truncated normal's density ``f(y) = f(0) exp(-beta^2 y^2/2)``
    (``f^(n)(y) = f(0) (-beta)^n He_n(beta y) exp(-beta^2 y^2 / 2)``), and the remainder constant
    ``2 f(0) beta^8 1.0865 sqrt(8!)`` (Cramer's inequality ``|He_n(z)| exp(-z^2/4) <= 1.0865 sqrt(n!)``
    bounds ``int_0^1 |f^(8)|``)."""
    f0 = shape(f"truncnormal({beta:g})").peak
    e = math.exp(-0.5 * beta * beta)
    he = [1.0, beta]
    for n in range(2, ASYMPTOTIC_TERMS):
        he.append(beta * he[-1] - (n - 1) * he[-2])  # He_n = z He_(n-1) - (n-1) He_(n-2)
    d = tuple(f0 * (-beta) ** n * he[n] * e for n in range(ASYMPTOTIC_TERMS))
    return d, 2.0 * f0 * beta**ASYMPTOTIC_TERMS * 1.0865 * math.sqrt(math.factorial(ASYMPTOTIC_TERMS))


@lru_cache(maxsize=None)
def asymptotic_start(beta: float) -> float:
    """Where the expansion's remainder bound falls to ``ASYMPTOTIC_ERROR`` (at least 32)."""
    C = _derivatives_at_one(beta)[1]
    return max(32.0, (C / ASYMPTOTIC_ERROR) ** (1.0 / ASYMPTOTIC_TERMS))


def _asymptotic(beta: float, s: np.ndarray) -> np.ndarray:
    """``2 sum_{n<8} f^(n)(1) T_n(s)``, ``T_n = (-1)^floor(n/2) (sin s if n even else cos s) / s^(n+1)``:
    ``int_{-1}^{1} f cos(sy)`` integrated by parts eight times (f even, so the terms at 0 vanish);
    the remainder is ``(2 / s^8) int_0^1 f^(8) cos(sy) dy``."""
    d, _ = _derivatives_at_one(beta)
    sn, cs = np.sin(s), np.cos(s)
    inv = 1.0 / s
    out = np.zeros(s.shape)
    p = inv.copy()
    for n in range(ASYMPTOTIC_TERMS):
        trig = sn if n % 2 == 0 else cs
        out += (-1) ** (n // 2) * d[n] * trig * p
        p = p * inv
    return 2.0 * out


def _table(beta: float, top: int) -> np.ndarray:
    """The table of ``cf(i h)`` for nodes ``i = -3 .. >= top`` (position ``i + 3``), grown in blocks
    of fixed length, each computed the same way whenever it is (a cache changes speed, not answers)."""
    tab = _TABLES.get(beta)
    have = 0 if tab is None else tab.size - 3
    if have > top:
        return tab
    sh = shape(f"truncnormal({beta:g})")
    blocks = [] if tab is None else [tab]
    j = have // TABLE_BLOCK
    while j * TABLE_BLOCK <= top:
        blocks.append(sh.cf(np.arange(j * TABLE_BLOCK, (j + 1) * TABLE_BLOCK) * TABLE_STEP))
        j += 1
    if tab is None:
        blocks[0] = np.concatenate([blocks[0][3:0:-1], blocks[0]])  # cf is even: nodes -3..-1
    tab = np.concatenate(blocks)
    _TABLES[beta] = tab
    return tab


def tn_cf(beta: float, s: np.ndarray) -> np.ndarray:
    """The truncated normal's characteristic function.  Below :func:`asymptotic_start` (32 to
    about 1000 with beta) by 7-point Lagrange interpolation in a table of the 48-node rule
    (:func:`~tolsynth.probability.distributions._cf_truncnormal`) with step ``h = 1/32``: the
    interpolation error is at most ``max |prod_{j=-3..3} (t - j)| h^7 / 7! * max |phi^(7)|
    <= 12.3 h^7 / 5040 < 8e-14`` (``|phi^(7)(s)| = |E Y^7 sin sY| <= 1``), plus the table's own error
    (below 3e-13) times the interpolation's Lebesgue constant (below 3).  Beyond, by the expansion
    of :func:`_asymptotic` (remainder below 2e-14).  :func:`cf_error` states both bounds."""
    s = np.asarray(s, dtype=float)
    out = np.empty(s.shape)
    far = s >= asymptotic_start(beta)
    if far.any():
        out[far] = _asymptotic(beta, s[far])
    near = ~far
    if not near.any():
        return out
    x = s[near] / TABLE_STEP
    i = np.floor(x).astype(np.int64)
    t = x - i
    tab = _table(beta, int(i.max()) + 4)
    k = i + 3  # position of node i
    d = [t - j for j in range(-3, 4)]  # t - j for the nodes j = -3..3
    val = np.zeros(t.shape)
    for a in range(7):
        w = np.ones(t.shape)
        for c in range(7):
            if c != a:
                w *= d[c]
        denom = math.prod(float(a - c) for c in range(7) if c != a)
        val += (w / denom) * tab[k + a - 3]
    out[near] = val
    return out


def _tn_env(beta: float, s: np.ndarray) -> np.ndarray:
    """The truncated normal's envelope (module docstring), non-increasing."""
    sh = shape(f"truncnormal({beta:g})")
    f0 = sh.peak
    f1 = f0 * math.exp(-0.5 * beta * beta)
    V = 4.0 * beta * f0 * math.exp(-0.5) if beta > 1.0 else 4.0 * beta * beta * f1
    c = 2.0 * math.exp(-0.5 * beta * beta) / (math.sqrt(math.pi) * math.erf(beta / _SQRT2))
    y = s / (beta * _SQRT2)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        out = np.minimum(1.0, 2.0 * f0 / s)
        out = np.minimum(out, 2.0 * f1 / s + V / (s * s))
        out = np.minimum(out, np.exp(-y * y) + c * np.minimum(DAWSON_MAX, 1.0 / y))
    return out


def _make(kind: str, beta: float = 0.0) -> Part:
    if kind == "uniform":
        return Part("uniform", 0.0, 1.0 / 3.0, 0.5, 1.0, math.inf, 1.0, 1, cost=1.0, edges=(1.0,))
    if kind == "triangular":
        return Part("triangular", 0.0, 1.0 / 6.0, 1.0, 2.0, 1.0, 4.0, 2, cost=1.5, edges=(0.0, 1.0), slope_in=1.0)
    if kind == "normal":
        peak = 3.0 / _SQRT2PI
        # max |f'| of N(0, 1/9): 1 / (sigma^2 sqrt(2 pi e)); max |f''|: phi(0) / sigma^3
        slope = 9.0 / math.sqrt(2 * math.pi * math.e)
        return Part(
            "normal",
            0.0,
            1.0 / 9.0,
            peak,
            2.0 * peak,
            slope,
            1.0,
            0,
            cost=1.0,
            slope_in=slope,
            curve_in=27.0 / _SQRT2PI,
        )
    sh = shape(f"truncnormal({beta:g})")
    f0 = sh.peak
    f1 = f0 * math.exp(-0.5 * beta * beta)
    w = 2.0 * f1
    V = 4.0 * beta * f0 * math.exp(-0.5) if beta > 1.0 else 4.0 * beta * beta * f1
    maxslope = beta * f0 * math.exp(-0.5) if beta > 1.0 else beta * beta * f1  # max |f'| on [-1, 1]
    # |f''| = f(0) beta^2 |beta^2 y^2 - 1| exp(-beta^2 y^2 / 2) <= f(0) beta^2 (|z^2 - 1| e^(-z^2/2) <= 1)
    curve = f0 * beta * beta
    if kind == "truncnormal":
        return Part(
            "truncnormal",
            beta,
            sh.variance,
            f0,
            2.0 * f0,
            math.inf,
            2.0 * f0,
            1,
            w,
            V,
            cost=60.0,
            edges=(1.0,),
            slope_in=maxslope,
            curve_in=curve,
        )
    peak = (f0 - f1) / (1.0 - w)
    var = (sh.variance - w / 3.0) / (1.0 - w)
    return Part(
        "cap",
        beta,
        var,
        peak,
        2.0 * peak,
        maxslope / (1.0 - w),
        V / (1.0 - w),
        2,
        w,
        V / (1.0 - w),
        cost=62.0,
        edges=(1.0,),
        slope_in=maxslope / (1.0 - w),
        curve_in=curve / (1.0 - w),
    )


@lru_cache(maxsize=None)
def part_of(sh) -> Part:
    """The :class:`Part` of a shape (a :class:`Shape` or a shape name)."""
    sh = shape(sh)
    return _make(sh.kind, sh.beta)


@lru_cache(maxsize=None)
def cap_of(beta: float) -> Part:
    """The cap of the truncated normal of this ``beta``."""
    return _make("cap", beta)


UNIFORM = _make("uniform")
