"""``synthesize(..., probability="worst_case")``: the arithmetic (worst-case) stack-up.

Every error anywhere in its band, the hand stays within R: at each pose the error zonotope
``{sum_i s_i eps_i a_i : |s_i| <= 1}`` lies in the ball of radius R, i.e.

    h(eps) = max over sign patterns s of |sum_i s_i eps_i a_i| <= R,

and likewise for the orientation rows against Phi.  No probability and no distribution enter.
``h`` is a maximum of norms of linear maps of eps, so the feasible set is convex in eps; every cost
model here but a tabulated one is convex in eps, so the problem is convex (a tabulated cost may not
be: then only a closed gap certifies, as for the other solvers).

Method: an exchange over sign patterns.  IPOPT (exact Hessian) solves the problem restricted to a
finite set of pattern cuts ``|A diag(s) eps|^2 <= R^2`` (one second-order cone each, smooth when
squared); the exact ``h`` at its point (:func:`tolsynth.solvers.worst_case_zonotope.zonotope_max`,
O(n^2) cells of an arrangement of great circles, never the 2^n patterns) names the violated
patterns, which become new cuts, until none is violated.  The last point is scaled onto the
specification (``h`` is positively homogeneous of degree 1 in eps) where IPOPT left it a hair
outside.

Certificate: for a unit direction d, ``sum_i |d . a_i| eps_i <= h(eps) <= R`` holds for every
feasible eps (the zonotope's support function), so finitely many such direction cuts define a
relaxation, whose Lagrangian dual with any multipliers ``lambda >= 0`` separates per parameter:

    lower = sum_i min over [lo_i, hi_i] of (c_i(eps_i) + w_i eps_i) - sum_k lambda_k,
    w = B^T lambda,  B_ki = |d_k . a_i| / R_k,

each 1-D minimum global (closed form for the power law, bisection where ``c`` is convex in u, an
interval bound on a grid otherwise).  The directions are those of the active cuts at the solution,
where the pattern cut's tangent half-space is that direction cut; the multipliers are IPOPT's,
and those recomputed from stationarity at the point, whichever bound is higher.  ``success`` needs
IPOPT's success, ``h <= R (1 + 1e-6)`` by the exact maximum at the returned point, and a gap within
1e-6 of the cost.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from functools import lru_cache

import casadi as ca
import numpy as np

from tolsynth.errors import InfeasibleSpecificationError
from tolsynth.model.cost import Chase, Exponential, Given, PowerLaw
from tolsynth.problem.nlp import cost_graph
from tolsynth.problem.result import ConstraintBlock, Status, SynthesisResult, optimality_gap
from tolsynth.solvers.common import ACTIVE_TOL, FEAS_TOL, GAP_TOL
from tolsynth.solvers.ipopt import IPOPT_STATUS
from tolsynth.solvers.worst_case_zonotope import candidate_patterns, zonotope_max, zonotope_patterns

__all__ = ["DEFAULT_OPTIONS", "WorstCaseResult", "lagrangian_weights", "solve_worst_case", "worst_case_values"]

#: IPOPT's tolerances and iteration limit per cut NLP; the exchange's round limit; new cuts per
#: violated block and round (its largest violated patterns); seconds the whole solve may take
#: (IPOPT's wall-time limit per cut NLP, and checked before each round: a solve that runs out is
#: reported as stopped by a limit, never as an optimum)
DEFAULT_OPTIONS = {
    "tol": 1e-11,
    "constr_viol_tol": 1e-12,
    "max_iter": 1000,
    "max_rounds": 60,
    "cuts_per_round": 3,
    "time_limit": 600.0,
}
#: a pattern is cut when its |dr| / R exceeds 1 by more than this
CUT_TOL = 1e-10
#: cut slots come in these sizes (unused slots are free constraints): one compiled NLP per size
_SLOTS = (8, 16, 32, 64, 128, 256, 512, 1024)
#: bisection steps of the 1-D minima of the bound (the interval shrinks by 2^-64)
_BISECT = 64
#: grid of the interval bound where a cost is not convex in u
_GRID = 4097


@dataclass(frozen=True)
class WorstCaseResult(SynthesisResult):
    """A :class:`~tolsynth.problem.result.SynthesisResult` of the worst-case stack-up.

    ``constraints`` hold, per pose and kind, ``max |dr| / R`` over every error in its band (``/ Phi``
    for the orientation) with the direction of the farthest point; ``statistical`` the statistical
    design at the same R and p when p was given: ``{"probability", "p", "cost", "success"}``.
    """

    statistical: dict | None = field(default=None, repr=False)

    @property
    def cost_ratio(self) -> float | None:
        """Worst-case cost / the statistical design's (None without one)."""
        st = self.statistical
        return None if not st or not st.get("cost") else self.cost / st["cost"]

    def summary(self, cost_line: str | None = None) -> str:
        """Status, cost with bound and gap, the comparison with the statistical design, the
        tolerances, the worst-case value of every pose, how the default design pose was chosen
        and the sampled workspace check once computed; ``cost_line`` as in
        :meth:`SynthesisResult.summary`."""
        lines = [
            f"{self.solver} (worst case: every error anywhere in its band): {self.status} ({self.message})",
            cost_line or f"cost {self.cost:.8g}  (dual bound {self.lower_bound:.8g}, gap {self.gap:.2e})",
        ]
        st = self.statistical
        if st:
            if st.get("cost") is not None and math.isfinite(st["cost"]):
                lines.append(
                    f"statistical design ({st['probability']} probability, p = {st['p']:g}) at the same R: "
                    f"cost {st['cost']:.8g}; the worst case costs {100 * (self.cost_ratio - 1):+.1f} %"
                    + ("" if st.get("success") else " (the statistical solve is not certified)")
                )
            else:
                lines.append(f"statistical design at p = {st['p']:g}: {st.get('message', 'none')}")
        lines.append(
            f"iterations {self.iterations}, evaluations {self.function_evaluations}, {self.wall_time * 1e3:.1f} ms"
        )
        fixed = {n for n, a, b in zip(self.spec.names, self.spec.lower, self.spec.upper) if a == b}  # locked
        for name, value in self.tolerances.items():
            flag = f"  [{self.bounds_active[name]} bound]" if name in self.bounds_active else ""
            flag = "  [fixed]" if name in fixed else flag
            lines.append(f"  {name:>8} = {value:.6g} {self.units[name]}{flag}")
        for b in self.constraints:
            what = "max |dr| / R" if b.kind.startswith("position") else "max |dphi| / Phi"
            lines.append(f"  {b.label}: {what} = {b.values[0]:.8f} (multiplier {b.multipliers[0]:.4g})")
        if self.inputs and self.inputs.get("default_pose"):
            lines.append(f"pose: {self.inputs['default_pose']}")
        return "\n".join(lines + self._workspace_lines())

    def to_dict(self) -> dict:
        out = super().to_dict()
        out["probability"] = "worst_case"
        out["statistical"] = self.statistical
        return out


