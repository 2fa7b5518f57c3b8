"""Honest exits of the command line: Ctrl-C stops a running command with status
130 and no traceback, a closed output pipe ends quietly (141), a command with nothing to do says so
and exits non-zero, output paths and the optional plotting dependency are checked before any work,
and messages quote the CLI's own values."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from tolsynth.cli import main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _start(argv: list[str]) -> subprocess.Popen:
    """``tolsynth ARGV`` in a child that says 'ready' on stderr once the package is imported, so
    that the signal lands in the command's work, not in the interpreter's start-up."""
    code = ("import sys, tolsynth.cli\n"
            "print('ready', file=sys.stderr, flush=True)\n"
            f"sys.exit(tolsynth.cli.main({argv!r}))\n")
    return subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=ROOT)


def _interrupt(argv: list[str], after: float = 1.0) -> tuple[int, str, float]:
    proc = _start(argv)
    try:
        assert proc.stderr.readline().strip() == "ready"
        time.sleep(after)
        assert proc.poll() is None, "the command finished before the signal; give it more work"
        t0 = time.perf_counter()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=30)
        return proc.returncode, err, time.perf_counter() - t0
    finally:
        if proc.poll() is None:  # pragma: no cover - only if the command ignored the signal
            proc.kill()
            proc.communicate()


@pytest.mark.parametrize("argv", [
    ["map", "--model", "xu_zhang_1988", "--n", "400", "--quiet"],
    ["montecarlo", "--model", "xu_zhang_1988", "--tolerances", "figure3", "--R", "0.2", "--n", "1000000000", "--quiet"],
], ids=["map", "montecarlo"])
def test_ctrl_c_exits_130_without_traceback(argv):
    rc, err, dt = _interrupt(argv)
    assert rc == 130, err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
    assert "interrupted" in err and "was not finished" in err
    assert dt < 5.0, f"{dt:.2f} s from SIGINT to exit"  # typically well under 1 s (see the report)


def test_closed_pipe_ends_quietly():
    proc = _start(["analyze", "--model", "xu_zhang_1988", "--tolerances", "figure3", "--R", "0.2", "--json"])
    assert proc.stderr.readline().strip() == "ready"
    proc.stdout.close()  # the reader goes away before the first line is written
    err = proc.stderr.read()
    proc.wait(timeout=60)
    assert proc.returncode == 141, err
    assert err == "", err


def test_reproduce_with_nothing_to_reproduce_says_so(capsys):
    assert main(["reproduce", "--model", "planar_2r"]) == 2
    cap = capsys.readouterr()
    assert cap.out == ""
    assert "planar_2r has no published results" in cap.err


@pytest.mark.parametrize("out, fragment", [
    ("x.xyz", "unsupported figure format .xyz"),
    ("/nonexistent/dir/x.png", "does not exist"),
    ("noext", "unsupported figure format (no suffix)"),
])
def test_map_output_path_checked_before_any_work(capsys, monkeypatch, out, fragment):
    import tolsynth.cli.workspace as w

    def no_work(*a, **k):  # pragma: no cover - reaching it is the failure
        raise AssertionError("the map was computed before the output path was checked")

    monkeypatch.setattr(w, "probability_map", no_work)
    assert main(["map", "--model", "xu_zhang_1988", "--out", out]) == 2
    err = capsys.readouterr().err
    assert err.startswith("tolsynth map: error: --out:") and fragment in err, err


def test_map_without_matplotlib_says_how_to_install(capsys, monkeypatch):
    import tolsynth.cli.workspace as w

    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib now raises ImportError
    monkeypatch.setitem(sys.modules, "matplotlib.backend_bases", None)
    monkeypatch.setattr(w, "probability_map", lambda *a, **k: (_ for _ in ()).throw(AssertionError("work done")))
    assert main(["map", "--model", "xu_zhang_1988", "--out", "fig.png"]) == 2
    err = capsys.readouterr().err
    assert "matplotlib" in err and 'pip install "tolsynth[plot]"' in err, err


def test_hand_axis_message_quotes_the_cli_value(capsys):
    assert main(["map", "--model", "xu_zhang_1988", "--hand-axis", "1,2"]) == 2
    err = capsys.readouterr().err
    assert "--hand-axis" in err and "'free'" in err and "None" not in err, err
