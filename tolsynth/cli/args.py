"""Argument helpers shared by the sub-commands: poses, tolerances, JSON output."""

from __future__ import annotations

import argparse
import json
import math

import numpy as np

from ..errors import InputError
from ..mechanism import Mechanism

__all__ = ["add_pose_arguments", "parse_pose", "parse_tolerances", "emit_json", "fmt_vec"]


def parse_pose(mech: Mechanism, text: str):
    """A configuration name, or comma-separated joint values in degrees."""
    if text in mech.configurations:
        return text
    try:
        values = [math.radians(float(v)) for v in text.split(",")]
    except ValueError:
        raise InputError(
            "--pose", f"{text!r} is neither a configuration nor joint values",
            "one of " + ", ".join(mech.configurations) + f", or {len(mech.joint_names)} comma-separated angles in deg",
        ) from None
    return np.array(values)


def parse_tolerances(mech: Mechanism, text: str) -> np.ndarray:
    """``SET``, ``name=value,...`` (every parameter) or ``SET,name=value,...`` (overrides)."""
    parts = [p.strip() for p in text.split(",") if p.strip()]
    base: dict[str, float] = {}
    overrides: dict[str, float] = {}
    for part in parts:
        if "=" in part:
            name, _, value = part.partition("=")
            key = mech.error_parameters[mech.index(name.strip())]  # UnknownNameError for a bad name
            try:
                overrides[key] = float(value)
            except ValueError:
                raise InputError("--tolerances", f"{part!r}: {value!r} is not a number", "name=value") from None
        else:
            if base:
                raise InputError("--tolerances", "more than one tolerance set named", "one SET, then name=value overrides")
            base = dict(zip(mech.error_parameters, mech.tolerances(part)))
    base.update(overrides)
    return mech.tolerances(base)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else str(v)
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def emit_json(obj) -> None:
    print(json.dumps(_jsonable(obj), indent=2))


def fmt_vec(v, fmt="{:.6g}") -> str:
    return "(" + ", ".join(fmt.format(x) for x in np.asarray(v).ravel()) + ")"


def add_pose_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments of a one-pose analysis: model, pose, tolerances, distribution, R, Phi."""
    p.add_argument("--model", required=True, help="bundled model name or path to a .toml file")
    p.add_argument("--pose", default="worst", help="configuration name or joint angles in deg, comma-separated")
    p.add_argument("--tolerances", required=True, help="SET | name=value,... | SET,name=value,...")
    p.add_argument("--dist", choices=["uniform", "normal"], default="uniform")
    p.add_argument("--R", type=float, required=True, help="radius of the accuracy sphere (mm)")
    p.add_argument("--Phi", type=float, default=None, help="orientation cone half-angle (rad)")
