"""``synthesize(..., probability="exact")``: the tolerance problem with the exact probabilities of
the linear error model as its constraints, no Gaussian approximation, solved with a certificate.

**The problem.**  At every pose and along every unit direction ``w``, ``P(|w . dr| <= R) >= p``
(the paper's per-component criterion, Eq. 6-7, read exactly), with ``w . dr = sum_i x_i Y_i``,
``x_i = (w . a_i) eps_i``.  For Gaussian errors the worst direction is the first principal axis
and this is the paper's ``z sigma_1 <= R``; for other shapes it moves off the axes.

**Why a local optimum is the global one.**  ``P(|x . Y| <= R) >= p`` is, by symmetry,
``P(x . Y <= R) >= (1 + p) / 2``, a level of at least 1/2, and for independent errors with
symmetric log-concave densities (uniform, normal, triangular, truncated normal) that set of ``x``
is convex: Lagoa, Li & Sznaier, "Probabilistically constrained linear programs and risk-adjusted
controller design", SIAM J. Optim. 15(3), 2005.  ``x`` is linear in ``eps``, so each direction's
feasible set is convex in ``eps``, closed downwards (P falls as any error grows), hence convex in
``u = ln eps`` as well, and in any mix of the two coordinates; the intersection over directions and
poses is convex, and where each cost ``c_i`` is convex in ``u_i`` or in ``eps_i`` (the exponential
where ``B eps < 1``) the problem is convex in that mix, so a KKT point (the same in ``u``) is the
global optimum.  The tests check the claim numerically (midpoints of feasible designs stay feasible).

**The method.**  An exchange: the constraint is imposed on a finite set of (pose, direction) cuts,
the cut problem solved by a primal-dual interior-point Newton method on the exact series
(:mod:`.exact_newton`, :mod:`.exact_series`) from the Gaussian design (which is close), and then
every direction of every pose is examined by a branch and bound over direction patches
(:func:`.exact_certify.cover`): a patch is either proven to meet ``p - 1e-7`` or split, and a
patch centre below p, refined to a local minimum of P by Newton's method on the sphere,
becomes a new cut.  The cuts at local minima track them (:mod:`.exact_cuts`): along each Newton
step of the tolerances their directions take the joint Newton step, and their Hessians are those
of ``min_w P``, so the exchange converges with the inner solve rather than one cut nearer per
round.  When no direction is short, the cuts' supporting
half-spaces give a rigorous lower bound (:func:`.exact_certify.half_space_bound`).  A result is
``success`` only when every pose is proven and the gap is within ``1e-6`` of the cost.

**All-normal errors** take the Gaussian path: then ``P(|w . dr| <= R) = erf(R / (sqrt 2 sigma_w))``
and the exact problem *is* the Gaussian one.  A shape that is not symmetric log-concave would have
no certificate: the status then says so (never "optimal").

**Sphere** (``criterion="sphere"``): ``P(|dr| <= R) >= p`` by the Radon identity of
:mod:`tolsynth.probability.exact` (:mod:`.exact_sphere`); not known to be convex, so its lower
bound is the certified optimum of the per-component problem at the same p (the sphere lies in
every slab), reported with its gap.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from tolsynth.errors import InfeasibleSpecificationError
from tolsynth.problem.nlp import ToleranceNLP
from tolsynth.problem.result import ConstraintBlock, Status, SynthesisResult, optimality_gap
from tolsynth.solvers.exact_certify import LOG_CONCAVE, cover, half_space_bound, refine_direction
from tolsynth.solvers.exact_cuts import Cuts, minimise_directions
from tolsynth.solvers.exact_newton import Barrier
from tolsynth.solvers.exact_newton import cost_function as _cost_fn
from tolsynth.solvers.exact_refute import verdict
from tolsynth.solvers.exact_series import probability
from tolsynth.solvers.worst_case import convex_in_eps

__all__ = [
    "solve_exact",
    "exact_margin",
    "exact_label",
    "PROBABILITIES",
    "EXACT_TOL",
    "DEFAULT_OPTIONS",
    "certifiable",
]

PROBABILITIES = ("gaussian", "exact")
#: every direction of every pose is proven to have P >= p - EXACT_TOL
EXACT_TOL = 1e-7
#: a direction is cut when its exact probability is below p - CUT_TOL
CUT_TOL = 3e-8
#: success needs the certificate's gap within this fraction of the cost
GAP_TOL = 1e-6
#: the options ``synthesize(..., probability="exact", options=...)`` accepts, with their defaults
DEFAULT_OPTIONS = {"max_rounds": 30, "max_iter": 200, "max_patches": 200_000}
#: blocks whose Gaussian constraint value is at least this get cuts from the start
START_CUTS = 0.9
#: violated directions added per pose and round (the worst ones)
NEW_CUTS = 3
#: a new cut this close (rad) to one of its pose's is not added
SAME_CUT = 1e-5
#: Newton steps on the sphere for a new cut's direction (the cut then tracks its minimum)
START_STEPS = 8
#: the barrier parameter (a fraction of the cost, per cut and parameter) a later round starts at
WARM_TAU = 1e-3
#: fresh barrier paths from a stalled one's last iterate before the solve reports failure
RESTARTS = 3


#: the readable name of each Gaussian solver's ``result.solver``, for the exact result's label
START_NAMES = {"ipm": "the compiled interior-point method", "ipopt": "IPOPT", "sumt": "SUMT + Powell"}


def exact_label(start_solver: str) -> str:
    """``result.solver`` of an exact solve: the barrier Newton method of this module is what ran;
    the solver the caller named only found the Gaussian optimum it starts from."""
    return f"exact interior point (started from the Gaussian optimum of {START_NAMES.get(start_solver, start_solver)})"


@dataclass
class _Block:
    """One pose and kind: raw rows A (3 x n per tolerance unit, shapes' scaling undone), R, p."""

    label: str
    pose: str
    kind: str  # "position", "orientation"
    A: np.ndarray
    R: float
    p: float


def _blocks(spec) -> list[_Block]:
    scale = spec.col_scale
    out = []
    for b in spec.blocks:
        R, p = (spec.R, spec.p) if b.kind == "position" else (spec.Phi, spec.p_orientation)
        out.append(_Block(b.label, b.pose, b.kind, np.asarray(b.A) / scale, float(R), float(p)))
    return out


def certifiable(shapes, spec) -> tuple[bool, str]:
    """Whether the convexity argument holds: every shape symmetric log-concave and every cost
    convex in ``u = ln eps`` or in ``eps`` on its range (the feasible set is convex in any mix of
    the two); else the reason."""
    bad = sorted({s.name for s in shapes if s.kind not in LOG_CONCAVE})
    if bad:
        return False, f"the error shape(s) {bad} are not symmetric log-concave: no certificate exists"
    costs = spec.costs
    if costs.power_law() is None:
        nonconvex = [
            nm
            for nm, m, a, b in zip(spec.names, costs.models, spec.lower, spec.upper)
            if not (m.convex_in_u(a, b) or convex_in_eps(m, a, b))
        ]
        if nonconvex:
            return False, (
                f"the cost of {nonconvex} is convex neither in eps nor in ln eps on its range "
                "(the exact reading's certificate needs one of them; probability='gaussian' needs convexity in eps^2)"
            )
    return True, ""


def _lattice(m: int) -> np.ndarray:
    """m nearly uniform unit vectors on the upper hemisphere (a Fibonacci lattice)."""
    i = np.arange(m) + 0.5
    z = 1.0 - i / m
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    return np.column_stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z])


