"""Argument helpers shared by the sub-commands: numbers with units, poses, per-parameter values
(tolerances, bounds, k, alpha), output paths, JSON output with the inputs recorded.

Units on the command line: every option has one unit, stated in its help, used for a bare number
(lengths mm, joint angles deg, ``--Phi`` rad, tolerances each parameter's own tolerance unit);
a number may carry another unit as a suffix (``0.1mm``, ``5um``, ``2mrad``, ``0.01deg``).  Bad
input raises a :class:`tolsynth.InputError` naming the option and quoting the same unit.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
from typing import Callable

import numpy as np

from tolsynth.checks import check_writable_path
from tolsynth.errors import InputError, UnknownNameError
from tolsynth.io.tables import jsonable
from tolsynth.kinematics.mechanism import Mechanism
from tolsynth.units import QUANTITY as _QTY
from tolsynth.units import SUFFIXES, split_quantity, to_base, unit_kind, units_label
from tolsynth.units import suffixes as _suffixes

__all__ = [
    "dist_for",
    "dist_label",
    "parse_distribution",
    "HelpFormatter",
    "version",
    "quantity",
    "split_items",
    "parse_pose",
    "parse_poses",
    "parse_reference",
    "check_figure_path",
    "inputs_record",
    "add_pose_arguments",
    "emit_json",
    "fmt_p",
    "fmt_vec",
    "add_table_out_argument",
    "check_table_out",
    "write_out",
]

_WILDCARD = re.compile(r"[*?\[]")


def version() -> str:
    """The installed package version (the distribution's metadata, else ``tolsynth.__version__``)."""
    try:
        from importlib.metadata import PackageNotFoundError
        from importlib.metadata import version as _v

        try:
            return _v("tolsynth")
        except PackageNotFoundError:
            pass
    except ImportError:  # pragma: no cover
        pass
    from tolsynth import __version__

    return __version__


class HelpFormatter(argparse.HelpFormatter):
    """Shows ``(default: X)`` after every option that has a default (not for flags or None)."""

    def _get_help_string(self, action):
        text = action.help or ""
        if "%(default)" in text or action.default in (None, False, argparse.SUPPRESS) or not action.option_strings:
            return text
        if isinstance(action, (argparse._StoreTrueAction, argparse._VersionAction, argparse._HelpAction)):
            return text
        return text + " (default: %(default)s)"


# ---------------------------------------------------------------------------------------------
# numbers with units
# ---------------------------------------------------------------------------------------------
def _split_quantity(text: str, field: str, allowed: str) -> tuple[float, str | None]:
    parsed = split_quantity(text)
    if parsed is not None:
        return parsed
    m = _QTY.match(str(text))
    if m and m.group(2) and m.group(2) not in SUFFIXES:
        raise InputError(field, f"{text!r}: unknown unit {m.group(2)!r}", allowed)
    raise InputError(field, f"{text!r} is not a number", allowed)


def quantity(text: str, field: str, kind: str, unit: str) -> float:
    """A number in ``unit``, or with a unit suffix of the same kind (converted to ``unit``).

    >>> quantity("500um", "--R", "length", "mm")
    0.5
    """
    allowed = f"a number in {unit}, or with a{'n' if kind == 'angle' else ''} {kind} unit suffix ({_suffixes(kind)})"
    value, suffix = _split_quantity(text, field, allowed)
    if suffix is None:
        return value
    if unit_kind(suffix) != kind:
        raise InputError(field, f"{text!r}: {suffix} is not a{'n' if kind == 'angle' else ''} {kind} unit", allowed)
    return value * to_base(suffix) / to_base(unit)


def _arg_type(fn, name: str):
    """An argparse ``type=`` from a parser that raises InputError: argparse reports the message
    (``argument --R: ...``) instead of a generic "invalid value"."""

    def parse(text):
        try:
            return fn(text)
        except InputError as exc:
            msg = str(exc)
            prefix = f"{exc.field}: "
            raise argparse.ArgumentTypeError(msg[len(prefix) :] if msg.startswith(prefix) else msg) from None

    parse.__name__ = name
    return parse


def length_mm(field: str):
    """argparse ``type=``: a length in mm (suffixes allowed)."""
    return _arg_type(lambda text: quantity(text, field, "length", "mm"), "length")


def angle_rad(field: str):
    """argparse ``type=``: an angle in rad (suffixes allowed)."""
    return _arg_type(lambda text: quantity(text, field, "angle", "rad"), "angle")


def half_angle_rad(field: str):
    """argparse ``type=``: a cone half-angle in rad (suffixes allowed), 0 < angle <= pi: a rotation
    turns the hand by at most pi, so a larger half-angle would allow everything and change nothing."""

    def parse(text):
        value = quantity(text, field, "angle", "rad")
        if not 0 < value <= math.pi:
            raise InputError(
                field,
                f"got {text}" + ("" if split_quantity(text)[1] is None else f" = {value:g} rad"),
                f"a half-angle > 0 and <= pi rad (180 deg), in rad or with an angle unit suffix ({_suffixes('angle')})",
            )
        return value

    return _arg_type(parse, "angle")


def number(field: str, allowed: str, check: Callable[[float], bool] | None = None, integer: bool = False):
    """argparse ``type=``: a plain finite number (int with ``integer``), optionally range-checked."""
    return _arg_type(_number(field, allowed, check, integer), "number")


def _number(field: str, allowed: str, check: Callable[[float], bool] | None = None, integer: bool = False):
    def parse(text):
        try:
            v = float(text)
        except (TypeError, ValueError):
            raise InputError(field, f"{text!r} is not a number", allowed) from None
        if not math.isfinite(v) or (integer and v != int(v)) or (check is not None and not check(v)):
            raise InputError(field, f"got {text}", allowed)
        return int(v) if integer else v

    return parse


def split_items(text: str, field: str) -> list[str]:
    """Comma-separated items, none empty (``'figure3,,'`` is an error, not ``'figure3'``)."""
    items = [t.strip() for t in str(text).split(",")]
    for i, t in enumerate(items):
        if not t:
            raise InputError(field, f"empty item {i + 1} in {text!r}", "comma-separated items, none empty")
    return items


# ---------------------------------------------------------------------------------------------
# poses
# ---------------------------------------------------------------------------------------------
def parse_pose(mech: Mechanism, text: str, field: str = "--pose"):
    """A configuration name, or comma-separated joint values in deg, a joint that slides in mm (a
    suffix ``rad`` or ``um`` allowed)."""
    if text in mech.configurations:
        return text
    allowed = (
        "one of " + ", ".join(mech.configurations) + " (configurations), or "
        f"{len(mech.joint_names)} comma-separated joint values in "
        f"{units_label(mech.joint_units)} ({', '.join(mech.joint_names)})"
    )
    items = [t.strip() for t in str(text).split(",")]
    if not any(_QTY.match(t) for t in items):
        raise UnknownNameError(field, f"{text!r} is neither a configuration nor joint values", allowed)
    if len(items) != len(mech.joint_names):
        raise InputError(field, f"{len(items)} joint values q given for {len(mech.joint_names)} joints", allowed)
    values = []
    for t, unit in zip(items, mech.joint_units):  # a parallel robot's struts in mm, other joints in deg
        if not t:
            raise InputError(field, f"empty item in {text!r}", allowed)
        values.append(
            quantity(t, field, "length", "mm") if unit == "mm" else math.radians(quantity(t, field, "angle", "deg"))
        )
    return np.array(values)


def default_pose(mech: Mechanism):
    """The model's default design pose, the one :func:`tolsynth.synthesize` takes without a pose
    (so a command and the library give the same design)."""
    from tolsynth.analysis.design_pose import default_design_pose

    return default_design_pose(mech)[0]


def parse_poses(mech: Mechanism, texts: list[str] | None, field: str = "--pose") -> list:
    """Every ``--pose`` given (the option repeated), or the model's reference pose."""
    if not texts:
        return [default_pose(mech)]
    return [parse_pose(mech, t, field) for t in texts]


def parse_reference(mech: Mechanism, text: str | None):
    """``--reference``: None (the model's reference pose), ``none``, a configuration or joints (deg)."""
    from tolsynth.kinematics.joint_space import MODEL_REFERENCE

    if text is None:
        return MODEL_REFERENCE
    if text.strip().lower() == "none" and "none" not in mech.configurations:
        return None
    return parse_pose(mech, text, "--reference")


def pose_label(pose) -> str | list:
    """A pose for reports and JSON: its name, or its joint values in rad."""
    return pose if isinstance(pose, str) else np.asarray(pose, dtype=float).tolist()


# ---------------------------------------------------------------------------------------------
# output files
# ---------------------------------------------------------------------------------------------
PLOT_INSTALL = 'pip install "tolsynth[plot]"'


def check_figure_path(path: str | None, field: str = "--out") -> None:
    """Before any work: matplotlib is installed, it can write the suffix, the folder is writable."""
    if path is None:
        return
    try:
        from matplotlib.backend_bases import FigureCanvasBase
    except ImportError:
        raise InputError(
            field, "writing a figure needs matplotlib, which is not installed", f"install it with: {PLOT_INSTALL}"
        ) from None
    types = FigureCanvasBase.get_supported_filetypes()
    ext = os.path.splitext(path)[1].lstrip(".").lower()
    if ext not in types:
        raise InputError(
            field,
            f"{path!r}: unsupported figure format {('.' + ext) if ext else '(no suffix)'}",
            "a file name ending in " + ", ".join("." + t for t in sorted(types)),
        )
    check_writable_path(path, field)


# ---------------------------------------------------------------------------------------------
# output
# ---------------------------------------------------------------------------------------------
def workspace_checked(res):
    """``res`` with its sampled workspace check computed, for the summary printed next: the command
    line shows it, and warns where the design is over its specification away from its poses."""
    ws = getattr(res, "workspace", None)
    if ws is not None:
        ws.line()
    return res


def emit_json(obj) -> None:
    print(json.dumps(jsonable(obj), indent=2))


def inputs_record(args, mech: Mechanism | None = None, **resolved) -> dict:
    """What a ``--json`` output records about its inputs: the package version, the command, every
    argument as given, the model (name, title, file) and the resolved values (mm, rad and
    tolerance units), so that the run can be repeated and audited."""
    given = {k: v for k, v in vars(args).items() if k not in ("func", "task")}
    rec = {"tolsynth_version": version(), "command": getattr(args, "command", None), "arguments": given}
    if mech is not None:
        rec["model"] = {"name": mech.name, "title": mech.title, "file": str(getattr(mech.spec, "path", "") or "")}
        rec["error_parameters"] = list(mech.error_parameters)
        rec["tolerance_units"] = dict(zip(mech.error_parameters, mech.units))
    rec.update(resolved)
    return jsonable(rec)


def add_table_out_argument(p: argparse.ArgumentParser, what: str, option: str = "--out") -> None:
    """``--out FILE.csv|.json|.parquet``: the result as a table, inputs recorded."""
    p.add_argument(
        option,
        default=None,
        metavar="FILE",
        help=f"write {what} to FILE: .csv (plain, metadata in FILE.json), .json, .parquet or .xlsx, with "
        "every input and the package version recorded (needs pandas, Parquet pyarrow: pip install "
        '"tolsynth[tables]"; Excel openpyxl: pip install "tolsynth[xlsx]"); default: none',
    )


def check_table_out(args, option: str = "--out") -> None:
    """Before any work: the table file's suffix is known, pandas (pyarrow) installed, the folder writable."""
    path = getattr(args, option.lstrip("-").replace("-", "_"))
    if path is not None:
        from tolsynth.io.tables import check_table_path

        check_table_path(path, option)
        check_writable_path(path, option)


def write_out(frame, args, mech: Mechanism | None = None, option: str = "--out", **resolved) -> None:
    """Write ``frame`` to the file of ``option``, with the command line's inputs beside the library's."""
    from tolsynth.io.tables import write_table

    path = getattr(args, option.lstrip("-").replace("-", "_"))
    if path is None:
        return
    frame.attrs.setdefault("inputs", {})
    frame.attrs["inputs"] = dict(frame.attrs["inputs"], command_line=inputs_record(args, mech, **resolved))
    write_table(frame, path, option)


def fmt_p(p: float) -> str:
    """A probability with enough digits that 1 - p keeps six significant ones (``0.99``, and
    ``0.999999999999`` rather than ``1``): near 1 the shortfall is the specification."""
    for digits in range(6, 18):
        text = f"{p:.{digits}g}"
        if abs((1.0 - float(text)) - (1.0 - p)) <= 5e-7 * abs(1.0 - p):
            return text
    return repr(float(p))


def fmt_vec(v, fmt="{:.6g}") -> str:
    return "(" + ", ".join(fmt.format(x) for x in np.asarray(v).ravel()) + ")"


def add_model_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--model",
        required=True,
        help="bundled model name (see tolsynth.bundled_models()) or path to a .toml model file",
    )


