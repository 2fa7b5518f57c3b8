"""``tolsynth pareto``: the optimal cost along a sweep of R (at a given p) or of p (at a given R),
each point a certified optimum (:func:`tolsynth.pareto_front`)."""

from __future__ import annotations

import math

from tolsynth.cli.args import _number, check_table_out, fmt_p, quantity
from tolsynth.cli.designs import add_output_arguments, design_command, design_kwargs, finish, parse_range
from tolsynth.errors import InputError
from tolsynth.kinematics.mechanism import load_model

__all__ = ["register", "cmd_pareto"]


def _R(text: str) -> float:
    return quantity(text, "--R", "length", "mm")


def cmd_pareto(args) -> int:
    from tolsynth.io.tables import make_frame
    from tolsynth.synthesis.pareto import pareto_front

    check_table_out(args)
    swept = [name for name, text in (("R", args.R), ("p", args.p)) if ":" in text or "," in text]
    if len(swept) != 1:
        raise InputError(
            "--R/--p",
            "give one as a range START:STOP:N (or comma-separated values) and the other as one number",
            "e.g. --R 0.2:2:10 --p 0.99, or --R 0.5 --p 0.9:0.999:5",
        )
    mech = load_model(args.model)
    kw, record = design_kwargs(mech, args)
    prob = _number("--p", "0 < p < 1", lambda v: 0 < v < 1)
    if swept == ["R"]:
        R = parse_range(args.R, "--R", lambda v: v > 0, _R, "radii > 0 (mm, or with a length unit suffix)")
        p = prob(args.p)
    else:
        p = parse_range(args.p, "--p", lambda v: 0 < v < 1, _number("--p", "0 < p < 1"), "probabilities 0 < p < 1")
        R = _R(args.R)
        if not R > 0:
            raise InputError("--R", f"got {args.R}", "a radius > 0 (mm)")
    front = pareto_front(mech, R=R, p=p, **kw)
    record.update(R_mm=R, p=p, axis=front.axis)
    units = {"R": "mm", "cost": "the paper's cost units", "lower_bound": "the paper's cost units"}
    rows = [{k: v for k, v in r.items() if k != "processes"} for r in front.rows]
    failed = [r for r in front.rows if not r["success"] and math.isfinite(r["cost"])]

    def text():
        # the reading each solve used (exact or Gaussian), as the API's table records it
        readings = sorted({r["probability"] for r in front.rows if r.get("probability")})
        lines = [
            f"{mech.name}: optimal cost against {front.axis} "
            + (f"at p = {fmt_p(p)}" if front.axis == "R" else f"at R = {R:g} mm")
            + (f", {' and '.join(readings).replace('gaussian', 'Gaussian')} reading" if readings else ""),
            f"{'R, mm':>12} {'p':>10} {'cost':>14} {'lower bound':>14}  status",
        ]
        for r in front.rows:
            status = "optimal" if r["success"] else ("infeasible" if not math.isfinite(r["cost"]) else "NOT certified")
            lines.append(f"{r['R']:>12.6g} {fmt_p(r['p']):>10} {r['cost']:>14.8g} {r['lower_bound']:>14.8g}  {status}")
        lines += [
            f"  the paper's {ref['table']} at R = {ref['R']:g}, p = {ref['p']:g}: printed tolerances cost "
            f"{ref['cost']:.8g}"
            for ref in front.reference
        ]
        lines.append(f"{len(front.rows)} solves in {front.wall_time:.2f} s")
        return "\n".join(lines)

    return finish(
        args,
        mech,
        record,
        frame=lambda: make_frame(
            rows,
            "ParetoFront",
            record,
            {"axis": front.axis, "reference": front.reference, "wall_time_s": front.wall_time},
            units,
        ),
        data=lambda: {
            "axis": front.axis,
            "rows": front.rows,
            "reference": front.reference,
            "wall_time": front.wall_time,
        },
        text=text,
        ok=not failed,
        failure=f"{len(failed)} point(s) not certified; their numbers are not optima",
    )


def register(sub) -> None:
    """Add ``tolsynth pareto`` to the sub-command parser."""
    p = design_command(
        sub,
        "pareto",
        "optimal cost against R (or p): a Pareto front",
        "Certified optima along a sweep of the radius R at a fixed p, or of p at a fixed "
        "R (tolsynth.pareto_front); each solve starts from the previous point.",
        R_and_p=False,
    )
    p.add_argument(
        "--R",
        required=True,
        help="radius, mm: START:STOP:N (N evenly spaced values), comma-separated "
        "values, or one value when --p is the range (suffixes allowed: 500um)",
    )
    p.add_argument(
        "--p",
        required=True,
        help="probability, 0 < p < 1: one value, or START:STOP:N / comma-separated values when R is fixed",
    )
    add_output_arguments(p, "the front (one row per point)", printed="the table")
    p.set_defaults(func=cmd_pareto, task="the Pareto sweep")