@dataclass(frozen=True)
class _Block:
    label: str
    pose: str
    kind: str  # "position" or "orientation"
    A: np.ndarray  # 3 x n, per tolerance unit
    R: float  # mm or rad
    #: the candidate sign patterns of the block's zonotope: they depend on the directions of its
    #: columns only, not on the tolerances, so they are found once per block
    S: np.ndarray


def _blocks(spec) -> list[_Block]:
    out = []
    for b in spec.blocks:
        R = spec.R if b.kind == "position" else spec.Phi
        A = np.asarray(b.A) / spec.col_scale
        out.append(
            _Block(f"{b.kind} at pose {b.pose!r}", b.pose, b.kind, A, float(R), candidate_patterns(A, unique=True))
        )
    return out


def worst_case_values(blocks, eps) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """Per block: ``(h / R, s, d)``: the exact worst-case value, its sign pattern and direction."""
    out = []
    for b in blocks:
        h, s, d = zonotope_max(b.A * eps, b.S)
        out.append((h / b.R, s, d))
    return out


@lru_cache(maxsize=32)
def _cut_solver(
    n: int,
    K: int,
    signature: tuple,
    tol: float,
    constr_viol_tol: float,
    max_iter: int,
    max_wall_time: float = DEFAULT_OPTIONS["time_limit"],
):
    """``min c(ln(ref x)) / f0  s.t.  |M_k x|^2 <= 1`` for K cut slots (x = eps / ref)."""
    cost = cost_graph(n, signature)
    nt = cost.size1_in(1)
    x = ca.SX.sym("x", n)
    p = ca.SX.sym("p", 3 * K * n + n + nt + 1)
    M = ca.reshape(p[: 3 * K * n], 3 * K, n)
    ref = p[3 * K * n : 3 * K * n + n]
    theta = p[3 * K * n + n : 3 * K * n + n + nt]
    f0 = p[-1]
    r = ca.reshape(ca.mtimes(M, x), 3, K)
    g = ca.sum1(r * r).T
    nlp = {"x": x, "p": p, "f": cost(ca.log(ref * x), theta) / f0, "g": g}
    opts = {
        "print_time": False,
        "show_eval_warnings": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.tol": tol,
        "ipopt.constr_viol_tol": constr_viol_tol,
        "ipopt.max_iter": max_iter,
        "ipopt.acceptable_iter": 0,
        "ipopt.hessian_approximation": "exact",
        "ipopt.mu_strategy": "adaptive",
        "ipopt.max_wall_time": max_wall_time,
    }
    return ca.nlpsol("worst_case_cuts", "ipopt", nlp, opts)


