"""``tolsynth budget``: the best accuracy a cost buys (:func:`tolsynth.best_accuracy`): the
smallest R at a given p, or the largest p at a given R, bracketed by certified bisection."""

from __future__ import annotations

import sys

from tolsynth.cli.args import (
    add_table_out_argument,
    check_table_out,
    emit_json,
    inputs_record,
    length_mm,
    number,
    write_out,
)
from tolsynth.cli.designs import add_design_arguments, design_kwargs
from tolsynth.errors import InputError
from tolsynth.kinematics.mechanism import load_model

__all__ = ["register", "cmd_budget"]


def cmd_budget(args) -> int:
    from tolsynth.synthesis.budget import best_accuracy

    check_table_out(args)
    if (args.p is None) == (args.R is None):
        raise InputError("--p/--R", "give exactly one of them", "--p P (the smallest R is found) or --R R (the largest p)")
    mech = load_model(args.model)
    kw, record = design_kwargs(mech, args)
    out = best_accuracy(mech, args.cost, p=args.p, R=args.R, rtol=args.rtol, **kw)
    record.update(budget=args.cost, p=args.p, R_mm=args.R, rtol=args.rtol)
    res = out.result
    summary = {"quantity": out.quantity, "value": out.value, "bracket": list(out.bracket), "certified": out.certified,
               "solves": out.solves, "budget": out.budget, "cost": res.cost, "wall_time_s": out.wall_time}
    if args.out:
        frame = res.to_frame()
        frame.attrs["summary"] = dict(frame.attrs["summary"], budget=summary)
        write_out(frame, args, mech, **record)
    if args.json:
        d = res.to_dict()
        d.update(budget=summary, log=out.log, inputs=inputs_record(args, mech, **record))
        emit_json(d)
    else:
        what = (f"the smallest R at p = {args.p:g}: R = {out.value:.6g} mm" if out.quantity == "R"
                else f"the largest p at R = {args.R:g} mm: p = {out.value:.8g}")
        print(f"{mech.name}: a budget of {out.budget:g} buys {what}")
        lo, hi = out.bracket
        print(f"  the optimum lies in [{lo:.6g}, {hi:.6g}] ({'certified' if out.certified else 'NOT certified'}), "
              f"{out.solves} solves, {out.wall_time:.2f} s; the tolerances cost {res.cost:.8g}")
        print(res.summary())
    if not out.certified:
        print("tolsynth budget: the bracket is not certified; the value above is not proven", file=sys.stderr)
        return 1
    return 0


def register(sub) -> None:
    """Add ``tolsynth budget`` to the sub-command parser."""
    p = sub.add_parser("budget", help="the best accuracy a given cost buys",
                       description="The smallest radius R a budget buys at probability p (give --p), or the largest "
                                   "p at a radius R (give --R), by certified bisection on optimal designs "
                                   "(tolsynth.best_accuracy).")
    add_design_arguments(p)
    p.add_argument("--cost", type=number("--cost", "a cost > 0 (the paper's units)", lambda v: v > 0), required=True,
                   help="the budget, in the paper's cost units (sum of k eps^-alpha)")
    p.add_argument("--p", type=number("--p", "0 < p < 1", lambda v: 0 < v < 1), default=None,
                   help="probability: find the smallest R it buys; default: none")
    p.add_argument("--R", type=length_mm("--R"), default=None,
                   help="radius, mm: find the largest p it buys; default: none")
    p.add_argument("--rtol", type=number("--rtol", "0 < rtol < 1", lambda v: 0 < v < 1), default=1e-4,
                   help="width of the final bracket, relative (in ln R or logit p)")
    add_table_out_argument(p, "the tolerances that buy it")
    p.add_argument("--json", action="store_true", help="print one JSON object (inputs recorded) instead of the report")
    p.set_defaults(func=cmd_budget, task="the budget search")
