"""Arc polygons with more tangent pieces: their hull holds the arc (SciPy's convex hull of the
points, checked at dense points of the arc), the polygons nest (more pieces, a smaller hull, so a
bound no larger), and the Puma 560's bound holds at dense random poses of random boxes
(sigma_1 from ``Mechanism.sensitivity`` and NumPy's eigensolver).  Every polygon point lies within
the radius the tuples' error bound assumes, and the sensitivity and its derivatives at the boxes'
centres (which choose the joint to halve) match the CasADi graph and its central differences."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

import tolsynth
from independent import sigma_max
from tolsynth.analysis.certify_polygon import POINT_RADIUS, PolygonSigmaBounds, _halves, arc_polygons
from tolsynth.analysis.certify_structure import structure, trig_polynomial


def _arm(name):
    """A model, its searched joints, its first tolerance set, the polynomial of ``A`` and the
    variances of its kept columns (uniform errors)."""
    mech = tolsynth.load_model(name)
    st = structure(mech)
    free = [j for j in st.joints if j != st.rotation]
    eps = mech.tolerances(list(mech.tolerance_sets)[0])
    return mech, free, eps, trig_polynomial(st, free, st.rotation), (eps**2 / 3.0)[list(st.columns)]


def _largest_found(mech, free, eps, lo, hi, n, rng):
    """The largest sigma_1 at n random poses of the box (the other joints at 0): ``sigma_max``."""
    q = np.zeros((n, len(mech.joint_names)))
    q[:, free] = lo + (hi - lo) * rng.random((n, len(free)))
    return sigma_max(mech, q, eps).max()


@pytest.mark.parametrize("pieces", [2, 3, 4, 6])
def test_polygon_holds_the_arc(pieces):
    rng = np.random.default_rng(pieces)
    a = rng.uniform(-7.0, 7.0, 40)
    b = a + np.concatenate([rng.uniform(1e-4, np.pi / 2, 30), rng.uniform(np.pi / 2, 2 * np.pi, 10)])
    P, rad = arc_polygons(a, b, pieces)
    assert P.shape == (40, pieces + 2, 2) and rad.shape == P.shape
    for i in range(40):
        hull = ConvexHull(P[i])
        t = np.linspace(a[i], b[i], 2001)
        pts = np.stack([np.cos(t), np.sin(t)], axis=1)
        # inside every facet, to the points' stated rounding
        assert (pts @ hull.equations[:, :2].T + hull.equations[:, 2] <= 4 * rad[i].max()).all()


def test_more_pieces_a_smaller_polygon():
    # the tangents of two pieces are among those of four: the hull of four pieces lies in that of two
    rng = np.random.default_rng(1)
    a = rng.uniform(-4.0, 4.0, 30)
    b = a + rng.uniform(1e-3, np.pi / 2, 30)
    P2, _ = arc_polygons(a, b, 2)
    P4, _ = arc_polygons(a, b, 4)
    for i in range(30):
        eq = ConvexHull(P2[i]).equations
        assert (P4[i] @ eq[:, :2].T + eq[:, 2] <= 1e-13).all()


def test_puma_bounds_hold_and_tighten_with_pieces():
    mech, free, eps, poly, w = _arm("puma560")
    rng = np.random.default_rng(7)
    c = rng.uniform(-3, 3, (12, len(free)))
    h = rng.uniform(0.01, 0.5, (12, len(free)))
    ub2, _ = PolygonSigmaBounds(poly, free, w, pieces=2).bound(c - h, c + h)
    ub4, split = PolygonSigmaBounds(poly, free, w, pieces=4).bound(c - h, c + h)
    assert (ub4 <= ub2 * (1 + 1e-12)).all() and (ub4 < ub2).any()
    assert np.isfinite(split).all() and (split >= 0).all()
    for i in range(12):
        found = _largest_found(mech, free, eps, c[i] - h[i], c[i] + h[i], 120, rng)
        assert found <= ub4[i]
        # a box's bound is no lower than the largest value found in it, nor far above it on small boxes
        if h[i].max() < 0.1:
            assert ub4[i] <= found * 1.01


@pytest.mark.parametrize("pieces", [2, 3, 4, 6])
def test_polygon_points_within_the_assumed_radius(pieces):
    # the tangents' crossings of arcs up to a quarter turn lie at 1 / cos(step / 2) <= 1 / cos(pi / 8)
    assert 1.0 / np.cos(np.pi / 8) < POINT_RADIUS < 1.0 / np.cos(np.pi / 8) + 1e-3
    rng = np.random.default_rng(10 + pieces)
    a = rng.uniform(-50.0, 50.0, 400)
    wid = np.concatenate(
        [rng.uniform(1e-9, np.pi / 2, 300), np.pi / 2 * (1 - rng.uniform(0, 1e-12, 50)), rng.uniform(2, 7, 50)]
    )
    P, rad = arc_polygons(a, a + wid, pieces)
    assert (np.abs(P) + rad <= POINT_RADIUS).all()
    # the quarter turns' crossings reach the radius of the closed form
    assert np.hypot(P[..., 0], P[..., 1]).max() > 1.0 / np.cos(np.pi / (4 * pieces)) - 1e-9


@pytest.mark.parametrize("model", ["puma560", "panda"])
def test_jet_matches_the_graph_and_central_differences(model):
    mech, free, _, poly, w = _arm(model)
    cols = list(structure(mech).columns)
    b = PolygonSigmaBounds(poly, free, w)
    rng = np.random.default_rng(3)
    X = rng.uniform(-3, 3, (5, len(free)))
    A, dA = b.jet(X)

    def sens(x):
        q = np.zeros(len(mech.joint_names))
        q[free] = x
        return mech.sensitivity(q, check_limits=False)[:3][:, cols]

    d = 1e-6
    for i in range(5):
        assert np.allclose(A[i], sens(X[i]), atol=1e-12)
        for j in range(len(free)):
            e = np.zeros(len(free))
            e[j] = d
            fd = (sens(X[i] + e) - sens(X[i] - e)) / (2 * d)
            assert np.allclose(dA[i, j], fd, atol=1e-6)


def test_halves_of_a_box_bounded_together_hold():
    # the branch and bound's batch: the lower halves of boxes, then their upper halves; the halves
    # share one contraction over their other joints.  Each half's bound holds at dense random poses
    # (sigma_max: Mechanism.sensitivity) and equals the bound of that half alone
    mech, free, eps, poly, w = _arm("ur5")
    b = PolygonSigmaBounds(poly, free, w)
    rng = np.random.default_rng(11)
    n, k = 6, len(free)
    c = rng.uniform(-3, 3, (n, k))
    h = rng.uniform(0.01, 0.3, (n, k))
    j = rng.integers(0, k, n)
    r = np.arange(n)
    lo, hi = c - h, c + h
    A_hi, B_lo = hi.copy(), lo.copy()
    A_hi[r, j] = c[r, j]
    B_lo[r, j] = c[r, j]
    L, H = np.concatenate([lo, B_lo]), np.concatenate([A_hi, hi])
    assert len(_halves(L + b.offsets, H + b.offsets)[0]) == n  # every pair found
    ub, _ = b.bound(L, H)
    alone = np.array([b.bound(L[i : i + 1], H[i : i + 1])[0][0] for i in range(2 * n)])
    assert np.allclose(ub, alone, rtol=1e-9, atol=0)
    for i in range(2 * n):
        found = _largest_found(mech, free, eps, L[i], H[i], 150, rng)
        assert found <= ub[i] <= found * 1.05


def test_bounds_with_a_level_hold_and_refine_the_undecided():
    # given the level a box must be proven below, the boxes above it are bounded again with more
    # points: each bound still holds at dense poses (sigma_max), none is above the four-point
    # bound, and some undecided boxes are brought below the level
    mech, free, eps, poly, w = _arm("puma560")
    b = PolygonSigmaBounds(poly, free, w)
    rng = np.random.default_rng(5)
    c = rng.uniform(-2.5, 2.5, len(free)) + rng.uniform(-0.05, 0.05, (40, len(free)))  # near one pose
    h = rng.uniform(0.02, 0.15, (40, len(free)))
    four, _ = PolygonSigmaBounds(poly, free, w, pieces=2).bound(c - h, c + h)
    centre = b.point(c)
    level = float(np.median(0.5 * (four + centre)))  # between the centres and the four-point bounds
    ub, _ = b.bound(c - h, c + h, level)
    assert (ub <= four * (1 + 1e-12)).all()
    assert ((four > level) & (ub <= level)).any()
    for i in range(40):
        assert _largest_found(mech, free, eps, c[i] - h[i], c[i] + h[i], 80, rng) <= ub[i]


def test_maximize_gives_the_level_to_a_level_aware_bound():
    from tolsynth.analysis.branch_bound import maximize

    seen = []

    def bound(lo, hi, level=None):  # minus the squared distance from (0.3, 0.3) to the box, loosened
        seen.append(level)
        return -((np.clip(0.3, lo, hi) - 0.3) ** 2).sum(axis=1) + 0.2 * (hi - lo).max(axis=1)

    r = maximize(
        bound, lambda x: -((x - 0.3) ** 2).sum(axis=1), [-1.0, -1.0], [2.0, 3.0], tol=1e-9, target=0.5, level_aware=True
    )
    # the maximum 0 is proven below the target 0.5 once the boxes are narrow: the halves were
    # bounded against it (the root, before any level, without one)
    assert r.certified and r.upper_bound <= 0.5 and seen[0] is None and set(seen[1:]) == {0.5}
