"""Symmetries of the sensitivity: maps of the joints (each kept, turned by half a turn or mirrored)
that change no column of ``A`` but its sign, ``A`` itself possibly turned by half a turn about the base
z axis, proven on the graph's exact polynomial up to a bounded residual (the twists' rounding); the
certified Gaussian search then covers a joint over half its range.  Checked against NumPy: the
model's own sensitivities at a pose and at its image, for the maps proven and for every other map of
the kind on the searched joints (which must really change ``A``), the fold of poses past the cuts
(sigma_1 from NumPy eigenvalues), and the certified bound against random poses over the whole joint
range, the parts past the cuts included."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

import tolsynth
from tolsynth.analysis.certify import certify_worst_pose
from tolsynth.analysis.certify_domain import domain
from tolsynth.analysis.certify_structure import structure
from tolsynth.kinematics.joint_space import _limits

_TURN_Z = np.diag([-1.0, -1.0, 1.0])


def _image(q, ops):
    shifts = {0: lambda v: v, 1: lambda v: v + math.pi, 2: lambda v: -v, 3: lambda v: math.pi - v}
    return np.array([shifts[op](v) for v, op in zip(q, ops)])


def _changes(m, q, ops):
    """Largest change of a column of A under the map, the column's sign allowed to flip, relative to
    the largest entry: with A as it is, and turned back by half a turn about z."""
    A = m.sensitivity(q, check_limits=False)[:3]
    B = m.sensitivity(_image(q, ops), check_limits=False)[:3]
    out = []
    for C in (B, _TURN_Z @ B):
        out.append(np.minimum(np.abs(C - A).max(axis=0), np.abs(C + A).max(axis=0)).max() / np.abs(A).max())
    return out


def _sigma(m, eps, Q):
    A = np.stack([m.sensitivity(q, check_limits=False)[:3] for q in Q])
    return np.sqrt(np.linalg.eigvalsh(np.einsum("nij,j,nkj->nik", A, eps**2 / 3.0, A))[:, -1])


@pytest.mark.parametrize("name", ["puma560", "ur5", "panda"])
def test_the_symmetries_proven_are_those_numpy_sees(name):
    """Every map proven changes A only by signs (1e-12) at random poses; every other map of the kind
    the proof considers (the base rotation kept, half-turn joints not turned, at least one other
    joint moved) changes it by more than 1e-3 at one of them, with A turned about z or not."""
    m = tolsynth.load_model(name)
    st = structure(m)
    lo, hi = _limits(m)
    Q = lo + (hi - lo) * np.random.default_rng(3).random((4, len(lo)))
    proven = {(s.ops, s.turn) for s in st.symmetries}
    assert proven  # each of these arms has one
    choices = [
        (0,)
        if j not in st.periodic or j not in st.joints or j == st.rotation
        else (0, 2)
        if j in st.half_turn
        else (0, 1, 2, 3)
        for j in range(len(lo))
    ]
    for ops in itertools.product(*choices):
        if not any(op and j not in st.half_turn for j, op in enumerate(ops)):
            continue
        seen = [True, True]  # per turn: no change above 1e-3 seen yet
        for q in Q:
            changes = _changes(m, q, ops)
            for t in (0, 1):
                if (ops, bool(t)) in proven:
                    assert changes[t] < 1e-12
                elif changes[t] > 1e-3:
                    seen[t] = False
            if not any(seen[t] for t in (0, 1) if (ops, bool(t)) not in proven):
                break  # every map not proven has been seen to change A
        for t in (0, 1):
            if (ops, bool(t)) not in proven:
                assert not seen[t], (ops, t)


def test_the_residual_is_the_twists_rounding():
    """What breaks the Puma 560's wrist flip is the rounding of its twists' constants: positive (the
    polynomial has monomials of the other sign), and below 1e-14 of the columns' scale."""
    m = tolsynth.load_model("puma560")
    names = list(m.joint_names)
    (flip,) = [s for s in structure(m).symmetries if s.describe(names) == "q4 + pi, -q5"]
    residual = np.asarray(flip.residual)
    lo, hi = _limits(m)
    Q = lo + (hi - lo) * np.random.default_rng(4).random((20, 6))
    scale = max(np.abs(m.sensitivity(q, check_limits=False)[:3]).max() for q in Q)
    assert 0.0 < residual.max() < 1e-14 * scale


