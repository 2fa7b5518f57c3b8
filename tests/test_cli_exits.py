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


def _sigint_default() -> None:
    """In the child: Ctrl-C's default disposition, as at a terminal (a shell's background job, or a
    CI runner, may start the test run with SIGINT ignored, which every child would inherit)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start(argv: list[str]) -> subprocess.Popen:
    """``tolsynth ARGV`` in a child that says 'ready' on stderr once the package is imported, so
    that the signal lands in the command's work, not in the interpreter's start-up."""
    code = (
        "import sys, tolsynth.cli\n"
        "print('ready', file=sys.stderr, flush=True)\n"
        f"sys.exit(tolsynth.cli.main({argv!r}))\n"
    )
    return subprocess.Popen(
        [sys.executable, "-c", code],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        preexec_fn=_sigint_default,
    )


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


@pytest.mark.parametrize(
    "argv",
    [
        ["map", "--model", "xu_zhang_1988", "--n", "400", "--quiet"],
        [
            "montecarlo",
            "--model",
            "xu_zhang_1988",
            "--tolerances",
            "figure3",
            "--R",
            "0.2",
            "--n",
            "1000000000",
            "--quiet",
        ],
    ],
    ids=["map", "montecarlo"],
)
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


@pytest.mark.parametrize(
    "out, fragment",
    [
        ("x.xyz", "unsupported figure format .xyz"),
        ("/nonexistent/dir/x.png", "does not exist"),
        ("noext", "unsupported figure format (no suffix)"),
    ],
)
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


# ---------------------------------------------------------------------------------------------
# no traceback ever: Ctrl-C wherever it lands, output files that cannot be written, any failure
# ---------------------------------------------------------------------------------------------
def _command_interrupted(argv: list[str], after: float) -> tuple[int | None, str]:
    """``python -m tolsynth ARGV`` as a user starts it, SIGINT after ``after`` s (maybe while the
    package is still being imported); (exit status, stderr), or (None, ...) if it ended first."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "tolsynth", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        preexec_fn=_sigint_default,
    )
    try:
        time.sleep(after)
        if proc.poll() is not None:
            return None, proc.communicate()[1]
        proc.send_signal(signal.SIGINT)
        sent = time.perf_counter()
        _, err = proc.communicate(timeout=60)
        if proc.returncode == 0 and time.perf_counter() - sent < 0.5:
            return None, err  # it was already exiting (the signal met its interpreter shutting down)
        return proc.returncode, err
    finally:
        if proc.poll() is None:  # pragma: no cover
            proc.kill()
            proc.communicate()


@pytest.mark.parametrize("after", [0.4, 1.0, 2.2, 3.0])
def test_ctrl_c_anywhere_in_reproduce_is_one_line(after):
    """During the import (the first second or so), inside IPOPT (CasADi turns the interrupt into
    a RuntimeError / SystemError in its callback and prints its own warning) and between solves:
    status 130 and one line, never a traceback."""
    rc, err = _command_interrupted(["reproduce", "--model", "xu_zhang_1988"], after)
    if rc is None:  # finished before the signal (a fast machine): nothing to check
        return
    lines = [line for line in err.splitlines() if line.strip()]
    assert rc == 130, err
    assert len(lines) == 1 and "interrupted (Ctrl-C)" in lines[0], err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err and "CasADi" not in err


@pytest.mark.long  # the default run interrupts reproduce at four of these times
def test_ctrl_c_many_times_in_reproduce():
    """Nine interrupts spread over a whole run, 0.6 s apart: all 130, one line.  They start at
    0.4 s, once the interpreter's own start-up is over (the first milliseconds, which the package
    cannot reach, are tests/test_cli_ctrl_c_start.py's)."""
    outcomes = []
    for after in [0.4 + 0.6 * i for i in range(9)]:
        rc, err = _command_interrupted(["reproduce", "--model", "xu_zhang_1988"], after)
        if rc is not None:
            lines = [line for line in err.splitlines() if line.strip()]
            outcomes.append((after, rc, len(lines), "Traceback" in err))
    assert outcomes and all(rc == 130 and n == 1 and not tb for _, rc, n, tb in outcomes), outcomes


