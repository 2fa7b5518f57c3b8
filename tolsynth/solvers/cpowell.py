"""Powell's method compiled together with a CasADi graph: SUMT's inner minimisation without Python
in the loop.

The interior penalty of :mod:`tolsynth.solvers.sumt` is a small CasADi graph (about 600
instructions for the paper's robot); one evaluation through CasADi's Python interface costs some
30 us of call overhead, and a SUMT solve takes some 60,000 of them.  Here the *same graph* is
written out as C by CasADi's code generator and compiled, with the C port of
:func:`tolsynth.solvers.powell.powell` below, into one shared library: a whole Powell
minimisation is one call.  The algorithm is the Python one step for step (same bracketing, same
Brent line search, same direction-replacement rule, same stopping tests), so both give the same
iterates up to rounding; the Python one stays as the fallback where no C compiler is found.

The library is built and cached on disk by :mod:`tolsynth.cbuild` (keyed by a hash of the
generated code, this file's C source, the compiler and its flags).  The first use of a graph
compiles it (about 0.2 s with gcc); later uses, in this process or another, only load it.
``TOLSYNTH_NO_COMPILE=1`` turns compilation off (the Python path is then used); ``TOLSYNTH_CC``
(or ``CC``) names the compiler.
"""

from __future__ import annotations

import ctypes
import math
from pathlib import Path

import casadi as ca
import numpy as np

from tolsynth.cbuild import GraphLibraries, cache_dir

__all__ = ["CompiledPowell", "compile_powell", "backend_status", "cache_dir"]

#: graphs larger than this stay on the Python path: their first compilation takes longer than a
#: Python solve (about 0.2 ms per instruction with gcc -O2: 0.7 s for 10 poses, 3,440 instructions;
#: 2.1 s for 30 poses; 5 s for the sphere criterion's quadrature, 39,000), and CasADi's per-call
#: overhead is then a smaller part of an evaluation
MAX_INSTRUCTIONS = 5_000
#: Powell's per-iteration history keeps the first this many iterations (maxiter may be 1e9)
HISTORY_MAX = 100_000

