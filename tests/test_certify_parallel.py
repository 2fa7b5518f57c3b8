"""The certified searches on several processes (tolsynth.analysis.certify_parallel).

The serial phase is set to zero here so that even the small problems go through the workers (a
spy on ``fan_out`` checks that they did).  References are independent of the package's bounds:
the planar arm's largest principal sigma in closed form on a grid of q2 refined by SciPy; sigma at
poses from the numeric sensitivity and NumPy's eigensolver, at random poses refined by SLSQP; the
exact per-direction probability by FFT convolution of the uniform densities (tests/independent.py)
on a grid of poses and directions.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import tolsynth
from independent import dense_then_local, fft_at_edge, sigma_max
from tolsynth.analysis import certify_parallel
from tolsynth.analysis.certify import certify_worst_pose
from tolsynth.errors import InputError
from tolsynth.kinematics.joint_space import _feasible, _limits


@pytest.fixture
def dealt(monkeypatch):
    """No serial phase, and the number of times the open boxes were dealt to workers."""
    monkeypatch.setattr(certify_parallel, "SERIAL_SECONDS", 0.0)
    calls = []
    fan_out = certify_parallel.fan_out

    def spy(parts, *args, **kw):
        calls.append(len(parts))
        return fan_out(parts, *args, **kw)

    monkeypatch.setattr(certify_parallel, "fan_out", spy)
    return calls


def test_sigma_on_two_workers_matches_the_closed_form(dealt):
    """Planar 2R: sigma_1 depends on q2 only; the reference is the 2 x 2 eigenvalue in closed form
    on a 2001-point grid of q2, refined by SciPy.  Serial and two workers: the same proof."""
    from scipy.optimize import minimize_scalar

    m = tolsynth.load_model("planar_2r")
    eps = m.tolerances("coarse")
    lo, hi = _limits(m)

    def sigma(q2):
        A = np.array([m.sensitivity([0.0, v], check_limits=False)[:2] for v in np.atleast_1d(q2)])
        V = np.einsum("nij,j,nkj->nik", A, eps**2 / 3.0, A)
        tr, det = V[:, 0, 0] + V[:, 1, 1], V[:, 0, 0] * V[:, 1, 1] - V[:, 0, 1] ** 2
        return np.sqrt(tr / 2 + np.sqrt(np.maximum(tr**2 / 4 - det, 0.0)))

    grid = np.linspace(lo[1], hi[1], 2001)
    vals = sigma(grid)
    k = int(np.argmax(vals))
    res = minimize_scalar(
        lambda v: -sigma(v)[0], bounds=(grid[max(k - 1, 0)], grid[min(k + 1, 2000)]), method="bounded"
    )
    ref = max(vals.max(), -res.fun)
    one = certify_worst_pose(m, eps, "uniform", progress=False, rtol=1e-6, workers=1)
    assert not dealt
    two = certify_worst_pose(m, eps, "uniform", progress=False, rtol=1e-6, workers=2)
    assert dealt and all(n == 2 for n in dealt)
    for c in (one, two):
        assert c.certified and c.reason == ""
        assert ref <= c.upper_bound <= ref * (1 + 1e-6)
        assert c.best_value == pytest.approx(ref, rel=1e-6)
        assert c.best_value == pytest.approx(sigma(c.q[1])[0], rel=1e-12)  # the value is the pose's


def test_sigma_on_two_workers_bounds_an_independent_search_on_the_paper_robot(dealt):
    """The paper's robot, 'figure3' tolerances, rtol 1e-4: serial and two workers certify bounds
    within the tolerance of each other, above random poses refined by SLSQP inside the joint
    constraints, and the progress callback follows the workers' boxes."""

    m = tolsynth.load_model("xu_zhang_1988")
    eps = m.tolerances("figure3")
    one = certify_worst_pose(m, eps, "uniform", progress=False, rtol=1e-4, workers=1)
    two = certify_worst_pose(m, eps, "uniform", progress=False, rtol=1e-4, workers=2)
    assert dealt
    assert one.certified and two.certified
    assert abs(one.upper_bound - two.upper_bound) <= 1e-4 * one.best_value
    assert two.best_value <= two.upper_bound <= two.best_value * (1 + 1e-4)
    assert two.best_value == pytest.approx(sigma_max(m, two.q, eps)[0], rel=1e-12)
    n = [h[0] for h in two.history]
    assert len(n) > 1 and n == sorted(n) and n[-1] <= two.boxes
    # the independent search: theta1 and theta5 are proven not to matter (held at 0)
    ref = dense_then_local(m, eps, 3000, 3, fixed={0: 0.0, 4: 0.0}, refine=3)
    for c in (one, two):
        assert ref <= c.upper_bound
        assert c.best_value >= ref * (1 - 1e-4)  # the search found the maximum the reference found


