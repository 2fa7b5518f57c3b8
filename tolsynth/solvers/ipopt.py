"""IPOPT (through CasADi) on the tolerance problem, by an exchange (cutting-plane) method.

Formulation.  The accuracy demand of a block b (a pose, position or orientation) is the matrix
inequality ``lambda_max(scale_b^2 V_b(eps)) <= 1``, i.e. for *every* unit direction w

    sum_i exp(2 u_i) C_i(w) <= 1,     C_i(w) = scale_b^2 (a_bi . w)^2 / c,   u = ln eps,

a sum of exponentials: smooth and convex in u for every w.  IPOPT solves a small NLP over a finite
set of such cuts (pose, direction) with the exact Hessian; NumPy then evaluates every block at the
IPOPT point at once (batched ``eigh``), adds the principal directions of the blocks that are still
violated as new cuts, and IPOPT re-solves from the previous round's optimum and multipliers (a
warm start; 0 for the new cuts).  This repeats until the largest
``sigma z / R`` over all blocks is within ``feas_tol`` of 1.  Why this and not the former factor form
``G(u) - L L^T = 0``: the factor variables made the NLP non-convex (IPOPT reported local
infeasibility on feasible multi-pose sets), and its size grew with the number of poses, while the
cut NLP stays convex in every variable IPOPT sees and only as large as the set of cuts that matter
(a handful of (pose, direction) pairs even at 1000 poses).

The cut multipliers ``mu_k >= 0`` give the LMI multipliers ``Z_b = sum_k mu_k w_k w_k^T``, positive
semi-definite by construction, for the dual-bound certificate of :meth:`ToleranceNLP.dual_bound`;
its Lagrangian weights come from the cuts directly (:meth:`ToleranceNLP.lagrangian_bound`), with no
eigensolve.

Scaling: the cost is divided by its value at the start point (so k, alpha and the tolerance units
can be extreme); the cuts are normalised to 1 by construction.

For the sphere criterion (beyond the paper) each sphere block adds the smooth inequality
``P_b(u) >= p_b`` from :func:`tolsynth.problem.nlp.sphere_graph` to the same NLP.

Return codes are mapped to :class:`tolsynth.problem.result.Status` here (``Solved_To_Acceptable_Level``
is *not* plain success).  A solve interrupted by Ctrl-C is never retried: KeyboardInterrupt is
raised again.
"""

from __future__ import annotations

import math
import threading
import time
from collections import OrderedDict
from functools import lru_cache

import casadi as ca
import numpy as np

from tolsynth.problem.nlp import ToleranceNLP, cost_graph, sphere_graph
from tolsynth.problem.result import Status
from tolsynth.progress import limit_seconds, remaining
from tolsynth.solvers.common import assemble

__all__ = ["solve_ipopt", "IPOPT_STATUS", "DEFAULT_OPTIONS"]

IPOPT_STATUS = {
    "Solve_Succeeded": Status.OPTIMAL,
    "Solved_To_Acceptable_Level": Status.OPTIMAL_INACCURATE,
    "Infeasible_Problem_Detected": Status.INFEASIBLE,
    "Maximum_Iterations_Exceeded": Status.ITERATION_LIMIT,
    "Maximum_CpuTime_Exceeded": Status.TIME_LIMIT,
    "Maximum_WallTime_Exceeded": Status.TIME_LIMIT,
    "Restoration_Failed": Status.NUMERICAL_ERROR,
    "Error_In_Step_Computation": Status.NUMERICAL_ERROR,
    "Search_Direction_Becomes_Too_Small": Status.NUMERICAL_ERROR,
    "Diverging_Iterates": Status.NUMERICAL_ERROR,
    "Invalid_Number_Detected": Status.NUMERICAL_ERROR,
}

