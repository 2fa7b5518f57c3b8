"""The worst-case reading joined to the other features: the workspace exchange, contributions,
reports, locks and the arguments the worst case reads no use for, each checked against brute force
over the sign patterns or a hand-derived Jacobian."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

import tolsynth
from tolsynth.errors import InputError

SIGNS4 = np.array(list(itertools.product([-1.0, 1.0], repeat=4)))


def planar_2r_worst_case(eps, q1, q2, l1=500.0, l2=300.0):
    """max |dr| over every error in its band of the planar 2R arm, by hand: the link lengths move
    the hand along each link, the joint offsets (mrad) turn what lies beyond them; all 16 sign
    patterns (eps in the order l1, l2, o1, o2)."""
    c1, s1, c12, s12 = math.cos(q1), math.sin(q1), math.cos(q1 + q2), math.sin(q1 + q2)
    x, y = l1 * c1 + l2 * c12, l1 * s1 + l2 * s12
    G = (
        np.array([[c1, s1], [c12, s12], [-1e-3 * y, 1e-3 * x], [-1e-3 * l2 * s12, 1e-3 * l2 * c12]])
        * np.asarray(eps)[:, None]
    )
    return float(np.max(np.linalg.norm(SIGNS4 @ G, axis=1)))


@pytest.mark.slow  # about 8 s: three exchange rounds, each a search of exact zonotope maxima
def test_workspace_exchange_of_the_worst_case_meets_r_on_a_dense_grid():
    m = tolsynth.load_model("planar_2r")
    ws = tolsynth.synthesize_workspace(m, R=0.5, probability="worst_case")
    assert ws.converged and ws.success
    assert "worst-case" in ws.worst_quantity
    eps = [ws.result.tolerances[n] for n in ("l1", "l2", "o1", "o2")]
    worst = max(
        planar_2r_worst_case(eps, q1, q2)
        for q1 in np.radians(np.linspace(-170, 170, 7))
        for q2 in np.radians(np.linspace(-150, 150, 3001))
    )
    # the single-pose design misses R by 0.8 % at q2 = 14.5 deg; the exchange's meets it to tol
    assert worst <= 0.5 * (1 + 1e-3)
    assert ws.worst_value == pytest.approx(worst / 0.5, abs=2e-4)


@pytest.mark.parametrize(
    "kw",
    [
        {"p": 0.99},
        {"distribution": "normal"},
        {"certify": True},
    ],
)
def test_workspace_exchange_refuses_what_the_worst_case_does_not_read(kw):
    with pytest.raises(InputError) as e:
        tolsynth.synthesize_workspace("planar_2r", R=0.5, probability="worst_case", **kw)
    assert e.value.field == next(iter(kw))


@pytest.mark.parametrize("kw", [{"R": 0.5}, {"p": 0.99}])
def test_best_accuracy_refuses_a_probability_the_worst_case_does_not_have(kw):
    with pytest.raises(InputError) as e:
        tolsynth.best_accuracy("planar_2r", 20.0, probability="worst_case", **kw)
    assert e.value.field == next(iter(kw))


def test_best_accuracy_of_the_worst_case_finds_the_smallest_r():
    m = tolsynth.load_model("planar_2r")
    out = tolsynth.best_accuracy(m, 20.0, probability="worst_case")
    assert out.quantity == "R"
    eps = [out.result.tolerances[n] for n in ("l1", "l2", "o1", "o2")]
    q = m.configurations["worst"]
    # the design bought meets its R by the hand Jacobian, spends the budget, and a 1 % smaller R costs more
    assert planar_2r_worst_case(eps, *q) <= out.value * (1 + 1e-6)
    assert out.result.cost <= 20.0
    assert tolsynth.synthesize(m, R=0.99 * out.value, probability="worst_case").cost > 20.0


def test_contributions_of_a_worst_case_design_are_the_stack_up_terms():
    m = tolsynth.load_model("xu_zhang_1988")
    res = tolsynth.synthesize(m, R=0.8, probability="worst_case")
    c = tolsynth.contributions(res)
    C = np.asarray(m.sensitivity("worst"))[:3] * np.array([res.tolerances[n] for n in m.error_parameters])
    signs = np.array(list(itertools.product([-1.0, 1.0], repeat=C.shape[1])))
    V = signs @ C.T
    k = int(np.argmax(np.einsum("ij,ij->i", V, V)))
    h = float(np.linalg.norm(V[k]))
    u = V[k] / h  # the brute-force farthest corner's direction
    order = [list(c.names).index(n) for n in m.error_parameters]
    assert h == pytest.approx(0.8, rel=1e-6)
    assert c.worst[0] == pytest.approx(h, rel=1e-9)
    assert c.terms[0].sum() == pytest.approx(h, rel=1e-9)
    np.testing.assert_allclose(c.terms[0][order], np.abs(u @ C), rtol=1e-7, atol=1e-12)


def test_cli_contributions_of_a_worst_case_design(capsys):
    from tolsynth.cli import main

    assert main(["solve", "--model", "planar_2r", "--R", "0.5", "--probability", "worst_case", "--contributions"]) == 0
    assert "term |u . a_i| eps_i" in capsys.readouterr().out


def test_report_of_a_worst_case_design_is_refused_before_any_work(tmp_path):
    m = tolsynth.load_model("planar_2r")
    res = tolsynth.synthesize(m, R=0.5, probability="worst_case")
    with pytest.raises(InputError) as e:
        tolsynth.report(res, mechanism=m, path=str(tmp_path / "r.md"))
    assert e.value.field == "source"
    assert not (tmp_path / "r.md").exists()


def test_worst_case_lock_that_alone_breaks_r_is_named():
    from tolsynth.errors import InfeasibleSpecificationError

    # h3 is a length along a joint axis: its sensitivity is a unit vector, so 5 mm alone is 5 / 0.8 R
    with pytest.raises(InfeasibleSpecificationError) as e:
        tolsynth.synthesize("xu_zhang_1988", R=0.8, probability="worst_case", locks={"h3": 5})
    assert "locked tolerances ['h3']" in str(e.value)
    assert e.value.value == pytest.approx(6.25, rel=1e-9)


def test_worst_case_summary_marks_a_lock_fixed():
    res = tolsynth.synthesize("xu_zhang_1988", R=0.8, probability="worst_case", locks={"h3": 0.3})
    line = next(ln for ln in res.summary().splitlines() if ln.strip().startswith("h3 ="))
    assert line.endswith("[fixed]")


@pytest.mark.parametrize(
    "kw, field",
    [
        ({"distribution": "normal"}, "distribution"),
        ({"criterion": "sphere"}, "criterion"),
        ({"p_orientation": 0.9}, "p_orientation"),
        ({"Phi": 0.01, "p_orientation": 0.9}, "p_orientation"),
        ({"probability": "worstcase"}, "probability"),
    ],
)
def test_synthesize_refuses_what_the_worst_case_would_ignore(kw, field):
    kw = {"probability": "worst_case", **kw}
    with pytest.raises(InputError) as e:
        tolsynth.synthesize("planar_2r", R=0.5, **kw)
    assert e.value.field == field
    if field == "probability":
        assert "'worst_case'" in str(e.value)


def test_worst_case_summary_shows_no_negative_gap():
    from tolsynth.problem.result import optimality_gap

    res = tolsynth.synthesize("planar_2r", R=0.5, probability="worst_case")
    assert res.gap >= 0.0 and "gap -" not in res.summary()
    # a bound above the cost by what rounding left on the command line (7.37e-11) is stored as 0
    assert optimality_gap(res.cost, res.cost + 7.37e-11) == 0.0


def test_worst_case_result_carries_a_sampled_workspace_check_in_the_worst_case():
    """The planar 2R's single-pose worst-case design, checked at 300 poses drawn uniformly inside
    the joint limits (seed 0, drawn again here): the largest worst-case |dr| / R is the brute force
    over all 16 sign patterns at every one of them, reached at the reported pose, over 1 (the
    design misses R away from its pose), so it warns; summary and to_dict show it once read."""
    from tolsynth.errors import WorkspaceWarning

    m = tolsynth.load_model("planar_2r")
    res = tolsynth.synthesize(m, R=0.5, probability="worst_case")
    assert res.workspace is not None and "workspace check: not computed" in res.summary()
    assert res.to_dict()["workspace_check"] is None  # never computed by a summary or a dict
    with pytest.warns(WorkspaceWarning):
        line = res.workspace.line()
    eps = [res.tolerances[n] for n in ("l1", "l2", "o1", "o2")]
    lo, hi = np.radians([-170.0, -150.0]), np.radians([170.0, 150.0])
    Q = lo[:, None] + (hi - lo)[:, None] * np.random.default_rng(0).random((2, 300))
    brute = np.array([planar_2r_worst_case(eps, *q) for q in Q.T]) / 0.5
    ws = res.workspace
    assert ws.worst == pytest.approx(brute.max(), rel=1e-9) and ws.worst > 1.005
    assert planar_2r_worst_case(eps, *ws.q) / 0.5 == pytest.approx(ws.worst, rel=1e-9)
    assert "worst-case |dr|/R" in line and "over the specification" in line
    d = res.to_dict()["workspace_check"]
    assert d["probabilities"] == "worst_case" and d["exceeds"] and d["worst"] == ws.worst
    assert line in res.summary()


def test_worst_case_workspace_check_within_r_does_not_warn():
    """The paper's robot at its worst pose: the largest sampled worst case (0.963) is below 1 and
    equals the brute force over the 2^11 sign patterns at the reported pose; no warning."""
    import warnings

    m = tolsynth.load_model("xu_zhang_1988")
    res = tolsynth.synthesize(m, R=0.5, probability="worst_case")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ws = res.workspace
        assert ws.worst < 1 and not ws.exceeds and "within the specification" in ws.line()
    C = np.asarray(m.sensitivity(ws.q))[:3] * res.x
    signs = np.array(list(itertools.product([-1.0, 1.0], repeat=m.n)))
    assert np.max(np.linalg.norm(signs @ C.T, axis=1)) / 0.5 == pytest.approx(ws.worst, rel=1e-9)


def test_worst_case_result_records_how_its_default_pose_was_chosen():
    """The PUMA 560 has no 'worst' configuration: the worst-case design is made at the worst-pose
    search's pose (the documented rule, computed here by calling worst_pose directly), and its
    inputs and summary say so, as a statistical result's do; a pose given is recorded as no note."""
    m = tolsynth.load_model("puma560")
    assert "worst" not in m.configurations
    lo, hi = (np.asarray(b, dtype=float) for b in m.bounds)
    q = np.asarray(tolsynth.worst_pose(m, np.sqrt(lo * hi), criterion="sigma", reference=None).q, dtype=float)
    res = tolsynth.synthesize(m, R=0.5, probability="worst_case")
    np.testing.assert_allclose(list(res.spec.poses.values())[0], q, atol=1e-12)
    note = res.inputs["default_pose"]
    assert "worst-pose search" in note and m.format_joints(q) in note
    assert f"pose: {note}" in res.summary()
    given = tolsynth.synthesize(m, R=0.5, probability="worst_case", pose=next(iter(m.configurations)))
    assert "default_pose" not in given.inputs


