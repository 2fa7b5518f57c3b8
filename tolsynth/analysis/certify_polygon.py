"""Upper bounds of ``sigma_1`` over boxes of joint angles for serial chains: arc polygons.

Where the sensitivity ``A`` is an exact trigonometric polynomial of the searched joints (degree one
in each joint's ``(cos, sin)``, :func:`tolsynth.analysis.certify_structure.trig_polynomial`), each
joint's arc is enclosed in a polygon (:func:`arc_polygons`) and ``sigma_1`` bounded at the tuples of
polygon points (:class:`PolygonSigmaBounds`); the contraction and the eigenvalue bound over the
tuples run compiled (:mod:`tolsynth.analysis.certify_kernels`).  Every floating-point step carries
a bound on its rounding, as in :mod:`tolsynth.analysis.certify_bounds`.
"""

from __future__ import annotations

import numpy as np

from tolsynth.analysis.certify_kernels import contract, jet, lambda_max, share_order
from tolsynth.analysis.interval_ops import round_up as _up

__all__ = ["PolygonSigmaBounds", "arc_polygons", "lambda_max_bound", "POLYGON_PIECES", "POLYGON_TUPLES", "REFINE"]

_U = 2.0**-53


def _largest_root(a1, a2, a3):
    """An upper bound of the largest real root of ``l^3 - a1 l^2 + a2 l - a3`` (arrays): Newton's
    iteration from Fujiwara's bound on all roots (it stays above the largest root, where the cubic
    is convex), then a check that the cubic and its first two derivatives are positive there
    (beyond it they stay so: the third derivative is 6), with their rounding accounted for."""
    lam = 2.0 * np.maximum(np.maximum(np.abs(a1), np.sqrt(np.abs(a2))), np.cbrt(np.abs(a3) / 2.0))
    lam = np.maximum(lam, a1 / 3.0) + 1e-300
    for _ in range(60):
        p = ((lam - a1) * lam + a2) * lam - a3
        dp = (3.0 * lam - 2.0 * a1) * lam + a2
        with np.errstate(all="ignore"):
            step = np.where(dp > 0, p / dp, 0.0)
        active = step > 1e-14 * lam
        if not active.any():
            break
        lam = np.where(active, lam - step, lam)
    lam = lam * (1.0 + 1e-12) + 1e-300
    for t in range(8):
        mag = ((lam + np.abs(a1)) * lam + np.abs(a2)) * lam + np.abs(a3)
        p = ((lam - a1) * lam + a2) * lam - a3
        dp = (3.0 * lam - 2.0 * a1) * lam + a2
        ddp = 3.0 * lam - a1
        ok = (
            (p > 16 * _U * mag)
            & (dp > 16 * _U * (3.0 * lam * lam + 2.0 * np.abs(a1) * lam + np.abs(a2)))
            & (ddp > 16 * _U * (3.0 * lam + np.abs(a1)))
        )
        if ok.all():
            return lam
        lam = np.where(ok, lam, lam * (1.0 + 1e-9 * 8.0**t) + 1e-300)
    return np.where(ok, lam, np.inf)


def _char_poly(G):
    """Coefficients of ``det(l I - G) = l^3 - c1 l^2 + c2 l - c3`` of symmetric 3 x 3 matrices,
    each moved by a bound on its rounding in the direction that raises the largest root (it grows
    with ``c1`` and ``c3`` and falls with ``c2``)."""
    return _char_poly_entries(G[..., 0, 0], G[..., 1, 1], G[..., 2, 2], G[..., 0, 1], G[..., 0, 2], G[..., 1, 2])


def _char_poly_entries(g00, g11, g22, g01, g02, g12):
    """:func:`_char_poly` from the six distinct entries (arrays of one shape)."""
    c1 = (g00 + g11 + g22) * (1.0 + 8.0 * _U)
    p2 = [g00 * g11, g01 * g01, g00 * g22, g02 * g02, g11 * g22, g12 * g12]
    c2 = p2[0] - p2[1] + p2[2] - p2[3] + p2[4] - p2[5]
    c2 = c2 - 8.0 * _U * sum(np.abs(t) for t in p2)
    p3 = [
        g00 * (g11 * g22),
        g00 * (g12 * g12),
        g01 * (g01 * g22),
        g01 * (g12 * g02),
        g02 * (g01 * g12),
        g02 * (g11 * g02),
    ]
    c3 = p3[0] - p3[1] - p3[2] + p3[3] + p3[4] - p3[5]
    c3 = c3 + 12.0 * _U * sum(np.abs(t) for t in p3)
    return c1, c2, c3