# The C port of tolsynth.solvers.powell (keep the two in step).  TS_F / TS_F_WORK are the
# CasADi-generated function and its work-size query; argument 0 of TS_F is the point.
C_SOURCE = r"""
#define TS_GOLD 1.618033988749895
#define TS_CGOLD 0.3819660112501051

typedef struct {
  const casadi_real **arg;
  casadi_real **res;
  casadi_int *iw;
  casadi_real *w;
  casadi_real out;
  long nfev;
  int n;
  const double *x;   /* line: base point */
  const double *dn;  /* line: unit direction */
  double *xt;        /* line: trial point */
} ts_ctx;

static double ts_f(ts_ctx *c, const double *x) {
  c->nfev++;
  c->arg[0] = x;
  c->res[0] = &c->out;
  c->res[1] = 0;
  if (TS_F(c->arg, c->res, c->iw, c->w, 0)) return NAN;
  return c->out;
}

static double ts_phi(ts_ctx *c, double t) {
  int i;
  for (i = 0; i < c->n; i++) c->xt[i] = c->x[i] + t * c->dn[i];
  return ts_f(c, c->xt);
}

/* a < b < c (or c < b < a) with fb <= min(fa, fc); out = a, b, c, fa, fb, fc */
static void ts_bracket(ts_ctx *cx, double f0, double h, double *out) {
  double a = 0.0, fa = f0, b = h, fb = ts_phi(cx, h), c, fc;
  int k;
  if (!(fb < fa)) {
    c = -h; fc = ts_phi(cx, -h);
    if (!(fc < fa)) {
      out[0] = -h; out[1] = 0.0; out[2] = h; out[3] = fc; out[4] = f0; out[5] = fb;
      return;
    }
    b = c; fb = fc;
  }
  c = b; fc = fb;
  for (k = 0; k < 200; k++) {
    c = b + TS_GOLD * (b - a);
    fc = ts_phi(cx, c);
    if (fc >= fb) break;
    a = b; fa = fb; b = c; fb = fc;
  }
  out[0] = a; out[1] = b; out[2] = c; out[3] = fa; out[4] = fb; out[5] = fc;
}

static void ts_brent(ts_ctx *cx, double a, double b, double c, double fb, double rtol,
                     double atol, int maxiter, double *xo, double *fo) {
  double lo = a < c ? a : c, hi = a < c ? c : a;
  double x = b, w = b, v = b, fx = fb, fw = fb, fv = fb, d = 0.0, e = 0.0;
  double xm, tol1, tol2, r, q, p, etemp, u, fu;
  int it, use_golden;
  for (it = 0; it < maxiter; it++) {
    xm = 0.5 * (lo + hi);
    tol1 = rtol * fabs(x) + atol;
    tol2 = 2.0 * tol1;
    if (fabs(x - xm) <= tol2 - 0.5 * (hi - lo)) break;
    use_golden = 1;
    if (fabs(e) > tol1 && isfinite(fw) && isfinite(fv)) {
      r = (x - w) * (fx - fv);
      q = (x - v) * (fx - fw);
      p = (x - v) * q - (x - w) * r;
      q = 2.0 * (q - r);
      if (q > 0.0) p = -p;
      q = fabs(q);
      etemp = e;
      e = d;
      if (!(fabs(p) >= fabs(0.5 * q * etemp) || p <= q * (lo - x) || p >= q * (hi - x))) {
        d = p / q;
        u = x + d;
        if (u - lo < tol2 || hi - u < tol2) d = (xm - x >= 0) ? tol1 : -tol1;
        use_golden = 0;
      }
    }
    if (use_golden) {
      e = (x >= xm) ? (lo - x) : (hi - x);
      d = TS_CGOLD * e;
    }
    u = x + (fabs(d) >= tol1 ? d : (d >= 0 ? tol1 : -tol1));
    fu = ts_phi(cx, u);
    if (fu <= fx) {
      if (u >= x) lo = x; else hi = x;
      v = w; w = x; x = u;
      fv = fw; fw = fx; fx = fu;
    } else {
      if (u < x) lo = u; else hi = u;
      if (fu <= fw || w == x) {
        v = w; w = u; fv = fw; fw = fu;
      } else if (fu <= fv || v == x || v == w) {
        v = u; fv = fu;
      }
    }
  }
  *xo = x; *fo = fx;
}

static double ts_norm(const double *d, int n) {
  double s = 0.0;
  int i;
  for (i = 0; i < n; i++) s += d[i] * d[i];
  return sqrt(s);
}

/* line minimisation from x (value *fx) along d with first step h: x, *fx updated; returns t */
static double ts_linemin(ts_ctx *cx, double *x, double *fx, const double *d, double h,
                         double line_rtol, double *dn, double *base) {
  int i, n = cx->n;
  double scale = ts_norm(d, n), br[6], t, ft;
  if (scale == 0.0) return 0.0;
  for (i = 0; i < n; i++) { dn[i] = d[i] / scale; base[i] = x[i]; }
  cx->x = base; cx->dn = dn;
  ts_bracket(cx, *fx, h, br);
  ts_brent(cx, br[0], br[1], br[2], br[4], line_rtol, 1e-14, 200, &t, &ft);
  if (ft < *fx) {
    for (i = 0; i < n; i++) x[i] = base[i] + t * dn[i];
    *fx = ft;
    return t;
  }
  return 0.0;
}

/* out = [F's first output, F's second output] at x (one evaluation, for the caller's checks) */
CASADI_SYMBOL_EXPORT int tolsynth_eval(const casadi_real **params, const double *x, double *out) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  const casadi_real **arg;
  casadi_real **res, *w;
  casadi_int *iw;
  int i, flag = 4;
  TS_F_WORK(&sz_arg, &sz_res, &sz_iw, &sz_w);
  arg = (const casadi_real **)calloc(sz_arg > TS_N_IN ? sz_arg : TS_N_IN, sizeof(casadi_real *));
  res = (casadi_real **)calloc(sz_res > 2 ? sz_res : 2, sizeof(casadi_real *));
  iw = (casadi_int *)calloc(sz_iw + 1, sizeof(casadi_int));
  w = (casadi_real *)calloc(sz_w + 1, sizeof(casadi_real));
  if (arg && res && iw && w) {
    for (i = 1; i < TS_N_IN; i++) arg[i] = params[i];
    arg[0] = x;
    res[0] = out;
    res[1] = out + 1;
    flag = TS_F(arg, res, iw, w, 0);
  }
  free(arg); free(res); free(iw); free(w);
  return flag;
}

/* info: [fx, nit, nfev, status] with status 0 converged, 1 maxfev, 2 maxiter, 3 start outside
   the domain, 4 out of memory; history[0..min(nit, hist_len - 1)] = f at the start and after
   each iteration (the first hist_len values) */
CASADI_SYMBOL_EXPORT int tolsynth_powell(const casadi_real **params, double *x, double *D, int n,
                                         double step, double ftol, double line_rtol, long maxiter,
                                         long maxfev, double *info, double *history,
                                         long hist_len) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  ts_ctx cx;
  double *steps, *xs, *dnew, *dn, *base, *xt, fx, f_start, f_prev, big, fe, tt, t, nrm;
  long it, k;
  int i, ibig, status = 2;
  TS_F_WORK(&sz_arg, &sz_res, &sz_iw, &sz_w);
  if (sz_arg < TS_N_IN) sz_arg = TS_N_IN;
  if (sz_res < 2) sz_res = 2;
  cx.arg = (const casadi_real **)calloc(sz_arg, sizeof(casadi_real *));
  cx.res = (casadi_real **)calloc(sz_res, sizeof(casadi_real *));
  cx.iw = (casadi_int *)calloc(sz_iw + 1, sizeof(casadi_int));
  cx.w = (casadi_real *)calloc(sz_w + 1, sizeof(casadi_real));
  steps = (double *)calloc(6 * (size_t)n + 1, sizeof(double));
  if (!cx.arg || !cx.res || !cx.iw || !cx.w || !steps) {
    free(cx.arg); free(cx.res); free(cx.iw); free(cx.w); free(steps);
    info[3] = 4;
    return 4;
  }
  xs = steps + n + 1; dnew = xs + n; dn = dnew + n; base = dn + n; xt = base + n;
  for (i = 1; i < TS_N_IN; i++) cx.arg[i] = params[i];
  cx.nfev = 0; cx.n = n; cx.xt = xt;
  fx = ts_f(&cx, x);
  history[0] = fx;
  it = 0;
  if (!isfinite(fx)) {
    status = 3;
    goto done;
  }
  for (i = 0; i <= n; i++) steps[i] = step;
  for (it = 1; it <= maxiter; it++) {
    f_start = fx;
    memcpy(xs, x, n * sizeof(double));
    big = 0.0; ibig = 0;
    for (i = 0; i < n; i++) {
      f_prev = fx;
      t = ts_linemin(&cx, x, &fx, D + (size_t)i * n, steps[i], line_rtol, dn, base);
      if (t != 0.0) steps[i] = fabs(t) > 1e-8 ? fabs(t) : 1e-8;
      if (f_prev - fx > big) { big = f_prev - fx; ibig = i; }
    }
    if (it < hist_len) history[it] = fx;
    if (2.0 * (f_start - fx) <= ftol * (fabs(f_start) + fabs(fx)) + 1e-300) { status = 0; goto done; }
    if (cx.nfev >= maxfev) { status = 1; goto done; }
    for (i = 0; i < n; i++) { dnew[i] = x[i] - xs[i]; xt[i] = x[i] + dnew[i]; }
    fe = ts_f(&cx, xt);
    if (fe < f_start) {
      tt = 2.0 * (f_start - 2.0 * fx + fe) * (f_start - fx - big) * (f_start - fx - big)
           - big * (f_start - fe) * (f_start - fe);
      if (tt < 0.0) {
        nrm = ts_norm(dnew, n);
        ts_linemin(&cx, x, &fx, dnew, nrm > 1e-8 ? nrm : 1e-8, line_rtol, dn, base);
        for (k = 0; k < n; k++) D[(size_t)ibig * n + k] = D[(size_t)(n - 1) * n + k];
        nrm = nrm > 1e-300 ? nrm : 1e-300;
        for (k = 0; k < n; k++) D[(size_t)(n - 1) * n + k] = dnew[k] / nrm;
      }
    }
  }
  it = maxiter;
done:
  info[0] = fx; info[1] = (double)it; info[2] = (double)cx.nfev; info[3] = (double)status;
  free(cx.arg); free(cx.res); free(cx.iw); free(cx.w); free(steps);
  return status;
}
"""

