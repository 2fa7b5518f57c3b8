"""Ctrl-C on the command line: one line on stderr and exit status 130, wherever it lands.

Two places need help beyond Python's own ``KeyboardInterrupt``:

* while the package is still being imported (about 1.5 s: NumPy, CasADi), before the command
  line's ``main`` runs: :func:`guard_start`, called first thing by ``tolsynth/__init__.py``, makes
  a Ctrl-C there end the process with one line, but only when the process was started as the
  ``tolsynth`` command (``tolsynth ...`` or ``python -m tolsynth ...``); a library user's
  interpreter keeps Python's own behaviour;
* inside a CasADi call (an IPOPT callback, a compiled function), where the ``KeyboardInterrupt``
  raised by the signal handler comes back wrapped as a ``RuntimeError`` or ``SystemError``:
  :class:`Interrupts` records that the signal arrived, so the command line can tell an interrupt
  from a failure whatever exception it turned into.
"""

from __future__ import annotations

import os
import re
import signal
import sys
import threading

__all__ = ["EXIT_INTERRUPTED", "started_as_command", "guard_start", "Interrupts", "QuietCasadiInterrupt"]

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


def _interrupted_while_starting(signum, frame):  # pragma: no cover - runs in a child process (tested there)
    try:
        os.write(2, b"\ntolsynth: interrupted (Ctrl-C) while starting; nothing was done.\n")
    finally:
        os._exit(EXIT_INTERRUPTED)


def guard_start() -> None:
    """For the ``tolsynth`` command only: a Ctrl-C before ``main`` takes over ends the process with
    one line and status 130 (instead of a traceback from inside an import)."""
    if not started_as_command() or threading.current_thread() is not threading.main_thread():
        return
    try:
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, _interrupted_while_starting)
    except (ValueError, OSError):  # pragma: no cover - no signals here
        pass


class Interrupts:
    """While active (a ``with`` block in the main thread): SIGINT raises ``KeyboardInterrupt`` as
    usual and sets :attr:`seen`, so an exception that CasADi made of it is still known to be an
    interrupt.  CasADi may also swallow it (IPOPT treats the failed evaluation as a bad step and
    goes on): until the block ends, the interrupt is raised again every :attr:`REPEAT` s, as a
    user pressing Ctrl-C again would.  Outside the main thread it does nothing (signals go to the
    main thread)."""

    REPEAT = 0.2

    def __init__(self):
        self.seen = False
        self._previous = None
        self._done = threading.Event()
        self._repeater = None

    def _handler(self, signum, frame):
        if self._done.is_set():  # a repeat that arrived as the block ended: nothing left to stop
            return
        self.seen = True
        if self._repeater is None:
            self._repeater = threading.Thread(target=self._repeat, name="tolsynth-interrupt", daemon=True)
            self._repeater.start()
        raise KeyboardInterrupt

    def _repeat(self) -> None:
        import _thread

        while not self._done.wait(self.REPEAT):
            _thread.interrupt_main()

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            try:
                self._previous = signal.signal(signal.SIGINT, self._handler)
            except (ValueError, OSError):  # pragma: no cover
                self._previous = None
        return self

    def __exit__(self, *exc):
        self._done.set()
        if self._repeater is not None:
            self._repeater.join()
        if self._previous is not None:
            previous = signal.default_int_handler if self._previous is _interrupted_while_starting else self._previous
            try:
                signal.signal(signal.SIGINT, previous)
            except (ValueError, OSError):  # pragma: no cover
                pass
        return False


class QuietCasadiInterrupt:
    """For the ``tolsynth`` command process only: stderr (file descriptor 2) passes through a pipe
    that drops the one line CasADi's C++ code writes when a Ctrl-C lands inside an IPOPT callback
    (``CasADi - ... WARNING("KeyboardInterruptException") [...]``), so that an interrupt shows the
    command's own line only.  Everything else is forwarded as it comes (progress bars' partial
    lines too).  Restores stderr on exit."""

    NOISE = re.compile(rb'^CasADi - .*WARNING\("KeyboardInterruptException"\)')
    PREFIX = b"CasADi - "

    def __init__(self):
        self.saved = None
        self.thread = None

    def __enter__(self):
        try:
            sys.stderr.flush()
            saved = os.dup(2)
            r, w = os.pipe()
            os.dup2(w, 2)
            os.close(w)
        except (OSError, ValueError, AttributeError):  # pragma: no cover - no file descriptors here
            return self
        self.saved = saved
        self.thread = threading.Thread(target=self._pump, args=(r,), name="tolsynth-stderr", daemon=True)
        self.thread.start()
        return self

    def _write(self, data: bytes) -> None:
        try:
            os.write(self.saved, data)
        except OSError:  # pragma: no cover - the terminal went away
            pass

    def _pump(self, r: int) -> None:
        pending = b""
        while True:
            try:
                chunk = os.read(r, 65536)
            except OSError:  # pragma: no cover
                break
            if not chunk:
                break
            pending += chunk
            *lines, pending = pending.split(b"\n")
            out = b"".join(line + b"\n" for line in lines if not self.NOISE.match(line))
            # a partial line that cannot become CasADi's (a progress bar's \r line) goes out now
            if pending and not self.PREFIX.startswith(pending[: len(self.PREFIX)]):
                out, pending = out + pending, b""
            if out:
                self._write(out)
        if pending and not self.NOISE.match(pending):
            self._write(pending)
        os.close(r)

    def __exit__(self, *exc):
        if self.saved is None:
            return False
        try:
            sys.stderr.flush()
        except (OSError, ValueError):  # pragma: no cover
            pass
        os.dup2(self.saved, 2)  # the pipe's last writer (unless a child holds it) goes: the pump ends
        self.thread.join(timeout=2.0)
        os.close(self.saved)
        self.saved = None
        return False
