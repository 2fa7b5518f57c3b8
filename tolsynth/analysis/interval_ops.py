"""Interval extensions of the CasADi operations, on NumPy arrays of lower and upper end points.

Each extension takes a context (which boxes stay proven regular) and the end points of its
arguments, arrays of shape (group size, boxes), and returns the end points of the result.  Results
are rounded outward: the correctly rounded operations (``+ - * / sqrt``) are stepped down and up by
two ulp (cheaper than ``np.nextafter``, and as rigorous), the library functions (sin, exp, ...) by a
relative ``2**-49`` and a small absolute term.  A NaN end point carries "no information" on its
side; every extension keeps that reading sound (NaN comparisons fall on the cautious branch).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

__all__ = [
    "UNARY",
    "BINARY",
    "MULC_POS",
    "MULC_NEG",
    "OP_NAMES",
    "SUPPORTED_OPERATIONS",
    "Context",
    "round_down",
    "round_up",
]

_INF = np.inf
_REL = 2.0**-49  # relative widening of library functions (glibc: < 1 ulp; 8 ulp of margin)
_ABS = 2.0**-1000  # absolute widening, for results in the subnormal range
_PI_UP = np.nextafter(np.pi, _INF)  # the double nearest pi is below pi
_HALF_PI_UP = np.nextafter(np.pi / 2, _INF)
_TWO_PI = 2.0 * np.pi
_TRIG_WIDE = 2.0**40  # beyond this argument, sin and cos are bounded by [-1, 1] only
_ULP2 = 2.0**-51  # |x| * 2**-51 is at least two ulp of x (exact: a power-of-two scaling)
_SUB = 2.0**-1074  # one ulp in the subnormal range, where the relative term vanishes


def _dn(x):
    """A double below the exact value of a correctly rounded result x (np.nextafter is ~20x slower;
    this steps two ulp down, then one subnormal ulp more for results near zero)."""
    w = np.abs(x)
    w *= _ULP2
    w += _SUB
    return x - w


def _up(x):
    w = np.abs(x)
    w *= _ULP2
    w += _SUB
    return x + w


def _tdn(x, arg_mag=None):
    """Lower end of a library function's result, widened beyond its error."""
    w = np.abs(x) * _REL + _ABS
    if arg_mag is not None:  # argument reduction of sin/cos/tan: absolute error grows with |x|
        w = w + np.maximum(arg_mag, 1.0) * 2.0**-52
    return x - w


def _tup(x, arg_mag=None):
    w = np.abs(x) * _REL + _ABS
    if arg_mag is not None:
        w = w + np.maximum(arg_mag, 1.0) * 2.0**-52
    return x + w


class Context:
    """Per-evaluation state: which boxes are still proven regular."""

    __slots__ = ("reg",)

    def __init__(self, n):
        self.reg = np.ones(n, dtype=bool)

    def irregular(self, mask):
        bad = np.asarray(mask)
        if bad.ndim > 1:
            bad = bad.any(axis=0)
        self.reg &= ~bad


def _nan_where(mask, lo, hi):
    """Mark an empty result (the whole box outside the domain) as NaN: no information."""
    if np.any(mask):
        lo = np.where(mask, np.nan, lo)
        hi = np.where(mask, np.nan, hi)
    return lo, hi


# ---------------------------------------------------------------- arithmetic
def _add(c, al, ah, bl, bh):
    return _dn(al + bl), _up(ah + bh)


def _sub(c, al, ah, bl, bh):
    return _dn(al - bh), _up(ah - bl)


def _mul(c, al, ah, bl, bh):
    # minimum/maximum propagate NaN (no information), also that of 0 * inf: sound, if loose;
    # in place, as this is the most frequent operation of the kinematic graphs
    p1, p2, p3, p4 = al * bl, al * bh, ah * bl, ah * bh
    lo = np.minimum(p1, p2)
    np.minimum(lo, p3, out=lo)
    np.minimum(lo, p4, out=lo)
    np.maximum(p1, p2, out=p1)
    np.maximum(p1, p3, out=p1)
    np.maximum(p1, p4, out=p1)
    return _dn(lo), _up(p1)


def _div(c, al, ah, bl, bh):
    zero = (bl <= 0.0) & (bh >= 0.0)
    q1, q2, q3, q4 = al / bl, al / bh, ah / bl, ah / bh
    lo = np.minimum(np.minimum(q1, q2), np.minimum(q3, q4))
    hi = np.maximum(np.maximum(q1, q2), np.maximum(q3, q4))
    lo, hi = _dn(lo), _up(hi)
    if np.any(zero):
        c.irregular(zero)
        lo = np.where(zero, -_INF, lo)
        hi = np.where(zero, _INF, hi)
    return lo, hi


