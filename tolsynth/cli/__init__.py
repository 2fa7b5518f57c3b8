"""Command line: tolsynth analyze | solve | report | sweep | reproduce | montecarlo | map | worst-pose.

Every sub-command prints a readable report, or one JSON object with --json (its inputs and the
package version recorded).  Exit status: 0 done (a design that meets the specification without an
optimality proof, status "feasible", says so in one line); 1 a solver did not converge (the numbers are not
an optimum); 2 bad input or nothing to do (a one-line message naming the option and the allowed
range); 130 interrupted (Ctrl-C, wherever it lands); 141 the output pipe was closed.  No command prints a
traceback: an output file that cannot be written is a one-line error (2), and an unexpected
failure one line naming it (1).

Layout: one module per command family (``analyze``, ``solve``, ``report``, ``sweep``, ``reproduce``, ``montecarlo``,
``workspace``: map and worst-pose), each with ``register(subparsers)``; the argument helpers in
:mod:`tolsynth.cli.args`.  A new sub-command is a new module here, added to :data:`COMMANDS`.
The library never imports this package.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import warnings

from tolsynth.cli import (
    analyze,
    budget,
    grades,
    models,
    montecarlo,
    pareto,
    processes,
    report,
    reproduce,
    solve,
    sweep,
    workspace,
)
from tolsynth.cli.args import HelpFormatter, add_pose_arguments, emit_json, parse_pose, version
from tolsynth.cli.everywhere import cli_words
from tolsynth.cli.interrupts import Interrupts, QuietCasadiInterrupt
from tolsynth.cli.params import parse_tolerances
from tolsynth.errors import TolsynthError
from tolsynth.interrupts import started_as_command

__all__ = ["main", "build_parser", "add_pose_arguments", "parse_pose", "parse_tolerances", "emit_json"]

#: the modules that register sub-commands, in the order of the help text
COMMANDS = [analyze, solve, report, sweep, reproduce, montecarlo, workspace, models, pareto, budget, processes, grades]

EXIT_OK, EXIT_NOT_CONVERGED, EXIT_INPUT, EXIT_INTERRUPTED, EXIT_PIPE = 0, 1, 2, 130, 141


def build_parser() -> argparse.ArgumentParser:
    doc = __doc__.split("\n\n")
    parser = argparse.ArgumentParser(
        prog="tolsynth",
        formatter_class=HelpFormatter,
        description="Cheapest manufacturing tolerances for a robot's link parameters that meet its pose "
        "accuracy with a stated probability (Xu & Zhang 1988, and beyond).",
        epilog=doc[1].replace("\n", " ") + "\n\nRun 'tolsynth COMMAND --help' for the options of a command.",
    )
    parser.add_argument(
        "--version", action="version", version=f"tolsynth {version()}", help="print the package version and exit"
    )
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


def _os_error(exc: OSError) -> str:
    """An OSError as one line: what could not be done to which file, and why."""
    name = exc.filename if exc.filename is not None else ""
    why = exc.strerror or type(exc).__name__
    return f"cannot write or read {name!r}: {why}" if name != "" else f"{why}"


def main(argv=None) -> int:
    """Run the command line; returns the exit status (see the module docstring).

    No traceback reaches the user: a typed error is one line (status 2), a file that cannot be
    written one line (2), Ctrl-C one line (130) whatever exception it became inside CasADi, and an
    unexpected exception one line naming it (1; ``TOLSYNTH_DEBUG=1`` shows its traceback)."""
    if started_as_command():  # the command's own process: CasADi's C++ interrupt warning filtered out
        with QuietCasadiInterrupt():
            rc = _main(argv)
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # done: a late Ctrl-C has nothing left to stop
        return rc
    return _main(argv)


def _main(argv) -> int:
    command = "tolsynth"
    args = None

    def one_line(message, category, filename, lineno, file=None, line=None):  # a warning: one line, no source
        try:
            print(f"{command}: warning: {message}", file=sys.stderr)
        except (OSError, ValueError):  # pragma: no cover - stderr gone
            pass

    with Interrupts() as interrupts, warnings.catch_warnings():
        warnings.showwarning = one_line
        try:
            parser = build_parser()
            args = parser.parse_args(argv)  # a usage error exits 2 (SystemExit) with argparse's message
            command = f"tolsynth {args.command}"
            try:
                rc = args.func(args)
            except TolsynthError as exc:
                if interrupts.seen:
                    raise KeyboardInterrupt from None
                print(f"{command}: error: {cli_words(str(exc))}", file=sys.stderr)
                rc = EXIT_INPUT
            sys.stdout.flush()  # a closed pipe shows here, not in the interpreter's final flush
            return rc
        except KeyboardInterrupt:
            return _interrupted(command, args)
        except BrokenPipeError:
            _quiet_stdout()
            return EXIT_PIPE
        except OSError as exc:  # an output file that cannot be written (a full disk, /proc, a long name)
            if interrupts.seen:
                return _interrupted(command, args)
            print(f"{command}: error: {_os_error(exc)}", file=sys.stderr)
            return EXIT_INPUT
        except Exception as exc:  # noqa: BLE001 - the one place that turns any failure into one line
            if interrupts.seen:  # CasADi wraps a KeyboardInterrupt raised in a callback
                return _interrupted(command, args)
            if os.environ.get("TOLSYNTH_DEBUG"):
                raise
            text = " ".join(str(exc).split())[:300]
            print(
                f"{command}: internal error: {type(exc).__name__}: {text} (a bug: please report it with the "
                "command line; TOLSYNTH_DEBUG=1 shows the traceback)",
                file=sys.stderr,
            )
            return EXIT_NOT_CONVERGED


def _interrupted(command: str, args) -> int:
    task = getattr(args, "task", None) or "the command"
    try:
        # on a terminal the line starts fresh (after the echoed ^C or a progress bar); in a log it is one line
        lead = "\n" if sys.stderr.isatty() else ""
        print(f"{lead}{command}: interrupted (Ctrl-C): {task} was not finished; nothing was written.", file=sys.stderr)
    except (OSError, ValueError):  # pragma: no cover - stderr gone
        pass
    return EXIT_INTERRUPTED
