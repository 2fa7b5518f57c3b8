"""The map's compiled inverse kinematics (tolsynth.kinematics.ik_compiled) against the NumPy iteration, NumPy's
least squares, a plain-NumPy forward kinematics and the closed form of tests/test_workspace.py.

The compiled path is the default wherever a C compiler is found (the map tests in
tests/test_workspace.py run it against the closed-form IK); here: it gives the maps of the NumPy
path (the same reachable set and joints up to rounding) on every bundled model with a 3-D arm,
its least-squares fallback is NumPy's ``lstsq``, its threads change nothing, and without a
compiler the NumPy path is used.
"""

from __future__ import annotations

import numpy as np
import pytest

import tolsynth
from tolsynth import cbuild
from tolsynth.analysis.workspace_map import probability_map
from tolsynth.kinematics import ik, ik_compiled

needs_cc = pytest.mark.skipif(cbuild.find_compiler() is None, reason="no C compiler")

CASES = [
    ("xu_zhang_1988", "figure3", {"n": 30}),
    ("xu_zhang_1988", "figure3", {"n": 24, "hand_axis": None}),
    ("puma560", None, {"n": 20}),
    ("ur5", None, {"n": 16}),
    ("panda", None, {"n": 16, "plane": "yz", "hand_axis": None}),
]


def _map(name, tol, kw):
    m = tolsynth.load_model(name)
    tol = tol or next(iter(m.tolerance_sets))
    return probability_map(m, tol, R=0.3, progress=False, **kw)


@needs_cc
@pytest.mark.parametrize(
    "name, tol, kw",
    # the six- and seven-joint maps take 3-4 s each: with the slow tests
    [pytest.param(*c, marks=pytest.mark.slow) if c[0] != "xu_zhang_1988" else c for c in CASES],
    ids=[f"{c[0]}-{i}" for i, c in enumerate(CASES)],
)
def test_compiled_map_is_the_numpy_map(name, tol, kw, monkeypatch):
    comp = _map(name, tol, kw)
    assert ik_compiled.backend_status()["backend"] == "compiled"
    monkeypatch.setenv("TOLSYNTH_NO_COMPILE", "1")
    ref = _map(name, tol, kw)
    assert ik_compiled.backend_status()["backend"] == "numpy"
    assert np.array_equal(comp.reachable, ref.reachable) and ref.reachable.any()
    assert comp.n_alternative_solutions == ref.n_alternative_solutions
    np.testing.assert_allclose(comp.P, ref.P, rtol=0, atol=1e-9, equal_nan=True)
    if kw.get("hand_axis", ()) is not None:  # a redundant arm may land elsewhere on its self-motion
        np.testing.assert_allclose(comp.Q, ref.Q, rtol=0, atol=1e-7, equal_nan=True)


@needs_cc
def test_solutions_reach_their_targets_by_plain_numpy_fk():
    """Joints returned as converged put the hand on the target (plain-NumPy chain of
    tests/test_kinematics.py), the hand axis up; from random starts, targets on a grid."""
    from test_kinematics import NUMPY_FK

    xz = tolsynth.load_model("xu_zhang_1988")
    ev = ik._ik_evaluator(xz, (1, 2, 3), True)
    rng = np.random.default_rng(3)
    lo, hi = np.radians([0, 140, 50, -110, 0]), np.radians([0, 200, 130, 110, 0])
    N = 3000
    Q0 = lo[:, None] + (hi - lo)[:, None] * rng.random((5, N))
    T = np.vstack([rng.uniform(200, 1500, N), np.zeros(N), rng.uniform(300, 1700, N)])
    axis = np.array([0.0, 0.0, 1.0])
    lm = ik_compiled.compile_lm(ev.function)
    Q, conv = lm.solve((1, 2, 3), Q0, T, axis, 1e-7, 60)
    assert np.array_equal(Q[[0, 4]], Q0[[0, 4]])  # joints not free are not moved
    Qw = ik._wrap(xz, Q)
    valid = conv & ik._feasible(xz, Qw)  # what the map takes (the hand-written chain holds there)
    assert 300 < valid.sum() < conv.sum() < N  # some valid, some past a limit, some out of reach
    for b in np.flatnonzero(valid)[:200]:
        Tb = NUMPY_FK["xu_zhang_1988"](Qw[:, b])
        assert np.linalg.norm(Tb[:3, 3] - T[:, b]) <= 1e-7
        assert np.linalg.norm(Tb[:3, 2] - axis) <= 1e-9
    for b in np.flatnonzero(~conv)[:200]:  # not converged: not on the target (no false negatives hidden)
        Tb = NUMPY_FK["xu_zhang_1988"](Q[:, b])
        r = np.concatenate([Tb[:3, 3] - T[:, b], 1000.0 * (Tb[:3, 2] - axis)])
        assert np.linalg.norm(r) > 1e-7


@needs_cc
@pytest.mark.parametrize("n", [1, 2, 3, 5, 7])
def test_least_squares_fallback_is_numpy_lstsq(n, rng):
    xz = tolsynth.load_model("xu_zhang_1988")
    lm = ik_compiled.compile_lm(ik._ik_evaluator(xz, (1, 2, 3), True).function)
    for rank in range(n + 1):
        B = rng.normal(size=(n, rank))
        A = B @ B.T  # symmetric, rank-deficient below n
        b = rng.normal(size=n)
        ref = np.linalg.lstsq(A, b, rcond=None)[0]
        np.testing.assert_allclose(lm.sym_lstsq(A, b), ref, rtol=1e-8, atol=1e-8 * (1 + np.abs(ref).max()))
    with pytest.raises(ValueError):
        lm.sym_lstsq(np.eye(17), np.ones(17))


@needs_cc
def test_threads_change_nothing(monkeypatch):
    xz = tolsynth.load_model("xu_zhang_1988")
    ev = ik._ik_evaluator(xz, (1, 2, 3), True)
    rng = np.random.default_rng(5)
    N = 5000
    Q0 = np.repeat(xz.configurations["home"][:, None], N, axis=1)
    Q0[1:4] += rng.normal(scale=0.3, size=(3, N))
    T = np.vstack([rng.uniform(200, 1500, N), np.zeros(N), rng.uniform(300, 1700, N)])
    axis = np.array([0.0, 0.0, 1.0])
    monkeypatch.setattr(ik_compiled, "PARALLEL_MIN", 100)
    out = {}
    for threads in (1, 2, 3):
        monkeypatch.setattr(ik_compiled, "THREADS", threads)
        out[threads] = ik._solve_ik(ev, (1, 2, 3), Q0, T, axis)
    for threads in (2, 3):
        assert np.array_equal(out[threads][0], out[1][0]) and np.array_equal(out[threads][1], out[1][1])


@pytest.mark.parametrize("env", [{"TOLSYNTH_NO_COMPILE": "1"}, {"TOLSYNTH_CC": "no-such-compiler-here"}])
def test_numpy_fallback(env, monkeypatch):
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    xz = tolsynth.load_model("xu_zhang_1988")
    pm = probability_map(xz, "figure3", R=0.2, n=12, progress=False)
    st = ik_compiled.backend_status()
    assert st["backend"] == "numpy" and st["reason"]
    assert 0 < pm.reachable.sum() < 144
