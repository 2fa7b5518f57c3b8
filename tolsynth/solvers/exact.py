"""``synthesize(..., probability="exact")``: the tolerance problem with the exact probabilities of
the linear error model (:mod:`tolsynth.probability.exact`) as its constraints, no Gaussian approximation.

**Per component** (the paper's criterion, Eq. 6-7, read exactly): at every pose, along every unit
direction ``w``, ``P(|w . dr| <= R) >= p``.  For Gaussian errors the worst direction is the first
principal axis and this is the paper's ``z sigma_1 <= R``; for other shapes the worst direction
can move off the axes, so the constraint is imposed for all of them by an exchange (cutting-plane)
method: the NLP carries one constraint per (pose, direction) cut, starting from the principal
axes of the Gaussian design, and after each solve the worst direction of each pose is searched
(:func:`tolsynth.probability.exact.worst_direction`); a direction short of ``p`` becomes a new cut.

**Sphere**: ``P(|dr| <= R) >= p`` per pose by the Radon identity of :mod:`tolsynth.probability.exact` on a
fixed hemisphere rule (``nodes`` Gauss-Legendre in ``v_z`` x ``2 nodes`` azimuths).

Each cut is one smooth CasADi graph of ``u = ln eps`` (:func:`direction_function`): the Fourier
series of the periodised density with K terms,

    P(u) = R/L + sum_{k=1..K} (2 / (k pi)) sin(k pi R / L) prod_i phi_i(k pi b_i e^{u_i} / L),

``b_i = |w . a_i|`` and ``L(u) = R + (sum_bounded b_i e^{u_i} + 8.5 sd_normal(u)) / 2``.  IPOPT
(limited-memory Hessian) and SUMT + Powell (interior penalty ``-ln((P - p)/(1 - p))``) read the
same graphs.  After each solve the probabilities are recomputed by :mod:`tolsynth.probability.exact` with its
rigorous error bound, independently of the graph's fixed K and nodes: if the graph was off, K (or
the nodes) double and the NLP is solved again from where it stopped; for the sphere the target is
raised by the shortfall the rule leaves.  A result is ``success`` only if that independent check
finds every pose within ``1e-7`` of ``p`` (or above it).

There is no convexity certificate: the exact problem is not known to be convex.  The reported
``lower_bound`` is a valid but loose one from the density's peak: ``P(|w| <= R) <= 2 R f_w(0)``
and ``f_w(0) <= f_i(0) / (|w . a_i| eps_i)`` for each error i (the density of a sum of independent
symmetric unimodal variables is at most that of any one term), so ``p`` caps each ``eps_i`` alone;
the cheapest point under those caps bounds the cost from below.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from tolsynth.probability import exact as ex
from tolsynth.problem.nlp import ToleranceNLP, cost_graph
from tolsynth.problem.result import ConstraintBlock, Status, SynthesisResult

__all__ = ["solve_exact", "direction_function", "exact_margin", "PROBABILITIES", "EXACT_TOL"]

PROBABILITIES = ("gaussian", "exact")
#: the independent check: every pose's exact probability at least p - EXACT_TOL
EXACT_TOL = 1e-7
#: a direction is cut when its exact probability is below p - CUT_TOL
CUT_TOL = 1e-8
#: with each new cut w, four neighbours at this angle (rad) around it: the worst direction moves
#: as the tolerances change, and the neighbours bound its motion (fewer exchange rounds)
NEIGHBOUR = 0.03
#: the sphere's exact probability (a 2-D integral over directions, algebraically convergent for
#: uniform errors) is checked to this accuracy
SPHERE_TOL = 1e-6
K_START = 64
K_MAX = 4096
NODES_START = 8
NODES_MAX = 32
MAX_ROUNDS = 30


@lru_cache(maxsize=None)
def direction_function(shapes: tuple, K: int) -> ca.Function:
    """``(u, b, R) -> (P, Q)`` for one direction: ``P = P(|sum b_i e^{u_i} Y_i| <= R)`` by the
    K-term series, and ``Q`` the sphere kernel ``sum_k (2/(k pi)) (sin x_k - x_k cos x_k) prod phi``
    (:mod:`tolsynth.probability.exact`), an SX graph (exact derivatives by CasADi's AD)."""
    n = len(shapes)
    u = ca.SX.sym("u", n)
    b = ca.SX.sym("b", n)
    R = ca.SX.sym("R")
    c = b * ca.exp(u)
    B = 0
    normal = []
    for i, s in enumerate(shapes):
        if s.bounded:
            B = B + c[i]
        else:
            normal.append(c[i] / 3.0)
    if normal:
        B = B + ex.NORMAL_REACH * ca.sqrt(ca.sumsqr(ca.vertcat(*normal)) + 1e-300)
    L = R + 0.5 * B
    P = R / L
    Q = 0
    for k in range(1, K + 1):
        t = k * math.pi / L
        prod = 1
        for i, s in enumerate(shapes):
            prod = prod * s.cf(t * c[i], lib=ca)
        x = k * math.pi * R / L
        w = 2.0 / (k * math.pi)
        P = P + w * ca.sin(x) * prod
        Q = Q + w * (ca.sin(x) - x * ca.cos(x)) * prod
    return ca.Function("direction", [u, b, R], [P, Q], ["u", "b", "R"], ["P", "Q"])


@dataclass
class _Block:
    """One pose and kind: raw rows A (3 x n or 2 x n per tolerance unit), R, p."""

    label: str
    pose: str
    kind: str  # "position", "orientation", "sphere"
    A: np.ndarray
    R: float
    p: float


def _blocks(spec) -> list[_Block]:
    out = []
    scale = spec.col_scale
    for b in spec.blocks:
        R, p = (spec.R, spec.p) if b.kind == "position" else (spec.Phi, spec.p_orientation)
        out.append(_Block(b.label, b.pose, b.kind, np.asarray(b.A) / scale, float(R), float(p)))
    for b in spec.sphere_blocks:
        out.append(_Block(b.label, b.pose, "sphere", np.asarray(b.A) / scale, float(b.R), float(b.p)))
    return out


class _Problem:
    """The NLP of one cut set: cuts (block index, direction) and sphere blocks with their rules."""

    def __init__(self, nlp: ToleranceNLP, shapes: tuple, blocks: list[_Block], K: int, nodes: int):
        self.nlp, self.spec, self.shapes, self.blocks, self.K, self.nodes = nlp, nlp.spec, shapes, blocks, K, nodes
        self.F = direction_function(shapes, K)
        self.dirs, self.weights = ex._hemisphere(nodes)
        self.cuts: list[tuple[int, np.ndarray]] = []
        self.target = {i: b.p for i, b in enumerate(blocks)}
        self.lam_g = self.lam_x = None  # IPOPT's multipliers of the last round (warm start)

    def rows(self):
        """(b rows n x m, R, p, which constraint each cut feeds) for the graph."""
        n = self.spec.n
        cols, Rs, ps = [], [], []
        for i, w in self.cuts:
            blk = self.blocks[i]
            cols.append(np.abs(w @ blk.A))
            Rs.append(blk.R)
            ps.append(self.target[i])
        return (np.array(cols).T if cols else np.zeros((n, 0))), np.array(Rs), np.array(ps)

    def graph(self):
        """``u -> g`` (normalised margins ``(P - p) / (1 - p)``, >= 0 required) as an MX function."""
        n = self.spec.n
        u = ca.MX.sym("u", n)
        g = []
        Bc, Rs, ps = self.rows()
        if Bc.shape[1]:
            Fm = self.F.map(Bc.shape[1])
            P, _ = Fm(ca.repmat(u, 1, Bc.shape[1]), ca.DM(Bc), ca.DM(Rs).T)
            g.append(((P - ca.DM(ps).T) / ca.DM(1.0 - ps).T).T)
        for i, blk in enumerate(self.blocks):
            if blk.kind != "sphere":
                continue
            Bd = np.abs(self.dirs @ blk.A).T  # n x D
            Fm = self.F.map(Bd.shape[1])
            _, Q = Fm(ca.repmat(u, 1, Bd.shape[1]), ca.DM(Bd), blk.R)
            P = ca.mtimes(Q, ca.DM(self.weights))
            g.append((P - self.target[i]) / (1.0 - self.target[i]))
        gg = ca.vertcat(*g) if g else ca.MX(0, 1)
        f = cost_graph(n, self.nlp.costs.signature)(u, self.nlp.theta)
        return u, f, gg

    # -- exact values (independent of the graph's K and nodes) --------------------------------
    def exact_values(self, eps: np.ndarray):
        """Per block: (P at its worst direction (or the sphere), worst direction, principal P's and
        directions, error bound)."""
        out = []
        for blk in self.blocks:
            if blk.kind == "sphere":
                P, err = ex.ball_probability(blk.A, eps, self.shapes, blk.R, tol=SPHERE_TOL, max_nodes=128,
                                             return_error=True)
                out.append((P, None, None, None, err))
                continue
            A = blk.A if blk.A.shape[0] == 3 else blk.A
            w, Pw = ex.worst_direction(A, eps, self.shapes, blk.R, tol=1e-10)
            Pc, E = ex.components_probability(A, eps, self.shapes, blk.R, tol=1e-10)
            out.append((Pw, w, Pc, E, 1e-10))
        return out


def _ipopt(prob: _Problem, u0: np.ndarray, options: dict):
    u, f, g = prob.graph()
    nlp = {"x": u, "f": f, "g": g}
    opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
            "ipopt.hessian_approximation": "limited-memory", "ipopt.tol": options.get("tol", 1e-10),
            "ipopt.max_iter": options.get("max_iter", 3000), "ipopt.acceptable_iter": 0,
            "ipopt.mu_strategy": "adaptive", "ipopt.nlp_scaling_method": "none"}
    m = g.shape[0]
    warm = {}
    if prob.lam_g is not None and prob.lam_g.size <= m:  # the previous round's multipliers, new cuts 0
        opts.update({"ipopt.warm_start_init_point": "yes", "ipopt.mu_init": 1e-6,
                     "ipopt.warm_start_bound_push": 1e-9, "ipopt.warm_start_mult_bound_push": 1e-9})
        warm = {"lam_g0": np.concatenate([prob.lam_g, np.zeros(m - prob.lam_g.size)]), "lam_x0": prob.lam_x}
    S = ca.nlpsol("exact", "ipopt", nlp, opts)
    r = S(x0=u0, lbx=prob.nlp.lu, ubx=prob.nlp.uu, lbg=np.zeros(m), ubg=np.full(m, np.inf), **warm)
    st = S.stats()
    prob.lam_g, prob.lam_x = np.array(r["lam_g"]).ravel(), np.array(r["lam_x"]).ravel()
    ok = st.get("success", False) or st.get("return_status") in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    return (np.array(r["x"]).ravel(), ok, st.get("return_status", "?"), int(st.get("iter_count", 0)),
            np.array(r["lam_x"]).ravel())