def parse_distribution(text: str):
    """``--dist``: one shape for every error (``uniform``, ``normal``, ``triangular``, ``truncnormal``,
    ``truncnormal(3)``), or per parameter: ``*=uniform,h2=normal``."""
    from tolsynth.probability.distributions import shape

    text = text.strip()
    if "=" not in text:
        shape(text)
        return text
    out = {}
    for part in text.split(","):
        if "=" not in part:
            raise InputError(
                "--dist", f"{part!r} in a per-parameter list", "name=shape pairs, e.g. *=uniform,h2=normal"
            )
        k, v = (s.strip() for s in part.split("=", 1))
        try:
            shape(v)
        except InputError as exc:
            raise InputError(
                "--dist", f"{k}={v}: {exc}", "uniform, normal, triangular, truncnormal, truncnormal(beta)"
            ) from None
        out[k] = v
    return out


def dist_for(args, mech):
    """``--dist`` resolved against the model (not given: the model file's own shapes, else uniform)."""
    from tolsynth.probability.distributions import resolve

    return resolve(args.dist, mech)


def dist_label(distribution) -> str:
    from tolsynth.probability.distributions import label

    return label(distribution)


def add_dist_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--dist",
        type=_arg_type(parse_distribution, "distribution"),
        default=None,
        help="distribution of each error in its band: uniform (variance eps^2/3), normal (3 sigma = eps), "
        "triangular (eps^2/6), truncnormal or truncnormal(beta) (sigma = eps/beta cut at +-eps); "
        "or per parameter, e.g. '*=uniform,h2=normal'; default: the model file's, else uniform",
    )


