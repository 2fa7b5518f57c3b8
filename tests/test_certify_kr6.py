"""The KUKA KR 6 R900 sixx model against its source, and its certified worst pose.

Source numbers typed in from ROS-Industrial's kuka_experimental,
kuka_kr6_support/urdf/kr6r900sixx_macro.xacro (joint origins in m, axes, limits in deg); the
model's standard D-H table is derived from that chain, so its forward kinematics is checked
against the URDF chain itself, written here in plain NumPy."""

from __future__ import annotations

import math

import numpy as np
import pytest

import tolsynth
from tolsynth.kinematics.joint_space import _limits

#: (origin xyz in m, axis) of joints A1..A6, the flange at A6's origin; limits in deg
URDF = [
    ((0.0, 0.0, 0.400), (0, 0, -1)),
    ((0.025, 0.0, 0.0), (0, 1, 0)),
    ((0.455, 0.0, 0.0), (0, 1, 0)),
    ((0.0, 0.0, 0.035), (-1, 0, 0)),
    ((0.420, 0.0, 0.0), (0, 1, 0)),
    ((0.080, 0.0, 0.0), (-1, 0, 0)),
]
LIMITS_DEG = [(-170, 170), (-190, 45), (-120, 156), (-185, 185), (-120, 120), (-350, 350)]
#: the model's joints against KUKA's axis angles: q = sign * A
SIGN = [-1, 1, 1, -1, 1, -1]


def _rot(axis, t):
    """Rodrigues' rotation about a unit axis."""
    k = np.asarray(axis, dtype=float)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(t) * K + (1 - math.cos(t)) * K @ K


def _urdf_fk(A):
    """Flange frame (rotation, position in mm) of the URDF chain at KUKA axis angles A (rad)."""
    R, p = np.eye(3), np.zeros(3)
    for (xyz, axis), a in zip(URDF, A):
        p = p + R @ (1000.0 * np.array(xyz))
        R = R @ _rot(axis, a)
    return R, p


def test_kr6_numbers_and_limits_are_the_urdf():
    m = tolsynth.load_model("kr6r900sixx")
    sym = m.spec.symbols
    assert [sym[f"d{i}"] for i in range(1, 7)] == [400.0, 0.0, 0.0, 420.0, 0.0, 80.0]
    assert [sym[f"a{i}"] for i in range(1, 7)] == [25.0, 455.0, 35.0, 0.0, 0.0, 0.0]
    lo, hi = _limits(m)
    for i, (l, h) in enumerate(LIMITS_DEG):
        ends = sorted([SIGN[i] * l, SIGN[i] * h])
        assert np.degrees([lo[i], hi[i]]) == pytest.approx(ends, abs=1e-12)
    assert m.n == 24 and m.spec.convention == "standard"


def test_kr6_fk_against_the_urdf_chain():
    m = tolsynth.load_model("kr6r900sixx")
    lo, hi = _limits(m)
    rng = np.random.default_rng(8)
    for q in lo + (hi - lo) * rng.random((60, 6)):
        R, p = _urdf_fk(np.array(SIGN) * q)
        T = m.fk(q, check_limits=False)
        assert np.allclose(T[:3, 3], p, atol=1e-9)
        assert np.allclose(T[:3, 2], R[:, 0], atol=1e-12)  # D-H z6 along the flange's A6 direction
    # KUKA's home (A2 = -90, A3 = 90 deg): upper arm up, forearm level: (25 + 420 + 80, 0, 400 + 455 + 35)
    assert np.allclose(m.fk("home")[:3, 3], [525.0, 0.0, 890.0], atol=1e-9)


@pytest.mark.slow  # 5-15 s: a certified search with a time limit and 3000 poses
def test_kr6_certified_worst_pose_bounds_random_poses():
    m = tolsynth.load_model("kr6r900sixx")
    w = tolsynth.worst_pose(m, "fine", certify=True, time_limit=8.0, progress=False)
    c = w.certificate
    assert list(c.held) == ["q1"]  # the base rotation, proven; q6 turns a6's error about the flange axis
    assert set(c.dropped) == {"alpha6", "o6"}  # turns about the flange point: no effect on its position
    eps = m.tolerances("fine")
    lo, hi = _limits(m)
    Q = lo + (hi - lo) * np.random.default_rng(2).random((3000, 6))
    A = np.stack([m.sensitivity(q, check_limits=False)[:3] for q in Q])
    s = np.sqrt(np.linalg.eigvalsh(np.einsum("nij,j,nkj->nik", A, eps**2 / 3.0, A))[:, -1])
    assert s.max() <= c.upper_bound and s.max() <= w.value * (1 + 1e-9)
    assert c.best_value <= c.upper_bound
