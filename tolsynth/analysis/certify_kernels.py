"""Compiled contraction of the arc-polygon bound (:class:`tolsynth.analysis.certify_polygon.PolygonSigmaBounds`).

The bound evaluates the six entries of ``V = A W A^T``, a polynomial of degree two in each joint's
``(cos, sin)``, at every tuple of polygon points: the coefficient tensor ``gamma`` (6, 6^k) is
contracted joint by joint with each joint's six monomials at its points.  NumPy does that with a
batched matrix product per joint and a transposed copy between them, over intermediates of
``6^k * 4`` numbers a box (a quarter of a megabyte for six joints), so the search was bound by
memory traffic.  Here one C function contracts box after box in a cache-sized work area, the last
joint first, each output a plain sum of six products in a fixed order: the same sums, rounded as a
dot product of six terms is, which the bound's error term covers (any summation order).  The
boxes' centres (the value found and the direction to halve) read ``A`` and its derivatives from
its own polynomial, compiled likewise (NumPy's broadcast products took a quarter of the Panda's
search).  Without a compiler (or with ``TOLSYNTH_NO_COMPILE=1``) the NumPy path runs.
"""

from __future__ import annotations

import ctypes

import numpy as np

from tolsynth.cbuild import disabled, find_compiler, load_library

__all__ = ["contract", "jet", "lambda_max", "share_order"]

