"""``tolsynth report``: a design-review report of one optimum, at given poses or at every reachable pose
(HTML, or Markdown + PNG)."""

from __future__ import annotations

import sys
import time

from tolsynth.cli.args import (  # noqa: I001
    add_specification_arguments,
    dist_for,
    emit_json,
    inputs_record,
    number,
    parse_poses,
    pose_label,
)
from tolsynth.cli.everywhere import add_everywhere_arguments, cli_words, exchange_options, reject_exchange_flags
from tolsynth.cli.solve import _parse_locks, _spec_kwargs
from tolsynth.cli.workspace import _hand_axis
from tolsynth.errors import InputError
from tolsynth.kinematics.mechanism import load_model
from tolsynth.progress import Working

__all__ = ["register"]


def _cmd_report(args) -> int:
    from tolsynth.io.reports import check_report_path, report

    fmt = check_report_path(args.out, args.format, "--out")  # before any work: the folder, matplotlib
    if not 0 < args.p < 1:
        raise InputError("--p", f"got {args.p:g}", "0 < p < 1")
    mech = load_model(args.model)
    args.dist = dist_for(args, mech)
    alpha, kw = _spec_kwargs(mech, args)
    if args.lock:
        kw["locks"] = _parse_locks(mech, args.lock)
    checks = dict(
        mc_samples=args.mc_samples,
        seed=args.seed,
        map_n=args.map_n,
        map_plane=args.plane,
        map_hand_axis=_hand_axis(args.hand_axis),
        worst_grid=args.worst_grid,
    )
    ws = None
    if args.everywhere:
        from tolsynth.synthesis.workspace import synthesize_workspace

        if args.processes:
            raise InputError("--processes", "does not combine with --everywhere", "one of the two")
        start, ex = exchange_options(args, mech)
        t0 = time.perf_counter()
        with Working("tolsynth report: the design for every reachable pose (exchange rounds)"):
            ws = synthesize_workspace(
                mech, args.R, args.p, args.dist, alpha, solver=args.solver, pose=start, **ex, **kw
            )
        exchange_s = time.perf_counter() - t0
        with Working("tolsynth report: Monte Carlo, map and worst pose of the report"):
            # the exchange's design as it is (not solved again), its certified exchange's proof shown
            rep = report(ws, mechanism=mech, **checks)
    else:
        reject_exchange_flags(args, certify_alone=True)
        kw["poses"] = parse_poses(mech, args.pose)
        with Working("tolsynth report: the solve, Monte Carlo, map and worst pose of the report"):
            rep = report(
                mech,
                args.R,
                args.p,
                args.dist,
                alpha,
                solver=args.solver,
                processes=True if args.processes else None,
                certify=args.certify,
                **checks,
                **kw,
            )
    files = rep.write(args.out, fmt)
    res = rep.result
    if args.json:
        emit_json(
            {
                "files": files,
                "cost": res.cost,
                "lower_bound": res.lower_bound,
                "gap": res.gap,
                "success": res.success,
                "tolerances": res.tolerances,
                "elapsed_s": rep.elapsed_s,
                "skipped": rep.skipped,
                **(
                    {
                        "converged": ws.converged,
                        "certified": ws.certified,
                        "upper_bound": ws.upper_bound,
                        "probability_lower_bound": ws.probability_lower_bound,
                        "reason": ws.reason,
                        "exchange_s": exchange_s,
                        "poses": [pose_label(q) for q in ws.poses],
                    }
                    if ws is not None
                    else {}
                ),
                "inputs": inputs_record(args, mech, R_mm=args.R, p=args.p, distribution=args.dist, alpha=alpha),
            }
        )
    else:
        print(f"report       {files[0]}" + (f" (+ {len(files) - 1} figure files)" if len(files) > 1 else ""))
        print(
            f"optimum      {ws.cost_line() if ws is not None else f'cost {res.cost:.8g}, dual bound {res.lower_bound:.8g}, gap {res.gap:.2e}'} ({res.status})"
        )
        if ws is not None:
            print(f"exchange     {'converged' if ws.converged else 'NOT converged'}, {len(ws.poses)} pose(s) imposed")
            if ws.certified is not None:
                print("             " + cli_words(ws.certificate_line()))
        for name, why in rep.skipped.items():
            print(f"left out     {name}: {why}")
        print(
            f"time         {rep.elapsed_s:.2f} s"
            + (f" (before it, the exchange: {exchange_s:.2f} s)" if ws is not None else "")
        )
    if ws is not None and not ws.success and not (ws.converged and res.feasible):
        print(
            f"tolsynth report: no convergence over the workspace ({cli_words(ws.reason) or 'the last solve failed'}); the "
            "report says so, and its numbers are not an optimum",
            file=sys.stderr,
        )
        return 1
    if res.feasible and not res.success:  # a design that meets the specification, its optimality not proven
        print(
            f"tolsynth report: status {res.status}: the design meets the specification (checked), but its "
            f"optimality is not proven (gap {res.gap / res.cost:.1%} of the cost)",
            file=sys.stderr,
        )
    elif not res.success:
        print(
            "tolsynth report: the solver did not converge; the report says so and shows its last iterate",
            file=sys.stderr,
        )
        return 1
    return 0


