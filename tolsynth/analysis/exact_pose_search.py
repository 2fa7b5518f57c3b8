"""The worst pose by the exact probabilities: the configuration and direction of lowest
``P(|u . dr| <= R)`` of the linear error model ``dr = A(q) diag(eps) Y``.

:func:`worst_pose` ranks poses by the Gaussian sigma of the linear model; with errors that are not
normal the pose of largest sigma need not be the pose of lowest exact per-direction probability
(a few uniform terms of different sizes have a flatter density than a normal of the same
variance, and which pose is worst depends on how the terms mix there, not on the variance alone).
:func:`worst_exact_pose` minimises the exact probability itself, over joints and directions
together, inside the joint limits and joint constraints.  Units: mm and rad.

>>> import tolsynth
>>> from tolsynth.analysis.exact_pose_search import worst_exact_pose
>>> w = worst_exact_pose(tolsynth.load_model("planar_2r"), "coarse", 0.1, p=0.99)
>>> round(w.probability, 6), round(w.margin, 4)  # at q2 = +-1.7 or +-74 deg, equal by symmetry
(0.979991, 2.0009)
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from tolsynth.checks import check_count, check_mapping, check_positive, check_real, check_seed
from tolsynth.errors import InputError, OutOfRangeError
from tolsynth.kinematics.batch_stats import SMALL_BATCH, _evaluator, _small_maps
from tolsynth.kinematics.joint_space import (
    MODEL_REFERENCE,
    STREAK,
    _feasible,
    _limits,
    _reference,
    hold_fixed,
    scaled_joints,
    tangent_directions,
)
from tolsynth.probability.exact import _fibonacci_hemisphere
from tolsynth.solvers.exact_cuts import minimise_directions
from tolsynth.solvers.exact_series import probability

__all__ = ["ExactWorstPose", "worst_exact_pose"]

#: Newton steps on the sphere for the worst direction at a polled pose, from its incumbent's
#: direction (a poll moves the pose a little, so the direction moves a little: two or three steps
#: reach the minimum to the evaluator's precision)
POLL_STEPS = 4
#: Newton steps at the grid's poses, from the best direction of the candidate set
GRID_STEPS = 3
#: grid poses (the lowest by their candidate directions) that get those Newton steps
GRID_NEWTON = 128
#: error allowed in P on the grid (which only ranks the starts) and in the local search
GRID_TOL = 1e-8
SEARCH_TOL = 1e-11
#: a poll is a descent when it lowers P by more than this (the evaluator's precision)
DESCENT = 1e-12
#: global direction checks (a lattice of directions at the pose found, then another local search
#: where a lower direction turns up there)
DIRECTION_CHECKS = 3
#: a pose this close (a fraction of each joint's range) to a joint limit or joint constraint is
#: tried on it (the coarse searches of the workspace exchange end 1e-4 of the range from a corner)
SNAP = 1e-3
#: the checks' lattice of directions, the lattice points (at least 0.3 rad apart) Newton's method
#: starts from, and its steps
CHECK_DIRECTIONS = 400
CHECK_STARTS = 3
CHECK_STEPS = 20
#: grid points per joint at most by default (the local search does the rest; one or two joints
#: would otherwise get a grid far finer than the starts need)
MAX_PER_JOINT = 41


@dataclass(frozen=True)
class ExactWorstPose:
    """The pose and direction of lowest exact ``P(|u . dr| <= R)`` found.

    Attributes
    ----------
    q : ndarray
        Joint values (rad), every joint (held ones at their held value); inside every joint limit
        and joint constraint.
    position : ndarray
        Hand position there (mm).
    direction : ndarray
        The unit direction u of lowest probability there.
    probability : float
        ``P(|u . dr| <= R)`` there, the exact probability of the linear model (to 1e-9).
    margin : float or None
        ``(1 - P) / (1 - p)`` with ``p`` (the workspace exchange's reading: <= 1 meets p).
    value : float
        The same as ``probability`` (as :class:`~tolsynth.analysis.pose_search.WorstPose` names it).
    held_joints : dict
        Joint name -> value (rad) held: joints that do not change the error's distribution up to a
        rotation (found numerically), plus any ``fixed`` by the caller.
    n_grid, n_evaluations : int
        Feasible grid poses and poses evaluated in all.
    seed : int
        Of the random poses that find the held joints.
    method : str
    """

    model: str
    R: float
    p: float | None
    q: np.ndarray
    position: np.ndarray
    direction: np.ndarray
    probability: float
    margin: float | None
    held_joints: dict
    n_grid: int
    n_evaluations: int
    seed: int
    elapsed_s: float
    method: str

    @property
    def value(self) -> float:
        return self.probability

    def summary(self) -> str:
        """One line: the probability, the margin, the pose (deg) and the direction."""
        qd = ", ".join(f"{math.degrees(v):.3f}" for v in self.q)
        ud = ", ".join(f"{v:.4f}" for v in self.direction)
        m = "" if self.margin is None else f", (1-P)/(1-p) = {self.margin:.6f}"
        return f"lowest exact P(|u.dr| <= {self.R:g} mm) = {self.probability:.9f}{m} at q = ({qd}) deg, u = ({ud})"


def _position_sensitivities(mech, Q: np.ndarray) -> np.ndarray:
    """``A(q)`` (N, 3, n), the position rows of the sensitivity at each column of ``Q``, by the
    model's own sensitivity graph (NaN where a parallel robot's platform is not assembled)."""
    N = Q.shape[1]
    out = np.empty((N, 3, mech.n))
    for a in range(0, N, 20000):
        Qc = Q[:, a : a + 20000]
        if Qc.shape[1] <= SMALL_BATCH:  # CasADi's virtual machine (the polls' small batches)
            S = np.asarray(_small_maps(mech, Qc.shape[1])[0](Qc, np.zeros(mech.n)))  # (6, n N)
            out[a : a + Qc.shape[1]] = S[:3].reshape(3, Qc.shape[1], mech.n).transpose(1, 0, 2)
        else:
            sens = _evaluator(mech, "sensitivity")
            S = sens.dense(0, sens([Qc, np.zeros(mech.n)])[0])  # (6, n, N)
            out[a : a + Qc.shape[1]] = S[:3].transpose(2, 0, 1)
    return out


def _rotation_invariant(mech, eps: np.ndarray, lo, hi, rng) -> list[int]:
    """Joints that change ``M = A diag(eps)`` by a rotation at most (its Gram matrix ``M^T M``
    unchanged at random poses): the distribution of ``dr`` only turns, so the lowest probability
    over directions is the same.  (Equal principal sigmas would not do: the exact probabilities
    depend on how the terms mix, not on the covariance alone.)"""
    nq = len(lo)
    Q = lo[:, None] + (hi - lo)[:, None] * rng.random((nq, 6))

    def gram(Q):
        M = _position_sensitivities(mech, Q) * eps
        return np.einsum("kxi,kxj->kij", M, M)

    G = gram(Q)
    scale = np.max(np.abs(G)) if np.all(np.isfinite(G)) else np.nan
    out = []
    for j in range(nq):
        Q2 = Q.copy()
        Q2[j] = lo[j] + (hi[j] - lo[j]) * rng.random(Q.shape[1])
        if np.all(np.abs(gram(Q2) - G) <= 1e-10 * scale):  # NaN (not assembled) fails: searched
            out.append(j)
    return out


def worst_exact_pose(
    mechanism,
    tolerances,
    R: float,
    p: float | None = None,
    distribution=None,
    *,
    x0: Sequence | None = None,
    grid: int | None = None,
    max_grid_points: int = 2000,
    directions: int = 24,
    starts: int = 4,
    step_tol: float = 1e-6,
    fixed: Mapping[str, float] | None = None,
    seed: int = 0,
) -> ExactWorstPose:
    """The pose and direction of lowest exact ``P(|u . dr| <= R)`` over the joint space.

    Method: (1) joints that only turn the error's distribution (its Gram matrix unchanged, checked
    at random poses of ``seed``) are held at the model's reference pose (``xu_zhang_1988``: the
    waist and the roll); (2) a grid over the other joints inside every joint limit and joint
    constraint (``grid`` points per joint, default as many as keep it under ``max_grid_points``),
    each pose's lowest probability over its principal axes, their bisectors and a Fibonacci
    lattice of ``directions`` directions, then a few Newton steps on the sphere at the lowest 128;
    (3) from the ``starts`` best mutually separated grid poses and every pose of ``x0`` (e.g. the
    sigma search's worst pose), a pattern search over the joints (compass directions and the
    tangents of the linear joint constraints, infeasible polls rejected, step halved on failure
    down to ``step_tol`` of each joint's range) in which every polled pose's value is the minimum
    over directions reached by Newton's method on the sphere from the incumbent's direction: a
    descent over joints and directions together, whose end is tried on the limits and joint
    constraints within 1e-3 of the range (a pattern search ends a step away from a corner);
    (4) at the pose found, a lattice of 400 directions checks that no other direction is lower
    (if one is, the search goes on from it).  Every value is the compiled exact evaluator's
    (rigorous error bound; 1e-11 in the search), so the result depends on the inputs alone.

    Parameters
    ----------
    mechanism : Mechanism
    tolerances : str, dict or array
        Tolerance set name or half-widths (tolerance units).
    R : float
        Radius (mm), > 0.
    p : float, optional
        Probability asked for, in (0, 1): the result's ``margin`` is ``(1 - P) / (1 - p)``.
    distribution : str or dict, optional
        As :func:`tolsynth.synthesize` (default: the model file's, else uniform).
    x0 : sequence of joint vectors (rad), optional
        Further starts of the local search (held joints are set to their held value).
    grid, max_grid_points, directions, starts, step_tol, fixed, seed
        As above; ``fixed`` maps joint names to values (rad) held in addition.

    Returns
    -------
    ExactWorstPose
    """
    t0 = time.perf_counter()
    from tolsynth.kinematics.mechanism import as_mechanism
    from tolsynth.probability.distributions import resolve, shapes_of

    mech = as_mechanism(mechanism)
    R = check_positive(R, "R")
    if p is not None:
        p = check_real(p, "p", "", 0.0, 1.0)
        if not 0.0 < p < 1.0:
            raise OutOfRangeError("p", f"got {p!r}", "a probability strictly between 0 and 1")
    distribution = resolve(distribution, mech)
    shapes = shapes_of(distribution, mech.error_parameters, mech.index)
    eps = np.asarray(mech.tolerances(tolerances), dtype=float)
    max_grid_points = check_count(max_grid_points, "max_grid_points", 1, 10**6)
    grid = None if grid is None else check_count(grid, "grid", 2, 10**6)
    directions = check_count(directions, "directions", 0, 100_000)
    starts = check_count(starts, "starts", 1, 1000)
    step_tol = check_positive(step_tol, "step_tol", "fraction of each joint's range", upper=1.0)
    seed = check_seed(seed)
    fixed = {
        name: check_real(v, f"fixed[{name}]", "rad")
        for name, v in check_mapping(fixed, "fixed", "a dict joint name -> value (rad)").items()
    }
    lo, hi = _limits(mech)
    nq = len(lo)
    names = list(mech.joint_names)
    _, ref_q = _reference(mech, MODEL_REFERENCE)
    base_q = ref_q if ref_q is not None else np.clip(np.zeros(nq), lo, hi)
    held = {
        j: float(np.clip(base_q[j], lo[j], hi[j]))
        for j in _rotation_invariant(mech, eps, lo, hi, np.random.default_rng(seed))
    }
    hold_fixed(mech, fixed, lo, hi, held)
    free = [j for j in range(nq) if j not in held]
    k = len(free)
    span = hi[free] - lo[free]
    zero_u = np.zeros(mech.n)
    n_eval = 0

    def full(U: np.ndarray) -> np.ndarray:  # scaled (k, N) -> joints (nq, N)
        return scaled_joints(U, held, free, lo, hi)

    def scaled(q: np.ndarray) -> np.ndarray:
        return np.clip((q[free] - lo[free]) / span, 0.0, 1.0)

    def blocks(U: np.ndarray):
        """``M = A diag(eps)`` (N, 3, n) at the feasible columns of U, and their mask."""
        nonlocal n_eval
        Q = full(U)
        ok = _feasible(mech, Q) & np.all((U >= 0) & (U <= 1), axis=0)
        M = np.full((U.shape[1], 3, mech.n), np.nan)
        if np.any(ok):
            M[ok] = _position_sensitivities(mech, Q[:, ok]) * eps
            n_eval += int(np.count_nonzero(ok))
        ok &= np.all(np.isfinite(M), axis=(1, 2))  # a parallel robot not assembled there
        return M, ok

    def descend(M: np.ndarray, W: np.ndarray, steps: int, tol: float):
        """Local minima over directions from W, rows at once (W, P)."""
        return minimise_directions(M, W, zero_u, shapes, R, steps=steps, tol=tol)

    def best_directions(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per pose: the lowest of the principal axes, their bisectors and a lattice, then Newton."""
        W, F = screen_directions(M, shapes, R, directions)
        top = np.argsort(F, kind="stable")[:GRID_NEWTON]  # the rest stay at their candidates' lowest
        W[top], F[top] = descend(M[top], W[top], GRID_STEPS, GRID_TOL)
        return W, F

    def lowest_direction(M: np.ndarray, W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per pose, the lowest local minimum over directions: from W and from the best points of
        a lattice of :data:`CHECK_DIRECTIONS` (at least 0.3 rad apart), by Newton on the sphere."""
        L = _lattice_of(CHECK_DIRECTIONS)
        N = M.shape[0]
        P, _ = probability(np.abs(np.einsum("dx,kxn->kdn", L, M)).reshape(-1, mech.n), shapes, R, GRID_TOL)
        P = P.reshape(N, -1)
        rows, starts_w = [], []
        for i in range(N):
            chosen: list = []
            for j in np.argsort(P[i], kind="stable"):
                if all(abs(float(L[j] @ L[c])) < math.cos(0.3) for c in chosen):
                    chosen.append(int(j))
                if len(chosen) >= CHECK_STARTS:
                    break
            rows += [i] * (len(chosen) + 1)
            starts_w += [W[i]] + [L[c] for c in chosen]
        rows = np.array(rows)
        Wl, Pl = descend(M[rows], np.array(starts_w), CHECK_STEPS, SEARCH_TOL)
        Wout, Pout = np.empty((N, 3)), np.empty(N)
        for i in range(N):
            r = np.flatnonzero(rows == i)
            j = r[int(np.argmin(Pl[r]))]
            Wout[i], Pout[i] = Wl[j], Pl[j]
        return Wout, Pout

    # (2) the grid, ranked by the exact probability
    if k:
        g = int(grid) if grid is not None else min(MAX_PER_JOINT, max(3, int(math.floor(max_grid_points ** (1.0 / k)))))
        if g**k > 10**6:
            raise OutOfRangeError("grid", f"{g}**{k} searched joints = {g**k} points", "at most 1000000 points")
        axes = np.meshgrid(*[np.linspace(0.0, 1.0, g)] * k, indexing="ij")
        U = np.array([a.ravel() for a in axes])
    else:
        g, U = 1, np.zeros((0, 1))
    M, ok = blocks(U)
    if not np.any(ok):
        raise OutOfRangeError(
            "joint limits",
            "no grid point satisfies every joint limit and constraint",
            "a non-empty feasible joint space",
        )
    n_grid = int(np.count_nonzero(ok))
    U, M = U[:, ok], M[ok]
    W, F = best_directions(M)
    order = np.argsort(F, kind="stable")
    picked: list[int] = []
    h0 = 1.0 / (g - 1) if k else 0.0
    for i in order:
        if all(np.max(np.abs(U[:, i] - U[:, j]), initial=0.0) > 1.5 * h0 for j in picked):
            picked.append(int(i))
        if len(picked) >= starts:
            break
    X, WX, FX = U[:, picked], W[picked], F[picked]
    extra = [] if x0 is None else [np.asarray(mech.joints(q, check_limits=False), dtype=float) for q in x0]
    if extra:
        Ux = np.array([scaled(q) for q in extra]).reshape(len(extra), k).T
        Mx, okx = blocks(Ux)
        if np.any(okx):
            Wx, Fx = best_directions(Mx[okx])
            X = np.hstack([X, Ux[:, okx]])
            WX, FX = np.vstack([WX, Wx]), np.concatenate([FX, Fx])

    # the linear joint constraints in scaled coordinates: a @ U + c between their bounds
    lin = []
    for con in mech.spec.joint_constraints:
        a, c0 = np.zeros(k), 0.0
        for jn, coef in con.terms.items():
            j = names.index(jn)
            if j in held:
                c0 += coef * held[j]
            else:
                a[free.index(j)] = coef * span[free.index(j)]
                c0 += coef * lo[j]
        if np.any(a):
            lin.append((a, c0, con.lower, con.upper))

    def snap(u: np.ndarray) -> np.ndarray:
        """``u`` moved onto the limits and the joint constraints within :data:`SNAP` of it (the
        least change of the other coordinates), then inward by rounding's width if it must be:
        a pattern search ends a final step away from a corner, not on it."""
        y = np.where(u < SNAP, 0.0, np.where(u > 1.0 - SNAP, 1.0, u))
        rows, rhs = [], []
        for a, c0, lower, upper in lin:
            v = a @ y + c0
            for bound in (lower, upper):
                if abs(v - bound) <= SNAP * np.linalg.norm(a):
                    rows.append(a)
                    rhs.append(bound - c0)
        move = (y > 0.0) & (y < 1.0)
        if rows and np.any(move):
            Aeq = np.array(rows)[:, move]
            r = np.array(rhs) - np.array(rows) @ y
            y[move] += np.linalg.lstsq(Aeq, r, rcond=None)[0]
        for shrink in (0.0, 1e-13, 1e-11, 1e-9):  # inward along the way back to u, as rounding needs
            t = y + shrink * (u - y) / max(float(np.max(np.abs(u - y))), 1e-300)
            if _feasible(mech, full(t[:, None]))[0] and np.all((t >= 0) & (t <= 1)):
                return t
        return u

    # (3) the pattern search over joints, each poll's value its own minimum over directions
    D = tangent_directions(mech, free, span) if k else np.zeros((0, 0))
    h = np.full(X.shape[1], 0.5 * h0)
    streak = np.zeros(X.shape[1], dtype=int)
    checks = 0
    while True:
        while k and np.any(h >= step_tol):
            act = np.flatnonzero(h >= step_tol)
            nd = D.shape[0]
            Pp = X[:, act, None] + h[act][None, :, None] * D.T[:, None, :]  # (k, A, nd)
            Mp, okp = blocks(Pp.reshape(k, -1))
            vals = np.full(okp.size, np.inf)
            dirs = np.repeat(WX[act], nd, axis=0)
            if np.any(okp):
                dirs[okp], vals[okp] = descend(Mp[okp], dirs[okp], POLL_STEPS, SEARCH_TOL)
            vals = vals.reshape(len(act), nd)
            j = np.argmin(vals, axis=1)
            best = vals[np.arange(len(act)), j]
            for a_i, s in enumerate(act):
                if best[a_i] < FX[s] - DESCENT:
                    X[:, s] = Pp[:, a_i, j[a_i]]
                    FX[s] = best[a_i]
                    WX[s] = dirs[a_i * nd + j[a_i]]
                    streak[s] += 1
                    if streak[s] >= STREAK:  # a run of successes doubles the step: no creep along a ridge
                        h[s], streak[s] = min(2.0 * h[s], 0.5 * h0), 0
                else:
                    h[s] *= 0.5
                    streak[s] = 0
        if k:  # onto the limits and joint constraints a pose ends near, where that is lower
            Y = np.column_stack([snap(X[:, s]) for s in range(X.shape[1])])
            My, oky = blocks(Y)
            if np.any(oky):
                Wy, Py = descend(My[oky], WX[oky], CHECK_STEPS, SEARCH_TOL)
                better = np.flatnonzero(oky)[Py <= FX[oky]]
                X[:, better], WX[better], FX[better] = Y[:, better], Wy[Py <= FX[oky]], Py[Py <= FX[oky]]
        # (4) no other direction lower at the poses found
        Mf, _ = blocks(X)
        Wc, Pc = lowest_direction(Mf, WX)
        lower = (Pc < FX - 1e-9) & (checks < DIRECTION_CHECKS) & (k > 0)
        h[lower] = 8.0 * step_tol  # another basin of directions: search on from it
        take = Pc < FX
        WX[take], FX[take] = Wc[take], Pc[take]
        checks += 1
        if not np.any(lower):
            break
    b = int(np.argmin(FX))
    q = full(X[:, b : b + 1])[:, 0]
    u, P = WX[b], float(FX[b])
    if not np.isfinite(P):
        raise InputError("mechanism", "the exact probability is not finite at the pose found", "an assembled pose")
    position = np.asarray(mech.fk(q, check_limits=False))[:3, 3]
    return ExactWorstPose(
        model=mech.name,
        R=R,
        p=p,
        q=q,
        position=position,
        direction=u,
        probability=float(P),
        margin=None if p is None else (1.0 - float(P)) / (1.0 - p),
        held_joints={names[j]: v for j, v in held.items()},
        n_grid=n_grid,
        n_evaluations=n_eval,
        seed=seed,
        elapsed_s=time.perf_counter() - t0,
        method=f"grid {g}^{k} over {', '.join(names[j] for j in free) or '-'} ranked by exact P "
        f"({directions} lattice directions + axes, Newton on the sphere), then pattern search over joints "
        f"with Newton over directions from {X.shape[1]} starts",
    )


def screen_directions(M: np.ndarray, shapes, R: float, directions: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Per pose of ``M = A diag(eps)`` (N, 3, n): the lowest exact ``P(|u . dr| <= R)`` over its
    principal axes, their bisectors and a Fibonacci lattice of ``directions`` (the direction (N, 3)
    and P (N,)), one batch of the compiled series: a screen, never below the lowest over all directions."""
    N = M.shape[0]
    _, vec = np.linalg.eigh(np.einsum("kxi,kyi->kxy", M, M))
    cand = [vec[:, :, 0], vec[:, :, 1], vec[:, :, 2]]
    for a in range(3):
        for b in range(a + 1, 3):
            cand += [(vec[:, :, a] + vec[:, :, b]) / math.sqrt(2), (vec[:, :, a] - vec[:, :, b]) / math.sqrt(2)]
    C = np.concatenate([np.stack(cand, axis=1), np.broadcast_to(_lattice_of(directions), (N, directions, 3))], axis=1)
    P, _ = probability(np.abs(np.einsum("kdx,kxn->kdn", C, M)).reshape(-1, M.shape[2]), shapes, R, GRID_TOL)
    P = P.reshape(N, -1)
    return C[np.arange(N), np.argmin(P, axis=1)], P.min(axis=1)


_LATTICES: dict = {}


def _lattice_of(m: int) -> np.ndarray:
    """The Fibonacci hemisphere of m directions (a constant per m, built once)."""
    if m not in _LATTICES:
        _LATTICES[m] = _fibonacci_hemisphere(m) if m else np.zeros((0, 3))
    return _LATTICES[m]