_SOURCE = r"""
/* the loops over the tuples vectorised (each sum still its six products in order: the same bits) */
#pragma GCC optimize("O3", "no-trapping-math")
#include <stdlib.h>
#include <string.h>

/* out[b, e, tuple] = sum over monomials of g[e, m_1, ..., m_k] prod_j V_j[b, p_j, m_j], the tuple's
   flat index with the first joint's point most significant.  V holds, per box, the k joints'
   (p_j, 6) blocks one after the other.  The boxes are taken in `order` (NULL: as given); the
   tensor left after contracting the last joints is kept while the next box has the same points on
   them (a batch of a thousand boxes has a dozen arcs a joint), and every number is computed by the
   same loop, in the same order, as it would be for that box alone: the same bits. */
int ts_contract(int n, int k, const int *p, const double *g, const double *V, const int *order, double *out) {
    if (k < 1 || k > 16) return -2;
    size_t g_size = 6, vstride = 0, P = 1, offs[16], size = 1;
    for (int j = 0; j < k; j++) {
        g_size *= 6;
        offs[j] = vstride;
        vstride += (size_t)p[j] * 6;
        P *= (size_t)p[j];
    }
    double *lv[16] = {0};  /* lv[j]: the tensor after contracting joints k-1 .. j (j >= 1) */
    size_t Rj = g_size / 6, Qj = 1;
    for (int j = k - 1; j >= 1; j--) {
        size = Rj * (size_t)p[j] * Qj;
        lv[j] = malloc(sizeof(double) * size);
        if (!lv[j]) { for (int i = j + 1; i < k; i++) free(lv[i]); return -1; }
        Qj *= (size_t)p[j];
        Rj /= 6;
    }
    int prev = -1;
    for (int i = 0; i < n; i++) {
        int b = order ? order[i] : i;
        int from = k - 1;  /* the first joint (from the last) whose points differ from the previous box's */
        if (prev >= 0)
            while (from >= 1 && memcmp(V + (size_t)b * vstride + offs[from], V + (size_t)prev * vstride + offs[from],
                                       sizeof(double) * 6 * (size_t)p[from]) == 0)
                from--;
        prev = b;
        size_t R = g_size / 6, Q = 1;  /* before joint j: src (R, 6, Q) */
        for (int j = k - 1; j > from; j--) {
            Q *= (size_t)p[j];
            R /= 6;
        }
        for (int j = from; j >= 0; j--) {
            int pj = p[j];
            const double *Vj = V + (size_t)b * vstride + offs[j];
            const double *src = (j == k - 1) ? g : lv[j + 1];
            double *dst = (j == 0) ? out + (size_t)b * 6 * P : lv[j];
            if (Q == 1 && pj <= 64) {  /* the first joint: across its points, each sum in the same order */
                double Vt[6][64];
                for (int q = 0; q < pj; q++)
                    for (int m = 0; m < 6; m++) Vt[m][q] = Vj[(size_t)q * 6 + m];
                for (size_t r = 0; r < R; r++) {
                    const double *s0 = src + r * 6;
                    double *d = dst + r * (size_t)pj;
                    for (int q = 0; q < pj; q++) d[q] = s0[0] * Vt[0][q];
                    for (int m = 1; m < 6; m++)
                        for (int q = 0; q < pj; q++) d[q] += s0[m] * Vt[m][q];
                }
                Q *= (size_t)pj;
                R /= 6;
                continue;
            }
            for (size_t r = 0; r < R; r++) {
                const double *s0 = src + r * 6 * Q;
                for (int q = 0; q < pj; q++) {
                    const double *v = Vj + (size_t)q * 6;
                    double *d = dst + (r * (size_t)pj + (size_t)q) * Q;
                    double v0 = v[0], v1 = v[1], v2 = v[2], v3 = v[3], v4 = v[4], v5 = v[5];
                    for (size_t t = 0; t < Q; t++) {
                        double acc = s0[t] * v0;
                        acc += s0[Q + t] * v1;
                        acc += s0[2 * Q + t] * v2;
                        acc += s0[3 * Q + t] * v3;
                        acc += s0[4 * Q + t] * v4;
                        acc += s0[5 * Q + t] * v5;
                        d[t] = acc;
                    }
                }
            }
            Q *= (size_t)pj;
            R /= 6;
        }
    }
    for (int j = 1; j < k; j++) free(lv[j]);
    return 0;
}

/* The largest eigenvalue bound of certify_polygon.lambda_max_bound_entries (reduce_last) for each box
   of T tuples g[b, 0..5, t] (entries 00 11 22 01 02 12), statement for statement its NumPy
   arithmetic: the characteristic polynomial's coefficients moved by their rounding, a candidate
   proven above every root by the cubic and its first two derivatives.  The candidate only rises
   (a value proven above the roots stays so further up: the third derivative is 6), from the
   tuples' closed-form eigenvalues where a tuple does not prove it (raised a little where that
   estimate falls short).  out[b] before its last
   rounding up; ok[b] = 0 where some tuple proved nothing (the caller's NumPy path decides). */
#include <math.h>
#define U_ 1.1102230246251565e-16
static int above(double lam, double a1, double a2, double a3) {
    double aa1 = fabs(a1), aa2 = fabs(a2), aa3 = fabs(a3);
    double mag = ((lam + aa1) * lam + aa2) * lam + aa3;
    double p = ((lam - a1) * lam + a2) * lam - a3;
    double dp = (3.0 * lam - 2.0 * a1) * lam + a2;
    double ddp = 3.0 * lam - a1;
    /* & rather than &&: no branches, so the loops that call it vectorise */
    return (p > 16 * U_ * mag) & (dp > 16 * U_ * (3.0 * lam * lam + 2.0 * aa1 * lam + aa2))
        & (ddp > 16 * U_ * (3.0 * lam + aa1));
}
static double estimate(double g00, double g11, double g22, double g01, double g02, double g12) {
    double q = (g00 + g11 + g22) / 3.0;
    double off = g01 * g01 + g02 * g02 + g12 * g12;
    double d0 = g00 - q, d1 = g11 - q, d2 = g22 - q;
    double p = (d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * off) / 6.0;
    p = sqrt(p > 0.0 ? p : 0.0);
    double det = d0 * (d1 * d2 - g12 * g12) - g01 * (g01 * d2 - g12 * g02) + g02 * (g01 * g12 - d1 * g02);
    double r = p > 0 ? det / (2.0 * p * p * p) : 0.0;
    r = r < -1.0 ? -1.0 : (r > 1.0 ? 1.0 : r);
    return q + 2.0 * p * cos(acos(r) / 3.0);
}
static double candidate(double L, double s) {
    double r = L / s;
    return (r > 0.0 ? r : 0.0) * (1.0 + 1e-12) + 1e-13;
}
#define LM_CHUNK 512
#define LM_BLOCK 32
void ts_lambda_max(int n, int T, const double *g, const double *err, double *out, int *ok) {
    /* Each chunk of tuples in two passes: first every tuple's scaled coefficients (independent
       of one another: vectorised), then the candidate checked block by block at the running L,
       which only changes where a tuple does not prove it; a block where every tuple proves it
       (the common case) is checked as one vector loop and its largest value taken, else the block
       is gone through tuple by tuple as before.  The values and their order of use are those of
       the plain loop: the same bits. */
    double S[LM_CHUNK], A1[LM_CHUNK], A2[LM_CHUNK], A3[LM_CHUNK], Vb[LM_BLOCK];
    int Fb[LM_BLOCK];
    for (int b = 0; b < n; b++) {
        const double *G = g + (size_t)b * 6 * T, *e = err + (size_t)b * 6;
        double frob = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2] + 2.0 * (e[3] * e[3] + e[4] * e[4] + e[5] * e[5]));
        double L = -INFINITY, best = -INFINITY;
        int good = 1;
        for (int t0 = 0; t0 < T && good; t0 += LM_CHUNK) {
            int m = T - t0 < LM_CHUNK ? T - t0 : LM_CHUNK;
            const double *G0 = G + t0, *G1 = G + T + t0, *G2 = G + 2 * T + t0, *G3 = G + 3 * T + t0,
                         *G4 = G + 4 * T + t0, *G5 = G + 5 * T + t0;
            for (int i = 0; i < m; i++) {
                double g00 = G0[i], g11 = G1[i], g22 = G2[i], g01 = G3[i], g02 = G4[i], g12 = G5[i];
                double c1 = (g00 + g11 + g22) * (1.0 + 8.0 * U_);
                double p0 = g00 * g11, p1 = g01 * g01, p2 = g00 * g22, p3 = g02 * g02, p4 = g11 * g22, p5 = g12 * g12;
                double c2 = p0 - p1 + p2 - p3 + p4 - p5;
                double s2 = 0.0 + fabs(p0);
                s2 = s2 + fabs(p1); s2 = s2 + fabs(p2); s2 = s2 + fabs(p3); s2 = s2 + fabs(p4); s2 = s2 + fabs(p5);
                c2 = c2 - 8.0 * U_ * s2;
                double r0 = g00 * (g11 * g22), r1 = g00 * (g12 * g12), r2 = g01 * (g01 * g22), r3 = g01 * (g12 * g02),
                       r4 = g02 * (g01 * g12), r5 = g02 * (g11 * g02);
                double c3 = r0 - r1 - r2 + r3 + r4 - r5;
                double s3 = 0.0 + fabs(r0);
                s3 = s3 + fabs(r1); s3 = s3 + fabs(r2); s3 = s3 + fabs(r3); s3 = s3 + fabs(r4); s3 = s3 + fabs(r5);
                c3 = c3 + 12.0 * U_ * s3;
                double s = fabs(c1) > 1e-100 ? fabs(c1) : 1.0;
                S[i] = s;
                A1[i] = c1 / s;
                A2[i] = c2 / (s * s);
                A3[i] = c3 / (s * s * s);
            }
            for (int i0 = 0; i0 < m && good; i0 += LM_BLOCK) {
                int nb = m - i0 < LM_BLOCK ? m - i0 : LM_BLOCK;
                for (int i = 0; i < nb; i++) {
                    double s = S[i0 + i], x = candidate(L, s);
                    double v = x * s * (1.0 + 8.0 * U_) + frob * (1.0 + 8.0 * U_);
                    Fb[i] = above(x, A1[i0 + i], A2[i0 + i], A3[i0 + i]) & (v <= INFINITY);
                    Vb[i] = v;
                }
                int all = 1;
                for (int i = 0; i < nb; i++) all &= Fb[i];
                if (all) {
                    for (int i = 0; i < nb; i++)
                        if (Vb[i] > best) best = Vb[i];
                    continue;
                }
                for (int i = i0; i < i0 + nb; i++) {
                    double s = S[i], a1 = A1[i], a2 = A2[i], a3 = A3[i];
                    double x = candidate(L, s);
                    if (!above(x, a1, a2, a3)) {
                        int t = t0 + i;
                        double lam = estimate(G[t], G[T + t], G[2 * T + t], G[3 * T + t], G[4 * T + t], G[5 * T + t]);
                        if (!(lam <= INFINITY)) { good = 0; break; }
                        if (lam > L) L = lam;
                        x = candidate(L, s);
                        /* the closed form loses digits where the top eigenvalues nearly meet (a nearly
                           isotropic V): raised a little at a time, as the NumPy path's last resort does */
                        for (int r = 0; r < 14 && !above(x, a1, a2, a3); r++) x = x * (1.0 + 1e-12 * (double)(1L << (3 * r))) + 1e-300;
                        if (!above(x, a1, a2, a3)) { good = 0; break; }
                        if (x * s > L) L = x * s;
                    }
                    double v = x * s * (1.0 + 8.0 * U_) + frob * (1.0 + 8.0 * U_);
                    if (!(v <= INFINITY)) { good = 0; break; }
                    if (v > best) best = v;
                }
            }
        }
        out[b] = best;
        ok[b] = good;
    }
}
/* The trigonometric polynomial A(t) (na entries, each a polynomial of degree one in every joint's
   (1, cos, sin), the first joint's index most significant in T's (na, 3^k) layout) at n points,
   cs[b, j] = (cos t_j, sin t_j), and its derivative along every joint (deriv != 0): forward mode,
   the last joint first, every step in place (output r reads its inputs 3r..3r+2).  A (n, na),
   dA (n, k, na).  Floating point: the centre's value and the direction to halve, not a bound. */
int ts_jet(int n, int k, int na, const double *T, const double *cs, int deriv, double *A, double *dA) {
    size_t top = (size_t)na;
    for (int j = 0; j < k - 1; j++) top *= 3;  /* na * 3^(k-1): after the last joint */
    double *buf = malloc(sizeof(double) * top * (size_t)(deriv ? k + 1 : 1));
    if (!buf) return -1;
    double *val = buf;
    for (int b = 0; b < n; b++) {
        const double *c = cs + (size_t)b * 2 * k;
        size_t len = top;  /* the entries left after the joint being contracted */
        double cj = c[2 * (k - 1)], sj = c[2 * (k - 1) + 1];
        double *g0 = deriv ? buf + top * (size_t)k : NULL;  /* the last joint's derivative */
        for (size_t r = 0; r < len; r++) {
            const double *x = T + 3 * r;
            val[r] = x[0] + x[1] * cj + x[2] * sj;
            if (deriv) g0[r] = x[2] * cj - x[1] * sj;
        }
        for (int j = k - 2; j >= 0; j--) {
            cj = c[2 * j];
            sj = c[2 * j + 1];
            len /= 3;
            if (deriv) {
                double *gj = buf + top * (size_t)(j + 1);
                for (size_t r = 0; r < len; r++) {
                    const double *x = val + 3 * r;
                    gj[r] = x[2] * cj - x[1] * sj;
                }
                for (int i = j + 1; i < k; i++) {
                    double *gi = buf + top * (size_t)(i + 1);
                    for (size_t r = 0; r < len; r++) {
                        const double *x = gi + 3 * r;
                        gi[r] = x[0] + x[1] * cj + x[2] * sj;
                    }
                }
            }
            for (size_t r = 0; r < len; r++) {
                const double *x = val + 3 * r;
                val[r] = x[0] + x[1] * cj + x[2] * sj;
            }
        }
        memcpy(A + (size_t)b * na, val, sizeof(double) * na);
        if (deriv)
            for (int j = 0; j < k; j++) memcpy(dA + ((size_t)b * k + j) * na, buf + top * (size_t)(j + 1), sizeof(double) * na);
    }
    free(buf);
    return 0;
}
"""