def _local_minima(A: np.ndarray, u: np.ndarray, shapes, R: float, count: int = 4) -> np.ndarray:
    """The lowest few local minima of P over directions at ``eps = e^u`` (a lattice, then Newton's
    method on the sphere from the best points at least 0.3 rad apart), as rows."""
    D = _LATTICE
    P, _ = probability(np.abs(D @ (A * np.exp(u))), shapes, R, 1e-6)
    starts: list = []
    for j in np.argsort(P):
        if all(abs(float(D[j] @ D[k])) < math.cos(0.3) for k in starts):
            starts.append(j)
        if len(starts) >= count:
            break
    W, _ = minimise_directions(np.repeat(A[None], len(starts), axis=0), D[starts], u, shapes, R, steps=START_STEPS)
    return W


_LATTICE = _lattice(300)


def _deadline(what: str) -> None:
    from tolsynth import progress

    check = getattr(progress, "check_deadline", None)
    if check is not None:
        check(what)


def _feasible_start(cuts: Cuts, u: np.ndarray, lu: np.ndarray, uu: np.ndarray, blocks) -> np.ndarray:
    """``u`` shrunk (every tolerance by one factor: every P rises) until every cut holds strictly:
    the cuts that fail at ``u`` evaluated at a ladder of factors in one batch."""
    free = uu - lu > 1e-12
    g = cuts(np.where(free, np.clip(u, lu, uu), lu), 0)[0]
    if not g.size or np.all(g > 1e-3):
        return np.where(free, np.clip(u, lu, uu), lu)
    bad = np.flatnonzero(g <= 1e-3)
    C, Rc, pc = (x[bad] for x in cuts.arrays())
    V = [np.where(free, np.clip(u - 1e-4 * 2.0**k, lu, uu), lu) for k in range(40)]
    last = next((k for k, v in enumerate(V) if np.all(v[free] <= lu[free])), len(V) - 1)
    for a in range(0, last + 1, 8):  # the barrier checks the start itself: 1e-9 is plenty against 1e-3
        Vk = np.array(V[a : min(a + 8, last + 1)])
        rows = (C[None, :, :] * np.exp(Vk)[:, None, :]).reshape(-1, C.shape[1])
        P, _ = probability(rows, cuts.shapes, np.tile(Rc, len(Vk)), 1e-9)
        ok = np.all(((P.reshape(len(Vk), -1) - pc) / (1 - pc)) > 1e-3, axis=1)
        if ok.any():
            return Vk[int(np.argmax(ok))]
    Pl = P.reshape(len(Vk), -1)[-1]
    j = int(np.argmin((Pl - pc) / (1 - pc)))
    blk = blocks[cuts.block[bad[j]]]
    value, text = verdict(float(Pl[j]), float(pc[j]), f"exact P = {Pl[j]:.6g} < p = {blk.p:g} along a direction")
    raise InfeasibleSpecificationError(
        blk.label,
        value,
        f"infeasible specification: the {blk.label} fails even with every tolerance "
        f"at its lower bound: {text}.  Lower the bounds, or relax R/Phi or p.",
    )


