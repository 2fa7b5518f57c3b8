"""A primal-dual interior-point method for the tolerance problem's LMI form, compiled from C.

The problem (per-component criterion, the paper's power-law cost) in ``y_i = eps_i^2``:

    minimise  sum_i k_i y_i^(-alpha_i / 2)   s.t.   A_b diag(y) A_b^T <= I   (3 x 3, every block b),
              lower_i^2 <= y_i <= upper_i^2,

``A_b`` a block's scaled sensitivity rows divided by ``sqrt(c)`` (``A_b diag(y) A_b^T`` is
``(z/R)^2`` times the covariance).  The iterates are the LMI multipliers ``Z_b > 0``, the slacks
``S_b > 0`` with primal residual ``rp_b = S_b + A_b diag(y) A_b^T - I``, and ``y`` strictly inside
its bounds, which are held by a logarithmic barrier of weight ``nu`` (their multipliers
``nu / (y - L)`` and ``nu / (U - y)``: exactly centred).  Each iteration: Nesterov-Todd scaling per
block, Mehrotra's predictor and corrector, with ``nu`` driven to the corrector's target
``sigma mu``; the Newton system is eliminated down to the movable parameters,
``(phi'' + Gamma) dy = rhs`` with ``Gamma_pq = sum_b (a_bp^T W_b a_bq)^2``: n x n whatever the number
of blocks, each iteration O(m n^2).  A step is halved while the residual it reaches is not within
half its predicted decrease (the cost is a power of y: its linear model can be far off).

Two modes of ``y``: the Lagrangian's minimiser at each iterate's ``Z`` (``primal=False``; a 1-D
Newton solve per parameter, so the stationarity residual is always 0: fewest iterations on most
problems), or an iterate of its own moved by the Newton step (``primal=True``; slower, but robust
where the minimiser moves by large factors between iterates, e.g. a parameter on its way to its
upper bound).  :mod:`tolsynth.solvers.fast` tries them in that order.

The C code is the whole solve in one call (no Python between iterations: some 10 us per
iteration on the paper's robot, against about 1 ms for the same iteration in NumPy, whose per-call
overhead dominates on 3 x 3 blocks).  It is built and cached by :mod:`tolsynth.cbuild`; without a
C compiler (or with ``TOLSYNTH_NO_COMPILE=1``) :func:`kernel` returns None and the callers use
IPOPT.  What it returns is a candidate: :mod:`tolsynth.solvers.fast` checks the point's
feasibility with NumPy's eigensolver and certifies it with the dual bound of ``Z`` in Python.
"""

from __future__ import annotations

import ctypes
import threading

import numpy as np

from tolsynth.cbuild import C_INCLUDES, disabled, find_compiler, load_library
from tolsynth.solvers.fast_linalg import C_LINALG

__all__ = ["IPMKernel", "kernel", "kernel_status", "unpack"]