_state: dict = {}


def _library():
    if disabled():
        return None
    cc = find_compiler()
    if cc is None:
        return None
    if cc not in _state:
        try:
            lib, _ = load_library(
                _SOURCE, "tolsynth_polygon", cc, ("ts_contract", "ts_lambda_max", "ts_jet"), native=True
            )
            fn = lib.ts_contract
            f64 = np.ctypeslib.ndpointer(np.float64, flags="C_CONTIGUOUS")
            i32 = np.ctypeslib.ndpointer(np.int32, flags="C_CONTIGUOUS")
            fn.argtypes = [ctypes.c_int, ctypes.c_int, i32, f64, f64, i32, f64]
            fn.restype = ctypes.c_int
            lm = lib.ts_lambda_max
            lm.argtypes = [ctypes.c_int, ctypes.c_int, f64, f64, f64, i32]
            lm.restype = None
            jt = lib.ts_jet
            jt.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int, f64, f64, ctypes.c_int, f64, f64]
            jt.restype = ctypes.c_int
            _state[cc] = (fn, lm, jt)
        except (OSError, AttributeError, RuntimeError):
            _state[cc] = None
    return _state[cc]


def share_order(V: list, n: int) -> np.ndarray:
    """An order of the boxes (``V[j]`` (n, p_j, 6), each joint's monomials at its points) that puts
    boxes with the same points on the last joints next to each other: the contraction takes the
    last joint first and keeps what consecutive boxes share (where every point is the same bits).
    Sorted by each joint's first and last point, the last joint first; ``n`` boxes as given when
    there are no joints (a box halved on its only joint)."""
    if not V:
        return np.arange(n)
    return np.lexsort([x for v in V for x in (v[:, 0, 1], v[:, 0, 2], v[:, -1, 1], v[:, -1, 2])])


