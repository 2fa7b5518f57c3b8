"""The design report's certificate section: the certified exchange's and the certified worst-pose
search's bounds, shown when the design has them, checked against a dense grid of the planar 2R's
joint space (NumPy eigenvalues of ``Mechanism.sensitivity``), which no proven bound may be below."""

from __future__ import annotations

import numpy as np
import pytest

import tolsynth
from tolsynth.io.report_certificate import certificate_blocks
from tolsynth.io.reports import report
from tolsynth.kinematics.joint_space import _limits
from tolsynth.probability.stats import z_of_p
from tolsynth.synthesis.workspace import synthesize_workspace

R, P = 0.2, 0.99


def _grid_ratio(mech, eps, n=121):
    """Largest sigma z / R over an n x n grid of the two joints (uniform errors: variance eps^2 / 3)."""
    lo, hi = _limits(mech)
    t1, t2 = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
    A = np.stack([mech.sensitivity(q, check_limits=False)[:3] for q in np.stack([t1.ravel(), t2.ravel()], 1)])
    V = np.einsum("nij,j,nkj->nik", A, eps**2 / 3.0, A)
    return float(np.sqrt(np.linalg.eigvalsh(V)[:, -1].max())) * z_of_p(P) / R


@pytest.fixture(scope="module")
def design():
    mech = tolsynth.load_model("planar_2r")
    w = synthesize_workspace(mech, R, P, "uniform", 0.7, probability="gaussian", certify=True, progress=False)
    return mech, w


def _rows(blocks, head):
    for b in blocks:
        if b[0] == "table" and b[1][0] == head:
            return dict((r[0], r[1]) for r in b[2])
    raise AssertionError(f"no table {head!r}")


@pytest.mark.slow  # 5-20 s: the certified exchange and the certified search
def test_report_shows_the_certified_exchange_and_search(design):
    mech, w = design
    assert w.certified is True and w.upper_bound <= 1.001
    rep = report(w, mc_samples=0, map_n=0, certify=True)
    blocks = certificate_blocks(rep)
    assert blocks[0] == ("h", 3, "Certificate over the whole joint space")
    grid = _grid_ratio(mech, np.asarray(w.result.x))
    ws = _rows(blocks, "workspace design")
    shown = float(ws["max sigma z / R over the joint space, proven upper bound"])
    assert shown == pytest.approx(w.upper_bound, abs=1e-6)
    assert grid <= w.upper_bound and w.upper_bound - grid <= 2e-3  # sound, and tight to the exchange's tol
    assert ws["exchange"].startswith("converged")
    searches = [r for r in w.rounds if r["certified"] is not None]
    assert (
        ws["certified searches (boxes)"].startswith(f"{len(searches)} (")
        and str(searches[-1]["boxes"]) in ws["certified searches (boxes)"]
    )
    wc = _rows(blocks, "worst-pose search at these tolerances")
    assert wc["certified"] == "yes" and int(wc["boxes bounded"]) == rep.worst.certificate.boxes > 0
    ratio = float(wc["same, as sigma z / R"])
    assert grid <= ratio + 1e-6 and ratio - grid <= 1e-3
    md, _ = rep.to_markdown()
    assert "Certificate over the whole joint space" in md and "NOT proven" not in md


def test_no_certificate_section_without_a_certified_search():
    mech = tolsynth.load_model("planar_2r")
    w = synthesize_workspace(mech, R, P, "uniform", 0.7, probability="gaussian", progress=False)
    assert w.certified is None
    rep = report(w, mc_samples=0, map_n=0, worst_grid=0)
    assert certificate_blocks(rep) == [] and rep.workspace is w
    md, _ = rep.to_markdown()
    assert "Certificate over the whole joint space" not in md