C_SOURCE = r"""
#define START_TRACE 2.0 /* the cold start's largest trace of A_b diag(y) A_b^T */
#define START_PAD 0.1   /* the cold start's y at least this far inside its bounds, in ln y */
#define FLOOR 1e-6       /* the relative tests' scale: at least this fraction of the cost */
#define SIGMA_CUT 0.5    /* the centring at least, after a step the line search cut below 1/2 */
#define STALL 15         /* iterations without a better iterate before giving up */
typedef struct {
  int m, n, nf, primal;             /* primal: y an iterate of its own (else the Lagrangian's minimiser) */
  long m9, len;                     /* 9 m; a state: Z, S (9 m each), y, sL, sU (n each), nu */
  const double *A, *ks, *alpha, *L, *U;
  int *F;                           /* the movable parameters (L < U) */
  double *w, *D, *e, *rd, *t, *K;   /* per parameter; K: nf x nf */
  double *M, *rp, *G, *Gi, *W, *lam, *WrW;
} ts_ipm;

#define ZP(x) (x)
#define SP(p, x) ((x) + (p)->m9)
#define YP(p, x) ((x) + 2*(p)->m9)
#define SLP(p, x) ((x) + 2*(p)->m9 + (p)->n)
#define SUP(p, x) ((x) + 2*(p)->m9 + 2*(p)->n)
#define NU(p, x) ((x)[2*(p)->m9 + 3*(p)->n])

/* The Lagrangian's minimiser in one parameter, its bounds held by a log barrier of weight nu:
   phi(y) = -a ks y^(-a-1) + w - nu/sL + nu/sU = 0 on L < y < U (a = alpha/2; phi increases from
   -inf to +inf), by Newton's method from (y, sL, sU) kept inside a bracket of the root (bisection,
   geometric in the smaller gap, where a step leaves it).  The gaps sL = y - L and sU = U - y are
   carried along with y, never recomputed from it (near a bound the gap is far below y's rounding).
   Returns 1/phi' (the derivative -dy/dw). */
static double ts_inner(double ks, double a, double w, double nu, double L, double U, double *y, double *sL,
                       double *sU) {
  int k;
  double width = U - L, lL = 0, hL = width, lU = width, hU = 0, cl = *sL, cu = *sU, yy = *y, dphi = 1;
  for (k = 0; k < 300; k++) {
    double h = a*ks*pow(yy, -a - 1), phi = -h + w - nu/cl + nu/cu, step;
    dphi = (a + 1)*h/yy + nu/(cl*cl) + nu/(cu*cu);
    /* at the root to rounding: phi within a few ulps of its largest term */
    if (fabs(phi) <= 1e-15*(h + fabs(w) + nu/cl + nu/cu)) break;
    if (phi < 0) { lL = cl; lU = cu; } else { hL = cl; hU = cu; }
    step = -phi/dphi;
    if (cl + step > lL && cu - step > hU) {  /* Newton's step, inside the bracket */
      cl += step; cu -= step;
      yy = cl <= cu ? L + cl : U - cu;
      if (fabs(step) <= 1e-14*fmin(cl, cu)) break;
      continue;
    }
    if (hL <= lU) {  /* the bracket nearer to L: bisect in sL */
      cl = lL > 0 && hL < 4*lL ? 0.5*(lL + hL) : (lL > 0 ? sqrt(lL*hL) : 0.01*hL);
      cu = width - cl;
    } else {         /* nearer to U: bisect in sU */
      cu = hU > 0 && lU < 4*hU ? 0.5*(hU + lU) : (hU > 0 ? sqrt(hU*lU) : 0.01*lU);
      cl = width - cu;
    }
    yy = cl <= cu ? L + cl : U - cu;
    if (hL - lL <= 1e-15*fmin(cl, cu)) break;
  }
  *y = yy; *sL = cl; *sU = cu;
  return 1/dphi;
}

/* w(Z), the Lagrangian's minimiser y (with the gaps), D = -dy/dw and e = dy/dnu of every movable
   parameter, M_b and the primal residual rp_b = S_b + M_b - I; returns what the cost can still
   fall by (its excess over its value at the upper bounds: the scale of the relative tests) and sets
   *compl to <Z, S> + 2 nf nu */
static double ts_eval(ts_ipm *p, double *x, double *compl) {
  int m = p->m, n = p->n, b, i, q, r, s;
  const double *Z = ZP(x), *S = SP(p, x);
  double *y = YP(p, x), f = 0, ftot = 0, c = 0, nu = NU(p, x);
  for (i = 0; i < n; i++) p->w[i] = 0;
  for (b = 0; b < m; b++) {
    const double *A = p->A + (long)b*3*n, *z = Z + 9*b;
    for (i = 0; i < n; i++) {
      double a0 = A[i], a1 = A[n+i], a2 = A[2*n+i];
      p->w[i] += a0*(z[0]*a0 + z[1]*a1 + z[2]*a2) + a1*(z[3]*a0 + z[4]*a1 + z[5]*a2)
               + a2*(z[6]*a0 + z[7]*a1 + z[8]*a2);
    }
    for (r = 0; r < 9; r++) c += Z[9*b+r]*S[9*b+r];
  }
  for (q = 0; q < p->nf; q++) {
    double a, *sL, *sU;
    i = p->F[q]; a = 0.5*p->alpha[i]; sL = SLP(p, x) + i; sU = SUP(p, x) + i;
    if (p->primal) {  /* the stationarity residual and its derivative in y */
      double h = a*p->ks[i]*pow(y[i], -a - 1);
      p->rd[i] = -h + p->w[i] - nu / *sL + nu / *sU;
      p->D[i] = 1/((a + 1)*h/y[i] + nu/(*sL * *sL) + nu/(*sU * *sU));
    } else {
      p->D[i] = ts_inner(p->ks[i], a, p->w[i], nu, p->L[i], p->U[i], y + i, sL, sU);
      p->rd[i] = 0;
    }
    p->e[i] = (1 / *sL - 1 / *sU)*p->D[i];
    f += p->ks[i]*(pow(y[i], -a) - pow(p->U[i], -a));
    ftot += p->ks[i]*pow(y[i], -a);
  }
  /* the excess, but not below FLOOR of the movable parameters' whole cost (all at their upper
     bounds, it is 0) */
  f = fmax(f, FLOOR*ftot);
  c += 2.0*p->nf*nu;
  for (b = 0; b < m; b++) {
    const double *A = p->A + (long)b*3*n;
    double *Mb = p->M + 9*b, *rb = p->rp + 9*b;
    for (r = 0; r < 3; r++)
      for (s = r; s < 3; s++) {
        double v = 0;
        for (i = 0; i < n; i++) v += A[r*n+i]*y[i]*A[s*n+i];
        Mb[3*r+s] = Mb[3*s+r] = v;
      }
    for (r = 0; r < 9; r++) rb[r] = S[9*b+r] + Mb[r] - ((r % 4) == 0 ? 1.0 : 0.0);
  }
  *compl = c;
  return f;
}

/* the largest primal residual |rp| and relative dual residual |rd| y / f after ts_eval */
static void ts_residuals(ts_ipm *p, const double *x, double f, double *rpmax, double *rdmax) {
  long k;
  int q;
  double r = 0, d = 0;
  for (k = 0; k < p->m9; k++) if (fabs(p->rp[k]) > r) r = fabs(p->rp[k]);
  for (q = 0; q < p->nf; q++) { int i = p->F[q]; double v = fabs(p->rd[i])*YP(p, x)[i]; if (v > d) d = v; }
  *rpmax = r; *rdmax = d/f;
}

/* Nesterov-Todd scaling per block (G^-1 Z G^-T = G^T S G = diag(lam), W = G G^T), W rp W, and the
   Schur complement on the movable parameters scaled by y, y_p y_q (Gamma_pq + [p = q] / D_p) with
   Gamma_pq = sum_b (a_bp^T W_b a_bq)^2, factorised; 1 on failure */
static int ts_newton_matrix(ts_ipm *p, const double *x) {
  int m = p->m, n = p->n, nf = p->nf, b, q, qq, k, r, s;
  const double *Z = ZP(x), *S = SP(p, x), *y = YP(p, x);
  for (b = 0; b < m; b++) {
    double LZ[9], LS[9], B[9], U[9], X[9], *G = p->G + 9*b, *Gi = p->Gi + 9*b, *l = p->lam + 3*b;
    if (chol3(Z + 9*b, LZ) || chol3(S + 9*b, LS)) return 1;
    mtm3(LZ, LS, B);
    svd3(B, U, l);
    if (!(l[0] > 0 && l[1] > 0 && l[2] > 0)) return 1;
    mm3(LZ, U, G);
    for (r = 0; r < 3; r++) for (s = 0; s < 3; s++) G[3*r+s] /= sqrt(l[s]);
    mtm3(G, S + 9*b, X);
    for (r = 0; r < 3; r++) for (s = 0; s < 3; s++) Gi[3*r+s] = X[3*r+s]/l[r];
    mmt3(G, G, p->W + 9*b); sym3(p->W + 9*b);
    mm3(p->W + 9*b, p->rp + 9*b, X); mm3(X, p->W + 9*b, p->WrW + 9*b);
  }
  for (k = 0; k < nf*nf; k++) p->K[k] = 0;
  for (q = 0; q < nf; q++) {
    int i = p->F[q];
    p->K[q*nf+q] = y[i]*y[i]/p->D[i];
  }
  for (b = 0; b < m; b++) {
    const double *Ab = p->A + (long)b*3*n, *Wm = p->W + 9*b;
    for (q = 0; q < nf; q++) {
      int iq = p->F[q];
      double c0 = Ab[iq], c1 = Ab[n+iq], c2 = Ab[2*n+iq];
      double v0 = Wm[0]*c0 + Wm[1]*c1 + Wm[2]*c2, v1 = Wm[3]*c0 + Wm[4]*c1 + Wm[5]*c2,
             v2 = Wm[6]*c0 + Wm[7]*c1 + Wm[8]*c2;
      for (qq = 0; qq <= q; qq++) {
        int j = p->F[qq];
        double g = Ab[j]*v0 + Ab[n+j]*v1 + Ab[2*n+j]*v2;
        p->K[q*nf+qq] += y[iq]*y[j]*g*g;
      }
    }
  }
  return choln(p->K, nf);
}

/* the Newton direction for the blocks' right-hand side T (dZ + W dS W = T) and the barrier weight's
   change dnu: dZ, dS, dy (dy = -D dw + e dnu, dw = t + Gamma dy, dS = -rp - M(dy)) */
static void ts_direction(ts_ipm *p, const double *x, const double *T, double dnu, double *dZ, double *dS,
                         double *dy) {
  int m = p->m, n = p->n, nf = p->nf, b, i, q, k, r, s;
  const double *y = YP(p, x);
  double E[9], X[9];
  for (q = 0; q < nf; q++) p->t[q] = 0;
  for (b = 0; b < m; b++) {
    const double *A = p->A + (long)b*3*n;
    for (k = 0; k < 9; k++) E[k] = T[9*b+k] + p->WrW[9*b+k];
    for (q = 0; q < nf; q++) {
      double a0, a1, a2;
      i = p->F[q]; a0 = A[i]; a1 = A[n+i]; a2 = A[2*n+i];
      p->t[q] += a0*(E[0]*a0 + E[1]*a1 + E[2]*a2) + a1*(E[3]*a0 + E[4]*a1 + E[5]*a2)
               + a2*(E[6]*a0 + E[7]*a1 + E[8]*a2);
    }
  }
  for (q = 0; q < nf; q++) {
    i = p->F[q];
    p->t[q] = y[i]*(-p->t[q] - p->rd[i] + p->e[i]/p->D[i]*dnu);
  }
  if (nf) cholsolve(p->K, nf, p->t);
  for (i = 0; i < n; i++) dy[i] = 0;
  for (q = 0; q < nf; q++) { i = p->F[q]; dy[i] = y[i]*p->t[q]; }
  for (b = 0; b < m; b++) {
    const double *A = p->A + (long)b*3*n, *Wb = p->W + 9*b;
    double *dSb = dS + 9*b, *dZb = dZ + 9*b;
    for (r = 0; r < 3; r++)
      for (s = r; s < 3; s++) {
        double v = 0;
        for (q = 0; q < nf; q++) { i = p->F[q]; v += A[r*n+i]*dy[i]*A[s*n+i]; }
        dSb[3*r+s] = dSb[3*s+r] = -v;
      }
    for (k = 0; k < 9; k++) dSb[k] -= p->rp[9*b+k];
    mm3(Wb, dSb, X);
    mm3(X, Wb, E);
    for (k = 0; k < 9; k++) dZb[k] = T[9*b+k] - E[k];
    sym3(dZb);
  }
}

/* the largest step (may be > 1) keeping Z + a dZ and S + a dS positive definite, with the scaled
   directions dZh = Gi dZ Gi^T and dSh = G^T dS G */
static double ts_step(ts_ipm *p, const double *dZ, const double *dS, double *dZh, double *dSh) {
  int b, i, j;
  double emin = 0, X[9], E[9];
  for (b = 0; b < p->m; b++) {
    const double *G = p->G + 9*b, *Gi = p->Gi + 9*b, *l = p->lam + 3*b;
    double il[3] = {1/sqrt(l[0]), 1/sqrt(l[1]), 1/sqrt(l[2])}, e;
    mm3(Gi, dZ + 9*b, X); mmt3(X, Gi, dZh + 9*b); sym3(dZh + 9*b);
    mtm3(G, dS + 9*b, X); mm3(X, G, dSh + 9*b); sym3(dSh + 9*b);
    for (i = 0; i < 3; i++) for (j = 0; j < 3; j++) E[3*i+j] = il[i]*dZh[9*b+3*i+j]*il[j];
    e = eigmin3(E); if (e < emin) emin = e;
    for (i = 0; i < 3; i++) for (j = 0; j < 3; j++) E[3*i+j] = il[i]*dSh[9*b+3*i+j]*il[j];
    e = eigmin3(E); if (e < emin) emin = e;
  }
  return emin < 0 ? -1/emin : INFINITY;
}

/* primal mode: the largest step keeping y inside its bounds (the gaps positive) */
static double ts_bound_step(ts_ipm *p, const double *x, const double *dy) {
  int q;
  double amax = INFINITY;
  if (!p->primal) return amax;
  for (q = 0; q < p->nf; q++) {
    int i = p->F[q];
    if (dy[i] < 0) amax = fmin(amax, -SLP(p, x)[i]/dy[i]);
    if (dy[i] > 0) amax = fmin(amax, SUP(p, x)[i]/dy[i]);
  }
  return amax;
}

/* the cold start: Z = zeta I, S = I, nu = zeta, with zeta such that the largest trace of
   A_b diag(y) A_b^T is START_TRACE at the Lagrangian's (unbarriered) minimiser y(zeta w1),
   w1_i = sum_b |a_bi|^2, held START_PAD inside its bounds in ln y (regula falsi in ln zeta; the
   trace falls as zeta grows); that y starts the first inner solve */
static double ts_trace_at(ts_ipm *p, double s, double *y) {
  int b, q, i, n = p->n;
  double h = 0;
  for (q = 0; q < p->nf; q++) {
    double a, uc, lo = log(p->L[i = p->F[q]]), hi = log(p->U[i]), pad = fmin(START_PAD, 0.25*(hi - lo));
    a = 0.5*p->alpha[i];
    uc = p->w[i] > 0 ? (log(a*p->ks[i]) - s - log(p->w[i]))/(a + 1) : INFINITY;
    y[i] = exp(fmin(fmax(uc, lo + pad), hi - pad));
  }
  for (b = 0; b < p->m; b++) {
    const double *A = p->A + (long)b*3*n;
    double t = 0;
    for (i = 0; i < n; i++) t += y[i]*(A[i]*A[i] + A[n+i]*A[n+i] + A[2*n+i]*A[2*n+i]);
    if (t > h) h = t;
  }
  return h;
}
static void ts_start(ts_ipm *p, double *x) {
  int i, b, q, k, side = 0, n = p->n;
  double lo = INFINITY, hi = -INFINITY, flo, fhi, zeta, target = log(START_TRACE), *y = YP(p, x);
  for (i = 0; i < n; i++) {
    double w = 0;
    for (b = 0; b < p->m; b++) {
      const double *A = p->A + (long)b*3*n;
      w += A[i]*A[i] + A[n+i]*A[n+i] + A[2*n+i]*A[2*n+i];
    }
    p->w[i] = w;
    y[i] = p->L[i];  /* the locked ones */
  }
  for (q = 0; q < p->nf; q++) {
    double a = 0.5*p->alpha[i = p->F[q]];
    if (p->w[i] > 0) {
      lo = fmin(lo, log(a*p->ks[i]) - log(p->w[i]) - (a + 1)*log(p->U[i]));
      hi = fmax(hi, log(a*p->ks[i]) - log(p->w[i]) - (a + 1)*log(p->L[i]));
    }
  }
  if (!(lo < hi)) zeta = isfinite(lo) ? lo : 0.0;
  else if ((flo = log(ts_trace_at(p, lo, y)) - target) <= 0) zeta = lo;
  else if ((fhi = log(ts_trace_at(p, hi, y)) - target) >= 0) zeta = hi;
  else {
    for (k = 0; k < 60 && hi - lo > 1e-3; k++) {
      double s = (lo*fhi - hi*flo)/(fhi - flo), fs = log(ts_trace_at(p, s, y)) - target;
      if (fs > 0) { lo = s; flo = fs; if (side == 1) fhi *= 0.5; side = 1; }
      else { hi = s; fhi = fs; if (side == -1) flo *= 0.5; side = -1; }
    }
    zeta = 0.5*(lo + hi);
  }
  ts_trace_at(p, zeta, y);
  zeta = exp(zeta);
  for (k = 0; k < p->m9; k++) { ZP(x)[k] = (k % 9) % 4 == 0 ? zeta : 0.0; SP(p, x)[k] = (k % 9) % 4 == 0 ? 1.0 : 0.0; }
  for (q = 0; q < p->nf; q++) {
    i = p->F[q];
    SLP(p, x)[i] = y[i] - p->L[i];
    SUP(p, x)[i] = p->U[i] - y[i];
  }
  NU(p, x) = zeta;
}

/* Solve.  par: ks, alpha, L, U (n each: the cost ks y^(-alpha/2), the bounds L <= y <= U, L = U
   locked); x: the state (Z, S: m 3 x 3 blocks each; y, sL, sU: n each; nu), in/out; zb: out, the
   bounds' multipliers; cold: start from ts_start (else from x as given).  info: best iteration, its error, cost excess, complementarity,
   primal residual, barrier weight, iterations run.  Returns 0 converged (error <= tol), 1 stalled
   or at the iteration limit (the best iterate returned), 2 no step from the start (not positive
   definite), 3 out of memory. */
int ts_ipm_solve(int m, int n, const double *A, const double *par, double *x, double *zb, int cold, double tol,
                 int maxit, double tau, double sigma_min, int primal, double *info) {
  ts_ipm p;
  const double *ks = par, *alpha = par + n, *L = par + 2*n, *U = par + 3*n;
  long m9 = 9L*m, len = 18L*m + 3L*n + 1;
  int it, b, k, i, ls, status = 1, stall = 0, fresh = 0;
  double a_prev = 1, best = INFINITY, f = 0, compl = 0, rpmax = 0, rdmax = 0, mu;
  double *buf = (double *)calloc((size_t)(6*n + n*n + 3*m + 13*m9 + 2*len + n + 2), sizeof(double));
  int *ibuf = (int *)calloc((size_t)n + 1, sizeof(int));
  double *xb, *xt, *dZa, *dSa, *dZ, *dS, *dZh, *dSh, *T, *dy;
  if (!buf || !ibuf) { free(buf); free(ibuf); return 3; }
  p.m = m; p.n = n; p.m9 = m9; p.len = len; p.A = A; p.ks = ks; p.alpha = alpha; p.L = L; p.U = U;
  p.w = buf; p.D = p.w + n; p.e = p.D + n; p.rd = p.e + n; p.t = p.rd + n; p.K = p.t + n;
  p.M = p.K + n*n + n; p.rp = p.M + m9; p.G = p.rp + m9; p.Gi = p.G + m9; p.W = p.Gi + m9;
  p.WrW = p.W + m9; p.lam = p.WrW + m9;
  xb = p.lam + 3*m; xt = xb + len; dZa = xt + len; dSa = dZa + m9; dZ = dSa + m9; dS = dZ + m9;
  dZh = dS + m9; dSh = dZh + m9; T = dSh + m9; dy = T + m9;
  p.F = ibuf; p.nf = 0; p.primal = primal;
  for (i = 0; i < n; i++) if (L[i] < U[i]) p.F[p.nf++] = i;
  if (cold) {
    ts_start(&p, x);
    if (primal) {  /* y the Lagrangian's minimiser at the start (its stationarity residual 0) */
      p.primal = 0;
      ts_eval(&p, x, &compl);
      p.primal = 1;
    }
  }
  for (it = 0; it <= maxit; it++) {
    double err, amax, a, mua, sigma, dnu, ntot = 3.0*m + 2.0*p.nf, nu = NU(&p, x);
    if (!fresh) {
      f = fmax(ts_eval(&p, x, &compl), 1e-300);
      ts_residuals(&p, x, f, &rpmax, &rdmax);
    }
    fresh = 0;
    mu = compl/ntot;
    err = fmax(fmax(rpmax, rdmax), compl/f);
#ifdef TS_DEBUG
    fprintf(stderr, "%3d f %.14g mu %.2e nu %.2e rp %.2e\n", it, f, mu, nu, rpmax);
#endif
    if (err < best) {
      best = err; stall = 0;
      memcpy(xb, x, len*sizeof(double));
      info[0] = it; info[1] = err; info[2] = f; info[3] = compl; info[4] = rpmax; info[5] = nu;
    } else if (++stall >= STALL) break;
    if (err <= tol) { status = 0; break; }
    if (it == maxit) break;
    if (ts_newton_matrix(&p, x)) {
      if (it == 0) status = 2;
      break;
    }
    /* predictor: to complementarity 0 */
    for (k = 0; k < m9; k++) T[k] = -ZP(x)[k];
    ts_direction(&p, x, T, -nu, dZa, dSa, dy);
    amax = fmin(ts_step(&p, dZa, dSa, dZh, dSh), ts_bound_step(&p, x, dy));
    a = fmin(1.0, amax);
    mua = 2.0*p.nf*(1 - a)*nu;
    for (k = 0; k < m9; k++) mua += (ZP(x)[k] + a*dZa[k])*(SP(&p, x)[k] + a*dSa[k]);
    mua /= ntot;
    sigma = mu > 0 ? fmin(1.0, pow(fmax(mua, 0.0)/mu, 3)) : 0.0;
    if (a_prev < 0.5) sigma = fmax(sigma, SIGMA_CUT);
    sigma = fmax(sigma, sigma_min);
    /* corrector: lam o (dZh + dSh) = sigma mu I - lam^2 - dZh_a o dSh_a in each block's scaled
       space; the barrier weight to sigma mu */
    for (b = 0; b < m; b++) {
      double R[9], X[9], Y[9], *l = p.lam + 3*b;
      int r, s;
      mm3(dZh + 9*b, dSh + 9*b, X);
      for (r = 0; r < 3; r++)
        for (s = 0; s < 3; s++) {
          R[3*r+s] = -0.5*(X[3*r+s] + X[3*s+r]) + (r == s ? sigma*mu - l[r]*l[r] : 0.0);
          Y[3*r+s] = 2*R[3*r+s]/(l[r] + l[s]);
        }
      mm3(p.G + 9*b, Y, X); mmt3(X, p.G + 9*b, T + 9*b); sym3(T + 9*b);
    }
    dnu = sigma*mu - nu;
    ts_direction(&p, x, T, dnu, dZ, dS, dy);
    amax = fmin(ts_step(&p, dZ, dS, dZh, dSh), ts_bound_step(&p, x, dy));
    a = fmin(1.0, tau*amax);
    /* the step, halved while the residual it reaches (the larger of the primal and the relative
       dual one) has not fallen by half the predicted amount (give or take the relative
       complementarity): the cost is a power of y, and where y or w change by large factors the
       linear model of the Newton step no longer holds */
    for (ls = 0; ; ls++) {
      double rt = 0, rdt = 0, ct, ft;
      memcpy(xt, x, len*sizeof(double));
      for (k = 0; k < m9; k++) { ZP(xt)[k] += a*dZ[k]; SP(&p, xt)[k] += a*dS[k]; }
      for (b = 0; b < m; b++) { sym3(ZP(xt) + 9*b); sym3(SP(&p, xt) + 9*b); }
      NU(&p, xt) = nu + a*dnu;
      for (k = 0; k < p.nf; k++) {  /* primal: the step; else the inner solves' start */
        double st;
        i = p.F[k];
        st = a*dy[i];
        if (!p.primal) {
          if (st < -0.9*SLP(&p, xt)[i]) st = -0.9*SLP(&p, xt)[i];
          if (st > 0.9*SUP(&p, xt)[i]) st = 0.9*SUP(&p, xt)[i];
        }
        YP(&p, xt)[i] += st; SLP(&p, xt)[i] += st; SUP(&p, xt)[i] -= st;
      }
      ft = fmax(ts_eval(&p, xt, &ct), 1e-300);
      ts_residuals(&p, xt, ft, &rt, &rdt);
#ifdef TS_DEBUG
      fprintf(stderr, "     ls %d a %.3e sigma %.2e rp %.2e (predicted %.2e) rd %.2e (was %.2e) compl/f %.2e\n", ls, a, sigma, rt, (1 - a)*rpmax, rdt, rdmax, ct/ft);
#endif
      if (fmax(rt, rdt) <= (1 - 0.5*a)*fmax(rpmax, rdmax) + ct/ft || ls >= 30) {
        a_prev = a;
        f = ft; compl = ct; rpmax = rt; rdmax = rdt;
        break;
      }
      a *= 0.5;
    }
    memcpy(x, xt, len*sizeof(double));
    fresh = 1;
  }
  if (best < INFINITY) memcpy(x, xb, len*sizeof(double));
  info[6] = it;
  for (i = 0; i < n; i++) zb[i] = 0;  /* the bounds' multipliers of the barrier, nu/sU - nu/sL */
  for (k = 0; k < p.nf; k++) { i = p.F[k]; zb[i] = NU(&p, x)/SUP(&p, x)[i] - NU(&p, x)/SLP(&p, x)[i]; }
  free(buf); free(ibuf);
  return status;
}
"""


