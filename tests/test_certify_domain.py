"""The certified searches' coordinates with a joint constraint taken as a coordinate: the same joint
space, the graphs in the new coordinates equal to the model's own sensitivity, and the exact bounds
on boxes of those coordinates sound against an FFT convolution at sampled feasible poses."""

from __future__ import annotations

import math

import numpy as np

import tolsynth
from tolsynth.analysis.certify_bounds import joint_graphs, taylor_enclosure
from tolsynth.analysis.certify_domain import domain, sheared
from tolsynth.analysis.certify_structure import structure
from tolsynth.kinematics.joint_space import _feasible


def _paper():
    m = tolsynth.load_model("xu_zhang_1988")
    st = structure(m)
    base = np.zeros(len(m.joint_names))
    return m, st, domain(m, st, base)


def _inside(m, dom, X):
    """The package's own feasibility test at searched joints X (n, k), the others held."""
    Q = np.zeros((len(m.joint_names), len(X)))
    for j, v in dom.held.items():
        Q[j] = v
    for i, j in enumerate(dom.free):
        Q[j] = X[:, i]
    return _feasible(m, Q)


def _rows_hold(dom, S):
    ok = np.all((S >= dom.lo) & (S <= dom.hi), axis=1)
    for a, lo, hi in dom.linear:
        v = S @ a
        ok &= (v >= lo - 1e-12) & (v <= hi + 1e-12)
    return ok


def test_sheared_domain_is_the_same_joint_space():
    m, st, dom = _paper()
    sd = sheared(m, dom)
    assert sd.M is not None and sd is not dom
    # the interference limit is now a face: its coordinate's range is the band (deg 50..130)
    assert np.isclose(np.degrees(sd.hi - sd.lo), [80.0, 80.0, 220.0]).sum() >= 2
    rng = np.random.default_rng(3)
    X = dom.lo + (dom.hi - dom.lo) * rng.random((4000, len(dom.free)))
    feasible = _inside(m, dom, X)
    assert 0.2 < feasible.mean() < 0.95  # the sample meets both sides of the limit
    # joints -> coordinates: inside the sheared box and rows exactly where feasible
    S = sd.coords(X)
    assert np.array_equal(_rows_hold(sd, S), feasible)
    np.testing.assert_allclose(sd.joints(S), X, atol=1e-13)
    # coordinates -> joints: every point of the sheared box meeting its rows is a feasible pose
    S = sd.lo + (sd.hi - sd.lo) * rng.random((4000, len(dom.free)))
    keep = _rows_hold(sd, S)
    assert keep.mean() > 0.3 and _inside(m, dom, sd.joints(S[keep])).all()
    # the constraint function agrees on points
    g_lo, g_hi = sd.constraint_fn(S[:200], S[:200])
    assert np.array_equal((g_hi <= 0).all(axis=1), keep[:200] & _inside(m, dom, sd.joints(S[:200])))


def test_sheared_graphs_are_the_model_sensitivity():
    m, st, dom = _paper()
    sd = sheared(m, dom)
    g = joint_graphs(st, len(m.joint_names), sd.free, sd.held, M=sd.M)
    rng = np.random.default_rng(4)
    S = sd.lo + (sd.hi - sd.lo) * rng.random((20, len(sd.free)))
    A = g.values(S)
    cols = list(st.columns)
    for s, a in zip(S, A):
        q = np.zeros(len(m.joint_names))
        for j, v in sd.held.items():
            q[j] = v
        q[sd.free] = sd.joints(s[None])[0]
        np.testing.assert_allclose(a, m.sensitivity(q, check_limits=False)[:3][:, cols], rtol=1e-10, atol=1e-10)


