"""Long runs: progress reports on stderr (Monte Carlo, the workspace map, Tables 1-3, solves),
and the time limit every solve runs under (:func:`time_limit`, :func:`remaining`).

A tqdm bar where the optional extra ``progress`` (tqdm) is installed; without it, plain lines
(:class:`LineProgress`: one line every few seconds, then one when done), so that a long run is
never silent after the core install.  tqdm stays optional: the core path is casadi + numpy, and
the plain lines carry the same information (done, total, elapsed, estimated time left).
"""

from __future__ import annotations

import contextlib
import contextvars
import math
import sys
import time

__all__ = [
    "make_bar",
    "Progress",
    "LineProgress",
    "AUTO_PROGRESS_DELAY",
    "time_limit",
    "remaining",
    "limit_seconds",
    "check_deadline",
    "Working",
    "interactive",
]

AUTO_PROGRESS_DELAY = 2.0  # s: with progress=None the bar appears only on runs longer than this


class LineProgress:
    """Plain-text progress on a stream: nothing during the first ``delay`` s, then a line such as
    ``map (inverse kinematics): 4200/10000 pt (42%), 3.1 s, about 4 s left`` at most every
    ``every`` s, and a last line when closed (only if a line was printed).  The interface is the
    part of tqdm's that the package uses: ``update(step)``, ``n``, ``total``, ``close()``."""

    def __init__(
        self, total: int, desc: str, unit: str, delay: float = AUTO_PROGRESS_DELAY, every: float = 5.0, file=None
    ):
        self.total, self.desc, self.unit = int(total), desc, unit
        self.delay, self.every = float(delay), float(every)
        self.file = file if file is not None else sys.stderr
        self.n = 0
        self.t0 = time.perf_counter()
        self._last = None  # time of the last line printed

    def _line(self, text: str) -> None:
        try:
            print(text, file=self.file, flush=True)
        except (OSError, ValueError):  # a closed stream: progress is not worth an error
            pass

    def update(self, step: int = 1) -> None:
        self.n += int(step)
        now = time.perf_counter()
        elapsed = now - self.t0
        if elapsed < self.delay or (self._last is not None and now - self._last < self.every):
            return
        self._last = now
        frac = self.n / self.total if self.total else 0.0
        left = f", about {elapsed * (1 - frac) / frac:.0f} s left" if 0 < frac < 1 else ""
        self._line(f"{self.desc}: {self.n}/{self.total} {self.unit} ({100 * frac:.0f}%), {elapsed:.1f} s{left}")

    def close(self) -> None:
        if self._last is not None:
            self._line(f"{self.desc}: {self.n}/{self.total} {self.unit}, done in {time.perf_counter() - self.t0:.1f} s")
            self._last = None


def make_bar(total: int, desc: str, unit: str, delay: float):
    """A tqdm bar on stderr (tqdm is the optional extra ``progress``), or plain lines without tqdm."""
    try:
        from tqdm import tqdm
    except ImportError:
        return LineProgress(total, desc, unit, delay)
    kw = dict(total=total, desc=desc, unit=unit, unit_scale=True, file=sys.stderr, leave=False)
    try:
        return tqdm(delay=delay, **kw)
    except TypeError:  # tqdm < 4.62 has no delay
        return tqdm(**kw)


def interactive() -> bool:
    """Someone is watching: stderr is a terminal, or the code runs in a Jupyter kernel (whose
    stderr is shown under the cell).  The automatic progress reports appear only then."""
    try:
        if sys.stderr.isatty():
            return True
    except (AttributeError, ValueError):  # a closed or replaced stream
        return False
    return "ipykernel" in sys.modules


class Working:
    """A run whose length is not known in steps (an everywhere design, an exact solve, a report):
    after ``delay`` s, a line on stderr every ``every`` s saying what runs and for how long
    (``tolsynth solve: the workspace design, 4 s``), and when it ends, how long it took; nothing
    for a run shorter than ``delay``.  A ``with`` block; a daemon thread, so Ctrl-C is not held up."""

    def __init__(self, desc: str, delay: float = 1.0, every: float = 5.0, file=None, show: bool | None = None):
        import threading

        self.desc, self.delay, self.every = desc, float(delay), float(every)
        self.file = file if file is not None else sys.stderr
        self.show = interactive() if show is None else bool(show)
        self._stop = threading.Event()
        self._thread = None
        self._printed = False
        self.t0 = 0.0

    def _line(self, text: str) -> None:
        try:
            print(text, file=self.file, flush=True)
        except (OSError, ValueError):  # a closed stream: progress is not worth an error
            pass

    def _run(self) -> None:
        wait = self.delay
        while not self._stop.wait(wait):
            self._printed = True
            self._line(f"{self.desc}, {time.perf_counter() - self.t0:.0f} s ...")
            wait = self.every

    def __enter__(self):
        import threading

        self.t0 = time.perf_counter()
        if self.show:
            self._thread = threading.Thread(target=self._run, name="tolsynth-working", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        if self._printed and exc[0] is None:
            self._line(f"{self.desc}: done in {time.perf_counter() - self.t0:.1f} s")
        return False


class Progress:
    """tqdm (or plain lines) on stderr if wanted; a callable ``progress(done, total)`` also works."""

    def __init__(self, progress, total: int, desc: str, unit: str = "sample"):
        from tolsynth.checks import check_progress

        check_progress(progress)
        self.bar = None
        self.callback = None
        self.total = total
        if callable(progress) and not isinstance(progress, bool):
            self.callback = progress
            return
        show = progress if progress is not None else interactive()
        if show:  # auto (None): only runs longer than ~2 s show the bar
            self.bar = make_bar(total, desc, unit, 0.0 if progress else AUTO_PROGRESS_DELAY)

    def update(self, done: int, step: int) -> None:
        if self.bar is not None:
            self.bar.update(step)
        if self.callback is not None:
            self.callback(done, self.total)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


# ---------------------------------------------------------------------------------------------
# time limits
# ---------------------------------------------------------------------------------------------
#: (deadline on time.monotonic(), the limit in seconds) of the innermost time_limit block
_DEADLINE: contextvars.ContextVar = contextvars.ContextVar("tolsynth_deadline", default=(math.inf, math.inf))


@contextlib.contextmanager
def time_limit(seconds: float):
    """Code in the block may run ``seconds`` (an enclosing block's earlier deadline stays in force):
    the solvers' loops read :func:`remaining` and stop with ``Status.TIME_LIMIT`` once it is 0."""
    outer = _DEADLINE.get()
    token = _DEADLINE.set((min(outer[0], time.monotonic() + seconds), min(outer[1], seconds)))
    try:
        yield
    finally:
        _DEADLINE.reset(token)


def remaining() -> float:
    """Seconds left before the innermost deadline (inf outside any :func:`time_limit` block)."""
    return _DEADLINE.get()[0] - time.monotonic()


def limit_seconds() -> float:
    """The innermost block's limit in seconds (inf outside any): a constant of the run, for
    solver settings that are compiled once (IPOPT's max_wall_time)."""
    return _DEADLINE.get()[1]


def check_deadline(what: str) -> None:
    """Raise :class:`tolsynth.errors.TimeLimitError` if the deadline has passed (for long loops
    inside one evaluation; a solver turns it into a result with ``Status.TIME_LIMIT``)."""
    if _DEADLINE.get()[0] <= time.monotonic():
        from tolsynth.errors import TimeLimitError

        raise TimeLimitError(what, _DEADLINE.get()[1])