@pytest.mark.slow  # 4-15 s: the default run stays under 4 minutes
def test_report_shows_the_design_margin_and_the_bound_at_R():
    """With a margin the report's certificate names it, with the cost and the lower bound at R; the
    design stays below R on a 121 x 121 grid (NumPy eigenvalues), as the margin leaves it."""
    mech = tolsynth.load_model("planar_2r")
    w = synthesize_workspace(
        mech,
        R,
        P,
        "uniform",
        0.7,
        probability="gaussian",
        certify=True,
        certify_options={"margin": 3e-3},
        progress=False,
    )
    assert w.certified and w.margin == 3e-3
    assert _grid_ratio(mech, np.asarray(w.result.x)) <= (1 + 1e-3) / (1 + 3e-3)
    rep = report(w, mc_samples=0, map_n=0, worst_grid=0)
    row = _rows(certificate_blocks(rep), "workspace design")[
        "design margin on R (the designs at R / (1 + margin), the proof at R)"
    ]
    assert row == f"0.003: cost {w.result.cost:.8g}, lower bound at R {w.lower_bound:.8g}"
    assert w.lower_bound < w.result.cost


@pytest.mark.slow  # 4-15 s: the default run stays under 4 minutes
def test_report_everywhere_certify_on_the_command_line(tmp_path, capsys):
    """``tolsynth report --everywhere --certify``: the certified exchange's design reported, its
    proven bound in the report and in the JSON, at or above the dense grid's largest sigma of the
    reported tolerances and within 1 + tol."""
    import json

    from tolsynth.cli import main

    out = tmp_path / "ws.md"
    argv = ["report", "--model", "planar_2r", "--R", str(R), "--p", str(P), "--probability", "gaussian"]
    argv += ["--everywhere", "--certify", "--mc-samples", "0", "--map-n", "0", "--worst-grid", "0"]
    assert main([*argv, "--out", str(out), "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert js["certified"] is True and js["converged"] is True
    eps = np.array(list(js["tolerances"].values()))
    assert _grid_ratio(tolsynth.load_model("planar_2r"), eps) <= js["upper_bound"] <= 1 + 1e-3
    assert f"| max sigma z / R over the joint space, proven upper bound | {js['upper_bound']:.6f} |" in out.read_text()


@pytest.mark.parametrize(
    ("extra", "says"),
    [
        (["--margin", "3e-3"], "--everywhere"),
        (["--max-rounds", "3"], "--everywhere"),
        (["--reference", "none"], "--everywhere"),
        (["--everywhere", "--workers", "2"], "--certify"),
        (["--everywhere", "--processes"], "--processes"),
    ],
    ids=["margin-alone", "max-rounds-alone", "reference-alone", "workers-without-certify", "processes-everywhere"],
)
def test_report_exchange_options_misused_exit_2_naming_them(tmp_path, extra, says, capsys):
    from tolsynth.cli import main

    argv = ["report", "--model", "planar_2r", "--R", str(R), "--p", str(P), "--out", str(tmp_path / "r.md")]
    try:
        rc = main([*argv, *extra])
    except SystemExit as exc:
        rc = exc.code
    err = capsys.readouterr().err
    assert rc == 2 and says in err and "Traceback" not in err
    assert not (tmp_path / "r.md").exists()


def test_report_everywhere_not_converged_exits_1_and_says_so(tmp_path, capsys):
    """One round cannot settle the planar 2R's exchange (its first pose is not the worst): exit status
    1 with one line on stderr, and the report written, saying the exchange did not converge."""
    from tolsynth.cli import main

    out = tmp_path / "ws.md"
    argv = ["report", "--model", "planar_2r", "--R", str(R), "--p", str(P), "--probability", "gaussian"]
    argv += ["--everywhere", "--certify", "--max-rounds", "1", "--mc-samples", "0", "--map-n", "0"]
    assert main([*argv, "--worst-grid", "0", "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no convergence over the workspace" in err[0]
    assert "| exchange | NOT converged, 1 round(s) |" in out.read_text()
