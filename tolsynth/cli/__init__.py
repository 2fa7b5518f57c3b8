"""Command line: tolsynth analyze | solve | report | sweep | reproduce | montecarlo | map | worst-pose.

Every sub-command prints a readable report, or one JSON object with --json (its inputs and the
package version recorded).  Exit status: 0 done; 1 a solver did not converge (the numbers are not
an optimum); 2 bad input or nothing to do (a one-line message naming the option and the allowed
range); 130 interrupted (Ctrl-C); 141 the output pipe was closed.

Layout: one module per command family (``analyze``, ``solve``, ``report``, ``sweep``, ``reproduce``, ``montecarlo``,
``workspace``: map and worst-pose), each with ``register(subparsers)``; the argument helpers in
:mod:`tolsynth.cli.args`.  A new sub-command is a new module here, added to :data:`COMMANDS`.
The library never imports this package.
"""

from __future__ import annotations

import argparse
import os
import sys

from tolsynth.errors import TolsynthError
from tolsynth.cli import analyze, montecarlo, report, reproduce, solve, sweep, workspace
from tolsynth.cli import budget, models, pareto, processes
from tolsynth.cli.args import HelpFormatter, add_pose_arguments, emit_json, parse_pose, parse_tolerances, version

__all__ = ["main", "build_parser", "add_pose_arguments", "parse_pose", "parse_tolerances", "emit_json"]

#: the modules that register sub-commands, in the order of the help text
COMMANDS = [analyze, solve, report, sweep, reproduce, montecarlo, workspace, models, pareto, budget, processes]

EXIT_OK, EXIT_NOT_CONVERGED, EXIT_INPUT, EXIT_INTERRUPTED, EXIT_PIPE = 0, 1, 2, 130, 141


def build_parser() -> argparse.ArgumentParser:
    doc = __doc__.split("\n\n")
    parser = argparse.ArgumentParser(
        prog="tolsynth", formatter_class=HelpFormatter,
        description="Cheapest manufacturing tolerances for a robot's link parameters that meet its pose "
                    "accuracy with a stated probability (Xu & Zhang 1988, and beyond).",
        epilog=doc[1].replace("\n", " ") + "\n\nRun 'tolsynth COMMAND --help' for the options of a command.",
    )
    parser.add_argument("--version", action="version", version=f"tolsynth {version()}",
                        help="print the package version and exit")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", title="commands")
    for module in COMMANDS:
        module.register(sub)
    for p in sub.choices.values():
        p.formatter_class = HelpFormatter
    return parser


def _quiet_stdout() -> None:
    """After a closed pipe: point stdout at /dev/null so that the interpreter's final flush is quiet."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # pragma: no cover - stdout without a file descriptor
        pass


def main(argv=None) -> int:
    """Run the command line; returns the exit status (see the module docstring)."""
    command = "tolsynth"
    try:
        parser = build_parser()
        args = parser.parse_args(argv)  # a usage error exits 2 (SystemExit) with argparse's message
        command = f"tolsynth {args.command}"
        try:
            rc = args.func(args)
        except TolsynthError as exc:
            print(f"{command}: error: {exc}", file=sys.stderr)
            rc = EXIT_INPUT
        sys.stdout.flush()  # a closed pipe shows here, not in the interpreter's final flush
        return rc
    except KeyboardInterrupt:
        task = getattr(locals().get("args"), "task", None) or "the command"
        print(f"\n{command}: interrupted (Ctrl-C): {task} was not finished; nothing was written.", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _quiet_stdout()
        return EXIT_PIPE
