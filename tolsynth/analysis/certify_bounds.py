"""Rigorous bounds of the largest principal standard deviation over boxes of joint values.

The certified worst-pose search (:mod:`tolsynth.analysis.certify`) splits the joint space into
boxes; this module bounds ``sigma_1(q) = sqrt(lambda_max(A(q) W A(q)^T))`` from above on each box,
where ``A(q)`` is the position sensitivity at zero error (only the columns that are not
structurally zero, :mod:`tolsynth.analysis.certify_structure`) and ``W`` the diagonal of the
variances per tolerance unit squared (``eps_i^2 / c_i``).  Two bounds, the smaller one used:

* **natural**: interval enclosures of the entries of ``A`` on the box, ``A in [A_mid - R, A_mid + R]``,
  and Weyl's inequality for singular values, ``sigma_1(A W^1/2) <= sigma_1(A_mid W^1/2) + ||R W^1/2||_2``
  (``||D||_2 <= || |D| ||_2 <= ||R||_2`` for ``|D| <= R`` entrywise).  Good on large boxes.
* **corners**: with ``c`` the box's centre and ``r`` its half-widths,
  ``A(c + d) = A(c) + J(c) d + E`` with ``|E| <= 1/2 sum_jk |H_jk(B)| r_j r_k`` (Taylor's theorem with the
  interval Hessian ``H(B)`` of every entry over the box; or ``sum_k |J_k(B) - J_k(c)| r_k`` from the
  interval Jacobian, when the Hessian's graph is much larger).  ``sigma_1`` is a norm of ``A W^1/2``,
  hence convex in ``A``, so its largest value over the affine image of the box is at one of the
  ``2^k`` corners ``d = +-r``; the remainder adds at most ``||E W^1/2||_2``.  The excess over the
  true maximum falls like the square of the box's width, so boxes around the worst pose stay few.

Every floating-point step is rounded outward or covered by a stated error bound: the interval
evaluations round outward (:mod:`tolsynth.analysis.intervals`), the corner matrices' rounding is
added to ``E``, and an eigenvalue computed by LAPACK is raised by a bound on its backward error
(``(m + 30) u ||M||_F^2`` for ``lambda_max(M M^T)``, ``M`` of size 3 x m, ``u`` the unit roundoff).
"""

from __future__ import annotations

import itertools
import weakref
from typing import NamedTuple

import casadi as ca
import numpy as np

# the eigenvalue bounds and the arc polygons live in certify_polygon; the polygon names are read
# from here as well
from tolsynth.analysis.certify_polygon import (  # noqa: F401
    _U,
    PolygonSigmaBounds,
    _char_poly,
    _eig_estimate,
    _mat,
    _prove,
    arc_polygons,
    lambda_max_bound,
)
from tolsynth.analysis.certify_structure import trig_polynomial
from tolsynth.analysis.interval_ops import round_up as _up
from tolsynth.analysis.intervals import IntervalFunction

__all__ = [
    "sigma_bounds",
    "JointGraphs",
    "joint_graphs",
    "SigmaBounds",
    "largest_singular_bound",
    "taylor_enclosure",
    "Enclosure",
    "HESSIAN_FACTOR",
]

#: boxes wider than this (rad, on some side) also get the natural interval bound
NATURAL_WIDTH = 0.2
#: the Hessian's graph is used for the remainder when it has at most this many times the
#: operations of the Jacobian's (else the interval Jacobian: half as tight, much cheaper there)
HESSIAN_FACTOR = 4.0
#: the same with the compiled interval interpreter, where the evaluations cost less than the
#: corner bounds of the boxes they save (the paper's robot: 12.7 times the operations, 4.7 times
#: fewer boxes)
HESSIAN_FACTOR_COMPILED = 16.0
#: the third derivatives' graph is used when it has at most this many times the Hessian's operations
THIRD_FACTOR = 4.0


