"""The certified searches on several cores: the open boxes of a best-first search dealt to workers.

A branch and bound (:func:`tolsynth.analysis.branch_bound.maximize`,
:func:`tolsynth.analysis.certify_exact.certify_components_exact`) runs serially first: small
problems finish in that phase and pay nothing for processes.  When it has not finished after
:data:`SERIAL_SECONDS`, its open boxes, best first, are dealt round-robin to forked workers (the
children inherit the compiled interval programs and CasADi functions; nothing is pickled on the way
in), so that the boxes of the hard region, next to each other in the heap, are spread over them.
Each worker goes on best-first with its share against the **global** incumbent, the best value any
of them has found (:class:`Shared`): the threshold that decides a box is the one the serial search
would use with that value, so every box a worker sets aside is decided as the serial search would
decide it, and the parts' results combine into one certificate (the parent takes the best point
and the loosest bound).  Only the results come back through pipes.

A search hands :func:`run` an object with: ``heap`` (entries ordered best first), ``processed``
(boxes bounded), ``best``, ``sense`` (+1 maximum, -1 minimum), ``shared``; ``threshold()``,
``step(thr)`` (one round), ``settled(thr)`` (nothing open can pass the threshold: the heap is
decided), ``past(level)`` (the reason to stop when the best is past a stopping level, or ""),
``bound()`` (the bound proven so far), ``key(entry)`` (a heap entry's bound), ``seq`` (the heap's
tie-breaking counter), ``to_worker(heap, shared)`` (a forked copy takes its share), ``part()`` (a
worker's result but its open boxes) and ``merge(part)``.

The parent polls: it reports the workers' box counts to the progress callback, stops them when the
time limit passes or one of them has found a point past the stopping level, and terminates them on
any exception, Ctrl-C included, before re-raising it.
"""

from __future__ import annotations

import heapq
import math
import multiprocessing
import os
import signal
import time
import traceback
from multiprocessing.connection import wait

import numpy as np

from tolsynth.errors import InputError

__all__ = ["SERIAL_SECONDS", "MAX_WORKERS", "worker_count", "run", "Shared", "fan_out", "Background"]

#: seconds of serial search before the open boxes go to workers (a small problem ends before)
SERIAL_SECONDS = 0.5
#: default upper limit of the worker count (each worker holds a copy of the search's state)
MAX_WORKERS = 8
#: the reason a worker gives when another one ended the search (never the combined reason)
HALTED = "ended by another worker"
#: seconds between the parent's looks at the workers
POLL = 0.05


def worker_count(workers, field: str = "workers") -> int:
    """Processes for a search: ``None`` the cores this process may use (at most
    :data:`MAX_WORKERS`; 1 inside a worker process, whose siblings have the other cores), else an
    integer >= 1 (1: the serial search alone; not a bool, which is no count); 1 where processes
    cannot be forked."""
    if workers is None:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
        n = 1 if multiprocessing.parent_process() is not None else min(cores or 1, MAX_WORKERS)
    else:
        try:
            n = 0 if isinstance(workers, (bool, np.bool_)) else int(workers)
        except (TypeError, ValueError, OverflowError):
            n = 0
        if n < 1 or n != workers:
            raise InputError(field, f"got {workers!r}", "None (the machine's cores) or an integer >= 1")
    if n > 1 and "fork" not in multiprocessing.get_all_start_methods():
        return 1  # the workers inherit the compiled programs: without fork they would rebuild them
    return n


def deal(heap: list, n: int) -> list:
    """The entries of a heap, best first, dealt round-robin into ``n`` heaps (a sorted list is a heap)."""
    order = sorted(heap)
    return [order[i::n] for i in range(n)]