_MESSAGES = {
    0: "converged: a sweep no longer lowers f",
    1: "stopped: {nfev} evaluations (maxfev)",
    2: "stopped: {nit} iterations (maxiter)",
    3: "start point outside the domain (f is not finite)",
    4: "out of memory",
}


def backend_status() -> dict:
    """How the last :func:`compile_powell` went: ``backend`` ("compiled", "python" or "not
    tried") and, for "python", the reason (no compiler, compilation failed, turned off)."""
    return dict(_LIBS.status)


class CompiledPowell:
    """Powell's method on a compiled CasADi function ``F(x, p1, p2, ...) -> (f, g, ...)``.

    :meth:`minimize` takes the values of ``p1, p2, ...`` (NumPy arrays, dense; they are read at
    each call, so an array changed in place between calls is seen) and runs the whole
    minimisation of F's first output in C; its result has the fields of
    :class:`tolsynth.solvers.powell.PowellResult`.  :meth:`evaluate` returns F's first two outputs
    at one point.
    """

    def __init__(self, lib: ctypes.CDLL, n_in: int, path: Path):
        self.path = path
        self.n_in = n_in
        dp = ctypes.POINTER(ctypes.c_double)
        self._fn = lib.tolsynth_powell
        self._fn.restype = ctypes.c_int
        self._fn.argtypes = [
            ctypes.c_void_p,
            dp,
            dp,
            ctypes.c_int,
            ctypes.c_double,
            ctypes.c_double,
            ctypes.c_double,
            ctypes.c_long,
            ctypes.c_long,
            dp,
            dp,
            ctypes.c_long,
        ]
        self._eval = lib.tolsynth_eval
        self._eval.restype = ctypes.c_int
        self._eval.argtypes = [ctypes.c_void_p, dp, dp]
        self._lib = lib  # keep it loaded

    def _pointers(self, params):
        keep = [np.ascontiguousarray(p, dtype=float).ravel() for p in params]
        if len(keep) != self.n_in - 1:
            raise ValueError(f"expected {self.n_in - 1} parameter arrays, got {len(keep)}")
        ptrs = (ctypes.c_void_p * self.n_in)()
        for i, p in enumerate(keep, start=1):
            ptrs[i] = p.ctypes.data if p.size else None
        return ptrs, keep

    def evaluate(self, params, x) -> tuple[float, float]:
        ptrs, _keep = self._pointers(params)
        x = np.ascontiguousarray(x, dtype=float)
        out = np.zeros(2)
        dp = ctypes.POINTER(ctypes.c_double)
        if self._eval(ptrs, x.ctypes.data_as(dp), out.ctypes.data_as(dp)) != 0:
            return math.nan, math.nan
        return float(out[0]), float(out[1])

    def minimize(
        self, params, x0, *, directions=None, step=0.1, ftol=1e-13, line_rtol=1e-9, maxiter=5000, maxfev=2_000_000
    ):
        from tolsynth.solvers.powell import PowellResult

        x = np.array(x0, dtype=float)  # a fresh contiguous copy: the C code writes into it
        n = x.size
        D = np.eye(n) if directions is None else np.array(directions, dtype=float, order="C")
        ptrs, _keep = self._pointers(params)
        info = np.zeros(4)
        history = np.zeros(min(int(maxiter), HISTORY_MAX) + 1)  # maxiter may be huge
        dp = ctypes.POINTER(ctypes.c_double)
        self._fn(
            ptrs,
            x.ctypes.data_as(dp),
            D.ctypes.data_as(dp),
            n,
            float(step),
            float(ftol),
            float(line_rtol),
            int(maxiter),
            int(maxfev),
            info.ctypes.data_as(dp),
            history.ctypes.data_as(dp),
            history.size,
        )
        fx, nit, nfev, status = float(info[0]), int(info[1]), int(info[2]), int(info[3])
        message = _MESSAGES[status].format(nfev=nfev, nit=nit)
        hist = history[: min(nit, history.size - 1) + 1].tolist() if status != 3 else [fx]
        return PowellResult(x, fx, nit, nfev, status == 0, message, D, hist)


def compile_powell(F: ca.Function) -> CompiledPowell | None:
    """The compiled Powell minimiser of ``F``'s first output over its first input, or None (then
    use the Python :func:`tolsynth.solvers.powell.powell`; :func:`backend_status` says why)."""
    return _LIBS.get(F, lambda lib, path: CompiledPowell(lib, F.n_in(), path))


_LIBS = GraphLibraries(
    "powell",
    C_SOURCE,
    ("tolsynth_powell", "tolsynth_eval"),
    "python",
    MAX_INSTRUCTIONS,
    lambda F: {"TS_N_IN": F.n_in()},
)
