"""Ctrl-C on the command line: one line on stderr and exit status 130, wherever it lands.

Two places need help beyond Python's own ``KeyboardInterrupt``:

* while the package is still being imported (about 1.5 s: NumPy, CasADi), before the command
  line's ``main`` runs: :func:`guard_start`, called first thing by ``tolsynth/__init__.py``, makes
  a Ctrl-C there end the process with one line, but only when the process was started as the
  ``tolsynth`` command (``tolsynth ...`` or ``python -m tolsynth ...``); a library user's
  interpreter keeps Python's own behaviour.  This module imports nothing but ``os``, ``sys`` and
  the C module ``_signal`` (``os`` is loaded by the interpreter's start-up already), so that the
  handler is in place before any other module loads;
* inside a CasADi call (an IPOPT callback, a compiled function), where the ``KeyboardInterrupt``
  raised by the signal handler comes back wrapped as a ``RuntimeError`` or ``SystemError``:
  :mod:`tolsynth.cli.interrupts` records that the signal arrived, so the command line can tell an
  interrupt from a failure whatever exception it turned into.

What Python does before the package's first line runs is the interpreter's own: a Ctrl-C in its
first milliseconds (before it has installed its handler) ends the process by the signal, silently
(a shell reports status 130); one while it loads its ``site`` module (the site-packages' ``.pth``
files; an editable install's import finder loads ``pathlib`` there) makes it print its own fatal
error.  No code of a package runs before that.
"""

import _signal
import os
import sys

__all__ = ["EXIT_INTERRUPTED", "started_as_command", "worker_of_a_pool", "guard_start", "restore_default"]

EXIT_INTERRUPTED = 130


def started_as_command(argv=None, orig_argv=None) -> bool:
    """True if this process is the ``tolsynth`` command: its script is named tolsynth, or it was
    started as ``python -m tolsynth``."""
    argv = sys.argv if argv is None else argv
    orig = getattr(sys, "orig_argv", []) if orig_argv is None else orig_argv
    if argv and os.path.basename(str(argv[0])).split(".")[0] == "tolsynth":
        return True
    for i, item in enumerate(orig[:-1]):
        if item == "-m":
            return orig[i + 1] in ("tolsynth", "tolsynth.cli", "tolsynth.__main__")
    return False


def worker_of_a_pool(orig_argv=None) -> bool:
    """True in a worker process that :mod:`multiprocessing` started (spawn or forkserver: the
    interpreter was started with ``-c 'from multiprocessing...'``).  Such a process copies its
    parent's ``sys.argv``, so it looks like the ``tolsynth`` command, but a Ctrl-C there is its
    parent's to report."""
    orig = getattr(sys, "orig_argv", []) if orig_argv is None else orig_argv
    return any(a == "-c" and str(b).startswith("from multiprocessing") for a, b in zip(orig, orig[1:]))


def _interrupted_while_starting(signum, frame):  # pragma: no cover - runs in a child process (tested there)
    try:
        lead = b"\n" if os.isatty(2) else b""  # a fresh line after the terminal's ^C; none in a log
        os.write(2, lead + b"tolsynth: interrupted (Ctrl-C) while starting; nothing was done.\n")
    finally:
        os._exit(EXIT_INTERRUPTED)


def guard_start() -> None:
    """For the ``tolsynth`` command only: a Ctrl-C before ``main`` takes over ends the process with
    one line and status 130 (instead of a traceback from inside an import)."""
    if not started_as_command():
        return
    try:  # outside the main thread signal() raises ValueError: nothing to guard there
        if _signal.getsignal(_signal.SIGINT) is _signal.default_int_handler:
            # a pool's worker: the Ctrl-C reaches the whole process group and the parent reports
            # it (and ends the workers), so the worker stays silent, as it does once started
            ignore = worker_of_a_pool()
            _signal.signal(_signal.SIGINT, _signal.SIG_IGN if ignore else _interrupted_while_starting)
    except (ValueError, OSError):  # pragma: no cover - no signals here
        pass


def restore_default(handler):
    """The handler to put back when a block that replaced ``handler`` ends: the start-up guard is
    replaced by Python's own (the package is loaded by then), any other handler kept as it was."""
    return _signal.default_int_handler if handler is _interrupted_while_starting else handler
