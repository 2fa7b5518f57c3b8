"""The map's Levenberg-Marquardt inverse kinematics compiled together with the model's IK graph.

:func:`tolsynth.kinematics.ik._solve_ik` runs a batched Levenberg-Marquardt iteration in NumPy: every
operation of the residual graph and of the iteration is one NumPy pass over the running columns.
For a 100 x 100 map that is some 1.4 million column-iterations, most of them on grid points that
no joint vector within the limits reaches (every seed has to fail there).  Here the *same graph*
(residual and Jacobian, :func:`tolsynth.kinematics.ik._ik_evaluator`) is written out as C by CasADi's code
generator and compiled, with the C port of the iteration below, into one shared library (built
and cached by :mod:`tolsynth.cbuild`): one call solves every column, each column in registers
and L1 cache from start to end.

The iteration is the NumPy one step for step -- the same damping (``mu (diag(J^T J) + 1e-9)``,
from ``1e-3``, divided by 3 on an accepted step down to ``1e-12``, times 4 on a rejected one),
the same Cholesky solve with the least-squares fallback where it breaks down (the minimum-norm
solution with NumPy's ``lstsq`` cut-off, from a Jacobi eigendecomposition), and the same stopping
tests -- so both give the same iterates up to rounding.  The NumPy path stays where no C compiler
is found or ``TOLSYNTH_NO_COMPILE`` is set.  Units: those of the graph (mm and rad).
"""

from __future__ import annotations

import ctypes
import os
from concurrent.futures import ThreadPoolExecutor

import casadi as ca
import numpy as np

from tolsynth.cbuild import GraphLibraries

__all__ = ["CompiledLM", "compile_lm", "backend_status"]

#: graphs larger than this stay on the NumPy path (compilation time grows with the graph: about
#: 0.2 ms per instruction with gcc -O2; the bundled models' IK graphs have 300-800)
MAX_INSTRUCTIONS = 20_000

