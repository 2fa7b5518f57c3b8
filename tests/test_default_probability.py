"""The library's default probability is the exact one, everywhere a probability enters: the API's
design functions, sweeps, fronts, budgets, the CLI and the records they write; ``reproduce`` and
``compare`` read the paper's Gaussian criterion and say so; ``probability="gaussian"`` opts out.

The designs themselves are checked against independent computations elsewhere (the README's
example by FFT convolution, tests/test_exact*.py by convolution, Monte Carlo and brute force); here
each default design is checked to be the exact design (the same cost as ``probability="exact"``
to 1e-9, and a different one from the Gaussian design) and to meet p along its worst direction
by FFT convolution and an independent Monte Carlo of the linear error model."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import tolsynth
from independent import fft_probabilities, fibonacci_directions
from tolsynth.model.cost import Chase, PowerLaw
from tolsynth.synthesis.processes import Process

XZ = "xu_zhang_1988"


@pytest.fixture(scope="module")
def xz():
    return tolsynth.load_model(XZ)


@pytest.fixture(scope="module")
def designs(xz):
    return {
        prob: tolsynth.synthesize(xz, R=0.5, p=0.9, **({} if prob is None else {"probability": prob}))
        for prob in (None, "exact", "gaussian")
    }


def test_synthesize_defaults_to_the_exact_design(xz, designs):
    d, e, g = designs[None], designs["exact"], designs["gaussian"]
    assert d.success and d.probability_kind == "exact" and d.inputs["probability"] == "exact"
    assert d.cost == pytest.approx(e.cost, rel=1e-9)
    assert abs(d.cost - g.cost) > 1e-3 * g.cost  # the two criteria differ on uniform errors
    assert g.probability_kind == "gaussian"
    # the default design meets p = 0.9 along every direction (FFT convolution of the uniform
    # densities, 1000 directions) and is at p along the worst of them, where an independent Monte
    # Carlo of the linear model agrees
    A = xz.sensitivity("worst")[:3]
    W = fibonacci_directions(1000)
    probs = fft_probabilities((W @ A) * d.x, 0.5)
    assert 0.9 - 5e-5 <= probs.min() <= 0.9 + 2e-3
    w = W[int(np.argmin(probs))]
    rng = np.random.default_rng(7)
    U = rng.uniform(-1.0, 1.0, size=(400_000, A.shape[1]))
    p_mc = np.mean(np.abs(U @ ((w @ A) * d.x)) <= 0.5)
    assert abs(p_mc - probs.min()) <= 4 * np.sqrt(0.9 * 0.1 / U.shape[0])


def test_the_records_say_which_probability(designs):
    d, g = designs[None], designs["gaussian"]
    assert d.to_dict()["probability"] == "exact" and g.to_dict()["probability"] == "gaussian"
    assert "probabilities: exact" in d.summary()
    pytest.importorskip("pandas")
    assert d.to_frame().attrs["summary"]["probability"] == "exact"


def test_sweep_front_and_budget_default_to_exact(xz, designs):
    pytest.importorskip("pandas")
    df = tolsynth.sweep(xz, R=[0.5], p=[0.9], client="serial", progress=False)
    assert list(df["probability"]) == ["exact"]
    assert df["cost"].iloc[0] == pytest.approx(designs["exact"].cost, rel=1e-9)
    front = tolsynth.pareto_front(xz, R=[0.5, 1.0], p=0.9)
    assert front.rows[0]["cost"] == pytest.approx(designs["exact"].cost, rel=1e-9)
    assert all(row["probability"] == "exact" for row in front.rows)
    # the budget of the exact design at R = 0.5 buys R = 0.5 (to the bisection's width) at p = 0.9
    out = tolsynth.best_accuracy(xz, designs["exact"].cost, p=0.9, rtol=1e-3)
    assert out.value == pytest.approx(0.5, rel=2e-3)
    gauss = tolsynth.best_accuracy(xz, designs["exact"].cost, p=0.9, rtol=1e-3, probability="gaussian")
    assert abs(gauss.value / out.value - 1) > 1e-3  # the Gaussian reading buys another R for that cost


def _same_exchange(mech, R, p):
    """The default exchange against the one with probability="exact" named: every round reads the
    default, its pose searches included."""
    w = tolsynth.synthesize_workspace(mech, R=R, p=p)
    named = tolsynth.synthesize_workspace(mech, R=R, p=p, probability="exact")
    assert w.converged and w.result.probability_kind == "exact"
    assert w.result.cost == pytest.approx(named.result.cost, rel=1e-9)
    assert [r["worst_value"] for r in w.rounds] == pytest.approx([r["worst_value"] for r in named.rounds], rel=1e-6)


def test_workspace_defaults_to_exact():
    _same_exchange(tolsynth.load_model("planar_2r"), 0.5, 0.99)


@pytest.mark.slow  # 12 exact solves of the process search, about 4 s
def test_processes_default_to_exact():
    mech = tolsynth.load_model("planar_2r")
    lengths = [
        Process("turning", Chase(1.0, 0.4, 1.0), 0.05, 1.0),
        Process("grinding", Chase(3.0, 0.3, 1.0), 0.005, 0.06),
    ]
    angles = [Process("standard", PowerLaw(1.5, 0.7), 0.5, 5.0), Process("precision", PowerLaw(6.0, 0.7), 0.05, 0.4)]
    procs = {"l1": lengths, "l2": lengths, "o1": angles, "o2": angles}
    best = tolsynth.synthesize_processes(mech, 0.5, 0.9, procs)
    assert best.proven and best.result.probability_kind == "exact"
    again = tolsynth.synthesize_processes(mech, 0.5, 0.9, procs, probability="exact")
    assert best.cost == pytest.approx(again.cost, rel=1e-9)


@pytest.mark.slow
def test_paper_robot_workspace_defaults_to_exact(xz):
    _same_exchange(xz, 0.5, 0.99)


def test_compare_reads_the_paper_criterion(xz, designs):
    c = tolsynth.compare(xz, R=0.5, p=0.9)
    assert c.ipopt.probability_kind == "gaussian" and c.sumt.probability_kind == "gaussian"
    assert c.ipopt.cost == pytest.approx(designs["gaussian"].cost, rel=1e-7)


def _cli(*args):
    out = subprocess.run([sys.executable, "-m", "tolsynth", *args], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout


@pytest.mark.slow  # 4-15 s: the default run stays under 4 minutes
def test_cli_defaults_to_exact_and_opts_out(designs):
    d = json.loads(_cli("solve", "--model", XZ, "--R", "0.5", "--p", "0.9", "--json"))
    assert d["probability"] == "exact" and d["inputs"]["probability"] == "exact"
    assert d["cost"] == pytest.approx(designs["exact"].cost, rel=1e-9)
    g = json.loads(_cli("solve", "--model", XZ, "--R", "0.5", "--p", "0.9", "--json", "--probability", "gaussian"))
    assert g["probability"] == "gaussian" and g["cost"] == pytest.approx(designs["gaussian"].cost, rel=1e-9)


@pytest.mark.slow
def test_cli_sweep_pareto_budget_default_to_exact(designs):
    text = _cli("solve", "--model", XZ, "--R", "0.5", "--p", "0.9", "--solver", "both")
    assert "the paper's Gaussian criterion" in text.splitlines()[0]
    assert "the paper's Gaussian criterion" in _cli("reproduce", "--no-sumt")
    pytest.importorskip("pandas")
    s = json.loads(_cli("sweep", "--model", XZ, "--R", "0.5", "--p", "0.9", "--json", "--quiet"))
    assert s["rows"][0]["probability"] == "exact" and s["inputs"]["probability"] == "exact"
    assert s["rows"][0]["cost"] == pytest.approx(designs["exact"].cost, rel=1e-9)
    s = json.loads(
        _cli("sweep", "--model", XZ, "--R", "0.5", "--p", "0.9", "--json", "--quiet", "--probability", "gaussian")
    )
    assert s["rows"][0]["cost"] == pytest.approx(designs["gaussian"].cost, rel=1e-9)
    b = json.loads(_cli("budget", "--model", XZ, "--cost", f"{designs['exact'].cost}", "--p", "0.9", "--json"))
    assert b["inputs"]["probability"] == "exact"
