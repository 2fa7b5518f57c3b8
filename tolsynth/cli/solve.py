"""``tolsynth solve``: optimal tolerances for one specification (auto: the compiled interior-point
method where it applies, else IPOPT; IPOPT; SUMT + Powell; or IPOPT and SUMT + Powell side by side)."""

from __future__ import annotations

import sys

import numpy as np

from tolsynth.analysis.design_pose import default_design_pose
from tolsynth.cli.args import (  # noqa: I001
    add_specification_arguments,
    add_table_out_argument,
    check_table_out,
    dist_for,
    dist_label,
    emit_json,
    fmt_p,
    inputs_record,
    parse_poses,
    pose_label,
    workspace_checked,
    write_out,
)
from tolsynth.cli.everywhere import add_everywhere_arguments, cli_words, exchange_options, reject_exchange_flags
from tolsynth.cli.params import parse_bounds, parse_per_parameter
from tolsynth.errors import InputError
from tolsynth.kinematics.mechanism import load_model
from tolsynth.problem.specification import ALPHA_DEFAULT
from tolsynth.progress import Working
from tolsynth.units import joint_values

__all__ = ["register", "side_by_side"]


def _fmt(v) -> str:
    return "(" + ", ".join(f"{x:.1f}" for x in v) + ")"


def side_by_side(c, width: int = 22) -> str:
    """Everything a single solve's summary shows, for IPOPT and SUMT + Powell side by side: status,
    cost, dual lower bound and gap, tolerances with units and bound markers, the constraint values
    and multipliers, iterations, evaluations and time, with relative differences."""
    i, s = c.ipopt, c.sumt
    w = width
    labels = [f"  {b.label} [{j + 1}]" for b in i.constraints for j in range(len(b.values))]
    lw = max([24] + [len(x) + 2 for x in labels])

    def row(label, a, b, diff=""):
        return f"{label:<{lw}}{a:>{w}}{b:>{w}}{diff:>12}"

    def rel(a, b):
        return f"{abs(b - a) / abs(a):.2e}" if a not in (0, None) and np.isfinite(a) and np.isfinite(b) else "-"

    lines = [
        row("", "IPOPT", "SUMT + Powell", "rel. diff"),
        row("status", str(i.status), str(s.status)),
        row("cost", f"{i.cost:.8g}", f"{s.cost:.8g}", rel(i.cost, s.cost)),
        row("dual lower bound", f"{i.lower_bound:.8g}", f"{s.lower_bound:.8g}"),
        row("gap (cost - bound)", f"{i.gap:.2e}", f"{s.gap:.2e}"),
        row("max sigma z / limit", f"{i.max_constraint:.6f}", f"{s.max_constraint:.6f}"),
    ]
    lines.append("tolerances (bound markers: [lower] / [upper] = at that bound)")
    for name, v in i.tolerances.items():
        u = i.units[name]
        a = f"{v:.6g} {u}" + (f" [{i.bounds_active[name]}]" if name in i.bounds_active else "")
        vs = s.tolerances[name]
        b = f"{vs:.6g} {u}" + (f" [{s.bounds_active[name]}]" if name in s.bounds_active else "")
        lines.append(row(f"  {name}", a, b, rel(v, vs)))
    lines.append("constraints: sigma z / limit (for the sphere (1-P)/(1-p)), <= 1; (Lagrange multiplier)")
    for bi, bs in zip(i.constraints, s.constraints):
        for j in range(len(bi.values)):
            lines.append(
                row(
                    f"  {bi.label} [{j + 1}]",
                    f"{bi.values[j]:.6f} ({bi.multipliers[j]:.4g})",
                    f"{bs.values[j]:.6f} ({bs.multipliers[j]:.4g})",
                )
            )
    lines += [
        row("iterations", str(i.iterations), str(s.iterations)),
        row("evaluations", str(i.function_evaluations), str(s.function_evaluations)),
        row(
            "time (ms)",
            f"{i.wall_time * 1e3:.2f}",
            f"{s.wall_time * 1e3:.2f}",
            f"{c.time_ratio:.1f}x" if i.wall_time > 0 else "-",
        ),
        f"IPOPT: {i.message}",
        f"SUMT:  {s.message}",
    ]
    return "\n".join(lines)