@lru_cache(maxsize=None)
def _penalty_function(shapes: tuple, K: int, M: int, D: int, signature) -> ca.Function:
    """SUMT's penalty on the same direction graph: ``(u, B, Rs, ps, Bs, ws, Rb, pb, theta, lu, uu,
    r) -> (value, f)`` for M cut slots (an unused slot has b = 0: P = 1, margin 1, ln 1 = 0) and one
    sphere slot of D directions with weights ``ws`` (unused: weights 0, target -1)."""
    n = len(shapes)
    F = direction_function(shapes, K)
    u = ca.MX.sym("u", n)
    B, Rs, ps = ca.MX.sym("B", n, M), ca.MX.sym("Rs", 1, M), ca.MX.sym("ps", 1, M)
    Bs, ws, Rb, pb = ca.MX.sym("Bs", n, D), ca.MX.sym("ws", D, 1), ca.MX.sym("Rb"), ca.MX.sym("pb")
    theta = ca.MX.sym("theta", cost_graph(n, signature).size1_in(1))
    lu, uu, r = ca.MX.sym("lu", n), ca.MX.sym("uu", n), ca.MX.sym("r")
    P, _ = F.map(M)(ca.repmat(u, 1, M), B, Rs)
    marg = (P - ps) / (1 - ps)
    _, Q = F.map(D)(ca.repmat(u, 1, D), Bs, Rb)
    ball = (ca.mtimes(Q, ws) - pb) / (1 - pb)
    inside = ca.logic_and(ca.logic_and(ca.mmin(marg) > 0, ball > 0),
                          ca.logic_and(ca.mmin(u - lu) > 0, ca.mmin(uu - u) > 0))
    f = cost_graph(n, signature)(u, theta)
    bar = -ca.sum2(ca.log(ca.fmax(marg, 1e-300))) - ca.log(ca.fmax(ball, 1e-300))
    bnd = -ca.sum1(ca.log(ca.fmax(u - lu, 1e-300)) + ca.log(ca.fmax(uu - u, 1e-300)))
    value = ca.if_else(inside, f + r * (bar + 0.01 * bnd), ca.inf)
    return ca.Function("exact_penalty", [u, B, Rs, ps, Bs, ws, Rb, pb, theta, lu, uu, r], [value, f])


