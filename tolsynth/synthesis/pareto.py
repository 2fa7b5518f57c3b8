"""Pareto fronts: optimal cost against R (at a given p) or against p (at a
given R), optionally with discrete process choice (then a staircase).

Every point is a certified optimum (:func:`tolsynth.synthesize`, or
:func:`tolsynth.synthesize_processes` with processes); the sweep gives each solve the previous
point's tolerances as its start (IPOPT and SUMT start there; the default compiled method needs no
start).  The paper's columns (the model's ``reference_results`` with the
same p, distribution and alpha) are marked on the plot at their own printed tolerances' cost.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from tolsynth.checks import check_positive, check_probability
from tolsynth.errors import InfeasibleSpecificationError, InputError
from tolsynth.problem.specification import ALPHA_DEFAULT

__all__ = ["pareto_front", "ParetoFront"]


@dataclass(frozen=True)
class ParetoFront:
    """Optimal cost along a sweep of R or p.

    Attributes
    ----------
    axis : str
        ``"R"`` (mm) or ``"p"``.
    rows : list of dict
        Per point: ``R``, ``p``, ``cost``, ``lower_bound``, ``success``, ``probability`` (the
        kind the design meets; and ``processes`` with process choice); an infeasible point has
        ``cost = inf``.
    reference : list of dict
        The paper's columns on this sweep: ``table``, ``R``, ``p``, ``cost`` of the printed
        tolerances.
    wall_time : float
    """

    axis: str
    rows: list
    reference: list
    wall_time: float

    def table(self):
        """A pandas DataFrame if pandas is installed, else the list of dicts."""
        try:
            import pandas as pd
        except ImportError:
            return self.rows
        return pd.DataFrame(self.rows)

    def plot(self, ax=None):
        """Cost against the swept quantity (matplotlib, lazily), the paper's columns marked."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(5.5, 3.5))
        x = [r[self.axis] for r in self.rows]
        y = [r["cost"] for r in self.rows]
        staircase = any("processes" in r for r in self.rows)
        ax.plot(x, y, "-o", ms=3, drawstyle="default", label="optimum" + (" (process choice)" if staircase else ""))
        for ref in self.reference:
            ax.plot(ref[self.axis], ref["cost"], "r*", ms=10)
            ax.annotate(
                ref["table"], (ref[self.axis], ref["cost"]), fontsize="small", xytext=(4, 4), textcoords="offset points"
            )
        if self.reference:
            ax.plot([], [], "r*", label="paper's printed tolerances")
        ax.set_xlabel("R, mm" if self.axis == "R" else "p")
        ax.set_ylabel("cost")
        ax.legend(fontsize="small")
        return ax


def pareto_front(
    mechanism, *, R=None, p=None, distribution=None, alpha=ALPHA_DEFAULT, processes=None, **kwargs
) -> ParetoFront:
    """Sweep one of R (mm, or strings with a unit: ``["500um", "1mm"]``) or p (give a sequence)
    with the other fixed (a number).

    ``processes`` (as :func:`tolsynth.synthesize_processes`) makes each point a process choice.
    Other keyword arguments go to :func:`tolsynth.synthesize`.

    Examples
    --------
    >>> import tolsynth
    >>> front = tolsynth.pareto_front("xu_zhang_1988", R=[0.5, 1.0, 2.0], p=0.99)
    >>> [round(r["cost"], 1) for r in front.rows]  # doctest: +SKIP
    """
    from tolsynth.kinematics.mechanism import as_mechanism
    from tolsynth.problem.nlp import ToleranceNLP
    from tolsynth.problem.specification import make_specification
    from tolsynth.synthesis.single import STARTING_SOLVERS, synthesize

    mechanism = as_mechanism(mechanism)
    R_seq, p_seq = np.ndim(R) == 1, np.ndim(p) == 1
    if R_seq == p_seq or R is None or p is None:
        raise InputError(
            "R/p", "give one as a sequence (the sweep) and the other as a number", "e.g. R=[0.25, 0.5, 1.0], p=0.99"
        )
    axis = "R" if R_seq else "p"
    # R in mm or with a unit ("500um"), as synthesize reads it; checked here, before any solve
    if R_seq:
        values = sorted(check_positive(v, f"R[{i}]") for i, v in enumerate(R))
        p = check_probability(p, "p")
    else:
        values = sorted(check_probability(v, f"p[{i}]") for i, v in enumerate(p))
        R = check_positive(R, "R")
    if not values:
        raise InputError(axis, "empty sweep", "at least one value")
    t0 = time.perf_counter()
    rows = []
    x0 = None
    for v in values:
        Rv, pv = (v, p) if R_seq else (R, v)
        try:
            if processes is not None:
                from tolsynth.synthesis.processes import synthesize_processes

                pc = synthesize_processes(mechanism, Rv, pv, processes, distribution, alpha=alpha, **kwargs)
                rows.append(
                    {
                        "R": Rv,
                        "p": pv,
                        "cost": pc.cost,
                        "lower_bound": pc.lower_bound,
                        "success": pc.proven,
                        "probability": pc.result.probability_kind,
                        "processes": pc.processes,
                    }
                )
            else:
                res = synthesize(mechanism, Rv, pv, distribution, alpha, x0=x0, **kwargs)
                x0 = res.x if res.success and kwargs.get("solver") in STARTING_SOLVERS else None
                rows.append(
                    {
                        "R": Rv,
                        "p": pv,
                        "cost": res.cost,
                        "lower_bound": res.lower_bound,
                        "success": res.success,
                        "probability": res.probability_kind,
                    }
                )
        except InfeasibleSpecificationError:
            rows.append({"R": Rv, "p": pv, "cost": float("inf"), "lower_bound": float("inf"), "success": False})
    reference = []
    for ref in getattr(mechanism.spec, "reference_results", ()) or ():
        from tolsynth.probability.distributions import resolve

        same = (
            ref.distribution == resolve(distribution, mechanism)
            and np.isscalar(alpha)
            and abs(ref.alpha - float(alpha)) < 1e-12
        )
        fixed_ok = abs(ref.p - p) < 1e-12 if R_seq else abs(ref.R - R) < 1e-12
        swept = ref.R if R_seq else ref.p
        # the printed tolerances' cost under the model's own cost (the probability and the solver
        # change the optimum beside it, not that cost)
        same_cost = not set(kwargs) - {"probability", "solver", "options", "time_limit"}
        if same and fixed_ok and values[0] <= swept <= values[-1] and processes is None and same_cost:
            spec = make_specification(mechanism, ref.R, ref.p, ref.distribution, ref.alpha)
            reference.append(
                {
                    "table": ref.table,
                    "R": ref.R,
                    "p": ref.p,
                    "cost": ToleranceNLP(spec).cost(np.asarray(ref.tolerances, dtype=float)),
                }
            )
    return ParetoFront(axis, rows, reference, time.perf_counter() - t0)
