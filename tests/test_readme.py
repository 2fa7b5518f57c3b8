"""The README's promises: its quickstart runs and says true things, and CI runs its test command."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()


def code_blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README, flags=re.S)


def test_quickstart_runs_and_its_numbers_hold(capsys):
    (block,) = [b for b in code_blocks("python") if "import tolsynth" in b]
    namespace: dict = {}
    exec(compile(block, "README.md", "exec"), namespace)
    # what the comments claim, checked against numbers not taken from the block itself
    m, res = namespace["m"], namespace["res"]
    np.testing.assert_allclose(m.fk("worst")[:3, 3], [925.0, 0.0, 1225.0], atol=0.01)
    assert namespace["S"].shape == (6, 11)
    assert res.gap <= 1e-8 * res.cost
    assert sum(int(b.active.sum()) for b in res.constraints) == 2


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