def _slots(k: int) -> int:
    return max(8, 1 << (max(k, 1) - 1).bit_length())


def _sumt(prob: _Problem, u0: np.ndarray, options: dict):
    """SUMT (interior penalty ``-ln((P - p)/(1 - p))`` per cut, ``0.01 ln`` per bound) + Powell on
    the same direction graphs, the minimisation in C where a compiler is found
    (:mod:`tolsynth.solvers.cpowell`), else Powell in Python.  One sphere block at most."""
    from tolsynth.solvers.cpowell import compile_powell
    from tolsynth.solvers.powell import powell

    spec = prob.spec
    n = spec.n
    Bc, Rs, ps = prob.rows()
    M = _slots(Bc.shape[1])
    B = np.zeros((n, M))
    B[:, : Bc.shape[1]] = Bc
    R_ = np.ones((1, M))
    R_[0, : Bc.shape[1]] = Rs
    p_ = np.zeros((1, M))
    p_[0, : Bc.shape[1]] = ps
    sph = [i for i, b in enumerate(prob.blocks) if b.kind == "sphere"]
    if len(sph) > 1:
        from tolsynth.errors import InputError

        raise InputError("poses", "SUMT with exact sphere probabilities at several poses", "one pose (or solver='ipopt')")
    D = prob.dirs.shape[0] if sph else 1  # no sphere: one dummy direction of weight 0
    Bs, ws, Rb, pb = np.zeros((n, D)), np.zeros((D, 1)), np.ones(1), np.array([-1.0])
    if sph:
        blk = prob.blocks[sph[0]]
        Bs, ws, Rb, pb = np.abs(prob.dirs @ blk.A).T, prob.weights[:, None], np.array([blk.R]), np.array([prob.target[sph[0]]])
    lu, uu = prob.nlp.lu.copy(), prob.nlp.uu.copy()
    locked = uu - lu <= 1e-12
    lu[locked] -= 1e-9
    uu[locked] += 1e-9
    G = _penalty_function(prob.shapes, prob.K, M, D, prob.nlp.costs.signature)
    r_box = np.zeros(1)
    # dense column-major, as CasADi reads its inputs
    values = [B.ravel(order="F"), R_.ravel(), p_.ravel(), Bs.ravel(order="F"), ws.ravel(), Rb, pb,
              prob.nlp.theta, lu, uu, r_box]
    shaped = [B, R_, p_, Bs, ws, Rb, pb, prob.nlp.theta, lu, uu, r_box]
    compiled = compile_powell(G)

    def fun(z):
        return compiled.evaluate(values, z)[0] if compiled is not None else float(G(z, *shaped)[0])

    x = np.clip(np.array(u0, dtype=float), lu + 1e-6, uu - 1e-6)
    x[locked] = 0.5 * (lu[locked] + uu[locked])
    r_box[0] = 1.0
    # an interior start: shrink the tolerances (every probability rises as the errors shrink)
    for _ in range(400):
        if math.isfinite(fun(x)):
            break
        x[~locked] = np.clip(x[~locked] - 0.05, lu[~locked] + 1e-6, uu[~locked] - 1e-6)
    else:
        return x, False, "SUMT: no interior start found", 0, np.zeros(n)
    f0 = float(G(x, *shaped)[1])
    nu = Bc.shape[1] + len(sph) + 0.02 * n
    rr = options.get("r0") or 0.1 * abs(f0) / nu
    iters, Dir = 0, None
    for _ in range(options.get("outer", 16)):
        r_box[0] = rr
        if compiled is not None:
            res = compiled.minimize(values, x, directions=Dir, step=0.05, ftol=1e-14)
        else:
            res = powell(fun, x, directions=Dir, step=0.05, ftol=1e-14)
        x, Dir = res.x, res.directions
        iters += res.nit
        if rr * nu <= 1e-10 * abs(f0):
            break
        rr *= 0.1
    x[locked] = 0.5 * (lu[locked] + uu[locked])
    return x, True, f"SUMT converged (r = {rr:.1e})", iters, np.zeros(n)


