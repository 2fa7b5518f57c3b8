"""``tolsynth analyze``: linearised, Gaussian error analysis of one pose."""

from __future__ import annotations

from tolsynth.cli.args import (
    add_pose_arguments,
    default_pose,
    dist_for,
    emit_json,
    inputs_record,
    parse_pose,
    pose_label,
)
from tolsynth.cli.args import fmt_vec as _fmt_vec
from tolsynth.cli.params import parse_tolerances
from tolsynth.kinematics.mechanism import load_model
from tolsynth.units import joint_values

__all__ = ["register"]


def cmd_analyze(args) -> int:
    mech = load_model(args.model)
    if hasattr(args, "dist"):
        args.dist = dist_for(args, mech)
    q = parse_pose(mech, args.pose) if args.pose is not None else default_pose(mech)
    eps = parse_tolerances(mech, args.tolerances)
    a = mech.analyze(q, eps, args.dist, R=args.R, Phi=args.Phi)
    pose_name = pose_label(q) if isinstance(q, str) else args.pose
    if args.json:
        out = {
            "inputs": inputs_record(
                args,
                mech,
                pose=pose_label(q),
                **joint_values(a.q, mech.joint_value_units),
                tolerances=a.tolerances,
                distribution=args.dist,
                R_mm=args.R,
                Phi_rad=args.Phi,
            ),
            "model": mech.name,
            "pose": pose_name,
            **joint_values(a.q, mech.joint_value_units),
            "distribution": args.dist,
            "tolerances": a.tolerances,
            "units": {
                "position": "mm",
                "covariance": "mm^2",
                "principal_std": "mm",
                "R": "mm",
                "sensitivity": "rows mm, mm, mm, rad, rad, rad per tolerance unit",
                "tolerances": dict(zip(mech.error_parameters, mech.units)),
            },
            "position": a.position,
            "sensitivity": a.sensitivity,
            "covariance": a.covariance,
            "principal_std": a.principal_std,
            "principal_directions": a.principal_directions,
            "principal_std_cubic": a.principal_std_cubic,
            "R": a.R,
            "p_components": a.p_components,
            "p_sphere": a.p_sphere,
        }
        if args.Phi is not None:
            out.update(
                Phi=a.Phi,
                orientation_covariance=a.orientation_covariance,
                orientation_principal_std=a.orientation_principal_std,
                p_orientation_components=a.p_orientation_components,
                p_cone=a.p_cone,
            )
        emit_json(out)
        return 0
    print(f"model        {mech.name}: {mech.title}")
    print(f"pose         {pose_name}  q = {mech.format_joints(a.q)}")
    from tolsynth.probability.distributions import describe

    print(f"errors       {describe(args.dist)}")
    print("tolerances   " + ", ".join(f"{n}={v:g} {u}" for (n, v), u in zip(a.tolerances.items(), mech.units)))
    print(f"hand         {_fmt_vec(a.position, '{:.4f}')} mm")
    print("covariance   (mm^2)")
    for row in a.covariance:
        print("             " + "  ".join(f"{x:+.6e}" for x in row))
    print(f"principal    sigma = {_fmt_vec(a.principal_std)} mm")
    for j in range(3):
        print(f"  direction {j + 1} {_fmt_vec(a.principal_directions[:, j], '{:+.4f}')}")
    print(f"R            {args.R:g} mm")
    print("P(|w_j|<=R)  " + _fmt_vec(a.p_components, "{:.6f}") + "  (Gaussian)")
    print(f"P(|dr|<=R)   {a.p_sphere:.6f}  (sphere, Eq. 5, Gaussian)")
    if args.Phi is not None:
        print(f"Phi          {args.Phi:g} rad; orientation sigma = {_fmt_vec(a.orientation_principal_std)} rad")
        print("P(|phi_j|<=Phi) " + _fmt_vec(a.p_orientation_components, "{:.6f}"))
        print(f"P(cone)      {a.p_cone:.6f}  (hand z axis inside the cone, Eq. 8)")
    return 0


def register(sub) -> None:
    """Add ``tolsynth analyze`` to the sub-command parser."""
    p = sub.add_parser(
        "analyze",
        help="linearised, Gaussian error analysis of one pose",
        description="Linearised, Gaussian error analysis of one pose: covariance, principal "
        "standard deviations and the probabilities of the paper's Eqs. 5-8.",
    )
    add_pose_arguments(p)
    p.add_argument("--json", action="store_true", help="print one JSON object (inputs recorded) instead of the report")
    p.set_defaults(func=cmd_analyze, task="the analysis")
