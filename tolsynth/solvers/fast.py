"""The default engine of :func:`tolsynth.synthesize` (``solver="auto"``): a structure-exploiting
interior-point method where the problem is in its class, IPOPT everywhere else.

The class: the per-component criterion (the paper's Eq. 20-22, position and orientation blocks at
any number of poses) with every cost the paper's power law ``k eps^-alpha``.  There the compiled
primal-dual method of :mod:`tolsynth.solvers.fast_ipm` solves the LMI form directly (a few
hundred microseconds on the paper's robot, cold).  Anything else (the sphere criterion, other cost
models, no compiler, a run of the method that does not reach its accuracy) goes to
:func:`tolsynth.solvers.ipopt.solve_ipopt`, which stays the general path and the cross-check
(``solver="ipopt"`` always runs it).

What is returned does not rest on the compiled code: the primal point is recomputed here from
the method's multipliers ``Z`` (the closed-form Lagrangian minimiser,
:meth:`tolsynth.model.cost_set.CostSet.dual_min`), every block is checked at it by NumPy's
eigensolver, and :func:`tolsynth.solvers.common.assemble` certifies it with the dual bound of
``Z`` (PSD-projected) exactly as for IPOPT: ``success`` needs the point feasible and the gap within
1e-6 of the cost.

Many poses.  Up to :data:`ALL_BLOCKS` blocks the method takes them all at once (one solve, the
same whatever ran before).  Beyond, it works on a set of blocks (an exchange method over poses):
those active at the last solve of the same poses (a sweep re-solves the same poses), else those
nearest to their limit at the start point; every block is checked at each round's optimum and the
violated ones join the set.  Each round is solved to the same accuracy, so the working set
changes the time, not the answer.
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict

import numpy as np

from tolsynth.model.cost import PowerLaw
from tolsynth.problem.nlp import ToleranceNLP
from tolsynth.problem.result import Status
from tolsynth.progress import remaining
from tolsynth.solvers.common import assemble
from tolsynth.solvers.fast_ipm import kernel, kernel_status, unpack

__all__ = ["solve_auto", "solve_fast", "applies", "ALL_BLOCKS"]

#: up to this many blocks the method solves them all at once (no working set)
ALL_BLOCKS = 128
#: the first working set of a larger problem: the blocks within this fraction of the worst value at
#: the start point, at most START_BLOCKS of them
START_FRACTION = 0.7
START_BLOCKS = 32
#: violated blocks added per exchange round at most (the most violated first)
MAX_NEW_BLOCKS = 64
#: what the method must at least reach (largest primal residual |S + M - I|, complementarity over
#: the cost) for its answer to be used, else IPOPT solves; it aims at ``tol`` (IPOPT's option, 1e-10)
ACCEPT = 1e-9
#: Z_b counts as active where its trace is above this fraction of the largest
ACTIVE_Z = 1e-9
MAX_ROUNDS = 30
#: the method's attempts on one working set: y the Lagrangian's minimiser of each iterate's
#: multipliers (fewest iterations on most problems), then, where that does not reach its accuracy,
#: y an iterate of its own (robust where the minimiser moves by large factors between iterates)
MODES = (False, True)
#: ... the first at most this many iterations (it converges in 8-30 where it converges at all)
FIRST_MODE_ITER = 40

#: the active blocks of recent solves, by the blocks' sensitivity rows (free of R, p and the cost)
_ACTIVE: "OrderedDict[bytes, np.ndarray]" = OrderedDict()
_ACTIVE_SIZE = 64


def applies(nlp: ToleranceNLP) -> str | None:
    """None if the interior-point method takes this problem, else why not (a sentence)."""
    spec = nlp.spec
    if spec.sphere_blocks:
        return "the sphere criterion"
    if nlp.costs.power_law() is None:
        return "a cost model other than the power law"
    if not spec.blocks:
        return "no accuracy block"
    if kernel() is None:
        return f"the compiled interior-point method is not available ({kernel_status()['reason']})"
    return None


def solve_auto(nlp: ToleranceNLP, eps0: np.ndarray | None = None, **options):
    """The interior-point method where it applies and reaches its accuracy, else IPOPT (from
    ``eps0``; the interior-point method needs no start).  Options: those of
    :data:`tolsynth.solvers.ipopt.DEFAULT_OPTIONS`, read by both (see :func:`solve_fast`)."""
    from tolsynth.solvers.ipopt import DEFAULT_OPTIONS, solve_ipopt

    if options:
        unknown = set(options) - set(DEFAULT_OPTIONS)
        if unknown:
            from tolsynth.errors import InputError

            raise InputError("options", f"unknown option(s) {sorted(unknown)}", ", ".join(DEFAULT_OPTIONS))
    why = applies(nlp)
    if why is None:
        result, why = solve_fast(nlp, **options)
        if result is not None:
            return result
    from dataclasses import replace

    result = solve_ipopt(nlp, eps0, **options)
    return replace(result, message=f"{result.message} (IPOPT: {why})")


def solve_fast(nlp: ToleranceNLP, **options):
    """``(result, None)`` from the interior-point method, or ``(None, why)`` where it did not reach
    :data:`ACCEPT` or its point is not feasible (the caller then runs IPOPT).

    Options (IPOPT's names): ``tol`` (the method's target for the largest primal residual and the
    complementarity relative to the cost, default and at most 1e-10), ``feas_tol`` (largest ``sigma z / R - 1``
    accepted at the returned point, default 1e-9), ``max_iter`` (per solve of the
    method, at most 100), ``max_rounds`` (exchange rounds over blocks) and ``warm_start`` (False:
    the first working set of a problem with many blocks from the start point, not from the last
    solve of the same blocks); ``constr_viol_tol`` is IPOPT's alone.
    """
    spec = nlp.spec
    tol = min(float(options.get("tol", 1e-10)), 1e-10)  # the method is cheap: never looser than 1e-10
    feas_tol = options.get("feas_tol")
    feas_tol = 1e-9 if feas_tol is None else float(feas_tol)
    max_iter = min(int(options.get("max_iter", 100)), 100)
    max_rounds = min(int(options.get("max_rounds", MAX_ROUNDS)), MAX_ROUNDS)
    t_start = time.perf_counter()
    m, n = len(spec.blocks), spec.n
    lo, hi = spec.lower, spec.upper
    if not (lo < hi).any():  # every tolerance locked: nothing to choose, the multipliers are 0
        vals = nlp.block_values(lo)[0][:, 0]
        if not float(vals.max()) <= 1.0 + feas_tol:
            return None, "every tolerance is locked and the locks break the specification"
        return assemble("ipm", nlp, lo, np.zeros((m, 3, 3)), np.zeros(n), Status.OPTIMAL,
                        "every tolerance locked: nothing to optimise", 0, 0, time.perf_counter() - t_start, []), None
    # the cost in y = eps^2, divided by what it can fall by from the middle of the bounds to the
    # upper bounds (a locked parameter, or one held near its upper bound, adds a constant that may
    # be most of the cost and says nothing of the multipliers' size; the method's iterates do not
    # depend on this scale, its arithmetic does)
    k, alpha = nlp.costs.power_law()
    excess = PowerLaw._expr(0.5 * (nlp.lu + nlp.uu), (k, alpha), np) - PowerLaw._expr(nlp.uu, (k, alpha), np)
    f_ref = float(excess.sum())
    if not f_ref > 0.0:
        f_ref = float(k.sum())
    par = np.concatenate([k / f_ref, alpha, lo * lo, hi * hi])
    A_all = nlp.As * (1.0 / math.sqrt(spec.c))  # block b: A_b diag(eps^2) A_b^T = (z/R)^2 V_b
    if m <= ALL_BLOCKS:
        J, key = None, None
    else:
        key = b"".join(b.A.tobytes() for b in spec.blocks)
        J = _ACTIVE.get(key) if options.get("warm_start", True) else None
        if J is None:
            J = _start_set(nlp)
    solve = kernel().solve
    iterations, history, rounds = 0, [], 0
    while True:
        rounds += 1
        A = A_all if J is None else np.ascontiguousarray(A_all[J])
        if remaining() <= 0:  # the time limit (tolsynth.progress.time_limit): IPOPT reports it
            return None, "the time limit passed"
        for primal in MODES:
            limit = max_iter if primal else min(max_iter, FIRST_MODE_ITER)
            status, state, zb, info = solve(A, par, None, tol, limit, primal=primal)
            iterations += int(info[6])
            Z, _, y = unpack(state, A.shape[0], n)
            eps = np.minimum(np.maximum(np.sqrt(y), lo), hi)  # as assemble clips it (the same memo)
            # one entry per run of the method: its best iterate's cost, primal residual and
            # complementarity relative to the cost
            history.append({"round": rounds, "mode": "iterate" if primal else "minimiser",
                            "iteration": int(info[0]), "objective": nlp.cost(eps), "inf_pr": float(info[4]),
                            "inf_du": float(info[3]) / max(float(info[2]), 1e-300)})
            if status < 2 and info[1] <= max(ACCEPT, tol):
                break
        else:
            return None, (f"the interior-point method stopped at error {info[1]:.1e} > {max(ACCEPT, tol):g} "
                          f"(status {status}, round {rounds})")
        vals = nlp.block_values(eps)[0][:, 0]
        worst = float(vals.max())
        if worst <= 1.0 + feas_tol or J is None or len(J) == m:
            break
        if rounds >= max_rounds:
            return None, f"the exchange over blocks did not close in {max_rounds} rounds"
        out = np.setdiff1d((vals > 1.0 + feas_tol).nonzero()[0], J)
        J = np.union1d(J, out[np.argsort(-vals[out])][:MAX_NEW_BLOCKS])
    wall = time.perf_counter() - t_start
    if worst > 1.0 + feas_tol:
        return None, f"largest sigma z/R - 1 = {worst - 1:.1e} > {feas_tol:g} at the method's point"
    if J is None:
        Zs = Z * f_ref
    else:
        Zs = np.zeros((m, 3, 3))
        Zs[J] = Z * f_ref
        tr = np.trace(Z, axis1=1, axis2=2)
        _remember(key, J[tr > ACTIVE_Z * max(float(tr.max()), 1e-300)])
    lam_u = (2.0 * f_ref) * y * zb  # the bounds' multipliers in u = ln eps (d/du = 2 y d/dy)
    message = (f"interior point: {iterations} iterations, {rounds} round(s), {m if J is None else len(J)} of "
               f"{m} block(s); primal residual {info[4]:.1e}")
    return assemble("ipm", nlp, eps, Zs, lam_u, Status.OPTIMAL, message, iterations, iterations + rounds, wall,
                    history), None


def _start_set(nlp: ToleranceNLP) -> np.ndarray:
    """The first working set of a problem with many blocks: those near the worst at the start point
    (within :data:`START_FRACTION` of it, at most :data:`START_BLOCKS`)."""
    vals = nlp.block_values(nlp.start_point())[0][:, 0]
    order = np.argsort(-vals)[:START_BLOCKS]
    return np.sort(order[vals[order] >= START_FRACTION * vals[order[0]]])


def _remember(key: bytes, active: np.ndarray) -> None:
    _ACTIVE[key] = active
    _ACTIVE.move_to_end(key)
    while len(_ACTIVE) > _ACTIVE_SIZE:
        _ACTIVE.popitem(last=False)