def _inv(c, al, ah):
    return _div(c, np.ones_like(al), np.ones_like(ah), al, ah)


def _neg(c, al, ah):
    return -ah, -al


def _twice(c, al, ah):
    return 2.0 * al, 2.0 * ah


def _fabs(c, al, ah):
    lo = np.where(al >= 0.0, al, np.where(ah <= 0.0, -ah, 0.0))
    return lo, np.maximum(np.abs(al), np.abs(ah))


def _sq(c, al, ah):
    ml, mh = _fabs(c, al, ah)
    return np.maximum(_dn(ml * ml), 0.0), _up(mh * mh)


def _fmin(c, al, ah, bl, bh):
    return np.minimum(al, bl), np.minimum(ah, bh)


def _fmax(c, al, ah, bl, bh):
    return np.maximum(al, bl), np.maximum(ah, bh)


def _sqrt(c, al, ah):
    c.irregular(al < 0.0)
    lo = np.maximum(_dn(np.sqrt(np.maximum(al, 0.0))), 0.0)
    return _nan_where(ah < 0.0, lo, _up(np.sqrt(np.maximum(ah, 0.0))))


def _hypot(c, al, ah, bl, bh):
    xl, xh = _fabs(c, al, ah)
    yl, yh = _fabs(c, bl, bh)
    return np.maximum(_tdn(np.hypot(xl, yl)), 0.0), _tup(np.hypot(xh, yh))


# ---------------------------------------------------------------- monotone library functions
def _increasing(fn, dom_lo=-_INF, dom_hi=_INF, open_ends=False, rng=(-_INF, _INF)):
    """Interval extension of an increasing function defined on [dom_lo, dom_hi] (open ends: the
    end points themselves are outside the domain, where the function is infinite)."""

    def ext(c, al, ah):
        if open_ends:
            c.irregular((al <= dom_lo) | (ah >= dom_hi))
            empty = (ah <= dom_lo) | (al >= dom_hi)
        else:
            c.irregular((al < dom_lo) | (ah > dom_hi))
            empty = (ah < dom_lo) | (al > dom_hi)
        lo = _tdn(fn(np.clip(al, dom_lo, dom_hi)))
        hi = _tup(fn(np.clip(ah, dom_lo, dom_hi)))
        lo, hi = np.maximum(lo, rng[0]), np.minimum(hi, rng[1])
        return _nan_where(empty, lo, hi)

    return ext


def _decreasing(fn, dom_lo, dom_hi, rng):
    def ext(c, al, ah):
        c.irregular((al < dom_lo) | (ah > dom_hi))
        empty = (ah < dom_lo) | (al > dom_hi)
        lo = np.maximum(_tdn(fn(np.clip(ah, dom_lo, dom_hi))), rng[0])
        hi = np.minimum(_tup(fn(np.clip(al, dom_lo, dom_hi))), rng[1])
        return _nan_where(empty, lo, hi)

    return ext


def _even(fn, rng_lo):
    """Interval extension of an even function increasing on [0, inf) (cosh)."""

    def ext(c, al, ah):
        ml, mh = _fabs(c, al, ah)
        return np.maximum(_tdn(fn(ml)), rng_lo), _tup(fn(mh))

    return ext


def _erf(x):
    return np.vectorize(math.erf, otypes=[float])(x)