def solve_exact(nlp: ToleranceNLP, shapes: tuple, solver: str = "ipopt", eps0=None, options=None,
                verbose: bool = False) -> SynthesisResult:
    """The exchange method of this module with IPOPT or SUMT + Powell as the inner solver."""
    options = dict(options or {})
    t0 = time.perf_counter()
    spec = nlp.spec
    shapes = tuple(shapes)
    blocks = _blocks(spec)
    if eps0 is None:
        from tolsynth.solvers.ipopt import solve_ipopt

        eps0 = solve_ipopt(nlp).x  # the Gaussian design starts the search
    eps = np.clip(np.asarray(eps0, dtype=float), spec.lower, spec.upper)
    K = options.pop("K", K_START)
    nodes = options.pop("nodes", NODES_START)
    prob = _Problem(nlp, shapes, blocks, K, nodes)
    for i, blk in enumerate(blocks):  # first cuts: the principal axes at the start point
        if blk.kind != "sphere":
            var = np.array([s.variance for s in shapes])
            V = (blk.A * (eps**2 * var)) @ blk.A.T
            _, vec = np.linalg.eigh(V)
            for j in range(vec.shape[1]):
                prob.cuts.append((i, vec[:, -1 - j]))
    inner = _ipopt if solver == "ipopt" else _sumt
    history, iters, status_text, ok = [], 0, "", False
    lam = np.zeros(spec.n)
    for rnd in range(MAX_ROUNDS):
        u, ok, status_text, it, lam = inner(prob, np.log(eps), options)
        iters += it
        eps = np.clip(np.exp(u), spec.lower, spec.upper)
        vals = prob.exact_values(eps)
        added, refine = 0, False
        Bc, Rs, ps = prob.rows()
        if Bc.shape[1]:
            graphP = np.array(prob.F.map(Bc.shape[1])(np.tile(u[:, None], Bc.shape[1]), Bc, Rs[None, :])[0]).ravel()
            exactP = ex.direction_probability((Bc * eps[:, None]).T, shapes, 1.0 * Rs[0], tol=1e-10,
                                              return_error=True)[0] if np.all(Rs == Rs[0]) else \
                np.array([ex.direction_probability(Bc[:, j] * eps, shapes, Rs[j], tol=1e-10) for j in range(Bc.shape[1])])
            if np.max(np.abs(graphP - exactP)) > 0.1 * EXACT_TOL:
                refine = True
        for i, (blk, (Pw, w, _, _, _)) in enumerate(zip(blocks, vals)):
            if blk.kind == "sphere":
                short = blk.p - Pw
                if short > 0.5 * EXACT_TOL:
                    prob.target[i] = min(prob.target[i] + short + 0.1 * EXACT_TOL, 1 - 1e-12)
                    added += 1
                continue
            if Pw < blk.p - CUT_TOL:
                prob.cuts.append((i, w))
                h = np.eye(3)[int(np.argmin(np.abs(w)))]
                e1 = np.cross(w, h)
                e1 /= np.linalg.norm(e1)
                e2 = np.cross(w, e1)
                for e in (e1, -e1, e2, -e2):
                    v = w + NEIGHBOUR * e
                    prob.cuts.append((i, v / np.linalg.norm(v)))
                added += 1
        worst = max(((blk.p - v[0]) for blk, v in zip(blocks, vals)), default=0.0)
        history.append({"round": rnd, "cuts": len(prob.cuts), "K": prob.K, "nodes": prob.nodes,
                        "worst_shortfall": float(worst), "inner": status_text, "iterations": it,
                        "cost": nlp.cost(eps)})
        if verbose:
            print(history[-1])
        if refine and prob.K < K_MAX:
            prob.K *= 2
            prob.F = direction_function(shapes, prob.K)
            continue
        if not ok:
            break
        if added == 0:
            break
    cost = nlp.cost(eps)
    vals = prob.exact_values(eps)
    cblocks = []
    for blk, (Pw, w, Pc, E, err) in zip(blocks, vals):
        if blk.kind == "sphere":
            v = np.array([(1 - Pw) / (1 - blk.p)])
            d = np.zeros((3, 1))
        else:
            v = np.concatenate([[(1 - Pw) / (1 - blk.p)], (1 - Pc) / (1 - blk.p)])
            d = np.column_stack([w, E])
        cblocks.append(ConstraintBlock(blk.label, blk.pose, blk.kind + " (exact)", v, d,
                                       v >= 1 - 1e-6, np.zeros_like(v)))
    shortfall = max(((blk.p - v[0]) for blk, v in zip(blocks, vals)), default=0.0)
    lower = _peak_bound(nlp, shapes, blocks)
    if ok and shortfall <= EXACT_TOL:
        status = Status.OPTIMAL
        message = (f"exact probabilities: {len(prob.cuts)} direction cuts, K = {prob.K} terms"
                   + (f", {prob.nodes} hemisphere nodes" if any(b.kind == "sphere" for b in blocks) else "")
                   + f"; every pose within {EXACT_TOL:g} of p by the independent check; {status_text}; "
                   "no convexity certificate (lower_bound: the loose peak-density bound)")
    else:
        status = Status.NUMERICAL_ERROR if ok else Status.SOLVER_ERROR
        message = f"exact probabilities: shortfall {shortfall:.2e} after {len(history)} rounds; {status_text}"
    bounds_active, bound_mult = {}, {}
    for i, name in enumerate(spec.names):
        if eps[i] <= spec.lower[i] * (1 + 1e-6):
            bounds_active[name] = "lower"
        elif eps[i] >= spec.upper[i] * (1 - 1e-6):
            bounds_active[name] = "upper"
        if name in bounds_active:
            bound_mult[name] = float(lam[i] / eps[i])
    return SynthesisResult(
        solver=solver, status=status, success=status is Status.OPTIMAL, message=message,
        tolerances=dict(zip(spec.names, map(float, eps))), units=dict(zip(spec.names, spec.units)),
        cost=cost, constraints=tuple(cblocks), bounds_active=bounds_active, bound_multipliers=bound_mult,
        lower_bound=lower, gap=cost - lower, iterations=iters, function_evaluations=0,
        wall_time=time.perf_counter() - t0, spec=spec, history=history)