def test_process_choice_in_the_worst_case_takes_no_p():
    """synthesize_processes with probability='worst_case' needs no p (its design meets R at the
    pose over all 16 sign patterns, exactly, by hand); a p given would be ignored, so it is
    refused, and a statistical reading without p is refused too, each naming p."""
    from tolsynth.model.cost import PowerLaw
    from tolsynth.synthesis.processes import Process

    procs = {
        "l1": [Process("turning", PowerLaw(1.0, 0.7), 0.05, 0.5), Process("grinding", PowerLaw(3.0, 0.7), 0.01, 0.05)]
    }
    best = tolsynth.synthesize_processes("planar_2r", 0.5, processes=procs, probability="worst_case")
    assert best.proven and best.result.probability_kind == "worst_case"
    eps = [best.result.tolerances[n] for n in ("l1", "l2", "o1", "o2")]
    assert planar_2r_worst_case(eps, 0.0, 0.0) == pytest.approx(0.5, rel=1e-6)
    for p, probability in ((0.99, "worst_case"), (None, "gaussian"), (None, None)):
        with pytest.raises(InputError) as e:
            tolsynth.synthesize_processes("planar_2r", 0.5, p, procs, probability=probability)
        assert e.value.field == "p"


def test_sweep_in_the_worst_case_has_no_p(capsys):
    """A worst-case sweep takes no p and no shape and has no such columns; each row's design meets
    R at the pose over all 16 sign patterns (by hand); a p (one or a grid) or a distribution would
    be ignored, so it is refused before any solve, as is a statistical sweep without p.  The
    command line's sweep offers no worst case (exit 2, one message, no traceback)."""
    pytest.importorskip("pandas")
    from tolsynth.cli import main

    df = tolsynth.sweep("planar_2r", [0.5, 0.8], probability="worst_case", client="serial")
    assert "p" not in df.columns and "distribution" not in df.columns
    assert "p" not in df.attrs["inputs"]["grid"]
    assert list(df["probability"]) == ["worst_case"] * 2 and df["success"].all()
    for _, row in df.iterrows():
        eps = [row[f"eps_{n}"] for n in ("l1", "l2", "o1", "o2")]
        assert planar_2r_worst_case(eps, 0.0, 0.0) == pytest.approx(row["R"], rel=1e-6)
    for kw in ({"p": 0.99}, {"p": [0.9, 0.99]}, {"distribution": "normal"}):
        with pytest.raises(InputError) as e:
            tolsynth.sweep("planar_2r", [0.5], probability="worst_case", client="serial", **kw)
        assert e.value.field == next(iter(kw))
    with pytest.raises(InputError) as e:
        tolsynth.sweep("planar_2r", [0.5], client="serial")
    assert e.value.field == "p"
    cli = ["sweep", "--model", "planar_2r", "--R", "0.5", "--p", "0.9", "--probability", "worst_case"]
    with pytest.raises(SystemExit) as ex:
        main(cli)
    err = capsys.readouterr().err
    assert ex.value.code == 2 and "--probability" in err and "Traceback" not in err