def solve_exact(
    nlp: ToleranceNLP, shapes: tuple, solver: str = "ipopt", eps0=None, options=None, verbose: bool = False
) -> SynthesisResult:
    """The exact problem of this module's docstring; ``solver`` solves the Gaussian problem whose
    optimum starts the search (or the whole problem, when every error is normal)."""
    t0 = time.perf_counter()
    opts = {**DEFAULT_OPTIONS, **_checked(options)}
    spec = nlp.spec
    shapes = tuple(shapes)
    if all(s.kind == "normal" for s in shapes):
        return _gaussian_route(nlp, solver, eps0, t0)
    if spec.sphere_blocks:
        from tolsynth.solvers.exact_sphere import solve_sphere

        # the per-component problem at the same p: the sphere's lower bound
        comp = _solve_components(ToleranceNLP(spec.relaxed()), shapes, solver, eps0, opts, t0, False)
        start = _gaussian_start(nlp, solver, eps0)
        return solve_sphere(nlp, shapes, exact_label(start.solver), comp, start.x, opts, t0)
    return _solve_components(nlp, shapes, solver, eps0, opts, t0, verbose)


def _checked(options) -> dict:
    """The exact solver's options, each a known key with a positive whole number (typed errors
    naming the field otherwise)."""
    from collections.abc import Mapping

    from tolsynth.errors import InputError

    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise InputError("options", f"got {type(options).__name__}", "a dict of " + ", ".join(DEFAULT_OPTIONS))
    for key, value in options.items():
        if key not in DEFAULT_OPTIONS:
            raise InputError(f"options[{key!r}]", "unknown option of the exact solver", ", ".join(DEFAULT_OPTIONS))
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise InputError(f"options[{key!r}]", f"got {value!r}", "a whole number >= 1")
    return dict(options)