def _above_roots(lam, a1, a2, a3):
    """Whether ``lam`` is proven above every real root: the cubic and its first two derivatives
    positive there (beyond, they stay so: the third derivative is 6), rounding accounted for."""
    mag = ((lam + np.abs(a1)) * lam + np.abs(a2)) * lam + np.abs(a3)
    p = ((lam - a1) * lam + a2) * lam - a3
    dp = (3.0 * lam - 2.0 * a1) * lam + a2
    ddp = 3.0 * lam - a1
    return (
        (p > 16 * _U * mag)
        & (dp > 16 * _U * (3.0 * lam * lam + 2.0 * np.abs(a1) * lam + np.abs(a2)))
        & (ddp > 16 * _U * (3.0 * lam + np.abs(a1)))
    )


def _prove(cand: np.ndarray, a1, a2, a3) -> None:
    """Where ``cand`` is not proven above every root, replace it (in place) by Newton's bound."""
    a1, a2, a3 = (np.broadcast_to(a, cand.shape) for a in (a1, a2, a3))
    bad = ~_above_roots(cand, a1, a2, a3)
    if bad.any():
        cand[bad] = _largest_root(a1[bad], a2[bad], a3[bad])


def _mat(v: np.ndarray, m: int) -> np.ndarray:
    """Column-major vectors (..., 3 m) as matrices (..., 3, m)."""
    return np.swapaxes(v.reshape(v.shape[:-1] + (m, 3)), -1, -2)


#: the six entries 00, 11, 22, 01, 02, 12 of a symmetric 3 x 3 matrix
_SYM = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def _eig_estimate(G: np.ndarray) -> np.ndarray:
    """The largest eigenvalue of symmetric 3 x 3 matrices by the closed form (Smith 1961), a
    candidate only: the bound proves or raises it."""
    return _eig_estimate_entries(G[..., 0, 0], G[..., 1, 1], G[..., 2, 2], G[..., 0, 1], G[..., 0, 2], G[..., 1, 2])


def _eig_estimate_entries(g00, g11, g22, g01, g02, g12):
    """:func:`_eig_estimate` from the six distinct entries."""
    q = (g00 + g11 + g22) / 3.0
    off = g01**2 + g02**2 + g12**2
    d0, d1, d2 = g00 - q, g11 - q, g22 - q
    p = np.sqrt(np.maximum((d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * off) / 6.0, 0.0))
    with np.errstate(all="ignore"):
        det = d0 * (d1 * d2 - g12**2) - g01 * (g01 * d2 - g12 * g02) + g02 * (g01 * g12 - d1 * g02)
        r = np.where(p > 0, det / (2.0 * p**3), 0.0)
    phi = np.arccos(np.clip(r, -1.0, 1.0)) / 3.0
    lam = q + 2.0 * p * np.cos(phi)
    return np.where(np.isfinite(lam), lam, np.inf)


def lambda_max_bound(G: np.ndarray, err: np.ndarray, reduce_last: bool = False) -> np.ndarray:
    """Upper bounds of the largest eigenvalue of symmetric 3 x 3 matrices within ``err`` (entrywise,
    (..., 6) in the order of ``_SYM``) of the computed ``G`` (..., 3, 3): the largest root of the
    characteristic polynomial with its coefficients' rounding (:func:`_char_poly`), plus the
    Frobenius norm of the error (Weyl).  With ``reduce_last``, one bound for the whole last batch
    axis (the largest candidate is checked against every matrix)."""
    return lambda_max_bound_entries(tuple(G[..., r, c] for r, c in _SYM), err, reduce_last)


