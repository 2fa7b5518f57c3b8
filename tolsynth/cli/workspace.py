"""``tolsynth map`` (the paper's Figure 3) and ``tolsynth worst-pose``."""

from __future__ import annotations

import math

import numpy as np

from tolsynth.analysis.pose_search import worst_pose
from tolsynth.analysis.workspace_map import PLANES, ProbabilityMap, probability_map
from tolsynth.cli.args import (  # noqa: I001
    TOLERANCES_HELP,
    add_dist_argument,
    add_model_argument,
    add_table_out_argument,
    check_figure_path,
    check_table_out,
    dist_for,
    emit_json,
    inputs_record,
    length_mm,
    number,
    parse_reference,
    quantity,
    split_items,
    write_out,
)
from tolsynth.cli.designs import finish
from tolsynth.cli.params import parse_tolerances
from tolsynth.errors import InputError
from tolsynth.kinematics.mechanism import load_model
from tolsynth.progress import Working

__all__ = ["register"]

REFERENCE_HELP = (
    "reference pose: a configuration NAME, none, or joint values in deg (a strut or slide in mm), comma-separated; "
    "default: the model's reference pose (a parallel robot's 'home', else its 'worst' configuration if it has one, else none)"
)


def _hand_axis(text: str):
    if text.strip().lower() == "free":
        return None
    allowed = "3 comma-separated numbers (a direction in the base frame, not all 0), or 'free'"
    items = split_items(text, "--hand-axis")
    try:
        axis = np.array([float(x) for x in items])
    except ValueError:
        raise InputError("--hand-axis", f"{text!r}", allowed) from None
    if axis.shape != (3,) or not np.all(np.isfinite(axis)) or not np.any(axis):
        raise InputError("--hand-axis", f"{text!r}", allowed)
    return axis


def _extent(text: str | None):
    if text is None:
        return None
    items = split_items(text, "--extent")
    if len(items) != 4:
        raise InputError("--extent", f"{text!r}: {len(items)} values", "umin,umax,vmin,vmax in mm (suffixes allowed)")
    return [quantity(x, "--extent", "length", "mm") for x in items]


def _tolerances(mech, text: str | None):
    """``--tolerances``, or when not given: the model's figure3 set (the paper's Figure 3), else its
    first tolerance set, else the geometric middle of every parameter's bounds.  Returns the
    tolerances and a label that says which was chosen."""
    if text is not None:
        return parse_tolerances(mech, text), text
    sets = list(mech.tolerance_sets)
    if "figure3" in sets:
        return mech.tolerances("figure3"), "figure3"
    if sets:
        return mech.tolerances(sets[0]), f"{sets[0]} (the model's first tolerance set; --tolerances not given)"
    lo, hi = (np.asarray(b, dtype=float) for b in mech.bounds)
    return np.sqrt(
        lo * hi
    ), "the geometric middle of the bounds (the model has no tolerance set; --tolerances not given)"


def _joint_columns_with_units(frame, mech, columns):
    """The joint columns named with their unit (``q2`` -> ``q2_rad``; a strut's ``_mm``): the
    table holds the API's rad while the command line reads and shows deg, so the name says which."""
    names = {}
    for column, unit in zip(columns, mech.joint_units):
        names[column] = f"{column}_{'mm' if unit == 'mm' else 'rad'}"
    units = {k: v for k, v in frame.attrs.get("units", {}).items() if k != "q" and k not in names}
    units.update({new: new.rsplit("_", 1)[1] for new in names.values()})
    out = frame.rename(columns=names)
    out.attrs = dict(frame.attrs, units=units)
    return out