def _contributions(args, results: dict) -> dict:
    """``--contributions``: each result's contributor report (label -> report), or {} if not asked."""
    if not args.contributions:
        return {}
    from tolsynth.analysis.contributions import contributions

    return {label: contributions(res) for label, res in results.items()}


def _print_contributions(reps: dict) -> None:
    for label, rep in reps.items():
        what = (
            "each parameter's term |u . a_i| eps_i of the worst case along its direction u"
            if hasattr(rep, "terms")
            else "share of each principal variance, of tr V and of 1 - P(sphere)"
        )
        print(f"contributions{' of ' + label if len(reps) > 1 else ''} ({what}):")
        print(rep.format())


def _spec_kwargs(mech, args) -> tuple:
    kw = dict(Phi=args.Phi, criterion=args.criterion, probability=args.probability)
    if args.verify is not None:
        if args.solver == "both" or getattr(args, "everywhere", False):
            raise InputError(
                "--verify",
                "given with " + ("--solver both" if args.solver == "both" else "--everywhere"),
                "one solve at given poses (verify an everywhere design with tolsynth montecarlo)",
            )
        kw["verify"] = True if args.verify == "auto" else int(args.verify)
    if args.p_orientation is not None:
        if args.Phi is None:
            raise InputError("--p-orientation", "given without --Phi", "--Phi ANGLE together with --p-orientation P")
        kw["p_orientation"] = args.p_orientation
    alpha = parse_per_parameter(mech, args.alpha, "--alpha", ALPHA_DEFAULT, "a number > 0 (the paper: 0.7)")
    k = parse_per_parameter(mech, args.k, "--k", mech.k, "a number > 0")
    bounds = parse_bounds(mech, args.bounds)
    if k is not None:
        kw["k"] = k
    if bounds is not None:
        kw["bounds"] = bounds
    return alpha if alpha is not None else 0.7, kw


