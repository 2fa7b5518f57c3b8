"""The certified search as a decision (``target=``) and the limits of the certified search.

With a target, ``certified`` means the target is proven and nothing else.  The references are
independent of the code under test: the planar arm's sensitivity in closed form (its hand position
``l1 (cos q1, sin q1) + l2 (cos q12, sin q12)`` differentiated by hand) with NumPy's eigensolver on
a dense grid of the elbow, the model's numeric sensitivity for the paper's robot, and the FFT
convolution of the uniform errors for the exact probability.
"""

from __future__ import annotations

import math
import re
import time

import numpy as np
import pytest

import tolsynth
from independent import fft_at_edge, sigma_max
from tolsynth.analysis.certify import certify_worst_pose
from tolsynth.errors import InputError, OutOfRangeError
from tolsynth.kinematics.joint_space import _limits

L1, L2 = 500.0, 300.0  # mm, models/planar_2r.toml
EPS = np.array([0.05, 0.05, 0.1e-3, 0.1e-3])  # its 'coarse' set: l1, l2 (mm), o1, o2 (mrad, here rad)


def planar_sigma1(q1, q2):
    """sigma_1 (mm) of the planar arm with uniform errors (variance eps^2 / 3): the columns of the
    hand position's sensitivity to l1, l2 and the two joint offsets, in closed form."""
    q1, q2 = np.broadcast_arrays(np.asarray(q1, dtype=float), np.asarray(q2, dtype=float))
    c1, s1, c12, s12 = np.cos(q1), np.sin(q1), np.cos(q1 + q2), np.sin(q1 + q2)
    x, y = L1 * c1 + L2 * c12, L1 * s1 + L2 * s12
    cols = np.stack(
        [np.stack([c1, s1], -1), np.stack([c12, s12], -1), np.stack([-y, x], -1), np.stack([-L2 * s12, L2 * c12], -1)],
        -1,
    )  # (..., 2, 4)
    V = np.einsum("...ij,j,...kj->...ik", cols, EPS**2 / 3.0, cols)
    return np.sqrt(np.linalg.eigvalsh(V)[..., -1])


def named_pose(reason: str) -> np.ndarray:
    """The joint values (rad) of the pose a reason names, '... at the pose (a, b, ...) deg'."""
    m = re.search(r"at the pose \(([^)]*)\) deg", reason)
    assert m, reason
    return np.radians([float(v) for v in m.group(1).split(",")])


@pytest.fixture(scope="module")
def planar():
    return tolsynth.load_model("planar_2r")


@pytest.fixture(scope="module")
def grid_max():
    """The planar arm's largest sigma_1 on a dense grid of the elbow (the waist turns it rigidly)."""
    return float(planar_sigma1(0.0, np.radians(np.linspace(-150.0, 150.0, 300_001))).max())


def test_a_target_below_the_maximum_is_not_certified(planar, grid_max):
    """0.04 mm is below the planar arm's largest sigma_1 (0.0493 mm by the closed form): not
    certified, the target recorded, and the pose the reason names is past it by the closed form,
    with the value the reason gives."""
    assert grid_max > 0.04  # the target is false: a pose exceeds it
    c = certify_worst_pose(planar, "coarse", target=0.04, progress=False, workers=1)
    assert not c.certified and c.target == 0.04
    assert c.reason.startswith("the target is exceeded")
    q = named_pose(c.reason)
    assert planar_sigma1(*q) > 0.04
    said = float(re.search(r"sigma_1 = ([0-9.eE+-]+) mm", c.reason).group(1))
    assert said == pytest.approx(float(planar_sigma1(*c.q)), rel=1e-8)
    assert np.allclose(q, c.q, atol=math.radians(1e-3))
    assert c.upper_bound >= grid_max * (1 - 1e-12)  # the bound reported still holds
    assert "NOT proven" in c.summary()


def test_a_target_above_the_maximum_is_proven(planar, grid_max):
    """A target 1 % above the closed form's maximum is proven: certified, the bound between the
    maximum and the target."""
    target = grid_max * 1.01
    c = certify_worst_pose(planar, "coarse", target=target, progress=False, workers=1)
    assert c.certified and c.reason == "" and c.target == target
    assert grid_max * (1 - 1e-12) <= c.upper_bound <= target


def test_paper_robot_target_exceeded_at_the_named_pose():
    """figure3 with a target of 0.30 mm: the pose the reason names has sigma_1 above it by the
    model's numeric sensitivity, and is inside the joint limits."""
    m = tolsynth.load_model("xu_zhang_1988")
    eps = m.tolerances("figure3")
    c = certify_worst_pose(m, "figure3", target=0.30, progress=False, workers=1)
    assert not c.certified and c.target == 0.30
    q = named_pose(c.reason)
    lo, hi = _limits(m)
    assert np.all(q >= lo - 1e-4) and np.all(q <= hi + 1e-4)
    assert sigma_max(m, q, eps)[0] > 0.30


def test_exact_target_not_proven_is_not_certified(planar):
    """Exact reading, R = 0.2 mm: a target of 1 - 1e-11 beyond the bound the search proves is not
    certified (the search closes its own tolerance first), and a target of 0.99 at R = 0.1 mm,
    which the worst pose misses by the FFT convolution, is disproved at that pose."""
    kw = dict(criterion="components", probability="exact", progress=False, workers=1)
    c = certify_worst_pose(planar, "coarse", R=0.2, target=0.99999999999, **kw)
    assert c.probability_lower_bound < 0.99999999999
    assert not c.certified and "not proven" in c.reason and c.target == 0.99999999999
    c = certify_worst_pose(planar, "coarse", R=0.1, target=0.99, **kw)
    assert not c.certified and c.reason.startswith("the target is exceeded")
    A = planar.sensitivity(c.q, check_limits=False)[:3] * planar.tolerances("coarse")
    assert float(fft_at_edge((c.direction @ A)[None], 0.1, 1 << 14)[0]) < 0.99
    assert np.allclose(named_pose(c.reason), c.q, atol=math.radians(1e-3))