class IPMKernel:
    """The compiled :data:`C_SOURCE`, called through ctypes."""

    def __init__(self, lib: ctypes.CDLL):
        fn = lib.ts_ipm_solve
        vp = ctypes.c_void_p
        fn.restype = ctypes.c_int
        fn.argtypes = [
            ctypes.c_int,
            ctypes.c_int,
            vp,
            vp,
            vp,
            vp,
            ctypes.c_int,
            ctypes.c_double,
            ctypes.c_int,
            ctypes.c_double,
            ctypes.c_double,
            ctypes.c_int,
            vp,
        ]
        self._fn = fn

    def solve(
        self,
        A: np.ndarray,
        par: np.ndarray,
        state: np.ndarray | None = None,
        tol: float = 1e-10,
        maxit: int = 100,
        tau: float = 0.99,
        sigma_min: float = 0.0,
        primal: bool = False,
    ) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
        """Run the method on ``A`` ((m, 3, n) float64, C order) with ``par`` = ``(ks, alpha, L, U)``
        stacked (float64, 4 n: the cost ``ks y^(-alpha/2)``, the bounds ``L <= y <= U``, ``L = U``
        locked), from the cold start, or from ``state`` (one this method returned; overwritten).

        Returns the status (0 converged to ``tol``, 1 stalled or at ``maxit`` with the best iterate,
        2 no step from the start, 3 out of memory), the state (:func:`unpack` reads it), the bounds'
        multipliers ``zU - zL`` (per unit of y) and ``info`` = (best iteration, its error, cost
        excess, complementarity, primal residual, barrier weight, iterations run)."""
        m, _, n = A.shape
        cold = state is None
        if cold:
            state = np.zeros(18 * m + 3 * n + 1)
        zb = np.empty(n)
        info = np.zeros(7)
        status = self._fn(
            m,
            n,
            A.ctypes.data,
            par.ctypes.data,
            state.ctypes.data,
            zb.ctypes.data,
            cold,
            tol,
            maxit,
            tau,
            sigma_min,
            int(primal),
            info.ctypes.data,
        )
        return status, state, zb, info


