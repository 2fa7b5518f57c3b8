"""The report's figures: each pose's contribution bars and the probability map, as PNG bytes."""

from __future__ import annotations

import io

from tolsynth.errors import MissingDependencyError
from tolsynth.io.report_layout import PLOT_INSTALL


def _figures(rep, dpi: int) -> dict[str, bytes]:
    try:
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
    except ImportError:
        raise MissingDependencyError("matplotlib", "the report's figures", PLOT_INSTALL) from None

    out = {}

    def png(fig) -> bytes:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
        plt.close(fig)
        return buf.getvalue()

    c = rep.contributions
    for b in range(len(c.poses)):
        fig, ax = plt.subplots(figsize=(min(11.0, max(6.0, 0.75 * len(c.names))), 3.4))
        c.plot(pose=b, ax=ax)
        ax.legend(fontsize="small", ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.12), frameon=False)
        if len(c.names) > 12:
            ax.tick_params(axis="x", labelrotation=90)
        out[f"contributions_{b}"] = png(fig)
    if rep.map is not None:
        from dataclasses import replace

        from tolsynth.analysis.plot import plot_map

        out["map"] = png(plot_map(replace(rep.map, tolerance_label="optimal")))
    return out
