"""Accuracy over the workspace: the worst-error pose search and the probability map (Figure 3).

This module gathers, for convenience and for older imports, what now lives in

* :mod:`tolsynth.pose_search` -- :func:`worst_pose`, :class:`WorstPose`;
* :mod:`tolsynth.workspace_map` -- :func:`probability_map`, :class:`ProbabilityMap` (with the
  inverse kinematics of :mod:`tolsynth.ik`);
* :mod:`tolsynth.plot` -- :func:`plot_map`;
* :mod:`tolsynth.batch_stats` -- :func:`principal_std_batch`.

>>> import tolsynth
>>> m = tolsynth.load_model("xu_zhang_1988")
>>> w = tolsynth.worst_pose(m, "figure3", criterion="sigma")
>>> bool(w.value >= w.reference_value)
True
"""

from __future__ import annotations

from .batch_stats import principal_std_batch
from .ik import PLANES
from .plot import plot_map
from .pose_search import WorstPose, worst_pose
from .workspace_map import ProbabilityMap, probability_map

__all__ = [
    "WorstPose",
    "ProbabilityMap",
    "worst_pose",
    "probability_map",
    "plot_map",
    "principal_std_batch",
    "PLANES",
]