def _slots(k: int) -> int:
    for s in _SLOTS:
        if k <= s:
            return s
    raise InfeasibleSpecificationError("worst case", float(k), f"more than {_SLOTS[-1]} pattern cuts needed")


def convex_in_eps(model, lo: float, hi: float) -> bool:
    """True if the cost is convex in eps on ``[lo, hi]`` (then the worst-case problem is convex):
    the power law, Chase's model, the exponential and a given error everywhere; any model convex in
    ``u = ln eps`` (non-increasing and convex in u is convex in eps)."""
    return isinstance(model, (PowerLaw, Chase, Exponential, Given)) or model.convex_in_u(lo, hi)


def _linear_min(model, w: float, lu: float, uu: float) -> tuple[float, float]:
    """``(min, argmin u)`` over ``u`` in ``[lu, uu]`` of ``c(u) + w e^u`` (``w >= 0``), global: closed
    form for the power law, bisection where c is convex in eps (the sign of ``c'(eps) + w`` then
    changes once), else a
    rigorous grid bound (c non-increasing: on ``[a, b]`` the sum is at least ``c(b) + w e^a``)."""
    if isinstance(model, PowerLaw):
        k, a = model.k, model.alpha
        u = math.log(a * k / w) / (1.0 + a) if w > 0 else uu
        u = min(max(u, lu), uu)
        return k * math.exp(-a * u) + w * math.exp(u), u
    if convex_in_eps(model, math.exp(lu), math.exp(uu)):
        lo, hi = lu, uu
        for _ in range(_BISECT):
            m = 0.5 * (lo + hi)
            if float(model.du(np.array([m]))[0]) + w * math.exp(m) > 0.0:
                hi = m
            else:
                lo = m
        cands = np.array([0.5 * (lo + hi), lu, uu])
        vals = model.value(cands) + w * np.exp(cands)
        j = int(np.argmin(vals))
        return float(vals[j]), float(cands[j])
    grid = np.linspace(lu, uu, _GRID)
    c = model.value(grid)
    we = w * np.exp(grid)
    exact = c + we
    j = int(np.argmin(exact))
    return float(min(np.min(c[1:] + we[:-1]), exact[j])), float(grid[j])


def dual_bound(costs, lower, upper, B: np.ndarray, lam: np.ndarray) -> float:
    """The Lagrangian lower bound of the direction-cut relaxation ``B eps <= 1`` (module docstring)."""
    lam = np.maximum(np.asarray(lam, dtype=float), 0.0)
    w = B.T @ lam if len(lam) else np.zeros(len(lower))
    lu, uu = np.log(lower), np.log(upper)
    terms = [_linear_min(m, float(wi), float(a), float(b))[0] for m, wi, a, b in zip(costs.models, w, lu, uu)]
    return math.fsum(terms) - math.fsum(lam.tolist())


