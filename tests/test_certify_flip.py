"""Wrist flips: turning joints a and c by half a turn and mirroring joint b between them changes no
column of the position sensitivity but its sign (to the twists' rounding, bounded), proven on the
graph's exact polynomial; the certified Gaussian search then covers one of a and c over half a turn.
Checked against NumPy: the model's own sensitivities at a pose and at its flip, for the flips proven
and for every other triple of consecutive periodic joints (which must really change ``A``), the fold
of poses past the cut (sigma_1 from NumPy eigenvalues), and the certified bound against random poses
over the whole joint range, the part past the cut included."""

from __future__ import annotations

import math

import numpy as np
import pytest

import tolsynth
from tolsynth.analysis.certify import certify_worst_pose
from tolsynth.analysis.certify_domain import domain
from tolsynth.analysis.certify_structure import structure
from tolsynth.kinematics.joint_space import _limits


def _flip_change(m, q, a):
    """Largest change of a column of A under the flip at joints a, a+1, a+2, the column's sign
    allowed to flip, relative to the largest entry."""
    A = m.sensitivity(q, check_limits=False)[:3]
    q2 = q.copy()
    q2[a] += math.pi
    q2[a + 1] = -q2[a + 1]
    q2[a + 2] += math.pi
    B = m.sensitivity(q2, check_limits=False)[:3]
    return np.minimum(np.abs(B - A).max(axis=0), np.abs(B + A).max(axis=0)).max() / np.abs(A).max()


def _sigma(m, eps, Q):
    A = np.stack([m.sensitivity(q, check_limits=False)[:3] for q in Q])
    return np.sqrt(np.linalg.eigvalsh(np.einsum("nij,j,nkj->nik", A, eps**2 / 3.0, A))[:, -1])


@pytest.mark.parametrize(
    ("name", "proven"),
    [
        ("puma560", [("q4", "q5", "q6")]),
        ("kr6r900sixx", [("q4", "q5", "q6")]),
        ("panda", [("q1", "q2", "q3")]),
        ("ur5", []),
    ],
)
def test_flips_are_those_numpy_sees(name, proven):
    m = tolsynth.load_model(name)
    st = structure(m)
    names = list(m.joint_names)
    assert [tuple(names[j] for j in f[:3]) for f in st.flips] == proven
    lo, hi = _limits(m)
    Q = lo + (hi - lo) * np.random.default_rng(3).random((12, len(names)))
    flips = {f[0] for f in st.flips}
    for a in st.periodic:
        if a + 1 not in st.periodic or a + 2 not in st.periodic:
            continue
        change = max(_flip_change(m, q, a) for q in Q)
        if a in flips:
            assert change < 1e-12
        else:  # not proven, and not true either: the proof misses none of these arms' flips
            assert change > 1e-3


def test_the_residual_is_the_twists_rounding():
    """What breaks the Puma 560's flip is the rounding of its twists' constants: positive (the
    polynomial has monomials of the other sign), and below 1e-14 of the columns' scale."""
    m = tolsynth.load_model("puma560")
    (flip,) = structure(m).flips
    residual = np.asarray(flip[3])
    lo, hi = _limits(m)
    Q = lo + (hi - lo) * np.random.default_rng(4).random((20, 6))
    scale = max(np.abs(m.sensitivity(q, check_limits=False)[:3]).max() for q in Q)
    assert 0.0 < residual.max() < 1e-14 * scale


def test_the_search_cuts_one_joint_of_a_flip_to_half_a_turn():
    """The Puma 560's q4 (280 deg) and the KR 6 R900's (370 deg, one period first) are searched over
    half a turn; the Panda's flip turns q1, searched there and over less than a turn, so nothing is
    cut; a map (the whole range) and the exact reading cut nothing."""
    for name, cut in (("puma560", 3), ("kr6r900sixx", 3)):
        m = tolsynth.load_model(name)
        st = structure(m)
        base = np.zeros(len(m.joint_names))
        dom = domain(m, st, base)
        i = dom.free.index(cut)
        assert dom.flip[:3] == (3, 4, 5) and dom.flip_index[0] == i
        assert dom.hi[i] - dom.lo[i] == pytest.approx(math.pi)
        for whole in (domain(m, st, base, half_turns=False), domain(m, st, base, flips=False)):
            assert whole.flip is None and whole.hi[i] - whole.lo[i] > math.pi + 1.0
    panda = tolsynth.load_model("panda")
    assert domain(panda, structure(panda), np.zeros(7)).flip is None


@pytest.mark.parametrize("name", ["puma560", "kr6r900sixx"])
def test_poses_past_the_cut_fold_into_the_box_with_their_sigma(name):
    m = tolsynth.load_model(name)
    st = structure(m)
    dom = domain(m, st, np.zeros(6))
    eps = m.tolerances("fine")
    lo, hi = _limits(m)
    Q = lo + (hi - lo) * np.random.default_rng(9).random((400, 6))
    i = dom.flip_index[0]
    turn = dom.lo[i] + np.mod(Q[:, dom.free[i]] - dom.lo[i], 2 * math.pi)  # the KR 6's q4 spans 370 deg
    past = turn > dom.hi[i]
    assert past.mean() > 0.3  # a good share of the range lies past the cut
    X = dom.fold(Q[:, dom.free])
    assert np.all((dom.lo <= X) & (X <= dom.hi))
    Q2 = Q.copy()
    Q2[:, dom.free] = X
    assert np.allclose(_sigma(m, eps, Q2), _sigma(m, eps, Q), rtol=1e-12, atol=0.0)
    assert np.abs(Q2[past, 4] + Q[past, 4]).max() < 1e-12  # q5 mirrored where the flip was applied


@pytest.mark.slow  # 5 s
def test_the_bound_with_a_flip_holds_over_the_whole_range():
    """The certified Gaussian search with q4 cut to half a turn (and q6 to half a turn) bounds
    sigma_1 at random poses over every joint's whole range (NumPy eigenvalues), most of them past a
    cut, and finds a pose at least as bad as every one of them (a 3 s search: its bound may be
    loose, its best pose is not)."""
    m = tolsynth.load_model("puma560")
    eps = m.tolerances("fine")
    c = certify_worst_pose(m, eps, "uniform", progress=False, time_limit=3.0)  # proven or not, a bound
    assert c.flip == ("q4", "q5", "q6")
    lo, hi = _limits(m)
    Q = lo + (hi - lo) * np.random.default_rng(8).random((4000, 6))
    s = _sigma(m, eps, Q)
    assert s.max() <= c.upper_bound
    assert c.q[3] <= lo[3] + math.pi + 1e-12  # the pose found lies in the part of q4 searched
    past = Q[:, 3] > lo[3] + math.pi
    assert c.best_value >= s[past].max() * (1 - 1e-3)  # to the search's own tolerance


def test_the_certificate_and_its_report_name_the_flip():
    from tolsynth.io.report_certificate import _search_rows

    c = certify_worst_pose(tolsynth.load_model("puma560"), "fine", "uniform", progress=False, max_boxes=100, workers=1)
    assert c.flip == ("q4", "q5", "q6")
    assert "wrist flip (q4, q6 half a turn, q5 mirrored" in c.summary()
    rows = dict((r[0], r[1]) for r in _search_rows(c, 2.5758, 0.5))
    assert rows["wrist flip (proven; its residual added to the bound)"] == "q4, q6 half a turn, q5 mirrored"
