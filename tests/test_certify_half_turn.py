"""Half-turn joints: a periodic joint whose half turn changes no column of the position sensitivity
but its sign, proven on the graph's exact polynomial, is searched over half a turn.  Checked against
NumPy: the model's own sensitivities at a pose and at the pose turned by half a turn, for the joints
proven and for every other periodic joint (which must really change ``A``), and the certified bound
against random poses over the whole joint range, the other half turn included."""

from __future__ import annotations

import math

import numpy as np
import pytest

import tolsynth
from tolsynth.analysis.certify import certify_worst_pose
from tolsynth.analysis.certify_domain import domain
from tolsynth.analysis.certify_structure import structure
from tolsynth.kinematics.joint_space import _limits


def _sign_change(m, q, j):
    """Largest change of a column of A under half a turn of joint j, the column's sign allowed to flip,
    relative to the largest entry."""
    A = m.sensitivity(q, check_limits=False)[:3]
    q2 = q.copy()
    q2[j] += math.pi
    B = m.sensitivity(q2, check_limits=False)[:3]
    per_column = np.minimum(np.abs(B - A).max(axis=0), np.abs(B + A).max(axis=0))
    return per_column.max() / np.abs(A).max()


@pytest.mark.parametrize(
    ("name", "proven"), [("puma560", ["q6"]), ("ur5", ["q6"]), ("kr6r900sixx", ["q6"]), ("panda", [])]
)
def test_half_turn_joints_are_those_numpy_sees(name, proven):
    m = tolsynth.load_model(name)
    st = structure(m)
    names = list(m.joint_names)
    assert [names[j] for j in st.half_turn] == proven
    lo, hi = _limits(m)
    Q = lo + (hi - lo) * np.random.default_rng(5).random((12, len(names)))
    for j in st.periodic:
        change = max(_sign_change(m, q, j) for q in Q)
        if j in st.half_turn:
            assert change < 1e-12
        else:  # not proven, and not true either: the proof misses none of these arms' half turns
            assert change > 1e-3


def test_the_search_covers_half_a_turn_and_a_map_the_whole_range():
    m = tolsynth.load_model("puma560")
    st = structure(m)
    base = np.zeros(len(m.joint_names))
    i = domain(m, st, base).free.index(5)
    assert domain(m, st, base).hi[i] - domain(m, st, base).lo[i] == pytest.approx(math.pi)
    whole = domain(m, st, base, half_turns=False)
    assert whole.hi[i] - whole.lo[i] == pytest.approx(2 * math.pi)  # one period of its 532 deg


@pytest.mark.slow  # 5 s
def test_the_bound_over_half_a_turn_holds_over_the_whole_range():
    """The certified search over q6 in half a turn bounds sigma_1 at random poses over all of q6's
    range (NumPy eigenvalues), poses in the half not searched among them, and finds in its half a
    pose at least as bad as any of those in the other (a 3 s search: its bound may be loose, its
    best pose is not)."""
    m = tolsynth.load_model("ur5")
    eps = m.tolerances("fine")
    c = certify_worst_pose(m, eps, "uniform", progress=False, time_limit=3.0)  # proven or not, a bound
    lo, hi = _limits(m)
    Q = lo + (hi - lo) * np.random.default_rng(7).random((4000, 6))
    cut = lo[5] + math.pi
    assert (Q[:, 5] > cut).mean() > 0.5  # most of q6's range lies past the half turn searched
    A = np.stack([m.sensitivity(q, check_limits=False)[:3] for q in Q])
    s = np.sqrt(np.linalg.eigvalsh(np.einsum("nij,j,nkj->nik", A, eps**2 / 3.0, A))[:, -1])
    assert s.max() <= c.upper_bound
    assert c.q[5] <= cut + 1e-12  # the pose found lies in the half searched
    assert c.best_value >= s[Q[:, 5] > cut].max() * (1 - 1e-3)  # to the search's own tolerance


def test_the_certificate_says_which_joints_it_searched_over_half_a_turn():
    """The certificate names the joints halved, in its summary too; the planar 2R's one half-turn
    joint is its base rotation, held, so it halves nothing."""
    c = certify_worst_pose(tolsynth.load_model("puma560"), "fine", "uniform", progress=False, max_boxes=100, workers=1)
    assert c.half_turn == ("q6",)
    assert "half a turn" in c.summary() and "q6" in c.summary().split("half a turn")[1]
    c2 = certify_worst_pose(tolsynth.load_model("planar_2r"), "coarse", progress=False)
    assert c2.half_turn == ()  # its half-turn joint q1 is held as the base rotation


def test_a_seed_in_the_half_not_searched_is_folded_in_with_its_value():
    """A pose with q6 past the half turn searched (and q4 past one period) moves by whole periods
    into the search's box: inside it, sigma_1 unchanged (NumPy eigenvalues), not clipped to an end."""
    m = tolsynth.load_model("ur5")
    st = structure(m)
    dom = domain(m, st, np.zeros(6))
    eps = m.tolerances("fine")
    q = np.radians([0.0, -60.0, 80.0, 200.0, 40.0, 150.0])  # q6 = 150 deg: past [-360, -180] deg
    x = dom.fold(q[dom.free][None])[0]
    assert np.all((dom.lo <= x) & (x <= dom.hi)) and np.all(x < dom.hi - 1e-3)

    def sigma(qv):
        A = m.sensitivity(qv, check_limits=False)[:3]
        return np.sqrt(np.linalg.eigvalsh(A @ np.diag(eps**2 / 3.0) @ A.T)[-1])

    q2 = q.copy()
    q2[dom.free] = x
    assert sigma(q2) == pytest.approx(sigma(q), rel=1e-12)


def test_the_report_table_names_the_half_turn_joints():
    from tolsynth.io.report_certificate import _search_rows

    c = certify_worst_pose(tolsynth.load_model("puma560"), "fine", "uniform", progress=False, max_boxes=100, workers=1)
    rows = dict((r[0], r[1]) for r in _search_rows(c, 2.5758, 0.5))
    assert rows["searched over half a turn (the other half the same, proven)"] == "q6"
    assert rows["joints searched"] == "q2, q3, q4, q5, q6"
