"""Every notebook under ``notebooks/`` runs from a fresh kernel without an error.

The notebooks are stored as jupytext ``py:percent`` text (no outputs); each is converted to an
nbformat notebook and executed by nbclient with ``notebooks/`` as the working directory and the
Agg matplotlib backend.  A notebook that is not run rots: a broken one fails the suite.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest

jupytext = pytest.importorskip("jupytext")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

NOTEBOOK_DIR = Path(__file__).resolve().parent.parent / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("[0-9][0-9]_*.py"))


def test_notebooks_found():
    assert {"01", "02", "03", "04", "07", "09"} <= {p.name[:2] for p in NOTEBOOKS}


#: notebooks of several minutes run with the slow tests (CI runs them, and the docs build executes them)
SLOW = {"11_exact_probability"}


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.stem in SLOW else p for p in NOTEBOOKS],
                         ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes(path, monkeypatch):
    # the kernel inherits this process's environment: no display, and plain-text progress bars
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = jupytext.read(path)
    assert not any(c.get("outputs") for c in nb.cells if c.cell_type == "code"), "outputs must not be stored"
    client = nbclient.NotebookClient(
        nb,
        timeout=600,
        kernel_name="python3",
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