def test_exact_bounds_in_sheared_coordinates_are_sound():
    """Boxes along the interference limit (now a face) and across the replaced joint's limit (now a
    row crossing the box): each pair's bound stays below the probability, by FFT convolution, at
    feasible joints sampled in the box along sampled directions of the patch."""
    from independent import fft_probabilities
    from tolsynth.analysis.certify_exact_bounds import ExactBounds
    from tolsynth.probability.distributions import shapes_of

    m, st, dom = _paper()
    sd = sheared(m, dom)
    cols = list(st.columns)
    eps = m.tolerances("figure3")
    shapes = shapes_of("uniform", m.error_parameters, m.index)
    held = dict(sd.held)
    held[st.rotation] = 0.0
    enc = joint_graphs(st, len(m.joint_names), sd.free, held, third=True, M=sd.M)
    B = ExactBounds(enc, eps[cols], tuple(shapes[i] for i in cols), 0.3, sd.linear)
    rng = np.random.default_rng(5)
    n = 8
    C = sd.lo + (sd.hi - sd.lo) * rng.random((200, 3))
    C = C[_rows_hold(sd, C)][:n]  # feasible centres
    band = [i for i in range(3) if np.isclose(sd.hi[i] - sd.lo[i], math.radians(80.0)) and sd.M[i, i] == 1.0]
    h = 0.03
    # half of them on a face of the band's coordinate, the others where the replaced joint's limit
    # crosses them (its row through the centre)
    for i in range(n // 2):
        C[i, band[-1] if band else 0] = sd.lo[band[-1] if band else 0] + h
    a, lo_r, hi_r = sd.linear[0]
    for i in range(n // 2, n):
        j = int(np.flatnonzero(a)[0])
        C[i, j] += ((lo_r if i % 2 else hi_r) - C[i] @ a) / a[j]
    C = np.clip(C, sd.lo + h, sd.hi - h)
    box = taylor_enclosure(enc, C - h, C + h, sd.linear)
    faces = rng.integers(0, 3, n)
    ph = 2.0**-6
    s0 = rng.integers(0, int(2 / ph), n) * ph - 1.0
    t0 = rng.integers(0, int(2 / ph), n) * ph - 1.0
    checked = proven = 0
    for i in range(n):
        # the box's feasible corners along the patch's corner rays (every pair: where the bound is
        # tightest), then random feasible points along random directions of the patch
        corners = C[i] + h * np.array(np.meshgrid(*[[-1.0, 1.0]] * 3, indexing="ij")).reshape(3, -1).T
        corners = corners[_rows_hold(sd, corners)]
        rand = (C[i] - h) + 2 * h * rng.random((60, 3))
        rand = rand[_rows_hold(sd, rand)][:6]
        ray = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
        X = sd.joints(np.vstack([np.repeat(corners, 4, axis=0), rand]))
        st_ = np.vstack([np.tile(ray, (len(corners), 1)), rng.random((len(rand), 2))]) * ph + [s0[i], t0[i]]
        F = np.eye(3)[[faces[i], (faces[i] + 1) % 3, (faces[i] + 2) % 3]]
        U = F[0] + st_[:, :1] * F[1] + st_[:, 1:] * F[2]
        U /= np.linalg.norm(U, axis=1, keepdims=True)
        rows = [
            np.abs(u @ m.sensitivity(np.concatenate([[0.0], x, [0.0]]), check_limits=False)[:3]) * eps
            for x, u in zip(X, U)
        ]
        if not rows:
            continue
        checked += 1
        low = fft_probabilities(rows, 0.3, 1 << 14).min()
        # asked to prove a level a little below the sampled minimum, the bound runs its whole
        # refinement (corner groups, the feasible part's own points) and must stay below the minimum
        lb, *_ = B.pairs(box, np.array([i]), faces[i : i + 1], s0[i : i + 1], t0[i : i + 1], np.full(1, ph), low - 0.01)
        assert lb[0] <= low + 5e-5
        proven += lb[0] >= low - 0.01
    assert checked >= n - 1
    assert proven >= checked - 1  # and it is tight: the level is proven
