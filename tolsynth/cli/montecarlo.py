"""``tolsynth montecarlo``: Monte Carlo through the nonlinear kinematics vs the analytic model."""

from __future__ import annotations

from ..mechanism import load_model
from ..montecarlo import DEFAULT_BATCH, monte_carlo
from .args import add_pose_arguments, emit_json, parse_pose, parse_tolerances

__all__ = ["register"]


def _cmd_montecarlo(args) -> int:
    mech = load_model(args.model)
    q = parse_pose(mech, args.pose)
    eps = parse_tolerances(mech, args.tolerances)
    progress = False if args.quiet else None  # None: a bar on stderr for long runs on a terminal
    r = monte_carlo(mech, q, eps, args.dist, R=args.R, n=args.n, seed=args.seed, batch=args.batch,
                    Phi=args.Phi, progress=progress, confidence=args.confidence)
    if args.json:
        out = r.to_dict()
        out["pose"] = args.pose
        emit_json(out)
    else:
        print(r.report())
    return 0


def register(sub) -> None:
    """Add ``tolsynth montecarlo`` to the sub-command parser."""
    p = sub.add_parser("montecarlo", help="Monte Carlo through the nonlinear kinematics vs the analytic model")
    add_pose_arguments(p)
    p.add_argument("--n", type=int, default=1_000_000, help="number of samples")
    p.add_argument("--seed", type=int, default=0, help="seed of the random generator (recorded)")
    p.add_argument("--batch", type=int, default=DEFAULT_BATCH, help="samples per batch (memory ~ batch, not n)")
    p.add_argument("--confidence", type=float, default=0.95, help="level of the intervals")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_montecarlo)