def unpack(state: np.ndarray, m: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(Z (m, 3, 3), S (m, 3, 3), y (n))`` of a state of :meth:`IPMKernel.solve` (views)."""
    return state[: 9 * m].reshape(m, 3, 3), state[9 * m : 18 * m].reshape(m, 3, 3), state[18 * m : 18 * m + n]


_lock = threading.Lock()
_state: dict = {}  # compiler -> (kernel or None, reason)


_loaded: list = []  # the kernel once built (every solve asks; the compiler lookup reads the environment)


def kernel() -> IPMKernel | None:
    """The compiled kernel (built on first use and cached on disk), or None where it cannot be had
    (no compiler, ``TOLSYNTH_NO_COMPILE``, a failed build): :func:`kernel_status` says why."""
    if disabled():
        return None
    if _loaded:
        return _loaded[0]
    cc = find_compiler()
    hit = _state.get(cc)
    if hit is not None:
        return hit[0]
    with _lock:
        if cc not in _state:
            if cc is None:
                _state[cc] = (None, "no C compiler found (cc, gcc, clang; or set TOLSYNTH_CC)")
            else:
                try:
                    lib, _ = load_library(C_INCLUDES + C_LINALG + C_SOURCE, "ipm", cc, ("ts_ipm_solve",))
                    _state[cc] = (IPMKernel(lib), "")
                    _loaded.append(_state[cc][0])
                except (OSError, AttributeError, RuntimeError) as err:
                    _state[cc] = (None, f"compilation failed: {err}")
        return _state[cc][0]


def kernel_status() -> dict:
    """``{"backend": "compiled" | "ipopt", "reason": ...}`` of the interior-point kernel."""
    if disabled():
        return {"backend": "ipopt", "reason": "TOLSYNTH_NO_COMPILE is set"}
    k = kernel()
    return {"backend": "compiled" if k is not None else "ipopt", "reason": _state.get(find_compiler(), (None, ""))[1]}
