"""Monte Carlo through the full nonlinear kinematics, and validation of an optimum.

The analytic model of the paper (section 3) is linear in the errors and treats the hand error as
Gaussian.  :func:`monte_carlo` checks both approximations: it samples the error parameters
(uniform within ``+-eps``, or normal with ``3 sigma = eps``), pushes every sample through the
model's own CasADi forward-kinematics graph (``graphs.position`` -- never a second copy of the
formula), and reports the covariance and the probabilities ``P(|w_j| <= R)`` along the analytic
principal directions and ``P(|dr| <= R)`` in the sphere, each with a confidence interval, next to
the analytic values of :meth:`tolsynth.Mechanism.analyze`.

Speed: the CasADi SX graph is evaluated on whole NumPy batches by :class:`NumpyEvaluator`, a
small interpreter of the graph's instruction list (one NumPy ufunc per CasADi operation, the
sub-graph that does not depend on the sampled errors evaluated once).  On one core this runs the
paper's robot at several million samples per second; ``benchmarks/bench_montecarlo.py`` compares
it with CasADi's own ``map`` evaluation and with per-sample calls.  Samples are drawn and
evaluated in batches of fixed size, so memory does not grow with ``n``.

Units: mm and rad; tolerances in each error parameter's tolerance unit; covariances in mm^2.

>>> import tolsynth
>>> m = tolsynth.load_model("xu_zhang_1988")
>>> r = tolsynth.monte_carlo(m, "worst", "figure3", R=0.2, n=200_000, seed=1)
>>> bool(r.p_sphere_ci[0] <= r.p_sphere <= r.p_sphere_ci[1])
True
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field
from statistics import NormalDist
from typing import Any, Callable, Mapping, Sequence

import casadi as ca
import numpy as np

from .errors import InputError, LoopClosureError, OutOfRangeError
from .stats import check_positive, check_probability, principal, variance_divisor

__all__ = [
    "NumpyEvaluator",
    "MonteCarloResult",
    "ValidationResult",
    "monte_carlo",
    "validate",
    "wilson_interval",
    "register",
]

DEFAULT_BATCH = 1 << 14  # samples per batch: a few MB of work arrays, whatever n is
_AUTO_PROGRESS_DELAY = 2.0  # s: with progress=None the bar appears only on runs longer than this


# =============================================================================================
# A NumPy interpreter of CasADi SX Functions
# =============================================================================================
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
                    "f", f"operation {_OP_NAMES.get(op, op)} in {f.name()} has no NumPy counterpart here",
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
        return _BoundProgram(self, fixed, varying)

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
        self._buffers: dict[int, np.ndarray] = {}

    def _work(self, batch: int) -> np.ndarray:
        buf = self._buffers.get(batch)
        if buf is None:
            self._buffers.clear()  # keep one batch size only: memory stays bounded
            buf = self._buffers[batch] = np.empty((self.ev.n_work, batch))
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


# =============================================================================================
# statistics helpers
# =============================================================================================
def wilson_interval(k, n: int, confidence: float = 0.95) -> np.ndarray:
    """Wilson score interval of a binomial proportion ``k / n``.

    Parameters
    ----------
    k : int or array of int
        Successes.
    n : int
        Trials (> 0).
    confidence : float
        Two-sided confidence level, 0 < confidence < 1.

    Returns
    -------
    ndarray, shape ``(..., 2)``
        Lower and upper bounds.  Unlike the normal approximation, the interval stays inside
        [0, 1] and does not collapse to a point at ``k = 0`` or ``k = n``.
    """
    confidence = check_probability(confidence, "confidence")
    z = NormalDist().inv_cdf(0.5 + 0.5 * confidence)
    k = np.asarray(k, dtype=float)
    ph = k / n
    den = 1.0 + z * z / n
    centre = (ph + z * z / (2 * n)) / den
    half = z * np.sqrt(ph * (1 - ph) / n + z * z / (4.0 * n * n)) / den
    return np.stack([np.clip(centre - half, 0, 1), np.clip(centre + half, 0, 1)], axis=-1)


def _check_n(n, field: str = "n") -> int:
    if isinstance(n, bool) or not isinstance(n, (int, np.integer, float)) or n != int(n) or int(n) <= 0:
        raise OutOfRangeError(field, f"got {n!r}", "an integer >= 1")
    return int(n)


def _check_seed(seed) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or int(seed) < 0:
        raise OutOfRangeError("seed", f"got {seed!r}", "an integer >= 0 (recorded in the result)")
    return int(seed)


def make_bar(total: int, desc: str, unit: str, delay: float):
    """A tqdm bar on stderr (tqdm is the optional extra ``progress``), or None without tqdm."""
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    kw = dict(total=total, desc=desc, unit=unit, unit_scale=True, file=sys.stderr, leave=False)
    try:
        return tqdm(delay=delay, **kw)
    except TypeError:  # tqdm < 4.62 has no delay
        return tqdm(**kw)


class _Progress:
    """tqdm to stderr if wanted and installed; a callable ``progress(done, total)`` also works."""

    def __init__(self, progress, total: int, desc: str):
        self.bar = None
        self.callback = None
        self.total = total
        if callable(progress) and not isinstance(progress, bool):
            self.callback = progress
            return
        show = progress if progress is not None else sys.stderr.isatty()
        if show:  # auto (None): only runs longer than ~2 s show the bar
            self.bar = make_bar(total, desc, "sample", 0.0 if progress else _AUTO_PROGRESS_DELAY)

    def update(self, done: int, step: int) -> None:
        if self.bar is not None:
            self.bar.update(step)
        if self.callback is not None:
            self.callback(done, self.total)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


# =============================================================================================
# the sampler
# =============================================================================================
class _Sampler:
    """One pose, one set of tolerances: draws error batches and evaluates the hand position
    (and, with ``orientation``, the hand rotation) through the model's graphs."""

    def __init__(self, mechanism, q: np.ndarray, eps: np.ndarray, distribution: str, orientation: bool):
        self.mech = mechanism
        self.eps = eps
        self.distribution = distribution
        self.active = np.flatnonzero(eps > 0)  # zero tolerance: that error is exactly 0
        g = mechanism.graphs
        qs = ca.SX.sym("q", len(q))
        ds = ca.SX.sym("delta", mechanism.n)
        outs = [g.position(qs, ds), g.closure(qs, ds)]
        if orientation:
            T = g.fk(qs, ds)
            outs.append(ca.vec(T[:3, :3]))
        f = ca.Function("mc_eval", [qs, ds], outs, ["q", "delta"], ["p", "c", "R"][: len(outs)])
        # one SX graph built from the model's graphs; cse merges what position/closure/fk share
        if hasattr(ca, "cse"):
            f = ca.Function("mc_eval", [qs, ds], [ca.cse(o) for o in outs])
        self.evaluator = NumpyEvaluator(f)
        varying_d = np.zeros(mechanism.n, bool)
        varying_d[self.active] = True
        self.program = self.evaluator.bind([q, np.zeros(mechanism.n)], [np.zeros(len(q), bool), varying_d])
        nominal = self.evaluator([q, np.zeros(mechanism.n)])
        self.p0 = nominal[0]
        self.R0 = nominal[2].reshape(3, 3, order="F") if orientation else None
        self.scale = eps[self.active] if distribution == "uniform" else eps[self.active] / 3.0
        self._rows = None

    def draw(self, rng: np.random.Generator, batch: int) -> np.ndarray:
        if self._rows is None or self._rows.shape[1] != batch:
            self._rows = np.empty((self.active.size, batch))
        rows = self._rows
        if self.distribution == "uniform":
            rng.random(out=rows)  # [0, 1)
            rows *= 2.0
            rows -= 1.0
        else:
            rng.standard_normal(out=rows)
        rows *= self.scale[:, None]
        return rows

    def evaluate(self, rows: np.ndarray) -> list[np.ndarray]:
        return self.program(rows)


