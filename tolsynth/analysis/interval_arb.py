"""An independent cross-check of tolsynth's interval evaluation with python-flint's ``arb`` balls.

The certified searches rest on :class:`tolsynth.analysis.intervals.IntervalFunction`, tolsynth's
own interval arithmetic (NumPy and a compiled interpreter, rounded outward by hand).  This module
evaluates the same SX graph with a well-kept library instead: every node becomes an ``arb`` ball
(midpoint and radius, FLINT's ball arithmetic, which rounds outward itself, at ``prec`` bits),
walking the algorithm of the CasADi Function in the order CasADi runs it.  Nothing is shared with
the package's extensions but the graph: the constants (doubles, exact in ``arb``), the operation
codes and the inputs and outputs.

Two enclosures of one box are both valid and neither need hold the other (ball products are
looser than interval products near zero; the package's monotone extensions are looser than arb's
on some library functions).  What must hold, and what :func:`check_enclosures` checks, is that
the exact value of the graph at every point of a box lies in both: arb evaluates the graph at
points of each box (thin balls, about ``2**-prec`` wide), a point value proven outside an
enclosure is a fault of that enclosure, and two enclosures of the same box that do not meet
prove a fault in one of them.

This is a check, not a replacement: arb runs one box at a time in Python, 0.5-1.4 us of CPU per
instruction on the bundled arms' sensitivity graphs against 4-20 ns per instruction and box for
the package's batched evaluation, so the certified search's hot path stays the package's own.

Semantics follow :mod:`tolsynth.analysis.intervals`: an enclosure contains the value at every
point of the box where the graph is defined.  Where arb cannot bound a node (a division by a
ball holding zero, a logarithm of a ball reaching zero) the result is a NaN ball, reported as
``-inf`` / ``+inf`` (no information).  Functions defined on a closed part of the line (``sqrt``,
``asin``, ``acos``, ``acosh``) are evaluated on the ball's part inside their domain, at its two
end points (they are monotone there), as the package does.

Needs python-flint (``pip install "tolsynth[interval]"``).
"""

from __future__ import annotations

import operator
import time
from dataclasses import dataclass

import casadi as ca
import numpy as np

from tolsynth.analysis.certify_structure import position_sensitivity
from tolsynth.analysis.interval_ops import OP_NAMES
from tolsynth.analysis.intervals import IntervalFunction, _as_sx
from tolsynth.checks import check_count, check_seed
from tolsynth.errors import InputError, MissingDependencyError

__all__ = [
    "ArbFunction",
    "EnclosureCheck",
    "arb_enclosure",
    "check_enclosures",
    "check_certificate_enclosures",
    "INTERVAL_INSTALL",
]

INTERVAL_INSTALL = 'pip install "tolsynth[interval]"'
_BINARY, _UNARY, _IN, _CONST, _OUT, _COPY = range(6)  # kinds of program steps, the frequent first
_CORNERS_UP_TO = 4  # the corners of a box are points of the check up to this many inputs (16 corners)


def _flint():
    try:
        import flint
    except ImportError:
        raise MissingDependencyError(
            "python-flint", "the arb cross-check of the interval evaluation", INTERVAL_INSTALL
        ) from None
    return flint


