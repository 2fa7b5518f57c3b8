"""Grids of solves: :func:`sweep` over R x p x alpha x distribution (x criterion x solver).

One row per solve in a :class:`pandas.DataFrame`: the inputs, the status, cost, dual lower bound,
gap, every tolerance, the times, and the error message of a solve that raised (a failed solve is a
row, never a lost grid).  The engine is chosen by ``client``:

``None`` (default)
    processes on this machine (:class:`concurrent.futures.ProcessPoolExecutor`, one worker per
    CPU, no set-up) when the grid is large enough to pay for starting them: the first
    :data:`AUTO_PROBE` solves run in this process, timed, and the rest go to processes only if
    they would take more than :data:`AUTO_PROCESSES_S` here, otherwise they stay here;
``"processes"`` / ``"serial"``
    force one or the other;
a :class:`dask.distributed.Client`, or a scheduler address such as ``"tcp://10.0.0.5:8786"``
    the same tasks on a Dask cluster (the workers need tolsynth installed); for an address the
    client is opened and closed here.

Tasks are chunks of grid points; the model is sent once per chunk (scattered once on Dask) and
kept by each worker, so a worker builds its CasADi graphs once.  pandas and Dask are the optional
extra ``sweep`` (``pip install "tolsynth[sweep]"``).

>>> import tolsynth
>>> df = tolsynth.sweep("xu_zhang_1988", R=[0.3, 0.5], p=[0.9, 0.99], client="serial")  # doctest: +SKIP
>>> df[["R", "p", "status", "cost"]]  # doctest: +SKIP
"""

from __future__ import annotations

import inspect
import itertools
import math
import os
import time
import uuid
from collections.abc import Mapping, Sequence

import numpy as np

from tolsynth.checks import check_count, check_positive, check_probability
from tolsynth.errors import InputError, MissingDependencyError, OutOfRangeError
from tolsynth.problem.specification import ALPHA_DEFAULT
from tolsynth.tabular import jsonable, make_frame, require_pandas, synthesis_row

__all__ = ["sweep", "ENGINES", "MAX_ROWS"]

#: the string values of ``client`` (any other string is a Dask scheduler address)
ENGINES = ("serial", "processes")
#: largest grid accepted (rows)
MAX_ROWS = 1_000_000
SWEEP_INSTALL = 'pip install "tolsynth[sweep]"'
#: client=None: solves timed in this process first, and processes used only if the rest would
#: take longer than this serially (starting worker processes costs about 1 s here)
AUTO_PROBE = 4
AUTO_PROCESSES_S = 2.0

#: the grid's axes, in the order of the columns
AXES = ("R", "p", "alpha", "distribution", "criterion", "solver")
#: keyword arguments of synthesize that a sweep does not pass through (they are axes, or per-run)
_NOT_PASSED = set(AXES) | {"mechanism", "validate", "seed"}


def _axis(values, name: str) -> list:
    """A grid axis: a scalar (one value) or a non-empty sequence of values."""
    if isinstance(values, (str, bytes, Mapping)) or not isinstance(values, (Sequence, np.ndarray)):
        return [values]
    values = list(np.asarray(values).ravel()) if isinstance(values, np.ndarray) else list(values)
    if not values:
        raise InputError(name, "empty list", f"one value or a non-empty list of values of {name}")
    return values


def _check_choice(v, name: str, allowed: Sequence[str]) -> str:
    if not isinstance(v, str) or v not in allowed:
        raise InputError(name, f"unknown value {v!r}", " or ".join(repr(a) for a in allowed))
    return v


def _check_alpha(a) -> object:
    from tolsynth.problem.specification import ALPHA_MAX

    if isinstance(a, Mapping):
        return dict(a)  # checked per parameter by make_specification (below, on the first point)
    if isinstance(a, (bool, np.bool_)):
        raise InputError("alpha", f"got {a!r}", "a number > 0 or a dict name -> number")
    return check_positive(a, "alpha", "", upper=ALPHA_MAX)


def _check_shape(d, mechanism):
    """A shape name (tolsynth.probability.distributions) or a per-parameter mapping, checked later;
    None is the model file's distribution, written into the point so that the row names what it used."""
    from collections.abc import Mapping

    from tolsynth.probability.distributions import resolve, shape

    if d is None:
        return resolve(None, mechanism)
    if isinstance(d, Mapping):
        return d
    shape(d)  # typed error naming distribution
    return d