#: IPOPT's own tolerances, its iteration limit per cut NLP, the exchange method's limits, and
#: whether a solve may start from what an earlier solve of the same blocks in this process left
#: (its active cuts and its optimum rescaled).  False by default: a solve starts from scratch, so
#: its answer depends on nothing run before it; a warm start lands on the same optimum only to
#: about the solver's tolerance (1e-9 of a tolerance on the paper's column), so it is the user's
#: explicit choice, for speed
DEFAULT_OPTIONS = {
    "tol": 1e-10,
    "constr_viol_tol": 1e-12,
    "max_iter": 500,
    "feas_tol": None,
    "max_rounds": 60,
    "warm_start": False,
}

#: tried in turn on a cut NLP until one ends in Solve_Succeeded
ATTEMPTS = ("adaptive", "monotone")

#: cut slots come in these sizes (padded with zero rows), so one compiled NLP serves many cut sets
_SLOTS = (4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096)

#: new cuts per round at most (the most violated blocks first)
MAX_NEW_CUTS = 64
AGGREGATE = True  # aggregate multiplier directions as cuts and drop inactive cuts (bundle-style)

#: later exchange rounds start from the last round's primal-dual optimum (False: cold, as round 1)
REWARM = True
#: ... with IPOPT's barrier parameter and warm-start pushes at these values
REWARM_MU = 1e-6
REWARM_PUSH = 1e-10

#: principal directions within this fraction of a block's largest sigma count as near-active
NEAR_ACTIVE = 0.9


class CutNLP:
    """A cut NLP's ``nlpsol``, called through CasADi's zero-copy buffers.

    :meth:`solve` copies the inputs into NumPy arrays that the solver reads in place, runs it, and
    returns copies of the outputs with the solver's ``stats``: no ``DM`` conversion on the way in
    or out (about 0.15 ms of a 0.6 ms warm IPOPT call on the paper's column).  Each thread gets its
    own buffer (a buffer holds one solver memory), made on its first call.
    """

    _INPUTS = ("x0", "p", "lbx", "ubx", "lbg", "ubg", "lam_x0", "lam_g0")
    _OUTPUTS = ("x", "f", "g", "lam_x", "lam_g")
    #: a buffer's solver memory counts evaluations over all its calls: reported per call
    _COUNTERS = ("n_call_nlp_f", "n_call_nlp_g")

    def __init__(self, function: ca.Function):
        self.function = function
        self._local = threading.local()
        self._in_index = [function.index_in(name) for name in self._INPUTS]
        self._out_index = [function.index_out(name) for name in self._OUTPUTS]

    def _buffer(self):
        buf = getattr(self._local, "buf", None)
        if buf is None:
            f = self.function
            ins = [np.zeros(f.nnz_in(i)) for i in self._in_index]
            outs = [np.zeros(f.nnz_out(i)) for i in self._out_index]
            handle, run = f.buffer()
            for i, a in zip(self._in_index, ins):
                handle.set_arg(i, memoryview(a))
            for i, a in zip(self._out_index, outs):
                handle.set_res(i, memoryview(a))
            buf = self._local.buf = (handle, run, ins, outs)
            self._local.calls = dict.fromkeys(self._COUNTERS, 0)
        return buf

    def solve(self, x0, p, lbx, ubx, lbg, ubg, lam_x0=None, lam_g0=None) -> tuple[dict, dict]:
        """Run IPOPT; ``({"x", "f", "g", "lam_x", "lam_g"}: 1-D arrays, stats)``."""
        handle, run, ins, outs = self._buffer()
        for a, v in zip(ins, (x0, p, lbx, ubx, lbg, ubg, lam_x0, lam_g0)):
            if v is None:
                a.fill(0.0)
            else:
                a[:] = v
        run()
        stats = handle.stats()
        last = self._local.calls
        for key in self._COUNTERS:  # this call's own evaluations
            total = stats.get(key, 0)
            stats[key], last[key] = total - last[key], total
        return dict(zip(self._OUTPUTS, (a.copy() for a in outs))), stats