# ---------------------------------------------------------------- arb operations
def _operations(arb):
    """Operation code -> (arity, function of arb balls), built once on first use."""
    one, zero = arb(1), arb(0)
    unit = zero.union(one)  # [0, 1]: a comparison not decided on the balls

    def span(a, b):
        """The ball holding the exact numbers a <= b (radius rounded up by arb)."""
        return a.union(b)

    def mag(x):
        """|x| as a ball: the exact end points of |x| (abs of a ball is looser near zero)."""
        if x >= 0:
            return x
        if x <= 0:
            return -x
        return span(zero, x.abs_upper())

    def sq(x):
        lo, hi = x.abs_lower(), x.abs_upper()
        return span(lo * lo, hi * hi)

    def clipped(method, dom_lo, dom_hi, increasing=True):
        """A function monotone on the closed domain [dom_lo, dom_hi], on the part of the ball inside it."""

        def ext(x):
            r = method(x)
            if r.is_finite():
                return r
            lo, hi = x.lower(), x.upper()
            if (dom_lo is not None and hi < dom_lo) or (dom_hi is not None and lo > dom_hi) or not x.is_finite():
                return arb.nan()
            if dom_lo is not None and lo < dom_lo:
                lo = dom_lo
            if dom_hi is not None and hi > dom_hi:
                hi = dom_hi
            a, b = method(lo), method(hi)
            return span(a.lower(), b.upper()) if increasing else span(b.lower(), a.upper())

        return ext

    def decided(true, false):
        return one if true else zero if false else unit

    def nonzero(x):
        return (x > 0) or (x < 0)

    def is_zero(x):
        return x.is_zero()

    def same(a, b):
        return a.is_exact() and b.is_exact() and a == b

    def pow_(x, y):
        if y.is_exact() and y.is_integer() and abs(y) <= 2**31:
            n = int(y.unique_fmpz())
            if n == 0:
                return one
            if n % 2 == 0:
                m = mag(x) ** n
                return m if m >= 0 else m.nonnegative_part()
            return x**n
        return x**y

    def if_else_zero(c, x):
        if nonzero(c):
            return x
        if is_zero(c):
            return zero
        return x.union(zero)

    def copysign(x, y):
        m = mag(x)
        if y > 0:
            return m
        if y < 0:
            return -m
        return m.union(-m)

    def sign(x):
        if x > 0:
            return one
        if x < 0:
            return -one
        if is_zero(x):
            return zero
        return span(-one, one)

    def step(method):
        def ext(x):
            lo, hi = method(x.lower()), method(x.upper())
            return lo if lo == hi else span(lo, hi)

        return ext

    sqrt = clipped(arb.sqrt, zero, None)
    return {
        ca.OP_ADD: (2, operator.add),
        ca.OP_SUB: (2, operator.sub),
        ca.OP_MUL: (2, operator.mul),
        ca.OP_DIV: (2, operator.truediv),
        ca.OP_POW: (2, pow_),
        ca.OP_CONSTPOW: (2, pow_),
        ca.OP_ATAN2: (2, arb.atan2),
        ca.OP_FMIN: (2, lambda a, b: a.min(b)),
        ca.OP_FMAX: (2, lambda a, b: a.max(b)),
        ca.OP_HYPOT: (2, lambda a, b: sqrt(sq(a) + sq(b))),
        ca.OP_LT: (2, lambda a, b: decided(a < b, a >= b)),
        ca.OP_LE: (2, lambda a, b: decided(a <= b, a > b)),
        ca.OP_EQ: (2, lambda a, b: decided(same(a, b), not a.overlaps(b))),
        ca.OP_NE: (2, lambda a, b: decided(not a.overlaps(b), same(a, b))),
        ca.OP_AND: (2, lambda a, b: decided(nonzero(a) and nonzero(b), is_zero(a) or is_zero(b))),
        ca.OP_OR: (2, lambda a, b: decided(nonzero(a) or nonzero(b), is_zero(a) and is_zero(b))),
        ca.OP_IF_ELSE_ZERO: (2, if_else_zero),
        ca.OP_COPYSIGN: (2, copysign),
        ca.OP_NEG: (1, operator.neg),
        ca.OP_TWICE: (1, lambda a: 2 * a),
        ca.OP_FABS: (1, mag),
        ca.OP_SQ: (1, sq),
        ca.OP_INV: (1, lambda a: one / a),
        ca.OP_SQRT: (1, sqrt),
        ca.OP_EXP: (1, arb.exp),
        ca.OP_LOG: (1, arb.log),  # open at 0: a ball reaching 0 gives no information
        ca.OP_SIN: (1, arb.sin),
        ca.OP_COS: (1, arb.cos),
        ca.OP_TAN: (1, arb.tan),
        ca.OP_ASIN: (1, clipped(arb.asin, -one, one)),
        ca.OP_ACOS: (1, clipped(arb.acos, -one, one, increasing=False)),
        ca.OP_ATAN: (1, arb.atan),
        ca.OP_SINH: (1, arb.sinh),
        ca.OP_COSH: (1, arb.cosh),
        ca.OP_TANH: (1, arb.tanh),
        ca.OP_ASINH: (1, arb.asinh),
        ca.OP_ACOSH: (1, clipped(arb.acosh, one, None)),
        ca.OP_ATANH: (1, arb.atanh),
        ca.OP_LOG1P: (1, arb.log1p),
        ca.OP_EXPM1: (1, arb.expm1),
        ca.OP_ERF: (1, arb.erf),
        ca.OP_FLOOR: (1, step(arb.floor)),
        ca.OP_CEIL: (1, step(arb.ceil)),
        ca.OP_SIGN: (1, sign),
        ca.OP_NOT: (1, lambda a: decided(is_zero(a), nonzero(a))),
    }