def contract(g: np.ndarray, V: list):
    """``g`` (6, 6^k) contracted with each joint's monomials ``V[j]`` (n, p_j, 6): shape
    (n, 6, prod p_j), the tuples with the first joint's point most significant; None when the
    compiled kernel is not available (the caller then runs its NumPy path)."""
    lib = _library()
    if lib is None:
        return None
    fn = lib[0]
    k = len(V)
    n = V[0].shape[0]
    p = np.array([v.shape[1] for v in V], dtype=np.int32)
    Vc = np.ascontiguousarray(np.concatenate([v.reshape(n, -1) for v in V], axis=1), dtype=np.float64)
    out = np.empty((n, 6, int(np.prod(p))))
    order = np.ascontiguousarray(share_order(V, n), dtype=np.int32)
    if n and fn(n, k, p, np.ascontiguousarray(g, dtype=np.float64), Vc, order, out) != 0:
        raise MemoryError("the polygon contraction could not allocate its work area")
    return out


def lambda_max(g: np.ndarray, err: np.ndarray):
    """Per box, the largest over its tuples of the bound of
    :func:`tolsynth.analysis.certify_polygon.lambda_max_bound_entries` before its last rounding up:
    ``g`` (n, 6, T) the tuples' entries, ``err`` (n, 6) their common error.  Returns ``(out, ok)``
    (``ok`` False where a tuple proved nothing: the caller bounds that box itself), or None
    without the compiled kernel."""
    lib = _library()
    if lib is None:
        return None
    n, _, T = g.shape
    out = np.empty(n)
    ok = np.zeros(n, dtype=np.int32)
    if n:
        lib[1](n, T, np.ascontiguousarray(g, dtype=np.float64), np.ascontiguousarray(err, dtype=np.float64), out, ok)
    return out, ok.astype(bool)


def jet(T: np.ndarray, t: np.ndarray, derivatives: bool = True):
    """``A`` (n, na) at the angles ``t`` (n, k) of the polynomial ``T`` (na, 3^k, each joint's
    (1, cos, sin), the first joint's index most significant) and, with ``derivatives``, its
    derivative along each joint (n, k, na), else None; or None without the compiled kernel."""
    lib = _library()
    if lib is None:
        return None
    n, k = t.shape
    na = T.shape[0]
    cs = np.ascontiguousarray(np.stack([np.cos(t), np.sin(t)], axis=-1))
    A = np.empty((n, na))
    dA = np.empty((n, k, na)) if derivatives else np.empty(0)
    if n and lib[2](n, k, na, np.ascontiguousarray(T, dtype=np.float64), cs, int(derivatives), A, dA) != 0:
        raise MemoryError("the polynomial's evaluation could not allocate its work area")
    return A, dA if derivatives else None
