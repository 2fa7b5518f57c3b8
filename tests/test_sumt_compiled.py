"""SUMT's compiled Powell (tolsynth.solvers.cpowell) against the Python Powell and against IPOPT.

The paper's 18 columns (IPOPT vs SUMT to 1e-6 in cost) are in tests/test_synthesis.py and run the
compiled path wherever a C compiler is found; here: the Python fallback still agrees with IPOPT
(no compiler, or compilation turned off), the two Powell implementations find the same minimiser
of the same penalty, and the on-disk cache is used.
"""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

import tolsynth
from tolsynth import cbuild, synthesize
from tolsynth.solvers import cpowell
from tolsynth.solvers.powell import powell

needs_cc = pytest.mark.skipif(cbuild.find_compiler() is None, reason="no C compiler")


@pytest.mark.parametrize("env", [{"TOLSYNTH_NO_COMPILE": "1"}, {"TOLSYNTH_CC": "no-such-compiler-here"}])
def test_python_fallback_agrees_with_ipopt(monkeypatch, env):
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    mech = tolsynth.load_model("planar_2r")
    ip = synthesize(mech, 0.1, 0.9, solver="ipopt", probability="gaussian")
    su = synthesize(mech, 0.1, 0.9, solver="sumt", probability="gaussian")
    assert cpowell.backend_status()["backend"] == "python"
    assert cpowell.backend_status()["reason"]
    assert su.success and ip.success
    assert abs(su.cost - ip.cost) / ip.cost < 1e-6


@needs_cc
def test_compiled_and_python_powell_find_the_same_minimiser():
    """One SUMT inner problem of the paper's robot (r fixed): the C port and the Python Powell from
    the same start reach the same minimiser; the penalty is checked at the C minimiser through
    CasADi's own evaluator (not the compiled code)."""
    from tolsynth.problem.nlp import ToleranceNLP
    from tolsynth.problem.specification import make_specification
    from tolsynth.solvers.sumt import penalty_graph

    mech = tolsynth.load_model("xu_zhang_1988")
    nlp = ToleranceNLP(make_specification(mech, 0.5, 0.99))
    F = penalty_graph(nlp.spec.n, 1, 0, 0, nlp.costs.signature)
    values = [
        nlp.P,
        nlp.theta,
        nlp.lu,
        nlp.uu,
        np.array([2.0]),
        np.array([1.0]),
        np.array([0.01]),
        np.zeros(0),
        np.zeros(0),
    ]
    u0 = np.log(nlp.interior_start())
    comp = cpowell.compile_powell(F)
    assert comp is not None
    rc = comp.minimize(values, u0, ftol=1e-13)
    rp = powell(lambda z: float(F(z, *values)[0]), u0, ftol=1e-13)
    assert rc.converged and rp.converged
    assert float(F(rc.x, *values)[0]) == pytest.approx(rc.fun, rel=1e-14)
    assert rc.fun == pytest.approx(rp.fun, rel=1e-11)
    np.testing.assert_allclose(rc.x, rp.x, atol=1e-4)
    assert rc.history[0] == pytest.approx(rp.history[0], rel=1e-14) and len(rc.history) == rc.nit + 1


@needs_cc
def test_library_is_cached_on_disk(tmp_path, monkeypatch):
    """First use compiles into the cache directory; a fresh process (here: emptied in-process
    tables) loads the same file without compiling again; the result is unchanged."""
    monkeypatch.setenv("TOLSYNTH_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(cbuild, "_loaded", {})
    monkeypatch.setattr(cpowell._LIBS, "_by_function", {})
    mech = tolsynth.load_model("planar_2r")
    first = synthesize(mech, 0.1, 0.9, solver="sumt", probability="gaussian")
    assert cpowell.backend_status()["backend"] == "compiled"
    ipopt = synthesize(mech, 0.1, 0.9, solver="ipopt", probability="gaussian")
    assert abs(first.cost - ipopt.cost) <= 1e-6 * ipopt.cost
    files = list(tmp_path.iterdir())
    assert len(files) == 1 and files[0].suffix == ".so"  # no temporaries left
    stamp = files[0].stat().st_mtime_ns
    monkeypatch.setattr(cbuild, "_loaded", {})
    monkeypatch.setattr(cpowell._LIBS, "_by_function", {})
    again = synthesize(mech, 0.1, 0.9, solver="sumt", probability="gaussian")
    assert list(tmp_path.iterdir()) == files and files[0].stat().st_mtime_ns == stamp
    assert again.cost == first.cost
    # a damaged file in the cache is built again (in a new process: this one has the library
    # loaded, and dlopen hands back the loaded one by its path)
    (tmp_path / "damaged").write_bytes(b"not a library")
    (tmp_path / "damaged").replace(files[0])  # a new file: the loaded one stays mapped
    code = (
        "import tolsynth; from tolsynth.solvers import cpowell; "
        "r = tolsynth.synthesize('planar_2r', 0.1, 0.9, solver='sumt', probability='gaussian'); "
        "print(cpowell.backend_status()['backend'], repr(r.cost))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "TOLSYNTH_CACHE_DIR": str(tmp_path)},
    ).stdout.split()
    assert out[0] == "compiled" and float(out[1]) == pytest.approx(first.cost, rel=1e-12)
    assert files[0].stat().st_size > 1000


def test_huge_iteration_limit_is_accepted():
    """maxiter may be as large as the options allow (1e9): the history buffer is bounded."""
    mech = tolsynth.load_model("planar_2r")
    ref = synthesize(mech, 0.1, 0.9, solver="ipopt", probability="gaussian")
    su = synthesize(mech, 0.1, 0.9, solver="sumt", options={"maxiter": 10**9, "maxfev": 10**9}, probability="gaussian")
    assert su.success and abs(su.cost - ref.cost) <= 1e-6 * ref.cost
    assert all(len(h["inner_history"]) == h["inner_iterations"] + 1 for h in su.history)
