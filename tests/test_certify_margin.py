"""A design margin in the certified exchange: the designs at ``R / (1 + margin)``, the proof at ``R``,
and the cost's lower bound from a solve at ``R`` itself."""

from __future__ import annotations

import numpy as np
import pytest

import tolsynth
from convex_reference import clarabel
from independent import dense_then_local, sigma_max
from tolsynth.errors import InputError, OutOfRangeError
from tolsynth.probability.stats import z_of_p
from tolsynth.problem.specification import make_specification

R, P, MARGIN, TOL = 0.5, 0.99, 3e-3, 1e-3


def _exchange(mech, **options):
    """The Gaussian certified exchange at R, P, tol, uniform errors, alpha 0.7, with these
    ``certify_options``."""
    return tolsynth.synthesize_workspace(
        mech,
        R,
        P,
        "uniform",
        0.7,
        probability="gaussian",
        tol=TOL,
        certify=True,
        certify_options=options,
        progress=False,
    )


@pytest.fixture(scope="module")
def margin_design(xz):
    return _exchange(xz, margin=MARGIN)


def test_the_design_meets_the_smaller_radius_at_its_poses(xz, margin_design):
    """NumPy eigenvalues at the imposed poses: z sigma_1 <= R / (1 + margin), binding at some."""
    w = margin_design
    assert w.certified and w.converged and w.success and w.margin == MARGIN
    ratio = sigma_max(xz, np.array(w.poses), w.result.x) * z_of_p(P) * (1 + MARGIN) / R
    assert ratio.max() <= 1 + 1e-6 and ratio.max() >= 1 - 1e-6


@pytest.mark.slow  # 5-6 s
def test_the_proof_at_R_holds_against_a_dense_search(xz, margin_design):
    """The largest sigma an independent search finds (20 000 poses and SLSQP) lies below the proven
    bound, which meets 1 + tol at R; the margin leaves the design below R there."""
    w = margin_design
    z = z_of_p(P)
    ref = dense_then_local(xz, w.result.x, 20000, 12, fixed={0: 0.0, 4: 0.0}) * z / R
    assert ref <= w.upper_bound <= 1 + TOL
    assert ref <= (1 + TOL) / (1 + MARGIN) + 1e-9


def test_the_lower_bound_is_the_optimum_at_R_by_clarabel(xz, margin_design):
    """``lower_bound`` is the cheapest cost at R at the final poses (cvxpy + Clarabel, an SDP sharing
    nothing with the NLP), and the design's own cost the cheapest at R / (1 + margin): the gap is
    what the margin costs."""
    pytest.importorskip("cvxpy")
    w = margin_design
    at_R = clarabel(make_specification(xz, R, P, "uniform", 0.7, poses=w.poses))
    at_Rd = clarabel(make_specification(xz, R / (1 + MARGIN), P, "uniform", 0.7, poses=w.poses))
    assert at_R is not None and at_Rd is not None
    assert w.lower_bound == pytest.approx(at_R, rel=1e-6) and w.lower_bound <= at_R * (1 + 1e-9)
    assert w.result.cost == pytest.approx(at_Rd, rel=1e-6)
    assert w.gap == pytest.approx(at_Rd - at_R, rel=1e-3)
    assert "within 0.2" in w.certificate_line() and "margin of 0.003" in w.certificate_line()


def test_without_a_margin_the_reason_names_it(xz):
    """A proof that cannot close in its box budget, and finds no pose past the goal, says that a
    margin gives it room (a budget of 50 boxes is far too few for the paper's robot)."""
    w = _exchange(xz, max_boxes=50, workers=1)
    assert not w.certified and not w.converged
    assert "margin" in w.reason and w.upper_bound > 1 + TOL


def test_not_converged_with_a_margin_still_bounds_the_cost_at_R(xz):
    """A proof stopped by its box budget: not certified, and ``lower_bound`` is still the optimum at
    R at the poses imposed (cvxpy + Clarabel), not the last solve's own bound at R / (1 + margin)."""
    pytest.importorskip("cvxpy")
    w = _exchange(xz, margin=MARGIN, max_boxes=50, workers=1)
    assert not w.certified and not w.converged
    at_R = clarabel(make_specification(xz, R, P, "uniform", 0.7, poses=w.poses))
    assert w.lower_bound == pytest.approx(at_R, rel=1e-6) and w.lower_bound < w.result.cost
    assert f"a larger design margin than {MARGIN:g}" in w.reason