def _grid(mechanism, R, p, alpha, distribution, criterion, solver, worst_case: bool = False) -> list[dict]:
    from tolsynth.problem.specification import CRITERIA
    from tolsynth.synthesis.single import SOLVERS

    if worst_case:  # no probability and no shape: p and distribution are no axes, None in every row
        for name, value in (("p", p), ("distribution", distribution)):
            if value is not None:
                raise InputError(
                    name,
                    f"{value!r} with probability='worst_case' (every error anywhere in its band: no "
                    f"{'probability' if name == 'p' else 'error shape'} is read)",
                    f"no {name} with probability='worst_case', or a statistical probability ('exact', "
                    f"'gaussian') with it",
                )
    elif p is None:
        raise InputError("p", "missing", "0 < p < 1, or a list of them (only probability='worst_case' reads no p)")
    axes = {
        "R": [check_positive(r, "R") for r in _axis(R, "R")],
        "p": [None] if worst_case else [check_probability(q, "p") for q in _axis(p, "p")],
        "alpha": [_check_alpha(a) for a in _axis(alpha, "alpha")],
        "distribution": [None]
        if worst_case
        else [_check_shape(d, mechanism) for d in _axis(distribution, "distribution")],
        "criterion": [_check_choice(c, "criterion", CRITERIA) for c in _axis(criterion, "criterion")],
        "solver": [_check_choice(s, "solver", tuple(SOLVERS)) for s in _axis(solver, "solver")],
    }
    n = math.prod(len(v) for v in axes.values())
    if n > MAX_ROWS:
        raise OutOfRangeError("grid", f"{n} solves", f"at most {MAX_ROWS} rows per sweep")
    return [dict(zip(AXES, combo)) for combo in itertools.product(*(axes[a] for a in AXES))]


def _check_kwargs(kwargs: dict) -> None:
    from tolsynth.synthesis.single import synthesize

    allowed = [k for k in inspect.signature(synthesize).parameters if k not in _NOT_PASSED]
    for key in kwargs:
        if key not in allowed:
            raise InputError(
                key,
                "not an argument a sweep passes to synthesize",
                "the grid axes R, p, alpha, distribution, criterion, solver, or one of " + ", ".join(allowed),
            )


# ---------------------------------------------------------------------------------------------
# the task (runs in a worker)
# ---------------------------------------------------------------------------------------------
_WORKER_MODELS: dict = {}  # token -> Mechanism, per worker process


def _error_row(exc: BaseException) -> dict:
    return {"status": "error", "success": False, "message": "", "error": f"{type(exc).__name__}: {exc}"}


def _solve_chunk(token: str, mechanism, points: list, kwargs: dict) -> list[dict]:
    """Solve ``points`` (index, grid point) in turn; every exception becomes that row's error."""
    from tolsynth.synthesis.single import synthesize

    mech = _WORKER_MODELS.setdefault(token, mechanism)
    out = []
    for index, point in points:
        t0 = time.perf_counter()
        try:
            row = synthesis_row(synthesize(mech, **point, **kwargs))
            row["error"] = None
        except Exception as exc:  # noqa: BLE001 - any failure is that row's result, not the sweep's
            row = _error_row(exc)
        row["row"] = index
        row["time_s"] = time.perf_counter() - t0
        out.append(row)
    return out


# ---------------------------------------------------------------------------------------------
# engines
# ---------------------------------------------------------------------------------------------
class _Lazy:
    """A task of the serial engine, run when its result is asked for (so the bar advances)."""

    def __init__(self, fn, args):
        self.fn, self.args = fn, args

    def result(self):
        return self.fn(*self.args)


class _Serial:
    name = "serial (this process)"
    workers = 1

    def submit(self, fn, *args):
        return _Lazy(fn, args)

    def as_completed(self, futures):
        return iter(futures)

    def model(self, mech):
        return mech

    def close(self, cancel: bool = False):
        pass


class _Processes:
    def __init__(self, workers: int):
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        # forkserver: workers start from a clean interpreter (no threads inherited), cheaply
        method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
        self.pool = ProcessPoolExecutor(
            max_workers=workers, mp_context=multiprocessing.get_context(method), initializer=_ignore_ctrl_c
        )
        self.workers = workers
        self.name = f"processes ({workers} on this machine)"

    def submit(self, fn, *args):
        return self.pool.submit(fn, *args)

    def as_completed(self, futures):
        from concurrent.futures import as_completed

        return as_completed(futures)

    def model(self, mech):
        return mech

    def close(self, cancel: bool = False):
        if cancel:  # the workers ignore Ctrl-C: ended here, not left to finish their chunks
            for proc in list((getattr(self.pool, "_processes", None) or {}).values()):
                proc.terminate()
        self.pool.shutdown(wait=True, cancel_futures=cancel)


