"""The C source of :mod:`.exact_kernel`: the exact series, its truncation bounds, the dropping of
small terms and the closed forms of a few uniform terms, each a function over rows (the NumPy
code each ports is named in its comment)."""

__all__ = ["C_SOURCE"]

C_SOURCE = r"""
#define TS_PI 3.14159265358979323846
#define TS_MAXN 64 /* columns at most (MAX_COLUMNS) */
#define TS_SYNC 16
#if defined(__GNUC__)
#define TS_INLINE static inline __attribute__((always_inline)) /* one copy per constant argument */
#else
#define TS_INLINE static inline
#endif
#define TS_ROTATE 512 /* the sphere's rows of more terms take every sine afresh: its kernel
                         sin x - x cos x multiplies the rounding by x, which grows with k */

/* phi(t), and for order >= 1 D1 = t phi'(t), D2 = t dD1/dt, of the uniform (0), normal (1,
   3 sigma = 1) and triangular (2) shapes: the closed forms of the NumPy path.  sn, cs: sin and cos
   of t (uniform) or of t/2 (triangular), from the caller's rotation; unused for the normal. */
static void ts_cf(int kind, double t, double sn, double cs, double it, int order, double *phi, double *d1,
                  double *d2) {
  /* it: 1/t (uniform) or 2/t (triangular), from reciprocals the caller keeps (no division) */
  if (kind == 0) {
    if (fabs(t) < 1e-4) {
      *phi = 1.0 - t*t/6.0;
      if (order) { *d1 = -t*t/3.0; *d2 = -2.0*t*t/3.0; }
    } else {
      *phi = sn*it;
      if (order) { *d1 = cs - *phi; *d2 = -t*sn - *d1; }
    }
  } else if (kind == 1) {
    double a = t*t/9.0;
    *phi = exp(-t*t/18.0);
    if (order) { *d1 = -a * *phi; *d2 = (a*a - 2.0*a) * *phi; }
  } else {
    double h = 0.5*t, s, e, he;
    if (fabs(h) < 1e-4) { s = 1.0 - h*h/6.0; e = -h*h/3.0; he = -2.0*h*h/3.0; }
    else { s = sn*it; e = cs - s; he = -h*sn - e; }
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
    tmp = (c[((long)k*nf + f)*pieces + j] - b2) + 2.0*t*b1;  /* b2 off the chain of b1 */
    b2 = b1;
    b1 = tmp;
  }
  return c[(long)f*pieces + j] + t*b1 - b2;
}

/* Both functions of a two-function interpolant at z, in one pass (same piece, same t). */
static void ts_clenshaw2(const double *blk, double z, double *f0, double *f1) {
  double a = blk[0], h = blk[1], u = (z - a)/h, t, b1 = 0.0, b2 = 0.0, e1 = 0.0, e2 = 0.0, tmp;
  int pieces = (int)blk[2], deg = (int)blk[3], k;
  long j;
  const double *c = blk + 5;
  double fl = floor(u);
  j = fl < 0 ? 0 : (fl > pieces - 1 ? pieces - 1 : (long)fl);
  t = 2.0*(u - (double)j) - 1.0;
  for (k = deg; k > 0; k--) {
    const double *ck = c + (long)k*2*pieces + j;
    tmp = (ck[0] - b2) + 2.0*t*b1;
    b2 = b1;
    b1 = tmp;
    tmp = (ck[pieces] - e2) + 2.0*t*e1;
    e2 = e1;
    e1 = tmp;
  }
  *f0 = c[j] + t*b1 - b2;
  *f1 = c[pieces + j] + t*e1 - e2;
}

/* phi, D1, D2 of the truncated normal from its packed interpolants: truncnormal.cf3's formulas
   (sn, cs: sin and cos of s, which is cf3's theta = 2 x y) */
static void ts_tn(const double *tb, double s, double sn, double cs, int order, double *phi, double *d1,
                  double *d2) {
  double beta = tb[0], x = tb[1], cc = tb[2], split = tb[3];
  double y = fabs(s)/(beta*sqrt(2.0)), g = y > 40.0 ? 0.0 : exp(-y*y), I, LI = 0.0, LLI = 0.0, y2 = y*y;
  if (y <= split) {
    double Is = ts_clenshaw(tb + (long)tb[4], 0, y);
    I = Is;
    if (order >= 1) {
      double I1 = sn - 2.0*y*Is;
      LI = y*I1;
      if (order >= 2) {
        double I2 = 2.0*x*cs - 2.0*Is - 2.0*y*I1;
        LLI = y*I1 + y*y*I2;
      }
    }
  } else {
    const double *l0 = tb + (long)tb[5];
    double v = 1.0/y, C, S, th = 2.0*x*y, P;
    ts_clenshaw2(l0, v, &C, &S);
    P = sn*C - cs*S;
    I = 0.5*v*P;
    if (order >= 1) {
      const double *l1 = tb + (long)tb[6];
      double C1, S1, Pt, Pv, Q;
      ts_clenshaw2(l1, v, &C1, &S1);
      Pt = cs*C + sn*S;
      Pv = sn*C1 - cs*S1;
      Q = -P + th*Pt - v*Pv;
      LI = 0.5*v*Q;
      if (order >= 2) {
        const double *l2 = tb + (long)tb[7];
        double C2, S2, Ptv, Pvv, LQ;
        ts_clenshaw2(l2, v, &C2, &S2);
        Ptv = cs*C1 + sn*S1;
        Pvv = sn*C2 - cs*S2;
        LQ = 2.0*v*Pv - th*th*P - 2.0*th*v*Ptv + v*v*Pvv;
        LLI = 0.5*v*(-Q + LQ);
      }
    }
  }
  *phi = g + cc*I;
  if (order >= 1) *d1 = -2.0*y2*g + cc*LI;
  if (order >= 2) *d2 = (4.0*y2*y2 - 4.0*y2)*g + cc*LLI;
}

/* 1/k of the first terms (the series' rows mostly have 16 or 32 terms) */
#define TS_NINV 64
static const double ts_inv[TS_NINV + 1] = {
  0.0, 1.0/1, 1.0/2, 1.0/3, 1.0/4, 1.0/5, 1.0/6, 1.0/7, 1.0/8, 1.0/9, 1.0/10, 1.0/11, 1.0/12, 1.0/13, 1.0/14,
  1.0/15, 1.0/16, 1.0/17, 1.0/18, 1.0/19, 1.0/20, 1.0/21, 1.0/22, 1.0/23, 1.0/24, 1.0/25, 1.0/26, 1.0/27,
  1.0/28, 1.0/29, 1.0/30, 1.0/31, 1.0/32, 1.0/33, 1.0/34, 1.0/35, 1.0/36, 1.0/37, 1.0/38, 1.0/39, 1.0/40,
  1.0/41, 1.0/42, 1.0/43, 1.0/44, 1.0/45, 1.0/46, 1.0/47, 1.0/48, 1.0/49, 1.0/50, 1.0/51, 1.0/52, 1.0/53,
  1.0/54, 1.0/55, 1.0/56, 1.0/57, 1.0/58, 1.0/59, 1.0/60, 1.0/61, 1.0/62, 1.0/63, 1.0/64};

/* Rotates n pairs (s, c) by the angles of (rc, rs), two columns at a time (the compiler's vector
   arithmetic; the same operations per column). */
static inline void ts_turn(int n, double *sk, double *ck, const double *rc, const double *rs) {
  int p;
  for (p = 0; p < (n + 1)/2; p++) {
    double *s = sk + 2*p, *c = ck + 2*p;
    const double *u = rc + 2*p, *v = rs + 2*p;
    double c0 = c[0]*u[0] - s[0]*v[0], c1 = c[1]*u[1] - s[1]*v[1];
    s[0] = s[0]*u[0] + c[0]*v[0];
    s[1] = s[1]*u[1] + c[1]*v[1];
    c[0] = c0;
    c[1] = c1;
  }
}

/* ts_series' sum for P alone (order 0, not the sphere's), the same factors phi by the same
   formulas, grouped by kind: the uniform columns whose arguments k ang never reach the
   small-argument form's 1e-4 (ang: that of k = 1; the argument grows with k) as
   sin(k ang) * (1/k * 1/ang), rotated by pairs and multiplied in two products (even and odd
   places); the normal columns as one exponential, exp(-tau^2 sum b^2 / 18); the others by
   ts_cf and ts_tn.  Only the order of the products differs from ts_series (their rounding).
   rc, rs: cos and sin of the angles of k = 1; xc, xs: of pi R / L. */
TS_INLINE double ts_sum0(int nz, long Kr, const double *br, const int *col, const int *kind,
                         const double *tnt, const long *tno, double L, double R, const double *ang,
                         const double *iang, const double *rc, const double *rs, double xc, double xs, int mixed) {
  /* u: the uniform columns, o: the others but the normal; each padded to pairs by a still column */
  double su[TS_MAXN + 1], cu[TS_MAXN + 1], ucos[TS_MAXN + 1], usin[TS_MAXN + 1], iu[TS_MAXN + 1];
  double so[TS_MAXN + 1], co[TS_MAXN + 1], ocos[TS_MAXN + 1], osin[TS_MAXN + 1], io[TS_MAXN];
  double ks = xs, kc = xc, sum = 0.0, t0, bn = 0.0;
  long k;
  int a, p, nu = 0, no = 0, nn = 0, oc[TS_MAXN], ou[TS_MAXN];
  for (a = 0; a < nz; a++) {
    int j = col[a];
    if (!mixed || (kind[j] == 0 && ang[a] >= 1e-4)) {
      ou[nu] = j;
      usin[nu] = rs[a];
      ucos[nu] = rc[a];
      iu[nu++] = iang[a];
    } else if (kind[j] == 1) {
      bn += br[j]*br[j];
      nn++;
    } else {
      oc[no] = j;
      io[no] = iang[a];
      osin[no] = rs[a];
      ocos[no++] = rc[a];
    }
  }
  for (a = 0; a < nu; a++) {
    su[a] = usin[a];
    cu[a] = ucos[a];
  }
  for (a = 0; mixed && a < no; a++) {
    so[a] = osin[a];
    co[a] = ocos[a];
  }
  su[nu] = usin[nu] = so[no] = osin[no] = 0.0;
  cu[nu] = ucos[nu] = co[no] = ocos[no] = 1.0;
  for (k = 1; k <= Kr; k++) {
    double ik = k <= TS_NINV ? ts_inv[k] : 1.0/(double)k, tau = 0.0, pe = 1.0, po = 1.0, pr = 1.0;
    int fresh = k > 1 && (k - 1) % TS_SYNC == 0;
    if (fresh || (mixed && (no || nn))) tau = TS_PI*(double)k/L;  /* the uniform columns' need it only afresh */
    if (fresh) {  /* afresh, as ts_series takes them */
      double x = TS_PI*(double)k*(R/L);
      for (a = 0; a < nu; a++) {
        double t = tau*br[ou[a]]*1.0;
        su[a] = sin(t);
        cu[a] = cos(t);
      }
      for (a = 0; mixed && a < no; a++) {
        double t = tau*br[oc[a]]*(kind[oc[a]] == 2 ? 0.5 : 1.0);
        so[a] = sin(t);
        co[a] = cos(t);
      }
      ks = sin(x);
      kc = cos(x);
    } else if (k > 1) {
      ts_turn(nu, su, cu, ucos, usin);
      if (mixed && no) ts_turn(no, so, co, ocos, osin);
      t0 = kc*xc - ks*xs;
      ks = ks*xc + kc*xs;
      kc = t0;
    }
    for (p = 0; p < nu/2; p++) {  /* two products side by side: half as long a chain each */
      pe *= su[2*p]*(ik*iu[2*p]);
      po *= su[2*p + 1]*(ik*iu[2*p + 1]);
    }
    if (nu & 1) pe *= su[nu - 1]*(ik*iu[nu - 1]);
    if (!mixed) {
      sum += (2.0/TS_PI)*ik*ks*(pe*po);
      continue;
    }
    if (nn) pr = exp(-(tau*tau*bn)/18.0);
    for (a = 0; a < no; a++) {
      int j = oc[a];
      double phi, d;
      if (kind[j] == 3) ts_tn(tnt + tno[j], tau*br[j], so[a], co[a], 0, &phi, &d, &d);
      else ts_cf(kind[j], tau*br[j], so[a], co[a], ik*io[a], 0, &phi, &d, &d);
      pr *= phi;
    }
    sum += (2.0/TS_PI)*ik*ks*((pe*po)*pr);
  }
  return sum;
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
    double ang[TS_MAXN], iang[TS_MAXN], rc[TS_MAXN], rs[TS_MAXN], sk[TS_MAXN], ck[TS_MAXN], xr, xc, xs, ks = 0.0, kc = 1.0;
    long k, Kr = K[r];
    for (j = 0; j < n; j++)
      if (br[j] > 0) col[nz++] = j;
    for (a = 0; a < nz; a++) g[a] = 0.0;
    if (order > 1) for (a = 0; a < nz*nz; a++) h[a] = 0.0;
    for (a = 0; a < nz; a++) {  /* the angle of k = 1 as the loop forms it: the argument, or half */
      j = col[a];
      ang[a] = TS_PI*1.0/L[r]*br[j]*(kind[j] == 2 ? 0.5 : 1.0);
      iang[a] = 1.0/ang[a];
      rc[a] = cos(ang[a]);
      rs[a] = sin(ang[a]);
    }
    xr = TS_PI*1.0*(R[r]/L[r]);
    xc = cos(xr);
    xs = sin(xr);
    if (!order && !ball) {  /* rows of uniform columns alone by a copy of ts_sum0 without the others */
      int mixed = 0;
      for (a = 0; a < nz; a++) mixed |= kind[col[a]] != 0 || !(ang[a] >= 1e-4);
      P[r] = R[r]/L[r] + (mixed ? ts_sum0(nz, Kr, br, col, kind, tnt, tno, L[r], R[r], ang, iang, rc, rs, xc, xs, 1)
                                : ts_sum0(nz, Kr, br, col, kind, tnt, tno, L[r], R[r], ang, iang, rc, rs, xc, xs, 0));
      continue;
    }
    for (k = 1; k <= Kr; k++) {
      double tau = TS_PI*(double)k/L[r], x = TS_PI*(double)k*(R[r]/L[r]), s, ik = 1.0/(double)k;
      /* sin and cos of k times each angle by rotation, taken afresh every TS_SYNC terms: the
         rotation's rounding (about one ulp a step) never builds up past TS_SYNC ulp; at k = 1
         they are those of the angles above */
      if (k == 1) {
        for (a = 0; a < nz; a++) {
          sk[a] = rs[a];
          ck[a] = rc[a];
        }
        ks = xs;
        kc = xc;
      } else if ((k - 1) % TS_SYNC == 0 || (ball && Kr > TS_ROTATE)) {
        for (a = 0; a < nz; a++) {  /* the argument as ts_cf forms it */
          double t = tau*br[col[a]]*(kind[col[a]] == 2 ? 0.5 : 1.0);
          sk[a] = sin(t);
          ck[a] = cos(t);
        }
        ks = sin(x);
        kc = cos(x);
      } else {
        double t0;
        for (a = 0; a < nz; a++) {
          t0 = ck[a]*rc[a] - sk[a]*rs[a];
          sk[a] = sk[a]*rc[a] + ck[a]*rs[a];
          ck[a] = t0;
        }
        t0 = kc*xc - ks*xs;
        ks = ks*xc + kc*xs;
        kc = t0;
      }
      s = ball ? 2.0/((double)k*TS_PI)*(ks - x*kc) : (2.0/TS_PI)*ik*ks;
      for (a = 0; a < nz; a++) {
        j = col[a];
        if (kind[j] == 3) ts_tn(tnt + tno[j], tau*br[j], sk[a], ck[a], order, &phi[a], &d1[a], &d2[a]);
        else ts_cf(kind[j], tau*br[j], sk[a], ck[a], ik*iang[a], order, &phi[a], &d1[a], &d2[a]);
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

/* Rows.split's dropping of the smallest terms (see exact_series._split): out, the bound on P's
   change per row, and the gradient's bound per entry.  var, peak: per column. */
void ts_split(int m, int n, const double *b, const double *var, const double *peak, double budget,
              double *out, double *dropped, double *gerr) {
  int r, i, j, ord[TS_MAXN];
  for (r = 0; r < m; r++) {
    const double *br = b + (long)r*n;
    double *orow = out + (long)r*n, *grow = gerr + (long)r*n;
    double S, S3, cv, var_e = 0.0, b1, b2, b3;
    int count = 0, nan = 0, t0 = -1, t1 = -1, t2 = -1, low = 0;
    /* the three last and the first of the stable ascending order in one pass: the whole order is
       needed only where the first is dropped (most rows keep every column) */
    for (i = 0; i < n; i++) {
      double v = br[i];
      nan |= v != v;
      if (v < br[low]) low = i;
      if (t0 < 0 || v >= br[t0]) {
        t2 = t1;
        t1 = t0;
        t0 = i;
      } else if (t1 < 0 || v >= br[t1]) {
        t2 = t1;
        t1 = i;
      } else if (t2 < 0 || v >= br[t2])
        t2 = i;
    }
    b1 = br[t0];
    b2 = br[t1];
    b3 = br[t2];
    S = 2.0*peak[t0]*peak[t1]/(b1*b2 > 1e-300 ? b1*b2 : 1e-300);
    S3 = 4.0*peak[t0]*peak[t1]*peak[t2]/(b1*b2*b3 > 1e-300 ? b1*b2*b3 : 1e-300);
    cv = 0.0;
    if (nan || br[low]*br[low]*var[low]*S <= budget) {
      for (i = 0; i < n; i++) {  /* ascending, stable: each column's rank, counted without branches */
        int rank = 0;
        double v = br[i];
        for (j = 0; j < i; j++) rank += br[j] <= v;
        for (j = i + 1; j < n; j++) rank += br[j] < v;
        ord[rank] = i;
      }
      if (nan)  /* no order of ranks then: an insertion sort's order */
        for (i = 0; i < n; i++) {
          int x = i;
          for (j = i; j > 0 && br[ord[j - 1]] > br[x]; j--) ord[j] = ord[j - 1];
          ord[j] = x;
        }
      for (i = 0; i < n - 2; i++) {  /* the cumulative variance is increasing: the dropped are a prefix */
        double next = cv + br[ord[i]]*br[ord[i]]*var[ord[i]];
        if (!(next*S <= budget)) break;
        cv = next;
        count = i + 1;
      }
    }
    var_e = count > 0 ? cv : 0.0;
    for (i = 0; i < n; i++) orow[i] = br[i];
    for (i = 0; i < count; i++) orow[ord[i]] = 0.0;
    dropped[r] = var_e*S;
    for (i = 0; i < n; i++)
      grow[i] = orow[i] == 0.0 ? (br[i] > 0 ? 2.0*br[i]*br[i]*var[i]*S : 0.0) : 2.0*br[i]*(var_e*S3);
  }
}

/* exact_closed._spline: F(x) of a sum of mp uniforms of half-widths beta, its gradient g and
   Hessian h in ln beta (order 1, 2), and the rounding bound (returned). */
static double ts_spline(int mp, const double *beta, double x, int order, double *F, double *g, double *h) {
  int q, i, j, nq = 1 << mp;
  double D = 1.0, Fs = 0.0, big = 0.0, sb[5], G[5], Q[25];
  for (i = 0; i < mp; i++) D *= (double)(i + 1)*2.0*beta[i];
  for (i = 0; i < mp; i++) { G[i] = 0.0; for (j = 0; j < mp; j++) Q[i*mp + j] = 0.0; }
  for (q = 0; q < nq; q++) {
    double sigma = 1.0, dot = 0.0, A, Am, w1, w2;
    for (i = 0; i < mp; i++) {  /* itertools.product's order: the first sign varies slowest */
      double sg = (q >> (mp - 1 - i)) & 1 ? 1.0 : -1.0;
      sigma *= sg;
      sb[i] = sg*beta[i];
      dot += sb[i];
    }
    A = x + dot > 0.0 ? x + dot : 0.0;
    Am = pow(A, mp);
    Fs += sigma*Am/D;
    if (fabs(Am)/D > big) big = fabs(Am)/D;
    if (!order) continue;
    w1 = sigma*mp*pow(A, mp - 1)/D;
    for (i = 0; i < mp; i++) G[i] += w1*sb[i];
    if (order < 2) continue;
    w2 = sigma*mp*(mp - 1)*(A > 0.0 ? pow(A, mp - 2) : 0.0)/D;
    for (i = 0; i < mp; i++)
      for (j = 0; j < mp; j++) Q[i*mp + j] += sb[i]*w2*sb[j];
  }
  *F = Fs;
  if (order >= 1) for (i = 0; i < mp; i++) g[i] = G[i] - Fs;
  if (order >= 2)
    for (i = 0; i < mp; i++)
      for (j = 0; j < mp; j++) h[i*mp + j] = Q[i*mp + j] + (i == j ? G[i] : 0.0) - G[i] - G[j] + Fs;
  return 4.0*mp*nq*DBL_EPSILON*big*(order >= 1 ? mp : 1)*(order >= 2 ? mp : 1);
}

/* exact_closed.closed_rows: ok[r] = 1 where a row of at most five uniform pieces (a triangular
   term is two) has its closed form within tol, with P, G, H (order) and err of that row. */
void ts_closed(int m, int n, const double *b, const double *R, const int *kind, int order, double tol, int *ok,
               double *P, double *G, double *H, double *err) {
  int r, i, j;
  for (r = 0; r < m; r++) {
    const double *br = b + (long)r*n;
    double beta[6], Fa, Fc, ga[5], gc[5], ha[25], hc[25], e;
    int owner[6], mp = 0, good = 1;
    ok[r] = 0;
    for (j = 0; j < n && good; j++) {
      if (br[j] == 0.0) continue;
      if (kind[j] == 0) { beta[mp] = br[j]; owner[mp++] = j; }
      else if (kind[j] == 2) { beta[mp] = 0.5*br[j]; owner[mp++] = j; beta[mp] = 0.5*br[j]; owner[mp++] = j; }
      else good = 0;
      if (mp > 5) good = 0;
    }
    if (!good || mp < 2) continue;
    e = ts_spline(mp, beta, R[r], order, &Fa, ga, ha) + ts_spline(mp, beta, -R[r], order, &Fc, gc, hc);
    if (e > tol) continue;
    ok[r] = 1;
    P[r] = Fa - Fc;
    err[r] = e;
    if (order >= 1) {
      double *Gr = G + (long)r*n;
      for (j = 0; j < n; j++) Gr[j] = 0.0;
      for (i = 0; i < mp; i++) Gr[owner[i]] += ga[i] - gc[i];
    }
    if (order >= 2) {
      double *Hr = H + (long)r*n*n;
      for (j = 0; j < n*n; j++) Hr[j] = 0.0;
      for (i = 0; i < mp; i++)
        for (j = 0; j < mp; j++) Hr[owner[i]*n + owner[j]] += ha[i*mp + j] - hc[i*mp + j];
    }
  }
}

/* The truncation bound of Rows.tail for one row at K (see its docstring): power factors
   (fidx, fmult; nf of them, fmult followed by their far factors a and c: m = min(m, a + c / s0)), normal columns (normal[j] != 0), column drop left out (-1: none). */
static double ts_tail1(int n, const double *br, double L, double K, int nf, const long *fidx,
                       const double *fmult, const int *normal, int drop) {
  int f, j, q = 0;
  double logC = 0.0, C = 1.0, a = 0.0, power = INFINITY, gauss = INFINITY;
  for (f = 0; f < nf; f++) {
    double bf = br[fidx[f]], c, bb, s0, mf;
    if (fidx[f] == drop || !(bf > 0)) continue;
    bb = bf > 1e-300 ? bf : 1e-300;
    /* the factor at the tail's arguments s >= s0 (fmult + nf: a, + 2 nf: c; c / s0 = 0 if c = 0) */
    if (fmult[2*nf + f] != 0.0) {
      s0 = K*TS_PI*bb/L;
      mf = fmult[nf + f] + fmult[2*nf + f]/s0;
    } else mf = fmult[nf + f];
    if (fmult[f] < mf) mf = fmult[f];
    c = mf*L/(TS_PI*bb);
    if (c < K) {  /* the product of the c, its logarithm taken once (and whenever it nears the range's end) */
      q++;
      C *= c;
      if (!(C < 1e250 && C > 1e-250)) { logC += log(C); C = 1.0; }
    }
  }
  for (j = 0; j < n; j++)
    if (normal[j] && j != drop) a += br[j]*br[j];
  a *= (TS_PI/L)*(TS_PI/L)/18.0;
  if (q > 0) power = (2.0/TS_PI)*exp(logC + log(C) - q*log(K) - a*K*K)/q;
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

/* The least of Ks (ascending, nk of them) whose tail bound is <= tol, else the last, for one row;
   *tail: the bound at it. */
static long ts_terms1(int n, const double *br, double L, const double *Ks, int nk, double tol, int nf,
                      const long *fidx, const double *fmult, const int *normal, double *tail) {
  int i;
  *tail = INFINITY;
  for (i = 0; i < nk; i++) {
    *tail = ts_tail1(n, br, L, Ks[i], nf, fidx, fmult, normal, -1);
    if (*tail <= tol) return (long)Ks[i];
  }
  return (long)Ks[nk - 1];
}

/* K[r] = ts_terms1 of row r. */
void ts_terms(int m, int n, const double *b, const double *L, const double *Ks, int nk, double tol, int nf,
              const long *fidx, const double *fmult, const int *normal, long *K) {
  int r;
  double tail;
  for (r = 0; r < m; r++) K[r] = ts_terms1(n, b + (long)r*n, L[r], Ks, nk, tol, nf, fidx, fmult, normal, &tail);
}
/* The whole evaluation of exact_series.probability (order 0) and derivatives (order 1, 2; not
   the rigorous or sphere variants) per row: the smallest terms dropped (rows of >= 3 columns),
   L, the number of terms K (the least of Ks within tol), the closed form for rows of at least
   closed_from terms where it serves, else the series; err = the truncation bound (or the closed
   form's rounding bound) + rounding + what the dropping may change.  bw: the rows after the
   dropping; gerr: the gradient's bound of the dropping. */
int ts_eval(int m, int n, const double *b, const double *R, double tol, const double *Ks, int nk, int order,
            const int *kind, const double *tnt, const long *tno, const double *var, const double *peak, int nf,
            const long *fidx, const double *fmult, const int *normal, double lmargin, double reach,
            long closed_from, double rounding, double *bw, double *P, double *G, double *H, double *err,
            double *gerr, long *K) {
  int r, j, anynormal = 0;
  if (n > TS_MAXN) return 1;
  for (j = 0; j < n; j++) anynormal |= normal[j];
  for (r = 0; r < m; r++) {
    const double *br = b + (long)r*n;
    double *bo = bw + (long)r*n, *go = gerr + (long)r*n, dropped = 0.0, B = 0.0, sq = 0.0, L, tail;
    double *Gr = order >= 1 ? G + (long)r*n : NULL, *Hr = order >= 2 ? H + (long)r*n*n : NULL;
    if (n >= 3 && tol > 0) ts_split(1, n, br, var, peak, 0.25*tol, bo, &dropped, go);
    else for (j = 0; j < n; j++) { bo[j] = br[j]; go[j] = 0.0; }
    for (j = 0; j < n; j++) {
      if (normal[j]) sq += (bo[j]/3.0)*(bo[j]/3.0);
      else B += bo[j];
    }
    if (anynormal) B += reach*sqrt(sq);
    L = R[r] + 0.5*B*lmargin;
    K[r] = ts_terms1(n, bo, L, Ks, nk, tol, nf, fidx, fmult, normal, &tail);
    if (K[r] >= closed_from) {
      int ok = 0;
      double e = 0.0;
      ts_closed(1, n, bo, &R[r], kind, order, tol, &ok, &P[r], Gr, Hr, &e);
      if (ok) {
        err[r] = e + rounding + dropped;
        continue;
      }
    }
    ts_series(1, n, bo, &R[r], &L, &K[r], kind, tnt, tno, order, 0, &P[r], Gr, Hr);
    err[r] = tail + rounding + dropped;  /* the bound at K[r], as ts_terms1 found it */
  }
  return 0;
}
"""