def _gaussian_start(nlp, solver, eps0) -> SynthesisResult:
    """The Gaussian optimum the exact solve starts from, solved by ``solver`` (its ``solver``
    field names the method that ran)."""
    # A user's start (another R's design in a sweep) only warm-starts the Gaussian solve: the cuts
    # are placed at this problem's Gaussian design, which is near the exact one; cuts placed at a
    # far start took 30 times longer to move.
    if eps0 is not None:
        eps0 = np.clip(np.asarray(eps0, dtype=float), nlp.spec.lower, nlp.spec.upper)
    if nlp.spec.sphere_blocks and solver != "sumt":  # the design alone: its sphere bounds took 0.2-0.9 s
        from tolsynth.solvers.ipopt import solve_ipopt

        return solve_ipopt(nlp, eps0, sphere_bounds=False)
    if solver == "sumt":
        from tolsynth.solvers.sumt import solve_sumt

        return solve_sumt(nlp, eps0)
    if solver == "auto":  # the compiled method where it applies: the start costs a millisecond
        from tolsynth.solvers.fast import solve_auto

        return solve_auto(nlp, eps0)
    from tolsynth.solvers.ipopt import solve_ipopt

    return solve_ipopt(nlp, eps0)


def _gaussian_route(nlp, solver, eps0, t0):
    from dataclasses import replace

    if solver == "sumt":
        from tolsynth.solvers.sumt import solve_sumt as run
    elif solver == "auto":
        from tolsynth.solvers.fast import solve_auto as run
    else:
        from tolsynth.solvers.ipopt import solve_ipopt as run
    res = run(nlp, eps0)
    return replace(
        res,
        message="exact probabilities: every error is normal, so P(|w . dr| <= R) = "
        "erf(R / (sqrt(2) sigma_w)) along every direction and the exact problem is the Gaussian "
        f"one, solved on its path; {res.message}",
        wall_time=time.perf_counter() - t0,
    )


def _solve_components(nlp, shapes, solver, eps0, opts, t0, verbose):
    spec = nlp.spec
    blocks = _blocks(spec)
    lu, uu = nlp.lu, nlp.uu
    start = _gaussian_start(nlp, solver, eps0)
    eps_g = start.x
    cuts = Cuts(shapes, SAME_CUT)
    vals, dirs = nlp.block_values(eps_g)
    for i, blk in enumerate(blocks):
        if vals[i, 0] >= START_CUTS:  # all three axes (a free axis would let its errors grow far) and
            for j in range(3):  # the exact worst directions at the Gaussian design, which track
                cuts.add(i, blk.A, blk.R, blk.p, dirs[i][:, j], moving=True)  # the worst directions from then on
            for w in _local_minima(blk.A, np.log(eps_g), shapes, blk.R):
                cuts.add(i, blk.A, blk.R, blk.p, w, moving=True, slides=True)
    if not len(cuts):  # nothing near its limit: the worst block still starts the cut set
        i = int(np.argmax(vals[:, 0]))
        cuts.add(i, blocks[i].A, blocks[i].R, blocks[i].p, dirs[i][:, 0])
    cost_fn = _cost_fn(nlp)
    u = np.log(eps_g)
    lam = None
    history, iters, evals = [], 0, 0
    ok, message, covers = False, "", []
    for rnd in range(int(opts["max_rounds"])):
        _deadline("the exact solve")
        u_start = _feasible_start(cuts, u, lu, uu, blocks)
        lam0 = None if lam is None else np.concatenate([lam, np.zeros(len(cuts) - lam.size)])
        res = Barrier(cost_fn, cuts, lu, uu).solve(
            u_start,
            lam0,
            max_iter=int(opts["max_iter"]),
            tau0=None if rnd == 0 else WARM_TAU * cost_fn(u_start)[0] / (len(cuts) + spec.n),
        )
        for _ in range(RESTARTS):  # a stalled path (the 42-error hexapod) re-centred from where it stopped
            if res.ok or not res.message.startswith("iteration limit"):
                break
            iters += res.iterations
            res = Barrier(cost_fn, cuts, lu, uu).solve(
                res.u, res.lam, max_iter=int(opts["max_iter"]), tau0=WARM_TAU * cost_fn(res.u)[0] / (len(cuts) + spec.n)
            )
        iters += res.iterations
        u, lam, zb, ok, message = res.u, res.lam, res.z, res.ok, res.message
        eps = np.exp(u)
        covers, starts = [], []
        for i, blk in enumerate(blocks):
            cv = cover(blk.A * eps, shapes, blk.R, blk.p, EXACT_TOL, CUT_TOL, int(opts["max_patches"]))
            evals += cv.evaluations
            covers.append(cv)
            if not cv.certified:  # proven to p - EXACT_TOL: what the result claims, whatever is short of p itself
                starts += [(i, w) for w, _ in cv.violations[:NEW_CUTS]]
        added = 0
        if starts:  # the violations' local minima, all in one batch, become tracking cuts
            idx = [i for i, _ in starts]
            W, _ = minimise_directions(
                np.array([blocks[i].A for i in idx]),
                np.array([w for _, w in starts]),
                u,
                shapes,
                np.array([blocks[i].R for i in idx]),
                steps=START_STEPS,
            )
            for i, w in zip(idx, W):
                added += cuts.add(i, blocks[i].A, blocks[i].R, blocks[i].p, w, moving=True, slides=True)
        history.append(
            {
                "round": rnd,
                "cuts": len(cuts),
                "newton": res.iterations,
                "added": added,
                "cost": nlp.cost(eps),
                "inner": message,
                "proven": min((c.proven for c in covers), default=1.0),
            }
        )
        if verbose:
            print(history[-1])
        if not ok or added == 0:
            break
    eps = np.minimum(np.maximum(np.exp(u), spec.lower), spec.upper)
    return _assemble(
        opts,
        nlp,
        shapes,
        exact_label(start.solver),
        blocks,
        cuts,
        eps,
        lam,
        zb,
        ok,
        message,
        covers,
        history,
        iters,
        evals,
        t0,
    )


