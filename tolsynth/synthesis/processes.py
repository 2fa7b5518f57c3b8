"""Discrete process choice with a proven optimum.

Each parameter may be made by one of several processes (turning, grinding, lapping, ...), each
with its own cost model (:mod:`tolsynth.model.cost`) and the tolerance range ``[lower, upper]`` it can
hold.  :func:`synthesize_processes` picks one process per parameter and the tolerances within it
at minimum total cost, by branch and bound; Chase et al. 1990 select processes by exhaustive
search, which this replaces.

Bounds.  A node fixes the process of some parameters and leaves a set ``S_i`` of processes open
for the others.  For any positive semi-definite multipliers ``Z`` the Lagrangian separates per
parameter (:meth:`tolsynth.problem.nlp.ToleranceNLP.dual_weights`), so

    min over the node's choices and tolerances of the cost
        >= sum_i min over p in S_i of min over [lo_p, hi_p] of (c_p(u) + w_i(Z) e^{2u}) - tr Z

(weak duality, the inner 1-D minima global: :meth:`tolsynth.model.cost.CostModel.dual_min`).  That is
the node's certified lower bound whatever Z is; Z is taken from the optimum of a continuous
relaxation in which each open parameter's cost is the lower convex hull (in ``eps^2``) of its
processes' costs over the union of their ranges.  A leaf (every process fixed) is the continuous
problem, solved and certified by :func:`tolsynth.synthesize`.  Nodes whose bound is not below the
incumbent (within ``rel_gap``) are pruned; the optimum is proven when every node is closed, and
``lower_bound`` is the smallest bound over the closed nodes and leaves.

Other probability models.  The Lagrangian above reads the Gaussian constraint; with
``probability="exact"`` or ``"worst_case"`` its multipliers bound nothing.  A node's bound is then
the cheapest cost inside the node's ranges (every tolerance at its cheapest point: a bound for any
constraint at all, loose), and a leaf's bound is its own solve's certified ``lower_bound`` where that
solve succeeded (else the same box bound).  The relaxations still guide the branching and the
rounding; the search is proven only by those valid bounds, so it may solve more leaves.
"""

from __future__ import annotations

import heapq
import itertools
import math
import time
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from tolsynth.errors import InfeasibleSpecificationError, InputError
from tolsynth.model.cost import CostModel, Tabulated
from tolsynth.model.process import Process
from tolsynth.problem.result import optimality_gap

__all__ = ["Process", "ProcessChoice", "synthesize_processes", "enumerate_processes"]

#: knots of the relaxation's hull table
_HULL_KNOTS = 24
#: the probability models a process choice accepts (each with a valid bound, see the docstring)
_PROBABILITIES = ("gaussian", "exact", "worst_case")


@dataclass(frozen=True)
class ProcessChoice:
    """The proven cheapest process per parameter and the tolerances within it.

    Attributes
    ----------
    result : SynthesisResult
        The continuous optimum at the chosen processes (its own certificate).
    processes : dict
        Parameter -> chosen process name (only the parameters given processes).
    cost, lower_bound, gap : float
        The optimum's cost, a certified lower bound over *every* process choice, and their
        difference; ``proven`` when the gap is within ``rel_gap`` of the cost.
    nodes : int
        Continuous problems solved (relaxations and leaves).
    combinations : int
        Number of process combinations (what brute force would solve).
    rounded : dict or None
        The continuous relaxation at the root rounded to a process per parameter (the cheapest
        process whose range holds its tolerance, else the nearest): ``{"processes", "cost"}``.
    wall_time : float
        Seconds.
    """

    result: object
    processes: dict
    cost: float
    lower_bound: float
    gap: float
    proven: bool
    nodes: int
    combinations: int
    rounded: dict | None = None
    wall_time: float = 0.0
    log: list = field(default_factory=list, repr=False)

    @property
    def tolerances(self) -> dict:
        """The chosen tolerances, name -> value in tolerance units (those of :attr:`result`)."""
        return self.result.tolerances

    def summary(self) -> str:
        """Readable summary: cost, bound, whether proven, and the process and tolerance per parameter."""
        lines = [
            f"process choice: cost {self.cost:.8g} (lower bound {self.lower_bound:.8g}, "
            f"{'proven' if self.proven else 'NOT proven'}); {self.nodes} solves for "
            f"{self.combinations} combinations"
        ]
        if self.rounded:
            lines.append(f"rounding the continuous relaxation instead: cost {self.rounded['cost']:.8g}")
        # every parameter, those the table gives no process keeping the model's own cost
        for nm, eps in self.result.tolerances.items():
            proc = self.processes.get(nm, "model cost")
            lines.append(f"  {nm:>8}: {proc:<12} eps = {eps:.6g} {self.result.units[nm]}")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """Plain dict for JSON (processes, cost, bound, gap, proof, search size, tolerances, time)."""
        return {
            "processes": self.processes,
            "cost": self.cost,
            "lower_bound": self.lower_bound,
            "gap": self.gap,
            "proven": self.proven,
            "nodes": self.nodes,
            "combinations": self.combinations,
            "rounded": self.rounded,
            "tolerances": self.result.tolerances,
            "wall_time": self.wall_time,
        }


