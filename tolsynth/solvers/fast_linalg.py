"""Small dense linear algebra in C for :mod:`tolsynth.solvers.fast_ipm`: 3 x 3 products, Cholesky
factors, a one-sided Jacobi SVD and the smallest eigenvalue of symmetric 3 x 3 matrices, and an
n x n Cholesky factorisation and solve (the interior-point method's Newton matrix).

Plain C with no library beyond ``<math.h>`` and ``<string.h>``: the interior-point method's blocks
are 3 x 3 and its Newton matrix at most some 50 x 50, where calls into LAPACK would cost more than
the arithmetic.  Matrices are row-major; symmetric ones are read in full.
"""

__all__ = ["C_LINALG"]

C_LINALG = r"""
/* 3 x 3 matrices row-major, symmetric ones read in full */
static void mm3(const double *a, const double *b, double *c) {
  int i, j;
  for (i = 0; i < 3; i++)
    for (j = 0; j < 3; j++) c[3*i+j] = a[3*i]*b[j] + a[3*i+1]*b[3+j] + a[3*i+2]*b[6+j];
}
static void mtm3(const double *a, const double *b, double *c) { /* a^T b */
  int i, j;
  for (i = 0; i < 3; i++)
    for (j = 0; j < 3; j++) c[3*i+j] = a[i]*b[j] + a[3+i]*b[3+j] + a[6+i]*b[6+j];
}
static void mmt3(const double *a, const double *b, double *c) { /* a b^T */
  int i, j;
  for (i = 0; i < 3; i++)
    for (j = 0; j < 3; j++) c[3*i+j] = a[3*i]*b[3*j] + a[3*i+1]*b[3*j+1] + a[3*i+2]*b[3*j+2];
}
static void sym3(double *a) {
  double t;
  t = 0.5*(a[1]+a[3]); a[1] = a[3] = t;
  t = 0.5*(a[2]+a[6]); a[2] = a[6] = t;
  t = 0.5*(a[5]+a[7]); a[5] = a[7] = t;
}
/* lower Cholesky factor of a symmetric positive definite 3 x 3; 1 if not positive definite */
static int chol3(const double *x, double *l) {
  double d;
  memset(l, 0, 9*sizeof(double));
  if (!(x[0] > 0)) return 1;
  l[0] = sqrt(x[0]); l[3] = x[3]/l[0]; l[6] = x[6]/l[0];
  d = x[4] - l[3]*l[3]; if (!(d > 0)) return 1;
  l[4] = sqrt(d); l[7] = (x[7] - l[6]*l[3])/l[4];
  d = x[8] - l[6]*l[6] - l[7]*l[7]; if (!(d > 0)) return 1;
  l[8] = sqrt(d);
  return 0;
}
/* B = U diag(s) V^T by one-sided Jacobi on the columns of B (accurate small singular values) */
static void svd3(const double *b, double *u, double *s) {
  double c[9];
  int sweep, p, q, k, rot;
  memcpy(c, b, sizeof c);
  for (sweep = 0; sweep < 40; sweep++) {
    rot = 0;
    for (p = 0; p < 2; p++)
      for (q = p + 1; q < 3; q++) {
        double al = 0, be = 0, ga = 0, ze, t, cs, sn;
        for (k = 0; k < 3; k++) { al += c[3*k+p]*c[3*k+p]; be += c[3*k+q]*c[3*k+q]; ga += c[3*k+p]*c[3*k+q]; }
        if (fabs(ga) <= 1e-15*sqrt(al*be) || ga == 0) continue;
        rot = 1;
        ze = (be - al)/(2*ga);
        t = (ze >= 0 ? 1.0 : -1.0)/(fabs(ze) + sqrt(1 + ze*ze));
        cs = 1/sqrt(1 + t*t); sn = cs*t;
        for (k = 0; k < 3; k++) {
          double x = c[3*k+p], y = c[3*k+q];
          c[3*k+p] = cs*x - sn*y; c[3*k+q] = sn*x + cs*y;
        }
      }
    if (!rot) break;
  }
  for (k = 0; k < 3; k++) {
    double nn = sqrt(c[k]*c[k] + c[3+k]*c[3+k] + c[6+k]*c[6+k]);
    s[k] = nn;
    u[k] = c[k]/nn; u[3+k] = c[3+k]/nn; u[6+k] = c[6+k]/nn;
  }
}
/* smallest eigenvalue of a symmetric 3 x 3 (cyclic Jacobi) */
static double eigmin3(const double *x) {
  double a[9];
  int sweep, p, q, k;
  memcpy(a, x, sizeof a);
  for (sweep = 0; sweep < 40; sweep++) {
    double off = a[1]*a[1] + a[2]*a[2] + a[5]*a[5];
    double dia = a[0]*a[0] + a[4]*a[4] + a[8]*a[8];
    if (off <= 1e-32*dia || off == 0) break;
    for (p = 0; p < 2; p++)
      for (q = p + 1; q < 3; q++) {
        double apq = a[3*p+q], th, t, cs, sn;
        if (apq == 0) continue;
        th = (a[3*q+q] - a[3*p+p])/(2*apq);
        t = (th >= 0 ? 1.0 : -1.0)/(fabs(th) + sqrt(1 + th*th));
        cs = 1/sqrt(1 + t*t); sn = cs*t;
        for (k = 0; k < 3; k++) { /* columns p, q */
          double x = a[3*k+p], y = a[3*k+q];
          a[3*k+p] = cs*x - sn*y; a[3*k+q] = sn*x + cs*y;
        }
        for (k = 0; k < 3; k++) { /* rows p, q */
          double x = a[3*p+k], y = a[3*q+k];
          a[3*p+k] = cs*x - sn*y; a[3*q+k] = sn*x + cs*y;
        }
      }
  }
  return fmin(a[0], fmin(a[4], a[8]));
}
/* Cholesky of the n x n (row-major, lower part used) in place; 1 if not positive definite */
static int choln(double *k, int n) {
  int i, j, p;
  for (j = 0; j < n; j++) {
    double d = k[j*n+j];
    for (p = 0; p < j; p++) d -= k[j*n+p]*k[j*n+p];
    if (!(d > 0)) return 1;
    d = sqrt(d);
    k[j*n+j] = d;
    for (i = j + 1; i < n; i++) {
      double v = k[i*n+j];
      for (p = 0; p < j; p++) v -= k[i*n+p]*k[j*n+p];
      k[i*n+j] = v/d;
    }
  }
  return 0;
}
static void cholsolve(const double *l, int n, double *x) {
  int i, p;
  for (i = 0; i < n; i++) {
    double v = x[i];
    for (p = 0; p < i; p++) v -= l[i*n+p]*x[p];
    x[i] = v/l[i*n+i];
  }
  for (i = n - 1; i >= 0; i--) {
    double v = x[i];
    for (p = i + 1; p < n; p++) v -= l[p*n+i]*x[p];
    x[i] = v/l[i*n+i];
  }
}

"""