def _stationary_multipliers(costs, eps, lower, upper, B) -> np.ndarray:
    """Multipliers of the direction cuts from stationarity at ``eps`` (least squares on the
    parameters off their bounds, clipped at 0): ``c_i'(eps_i) + (B^T lambda)_i = 0``."""
    free = (eps > lower * (1 + ACTIVE_TOL)) & (eps < upper * (1 - ACTIVE_TOL))
    if not free.any() or not len(B):
        return np.zeros(len(B))
    grad = costs.du(np.log(eps)) / eps
    lam, *_ = np.linalg.lstsq(B[:, free].T, -grad[free], rcond=None)
    return np.maximum(lam, 0.0)


def lagrangian_weights(spec, eps) -> tuple[np.ndarray, float]:
    """``(w, T)`` with ``cost(e) >= sum_i [c_i(e_i) + w_i e_i] - T`` for every tolerance vector e
    meeting the worst case (weak duality on the direction cuts through the exact worst directions
    at ``eps``, multipliers from stationarity there): a separable lower bound for discrete choices."""
    blocks = _blocks(spec)
    lower, upper = np.asarray(spec.lower, dtype=float), np.asarray(spec.upper, dtype=float)
    rows = [
        np.abs(b.A.T @ d) / b.R for b, (v, _, d) in zip(blocks, worst_case_values(blocks, eps)) if v >= 1.0 - ACTIVE_TOL
    ]
    if not rows:
        return np.zeros(spec.n), 0.0
    B = np.array(rows)
    lam = _stationary_multipliers(spec.costs, np.asarray(eps, dtype=float), lower, upper, B)
    return B.T @ lam, float(lam.sum())


def check_feasible(blocks, lower, upper=None, names=()) -> None:
    """Raise :class:`InfeasibleSpecificationError` if the locked tolerances (``lower == upper``)
    alone, every other at zero, break a block (then the message names them, as the statistical
    path's :func:`tolsynth.model.locks.check_locks`), or if every tolerance at its lower bound
    does (h grows with every eps_i)."""
    locked = [] if upper is None else [i for i, (a, b) in enumerate(zip(lower, upper)) if a == b]
    if locked:
        alone = np.zeros(len(lower))
        alone[locked] = np.asarray(lower, dtype=float)[locked]
        for b, (v, _, _) in zip(blocks, worst_case_values(blocks, alone)):
            if v > 1.0:
                limit = "R" if b.kind == "position" else "Phi"
                raise InfeasibleSpecificationError(
                    b.label,
                    v,
                    f"infeasible specification: the locked tolerances {[names[i] for i in locked]} alone break "
                    f"the worst case of the {b.label} (max |error| / {limit} = {v:.6g} > 1 with every other "
                    f"tolerance at zero).  Loosen {limit}, or tighten the locked tolerances.",
                )
    for b, (v, _, _) in zip(blocks, worst_case_values(blocks, lower)):
        if v > 1.0:
            limit = "R" if b.kind == "position" else "Phi"
            raise InfeasibleSpecificationError(
                b.label,
                v,
                f"infeasible specification: the worst case of the {b.label} exceeds {limit} even with "
                f"every tolerance at its lower bound (max |error| / {limit} = {v:.6g} > 1).  Lower the "
                f"bounds, or relax {limit}.",
            )


def _checked_options(opts: dict) -> dict:
    """The options as numbers of the right kind, or a typed error naming the option."""
    from tolsynth.checks import check_count, check_positive

    out = dict(opts)
    for key in ("tol", "constr_viol_tol", "time_limit"):
        out[key] = check_positive(opts[key], f"options['{key}']")
    for key in ("max_iter", "max_rounds", "cuts_per_round"):
        out[key] = check_count(opts[key], f"options['{key}']", lower=1)
    return out


