"""The compiled contraction of the arc-polygon bound: the same sums as a direct einsum of the
coefficient tensor with each joint's monomials, the same bounds as the NumPy path, and bounds that
hold at random poses of each box (sigma_1 from ``Mechanism.sensitivity`` and NumPy's eigensolver)."""

from __future__ import annotations

import numpy as np
import pytest

import tolsynth
from tolsynth.analysis.certify_kernels import contract, jet, lambda_max
from tolsynth.analysis.certify_polygon import PolygonSigmaBounds
from tolsynth.analysis.certify_structure import structure, trig_polynomial


def _check_boxes(g, V, out):
    """Each box's tuples against a direct einsum, within the rounding of sums of six products per
    joint at the sums of absolute values, and bit for bit against the box contracted alone (a
    box's tuples do not depend on the boxes contracted with it)."""
    k = len(V)
    T = g.reshape((6,) * (k + 1))
    letters = "abcdefgh"[:k]
    spec = "z" + letters + "," + ",".join(f"{c.upper()}{c}" for c in letters) + "->z" + letters.upper()
    for b in range(len(out)):
        ref = np.einsum(spec, T, *[v[b] for v in V], optimize=True).reshape(6, -1)
        mag = np.einsum(spec, np.abs(T), *[np.abs(v[b]) for v in V], optimize=True).reshape(6, -1)
        assert (np.abs(out[b] - ref) <= 16 * (k + 1) * 2.0**-53 * mag).all()
        assert np.array_equal(contract(g, [v[b : b + 1] for v in V])[0], out[b])


# two joints, four, six with six points each (the search's usual shape), and more points than
# monomials on a joint
@pytest.mark.parametrize("points", [(3, 5), (4, 1, 3, 4), (6, 6, 6, 6, 6, 6), (2, 8, 1, 3, 7)])
def test_contraction_against_einsum(points):
    rng = np.random.default_rng(0)
    g = rng.normal(size=(6, 6 ** len(points)))
    V = [rng.normal(size=(3, p, 6)) for p in points]
    out = contract(g, V)
    if out is None:
        pytest.skip("no C compiler (or TOLSYNTH_NO_COMPILE set)")
    _check_boxes(g, V, out)


@pytest.mark.parametrize("points", [(4, 4, 4, 4, 4, 4), (3, 5, 2)])
def test_contraction_of_boxes_sharing_points(points):
    # boxes drawn from two or three point sets a joint, in no order: the part the kernel keeps
    # between boxes that share their last joints' points changes no bit of any box's tuples
    rng = np.random.default_rng(2)
    g = rng.normal(size=(6, 6 ** len(points)))
    choices = [rng.normal(size=(int(rng.integers(2, 4)), p, 6)) for p in points]
    V = [c[rng.integers(0, len(c), 40)] for c in choices]
    out = contract(g, V)
    if out is None:
        pytest.skip("no C compiler (or TOLSYNTH_NO_COMPILE set)")
    _check_boxes(g, V, out)


def test_numpy_contraction_in_the_compiled_order(monkeypatch):
    # without a compiler the tuples come in the same order (the first joint's point most
    # significant): the halves of a box read that joint's index off it
    monkeypatch.setenv("TOLSYNTH_NO_COMPILE", "1")
    rng = np.random.default_rng(1)
    k, n = 4, 5
    g = rng.normal(size=(6, 6**k))
    V = [rng.normal(size=(n, p, 6)) for p in (3, 1, 6, 2)]
    B = PolygonSigmaBounds.__new__(PolygonSigmaBounds)
    B.k = k
    out = B._contract(g, V)
    T = g.reshape((6,) * (k + 1))
    for b in range(n):
        ref = np.einsum("eabcd,ia,jb,kc,ld->eijkl", T, *[v[b] for v in V]).reshape(6, -1)
        assert np.allclose(out[b], ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())


@pytest.mark.parametrize("T", [300, 1100])  # within one chunk of the kernel's passes, and across two
def test_compiled_eigenvalue_bound_holds(T):
    # per box the largest eigenvalue over its tuples: never below LAPACK's (to its own error),
    # within 1e-5 of it, also where the top two nearly meet (an isotropic error ellipsoid: the closed
    # form the candidate comes from loses half its digits there, and the candidate is raised: the
    # more tuples, the more raised candidates, 3e-7 above LAPACK's at 300 tuples, 2.4e-6 at 1 100)
    rng = np.random.default_rng(3)
    n = 40
    Q = np.linalg.qr(rng.normal(size=(n, T, 3, 3)))[0]
    lam = rng.uniform(0.01, 0.04, (n, T, 3))
    lam[:20, :, 1] = lam[:20, :, 2] * (1 - rng.uniform(0, 1e-9, (20, T)))  # near-degenerate
    G = np.einsum("ntij,ntj,ntkj->ntik", Q, lam, Q)
    g = np.stack([G[..., r, c] for r, c in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))], axis=1)
    res = lambda_max(g, np.full((n, 6), 1e-16))
    if res is None:
        pytest.skip("no C compiler (or TOLSYNTH_NO_COMPILE set)")
    out, ok = res
    ref = np.linalg.eigvalsh(G)[..., -1].max(axis=1)
    assert ok.all()
    assert (out >= ref * (1 - 1e-14)).all() and (out <= ref * (1 + 1e-5)).all()


