"""A CasADi graph of a box variable, shaped for the branch and bound, with a second-order form.

:class:`BoxFunction` wraps an SX Function whose first input ``x`` ranges over boxes and whose other
inputs are fixed.  It gives what :func:`tolsynth.analysis.branch_bound.maximize` takes: interval
bounds of every output (a constraint function), an upper bound of the first output entry with
bounds of its gradient (an objective's bound function), and point values.

The objective's upper bound is the smallest of three rigorous ones (``order`` chooses how many):
the natural interval extension, the mean-value form ``f(c) + |J(B)| r``, and the second-order
Taylor form

    f(x) <= f(c) + |g(c)| r + 1/2 sum_j max(H_jj(B), 0) r_j^2 + 1/2 sum_{j != k} |H_jk(B)| r_j r_k

(Taylor's theorem with the Lagrange remainder, H(B) the interval Hessian over the box, c its
centre, r its half-widths).  Near an interior maximum the diagonal terms vanish and ``g(c)`` is
small, so the bound's excess falls like the cube of the width instead of the square: far fewer boxes
cluster around the maximiser.  The forms are used only on boxes proven regular (the graph
defined and smooth on the whole box).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from tolsynth.analysis.interval_ops import round_up as _up
from tolsynth.analysis.intervals import IntervalFunction, MeanValueFunction, _as_sx
from tolsynth.errors import InputError

__all__ = ["BoxFunction"]

_U = 2.0**-53  # unit roundoff


def _sum_up(terms, axis):
    """An upper bound of the exact sum of nonnegative floating-point terms along ``axis`` (the
    computed sum is within (m - 1) units of roundoff of it, relatively)."""
    m = terms.shape[axis]
    return _up(terms.sum(axis=axis) * (1.0 + 4.0 * (m + 2) * _U))


class BoxFunction:
    """An SX Function of a box variable ``x`` (its first input) and fixed values of its other
    inputs, in the shapes :func:`tolsynth.analysis.branch_bound.maximize` takes.

    Parameters
    ----------
    f : casadi.Function
        SX Function (an MX Function is expanded); input 0 is x, the others are fixed.
    fixed : sequence of array_like
        Values of inputs 1, 2, ... (their numbers of nonzeros).
    order : int
        0: natural interval extension; 1: and the mean-value form; 2: and the second-order Taylor
        form for :meth:`upper` (builds the Hessian graph of the first output entry).
    chunk : int
        Boxes evaluated together (see :class:`~tolsynth.analysis.intervals.IntervalFunction`).

    Examples
    --------
    >>> import casadi as ca, numpy as np
    >>> from tolsynth.analysis.branch_bound import maximize
    >>> q = ca.SX.sym("q", 2)
    >>> reach = BoxFunction(ca.Function("r", [q], [ca.norm_2(ca.vertcat(ca.cos(q[0]) + ca.cos(q[0] + q[1]),
    ...                                                                  ca.sin(q[0]) + ca.sin(q[0] + q[1])))]))
    >>> r = maximize(reach.upper, reach.point, [0.0, 0.5], [1.0, 2.0], tol=1e-9)
    >>> bool(r.certified), bool(abs(r.upper_bound - 2 * np.cos(0.25)) < 1e-8)
    (True, True)
    """

    def __init__(self, f: ca.Function, fixed=(), order: int = 2, chunk: int = 512):
        f = _as_sx(f)
        if len(fixed) != f.n_in() - 1:
            raise InputError("fixed", f"{len(fixed)} values given", f"{f.n_in() - 1} (inputs 1.. of {f.name()})")
        if order not in (0, 1, 2):
            raise InputError("order", f"{order!r}", "0, 1 or 2")
        self.function = f
        self.fixed = [np.asarray(v, dtype=float).reshape(-1) for v in fixed]
        for i, v in enumerate(self.fixed):
            if v.size != f.nnz_in(i + 1) or not np.all(np.isfinite(v)):
                raise InputError(f"fixed[{i}]", f"{v.size} values", f"{f.nnz_in(i + 1)} finite numbers")
        if f.nnz_in(0) == 0 or sum(f.numel_out(i) for i in range(f.n_out())) == 0:
            raise InputError("f", f"{f.name()} has no box variable or no output", "input 0 and an output")
        self.d = f.nnz_in(0)
        self.order = int(order)
        self._F = IntervalFunction(f, chunk) if order == 0 else MeanValueFunction(f, wrt=[0], chunk=chunk)
        self._fixed_row = np.concatenate([np.zeros(0)] + self.fixed)[None, :]
        self._shapes = [(f.size1_out(i), f.size2_out(i)) for i in range(f.n_out())]
        if order == 2:
            sx = f.sx_in()
            y0 = ca.vertcat(*[ca.densify(o)[:] for o in f.call(sx)])[0]
            x = ca.vertcat(*sx[0].nonzeros())
            H, g = ca.hessian(y0, x)
            self._fgh = IntervalFunction(ca.Function("fgh", sx, [y0, g, ca.densify(H)]), chunk)
            self._fg = IntervalFunction(ca.Function("fg", sx, [y0, g]), chunk)

    def _stack(self, x):
        x = np.asarray(x, dtype=float).reshape(-1, self.d)
        return np.concatenate([x, np.broadcast_to(self._fixed_row, (len(x), self._fixed_row.shape[1]))], axis=1)

    def box(self, lo, hi):
        """Bounds ``(lo, hi)`` of every output entry on each box, each of shape (n, m): the entries
        dense, column-major, the outputs in turn.  NaN: no information on that side."""
        OL, OH = self._F.evaluate(self._stack(lo), self._stack(hi))[:2]
        return OL, OH

    __call__ = box

    def upper(self, lo, hi):
        """Upper bounds (n,) of the first output entry on each box; for ``order >= 1`` a tuple
        ``(upper, g_lo, g_hi)`` with bounds (n, d) of its gradient over each box (NaN where the box
        is not proven regular)."""
        lo = np.asarray(lo, dtype=float).reshape(-1, self.d)
        hi = np.asarray(hi, dtype=float).reshape(-1, self.d)
        XL, XH = self._stack(lo), self._stack(hi)
        if self.order == 0:
            return self._F.evaluate(XL, XH)[1][:, 0]
        if self.order == 1:
            _, OH, _, JL, JH = self._F.evaluate(XL, XH, jacobian=True)
            return OH[:, 0], JL[:, 0, :], JH[:, 0, :]
        n, d = len(lo), self.d
        c = np.minimum(np.maximum(0.5 * (lo + hi), lo), hi)
        r = np.maximum(_up(hi - c), _up(c - lo))
        BL, BH, breg = self._fgh.evaluate(XL, XH)
        C = self._stack(c)
        PL, PH, preg = self._fg.evaluate(C, C)
        with np.errstate(all="ignore"):
            JL, JH = BL[:, 1 : 1 + d], BH[:, 1 : 1 + d]
            HL = BL[:, 1 + d :].reshape(n, d, d).transpose(0, 2, 1)  # column-major storage
            HH = BH[:, 1 + d :].reshape(n, d, d).transpose(0, 2, 1)
            mJ = np.maximum(np.abs(JL), np.abs(JH))
            mg = np.maximum(np.abs(PL[:, 1:]), np.abs(PH[:, 1:]))
            mH = np.maximum(np.abs(HL), np.abs(HH))
            diag = np.arange(d)
            rr = r[:, :, None] * r[:, None, :]
            quad = mH * rr
            quad[:, diag, diag] = np.maximum(HH[:, diag, diag], 0.0) * r * r
            # first order: f(c) + |J(B)| r; second order: f(c) + |g(c)| r + r' H(B) r / 2
            t1 = _up(PH[:, 0] + _sum_up(mJ * r, axis=1))
            t2 = _up(PH[:, 0] + _sum_up(np.concatenate([mg * r, 0.5 * quad.reshape(n, d * d)], axis=1), axis=1))
            ok = breg & preg
            ub = np.fmin(BH[:, 0], np.where(ok, np.fmin(t1, t2), np.nan))
            # the gradient over the box, also g(c) + H(B) [-r, r]
            spread = _sum_up(mH * r[:, None, :], axis=2)
            g_lo = np.fmax(JL, -_up(spread - PL[:, 1:]))
            g_hi = np.fmin(JH, _up(PH[:, 1:] + spread))
        g_lo = np.where(ok[:, None], g_lo, np.nan)
        g_hi = np.where(ok[:, None], g_hi, np.nan)
        return ub, g_lo, g_hi

    def values(self, x) -> np.ndarray:
        """Every output entry at the points x (n, d), plain CasADi: shape (n, m)."""
        x = np.asarray(x, dtype=float).reshape(-1, self.d)
        if len(x) == 0:
            return np.zeros((0, sum(r * c for r, c in self._shapes)))
        # a call with n columns per input evaluates the Function n times (CasADi maps it)
        out = self.function(x.T, *[v[:, None] for v in self.fixed])
        out = out if isinstance(out, (list, tuple)) else [out]
        parts = []
        for o, (r, c) in zip(out, self._shapes):
            a = np.array(o).reshape(r, len(x), c)  # the columns of point j: j*c .. j*c + c - 1
            parts.append(a.transpose(1, 2, 0).reshape(len(x), r * c))  # column-major per point
        return np.concatenate(parts, axis=1)

    def point(self, x) -> np.ndarray:
        """The first output entry at the points x (n, d)."""
        return self.values(x)[:, 0]