def _ignore_ctrl_c() -> None:  # pragma: no cover - runs in the worker
    """A worker's start: Ctrl-C reaches the whole process group, and the parent alone handles it
    (it reports the interrupt once and ends the workers)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


class _Dask:
    def __init__(self, client):
        try:
            import distributed
        except ImportError:
            raise MissingDependencyError("dask.distributed", "a sweep on a Dask cluster", SWEEP_INSTALL) from None
        self._own = None
        if isinstance(client, str):
            try:
                client = distributed.Client(client, timeout="10s")
            except (OSError, TimeoutError, ValueError) as exc:
                raise InputError(
                    "client",
                    f"cannot reach the Dask scheduler {client!r}: {exc}",
                    "a running scheduler's address, e.g. tcp://host:8786",
                ) from None
            self._own = client
        self.client = client
        self.workers = max(1, len(client.scheduler_info().get("workers", {})))
        self.name = f"dask ({self.workers} worker(s) at {client.scheduler.address})"
        self._as_completed = distributed.as_completed

    def submit(self, fn, *args):
        return self.client.submit(fn, *args, pure=False)

    def as_completed(self, futures):
        return self._as_completed(futures)

    def model(self, mech):
        return self.client.scatter(mech, broadcast=True)

    def close(self, cancel: bool = False):
        if self._own is not None:
            self._own.close()


def _engine(client, workers, n_rows: int):
    if isinstance(client, str) and client in ENGINES:
        if client == "serial":
            return _Serial()
        n = workers if workers is not None else (os.cpu_count() or 1)
        return _Processes(max(1, min(n, n_rows)))
    if isinstance(client, str):
        if "://" not in client and ":" not in client:
            raise InputError(
                "client",
                f"unknown engine {client!r}",
                "None, 'serial', 'processes', a dask.distributed.Client or a scheduler "
                "address such as 'tcp://host:8786'",
            )
        return _Dask(client)
    if type(client).__name__ == "Client" and hasattr(client, "submit") and hasattr(client, "scatter"):
        return _Dask(client)
    raise InputError(
        "client",
        f"got {type(client).__name__}",
        "None, 'serial', 'processes', a dask.distributed.Client or a scheduler address",
    )


# ---------------------------------------------------------------------------------------------
# the front door
# ---------------------------------------------------------------------------------------------
def sweep(
    mechanism,
    R,
    p=None,
    alpha=ALPHA_DEFAULT,
    distribution=None,
    *,
    criterion="components",
    solver="auto",
    client=None,
    workers: int | None = None,
    chunk: int | None = None,
    progress=None,
    **kwargs,
):
    """Solve :func:`tolsynth.synthesize` over a grid; one DataFrame row per solve.

    Parameters
    ----------
    mechanism : Mechanism or str
        A loaded model, or a model name / path.
    R, p, alpha, distribution, criterion, solver
        Each one value or a list of values; the grid is their Cartesian product, in this order
        (R mm; 0 < p < 1; alpha a number > 0 or a dict name -> number; distribution a shape name
        such as "uniform" / "normal" or a dict name -> shape (None, the default: the model file's
        distribution, as synthesize reads it, else uniform); criterion "components" / "sphere"; solver "auto" / "ipopt" /
        "sumt").  With ``probability="worst_case"`` give no p and no distribution (either is an
        :class:`InputError`: the worst case reads neither); its table has no p and no
        distribution column.
    client : None, "serial", "processes", dask.distributed.Client or str
        Where the solves run (see :mod:`tolsynth.synthesis.sweeps`); a string with ``://`` is a Dask
        scheduler address.
    workers : int, optional
        Worker processes for ``"processes"`` (default: the CPUs).
    chunk : int, optional
        Grid points per task (default: about four tasks per worker, at most 64 points).
    progress : bool, callable or None
        A bar on stderr (None: only on a terminal for runs over 2 s), or ``progress(done, total)``.
    **kwargs
        Any other keyword argument of :func:`tolsynth.synthesize` (k, bounds, pose, poses, Phi,
        p_orientation, cost, locks, options, x0), the same for every row.  Without ``pose`` and
        ``poses``: synthesize's default, the model's default design pose
        (:func:`tolsynth.analysis.design_pose.default_design_pose`), chosen once; how it was chosen
        is in ``attrs["inputs"]["default_pose"]`` when it is not the model's ``worst`` configuration.

    Returns
    -------
    pandas.DataFrame
        One row per grid point, in grid order: ``row``, the axes (``R`` in mm), ``status``
        (:class:`tolsynth.Status` values, or ``"error"`` where the solve raised), ``success``,
        ``cost``, ``lower_bound``, ``gap``, ``max_constraint``, ``iterations``,
        ``function_evaluations``, ``wall_time_s`` (solver), ``time_s`` (whole row, in the worker),
        ``message``, ``error`` (the exception, else empty), ``eps_<name>`` per parameter (its
        tolerance unit).  ``attrs`` hold the inputs, the engine, the units and the package version
        (kept by :func:`tolsynth.write_table`).

    Raises
    ------
    InputError, OutOfRangeError, UnknownNameError
        For a bad grid or argument, before any solve.
    MissingDependencyError
        Without pandas (or without Dask for a cluster).
    """
    from tolsynth.analysis.design_pose import resolve_design_pose
    from tolsynth.kinematics.mechanism import as_mechanism
    from tolsynth.problem.specification import make_specification
    from tolsynth.progress import Progress

    pd = require_pandas("tolsynth.sweep")
    mechanism = as_mechanism(mechanism)
    _check_kwargs(kwargs)
    worst_case = asked_worst_case(kwargs)
    points = _grid(mechanism, R, p, alpha, distribution, criterion, solver, worst_case)
    if workers is not None:
        workers = check_count(workers, "workers", lower=1, upper=4096)
    if chunk is not None:
        chunk = check_count(chunk, "chunk", lower=1, upper=MAX_ROWS)
    # the pose synthesize would choose, chosen once here so that no worker searches for it again
    pose, chosen = resolve_design_pose(mechanism, kwargs.get("pose"), kwargs.get("poses"))
    solve_kwargs = {**kwargs, "pose": pose} if kwargs.get("poses") is None else kwargs
    # the common arguments checked once, here, on the first grid point (typed errors before work)
    first = points[0]
    first_p = first["p"]
    if worst_case:  # what the worst case would ignore refused here, as synthesize refuses it
        from tolsynth.synthesis.worst_case import _NO_P, refuse_unread

        for c in {pt["criterion"] for pt in points}:
            refuse_unread(None, None, c, kwargs.get("Phi"), kwargs.get("p_orientation"))
        first_p = _NO_P  # the specification builder's placeholder: the worst case reads no p
    make_specification(
        mechanism,
        first["R"],
        first_p,
        first["distribution"],
        first["alpha"],
        kwargs.get("k"),
        kwargs.get("bounds"),
        pose,
        kwargs.get("poses"),
        kwargs.get("Phi"),
        kwargs.get("p_orientation"),
        first["criterion"],
        kwargs.get("cost"),
    )
    for a in {id(pt["alpha"]): pt["alpha"] for pt in points if isinstance(pt["alpha"], dict)}.values():
        make_specification(mechanism, first["R"], first_p, first["distribution"], a)

    n = len(points)
    indexed = list(enumerate(points))
    token = uuid.uuid4().hex
    t0 = time.perf_counter()
    rows: list[dict] = []
    bar = Progress(progress, n, "sweep", unit="solve")
    engine = None
    try:
        label = ""
        rest = indexed
        if client is None:  # auto: time a few solves here, then go to processes only if it pays
            probe = indexed[:AUTO_PROBE]
            rows = _solve_chunk(token, mechanism, probe, solve_kwargs)
            bar.update(len(rows), len(rows))
            per_row = (time.perf_counter() - t0) / len(probe)
            rest = indexed[len(probe) :]
            big = per_row * len(rest) > AUTO_PROCESSES_S and (os.cpu_count() or 1) > 1
            client = "processes" if big else "serial"
            label = (
                f"auto ({len(probe)} solves here, {per_row * 1e3:.1f} ms each), then "
                if rest
                else f"auto (all {len(probe)} solves in this process)"
            )
        if rest:
            engine = _engine(client, workers, len(rest))
            label += engine.name
            rows += _run(engine, token, mechanism, rest, solve_kwargs, chunk, bar, len(rows))
    except BaseException:
        if engine is not None:
            engine.close(cancel=True)
        raise
    finally:
        bar.close()
    if engine is not None:
        engine.close()
    elapsed = time.perf_counter() - t0
    return _frame(pd, mechanism, points, rows, label or "serial (this process)", elapsed, kwargs, chosen)


def _run(engine, token, mechanism, indexed, kwargs, chunk, bar, done) -> list[dict]:
    """Dispatch ``indexed`` grid points to ``engine`` in chunks; collect the rows as they finish."""
    n = len(indexed)
    size = chunk or max(1, min(64, math.ceil(n / (4 * engine.workers))))
    model = engine.model(mechanism)
    futures = {}
    for i in range(0, n, size):
        c = indexed[i : i + size]
        futures[engine.submit(_solve_chunk, token, model, c, kwargs)] = c
    rows = []
    for f in engine.as_completed(list(futures)):
        c = futures[f]
        try:
            got = f.result()
        except Exception as exc:  # noqa: BLE001 - a lost worker loses its chunk's rows only
            got = [dict(_error_row(exc), row=i) for i, _ in c]
        rows.extend(got)
        done += len(c)
        bar.update(done, len(c))
    return rows


def _frame(pd, mechanism, points, rows, engine: str, elapsed: float, kwargs: dict, default_pose: str | None):
    by_index = {r["row"]: r for r in rows}
    eps_cols = ["eps_" + n for n in mechanism.error_parameters]
    result_cols = [
        "probability",
        "status",
        "success",
        "cost",
        "lower_bound",
        "gap",
        "max_constraint",
        "iterations",
        "function_evaluations",
        "wall_time_s",
        "time_s",
        "message",
        "error",
    ]
    # the worst case reads no p and no shape: no such columns, rather than a value nothing read
    axes = [a for a in AXES if not (asked_worst_case(kwargs) and a in ("p", "distribution"))]
    # a per-parameter alpha (dict) anywhere: the whole column as JSON text, one type per column
    as_text = {a for a in AXES if any(isinstance(pt[a], dict) for pt in points)}
    from tolsynth.synthesis.single import DEFAULT_PROBABILITY

    # a row whose solve raised still says which reading it was asked in (its error is in that reading)
    asked = kwargs.get("probability") or DEFAULT_PROBABILITY
    records = []
    for i, point in enumerate(points):
        r = by_index.get(i, {"status": "error", "success": False, "error": "no result returned"})
        rec = {"row": i}
        for a in axes:
            v = point[a]
            rec[a] = json_text(v) if a in as_text else v
        for c in result_cols + eps_cols:
            rec[c] = r.get(c)
        rec["error"] = rec["error"] or ""
        rec["probability"] = rec["probability"] or asked
        rec["message"] = rec["message"] or ""
        records.append(rec)
    columns = ["row", *axes, *result_cols, *eps_cols]
    frame = pd.DataFrame.from_records(records, columns=columns)
    for c in ["cost", "lower_bound", "gap", "max_constraint", "wall_time_s", "time_s", *eps_cols]:
        frame[c] = pd.to_numeric(frame[c], errors="coerce").astype(float)
    for c in ["iterations", "function_evaluations"]:
        frame[c] = pd.to_numeric(frame[c], errors="coerce").astype("Int64")
    frame["success"] = frame["success"].astype(bool)
    path = getattr(mechanism.spec, "path", None)
    inputs = {
        "model": {"name": mechanism.name, "title": mechanism.title, "file": str(path) if path else None},
        "grid": {
            a: sorted(
                {json_text(pt[a]) if isinstance(pt[a], dict) else pt[a] for pt in points},
                key=lambda v: (str(type(v)), v),
            )
            for a in axes
        },
        "common": kwargs,
        **({"default_pose": default_pose} if default_pose else {}),
        "error_parameters": list(mechanism.error_parameters),
        "tolerance_units": dict(zip(mechanism.error_parameters, mechanism.units)),
    }
    n_ok = int(frame["success"].sum())
    n_met = int((frame["status"] == "feasible").sum())  # met, optimality not proven (the sphere's)
    summary = {
        "rows": len(frame),
        "succeeded": n_ok,
        "feasible": n_met,
        "failed": len(frame) - n_ok - n_met,
        "engine": engine,
        "elapsed_s": elapsed,
        "rows_per_s": len(frame) / elapsed if elapsed > 0 else None,
    }
    units = {
        "R": "mm",
        "cost": "the paper's cost units",
        "wall_time_s": "s",
        "time_s": "s",
        **{"eps_" + n: u for n, u in zip(mechanism.error_parameters, mechanism.units)},
    }
    out = make_frame(frame, "Sweep", inputs, summary, units)
    return out


def asked_worst_case(kwargs: dict) -> bool:
    """The sweep's rows are worst-case designs (no p, no distribution)."""
    return kwargs.get("probability") == "worst_case"


def json_text(v) -> str:
    """A dict cell (per-parameter alpha) as compact JSON text, so that every format can hold it."""
    import json

    return json.dumps(jsonable(v), sort_keys=True, separators=(",", ":"))