# =============================================================================================
# result types
# =============================================================================================
@dataclass(frozen=True)
class MonteCarloResult:
    """Monte Carlo error statistics at one pose, next to the analytic (linear, Gaussian) ones.

    Every probability has a two-sided confidence interval (``ci_method``, level ``confidence``);
    ``*_analytic`` are the values of :meth:`tolsynth.Mechanism.analyze` and ``*_diff`` the Monte
    Carlo value minus the analytic one.  ``*_analytic_in_ci`` is False where the analytic value
    lies outside the Monte Carlo interval, i.e. where the linear + Gaussian model is off by more
    than the sampling noise explains.

    Attributes
    ----------
    model : str
    q : ndarray (rad)
        Joint values of the pose.
    position : ndarray (mm)
        Nominal hand position.
    distribution : str
        "uniform" (within +-eps) or "normal" (3 sigma = eps, not truncated).
    tolerances : dict
        Half-widths, name -> value in the parameter's tolerance unit.
    R : float (mm)
    n, seed, batch : int
        Samples, the seed of ``numpy.random.default_rng`` and the batch size.
    n_loop_failures : int
        Samples for which a closed loop could not be assembled.  They are *kept* in ``n`` and
        counted as outside every tolerance zone (conservative); the moments exclude them.
    mean, mean_ci : ndarray (mm)
        Mean position error (3,) and its normal-approximation interval (3, 2).
    covariance, covariance_analytic : ndarray (mm^2)
        Sample covariance of the position error (3, 3), and the linear model's.
    principal_directions : ndarray
        The analytic principal directions (columns, descending sigma); the components ``w_j``
        are the projections of the position error on them.
    principal_std, principal_std_analytic : ndarray (mm)
        Standard deviation of ``w_j`` sampled, and analytic ``sigma_j``.
    kurtosis, kurtosis_se : ndarray
        Excess kurtosis of each ``w_j`` (0 for a normal, -1.2 for one uniform source) and its
        standard error ``sqrt(24 / n)``.  Far from 0 means the Gaussian reading of that direction
        is poor (typically one dominant uniform error source).
    p_components, p_components_ci, p_components_analytic, p_components_diff : ndarray
        ``P(|w_j| <= R)``.
    p_sphere, p_sphere_ci, p_sphere_analytic, p_sphere_diff : float / ndarray
        ``P(|dr| <= R)`` (Eq. 5).
    p_components_analytic_in_ci : ndarray of bool
    p_sphere_analytic_in_ci : bool
    Phi : float (rad) or None
        With ``Phi``: ``p_orientation_components`` (along the analytic orientation principal
        directions, of the rotation vector), ``p_cone`` (angle between the actual and nominal hand
        z axes <= Phi), their intervals and analytic values.
    elapsed_s, samples_per_s : float
        Wall time of the sampling.
    """

    model: str
    q: np.ndarray
    position: np.ndarray
    distribution: str
    tolerances: dict
    R: float
    n: int
    seed: int
    batch: int
    confidence: float
    ci_method: str
    n_loop_failures: int
    mean: np.ndarray
    mean_ci: np.ndarray
    covariance: np.ndarray
    covariance_analytic: np.ndarray
    principal_directions: np.ndarray
    principal_std: np.ndarray
    principal_std_analytic: np.ndarray
    kurtosis: np.ndarray
    kurtosis_se: float
    p_components: np.ndarray
    p_components_ci: np.ndarray
    p_components_analytic: np.ndarray
    p_components_diff: np.ndarray
    p_components_analytic_in_ci: np.ndarray
    p_sphere: float
    p_sphere_ci: np.ndarray
    p_sphere_analytic: float
    p_sphere_diff: float
    p_sphere_analytic_in_ci: bool
    elapsed_s: float
    samples_per_s: float
    Phi: float | None = None
    p_orientation_components: np.ndarray | None = None
    p_orientation_components_ci: np.ndarray | None = None
    p_orientation_components_analytic: np.ndarray | None = None
    p_cone: float | None = None
    p_cone_ci: np.ndarray | None = None
    p_cone_analytic: float | None = None
    units: dict = field(default_factory=lambda: {
        "position": "mm", "mean": "mm", "covariance": "mm^2", "principal_std": "mm", "R": "mm",
        "q": "rad", "Phi": "rad", "tolerances": "each parameter's tolerance unit",
    })

    def to_dict(self) -> dict:
        """Plain dict (arrays as lists) for JSON."""
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items()}

    def report(self) -> str:
        """A readable table: Monte Carlo vs analytic, with intervals and flags."""
        pct = int(round(100 * self.confidence))
        lines = [
            f"model        {self.model}",
            f"pose         q = ({', '.join(f'{math.degrees(v):.4f}' for v in self.q)}) deg; "
            f"hand ({', '.join(f'{v:.3f}' for v in self.position)}) mm",
            f"errors       {self.distribution}" + (" within +-eps" if self.distribution == "uniform" else ", 3 sigma = eps"),
            f"samples      n = {self.n}, seed = {self.seed}, batch = {self.batch}; "
            f"{self.samples_per_s / 1e6:.2f} M samples/s; loop failures {self.n_loop_failures}",
            f"intervals    {pct}% {self.ci_method}",
            f"mean error   ({', '.join(f'{v:+.2e}' for v in self.mean)}) mm",
            "",
            f"{'':14}{'Monte Carlo':>12} {pct}% interval{'':9}{'analytic':>10}{'MC-analytic':>13}  flag",
        ]
        for j in range(3):
            lo, hi = self.p_components_ci[j]
            flag = "" if self.p_components_analytic_in_ci[j] else "analytic outside CI"
            lines.append(
                f"P(|w{j + 1}|<=R)    {self.p_components[j]:12.5f} [{lo:.5f}, {hi:.5f}]  "
                f"{self.p_components_analytic[j]:10.5f}{self.p_components_diff[j]:+13.5f}  {flag}"
            )
        lo, hi = self.p_sphere_ci
        flag = "" if self.p_sphere_analytic_in_ci else "analytic outside CI"
        lines.append(
            f"P(|dr|<=R)    {self.p_sphere:12.5f} [{lo:.5f}, {hi:.5f}]  {self.p_sphere_analytic:10.5f}"
            f"{self.p_sphere_diff:+13.5f}  {flag}"
        )
        lines.append("")
        lines.append(f"{'direction':14}{'sigma MC':>12}{'sigma lin.':>12}{'excess kurtosis':>17} (Gaussian 0, +-{self.kurtosis_se:.3f} s.e.)")
        for j in range(3):
            d = self.principal_directions[:, j]
            note = "" if abs(self.kurtosis[j]) <= 4 * self.kurtosis_se + 0.1 else "  not Gaussian"
            lines.append(
                f"w{j + 1} ({d[0]:+.3f},{d[1]:+.3f},{d[2]:+.3f}) {self.principal_std[j]:9.5f}"
                f"{self.principal_std_analytic[j]:12.5f}{self.kurtosis[j]:+17.3f}{note}"
            )
        if self.Phi is not None:
            lines.append("")
            lines.append(f"Phi          {self.Phi:g} rad")
            for j in range(3):
                lo, hi = self.p_orientation_components_ci[j]
                lines.append(
                    f"P(|phi{j + 1}|<=Phi) {self.p_orientation_components[j]:10.5f} [{lo:.5f}, {hi:.5f}]  "
                    f"{self.p_orientation_components_analytic[j]:10.5f}"
                )
            lo, hi = self.p_cone_ci
            lines.append(f"P(cone)       {self.p_cone:12.5f} [{lo:.5f}, {hi:.5f}]  {self.p_cone_analytic:10.5f}")
        lines.append("R = {:g} mm; w_j along the analytic principal directions; sphere = Eq. 5".format(self.R))
        return "\n".join(lines)