def lambda_max_bound_entries(e: tuple, err: np.ndarray, reduce_last: bool = False) -> np.ndarray:
    """:func:`lambda_max_bound` from the six distinct entries ``e`` (in the order of ``_SYM``, arrays
    of one shape ``S``), with ``err`` of shape ``S + (6,)`` or broadcastable to it."""
    c1, c2, c3 = _char_poly_entries(*e)
    lam = _eig_estimate_entries(*e)
    if reduce_last:
        lam = np.broadcast_to(lam.max(axis=-1, keepdims=True), lam.shape)
    s = np.where(np.abs(c1) > 1e-100, np.abs(c1), 1.0)
    a1, a2, a3 = c1 / s, c2 / (s * s), c3 / (s * s * s)
    cand = np.maximum(lam / s, 0.0) * (1.0 + 1e-12) + 1e-13
    _prove(cand, a1, a2, a3)
    frob = np.sqrt(
        err[..., 0] ** 2
        + err[..., 1] ** 2
        + err[..., 2] ** 2
        + 2.0 * (err[..., 3] ** 2 + err[..., 4] ** 2 + err[..., 5] ** 2)
    )
    out = _up(cand * s * (1.0 + 8.0 * _U) + frob * (1.0 + 8.0 * _U))
    return out.max(axis=-1) if reduce_last else out


#: tangent pieces per arc at most (None: the most, up to PIECES_CAP, keeping a box's tuples within
#: POLYGON_TUPLES); the excess falls with the square of the pieces, the work grows with the tuples
#: (Puma 560, five joints: seven pieces proved in 14 s what four proved in 31 s)
POLYGON_PIECES = None
POLYGON_TUPLES = 60000
#: the most tangent pieces a box is bounded with (more pieces a joint cost more than they save)
PIECES_CAP = 8
#: with a level to prove: the share of the room below it a refined bound is planned to use
REFINE_SPARE = 0.5
#: a box is bounded again with more pieces when its bound with two is within this fraction of sigma_1
#: at its centre (a wider excess is rarely decided by the finer bound, at four times the cost)
REFINE = 0.1
TUPLES_PER_CHUNK = 1 << 18  # tuples bounded in one pass: the eigenvalue bound's work arrays stay small
#: a bound of every coordinate of an arc polygon's points, their rounding included: the tangents'
#: crossings lie at 1 / cos(step / 2) <= 1 / cos(pi / 8) = 1.08239..., the rectangles' corners at 1
POINT_RADIUS = 1.0825


def arc_polygons(a: np.ndarray, b: np.ndarray, pieces: int = 2):
    """``pieces + 2`` points per arc ``[a, b]`` of the unit circle (arrays (n,)) whose convex hull
    holds the arc: the end points and the crossings of the tangents at ``pieces + 1`` equally spaced
    angles from ``a`` to ``b`` (arcs up to a quarter turn; between two tangents ``d`` apart the
    crossing lies at radius ``1 / cos(d / 2)``), else the corners of the arc's bounding rectangle
    (repeated to the same count).  Returns ``(P, rad)``: the points (n, pieces + 2, 2) and a bound
    of each coordinate's rounding (n, pieces + 2, 2)."""
    # the arc widened by its end points' rounding, so that it holds the exact one
    a = a - 4.0 * _U * (np.abs(a) + 1.0)
    b = b + 4.0 * _U * (np.abs(b) + 1.0)
    h = 0.5 * (b - a)
    small = h <= np.pi / 4
    step = 2.0 * np.minimum(h, np.pi / 4) / pieces  # between tangent angles
    rho = 1.0 / np.cos(step / 2)
    ang = np.stack([a] + [a + (i + 0.5) * step for i in range(pieces)] + [b], axis=1)
    rad_ = np.concatenate([np.ones((len(a), 1)), np.repeat(rho[:, None], pieces, axis=1), np.ones((len(a), 1))], axis=1)
    P_small = np.stack([rad_ * np.cos(ang), rad_ * np.sin(ang)], axis=2)
    # bounding rectangle: the extremes of cos and sin over [a, b], end points and the crossings
    # of the axes inside
    ca_, cb_, sa_, sb_ = np.cos(a), np.cos(b), np.sin(a), np.sin(b)

    def hits(phase):
        k = np.ceil((a - phase) / (2 * np.pi))
        return phase + 2 * np.pi * k <= b

    xmax = np.where(hits(0.0), 1.0, np.maximum(ca_, cb_))
    xmin = np.where(hits(np.pi), -1.0, np.minimum(ca_, cb_))
    ymax = np.where(hits(np.pi / 2), 1.0, np.maximum(sa_, sb_))
    ymin = np.where(hits(-np.pi / 2), -1.0, np.minimum(sa_, sb_))
    xs, ys = (xmin, xmax, xmax, xmin), (ymin, ymin, ymax, ymax)  # the corners, repeated to the count
    P_big = np.stack([np.stack([xs[min(i, 3)], ys[min(i, 3)]], 1) for i in range(pieces + 2)], axis=1)
    P = np.where(small[:, None, None], P_small, P_big)
    # library sin/cos are within an ulp or two; the angles' own rounding moves a point along the
    # tangent lines by at most the same relative amount: 64 units of roundoff cover both
    rad = 64.0 * _U * (np.abs(P) + 1.0)
    return P, rad


