"""``tolsynth sweep``: a grid of solves (R x p x alpha x distribution x criterion x solver), one row
each, locally on processes or on a Dask cluster (``--scheduler tcp://...``), written as CSV,
JSON or Parquet."""

from __future__ import annotations

import sys

from tolsynth.cli.args import (
    DEFAULT_POSE_HELP,
    POSE_HELP,
    SOLVER_HELP,
    _number,  # the InputError form of number(), for comma-separated items
    add_table_out_argument,
    check_table_out,
    emit_json,
    fmt_p,
    half_angle_rad,
    inputs_record,
    number,
    parse_poses,
    pose_label,
    quantity,
    split_items,
    write_out,
)
from tolsynth.cli.params import parse_bounds, parse_per_parameter
from tolsynth.errors import InputError
from tolsynth.kinematics.mechanism import load_model
from tolsynth.units import split_quantity

__all__ = ["register", "GRID_KEYS", "read_grid_file"]

#: keys of a grid file (TOML), each a value or a list of values; the command line overrides them
GRID_KEYS = {
    "model": "model name or path",
    "R": 'radius, mm (numbers, or strings with a unit: "500um")',
    "p": "probability, 0 < p < 1",
    "alpha": "cost exponent > 0",
    "distribution": '"uniform", "normal", "triangular", "truncnormal" or "truncnormal(beta)"',
    "criterion": '"components" or "sphere"',
    "solver": '"auto", "ipopt" or "sumt"',
}


def read_grid_file(path: str) -> dict:
    """A grid file: TOML with the keys of :data:`GRID_KEYS` only (typed errors otherwise)."""
    import difflib

    try:
        import tomllib
    except ImportError:  # pragma: no cover - Python 3.10
        import tomli as tomllib
    try:
        with open(path, "rb") as fh:
            data = tomllib.load(fh)
    except FileNotFoundError:
        raise InputError(
            "--grid", f"{path!r} does not exist", "a TOML file with keys " + ", ".join(GRID_KEYS)
        ) from None
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise InputError("--grid", f"{path!r} cannot be read as TOML: {exc}", "a TOML file") from None
    for key, value in data.items():
        if key not in GRID_KEYS:
            near = difflib.get_close_matches(key, list(GRID_KEYS), n=1)
            raise InputError(
                f"--grid {path}: {key}",
                "unknown key" + (f" (did you mean {near[0]!r}?)" if near else ""),
                ", ".join(GRID_KEYS),
            )
        values = value if isinstance(value, list) else [value]
        if key == "model":
            if not isinstance(value, str):
                raise InputError(f"--grid {path}: model", f"got {value!r}", GRID_KEYS[key])
            continue
        for v in values:
            text_ok = isinstance(v, str) and key in ("R", "distribution", "criterion", "solver")
            num_ok = isinstance(v, (int, float)) and not isinstance(v, bool) and key in ("R", "p", "alpha")
            if not (text_ok or num_ok):
                unit = isinstance(v, str) and key in ("p", "alpha") and (split_quantity(v) or (0, None))[1]
                said = f"{v!r} has a unit, but {key} is a plain number" if unit else f"got {v!r}"
                raise InputError(f"--grid {path}: {key}", said, GRID_KEYS[key])
        data[key] = [quantity(v, "R", "length", "mm") if key == "R" and isinstance(v, str) else v for v in values]
    return data


def _numbers(text: str, field: str, parse) -> list:
    return [parse(t) for t in split_items(text, field)]