def _hull_model(procs: list[Process]) -> tuple[Tabulated, float, float]:
    """Lower convex hull in (eps^2, cost) of the processes' costs over their ranges, as a table."""
    ys, cs = [], []
    for pr in procs:
        e = (
            np.exp(np.linspace(math.log(pr.lower), math.log(pr.upper), 33))
            if pr.upper > pr.lower
            else np.array([pr.lower])
        )
        ys.append(e**2)
        cs.append(pr.cost.cost(e))
    y, c = np.concatenate(ys), np.concatenate(cs)
    order = np.lexsort((c, y))
    y, c = y[order], c[order]
    hull: list[int] = []
    for i in range(len(y)):
        if hull and y[hull[-1]] == y[i]:
            continue
        while len(hull) >= 2:
            a, b = hull[-2], hull[-1]
            if (c[b] - c[a]) * (y[i] - y[a]) >= (c[i] - c[a]) * (y[b] - y[a]):
                hull.pop()
            else:
                break
        hull.append(i)
    hy, hc = y[hull], c[hull]
    stop = int(np.argmin(hc)) + 1  # beyond the cheapest point a looser tolerance only costs more
    hy, hc = hy[:stop], hc[:stop]
    if len(hy) < 2:  # one point: a flat table on a tiny range
        hy = np.array([hy[0], hy[0] * (1 + 1e-9)])
        hc = np.array([hc[0], hc[0]])
    # resampled on a fixed number of knots, so every relaxation shares one compiled NLP
    e = np.exp(np.linspace(0.5 * math.log(hy[0]), 0.5 * math.log(hy[-1]), _HULL_KNOTS))
    c = np.interp(e**2, hy, hc)
    table = Tabulated(e, np.maximum.accumulate(c[::-1])[::-1])
    return table, table.eps[0], table.eps[-1]


def located(exc: InputError, where: str) -> InputError:
    """``exc`` (same type, same ``allowed``) with ``where`` in front of its text: a table of many
    processes needs the parameter and process named, a file its name, to find the bad entry."""
    err = type(exc)(where, str(exc))
    err.field, err.allowed = f"{where}: {exc.field}", exc.allowed
    return err


def normalise_processes(mechanism, processes) -> dict[str, list[Process]]:
    """Parameter name -> list of :class:`Process` from ``processes`` (Process objects or dicts
    ``{name, cost, lower, upper}``); a typed error naming the parameter and process otherwise."""
    if not isinstance(processes, Mapping) or not processes:
        raise InputError("processes", f"got {processes!r}", "a dict parameter name -> list of processes")
    out = {}
    for key, plist in processes.items():
        try:
            nm = mechanism.error_parameters[mechanism.index(key)]
        except InputError as exc:
            raise located(exc, f"processes: parameter {key}") from None
        if isinstance(plist, (Process, Mapping)) or not hasattr(plist, "__len__") or len(plist) == 0:
            raise InputError(f"processes[{key}]", "expected a non-empty list", "a list of processes")
        procs = []
        for j, item in enumerate(plist):
            try:
                procs.append(Process.make(item, mechanism.units[mechanism.index(nm)]))
            except InputError as exc:
                name = item.get("name") if isinstance(item, Mapping) else getattr(item, "name", None)
                which = f"process {name!r}" if name is not None else f"process {j + 1}"
                raise located(exc, f"processes: parameter {key}, {which}") from None
        names = [p.name for p in procs]
        if len(set(names)) != len(names):
            raise InputError(f"processes[{key}]", f"duplicate process names {names}", "distinct names")
        out[nm] = procs
    return out


