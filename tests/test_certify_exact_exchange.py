"""The certified exchange with exact probabilities (``synthesize_workspace(certify=True,
probability="exact")``): it stops when every component probability is proven ``>= p - 1e-6`` over
the whole joint space.  Checked on the planar 2R against numbers computed here without the
package's probability code: P(|u . dr| <= R) of the linear model, a sum of independent uniform
errors, by FFT convolution of their densities, at a grid of poses and directions."""

from __future__ import annotations

import numpy as np
import pytest

import tolsynth
from tolsynth.errors import CertificationWarning, OutOfRangeError
from tolsynth.kinematics.joint_space import _limits
from tolsynth.synthesis.workspace import synthesize_workspace

R, P = 0.2, 0.99


def _p_uniform_sum(c, R, n=1 << 16):
    """P(|sum c_i U_i| <= R), U_i uniform on [-1, 1], by FFT convolution of the box densities on a
    grid of n points (error well under 1e-7 here, the densities are continuous after one term)."""
    c = np.abs(np.asarray(c, dtype=float))
    c = c[c > 1e-15]
    L = 1.05 * c.sum() + R
    x = np.linspace(-L, L, n, endpoint=False)
    dx = x[1] - x[0]
    f = np.fft.rfftfreq(n, dx)
    ch = np.ones_like(f, dtype=complex)
    for ci in c:  # characteristic function of each uniform: sinc
        ch *= np.sinc(2.0 * ci * f)
    dens = np.fft.irfft(ch, n) / dx
    dens = np.fft.fftshift(dens)
    cdf = np.cumsum(dens) * dx
    return float(np.interp(R, x + dx / 2, cdf) - np.interp(-R, x + dx / 2, cdf))


@pytest.mark.slow  # 4-10 s: four solves and a certified search of ~16 000 boxes
def test_exact_certified_exchange_on_the_planar_2r():
    mech = tolsynth.load_model("planar_2r")
    w = synthesize_workspace(mech, R, P, "uniform", 0.7, probability="exact", certify=True, progress=False)
    assert w.converged and w.certified and w.reason == ""
    assert w.upper_bound is None and w.probability_lower_bound >= P - 1e-6
    assert w.rounds[-1]["certified"] is True and w.rounds[-1]["boxes"] > 0
    cert = w.certificate
    assert cert.probability == "exact" and cert.criterion == "components"
    eps = np.asarray(w.result.x)
    # the best pose's probability, recomputed by convolution: within 1e-6 of the search's value
    A = mech.sensitivity(cert.q, check_limits=False)[:3]
    assert _p_uniform_sum((cert.direction @ A) * eps, R) == pytest.approx(cert.best_value, abs=1e-6)
    # no pose of a grid, along any of 90 directions, below the proven bound
    lo, hi = _limits(mech)
    q1, q2 = np.meshgrid(np.linspace(lo[0], hi[0], 9), np.linspace(lo[1], hi[1], 25))
    th = np.linspace(0, np.pi, 90, endpoint=False)
    U = np.stack([np.cos(th), np.sin(th), np.zeros_like(th)], 1)
    worst = 1.0
    for q in np.stack([q1.ravel(), q2.ravel()], 1):
        A = mech.sensitivity(q, check_limits=False)[:3]
        C = np.abs(U @ A) * eps
        i = int(np.argmax((C**2).sum(axis=1)))  # the largest variance: where P is lowest, near enough
        for j in (i - 1, i, (i + 1) % len(th)):
            worst = min(worst, _p_uniform_sum(C[j], R))
    assert worst >= w.probability_lower_bound - 1e-7
    assert worst - w.probability_lower_bound <= 2e-4  # and the bound is not trivially low


@pytest.mark.slow  # 40-70 s: six solves, their pose searches, and a certified proof of ~10 000 boxes
def test_exact_certified_exchange_on_the_paper_robot():
    """The paper's robot (R 0.5 mm, p 0.99, uniform errors, alpha 0.7) with the default exact
    reading: the exchange converges with every component probability proven >= p - 1e-6 over the
    continuous joint space.  Checked against an independent evaluation (FFT convolution, its worst
    direction by shrinking Fibonacci caps): at the certificate's pose the probability equals the
    search's value; at the binding poses, 2 deg from them along the interference limit and at a few
    poses about the certificate's none is below the proven bound, and the bound is within 1e-3 of
    the lowest the independent search finds (tight)."""
    from independent import fft_at_edge, independent_worst

    m = tolsynth.load_model("xu_zhang_1988")
    w = synthesize_workspace(m, 0.5, P, progress=False, certify=True)
    assert w.converged and w.certified and w.result.probability_kind == "exact"
    lb = w.probability_lower_bound
    assert lb >= P - 1e-6
    cert = w.certificate
    eps = np.asarray(w.result.x)
    M = m.sensitivity(cert.q, check_limits=False)[:3] * eps
    assert fft_at_edge((cert.direction @ M)[None], 0.5, 1 << 14)[0] == pytest.approx(cert.best_value, abs=2e-7)
    lowest = 1.0
    about = np.radians([[0, 0, 0], [0, 0, 2], [0, 0, -2], [2, 2, 2]])
    for q, offsets in [(q, about[[0, 3]]) for q in w.poses] + [(cert.q, about)]:
        for d in offsets:
            qq = np.array(q, dtype=float)
            qq[[1, 2, 3]] += d
            try:
                A = m.sensitivity(qq)[:3]
            except OutOfRangeError:  # outside the limits or the interference constraint
                continue
            lowest = min(lowest, independent_worst(A * eps, 0.5)[0])
    assert lowest >= lb - 2e-7
    assert lowest - lb <= 1e-3


