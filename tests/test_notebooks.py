"""Every notebook under ``notebooks/`` runs from a fresh kernel without an error.

The notebooks are stored as jupytext ``py:percent`` text (no outputs); each is converted to an
nbformat notebook as the docs build reads it and executed by nbclient with ``notebooks/`` as the
working directory and the inline matplotlib backend (figures become outputs, as on the docs'
pages).  A notebook that is not run rots: a broken one fails the suite.  A notebook that ran
cleanly is stored, outputs and all, in the docs build's notebook cache
(``docs/_ext.py:notebook_cache_dir``, keyed by the notebook's code and the package's source), so
that the docs build shows it without executing it again.
"""

from __future__ import annotations

import copy
import importlib.util
import time
from pathlib import Path

import pytest

jupytext = pytest.importorskip("jupytext")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOK_DIR = ROOT / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("[0-9][0-9]_*.py"))


def test_notebooks_found():
    assert {"01", "02", "03", "04", "07", "09"} <= {p.name[:2] for p in NOTEBOOKS}


#: every notebook runs with the slow tests: together they take minutes, more than the default run's
#: budget, and CI's slow step executes each once and keeps its outputs for the docs build
@pytest.mark.parametrize(
    "path", [pytest.param(p, marks=pytest.mark.slow) for p in NOTEBOOKS], ids=[p.stem for p in NOTEBOOKS]
)
def test_notebook_executes(path, monkeypatch):
    # the kernel inherits this process's environment: figures as inline outputs (the docs' pages
    # show them), and plain-text progress bars
    monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
    source = jupytext.reads(path.read_text(encoding="utf-8"), fmt="py:percent")  # as the docs build reads it
    nb = copy.deepcopy(source)
    assert not any(c.get("outputs") for c in nb.cells if c.cell_type == "code"), "outputs must not be stored"
    client = nbclient.NotebookClient(
        nb,
        timeout=600,
        kernel_name="python3",
        record_timing=False,  # no timestamps in the cells' metadata, which the cache key reads
        resources={"metadata": {"path": str(NOTEBOOK_DIR)}},
    )
    t0 = time.perf_counter()
    client.execute()  # raises CellExecutionError, naming the cell, on any error
    elapsed = time.perf_counter() - t0
    print(f"{path.name}: executed in {elapsed:.1f} s")
    errors = [
        out
        for cell in nb.cells
        if cell.cell_type == "code"
        for out in cell.get("outputs", [])
        if out.get("output_type") == "error"
    ]
    assert not errors
    _keep_for_the_docs(path, source, nb)


def _keep_for_the_docs(path, source, executed):
    """Store the executed notebook where the docs build looks for it (needs jupyter-cache, in the
    test and docs extras); the stored copy must be found again from the unexecuted source."""
    try:
        from jupyter_cache import get_cache
        from jupyter_cache.base import CacheBundleIn
    except ImportError:
        return
    spec = importlib.util.spec_from_file_location("docs_ext", ROOT / "docs" / "_ext.py")
    ext = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(ext)
    cache = get_cache(str(ext.notebook_cache_dir()))
    cache.cache_notebook_bundle(
        CacheBundleIn(executed, str(ROOT / "docs" / "notebooks" / path.name)), check_validity=False, overwrite=True
    )
    assert cache.match_cache_notebook(source) is not None
