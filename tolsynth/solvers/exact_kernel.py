"""The exact series of :mod:`.exact_series` compiled from C: its sums and its truncation bounds.

An exact solve evaluates the series a few hundred times, each time on a few rows of a dozen
terms and a few dozen to a few thousand series terms.  In NumPy each evaluation is some fifty
array operations on small arrays, whose per-call overhead is most of the time; here one call does
every row, each row in registers:

* :func:`series`: ``P``, and its gradient and Hessian in ``u`` (or P alone), the same sums as
  ``_series_block`` / ``_products`` of :mod:`.exact_series` (term by term: the weight
  ``(2/(k pi)) sin(k pi R / L)``, or the sphere's, times the product of the characteristic
  functions; the gradient's and Hessian's products without one or two factors built from prefix,
  running and suffix products, so no factor is ever divided out).  Zero coefficients are factors
  1 and are skipped.  The uniform, normal and triangular characteristic functions are evaluated
  in C (their closed forms, ``sin`` and ``cos`` called directly: no recurrence whose rounding
  drifts with k), and the truncated normal's from the interpolants of
  :func:`tolsynth.probability.truncnormal.cf3` (:func:`~tolsynth.probability.truncnormal.packed`),
  by the same formulas.
* :func:`terms` and :func:`tail`: the rigorous truncation bound of :meth:`.exact_series.Rows.tail`
  and the least power of two that meets a tolerance.

The NumPy code stays the reference: it runs where no C compiler is found (or with
``TOLSYNTH_NO_COMPILE=1``), and the tests check that both agree to rounding.  The library is
built and cached on disk by :mod:`tolsynth.cbuild`.
"""

from __future__ import annotations

import ctypes
import threading

import numpy as np

from tolsynth.cbuild import C_INCLUDES, disabled, find_compiler, load_library
from tolsynth.probability.truncnormal import packed as truncnormal_packed

__all__ = ["available", "series", "terms", "tail", "CODES"]

#: the kind codes of the C source's columns
CODES = {"uniform": 0, "normal": 1, "triangular": 2, "truncnormal": 3}