_TABLE: dict = {}


def _table():
    flint = _flint()
    if not _TABLE:
        _TABLE.update(_operations(flint.arb))
    return flint, _TABLE


def _down(x, arb) -> float:
    """The largest double at or below the lower end of the ball x (-inf without information)."""
    if not x.is_finite():
        return -np.inf
    lo = x.lower()
    f = float(lo)
    if arb(f) > lo:
        f = float(np.nextafter(f, -np.inf))
    return f


def _upward(x, arb) -> float:
    if not x.is_finite():
        return np.inf
    hi = x.upper()
    f = float(hi)
    if arb(f) < hi:
        f = float(np.nextafter(f, np.inf))
    return f


# ---------------------------------------------------------------- the graph as an arb program
class ArbFunction:
    """An SX :class:`casadi.Function` evaluated over boxes with arb balls, one box at a time.

    Parameters
    ----------
    f : casadi.Function
        An SX Function (an MX Function is expanded), the inputs stacked as in
        :meth:`tolsynth.analysis.intervals.IntervalFunction.evaluate`: one row of ``n_x`` numbers,
        every input's nonzeros in turn.
    prec : int
        Working precision of the balls, bits (53 to 4096; 106 is about twice a double's).
    """

    def __init__(self, f: ca.Function, prec: int = 106):
        self.prec = check_count(prec, "prec", lower=53, upper=4096)
        flint, table = _table()
        self._flint = flint
        f = _as_sx(f)
        self.function = f
        in_nnz = [f.nnz_in(i) for i in range(f.n_in())]
        offset = np.concatenate([[0], np.cumsum(in_nnz)]).astype(int)
        self.n_x = int(offset[-1])
        # dense outputs, column-major and concatenated (the layout of IntervalFunction.evaluate);
        # structural zeros stay at zero
        out_pos, start = {}, 0
        for i in range(f.n_out()):
            sp = f.sparsity_out(i)
            rows, cols = sp.get_triplet()
            for nz, (r, c) in enumerate(zip(rows, cols)):
                out_pos[(i, nz)] = start + c * sp.size1() + r
            start += sp.numel()
        self.n_out = start
        arb = flint.arb
        # the program, in CasADi's order: (kind, function, destination, source, second source)
        program, size = [], 0
        for k in range(f.n_instructions()):
            op = f.instruction_id(k)
            ins, outs = f.instruction_input(k), f.instruction_output(k)
            if op == ca.OP_OUTPUT:
                # read when CasADi reads it: the work slot is reused by later instructions
                program.append((_OUT, None, out_pos[(outs[0], outs[1])], ins[0], 0))
                continue
            size = max(size, outs[0] + 1)
            if op == ca.OP_INPUT:
                program.append((_IN, None, outs[0], int(offset[ins[0]]) + ins[1], 0))
            elif op == ca.OP_CONST:
                program.append((_CONST, arb(f.instruction_constant(k)), outs[0], 0, 0))  # a double is exact in arb
            elif op == ca.OP_ASSIGN:
                program.append((_COPY, None, outs[0], ins[0], 0))
            elif op in table:
                arity, fn = table[op]
                program.append((_BINARY if arity == 2 else _UNARY, fn, outs[0], ins[0], ins[1] if arity == 2 else 0))
            else:
                raise InputError(
                    "f",
                    f"{f.name()} uses the operation {OP_NAMES.get(op, op)}, which has no arb extension here",
                    ", ".join(sorted(OP_NAMES[o] for o in table)),
                )
        self._program = program
        self._size = size

    def balls(self, x: list) -> list:
        """The outputs (dense, column-major, concatenated) as arb balls, for the input balls x (at
        the precision of the caller's ``flint.ctx``)."""
        w = [None] * self._size
        out = [self._flint.arb(0)] * self.n_out
        for kind, fn, o, i, j in self._program:
            if kind == _BINARY:
                w[o] = fn(w[i], w[j])
            elif kind == _UNARY:
                w[o] = fn(w[i])
            elif kind == _IN:
                w[o] = x[i]
            elif kind == _CONST:
                w[o] = fn
            elif kind == _OUT:
                out[o] = w[i]
            else:
                w[o] = w[i]
        return out

    def __call__(self, lo, hi):
        """Enclosures on the boxes ``lo <= x <= hi`` (arrays (n_x,) or (n_boxes, n_x)): arrays
        ``(lo, hi)`` of shape (n_out,) or (n_boxes, n_out), rounded outward to doubles, -inf / +inf
        where arb gives no information."""
        XL, XH, single = _boxes(lo, hi, self.n_x)
        OL = np.empty((len(XL), self.n_out))
        OH = np.empty_like(OL)
        arb = self._flint.arb
        with self._flint.ctx.workprec(self.prec):
            for k in range(len(XL)):
                x = [arb(a) if a == b else arb(a).union(arb(b)) for a, b in zip(XL[k].tolist(), XH[k].tolist())]
                for j, v in enumerate(self.balls(x)):
                    OL[k, j], OH[k, j] = _down(v, arb), _upward(v, arb)
        return (OL[0], OH[0]) if single else (OL, OH)