def test_cli_worst_case_wording_names_no_probabilities(capsys):
    """A worst-case solve has no probabilities: its heading says "worst case" once, with or
    without --p."""
    from tolsynth.cli import main

    base = ["solve", "--model", "planar_2r", "--R", "0.5", "--probability", "worst_case"]
    assert main(base) == 0
    head = capsys.readouterr().out.splitlines()[0]
    assert head.count("worst case") == 1 and "probabilit" not in head
    assert main(base + ["--p", "0.99"]) == 0
    head = capsys.readouterr().out.splitlines()[0]
    assert head.count("worst case") == 1 and "probabilit" not in head and "p=0.99" in head


@pytest.mark.slow  # the worst-case exchange on planar_2r: about 10 s
def test_cli_worst_case_rounds_name_the_worst_case_quantity(capsys):
    """With --everywhere each round line of a worst-case solve reports the largest worst-case
    |dr| / R, once."""
    from tolsynth.cli import main

    argv = ["solve", "--model", "planar_2r", "--R", "0.5", "--probability", "worst_case", "--everywhere"]
    assert main(argv) == 0
    rounds = [ln for ln in capsys.readouterr().out.splitlines() if ln.lstrip().startswith("round ")]
    assert rounds and all("largest worst-case |dr| / R over the workspace" in ln for ln in rounds)
    assert not any("worst worst" in ln for ln in rounds)
