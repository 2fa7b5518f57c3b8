"""The package layout: the library never imports its command line or matplotlib,
``python -m tolsynth`` runs the CLI (the layers themselves: test_architecture.py)."""

from __future__ import annotations

import pkgutil
import subprocess
import sys

import tolsynth


def _library_modules():
    return [
        m.name
        for m in pkgutil.walk_packages(tolsynth.__path__, "tolsynth.")
        if not (m.name == "tolsynth.cli" or m.name.startswith("tolsynth.cli.") or m.name == "tolsynth.__main__")
    ]


def test_library_never_imports_the_cli_or_matplotlib():
    mods = _library_modules()
    assert "tolsynth.analysis.montecarlo" in mods and "tolsynth.analysis.workspace_map" in mods
    code = (
        "import sys, importlib\n"
        f"for m in {mods!r}:\n"
        "    importlib.import_module(m)\n"
        "bad = sorted(k for k in sys.modules if k == 'tolsynth.cli' or k.startswith('tolsynth.cli.')"
        " or k.split('.')[0] == 'matplotlib')\n"
        "print(','.join(bad))\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "", f"library modules imported {run.stdout.strip()}"


def test_python_dash_m_runs_the_cli():
    run = subprocess.run([sys.executable, "-m", "tolsynth", "--help"], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    for cmd in ("analyze", "solve", "reproduce", "montecarlo", "map", "worst-pose"):
        assert cmd in run.stdout