def _sigma(M: np.ndarray) -> np.ndarray:
    """The largest singular value of each matrix ``M`` (n, 3, m), floating point (a value, not a bound)."""
    return np.sqrt(np.maximum(np.linalg.eigvalsh(M @ np.swapaxes(M, -1, -2))[:, -1], 0.0))


def _halves(a: np.ndarray, b: np.ndarray):
    """Rows ``i`` and ``i + n/2`` that are the two halves of one box along one joint (the branch and
    bound bounds both halves of each box it splits in one call, the lower halves first): their
    indices and that joint; any other batch has none."""
    nb, k = a.shape
    h = nb // 2
    if nb < 2 or nb % 2:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    same = (a[:h] == a[h:]) & (b[:h] == b[h:])
    j = np.argmin(same, axis=1)
    r = np.arange(h)
    ok = (same.sum(axis=1) == k - 1) & (b[r, j] == a[h + r, j])
    return r[ok], r[ok] + h, j[ok]


#: per joint, the products of two factors (1, cos, sin) as the monomials (1, c, s, c^2, cs, s^2)
_FOLD = np.zeros((3, 3, 6))
for _a, _b, _mu in [(0, 0, 0), (0, 1, 1), (1, 0, 1), (0, 2, 2), (2, 0, 2), (1, 1, 3), (1, 2, 4), (2, 1, 4), (2, 2, 5)]:
    _FOLD[_a, _b, _mu] = 1.0