def _cmd_map(args) -> int:
    check_figure_path(args.out)  # before any work: matplotlib, the format, the folder
    check_table_out(args, "--data")
    mech = load_model(args.model)
    if hasattr(args, "dist"):
        args.dist = dist_for(args, mech)
    eps, label = _tolerances(mech, args.tolerances)
    extent = _extent(args.extent)
    axis = _hand_axis(args.hand_axis)
    reference = parse_reference(mech, args.reference)
    pm = probability_map(
        mech,
        eps,
        R=args.R,
        distribution=args.dist,
        n=args.n,
        plane=args.plane,
        offset=args.offset,
        hand_axis=axis,
        extent=extent,
        reference=reference,
        progress=False if args.quiet else None,
    )
    pm = ProbabilityMap(**{**pm.__dict__, "tolerance_label": label})
    if not pm.reachable.any():  # (a plane that only touches the reachable set along a line)
        raise InputError(
            "--plane",
            f"no point of the {pm.plane} plane's {args.n} x {args.n} grid at offset {pm.offset:g} mm is reachable "
            "with this hand axis",
            "a plane the hand reaches with that axis (by default a planar mechanism's own plane)",
        )
    if args.out:
        import matplotlib

        matplotlib.use("Agg")
        from tolsynth.analysis.plot import plot_map

        plot_map(pm, path=args.out)
    record = dict(
        tolerances=pm.tolerances,
        distribution=args.dist,
        R_mm=args.R,
        plane=pm.plane,
        offset_mm=pm.offset,
        hand_axis=axis,
        extent_mm=extent,
        reference=pm.reference,
        n=args.n,
    )
    if args.data:
        frame = _joint_columns_with_units(pm.to_frame(), mech, [f"q_{n}" for n in pm.joint_names])
        write_out(frame, args, mech, "--data", **record)
    if args.json:
        out = {k: v for k, v in pm.to_dict().items() if k not in ("Q", "sigma")}
        out["out"] = args.out
        out["inputs"] = inputs_record(args, mech, **record)
        emit_json(out)
    else:
        rch = pm.reachable
        at = f" at {'XYZ'[PLANES[pm.plane][2]]}0 = {pm.offset:g} mm" if pm.offset else ""
        print(f"map          {mech.name}, plane {pm.plane}{at}, {args.n} x {args.n} points, {int(rch.sum())} reachable")
        print(f"tolerances   {label}")
        print(f"extent       {pm.u[0]:.1f} .. {pm.u[-1]:.1f} x {pm.v[0]:.1f} .. {pm.v[-1]:.1f} mm")
        if rch.any():
            print(
                f"P(|dr|<=R)   {np.nanmin(pm.P):.4f} .. {np.nanmax(pm.P):.4f}  (Gaussian: normal errors of the "
                f"{pm.distribution} errors' variances; R = {pm.R:g} mm)"
            )
            print(f"lowest P     {pm.worst[2]:.4f} (Gaussian) at ({pm.worst[0]:.1f}, {pm.worst[1]:.1f}) mm")
        print(f"reference    {pm.reference or 'none'}")
        print(f"branch       {pm.branch}")
        print(
            "held         "
            + ("; ".join(f"{k} = {math.degrees(v):g} deg ({w})" for k, (v, w) in pm.fixed.items()) or "none")
        )
        print(f"time         {pm.elapsed_s:.2f} s")
        if args.out:
            print(f"figure       {args.out}")
        if args.data:
            print(f"data         {args.data}")
    return 0


def _cmd_worst(args) -> int:
    check_table_out(args)  # before any work
    mech = load_model(args.model)
    if hasattr(args, "dist"):
        args.dist = dist_for(args, mech)
    for flag, value in (("--certify-time-limit", args.certify_time_limit), ("--workers", args.workers)):
        if value is not None and not args.certify:
            raise InputError(flag, "only used with --certify", f"--certify {flag} VALUE")
    if args.probability is not None and args.criterion != "components":
        # only the per-component probability has two readings; the others would ignore it
        raise InputError(
            "--probability",
            f"only used with --criterion components (got --criterion {args.criterion})",
            f"--criterion components --probability {args.probability}",
        )
    eps, label = _tolerances(mech, args.tolerances)
    what = "the grid and pattern search" + (", then the certified branch and bound" if args.certify else "")
    with Working(f"tolsynth worst-pose: {what}"):
        w = worst_pose(
            mech,
            eps,
            criterion=args.criterion,
            R=args.R,
            distribution=args.dist,
            grid=args.grid,
            reference=parse_reference(mech, args.reference),
            certify=args.certify,
            probability=args.probability,
            time_limit=args.certify_time_limit,
            workers=args.workers,
        )
    record = dict(
        tolerances=w.tolerances, distribution=args.dist, R_mm=args.R, criterion=args.criterion, reference=w.reference
    )
    unproven = args.certify and not w.certified
    return finish(
        args,
        mech,
        record,
        frame=lambda: _joint_columns_with_units(w.to_frame(), mech, [f"q{j + 1}" for j in range(len(w.q))]),
        data=w.to_dict,
        text=lambda: f"tolerances   {label}\n{w.report(mech.joint_names, mech.joint_units)}",
        ok=not unproven,
        failure=f"the bound is not certified ({w.certificate.reason}); it holds, the gap did not close"
        if unproven
        else "",
    )


