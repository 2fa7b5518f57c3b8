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
  in C (their closed forms, the sines and cosines of ``k theta`` by rotation from those of
  ``theta``, taken afresh every 16 terms so that the rotation's rounding stays below 16 ulp; rows
  of more than 512 terms take each afresh), and the truncated normal's from the interpolants of
  :func:`tolsynth.probability.truncnormal.cf3` (:func:`~tolsynth.probability.truncnormal.packed`),
  by the same formulas.  For P alone (order 0, not the sphere's) the columns go by kind: the
  uniform ones rotated and multiplied two at a time (which the compiler turns into vector
  arithmetic), the normal ones as one exponential; the products' order, so their rounding, is all
  that differs.
* :func:`terms` and :func:`tail`: the rigorous truncation bound of :meth:`.exact_series.Rows.tail`
  and the least power of two that meets a tolerance.

The NumPy code stays the reference: it runs where no C compiler is found (or with
``TOLSYNTH_NO_COMPILE=1``), and the tests check that both agree to rounding.  The library is
built and cached on disk by :mod:`tolsynth.cbuild`.
"""

from __future__ import annotations

import ctypes
import threading
from functools import lru_cache

import numpy as np

from tolsynth.cbuild import C_INCLUDES, disabled, find_compiler, load_library
from tolsynth.probability.truncnormal import packed as truncnormal_packed
from tolsynth.solvers.exact_kernel_c import C_SOURCE

__all__ = ["available", "evaluate", "series", "terms", "tail", "split", "closed", "CODES"]

#: rows of more columns run the NumPy path (the C source's work arrays are of this size)
MAX_COLUMNS = 64
#: the kind codes of the C source's columns
CODES = {"uniform": 0, "normal": 1, "triangular": 2, "truncnormal": 3}


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
                    lib, _ = load_library(
                        C_INCLUDES + C_SOURCE,
                        "exact",
                        cc,
                        ("ts_series", "ts_tail", "ts_terms", "ts_split", "ts_closed", "ts_eval"),
                    )
                    vp, ci, cd = ctypes.c_void_p, ctypes.c_int, ctypes.c_double
                    lib.ts_series.restype = ci
                    lib.ts_series.argtypes = [ci, ci] + [vp] * 7 + [ci, ci, vp, vp, vp]
                    lib.ts_tail.restype = None
                    lib.ts_tail.argtypes = [ci, ci, vp, vp, vp, ci, vp, vp, vp, ci, vp]
                    lib.ts_terms.restype = None
                    lib.ts_terms.argtypes = [ci, ci, vp, vp, vp, ci, cd, ci, vp, vp, vp, vp]
                    lib.ts_split.restype = None
                    lib.ts_split.argtypes = [ci, ci, vp, vp, vp, cd, vp, vp, vp]
                    lib.ts_closed.restype = None
                    lib.ts_closed.argtypes = [ci, ci, vp, vp, vp, ci, cd, vp, vp, vp, vp, vp]
                    lib.ts_eval.restype = ci
                    lib.ts_eval.argtypes = [ci, ci, vp, vp, cd, vp, ci, ci] + [vp] * 5 + [ci, vp, vp, vp]
                    lib.ts_eval.argtypes += [cd, cd, ctypes.c_long, cd] + [vp] * 7
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
        self.fmult = np.ascontiguousarray(np.concatenate([rw.f_mult, rw.f_far, rw.f_far2]), dtype=float)
        self.normal = np.ascontiguousarray(rw.normal, dtype=np.intc)
        self.var = np.array([s.variance for s in rw.shapes])
        self.peak = np.array([s.peak for s in rw.shapes])


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


def split(rw, b, budget: float):
    """``exact_series._split`` (rows of at least three columns), or None without the kernel."""
    lib = _lib()
    if lib is None or b.shape[1] > MAX_COLUMNS:
        return None
    lay = _layout(rw)
    b = _c(b)
    m, n = b.shape
    out, dropped, gerr = np.empty((m, n)), np.empty(m), np.empty((m, n))
    lib.ts_split(
        m,
        n,
        b.ctypes.data,
        lay.var.ctypes.data,
        lay.peak.ctypes.data,
        float(budget),
        out.ctypes.data,
        dropped.ctypes.data,
        gerr.ctypes.data,
    )
    return out, dropped, gerr


@lru_cache(maxsize=64)
def _kinds(shapes: tuple) -> np.ndarray:
    return np.array([CODES[s.kind] for s in shapes], dtype=np.intc)


def closed(shapes: tuple, b, R, order: int, tol: float):
    """``exact_closed.closed_rows`` (the same dict), or None without the kernel."""
    lib = _lib()
    if lib is None or b.shape[1] > MAX_COLUMNS:
        return None
    kinds = _kinds(tuple(shapes))
    b = _c(b)
    m, n = b.shape
    R = _c(np.broadcast_to(R, (m,)))
    ok = np.zeros(m, dtype=np.intc)
    P, err = np.empty(m), np.empty(m)
    G = np.empty((m, n)) if order >= 1 else np.zeros(1)
    H = np.empty((m, n, n)) if order >= 2 else np.zeros(1)
    lib.ts_closed(
        m,
        n,
        b.ctypes.data,
        R.ctypes.data,
        kinds.ctypes.data,
        order,
        float(tol),
        ok.ctypes.data,
        P.ctypes.data,
        G.ctypes.data,
        H.ctypes.data,
        err.ctypes.data,
    )
    return {
        int(r): (float(P[r]), G[r] if order >= 1 else None, H[r] if order >= 2 else None, float(err[r]))
        for r in np.flatnonzero(ok)
    }


def evaluate(rw, b, R, tol: float, order: int, Ks: np.ndarray, consts: tuple):
    """The whole of ``exact_series.probability`` (order 0, before its slow rows) or of
    ``derivatives`` (order 1, 2; neither rigorous nor the sphere's) in one call: ``(P unclipped,
    G, H, err, rows after the dropping)``, or None without the kernel.  ``consts``: L's margin,
    the normal reach, the least number of terms that tries the closed form, the rounding
    allowance (the caller's constants)."""
    lib = _lib()
    if lib is None or b.shape[1] > MAX_COLUMNS:
        return None
    lay = _layout(rw)
    b = _c(b)
    m, n = b.shape
    R = _c(np.broadcast_to(R, (m,)))
    Ks = _c(Ks)
    bw, gerr = np.empty((m, n)), np.empty((m, n))
    P, err, K = np.empty(m), np.empty(m), np.empty(m, dtype=np.int64)
    G = np.empty((m, n)) if order >= 1 else bw
    H = np.empty((m, n, n)) if order >= 2 else bw
    lmargin, reach, closed_from, rounding = consts
    status = lib.ts_eval(
        m,
        n,
        b.ctypes.data,
        R.ctypes.data,
        float(tol),
        Ks.ctypes.data,
        Ks.size,
        order,
        lay.kind.ctypes.data,
        lay.tnt.ctypes.data,
        lay.tno.ctypes.data,
        lay.var.ctypes.data,
        lay.peak.ctypes.data,
        lay.fidx.size,
        lay.fidx.ctypes.data,
        lay.fmult.ctypes.data,
        lay.normal.ctypes.data,
        float(lmargin),
        float(reach),
        int(closed_from),
        float(rounding),
        bw.ctypes.data,
        P.ctypes.data,
        G.ctypes.data,
        H.ctypes.data,
        err.ctypes.data,
        gerr.ctypes.data,
        K.ctypes.data,
    )
    if status:
        return None
    return P, (G if order >= 1 else None), (H if order >= 2 else None), err, bw
