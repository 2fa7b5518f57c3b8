"""The default engine of :func:`tolsynth.synthesize` (``solver="auto"``): a structure-exploiting
interior-point method where the problem is in its class, IPOPT everywhere else.

The class: the per-component criterion (the paper's Eq. 20-22, position and orientation blocks at
any number of poses) with every cost the paper's power law ``k eps^-alpha``.  There the compiled
primal-dual method of :mod:`tolsynth.solvers.fast_ipm` solves the LMI form directly (a few
hundred microseconds on the paper's robot, cold).  Anything else (the sphere criterion, other cost
models, no compiler, a run of the method that does not reach its accuracy) goes to
:func:`tolsynth.solvers.ipopt.solve_ipopt`, which stays the general path and the cross-check
(``solver="ipopt"`` always runs it).

What is returned does not rest on the compiled code's word: every block is checked at the
method's point by NumPy's eigensolver, and :func:`tolsynth.solvers.common.assemble` certifies the
point with the dual bound of the method's multipliers ``Z`` (PSD-projected, the Lagrangian
minimised in closed form by :meth:`tolsynth.model.cost_set.CostSet.dual_min`), exactly as for
IPOPT: ``success`` needs the point feasible and the gap within 1e-6 of the cost (the method closes
it to about 1e-11).

Cold by default.  Every solve starts from scratch (8-12 iterations on one pose), so that its
answer is a function of its problem alone, bit for bit, whatever ran before it in the process.

Warm starts, asked for (``options={"warm_start": True}``).  The last solve of each set of blocks
(the same poses and rows, whatever R, p, k, alpha, the bounds or the locks) is remembered; a solve
asked to warm-start that is close to it (a sweep's step: every change a few per cent at most)
starts from its optimum moved slightly into the interior, and takes 4-5 iterations; the very same
problem again takes none.  It reaches the same optimum only to about 1e-11 of the cost (1e-8 of a
tolerance), so its answer then depends on what ran before it: the user's choice, for speed.

Many poses.  Up to :data:`ALL_BLOCKS` blocks the method takes them all at once.  Beyond, it works
on a set of blocks (an exchange method over poses): those nearest to their limit at the start
point (with a warm start, those active at the last solve of the same poses); every block is
checked at each round's optimum and the violated ones join the set.
"""

from __future__ import annotations

import hashlib
import math
import time
from collections import OrderedDict
from functools import lru_cache

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

#: the last solve of recent block sets, by the blocks' sensitivity rows (free of R, p and the cost):
#: (the active blocks of a problem with many, else None; the final state on them; its cost
#: scale; its bounds of y; its k, alpha and blocks' scales); read only by a solve asked to
#: warm-start, as reading it makes the answer depend on the solves before
_MEMORY: "OrderedDict[tuple, tuple]" = OrderedDict()
_MEMORY_SIZE = 64
#: a warm start's distance from the cones' boundary (in the scaled multipliers and slacks)
WARM_SHIFT = 1e-4
#: ... taken only where the problem is this close to the remembered one (:func:`_distance`): a
#: sweep's step (a few per cent) halves the iterations; from farther an optimum is a worse start
#: than the cold one
WARM_DISTANCE = 0.05
#: a parameter whose bounds moved starts this far inside them (in ln y) at most
START_PAD = 0.1


def applies(nlp: ToleranceNLP, compiled=None) -> str | None:
    """None if the interior-point method takes this problem, else why not (a sentence);
    ``compiled``: the kernel if the caller has asked for it already."""
    spec = nlp.spec
    if spec.sphere_blocks:
        return "the sphere criterion"
    if nlp.costs.power_law() is None:
        return "a cost model other than the power law"
    if not spec.blocks:
        return "no accuracy block"
    if (compiled or kernel()) is None:
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
    compiled = kernel()
    why = applies(nlp, compiled)
    if why is None:
        result, why = solve_fast(nlp, compiled, **options)
        if result is not None:
            return result
    from dataclasses import replace

    result = solve_ipopt(nlp, eps0, **options)
    return replace(result, message=f"{result.message} (IPOPT: {why})")


