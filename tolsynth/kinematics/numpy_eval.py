"""A NumPy interpreter of CasADi SX graphs: one graph, evaluated on whole batches.

:class:`NumpyEvaluator` walks the instruction list of a CasADi SX ``Function`` and applies one
NumPy ufunc per CasADi operation to a whole batch of inputs, so that the model's *one* symbolic
copy of a formula (forward kinematics, sensitivities, the covariance graph) is evaluated for
thousands of samples or poses per ufunc call, with no second implementation.  The sub-graph that
does not depend on the batch-varying inputs is evaluated once per :meth:`NumpyEvaluator.bind`.

Used by the Monte Carlo (:mod:`tolsynth.analysis.montecarlo`), the batched analytic statistics
(:mod:`tolsynth.kinematics.batch_stats`), the pose search and the inverse kinematics of the map.
``benchmarks/bench_montecarlo.py`` compares it with CasADi's own ``map`` evaluation.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Any, Sequence

import casadi as ca
import numpy as np

from tolsynth.errors import InputError

__all__ = ["NumpyEvaluator"]

#: bound programs remembered per evaluator (varying pattern + fixed values)
BOUND_CACHE = 16


def _if_else_zero(c, x, out=None):
    r = np.where(c != 0, x, 0.0)
    if out is None:
        return r
    out[...] = r
    return out


def _twice(x, out=None):
    return np.add(x, x, out=out)


def _assign(x, out=None):
    if out is None:
        return np.array(x, dtype=float)
    out[...] = x
    return out


def _erf(x, out=None):  # NumPy has no erf; CasADi's own (slow path, never used by the kinematics)
    x = np.asarray(x, dtype=float)
    r = np.array(ca.erf(ca.DM(x.reshape(-1, 1)))).reshape(x.shape)
    if out is None:
        return r
    out[...] = r
    return out


_UNARY = {
    ca.OP_ASSIGN: _assign,
    ca.OP_NEG: np.negative,
    ca.OP_EXP: np.exp,
    ca.OP_LOG: np.log,
    ca.OP_SQRT: np.sqrt,
    ca.OP_SQ: np.square,
    ca.OP_TWICE: _twice,
    ca.OP_SIN: np.sin,
    ca.OP_COS: np.cos,
    ca.OP_TAN: np.tan,
    ca.OP_ASIN: np.arcsin,
    ca.OP_ACOS: np.arccos,
    ca.OP_ATAN: np.arctan,
    ca.OP_NOT: np.logical_not,
    ca.OP_FLOOR: np.floor,
    ca.OP_CEIL: np.ceil,
    ca.OP_FABS: np.fabs,
    ca.OP_SIGN: np.sign,
    ca.OP_ERF: _erf,
    ca.OP_INV: np.reciprocal,
    ca.OP_SINH: np.sinh,
    ca.OP_COSH: np.cosh,
    ca.OP_TANH: np.tanh,
    ca.OP_ASINH: np.arcsinh,
    ca.OP_ACOSH: np.arccosh,
    ca.OP_ATANH: np.arctanh,
}
_BINARY = {
    ca.OP_ADD: np.add,
    ca.OP_SUB: np.subtract,
    ca.OP_MUL: np.multiply,
    ca.OP_DIV: np.divide,
    ca.OP_POW: np.power,
    ca.OP_CONSTPOW: np.power,
    ca.OP_LT: np.less,
    ca.OP_LE: np.less_equal,
    ca.OP_EQ: np.equal,
    ca.OP_NE: np.not_equal,
    ca.OP_AND: np.logical_and,
    ca.OP_OR: np.logical_or,
    ca.OP_FMOD: np.fmod,
    ca.OP_COPYSIGN: np.copysign,
    ca.OP_IF_ELSE_ZERO: _if_else_zero,
    ca.OP_FMIN: np.fmin,
    ca.OP_FMAX: np.fmax,
    ca.OP_ATAN2: np.arctan2,
}
_OP_NAMES = {getattr(ca, n): n for n in dir(ca) if n.startswith("OP_")}


class NumpyEvaluator:
    """Evaluate a CasADi SX ``Function`` on NumPy batches by interpreting its instruction list.

    Every CasADi operation of the graph (``f.instruction_id(k)``, ``OP_ADD``, ``OP_COS``, ...)
    maps to one NumPy ufunc applied to a whole batch at once, so the *one* symbolic copy of a
    formula is evaluated for ``batch`` samples per ufunc call, with no second implementation.
    Inputs are given per input as an array of shape ``(nnz,)`` (the same for every sample) or
    ``(nnz, batch)``; a ``(nnz,)`` row that is the same for all samples is cheaper.  Instructions
    that depend only on batch-invariant entries are evaluated once per :meth:`bind` (for the
    Monte Carlo: everything that depends on the joints only).

    Parameters
    ----------
    f : casadi.Function
        An SX function (``f.is_a("SXFunction")``) with dense or sparse inputs and outputs.

    Examples
    --------
    >>> import casadi as ca, numpy as np
    >>> x = ca.SX.sym("x", 2)
    >>> ev = NumpyEvaluator(ca.Function("f", [x], [ca.sin(x[0]) * x[1]]))
    >>> ev([np.array([[0.0, np.pi / 2], [2.0, 3.0]])])[0].round(12).tolist()
    [[0.0, 3.0]]
    """

    def __init__(self, f: ca.Function):
        if not f.is_a("SXFunction"):
            raise InputError("f", f"{f.name()} is not an SX Function", "a casadi.Function built from SX expressions")
        self.function = f
        self.nnz_in = [f.nnz_in(i) for i in range(f.n_in())]
        self.nnz_out = [f.nnz_out(i) for i in range(f.n_out())]
        self.n_work = f.sz_w()
        code = []
        for k in range(f.n_instructions()):
            op = f.instruction_id(k)
            ins = list(f.instruction_input(k))
            outs = list(f.instruction_output(k))
            const = f.instruction_constant(k) if op == ca.OP_CONST else None
            if op not in _UNARY and op not in _BINARY and op not in (ca.OP_CONST, ca.OP_INPUT, ca.OP_OUTPUT):
                raise InputError(
                    "f",
                    f"operation {_OP_NAMES.get(op, op)} in {f.name()} has no NumPy counterpart here",
                    "elementwise SX operations (no calls, no parameters)",
                )
            code.append((op, ins, outs, const))
        self._code = code

    def dense(self, i: int, values: np.ndarray) -> np.ndarray:
        """Output ``i`` from its nonzeros ``(nnz, batch)`` to a dense ``(rows, cols, batch)`` array."""
        sp = self.function.sparsity_out(i)
        values = np.asarray(values)
        out = np.zeros((sp.size1(), sp.size2()) + values.shape[1:])
        rows, cols = sp.get_triplet()
        out[np.asarray(rows, int), np.asarray(cols, int)] = values
        return out

    def bind(self, fixed: Sequence[np.ndarray], varying: Sequence[np.ndarray]) -> "_BoundProgram":
        """Specialise the program to a set of batch-varying input entries.

        Parameters
        ----------
        fixed : list of array (nnz_in[i],)
            Values of every input entry that is the same for all samples (entries that vary are
            ignored here).
        varying : list of bool array (nnz_in[i],)
            True where the entry varies over the batch.

        Returns
        -------
        program
            Callable ``program(rows, out=None)`` with ``rows`` one array ``(n_varying, batch)``
            holding the varying entries in input order; returns one ``(nnz_out[i], batch)`` array
            per output (a batch-invariant output entry is broadcast).
        """
        # a bound program depends on the varying pattern and on the fixed values only: the same
        # binding asked again (the pose search's and the map's batches at the same tolerances, the
        # Levenberg-Marquardt steps of the IK) is reused instead of re-running the scalar pass
        varying = [np.asarray(v, dtype=bool).reshape(-1) for v in varying]
        fixed = [np.asarray(v, dtype=float).reshape(-1) for v in fixed]
        try:
            key = (
                b"".join(v.tobytes() for v in varying),
                b"".join(np.where(vv, 0.0, fv).tobytes() for fv, vv in zip(fixed, varying)),
            )
        except ValueError:  # shapes wrong: _BoundProgram names the input
            return _BoundProgram(self, fixed, varying)
        cache = self.__dict__.setdefault("_bound", OrderedDict())
        prog = cache.get(key)
        if prog is None:
            prog = cache[key] = _BoundProgram(self, fixed, varying)
            while len(cache) > BOUND_CACHE:
                cache.popitem(last=False)
        else:
            cache.move_to_end(key)
        return prog

    def __call__(self, args: Sequence[np.ndarray]) -> list[np.ndarray]:
        """Evaluate on inputs of shape ``(nnz,)`` or ``(nnz, batch)`` (see the class docstring)."""
        fixed, varying, rows = [], [], []
        batch = None
        for i, a in enumerate(args):
            a = np.asarray(a, dtype=float)
            if a.ndim == 1:
                fixed.append(a.reshape(-1))
                varying.append(np.zeros(self.nnz_in[i], bool))
            else:
                if batch is not None and a.shape[1] != batch:
                    raise InputError("args", "inputs with different batch sizes", "one batch size")
                batch = a.shape[1]
                fixed.append(np.zeros(self.nnz_in[i]))
                varying.append(np.ones(self.nnz_in[i], bool))
                rows.append(a)
        prog = self.bind(fixed, varying)
        if batch is None:
            return [o[:, 0] for o in prog(np.zeros((0, 1)))]
        return prog(np.vstack(rows))


class _BoundProgram:
    """The instruction list of a :class:`NumpyEvaluator` split into a once-only scalar part and a
    per-batch vector part (see :meth:`NumpyEvaluator.bind`)."""

    def __init__(self, ev: NumpyEvaluator, fixed, varying):
        self.ev = ev
        fixed = [np.asarray(v, dtype=float).reshape(-1) for v in fixed]
        varying = [np.asarray(v, dtype=bool).reshape(-1) for v in varying]
        for i, (fv, vv) in enumerate(zip(fixed, varying)):
            if fv.shape != (ev.nnz_in[i],) or vv.shape != (ev.nnz_in[i],):
                raise InputError(f"input {i}", f"expected {ev.nnz_in[i]} entries", "one value per nonzero")
        # row of each varying input entry in the rows array
        self.row_of = {}
        for i, vv in enumerate(varying):
            for j in np.flatnonzero(vv):
                self.row_of[(i, int(j))] = len(self.row_of)
        self.n_rows = len(self.row_of)
        # symbolic pass: which work slot is batch-varying at each point; evaluate the rest now
        scal: list[Any] = [None] * ev.n_work
        is_vec = [False] * ev.n_work
        steps = []  # (kind, payload)
        self.out_fixed = [np.zeros(n) for n in ev.nnz_out]
        with np.errstate(all="ignore"):
            for op, ins, outs, const in ev._code:
                if op == ca.OP_CONST:
                    scal[outs[0]], is_vec[outs[0]] = np.float64(const), False
                elif op == ca.OP_INPUT:
                    i, j = ins
                    if varying[i][j]:
                        is_vec[outs[0]] = True
                        steps.append(("input", (outs[0], self.row_of[(i, j)])))
                    else:
                        scal[outs[0]], is_vec[outs[0]] = np.float64(fixed[i][j]), False
                elif op == ca.OP_OUTPUT:
                    o, nz = outs
                    if is_vec[ins[0]]:
                        steps.append(("output", (o, nz, ins[0])))  # copied when reached: slots are reused
                    else:
                        self.out_fixed[o][nz] = float(scal[ins[0]])
                else:
                    fn = _UNARY.get(op) or _BINARY[op]
                    srcs = ins[:1] if op in _UNARY else ins[:2]
                    if any(is_vec[s] for s in srcs):
                        args = tuple(("v", s) if is_vec[s] else ("s", scal[s]) for s in srcs)
                        steps.append(("op", (fn, args, outs[0])))
                        is_vec[outs[0]] = True
                    else:
                        scal[outs[0]] = np.float64(fn(*[scal[s] for s in srcs]))
                        is_vec[outs[0]] = False
        self._steps = steps

    def _work(self, batch: int) -> np.ndarray:
        # one work array per evaluator and thread (programs are cached and may be shared by
        # threads; the outputs are copied out of it), of the last batch size: memory stays bounded
        store = self.ev.__dict__.setdefault("_work_store", threading.local())
        buf = getattr(store, "buf", None)
        if buf is None or buf.shape[1] != batch:
            buf = store.buf = np.empty((self.ev.n_work, batch))
        return buf

    @property
    def n_vector_ops(self) -> int:
        """Number of ufunc calls per batch (the rest was evaluated once at bind time)."""
        return sum(1 for kind, _ in self._steps if kind == "op")

    def __call__(self, rows: np.ndarray, out: list[np.ndarray] | None = None) -> list[np.ndarray]:
        rows = np.asarray(rows, dtype=float)
        if rows.ndim != 2 or rows.shape[0] != self.n_rows:
            raise InputError("rows", f"expected shape ({self.n_rows}, batch), got {rows.shape}", "(n_varying, batch)")
        batch = rows.shape[1]
        W = self._work(batch)
        slot: list[Any] = [None] * self.ev.n_work
        if out is None:
            out = [np.empty((n, batch)) for n in self.ev.nnz_out]
        for o, vals in enumerate(self.out_fixed):
            out[o][...] = vals[:, None]
        with np.errstate(all="ignore"):  # acos(>1) -> NaN is how a loop failure shows; counted by the caller
            for kind, payload in self._steps:
                if kind == "op":
                    fn, args, o = payload
                    slot[o] = fn(*[slot[b] if t == "v" else b for t, b in args], out=W[o])
                elif kind == "input":
                    s, r = payload
                    slot[s] = rows[r]
                else:
                    o, nz, s = payload
                    out[o][nz] = slot[s]
        return out