def register(sub) -> None:
    """Add ``tolsynth map`` and ``tolsynth worst-pose`` to the sub-command parser."""
    p = sub.add_parser(
        "map",
        help="P(dr <= R) over the reachable part of a plane (the paper's Figure 3)",
        description="P(|dr| <= R) of the linear, Gaussian model over the reachable part of a "
        "base-frame plane for a fixed hand axis, by inverse kinematics on the model's "
        "forward-kinematics graph; optionally drawn as the paper's Figure 3.",
    )
    add_model_argument(p)
    p.add_argument(
        "--tolerances",
        default=None,
        help=TOLERANCES_HELP + "; default: the model's figure3 set (the paper's model), else its first "
        "tolerance set, else the geometric middle of the bounds (said in the output)",
    )
    add_dist_argument(p)
    p.add_argument(
        "--R", type=length_mm("--R"), default=0.2, help="radius of the accuracy sphere, mm (suffixes allowed)"
    )
    p.add_argument("--n", type=number("--n", "an integer >= 5", integer=True), default=100, help="grid points per axis")
    p.add_argument(
        "--plane",
        choices=sorted(PLANES),
        default=None,
        help="base-frame plane of the map; default: the plane a planar mechanism's hand moves in, else xz",
    )
    p.add_argument(
        "--offset",
        type=length_mm("--offset"),
        default=None,
        help="offset of the plane along its normal, mm (suffixes allowed); default: the planar "
        "mechanism's plane's, else 0",
    )
    p.add_argument(
        "--hand-axis",
        default="0,0,1",
        help="hand z axis in the base frame (3 numbers, normalised), or 'free' for any orientation",
    )
    p.add_argument(
        "--extent",
        default=None,
        help="umin,umax,vmin,vmax of the grid, mm (suffixes allowed); default: the reachable box",
    )
    p.add_argument(
        "--reference", default=None, help=REFERENCE_HELP + "; the continuation starts there and it is marked"
    )
    p.add_argument(
        "--out",
        default=None,
        help='figure file (.png, .pdf, .svg, ...; needs matplotlib: pip install "tolsynth[plot]"); default: none',
    )
    p.add_argument("--quiet", action="store_true", help="no progress report on stderr")
    p.add_argument("--json", action="store_true", help="print one JSON object (inputs recorded) instead of the report")
    add_table_out_argument(p, "the map's points (u, v, P, sigma, joints)", "--data")
    p.set_defaults(func=_cmd_map, task="the workspace map")

    p = sub.add_parser(
        "worst-pose",
        help="search the joint space for the pose of worst accuracy",
        description="Grid plus pattern search over the joint space (inside the joint limits and "
        "constraints) for the pose of largest principal sigma or lowest P(|dr| <= R).",
    )
    add_model_argument(p)
    p.add_argument(
        "--tolerances",
        default=None,
        help=TOLERANCES_HELP + "; default: the model's figure3 set (the paper's model), else its first "
        "tolerance set, else the geometric middle of the bounds (said in the output)",
    )
    add_dist_argument(p)
    p.add_argument(
        "--criterion",
        choices=["sigma", "probability", "components"],
        default="sigma",
        help="largest principal standard deviation, lowest P(|dr| <= R), or lowest per-component "
        "probability P(|u.dr| <= R) over directions u (the last two need --R)",
    )
    p.add_argument(
        "--certify",
        action="store_true",
        help="also prove a bound over the whole continuous joint space (branch and bound; sigma or "
        "components); not proven: exit status 1",
    )
    p.add_argument(
        "--certify-time-limit",
        dest="certify_time_limit",
        type=number("--certify-time-limit", "a number of seconds > 0", lambda v: v > 0),
        default=None,
        help="with --certify: seconds for the branch and bound; reached: not proven (exit status 1), "
        "the bound reached reported (it holds, only looser); default: none (the box limit)",
    )
    p.add_argument(
        "--workers",
        type=number("--workers", "an integer >= 1", lambda v: v >= 1, integer=True),
        default=None,
        help="with --certify: processes of the branch and bound (default: the cores this process may use; 1: one)",
    )
    p.add_argument(
        "--probability",
        choices=["exact", "gaussian"],
        default=None,
        help="reading of the per-component probability (--criterion components): exact (the default) "
        "or the paper's Gaussian reading",
    )
    p.add_argument(
        "--R",
        type=length_mm("--R"),
        default=None,
        help="radius, mm (suffixes allowed); needed for --criterion probability; default: none",
    )
    p.add_argument(
        "--grid",
        type=number("--grid", "an integer >= 2", integer=True),
        default=None,
        help="grid points per searched joint; default: as many as keep the grid under 20000 points",
    )
    p.add_argument("--reference", default=None, help=REFERENCE_HELP + "; reported beside the result")
    add_table_out_argument(p, "the worst and the reference pose")
    p.add_argument("--json", action="store_true", help="print one JSON object (inputs recorded) instead of the report")
    p.set_defaults(func=_cmd_worst, task="the worst-pose search")