def largest_singular_bound(M: np.ndarray, reduce_last: bool = False) -> np.ndarray:
    """Upper bounds of the largest singular value of each 3 x m matrix ``M[..., :, :]`` (finite
    entries); with ``reduce_last``, of the largest over the last batch axis.

    ``lambda_max(G)``, ``G = M M^T``, is the largest root of its characteristic polynomial, whose
    coefficients are moved by their rounding error (:func:`_char_poly`); LAPACK's eigenvalue
    (raised a little) is a candidate, proven by :func:`_above_roots` or else raised by Newton's
    iteration from above (:func:`_largest_root`).  ``(m + 2) u ||M||_F^2`` covers the rounding of
    ``G`` itself (Weyl)."""
    m = M.shape[-1]
    G = M @ np.swapaxes(M, -1, -2)
    c1, c2, c3 = _char_poly(G)
    frob = np.einsum("...ij,...ij->...", M, M)
    lam = _eig_estimate(G)
    if reduce_last:
        lam = np.broadcast_to(lam.max(axis=-1, keepdims=True), lam.shape)
    s = np.where(c1 > 1e-100, c1, 1.0)  # the cubic scaled to a unit trace (a zero matrix as it is)
    a1, a2, a3 = c1 / s, c2 / (s * s), c3 / (s * s * s)
    cand = np.maximum(lam / s, 0.0) * (1.0 + 1e-12) + 1e-13
    _prove(cand, a1, a2, a3)
    lam = cand * s * (1.0 + 8.0 * _U) + (m + 2) * 2.0 * _U * frob
    out = _up(np.sqrt(np.maximum(lam, 0.0)))
    return out.max(axis=-1) if reduce_last else out


_GRAPHS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def joint_graphs(structure, nq: int, free, held: dict, third: bool = False, M=None) -> "JointGraphs":
    """:class:`JointGraphs`, built once per structure, searched joints, held values, order and
    coordinates: a certified exchange certifies the same joint space every round, and compiling the
    interval programs costs about a second (the graphs depend on nothing else, so the answers
    cannot)."""
    shear = None if M is None else np.asarray(M, dtype=float)
    key = (
        int(nq),
        tuple(int(j) for j in free),
        tuple(sorted((int(j), float(v)) for j, v in held.items())),
        bool(third),
        None if shear is None else (shear.shape, shear.tobytes()),
    )
    cache = _GRAPHS.setdefault(structure, {})
    hit = cache.get(key)
    if hit is None:
        hit = cache[key] = JointGraphs(structure, nq, free, held, third=third, M=shear)
    return hit


class JointGraphs:
    """The interval functions of ``A`` for one set of searched joints (the others held).

    Parameters
    ----------
    structure : Structure
    nq : int
        Number of joints.
    free : sequence of int
        The searched joints, in the order of the box coordinates.
    held : dict
        Joint index -> value (rad) of every other joint.
    third : bool
        Also the third derivatives, for the third-order remainder of :func:`taylor_enclosure`.
    M : ndarray, optional
        The box coordinates ``x`` give the searched joints as ``M x`` (k, k); by default they are
        the joints themselves.  A joint constraint taken as a coordinate turns its planes into
        faces of the boxes (:func:`tolsynth.analysis.certify_domain.sheared`).
    """

    def __init__(self, structure, nq: int, free, held: dict, third: bool = False, M=None):
        self.free = tuple(int(j) for j in free)
        self.k = len(self.free)
        cols = list(structure.columns)
        self.m = len(cols)
        x = ca.SX.sym("x", self.k)
        joints = x if M is None else ca.mtimes(ca.DM(np.asarray(M, dtype=float)), x)
        q = [ca.SX(float(held.get(j, 0.0))) for j in range(nq)]
        for i, j in enumerate(self.free):
            q[j] = joints[i]
        A = structure.A.call([ca.vertcat(*q)])[0][:, cols]
        a = ca.densify(ca.vec(A))  # column-major: the 3 rows of column 0, then column 1, ...
        self.na = a.numel()
        J = ca.densify(ca.jacobian(a, x))
        self.point_fn = ca.Function("A", [x], [a])
        self.centre = IntervalFunction(ca.Function("aJ", [x], [a, J]))
        H = ca.densify(ca.vertcat(*[ca.vec(ca.hessian(a[i], x)[0]) for i in range(self.na)])) if self.k else ca.SX(0, 1)
        hess = IntervalFunction(ca.Function("aH", [x], [a, H]))
        factor = HESSIAN_FACTOR_COMPILED if hess.compiled else HESSIAN_FACTOR
        self.use_hessian = hess.n_operations <= factor * self.centre.n_operations
        self.hess = hess
        self.box = hess if self.use_hessian else self.centre
        self.corners = np.array(list(itertools.product([-1.0, 1.0], repeat=self.k))) if self.k else np.zeros((1, 0))
        # third derivatives over the box with the Hessian at the centre: a third-order remainder,
        # where the interval Hessian over a wider box is much wider than the Hessian itself (the
        # paper robot's, over a 0.06 rad box, three times); asked for by a search whose boxes cost
        # more than the third derivatives' evaluation (the exact one: it halves the sigma search's
        # speed for a third fewer boxes)
        self.third = None
        if third and self.use_hessian and self.k:
            T = ca.jacobian(ca.vec(ca.jacobian(ca.vec(J), x)), x)
            third = IntervalFunction(ca.Function("aT", [x], [a, ca.densify(ca.vec(T))]))
            if third.n_operations <= THIRD_FACTOR * hess.n_operations:
                self.third = third

    def values(self, X: np.ndarray) -> np.ndarray:
        """``A`` at the points X (n, k), shape (n, 3, m)."""
        X = np.atleast_2d(X)
        if len(X) == 0:
            return np.zeros((0, 3, self.m))
        a = np.array(self.point_fn.map(len(X))(X.T)).T.reshape(len(X), self.m, 3)
        return a.transpose(0, 2, 1)


