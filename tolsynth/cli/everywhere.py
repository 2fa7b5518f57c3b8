"""The exchange's options, shared by ``tolsynth solve --everywhere`` and ``tolsynth report
--everywhere``: where it starts, its round and tolerance limits, and the certified search's options."""

from __future__ import annotations

import re

from tolsynth.cli.args import number, parse_poses, parse_reference
from tolsynth.errors import InputError

__all__ = ["add_everywhere_arguments", "cli_words", "exchange_options", "reject_exchange_flags"]

#: the options read only with ``--everywhere --certify``: flag, attribute, certify_options key
CERTIFY_FLAGS = (
    ("--certify-time-limit", "certify_time_limit", "time_limit"),
    ("--workers", "workers", "workers"),
    ("--margin", "margin", "margin"),
    ("--through-sigma", "through", "through"),
)


def cli_words(text: str) -> str:
    """A library message in the command line's words: the certified search's options by their flags
    (``certify_options['through']`` is ``--through-sigma``, ``certify_options 'margin': 3e-3`` is
    ``--margin 3e-3``) and ``probability='gaussian'`` by ``--probability gaussian``, since a command's
    user set flags, not Python arguments."""
    flags = {key: flag for flag, _, key in CERTIFY_FLAGS}

    def flag_with(m) -> str:
        flag = flags.get(m.group(1))
        if flag is None:
            return m.group(0)
        value = m.group(2) if len(m.groups()) > 1 else None
        return flag if value is None or m.group(1) == "through" else f"{flag} {value}"

    text = re.sub(r"certify_options\['(\w+)'\]", flag_with, text)
    text = re.sub(r"certify_options '(\w+)': '?([\w.+-]+)'?", flag_with, text)
    text = re.sub(r"certify_options '(\w+)'", flag_with, text)
    return text.replace("probability='gaussian'", "--probability gaussian")


def add_everywhere_arguments(p) -> None:
    """Add ``--everywhere`` and the exchange's options (the command adds its own ``--certify``)."""
    p.add_argument(
        "--everywhere",
        action="store_true",
        help="impose the constraint at every reachable pose (exchange method with the worst-pose search)",
    )
    p.add_argument(
        "--reference",
        default=None,
        help="with --everywhere: the pose the exchange method starts from: NAME, none (the search's "
        "worst pose at mid-bound tolerances), or joint values in deg (a strut or slide in mm); default: the model's "
        "reference pose (a parallel robot's 'home', else its 'worst' configuration if it has one, else none)",
    )
    p.add_argument(
        "--max-rounds",
        type=number("--max-rounds", "an integer >= 1", lambda v: v >= 1, integer=True),
        default=None,
        help="with --everywhere: exchange rounds before giving up (default 20; 30 with --certify, the Gaussian "
        "reading and no --margin); reached: not converged",
    )
    p.add_argument(
        "--tol",
        type=number("--tol", "a number in (0, 1]", lambda v: 0 < v <= 1),
        default=None,
        help="with --everywhere: relative tolerance on the specification (default 1e-3)",
    )
    p.add_argument(
        "--certify-time-limit",
        dest="certify_time_limit",
        type=number("--certify-time-limit", "a number of seconds > 0", lambda v: v > 0),
        default=None,
        help="with --everywhere --certify: seconds for each certified search; reached: not converged (exit "
        "status 1), with the bound reached; default: none, but 120 for the exact reading on five or more "
        "searched joints, where its proof has not been seen to close",
    )
    p.add_argument(
        "--workers",
        type=number("--workers", "an integer >= 1", lambda v: v >= 1, integer=True),
        default=None,
        help="with --everywhere --certify: processes of each certified search (default: the cores this "
        "process may use; 1: one)",
    )
    p.add_argument(
        "--margin",
        type=number("--margin", "a number from 0 to 0.5", lambda v: 0 <= v <= 0.5),
        default=None,
        help="with --everywhere --certify: design at R / (1 + MARGIN) and prove at R, which gives the proof "
        "room on an arm whose design is nearly flat (e.g. 3e-3 on a six- or seven-joint arm, +0.2 %% cost, "
        "the Panda then in 1.5 min rather than 4); the lower bound is then a solve's at R (default 0)",
    )
    p.add_argument(
        "--through-sigma",
        dest="through",
        action="store_const",
        const="sigma",
        default=None,
        help="with --everywhere --certify and the exact reading: prove it through sigma_1 and Eaton's tail "
        "bound (the Gaussian reading's certified exchange at z = 3.03 for p 0.99), where the exact proof does "
        "not close (five or more searched joints); at a cost premium, shown as the gap (Puma 560: +12 %%)",
    )


def exchange_options(args, mech):
    """``(start, options)`` of :func:`tolsynth.synthesize_workspace` from the command line: the start
    pose (``--pose`` once, or ``--reference``; None: the search's worst pose) and the keyword
    arguments of the exchange and its certified search."""
    from tolsynth.kinematics.joint_space import _reference

    if args.solver == "both":
        raise InputError("--solver", "'both' does not combine with --everywhere", "auto, ipopt or sumt")
    if args.pose and len(args.pose) > 1:
        raise InputError("--pose", "given more than once with --everywhere", "one starting pose, or --reference")
    if args.pose:
        start = parse_poses(mech, args.pose)[0]
    else:
        name, q = _reference(mech, parse_reference(mech, args.reference))
        start = name if (name is not None and name != "given") else q
    ex = {
        k: v
        for k, v in (("certify", args.certify or None), ("max_rounds", args.max_rounds), ("tol", args.tol))
        if v is not None
    }
    options = {}
    for flag, attr, key in CERTIFY_FLAGS:
        value = getattr(args, attr)
        if value is not None and not args.certify:
            raise InputError(
                flag, "only used with --certify", f"--certify {flag}" + ("" if attr == "through" else " VALUE")
            )
        if value is not None:
            options[key] = value
    if options:
        ex["certify_options"] = options
    return start, ex


def reject_exchange_flags(args, certify_alone: bool) -> None:
    """Without ``--everywhere``: an exchange option given is an error naming it (``--certify`` too,
    unless the command reads it alone)."""
    flags = [("--max-rounds", args.max_rounds), ("--tol", args.tol)]
    flags += [(flag, getattr(args, attr)) for flag, attr, _ in CERTIFY_FLAGS]
    if not certify_alone:
        flags.insert(0, ("--certify", args.certify or None))
    for flag, value in flags:
        if value is not None:
            raise InputError(flag, "only used with --everywhere", "--everywhere " + flag)
    if args.reference is not None:
        raise InputError(
            "--reference",
            "only used with --everywhere (the pose the search starts from)",
            "--pose for the poses of a single solve",
        )
