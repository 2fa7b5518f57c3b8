"""``tolsynth reproduce``: the paper's Tables 1-3, printed vs IPOPT vs SUMT."""

from __future__ import annotations

from tolsynth.cli.args import emit_json, inputs_record
from tolsynth.errors import InputError
from tolsynth.kinematics.mechanism import load_model
from tolsynth.progress import interactive

__all__ = ["register"]


def cmd_reproduce(args) -> int:
    from tolsynth.synthesis.reproduce import format_report, reproduce

    mech = load_model(args.model)
    if not mech.spec.reference_results:  # nothing to do is an error, not an empty table
        raise InputError(
            "--model",
            f"{mech.name} has no published results to reproduce (no [[reference_results]] in its model file)",
            "a model with reference results, e.g. xu_zhang_1988",
        )
    reports = reproduce(mech, sumt=not args.no_sumt, progress=not args.json and interactive())
    if args.json:
        emit_json(
            {
                "inputs": inputs_record(args, mech, sumt=not args.no_sumt, probability="gaussian"),
                "model": mech.name,
                "columns": [r.to_dict() for r in reports],
            }
        )
    else:
        print(
            f"{mech.name}: the paper's Tables 1-3 reproduced (tolerances in mm and 1e-2 rad; cost = sum k eps^-alpha)"
        )
        print("Model: " + mech.title + " -- a reconstruction; see the model file's assumptions.")
        print(
            "Probability: the paper's Gaussian criterion (each principal component read as normal, Eq. 20), "
            "as the paper solved it; a design (tolsynth solve) meets the exact probabilities by default."
        )
        print(format_report(reports))
    ok = all(
        r.printed_unit.ipopt.success and (r.printed_unit.sumt is None or r.printed_unit.sumt.success) for r in reports
    )
    return 0 if ok else 1


def register(sub) -> None:
    """Add ``tolsynth reproduce`` to the sub-command parser."""
    p = sub.add_parser(
        "reproduce",
        help="the paper's Tables 1-3: printed vs IPOPT vs SUMT",
        description="The published optima of a model (the paper's Tables 1-3 for xu_zhang_1988): "
        "printed tolerances against IPOPT's and SUMT + Powell's optimum.",
    )
    p.add_argument(
        "--model",
        default="xu_zhang_1988",
        help="bundled model name or path to a .toml model file with [[reference_results]]",
    )
    p.add_argument(
        "--no-sumt", action="store_true", help="skip SUMT + Powell (IPOPT only; SUMT adds a few milliseconds a column)"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object (inputs recorded) instead of the report")
    p.set_defaults(func=cmd_reproduce, task="the reproduction of the published tables")