def register(sub) -> None:
    """Add ``tolsynth report`` to the sub-command parser."""
    p = sub.add_parser(
        "report",
        help="a design-review report of the optimum (HTML with figures, or Markdown + PNG)",
        description="Solves one specification (at given poses, or with --everywhere at every reachable pose) "
        "and writes a report for a design review: the specification and "
        "the model with its source and assumptions, the optimal tolerance table (units, bounds, "
        "active bounds, process or cost model), the certificate (dual bound, gap), each parameter's "
        "contribution, a Monte Carlo check with confidence intervals, the workspace map of "
        'P(|dr| <= R) and the worst pose.  Needs matplotlib (pip install "tolsynth[plot]").',
    )
    add_specification_arguments(p)
    p.add_argument(
        "--processes",
        action="store_true",
        help="choose a process per parameter among the model file's processes (branch and bound)",
    )
    p.add_argument(
        "--mc-samples",
        dest="mc_samples",
        type=number("--mc-samples", "an integer >= 0", lambda v: v >= 0, integer=True),
        default=20_000,
        help="Monte Carlo samples per pose (0: no Monte Carlo section)",
    )
    p.add_argument(
        "--seed",
        type=number("--seed", "an integer >= 0", lambda v: v >= 0, integer=True),
        default=0,
        help="seed of the Monte Carlo run (recorded)",
    )
    p.add_argument(
        "--map-n",
        dest="map_n",
        type=number(
            "--map-n", "0 (no map) or an integer from 5 to 2000", lambda v: v == 0 or 5 <= v <= 2000, integer=True
        ),
        default=30,
        help="points per axis of the workspace map (0: no map)",
    )
    p.add_argument(
        "--plane",
        choices=["xy", "xz", "yz"],
        default=None,
        help="base-frame plane of the map; default: the plane a planar mechanism's hand moves in, else xz",
    )
    p.add_argument(
        "--hand-axis", default="0,0,1", help="hand z axis of the map in the base frame (3 numbers), or 'free'"
    )
    p.add_argument(
        "--worst-grid",
        dest="worst_grid",
        type=number(
            "--worst-grid",
            "0 (no search) or an integer from 2 to 1000",
            lambda v: v == 0 or 2 <= v <= 1000,
            integer=True,
        ),
        default=None,
        help="grid points per joint of the worst-pose search (0: no search); "
        "default: the search's own (a grid under 20000 points)",
    )
    add_everywhere_arguments(p)
    p.add_argument(
        "--certify",
        action="store_true",
        help="also prove a bound of the largest principal sigma over the whole joint space (branch and "
        "bound), shown in the report's certificate section; with --everywhere: the certified exchange "
        "(as solve --everywhere --certify), its proof shown there; not proven: exit status 1",
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="FILE",
        help="the report file: .html (one file, figures embedded) or .md (Markdown, figures as PNG in "
        "FILE_files/ beside it)",
    )
    p.add_argument(
        "--format",
        choices=["html", "md"],
        default=None,
        help="html or md, which must agree with the suffix of --out (.html or .htm HTML, .md or .markdown "
        "Markdown; any other suffix is refused); default: from that suffix",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object (inputs recorded) instead of the summary")
    p.set_defaults(func=_cmd_report, task="the report")