@pytest.mark.parametrize("name", ["puma560", pytest.param("panda", marks=pytest.mark.slow)])  # panda: 3-7 s
def test_polygon_bounds_compiled_equal_numpy_and_hold(name, monkeypatch):
    mech = tolsynth.load_model(name)
    st = structure(mech)
    free = [j for j in st.joints if j != st.rotation]
    eps = mech.tolerances(list(mech.tolerance_sets)[0])
    w = (eps**2 / 3.0)[list(st.columns)]
    B = PolygonSigmaBounds(trig_polynomial(st, free, st.rotation), free, w)
    rng = np.random.default_rng(4)
    c = rng.uniform(-3, 3, (16, len(free)))
    h = rng.uniform(0, 0.4, (16, len(free)))
    ub, split = B.bound(c - h, c + h)
    monkeypatch.setenv("TOLSYNTH_NO_COMPILE", "1")
    ub0, split0 = B.bound(c - h, c + h)
    # the compiled eigenvalue bound proves its own candidate (within 1e-8 of the NumPy path's)
    np.testing.assert_allclose(ub, ub0, rtol=1e-8)
    np.testing.assert_allclose(split, split0, rtol=1e-12)
    held = {j: 0.0 for j in range(len(mech.joint_names)) if j not in free}
    for i in range(16):
        X = c[i] - h[i] + 2 * h[i] * rng.random((25, len(free)))
        for x in X:
            q = np.zeros(len(mech.joint_names))
            q[free] = x
            for j, v in held.items():
                q[j] = v
            A = mech.sensitivity(q, check_limits=False)[:3]
            s1 = np.sqrt(max(np.linalg.eigvalsh((A * (eps**2 / 3.0)) @ A.T)[-1], 0.0))
            assert s1 <= ub[i]


@pytest.mark.parametrize("name", ["puma560", "panda"])
def test_compiled_jet_against_the_sensitivity_and_central_differences(name, monkeypatch):
    # the centre's A from the trigonometric polynomial (compiled, and NumPy's path) equals the
    # CasADi graph's sensitivity; its derivatives equal central differences of that graph
    mech = tolsynth.load_model(name)
    st = structure(mech)
    free = [j for j in st.joints if j != st.rotation]
    eps = mech.tolerances(list(mech.tolerance_sets)[0])
    B = PolygonSigmaBounds(trig_polynomial(st, free, st.rotation), free, (eps**2 / 3.0)[list(st.columns)])
    rng = np.random.default_rng(7)
    Q = rng.uniform(-3, 3, (70, len(free)))  # more than one of the NumPy path's chunks of 64
    A, dA = B.jet(Q)
    if jet(B.T.reshape(B.na, -1), Q[:1] + B.offsets) is None:
        pytest.skip("no C compiler (or TOLSYNTH_NO_COMPILE set)")
    monkeypatch.setenv("TOLSYNTH_NO_COMPILE", "1")
    A0, dA0 = B.jet(Q)
    scale = np.abs(A0).max()
    np.testing.assert_allclose(A, A0, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(dA, dA0, rtol=0, atol=1e-13 * scale)
    assert B.jet(Q, derivatives=False)[1] is None
    cols, h = list(st.columns), 1e-6
    for i in range(0, 70, 7):
        q = np.zeros(len(mech.joint_names))
        q[free] = Q[i]
        S = mech.sensitivity(q, check_limits=False)[:3][:, cols]
        np.testing.assert_allclose(A[i], S, rtol=0, atol=1e-10 * np.abs(S).max())
        for jj, j in enumerate(free):
            dq = np.zeros_like(q)
            dq[j] = h
            up, down = (mech.sensitivity(q + s * dq, check_limits=False)[:3][:, cols] for s in (1, -1))
            np.testing.assert_allclose(dA[i, jj], (up - down) / (2 * h), rtol=0, atol=1e-6 * np.abs(S).max())


def test_the_kernels_built_for_this_processor_give_the_bits_of_the_plain_build(monkeypatch):
    # wider vectors, the same IEEE operations in the same order: every output bit equal
    import tolsynth.analysis.certify_kernels as K
    import tolsynth.cbuild as cbuild

    rng = np.random.default_rng(11)
    g = rng.normal(size=(6, 6**3))
    V = [rng.normal(size=(30, p, 6)) for p in (3, 4, 5)]
    G = rng.normal(size=(20, 3, 1100, 3))
    G = G @ np.swapaxes(G, -1, -2)
    e = np.stack([G[:, :, r, c] for r, c in ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))], axis=1)
    t = rng.uniform(-3, 3, (25, 3))
    T = rng.normal(size=(9, 27))
    runs = []
    for flags in (cbuild.NATIVE_FLAGS, []):
        monkeypatch.setattr(cbuild, "NATIVE_FLAGS", flags)
        monkeypatch.setattr(K, "_state", {})
        out = K.contract(g, V), K.lambda_max(e, np.full((20, 6), 1e-16)), K.jet(T, t)
        if out[0] is None:
            pytest.skip("no C compiler (or TOLSYNTH_NO_COMPILE set)")
        runs.append(out)
    (c1, (l1, o1), (a1, d1)), (c2, (l2, o2), (a2, d2)) = runs
    assert o1.all() and (o1 == o2).all()
    for x, y in ((c1, c2), (l1, l2), (a1, a2), (d1, d2)):
        assert x.tobytes() == y.tobytes()
