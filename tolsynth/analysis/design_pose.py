"""The model's default design pose: the one rule for the pose a design is made at when none is given.

:func:`tolsynth.synthesize` and :func:`tolsynth.sweep` (through :func:`resolve_design_pose`), the
designs built on them and every command of the command line (through :func:`default_design_pose`)
take it, and :func:`tolsynth.validate` checks plain tolerances there, so that the same request
gives the same design through every door.  The rule: the model's configuration ``worst`` if it
has one (the paper's pose of largest error, or the one a model file's author found); else the pose
of largest principal sigma at the geometric middle of the tolerance bounds, found by
:func:`worst_pose` (deterministic, remembered per mechanism); else, if that search fails, the
model's first configuration.  A parallel robot's ``reference`` configuration (``home``) is the pose
its searches and maps compare with, not its design pose.  Units: joint values in rad (mm for a
sliding joint).
"""

from __future__ import annotations

import numpy as np

__all__ = ["default_design_pose", "resolve_design_pose"]


def default_design_pose(mechanism) -> tuple:
    """``(pose, note)``: the model's default design pose (see the module docstring) and the sentence
    that says how it was chosen (None for the model's own ``worst`` configuration)."""
    if "worst" in mechanism.configurations:
        return "worst", None
    known = mechanism.__dict__.get("_default_design_pose")
    if known is not None:
        return known
    from tolsynth.analysis.pose_search import worst_pose
    from tolsynth.errors import TolsynthError

    lo, hi = (np.asarray(b, dtype=float) for b in mechanism.bounds)
    try:
        w = worst_pose(mechanism, np.sqrt(lo * hi), criterion="sigma", reference=None)
        q = np.asarray(w.q, dtype=float)
        out = (
            q,
            f"the worst-pose search's pose q = {mechanism.format_joints(q)} "
            "(largest principal sigma at the middle of the bounds; the model has no 'worst' configuration)",
        )
    except TolsynthError:
        first = next(iter(mechanism.configurations))
        out = (first, f"the model's first configuration {first!r} (it has no 'worst' one; the pose search failed)")
    # the search takes seconds on a six-joint arm; a mechanism is immutable, so its answer stands
    mechanism.__dict__["_default_design_pose"] = out
    return out


def resolve_design_pose(mechanism, pose=None, poses=None) -> tuple:
    """``(pose, note)`` for a design request: ``pose`` as given, unless neither ``pose`` nor
    ``poses`` is given, or ``pose="worst"`` (the keyword's documented default, so a model without
    that configuration is not an error): then the model's default design pose and its note."""
    if poses is not None:
        return pose, None
    if pose is None or (isinstance(pose, str) and pose == "worst"):
        return default_design_pose(mechanism)
    return pose, None