# =============================================================================================
# monte_carlo
# =============================================================================================
def monte_carlo(
    mechanism,
    q,
    tolerances,
    distribution: str = "uniform",
    *,
    R: float,
    n: int = 1_000_000,
    seed: int = 0,
    batch: int = DEFAULT_BATCH,
    Phi: float | None = None,
    progress: bool | Callable[[int, int], None] | None = None,
    confidence: float = 0.95,
    check_limits: bool = True,
) -> MonteCarloResult:
    """Monte Carlo of the hand position error through the full nonlinear kinematics.

    Parameters
    ----------
    mechanism : Mechanism
        From :func:`tolsynth.load_model`.
    q : str or array
        Configuration name or joint values (rad).
    tolerances : str, dict or array
        Tolerance set name, or half-widths in each parameter's tolerance unit.
    distribution : {"uniform", "normal"}
        Uniform within ``+-eps``, or normal with ``3 sigma = eps`` (not truncated, so that its
        variance is the analytic ``eps^2 / 9``).
    R : float
        Radius of the accuracy sphere and half-width of each component's zone (mm), > 0.
    n : int
        Number of samples, >= 1.
    seed : int
        Seed of ``numpy.random.default_rng`` (recorded in the result); the same seed and batch
        size give the same numbers.
    batch : int
        Samples per batch (memory ~ ``batch * (work slots + errors) * 8`` bytes, not ~ n).
    Phi : float, optional
        Orientation tolerance (rad): adds the orientation-component and cone probabilities.
    progress : bool, callable or None
        A tqdm bar on stderr (None: on a terminal, shown once the run has taken 2 s), or a
        callable ``progress(done, total)``.
    confidence : float
        Level of the intervals (Wilson score for the probabilities, normal for the mean).
    check_limits : bool
        Check the joint values against the limits (named configurations keep their waivers).

    Returns
    -------
    MonteCarloResult

    Raises
    ------
    OutOfRangeError
        ``n <= 0``, ``R <= 0``, negative seed, unknown distribution, a joint past its limit.
    UnknownNameError
        Unknown configuration or tolerance set.
    LoopClosureError
        The loop cannot close at the nominal dimensions.

    Examples
    --------
    >>> import tolsynth
    >>> m = tolsynth.load_model("xu_zhang_1988")
    >>> r = tolsynth.monte_carlo(m, "worst", "figure3", R=0.2, n=100_000, seed=7)
    >>> r.n, r.seed, r.n_loop_failures
    (100000, 7, 0)
    """
    variance_divisor(distribution)
    R = check_positive(R, "R")
    n = _check_n(n)
    seed = _check_seed(seed)
    batch = _check_n(batch, "batch")
    confidence = check_probability(confidence, "confidence")
    if Phi is not None:
        Phi = check_positive(Phi, "Phi", "rad")
    eps = mechanism.tolerances(tolerances)
    qv = mechanism.joints(q, check_limits)
    ana = mechanism.analyze(qv, eps, distribution, R=R, Phi=Phi, check_limits=False)
    U = ana.principal_directions
    sampler = _Sampler(mechanism, qv, eps, distribution, orientation=Phi is not None)
    if mechanism.spec.loops:
        c0 = np.asarray(mechanism.graphs.closure(qv, np.zeros(mechanism.n))).ravel()
        if not np.all(np.abs(c0) <= 1):
            raise LoopClosureError(f"a loop cannot close at the nominal dimensions at q = {np.degrees(qv).round(4).tolist()} deg")
    p0 = sampler.p0
    if Phi is not None:
        Uo = principal(ana.orientation_covariance)[1]
        z0 = sampler.R0[:, 2]

    rng = np.random.default_rng(seed)
    R2 = R * R
    inside_sphere = 0
    inside_comp = np.zeros(3, dtype=np.int64)
    inside_ocomp = np.zeros(3, dtype=np.int64)
    inside_cone = 0
    failures = 0
    m_ok = 0
    shift = None
    s1 = np.zeros(3)
    s2 = np.zeros((3, 3))
    w_shift = None
    wpow = np.zeros((4, 3))  # sums of (w - w_shift)^k, k = 1..4
    bar = _Progress(progress, n, "monte carlo")
    t0 = time.perf_counter()
    done = 0
    try:
        while done < n:
            b = min(batch, n - done)
            rows = sampler.draw(rng, b)
            outs = sampler.evaluate(rows)
            p, c = outs[0], outs[1]
            dr = p - p0[:, None]  # (3, b) mm
            ok = np.all(np.abs(c) <= 1.0, axis=0) if c.shape[0] else np.ones(b, bool)
            ok &= np.all(np.isfinite(dr), axis=0)
            nbad = int(b - np.count_nonzero(ok))
            failures += nbad
            if nbad:
                dr = dr[:, ok]
            # probabilities: failures count as outside (numerators over ok samples, denominators n)
            d2 = np.einsum("ib,ib->b", dr, dr)
            inside_sphere += int(np.count_nonzero(d2 <= R2))
            w = U.T @ dr  # (3, b) components along the analytic principal directions
            inside_comp += np.count_nonzero(np.abs(w) <= R, axis=1)
            # moments about a shift (the first batch's mean) for numerical safety
            if dr.shape[1]:
                if shift is None:
                    shift = dr.mean(axis=1)
                    w_shift = U.T @ shift
                x = dr - shift[:, None]
                s1 += x.sum(axis=1)
                s2 += x @ x.T
                y = w - w_shift[:, None]
                y2 = y * y
                wpow[0] += y.sum(axis=1)
                wpow[1] += y2.sum(axis=1)
                wpow[2] += (y2 * y).sum(axis=1)
                wpow[3] += (y2 * y2).sum(axis=1)
                m_ok += dr.shape[1]
            if Phi is not None:
                Rm = outs[2][:, ok].reshape(3, 3, -1, order="F")  # R[i, j, b]
                # small rotation of the hand: dR = R R0^T; rotation vector from its skew part
                dR = np.einsum("ikb,jk->ijb", Rm, sampler.R0)
                s = 0.5 * np.stack([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0], dR[1, 0] - dR[0, 1]])
                sn = np.sqrt(np.einsum("ib,ib->b", s, s))
                with np.errstate(invalid="ignore", divide="ignore"):
                    fac = np.where(sn > 0, np.arcsin(np.minimum(sn, 1.0)) / np.where(sn > 0, sn, 1.0), 1.0)
                phi = s * fac
                inside_ocomp += np.count_nonzero(np.abs(Uo.T @ phi) <= Phi, axis=1)
                z = Rm[:, 2, :]
                ang = np.arctan2(np.linalg.norm(np.cross(z0, z.T), axis=1), z0 @ z)
                inside_cone += int(np.count_nonzero(ang <= Phi))
            done += b
            bar.update(done, b)
    finally:
        bar.close()
    elapsed = time.perf_counter() - t0

    zc = NormalDist().inv_cdf(0.5 + 0.5 * confidence)
    if m_ok >= 2:
        mx = s1 / m_ok
        mean = shift + mx
        cov = (s2 - m_ok * np.outer(mx, mx)) / (m_ok - 1)
        # central moments of w_j
        mu = wpow[0] / m_ok
        c2 = wpow[1] / m_ok - mu**2
        c4 = wpow[3] / m_ok - 4 * mu * wpow[2] / m_ok + 6 * mu**2 * wpow[1] / m_ok - 3 * mu**4
        with np.errstate(invalid="ignore", divide="ignore"):
            kurt = np.where(c2 > 0, c4 / np.where(c2 > 0, c2, 1.0) ** 2 - 3.0, np.nan)
        std_w = np.sqrt(np.maximum(np.diag(U.T @ cov @ U), 0.0))
        se_mean = np.sqrt(np.maximum(np.diag(cov), 0.0) / m_ok)
    else:
        mean = np.full(3, np.nan)
        cov = np.full((3, 3), np.nan)
        kurt = np.full(3, np.nan)
        std_w = np.full(3, np.nan)
        se_mean = np.full(3, np.nan)
    p_comp = inside_comp / n
    p_comp_ci = wilson_interval(inside_comp, n, confidence)
    p_sph = inside_sphere / n
    p_sph_ci = wilson_interval(inside_sphere, n, confidence)
    pa = np.asarray(ana.p_components)
    extra = {}
    if Phi is not None:
        extra = dict(
            Phi=Phi,
            p_orientation_components=inside_ocomp / n,
            p_orientation_components_ci=wilson_interval(inside_ocomp, n, confidence),
            p_orientation_components_analytic=np.asarray(ana.p_orientation_components),
            p_cone=inside_cone / n,
            p_cone_ci=wilson_interval(inside_cone, n, confidence),
            p_cone_analytic=float(ana.p_cone),
        )
    return MonteCarloResult(
        model=mechanism.name,
        q=qv,
        position=p0.copy(),
        distribution=distribution,
        tolerances=dict(zip(mechanism.error_parameters, eps.tolist())),
        R=R,
        n=n,
        seed=seed,
        batch=batch,
        confidence=confidence,
        ci_method="Wilson score (probabilities), normal approximation (mean)",
        n_loop_failures=failures,
        mean=mean,
        mean_ci=np.stack([mean - zc * se_mean, mean + zc * se_mean], axis=-1),
        covariance=cov,
        covariance_analytic=ana.covariance,
        principal_directions=U,
        principal_std=std_w,
        principal_std_analytic=ana.principal_std,
        kurtosis=kurt,
        kurtosis_se=math.sqrt(24.0 / max(m_ok, 1)),
        p_components=p_comp,
        p_components_ci=p_comp_ci,
        p_components_analytic=pa,
        p_components_diff=p_comp - pa,
        p_components_analytic_in_ci=(p_comp_ci[:, 0] <= pa) & (pa <= p_comp_ci[:, 1]),
        p_sphere=p_sph,
        p_sphere_ci=p_sph_ci,
        p_sphere_analytic=float(ana.p_sphere),
        p_sphere_diff=p_sph - float(ana.p_sphere),
        p_sphere_analytic_in_ci=bool(p_sph_ci[0] <= ana.p_sphere <= p_sph_ci[1]),
        elapsed_s=elapsed,
        samples_per_s=n / elapsed if elapsed > 0 else math.inf,
        **extra,
    )


