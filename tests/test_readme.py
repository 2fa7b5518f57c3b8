"""The README's promises: its quickstart runs and says true things, and CI runs its test command."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import tolsynth

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()


def code_blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README, flags=re.S)


def test_quickstart_runs_and_its_numbers_hold(capsys):
    blocks = code_blocks("python")
    assert len(blocks) == 4 and "import tolsynth" in blocks[0]
    namespace: dict = {}
    for block in blocks:  # in order, in one namespace, as a reader would
        if "load_urdf" in block:  # needs the test extra's URDFs: tests/test_urdf.py runs it
            continue
        exec(compile(block, "README.md", "exec"), namespace)
    # what the comments claim, checked against numbers not taken from the block itself
    m, res = namespace["m"], namespace["res"]
    np.testing.assert_allclose(m.fk("worst")[:3, 3], [925.0, 0.0, 1225.0], atol=0.01)
    assert namespace["S"].shape == (6, 11)
    assert res.gap <= 1e-8 * res.cost
    assert sum(int(b.active.sum()) for b in res.constraints) == 2
    # beyond the paper: the workspace optimum costs more and is met everywhere the search looked
    ws, mc, w = namespace["ws"], namespace["mc"], namespace["w"]
    assert ws.converged and ws.rounds[0]["worst_value"] > 1.1 and ws.result.cost > res.cost
    # the README says: Monte Carlo 0.1997, Gaussian 0.2692 (independent: stats.p_ball on S)
    from tolsynth.probability.stats import covariance, p_ball, principal

    sig, _ = principal(covariance(m.sensitivity("worst"), m.tolerances("figure3"), "uniform")[0])
    assert mc.p_sphere_analytic == pytest.approx(p_ball(sig**2, 0.2), rel=1e-9)
    assert abs(mc.p_sphere - 0.1997) < 4 * (0.2 * 0.8 / mc.n) ** 0.5  # 2e6-sample value in the README
    assert w.value > w.reference_value  # the paper's pose is not the worst for figure3


def test_from_dh_block_says_true_things():
    """The "Your robot from a D-H table" block: its hand point against a plain-NumPy D-H chain of
    Universal Robots' table, and its optimum meets the specification at that pose, computed with
    the sensitivities of the bundled ur5 file (not the block's mechanism)."""
    (block,) = [b for b in code_blocks("python") if "from_dh" in b]
    namespace: dict = {}
    exec(compile(block, "README.md", "exec"), namespace)
    ur5, res = namespace["ur5"], namespace["res_ur5"]
    import math

    a, d = [0, -425.0, -392.25, 0, 0, 0], [89.159, 0, 0, 109.15, 94.65, 82.3]
    alpha = np.radians([90, 0, 0, 90, -90, 0])
    T = np.eye(4)
    for q, ai, di, al in zip(np.radians([0, 0, 0, -90, 0, 0]), a, d, alpha):
        ct, st, ca, sa = math.cos(q), math.sin(q), math.cos(al), math.sin(al)
        T = T @ np.array([[ct, -st * ca, st * sa, ai * ct], [st, ct * ca, -ct * sa, ai * st],
                          [0, sa, ca, di], [0, 0, 0, 1]])
    np.testing.assert_allclose(T[:3, 3], [-911.9, -191.45, 89.159], atol=1e-9)  # the comment
    np.testing.assert_allclose(ur5.fk("stretched"), T, atol=1e-9)
    from tolsynth.probability.stats import covariance, principal

    ref = tolsynth.load_model("ur5")
    S = ref.sensitivity("worst")[:, [ref.index(n) for n in ur5.error_parameters]]
    sig, _ = principal(covariance(S, res.x, "uniform")[0])
    assert res.success and max(sig) * tolsynth.z_of_p(0.99) / 0.5 == pytest.approx(1.0, abs=1e-6)
    assert round(res.cost, 2) == 44.6 and len(ur5.error_parameters) == 14


def test_ci_runs_the_readme_test_command():
    bash = code_blocks("bash")
    test_cmd = [line for b in bash for line in b.splitlines() if "pytest" in line and not line.startswith("#")]
    assert len(test_cmd) == 1
    ci = (ROOT / ".ci" / "run").read_text()
    assert test_cmd[0].strip() in ci


def test_main_job_command_is_reproduce():
    bash = code_blocks("bash")
    main = [line for b in bash for line in b.splitlines() if "tolsynth reproduce" in line]
    assert main and main[0].startswith("python3 -m venv .venv")
