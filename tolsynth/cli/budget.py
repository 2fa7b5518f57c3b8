"""``tolsynth budget``: the best accuracy a cost buys (:func:`tolsynth.best_accuracy`): the
smallest R at a given p, or the largest p at a given R, bracketed by certified bisection."""

from __future__ import annotations

from tolsynth.cli.args import check_table_out, fmt_p, length_mm, number, workspace_checked
from tolsynth.cli.designs import add_output_arguments, design_command, design_kwargs, finish
from tolsynth.errors import InputError
from tolsynth.kinematics.mechanism import load_model

__all__ = ["register", "cmd_budget"]


def cmd_budget(args) -> int:
    from tolsynth.synthesis.budget import best_accuracy

    check_table_out(args)
    if (args.p is None) == (args.R is None):
        raise InputError(
            "--p/--R", "give exactly one of them", "--p P (the smallest R is found) or --R R (the largest p)"
        )
    mech = load_model(args.model)
    kw, record = design_kwargs(mech, args)
    out = best_accuracy(mech, args.cost, p=args.p, R=args.R, rtol=args.rtol, **kw)
    record.update(budget=args.cost, p=args.p, R_mm=args.R, rtol=args.rtol)
    res = out.result
    summary = {
        "quantity": out.quantity,
        "value": out.value,
        "bracket": list(out.bracket),
        "certified": out.certified,
        "solves": out.solves,
        "budget": out.budget,
        "cost": res.cost,
        "wall_time_s": out.wall_time,
    }

    def frame():
        table = res.to_frame()
        table.attrs["summary"] = dict(table.attrs["summary"], budget=summary)
        return table

    def text():
        what = (
            f"the smallest R at p = {fmt_p(args.p)}: R = {out.value:.6g} mm"
            if out.quantity == "R"
            else f"the largest p at R = {args.R:g} mm: p = {out.value:.8g}"
        )
        lo, hi = out.bracket
        return (
            f"{mech.name}: a budget of {out.budget:g} buys {what}\n"
            f"  the optimum lies in [{lo:.6g}, {hi:.6g}] ({'certified' if out.certified else 'NOT certified'}), "
            f"{out.solves} solves, {out.wall_time:.2f} s; the tolerances cost {res.cost:.8g}\n{workspace_checked(res).summary()}"
        )

    return finish(
        args,
        mech,
        record,
        frame=frame,
        data=lambda: dict(res.to_dict(), budget=summary, log=out.log),
        text=text,
        ok=out.certified,
        failure="the bracket is not certified; the value above is not proven",
    )


def register(sub) -> None:
    """Add ``tolsynth budget`` to the sub-command parser."""
    p = design_command(
        sub,
        "budget",
        "the best accuracy a given cost buys",
        "The smallest radius R a budget buys at probability p (give --p), or the largest "
        "p at a radius R (give --R), by certified bisection on optimal designs "
        "(tolsynth.best_accuracy).",
        R_and_p=False,
    )
    p.add_argument(
        "--cost",
        type=number("--cost", "a cost > 0 (the paper's units)", lambda v: v > 0),
        required=True,
        help="the budget, in the paper's cost units (sum of k eps^-alpha)",
    )
    p.add_argument(
        "--p",
        type=number("--p", "0 < p < 1", lambda v: 0 < v < 1),
        default=None,
        help="probability: find the smallest R it buys; default: none",
    )
    p.add_argument(
        "--R", type=length_mm("--R"), default=None, help="radius, mm: find the largest p it buys; default: none"
    )
    p.add_argument(
        "--rtol",
        type=number("--rtol", "0 < rtol < 1", lambda v: 0 < v < 1),
        default=1e-4,
        help="width of the final bracket, relative (in ln R or logit p)",
    )
    add_output_arguments(p, "the tolerances that buy it")
    p.set_defaults(func=cmd_budget, task="the budget search")