def solve_fast(nlp: ToleranceNLP, compiled=None, **options):
    """``(result, None)`` from the interior-point method, or ``(None, why)`` where it did not reach
    :data:`ACCEPT` or its point is not feasible (the caller then runs IPOPT); ``compiled``: the
    kernel (:func:`tolsynth.solvers.fast_ipm.kernel`), if the caller has it.

    Options (IPOPT's names): ``tol`` (the method's target for the largest primal residual and the
    complementarity relative to the cost, default and at most 1e-10), ``feas_tol`` (largest
    ``sigma z / R - 1`` accepted at the returned point, default 1e-9), ``max_iter`` (per solve of
    the method, at most 100), ``max_rounds`` (exchange rounds over blocks) and ``warm_start``
    (default False: nothing from an earlier solve; True: the last solve of the same blocks in this
    process gives its optimum as the start, where the problem is close to it, and its active
    blocks as the working set); ``constr_viol_tol`` is IPOPT's alone.
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
        return assemble(
            "ipm",
            nlp,
            lo,
            np.zeros((m, 3, 3)),
            np.zeros(n),
            Status.OPTIMAL,
            "every tolerance locked: nothing to optimise",
            0,
            0,
            time.perf_counter() - t_start,
            [],
        ), None
    # the cost in y = eps^2, divided by what it can fall by from the middle of the bounds to the
    # upper bounds (a locked parameter, or one held near its upper bound, adds a constant that may
    # be most of the cost and says nothing of the multipliers' size; the method's iterates do not
    # depend on this scale, its arithmetic does)
    k, alpha = nlp.costs.power_law()
    excess = PowerLaw._expr(0.5 * (nlp.lu + nlp.uu), (k, alpha), np) - PowerLaw._expr(nlp.uu, (k, alpha), np)
    f_ref = float(excess.sum())
    if not f_ref > 0.0:
        f_ref = float(k.sum())
    L, U = lo * lo, hi * hi
    par = np.concatenate([k / f_ref, alpha, L, U])
    A_all = nlp.As * (1.0 / math.sqrt(spec.c))  # block b: A_b diag(eps^2) A_b^T = (z/R)^2 V_b
    # a digest, not the rows themselves: a thousand poses' rows are half a megabyte
    key = (n, m, hashlib.blake2b(b"".join(b.A.tobytes() for b in spec.blocks), digest_size=16).digest())
    scales = nlp.scales * (1.0 / math.sqrt(spec.c))  # each block's factor on its rows
    memo = _MEMORY.get(key) if options.get("warm_start", False) else None
    memo_start, shift = memo, WARM_SHIFT
    if memo is not None:
        d = _distance(memo, k, alpha, L, U, scales)
        if d > WARM_DISTANCE:
            memo_start = None  # too far from the last solve for its optimum to help: its working set only
        elif d == 0.0 and memo[1] is not None and memo[0] is None:
            shift = 0.0  # the same problem again: its optimum, as it was, is the answer (checked below)
    if m <= ALL_BLOCKS:
        J = None
    else:
        J = memo[0] if memo is not None else _start_set(nlp)
    solve = (compiled or kernel()).solve
    iterations, history, rounds = 0, [], 0
    while True:
        rounds += 1
        A = A_all if J is None else np.ascontiguousarray(A_all[J])
        if remaining() <= 0:  # the time limit (tolsynth.progress.time_limit): IPOPT reports it
            return None, "the time limit passed"
        # from the last solve of the same blocks where there is one (its optimum, moved back into
        # the interior), then cold in each mode
        attempts = [(False, None)] + [(primal, None) for primal in MODES]
        if rounds == 1 and memo_start is not None:
            attempts[0] = (False, _warm_state(memo_start, f_ref, L, U, shift))
        else:
            attempts = attempts[1:]
        for primal, start in attempts:
            limit = max_iter if primal else min(max_iter, FIRST_MODE_ITER)
            status, state, zb, info = solve(A, par, start, tol, limit, primal=primal)
            iterations += int(info[6])
            # one entry per run of the method: its best iterate's primal residual and complementarity
            # relative to the cost (the objective: the returned point's cost, filled in below)
            history.append(
                {
                    "round": rounds,
                    "mode": ("warm " if start is not None else "") + ("iterate" if primal else "minimiser"),
                    "iteration": int(info[0]),
                    "objective": math.nan,
                    "inf_pr": float(info[4]),
                    "inf_du": float(info[3]) / max(float(info[2]), 1e-300),
                }
            )
            if status < 2 and info[1] <= max(ACCEPT, tol):
                break
        else:
            return None, (
                f"the interior-point method stopped at error {info[1]:.1e} > {max(ACCEPT, tol):g} "
                f"(status {status}, round {rounds})"
            )
        Z, _, y = unpack(state, A.shape[0], n)
        eps = np.minimum(np.maximum(np.sqrt(y), lo), hi)  # as assemble clips it (the same memo)
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
        _remember(key, (None, state, f_ref, L, U, k, alpha, scales))
    else:
        Zs = np.zeros((m, 3, 3))
        Zs[J] = Z * f_ref
        tr = np.trace(Z, axis1=1, axis2=2)
        keep = tr > ACTIVE_Z * max(float(tr.max()), 1e-300)
        # the active blocks and the state restricted to them (dropping inactive blocks from an
        # optimum leaves an optimum)
        sub = np.concatenate([Z[keep].ravel(), _S_of(state, len(J))[keep].ravel(), state[18 * len(J) :]])
        _remember(key, (J[keep], sub, f_ref, L, U, k, alpha, scales))
    lam_u = (2.0 * f_ref) * y * zb  # the bounds' multipliers in u = ln eps (d/du = 2 y d/dy)
    message = (
        f"interior point: {iterations} iterations, {rounds} round(s), {m if J is None else len(J)} of "
        f"{m} block(s); primal residual {info[4]:.1e}"
    )
    result = assemble(
        "ipm", nlp, eps, Zs, lam_u, Status.OPTIMAL, message, iterations, iterations + rounds, wall, history
    )
    history[-1]["objective"] = result.cost
    return result, None


def _S_of(state: np.ndarray, m: int) -> np.ndarray:
    return state[9 * m : 18 * m].reshape(m, 3, 3)


def _distance(memo: tuple, k, alpha, L, U, scales) -> float:
    """How far this problem is from the one remembered: the largest change of a block's scale, of
    a parameter's bounds (in ln eps) or exponent, and the spread of the changes of ln k (a common
    factor on k moves no optimum)."""
    _, _, _, L_old, U_old, k_old, alpha_old, scales_old = memo
    n = len(k)
    # one logarithm of every ratio: k's, the bounds' (halved: y = eps^2), the scales'
    r = np.log(np.concatenate([k / k_old, np.sqrt(np.concatenate([L / L_old, U / U_old])), scales / scales_old]))
    dk = r[:n]
    return max(float(dk.max() - dk.min()), float(np.abs(r[n:]).max()), float(np.abs(alpha - alpha_old).max()))


def _warm_state(memo: tuple, f_ref: float, L: np.ndarray, U: np.ndarray, shift: float = WARM_SHIFT) -> np.ndarray:
    """The start of a solve of the same blocks from the last one's final state: the multipliers in
    this solve's cost scale, ``Z`` and ``S`` moved ``shift`` into the interior (an optimum sits on
    the cones' boundary, where an interior-point method cannot start on another problem), the
    barrier weight at least ``shift^2``; a parameter whose bounds moved is held inside them."""
    _, old, f_old, L_old, U_old = memo[:5]
    n = len(L)
    mb = (len(old) - 3 * n - 1) // 18
    x = old.copy()
    scale = f_old / f_ref
    eye = _eyes(mb)
    x[: 9 * mb] *= scale
    if shift:
        x[: 9 * mb] += shift * eye
        x[9 * mb : 18 * mb] += shift * eye
    x[-1] = max(x[-1] * scale, shift**2)
    base = 18 * mb
    # a sweep moves one or two parameters' bounds: one at a time, in plain floats
    for i in ((L != L_old) | (U != U_old)).nonzero()[0].tolist():
        lo, hi = float(L[i]), float(U[i])
        if lo == hi:  # locked: held at its value exactly (the method reads y there, never moves it)
            yi = lo
        else:
            pad = min(START_PAD, 0.25 * math.log(hi / lo))
            yi = min(max(float(x[base + i]), lo * math.exp(pad)), hi * math.exp(-pad))
        x[base + i], x[base + n + i], x[base + 2 * n + i] = yi, yi - lo, hi - yi
    return x


@lru_cache(maxsize=16)
def _eyes(mb: int) -> np.ndarray:
    """``mb`` 3 x 3 identities, row-major, one after the other (read-only)."""
    eye = np.tile(np.eye(3).ravel(), mb)
    eye.setflags(write=False)
    return eye


def _start_set(nlp: ToleranceNLP) -> np.ndarray:
    """The first working set of a problem with many blocks: those near the worst at the start point
    (within :data:`START_FRACTION` of it, at most :data:`START_BLOCKS`)."""
    vals = nlp.block_values(nlp.start_point())[0][:, 0]
    order = np.argsort(-vals)[:START_BLOCKS]
    return np.sort(order[vals[order] >= START_FRACTION * vals[order[0]]])


def _remember(key: tuple, memo: tuple) -> None:
    _MEMORY[key] = memo
    _MEMORY.move_to_end(key)
    while len(_MEMORY) > _MEMORY_SIZE:
        _MEMORY.popitem(last=False)
