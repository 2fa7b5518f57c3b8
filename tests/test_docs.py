"""The documentation: every public name has an API entry, every notebook is
linked into the docs, and (slow) the Sphinx build passes with warnings as errors.  CI runs the full
build with the notebooks executed (.ci/run); the slow test here builds without executing them, to
check the docstrings, the generated pages and the configuration in about 15 s."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

import tolsynth

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def test_every_public_name_is_in_the_api_reference():
    text = (DOCS / "api.rst").read_text(encoding="utf-8")
    listed = set(re.findall(r"^\s{3}(\w+)\s*$", text, flags=re.M))
    missing = sorted(set(tolsynth.__all__) - listed)
    assert not missing, f"add to docs/api.rst: {missing}"


def test_every_notebook_is_linked_into_the_docs():
    notebooks = {p.name for p in (ROOT / "notebooks").glob("[0-9][0-9]_*.py")}
    linked = {p.name for p in (DOCS / "notebooks").glob("*.py")}
    assert notebooks == linked, f"ln -s ../../notebooks/NAME docs/notebooks/ for {sorted(notebooks - linked)}"
    for p in (DOCS / "notebooks").glob("*.py"):
        assert p.is_symlink() and p.resolve() == (ROOT / "notebooks" / p.name).resolve()


def test_ci_builds_the_docs_with_warnings_as_errors():
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert 'pip install -e ".[docs]"' in ci
    assert "sphinx-build -W --keep-going -b html docs docs/_build/html" in ci


@pytest.mark.slow
def test_sphinx_build_without_executing_the_notebooks(tmp_path):
    pytest.importorskip("sphinx")
    pytest.importorskip("numpydoc")
    pytest.importorskip("myst_nb")
    pytest.importorskip("pydata_sphinx_theme")
    out = tmp_path / "html"
    run = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-b", "html",
                          "-D", "nb_execution_mode=off", "-d", str(tmp_path / "doctrees"), str(DOCS), str(out)],
                         capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert run.returncode == 0, run.stderr[-4000:]
    api = (out / "generated" / "tolsynth.SynthesisResult.html").read_text(encoding="utf-8")
    assert "summary" in api and "to_frame" in api  # own and inherited (Tabular) methods
    cli = (out / "cli.html").read_text(encoding="utf-8")
    assert "tolsynth report" in cli and "--mc-samples" in cli
    fmt = (out / "model_format.html").read_text(encoding="utf-8")
    assert "error_parameters" in fmt and "joint_errors" in fmt
    assert (out / "notebooks" / "01_reproduce_paper.html").exists()