class _Search:
    def __init__(self, mechanism, R, p, distribution, procs, kwargs):
        from tolsynth.synthesis.single import synthesize

        self.synth = synthesize
        self.mech, self.R, self.p, self.dist = mechanism, R, p, distribution
        self.procs = procs
        self.names = list(procs)
        self.kwargs = dict(kwargs)
        self.user_cost = self.kwargs.pop("cost", None) or dict(mechanism.cost_models)
        if isinstance(self.user_cost, (CostModel, list, tuple)) or (
            isinstance(self.user_cost, Mapping) and "model" in self.user_cost
        ):
            raise InputError(
                "cost",
                "with processes, give per-parameter costs as a dict name -> model",
                "a dict for the parameters without processes",
            )
        self.user_bounds = self.kwargs.pop("bounds", None)
        from tolsynth.synthesis.single import DEFAULT_PROBABILITY

        prob = self.kwargs.get("probability")
        prob = DEFAULT_PROBABILITY if prob is None else prob
        if not isinstance(prob, str) or prob not in _PROBABILITIES:
            raise InputError("probability", f"got {prob!r}", " or ".join(repr(s) for s in _PROBABILITIES))
        self.probability = self.kwargs["probability"] = prob
        # the worst case reads no p (and compares with no statistical design at each node): a p
        # given with it would be ignored, so it is refused; every other reading needs one
        if prob == "worst_case" and p is not None:
            raise InputError(
                "p",
                f"{p!r} with probability='worst_case' (every error anywhere in its band: no probability)",
                "no p with probability='worst_case', or a statistical probability ('exact', 'gaussian') with it",
            )
        if prob != "worst_case" and p is None:
            raise InputError("p", "missing", "0 < p < 1 (only probability='worst_case' reads no p)")
        self.solves = 0
        self.leaf_cache: dict[tuple, object] = {}

    def _solve(self, models: dict, ranges: dict):
        from tolsynth.model.locks import apply_locks

        bounds = apply_locks(self.mech, self.user_bounds, {})
        bounds.update(ranges)
        cost = dict(self.user_cost)
        cost.update(models)
        self.solves += 1
        try:
            return self.synth(self.mech, self.R, self.p, self.dist, bounds=bounds, cost=cost, **self.kwargs)
        except InfeasibleSpecificationError:
            return None

    def leaf(self, choice: tuple):
        if choice not in self.leaf_cache:
            models = {nm: self.procs[nm][j].cost for nm, j in zip(self.names, choice)}
            ranges = {nm: (self.procs[nm][j].lower, self.procs[nm][j].upper) for nm, j in zip(self.names, choice)}
            self.leaf_cache[choice] = self._solve(models, ranges)
        return self.leaf_cache[choice]

    def relax(self, node: tuple):
        """Relaxation at a node: its certified bound, its tolerances (or None) and the result."""
        models, ranges = {}, {}
        for nm, S in zip(self.names, node):
            # every listed parameter as a hull table of the same size (a fixed process too): one
            # compiled NLP serves every relaxation; the bound's validity does not depend on it
            hull, _, _ = _hull_model([self.procs[nm][j] for j in S])
            models[nm], ranges[nm] = hull, (hull.eps[0], hull.eps[-1])
        res = self._solve(models, ranges)
        if res is None:  # even the relaxation's range cannot meet it: no choice in the node can
            return math.inf, None, None
        return self.node_bound(res, node), res.x, res

    def box_bound(self, spec, node) -> float:
        """The cheapest cost inside the node's ranges (its processes' for the listed parameters, the
        specification's bounds for the others): a lower bound whatever the constraint is."""
        open_set = dict(zip(self.names, node))
        zero = np.zeros(1)
        total = 0.0
        for i, nm in enumerate(spec.names):
            if nm in open_set:
                total += min(
                    float(pr.cost.dual_min(zero, math.log(pr.lower), math.log(pr.upper))[0][0])
                    for pr in (self.procs[nm][j] for j in open_set[nm])
                )
            else:
                total += float(
                    spec.costs.models[i].dual_min(zero, math.log(spec.lower[i]), math.log(spec.upper[i]))[0][0]
                )
        return total

    def leaf_bound(self, choice: tuple, res) -> float:
        """A leaf's certified lower bound: its solve's own where that is valid (the Gaussian dual
        bound holds for any multipliers; another probability's only when its solve succeeded)."""
        if res is None:
            return math.inf
        if self.probability == "gaussian" or res.success:
            return res.lower_bound
        return self.box_bound(res.spec, tuple((j,) for j in choice))

    def node_bound(self, res, node) -> float:
        from tolsynth.problem.nlp import ToleranceNLP

        if self.probability != "gaussian":  # the Gaussian Lagrangian does not bound these
            return self.box_bound(res.spec, node)

        nlp = ToleranceNLP(res.spec)
        best = -math.inf
        for Z in (nlp.kkt_multipliers(res.x),):
            w, trace = nlp.dual_weights(Z)
            total = -trace
            index = {nm: i for i, nm in enumerate(res.spec.names)}
            open_set = {nm: S for nm, S in zip(self.names, node)}
            for i, nm in enumerate(res.spec.names):
                if nm in open_set:
                    vals = [
                        self.procs[nm][j].cost.dual_min(
                            np.array([w[i]]), math.log(self.procs[nm][j].lower), math.log(self.procs[nm][j].upper)
                        )[0][0]
                        for j in open_set[nm]
                    ]
                    total += min(vals)
                else:
                    total += res.spec.costs.models[i].dual_min(np.array([w[i]]), nlp.lu[i], nlp.uu[i])[0][0]
            del index
            best = max(best, float(total))
        return best

    def round(self, node, eps) -> tuple:
        """Per open parameter: the cheapest process holding eps_i, else the nearest range."""
        choice = []
        for k, (nm, S) in enumerate(zip(self.names, node)):
            e = eps[self.mech.index(nm)]
            inside = [j for j in S if self.procs[nm][j].lower * (1 - 1e-9) <= e <= self.procs[nm][j].upper * (1 + 1e-9)]
            if inside:
                choice.append(min(inside, key=lambda j: float(self.procs[nm][j].cost.cost(e))))
            else:
                dist = [abs(math.log(e / min(max(e, self.procs[nm][j].lower), self.procs[nm][j].upper))) for j in S]
                choice.append(S[int(np.argmin(dist))])
        return tuple(choice)


