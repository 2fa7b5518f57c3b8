"""``tolsynth montecarlo``: Monte Carlo through the nonlinear kinematics vs the analytic model."""

from __future__ import annotations

from tolsynth.analysis.montecarlo import ANALYTIC, DEFAULT_BATCH, monte_carlo
from tolsynth.cli.args import (  # noqa: I001
    add_pose_arguments,
    add_table_out_argument,
    check_table_out,
    default_pose,
    dist_for,
    emit_json,
    inputs_record,
    number,
    parse_pose,
    pose_label,
    write_out,
)
from tolsynth.cli.params import parse_tolerances
from tolsynth.kinematics.mechanism import load_model

__all__ = ["register"]


def _cmd_montecarlo(args) -> int:
    from tolsynth.synthesis.single import DEFAULT_PROBABILITY

    check_table_out(args)  # before any work
    mech = load_model(args.model)
    if hasattr(args, "dist"):
        args.dist = dist_for(args, mech)
    q = parse_pose(mech, args.pose) if args.pose is not None else default_pose(mech)
    eps = parse_tolerances(mech, args.tolerances)
    progress = False if args.quiet else None  # None: progress on stderr for long runs on a terminal
    r = monte_carlo(
        mech,
        q,
        eps,
        args.dist,
        R=args.R,
        n=args.n,
        seed=args.seed,
        batch=args.batch,
        Phi=args.Phi,
        progress=progress,
        confidence=args.confidence,
        analytic=args.probability or DEFAULT_PROBABILITY,
    )
    record = dict(
        pose=pose_label(q),
        tolerances=r.tolerances,
        distribution=args.dist,
        R_mm=args.R,
        Phi_rad=args.Phi,
        n=args.n,
        seed=args.seed,
        analytic=r.analytic,
    )
    if args.out:
        write_out(r.to_frame(), args, mech, **record)
    if args.json:
        out = r.to_dict()
        out["pose"] = pose_label(q) if isinstance(q, str) else args.pose
        out["inputs"] = inputs_record(args, mech, **record)
        emit_json(out)
    else:
        print(r.report())
    return 0


def register(sub) -> None:
    """Add ``tolsynth montecarlo`` to the sub-command parser."""
    p = sub.add_parser(
        "montecarlo",
        help="Monte Carlo through the nonlinear kinematics vs the analytic model",
        description="Samples the errors, pushes them through the model's nonlinear kinematics and "
        "reports the probabilities with confidence intervals next to the analytic ones.",
    )
    add_pose_arguments(p)
    p.add_argument(
        "--n", type=number("--n", "an integer >= 1", integer=True), default=1_000_000, help="number of samples"
    )
    p.add_argument(
        "--seed",
        type=number("--seed", "an integer >= 0", integer=True),
        default=0,
        help="seed of the random generator (recorded)",
    )
    p.add_argument(
        "--batch",
        type=number("--batch", "an integer >= 1", integer=True),
        default=DEFAULT_BATCH,
        help="samples per batch (memory ~ batch, not n)",
    )
    p.add_argument(
        "--confidence",
        type=number("--confidence", "0 < confidence < 1"),
        default=0.95,
        help="level of the confidence intervals",
    )
    p.add_argument(
        "--probability",
        choices=list(ANALYTIC),
        default=None,
        help="the linear model's reading in the analytic column: exact (the default, as a design's: its "
        "exact probabilities) or gaussian (the paper's: each principal component read as normal)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress report on stderr")
    add_table_out_argument(p, "the probabilities with their intervals and the analytic values")
    p.add_argument("--json", action="store_true", help="print one JSON object (inputs recorded) instead of the report")
    p.set_defaults(func=_cmd_montecarlo, task="the Monte Carlo run")