def _fft_worst_2r(m, eps, R):
    """Lowest P(|u . dr| <= R) of the planar 2R on a grid: q2 every 2 deg, in-plane directions every
    2 deg, by FFT convolution (q1 turns the distribution rigidly: held at 0)."""
    lo, hi = _limits(m)
    q2 = np.linspace(lo[1], hi[1], int(round(math.degrees(hi[1] - lo[1]) / 2)) + 1)
    t = np.radians(np.arange(0.0, 180.0, 2.0))
    U = np.stack([np.cos(t), np.sin(t), 0 * t], axis=1)
    X = np.concatenate([U @ (m.sensitivity([0.0, a], check_limits=False)[:3] * eps) for a in q2])
    return float(fft_at_edge(X, R, 1 << 11).min())


@pytest.mark.slow  # 4-15 s: the default run stays under 4 minutes
def test_exact_search_on_two_workers_bounds_a_brute_force_grid(dealt):
    """Planar 2R, 'coarse', R 0.1 mm, exact probabilities: serial and two workers prove bounds within
    the search's tolerance (2e-7) of each other, below every FFT probability of a pose and direction
    grid, and each best value is the FFT probability at its pose and direction."""
    m = tolsynth.load_model("planar_2r")
    eps = m.tolerances("coarse")
    R = 0.1
    kw = dict(criterion="components", R=R, probability="exact", progress=False)
    one = certify_worst_pose(m, eps, "uniform", workers=1, **kw)
    two = certify_worst_pose(m, eps, "uniform", workers=2, **kw)
    assert dealt
    grid = _fft_worst_2r(m, eps, R)
    for c in (one, two):
        assert c.certified and c.best_value - c.probability_lower_bound <= 2e-7
        assert c.probability_lower_bound <= grid + 1e-7
        A = m.sensitivity(c.q, check_limits=False)[:3] * eps
        assert float(fft_at_edge((c.direction @ A)[None], R, 1 << 14)[0]) == pytest.approx(c.best_value, abs=1e-7)
    assert abs(one.probability_lower_bound - two.probability_lower_bound) <= 2e-7
    assert abs(one.best_value - two.best_value) <= 2e-7


def test_stop_levels_still_end_the_search_on_workers(dealt):
    """A pose past the stopping level ends the search, not certified, on two workers; the pose is
    past the level by the independent evaluations."""
    m = tolsynth.load_model("xu_zhang_1988")
    eps = m.tolerances("figure3")
    c = certify_worst_pose(m, eps, "uniform", progress=False, rtol=1e-4, workers=2, stop_at=0.36)
    assert not c.certified and c.reason.startswith("a point above 0.36")
    assert sigma_max(m, c.q, eps)[0] > 0.36
    m2 = tolsynth.load_model("planar_2r")
    eps2 = m2.tolerances("coarse")
    kw = dict(criterion="components", R=0.1, probability="exact", progress=False, workers=2)
    c = certify_worst_pose(m2, eps2, "uniform", stop_at=0.98, **kw)
    assert not c.certified and c.reason.startswith("a pose below 0.98")
    A = m2.sensitivity(c.q, check_limits=False)[:3] * eps2
    assert float(fft_at_edge((c.direction @ A)[None], 0.1, 1 << 14)[0]) < 0.98
    assert dealt


@pytest.mark.slow  # 4-15 s: the default run stays under 4 minutes
def test_time_limit_still_ends_the_search_on_workers(dealt):
    """A 6-joint arm under a short time limit: not certified, the time limit the reason, on time,
    and the bound reached still above sigma at random poses (numeric sensitivity)."""
    m = tolsynth.load_model("puma560")
    eps = m.tolerances("fine")
    t = time.perf_counter()
    c = certify_worst_pose(m, eps, "uniform", progress=False, workers=2, time_limit=4.0)
    assert time.perf_counter() - t < 12.0  # a round of the search may overrun the limit
    assert dealt
    assert not c.certified and c.reason == "time limit reached"
    assert c.best_value <= c.upper_bound and c.open_boxes > 0
    lo, hi = _limits(m)
    Q = lo + (hi - lo) * np.random.default_rng(5).random((200, len(lo)))
    assert sigma_max(m, Q, eps).max() <= c.upper_bound
    assert c.best_value == pytest.approx(sigma_max(m, c.q, eps)[0], rel=1e-12)


def test_worker_count_is_checked():
    assert certify_parallel.worker_count(1) == 1
    assert 1 <= certify_parallel.worker_count(None) <= certify_parallel.MAX_WORKERS
    for bad in (0, -2, 1.5, "two"):
        with pytest.raises(InputError, match="workers"):
            certify_worst_pose(tolsynth.load_model("planar_2r"), "coarse", progress=False, workers=bad)