@pytest.mark.slow  # about 12 s: the certified minimum and an independent search about it
def test_exact_certified_minimum_on_the_paper_robot_against_an_independent_search():
    """The paper's robot at its Figure 3 tolerances, R 0.5 mm, the exact reading, no target: the
    certified smallest per-direction probability over the joint space.  The pose it reports is the
    corner of the joint limit theta2 = 140 deg and the interference limit; at it the probability by
    FFT convolution (worst direction by shrinking Fibonacci caps) equals the search's value, no
    pose of a few over the wrist angle and about the corner is below the proven bound."""
    from independent import fft_at_edge, independent_worst
    from tolsynth.analysis.certify import certify_worst_pose

    m = tolsynth.load_model("xu_zhang_1988")
    eps = m.tolerances("figure3")
    c = certify_worst_pose(m, "figure3", "uniform", "components", 0.5, "exact", progress=False)
    assert c.certified and c.best_value - c.probability_lower_bound <= 2e-7
    assert np.degrees(c.q[1:3]) == pytest.approx([140.0, 90.0], abs=1e-6)
    M = m.sensitivity(c.q, check_limits=False)[:3] * eps
    assert fft_at_edge((c.direction @ M)[None], 0.5, 1 << 14)[0] == pytest.approx(c.best_value, abs=2e-7)
    lowest = 1.0
    poses = [(140.0, 90.0, t4) for t4 in (20.0, 35.0, 45.0, 60.0)]
    poses += [(141.0, 91.0, 40.0), (160.0, 90.0, 40.0)]
    for t2, tp2, t4 in poses:
        A = m.sensitivity(np.radians([0.0, t2, tp2, t4, 0.0]))[:3]
        lowest = min(lowest, independent_worst(A * eps, 0.5)[0])
    assert lowest >= c.probability_lower_bound - 2e-7


@pytest.mark.slow
def test_exact_proof_on_five_searched_joints_is_announced_at_once():
    """The Puma 560 searches five joints (its waist turns the error rigidly): the certified exact
    exchange warns in its first round that this proof has not been seen to close, and the result
    says it did not; the paper's robot (three searched joints) gets no such warning."""
    import warnings

    with pytest.warns(CertificationWarning, match="5 searched joints"):
        ws = synthesize_workspace(
            tolsynth.load_model("puma560"), 0.5, 0.99, certify=True, max_rounds=1, certify_options={"time_limit": 1}
        )
    assert not ws.certified and ws.reason
    with warnings.catch_warnings():
        warnings.simplefilter("error", CertificationWarning)
        synthesize_workspace(
            tolsynth.load_model("xu_zhang_1988"),
            0.5,
            0.99,
            certify=True,
            max_rounds=1,
            certify_options={"time_limit": 1},
        )


@pytest.mark.slow
def test_exact_searches_on_five_searched_joints_have_a_default_time_limit(monkeypatch):
    """Without a limit of its own, each exact certified search on five searched joints stops after
    EXACT_WIDE_SECONDS (one search would otherwise bound 400 000 boxes, over 15 min on the Puma 560);
    a limit the caller gives, of time or of boxes, is kept, and a smaller robot gets none."""
    from tolsynth.analysis import certify
    from tolsynth.synthesis import workspace

    real, seen = certify.certify_worst_pose, []

    def spy(*args, **kw):
        seen.append({k: kw.get(k) for k in ("time_limit", "max_boxes")})
        kw["max_boxes"] = 50  # the limits passed are what is checked; the search itself is cut short
        kw.pop("time_limit", None)
        return real(*args, **kw)

    monkeypatch.setattr(certify, "certify_worst_pose", spy)
    puma = tolsynth.load_model("puma560")
    for options, expected in (
        (None, {"time_limit": workspace.EXACT_WIDE_SECONDS, "max_boxes": None}),
        ({"time_limit": 7}, {"time_limit": 7, "max_boxes": None}),
        ({"max_boxes": 300}, {"time_limit": None, "max_boxes": 300}),
    ):
        seen.clear()
        with pytest.warns(CertificationWarning, match="5 searched joints"):
            synthesize_workspace(puma, 0.5, 0.99, certify=True, max_rounds=1, certify_options=options)
        assert seen == [expected]
    seen.clear()
    synthesize_workspace(tolsynth.load_model("xu_zhang_1988"), 0.5, 0.99, certify=True, max_rounds=1)
    assert seen == [{"time_limit": None, "max_boxes": None}]


