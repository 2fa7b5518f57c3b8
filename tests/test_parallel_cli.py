"""The command line on the bundled parallel robots: ``solve`` and ``report`` for each, with the
Gaussian and the exact probabilities.  The tolerances ``solve`` prints are checked by NumPy from
the sensitivity matrix (every principal sigma z / R <= 1 for the Gaussian design) and by NumPy
Monte Carlo of the linear model (P >= p along each principal direction for the exact design)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import tolsynth
from tolsynth.cli import main
from tolsynth.probability.stats import z_of_p

MODELS = ["stewart_gough", "delta", "planar_3rrr"]


def _solve(capsys, name, probability, *extra, R="0.1", p="0.99"):
    args = ["solve", "--model", name, "--pose", "home", "--R", R, "--p", p]
    rc = main([*args, "--probability", probability, "--json", *extra])
    cap = capsys.readouterr()
    assert rc == 0, cap.err[-2000:]
    out = json.loads(cap.out)
    m = tolsynth.load_model(name)
    return m, out, np.array([out["tolerances"][n] for n in m.error_parameters])


@pytest.mark.parametrize("name", MODELS)
def test_solve_gaussian_meets_the_specification(capsys, name):
    m, out, eps = _solve(capsys, name, "gaussian")
    assert out["success"] and out["status"] == "optimal"
    A = m.sensitivity("home")[:3]
    sigma = np.sqrt(np.linalg.eigvalsh(A @ np.diag(eps**2 / 3) @ A.T).max())
    assert sigma * z_of_p(0.99) / 0.1 <= 1 + 1e-6


@pytest.mark.parametrize("name", MODELS)
def test_solve_exact_meets_p_along_the_principal_directions(capsys, name):
    # the hexapod's 42-error exact solve runs on IPOPT (the compiled interior point stops at its
    # iteration limit there).  R = 0.2 mm, p = 0.95: not the specification the API tests solve, as
    # an identical exact solve repeated in one process can fail (see test_parallel_models.py)
    extra = ["--solver", "ipopt"] if name == "stewart_gough" else []
    m, out, eps = _solve(capsys, name, "exact", *extra, R="0.2", p="0.95")
    assert out["success"] and out["status"] == "optimal", out["message"]
    A = m.sensitivity("home")[:3]
    w = np.random.default_rng(21).uniform(-1.0, 1.0, (200_000, m.n)) * eps @ A.T
    for v in np.linalg.eigh(A @ np.diag(eps**2 / 3) @ A.T)[1].T:
        if np.linalg.norm(A.T @ v) > 1e-12:
            assert np.mean(np.abs(w @ v) <= 0.2) >= 0.95 - 4 * np.sqrt(0.95 * 0.05 / 200_000)


@pytest.mark.parametrize(
    "name, plane",
    [pytest.param("stewart_gough", "xz", marks=pytest.mark.slow), ("delta", "xz"), ("planar_3rrr", "xy")],
)
def test_report_on_each_parallel_robot(tmp_path, capsys, name, plane):
    """A Markdown report: exit 0, the model's source cited, a workspace map, no NaN tolerance."""
    out = tmp_path / f"{name}.md"
    args = ["report", "--model", name, "--pose", "home", "--R", "0.1", "--p", "0.99", "--probability", "gaussian"]
    assert (
        main([*args, "--plane", plane, "--map-n", "9", "--mc-samples", "2000", "--out", str(out), "--format", "md"])
        == 0
    )
    text = out.read_text(encoding="utf-8")
    m = tolsynth.load_model(name)
    assert m.spec.source.split(",")[0].split("'")[0].strip()[:20] in text
    assert "left out" not in capsys.readouterr().out
    rows = [ln for ln in text.splitlines() if ln.startswith("| ") and any(f"| {n} |" in ln for n in m.error_parameters)]
    assert len(rows) >= m.n and not any("nan" in ln.lower() for ln in rows)