def _boxes(lo, hi, n_x):
    XL, XH = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    single = XL.ndim == 1 and XH.ndim == 1
    XL, XH = np.atleast_2d(XL), np.atleast_2d(XH)
    if XL.shape[-1] != n_x or XH.shape[-1] != n_x or XL.ndim != 2 or XH.ndim != 2:
        raise InputError("lo, hi", f"shapes {XL.shape} and {XH.shape}", f"({n_x},) or (n_boxes, {n_x})")
    XL, XH = np.broadcast_arrays(XL, XH)
    if not (np.all(np.isfinite(XL)) and np.all(np.isfinite(XH))):
        raise InputError("lo, hi", "box bounds must be finite numbers")
    if np.any(XL > XH):
        raise InputError("lo, hi", "a lower bound exceeds its upper bound", "lo <= hi")
    return XL, XH, single


def arb_enclosure(fn: ca.Function, lo, hi, prec: int = 106):
    """Enclosure of an SX Function's outputs over boxes, by arb ball arithmetic.

    Parameters
    ----------
    fn : casadi.Function
        An SX Function (an MX Function is expanded).
    lo, hi : array_like
        The boxes: shape (n_x,) or (n_boxes, n_x), every input's nonzeros in turn.
    prec : int
        Working precision, bits.

    Returns
    -------
    (ndarray, ndarray)
        Lower and upper bounds, shape (n_out,) or (n_boxes, n_out): the outputs dense,
        column-major, concatenated; -inf / +inf where arb gives no information.

    Raises
    ------
    MissingDependencyError
        python-flint is not installed (``pip install "tolsynth[interval]"``).
    """
    return ArbFunction(fn, prec)(lo, hi)