# =============================================================================================
# validation of an optimum
# =============================================================================================
@dataclass(frozen=True)
class ValidationResult:
    """Probabilities achieved at a set of tolerances, by Monte Carlo, against the ``p`` asked for.

    Attributes
    ----------
    p : float
        Probability asked for (per principal component, the paper's Eq. 14/20).
    p_components, p_components_ci : ndarray
        Achieved ``P(|w_j| <= R)`` and interval.
    components_met : ndarray of bool
        Point estimate >= p.
    components_short : ndarray of bool
        Significantly short: the interval's upper end < p.
    p_sphere, p_sphere_ci : float, ndarray
        Achieved ``P(|dr| <= R)`` (the sphere is not the constraint of Eq. 20; it is reported so
        that the stricter reading can be judged).
    sphere_met : bool
    montecarlo : MonteCarloResult
        The full run (analytic values, kurtosis, ...).
    """

    p: float
    R: float
    distribution: str
    pose: Any
    tolerances: dict
    p_components: np.ndarray
    p_components_ci: np.ndarray
    p_components_analytic: np.ndarray
    components_met: np.ndarray
    components_short: np.ndarray
    p_sphere: float
    p_sphere_ci: np.ndarray
    p_sphere_analytic: float
    sphere_met: bool
    n: int
    seed: int
    montecarlo: MonteCarloResult

    @property
    def met(self) -> bool:
        """All three components reach p (point estimates)."""
        return bool(np.all(self.components_met))

    def to_dict(self) -> dict:
        out = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items() if k != "montecarlo"}
        out["pose"] = self.pose if isinstance(self.pose, str) else np.asarray(self.pose).tolist()
        out["met"] = self.met
        return out

    def report(self) -> str:
        pct = int(round(100 * self.montecarlo.confidence))
        lines = [f"validation   p = {self.p:g} asked, R = {self.R:g} mm, {self.distribution}, n = {self.n}, seed = {self.seed}"]
        for j in range(3):
            lo, hi = self.p_components_ci[j]
            state = "met" if self.components_met[j] else ("SHORT" if self.components_short[j] else "below p (within noise)")
            lines.append(f"P(|w{j + 1}|<=R)  {self.p_components[j]:.5f} [{lo:.5f}, {hi:.5f}] ({pct}%)  analytic "
                         f"{self.p_components_analytic[j]:.5f}  {state}")
        lo, hi = self.p_sphere_ci
        lines.append(f"P(|dr|<=R)  {self.p_sphere:.5f} [{lo:.5f}, {hi:.5f}]  analytic {self.p_sphere_analytic:.5f}  "
                     + ("met" if self.sphere_met else "below p (sphere is stricter than Eq. 20)"))
        return "\n".join(lines)


