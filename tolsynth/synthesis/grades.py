"""Standard grades: the optimal tolerances rounded to ISO 286 IT grades (or a user's own grade
table), the cheapest combination that still meets the specification, with a proven optimum.

A drawing does not carry ``eps = 0.0794 mm``: it carries a grade.  :func:`round_to_grades` takes a
continuous optimum (:func:`tolsynth.synthesize`, any probability: Gaussian, exact or worst case)
and chooses one grade per parameter: for lengths the ISO 286-1 grades at the parameter's nominal
size (half the IT width: a symmetric zone, :mod:`tolsynth.model.iso286`), or the values of a
user's table (angles need one: ISO 286 has no angular grades).  Grades outside a parameter's
bounds are not offered; locked parameters keep their value.

The choice is a branch and bound over the grade indices (the method of "A designer's cost",
:mod:`tolsynth.synthesis.processes`, on the discrete values).  A node restricts each parameter to
a run of consecutive grades; its bound is the certified lower bound of the continuous problem on
the box those grades span (every grade combination of the node is a point of that box, with the
same cost), and never below the cost of every parameter at its coarsest grade.  A leaf is one
combination, checked directly: its constraint values at those tolerances (the same probability as
the result: principal sigmas for the Gaussian one, the exact probabilities along the worst
direction, or the exact zonotope maximum for the worst case) at most 1.  The first incumbent is
every tolerance rounded down to the next finer grade, which meets the specification because every
constraint value grows with each tolerance; coarsening steps that keep it feasible improve it.  So
the answer is never dearer than rounding down, and it is proven optimal when every node is closed
(``lower_bound`` the smallest bound left, the gap within ``rel_gap``).
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from dataclasses import dataclass, field

import numpy as np

from tolsynth.checks import check_count
from tolsynth.errors import InfeasibleSpecificationError, InputError, OutOfRangeError
from tolsynth.problem.result import optimality_gap
from tolsynth.synthesis.grade_tables import (
    API_NAMES,
    _candidates,
    _no_grade_message,
    _read_sizes,
    _size_of,
    grade_candidates,
)
from tolsynth.synthesis.grades_eval import _achieved, constraint_values, meets
from tolsynth.tabular import Tabular

__all__ = ["GradeChoice", "round_to_grades", "grade_candidates", "constraint_values", "meets", "API_NAMES"]


@dataclass(frozen=True)
class GradeChoice(Tabular):
    """The proven cheapest grade per parameter.

    Attributes
    ----------
    grades : dict
        Parameter -> grade label (``"IT7"``, a user table's label, or ``"locked"``).
    tolerances : dict
        Parameter -> the grade's symmetric tolerance, in the parameter's tolerance unit.
    cost, continuous_cost : float
        The grades' cost and the continuous optimum's; ``cost_increase`` their difference
        (``relative_increase`` over the continuous cost).
    lower_bound, gap, proven
        A certified lower bound over every grade combination, ``cost - lower_bound``, and whether
        the gap is within ``rel_gap`` of the cost with every node closed.
    probability : str
        The result's probability (``"gaussian"``, ``"exact"``, ``"worst_case"``).
    achieved : float
        The smallest probability any constraint achieves at the grades (1.0: the worst case holds).
    values : list
        Per constraint block: its value at the grades (``<= 1`` meets it).
    rounded_down : dict
        Every tolerance rounded down to the next finer grade: ``{"grades", "cost"}``.
    nodes, combinations : int
        Continuous problems solved plus combinations checked; what brute force would check.
    """

    grades: dict
    tolerances: dict
    units: dict
    cost: float
    continuous_cost: float
    lower_bound: float
    gap: float
    proven: bool
    probability: str
    achieved: float
    values: list
    rounded_down: dict
    nodes: int
    combinations: int
    wall_time: float
    sizes: dict = field(default_factory=dict)
    continuous: dict = field(default_factory=dict, repr=False)
    log: list = field(default_factory=list, repr=False)

    @property
    def cost_increase(self) -> float:
        return self.cost - self.continuous_cost

    @property
    def relative_increase(self) -> float:
        return self.cost_increase / self.continuous_cost

    def summary(self) -> str:
        lines = [
            f"standard grades: cost {self.cost:.8g}, {100 * self.relative_increase:+.2f} % over the continuous "
            f"optimum {self.continuous_cost:.8g} (lower bound {self.lower_bound:.8g}, "
            f"{'proven' if self.proven else 'NOT proven'}); {self.nodes} solves and checks for "
            f"{self.combinations} combinations",
            f"rounding every tolerance down to the next finer grade instead: cost {self.rounded_down['cost']:.8g}",
            f"achieved ({self.probability} probability): {self.achieved:.8g}; largest constraint value "
            f"{max(self.values):.6f}",
        ]
        for name, g in self.grades.items():
            size = f" at {self.sizes[name]:g} mm" if name in self.sizes else ""
            lines.append(
                f"  {name:>8}: {g:<8} eps = {self.tolerances[name]:.6g} {self.units[name]}{size} "
                f"(continuous {self.continuous[name]:.6g})"
            )
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {
            "grades": self.grades,
            "tolerances": self.tolerances,
            "units": self.units,
            "cost": self.cost,
            "continuous_cost": self.continuous_cost,
            "cost_increase": self.cost_increase,
            "relative_increase": self.relative_increase,
            "lower_bound": self.lower_bound,
            "gap": self.gap,
            "proven": self.proven,
            "probability": self.probability,
            "achieved": self.achieved,
            "values": list(self.values),
            "rounded_down": self.rounded_down,
            "nodes": self.nodes,
            "combinations": self.combinations,
            "sizes": self.sizes,
            "continuous": self.continuous,
            "wall_time": self.wall_time,
        }


# ---------------------------------------------------------------------------------------------
# the search
# ---------------------------------------------------------------------------------------------
def round_to_grades(
    mechanism, result, sizes=None, table=None, *, rel_gap: float = 1e-6, max_nodes: int = 5000
) -> GradeChoice:
    """The cheapest standard grades meeting ``result``'s specification, with a proven optimum.

    Parameters
    ----------
    mechanism : Mechanism or str
        The model ``result`` was solved on.
    result : SynthesisResult
        A continuous optimum of :func:`tolsynth.synthesize` (any probability).
    sizes : dict or float or str, optional
        Nominal size per length parameter for its ISO 286 grades, in mm or as a string with a
        length unit (``300``, ``"0.3m"``, ``{"l1": "300mm"}``); one size for every length, or a
        dict (default: the nominal value of the dimension it perturbs; a parameter of nominal
        size 0 must be given one).
    table : dict, optional
        Parameter name, pattern (``"o*"``) or ``"*"`` -> {grade label: tolerance}: a user's own
        grades, which angles need (ISO 286 has none for them).  A bare number is in the
        parameter's tolerance unit (``mechanism.units``: planar_2r's angles are in mrad); a string
        with a unit suffix (``"0.2mrad"``, ``"0.01deg"``) is converted to it.
    rel_gap, max_nodes
        Optimality tolerance of the search (relative to the cost) and its limit of solves and
        checks (then ``proven`` is False).

    Examples
    --------
    planar_2r's angle tolerances are in mrad, so its grade table's bare numbers are mrad:

    >>> import tolsynth
    >>> res = tolsynth.synthesize("planar_2r", R=0.5, p=0.99)
    >>> g = tolsynth.round_to_grades("planar_2r", res, sizes=300,
    ...                              table={"o*": {"A": 0.1, "B": 0.2, "C": 0.5, "D": 1.0}})
    >>> g.grades
    {'l1': 'IT12', 'l2': 'IT12', 'o1': 'B', 'o2': 'D'}
    >>> round(g.cost, 4), g.proven
    (11.2629, True)
    """
    from tolsynth.kinematics.mechanism import as_mechanism

    mechanism = as_mechanism(mechanism)
    t0 = time.perf_counter()
    max_nodes = check_count(max_nodes, "max_nodes", lower=1)
    if not (isinstance(rel_gap, (int, float)) and math.isfinite(rel_gap) and 0 <= rel_gap < 1):
        raise OutOfRangeError("rel_gap", f"got {rel_gap!r}", "0 <= rel_gap < 1")
    spec = getattr(result, "spec", None)
    if spec is None or not hasattr(result, "tolerances"):
        raise InputError("result", f"got {type(result).__name__}", "a SynthesisResult of tolsynth.synthesize")
    if tuple(spec.names) != tuple(mechanism.error_parameters):
        raise InputError("result", "solved on another model's parameters", f"a result of {mechanism.name}")
    if not result.success:
        raise InputError("result", f"not an optimum ({result.status}: {result.message})", "a successful result")
    probability = (result.inputs or {}).get("probability") or "gaussian"
    sizes = _read_sizes(mechanism, sizes, API_NAMES)
    candidates, sources = _candidates(mechanism, sizes, table, API_NAMES)
    search = _Search(mechanism, result, spec, probability, candidates, sources)
    return search.run(rel_gap, max_nodes, t0, sizes)


class _Search:
    def __init__(self, mechanism, result, spec, probability, candidates, sources=None):
        self.mech, self.result, self.spec, self.prob = mechanism, result, spec, probability
        self.costs = spec.costs
        self.lower, self.upper = np.asarray(spec.lower, dtype=float), np.asarray(spec.upper, dtype=float)
        self.eps_c = np.asarray(result.x, dtype=float)
        self.free, self.labels, self.values = [], {}, {}
        for i, name in enumerate(spec.names):
            if self.lower[i] == self.upper[i]:
                continue  # locked: keeps its value
            cand = [
                (g, v)
                for g, v in candidates[name].items()
                if self.lower[i] * (1 - 1e-12) <= v <= self.upper[i] * (1 + 1e-12)
            ]
            if not cand:
                raise InfeasibleSpecificationError(
                    f"grades[{name}]",
                    float(self.eps_c[i]),
                    _no_grade_message(
                        name, spec.units[i], (self.lower[i], self.upper[i]), candidates[name], (sources or {}).get(name)
                    ),
                )
            self.free.append(i)
            self.labels[i] = [g for g, _ in cand]
            self.values[i] = np.array([v for _, v in cand])
        self.checks = self.solves = 0
        self.feasible_memo: dict[tuple, bool] = {}

    # -- points -----------------------------------------------------------------------------
    def point(self, choice: tuple) -> np.ndarray:
        eps = self.eps_c.copy()
        for i, j in zip(self.free, choice):
            eps[i] = self.values[i][j]
        return eps

    def cost(self, choice: tuple) -> float:
        return self.costs.cost(self.point(choice))

    def feasible(self, choice: tuple) -> bool:
        if choice not in self.feasible_memo:
            self.checks += 1
            self.feasible_memo[choice] = meets(self.spec, self.prob, self.point(choice))
        return self.feasible_memo[choice]

    def round_down(self, eps, node=None) -> tuple:
        out = []
        for k, i in enumerate(self.free):
            lo, hi = node[k] if node is not None else (0, len(self.values[i]) - 1)
            vals = self.values[i][lo : hi + 1]
            below = np.nonzero(vals <= eps[i] * (1 + 1e-12))[0]
            out.append(lo + (int(below[-1]) if len(below) else 0))
        return tuple(out)

    def improve(self, choice: tuple, node=None) -> tuple:
        """Coarsen one grade at a time, the largest saving first, while the specification holds."""
        choice = list(choice)
        while True:
            best, best_k = 0.0, None
            base = self.cost(tuple(choice))
            for k, i in enumerate(self.free):
                hi = node[k][1] if node is not None else len(self.values[i]) - 1
                if choice[k] >= hi:
                    continue
                trial = choice.copy()
                trial[k] += 1
                saving = base - self.cost(tuple(trial))
                if saving > best and self.feasible(tuple(trial)):
                    best, best_k = saving, k
            if best_k is None:
                return tuple(choice)
            choice[best_k] += 1

    # -- relaxations --------------------------------------------------------------------------
    def relax(self, node):
        """The continuous problem on the node's box: (certified bound, optimum or None)."""
        from tolsynth.synthesis.single import synthesize

        lo, hi = self.lower.copy(), self.upper.copy()
        for (a, b), i in zip(node, self.free):
            lo[i], hi[i] = self.values[i][a], self.values[i][b]
        trivial = self.costs.cost(hi)  # every cost falls with its tolerance
        spec = self.spec
        # the paper's power law as k and alpha: the compiled method's closed forms serve it; no x0:
        # the parent's optimum clipped to the box breaks the specification and costs IPOPT 40-80
        # iterations
        cost = None if spec.costs.power_law() is not None else list(spec.costs.models)
        kw = dict(
            bounds=(lo, hi),
            poses=list(spec.poses.values()),
            Phi=spec.Phi,
            alpha=spec.alpha,
            k=spec.k,
            cost=cost,
            probability=self.prob,
        )
        if self.prob != "worst_case":
            kw.update(
                p=spec.p, distribution=spec.distribution, p_orientation=spec.p_orientation, criterion=spec.criterion
            )
        self.solves += 1
        try:
            res = synthesize(self.mech, spec.R, **kw)
        except InfeasibleSpecificationError:
            return math.inf, None
        bound = max(trivial, res.lower_bound) if math.isfinite(res.lower_bound) else trivial
        return bound, (res.x if res.success else None)

    def lagrangian(self, eps):
        """Separable weights ``(w, q, T)`` of a Lagrangian at a relaxation's optimum:
        ``cost(e) >= sum_i [c_i(e_i) + w_i e_i^q] - T`` wherever the specification holds (weak
        duality; any multipliers give a valid bound), or None where none is at hand (the exact
        probabilities, the sphere)."""
        spec = self.spec
        if self.prob == "worst_case":
            from tolsynth.solvers.worst_case import lagrangian_weights

            w, T = lagrangian_weights(spec, eps)
            return w, 1.0, T
        if self.prob == "gaussian" and not spec.sphere_blocks:
            from tolsynth.problem.nlp import ToleranceNLP

            nlp = ToleranceNLP(spec)
            w, T = nlp.dual_weights(nlp.kkt_multipliers(np.asarray(eps, dtype=float)))
            return w, 2.0, T
        return None

    def lagrangian_bound(self, node, lag) -> float:
        """``min over the node's grades of the Lagrangian``: separable, one small minimum per parameter."""
        if lag is None:
            return -math.inf
        w, q, T = lag
        total = -T
        fixed = np.ones(len(self.eps_c), dtype=bool)
        for (a, b), i in zip(node, self.free):
            vals = self.values[i][a : b + 1]
            total += float(np.min(self.costs.models[i].cost(vals) + w[i] * vals**q))
            fixed[i] = False
        for i in np.nonzero(fixed)[0]:  # locked parameters: their value
            total += float(self.costs.models[i].cost(self.eps_c[i]) + w[i] * self.eps_c[i] ** q)
        return total

    # -- branch and bound ----------------------------------------------------------------------
    def run(self, rel_gap, max_nodes, t0, sizes) -> GradeChoice:
        combos = int(np.prod([len(self.values[i]) for i in self.free])) if self.free else 1
        down = self.round_down(self.eps_c)
        down_cost = self.cost(down)
        if not self.feasible(down):
            raise InfeasibleSpecificationError(
                "grades",
                down_cost,
                "the tolerances rounded down to the next finer grade do not meet the "
                "specification: the continuous optimum is not feasible, or a tolerance lies "
                "below every grade inside its bounds",
            )
        inc = self.improve(down)
        inc_cost = self.cost(inc)
        root = tuple((0, len(self.values[i]) - 1) for i in self.free)
        heap = [(-math.inf, 0, root, self.lagrangian(self.eps_c))]
        counter = itertools.count(1)
        closed: list[float] = []
        log = []
        while heap:
            bound, _, node, lag = heapq.heappop(heap)
            if bound >= inc_cost * (1 - rel_gap):
                closed.append(bound)
                continue
            if self.solves + self.checks >= max_nodes:
                heapq.heappush(heap, (bound, next(counter), node, lag))
                break
            if all(a == b for a, b in node):
                choice = tuple(a for a, _ in node)
                c = self.cost(choice)
                if self.feasible(choice) and c < inc_cost:
                    inc, inc_cost = choice, c
                closed.append(c if self.feasible(choice) else math.inf)
                continue
            nb, eps = self.relax(node)
            lag = self.lagrangian(eps) if eps is not None else lag
            # the node's own multipliers over its grades alone: at least the box's bound where
            # they are the box's optimal ones (the grades are a subset of the box)
            nb = max(nb, bound, self.lagrangian_bound(node, lag))
            log.append({"node": [b - a + 1 for a, b in node], "bound": nb})
            if not math.isfinite(nb) or nb >= inc_cost * (1 - rel_gap):
                closed.append(nb)
                continue
            if eps is None:  # the relaxation's solve did not succeed (its bound holds): split in the middle
                eps = self.point(tuple((a + b) // 2 for a, b in node))
            cand = self.improve(self.round_down(eps, node), node)
            if self.feasible(cand) and self.cost(cand) < inc_cost:
                inc, inc_cost = cand, self.cost(cand)
            k, split = self._branch(node, eps)
            a, b = node[k]
            for part in ((a, split - 1), (split, b)):
                child = node[:k] + (part,) + node[k + 1 :]
                cb = max(nb, self.lagrangian_bound(child, lag))  # a child's grades are a subset
                if cb >= inc_cost * (1 - rel_gap):
                    closed.append(cb)
                    continue
                heapq.heappush(heap, (cb, next(counter), child, lag))
        lower = min([inc_cost] + closed + [b for b, *_ in heap])
        gap = optimality_gap(inc_cost, lower)
        eps = self.point(inc)
        values = constraint_values(self.spec, self.prob, eps)
        names = self.spec.names
        grades = {n: "locked" for n in names}
        for i, j in zip(self.free, inc):
            grades[names[i]] = self.labels[i][j]
        return GradeChoice(
            grades=grades,
            tolerances=dict(zip(names, map(float, eps))),
            units=dict(zip(names, self.spec.units)),
            cost=inc_cost,
            continuous_cost=float(self.result.cost),
            lower_bound=lower,
            gap=gap,
            proven=not heap and gap <= rel_gap * abs(inc_cost) + 1e-12,
            probability=self.prob,
            achieved=_achieved(self.spec, self.prob, values),
            values=[float(v) for v in values],
            rounded_down={"grades": {names[i]: self.labels[i][j] for i, j in zip(self.free, down)}, "cost": down_cost},
            nodes=self.solves + self.checks,
            combinations=combos,
            wall_time=time.perf_counter() - t0,
            sizes=_sizes_used(self.mech, sizes, self.free),
            continuous=dict(zip(names, map(float, self.eps_c))),
            log=log,
        )

    def _branch(self, node, eps) -> tuple[int, int]:
        """The parameter whose rounding down costs most at the relaxation's point, split there."""
        best, best_k, best_split = -1.0, None, None
        for k, ((a, b), i) in enumerate(zip(node, self.free)):
            if a == b:
                continue
            vals = self.values[i]
            below = np.nonzero(vals[a : b + 1] <= eps[i] * (1 + 1e-12))[0]
            j = a + (int(below[-1]) if len(below) else 0)
            split = j + 1 if a <= j < b else (a + b + 1) // 2
            loss = float(self.costs.models[i].cost(vals[j]) - self.costs.models[i].cost(eps[i]))
            if loss > best:
                best, best_k, best_split = loss, k, split
        return best_k, best_split


def _sizes_used(mechanism, sizes, free) -> dict:
    out = {}
    for i in free:
        par = mechanism.parameters[i]
        if par.kind == "length":
            try:
                out[par.name] = float(_size_of(mechanism, par, sizes))
            except (InputError, TypeError, ValueError):
                continue
    return out