def solve_worst_case(spec, eps0=None, options=None) -> WorstCaseResult:
    """The exchange method of the module docstring on a :class:`~tolsynth.problem.specification.Specification`
    (its blocks' rows, R, Phi, bounds and cost models; its p and distribution are not read)."""
    opts = _checked_options({**DEFAULT_OPTIONS, **(options or {})})
    t0 = time.perf_counter()
    blocks = _blocks(spec)
    lower, upper = np.asarray(spec.lower, dtype=float), np.asarray(spec.upper, dtype=float)
    costs = spec.costs
    n = spec.n
    check_feasible(blocks, lower, upper, spec.names)
    if eps0 is None:  # the geometric middle of the bounds scaled (h is homogeneous) to half the limit
        mid = np.sqrt(lower * upper)
        worst = max(v for v, _, _ in worst_case_values(blocks, mid))
        eps0 = mid * (0.5 / worst) if worst > 0 else mid
    eps = np.clip(np.asarray(eps0, dtype=float), lower, upper)
    ref = eps.copy()
    cuts: list[tuple[int, np.ndarray]] = []
    keys = set()

    def add(bi, s):
        key = (bi, s.tobytes())
        if key not in keys:
            keys.add(key)
            cuts.append((bi, s))

    for bi, (_, s, _) in enumerate(worst_case_values(blocks, eps)):
        add(bi, s)
    history, iters, evals = [], 0, 0
    status, message, lam_g, ok = Status.SOLVER_ERROR, "not run", np.zeros(0), False
    f0 = max(costs.cost(eps), 1e-300)
    limit = opts["time_limit"]
    for rnd in range(int(opts["max_rounds"])):
        if time.perf_counter() - t0 > limit:
            ok, status = False, getattr(Status, "TIME_LIMIT", Status.ITERATION_LIMIT)
            message += f"; stopped by the time limit ({limit:g} s) after {rnd} exchange rounds"
            break
        K = _slots(len(cuts))
        M = np.zeros((3 * K, n))
        for k, (bi, s) in enumerate(cuts):
            M[3 * k : 3 * k + 3] = blocks[bi].A * (s * ref) / blocks[bi].R
        solver = _cut_solver(
            n, K, costs.signature, float(opts["tol"]), float(opts["constr_viol_tol"]), int(opts["max_iter"]), limit
        )
        p = np.concatenate([M.ravel(order="F"), ref, costs.theta, [f0]])
        ubg = np.full(K, np.inf)
        ubg[: len(cuts)] = 1.0
        sol = solver(x0=eps / ref, p=p, lbx=lower / ref, ubx=upper / ref, lbg=-np.inf, ubg=ubg)
        st = solver.stats()
        iters += int(st.get("iter_count", 0))
        evals += int(st.get("n_call_nlp_f", 0))
        raw = st.get("return_status", "unknown")
        status = IPOPT_STATUS.get(raw, Status.SOLVER_ERROR)
        message = f"IPOPT: {raw}"
        x = np.array(sol["x"]).ravel()
        lam_g = np.array(sol["lam_g"]).ravel()[: len(cuts)] * f0
        eps = np.clip(ref * x, lower, upper)
        added = 0
        worst_all = 0.0
        for bi, b in enumerate(blocks):
            vals, S = zonotope_patterns(b.A * eps, top=int(opts["cuts_per_round"]), patterns=b.S)
            worst_all = max(worst_all, float(vals[0]) / b.R)
            for v, s in zip(vals, S):
                if v / b.R > 1.0 + CUT_TOL and (bi, s.tobytes()) not in keys:
                    add(bi, s)
                    added += 1
        history.append(
            {
                "round": rnd,
                "cuts": len(cuts),
                "iterations": int(st.get("iter_count", 0)),
                "status": raw,
                "cost": costs.cost(eps),
                "worst": worst_all,
            }
        )
        if status is not Status.OPTIMAL:
            ok = False
            if status is getattr(Status, "TIME_LIMIT", None):  # IPOPT's own clock is the same limit
                message += f"; stopped by the time limit ({limit:g} s) after {rnd + 1} exchange rounds"
            break
        ok = True
        if not added:
            break
    else:
        ok = False
        message += f"; still violated after {opts['max_rounds']} exchange rounds"
        status = Status.ITERATION_LIMIT
    return _assemble(
        spec, blocks, costs, eps, cuts, lam_g, status, message, ok, iters, evals, time.perf_counter() - t0, history
    )