@pytest.mark.parametrize(
    ("name", "cut", "widths"),
    [
        ("puma560", ["q4", "q5"], {"q4": 180.0, "q5": 180.0}),  # from 280 and 200 deg
        ("kr6r900sixx", ["q4"], {"q4": 180.0}),  # from 370 deg (one period first)
        ("ur5", ["q2"], {"q2": 180.0}),  # from one period
        ("panda", ["q3", "q1"], {"q1": 180.0, "q3": 180.0}),  # from 332 deg each
    ],
)
def test_the_search_cuts_joints_to_half_their_range(name, cut, widths):
    """The cuts of the four arms; a map (the whole range) and the exact reading cut nothing."""
    m = tolsynth.load_model(name)
    st = structure(m)
    names = list(m.joint_names)
    base = np.zeros(len(names))
    dom = domain(m, st, base)
    assert [names[dom.free[i]] for _, i in dom.cuts] == cut
    for joint, width in widths.items():
        i = dom.free.index(names.index(joint))
        assert math.degrees(dom.hi[i] - dom.lo[i]) == pytest.approx(width)
    for whole in (domain(m, st, base, half_turns=False), domain(m, st, base, symmetries=False)):
        assert whole.cuts == ()
        for joint in widths:
            i = whole.free.index(names.index(joint))
            assert math.degrees(whole.hi[i] - whole.lo[i]) > 199.0


@pytest.mark.parametrize("name", ["puma560", "kr6r900sixx", "ur5", "panda"])
def test_poses_past_the_cuts_fold_into_the_box_with_their_sigma(name):
    m = tolsynth.load_model(name)
    st = structure(m)
    nq = len(m.joint_names)
    dom = domain(m, st, np.zeros(nq))
    eps = m.tolerances("fine")
    lo, hi = _limits(m)
    Q = lo + (hi - lo) * np.random.default_rng(9).random((300, nq))
    X = dom.fold(Q[:, dom.free])
    assert np.all((dom.lo <= X) & (X <= dom.hi))
    moved = np.abs(X - Q[:, dom.free]).max(axis=1) > 1e-9
    assert moved.mean() > 0.5  # most poses lie past a cut (or a period)
    Q2 = Q.copy()
    Q2[:, dom.free] = X
    assert np.allclose(_sigma(m, eps, Q2), _sigma(m, eps, Q), rtol=1e-12, atol=0.0)


@pytest.mark.slow  # 7 s
def test_the_bound_with_cuts_holds_over_the_whole_range():
    """The certified Gaussian search on the UR5, cut to 1/128 of its joint ranges (periods, the half
    turn of q6 and the mirror of the arm), bounds sigma_1 at random poses over every joint's whole
    range (NumPy eigenvalues), and finds a pose at least as bad as every one of them (a 3 s search:
    its bound may be loose, its best pose is not); the exact search cuts nothing."""
    m = tolsynth.load_model("ur5")
    eps = m.tolerances("fine")
    c = certify_worst_pose(m, eps, "uniform", progress=False, time_limit=3.0)  # proven or not, a bound
    assert [joint for _, joint in c.symmetries] == ["q2"]
    exact = certify_worst_pose(m, eps, "uniform", "components", R=0.2, progress=False, max_boxes=10, workers=1)
    assert exact.symmetries == ()  # the exact search covers the whole range
    lo, hi = _limits(m)
    Q = lo + (hi - lo) * np.random.default_rng(8).random((4000, 6))
    s = _sigma(m, eps, Q)
    assert s.max() <= c.upper_bound
    assert c.best_value >= s.max() * (1 - 1e-3)  # to the search's own tolerance


def test_the_certificate_and_its_report_name_the_cuts():
    from tolsynth.io.report_certificate import _search_rows

    c = certify_worst_pose(tolsynth.load_model("puma560"), "fine", "uniform", progress=False, max_boxes=100, workers=1)
    assert c.symmetries == (("q4 + pi, -q5", "q4"), ("q5 + pi, -q6", "q5"))
    assert "q4 searched over half its range: the rest is the image of it under q4 + pi, -q5 (proven)" in c.summary()
    rows = dict((r[0], r[1]) for r in _search_rows(c, 2.5758, 0.5))
    assert rows["q5 searched over half its range (a symmetry, proven)"] == "q5 + pi, -q6"