def test_certified_exchange_still_decides_with_the_target():
    """The exchange's rounds record whether each certified search proved its goal: the last one
    of a converged exchange did, and its bound meets 1 + tol (z sigma_1 / R)."""
    m = tolsynth.load_model("planar_2r")
    w = tolsynth.synthesize_workspace(
        m, 0.2, 0.99, probability="gaussian", certify=True, certify_options={"workers": 1}, progress=False
    )
    searches = [r for r in w.rounds if r["certified"] is not None]
    assert w.converged and w.certified and searches and searches[-1]["certified"]
    assert w.upper_bound <= 1 + 1e-3
    assert w.certificate.target is not None and w.certificate.upper_bound <= w.certificate.target


# ------------------------------------------------------------------------------------------------
# the certified search's limits: refused as the command line refuses them
# ------------------------------------------------------------------------------------------------
def test_zero_time_limit_is_refused_everywhere(planar):
    mx = tolsynth.load_model("xu_zhang_1988")
    t = time.perf_counter()
    with pytest.raises(OutOfRangeError, match=r"certify_options\['time_limit'\].*None for no limit"):
        tolsynth.synthesize_workspace(mx, 0.5, 0.99, certify=True, certify_options={"time_limit": 0})
    assert time.perf_counter() - t < 2.0  # before any solve
    with pytest.raises(OutOfRangeError, match="time_limit"):
        certify_worst_pose(planar, "coarse", time_limit=0, progress=False)
    with pytest.raises(OutOfRangeError, match="time_limit"):
        tolsynth.worst_pose(planar, "coarse", certify=True, time_limit=0)


def test_zero_boxes_are_refused_by_worst_pose_as_by_the_certified_search(planar):
    for call in (
        lambda: tolsynth.worst_pose(planar, "coarse", certify=True, max_boxes=0),
        lambda: certify_worst_pose(planar, "coarse", max_boxes=0, progress=False),
        lambda: tolsynth.synthesize_workspace(planar, 0.2, 0.99, certify=True, certify_options={"max_boxes": 0}),
    ):
        with pytest.raises(OutOfRangeError, match="max_boxes"):
            call()


@pytest.mark.parametrize("key, value", [("rtol", 1e-3), ("time_limit", 5.0), ("max_boxes", 100), ("workers", 1)])
def test_certified_search_options_without_certify_are_refused(planar, key, value):
    with pytest.raises(InputError, match=f"^{key}: only used with certify=True"):
        tolsynth.worst_pose(planar, "coarse", **{key: value})


@pytest.mark.parametrize("progress", [True, lambda done, total: None])
def test_progress_without_certify_is_refused(planar, progress):
    """Only the certified search reports progress: a bar asked of the sampled search would never
    come, so the call names progress and certify=True; False (no bar) and None stay accepted."""
    with pytest.raises(InputError) as info:
        tolsynth.worst_pose(planar, "coarse", grid=4, starts=1, progress=progress)
    assert info.value.field == "progress" and "certify=True" in str(info.value)
    plain = tolsynth.worst_pose(planar, "coarse", grid=4, starts=1)
    quiet = tolsynth.worst_pose(planar, "coarse", grid=4, starts=1, progress=False)
    assert quiet.value == plain.value


def test_a_bool_is_no_count_of_workers(planar):
    with pytest.raises(InputError, match=r"^workers: got True"):
        certify_worst_pose(planar, "coarse", workers=True, progress=False)
    with pytest.raises(InputError, match=r"^workers: got True"):
        tolsynth.worst_pose(planar, "coarse", certify=True, workers=True)
    with pytest.raises(InputError, match=r"^certify_options\['workers'\]: got True"):
        tolsynth.synthesize_workspace(planar, 0.2, 0.99, certify=True, certify_options={"workers": True})


def test_unknown_certify_option_lists_every_key(planar):
    with pytest.raises(InputError) as e:
        tolsynth.synthesize_workspace(planar, 0.2, 0.99, certify=True, certify_options={"bogus": 1})
    assert e.value.allowed.split(", ") == ["rtol", "tol", "max_boxes", "time_limit", "workers", "margin", "through"]


def test_an_unclosed_bound_is_json_null_in_the_certificate_and_the_worst_pose():
    """One box of the paper's robot proves no finite sigma_1 bound (its upper_bound is inf): the
    dicts give None there, strict JSON takes them, and every finite number is kept as it is."""
    import json

    m = tolsynth.load_model("xu_zhang_1988")
    c = certify_worst_pose(m, "figure3", max_boxes=1, progress=False)
    assert not c.certified and math.isinf(c.upper_bound)
    d = json.loads(json.dumps(c.to_dict(), allow_nan=False))
    assert d["upper_bound"] is None and d["probability_lower_bound"] is None
    assert d["best_value"] == c.best_value and d["q"] == c.q.tolist() and d["certified"] is False
    assert "leaves" not in d
    w = tolsynth.worst_pose(m, "figure3", grid=4, starts=1, certify=True, max_boxes=1)
    assert math.isinf(w.upper_bound)
    dw = json.loads(json.dumps(w.to_dict(), allow_nan=False))
    assert dw["upper_bound"] is None and dw["certificate"]["upper_bound"] is None
    assert dw["value"] == w.value