class Shared:
    """What the workers share: the incumbent (the best value found, ``sense`` +1 for a maximum, -1
    for a minimum), the boxes bounded in all (the serial phase included), each worker's current
    bound, a flag that ends them all and one that calls their open boxes back."""

    def __init__(self, n: int, sense: float, best: float, boxes: int, bounds):
        ctx = multiprocessing.get_context("fork")
        self.sense = float(sense)
        self._best = ctx.Value("d", self.sense * float(best))
        self._boxes = ctx.Value("q", int(boxes))
        self._bounds = ctx.Array("d", [float(b) for b in bounds], lock=False)
        self._halt = ctx.Event()
        self._regroup = ctx.Event()
        self.n = n

    def incumbent(self) -> float:
        return self.sense * self._best.value

    def offer(self, value: float) -> None:
        with self._best.get_lock():
            if self.sense * value > self._best.value:
                self._best.value = self.sense * value

    def add(self, worker: int, boxes: int, bound: float) -> None:
        with self._boxes.get_lock():
            self._boxes.value += int(boxes)
        self._bounds[worker] = float(bound)

    @property
    def boxes(self) -> int:
        return int(self._boxes.value)

    def bounds(self) -> list:
        return list(self._bounds)

    def halt(self) -> None:
        self._halt.set()

    def halted(self) -> bool:
        return self._halt.is_set()

    def regroup(self) -> None:
        self._regroup.set()

    def regrouping(self) -> bool:
        return self._regroup.is_set()


def _child(run, i, part, shared, conn, parent) -> None:  # pragma: no cover - runs in the forked worker
    # Ctrl-C reaches the whole process group: the parent alone handles it (it terminates the workers)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _end_with_parent(parent)
    try:
        out = ("ok", run(i, part, shared))
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which raises it
        out = ("error", (exc, traceback.format_exc()))
    try:
        try:
            conn.send(out)
        except Exception:  # an exception that cannot be pickled: its traceback alone
            conn.send(("error", (None, out[1][1])))
    finally:
        conn.close()


def _raise(what: str, value) -> None:
    """A worker's exception raised in the parent: the same exception (a typed input error stays
    one) where it could be sent, with the worker's traceback as its cause."""
    exc, tb = value
    cause = RuntimeError(f"{what} failed:\n{tb}")
    if isinstance(exc, Exception):
        raise exc from cause
    raise cause


def fan_out(parts: list, run, shared: Shared, *, stop=None, tick=None) -> list:
    """``run(i, parts[i], shared)`` in a forked worker for each part; their return values, in order.

    ``stop() -> str`` (a time limit) is checked by the parent too, and ``tick(shared)`` is called at
    every look (progress).  A worker's exception is raised again in the parent (a RuntimeError with
    the worker's traceback where it cannot be sent); any exception in the parent (KeyboardInterrupt
    too) terminates the workers first.
    """
    ctx = multiprocessing.get_context("fork")
    procs, pending = [], {}
    try:
        for i, part in enumerate(parts):
            r, w = ctx.Pipe(duplex=False)
            p = ctx.Process(target=_child, args=(run, i, part, shared, w, os.getpid()), daemon=True)
            p.start()
            w.close()
            procs.append(p)
            pending[r] = i
        results = [None] * len(parts)
        while pending:
            for conn in wait(list(pending), timeout=POLL):
                i = pending.pop(conn)
                try:
                    status, value = conn.recv()
                except EOFError:
                    procs[i].join()
                    raise RuntimeError(f"search worker {i} ended without a result (exit code {procs[i].exitcode})")
                finally:
                    conn.close()
                if status != "ok":
                    _raise(f"search worker {i}", value)
                results[i] = value
            if tick is not None:
                tick(shared)
            if stop is not None and not shared.halted() and stop():
                shared.halt()  # the workers check the limit themselves; this one catches a slow round
        return results
    finally:
        for p in procs:
            if p.is_alive():
                p.terminate()
        for p in procs:
            p.join()
        for conn in pending:
            conn.close()


def run(s, *, workers: int, max_boxes: int, start: float, stop=None, level=None, callback=None):
    """The search ``s`` (module docstring) to its end: serial rounds until :data:`SERIAL_SECONDS`
    after ``start`` (time.perf_counter), then, while boxes are open, on ``workers`` processes.
    ``stop() -> str`` ends it with that reason (a time limit), ``level`` when the best point passes
    it, and ``callback(boxes, bound, best)`` follows it.  Returns the reason it stopped early, or
    ""."""

    def more():
        return s.processed < max_boxes

    # a daemonic process (a pool's worker) may not start processes of its own
    forks = int(workers) > 1 and not multiprocessing.current_process().daemon
    pause = start + SERIAL_SECONDS if forks else math.inf
    stopped, paused = _rounds(s, more, stop, level, callback, pause)
    while paused:
        stopped = _fan(s, min(int(workers), len(s.heap)), max_boxes, stop, level, callback)
        # the workers' open boxes are back: go on as the serial search would, dealing them again as
        # soon as there are two
        stopped, paused = (stopped, False) if stopped else _rounds(s, more, stop, level, callback, pause)
    return stopped