def _attr(obj, name):
    for o in (obj, getattr(obj, "spec", None), getattr(obj, "problem", None)):
        if o is not None and getattr(o, name, None) is not None:
            return getattr(o, name)
    return None


def validate(
    mechanism,
    tolerances_or_result,
    R: float | None = None,
    p: float | None = None,
    distribution: str | None = None,
    pose="worst",
    n: int = 1_000_000,
    seed: int = 0,
    batch: int = DEFAULT_BATCH,
    confidence: float = 0.95,
    progress=None,
) -> ValidationResult:
    """Monte Carlo check of an optimum: the probability achieved against the ``p`` asked for.

    Parameters
    ----------
    mechanism : Mechanism
    tolerances_or_result : dict, array, str or object with a ``.tolerances`` dict
        The tolerances (tolerance units), e.g. the result of ``tolsynth.synthesize``.
    R : float
        Radius (mm).  If None, taken from ``result.R`` or ``result.spec.R`` when present.
    p : float
        Probability asked for, 0 < p < 1 (same fallback).
    distribution : {"uniform", "normal"}
        Same fallback; default "uniform".
    pose : str or array
        Where to check (the paper's pose of largest error by default).
    n, seed, batch, confidence, progress
        As for :func:`monte_carlo`.

    Returns
    -------
    ValidationResult

    Examples
    --------
    >>> import tolsynth
    >>> m = tolsynth.load_model("xu_zhang_1988")
    >>> v = tolsynth.validate(m, "figure3", R=0.5, p=0.9, n=100_000, seed=3)
    >>> v.p_components.shape
    (3,)
    """
    tol = tolerances_or_result
    if not isinstance(tol, (str, Mapping, np.ndarray, list, tuple)) and hasattr(tol, "tolerances"):
        R = R if R is not None else _attr(tol, "R")
        p = p if p is not None else _attr(tol, "p")
        distribution = distribution if distribution is not None else _attr(tol, "distribution")
        tol = tol.tolerances
    if R is None:
        raise InputError("R", "no radius given", "a finite number > 0 (mm)")
    if p is None:
        raise InputError("p", "no probability given", "0 < p < 1")
    p = check_probability(p, "p")
    distribution = distribution or "uniform"
    mc = monte_carlo(mechanism, pose, tol, distribution, R=R, n=n, seed=seed, batch=batch,
                     confidence=confidence, progress=progress)
    return ValidationResult(
        p=p,
        R=mc.R,
        distribution=distribution,
        pose=pose,
        tolerances=mc.tolerances,
        p_components=mc.p_components,
        p_components_ci=mc.p_components_ci,
        p_components_analytic=mc.p_components_analytic,
        components_met=mc.p_components >= p,
        components_short=mc.p_components_ci[:, 1] < p,
        p_sphere=mc.p_sphere,
        p_sphere_ci=mc.p_sphere_ci,
        p_sphere_analytic=mc.p_sphere_analytic,
        sphere_met=bool(mc.p_sphere >= p),
        n=mc.n,
        seed=mc.seed,
        montecarlo=mc,
    )