def cmd_solve(args) -> int:
    from tolsynth.synthesis.compare import compare
    from tolsynth.synthesis.single import DEFAULT_PROBABILITY, synthesize

    check_table_out(args)  # before any work
    mech = load_model(args.model)
    if args.probability == "worst_case" and args.p is None and getattr(args, "dist", None) is not None:
        raise InputError(  # errors anywhere in their bands: no shape is read, so a shape given would be ignored
            "--dist",
            f"{args.dist} with --probability worst_case and no --p: the worst case places every error anywhere "
            "in its band, whatever its shape",
            "--probability worst_case without --dist, or --dist with a probability reading (--p and "
            "--probability exact|gaussian)",
        )
    if hasattr(args, "dist"):
        args.dist = dist_for(args, mech)
    if args.probability is None:  # the library's default; the paper's cross-check of two solvers reads Gaussian
        args.probability = "gaussian" if args.solver == "both" else DEFAULT_PROBABILITY
    if args.solver == "both" and args.probability == "exact":  # two labels on one and the same exact solve
        raise InputError(
            "--solver both",
            "given with --probability exact: there the solver only finds the Gaussian start of the exact "
            "interior-point method, which does the solve, so both columns would be the same run",
            "--solver both with --probability gaussian (the paper's cross-check of IPOPT and SUMT + Powell; its "
            "default), or --solver auto|ipopt|sumt with --probability exact",
        )
    if args.probability == "worst_case":
        for flag, given in (
            ("--solver both", args.solver == "both"),
            ("--criterion sphere", args.criterion == "sphere"),
        ):
            if given:
                raise InputError(
                    flag.split()[0],
                    f"{flag} with --probability worst_case",
                    "a worst-case solve with ipopt (every direction, so no sphere option)",
                )
        for flag, given, allowed in (  # the exchange compares no statistical design and proves no worst case
            ("--p", args.p is not None, "--everywhere --probability worst_case without --p"),
            ("--certify", args.everywhere and args.certify, "--everywhere --probability worst_case without --certify"),
        ):
            if given and args.everywhere:
                raise InputError(flag, f"{flag} with --everywhere --probability worst_case", allowed)
        if args.p is None:  # no statistical design to compare with: no shape is read
            args.dist = None
    elif args.p is None:
        raise InputError("--p", "missing", "0 < p < 1 (only --probability worst_case reads no p)")
    alpha, kw = _spec_kwargs(mech, args)
    p_text = "worst case" if args.p is None else f"p={fmt_p(args.p)}"
    head = (
        f"{mech.name}: R={args.R:g} mm, {p_text}, alpha={args.alpha or 0.7}, "
        + ("errors anywhere in their bands" if args.p is None else f"{dist_label(args.dist)} errors")
        + (f", Phi={args.Phi:g} rad" if args.Phi is not None else "")
        + (
            ", the paper's Gaussian criterion (the two solvers' cross-check)"
            if args.solver == "both" and args.probability == "gaussian"
            # without --p the heading already says "worst case" in place of p
            else ("" if args.probability == "worst_case" and args.p is None else f", {_reading(args)}")
        )
    )
    record = dict(
        R_mm=args.R,
        p=args.p,
        distribution=args.dist,
        alpha=alpha,
        criterion=args.criterion,
        Phi_rad=args.Phi,
        p_orientation=kw.get("p_orientation"),
        solver=args.solver,
        k=kw.get("k", mech.k),
        bounds=kw.get("bounds", mech.bounds),
        probability=args.probability,
        verify=args.verify,
    )
    if args.lock:
        kw["locks"] = _parse_locks(mech, args.lock)
        record["locks"] = kw["locks"]
    if args.everywhere:
        from tolsynth.synthesis.workspace import synthesize_workspace

        start, ex = exchange_options(args, mech)
        with Working(
            "tolsynth solve: the design for every reachable pose (exchange rounds with the worst-pose search)"
        ):
            w = synthesize_workspace(mech, args.R, args.p, args.dist, alpha, solver=args.solver, pose=start, **ex, **kw)
        reps = _contributions(args, {"the design": w.result})
        if args.out:  # the tolerance table; the exchange's rounds beside the summary
            frame = w.result.to_frame()
            frame.attrs["summary"].update(converged=w.converged, rounds=w.to_frame().to_dict(orient="records"))
            write_out(
                frame,
                args,
                mech,
                **joint_values(pose_label(start) if start is not None else None, mech.joint_value_units, "start_pose"),
                everywhere=True,
                **record,
            )
        if args.json:
            out = w.result.to_dict()
            out.update(
                converged=w.converged,
                rounds=w.rounds,
                poses=w.poses,
                worst_value=w.worst_value,
                max_violation=w.max_violation,
                certified=w.certified,
                upper_bound=w.upper_bound,
                probability_lower_bound=w.probability_lower_bound,
                reason=w.reason,
                margin=w.margin,
                through=w.through,
                lower_bound=w.lower_bound,
                gap=w.gap,
            )
            if reps:
                out["contributions"] = reps["the design"].to_dict()
            out["inputs"] = inputs_record(
                args,
                mech,
                **joint_values(pose_label(start) if start is not None else None, mech.joint_value_units, "start_pose"),
                everywhere=True,
                **record,
            )
            emit_json(out)
        else:
            print(
                f"{head}, every pose"
                + (
                    f" (proven through sigma_1: the design is the Gaussian reading's at z' = {w.through:.4f})"
                    if w.through
                    else ""
                )
            )
            # what the exchange ranks poses by: the Gaussian sigma ratio, else the probability's margin
            gauss = w.result.probability_kind == "gaussian" and args.criterion != "sphere"
            measure = "sigma z/R" if gauss else f"{w.result.probability_kind} (1-P)/(1-p)"
            if args.probability == "worst_case":
                measure = w.worst_quantity
            if w.through:  # the Gaussian reading at the z Eaton's bound needs
                measure = f"sigma z'/R (z' = {w.through:.4f})"
            if w.margin:  # the rounds are judged at the radius designed for
                measure += f" at R' = R/(1+{w.margin:g})"
            # "worst worst-case" says the same word twice
            word = "largest" if args.probability == "worst_case" else "worst"
            for k, r in enumerate(w.rounds):
                print(
                    f"  round {k}: {r['n_poses']} pose(s), cost {r['cost']:.6g}, {word} {measure} over the "
                    f"workspace {r['worst_value']:.5f} at hand {_fmt(r['worst_position'])} mm"
                )
            at = f" at R' = R/(1+{w.margin:g})" if w.margin else ""
            print(
                f"  certificate: lower bound {w.lower_bound:.8g} (valid at every pose), gap {w.gap:.2e}; "
                f"afterwards the largest value found anywhere{at} is {w.worst_value:.6f} "
                + (
                    f"(violation {w.max_violation:.2e} of R', the radius designed for; the proof below is at R)"
                    if w.margin
                    else f"({w.verdict()})"
                )
            )
            if w.certified is not None:  # the certified search's proof (or why there is none)
                print("  " + cli_words(w.certificate_line()))
            print(workspace_checked(w.result).summary(cost_line=w.cost_line()))
            _print_contributions(reps)
        if not w.success and w.converged and w.result.feasible:  # the sphere's: met, optimality not proven
            print(
                f"tolsynth solve: status {w.result.status}: the design meets the specification over the workspace, "
                f"but its optimality is not proven (gap {w.gap / w.result.cost:.1%} of the cost)",
                file=sys.stderr,
            )
            return 0
        if not w.success:
            print(
                f"tolsynth solve: no convergence over the workspace ({cli_words(w.reason) or 'the last solve failed'}); the "
                "numbers above are not an optimum",
                file=sys.stderr,
            )
            return 1
        return 0
    reject_exchange_flags(args, certify_alone=False)
    poses = parse_poses(mech, args.pose)
    kw["poses"] = poses
    record.update(joint_values([pose_label(q) for q in poses], mech.joint_value_units, "poses"))
    where = ", ".join(q if isinstance(q, str) else mech.format_joints(q) for q in poses)
    if args.solver == "both":
        with Working("tolsynth solve: IPOPT and SUMT + Powell"):
            c = compare(mech, args.R, args.p, args.dist, alpha, **kw)
        reps = _contributions(args, {"IPOPT's optimum": c.ipopt, "SUMT's optimum": c.sumt})
        if args.out:
            write_out(c.to_frame(), args, mech, **record)
        if args.json:
            out = c.to_dict()
            if reps:
                out["contributions"] = {
                    "ipopt": reps["IPOPT's optimum"].to_dict(),
                    "sumt": reps["SUMT's optimum"].to_dict(),
                }
            out["inputs"] = inputs_record(args, mech, **record)
            emit_json(out)
        else:
            print(f"{head}, pose{'s' if len(poses) > 1 else ''} {where}")
            print(side_by_side(c))
            _print_contributions(reps)
        ok = c.ipopt.success and c.sumt.success
        met = c.ipopt if c.ipopt.feasible and c.sumt.feasible else None
    else:
        what = (  # under the exact reading the named solver only finds the exact method's start
            f"the exact interior-point solve (its Gaussian start: {args.solver})"
            if args.probability == "exact"
            else SOLVER_LABELS[args.solver]
        )
        with Working(f"tolsynth solve: {what} ({_reading(args)})"):
            res = synthesize(mech, args.R, args.p, args.dist, alpha, solver=args.solver, **kw)
        reps = _contributions(args, {"the optimum": res})
        if args.out:
            write_out(res.to_frame(), args, mech, **record)
        if args.json:
            out = res.to_dict()
            if reps:
                out["contributions"] = reps["the optimum"].to_dict()
            if res.verification is not None:
                out["verification"] = res.verification.to_dict()
            if res.workspace is not None:
                out["workspace_check"] = res.workspace.to_dict()
            if not args.pose:  # the library's note on how it chose the pose, as synthesize gives it
                note = default_design_pose(mech)[1]
                if note:
                    out["default_pose"] = note
            out["inputs"] = inputs_record(args, mech, **record)
            emit_json(out)
        else:
            print(f"{head}, pose{'s' if len(poses) > 1 else ''} {where}")
            print(workspace_checked(res).summary())
            if res.verification is not None:
                print(res.verification.report())
            _print_contributions(reps)
        ok = res.success
        met = res if res.feasible else None
    if not ok and met is not None:  # a design that meets the specification, its optimality not proven
        print(
            f"tolsynth solve: status {met.status}: the design meets the specification (checked), but its optimality "
            f"is not proven (lower bound {met.lower_bound:.6g}, gap {met.gap / met.cost:.1%} of the cost)",
            file=sys.stderr,
        )
        return 0
    if not ok:
        print("tolsynth solve: the solver did not converge; the numbers above are not an optimum", file=sys.stderr)
        return 1
    return 0