C_SOURCE = r"""
#define TS_PI 3.14159265358979323846
#define TS_MAXN 256

/* phi(t), and for order >= 1 D1 = t phi'(t), D2 = t dD1/dt, of the uniform (0), normal (1,
   3 sigma = 1) and triangular (2) shapes: the closed forms of the NumPy path */
static void ts_cf(int kind, double t, int order, double *phi, double *d1, double *d2) {
  if (kind == 0) {
    if (fabs(t) < 1e-4) {
      *phi = 1.0 - t*t/6.0;
      if (order) { *d1 = -t*t/3.0; *d2 = -2.0*t*t/3.0; }
    } else {
      double s = sin(t);
      *phi = s/t;
      if (order) { *d1 = cos(t) - *phi; *d2 = -t*s - *d1; }
    }
  } else if (kind == 1) {
    double a = t*t/9.0;
    *phi = exp(-t*t/18.0);
    if (order) { *d1 = -a * *phi; *d2 = (a*a - 2.0*a) * *phi; }
  } else {
    double h = 0.5*t, s, e, he;
    if (fabs(h) < 1e-4) { s = 1.0 - h*h/6.0; e = -h*h/3.0; he = -2.0*h*h/3.0; }
    else { double sn = sin(h); s = sn/h; e = cos(h) - s; he = -h*sn - e; }
    *phi = s*s;
    if (order) { *d1 = 2.0*s*e; *d2 = 2.0*e*e + 2.0*s*he; }
  }
}

/* One interpolant of a packed truncated normal (see truncnormal.packed): function f at z. */
static double ts_clenshaw(const double *blk, int f, double z) {
  double a = blk[0], h = blk[1], u = (z - a)/h, t, b1 = 0.0, b2 = 0.0, tmp;
  int pieces = (int)blk[2], deg = (int)blk[3], nf = (int)blk[4], k;
  long j;
  const double *c = blk + 5;
  double fl = floor(u);
  j = fl < 0 ? 0 : (fl > pieces - 1 ? pieces - 1 : (long)fl);
  t = 2.0*(u - (double)j) - 1.0;
  for (k = deg; k > 0; k--) {
    tmp = c[((long)k*nf + f)*pieces + j] + 2.0*t*b1 - b2;
    b2 = b1;
    b1 = tmp;
  }
  return c[(long)f*pieces + j] + t*b1 - b2;
}

/* phi, D1, D2 of the truncated normal from its packed interpolants: truncnormal.cf3's formulas */
static void ts_tn(const double *tb, double s, int order, double *phi, double *d1, double *d2) {
  double beta = tb[0], x = tb[1], cc = tb[2], split = tb[3];
  double y = fabs(s)/(beta*sqrt(2.0)), g = exp(-y*y), I, LI = 0.0, LLI = 0.0, y2 = y*y;
  if (y <= split) {
    double Is = ts_clenshaw(tb + (long)tb[4], 0, y);
    I = Is;
    if (order >= 1) {
      double th = 2.0*x*y, I1 = sin(th) - 2.0*y*Is;
      LI = y*I1;
      if (order >= 2) {
        double I2 = 2.0*x*cos(th) - 2.0*Is - 2.0*y*I1;
        LLI = y*I1 + y*y*I2;
      }
    }
  } else {
    const double *l0 = tb + (long)tb[5];
    double v = 1.0/y, C = ts_clenshaw(l0, 0, v), S = ts_clenshaw(l0, 1, v), th = 2.0*x*y;
    double sn = sin(th), cs = cos(th), P = sn*C - cs*S;
    I = 0.5*v*P;
    if (order >= 1) {
      const double *l1 = tb + (long)tb[6];
      double C1 = ts_clenshaw(l1, 0, v), S1 = ts_clenshaw(l1, 1, v);
      double Pt = cs*C + sn*S, Pv = sn*C1 - cs*S1, Q = -P + th*Pt - v*Pv;
      LI = 0.5*v*Q;
      if (order >= 2) {
        const double *l2 = tb + (long)tb[7];
        double C2 = ts_clenshaw(l2, 0, v), S2 = ts_clenshaw(l2, 1, v);
        double Ptv = cs*C1 + sn*S1, Pvv = sn*C2 - cs*S2;
        double LQ = 2.0*v*Pv - th*th*P - 2.0*th*v*Ptv + v*v*Pvv;
        LLI = 0.5*v*(-Q + LQ);
      }
    }
  }
  *phi = g + cc*I;
  if (order >= 1) *d1 = -2.0*y2*g + cc*LI;
  if (order >= 2) *d2 = (4.0*y2*y2 - 4.0*y2)*g + cc*LLI;
}

/* The series of every row r (b: m x n, row-major, coefficients >= 0): P[r], and for order >= 1
   G[r, :] (d/du), order 2 H[r, :, :].  K[r] terms; a truncated normal column j (kind 3) has its
   packed interpolants at tnt + tno[j].  ball: the sphere's kernel. */
int ts_series(int m, int n, const double *b, const double *R, const double *L, const long *K,
              const int *kind, const double *tnt, const long *tno, int order, int ball,
              double *P, double *G, double *H) {
  int r;
  if (n > TS_MAXN) return 1;
  for (r = 0; r < m; r++) {
    const double *br = b + (long)r*n;
    int nz = 0, col[TS_MAXN], a, c, j;
    double phi[TS_MAXN], d1[TS_MAXN], d2[TS_MAXN], pre[TS_MAXN + 1], suf[TS_MAXN + 1];
    double sumP = 0.0, g[TS_MAXN], h[TS_MAXN*TS_MAXN];
    long k, Kr = K[r];
    for (j = 0; j < n; j++)
      if (br[j] > 0) col[nz++] = j;
    for (a = 0; a < nz; a++) g[a] = 0.0;
    if (order > 1) for (a = 0; a < nz*nz; a++) h[a] = 0.0;
    for (k = 1; k <= Kr; k++) {
      double tau = TS_PI*(double)k/L[r], x = TS_PI*(double)k*(R[r]/L[r]), s;
      s = ball ? 2.0/((double)k*TS_PI)*(sin(x) - x*cos(x)) : 2.0/((double)k*TS_PI)*sin(x);
      for (a = 0; a < nz; a++) {
        j = col[a];
        if (kind[j] == 3) ts_tn(tnt + tno[j], tau*br[j], order, &phi[a], &d1[a], &d2[a]);
        else ts_cf(kind[j], tau*br[j], order, &phi[a], &d1[a], &d2[a]);
      }
      pre[0] = 1.0;
      for (a = 0; a < nz; a++) pre[a + 1] = pre[a]*phi[a];
      sumP += s*pre[nz];
      if (!order) continue;
      suf[nz] = 1.0;
      for (a = nz - 1; a >= 0; a--) suf[a] = suf[a + 1]*phi[a];
      for (a = 0; a < nz; a++) {
        double oth = pre[a]*suf[a + 1];
        g[a] += s*d1[a]*oth;
        if (order > 1) {
          double mid = 1.0, sa = s*d1[a]*pre[a];
          h[a*nz + a] += s*d2[a]*oth;
          for (c = a + 1; c < nz; c++) {
            h[a*nz + c] += sa*mid*suf[c + 1]*d1[c];
            mid *= phi[c];
          }
        }
      }
    }
    P[r] = (ball ? 0.0 : R[r]/L[r]) + sumP;
    if (order) {
      double *Gr = G + (long)r*n;
      for (j = 0; j < n; j++) Gr[j] = 0.0;
      for (a = 0; a < nz; a++) Gr[col[a]] = g[a];
    }
    if (order > 1) {
      double *Hr = H + (long)r*n*n;
      for (j = 0; j < n*n; j++) Hr[j] = 0.0;
      for (a = 0; a < nz; a++)
        for (c = a; c < nz; c++) {
          Hr[col[a]*n + col[c]] = h[a*nz + c];
          Hr[col[c]*n + col[a]] = h[a*nz + c];
        }
    }
  }
  return 0;
}

/* The truncation bound of Rows.tail for one row at K (see its docstring): power factors
   (fidx, fmult; nf of them), normal columns (normal[j] != 0), column drop left out (-1: none). */
static double ts_tail1(int n, const double *br, double L, double K, int nf, const long *fidx,
                       const double *fmult, const int *normal, int drop) {
  int f, j, q = 0;
  double logC = 0.0, a = 0.0, power = INFINITY, gauss = INFINITY;
  for (f = 0; f < nf; f++) {
    double bf = br[fidx[f]], c;
    if (fidx[f] == drop || !(bf > 0)) continue;
    c = fmult[f]*L/(TS_PI*(bf > 1e-300 ? bf : 1e-300));
    if (c < K) { q++; logC += log(c); }
  }
  for (j = 0; j < n; j++)
    if (normal[j] && j != drop) a += br[j]*br[j];
  a *= (TS_PI/L)*(TS_PI/L)/18.0;
  if (q > 0) power = (2.0/TS_PI)*exp(logC - q*log(K) - a*K*K)/q;
  if (a > 0) gauss = exp(-a*K*K)/(TS_PI*a*K*K);
  return power < gauss ? power : gauss;
}

/* out[r] = the tail bound of row r at K[r] (drop: a column left out, -1 none). */
void ts_tail(int m, int n, const double *b, const double *L, const double *K, int nf, const long *fidx,
             const double *fmult, const int *normal, int drop, double *out) {
  int r;
  for (r = 0; r < m; r++)
    out[r] = ts_tail1(n, b + (long)r*n, L[r], K[r], nf, fidx, fmult, normal, drop);
}

/* K[r] = the least of Ks (ascending, nk of them) whose tail bound is <= tol, else the last. */
void ts_terms(int m, int n, const double *b, const double *L, const double *Ks, int nk, double tol, int nf,
              const long *fidx, const double *fmult, const int *normal, long *K) {
  int r, i;
  for (r = 0; r < m; r++) {
    K[r] = (long)Ks[nk - 1];
    for (i = 0; i < nk; i++)
      if (ts_tail1(n, b + (long)r*n, L[r], Ks[i], nf, fidx, fmult, normal, -1) <= tol) {
        K[r] = (long)Ks[i];
        break;
      }
  }
}
"""