def polytope_vertices(C: np.ndarray, r: np.ndarray, linear=()):
    """Points whose convex hull holds the part of each box ``C +- r`` (n, k) where the linear
    constraints ``lo <= a . x <= hi`` hold: the box's corners that satisfy them and the crossings of
    each constraint's planes with the box's edges.  Returns offsets ``d`` (n, P, k) from the centre
    and a mask (n, P) of the points to use.  A convex function is largest at one of them; points
    near a plane count when within a rounding slack of it (counting more points only raises the
    maximum), so the hull holds the feasible part even as computed."""
    n, k = C.shape
    signs = np.array(list(itertools.product([-1.0, 1.0], repeat=k))) if k else np.zeros((1, 0))
    pts = [signs[None] * r[:, None, :]]
    if not linear:
        return pts[0], np.ones(pts[0].shape[:2], dtype=bool)
    planes = []
    for a, lo, hi in linear:
        g = C @ a
        planes += [(a, lo - g), (a, hi - g)]  # a . d = gamma on each plane
    for a, gam in planes:
        for i in range(k):
            if a[i] == 0.0:
                continue
            others = [j for j in range(k) if j != i]
            sub = np.array(list(itertools.product([-1.0, 1.0], repeat=k - 1))) if k > 1 else np.zeros((1, 0))
            d = np.zeros((n, len(sub), k))
            d[:, :, others] = sub[None] * r[:, None, others]
            d[:, :, i] = (gam[:, None] - d[:, :, others] @ a[others]) / a[i]
            d[:, :, i] = np.where(np.abs(d[:, :, i]) <= r[:, None, i] * (1.0 + 1e-12), d[:, :, i], np.nan)
            pts.append(d)
    D = np.concatenate(pts, axis=1)
    ok = np.isfinite(D).all(axis=2)
    X = C[:, None, :] + np.where(ok[..., None], D, 0.0)
    for a, lo, hi in linear:
        v = X @ a
        slack = 1e-9 * (np.abs(X) @ np.abs(a) + 1.0)
        ok &= (v >= lo - slack) & (v <= hi + slack)
    return np.where(ok[..., None], D, 0.0), ok