# ---------------------------------------------------------------- the cross-check
@dataclass(frozen=True)
class EnclosureCheck:
    """The package's interval evaluation against arb's, on a set of boxes.

    Attributes
    ----------
    boxes, points : int
        Boxes checked, and points evaluated in them (the centre, the corners when there are at
        most 16, and random points).
    disjoint : tuple of int
        Boxes where the package's enclosure and arb's do not meet on some output: one of them is
        wrong (both must hold every value).
    missed : tuple of int
        Boxes where a point value (arb, a ball about ``2**-prec`` wide) is proven outside the
        package's enclosure.
    arb_missed : tuple of int
        The same against arb's own box enclosure (a fault of this check).
    width_ratio_max, width_ratio_median : float
        The package's enclosure width over arb's, over the outputs where both are finite and
        arb's is not zero (below 1: the package's is narrower).  On an output constant over a box
        both widths are roundings (the package's two ulp a step against arb's ``2**-prec``), and
        the ratio is large without meaning a loose enclosure.
    package_unbounded, arb_unbounded : int
        (box, output) pairs without information (an infinite end point) in each.
    elapsed_s : float
    """

    boxes: int
    points: int
    disjoint: tuple
    missed: tuple
    arb_missed: tuple
    width_ratio_max: float
    width_ratio_median: float
    package_unbounded: int
    arb_unbounded: int
    elapsed_s: float

    @property
    def ok(self) -> bool:
        """No fault found: every point value in both enclosures and every pair meeting."""
        return not (self.disjoint or self.missed or self.arb_missed)

    def summary(self) -> str:
        state = "agree" if self.ok else "DISAGREE"
        text = (
            f"package and arb enclosures {state} on {self.boxes} boxes ({self.points} point values); "
            f"width ratio package/arb: median {self.width_ratio_median:.3g}, max {self.width_ratio_max:.3g}"
        )
        for name, boxes in (("disjoint", self.disjoint), ("missed", self.missed), ("arb_missed", self.arb_missed)):
            if boxes:
                text += f"; {name} on boxes {list(boxes[:10])}"
        return text


def _points(xl, xh, samples, rng):
    n = len(xl)
    pts = [0.5 * (xl + xh)]
    if n <= _CORNERS_UP_TO:
        for bits in range(2**n):
            pts.append(np.where([(bits >> i) & 1 for i in range(n)], xh, xl))
    pts += list(xl + rng.random((samples, n)) * (xh - xl))
    return np.clip(np.array(pts), xl, xh)


def check_enclosures(fn: ca.Function, lo, hi, samples: int = 4, prec: int = 106, seed: int = 0) -> EnclosureCheck:
    """Cross-check the package's interval evaluation of a graph against arb, box by box.

    For each box, the package's enclosure (:class:`tolsynth.analysis.intervals.IntervalFunction`,
    the evaluation the certificates rest on) and arb's must meet, and the exact value at each of
    the box's points (the centre, the corners up to 16 of them, and ``samples`` random points),
    evaluated by arb as a thin ball, must lie in both.  A fault is reported only when proven
    (balls that do not meet); the widths are compared for information.  arb evaluates one box at
    a time in Python: use a few hundred boxes, not the search's thousands.

    Parameters
    ----------
    fn : casadi.Function
        An SX Function (an MX Function is expanded).
    lo, hi : array_like
        The boxes, shape (n_boxes, n_x) or (n_x,), every input's nonzeros in turn.
    samples : int
        Random points per box besides the centre and the corners.
    prec : int
        arb's working precision, bits.
    seed : int
        Seed of the random points.

    Returns
    -------
    EnclosureCheck
    """
    t0 = time.perf_counter()
    samples = check_count(samples, "samples", lower=0, upper=10**6)
    rng = np.random.default_rng(check_seed(seed))
    A = ArbFunction(fn, prec)
    XL, XH, _ = _boxes(lo, hi, A.n_x)
    PL, PH, _ = IntervalFunction(A.function).evaluate(XL, XH)
    PL = np.where(np.isnan(PL), -np.inf, PL)  # NaN: no information on that side
    PH = np.where(np.isnan(PH), np.inf, PH)
    AL, AH = A(XL, XH)
    flint = A._flint
    arb = flint.arb
    missed, arb_missed, n_points = [], [], 0
    with flint.ctx.workprec(A.prec):
        for k in range(len(XL)):
            pts = _points(XL[k], XH[k], samples, rng)
            n_points += len(pts)
            bad_p = bad_a = False
            for p in pts:
                v = A.balls([arb(float(c)) for c in p])
                vl = np.array([_down(b, arb) for b in v])
                vh = np.array([_upward(b, arb) for b in v])
                fin = np.isfinite(vl) & np.isfinite(vh)  # a point outside the graph's domain holds nothing
                bad_p |= bool(np.any(fin & ((vh < PL[k]) | (vl > PH[k]))))
                bad_a |= bool(np.any(fin & ((vh < AL[k]) | (vl > AH[k]))))
            if bad_p:
                missed.append(k)
            if bad_a:
                arb_missed.append(k)
    disjoint = np.flatnonzero(np.any((AH < PL) | (AL > PH), axis=1))
    pw, aw = PH - PL, AH - AL
    use = np.isfinite(pw) & np.isfinite(aw) & (aw > 0)
    ratio = pw[use] / aw[use]
    return EnclosureCheck(
        boxes=len(XL),
        points=n_points,
        disjoint=tuple(int(k) for k in disjoint),
        missed=tuple(missed),
        arb_missed=tuple(arb_missed),
        width_ratio_max=float(ratio.max()) if ratio.size else float("nan"),
        width_ratio_median=float(np.median(ratio)) if ratio.size else float("nan"),
        package_unbounded=int(np.sum(~(np.isfinite(PL) & np.isfinite(PH)))),
        arb_unbounded=int(np.sum(~(np.isfinite(AL) & np.isfinite(AH)))),
        elapsed_s=time.perf_counter() - t0,
    )


