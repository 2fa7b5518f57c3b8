"""A rigorous lower bound of the exact probability from the standard deviation alone.

For ``S = sum_i b_i Y_i`` with ``Y_i`` independent, each uniform on [-1, 1], triangular on [-1, 1] or
normal, and ``Var S <= s^2``::

    P(|S| <= R) >= 1 - 2 E (s G - h)_+^3 / (R - h)^3        for every h < R,

``G`` standard normal (Eaton's bound, variance-matched).  Why it holds:

* each shape is below the normal of its own variance in the order of the functions
  ``(x - h)_+^3``: ``E (Y - h)_+^3 <= E (sigma_Y G - h)_+^3`` for every real ``h``.  For the uniform,
  ``E (U - h)_+^3 = (1 - h)^4 / 8`` on [-1, 1], zero above it and ``E (U - h)^3 = -h^3 - h`` below it,
  which the normal's ``E (G / sqrt 3 - h)^3`` equals and ``x_+^3 >= x^3`` bounds; on [-1, 1] the
  tests prove it with interval arithmetic (the least margin, 0.0024, is at ``h = 1``).  The normal is
  its own bound; the triangular is the mean of two uniforms;
* the order passes to scaled sums of independent variables, one summand at a time
  (``x -> E (x + X - h)_+^3`` is a mixture of the same functions), and to a larger standard
  deviation of the normal (the functions are convex);
* Markov's inequality with ``(x - h)_+^3 / (R - h)^3 >= 1{x >= R}``, and the same on ``-S``.

It costs about a factor 4 over the normal tail (at most ``2 e^3 / 9``, Pinelis): at p = 0.99 it
proves ``R / s >= 3.03`` where the normal reading needs 2.576.  The truncated normal is not covered
(its order has not been proven here); :func:`covered` says which shapes are.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from tolsynth.probability.stats import _MATH_UFUNCS

__all__ = ["COVERED", "covered", "tail_upper", "probability_lower", "z_for"]

#: the shapes whose order below the normal of their variance is proven (module docstring)
COVERED = ("uniform", "triangular", "normal")

_GOLDEN = 0.5 * (3.0 - math.sqrt(5.0))
#: past this ratio the bound at it is used (the bound falls with z, and is about 1e-300 there): the
#: squares of larger ratios overflow
Z_CAP = 40.0


def covered(shapes) -> bool:
    """True when every shape (:class:`tolsynth.probability.distributions.Shape`) is covered."""
    return all(s.kind in COVERED for s in shapes)


# math's exp and erfc element by element: the same values as the scalar functions (numpy's own exp may
# differ from them in the last bit), while the loops around them run over whole arrays of boxes
_exp = np.frompyfunc(math.exp, 1, 1)
_erfc = _MATH_UFUNCS["erfc"]
_SQRT2PI, _SQRT2 = math.sqrt(2.0 * math.pi), math.sqrt(2.0)


def _e3(h: np.ndarray) -> np.ndarray:
    """``E (G - h)_+^3`` rounded up: ``(2 + h^2) phi(h) - h (3 + h^2) Q(h)``, with a margin for
    the rounding of its terms (the library's exp and erfc are within a few ulps) and their
    cancellation."""
    phi = _exp(-0.5 * h * h).astype(float) / _SQRT2PI
    q = 0.5 * _erfc(h / _SQRT2).astype(float)
    a, b = (2.0 + h * h) * phi, h * (3.0 + h * h) * q
    return np.maximum(0.0, a - b) + 1e-13 * (np.abs(a) + np.abs(b)) + 1e-300


def _ratio(h: np.ndarray, z: np.ndarray) -> np.ndarray:
    """``E (G - h)_+^3 / (z - h)^3`` rounded up (h < z)."""
    d = z - h
    return _e3(h) / (d * d * d) * (1.0 + 1e-14)


def _tail_upper(z: np.ndarray) -> np.ndarray:
    """:func:`tail_upper` of an array of finite ``z > 0``: the same golden-section steps on each."""
    lo, hi = z - 6.0, z - 1e-3 * np.maximum(1.0, z)
    x1, x2 = lo + _GOLDEN * (hi - lo), hi - _GOLDEN * (hi - lo)
    f1, f2 = _ratio(x1, z), _ratio(x2, z)
    for _ in range(48):
        left = f1 <= f2  # the least lies left of x2: [lo, x2] kept, x1 becomes its right point
        hi = np.where(left, x2, hi)
        lo = np.where(left, lo, x1)
        x1n = np.where(left, lo + _GOLDEN * (hi - lo), x2)
        x2n = np.where(left, x1, hi - _GOLDEN * (hi - lo))
        new = _ratio(np.where(left, x1n, x2n), z)  # one new evaluation a step, at the moved point
        f1, f2 = np.where(left, new, f2), np.where(left, f1, new)
        x1, x2 = x1n, x2n
    return np.minimum(1.0, 2.0 * np.minimum(f1, f2) * (1.0 + 1e-14))


def tail_upper(z: float) -> float:
    """An upper bound of ``P(|S| > z s)`` for every ``S`` of the module docstring with standard
    deviation at most ``s``: twice Eaton's bound at the ``h`` a golden-section search finds (any
    ``h < z`` gives a valid bound; the search only makes it the tightest)."""
    z = float(z)
    if not z > 0.0:
        return 1.0
    if math.isinf(z):
        return 0.0
    return float(_tail_upper(np.array([min(z, Z_CAP)]))[0])


def probability_lower(R: float, s) -> np.ndarray:
    """Lower bounds of ``P(|S| <= R)`` for standard deviations at most ``s`` (array; 0 where ``s``
    is 0 or below gives 1)."""
    s = np.asarray(s, dtype=float)
    out = np.ones(s.shape)
    pos = ~(s <= 0.0)  # NaN too: its bound is 0
    with np.errstate(over="ignore"):  # a ratio past the largest float is inf: no tail
        z = R / s[pos]
    t = np.ones(z.shape)  # the bound of z <= 0 (none here) or NaN: every probability at least 0
    ok = z > 0.0
    t[ok] = 0.0  # z infinite: no tail
    fin = ok & np.isfinite(z)
    t[fin] = _tail_upper(np.minimum(z[fin], Z_CAP))
    out[pos] = np.maximum(0.0, 1.0 - t - 1e-15)
    return out


@lru_cache(maxsize=64)
def z_for(tail: float) -> float:
    """A ratio ``R / s`` at which :func:`tail_upper` is at most ``tail`` (within 1e-9 of the least
    one, from above); ``inf`` when ``tail`` is 0 or below."""
    if not tail > 0.0:
        return math.inf
    if tail >= 1.0:
        return 0.0
    lo, hi = 0.0, 1.0
    while tail_upper(hi) > tail:
        lo, hi = hi, 2.0 * hi
    while hi - lo > 1e-9 * hi:
        mid = 0.5 * (lo + hi)
        if tail_upper(mid) > tail:
            lo = mid
        else:
            hi = mid
    return hi
