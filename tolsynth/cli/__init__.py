"""Command line: ``tolsynth analyze | solve | reproduce | montecarlo | map | worst-pose``.

Every sub-command prints a readable report, or one JSON object with ``--json``.  Bad input exits
with status 2 and a one-line message naming the field and the allowed range.

Layout: one module per command family (``analyze``, ``solve``, ``reproduce``, ``montecarlo``,
``workspace``: map and worst-pose), each with ``register(subparsers)``; the argument helpers in
:mod:`tolsynth.cli.args`.  A new sub-command is a new module here, added to :data:`COMMANDS`.
The library never imports this package.
"""

from __future__ import annotations

import argparse
import sys

from ..errors import TolsynthError
from . import analyze, montecarlo, reproduce, solve, workspace
from .args import add_pose_arguments, emit_json, parse_pose, parse_tolerances

__all__ = ["main", "build_parser", "add_pose_arguments", "parse_pose", "parse_tolerances", "emit_json"]

#: the modules that register sub-commands, in the order of the help text
COMMANDS = [analyze, solve, reproduce, montecarlo, workspace]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tolsynth", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for module in COMMANDS:
        module.register(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except TolsynthError as exc:
        print(f"tolsynth {args.command}: error: {exc}", file=sys.stderr)
        return 2