def taylor_enclosure(g: JointGraphs, L: np.ndarray, H: np.ndarray, linear=()):
    """``A`` over each box ``L <= x <= H`` (n, k): ``A(x)`` in the convex
    hull of the corner matrices ``Y[b, c]`` (column-major vectors, (n, C, 3 m); only where ``use``)
    plus ``[-E, E]`` entrywise (n, 3 m) for every x of the box that meets the linear constraints;
    ``ok`` False where the graph is not proven regular on the box (a closed loop near its limits);
    ``share`` (n, 3 m, k): each coordinate's part of the remainder (where to halve).  Returned as an
    :class:`Enclosure`, with the centre and Jacobian too (the affine part over a box without a
    constraint crossing it is ``am + Jm d`` for every ``|d| <= r``)."""
    na, k = g.na, g.k
    nb = len(L)
    C = np.minimum(np.maximum(0.5 * (L + H), L), H)
    r = np.maximum(_up(H - C), _up(C - L))
    with np.errstate(all="ignore"):
        BL, BH, breg = g.box.evaluate(L, H)
        CL, CH, creg = g.centre.evaluate(C, C)
        am = 0.5 * (CL[:, :na] + CH[:, :na])
        Jl, Jh = CL[:, na:].reshape(nb, k, na), CH[:, na:].reshape(nb, k, na)
        Jm = 0.5 * (Jl + Jh)
        # the centre's own enclosure widths and the rounding of am + Jm d, then the remainder
        lin = np.einsum("bkn,bk->bn", np.maximum(Jh - Jm, Jm - Jl) + 4.0 * (k + 2) * _U * np.abs(Jm), r)
        E = np.maximum(CH[:, :na] - am, am - CL[:, :na]) + lin + 4.0 * _U * np.abs(am)
        if g.use_hessian:
            Ha = np.maximum(np.abs(BL[:, na:]), np.abs(BH[:, na:])).reshape(nb, na, k, k)
            share = 0.5 * np.einsum("bnjk,bj,bk->bnk", Ha, r, r)
            if g.third is not None:
                # |d^T H(c) d| / 2 + |T(B)| r^3 / 6, coordinate by coordinate, where it is smaller
                HcL, HcH, _ = g.hess.evaluate(C, C)
                Hc = np.maximum(np.abs(HcL[:, na:]), np.abs(HcH[:, na:])).reshape(nb, na, k, k)
                TL, TH, treg = g.third.evaluate(L, H)
                # vec of the (na k) x k Jacobian of vec(J): entry (n + na (j + k l)) -> T[n, j, l, ...]
                Ta = np.maximum(np.abs(TL[:, na:]), np.abs(TH[:, na:])).reshape(nb, k, k, k, na)
                s3 = 0.5 * np.einsum("bnjk,bj,bk->bnk", Hc, r, r) + np.einsum("blkjn,bj,bk,bl->bnl", Ta, r, r, r) / 6.0
                better = treg[:, None] & np.isfinite(s3).all(axis=2) & (s3.sum(axis=2) < share.sum(axis=2))
                share = np.where(better[:, :, None], s3, share)
        else:
            dev = np.maximum(np.abs(BL[:, na:].reshape(nb, k, na) - Jm), np.abs(BH[:, na:].reshape(nb, k, na) - Jm))
            share = np.einsum("bkn,bk->bnk", dev, r)
        E = _up(E + share.sum(axis=2) * (1.0 + 4.0 * (k + 2) * _U))
        D, use = polytope_vertices(C, r, linear)
        # the constraint crossings are computed: their rounding moves the image by at most this
        E = E + 1e-12 * np.einsum("bkn,bk->bn", np.abs(Jm), r) if linear else E
        Y = am[:, None, :] + np.einsum("bkn,bck->bcn", Jm, D)
        ok = breg & creg & np.isfinite(E).all(axis=1) & np.isfinite(Y).all(axis=(1, 2))
    # the joints that move A most, the most first: the corners are grouped by their sides
    spread = np.linalg.norm(Jm, axis=2) * r  # (n, k)
    order = np.argsort(-spread, axis=1)
    bits = np.take_along_axis(D, order[:, None, :], axis=2) >= 0.0  # (n, C, k)
    corners = 1 << k
    cross = ~(use[:, :corners].all(axis=1) & ~use[:, corners:].any(axis=1))
    # the used points first, the array cut to the most any box uses
    keep = np.argsort(~use, axis=1, kind="stable")[:, : max(int(use.sum(axis=1).max(initial=0)), 1)]
    Y = np.take_along_axis(Y, keep[:, :, None], axis=1)
    bits = np.take_along_axis(bits, keep[:, :, None], axis=1)
    use = np.take_along_axis(use, keep, axis=1)
    return Enclosure(
        BL[:, :na],
        BH[:, :na],
        np.where(ok[:, None], am, 0.0),
        np.where(ok[:, None, None], Jm, 0.0),
        r,
        np.where(ok[:, None], E, 0.0),
        ok,
        share,
        order,
        cross,
        np.where(ok[:, None, None], Y, 0.0),
        use,
        bits,
    )


class Enclosure(NamedTuple):
    """``A`` over joint boxes (:func:`taylor_enclosure`)."""

    alo: np.ndarray  # (n, 3 m) interval evaluation of A over the box (NaN: no information)
    ahi: np.ndarray
    am: np.ndarray  # (n, 3 m) A at the centres (column-major)
    Jm: np.ndarray  # (n, k, 3 m) its Jacobian there
    r: np.ndarray  # (n, k) half-widths
    E: np.ndarray  # (n, 3 m) remainder bound (with every rounding)
    ok: np.ndarray  # (n,) the graph proven regular on the box
    share: np.ndarray  # (n, 3 m, k) each joint's part of the remainder
    order: np.ndarray  # (n, k) joints by how much they move A, the most first
    cross: np.ndarray  # (n,) a joint constraint crosses the box (its corners are not all feasible)
    Y: np.ndarray  # (n, C, 3 m) the affine part at the corners of the feasible part
    use: np.ndarray  # (n, C) which of them
    bits: np.ndarray  # (n, C, k) their sides of the centre along ``order``