def cmd_sweep(args) -> int:
    from tolsynth.synthesis.single import DEFAULT_PROBABILITY
    from tolsynth.synthesis.sweeps import sweep

    check_table_out(args)  # before any work: the suffix, pandas / pyarrow, the folder
    grid = read_grid_file(args.grid) if args.grid else {}
    model = args.model or grid.get("model")
    if model is None:
        raise InputError(
            "--model", "not given (and no 'model' in the grid file)", "a bundled model name or a .toml path"
        )
    if args.R is not None:
        grid["R"] = _numbers(args.R, "--R", lambda t: quantity(t, "--R", "length", "mm"))
    if args.p is not None:
        grid["p"] = _numbers(args.p, "--p", _number("--p", "0 < p < 1", lambda v: 0 < v < 1))
    if args.alpha is not None:
        grid["alpha"] = _numbers(args.alpha, "--alpha", _number("--alpha", "numbers > 0", lambda v: v > 0))
    for key, opt in (("distribution", "dist"), ("criterion", "criterion"), ("solver", "solver")):
        if getattr(args, opt) is not None:
            grid[key] = split_items(getattr(args, opt), f"--{opt}")
    for key in ("R", "p"):
        if key not in grid:
            raise InputError(f"--{key}", "not given (and not in a grid file)", "comma-separated values, e.g. 0.3,0.5")
    mech = load_model(model)
    kw = {}
    k = parse_per_parameter(mech, args.k, "--k", mech.k, "a number > 0")
    bounds = parse_bounds(mech, args.bounds)
    if k is not None:
        kw["k"] = k
    if bounds is not None:
        kw["bounds"] = bounds
    if args.pose:
        kw["poses"] = parse_poses(mech, args.pose)
    if args.Phi is not None:
        kw["Phi"] = args.Phi
    if args.probability is not None:
        kw["probability"] = args.probability
    if args.scheduler is not None:
        client = _scheduler(args.scheduler)
    elif args.workers is None:
        client = None  # auto: processes only where the grid pays for starting them
    else:
        client = "serial" if args.workers == 1 else "processes"
    axes = {a: grid[a] for a in ("R", "p", "alpha", "distribution", "criterion", "solver") if a in grid}
    try:
        df = sweep(
            mech,
            client=client,
            workers=args.workers if client in (None, "processes") else None,
            progress=False if args.quiet else None,
            **axes,
            **kw,
        )
    except InputError as exc:
        if exc.field != "client":
            raise
        # the library's argument is the command line's --scheduler (a scheduler it could not reach)
        raise InputError("--scheduler", str(exc).split(": ", 1)[-1]) from None
    record = dict(
        grid=axes,
        poses=[pose_label(q) for q in kw.get("poses", [])] or None,
        k=kw.get("k", mech.k),
        bounds=kw.get("bounds", mech.bounds),
        Phi_rad=args.Phi,
        probability=args.probability or DEFAULT_PROBABILITY,
        engine=client,
    )
    if args.out is not None:
        write_out(df, args, mech, **record)
    if args.json:
        emit_json(
            {
                "inputs": inputs_record(args, mech, **record),
                "summary": df.attrs["summary"],
                "rows": df.to_dict(orient="records"),
            }
        )
    else:
        cols = ["R", "p", "alpha", "distribution", "criterion", "solver", "probability", "status", "cost", "gap"]
        cols = [c for c in cols if c in df.columns] + ["time_s"]
        print(df[cols].to_string(index=False, float_format=lambda v: f"{v:.6g}", formatters={"p": fmt_p}))
        for _, row in df[df["error"] != ""].iterrows():
            print(f"row {row['row']}: {row['error']}")
        s = df.attrs["summary"]
        print(
            f"{s['rows']} solves, {s['succeeded']} succeeded, "
            + (f"{s['feasible']} met but not proven optimal, " if s.get("feasible") else "")
            + f"{s['failed']} failed; {s['engine']}; "
            f"{s['elapsed_s']:.2f} s ({s['rows_per_s']:.1f} rows/s)" + (f"; written to {args.out}" if args.out else "")
        )
    failed = int(df.attrs["summary"]["failed"])
    if failed:
        print(
            f"tolsynth sweep: {failed} of {len(df)} solves did not succeed (see the status and error columns); "
            "their numbers are not optima",
            file=sys.stderr,
        )
        return 1
    return 0