LONG_NAME = "x" * 300


@pytest.mark.parametrize(
    "argv",
    [
        ["report", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--pose", "elbow90", "--out", ""],
        ["report", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--pose", "elbow90", "--out", "/proc/r.html"],
        [
            "report",
            "--model",
            "planar_2r",
            "--R",
            "0.5",
            "--p",
            "0.99",
            "--pose",
            "elbow90",
            "--out",
            LONG_NAME + ".html",
        ],
        ["report", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--pose", "elbow90", "--out", "r.pdf"],
        ["report", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--pose", "elbow90", "--out", "/dev/full"],
        ["sweep", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--workers", "1", "--out", ""],
        ["sweep", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--workers", "1", "--out", "/proc/s.csv"],
        ["sweep", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--workers", "1", "--out", LONG_NAME + ".csv"],
        ["map", "--model", "planar_2r", "--tolerances", "coarse", "--out", "/proc/f.png"],
        ["map", "--model", "planar_2r", "--tolerances", "coarse", "--out", ""],
        ["solve", "--model", "planar_2r", "--R", "0.5", "--p", "0.99", "--out", "/proc/t.json"],
    ],
    ids=lambda a: f"{a[0]} --out {a[-1][:20]!r}",
)
def test_bad_output_paths_are_one_line_before_any_work(argv, capsys, monkeypatch):
    """An output file that cannot be written is found before the work starts: status 2 and one
    line naming --out, never a traceback, and no solve runs."""
    import tolsynth.synthesis.single as single

    def no_work(*a, **k):  # pragma: no cover - reaching it is the failure
        raise AssertionError("work started before the output path was checked")

    monkeypatch.setattr(single, "synthesize", no_work)
    import tolsynth.cli.workspace as w

    monkeypatch.setattr(w, "probability_map", no_work)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--out" in err and "Traceback" not in err, err


def test_a_full_device_at_write_time_is_one_line(tmp_path):
    """/dev/full accepts the open and fails the write (no space): one line, status 2."""
    link = tmp_path / "full.csv"
    link.symlink_to("/dev/full")
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "tolsynth",
            "sweep",
            "--model",
            "planar_2r",
            "--R",
            "0.5",
            "--p",
            "0.99",
            "--workers",
            "1",
            "--quiet",
            "--out",
            str(link),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=ROOT,
    )
    assert out.returncode == 2, out.stderr
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "No space left on device" in lines[0] and "Traceback" not in out.stderr


def test_unexpected_failure_is_one_line(capsys, monkeypatch):
    """A bug (any exception that is not a typed error) is one line naming it, status 1; with
    TOLSYNTH_DEBUG set the traceback is shown for a bug report."""
    import tolsynth.cli.analyze as analyze

    def broken(args):
        return 1 / 0

    monkeypatch.setattr(analyze, "cmd_analyze", broken)  # register() reads it when main builds the parser
    argv = ["analyze", "--model", "planar_2r", "--tolerances", "coarse", "--R", "0.5"]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "internal error: ZeroDivisionError" in err and "TOLSYNTH_DEBUG" in err
    monkeypatch.setenv("TOLSYNTH_DEBUG", "1")
    with pytest.raises(ZeroDivisionError):
        main(argv)


def test_report_refuses_a_format_it_cannot_write(tmp_path):
    """``report --out x.pdf`` (or .docx, or no suffix) wrote HTML under that name: now refused
    before any work, naming the formats it writes; the API's DesignReport.write likewise."""
    for name in ("x.pdf", "x.docx", "noext"):
        out = subprocess.run(
            [
                sys.executable,
                "-m",
                "tolsynth",
                "report",
                "--model",
                "planar_2r",
                "--R",
                "0.5",
                "--p",
                "0.99",
                "--out",
                str(tmp_path / name),
            ],
            capture_output=True,
            text=True,
            timeout=120,
            cwd=ROOT,
        )
        assert out.returncode == 2 and ".html" in out.stderr and ".md" in out.stderr, out.stderr
        assert not (tmp_path / name).exists()