def _log(c, al, ah):
    c.irregular(al <= 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        lo = np.where(al > 0.0, _tdn(np.log(np.maximum(al, 0.0))), -_INF)
        hi = _tup(np.log(np.maximum(ah, 0.0)))
    return _nan_where(ah <= 0.0, lo, hi)


def _exp(c, al, ah):
    return np.maximum(_tdn(np.exp(al)), 0.0), _tup(np.exp(ah))


# ---------------------------------------------------------------- periodic functions
def _hits(al, ah, phase, period):
    """Conservatively, whether [al, ah] holds a point phase + k * period (k integer): the slack
    turns a near miss into a hit, which only widens the result."""
    mag = np.maximum(np.abs(al), np.abs(ah))
    slack = 1e-9 * (1.0 + mag)
    k = np.ceil((al - slack - phase) / period)
    return phase + k * period <= ah + slack


def _trig(fn, max_phase, min_phase):
    def ext(c, al, ah):
        mag = np.maximum(np.abs(al), np.abs(ah))
        vl, vh = fn(al), fn(ah)
        lo = np.maximum(_tdn(np.minimum(vl, vh), mag), -1.0)
        hi = np.minimum(_tup(np.maximum(vl, vh), mag), 1.0)
        wide = ~((ah - al < _TWO_PI) & (mag < _TRIG_WIDE))  # NaN (no information) lands here
        hi = np.where(wide | _hits(al, ah, max_phase, _TWO_PI), 1.0, hi)
        lo = np.where(wide | _hits(al, ah, min_phase, _TWO_PI), -1.0, lo)
        return lo, hi

    return ext


def _tan(c, al, ah):
    mag = np.maximum(np.abs(al), np.abs(ah))
    pole = ~((ah - al < np.pi) & (mag < _TRIG_WIDE)) | _hits(al, ah, np.pi / 2, np.pi)
    c.irregular(pole)
    lo = np.where(pole, -_INF, _tdn(np.tan(al), mag))
    hi = np.where(pole, _INF, _tup(np.tan(ah), mag))
    return lo, hi


def _atan2(c, yl, yh, xl, xh):
    # continuous on a box that misses the cut {y = 0, x <= 0}; there the extremes sit at corners
    cut = (xl <= 0.0) & (yl <= 0.0) & (yh >= 0.0)
    c.irregular(cut)
    t = [np.arctan2(y, x) for y in (yl, yh) for x in (xl, xh)]
    lo = np.maximum(_tdn(np.minimum(np.minimum(t[0], t[1]), np.minimum(t[2], t[3]))), -_PI_UP)
    hi = np.minimum(_tup(np.maximum(np.maximum(t[0], t[1]), np.maximum(t[2], t[3]))), _PI_UP)
    return np.where(cut, -_PI_UP, lo), np.where(cut, _PI_UP, hi)


# ---------------------------------------------------------------- powers
def _pow(c, al, ah, bl, bh):
    """x ** y; an exponent fixed at an integer on a box keeps x < 0 in the domain."""
    n = bl
    integer = (bl == bh) & (np.floor(bl) == bl) & (np.abs(bl) <= 2.0**31)
    with np.errstate(all="ignore"):
        # integer exponent: |x| ** n on the magnitudes, the sign from the odd powers
        odd = integer & (np.abs(np.fmod(n, 2.0)) == 1.0)
        ml, mh = _fabs(c, al, ah)
        pos = n >= 0.0
        m_lo = np.where(pos, np.power(ml, n), np.power(mh, n))
        m_hi = np.where(pos, np.power(mh, n), np.power(ml, n))
        el, eh = np.maximum(_tdn(m_lo), 0.0), _tup(m_hi)  # even powers
        # odd powers are increasing (n > 0) or decreasing on each side of 0 (n < 0)
        sl = np.sign(al) * np.power(np.abs(al), n)
        sh = np.sign(ah) * np.power(np.abs(ah), n)
        ol = np.where(pos, _tdn(sl), _tdn(sh))
        oh = np.where(pos, _tup(sh), _tup(sl))
        zero_in = ~((al > 0.0) | (ah < 0.0))  # NaN (no information) counts as holding 0
        neg_pole = integer & ~pos & zero_in
        ol = np.where(neg_pole, -_INF, ol)
        oh = np.where(neg_pole, _INF, oh)
        eh = np.where(neg_pole, _INF, eh)
        il = np.where(odd, ol, el)
        ih = np.where(odd, oh, eh)
        il = np.where(n == 0.0, 1.0, il)
        ih = np.where(n == 0.0, 1.0, ih)
        # other exponents: exp(y log x) on x >= 0 (pow of a negative base is NaN)
        ll, lh = _log(Context(al.shape[-1]), al, ah)
        pl, ph = _mul(c, bl, bh, ll, lh)
        gl, gh = _exp(c, pl, ph)
    c.irregular((~integer & ((al < 0.0) | ((al == 0.0) & (bl <= 0.0)))) | neg_pole)
    lo = np.where(integer, il, gl)
    hi = np.where(integer, ih, gh)
    return _nan_where(~integer & (ah < 0.0), lo, hi)


# ---------------------------------------------------------------- logic and steps
def _decided(c, true, false):
    """A 0/1 result: 1 where proven true, 0 where proven false, [0, 1] (irregular) elsewhere."""
    undecided = ~true & ~false
    c.irregular(undecided)
    return np.where(true, 1.0, 0.0), np.where(false, 0.0, 1.0)


def _lt(c, al, ah, bl, bh):
    return _decided(c, ah < bl, al >= bh)


def _le(c, al, ah, bl, bh):
    return _decided(c, ah <= bl, al > bh)


def _eq(c, al, ah, bl, bh):
    return _decided(c, (al == ah) & (bl == bh) & (al == bl), (ah < bl) | (al > bh))


def _ne(c, al, ah, bl, bh):
    return _decided(c, (ah < bl) | (al > bh), (al == ah) & (bl == bh) & (al == bl))


def _nonzero(al, ah):
    return (al > 0.0) | (ah < 0.0), (al == 0.0) & (ah == 0.0)


def _not(c, al, ah):
    nz, z = _nonzero(al, ah)
    return _decided(c, z, nz)


def _and(c, al, ah, bl, bh):
    an, az = _nonzero(al, ah)
    bn, bz = _nonzero(bl, bh)
    return _decided(c, an & bn, az | bz)


def _or(c, al, ah, bl, bh):
    an, az = _nonzero(al, ah)
    bn, bz = _nonzero(bl, bh)
    return _decided(c, an | bn, az & bz)


def _if_else_zero(c, cl, ch, xl, xh):
    nz, z = _nonzero(cl, ch)
    c.irregular(~nz & ~z)
    lo = np.where(nz, xl, np.where(z, 0.0, np.minimum(xl, 0.0)))
    hi = np.where(nz, xh, np.where(z, 0.0, np.maximum(xh, 0.0)))
    return lo, hi


def _step(fn):
    def ext(c, al, ah):
        lo, hi = fn(al), fn(ah)
        c.irregular(lo != hi)
        return lo, hi

    return ext


def _sign(c, al, ah):
    c.irregular((al <= 0.0) & (ah >= 0.0) & (al != ah))
    return np.sign(al), np.sign(ah)


def _copysign(c, al, ah, bl, bh):
    ml, mh = _fabs(c, al, ah)
    pos, neg = bl > 0.0, bh < 0.0
    c.irregular(~pos & ~neg)
    return np.where(pos, ml, -mh), np.where(neg, -ml, mh)


def _mulc_pos(c, al, ah, k):
    return _dn(al * k), _up(ah * k)


def _mulc_neg(c, al, ah, k):
    return _dn(ah * k), _up(al * k)


MULC_POS, MULC_NEG = -1, -2  # internal codes: a product with a constant of known sign
UNARY = {
    MULC_POS: _mulc_pos,
    MULC_NEG: _mulc_neg,
    ca.OP_NEG: _neg,
    ca.OP_TWICE: _twice,
    ca.OP_FABS: _fabs,
    ca.OP_SQ: _sq,
    ca.OP_SQRT: _sqrt,
    ca.OP_INV: _inv,
    ca.OP_EXP: _exp,
    ca.OP_LOG: _log,
    ca.OP_SIN: _trig(np.sin, np.pi / 2, -np.pi / 2),
    ca.OP_COS: _trig(np.cos, 0.0, np.pi),
    ca.OP_TAN: _tan,
    ca.OP_ASIN: _increasing(np.arcsin, -1.0, 1.0, rng=(-_HALF_PI_UP, _HALF_PI_UP)),
    ca.OP_ACOS: _decreasing(np.arccos, -1.0, 1.0, rng=(0.0, _PI_UP)),
    ca.OP_ATAN: _increasing(np.arctan, rng=(-_HALF_PI_UP, _HALF_PI_UP)),
    ca.OP_SINH: _increasing(np.sinh),
    ca.OP_COSH: _even(np.cosh, 1.0),
    ca.OP_TANH: _increasing(np.tanh, rng=(-1.0, 1.0)),
    ca.OP_ASINH: _increasing(np.arcsinh),
    ca.OP_ACOSH: _increasing(np.arccosh, 1.0, _INF, rng=(0.0, _INF)),
    ca.OP_ATANH: _increasing(np.arctanh, -1.0, 1.0, open_ends=True),
    ca.OP_LOG1P: _increasing(np.log1p, -1.0, _INF, open_ends=True),
    ca.OP_EXPM1: _increasing(np.expm1, rng=(-1.0, _INF)),
    ca.OP_ERF: _increasing(_erf, rng=(-1.0, 1.0)),
    ca.OP_FLOOR: _step(np.floor),
    ca.OP_CEIL: _step(np.ceil),
    ca.OP_SIGN: _sign,
    ca.OP_NOT: _not,
}
BINARY = {
    ca.OP_ADD: _add,
    ca.OP_SUB: _sub,
    ca.OP_MUL: _mul,
    ca.OP_DIV: _div,
    ca.OP_POW: _pow,
    ca.OP_CONSTPOW: _pow,
    ca.OP_ATAN2: _atan2,
    ca.OP_FMIN: _fmin,
    ca.OP_FMAX: _fmax,
    ca.OP_HYPOT: _hypot,
    ca.OP_LT: _lt,
    ca.OP_LE: _le,
    ca.OP_EQ: _eq,
    ca.OP_NE: _ne,
    ca.OP_AND: _and,
    ca.OP_OR: _or,
    ca.OP_IF_ELSE_ZERO: _if_else_zero,
    ca.OP_COPYSIGN: _copysign,
}
OP_NAMES = {v: k[3:].lower() for k, v in vars(ca).items() if k.startswith("OP_") and isinstance(v, int)}
SUPPORTED_OPERATIONS = tuple(sorted(OP_NAMES[o] for o in (*UNARY, *BINARY) if o >= 0))

round_down, round_up = _dn, _up
