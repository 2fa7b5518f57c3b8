"""Compiled interval evaluation: the extensions of :mod:`tolsynth.analysis.interval_ops` in C.

One C interpreter, compiled once (:mod:`tolsynth.cbuild`), runs the single-assignment program of an
:class:`tolsynth.analysis.intervals.IntervalFunction` over a batch of boxes, a few boxes at a time
so that the work vector stays in cache.  Each operation is the NumPy extension's arithmetic
statement for statement: the same outward steps (two ulp for ``+ - * / sqrt``, a relative
``2^-49`` plus a small absolute term for the library functions), the same reading of a NaN end
point as "no information" (the minimum and maximum of two end points propagate NaN, as
``np.minimum`` does), the same cases where a box stops being regular.  The library functions are
the C library's (glibc: within one ulp), where NumPy may use its own: both lie well inside the
widening.  Graphs with an operation the interpreter lacks (``pow``, ``tan``, the hyperbolic
functions, ``erf``) run the NumPy extensions, as do all graphs when compilation is turned off
(``TOLSYNTH_NO_COMPILE=1``) or no compiler is found.
"""

from __future__ import annotations

import ctypes

import casadi as ca
import numpy as np

from tolsynth.analysis.interval_ops import MULC_NEG, MULC_POS
from tolsynth.cbuild import disabled, find_compiler, load_library

__all__ = ["CODES", "compiled_program", "evaluate_compiled", "library"]

#: operation -> the interpreter's code (the NumPy extension of the same operation in interval_ops)
CODES = {
    ca.OP_ADD: 1,
    ca.OP_SUB: 2,
    ca.OP_MUL: 3,
    ca.OP_DIV: 4,
    ca.OP_INV: 5,
    ca.OP_NEG: 6,
    ca.OP_TWICE: 7,
    ca.OP_FABS: 8,
    ca.OP_SQ: 9,
    ca.OP_SQRT: 10,
    ca.OP_EXP: 11,
    ca.OP_LOG: 12,
    ca.OP_SIN: 13,
    ca.OP_COS: 14,
    ca.OP_ASIN: 15,
    ca.OP_ACOS: 16,
    ca.OP_ATAN: 17,
    ca.OP_ATAN2: 18,
    ca.OP_FMIN: 19,
    ca.OP_FMAX: 20,
    ca.OP_HYPOT: 21,
    ca.OP_LT: 22,
    ca.OP_LE: 23,
    ca.OP_EQ: 24,
    ca.OP_NE: 25,
    ca.OP_NOT: 26,
    ca.OP_AND: 27,
    ca.OP_OR: 28,
    ca.OP_IF_ELSE_ZERO: 29,
    ca.OP_SIGN: 30,
    ca.OP_COPYSIGN: 31,
    ca.OP_FLOOR: 32,
    ca.OP_CEIL: 33,
    MULC_POS: 34,
    MULC_NEG: 35,
}

#: boxes interpreted together (the work vector: 16 bytes a node a box)
BLOCK = 16