class _CallNLP(CutNLP):
    """The same through ``Function.__call__`` (a CasADi without ``Function.buffer``)."""

    def __init__(self, function: ca.Function):
        self.function = function

    def solve(self, x0, p, lbx, ubx, lbg, ubg, lam_x0=None, lam_g0=None) -> tuple[dict, dict]:
        kw = dict(x0=x0, p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        if lam_x0 is not None:
            kw.update(lam_x0=lam_x0, lam_g0=lam_g0)
        sol = self.function(**kw)
        return {k: np.array(sol[k]).ravel() for k in self._OUTPUTS}, self.function.stats()


@lru_cache(maxsize=64)
def _solver(
    n: int,
    K: int,
    tol: float,
    constr_viol_tol: float,
    max_iter: int,
    mu_strategy: str,
    m_sphere: int = 0,
    sphere_nodes: int = 0,
    cost_signature: tuple | None = None,
    max_wall_time: float = 1e20,
) -> CutNLP:
    """The cut NLP for n parameters and K cut slots: ``min f(u)/f0  s.t.  C exp(2u) <= 1``."""
    n_ps = 1 + m_sphere + 3 * n * m_sphere if m_sphere else 0
    cost = cost_graph(n, cost_signature)
    nt = cost.size1_in(1)
    u = ca.SX.sym("u", n)
    p = ca.SX.sym("p", K * n + nt + 1 + n_ps)
    C = ca.reshape(p[: K * n], K, n)
    theta = p[K * n : K * n + nt]
    f0 = p[K * n + nt]
    g = [ca.mtimes(C, ca.exp(2 * u))]
    if m_sphere:  # P(|dr| <= R_b) >= p_b, bounds given through lbg
        g.append(sphere_graph(n, m_sphere, sphere_nodes)(u, p[K * n + nt + 1 :]))
    nlp = {"x": u, "p": p, "f": cost(u, theta) / f0, "g": ca.vertcat(*g)}
    opts = {
        "print_time": False,
        # a trial point may overflow (Inf) on the way; IPOPT backtracks from it by itself, so the
        # evaluation warning is noise for the user (the outcome is in the return status)
        "show_eval_warnings": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.tol": tol,
        "ipopt.constr_viol_tol": constr_viol_tol,
        "ipopt.max_iter": max_iter,
        "ipopt.max_wall_time": max_wall_time,  # the run's time limit (tolsynth.progress.time_limit)
        # never stop at the "acceptable" level silently: only Solve_Succeeded is success
        "ipopt.acceptable_iter": 0,
        "ipopt.hessian_approximation": "exact",
        "ipopt.mu_strategy": "monotone" if mu_strategy in ("warm", "rewarm") else mu_strategy,
    }
    # warm starts, from a point and multipliers given with the call:
    # * "warm": the remembered optimum of the same blocks.  The slacks and bounds pushed as little as
    #   the point itself: from an optimum IPOPT then needs 1 iteration instead of 3 (measured on the
    #   paper's column), and none where the point already meets this problem's KKT conditions to tol
    #   (the same column solved again: a push of 1e-9 alone left a complementarity of ~1e-10 there,
    #   one iteration more).  On 384 solves (3 models, R 0.3-10 mm, p 0.9-0.999, both
    #   distributions) 1e-12 against 1e-9: 107 solves with 0 iterations instead of 1, none slower,
    #   none failed.
    # * "rewarm": a later exchange round, from the last round's optimum and multipliers (0 for the
    #   new cuts, which that point violates).  On 48 random pose sets (1-30 poses, four models, two
    #   distributions) 4.45 s against 5.94 s from a cold start, the same optima to 3.5e-9, no round
    #   left to the cold attempts (which follow if it does not succeed).
    warm = {"warm": (1e-6, 1e-12), "rewarm": (REWARM_MU, REWARM_PUSH)}.get(mu_strategy)
    if warm is not None:
        mu_init, push = warm
        opts.update(
            {
                "ipopt.warm_start_init_point": "yes",
                "ipopt.mu_init": mu_init,
                "ipopt.warm_start_bound_push": push,
                "ipopt.warm_start_mult_bound_push": push,
                "ipopt.warm_start_bound_frac": push,
                "ipopt.warm_start_slack_bound_push": push,
                "ipopt.warm_start_slack_bound_frac": push,
            }
        )
    if mu_strategy == "warm":
        # from a rescaled optimum every cut is <= 1 (gradient <= 2) and the objective is divided
        # by f0 (for the power law each gradient is at most alpha_i <= 10), so IPOPT's
        # gradient-based scaling (only where a gradient exceeds 100) would be 1 anyway: "none"
        # saves its extra gradient and Jacobian evaluations.  (Another cost model may have
        # steeper gradients; the warm attempt then runs unscaled, and the cold attempts, with
        # the default scaling, follow if it does not succeed.)
        opts["ipopt.nlp_scaling_method"] = "none"
    solver = ca.nlpsol("tolerance_cuts", "ipopt", nlp, opts)
    return CutNLP(solver) if hasattr(solver, "buffer") else _CallNLP(solver)


#: the active cuts at the end of recent solves, by the blocks' sensitivity rows (directions do not
#: depend on R, p, c or the cost, only on where the optimum sits); read only by a solve asked to
#: warm-start (``warm_start=True``)
_CUT_CACHE: "OrderedDict[tuple, tuple[np.ndarray, np.ndarray]]" = OrderedDict()
_CUT_CACHE_SIZE = 256


def _cache_key(nlp: ToleranceNLP) -> tuple:
    spec = nlp.spec
    return (
        spec.n,
        len(spec.blocks),
        b"".join(np.ascontiguousarray(b.A).tobytes() for b in spec.blocks),
        nlp.costs.signature,
        nlp.theta.tobytes(),
        spec.lower.tobytes(),
        spec.upper.tobytes(),
    )


def _remember(key: tuple, cut_b: np.ndarray, cut_w: np.ndarray, raw: np.ndarray, warm: tuple | None = None) -> None:
    """Remember a solve's active cuts (blocks, unit directions and their rows ``(A_b^T w)^2`` free of
    z/R and c: see :func:`_row_factor`) and, for a warm start, ``(eps, cut
    multipliers, bound multipliers in u, lambda_max(A_b diag(eps^2) A_b^T) per block, cost)`` with
    the multipliers in cost units (not divided by that solve's f0); the fourth, free of z/R and c,
    rescales eps onto another specification of the same blocks without an eigensolve.  The arrays
    are kept as given (callers pass arrays of their own)."""
    _CUT_CACHE[key] = (cut_b, cut_w, raw, warm)
    _CUT_CACHE.move_to_end(key)
    while len(_CUT_CACHE) > _CUT_CACHE_SIZE:
        _CUT_CACHE.popitem(last=False)


def _slots(k: int) -> int:
    for s in _SLOTS:
        if s >= k:
            return s
    return k


@lru_cache(maxsize=None)
def _cut_bounds(slots: int) -> tuple[np.ndarray, np.ndarray]:
    """``(lbg, ubg)`` of ``slots`` cuts ``C exp(2u) <= 1`` (read-only; no sphere blocks)."""
    lbg, ubg = np.full(slots, -np.inf), np.ones(slots)
    lbg.setflags(write=False)
    ubg.setflags(write=False)
    return lbg, ubg


def _cut_rows(nlp: ToleranceNLP, blocks: np.ndarray, W: np.ndarray) -> np.ndarray:
    """``C_i = (As_b^T w)_i^2 / c`` for cuts (block b, unit direction w); shape (K, n)."""
    proj = np.einsum("kin,ki->kn", nlp.As[blocks], W)
    return proj**2 / nlp.spec.c


def _row_factor(nlp: ToleranceNLP, blocks: np.ndarray) -> np.ndarray:
    """``scale_b^2 / c`` per cut, a column: :func:`_cut_rows` is ``(A_b^T w)^2`` times this, and
    ``(A_b^T w)^2``, free of z/R and c, is what the cut cache keeps."""
    return (nlp.scales[blocks] ** 2 / nlp.spec.c)[:, None]


def solve_ipopt(nlp: ToleranceNLP, eps0: np.ndarray | None = None, *, sphere_bounds: bool = True, **options):
    """Solve with IPOPT by the exchange method from ``eps0`` (default: :meth:`ToleranceNLP.start_point`).

    Options: tol, constr_viol_tol, max_iter (IPOPT's own, per cut NLP), feas_tol (largest
    ``sigma z / R - 1`` accepted over all blocks; default ``min(1e-9, 10 tol)``), max_rounds
    (exchange rounds) and warm_start (default False: from scratch; True: start from the active cuts
    and the rescaled optimum of the last solve in this process of the same blocks, cost model and
    bounds, if there is one, which is faster but reaches the optimum only to the solver's
    tolerance, so that the answer then depends on what ran before).
    ``sphere_bounds=False`` leaves out the sphere criterion's lower bounds (their result's
    ``lower_bound`` is then -inf): for a design wanted only as another method's start.
    """
    opts = {**DEFAULT_OPTIONS, **options}
    unknown = set(opts) - set(DEFAULT_OPTIONS)
    if unknown:
        from tolsynth.errors import InputError

        raise InputError("options", f"unknown IPOPT option(s) {sorted(unknown)}", ", ".join(DEFAULT_OPTIONS))
    spec = nlp.spec
    n, m, ms = spec.n, len(spec.blocks), len(spec.sphere_blocks)
    # default: as tight as IPOPT's own tolerance asks (1e-9 at the default tol)
    feas_tol = min(1e-9, 10.0 * float(opts["tol"])) if opts["feas_tol"] is None else float(opts["feas_tol"])
    # initial cuts: with warm_start, those that were active at the end of the last solve on the
    # same blocks (a sweep over R, p, the distribution or the cost re-solves the same poses), else
    # every principal direction of the blocks that are near the worst at the start
    cut_b = np.zeros(0, dtype=int)
    cut_w = np.zeros((0, 3))
    key = _cache_key(nlp)
    cached = _CUT_CACHE.get(key) if opts["warm_start"] else None
    warm = raw_rows = None
    if cached is not None:
        cut_b, cut_w, raw_rows, warm = cached
    use_warm = warm is not None and eps0 is None and not ms and len(cut_b) == len(warm[1])
    if use_warm:
        # that optimum rescaled onto this specification's constraint (V is homogeneous of degree
        # 2 in eps): the start of the warm attempt, and the cost scale f0 (no start_point needed)
        worst = math.sqrt(float((warm[3] * nlp.scales**2).max()) / spec.c)  # largest sigma z/R at warm[0]
        eps_w = np.minimum(np.maximum(warm[0] / max(worst, 1e-300), spec.lower), spec.upper)
        eps = eps_w
    else:
        eps = nlp.start_point() if eps0 is None else np.clip(np.asarray(eps0, dtype=float), spec.lower, spec.upper)
    u = np.log(eps)
    f0 = nlp.cost(eps, u)
    pfix = np.concatenate([nlp.theta, [f0]] + ([nlp.Ps] if ms else []))
    if cached is None and m:
        vals, dirs = nlp.block_values(eps)
        worst = vals[:, 0]
        pick = np.argsort(-worst)[: min(m, 8)]
        pick = pick[worst[pick] >= 0.5 * worst[pick[0]]]
        cut_b = np.repeat(pick, 3)
        cut_w = dirs[pick].transpose(0, 2, 1).reshape(-1, 3)

    wall, iters, nfev, rounds = 0.0, 0, 0, 0
    tried: list[str] = []
    history: list[dict] = []
    lam_g = np.zeros(0)
    lam_x = np.zeros(n)
    lam_next = np.zeros(0)  # the multipliers a later round starts from (set at the end of each round)
    status, code = Status.ITERATION_LIMIT, f"exchange method: no convergence in {opts['max_rounds']} rounds"
    max_viol = np.inf
    settings = (float(opts["tol"]), float(opts["constr_viol_tol"]), int(opts["max_iter"]))
    sphere = (ms, nlp.sphere_nodes if ms else 0, nlp.costs.signature)
    t_start = time.perf_counter()
    while rounds < int(opts["max_rounds"]):
        if rounds and remaining() <= 0:  # the run's time limit: the last round's point stands
            status, code = Status.TIME_LIMIT, f"time limit of {limit_seconds():g} s reached after {rounds} rounds"
            break
        rounds += 1
        K = len(cut_b)
        slots = _slots(max(K, 1)) if m else 0
        # the parameter [vec(C) (column-major), pfix]: C written in place through a transposed view
        pval = np.zeros(slots * n + len(pfix))
        pval[slots * n :] = pfix
        if rounds == 1 and raw_rows is not None:  # the remembered cuts: their rows rescaled
            rows = raw_rows * _row_factor(nlp, cut_b)
        else:
            rows = _cut_rows(nlp, cut_b, cut_w) if K else np.zeros((0, n))
        pval[: slots * n].reshape(n, slots).T[:K] = rows
        solved = (cut_b, cut_w, rows)  # the cuts of this round's NLP (its multipliers' order)
        if ms:
            lbg = np.concatenate([np.full(slots, -np.inf), nlp.p_sphere])
            ubg = np.concatenate([np.ones(slots), np.full(ms, np.inf)])
        else:
            lbg, ubg = _cut_bounds(slots)
        # the first round of a problem whose blocks were solved before starts from that optimum
        # (rescaled onto this specification's constraint) with its multipliers; if that does not
        # end in Solve_Succeeded the cold attempts follow from the usual start
        attempts = ATTEMPTS
        if rounds == 1 and use_warm:
            attempts = ("warm",) + ATTEMPTS
        elif rounds > 1 and REWARM and not ms:
            attempts = ("rewarm",) + ATTEMPTS
        for mu_strategy in attempts:
            solver = _solver(n, slots, *settings, mu_strategy, *sphere, min(limit_seconds(), 1e20))
            if mu_strategy == "warm":
                lam0 = np.zeros(slots)
                # the multipliers divided by the remembered cost, not by f0: under the rescaling
                # u + ln s, the cost (a common alpha) and every multiplier scale by s^-alpha, so in
                # f0 units they are what they were in that solve's own (an R or p sweep's warm start
                # is then the new optimum with its multipliers: no IPOPT iteration)
                lam0[:K] = warm[1] / warm[4]
                sol, stats = solver.solve(u, pval, nlp.lu, nlp.uu, lbg, ubg, warm[2] / warm[4], lam0)
            elif mu_strategy == "rewarm":
                lam0 = np.zeros(slots)
                lam0[: len(lam_next)] = lam_next
                sol, stats = solver.solve(u, pval, nlp.lu, nlp.uu, lbg, ubg, lam_x, lam0)
            else:
                if rounds == 1 and use_warm:  # the warm attempt failed: the cold ones from the usual start
                    u = np.log(nlp.start_point())
                sol, stats = solver.solve(u, pval, nlp.lu, nlp.uu, lbg, ubg)
            code = stats.get("return_status", "unknown")
            if code in ("NonIpopt_Exception_Thrown", "User_Requested_Stop"):
                # Ctrl-C inside the solve: CasADi swallows the signal; never retry, re-raise it
                raise KeyboardInterrupt
            iters += int(stats.get("iter_count", 0))
            nfev += int(stats.get("n_call_nlp_f", 0)) + int(stats.get("n_call_nlp_g", 0))
            status = IPOPT_STATUS.get(code, Status.SOLVER_ERROR)
            it = stats.get("iterations", {})
            history += [
                {"round": rounds, "iteration": i, "objective": float(o) * f0, "inf_pr": float(ip), "inf_du": float(idu)}
                for i, (o, ip, idu) in enumerate(zip(it.get("obj", []), it.get("inf_pr", []), it.get("inf_du", [])))
            ]
            if status is Status.OPTIMAL:
                break
            tried.append(f"round {rounds} {mu_strategy}: {code}")
            if remaining() <= 0:  # the run's time limit (tolsynth.progress.time_limit): no more attempts
                status, code = Status.TIME_LIMIT, f"time limit of {limit_seconds():g} s reached"
                break
        u, lam_g, lam_x = sol["x"], sol["lam_g"], sol["lam_x"]
        if status is not Status.OPTIMAL:
            break
        if not m:
            break
        eps = np.exp(u)
        vals, dirs = nlp.block_values(eps)
        over = vals - 1.0  # (m, 3)
        max_viol = float(over[:, 0].max())
        if max_viol <= feas_tol:
            break
        # new cuts, for the most violated blocks: their near-active principal directions and,
        # for every pair of those, the two bisecting directions (e_i +- e_j)/sqrt 2.  Where two
        # principal sigma coincide at the optimum (the paper's case), cuts along e_i and e_j alone
        # leave the off-diagonal term of V in their plane free, and the exchange crawls; the
        # bisectors pin it (V_ii = V_jj = 1 and (V_ii + V_jj)/2 +- V_ij <= 1 give V_ij = 0).
        order = np.argsort(-over[:, 0])
        order = order[over[order, 0] > feas_tol][:MAX_NEW_CUTS]
        new_b, new_w = [], []
        for b in order:
            near = np.nonzero(vals[b] >= NEAR_ACTIVE * vals[b, 0])[0]
            E = dirs[b][:, near]
            cols = [E[:, i] for i in range(E.shape[1])]
            for i in range(E.shape[1]):
                for j in range(i + 1, E.shape[1]):
                    cols += [(E[:, i] + E[:, j]) / np.sqrt(2.0), (E[:, i] - E[:, j]) / np.sqrt(2.0)]
            new_b += [b] * len(cols)
            new_w += cols
        # and the eigenvectors of each block's multiplier matrix Z_b = sum mu_k w_k w_k^T: at the
        # optimum these (not V's, arbitrary in a degenerate eigenspace) are the cut directions
        # that reproduce the LMI exactly (a strictly convex cut problem with them has the LMI's
        # optimum as its own)
        if AGGREGATE:
            K = len(cut_b)
            mu = np.maximum(lam_g[:K], 0.0)
            mu = np.where(mu > 1e-6 * max(float(np.max(mu, initial=0.0)), 1e-300), mu, 0.0)
            for b in np.unique(cut_b[mu > 0]):
                sel = (cut_b == b) & (mu > 0)
                Zb = (cut_w[sel].T * mu[sel]) @ cut_w[sel]
                lz, vz = np.linalg.eigh(Zb)
                for j in np.nonzero(lz > 1e-9 * lz[-1])[0]:
                    new_b.append(b)
                    new_w.append(vz[:, j])
        lam_next = np.maximum(lam_g[: len(cut_b)], 0.0)  # the next round's start: the kept cuts' multipliers
        if AGGREGATE:  # the aggregated cuts carry the information of the inactive ones: drop those
            keep = lam_next > 1e-6 * max(float(np.max(lam_next, initial=0.0)), 1e-300)
            cut_b, cut_w, lam_next = cut_b[keep], cut_w[keep], lam_next[keep]
        cut_b = np.concatenate([cut_b, np.array(new_b, dtype=int)])
        cut_w = np.concatenate([cut_w, np.array(new_w)])
    else:
        status = Status.ITERATION_LIMIT
    wall = time.perf_counter() - t_start

    if not (m and status is Status.OPTIMAL):  # else eps = exp(u) was checked at the end of the last round
        eps = np.exp(u)
    # the multipliers of the cuts of the last NLP solved (later rounds' new cuts have none)
    cut_b, cut_w, rows = solved if rounds else (cut_b[:0], cut_w[:0], np.zeros((0, n)))
    K = len(cut_b)
    mu = np.maximum(lam_g[:K], 0.0) * f0
    # the cut NLP's Lagrangian f(u) - sum_k mu_k (1 - C_k e^{2u}) = sum_i [c_i(u_i) + w_i e^{2u_i}] -
    # sum_k mu_k |w_k|^2: the LMI's with Z_b = sum_k mu_k w_k w_k^T (PSD by construction), so no
    # eigensolve is needed for the certificate
    lagrangian = (mu @ rows, float(mu @ (cut_w * cut_w).sum(axis=1)))  # sum_b tr Z_b = sum_k mu_k |w_k|^2
    if m == 1:  # one block (one pose): no scatter
        Z = ((cut_w.T * mu) @ cut_w)[None]
    else:
        on = mu > 0
        Wk = cut_w[on] * np.sqrt(mu[on])[:, None]  # Z_b = sum_k mu_k w_k w_k^T = sum_k Wk Wk^T
        Z = np.zeros((m, 3, 3))
        np.add.at(Z, cut_b[on], Wk[:, :, None] * Wk[:, None, :])
    lam_u = lam_x * f0  # the bound multipliers in u, cost units
    if status is Status.OPTIMAL and K:
        # remember each block's multiplier matrix by its eigenvectors: the fewest cuts that
        # reproduce this optimum's Lagrangian.  Without new cuts (one round) the cuts of each block
        # are orthonormal already (the eigenvectors remembered last time, or the principal
        # directions of the start), so they are Z_b's eigenvectors with eigenvalues mu_k
        if rounds == 1:
            keep = mu > 1e-9 * max(float(mu.max()), 0.0)
            if raw_rows is not None and keep.all():  # the remembered cuts, all still active
                rb, rw, rl, rr = cut_b, cut_w, mu, raw_rows
            else:
                rb, rw, rl = cut_b[keep], cut_w[keep], mu[keep]
                rr = rows[keep] / _row_factor(nlp, rb)  # (A_b^T w)^2
        else:
            bs = np.unique(cut_b)
            lz, vz = np.linalg.eigh(Z[bs])
            i, j = (lz > 1e-9 * max(float(lz.max()), 0.0)).nonzero()
            rb, rw, rl = bs[i], vz[i, :, j], lz[i, j]  # the cut along an eigenvector: its eigenvalue
            rr = _cut_rows(nlp, rb, rw) / _row_factor(nlp, rb)
        if len(rb):
            top = (vals[:, 0] / nlp.scales) ** 2 * spec.c  # vals: the check at eps, last round
            _remember(key, rb, rw, rr, (eps, rl, lam_u, top, float(sol["f"][0]) * f0))
    # P_b >= p_b active at its lower bound: CasADi's lam is <= 0 there; f - mu (P - p) with mu >= 0
    mu_sphere = -lam_g[len(lam_g) - ms :] * f0 if ms else np.zeros(0)
    message = code if status is Status.OPTIMAL else "; ".join(tried + [code] * (status is Status.TIME_LIMIT)) or code
    message = f"{message}; {rounds} exchange round(s), {K} cut(s)"
    if status is Status.OPTIMAL and m and max_viol > feas_tol:
        status = Status.ITERATION_LIMIT
        message += f"; largest sigma z/R - 1 = {max_viol:.2e} > {feas_tol:g}"
    return assemble(
        "ipopt",
        nlp,
        eps,
        Z,
        lam_u,
        status,
        message,
        iters,
        nfev,
        wall,
        history,
        mu_sphere=mu_sphere,
        lagrangian=lagrangian if m else None,
        relaxation_bound=relaxation_bound if sphere_bounds else None,
    )


def relaxation_bound(nlp: ToleranceNLP) -> float:
    """Certified lower bound for the sphere criterion: the per-component problem with the same p
    contains its feasible set; its own dual bound is valid whatever its solver's status."""
    return solve_ipopt(ToleranceNLP(nlp.spec.relaxed())).lower_bound
