"""Ctrl-C inside a running command: whatever exception CasADi made of it, an interrupt; and the
one line CasADi's C++ code writes when a Ctrl-C lands inside an IPOPT callback kept off stderr.

Inside a CasADi call (an IPOPT callback, a compiled function) the ``KeyboardInterrupt`` raised by
the signal handler comes back wrapped as a ``RuntimeError`` or ``SystemError``: :class:`Interrupts`
records that the signal arrived, so the command line can tell an interrupt from a failure.  The
start-up part (a Ctrl-C while the package is still loading) is :mod:`tolsynth.interrupts`.
"""

from __future__ import annotations

import os
import re
import select
import signal
import sys
import threading

from tolsynth.interrupts import restore_default

__all__ = ["Interrupts", "QuietCasadiInterrupt"]


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
            try:
                signal.signal(signal.SIGINT, restore_default(self._previous))
            except (ValueError, OSError):  # pragma: no cover
                pass
        return False


class QuietCasadiInterrupt:
    """For the ``tolsynth`` command process only: stderr (file descriptor 2) passes through a pipe
    that drops the one line CasADi's C++ code writes when a Ctrl-C lands inside an IPOPT callback
    (``CasADi - ... WARNING("KeyboardInterruptException") [...]``), so that an interrupt shows the
    command's own line only.  Everything else is forwarded as it comes (progress bars' partial
    lines too).  Meanwhile ``sys.stderr`` answers ``isatty()`` for the terminal behind the pipe, so
    that progress reports still know someone is watching.  Restores stderr on exit."""

    NOISE = re.compile(rb'^CasADi - .*WARNING\("KeyboardInterruptException"\)')
    PREFIX = b"CasADi - "

    #: after the block, the pump stops once the pipe has been quiet this long (s): a process
    #: started inside the block (a sweep's forkserver) may hold the pipe open until the very end
    QUIET = 0.05

    def __init__(self):
        self.saved = None
        self.thread = None
        self.stream = None
        self._closing = threading.Event()

    def __enter__(self):
        try:
            sys.stderr.flush()
            terminal = os.isatty(2)
            saved = os.dup(2)
            r, w = os.pipe()
            os.dup2(w, 2)
            os.close(w)
        except (OSError, ValueError, AttributeError):  # pragma: no cover - no file descriptors here
            return self
        self.saved = saved
        self.stream, sys.stderr = sys.stderr, _Stderr(sys.stderr, terminal)
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
                if not _readable(r, self.QUIET):
                    if self._closing.is_set():
                        break
                    continue
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
        if isinstance(sys.stderr, _Stderr):
            sys.stderr = self.stream
        os.dup2(self.saved, 2)  # the pipe's last writer (unless a child holds it) goes: the pump ends
        self._closing.set()
        self.thread.join(timeout=2.0)
        os.close(self.saved)
        self.saved = None
        return False


def _readable(fd: int, timeout: float) -> bool:
    """True when ``fd`` has data (or its end) within ``timeout`` s; without ``select`` on pipes,
    True (a blocking read)."""
    try:
        return bool(select.select([fd], [], [], timeout)[0])
    except (OSError, ValueError):  # pragma: no cover - select cannot wait on this descriptor
        return True


class _Stderr:
    """``sys.stderr`` while file descriptor 2 is the filtering pipe: the same stream, except that
    ``isatty()`` answers for the terminal the pipe leads to."""

    def __init__(self, stream, terminal: bool):
        self._stream, self._terminal = stream, terminal

    def isatty(self) -> bool:
        return self._terminal

    def __getattr__(self, name):
        return getattr(self._stream, name)