def _assemble(opts, nlp, shapes, solver, blocks, cuts, eps, lam, zb, ok, inner, covers, history, iters, evals, t0):
    spec = nlp.spec
    u = np.log(eps)
    cost = nlp.cost(eps)
    C, Rc, pc = (x[: lam.size] for x in cuts.arrays())  # cuts added after the last solve carry no multiplier
    active = lam > 1e-6 * max(float(lam.max(initial=0.0)), 1e-300)  # the others add nothing to the bound
    lower, _ = half_space_bound(
        spec.costs, nlp.lu, nlp.uu, u, C[active], Rc[active], pc[active], shapes, lam[active] / (1 - pc[active])
    )
    Pcut, _ = probability(C * eps[None, :], shapes, Rc, 1e-12)
    cblocks = []
    for i, blk in enumerate(blocks):
        mine = [j for j, b in enumerate(cuts.block[: lam.size]) if b == i]
        var = np.array([s.variance for s in shapes])
        V = (blk.A * (eps**2 * var)) @ blk.A.T
        _, E = np.linalg.eigh(V)
        E = E[:, ::-1]
        PE, _ = probability(np.abs(E.T @ blk.A) * eps[None, :], shapes, blk.R, 1e-12)
        if mine:
            j = min(mine, key=lambda j: Pcut[j])
            w, Pw, mult = cuts.w[j], float(Pcut[j]), float(sum(lam[k] for k in mine))
        else:
            k = int(np.argmin(PE))
            w, Pw, mult = E[:, k], float(PE[k]), 0.0
        v = np.concatenate([[(1 - Pw) / (1 - blk.p)], (1 - PE) / (1 - blk.p)])
        cblocks.append(
            ConstraintBlock(
                blk.label,
                blk.pose,
                blk.kind + " (exact)",
                v,
                np.column_stack([w, E]),
                v >= 1 - 1e-6,
                np.concatenate([[mult], np.zeros(3)]),
            )
        )
    gap = optimality_gap(cost, lower)
    proven = all(c.certified for c in covers) and len(covers) == len(blocks)
    can, why = certifiable(shapes, spec)
    detail = (
        f"{len(cuts)} direction cuts, {len(history)} rounds; every direction of every pose "
        + (
            f"proven P >= p - {EXACT_TOL:g} by the branch and bound ({sum(c.patches for c in covers)} patches)"
            if proven
            else "NOT proven"
        )
        + f"; lower bound from the active cuts' half-spaces, gap {gap:.2e} ({gap / abs(cost):.1e} of the cost); "
        + inner
    )
    # the last round still added cuts (the loop stops early only on a failure or when none is added)
    out_of_rounds = ok and bool(history) and history[-1]["added"] > 0
    if not ok and inner.startswith("iteration limit"):
        status = Status.ITERATION_LIMIT
        message = (
            f"exact probabilities: the interior-point solve stopped at its iteration limit "
            f"(max_iter={opts['max_iter']}) before converging: {detail}"
        )
    elif not ok:
        status = Status.NUMERICAL_ERROR
        message = f"exact probabilities: the interior-point solve failed: {detail}"
    elif not proven:
        # a limit of the search (patches, rounds) is not a numerical failure: the user can raise it
        limited = any(c.limit for c in covers)
        status = Status.ITERATION_LIMIT if limited or out_of_rounds else Status.NUMERICAL_ERROR
        short = [
            f"{b.label} (the branch and bound over directions reached max_patches={opts['max_patches']} "
            "before covering every direction: no bound on P proven)"
            if c.limit
            else f"{b.label} (a direction with P = {c.proven:.9f} < p - {EXACT_TOL:g})"
            for b, c in zip(blocks, covers)
            if not c.certified
        ]
        why = (
            f"the exchange of direction cuts reached max_rounds={opts['max_rounds']} with directions still short of p; "
            if out_of_rounds
            else ""
        )
        message = f"exact probabilities: not certified: {why}not every direction proven to meet p: {', '.join(short)}; {detail}"
    elif not can:
        status = Status.OPTIMAL_INACCURATE
        message = f"exact probabilities: feasible, but {why}; {detail}"
    elif not gap <= GAP_TOL * abs(cost):
        status = Status.OPTIMAL_INACCURATE
        message = f"exact probabilities: not certified (gap above {GAP_TOL:g} of the cost): {detail}"
    else:
        status = Status.OPTIMAL
        message = f"exact probabilities, certified optimum: {detail}"
    bounds_active, bound_mult = {}, {}
    for i, name in enumerate(spec.names):
        if eps[i] <= spec.lower[i] * (1 + 1e-6):
            bounds_active[name] = "lower"
        elif eps[i] >= spec.upper[i] * (1 - 1e-6):
            bounds_active[name] = "upper"
        if name in bounds_active:
            bound_mult[name] = float(zb[i] / eps[i])
    return SynthesisResult(
        solver=solver,
        status=status,
        success=status is Status.OPTIMAL,
        message=message,
        tolerances=dict(zip(spec.names, map(float, eps))),
        units=dict(zip(spec.names, spec.units)),
        cost=cost,
        constraints=tuple(cblocks),
        bounds_active=bounds_active,
        bound_multipliers=bound_mult,
        lower_bound=lower,
        gap=gap,
        iterations=iters,
        function_evaluations=evals,
        wall_time=time.perf_counter() - t0,
        spec=spec,
        history=history,
    )


def exact_margin(mechanism, q, eps, distribution, R: float, p: float, criterion: str = "components") -> float:
    """``(1 - P) / (1 - p)`` at one pose by the exact probabilities: P along the worst direction
    (per component; a lattice of directions, then a local search from the best) or in the sphere;
    <= 1 meets the specification (used by the workspace exchange to rank poses)."""
    from tolsynth.probability import exact as ex
    from tolsynth.probability.distributions import resolve, shapes_of

    shapes = shapes_of(resolve(distribution, mechanism), mechanism.error_parameters, mechanism.index)
    A = mechanism.sensitivity(mechanism.joints(q), check_limits=False)[:3]
    eps = np.asarray(eps, dtype=float)
    if criterion == "sphere":
        P = ex.ball_probability(A, eps, shapes, R, tol=1e-6, max_nodes=128, return_error=True)[0]
        return (1.0 - P) / (1.0 - p)
    M = A * eps
    D = _lattice(400)
    P, _ = probability(np.abs(D @ M), shapes, R, 1e-10)
    best = min((refine_direction(M, shapes, R, D[j])[1] for j in np.argsort(P)[:3]), default=1.0)
    return (1.0 - best) / (1.0 - p)