def test_ctrl_c_ends_the_workers_and_raises_keyboard_interrupt(tmp_path):
    """SIGINT to the whole process group (as a terminal's Ctrl-C): the parent raises
    KeyboardInterrupt and no worker is left running."""
    script = tmp_path / "search.py"
    script.write_text(
        textwrap.dedent(
            """
            import os, signal, sys
            signal.signal(signal.SIGINT, signal.default_int_handler)
            import tolsynth
            from tolsynth.analysis import certify_parallel
            from tolsynth.analysis.certify import certify_worst_pose
            certify_parallel.SERIAL_SECONDS = 0.0
            m = tolsynth.load_model("puma560")
            try:
                certify_worst_pose(m, "fine", "uniform", progress=False, workers=2, rtol=1e-9)
            except KeyboardInterrupt:
                print("interrupted", flush=True)
                sys.exit(0)
            print("finished", flush=True)
            """
        )
    )
    p = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True, start_new_session=True)
    try:
        children = []
        for _ in range(300):  # wait for the workers to start
            time.sleep(0.1)
            out = subprocess.run(["pgrep", "-P", str(p.pid)], capture_output=True, text=True).stdout.split()
            if len(out) >= 2:
                children = [int(x) for x in out]
                break
        assert len(children) >= 2
        os.killpg(p.pid, signal.SIGINT)
        stdout, _ = p.communicate(timeout=30)
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
    assert p.returncode == 0 and stdout.strip() == "interrupted"
    # a child gone, or a zombie its new parent has not reaped yet, within a few seconds; a worker
    # left searching (rtol 1e-9) would run for minutes (a fresh-clone CI run on a loaded machine
    # once saw a child still listed at the instant the parent had exited)
    deadline = time.monotonic() + 10.0
    for pid in children:
        while _running(pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not _running(pid)


def _running(pid: int) -> bool:
    """Whether a process exists and is not a zombie (Linux's /proc)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


def test_boxes_kept_on_workers_cover_the_joint_space_with_sound_bounds(dealt):
    """Paper's robot, figure3, keep_boxes on two workers: random feasible poses lie in a kept box
    whose bound is above their sigma_1 (numeric sensitivity, NumPy); the largest bound kept is the
    certificate's, and the history ends at the certificate's numbers."""
    m = tolsynth.load_model("xu_zhang_1988")
    eps = m.tolerances("figure3")
    c = certify_worst_pose(m, eps, "uniform", progress=False, keep_boxes=True, workers=2)
    assert dealt and c.certified
    lo, hi, ub = c.leaves
    names = list(m.joint_names)
    free = [names.index(n) for n in c.searched]
    lq, hq = _limits(m)
    Q = lq + (hq - lq) * np.random.default_rng(17).random((400, len(names)))
    Q[:, [0, 4]] = 0.0
    Q = Q[_feasible(m, Q.T)][:150]
    X = Q[:, free]
    inside = (X[:, None] >= lo[None] - 1e-12).all(axis=2) & (X[:, None] <= hi[None] + 1e-12).all(axis=2)
    assert inside.any(axis=1).all()
    bound_at = np.where(inside, ub[None], -np.inf).max(axis=1)
    assert np.all(sigma_max(m, Q, eps) <= bound_at * (1 + 1e-12))
    assert ub.max() == pytest.approx(c.upper_bound, rel=1e-12)
    H = np.array(c.history)
    assert np.all(np.diff(H[:, 0]) >= 0) and np.all(np.diff(H[:, 2]) >= 0)
    assert H[-1, 1] == pytest.approx(c.upper_bound) and H[-1, 2] == pytest.approx(c.best_value)


def test_a_failing_background_step_raises_in_the_parent():
    """An exception in the forked process is raised again in the parent, with the worker's
    traceback as its cause; the process ends."""

    def fail():
        raise ValueError("no such pose")

    with pytest.raises(ValueError, match="no such pose") as err:
        with certify_parallel.Background(fail) as job:
            proc = job.proc
            job.result()
    assert isinstance(err.value.__cause__, RuntimeError) and "in fail" in str(err.value.__cause__)
    assert proc is not None and not proc.is_alive()
    with certify_parallel.Background(lambda: os.getpid()) as job:
        assert job.result() != os.getpid()  # it ran in another process


def test_box_limit_still_ends_the_search_on_workers(dealt):
    """The box limit counts every worker's boxes: past it the search ends, not certified, with the
    bound reached still above sigma_1 at the serial search's certified worst pose."""
    m = tolsynth.load_model("xu_zhang_1988")
    eps = m.tolerances("figure3")
    c = certify_worst_pose(m, eps, "uniform", progress=False, rtol=1e-4, workers=2, max_boxes=600)
    assert dealt
    assert not c.certified and c.reason.startswith("box limit reached") and c.open_boxes > 0
    assert 600 <= c.boxes <= 600 + 2 * 2 * 2 * 512  # a round per worker may pass it: two halves a box
    full = certify_worst_pose(m, eps, "uniform", progress=False, rtol=1e-4, workers=1)
    assert full.certified
    assert sigma_max(m, full.q, eps)[0] <= c.upper_bound