def _scheduler(text: str) -> str:
    """``--scheduler``: a Dask scheduler's address (the library's engine names are not addresses)."""
    from tolsynth.synthesis.sweeps import ENGINES

    if text.strip() in ENGINES or ":" not in text:
        raise InputError(
            "--scheduler",
            f"{text!r} is not a scheduler address",
            "a Dask scheduler's address such as tcp://host:8786 (processes on this machine: leave "
            "--scheduler out, --workers N)",
        )
    return text.strip()


def register(sub) -> None:
    """Add ``tolsynth sweep`` to the sub-command parser."""
    p = sub.add_parser(
        "sweep",
        help="a grid of solves (R x p x alpha x ...), one row each, locally or on a Dask cluster",
        description="Solves the tolerance problem for every combination of the values given (R x p x alpha x "
        "distribution x criterion x solver) and writes one row per solve (inputs, status, cost, "
        "bound, gap, every tolerance, time, error). Runs on processes on this machine, or on a "
        "Dask cluster with --scheduler. A failed solve is a row, never a lost grid.",
    )
    p.add_argument(
        "--model",
        default=None,
        help="bundled model name or path to a .toml model file; default: the grid file's 'model'",
    )
    p.add_argument(
        "--grid",
        default=None,
        metavar="FILE.toml",
        help="grid file (TOML) with keys " + ", ".join(GRID_KEYS) + ", each a value or a list; "
        "options given on the command line replace its values; default: none",
    )
    p.add_argument("--R", default=None, help="radii, mm, comma-separated (suffixes allowed: 300um,0.5mm)")
    p.add_argument("--p", default=None, help="probabilities, comma-separated, each 0 < p < 1")
    p.add_argument(
        "--alpha", default=None, help="cost exponents (the same for every parameter), comma-separated; default: 0.7"
    )
    p.add_argument(
        "--dist",
        default=None,
        help="distributions, comma-separated: uniform, normal, triangular, truncnormal, truncnormal(beta) "
        "(one shape for every error per row); default: the model file's (its per-parameter distribution, "
        "else uniform)",
    )
    p.add_argument(
        "--criterion", default=None, help="criteria, comma-separated: components, sphere; default: components"
    )
    p.add_argument(
        "--solver",
        default=None,
        help="solvers, comma-separated: auto, ipopt, sumt (" + SOLVER_HELP + "); default: auto",
    )
    p.add_argument(
        "--k", default=None, help="cost factors k for every row: VALUE, name=VALUE, pattern=VALUE; default: the model's"
    )
    p.add_argument(
        "--bounds", default=None, help="tolerance bounds LOW:HIGH for every row (as for solve); default: the model's"
    )
    p.add_argument(
        "--pose",
        action="append",
        default=None,
        help=f"{POSE_HELP}; repeat for several poses; {DEFAULT_POSE_HELP}",
    )
    p.add_argument(
        "--Phi",
        type=half_angle_rad("--Phi"),
        default=None,
        help="orientation accuracy half-angle for every row, rad (suffixes allowed); default: none",
    )
    p.add_argument(
        "--probability",
        choices=["exact", "gaussian"],
        default=None,
        help="exact (the default: the exact probabilities of the linear error model) or gaussian (the "
        "paper's: each principal component read as normal), for every row",
    )
    add_table_out_argument(p, "the table, one row per solve")
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="run on a Dask cluster: the scheduler's address, e.g. tcp://host:8786 (the workers need "
        "tolsynth installed); default: processes on this machine",
    )
    p.add_argument(
        "--workers",
        type=number("--workers", "an integer >= 1", lambda v: v >= 1, integer=True),
        default=None,
        help="worker processes on this machine (1: in this process); default: one per CPU, used only when "
        "the grid is large enough to pay for starting them (the first solves are timed here)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress report on stderr")
    p.add_argument(
        "--json", action="store_true", help="print one JSON object (inputs recorded, every row) instead of the table"
    )
    p.set_defaults(func=cmd_sweep, task="the sweep")