_SOURCE = r"""
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

#define NB %(block)d
#define ULP2 0x1p-51
#define SUBN 0x1p-1074
#define REL 0x1p-49
#define ABSW 0x1p-1000
#define TRIG_WIDE 0x1p40
#define PI_D 3.141592653589793
#define TWO_PI (2.0 * PI_D)

static inline double nmin(double a, double b) { return (a < b || a != a) ? a : b; }
static inline double nmax(double a, double b) { return (a > b || a != a) ? a : b; }
static inline double dn(double x) { double w = fabs(x); w *= ULP2; w += SUBN; return x - w; }
static inline double up(double x) { double w = fabs(x); w *= ULP2; w += SUBN; return x + w; }
static inline double tdn(double x) { double w = fabs(x) * REL + ABSW; return x - w; }
static inline double tup(double x) { double w = fabs(x) * REL + ABSW; return x + w; }
static inline double tdnm(double x, double m) { double w = fabs(x) * REL + ABSW; w = w + nmax(m, 1.0) * 0x1p-52; return x - w; }
static inline double tupm(double x, double m) { double w = fabs(x) * REL + ABSW; w = w + nmax(m, 1.0) * 0x1p-52; return x + w; }
static inline double nclip(double x, double lo, double hi) { return x != x ? x : (x < lo ? lo : (x > hi ? hi : x)); }
static inline int hits(double al, double ah, double phase) {
    double mag = nmax(fabs(al), fabs(ah));
    double slack = 1e-9 * (1.0 + mag);
    double k = ceil((al - slack - phase) / TWO_PI);
    return phase + k * TWO_PI <= ah + slack;
}
static inline double csign(double x) { return x > 0.0 ? 1.0 : (x < 0.0 ? -1.0 : x); }

static inline __attribute__((always_inline)) void one(const int code, double al, double ah, double bl, double bh,
        double k, double *lo, double *hi, int *rg, double PI_UP, double HPI_UP) {
    double rl, rh;
    switch (code) {
            case 1: rl = dn(al + bl); rh = up(ah + bh); break;
            case 2: rl = dn(al - bh); rh = up(ah - bl); break;
            case 3: {
                double p1 = al * bl, p2 = al * bh, p3 = ah * bl, p4 = ah * bh;
                if (p1 != p1 || p2 != p2 || p3 != p3 || p4 != p4) { rl = rh = NAN; break; } /* as nmin/nmax */
                double m1 = p1 < p2 ? p1 : p2, m2 = p3 < p4 ? p3 : p4, M1 = p1 > p2 ? p1 : p2, M2 = p3 > p4 ? p3 : p4;
                rl = dn(m1 < m2 ? m1 : m2);
                rh = up(M1 > M2 ? M1 : M2);
                break;
            }
            case 5: bl = al; bh = ah; al = 1.0; ah = 1.0; /* fall through: 1 / a */
            case 4: {
                int zero = (bl <= 0.0) && (bh >= 0.0);
                double q1 = al / bl, q2 = al / bh, q3 = ah / bl, q4 = ah / bh;
                rl = dn(nmin(nmin(q1, q2), nmin(q3, q4)));
                rh = up(nmax(nmax(q1, q2), nmax(q3, q4)));
                if (zero) { *rg = 0; rl = -INFINITY; rh = INFINITY; }
                break;
            }
            case 6: rl = -ah; rh = -al; break;
            case 7: rl = 2.0 * al; rh = 2.0 * ah; break;
            case 8: rl = al >= 0.0 ? al : (ah <= 0.0 ? -ah : 0.0); rh = nmax(fabs(al), fabs(ah)); break;
            case 9: {
                double ml = al >= 0.0 ? al : (ah <= 0.0 ? -ah : 0.0), mh = nmax(fabs(al), fabs(ah));
                rl = nmax(dn(ml * ml), 0.0); rh = up(mh * mh);
                break;
            }
            case 10:
                if (al < 0.0) *rg = 0;
                rl = nmax(dn(sqrt(nmax(al, 0.0))), 0.0); rh = up(sqrt(nmax(ah, 0.0)));
                if (ah < 0.0) rl = rh = NAN;
                break;
            case 11: rl = nmax(tdn(exp(al)), 0.0); rh = tup(exp(ah)); break;
            case 12:
                if (al <= 0.0) *rg = 0;
                rl = al > 0.0 ? tdn(log(nmax(al, 0.0))) : -INFINITY; rh = tup(log(nmax(ah, 0.0)));
                if (ah <= 0.0) rl = rh = NAN;
                break;
            case 13: case 14: {
                double mag = nmax(fabs(al), fabs(ah));
                double vl = code == 13 ? sin(al) : cos(al), vh = code == 13 ? sin(ah) : cos(ah);
                double pmax = code == 13 ? PI_D / 2.0 : 0.0, pmin = code == 13 ? -PI_D / 2.0 : PI_D;
                rl = nmax(tdnm(nmin(vl, vh), mag), -1.0); rh = nmin(tupm(nmax(vl, vh), mag), 1.0);
                int wide = !((ah - al < TWO_PI) && (mag < TRIG_WIDE));
                if (wide || hits(al, ah, pmax)) rh = 1.0;
                if (wide || hits(al, ah, pmin)) rl = -1.0;
                break;
            }
            case 15:
                if (al < -1.0 || ah > 1.0) *rg = 0;
                rl = nmax(tdn(asin(nclip(al, -1.0, 1.0))), -HPI_UP); rh = nmin(tup(asin(nclip(ah, -1.0, 1.0))), HPI_UP);
                if (ah < -1.0 || al > 1.0) rl = rh = NAN;
                break;
            case 16:
                if (al < -1.0 || ah > 1.0) *rg = 0;
                rl = nmax(tdn(acos(nclip(ah, -1.0, 1.0))), 0.0); rh = nmin(tup(acos(nclip(al, -1.0, 1.0))), PI_UP);
                if (ah < -1.0 || al > 1.0) rl = rh = NAN;
                break;
            case 17: rl = nmax(tdn(atan(al)), -HPI_UP); rh = nmin(tup(atan(ah)), HPI_UP); break;
            case 18: {
                int cut = (bl <= 0.0) && (al <= 0.0) && (ah >= 0.0);
                if (cut) *rg = 0;
                double t0 = atan2(al, bl), t1 = atan2(al, bh), t2 = atan2(ah, bl), t3 = atan2(ah, bh);
                rl = nmax(tdn(nmin(nmin(t0, t1), nmin(t2, t3))), -PI_UP);
                rh = nmin(tup(nmax(nmax(t0, t1), nmax(t2, t3))), PI_UP);
                if (cut) { rl = -PI_UP; rh = PI_UP; }
                break;
            }
            case 19: rl = nmin(al, bl); rh = nmin(ah, bh); break;
            case 20: rl = nmax(al, bl); rh = nmax(ah, bh); break;
            case 21: {
                double xl = al >= 0.0 ? al : (ah <= 0.0 ? -ah : 0.0), xh = nmax(fabs(al), fabs(ah));
                double yl = bl >= 0.0 ? bl : (bh <= 0.0 ? -bh : 0.0), yh = nmax(fabs(bl), fabs(bh));
                rl = nmax(tdn(hypot(xl, yl)), 0.0); rh = tup(hypot(xh, yh));
                break;
            }
            case 22: case 23: case 24: case 25: case 26: case 27: case 28: {
                int t, f;
                int an = al > 0.0 || ah < 0.0, az = al == 0.0 && ah == 0.0;
                int bn = bl > 0.0 || bh < 0.0, bz = bl == 0.0 && bh == 0.0;
                int eq = al == ah && bl == bh && al == bl, apart = ah < bl || al > bh;
                switch (code) {
                case 22: t = ah < bl; f = al >= bh; break;
                case 23: t = ah <= bl; f = al > bh; break;
                case 24: t = eq; f = apart; break;
                case 25: t = apart; f = eq; break;
                case 26: t = az; f = an; break;
                case 27: t = an && bn; f = az || bz; break;
                default: t = an || bn; f = az && bz; break;
                }
                if (!t && !f) *rg = 0;
                rl = t ? 1.0 : 0.0; rh = f ? 0.0 : 1.0;
                break;
            }
            case 29: {
                int nz = al > 0.0 || ah < 0.0, z = al == 0.0 && ah == 0.0;
                if (!nz && !z) *rg = 0;
                rl = nz ? bl : (z ? 0.0 : nmin(bl, 0.0));
                rh = nz ? bh : (z ? 0.0 : nmax(bh, 0.0));
                break;
            }
            case 30:
                if (al <= 0.0 && ah >= 0.0 && al != ah) *rg = 0;
                rl = csign(al); rh = csign(ah);
                break;
            case 31: {
                double ml = al >= 0.0 ? al : (ah <= 0.0 ? -ah : 0.0), mh = nmax(fabs(al), fabs(ah));
                int pos = bl > 0.0, neg = bh < 0.0;
                if (!pos && !neg) *rg = 0;
                rl = pos ? ml : -mh; rh = neg ? -ml : mh;
                break;
            }
            case 32: case 33:
                rl = code == 32 ? floor(al) : ceil(al); rh = code == 32 ? floor(ah) : ceil(ah);
                if (rl != rh) *rg = 0;
                break;
            case 34: rl = dn(al * k); rh = up(ah * k); break;
            case 35: rl = dn(ah * k); rh = up(al * k); break;
            default: rl = -INFINITY; rh = INFINITY; *rg = 0; break;
    }
    *lo = rl; *hi = rh;
}

#define RUN(c) case c: for (int j = 0; j < nb; j++) one(c, Al[j], Ah[j], Bl[j], Bh[j], k, lo + j, hi + j, reg + j, PI_UP, HPI_UP); break;

int ts_interval(int n, int n_x, int n_nodes, int n_ins, const int32_t *op, const int32_t *dst,
                const int32_t *ia, const int32_t *ib, const double *kc, int n_c, const double *cv,
                int n_out, const int32_t *oidx, const double *XL, const double *XH,
                double *OL, double *OH, uint8_t *REG) {
    double *L = malloc(sizeof(double) * (size_t)n_nodes * NB);
    double *H = malloc(sizeof(double) * (size_t)n_nodes * NB);
    if (!L || !H) { free(L); free(H); return -1; }
    const double PI_UP = nextafter(PI_D, INFINITY), HPI_UP = nextafter(PI_D / 2.0, INFINITY);
    for (int b0 = 0; b0 < n; b0 += NB) {
        int nb = n - b0 < NB ? n - b0 : NB;
        int reg[NB];
        for (int j = 0; j < nb; j++) {
            reg[j] = 1;
            for (int i = 0; i < n_x; i++) {
                L[i * NB + j] = XL[(size_t)(b0 + j) * n_x + i];
                H[i * NB + j] = XH[(size_t)(b0 + j) * n_x + i];
            }
            for (int i = 0; i < n_c; i++) L[(n_x + i) * NB + j] = H[(n_x + i) * NB + j] = cv[i];
        }
        for (int s = 0; s < n_ins; s++) {
            double *lo = L + (size_t)dst[s] * NB, *hi = H + (size_t)dst[s] * NB;
            const double *Al = L + (size_t)ia[s] * NB, *Ah = H + (size_t)ia[s] * NB;
            const double *Bl = L + (size_t)(ib[s] < 0 ? 0 : ib[s]) * NB, *Bh = H + (size_t)(ib[s] < 0 ? 0 : ib[s]) * NB;
            double k = kc[s];
            switch (op[s]) {
            RUN(1)
            RUN(2)
            RUN(3)
            RUN(4)
            RUN(5)
            RUN(6)
            RUN(7)
            RUN(8)
            RUN(9)
            RUN(10)
            RUN(11)
            RUN(12)
            RUN(13)
            RUN(14)
            RUN(15)
            RUN(16)
            RUN(17)
            RUN(18)
            RUN(19)
            RUN(20)
            RUN(21)
            RUN(22)
            RUN(23)
            RUN(24)
            RUN(25)
            RUN(26)
            RUN(27)
            RUN(28)
            RUN(29)
            RUN(30)
            RUN(31)
            RUN(32)
            RUN(33)
            RUN(34)
            RUN(35)
            default: for (int j = 0; j < nb; j++) { lo[j] = -INFINITY; hi[j] = INFINITY; reg[j] = 0; } break;
            }
        }
        for (int j = 0; j < nb; j++) {
            size_t row = (size_t)(b0 + j) * n_out;
            for (int i = 0; i < n_out; i++) {
                double l = L[oidx[i] * NB + j], h = H[oidx[i] * NB + j];
                OL[row + i] = l; OH[row + i] = h;
                if (!isfinite(l) || !isfinite(h)) reg[j] = 0;
            }
            REG[b0 + j] = (uint8_t)reg[j];
        }
    }
    free(L); free(H);
    return 0;
}
"""