class PolygonSigmaBounds:
    """Upper bounds of ``sigma_1`` over boxes of joint angles for a serial chain, from the exact
    trigonometric polynomial of ``A`` (:func:`tolsynth.analysis.certify_structure.trig_polynomial`).

    ``A`` has degree one in each pair ``(cos t_j, sin t_j)``, so over a box it stays in the convex
    hull of its values at the ``(pieces + 2)^k`` tuples of polygon points that hold each joint's arc
    (:func:`arc_polygons`; multi-affine maps send products of convex sets into the hull of the
    images of their vertices), and ``sigma_1``, a norm of ``A W^1/2``, is largest at one of them.
    The excess over the true maximum is a scaling of each joint's part of ``A`` by at most
    ``1 / cos(h / pieces) - 1 ~ h^2 / (2 pieces^2)`` (h: the half-width): small where a joint moves little of the
    error, which is where a Taylor bound is least efficient.

    At the tuples only ``V = A W A^T`` is needed: its six entries are polynomials of degree two in
    each pair, with coefficients ``Gamma`` formed once per set of variances from the exact ones of
    ``A``; every floating-point step carries a bound on its rounding (from the same sums taken
    over absolute values).
    """

    def __init__(self, poly, free, w, pieces: int | None = None):
        T = np.vectorize(float, otypes=[float])(poly.coefficients)  # exact values, rounded to nearest
        self.k = T.ndim - 1
        pieces = POLYGON_PIECES if pieces is None else pieces
        if pieces is None:
            pieces = max([p for p in range(3, PIECES_CAP + 1) if (p + 2) ** self.k <= POLYGON_TUPLES], default=2)
        self.pieces = int(pieces)
        self.na = T.shape[0]
        self.m = self.na // 3
        self.free = tuple(free)
        self.offsets = np.array([float(o) for o in poly.offsets])
        w = np.asarray(w, dtype=float)
        self.sw = np.sqrt(w)
        self.T = T
        k, m = self.k, self.m
        T3 = T.reshape(m, 3, 3**k)  # (column, row, monomial)
        Tw = T3 * w[:, None, None]
        gam, gabs = [], []
        for r, c in _SYM:
            P = Tw[:, r, :].T @ T3[:, c, :]  # (3^k, 3^k): coefficient of b_alpha b_beta
            Pabs = np.abs(Tw[:, r, :]).T @ np.abs(T3[:, c, :])
            gam.append(self._fold(P))
            gabs.append(self._fold(Pabs))
        self.gamma = np.stack(gam).reshape(6, 6**k)
        # rounding of T (half an ulp each), of the products and sums above (m + 2k + 8 roundings)
        self.gamma_abs = np.stack(gabs).reshape(6, 6**k) * (1.0 + (m + 2 * k + 12) * 2.0 * _U)
        self.gamma_err = self.gamma_abs * ((m + 2 * k + 12) * 2.0 * _U)
        # one error bound of the tuples' entries for every box: Gamma's own, the points' (64 u
        # relative per coordinate, two per monomial) and the contraction's (two roundings per
        # joint), at the largest monomials any polygon point has (|x|, |y| <= POINT_RADIUS)
        r = POINT_RADIUS
        top = np.array([1.0, r, r, r * r, r * r, r * r])
        e = (self.gamma_err + self.gamma_abs * ((130.0 + 4.0) * (k + 1) * _U)).reshape((6,) + (6,) * k)
        for _ in range(k):
            e = e @ top
        self.err = _up(e * (1.0 + 8.0 * (k + 1) * _U))

    def _fold(self, P: np.ndarray) -> np.ndarray:
        """(3^k, 3^k) coefficients of ``b_alpha(t) b_beta(t)`` -> (6,)*k of the monomials per joint."""
        k = self.k
        X = P.reshape((3,) * (2 * k))
        # interleave (alpha_1, beta_1, alpha_2, beta_2, ...) and fold each pair into 6 monomials
        X = X.transpose([i // 2 + (k if i % 2 else 0) for i in range(2 * k)])
        for j in range(k):
            X = np.tensordot(X, _FOLD, axes=([0, 1], [0, 1]))  # the pair of joint j -> its 6, at the end
        return X

    def _contract(self, g, V):
        """``g`` (6, 6^k) contracted per joint with ``V[j]`` (n, p_j, 6): shape (n, 6, prod p_j), the
        tuples with the first joint's point most significant (the halves of a box read that
        joint's index off it): compiled (:mod:`tolsynth.analysis.certify_kernels`); else by NumPy,
        the last joint first, so that the index summed (six terms each time, as a plain sum) is
        always the last axis, one batched matrix product per joint, the tuples' axes reversed at
        the end."""
        n, k = V[0].shape[0], self.k
        out = contract(g, V)  # compiled: box after box in cache (None without a compiler)
        if out is not None:
            return out
        X = np.matmul(g.reshape(1, 6**k, 6), np.swapaxes(V[k - 1], 1, 2))  # (n, 6 * 6^(k-1), p_k)
        done = V[k - 1].shape[1]
        for j in range(k - 2, -1, -1):
            rest = X.shape[1] // 6
            X = np.swapaxes(X.reshape(n, rest, 6, done), 2, 3).reshape(n, rest * done, 6)
            X = np.matmul(X, np.swapaxes(V[j], 1, 2)).reshape(n, rest, done * V[j].shape[1])
            done *= V[j].shape[1]
        p = [v.shape[1] for v in V]
        X = X.reshape((n, 6) + tuple(reversed(p)))  # (p_k, ..., p_1): reversed to (p_1, ..., p_k)
        return np.ascontiguousarray(X.transpose((0, 1) + tuple(range(k + 1, 1, -1)))).reshape(n, 6, -1)

    @staticmethod
    def _monomials(x, y):
        return np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=-1)

    def values(self, Q: np.ndarray) -> np.ndarray:
        """``A`` at joint values Q (n, k) of the searched joints, shape (n, 3, m) (floating point)."""
        return self.jet(Q, derivatives=False)[0]

    def jet(self, Q: np.ndarray, derivatives: bool = True):
        """``A`` and its derivative along each searched joint at joint values Q (n, k): shapes
        (n, 3, m) and (n, k, 3, m) (floating point; None without ``derivatives``): compiled
        (:func:`tolsynth.analysis.certify_kernels.jet`), else by NumPy, one pass over the joints
        from the first."""
        t = np.atleast_2d(Q) + self.offsets
        compiled = jet(self.T.reshape(self.na, -1), t, derivatives)  # None: no compiler
        if compiled is not None:
            A, dA = compiled
            return _mat(A, self.m), None if dA is None else _mat(dA, self.m)
        n, k = t.shape
        A, dA = np.empty((n, self.na)), np.empty((n, k, self.na)) if derivatives else None
        for s in range(0, n, 64):  # the first joint's partial sums are n x na x 3^(k-1)
            tt = t[s : s + 64]
            val, grads = self.T.reshape(1, self.na, 3**k), None
            for j in range(k):
                c, sn = np.cos(tt[:, j]), np.sin(tt[:, j])
                b = np.stack([np.ones(len(tt)), c, sn], axis=1)
                db = np.stack([np.zeros(len(tt)), -sn, c], axis=1)
                X = val.reshape(val.shape[0], self.na, 3, -1)
                cc, ss = c[:, None, None], sn[:, None, None]
                if grads is not None:
                    G = grads.reshape(grads.shape[:3] + (3, -1))
                    grads = G[:, :, :, 0] + G[:, :, :, 1] * cc[:, None] + G[:, :, :, 2] * ss[:, None]
                if X.shape[0] == 1:  # the first joint: one matrix product over every box
                    both = np.tensordot(np.concatenate([b, db]), X[0], axes=([1], [1]))
                    new, d = both[: len(tt)], both[len(tt) :]
                else:
                    new, d = X[:, :, 0] + X[:, :, 1] * cc + X[:, :, 2] * ss, X[:, :, 2] * cc - X[:, :, 1] * ss
                if derivatives:
                    grads = d[:, None] if grads is None else np.concatenate([grads, d[:, None]], axis=1)
                val = new
            A[s : s + 64] = val[..., 0]
            if derivatives:
                dA[s : s + 64] = grads[..., 0]
        return _mat(A, self.m), None if dA is None else _mat(dA, self.m)

    def point(self, Q: np.ndarray) -> np.ndarray:
        """``sigma_1`` at points (n, k) (floating point: the best value found, not a bound)."""
        return _sigma(self.values(Q) * self.sw)

    def _bound(self, a: np.ndarray, b: np.ndarray, pieces: int) -> np.ndarray:
        """Upper bounds of sigma_1 on the arcs ``[a, b]`` (n, k), ``pieces`` tangent pieces on each
        arc up to a quarter turn (a wider one has its rectangle's four corners: more would repeat
        them), the boxes grouped by which of their arcs are wide.  The two halves of one box
        (:func:`_halves`) share their other joints' points: their tuples come from one contraction
        over those joints, the halved joint's monomials left free, and a small product each."""
        nb, k = a.shape
        ub = np.empty(nb)
        wide = 0.5 * (b - a) > np.pi / 4
        groups = (
            [np.arange(nb)]
            if pieces == 2
            else [np.flatnonzero((wide == w).all(axis=1)) for w in np.unique(wide, axis=0)]
        )
        lo_half, hi_half, joint = _halves(a, b)
        for rows in groups:
            V = []
            for j in range(k):
                P, rad = arc_polygons(a[rows, j], b[rows, j], 2 if pieces == 2 or wide[rows[0], j] else pieces)
                if not np.all(np.abs(P) + rad <= POINT_RADIUS):  # self.err assumes it
                    raise RuntimeError("an arc polygon's point lies beyond POINT_RADIUS")
                V.append(self._monomials(P[..., 0], P[..., 1]))
            at = np.full(nb, -1)
            at[rows] = np.arange(len(rows))
            paired = (at[lo_half] >= 0) & (at[hi_half] >= 0)
            single = np.ones(len(rows), dtype=bool)
            for j in range(k):
                sel = paired & (joint == j)
                if not sel.any():
                    continue
                i1, i2 = at[lo_half[sel]], at[hi_half[sel]]
                single[i1] = single[i2] = False
                rest = [i for i in range(k) if i != j]
                # the chunks below in the order that lets the contraction share the most
                o = share_order([V[i][i1] for i in rest], len(i1))
                i1, i2 = i1[o], i2[o]
                free = np.broadcast_to(np.eye(6), (len(i1), 6, 6))  # the halved joint's monomials, left free
                chunk = max(1, TUPLES_PER_CHUNK // (6 * int(np.prod([V[i].shape[1] for i in rest]))))
                for s in range(0, len(i1), chunk):
                    part = slice(s, min(len(i1), s + chunk))
                    X = self._contract(self._first(j), [free[part]] + [V[i][i1[part]] for i in rest])
                    X = np.swapaxes(X.reshape(X.shape[0], 6, 6, -1), 2, 3)  # (n, entry, tuple, monomial)
                    for idx in (i1[part], i2[part]):
                        g = np.matmul(X, np.swapaxes(V[j][idx], 1, 2)[:, None]).reshape(len(idx), 6, -1)
                        ub[rows[idx]] = self._largest(g)
            idx = np.flatnonzero(single)
            idx = idx[share_order([v[idx] for v in V], len(idx))]
            chunk = max(1, TUPLES_PER_CHUNK // int(np.prod([v.shape[1] for v in V])))
            for s in range(0, len(idx), chunk):
                part = idx[s : s + chunk]
                ub[rows[part]] = self._largest(self._contract(self.gamma, [v[part] for v in V]))
        return ub

    def _first(self, j: int) -> np.ndarray:
        """The coefficients with joint ``j``'s axis first (the others in order), built once."""
        cache = self.__dict__.setdefault("_firsts", {})
        if j not in cache:
            G = self.gamma.reshape((6,) + (6,) * self.k)
            cache[j] = np.ascontiguousarray(np.moveaxis(G, 1 + j, 1).reshape(6, -1))
        return cache[j]

    def _largest(self, g: np.ndarray) -> np.ndarray:
        """Upper bounds of sigma_1 over each box's tuples ``g`` (n, 6, tuples), their entries within
        ``self.err``: compiled box after box, else (or where a tuple proved nothing) by NumPy."""
        err = np.broadcast_to(self.err[None, :], (len(g), 6))
        lam, ok = np.empty(len(g)), np.zeros(len(g), dtype=bool)
        compiled = lambda_max(g, err)  # None: no compiler
        if compiled is not None:
            lam, ok = _up(compiled[0]), compiled[1]
        if not ok.all():
            lam[~ok] = lambda_max_bound_entries(
                tuple(g[~ok, i, :] for i in range(6)), err[~ok][:, None, :], reduce_last=True
            )
        return _up(np.sqrt(np.maximum(lam, 0.0)))

    def bound(self, L: np.ndarray, H: np.ndarray, level: float | None = None):
        """``(ub, split)`` as :meth:`SigmaBounds.bound`.  Every box is bounded with four points a
        joint first.  Given ``level``, the value a box must be proven below to be set aside, a box
        above it whose centre is below it is bounded again with the fewest tangent pieces (at most
        ``self.pieces``) that would bring it below, were the bound's excess over sigma_1 at the
        centre all the polygons' (it falls with the square of the pieces): with half of it to
        spare, as the excess is partly the true rise; a box no count can decide is only halved.
        Without ``level``, a box whose bound is within REFINE of sigma_1 at its centre (where the
        maximum is flat) is bounded again with ``self.pieces``.  The smaller bound is kept."""
        nb, k = len(L), self.k
        a = L + self.offsets
        b = H + self.offsets
        used = np.full(nb, 2)
        with np.errstate(all="ignore"):
            ub = self._bound(a, b, 2)
            A, dA = self.jet(0.5 * (L + H))
            M = A * self.sw
            if self.pieces > 2 and nb:
                centre = _sigma(M)
                if level is not None and np.isfinite(level):
                    need = 2.0 * np.sqrt((ub - centre) / (REFINE_SPARE * (level - centre)))
                    pieces = np.maximum(3, np.ceil(need))
                    again = (ub > level) & (centre < level) & np.isfinite(ub) & (pieces <= self.pieces)
                else:
                    pieces = np.full(nb, self.pieces)
                    again = np.isfinite(ub) & (ub - centre <= REFINE * centre)
                for p in np.unique(pieces[again]).astype(int):
                    rows = np.flatnonzero(again & (pieces == p))
                    ub[rows] = np.fmin(ub[rows], self._bound(a[rows], b[rows], p))
                    used[rows] = p
            # where to halve: each joint's derivative of V = A W A^T at the centre (its six distinct
            # entries) times the scaling it allows
            split = np.empty((nb, k))
            for j in range(k):
                D = (dA[:, j] * self.sw) @ np.swapaxes(M, -1, -2)
                dV = np.stack([D[:, r, c] + D[:, c, r] for r, c in _SYM], axis=1)
                h = 0.5 * (b[:, j] - a[:, j])
                grow = np.where(h <= np.pi / 4, 1.0 / np.cos(np.minimum(h, np.pi / 4) / used) - 1.0, 1.0 + h)
                split[:, j] = grow * np.sqrt((dV**2).sum(axis=1))
        ub = np.where(np.isfinite(ub), ub, np.inf)
        return ub, split
