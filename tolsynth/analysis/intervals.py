"""Rigorous interval evaluation of CasADi SX graphs, and a mean-value (centred) form.

:class:`IntervalFunction` reads the algorithm of an SX :class:`casadi.Function` once, renames its
work vector into single-assignment nodes and groups the nodes by depth and operation, so that one
evaluation is a few NumPy calls per group, each over all the boxes of a batch at once.  Every
operation has an interval extension (:mod:`tolsynth.analysis.interval_ops`), rounded outward, so
the enclosure holds for the graph as CasADi evaluates it in floating point.

Semantics of a result ``[lo, hi]`` on a box: it contains the value of the output at every point of
the box where the graph is defined (each operation inside its domain).  A ``NaN`` end point means
"no information" on that side (read ``-inf`` for ``lo``, ``+inf`` for ``hi``).  ``regular[k]`` is
True when box ``k`` is proven to contain no point where an operation leaves its domain or is
discontinuous (a division by an interval holding zero, ``sqrt`` of a negative part, a comparison
not decided on the box...) and no output overflows; only on such boxes is a mean-value form valid,
and :class:`MeanValueFunction` uses it there only.

Example
-------
>>> import casadi as ca, numpy as np
>>> x = ca.SX.sym("x")
>>> F = IntervalFunction(ca.Function("f", [x], [ca.sin(x) * x]))
>>> v = F([np.array([[0.0], [3.0]])], [np.array([[1.0], [9.0]])])
>>> v.lo[0].shape
(2, 1, 1)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from tolsynth.analysis.interval_c import compiled_program, evaluate_compiled, library
from tolsynth.analysis.interval_ops import BINARY, MULC_NEG, MULC_POS, OP_NAMES, SUPPORTED_OPERATIONS, UNARY, Context
from tolsynth.analysis.interval_ops import round_down as _dn
from tolsynth.analysis.interval_ops import round_up as _up
from tolsynth.errors import InputError

__all__ = ["IntervalFunction", "IntervalValue", "MeanValueFunction", "SUPPORTED_OPERATIONS"]


def _as_sx(f, field: str = "f") -> ca.Function:
    if not isinstance(f, ca.Function):
        raise InputError(field, f"expected a casadi.Function, got {type(f).__name__}")
    if f.is_a("SXFunction"):
        return f
    try:
        return f.expand()
    except RuntimeError as err:
        raise InputError(
            field,
            f"{f.name()} cannot be expanded to an SX graph ({err})",
            "an SX Function, or an MX Function of scalar operations",
        ) from None


@dataclass(frozen=True)
class IntervalValue:
    """Enclosures of a Function's outputs on a batch of boxes.

    ``lo[i]`` and ``hi[i]`` have shape ``(n_boxes, rows_i, cols_i)`` (dense; structural zeros are
    0).  A NaN end point means "no information" on that side.  ``regular`` (shape ``(n_boxes,)``)
    is True where the box is proven free of domain violations and discontinuities.
    """

    lo: tuple
    hi: tuple
    regular: np.ndarray


class IntervalFunction:
    """Interval extension of an SX :class:`casadi.Function`, vectorised over boxes.

    Parameters
    ----------
    f : casadi.Function
        An SX Function (an MX Function is expanded).
    chunk : int
        Boxes evaluated together; larger batches are cut into chunks of this size (memory is
        about ``16 * n_nodes * chunk`` bytes, kept between calls: an instance is not for
        concurrent use by several threads).
    """

    def __init__(self, f: ca.Function, chunk: int = 512):
        f = _as_sx(f)
        self.function = f
        self.chunk = int(chunk)
        self.in_nnz = [f.nnz_in(i) for i in range(f.n_in())]
        self.in_offset = np.concatenate([[0], np.cumsum(self.in_nnz)]).astype(int)
        self.n_x = int(self.in_offset[-1])
        self._buffers = None
        self._compile(f)

    def _compile(self, f):
        n_x = self.n_x
        consts: dict[tuple, int] = {}
        cvals: list[float] = []
        ops, args, level, extra = [], [], [], []  # of the operation nodes, numbered after inputs + consts
        work: dict[int, tuple] = {}  # work index -> ("x"|"c"|"o", index)
        out_nodes = [{} for _ in range(f.n_out())]
        lvl = {"x": lambda i: 0, "c": lambda i: 0, "o": lambda i: level[i]}
        for k in range(f.n_instructions()):
            op = f.instruction_id(k)
            ins, outs = f.instruction_input(k), f.instruction_output(k)
            if op == ca.OP_INPUT:
                work[outs[0]] = ("x", int(self.in_offset[ins[0]]) + ins[1])
            elif op == ca.OP_CONST:
                v = f.instruction_constant(k)
                key = (v, math.copysign(1.0, v))  # keeps -0.0 apart from 0.0 (atan2, 1/x tell them apart)
                if key not in consts:
                    consts[key] = len(cvals)
                    cvals.append(v)
                work[outs[0]] = ("c", consts[key])
            elif op == ca.OP_OUTPUT:
                out_nodes[outs[0]][outs[1]] = work[ins[0]]
            elif op == ca.OP_ASSIGN:
                work[outs[0]] = work[ins[0]]
            elif op in UNARY or op in BINARY:
                a = [work[i] for i in ins[: 1 if op in UNARY else 2]]
                k = None
                if op == ca.OP_MUL and (a[0][0] == "c") != (a[1][0] == "c"):
                    # a product with a constant: two multiplications instead of four
                    (cref,), a = [r for r in a if r[0] == "c"], [r for r in a if r[0] != "c"]
                    k = cvals[cref[1]]
                    op = MULC_POS if k >= 0.0 else MULC_NEG
                ops.append(op)
                extra.append(k)
                args.append(a)
                level.append(1 + max(lvl[t](i) for t, i in a))
                work[outs[0]] = ("o", len(ops) - 1)
            else:
                raise InputError(
                    "f",
                    f"{f.name()} uses the operation {OP_NAMES.get(op, op)}, which has no interval extension here",
                    ", ".join(SUPPORTED_OPERATIONS),
                )
        # node numbering: inputs, constants (a 0 among them for structural zeros), then the
        # operations grouped by (depth, operation) so that each group's results form one slice
        if (0.0, 1.0) not in consts:
            consts[(0.0, 1.0)] = len(cvals)
            cvals.append(0.0)
        zero = consts[(0.0, 1.0)]
        self._consts = np.array(cvals, dtype=float)
        n_c = len(self._consts)
        order = sorted(range(len(ops)), key=lambda i: (level[i], ops[i]))
        new = np.empty(len(ops), dtype=int)
        new[order] = n_x + n_c + np.arange(len(ops))

        def node(ref):
            t, i = ref
            return i if t == "x" else n_x + i if t == "c" else int(new[i])

        self._program = []
        groups = []  # (operation, start, end, arguments, constants): the compiled interpreter's input
        start = 0
        while start < len(order):
            end = start
            key = (level[order[start]], ops[order[start]])
            while end < len(order) and (level[order[end]], ops[order[end]]) == key:
                end += 1
            members = order[start:end]
            arg_idx = tuple(np.array([node(args[m][j]) for m in members]) for j in range(len(args[members[0]])))
            fn = UNARY.get(key[1]) or BINARY[key[1]]
            k = np.array([extra[m] for m in members])[:, None] if extra[members[0]] is not None else None
            self._program.append((fn, n_x + n_c + start, n_x + n_c + end, arg_idx, k))
            groups.append((key[1], n_x + n_c + start, n_x + n_c + end, arg_idx, k))
            start = end
        self.n_nodes = n_x + n_c + len(ops)
        # outputs: node of every dense entry (column-major), structural zeros read the constant 0
        self.out_shape, out_idx = [], []
        for i in range(f.n_out()):
            sp = f.sparsity_out(i)
            self.out_shape.append((sp.size1(), sp.size2()))
            dense = np.full(sp.numel(), n_x + zero, dtype=int)
            rows, cols = sp.get_triplet()
            for k, (r, cc) in enumerate(zip(rows, cols)):
                if k in out_nodes[i]:
                    dense[cc * sp.size1() + r] = node(out_nodes[i][k])
            out_idx.append(dense)
        self._out_split = np.cumsum([len(d) for d in out_idx])[:-1]
        self._out_idx = np.concatenate(out_idx) if out_idx else np.zeros(0, dtype=int)
        self._compiled = compiled_program(groups, n_x, self._consts, self._out_idx)

    @property
    def n_operations(self) -> int:
        return self.n_nodes - self.n_x - len(self._consts)

    @property
    def compiled(self) -> bool:
        """Whether :meth:`evaluate` runs the compiled interpreter (:mod:`tolsynth.analysis.interval_c`)."""
        return self._compiled is not None and library() is not None

    @property
    def n_groups(self) -> int:
        return len(self._program)

    def stack_inputs(self, values, field: str) -> np.ndarray:
        """The inputs of one side (lower or upper) as one array (n_boxes, n_x)."""
        if (
            isinstance(values, np.ndarray)
            and len(self.in_nnz) != 1
            and values.ndim == 2
            and values.shape[-1] == self.n_x
        ):
            return values.astype(float)
        if not isinstance(values, (list, tuple)):
            values = [values]
        if len(values) != len(self.in_nnz):
            raise InputError(
                field,
                f"{len(values)} inputs given, {self.function.name()} takes {len(self.in_nnz)}",
                f"a list of {len(self.in_nnz)} arrays",
            )
        parts = [np.atleast_2d(np.asarray(v, dtype=float)) for v in values]
        n = max(p.shape[0] for p in parts)
        for i, (p, k) in enumerate(zip(parts, self.in_nnz)):
            if p.shape[-1] != k or p.shape[0] not in (1, n):
                raise InputError(f"{field}[{i}]", f"shape {p.shape}", f"(n_boxes, {k}) or ({k},)")
        return np.concatenate([np.broadcast_to(p, (n, p.shape[1])) for p in parts], axis=1)

    def __call__(self, lo, hi) -> IntervalValue:
        """Enclosures on the boxes ``lo <= x <= hi``: per input an array ``(n_boxes, nnz)`` or
        ``(nnz,)`` (shared by all boxes), or one array ``(n_boxes, n_x)`` of all inputs."""
        XL, XH = self.stack_inputs(lo, "lo"), self.stack_inputs(hi, "hi")
        if XL.shape != XH.shape:
            XL, XH = np.broadcast_arrays(XL, XH)
        if not (np.all(np.isfinite(XL)) and np.all(np.isfinite(XH))):
            raise InputError("lo, hi", "box bounds must be finite numbers")
        if np.any(XL > XH):
            raise InputError("lo, hi", "a lower bound exceeds its upper bound", "lo <= hi")
        OL, OH, reg = self.evaluate(XL, XH)
        return IntervalValue(self._dense(OL), self._dense(OH), reg)

    def _dense(self, flat):
        parts = np.split(flat, self._out_split, axis=1) if len(self.out_shape) > 1 else [flat]
        return tuple(p.reshape(p.shape[0], c, r).transpose(0, 2, 1) for p, (r, c) in zip(parts, self.out_shape))

    def evaluate(self, XL: np.ndarray, XH: np.ndarray):
        """Unchecked core: ``XL, XH`` of shape (n_boxes, n_x) -> output lower and upper bounds of
        shape (n_boxes, n_out_dense) (outputs concatenated, column-major) and ``regular``."""
        fn = library() if self._compiled is not None else None
        if fn is not None:
            return evaluate_compiled(fn, self._compiled, self.n_x, self.n_nodes, XL, XH)
        return self.evaluate_numpy(XL, XH)

    def evaluate_numpy(self, XL: np.ndarray, XH: np.ndarray):
        """:meth:`evaluate` by the NumPy extensions, a group of operations over a chunk of boxes at
        a time (the path without a compiler, and the reference of the compiled one)."""
        n = XL.shape[0]
        OL = np.empty((n, len(self._out_idx)))
        OH = np.empty_like(OL)
        reg = np.empty(n, dtype=bool)
        for s in range(0, n, self.chunk):
            e = min(n, s + self.chunk)
            OL[s:e], OH[s:e], reg[s:e] = self._evaluate_chunk(XL[s:e], XH[s:e])
        return OL, OH, reg

    def _evaluate_chunk(self, XL, XH):
        n = XL.shape[0]
        if self._buffers is None or self._buffers[0].shape[1] < n:
            # kept between calls: fresh pages cost more than the arithmetic; every node is
            # written before it is read, so nothing carries over from one call to the next
            self._buffers = (np.empty((self.n_nodes, max(n, self.chunk))), np.empty((self.n_nodes, max(n, self.chunk))))
        L, H = self._buffers[0][:, :n], self._buffers[1][:, :n]
        L[: self.n_x], H[: self.n_x] = XL.T, XH.T
        nc = self.n_x + len(self._consts)
        L[self.n_x : nc] = self._consts[:, None]
        H[self.n_x : nc] = self._consts[:, None]
        ctx = Context(n)
        with np.errstate(all="ignore"):
            for fn, s, e, idx, k in self._program:
                if k is not None:
                    L[s:e], H[s:e] = fn(ctx, L[idx[0]], H[idx[0]], k)
                elif len(idx) == 1:
                    L[s:e], H[s:e] = fn(ctx, L[idx[0]], H[idx[0]])
                else:
                    L[s:e], H[s:e] = fn(ctx, L[idx[0]], H[idx[0]], L[idx[1]], H[idx[1]])
        OL, OH = L[self._out_idx].T, H[self._out_idx].T
        # an overflow or a NaN that reaches an output also rules out the mean-value form
        ctx.irregular(~(np.isfinite(OL) & np.isfinite(OH)).all(axis=1))
        return OL, OH, ctx.reg


class MeanValueFunction:
    """Mean-value (centred) form intersected with the natural interval extension.

    On a box B with centre c and half-widths r, ``f(B) ⊆ f(c) + J(B) [-r, r]`` (mean-value theorem
    on each output, with J the interval Jacobian of the varied inputs); ``f(c)`` is itself an
    interval evaluation at the point, so rounding is covered.  The form is used only on boxes where
    f and J are proven regular; elsewhere the natural extension is returned.

    Parameters
    ----------
    f : casadi.Function
        An SX Function (an MX Function is expanded).
    wrt : sequence of int, optional
        Indices of the inputs that vary over the boxes (default: all).  Inputs not listed may still
        be intervals; they enter both terms as intervals.
    """

    def __init__(self, f: ca.Function, wrt=None, chunk: int = 512):
        f = _as_sx(f)
        self.natural = IntervalFunction(f, chunk)
        n_in = f.n_in()
        self.wrt = list(range(n_in)) if wrt is None else [int(i) for i in wrt]
        if any(not 0 <= i < n_in for i in self.wrt):
            raise InputError("wrt", f"input indices {self.wrt}", f"integers in [0, {n_in})")
        sx_in = f.sx_in()
        outs = f.call(sx_in)
        y = ca.vertcat(*[ca.densify(o)[:] for o in outs]) if outs else ca.SX(0, 1)
        x = ca.vertcat(*[ca.vertcat(*sx_in[i].nonzeros()) for i in self.wrt])
        # one graph for f and J over the box: they share most of their nodes
        self._fj = IntervalFunction(ca.Function(f.name() + "_fj", sx_in, [y, ca.densify(ca.jacobian(y, x))]), chunk)
        self.n_y = y.numel()
        cols = [np.arange(self.natural.in_offset[i], self.natural.in_offset[i + 1]) for i in self.wrt]
        self._cols = np.concatenate(cols) if cols else np.zeros(0, dtype=int)

    def __call__(self, lo, hi) -> IntervalValue:
        nat = self.natural
        XL, XH = nat.stack_inputs(lo, "lo"), nat.stack_inputs(hi, "hi")
        XL, XH = np.broadcast_arrays(XL, XH)
        if not (np.all(np.isfinite(XL)) and np.all(np.isfinite(XH))) or np.any(XL > XH):
            raise InputError("lo, hi", "box bounds must be finite with lo <= hi")
        OL, OH, reg = self.evaluate(XL, XH)
        return IntervalValue(nat._dense(OL), nat._dense(OH), reg)

    def evaluate(self, XL, XH, jacobian: bool = False):
        """Unchecked core, same layout as :meth:`IntervalFunction.evaluate`; with ``jacobian``, also
        the Jacobian's bounds (n_boxes, n_out_dense, n_wrt), NaN on boxes that are not regular."""
        n, ny = XL.shape[0], self.n_y
        FL, FH, reg = self._fj.evaluate(XL, XH)
        yl, yh = FL[:, :ny], FH[:, :ny]
        JL = FL[:, ny:].reshape(n, -1, ny).transpose(0, 2, 1)  # (n, ny, nx), from column-major
        JH = FH[:, ny:].reshape(n, -1, ny).transpose(0, 2, 1)
        if len(self._cols) == 0:
            return (yl, yh, reg, JL, JH) if jacobian else (yl, yh, reg)
        CL, CH = XL.copy(), XH.copy()
        cx = 0.5 * (XL[:, self._cols] + XH[:, self._cols])
        cx = np.minimum(np.maximum(cx, XL[:, self._cols]), XH[:, self._cols])
        CL[:, self._cols] = cx
        CH[:, self._cols] = cx
        cl, ch, creg = self.natural.evaluate(CL, CH)
        r = np.maximum(_up(XH[:, self._cols] - cx), _up(cx - XL[:, self._cols]))  # (n, nx)
        with np.errstate(all="ignore"):
            mag = np.maximum(np.abs(JL), np.abs(JH))
            terms = np.where(r[:, None, :] > 0.0, mag * r[:, None, :], 0.0)
            # a sum of d nonnegative terms is off by at most (d-1) units of roundoff, relatively
            d = terms.shape[2]
            rad = _up(terms.sum(axis=2) * (1.0 + 2.0 * (d + 2) * 2.0**-53))
            ml, mh = _dn(cl - rad), _up(ch + rad)
        ok = (reg & creg)[:, None]
        lo = np.where(ok, np.fmax(ml, yl), yl)
        hi = np.where(ok, np.fmin(mh, yh), yh)
        if not jacobian:
            return lo, hi, reg
        JL = np.where(reg[:, None, None], JL, np.nan)
        JH = np.where(reg[:, None, None], JH, np.nan)
        return lo, hi, reg, JL, JH