def check_certificate_enclosures(
    mechanism, certificate, boxes: int = 16, samples: int = 4, prec: int = 106, seed: int = 0
) -> EnclosureCheck:
    """Cross-check with arb the interval evaluation under a certified worst-pose bound.

    On the ``boxes`` boxes a certificate set aside (``certify_worst_pose(..., keep_boxes=True)``)
    whose bounds are nearest the certified one (those that set it), :func:`check_enclosures`
    compares the package's enclosures of the position sensitivity ``A`` over the searched joints
    (the others at the certificate's pose), its Jacobian and its Hessian (what the Taylor-corner
    bounds evaluate) with arb's.  It checks the interval arithmetic the bound rests on, not the
    bound itself; the arc-polygon bounds (``Certificate.method``) evaluate an exact polynomial
    instead, and there the check covers the graphs only.  It is not part of the search: arb, one
    box at a time in Python, is far slower than the batched evaluation.

    Parameters
    ----------
    mechanism : Mechanism
        The mechanism the certificate is for.
    certificate : Certificate
        With its boxes kept.
    boxes : int
        Boxes checked.
    samples, prec, seed
        As in :func:`check_enclosures`.

    Returns
    -------
    EnclosureCheck
    """
    _flint()  # before the graphs are built: a missing python-flint is reported at once
    if getattr(certificate, "leaves", None) is None:
        raise InputError("certificate", "no boxes kept", "a Certificate of certify_worst_pose(..., keep_boxes=True)")
    if certificate.model != mechanism.name:
        raise InputError("certificate", f"is for {certificate.model}, not {mechanism.name}", mechanism.name)
    boxes = check_count(boxes, "boxes")
    lo, hi, bound = certificate.leaves
    names = list(mechanism.joint_names)
    free = [names.index(n) for n in certificate.searched]
    x = ca.SX.sym("x", len(free))
    q = [ca.SX(float(v)) for v in certificate.q]
    for i, j in enumerate(free):
        q[j] = x[i]
    a = ca.densify(ca.vec(position_sensitivity(mechanism).call([ca.vertcat(*q)])[0]))
    H = [ca.vec(ca.hessian(a[i], x)[0]) for i in range(a.numel())]
    fn = ca.Function("aJH", [x], [a, ca.densify(ca.jacobian(a, x)), ca.densify(ca.vertcat(*H))])
    target = certificate.upper_bound if certificate.upper_bound is not None else certificate.probability_lower_bound
    order = np.argsort(np.abs(bound - target), kind="stable")[:boxes]  # the boxes that set the bound
    return check_enclosures(fn, lo[order], hi[order], samples=samples, prec=prec, seed=seed)