# The C port of tolsynth.kinematics.ik._solve_ik (keep the two in step).  TS_F / TS_F_WORK are the
# CasADi-generated residual function ik_residual(q, target, axis) -> (r, J) and its work sizes.
C_SOURCE = r"""
typedef struct {
  const casadi_real **arg;
  casadi_real **res;
  casadi_int *iw;
  casadi_real *w;
} ts_ws;

/* r, J at q (target t, axis a); returns r.r, +inf if not finite or the evaluation failed */
static double ts_eval(ts_ws *ws, const double *q, const double *t, const double *a, double *r,
                      double *J, int nr) {
  double c = 0.0;
  int i;
  ws->arg[0] = q; ws->arg[1] = t; ws->arg[2] = a;
  ws->res[0] = r; ws->res[1] = J;
  if (TS_F(ws->arg, ws->res, ws->iw, ws->w, 0)) return INFINITY;
  for (i = 0; i < nr; i++) c += r[i] * r[i];
  return isfinite(c) ? c : INFINITY;
}

/* minimum-norm least-squares solution of the symmetric system A x = b (n x n, row-major), as
   numpy.linalg.lstsq with rcond=None: singular values below n * eps * the largest are dropped.
   Cyclic Jacobi eigendecomposition (singular values of a symmetric matrix = |eigenvalues|). */
static void ts_sym_lstsq(int n, const double *A, const double *b, double *x, double *M, double *V) {
  int i, j, k, p, q, sweep;
  double off, lmax, cut;
  memcpy(M, A, (size_t)n * n * sizeof(double));
  for (i = 0; i < n * n; i++) V[i] = 0.0;
  for (i = 0; i < n; i++) V[i * n + i] = 1.0;
  for (sweep = 0; sweep < 100; sweep++) {
    off = 0.0;
    for (p = 0; p < n; p++) for (q = p + 1; q < n; q++) off += M[p * n + q] * M[p * n + q];
    if (!(off > 1e-300)) break;
    for (p = 0; p < n; p++) {
      for (q = p + 1; q < n; q++) {
        double apq = M[p * n + q], app, aqq, theta, tt, c, s;
        if (apq == 0.0) continue;
        app = M[p * n + p]; aqq = M[q * n + q];
        theta = (aqq - app) / (2.0 * apq);
        tt = (theta >= 0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
        c = 1.0 / sqrt(tt * tt + 1.0); s = tt * c;
        for (k = 0; k < n; k++) {  /* M = G^T M G */
          double mkp = M[k * n + p], mkq = M[k * n + q];
          M[k * n + p] = c * mkp - s * mkq; M[k * n + q] = s * mkp + c * mkq;
        }
        for (k = 0; k < n; k++) {
          double mpk = M[p * n + k], mqk = M[q * n + k];
          M[p * n + k] = c * mpk - s * mqk; M[q * n + k] = s * mpk + c * mqk;
        }
        for (k = 0; k < n; k++) {
          double vkp = V[k * n + p], vkq = V[k * n + q];
          V[k * n + p] = c * vkp - s * vkq; V[k * n + q] = s * vkp + c * vkq;
        }
      }
    }
  }
  lmax = 0.0;
  for (j = 0; j < n; j++) if (fabs(M[j * n + j]) > lmax) lmax = fabs(M[j * n + j]);
  cut = n * DBL_EPSILON * lmax;
  for (i = 0; i < n; i++) x[i] = 0.0;
  for (j = 0; j < n; j++) {
    double lam = M[j * n + j], vb = 0.0;
    if (!(fabs(lam) > cut)) continue;
    for (i = 0; i < n; i++) vb += V[i * n + j] * b[i];
    for (i = 0; i < n; i++) x[i] += V[i * n + j] * vb / lam;
  }
}

/* the least-squares fallback alone, for the tests (A n x n row-major, n <= 16) */
CASADI_SYMBOL_EXPORT void tolsynth_sym_lstsq(int n, const double *A, const double *b, double *x) {
  double M[256], V[256];
  if (n > 16) return;
  ts_sym_lstsq(n, A, b, x, M, V);
}

/* Levenberg-Marquardt on each column of Q (N x nq, row-major: column b of the joints is row b),
   targets T (N x 3), the hand axis a (3); free: the nf joints moved.  Q is overwritten with the
   result, conv[b] = 1 where the residual norm^2 is <= tol^2.  Returns 0, or 4 out of memory. */
CASADI_SYMBOL_EXPORT int tolsynth_lm(double *Q, const double *T, const double *a, long N, int nq,
                                     const int *free_idx, int nf, int nr, double tol, int max_iter,
                                     unsigned char *conv) {
  casadi_int sz_arg, sz_res, sz_iw, sz_w;
  ts_ws ws;
  double *buf, *qn, *r, *rn, *J, *Jn, *A, *g, *L, *y, *step, *M, *V, *nb, *tmp;
  double tol2 = tol * tol;
  long b;
  TS_F_WORK(&sz_arg, &sz_res, &sz_iw, &sz_w);
  ws.arg = (const casadi_real **)calloc(sz_arg > 3 ? sz_arg : 3, sizeof(casadi_real *));
  ws.res = (casadi_real **)calloc(sz_res > 2 ? sz_res : 2, sizeof(casadi_real *));
  ws.iw = (casadi_int *)calloc(sz_iw + 1, sizeof(casadi_int));
  ws.w = (casadi_real *)calloc(sz_w + 1, sizeof(casadi_real));
  buf = (double *)calloc((size_t)nq + 2 * (size_t)nr + 2 * (size_t)nr * nf + 4 * (size_t)nf * nf
                         + 4 * (size_t)nf + 1, sizeof(double));
  if (!ws.arg || !ws.res || !ws.iw || !ws.w || !buf) {
    free(ws.arg); free(ws.res); free(ws.iw); free(ws.w); free(buf);
    return 4;
  }
  qn = buf; r = qn + nq; rn = r + nr; J = rn + nr; Jn = J + (size_t)nr * nf;
  A = Jn + (size_t)nr * nf; L = A + (size_t)nf * nf; M = L + (size_t)nf * nf; V = M + (size_t)nf * nf;
  g = V + (size_t)nf * nf; y = g + nf; step = y + nf; nb = step + nf;
  for (b = 0; b < N; b++) {
    double *q = Q + (size_t)b * nq;
    const double *t = T + (size_t)b * 3;
    double cw, mu = 1e-3;
    int it, k, l, i;
    conv[b] = 0;
    cw = ts_eval(&ws, q, t, a, r, J, nr);
    if (cw <= tol2) { conv[b] = 1; continue; }
    if (!isfinite(cw)) continue;  /* never moves */
    for (it = 0; it < max_iter; it++) {
      double trace = 0.0, cn, big = 0.0;
      int moving, ok = 1, acc, small_gain, step_nan = 0, keep;
      /* A = J^T J, g = J^T r (J column-major: J[k * nr + i] = d r_i / d q_free[k]) */
      for (k = 0; k < nf; k++) {
        double s = 0.0;
        for (i = 0; i < nr; i++) s += J[(size_t)k * nr + i] * r[i];
        g[k] = s;
        for (l = 0; l <= k; l++) {
          double s2 = 0.0;
          for (i = 0; i < nr; i++) s2 += J[(size_t)k * nr + i] * J[(size_t)l * nr + i];
          A[k * nf + l] = A[l * nf + k] = s2;
        }
      }
      for (k = 0; k < nf; k++) trace += A[k * nf + k];
      moving = isfinite(trace);
      for (k = 0; k < nf; k++) A[k * nf + k] += mu * (A[k * nf + k] + 1e-9);
      /* Cholesky A = L L^T, then L y = -g, L^T step = y */
      for (k = 0; k < nf; k++) nb[k] = -g[k];
      for (l = 0; l < nf; l++) {
        double d = A[l * nf + l];
        for (k = 0; k < l; k++) d -= L[l * nf + k] * L[l * nf + k];
        if (!(d > 0)) { ok = 0; d = 1.0; }
        L[l * nf + l] = sqrt(d);
        for (i = l + 1; i < nf; i++) {
          double s = A[i * nf + l];
          for (k = 0; k < l; k++) s -= L[i * nf + k] * L[l * nf + k];
          L[i * nf + l] = s / L[l * nf + l];
        }
      }
      for (i = 0; i < nf; i++) {
        double s = nb[i];
        for (k = 0; k < i; k++) s -= L[i * nf + k] * y[k];
        y[i] = s / L[i * nf + i];
      }
      for (i = nf - 1; i >= 0; i--) {
        double s = y[i];
        for (k = i + 1; k < nf; k++) s -= L[k * nf + i] * step[k];
        step[i] = s / L[i * nf + i];
      }
      for (k = 0; k < nf; k++) if (!isfinite(step[k])) ok = 0;
      if (!ok && moving) ts_sym_lstsq(nf, A, nb, step, M, V);  /* breakdown: least squares */
      memcpy(qn, q, (size_t)nq * sizeof(double));
      for (k = 0; k < nf; k++) qn[free_idx[k]] += step[k];
      cn = ts_eval(&ws, qn, t, a, rn, Jn, nr);
      acc = moving && isfinite(cn) && cn < cw;
      if (acc) {
        memcpy(q, qn, (size_t)nq * sizeof(double));
        tmp = r; r = rn; rn = tmp;
        tmp = J; J = Jn; Jn = tmp;
      }
      small_gain = acc && (cw - cn <= 1e-14 * cw);
      if (acc) cw = cn;
      mu = acc ? (mu / 3.0 > 1e-12 ? mu / 3.0 : 1e-12) : mu * 4.0;
      for (k = 0; k < nf; k++) {
        if (isnan(step[k])) step_nan = 1;
        else if (fabs(step[k]) > big) big = fabs(step[k]);
      }
      keep = moving && cw > tol2 && !(mu > 1e8 || small_gain || (!step_nan && big < 1e-13));
      if (!keep) { conv[b] = cw <= tol2; break; }
    }
  }
  free(ws.arg); free(ws.res); free(ws.iw); free(ws.w); free(buf);
  return 0;
}
"""