def _peak_bound(nlp: ToleranceNLP, shapes: tuple, blocks: list[_Block]) -> float:
    """The valid, loose lower bound of the module docstring: eps_i <= 2 R f_i(0) / (p |a_i|) along
    the direction of a_i (sphere: P(|dr| <= R) <= P(|w . dr| <= R) for any w, the same cap)."""
    spec = nlp.spec
    cap = spec.upper.copy()
    peak = np.array([s.peak for s in shapes])
    for blk in blocks:
        norm = np.linalg.norm(blk.A, axis=0)
        with np.errstate(divide="ignore"):
            c = np.where(norm > 0, 2 * blk.R * peak / (blk.p * norm), np.inf)
        cap = np.minimum(cap, c)
    cap = np.maximum(cap, spec.lower)
    return float(nlp.cost(cap))


def exact_margin(mechanism, q, eps, distribution, R: float, p: float, criterion: str = "components") -> float:
    """``(1 - P) / (1 - p)`` at one pose by the exact probabilities: P along the worst direction
    (per component) or in the sphere; <= 1 meets the specification (used by the workspace exchange)."""
    from tolsynth.probability.distributions import resolve, shapes_of

    shapes = shapes_of(resolve(distribution, mechanism), mechanism.error_parameters, mechanism.index)
    A = mechanism.sensitivity(mechanism.joints(q), check_limits=False)[:3]
    eps = np.asarray(eps, dtype=float)
    if criterion == "sphere":
        P = ex.ball_probability(A, eps, shapes, R, tol=SPHERE_TOL, max_nodes=128, return_error=True)[0]
    else:
        P = ex.worst_direction(A, eps, shapes, R, tol=1e-10)[1]
    return (1.0 - P) / (1.0 - p)