_lock = threading.Lock()
_state: dict = {}  # compiler -> library or None


_loaded: list = []  # the library once loaded (each call asks; the compiler lookup reads the environment)


def _lib():
    if disabled():
        return None
    if _loaded:
        return _loaded[0]
    cc = find_compiler()
    if cc in _state:
        return _state[cc]
    with _lock:
        if cc not in _state:
            lib = None
            if cc is not None:
                try:
                    lib, _ = load_library(C_INCLUDES + C_SOURCE, "exact", cc, ("ts_series", "ts_tail", "ts_terms"))
                    vp, ci, cd = ctypes.c_void_p, ctypes.c_int, ctypes.c_double
                    lib.ts_series.restype = ci
                    lib.ts_series.argtypes = [ci, ci] + [vp] * 7 + [ci, ci, vp, vp, vp]
                    lib.ts_tail.restype = None
                    lib.ts_tail.argtypes = [ci, ci, vp, vp, vp, ci, vp, vp, vp, ci, vp]
                    lib.ts_terms.restype = None
                    lib.ts_terms.argtypes = [ci, ci, vp, vp, vp, ci, cd, ci, vp, vp, vp, vp]
                except (OSError, AttributeError, RuntimeError):  # the NumPy path then runs
                    lib = None
            _state[cc] = lib
            if lib is not None:
                _loaded.append(lib)
        return _state[cc]


