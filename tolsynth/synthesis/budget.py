"""Budget mode: the best accuracy a given cost buys.

The optimal cost ``C*(R, p)`` is non-increasing in ``R`` and non-decreasing in ``p`` (a looser
specification has a larger feasible set).  So the smallest ``R`` a budget ``B`` buys at a given
``p`` (or the largest ``p`` at a given ``R``) is bracketed by certified bisection:

* an upper end ``R_hi`` where a solve returns tolerances that meet the specification (checked
  independently by the solver's feasibility test) at cost ``<= B``: the budget buys ``R_hi``;
* a lower end ``R_lo`` where the certified lower bound exceeds ``B`` (or the specification is
  infeasible at every tolerance): no tolerances within the budget reach ``R_lo``.

The true answer lies in ``[R_lo, R_hi]``; the bisection stops when the bracket is within ``rtol``.
A solve that is neither (not certified, cost above ``B`` but bound below) stops the search with
``certified = False`` rather than guessing.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

from tolsynth.errors import InfeasibleSpecificationError, InputError

__all__ = ["best_accuracy", "BudgetResult"]


@dataclass(frozen=True)
class BudgetResult:
    """What a budget buys.

    Attributes
    ----------
    quantity : str
        ``"R"`` (smallest radius, mm, at the given p) or ``"p"`` (largest probability at the given R).
    value : float
        The certified achievable end of the bracket (``R_hi``, or ``p_lo``).
    bracket : (float, float)
        The optimum lies in it (``(R_lo, R_hi)`` or ``(p_lo, p_hi)``).
    result : SynthesisResult
        Tolerances that meet the specification at ``value`` within the budget.
    budget : float
    certified : bool
        True when both ends are certified (see the module docstring).
    solves : int
    wall_time : float
    """

    quantity: str
    value: float
    bracket: tuple
    result: object
    budget: float
    certified: bool
    solves: int
    wall_time: float
    log: list = field(default_factory=list, repr=False)


def best_accuracy(
    mechanism,
    budget: float,
    *,
    p: float | None = None,
    R: float | None = None,
    distribution=None,
    rtol: float = 1e-4,
    max_solves: int = 80,
    **kwargs,
) -> BudgetResult:
    """The smallest R at a given p (give ``p``), or the largest p at a given R (give ``R``), that
    tolerances costing at most ``budget`` achieve.  With ``probability="worst_case"`` give neither:
    the smallest R whose worst case (every error anywhere in its band) the budget buys.

    Keyword arguments are those of :func:`tolsynth.synthesize` (alpha, k, cost, locks, bounds,
    pose, poses, ...).

    Examples
    --------
    >>> import tolsynth
    >>> out = tolsynth.best_accuracy("xu_zhang_1988", 100.0, p=0.99)
    >>> out.bracket[0] <= out.value  # doctest: +SKIP
    True
    """
    from tolsynth.checks import check_count, check_positive, check_probability
    from tolsynth.kinematics.mechanism import as_mechanism
    from tolsynth.synthesis.single import STARTING_SOLVERS, synthesize

    mechanism = as_mechanism(mechanism)
    budget = check_positive(budget, "budget", "cost units")
    # the bracket's width in ln R (or logit p): NaN would end the bisection at once with R = 1
    rtol = check_positive(rtol, "rtol", "width of the bracket in ln R or logit p", upper=1.0)
    max_solves = check_count(max_solves, "max_solves", lower=2, upper=10_000)
    worst_case = kwargs.get("probability") == "worst_case"
    if worst_case:  # no probability to search or to hold: the smallest worst-case R is the answer
        for name, value in (("R", R), ("p", p)):
            if value is not None:
                raise InputError(
                    name,
                    f"{name}={value!r} with probability='worst_case', which reads no p (there is no p to "
                    + ("search at a given R)" if name == "R" else "hold while R is searched)"),
                    "neither p nor R: the smallest R whose worst case the budget buys",
                )
    elif (p is None) == (R is None):
        raise InputError("p/R", "give exactly one of them", "p (then the smallest R is found) or R (the largest p)")
    t0 = time.perf_counter()
    solves = 0
    log = []
    x0 = None

    def verdict(spec_R, spec_p):
        """'buys' (result), 'cannot' (None), or 'unknown' (result)."""
        nonlocal solves, x0
        solves += 1
        try:
            res = synthesize(mechanism, spec_R, spec_p, distribution, x0=x0, **kwargs)
        except InfeasibleSpecificationError:
            log.append({"R": spec_R, "p": spec_p, "verdict": "infeasible"})
            return "cannot", None
        if res.feasible and res.cost <= budget:  # (a met design buys it, proven optimal or not)
            x0 = res.x if kwargs.get("solver") in STARTING_SOLVERS else None
            out = "buys"
        elif res.lower_bound > budget:
            out = "cannot"
        else:
            out = "unknown"
        log.append({"R": spec_R, "p": spec_p, "cost": res.cost, "lower_bound": res.lower_bound, "verdict": out})
        return out, res

    if p is not None or worst_case:
        p = None if worst_case else check_probability(p, "p")
        to_x, from_x = math.log, math.exp  # bisection in ln R
        spec = lambda x: (from_x(x), p)  # noqa: E731
        good_is_high = True  # a larger R is easier
        x = math.log(1.0)
        x_range = (math.log(1e-9), math.log(1e6))  # 1 nm to 1 km
    else:
        R = check_positive(R, "R")
        to_x = lambda q: math.log(q / (1 - q))  # noqa: E731  (logit)
        from_x = lambda t: 1.0 / (1.0 + math.exp(-t))  # noqa: E731
        spec = lambda x: (R, from_x(x))  # noqa: E731
        good_is_high = False  # a larger p is harder
        x = to_x(0.9)
        x_range = (-27.0, 27.0)  # p within 1e-12 of 0 and 1
    good = bad = None
    good_res = None
    step = math.log(4.0)
    certified = True
    # bracket: walk until one end buys and the other cannot
    while (good is None or bad is None) and solves < max_solves:
        v, res = verdict(*spec(x))
        if v == "unknown":
            certified = False
            break
        if v == "buys":
            good, good_res = x, res
            x = x - step if good_is_high else x + step
        else:
            bad = x
            x = x + step if good_is_high else x - step
        if not x_range[0] <= x <= x_range[1]:
            break
    if good is None:
        raise InfeasibleSpecificationError(
            "budget",
            budget,
            f"the budget {budget:g} buys no accuracy in the searched range (its lowest cost exceeds it)",
        )
    if bad is None:  # everything tried is affordable: report the best end tried, bracket open
        certified = False
        bad = good - 1 if good_is_high else good + 1
    while certified and abs(good - bad) > rtol and solves < max_solves:
        mid = 0.5 * (good + bad)
        v, res = verdict(*spec(mid))
        if v == "unknown":
            # the budget lies within this solve's gap, so the answer lies within about the gap's
            # worth of x of mid: two solves that far to either side decide the bracket there
            slope = _slope(log, to_x, p is not None or worst_case)
            if slope is None or not slope > 0:
                certified = False
                break
            delta = 4.0 * (res.cost - res.lower_bound) / slope + 1e-12 * max(1.0, abs(mid))
            toward_good = delta if good > bad else -delta
            v_good, r_good = verdict(*spec(mid + toward_good))
            v_bad, _ = verdict(*spec(mid - toward_good))
            if v_good != "buys" or v_bad != "cannot":
                certified = False
                break
            good, good_res, bad = mid + toward_good, r_good, mid - toward_good
            break
        if v == "buys":
            good, good_res = mid, res
        else:
            bad = mid
    ends = sorted([from_x(good), from_x(bad)])
    return BudgetResult(
        quantity="R" if p is not None or worst_case else "p",
        value=from_x(good),
        bracket=tuple(ends),
        result=good_res,
        budget=budget,
        certified=certified and abs(good - bad) <= rtol,
        solves=solves,
        wall_time=time.perf_counter() - t0,
        log=log,
    )


def _slope(log: list, to_x, in_R: bool) -> float | None:
    """The cost's fall per unit of x (ln R, or logit p with the sign turned) between the two solves
    of the log nearest the last one: what a budget straddled by a solve's gap needs to step past it."""
    pts = [(to_x(e["R"] if in_R else e["p"]), e["cost"]) for e in log[:-1] if "cost" in e]
    if len(pts) < 2:
        return None
    last = to_x(log[-1]["R"] if in_R else log[-1]["p"])
    (x1, c1), (x2, c2) = sorted(pts, key=lambda t: abs(t[0] - last))[:2]
    if x1 == x2:
        return None
    s = (c1 - c2) / (x1 - x2)
    return -s if in_R else s  # cost falls as R grows, rises as p grows