def _assemble(spec, blocks, costs, eps, cuts, lam_g, status, message, ok, iters, evals, wall, history):
    lower, upper = np.asarray(spec.lower, dtype=float), np.asarray(spec.upper, dtype=float)
    # IPOPT may leave the point a hair outside: h is homogeneous of degree 1 in eps, so scaling
    # onto the specification costs as little as that hair
    vals = worst_case_values(blocks, eps)
    top = max(v for v, _, _ in vals)
    if top > 1.0:
        eps = np.maximum(eps / top, lower)
        vals = worst_case_values(blocks, eps)
    cost = costs.cost(eps)
    # the certificate: direction cuts from the active pattern cuts and the exact worst directions
    rows, lam_ipopt = [], []
    for k, (bi, s) in enumerate(cuts):
        b = blocks[bi]
        v = b.A @ (s * eps) / b.R
        nv = float(np.linalg.norm(v))
        if nv == 0.0:
            continue
        rows.append(np.abs(b.A.T @ (v / nv)) / b.R)
        lam_ipopt.append(2.0 * lam_g[k] * nv if k < len(lam_g) else 0.0)
    for b, (v, _, d) in zip(blocks, vals):
        rows.append(np.abs(b.A.T @ d) / b.R)
        lam_ipopt.append(0.0)
    B = np.array(rows) if rows else np.zeros((0, spec.n))
    lower_bound = dual_bound(costs, lower, upper, B, np.array(lam_ipopt))
    active = (B @ eps >= 1.0 - ACTIVE_TOL) if len(B) else np.zeros(0, dtype=bool)
    lam_st = np.zeros(len(B))
    if active.any():
        lam_st[active] = _stationary_multipliers(costs, eps, lower, upper, B[active])
        lower_bound = max(lower_bound, dual_bound(costs, lower, upper, B, lam_st))
    lower_bound = min(lower_bound, cost) if math.isfinite(lower_bound) else lower_bound
    gap = optimality_gap(cost, lower_bound)
    worst = max(v for v, _, _ in vals)
    convex = all(convex_in_eps(m, a, b) for m, a, b in zip(costs.models, lower, upper))
    if ok:
        if not worst <= 1.0 + FEAS_TOL:
            status, message = Status.NUMERICAL_ERROR, f"{message}; rejected: max |error| / limit {worst:.9g} > 1"
        elif not gap <= GAP_TOL * abs(cost):
            status = Status.OPTIMAL_INACCURATE
            message = f"{message}; not certified: gap {gap:.3g} ({gap / abs(cost):.2e} of the cost) > {GAP_TOL:g}" + (
                "" if convex else "; a cost is not convex in eps: possibly a local optimum"
            )
        else:
            message = (
                f"{message}; {len(cuts)} pattern cuts, every pose's exact worst case within the limit "
                f"(largest {worst:.9f}), gap {gap / abs(cost):.1e} of the cost"
            )
    # the cut multipliers per block: the multiplier of |dr| / R <= 1 (chain rule of |v|^2 <= 1)
    mult = np.zeros(len(blocks))
    for k, (bi, _) in enumerate(cuts):
        if k < len(lam_g):
            mult[bi] += 2.0 * lam_g[k]
    cblocks = tuple(
        ConstraintBlock(
            label=b.label,
            pose=b.pose,
            kind=f"{b.kind} (worst case)",
            values=np.array([v]),
            directions=d[:, None],
            active=np.array([v >= 1.0 - ACTIVE_TOL]),
            multipliers=np.array([mult[i]]),
        )
        for i, (b, (v, _, d)) in enumerate(zip(blocks, vals))
    )
    bounds_active = {}
    for i, name in enumerate(spec.names):
        if eps[i] <= lower[i] * (1 + ACTIVE_TOL):
            bounds_active[name] = "lower"
        elif eps[i] >= upper[i] * (1 - ACTIVE_TOL):
            bounds_active[name] = "upper"
    return WorstCaseResult(
        solver="ipopt",
        status=status,
        success=status is Status.OPTIMAL,
        message=message,
        tolerances=dict(zip(spec.names, map(float, eps))),
        units=dict(zip(spec.names, spec.units)),
        cost=cost,
        constraints=cblocks,
        bounds_active=bounds_active,
        bound_multipliers={},
        lower_bound=lower_bound,
        gap=gap,
        iterations=iters,
        function_evaluations=evals,
        wall_time=wall,
        spec=spec,
        history=history,
    )