def available() -> bool:
    """Whether the compiled kernel can be had (else the callers run their NumPy code)."""
    return _lib() is not None


class _Layout:
    """Per tuple of shapes: the columns' kind codes, the table columns grouped by shape, and the
    tail bound's power factors and normal columns as C arrays."""

    def __init__(self, rw):
        self.kind = np.array([CODES[s.kind] for s in rw.shapes], dtype=np.intc)
        # each truncated normal's packed interpolants, one copy per beta, and every column's offset
        tables, at, self.tno = {}, 0, np.zeros(len(rw.shapes), dtype=np.int64)
        for j, s in enumerate(rw.shapes):
            if s.kind == "truncnormal":
                if s.beta not in tables:
                    tables[s.beta] = (at, truncnormal_packed(s.beta))
                    at += tables[s.beta][1].size
                self.tno[j] = tables[s.beta][0]
        self.tnt = np.concatenate([np.zeros(1)] + [t for _, t in tables.values()])
        self.tno[self.kind == 3] += 1
        self.fidx = np.ascontiguousarray(rw.f_idx, dtype=np.int64)
        self.fmult = np.ascontiguousarray(rw.f_mult, dtype=float)
        self.normal = np.ascontiguousarray(rw.normal, dtype=np.intc)


def _layout(rw) -> _Layout:
    lay = getattr(rw, "_c_layout", None)
    if lay is None:
        lay = rw._c_layout = _Layout(rw)
    return lay


def _c(x, dtype=float):
    return np.ascontiguousarray(x, dtype=dtype)


def series(b, R, L, K, rw, order: int, ball: bool = False):
    """``(P, G, H)`` of rows ``b`` (m, n) with ``K`` terms each (G, H None below their order), or
    None where the kernel cannot be had."""
    lib = _lib()
    if lib is None:
        return None
    lay = _layout(rw)
    b = _c(b)
    m, n = b.shape
    R, L = _c(np.broadcast_to(R, (m,))), _c(np.broadcast_to(L, (m,)))
    K = _c(np.broadcast_to(K, (m,)), np.int64)
    P = np.empty(m)
    G = np.empty((m, n)) if order >= 1 else np.zeros(1)
    H = np.empty((m, n, n)) if order >= 2 else np.zeros(1)
    status = lib.ts_series(
        m,
        n,
        b.ctypes.data,
        R.ctypes.data,
        L.ctypes.data,
        K.ctypes.data,
        lay.kind.ctypes.data,
        lay.tnt.ctypes.data,
        lay.tno.ctypes.data,
        order,
        int(ball),
        P.ctypes.data,
        G.ctypes.data,
        H.ctypes.data,
    )
    if status:
        return None
    return P, (G if order >= 1 else None), (H if order >= 2 else None)


def tail(rw, b, L, K, drop: int | None = None):
    """:meth:`.exact_series.Rows.tail` with one K per row, or None without the kernel."""
    lib = _lib()
    if lib is None:
        return None
    lay = _layout(rw)
    b = _c(b)
    m, n = b.shape
    L = _c(np.broadcast_to(L, (m,)))
    K = _c(np.broadcast_to(K, (m,)))
    out = np.empty(m)
    lib.ts_tail(
        m,
        n,
        b.ctypes.data,
        L.ctypes.data,
        K.ctypes.data,
        lay.fidx.size,
        lay.fidx.ctypes.data,
        lay.fmult.ctypes.data,
        lay.normal.ctypes.data,
        -1 if drop is None else int(drop),
        out.ctypes.data,
    )
    return out


def terms(rw, b, L, Ks: np.ndarray, tol: float):
    """:meth:`.exact_series.Rows.terms` over the candidates ``Ks`` (ascending), or None."""
    lib = _lib()
    if lib is None:
        return None
    lay = _layout(rw)
    b = _c(b)
    m, n = b.shape
    L = _c(np.broadcast_to(L, (m,)))
    Ks = _c(Ks)
    K = np.empty(m, dtype=np.int64)
    lib.ts_terms(
        m,
        n,
        b.ctypes.data,
        L.ctypes.data,
        Ks.ctypes.data,
        Ks.size,
        float(tol),
        lay.fidx.size,
        lay.fidx.ctypes.data,
        lay.fmult.ctypes.data,
        lay.normal.ctypes.data,
        K.ctypes.data,
    )
    return K
