"""Discrete process choice: branch and bound against brute-force enumeration."""

import math

import pytest

import tolsynth
from tolsynth.model.cost import Chase, Exponential, PowerLaw
from tolsynth.synthesis.processes import Process, enumerate_processes, synthesize_processes


def _processes():
    lengths = [
        Process("turning", Chase(1.0, 0.4, 1.0), 0.1, 1.0),
        Process("grinding", Chase(3.0, 0.3, 1.0), 0.02, 0.06),
        Process("lapping", Exponential(12.0, 20.0), 0.002, 0.015),
    ]
    angles = [Process("standard", PowerLaw(1.5, 0.7), 0.5, 5.0), Process("precision", PowerLaw(6.0, 0.7), 0.05, 0.4)]
    return {"l1": lengths, "l2": lengths, "o1": angles, "o2": angles}


@pytest.mark.parametrize("R", [0.5, 0.2, 0.1])
def test_branch_and_bound_matches_brute_force(R):
    mech = tolsynth.load_model("planar_2r")
    best = synthesize_processes(mech, R, 0.99, _processes(), probability="gaussian")
    brute = [
        (c, r)
        for c, r in enumerate_processes(mech, R, 0.99, _processes(), probability="gaussian")
        if r is not None and r.success
    ]
    assert len(brute) >= 1
    choice, ref = min(brute, key=lambda cr: cr[1].cost)
    assert best.proven and best.result.success
    assert best.cost == pytest.approx(ref.cost, rel=1e-7)
    assert best.lower_bound <= ref.cost * (1 + 1e-9)
    assert best.gap <= 1e-6 * best.cost
    assert best.combinations == 36 and best.nodes <= 36
    # the chosen processes hold the chosen tolerances, and the cost is theirs
    procs = _processes()
    total = 0.0
    for nm, pname in best.processes.items():
        pr = next(p for p in procs[nm] if p.name == pname)
        e = best.tolerances[nm]
        assert pr.lower * (1 - 1e-9) <= e <= pr.upper * (1 + 1e-9)
        total += float(pr.cost.cost(e))
    assert best.cost == pytest.approx(total, rel=1e-9)
    assert best.rounded is not None and best.rounded["cost"] >= best.cost * (1 - 1e-9)


def test_process_errors():
    mech = tolsynth.load_model("planar_2r")
    with pytest.raises(tolsynth.InputError, match="lower"):
        Process("x", PowerLaw(1, 1), 0.5, 0.1)
    with pytest.raises(tolsynth.InputError, match="non-empty"):
        synthesize_processes(mech, 0.5, 0.99, {"l1": []}, probability="gaussian")
    with pytest.raises(tolsynth.UnknownNameError):
        synthesize_processes(mech, 0.5, 0.99, {"zz": [Process("x", PowerLaw(1, 1), 0.1, 1.0)]}, probability="gaussian")
    p = Process.make({"name": "t", "cost": {"model": "power", "k": 1, "alpha": 0.7}, "lower": 0.1, "upper": 1})
    assert p.cost == PowerLaw(1, 0.7)
    only_coarse = {
        "l1": [Process("turning", PowerLaw(1, 0.7), 3.0, 5.0)],
        "l2": [Process("turning", PowerLaw(1, 0.7), 3.0, 5.0)],
    }
    with pytest.raises(tolsynth.InfeasibleSpecificationError):
        synthesize_processes(mech, 0.05, 0.99, only_coarse, probability="gaussian")
    assert math.isfinite(synthesize_processes(mech, 0.5, 0.99, {"l1": _processes()["l1"]}, probability="gaussian").cost)


@pytest.mark.slow
def test_worst_case_process_choice_matches_brute_force():
    """probability="worst_case": the Gaussian multipliers bound nothing there, so the nodes are
    bounded by their cheapest box cost and the leaves by their own certified solves; the search
    still proves the brute-force optimum over the 36 combinations (23.168 at R 0.5; ~13 s)."""
    mech = tolsynth.load_model("planar_2r")
    best = synthesize_processes(mech, 0.5, None, _processes(), probability="worst_case")
    brute = [
        (c, r)
        for c, r in enumerate_processes(mech, 0.5, None, _processes(), probability="worst_case")
        if r is not None and r.success
    ]
    choice, ref = min(brute, key=lambda cr: cr[1].cost)
    assert best.proven and best.result.success and best.processes == choice
    assert best.cost == pytest.approx(ref.cost, rel=1e-7)
    assert best.lower_bound <= ref.cost * (1 + 1e-9) and best.gap <= 1e-6 * best.cost


@pytest.mark.slow
def test_exact_process_choice_matches_brute_force():
    """probability="exact" on two processes of one parameter: the proven choice is the cheaper of
    the two leaves solved separately, and its bound is below both."""
    mech = tolsynth.load_model("planar_2r")
    procs = {"l1": _processes()["l1"][:2]}
    best = synthesize_processes(mech, 0.5, 0.9, procs, probability="exact")
    brute = [
        (c, r)
        for c, r in enumerate_processes(mech, 0.5, 0.9, procs, probability="exact")
        if r is not None and r.success
    ]
    choice, ref = min(brute, key=lambda cr: cr[1].cost)
    assert best.proven and best.processes == choice
    assert best.cost == pytest.approx(ref.cost, rel=1e-7)
    assert best.lower_bound <= ref.cost * (1 + 1e-9)


def test_process_choice_refuses_an_unknown_probability():
    with pytest.raises(tolsynth.InputError, match="probability.*'gaussian' or 'exact' or 'worst_case'"):
        synthesize_processes("planar_2r", 0.5, 0.99, {"l1": _processes()["l1"]}, probability="bogus")