def _reading(args) -> str:
    """The reading in words: the worst case has no probabilities."""
    return "worst case" if args.probability == "worst_case" else f"{args.probability} probabilities"


#: the progress line's name of each ``--solver`` value
SOLVER_LABELS = {"auto": "the solve", "ipopt": "the IPOPT solve", "sumt": "the SUMT + Powell solve"}


def _parse_locks(mech, items) -> dict:
    """``--lock NAME=VALUE`` (repeatable): a tolerance fixed at VALUE, a bare number in the
    parameter's tolerance unit or with a unit suffix (``a=50um``); each parameter once."""
    from tolsynth.units import split_quantity, suffixes, to_base, unit_kind

    out = {}
    for item in items:
        name, sep, value = (s.strip() for s in item.partition("="))
        if not sep or not name or not value:
            raise InputError("--lock", f"got {item!r}", "NAME=VALUE, e.g. --lock h3=0.2 or --lock a=50um")
        i = mech.index(name, "--lock")  # UnknownNameError naming the option and the allowed names
        canon, unit = mech.error_parameters[i], mech.units[i]
        if canon in out:
            raise InputError(
                f"--lock {canon}", f"given twice ({out[canon][1]!r} and {item!r})", "each parameter locked once"
            )
        parsed = split_quantity(value)
        kind = unit_kind(unit)
        if parsed is None or (parsed[1] is not None and unit_kind(parsed[1]) != kind):
            raise InputError(
                f"--lock {canon}",
                f"{value!r} is not a tolerance",
                f"a number in {unit} (its tolerance unit), or with a{'n' if kind == 'angle' else ''} {kind} "
                f"unit suffix ({suffixes(kind)})",
            )
        v = parsed[0] if parsed[1] is None else parsed[0] * to_base(parsed[1]) / to_base(unit)
        out[canon] = (v, item)
    return {k: v for k, (v, _) in out.items()}


def register(sub) -> None:
    """Add ``tolsynth solve`` to the sub-command parser."""
    p = sub.add_parser(
        "solve",
        help="optimal tolerances for one specification",
        description="Cheapest tolerances such that each principal component of the hand position error "
        "stays within R with probability p (the paper's Eq. 20), or the sphere P(|dr| <= R) >= p; "
        "at one or more poses, or at every reachable pose (--everywhere).",
    )
    add_specification_arguments(p, ("auto", "ipopt", "sumt", "both"), worst_case=True)
    add_everywhere_arguments(p)
    p.add_argument(
        "--certify",
        action="store_true",
        help="with --everywhere: prove the specification at every pose of the continuous joint space "
        "(branch and bound) instead of a sampled search; not proven: exit status 1",
    )
    p.add_argument(
        "--contributions",
        action="store_true",
        help="also report each parameter's share of each principal variance and of 1 - P(sphere)",
    )
    add_table_out_argument(p, "the tolerance table (with --solver both: side by side)")
    p.add_argument("--json", action="store_true", help="print one JSON object (inputs recorded) instead of the report")
    p.set_defaults(func=cmd_solve, task="the solve")