@pytest.mark.parametrize("bad", [-1e-3, 0.6, float("nan"), "much"])
def test_a_bad_margin_is_a_typed_error_naming_it(xz, bad):
    with pytest.raises((OutOfRangeError, InputError), match="margin"):
        tolsynth.synthesize_workspace(
            xz, R, P, probability="gaussian", certify=True, certify_options={"margin": bad}, progress=False
        )


@pytest.mark.long  # 20-30 s per six-joint arm on 2 cores; the Panda 1.5 min at 1e-2, 4.5 min at 3 tol
@pytest.mark.parametrize(("name", "margin"), [("puma560", MARGIN), ("ur5", MARGIN), ("panda", 1e-2), ("panda", MARGIN)])
def test_six_joint_exchange_certified_with_a_margin(name, margin):
    """The Gaussian certified exchange on a six- or seven-joint arm closes with a margin (3 tol; the
    Panda's flatter design sooner with 1e-2): the bound at R meets 1 + tol and lies above the largest sigma
    an independent search finds (random poses and SLSQP); the cost is within the margin's price of
    the bound at R (about the margin's share of the cost)."""
    m = tolsynth.load_model(name)
    w = _exchange(m, margin=margin)
    assert w.certified and w.upper_bound <= 1 + TOL
    ref = dense_then_local(m, w.result.x, 20000, 13) * z_of_p(P) / R
    assert ref <= w.upper_bound
    assert 0 < w.gap <= margin * w.result.cost


@pytest.mark.long  # 50-80 s per arm on 2 cores
@pytest.mark.parametrize("name", ["puma560", "ur5", "kr6r900sixx"])
def test_six_joint_exchange_certified_without_a_margin(name):
    """Without a margin the sampled stage goes on to a tenth of tol, and the proof closes in the
    room that leaves: certified, the bound at or above an independent search's largest sigma
    (random poses and SLSQP), and the cost at its own dual bound (no margin's premium)."""
    m = tolsynth.load_model(name)
    w = _exchange(m)
    assert w.certified and w.upper_bound <= 1 + TOL and w.margin == 0
    ref = dense_then_local(m, w.result.x, 20000, 13) * z_of_p(P) / R
    assert ref <= w.upper_bound
    assert abs(w.gap) <= 1e-6 * w.result.cost


@pytest.mark.slow  # 5-6 s
def test_with_a_blind_sampled_stage_the_proofs_find_the_poses_past_the_designed_radius(xz):
    """With the sampled search replaced by one that never finds a miss, every pose comes from the
    certified search: each proof that does not close finds a pose past 1 + tol / 2 at R / (1 +
    margin), and the last design, binding at R / (1 + margin) at its poses (NumPy eigenvalues), is
    proven at R, above a dense search."""
    from types import SimpleNamespace

    from tolsynth.synthesis.workspace import _certified_exchange

    z = z_of_p(P)
    start = xz.joints("worst")
    w = _certified_exchange(
        xz,
        R,
        P,
        z,
        "uniform",
        0.7,
        [start],
        TOL,
        20,
        {"margin": MARGIN, "workers": 1},
        False,
        False,
        {"probability": "gaussian"},
        lambda eps, radius, fine=False: (SimpleNamespace(q=start, position=np.zeros(3)), 0.0),
    )
    assert w.certified and w.upper_bound <= 1 + TOL
    found = w.rounds[:-1]
    assert found and all(not r["certified"] for r in found)
    assert all(r["worst_value"] > 1 + TOL / 2 for r in found)
    Rd = R / (1 + MARGIN)
    last = sigma_max(xz, np.array(w.poses), w.result.x) * z / Rd
    assert last.max() == pytest.approx(1.0, abs=1e-6)
    ref = dense_then_local(xz, w.result.x, 20000, 14, fixed={0: 0.0, 4: 0.0}) * z / R
    assert ref <= w.upper_bound


def test_certify_options_without_certify_is_a_typed_error(xz):
    with pytest.raises(InputError, match="certify_options"):
        tolsynth.synthesize_workspace(xz, R, P, probability="gaussian", certify_options={"margin": MARGIN})
