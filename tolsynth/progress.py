"""Progress reports on stderr for long runs (Monte Carlo, the workspace map, Tables 1-3)."""

from __future__ import annotations

import sys

__all__ = ["make_bar", "Progress", "AUTO_PROGRESS_DELAY"]

AUTO_PROGRESS_DELAY = 2.0  # s: with progress=None the bar appears only on runs longer than this


def make_bar(total: int, desc: str, unit: str, delay: float):
    """A tqdm bar on stderr (tqdm is the optional extra ``progress``), or None without tqdm."""
    try:
        from tqdm import tqdm
    except ImportError:
        return None
    kw = dict(total=total, desc=desc, unit=unit, unit_scale=True, file=sys.stderr, leave=False)
    try:
        return tqdm(delay=delay, **kw)
    except TypeError:  # tqdm < 4.62 has no delay
        return tqdm(**kw)


class Progress:
    """tqdm to stderr if wanted and installed; a callable ``progress(done, total)`` also works."""

    def __init__(self, progress, total: int, desc: str):
        self.bar = None
        self.callback = None
        self.total = total
        if callable(progress) and not isinstance(progress, bool):
            self.callback = progress
            return
        show = progress if progress is not None else sys.stderr.isatty()
        if show:  # auto (None): only runs longer than ~2 s show the bar
            self.bar = make_bar(total, desc, "sample", 0.0 if progress else AUTO_PROGRESS_DELAY)

    def update(self, done: int, step: int) -> None:
        if self.bar is not None:
            self.bar.update(step)
        if self.callback is not None:
            self.callback(done, self.total)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