def _rounds(s, more, stop, level, callback, until=math.inf):
    """Rounds until the search ends: the reason it stopped early ("" if not), and whether it paused
    past ``until`` with two boxes or more open (to deal them)."""
    while s.heap and more():
        if level is not None:
            reason = s.past(level)
            if reason:
                return reason, False
        if stop is not None:
            reason = stop() or ""
            if reason:
                return reason, False
        thr = s.threshold()
        if s.settled(thr):
            return "", False
        if len(s.heap) > 1 and time.perf_counter() > until:
            return "", True
        s.step(thr)
        if callback is not None:
            callback(s.processed, s.bound(), s.best)
    return "", False


def _fan(s, n, max_boxes, stop, level, callback) -> str:
    """The open boxes dealt to ``n`` workers until one of them has finished its share (the others
    then hand their open boxes back, to be dealt again: no worker idles while another has a queue)
    or the search ends; their parts merged into ``s``.  The reason it stopped early, or ""."""
    parts = deal(s.heap, n)
    s.heap = []
    shared = Shared(n, s.sense, s.best, s.processed, [s.key(p[0]) for p in parts])

    def work(i, heap, shared):
        s.to_worker(heap, shared)
        seen = [0]

        def report(k, bound, best):
            shared.add(i, k - seen[0], bound)
            seen[0] = k

        def halt():
            return (stop() if stop is not None else "") or (HALTED if shared.halted() else "")

        def more():
            return shared.boxes < max_boxes and not shared.regrouping()

        reason, _ = _rounds(s, more, halt, level, report)
        if level is not None and s.past(level):
            shared.halt()  # the decision is made: the others stop
        elif not reason:
            shared.regroup()  # this share is done: the others hand theirs back for a new deal
        report(s.processed, s.bound(), s.best)
        return dict(s.part(), heap=s.heap, reason=reason)

    def tick(shared):
        if callback is not None:
            mine = s.sense * s.bound()
            callback(shared.boxes, s.sense * max(mine, *(s.sense * b for b in shared.bounds())), shared.incumbent())

    out = fan_out(parts, work, shared, stop=stop, tick=tick)
    for p in out:
        s.merge(p)
        for entry in p["heap"]:
            s.seq += 1  # entries of different workers may share a sequence number
            heapq.heappush(s.heap, (entry[0], s.seq, *entry[2:]))
    if callback is not None:
        callback(s.processed, s.bound(), s.best)
    reason = s.past(level) if level is not None else ""
    reason = reason or next((p["reason"] for p in out if p["reason"] and p["reason"] != HALTED), "")
    return reason or ((stop() or "") if stop is not None else "")


class Background:
    """``fn()`` in a forked process while the caller goes on (``enabled``; else it runs inside
    :meth:`result`): a search's start-up steps that do not depend on each other overlap.  Use as a
    context manager: leaving the block (an exception, Ctrl-C) terminates the process."""

    def __init__(self, fn, enabled: bool = True):
        self.fn, self.proc, self.conn = fn, None, None
        if enabled and not multiprocessing.current_process().daemon:
            ctx = multiprocessing.get_context("fork")
            self.conn, w = ctx.Pipe(duplex=False)
            self.proc = ctx.Process(target=_child, args=(lambda *_: fn(), 0, None, None, w, os.getpid()), daemon=True)
            self.proc.start()
            w.close()

    def result(self):
        if self.proc is None:
            return self.fn()
        try:
            status, value = self.conn.recv()
        except EOFError:
            self.proc.join()
            raise RuntimeError(f"background step ended without a result (exit code {self.proc.exitcode})") from None
        if status != "ok":
            _raise("background step", value)
        return value

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.proc is not None:
            if self.proc.is_alive():
                self.proc.terminate()
            self.proc.join()
            self.conn.close()
        return False


def _end_with_parent(parent: int) -> None:  # pragma: no cover - runs in the forked worker
    """A worker whose parent is killed outright (no chance to terminate it) ends too (Linux)."""
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # the parent died before the request took effect
        os._exit(1)