# =============================================================================================
# command line
# =============================================================================================
def _cmd_montecarlo(args) -> int:
    from .cli import emit_json, parse_pose, parse_tolerances
    from .mechanism import load_model

    mech = load_model(args.model)
    q = parse_pose(mech, args.pose)
    eps = parse_tolerances(mech, args.tolerances)
    progress = False if args.quiet else None  # None: a bar on stderr for long runs on a terminal
    r = monte_carlo(mech, q, eps, args.dist, R=args.R, n=args.n, seed=args.seed, batch=args.batch,
                    Phi=args.Phi, progress=progress, confidence=args.confidence)
    if args.json:
        out = r.to_dict()
        out["pose"] = args.pose
        emit_json(out)
    else:
        print(r.report())
    return 0


def register(sub) -> None:
    """Add ``tolsynth montecarlo`` to the sub-command parser."""
    from .cli import add_pose_arguments

    p = sub.add_parser("montecarlo", help="Monte Carlo through the nonlinear kinematics vs the analytic model")
    add_pose_arguments(p)
    p.add_argument("--n", type=int, default=1_000_000, help="number of samples")
    p.add_argument("--seed", type=int, default=0, help="seed of the random generator (recorded)")
    p.add_argument("--batch", type=int, default=DEFAULT_BATCH, help="samples per batch (memory ~ batch, not n)")
    p.add_argument("--confidence", type=float, default=0.95, help="level of the intervals")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_montecarlo)