def _verify_arg(text: str):
    """``--verify``: ``auto`` or a sample count >= 1000."""
    if text.strip() == "auto":
        return "auto"
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: expected auto or a whole number of samples >= 1000") from None
    if n < 1000:
        raise argparse.ArgumentTypeError(f"{n}: expected auto or a whole number of samples >= 1000")
    return n


def add_specification_arguments(
    p: argparse.ArgumentParser, solvers=("auto", "ipopt", "sumt"), worst_case: bool = False
) -> None:
    """The arguments of one tolerance specification, shared by ``solve`` and ``report``: model, R, p,
    distribution, cost (alpha, k, bounds), solver, poses, orientation, criterion, probability,
    verification and locked tolerances.  ``solvers``: the ``--solver`` choices; ``worst_case``:
    ``--probability worst_case`` offered (then ``--p`` is optional; the command checks it)."""
    add_model_argument(p)
    p.add_argument(
        "--R", type=length_mm("--R"), required=True, help="position accuracy radius, mm (or with a suffix: 500um)"
    )
    p.add_argument(
        "--p",
        type=number("--p", "0 < p < 1"),
        required=not worst_case,
        default=None,
        help="probability per principal component (or of the sphere), 0 < p < 1"
        + (
            "; not needed with --probability worst_case (given: the statistical design's cost is shown beside it)"
            if worst_case
            else ""
        ),
    )
    add_dist_argument(p)
    p.add_argument(
        "--alpha",
        default=None,
        help="cost exponent: VALUE for every parameter, name=VALUE or pattern=VALUE overrides "
        "(e.g. 0.7,alpha*=0.5); default: 0.7",
    )
    p.add_argument(
        "--k",
        default=None,
        help="cost factors k in sum k eps^-alpha: VALUE, name=VALUE, pattern=VALUE; default: the model's",
    )
    p.add_argument(
        "--bounds",
        default=None,
        help="tolerance bounds LOW:HIGH (either side may be empty: the model's), for every parameter "
        "or as name=LOW:HIGH / pattern=LOW:HIGH; in each parameter's tolerance unit or with a "
        "suffix (h*=5um:0.2mm); default: the model's",
    )
    both = "; both: IPOPT and SUMT + Powell side by side" if "both" in solvers else ""
    p.add_argument("--solver", choices=list(solvers), default="auto", help=f"{SOLVER_HELP}{both}")
    p.add_argument(
        "--pose",
        action="append",
        default=None,
        help=f"{POSE_HELP}; repeat the option for several poses (the constraints hold at each); {DEFAULT_POSE_HELP}",
    )
    p.add_argument(
        "--Phi",
        type=half_angle_rad("--Phi"),
        default=None,
        help="orientation accuracy half-angle, rad (or with a suffix: 2mrad, 0.1deg); default: none",
    )
    p.add_argument(
        "--p-orientation",
        dest="p_orientation",
        type=number("--p-orientation", "0 < p < 1"),
        default=None,
        help="probability of the orientation specification, 0 < p < 1; default: --p",
    )
    p.add_argument(
        "--criterion",
        choices=["components", "sphere"],
        default="components",
        help="per principal component (the paper's Eq. 20) or the sphere P(|dr| <= R) >= p",
    )
    p.add_argument(
        "--probability",
        choices=["gaussian", "exact"] + (["worst_case"] if worst_case else []),
        default=None,
        help="exact (the default: the exact probabilities of the linear error model, along every "
        "direction or in the sphere) or gaussian (the paper's: each principal component read as normal; "
        "--solver both always reads it)"
        + ("; worst_case: every error anywhere in its band, the hand still within R (no p)" if worst_case else ""),
    )
    p.add_argument(
        "--verify",
        default=None,
        type=_verify_arg,
        metavar="N|auto",
        help="close the loop: nonlinear Monte Carlo at the optimum with N samples per pose (auto: from p), "
        "and a tighter target until its 99%% lower bound reaches p; default: off",
    )
    p.add_argument(
        "--lock",
        action="append",
        default=None,
        metavar="NAME=VALUE",
        help="fix a tolerance at VALUE (its tolerance unit); repeatable; the others are optimised around it",
    )


