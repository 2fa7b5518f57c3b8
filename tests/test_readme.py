"""The README's promises: its example runs and its comments hold against independent computations,
CI runs its test command, and it stays short, with a delimited speed section and working links."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from independent import fft_probabilities, fibonacci_directions

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text(encoding="utf-8")

# the paper's cost factors (its section 5): 1 for the eight lengths, 1.5 for the three angles
PAPER_K = np.array([1.0] * 8 + [1.5] * 3)


def code_blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README, flags=re.S)


def clarabel_optimum(S, R, p, alpha, k):
    """Table 1's problem in its convex form in v = eps^2, solved by cvxpy + Clarabel: minimise
    sum k v^(-alpha/2) subject to (R/z)^2 I - sum v_i a_i a_i^T / 3 >= 0 (uniform errors), with z
    the two-sided normal quantile from SciPy. Shares nothing with tolsynth's NLP but the
    sensitivities."""
    cp = pytest.importorskip("cvxpy")
    from scipy.stats import norm

    z = norm.ppf((1 + p) / 2)
    A = S[:3]
    v = cp.Variable(A.shape[1])
    lmi = (R / z) ** 2 * np.eye(3) - sum(v[i] * np.outer(A[:, i], A[:, i]) / 3 for i in range(A.shape[1]))
    cost = sum(k[i] * cp.power(v[i], -alpha / 2, approx=False) for i in range(A.shape[1]))
    prob = cp.Problem(cp.Minimize(cost), [(lmi + lmi.T) / 2 >> 0])
    prob.solve(solver="CLARABEL")
    assert prob.status == "optimal"
    return prob.value, np.sqrt(v.value), z


def test_example_runs_and_its_comments_hold():
    (block,) = code_blocks("python")
    namespace: dict = {}
    exec(compile(block, "README.md", "exec"), namespace)
    m, res, g, c = namespace["m"], namespace["res"], namespace["g"], namespace["c"]
    # the hand at the paper's printed worst-pose point
    np.testing.assert_allclose(m.fk("worst")[:3, 3], [925.0, 0.0, 1225.0], atol=0.01)
    # the paper's criterion against an independent conic solver on the same sensitivities, the paper's k
    assert np.allclose(m.k, PAPER_K)
    ref_cost, ref_eps, z = clarabel_optimum(m.sensitivity("worst"), 0.5, 0.99, 0.7, PAPER_K)
    assert g.success and g.cost == pytest.approx(ref_cost, rel=1e-6)
    assert round(g.cost, 4) == 84.4189  # the comment
    assert g.gap < 1e-6 and g.lower_bound <= ref_cost * (1 + 1e-7)
    np.testing.assert_allclose(g.x, ref_eps, rtol=1e-3)
    A = m.sensitivity("worst")[:3]
    V = (A * g.x**2) @ A.T / 3  # principal sigma by NumPy's eigensolver, times z / R
    assert np.sqrt(np.linalg.eigvalsh(V).max()) * z / 0.5 == pytest.approx(1.0, abs=1e-7)
    # the default design: exact probabilities, certified
    assert res.success and res.probability_kind == "exact" and g.probability_kind == "gaussian"
    assert round(res.cost, 3) == 82.974 and res.cost < g.cost  # the comments
    assert round(1 - res.cost / g.cost, 3) == 0.017
    assert res.gap < 1e-6 * res.cost and res.lower_bound <= res.cost
    assert round(res.tolerances["h2"], 4) == 0.0419 and round(res.tolerances["alpha1"], 4) == 0.0270
    # every direction meets p, by FFT convolution of the uniform densities along 1000 directions,
    # and some direction is close to p (the design is not over-built)
    probs = fft_probabilities((fibonacci_directions(1000) @ A) * res.x, 0.5)
    assert 0.99 - 5e-5 <= probs.min() <= 0.99 + 1e-3
    # SUMT + Powell, a different algorithm on the same graphs, agrees as the comment says
    assert c.cost_rel_diff < 1e-8


def test_ci_runs_the_readme_test_command():
    bash = code_blocks("bash")
    test_cmd = [line for b in bash for line in b.splitlines() if "pytest" in line and not line.startswith("#")]
    assert len(test_cmd) == 1
    ci = (ROOT / ".ci" / "run").read_text()
    assert test_cmd[0].strip() in ci.splitlines()


def test_main_job_command_is_reproduce():
    bash = code_blocks("bash")
    main = [line for b in bash for line in b.splitlines() if "tolsynth reproduce" in line]
    assert main and main[0].startswith("python3 -m venv .venv")


def test_readme_is_short_and_its_links_resolve():
    assert len(README.splitlines()) <= 350
    # the speed section is one delimited block that the benchmark's table can replace whole
    speed = README.split("## Speed\n", 1)[1].split("\n## ", 1)[0]
    assert speed.count("<!-- speed table start -->") == 1 and speed.count("<!-- speed table end -->") == 1
    assert "benchmarks/speed_table.py" in speed
    links = re.findall(r"\]\(([^)#:]+)\)", README)
    assert links and all((ROOT / link).exists() for link in links), [x for x in links if not (ROOT / x).exists()]