_state: dict = {}


def library():
    """The compiled interpreter (a ctypes function), or None when compilation is off or fails."""
    if disabled():
        return None
    cc = find_compiler()
    if cc is None:
        return None
    key = cc
    if key not in _state:
        try:
            lib, _ = load_library(_SOURCE % {"block": BLOCK}, "tolsynth_interval", cc, ("ts_interval",))
            fn = lib.ts_interval
            i32 = np.ctypeslib.ndpointer(np.int32, flags="C_CONTIGUOUS")
            f64 = np.ctypeslib.ndpointer(np.float64, flags="C_CONTIGUOUS")
            u8 = np.ctypeslib.ndpointer(np.uint8, flags="C_CONTIGUOUS")
            ci = ctypes.c_int
            fn.argtypes = [ci, ci, ci, ci, i32, i32, i32, i32, f64, ci, f64, ci, i32, f64, f64, f64, f64, u8]
            fn.restype = ci
            _state[key] = fn
        except (OSError, AttributeError, RuntimeError):
            _state[key] = None
    return _state[key]


def compiled_program(groups, n_x: int, consts: np.ndarray, out_idx: np.ndarray):
    """The interpreter's arrays for a program of groups ``(op, start, end, arg_idx, k)`` (as
    :class:`IntervalFunction` builds them), or None when an operation has no compiled extension."""
    ops, dst, ia, ib, kc = [], [], [], [], []
    for op, s, e, idx, k in groups:
        code = CODES.get(op)
        if code is None:
            return None
        m = e - s
        ops.append(np.full(m, code, dtype=np.int32))
        dst.append(np.arange(s, e, dtype=np.int32))
        ia.append(np.asarray(idx[0], dtype=np.int32))
        ib.append(np.asarray(idx[1], dtype=np.int32) if len(idx) > 1 else np.full(m, -1, dtype=np.int32))
        kc.append(np.asarray(k, dtype=float).reshape(m) if k is not None else np.zeros(m))

    def cat(parts, dtype):
        return np.ascontiguousarray(np.concatenate(parts) if parts else np.zeros(0), dtype=dtype)

    return (
        cat(ops, np.int32),
        cat(dst, np.int32),
        cat(ia, np.int32),
        cat(ib, np.int32),
        cat(kc, np.float64),
        np.ascontiguousarray(consts, dtype=np.float64),
        np.ascontiguousarray(out_idx, dtype=np.int32),
    )


def evaluate_compiled(fn, program, n_x: int, n_nodes: int, XL: np.ndarray, XH: np.ndarray):
    """``(OL, OH, regular)`` of the program on the boxes ``XL, XH`` (n, n_x), as
    :meth:`IntervalFunction.evaluate` returns them."""
    op, dst, ia, ib, kc, cv, oidx = program
    n = XL.shape[0]
    XL = np.ascontiguousarray(XL, dtype=np.float64)
    XH = np.ascontiguousarray(XH, dtype=np.float64)
    OL = np.empty((n, len(oidx)))
    OH = np.empty((n, len(oidx)))
    reg = np.empty(n, dtype=np.uint8)
    if n:
        status = fn(n, n_x, n_nodes, len(op), op, dst, ia, ib, kc, len(cv), cv, len(oidx), oidx, XL, XH, OL, OH, reg)
        if status != 0:
            raise MemoryError("the interval interpreter could not allocate its work vector")
    return OL, OH, reg.astype(bool)