#: what each ``--solver`` value runs (solve, report and sweep say the same)
SOLVER_HELP = (
    "auto: the compiled interior-point method where it applies (per-component Gaussian criterion, "
    "power-law costs), IPOPT elsewhere; ipopt: IPOPT with exact derivatives always; sumt: the "
    "paper's SUMT + Powell; every result certified the same way. With --probability exact, the "
    "solver only finds the Gaussian optimum the exact interior-point method starts from"
)
TOLERANCES_HELP = (
    "SET | VALUE | name=VALUE,... | SET,name=VALUE,...; patterns such as *=0.02 or h*=0.01; "
    "bare numbers in each parameter's tolerance unit, or with a unit suffix (0.1mm, 5um, 2mrad, 0.01deg)"
)
POSE_HELP = (
    "configuration name, or joint values in deg (a strut or slide in mm), comma-separated (a suffix "
    "such as 1.2rad allowed)"
)
#: the default of every --pose, the library's rule (tolsynth.analysis.design_pose)
DEFAULT_POSE_HELP = (
    "default: the model's design pose, as tolsynth.synthesize takes it (its 'worst' configuration, else the "
    "worst-pose search's pose at mid-bound tolerances)"
)


def add_pose_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments of a one-pose analysis: model, pose, tolerances, distribution, R, Phi."""
    add_model_argument(p)
    p.add_argument("--pose", default=None, help=f"{POSE_HELP}; {DEFAULT_POSE_HELP}")
    p.add_argument("--tolerances", required=True, help=TOLERANCES_HELP)
    add_dist_argument(p)
    p.add_argument(
        "--R", type=length_mm("--R"), required=True, help="radius of the accuracy sphere, mm (or with a suffix: 500um)"
    )
    p.add_argument(
        "--Phi",
        type=half_angle_rad("--Phi"),
        default=None,
        help="orientation cone half-angle, rad (or with a suffix: 2mrad, 0.1deg); default: none",
    )