@pytest.mark.slow  # about 20 s: two certified searches and five independent worst directions
def test_exact_minimum_on_five_searched_joints_settled_from_the_sigma_bound(monkeypatch):
    """The Puma 560 (five searched joints) at its 'fine' tolerances and R 0.5 mm: the certified
    sigma_1 is below R / 3.03, where Eaton's tail bound proves every direction's probability, so the
    exact search settles its joint boxes whole and is certified in a few hundred boxes; without
    that bound the vertex pairs alone are far from it after 1 500.  The proven bound is below the
    probability by FFT convolution at the worst pose found and at random poses (worst direction
    by Fibonacci caps)."""
    from independent import fft_at_edge, independent_worst
    from tolsynth.analysis import certify_exact
    from tolsynth.analysis.certify import certify_worst_pose
    from tolsynth.probability.tail_bound import z_for

    m = tolsynth.load_model("puma560")
    eps = m.tolerances("fine")
    s = certify_worst_pose(m, "fine", "uniform", "sigma", 0.5, progress=False)
    assert s.certified and s.upper_bound < 0.5 / z_for(1e-7)
    c = certify_worst_pose(m, "fine", "uniform", "components", 0.5, "exact", progress=False, max_boxes=3000, workers=1)
    assert c.certified and c.boxes < 1000 and "sigma_1" in c.method
    assert c.probability_lower_bound >= 1 - 1e-7
    M = m.sensitivity(c.q, check_limits=False)[:3] * eps
    assert fft_at_edge((c.direction @ M)[None], 0.5, 1 << 14)[0] >= c.probability_lower_bound - 1e-9
    rng = np.random.default_rng(5)
    lo, hi = _limits(m)
    for q in lo + (hi - lo) * rng.random((4, len(lo))):
        A = m.sensitivity(q, check_limits=False)[:3]
        assert independent_worst(A * eps, 0.5)[0] >= c.probability_lower_bound - 1e-9
    monkeypatch.setattr(certify_exact, "covered", lambda shapes: False)
    c0 = certify_worst_pose(m, "fine", "uniform", "components", 0.5, "exact", progress=False, max_boxes=1500, workers=1)
    assert not c0.certified and c0.probability_lower_bound < 0.9 and "sigma_1" not in c0.method


@pytest.mark.slow  # about 10 s: a certified Gaussian exchange and FFT searches at its poses
def test_exact_reading_proven_through_sigma_on_the_paper_robot():
    """``certify_options={"through": "sigma"}``: the Gaussian reading's certified exchange at the
    z where Eaton's bound proves p - 1e-6 (3.027 at p 0.99, tol 1e-3); the proven sigma_1 then
    bounds every direction's exact probability.  Checked independently: at the Gaussian
    certificate's worst pose and at the binding poses the exact probability by FFT convolution
    (worst direction by Fibonacci caps) is above p (there it is about 0.998: what the proof this way
    gives away), and the cost premium over the exact reading's solve at the same poses is what
    the result reports as its gap."""
    from independent import independent_worst

    m = tolsynth.load_model("xu_zhang_1988")
    w = synthesize_workspace(m, 0.5, P, progress=False, certify=True, certify_options={"through": "sigma"})
    assert w.converged and w.certified and w.probability_lower_bound >= P - 1e-6
    assert w.through == pytest.approx(3.0272, abs=1e-3) and w.upper_bound is None
    assert w.certificate.upper_bound <= 1 + 1e-3  # the Gaussian proof it rests on
    eps = np.asarray(w.result.x)
    lowest = min(
        independent_worst(m.sensitivity(q, check_limits=False)[:3] * eps, 0.5)[0] for q in w.poses + [w.certificate.q]
    )
    assert P < lowest < 0.9995
    exact = tolsynth.synthesize(m, 0.5, P, poses=w.poses)
    assert exact.probability_kind == "exact" and w.lower_bound == pytest.approx(exact.lower_bound, rel=1e-9)
    assert 0.05 < w.gap / w.result.cost < 0.25
    assert "Eaton" in w.certificate_line()


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(certify_options={"through": "taylor"}), "'sigma'"),
        (dict(probability="gaussian", certify_options={"through": "sigma"}), "exact reading"),
        (dict(distribution="truncnormal", certify_options={"through": "sigma"}), "uniform, triangular, normal"),
    ],
)
def test_proof_through_sigma_refuses_what_it_cannot_prove(kwargs, match):
    from tolsynth.errors import InputError

    with pytest.raises(InputError, match=match):
        synthesize_workspace(tolsynth.load_model("planar_2r"), R, P, certify=True, progress=False, **kwargs)