def synthesize_processes(
    mechanism,
    R: float,
    p: float | None = None,
    processes=None,
    distribution=None,
    *,
    rel_gap: float = 1e-6,
    max_nodes: int = 10_000,
    **kwargs,
) -> ProcessChoice:
    """Cheapest process per parameter and tolerances within it, with a proven optimum.

    Parameters
    ----------
    mechanism : Mechanism or str
    R, p, distribution
        As :func:`tolsynth.synthesize`; with ``probability="worst_case"`` no p (one given is an
        :class:`InputError`: the worst case reads none).
    processes : dict
        Parameter name -> list of :class:`Process` (or dicts ``{name, cost, lower, upper}``).
        Parameters not listed keep their cost model and bounds.
    rel_gap : float
        Optimality tolerance of the search, relative to the cost, from 0 to 1.
    max_nodes : int
        Limit on the continuous solves, at least 2 (the root's relaxation and its rounding); a
        search stopped by it says ``proven = False``.
    **kwargs
        Further arguments of :func:`tolsynth.synthesize` (pose, poses, Phi, alpha, k, cost for the
        parameters without processes, bounds, ...).

    Returns
    -------
    ProcessChoice

    Examples
    --------
    >>> import tolsynth
    >>> from tolsynth.model.cost import PowerLaw
    >>> from tolsynth.synthesis.processes import Process
    >>> procs = {"h3": [Process("turning", PowerLaw(1.0, 0.7), 0.05, 0.5),
    ...                 Process("grinding", PowerLaw(3.0, 0.7), 0.005, 0.05)]}
    >>> best = tolsynth.synthesize_processes("xu_zhang_1988", R=0.5, p=0.99, processes=procs)
    >>> best.processes["h3"], best.proven  # doctest: +SKIP
    ('turning', True)
    """
    from tolsynth.checks import check_count, check_real
    from tolsynth.kinematics.mechanism import as_mechanism

    mechanism = as_mechanism(mechanism)
    rel_gap = check_real(rel_gap, "rel_gap", "(relative to the cost)", lower=0.0, upper=1.0)
    # the root's relaxation and its rounding are two solves: fewer cannot start the search
    max_nodes = check_count(max_nodes, "max_nodes", lower=2, upper=10**7)
    t0 = time.perf_counter()
    if processes is None:
        processes = mechanism.processes  # the model file's
    procs = normalise_processes(mechanism, processes)
    search = _Search(mechanism, R, p, distribution, procs, kwargs)
    names = search.names
    root = tuple(tuple(range(len(procs[nm]))) for nm in names)
    combinations = int(np.prod([len(procs[nm]) for nm in names]))
    incumbent, inc_choice = None, None
    closed_bounds: list[float] = []
    log = []

    def consider(choice):
        nonlocal incumbent, inc_choice
        res = search.leaf(choice)
        if res is not None and res.success and (incumbent is None or res.cost < incumbent.cost):
            incumbent, inc_choice = res, choice
        return res

    bound, eps, _ = search.relax(root)
    rounded = None
    if eps is not None:
        rc = search.round(root, eps)
        rres = consider(rc)
        rounded = {
            "processes": {nm: procs[nm][j].name for nm, j in zip(names, rc)},
            "cost": rres.cost if rres is not None and rres.success else math.inf,
        }
    heap = [(bound, 0, root, eps)]
    counter = itertools.count(1)
    while heap:
        bound, _, node, eps = heapq.heappop(heap)
        if incumbent is not None and bound >= incumbent.cost * (1 - rel_gap):
            closed_bounds.append(bound)
            continue
        if search.solves >= max_nodes:
            heapq.heappush(heap, (bound, next(counter), node, eps))
            break
        if all(len(S) == 1 for S in node):
            choice = tuple(S[0] for S in node)
            res = consider(choice)
            closed_bounds.append(search.leaf_bound(choice, res))
            continue
        if eps is None:
            closed_bounds.append(bound)
            continue
        # branch on the open parameter whose relaxed cost is furthest below its processes' cost
        gaps = []
        for k, (nm, S) in enumerate(zip(names, node)):
            if len(S) == 1:
                gaps.append(-math.inf)
                continue
            e = eps[mechanism.index(nm)]
            inside = [
                float(procs[nm][j].cost.cost(e))
                for j in S
                if procs[nm][j].lower * (1 - 1e-9) <= e <= procs[nm][j].upper * (1 + 1e-9)
            ]
            hull, _, _ = _hull_model([procs[nm][j] for j in S])
            gaps.append(
                (min(inside) if inside else math.inf) - float(hull.cost(min(max(e, hull.eps[0]), hull.eps[-1])))
            )
        k = int(np.argmax(gaps))
        for j in node[k]:
            child = node[:k] + ((j,),) + node[k + 1 :]
            if all(len(S) == 1 for S in child):
                cb, ce = -math.inf, None  # a leaf: solved when popped
                res = search.leaf(tuple(S[0] for S in child))
                cb = search.leaf_bound(tuple(S[0] for S in child), res)
                if res is not None and res.success and (incumbent is None or res.cost < incumbent.cost):
                    incumbent, inc_choice = res, tuple(S[0] for S in child)
            else:
                cb, ce, _ = search.relax(child)
                if ce is not None:
                    consider(search.round(child, ce))
            cb = max(cb, bound)  # a child's set is inside its parent's
            log.append({"node": [len(S) for S in child], "bound": cb})
            heapq.heappush(heap, (cb, next(counter), child, ce))
    if incumbent is None:
        raise InfeasibleSpecificationError(
            "processes", math.inf, "infeasible specification: no process combination meets it"
        )
    open_bounds = [b for b, *_ in heap]
    lower = min(closed_bounds + open_bounds + [search.leaf_bound(inc_choice, incumbent)])
    lower = min(lower, incumbent.cost)
    gap = optimality_gap(incumbent.cost, lower)
    return ProcessChoice(
        result=incumbent,
        processes={nm: procs[nm][j].name for nm, j in zip(names, inc_choice)},
        cost=incumbent.cost,
        lower_bound=lower,
        gap=gap,
        proven=not heap and gap <= rel_gap * abs(incumbent.cost) + 1e-12,
        nodes=search.solves,
        combinations=combinations,
        rounded=rounded,
        wall_time=time.perf_counter() - t0,
        log=log,
    )


def enumerate_processes(mechanism, R: float, p: float, processes, distribution=None, **kwargs):
    """Brute force: the continuous optimum of every process combination (for checks and figures).

    Returns a list of ``(choice dict, SynthesisResult or None if infeasible)``.
    """
    from tolsynth.kinematics.mechanism import as_mechanism

    mechanism = as_mechanism(mechanism)
    procs = normalise_processes(mechanism, processes)
    search = _Search(mechanism, R, p, distribution, procs, kwargs)
    out = []
    for choice in itertools.product(*(range(len(procs[nm])) for nm in search.names)):
        out.append(({nm: procs[nm][j].name for nm, j in zip(search.names, choice)}, search.leaf(choice)))
    return out