#: batches of at least this many columns are split over threads (the columns are independent)
PARALLEL_MIN = 2048
#: threads for large batches; None: the CPUs this process may run on, at most 8
THREADS: int | None = None
_pools: dict[tuple[int, int], ThreadPoolExecutor] = {}  # (pid, threads): a forked child makes its own


def _workers() -> int:
    if THREADS is not None:
        return max(1, int(THREADS))
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        n = os.cpu_count() or 1
    return max(1, min(n, 8))


def _pool(workers: int) -> ThreadPoolExecutor:
    key = (os.getpid(), workers)
    if key not in _pools:
        _pools[key] = ThreadPoolExecutor(workers, thread_name_prefix="tolsynth-ik")
    return _pools[key]


def backend_status() -> dict:
    """How the last :func:`compile_lm` went: ``backend`` ("compiled", "numpy" or "not tried") and,
    for "numpy", the reason (no compiler, compilation failed, turned off, graph too large)."""
    return dict(_LIBS.status)


class CompiledLM:
    """The compiled iteration for one IK graph ``F(q, target, axis) -> (r, J)``."""

    def __init__(self, lib: ctypes.CDLL, F: ca.Function):
        self.nq = F.nnz_in(0)
        self.nr = F.nnz_out(0)
        self.nf = F.size2_out(1)
        self._fn = lib.tolsynth_lm
        self._fn.restype = ctypes.c_int
        self._fn.argtypes = [
            ctypes.c_void_p,
            ctypes.c_void_p,
            ctypes.c_void_p,
            ctypes.c_long,
            ctypes.c_int,
            ctypes.c_void_p,
            ctypes.c_int,
            ctypes.c_int,
            ctypes.c_double,
            ctypes.c_int,
            ctypes.c_void_p,
        ]
        self._lstsq = lib.tolsynth_sym_lstsq
        self._lstsq.restype = None
        self._lstsq.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        self._lib = lib  # keep it loaded

    def sym_lstsq(self, A: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The iteration's least-squares fallback on its own: the minimum-norm solution of the
        symmetric system ``A x = b`` (n <= 16), as ``numpy.linalg.lstsq(A, b, rcond=None)``."""
        A = np.ascontiguousarray(A, dtype=float)
        b = np.ascontiguousarray(b, dtype=float)
        n = b.size
        if A.shape != (n, n) or n > 16:
            raise ValueError(f"expected a square A of size n <= 16 matching b, got {A.shape} and {b.shape}")
        x = np.zeros(n)
        self._lstsq(n, A.ctypes.data, b.ctypes.data, x.ctypes.data)
        return x

    def solve(
        self, free, Q0: np.ndarray, targets: np.ndarray, axis: np.ndarray, tol: float, max_iter: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """Joints (nq, N) and the converged flag (N,), as :func:`tolsynth.kinematics.ik._solve_ik`."""
        N = Q0.shape[1]
        Qt = np.array(Q0.T, dtype=float, order="C")  # row b = column b of the joints; written to
        Tt = np.ascontiguousarray(np.broadcast_to(np.asarray(targets, float), (3, N)).T)
        ax = np.ascontiguousarray(axis, dtype=float)
        fr = np.ascontiguousarray(free, dtype=np.intc)
        if fr.size != self.nf:
            raise ValueError(f"expected {self.nf} free joints, got {fr.size}")
        conv = np.zeros(N, np.uint8)
        ptr = ctypes.c_void_p

        def run(lo: int, hi: int) -> int:  # columns lo..hi-1 (ctypes releases the GIL during the call)
            return self._fn(
                ptr(Qt.ctypes.data + lo * Qt.strides[0]),
                ptr(Tt.ctypes.data + lo * Tt.strides[0]),
                ax.ctypes.data,
                hi - lo,
                self.nq,
                fr.ctypes.data,
                self.nf,
                self.nr,
                float(tol),
                int(max_iter),
                ptr(conv.ctypes.data + lo),
            )

        workers = _workers()
        if workers > 1 and N >= PARALLEL_MIN:
            # chunks several per thread: columns out of reach take many more iterations than
            # the others and cluster, so equal halves would leave a thread idle
            edges = np.linspace(0, N, 4 * workers + 1).astype(int)
            flags = list(_pool(workers).map(run, edges[:-1].tolist(), edges[1:].tolist()))
        else:
            flags = [run(0, N)]
        if any(flags):
            raise MemoryError("the compiled inverse kinematics ran out of memory")
        return Qt.T.copy(), conv.astype(bool)


def compile_lm(F: ca.Function) -> CompiledLM | None:
    """The compiled iteration for the IK graph ``F``, or None (then use the NumPy path;
    :func:`backend_status` says why)."""
    return _LIBS.get(F, lambda lib, path: CompiledLM(lib, F))


_LIBS = GraphLibraries("ik", C_SOURCE, ("tolsynth_lm", "tolsynth_sym_lstsq"), "numpy", MAX_INSTRUCTIONS)
