"""Packaging: a NON-editable install finds the bundled model files (shipped as package data).

Slow (a fresh virtual environment and two builds, ~10-20 s); CI runs it with ``--runslow``.
Offline: the fresh environment reuses the running environment's packages (casadi, numpy,
setuptools, wheel, pip) through a ``.pth`` file, and pip runs with ``--no-index --no-deps
--no-build-isolation``.  The source tree is copied first, so that the in-tree build leaves no
``build/`` or ``*.egg-info`` behind in the checkout.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

import tolsynth
from test_kinematics import planar_fk, puma_fk, xu_fk

ROOT = Path(__file__).resolve().parent.parent
MODELS = tuple(tolsynth.bundled_models())

pytestmark = pytest.mark.slow


def _run(cmd, cwd, timeout=600):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP")}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    run = subprocess.run([str(c) for c in cmd], cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env)
    assert run.returncode == 0, f"{cmd}\n--- stdout\n{run.stdout}\n--- stderr\n{run.stderr}"
    return run


def _require_build_tools():
    """--no-build-isolation builds with the setuptools and wheel of this environment (the test
    extra of pyproject.toml lists them)."""
    try:
        import setuptools
        import wheel  # noqa: F401
    except ImportError as exc:  # pragma: no cover - a setup error, reported as such
        pytest.fail(f"{exc}: install the test extra (pip install -e '.[test]'), it provides setuptools and wheel")
    major = int(setuptools.__version__.split(".")[0])
    assert major >= 68, f"setuptools {setuptools.__version__} < 68 (pyproject.toml's build requirement)"


@pytest.fixture(scope="module")
def source_copy(tmp_path_factory):
    dest = tmp_path_factory.mktemp("src") / "tolsynth-src"
    shutil.copytree(
        ROOT,
        dest,
        ignore=shutil.ignore_patterns(
            ".git", ".venv", "venv", "build", "dist", "*.egg-info", "__pycache__", ".pytest_cache", ".ipynb_checkpoints"
        ),
    )
    return dest


@pytest.fixture(scope="module")
def fresh_venv(tmp_path_factory, source_copy):
    """python -m venv --system-site-packages, this environment's packages visible through a .pth
    (its site-packages as plain path entries: its own .pth files, among them an editable
    install's finder, are not executed), then a non-editable install of the source copy."""
    _require_build_tools()
    venv = tmp_path_factory.mktemp("venv") / "env"
    _run([sys.executable, "-m", "venv", "--system-site-packages", "--without-pip", venv], cwd=venv.parent)
    py = venv / ("Scripts/python.exe" if sys.platform == "win32" else "bin/python")
    site = Path(_run([py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], cwd=venv).stdout.strip())
    here = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (site / "_tolsynth_test_parent_env.pth").write_text("\n".join(sorted(here)) + "\n")
    _run([py, "-m", "pip", "install", "--no-index", "--no-deps", "--no-build-isolation", source_copy], cwd=venv.parent)
    return venv, py, site


def test_non_editable_install_finds_the_models(fresh_venv, tmp_path):
    venv, py, site = fresh_venv
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    script = (
        "import json, tolsynth\n"
        "from importlib import resources\n"
        "out = {'file': tolsynth.__file__, 'bundled': tolsynth.bundled_models(),\n"
        "       'models_dir': str(resources.files('tolsynth.models')), 'fk': {}}\n"
        "for name, pose in [('xu_zhang_1988', 'worst'), ('puma560', 'qz'), ('planar_2r', 'elbow90')]:\n"
        "    m = tolsynth.load_model(name)\n"
        "    out['fk'][name] = [m.fk(pose).tolist(), m.configurations[pose].tolist()]\n"
        "print(json.dumps(out))\n"
    )
    out = json.loads(_run([py, "-c", script], cwd=elsewhere).stdout)
    # the installed copy, not the checkout or an editable finder
    assert Path(out["file"]).resolve().is_relative_to(site.resolve()), out["file"]
    models_dir = Path(out["models_dir"]).resolve()
    assert models_dir == (site / "tolsynth" / "models").resolve()
    for name in MODELS:
        assert name in out["bundled"]
        assert (models_dir / f"{name}.toml").is_file()
    # and the poses are right (the hand-written NumPy chains)
    import numpy as np

    for name, fk_np in (("xu_zhang_1988", xu_fk), ("puma560", puma_fk), ("planar_2r", planar_fk)):
        T, q = out["fk"][name]
        assert np.max(np.abs(np.array(T) - fk_np(np.array(q)))) < 1e-9, name
    assert np.allclose(np.array(out["fk"]["xu_zhang_1988"][0])[:3, 3], [925, 0, 1225], atol=0.01)


def test_installed_console_script(fresh_venv, tmp_path):
    venv, py, site = fresh_venv
    exe = py.parent / ("tolsynth.exe" if sys.platform == "win32" else "tolsynth")
    run = _run(
        [exe, "analyze", "--model", "puma560", "--pose", "qz", "--tolerances", "fine", "--R", "0.1", "--json"],
        cwd=tmp_path,
    )
    out = json.loads(run.stdout)
    assert abs(out["position"][0] - 452.1) < 1e-9 and abs(out["position"][2] - (26.45 * 25.4 + 431.8)) < 1e-9


def test_wheel_contains_the_model_files(source_copy, tmp_path):
    _require_build_tools()
    wheels = tmp_path / "wheels"
    _run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-index",
            "--no-deps",
            "--no-build-isolation",
            "-w",
            wheels,
            source_copy,
        ],
        cwd=tmp_path,
    )
    (whl,) = wheels.glob("tolsynth-*.whl")
    names = set(zipfile.ZipFile(whl).namelist())
    for name in MODELS:
        assert f"tolsynth/models/{name}.toml" in names, sorted(names)
    assert "tolsynth/models/__init__.py" in names
    assert not any(n.startswith(("models/", "tests/")) for n in names), "top-level folders leaked into the wheel"
    ep = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
    assert "tolsynth = tolsynth.cli:main" in zipfile.ZipFile(whl).read(ep).decode()
