"""Compiled contraction of the arc-polygon bound (:class:`tolsynth.analysis.certify_bounds.PolygonSigmaBounds`).

The bound evaluates the six entries of ``V = A W A^T``, a polynomial of degree two in each joint's
``(cos, sin)``, at every tuple of polygon points: the coefficient tensor ``gamma`` (6, 6^k) is
contracted joint by joint with each joint's six monomials at its points.  NumPy does that with a
batched matrix product per joint and a transposed copy between them, over intermediates of
``6^k * 4`` numbers a box (a quarter of a megabyte for six joints), so the search was bound by
memory traffic.  Here one C function contracts box after box in a cache-sized work area, the last
joint first, each output a plain sum of six products in a fixed order: the same sums, rounded as a
dot product of six terms is, which the bound's error term covers (any summation order).  Without
a compiler (or with ``TOLSYNTH_NO_COMPILE=1``) the NumPy path runs.
"""

from __future__ import annotations

import ctypes

import numpy as np

from tolsynth.cbuild import disabled, find_compiler, load_library

__all__ = ["contract"]

_SOURCE = r"""
#include <stdlib.h>
#include <string.h>

/* out[b, e, tuple] = sum over monomials of g[e, m_1, ..., m_k] prod_j V_j[b, p_j, m_j], the tuple's
   flat index with the first joint's point most significant.  V holds, per box, the k joints'
   (p_j, 6) blocks one after the other. */
int ts_contract(int n, int k, const int *p, const double *g, const double *V, double *out) {
    size_t g_size = 6, big = 6, vstride = 0, P = 1;
    for (int j = 0; j < k; j++) {
        g_size *= 6;
        big *= (size_t)(p[j] > 6 ? p[j] : 6);
        vstride += (size_t)p[j] * 6;
        P *= (size_t)p[j];
    }
    double *b1 = malloc(sizeof(double) * big), *b2 = malloc(sizeof(double) * big);
    if (!b1 || !b2) { free(b1); free(b2); return -1; }
    for (int b = 0; b < n; b++) {
        const double *src = g;
        size_t R = g_size / 6, Q = 1;      /* src: (R, 6, Q) */
        size_t voff = vstride;
        for (int j = k - 1; j >= 0; j--) {
            int pj = p[j];
            voff -= (size_t)pj * 6;
            const double *Vj = V + (size_t)b * vstride + voff;
            double *dst = (j == 0) ? out + (size_t)b * 6 * P : (src == b1 ? b2 : b1);
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
            src = dst;
            Q *= (size_t)pj;
            R /= 6;
        }
    }
    free(b1); free(b2);
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
            lib, _ = load_library(_SOURCE, "tolsynth_polygon", cc, ("ts_contract",))
            fn = lib.ts_contract
            f64 = np.ctypeslib.ndpointer(np.float64, flags="C_CONTIGUOUS")
            i32 = np.ctypeslib.ndpointer(np.int32, flags="C_CONTIGUOUS")
            fn.argtypes = [ctypes.c_int, ctypes.c_int, i32, f64, f64, f64]
            fn.restype = ctypes.c_int
            _state[cc] = fn
        except (OSError, AttributeError, RuntimeError):
            _state[cc] = None
    return _state[cc]


def contract(g: np.ndarray, V: list):
    """``g`` (6, 6^k) contracted with each joint's monomials ``V[j]`` (n, p_j, 6): shape
    (n, 6, prod p_j), the tuples with the first joint's point most significant; None when the
    compiled kernel is not available (the caller then runs its NumPy path)."""
    fn = _library()
    if fn is None:
        return None
    k = len(V)
    n = V[0].shape[0]
    p = np.array([v.shape[1] for v in V], dtype=np.int32)
    Vc = np.ascontiguousarray(np.concatenate([v.reshape(n, -1) for v in V], axis=1), dtype=np.float64)
    out = np.empty((n, 6, int(np.prod(p))))
    if n and fn(n, k, p, np.ascontiguousarray(g, dtype=np.float64), Vc, out) != 0:
        raise MemoryError("the polygon contraction could not allocate its work area")
    return out