class SigmaBounds:
    """Upper bounds of ``sigma_1`` on boxes of the searched joints, at one set of variances.

    Parameters
    ----------
    graphs : JointGraphs
    w : array_like
        Variance per tolerance unit squared of every kept column, ``eps_i^2 / c_i`` (mm^2 per
        unit^2 times units^2).
    """

    def __init__(self, graphs: JointGraphs, w, linear=()):
        self.g = graphs
        self.sw = np.sqrt(np.asarray(w, dtype=float))
        self.linear = tuple(linear)  # (a, lo, hi) of the joint constraints in box coordinates

    def point(self, X: np.ndarray) -> np.ndarray:
        """``sigma_1`` at points (n, k) (plain floating point: the best value found, not a bound)."""
        M = self.g.values(X) * self.sw
        lam = np.linalg.eigvalsh(M @ np.swapaxes(M, -1, -2))[:, -1]
        return np.sqrt(np.maximum(lam, 0.0))

    def bound(self, L: np.ndarray, H: np.ndarray):
        """``(ub, split)``: upper bounds (n,) of sigma_1 on the boxes ``L <= x <= H`` and, per box and
        coordinate, that coordinate's share of the corner bound's remainder (where to halve)."""
        g, m, k = self.g, self.g.m, self.g.k
        nb = len(L)
        with np.errstate(all="ignore"):
            if k == 0:
                BL, BH, _ = g.box.evaluate(L, H)
                aBl, aBh = BL[:, : g.na], BH[:, : g.na]
            else:
                enc = taylor_enclosure(g, L, H, self.linear)
                aBl, aBh = enc.alo, enc.ahi
            nat_ok = np.isfinite(aBl).all(axis=1) & np.isfinite(aBh).all(axis=1)
            amid = np.where(nat_ok[:, None], 0.5 * (aBl + aBh), 0.0)
            arad = np.where(nat_ok[:, None], _up(np.maximum(aBh - amid, amid - aBl)), 0.0)
            nat = np.full(nb, np.inf)

            def natural(rows):  # Weyl on the interval matrix; on small boxes the corners are tighter
                rows = rows & nat_ok
                if rows.any():
                    nat[rows] = _up(
                        largest_singular_bound(_mat(amid[rows], m) * self.sw)
                        + largest_singular_bound(_mat(arad[rows], m) * self.sw)
                    )

            if k == 0:
                natural(np.ones(nb, dtype=bool))
                return nat, None
            natural((H - L).max(axis=1) > NATURAL_WIDTH)
            ok, use, E, share = enc.ok, enc.use, enc.E, enc.share
            Y = np.where(use[..., None], enc.Y, 0.0)  # points outside the constraints: a zero matrix
            cor = np.where(use.any(axis=1), largest_singular_bound(_mat(Y, m) * self.sw, reduce_last=True), -np.inf)
            cor = _up(cor + largest_singular_bound(_mat(E, m) * self.sw))
            cor = np.where(ok, cor, np.inf)
            natural(~ok & ~np.isfinite(nat))
            split = np.sqrt(np.einsum("bnk,n->bk", share**2, np.repeat(self.sw**2, 3)))
        return np.fmin(nat, cor), np.where(ok[:, None], split, np.nan)


def sigma_bounds(st, dom, nq, w):
    """The bounds of sigma_1 on boxes of the searched joints (variance weights ``w`` of the kept
    columns), and the method's name: arc polygons where the sensitivity is a trigonometric
    polynomial of the searched joints, Taylor corners elsewhere."""
    poly = trig_polynomial(st, dom.free, st.rotation) if st.rotation is None or st.rotation in dom.held else None
    if poly is not None and all(j in st.joints for j in dom.free) and dom.M is None:
        return PolygonSigmaBounds(poly, dom.free, w), "arc polygons of the exact trigonometric polynomial"
    held_zero = dict(dom.held)
    if st.rotation is not None:
        held_zero[st.rotation] = 0.0
    bounds = SigmaBounds(joint_graphs(st, nq, dom.free, held_zero, M=dom.M), w, dom.linear)
    return bounds, "second-order Taylor corners" if bounds.g.use_hessian else "Taylor corners (interval Jacobian)"
