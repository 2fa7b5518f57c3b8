"""Figures (matplotlib, the optional extra ``plot``; imported only when a figure is drawn)."""

from __future__ import annotations

import math

import numpy as np

from tolsynth.errors import InputError
from tolsynth.kinematics.ik import PLANES

__all__ = ["plot_map"]

_AXIS_NAMES = "XYZ"


def plot_map(pmap, path=None, ax=None, levels=None):
    """Labelled contour lines of a :class:`ProbabilityMap` (needs matplotlib, extra ``plot``).

    Parameters
    ----------
    pmap : ProbabilityMap
    path : str or path, optional
        Save the figure there (PNG, PDF, ... by suffix).
    ax : matplotlib Axes, optional
    levels : sequence of float, optional
        Contour levels (probabilities); default: steps of 0.05 or 0.1 inside the map's range.

    Returns
    -------
    matplotlib.figure.Figure
    """
    try:
        import matplotlib

        if ax is None and path is not None:
            matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover
        raise ImportError("plot_map needs matplotlib: pip install 'tolsynth[plot]'") from exc

    iu, iv, _ = PLANES[pmap.plane]
    if ax is None:
        fig, ax = plt.subplots(figsize=(8.0, 8.6))
    else:
        fig = ax.figure
    P = pmap.P
    reach = np.isfinite(P)
    if not reach.any():
        raise InputError(
            "pmap",
            f"no point of the {pmap.plane} plane's grid is reachable: nothing to draw",
            "a map with reachable points",
        )
    if levels is None:
        lo_p, hi_p = np.nanmin(P), np.nanmax(P)
        span = hi_p - lo_p
        step = 0.1 if span > 0.6 else 0.05 if span > 0.2 else 0.02 if span > 0.08 else 0.005 if span > 0.02 else None
        if step is None:  # nearly flat: let matplotlib choose
            from matplotlib.ticker import MaxNLocator

            levels = MaxNLocator(8).tick_values(lo_p, hi_p)
        else:
            levels = np.arange(math.floor(lo_p / step) * step + step, hi_p, step)
        levels = levels[(levels > lo_p) & (levels < hi_p)]
        if levels.size == 0:
            levels = [0.5 * (lo_p + hi_p)]
    digits = max(2, int(math.ceil(-math.log10(max(np.min(np.diff(levels)) if len(levels) > 1 else 0.01, 1e-12)))))
    U, V = np.meshgrid(pmap.u, pmap.v)
    # the reachable region: light fill, its boundary, then the labelled contours of P inside it
    # the boundary is the zero contour of the joint-limit margin (smooth where a limit binds)
    mg = np.where(np.isfinite(pmap.limit_margin), pmap.limit_margin, -1.0)
    mg = np.where(reach, np.maximum(mg, 0.0), np.minimum(mg, -1e-12))  # the margin's sign = reachability
    ax.contourf(U, V, mg, levels=[0.0, np.inf], colors=["#eef3fa"])
    ax.contour(U, V, mg, levels=[0.0], colors="0.35", linewidths=1.2)
    cs = ax.contour(U, V, P, levels=levels, cmap="viridis_r", linewidths=1.1)
    ax.clabel(cs, fmt=lambda x: f"{x:.{digits}f}", fontsize=8, inline=True)
    wu, wv, wp = pmap.worst
    ax.plot(
        [wu],
        [wv],
        marker="v",
        color="crimson",
        ms=9,
        ls="none",
        label=f"lowest P on the map: {wp:.3f} at ({wu:.0f}, {wv:.0f}) mm",
    )
    if pmap.reference_point is not None:
        ru, rv = pmap.reference_point
        ax.plot(
            [ru],
            [rv],
            marker="*",
            color="black",
            ms=12,
            ls="none",
            label=f"configuration '{pmap.reference}' ({ru:.0f}, {rv:.0f}) mm, P = {pmap.reference_P:.3f}",
        )
    an, bn = _AXIS_NAMES[iu], _AXIS_NAMES[iv]
    ax.set_xlabel(f"{an}0 (mm)")
    ax.set_ylabel(f"{bn}0 (mm)")
    ax.set_aspect("equal")
    ax.grid(True, color="0.9", lw=0.5)
    ax.set_title(
        f"{pmap.model}: P(|dr| <= {pmap.R:g} mm), {pmap.distribution} errors, tolerances "
        f"'{pmap.tolerance_label}'\nlinear + Gaussian model (Eq. 5); blank = not reachable",
        fontsize=10,
    )
    deg = lambda x: f"{math.degrees(x):g} deg"  # noqa: E731
    axis_txt = (
        "hand z axis "
        + "("
        + ", ".join(f"{c:g}" for c in pmap.hand_axis)
        + ")"
        + (" = vertical, up" if pmap.hand_axis is not None and np.allclose(pmap.hand_axis, [0, 0, 1]) else "")
        if pmap.hand_axis is not None
        else "hand orientation free"
    )
    lines = [
        f"plane {pmap.plane} at {'XYZ'[PLANES[pmap.plane][2]]}0 = {pmap.offset:g} mm; {axis_txt}",
        "held: " + ("; ".join(f"{k} = {deg(v)} ({why})" for k, (v, why) in pmap.fixed.items()) or "none"),
        "IK on the fk graph (Levenberg-Marquardt), branch: " + pmap.branch,
        "reachable = IK solution inside all joint limits"
        + (" and " + "; ".join(pmap.constraints) if pmap.constraints else ""),
    ]
    import textwrap

    text = "\n".join(textwrap.fill(line, 110, subsequent_indent="   ") for line in lines)
    fig.text(0.02, 0.01, text, fontsize=7, va="bottom", ha="left", family="monospace")
    ax.legend(loc="upper left", fontsize=8, framealpha=0.9)
    fig.subplots_adjust(bottom=0.2, top=0.92)
    if path is not None:
        fig.savefig(path, dpi=130)
    return fig
