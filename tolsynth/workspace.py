"""Accuracy over the workspace: the worst-error pose search and the probability map (Figure 3).

* :func:`worst_pose` searches the joint ranges, inside the joint constraints (the interference
  limit of the paper's robot), for the configuration of worst accuracy: the largest principal
  standard deviation (``criterion="sigma"``) or the lowest sphere probability
  ``P(|dr| <= R)`` (``criterion="probability"``), by a coarse grid and then a local
  generating-set (pattern) search.
* :func:`probability_map` computes ``P(|dr| <= R)`` over the reachable part of a plane through the
  base (the paper's ``X0 Z0`` plane) for a fixed hand orientation, solving the inverse kinematics
  from the model's forward-kinematics graph; :func:`plot_map` draws it with labelled contours.

Both use the analytic (linear, Gaussian) model of :meth:`tolsynth.Mechanism.analyze` evaluated on
whole batches of poses by :class:`tolsynth.montecarlo.NumpyEvaluator` (the model's sensitivity
graph and the package's covariance graph, not second copies).  Units: mm and rad in the API; the
figure is labelled in mm and deg.

>>> import tolsynth
>>> m = tolsynth.load_model("xu_zhang_1988")
>>> w = tolsynth.worst_pose(m, "figure3", criterion="sigma")
>>> bool(w.value >= w.reference_value)
True
"""

from __future__ import annotations

import math
import sys
import time
import weakref
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from .errors import InputError, OutOfRangeError, UnknownNameError
from .montecarlo import NumpyEvaluator, make_bar
from .stats import check_positive, covariance_graph, p_ball, p_ball_batch, variance_divisor

__all__ = [
    "WorstPose",
    "ProbabilityMap",
    "worst_pose",
    "probability_map",
    "plot_map",
    "principal_std_batch",
    "register",
]

PLANES = {"xz": (0, 2, 1), "xy": (0, 1, 2), "yz": (1, 2, 0)}  # (horizontal, vertical, normal) axis
_AXIS_NAMES = "XYZ"

# ---------------------------------------------------------------------------------------------
# batched analytic statistics
# ---------------------------------------------------------------------------------------------
_CACHE: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _cache(mech) -> dict:
    c = _CACHE.get(mech)
    if c is None:
        c = _CACHE[mech] = {}
    return c


def _evaluator(mech, name: str) -> NumpyEvaluator:
    c = _cache(mech)
    if name not in c:
        if name == "covariance":
            c[name] = NumpyEvaluator(covariance_graph(mech.n))
        else:
            c[name] = NumpyEvaluator(getattr(mech.graphs, name))
    return c[name]


def principal_std_batch(mechanism, Q: np.ndarray, tolerances, distribution: str = "uniform") -> np.ndarray:
    """Principal standard deviations (mm, descending) of the linearised position error at many poses.

    Parameters
    ----------
    mechanism : Mechanism
    Q : ndarray, shape (n_joints, N)
        Joint values (rad), one pose per column.  Not checked against the limits.
    tolerances : str, dict or array
        Tolerance set name or half-widths in tolerance units.
    distribution : {"uniform", "normal"}

    Returns
    -------
    ndarray, shape (N, 3)
        The same numbers as ``mechanism.analyze(q, ...).principal_std`` for each column.
    """
    eps = mechanism.tolerances(tolerances)
    c = variance_divisor(distribution)
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    sens = _evaluator(mechanism, "sensitivity")
    cov = _evaluator(mechanism, "covariance")
    out = np.empty((Q.shape[1], 3))
    chunk = 20000
    for a in range(0, Q.shape[1], chunk):
        Qc = Q[:, a : a + chunk]
        S = sens.dense(0, sens([Qc, np.zeros(mechanism.n)])[0])  # (6, n, N)
        S = S.transpose(1, 0, 2).reshape(6 * mechanism.n, -1)  # column-major vec of each S
        V = cov.dense(0, cov([S, eps, np.array([c])])[0]).transpose(2, 0, 1)  # (N, 3, 3) mm^2
        lam = np.linalg.eigvalsh(0.5 * (V + V.transpose(0, 2, 1)))[:, ::-1]
        floor = 1e-15 * np.maximum(lam[:, :1], 0.0)
        lam = np.where(lam <= floor, 0.0, lam)
        out[a : a + chunk] = np.sqrt(lam)
    return out


# ---------------------------------------------------------------------------------------------
# joint-space helpers
# ---------------------------------------------------------------------------------------------
def _limits(mech) -> tuple[np.ndarray, np.ndarray]:
    return np.array([j.lower for j in mech.spec.joints]), np.array([j.upper for j in mech.spec.joints])


def _feasible(mech, Q: np.ndarray) -> np.ndarray:
    """Joint limits and joint constraints, evaluated exactly as :meth:`Mechanism.joints` does."""
    lo, hi = _limits(mech)
    ok = np.all((Q >= lo[:, None]) & (Q <= hi[:, None]), axis=0)
    names = list(mech.joint_names)
    for c in mech.spec.joint_constraints:
        v = 0
        for jn, coef in c.terms.items():
            v = v + coef * Q[names.index(jn)]
        ok &= (c.lower <= v) & (v <= c.upper)
    return ok


def _wrap(mech, Q: np.ndarray) -> np.ndarray:
    """Move each revolute joint value by a multiple of 2 pi into its limits where possible."""
    lo, hi = _limits(mech)
    Q = Q.copy()
    for j in range(Q.shape[0]):
        v = Q[j]
        k = np.ceil((lo[j] - v) / (2 * math.pi))  # smallest shift that reaches the lower limit
        w = v + 2 * math.pi * k
        Q[j] = np.where(w <= hi[j], w, v)
    return Q


def _reference(mech, reference) -> tuple[str | None, np.ndarray | None]:
    if reference is None:
        return None, None
    if isinstance(reference, str):
        if reference not in mech.configurations:
            raise UnknownNameError("reference", f"unknown configuration {reference!r}",
                                   "one of " + ", ".join(mech.configurations))
        return reference, mech.joints(reference)
    return "given", mech.joints(reference)


def _criterion_batch(mech, Q, eps, distribution, criterion, R):
    """Values to be *maximised* (sigma_1, or -P), plus sigma (N,3) and P (N,) for the report."""
    sig = principal_std_batch(mech, Q, eps, distribution)
    if criterion == "sigma":
        return sig[:, 0], sig, None
    P = p_ball_batch(sig**2, R)
    return -P, sig, P


def _invariant_joints(mech, eps, distribution, rng) -> list[int]:
    """Joints that do not change the principal standard deviations (checked at random poses)."""
    lo, hi = _limits(mech)
    nq = len(lo)
    Q = lo[:, None] + (hi - lo)[:, None] * rng.random((nq, 6))
    base = principal_std_batch(mech, Q, eps, distribution)
    out = []
    for j in range(nq):
        Q2 = Q.copy()
        Q2[j] = lo[j] + (hi[j] - lo[j]) * rng.random(Q.shape[1])
        s2 = principal_std_batch(mech, Q2, eps, distribution)
        if np.all(np.abs(s2 - base) <= 1e-9 * np.max(base) + 1e-15):
            out.append(j)
    return out


# ---------------------------------------------------------------------------------------------
# worst pose
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class WorstPose:
    """The configuration of worst accuracy found, next to a reference configuration.

    Attributes
    ----------
    criterion : {"sigma", "probability"}
        Largest principal standard deviation (mm; larger is worse) or ``P(|dr| <= R)``
        (Eq. 5; lower is worse), both of the linear, Gaussian model.
    q, position : ndarray
        Joint values (rad) and hand position (mm) of the worst pose found.  Inside every joint
        limit and joint constraint.
    value : float
        Criterion there (sigma in mm, or the probability).
    principal_std : ndarray (mm)
    p_sphere : float or None
        ``P(|dr| <= R)`` there (with ``R``).
    reference, reference_q, reference_position, reference_value, reference_principal_std,
    reference_p_sphere
        The same at the reference configuration (the model's ``worst``: the paper's pose
        (925, 0, 1225) mm, which lies 0.33 deg past the interference limit).
    held_joints : dict
        Joints held fixed (rad) because they do not change the error statistics (found
        numerically), plus any ``fixed`` by the caller.
    active : list of str
        Limits and constraints active (within 1e-6 rad) at the worst pose.
    n_grid, n_evaluations : int
        Feasible grid points and total poses evaluated.
    method : str
    """

    model: str
    criterion: str
    distribution: str
    R: float | None
    tolerances: dict
    q: np.ndarray
    position: np.ndarray
    value: float
    principal_std: np.ndarray
    p_sphere: float | None
    reference: str | None
    reference_q: np.ndarray | None
    reference_position: np.ndarray | None
    reference_value: float | None
    reference_principal_std: np.ndarray | None
    reference_p_sphere: float | None
    held_joints: dict
    active: list
    n_grid: int
    n_evaluations: int
    elapsed_s: float
    method: str

    def to_dict(self) -> dict:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items()}

    def report(self, joint_names: Sequence[str] | None = None) -> str:
        unit = "mm (largest principal sigma)" if self.criterion == "sigma" else f"(P(|dr|<={self.R:g} mm))"
        names = joint_names or [f"q{i + 1}" for i in range(len(self.q))]
        lines = [f"worst pose   criterion {self.criterion} {unit}, {self.distribution} errors; {self.method}"]
        lines.append(f"{'':22}{'found':>42}{'reference (' + str(self.reference) + ')':>40}")
        fmt = lambda v: "(" + ", ".join(f"{x:.3f}" for x in v) + ")"  # noqa: E731
        lines.append(f"{'joints (deg)':22}{fmt(np.degrees(self.q)):>42}"
                     f"{fmt(np.degrees(self.reference_q)) if self.reference_q is not None else '-':>40}")
        lines.append(f"{'hand (mm)':22}{fmt(self.position):>42}"
                     f"{fmt(self.reference_position) if self.reference_position is not None else '-':>40}")
        lines.append(f"{'criterion':22}{self.value:>42.6f}"
                     f"{self.reference_value if self.reference_value is not None else float('nan'):>40.6f}")
        lines.append(f"{'principal sigma (mm)':22}{fmt(self.principal_std):>42}"
                     f"{fmt(self.reference_principal_std) if self.reference_principal_std is not None else '-':>40}")
        if self.p_sphere is not None:
            lines.append(f"{'P(|dr|<=R)':22}{self.p_sphere:>42.6f}"
                         f"{self.reference_p_sphere if self.reference_p_sphere is not None else float('nan'):>40.6f}")
        lines.append("joint order  " + ", ".join(names))
        lines.append("held         " + (", ".join(f"{k} = {math.degrees(v):g} deg" for k, v in self.held_joints.items()) or "-"))
        lines.append("active       " + (", ".join(self.active) or "none (interior)"))
        return "\n".join(lines)


def _tangent_directions(mech, free: list[int], scale: np.ndarray) -> np.ndarray:
    """Poll directions in scaled coordinates: +-e_i and the constraint-tangent projections of
    e_i (so that the search can slide along an active joint constraint)."""
    k = len(free)
    dirs = [np.eye(k)[i] for i in range(k)]
    names = list(mech.joint_names)
    for c in mech.spec.joint_constraints:
        a = np.zeros(k)
        for jn, coef in c.terms.items():
            j = names.index(jn)
            if j in free:
                a[free.index(j)] = coef * scale[free.index(j)]
        if not np.any(a):
            continue
        for i in range(k):
            t = np.eye(k)[i] - a[i] / (a @ a) * a
            if np.linalg.norm(t) > 1e-12:
                dirs.append(t / np.linalg.norm(t))
    D = []
    for d in dirs:
        for s in (1.0, -1.0):
            v = s * d
            if not any(np.allclose(v, e) for e in D):
                D.append(v)
    return np.array(D)


def worst_pose(
    mechanism,
    tolerances,
    criterion: str = "sigma",
    R: float | None = None,
    distribution: str = "uniform",
    grid: int | None = None,
    reference: str | Sequence[float] | None = "worst",
    fixed: Mapping[str, float] | None = None,
    starts: int = 4,
    step_tol: float = 1e-7,
    max_grid_points: int = 20000,
    seed: int = 0,
) -> WorstPose:
    """Search the joint space for the pose of worst accuracy at given tolerances.

    Method: (1) joints that do not change the error statistics are found numerically (at random
    poses) and held at the reference value -- for ``xu_zhang_1988`` the waist ``theta1`` (it turns
    the whole error ellipsoid) and the roll ``theta5`` (the hand point lies on its axis); (2) a
    coarse grid over the remaining joints, inside every joint limit and joint constraint;
    (3) from the ``starts`` best, mutually separated grid points, a generating-set search
    (compass search with complete polling; step halved on failure down to ``step_tol`` of each
    joint's range) whose directions include the tangents of the linear joint constraints, with
    infeasible polls rejected.  Derivative-free on purpose: the largest principal sigma is not
    differentiable where two principal variances cross, the sphere probability is a quadrature,
    and the worst pose typically lies on limits and the interference constraint, where a tangent
    polling set is all that is needed.

    Parameters
    ----------
    mechanism : Mechanism
    tolerances : str, dict or array
        Tolerance set name or half-widths (tolerance units).
    criterion : {"sigma", "probability"}
        Maximise the largest principal sigma (mm), or minimise ``P(|dr| <= R)`` (needs ``R``).
    R : float, optional
        Radius (mm), > 0; required for ``"probability"``, reported otherwise if given.
    distribution : {"uniform", "normal"}
    grid : int, optional
        Grid points per searched joint (default: as many as keep the grid under
        ``max_grid_points``).
    reference : str or array, optional
        Configuration reported beside the result (default: the model's ``worst``).
    fixed : dict, optional
        Joint name -> value (rad) to hold in addition to the invariant joints.
    starts : int
        Local searches started from the best grid points.
    step_tol : float
        Final step, as a fraction of each joint's range.
    seed : int
        Seed of the random poses used to detect invariant joints.

    Returns
    -------
    WorstPose

    Examples
    --------
    >>> import tolsynth
    >>> m = tolsynth.load_model("xu_zhang_1988")
    >>> w = tolsynth.worst_pose(m, "figure3", criterion="probability", R=0.2)
    >>> bool(w.p_sphere <= w.reference_p_sphere)
    True
    """
    t0 = time.perf_counter()
    if criterion not in ("sigma", "probability"):
        raise OutOfRangeError("criterion", f"got {criterion!r}", "'sigma' or 'probability'")
    variance_divisor(distribution)
    if R is not None:
        R = check_positive(R, "R")
    elif criterion == "probability":
        raise InputError("R", "criterion 'probability' needs a radius", "a finite number > 0 (mm)")
    starts = int(starts)
    if starts < 1:
        raise OutOfRangeError("starts", f"got {starts}", "an integer >= 1")
    eps = mechanism.tolerances(tolerances)
    ref_name, ref_q = _reference(mechanism, reference)
    lo, hi = _limits(mechanism)
    nq = len(lo)
    names = list(mechanism.joint_names)
    rng = np.random.default_rng(seed)

    held: dict[int, float] = {}
    base_q = ref_q if ref_q is not None else np.clip(np.zeros(nq), lo, hi)
    for j in _invariant_joints(mechanism, eps, distribution, rng):
        held[j] = float(np.clip(base_q[j], lo[j], hi[j]))
    for name, v in (fixed or {}).items():
        if name not in names:
            raise UnknownNameError("fixed", f"unknown joint {name!r}", "one of " + ", ".join(names))
        if not lo[names.index(name)] <= float(v) <= hi[names.index(name)]:
            raise OutOfRangeError(f"fixed[{name}]", f"{math.degrees(v):g} deg",
                                  f"{math.degrees(lo[names.index(name)]):g} to {math.degrees(hi[names.index(name)]):g} deg")
        held[names.index(name)] = float(v)
    free = [j for j in range(nq) if j not in held]
    k = len(free)
    n_eval = 0

    def full(U: np.ndarray) -> np.ndarray:  # scaled (k, N) -> joints (nq, N)
        Q = np.empty((nq, U.shape[1]))
        for j, v in held.items():
            Q[j] = v
        for i, j in enumerate(free):
            Q[j] = np.where(U[i] >= 1.0, hi[j], lo[j] + (hi[j] - lo[j]) * U[i])  # the limit itself at 1
        return Q

    def evaluate(U: np.ndarray) -> np.ndarray:
        nonlocal n_eval
        Q = full(U)
        ok = _feasible(mechanism, Q) & np.all((U >= 0) & (U <= 1), axis=0)
        val = np.full(U.shape[1], -np.inf)
        if np.any(ok):
            val[ok] = _criterion_batch(mechanism, Q[:, ok], eps, distribution, criterion, R)[0]
            n_eval += int(np.count_nonzero(ok))
        return val

    # (2) coarse grid
    if k == 0:
        U = np.zeros((0, 1))
        vals = evaluate(U)
        g = 1
    else:
        g = int(grid) if grid is not None else max(5, int(math.floor(max_grid_points ** (1.0 / k))))
        if g < 2:
            raise OutOfRangeError("grid", f"got {grid}", "an integer >= 2")
        axes = [np.linspace(0.0, 1.0, g)] * k
        U = np.array([a.ravel() for a in np.meshgrid(*axes, indexing="ij")])
        vals = evaluate(U)
    feasible = np.isfinite(vals)
    if not np.any(feasible):
        raise OutOfRangeError("joint limits", "no grid point satisfies every joint limit and constraint",
                              "a non-empty feasible joint space")
    n_grid = int(np.count_nonzero(feasible))

    # (3) local generating-set search from the best separated grid points
    order = np.argsort(-vals)
    picked: list[int] = []
    h0 = 1.0 / (g - 1) if k else 0.0
    for i in order:
        if not np.isfinite(vals[i]):
            break
        if all(np.max(np.abs(U[:, i] - U[:, p])) > 1.5 * h0 for p in picked):
            picked.append(int(i))
        if len(picked) >= starts:
            break
    best_u = U[:, picked[0]].copy()
    if k:
        D = _tangent_directions(mechanism, free, hi[free] - lo[free])
        X = U[:, picked].copy()  # (k, S)
        F = vals[picked].copy()
        h = np.full(len(picked), 0.5 * h0)
        while np.any(h >= step_tol):
            act = np.flatnonzero(h >= step_tol)
            P = X[:, act, None] + h[act][None, :, None] * D.T[:, None, :]  # (k, A, nd)
            fv = evaluate(P.reshape(k, -1)).reshape(len(act), -1)
            j = np.argmax(fv, axis=1)
            gain = fv[np.arange(len(act)), j]
            better = gain > F[act] + 1e-14 * np.abs(F[act])
            for a_i, s in enumerate(act):
                if better[a_i]:
                    X[:, s] = P[:, a_i, j[a_i]]
                    F[s] = gain[a_i]
                else:
                    h[s] *= 0.5
        b = int(np.argmax(F))
        best_u = X[:, b]
    q = full(best_u[:, None])[:, 0]
    value, sig, P = _criterion_batch(mechanism, q[:, None], eps, distribution, criterion, R)
    p_sph = float(p_ball(sig[0] ** 2, R)) if R is not None else None
    position = np.asarray(mechanism.fk(q, check_limits=True))[:3, 3]

    active = []
    tol_a = 1e-6
    for j in range(nq):
        if j in held:
            continue
        if abs(q[j] - lo[j]) <= tol_a:
            active.append(f"{names[j]} lower ({math.degrees(lo[j]):g} deg)")
        if abs(q[j] - hi[j]) <= tol_a:
            active.append(f"{names[j]} upper ({math.degrees(hi[j]):g} deg)")
    for c in mechanism.spec.joint_constraints:
        v = sum(coef * q[names.index(jn)] for jn, coef in c.terms.items())
        if abs(v - c.lower) <= tol_a:
            active.append(f"{c.name} lower ({math.degrees(c.lower):g} deg)")
        if abs(v - c.upper) <= tol_a:
            active.append(f"{c.name} upper ({math.degrees(c.upper):g} deg)")

    ref = dict(reference_q=None, reference_position=None, reference_value=None,
               reference_principal_std=None, reference_p_sphere=None)
    if ref_q is not None:
        rv, rs, rp = _criterion_batch(mechanism, ref_q[:, None], eps, distribution, criterion, R)
        ref.update(
            reference_q=ref_q,
            reference_position=np.asarray(mechanism.fk(ref_name if ref_name != "given" else ref_q))[:3, 3],
            reference_value=float(rs[0, 0]) if criterion == "sigma" else float(rp[0]),
            reference_principal_std=rs[0],
            reference_p_sphere=float(p_ball(rs[0] ** 2, R)) if R is not None else None,
        )
    return WorstPose(
        model=mechanism.name,
        criterion=criterion,
        distribution=distribution,
        R=R,
        tolerances=dict(zip(mechanism.error_parameters, eps.tolist())),
        q=q,
        position=position,
        value=float(sig[0, 0]) if criterion == "sigma" else float(P[0]),
        principal_std=sig[0],
        p_sphere=p_sph,
        reference=ref_name,
        held_joints={names[j]: v for j, v in held.items()},
        active=active,
        n_grid=n_grid,
        n_evaluations=n_eval,
        elapsed_s=time.perf_counter() - t0,
        method=f"grid {g}^{k} over {', '.join(names[j] for j in free) or '-'}, then pattern search from {len(picked)} starts",
        **ref,
    )


# ---------------------------------------------------------------------------------------------
# inverse kinematics on the model's fk graph (batched Levenberg-Marquardt)
# ---------------------------------------------------------------------------------------------
_ORIENT_WEIGHT = 1000.0  # mm per unit of axis-direction error in the residual (1 mrad ~ 1 mm)


def _ik_evaluator(mech, free: tuple[int, ...], with_axis: bool) -> NumpyEvaluator:
    key = ("ik", free, with_axis)
    c = _cache(mech)
    if key not in c:
        nq = len(mech.joint_names)
        q = ca.SX.sym("q", nq)
        target = ca.SX.sym("target", 3)
        axis = ca.SX.sym("axis", 3)
        T = mech.graphs.fk(q, ca.DM.zeros(mech.n))
        r = T[:3, 3] - target
        if with_axis:
            r = ca.vertcat(r, _ORIENT_WEIGHT * (T[:3, 2] - axis))
        J = ca.densify(ca.jacobian(r, q[list(free)]))
        c[key] = NumpyEvaluator(ca.Function("ik_residual", [q, target, axis], [ca.densify(r), J],
                                            ["q", "target", "axis"], ["r", "J"]))
    return c[key]


def _solve_ik(ev: NumpyEvaluator, free: tuple[int, ...], Q0: np.ndarray, targets: np.ndarray,
              axis: np.ndarray, tol: float = 1e-7, max_iter: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Levenberg-Marquardt on all columns at once.  Returns joints (nq, N) and a converged flag
    (residual norm below ``tol``: mm, and 1e-3 * tol in the axis direction)."""
    Q = Q0.copy()
    N = Q.shape[1]
    if N == 0:
        return Q, np.zeros(0, bool)
    fr = list(free)
    nf = len(fr)

    def residual(Qa, Ta):
        r, J = ev([Qa, Ta, axis])
        return r, J.reshape(r.shape[0], nf, -1, order="F")  # column-major dense J (nr x nf)

    r, J = residual(Q, targets)
    cost = np.einsum("rb,rb->b", r, r)
    cost = np.where(np.isfinite(cost), cost, np.inf)
    mu = np.full(N, 1e-3)
    conv = cost <= tol * tol
    active = ~conv
    eye = np.eye(nf)
    for _ in range(max_iter):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        Ja, ra = J[:, :, idx], r[:, idx]
        A = np.einsum("rkb,rlb->bkl", Ja, Ja)
        g = np.einsum("rkb,rb->bk", Ja, ra)
        diag = np.einsum("bkk->bk", A)
        Ad = A + (mu[idx, None] * (diag + 1e-9))[:, :, None] * eye
        try:
            step = np.linalg.solve(Ad, -g[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:
            step = np.linalg.lstsq(Ad.reshape(-1, nf), -g.reshape(-1), rcond=None)[0].reshape(-1, nf)
        Qn = Q[:, idx].copy()
        Qn[fr] += step.T
        rn, Jn = residual(Qn, targets[:, idx])
        cn = np.einsum("rb,rb->b", rn, rn)
        acc = np.isfinite(cn) & (cn < cost[idx])
        a = idx[acc]
        Q[:, a] = Qn[:, acc]
        r[:, a] = rn[:, acc]
        J[:, :, a] = Jn[:, :, acc]
        small_gain = acc & (cost[idx] - cn <= 1e-14 * cost[idx])
        cost[a] = cn[acc]
        mu[idx] = np.where(acc, np.maximum(mu[idx] / 3.0, 1e-12), mu[idx] * 4.0)
        conv[idx] = cost[idx] <= tol * tol
        stalled = (mu[idx] > 1e8) | small_gain | (np.max(np.abs(step), axis=1) < 1e-13)
        active[idx] = ~conv[idx] & ~stalled
    return Q, conv


def _halton(n: int, dim: int) -> np.ndarray:
    primes = [2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37][:dim]
    out = np.empty((n, dim))
    for d, b in enumerate(primes):
        for i in range(n):
            f, r, k = 1.0, 0.0, i + 1
            while k > 0:
                f /= b
                r += f * (k % b)
                k //= b
            out[i, d] = r
    return out


def _limit_margin(mech, Q: np.ndarray) -> np.ndarray:
    """Smallest distance (rad) to a joint limit or joint constraint; negative outside."""
    lo, hi = _limits(mech)
    m = np.min(np.minimum(Q - lo[:, None], hi[:, None] - Q), axis=0)
    names = list(mech.joint_names)
    for c in mech.spec.joint_constraints:
        v = 0
        for jn, coef in c.terms.items():
            v = v + coef * Q[names.index(jn)]
        norm = math.sqrt(sum(coef * coef for coef in c.terms.values()))
        m = np.minimum(m, np.minimum(v - c.lower, c.upper - v) / norm)
    return m


class _GridIK:
    """Inverse kinematics on a grid of a plane: Levenberg-Marquardt on the fk graph, continuation
    over the grid from the reference configuration, quasi-random seeds for what it misses."""

    def __init__(self, mech, free, held, ref_q, axis, plane, offset, seeds):
        self.mech = mech
        self.free = free
        self.axis_in = axis if axis is not None else np.zeros(3)
        self.ev = _ik_evaluator(mech, free, axis is not None)
        self.iu, self.iv, self.inorm = PLANES[plane]
        self.offset = offset
        self.ref_q = ref_q.copy()
        for j, (v, _) in held.items():
            self.ref_q[j] = v
        lo, hi = _limits(mech)
        seed_set = [cq.copy() for cq in mech.configurations.values()]  # named configurations,
        for hrow in _halton(max(seeds, 0), len(free)):  # then Halton points inside the limits
            s = ref_q.copy()
            for i, j in enumerate(free):
                s[j] = lo[j] + (hi[j] - lo[j]) * hrow[i]
            seed_set.append(s)
        for s in seed_set:
            for j, (v, _) in held.items():
                s[j] = v
        self.seed_set = seed_set

    def targets(self, U, V) -> np.ndarray:
        T = np.empty((3, U.size))
        T[self.iu], T[self.iv], T[self.inorm] = U, V, self.offset
        return T

    def attempt(self, Q0, T):
        """Solve from Q0; returns wrapped joints, valid (converged and inside every limit), and
        the limit margin of converged solutions (-inf where not converged)."""
        Q, conv = _solve_ik(self.ev, self.free, Q0, T, self.axis_in)
        Q = _wrap(self.mech, Q)
        margin = np.where(conv, _limit_margin(self.mech, Q), -np.inf)
        return Q, conv & _feasible(self.mech, Q), margin

    def solve(self, u, v, bar=None):
        """Joints (nq, N), reachable flag (N,) and limit margin (N,) for the grid u x v (rows v)."""
        nu, nv = u.size, v.size
        Ug, Vg = np.meshgrid(u, v)
        T = self.targets(Ug.ravel(), Vg.ravel())
        N = T.shape[1]
        nq = len(self.ref_q)
        Qs = np.full((nq, N), np.nan)
        ok = np.zeros(N, bool)
        margin = np.full(N, -np.inf)
        tried = np.zeros(N, bool)

        def take(idx, Q, good, mg):
            better = mg > margin[idx]
            margin[idx[better]] = mg[better]
            Qs[:, idx[good]] = Q[:, good]
            ok[idx[good]] = True

        # start: the grid point nearest the reference hand point, from the reference joints
        p_ref = np.asarray(self.mech.graphs.position(self.ref_q, np.zeros(self.mech.n))).ravel()
        start = int(np.argmin((T[self.iu] - p_ref[self.iu]) ** 2 + (T[self.iv] - p_ref[self.iv]) ** 2))
        for s in [self.ref_q] + self.seed_set:
            take(np.array([start]), *self.attempt(s[:, None].copy(), T[:, [start]]))
            if ok[start]:
                break
        tried[start] = True
        flat = np.arange(N).reshape(nv, nu)
        last = np.full(N, -1)  # the neighbour a point was last seeded from

        def continuation():
            # sweeps: unsolved points next to solved ones, seeded with a solved neighbour's joints
            while True:
                grid_ok = ok.reshape(nv, nu)
                src = np.full((nv, nu), -1)
                for dv, du in ((0, 1), (0, -1), (1, 0), (-1, 0), (1, 1), (-1, -1), (1, -1), (-1, 1)):
                    vs, vd = slice(max(dv, 0), nv + min(dv, 0)), slice(max(-dv, 0), nv + min(-dv, 0))
                    us, ud = slice(max(du, 0), nu + min(du, 0)), slice(max(-du, 0), nu + min(-du, 0))
                    cand = np.where(grid_ok[vs, us], flat[vs, us], -1)
                    dst = src[vd, ud]
                    src[vd, ud] = np.where(dst < 0, cand, dst)
                src = src.ravel()
                front = np.flatnonzero((src >= 0) & ~ok & ~tried)
                if front.size == 0:
                    return
                tried[front] = True
                last[front] = src[front]
                take(front, *self.attempt(Qs[:, src[front]], T[:, front]))
                if bar is not None:
                    bar.update(front.size)

        continuation()
        for s in self.seed_set:  # points not reached: quasi-random seeds, then continuation again
            rest = np.flatnonzero(~ok)
            if rest.size == 0:
                break
            before = int(ok.sum())
            take(rest, *self.attempt(np.repeat(s[:, None], rest.size, axis=1), T[:, rest]))
            if ok.sum() > before:
                tried[:] = ok
                continuation()
        if bar is not None:
            bar.update(max(0, N - bar.n))
        return Qs, ok, margin


# ---------------------------------------------------------------------------------------------
# probability map
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ProbabilityMap:
    """``P(|dr| <= R)`` over the reachable part of a plane, for a fixed hand orientation.

    Attributes
    ----------
    u, v : ndarray (mm)
        Grid coordinates along the plane's horizontal and vertical axes (``X0`` and ``Z0`` for
        ``plane="xz"``).
    P : ndarray, shape (len(v), len(u))
        Probability; NaN where the point is not reachable with the hand orientation and the
        joint limits and constraints (the interference limit).
    sigma : ndarray, shape (len(v), len(u), 3)
        Principal standard deviations (mm), NaN outside.
    Q : ndarray, shape (n_joints, len(v), len(u))
        The inverse-kinematics solution used (rad), NaN outside.
    limit_margin : ndarray, shape (len(v), len(u))
        Smallest distance (rad) of that solution to a joint limit or joint constraint: >= 0 inside
        the reachable region, < 0 where the solution continued past a limit, -inf where no
        solution was found; its zero contour is the region's boundary.
    plane, offset, hand_axis
        The plane, its offset along the normal (mm) and the hand z axis imposed.
    fixed : dict
        Joints held (rad) and why.
    branch : str
        How the inverse-kinematics solution was chosen, and whether another one within the limits
        was found anywhere.
    worst : tuple
        ``(u, v, P)`` of the lowest probability on the map.
    reference_point : tuple or None
        ``(u, v)`` of the reference configuration's hand point, if it lies on the plane with the
        hand axis of the map; ``reference_P`` the probability there (that configuration's own
        joint values, with the limits it waives).  For ``xu_zhang_1988`` this is the paper's pose
        (925, 1225) mm, 0.33 deg past the interference limit: on the map's edge.
    """

    model: str
    u: np.ndarray
    v: np.ndarray
    P: np.ndarray
    sigma: np.ndarray
    Q: np.ndarray
    limit_margin: np.ndarray
    plane: str
    offset: float
    hand_axis: np.ndarray | None
    R: float
    distribution: str
    tolerances: dict
    tolerance_label: str
    fixed: dict
    free_joints: tuple
    joint_names: tuple
    branch: str
    n_alternative_solutions: int
    n_checked: int
    worst: tuple
    reference: str | None
    reference_point: tuple | None
    reference_P: float | None
    constraints: tuple
    elapsed_s: float
    units: dict = field(default_factory=lambda: {"u": "mm", "v": "mm", "sigma": "mm", "Q": "rad", "R": "mm"})

    @property
    def reachable(self) -> np.ndarray:
        return np.isfinite(self.P)

    def to_dict(self) -> dict:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items()}

    def plot(self, path=None, ax=None):
        """See :func:`plot_map`."""
        return plot_map(self, path=path, ax=ax)


def _yaw_joint(mech, ref_q: np.ndarray, rng) -> int | None:
    """A joint that only turns the whole arm about the base Z axis (dp/dq = e_z x p, and the
    same for the hand axis), checked at random poses; None if there is none."""
    pos = _evaluator(mech, "position")
    lo, hi = _limits(mech)
    nq = len(lo)
    Q = lo[:, None] + (hi - lo)[:, None] * rng.random((nq, 5))
    h = 1e-6
    p0 = pos([Q, np.zeros(mech.n)])[0]
    for j in range(nq):
        Q2 = Q.copy()
        Q2[j] += h
        dp = (pos([Q2, np.zeros(mech.n)])[0] - p0) / h
        ez_x_p = np.vstack([-p0[1], p0[0], np.zeros(p0.shape[1])])
        if np.allclose(dp, ez_x_p, atol=1e-4 * (1 + np.abs(p0).max())):
            return j
    return None


def probability_map(
    mechanism,
    tolerances="figure3",
    R: float = 0.2,
    distribution: str = "uniform",
    n: int = 100,
    plane: str = "xz",
    offset: float = 0.0,
    hand_axis: Sequence[float] | None = (0.0, 0.0, 1.0),
    fixed: Mapping[str, float] | None = None,
    extent: Sequence[float] | None = None,
    reference: str | None = "worst",
    seeds: int = 8,
    check_points: int = 200,
    progress: bool | None = None,
) -> ProbabilityMap:
    """``P(|dr| <= R)`` (Eq. 5, linear + Gaussian) over the reachable part of a plane (Figure 3).

    Inverse kinematics: for each grid point the joints are solved from the model's forward
    kinematics graph (hand point on the grid point, hand z axis along ``hand_axis``) by a
    batched Levenberg-Marquardt iteration, by continuation over the grid from the reference
    configuration (each point seeded with a solved neighbour's joints), with deterministic
    quasi-random seeds for points the continuation does not reach.  A point is *reachable* only
    if the solution lies inside every joint limit and joint constraint (for ``xu_zhang_1988`` the
    interference limit); revolute joints are first moved by multiples of 2 pi into their limits.
    The branch is therefore the one connected to the reference configuration; at
    ``check_points`` random reachable points all seeds are run again and the number of points
    with another valid solution is reported (0 means the solution is unique within the limits
    there).  Joints that change neither the hand point nor its axis are held at the reference
    value; for a plane containing ``Z0`` a joint that only turns the arm about ``Z0`` (the
    waist) is held at 0, so the plane is its ``theta = 0`` half.  The loops close on the branch
    declared in the model file.

    Parameters
    ----------
    mechanism : Mechanism
    tolerances : str, dict or array
        Default: the ``figure3`` set of the paper's Figure 3.
    R : float
        Radius (mm), > 0.
    distribution : {"uniform", "normal"}
    n : int
        Grid points per axis (n x n), >= 5.
    plane : {"xz", "xy", "yz"}
        Base-frame plane; ``offset`` (mm) along its normal.
    hand_axis : 3 floats or None
        Hand z axis imposed (base frame; normalised), None for none.  Default: vertical, up, as
        in the paper's worst pose.
    fixed : dict, optional
        Joint name -> value (rad) to hold fixed, replacing the automatic choice.
    extent : (umin, umax, vmin, vmax), optional
        Grid extent (mm); default: the reachable region's bounding box from a coarse pass.
    reference : str or None
        Configuration to start the continuation from and to mark (default ``worst``).
    seeds : int
        Quasi-random seeds for points not reached by continuation.
    check_points : int
        Reachable points at which uniqueness of the solution is checked.
    progress : bool or None
        A tqdm bar on stderr (None: on a terminal, shown once the run has taken 2 s).

    Returns
    -------
    ProbabilityMap
    """
    t0 = time.perf_counter()
    R = check_positive(R, "R")
    variance_divisor(distribution)
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 5:
        raise OutOfRangeError("n", f"got {n!r}", "an integer >= 5 (grid points per axis)")
    if plane not in PLANES:
        raise OutOfRangeError("plane", f"got {plane!r}", "one of " + ", ".join(PLANES))
    eps = mechanism.tolerances(tolerances)
    label = tolerances if isinstance(tolerances, str) else "given"
    axis = None
    if hand_axis is not None:
        axis = np.asarray(hand_axis, dtype=float).ravel()
        if axis.shape != (3,) or not np.all(np.isfinite(axis)) or np.linalg.norm(axis) == 0:
            raise InputError("hand_axis", f"got {hand_axis!r}", "3 finite numbers, not all 0, or None")
        axis = axis / np.linalg.norm(axis)
    names = list(mechanism.joint_names)
    nq = len(names)
    lo, hi = _limits(mechanism)
    ref_name, ref_q = _reference(mechanism, reference)
    if ref_q is None:
        ref_q = np.clip(np.zeros(nq), lo, hi)
    rng = np.random.default_rng(0)

    # joints held fixed
    held: dict[int, tuple[float, str]] = {}
    if fixed is not None:
        for name, val in fixed.items():
            if name not in names:
                raise UnknownNameError("fixed", f"unknown joint {name!r}", "one of " + ", ".join(names))
            held[names.index(name)] = (float(val), "given")
    else:
        ev_all = _ik_evaluator(mechanism, tuple(range(nq)), axis is not None)
        Qr = lo[:, None] + (hi - lo)[:, None] * rng.random((nq, 6))
        _, J = ev_all([Qr, np.zeros(3), axis if axis is not None else np.zeros(3)])
        J = J.reshape(-1, nq, Qr.shape[1], order="F")
        for j in range(nq):
            if np.all(np.abs(J[:, j, :]) <= 1e-9):
                held[j] = (float(ref_q[j]), "moves neither the hand point nor its axis")
        if "z" in plane:
            yaw = _yaw_joint(mechanism, ref_q, rng)
            if yaw is not None and yaw not in held and lo[yaw] <= 0.0 <= hi[yaw]:
                held[yaw] = (0.0, "turns the arm about Z0; the map is at its zero")
    free = tuple(j for j in range(nq) if j not in held)
    if not free:
        raise InputError("fixed", "every joint is held fixed", "at least one free joint")
    iu, iv, inorm = PLANES[plane]

    ik = _GridIK(mechanism, free, held, ref_q, axis, plane, offset, int(seeds))

    # extent: reachable bounding box from a coarse pass (unless given)
    if extent is None:
        pos = _evaluator(mechanism, "position")
        Qr = lo[:, None] + (hi - lo)[:, None] * rng.random((nq, 4000))
        for j, (v, _) in held.items():
            Qr[j] = v
        P = pos([Qr, np.zeros(mechanism.n)])[0]
        reach = float(np.max(np.linalg.norm(P - P.mean(axis=1, keepdims=True), axis=0)))
        cu, cv = P[iu].mean(), P[iv].mean()
        span = 1.6 * reach
        m0 = 41
        uc = np.linspace(cu - span, cu + span, m0)
        vc = np.linspace(cv - span, cv + span, m0)
        okc = ik.solve(uc, vc)[1].reshape(m0, m0)
        if not np.any(okc):
            raise InputError("plane", f"no reachable point found in the {plane} plane at offset {offset:g} mm "
                             "with this hand axis", "a plane and hand axis the arm can reach")
        du, dv = uc[1] - uc[0], vc[1] - vc[0]
        cols, rows = np.flatnonzero(okc.any(axis=0)), np.flatnonzero(okc.any(axis=1))
        # two coarse cells of margin: thin tips of the region can fall between coarse points
        extent = (uc[cols[0]] - 2 * du, uc[cols[-1]] + 2 * du, vc[rows[0]] - 2 * dv, vc[rows[-1]] + 2 * dv)
    else:
        extent = tuple(float(e) for e in extent)
        if len(extent) != 4 or not (extent[0] < extent[1] and extent[2] < extent[3]):
            raise InputError("extent", f"got {extent!r}", "(umin, umax, vmin, vmax) in mm with min < max")
    u = np.linspace(extent[0], extent[1], n)
    v = np.linspace(extent[2], extent[3], n)

    bar = None
    if progress or (progress is None and sys.stderr.isatty()):  # auto: shown on runs longer than ~2 s
        bar = make_bar(n * n, "map (inverse kinematics)", "pt", 0.0 if progress else 2.0)
    try:
        Qs, ok, margin = ik.solve(u, v, bar)
    finally:
        if bar is not None:
            bar.close()
    T = ik.targets(*[a.ravel() for a in np.meshgrid(u, v)])

    sig = np.full((n * n, 3), np.nan)
    Pv = np.full(n * n, np.nan)
    if np.any(ok):
        s = principal_std_batch(mechanism, Qs[:, ok], eps, distribution)
        sig[ok] = s
        Pv[ok] = p_ball_batch(s**2, R)

    # uniqueness check at sampled reachable points: every seed again, any other valid solution?
    idx = np.flatnonzero(ok)
    chk = rng.choice(idx, size=min(int(check_points), idx.size), replace=False) if idx.size else idx
    alt = np.zeros(chk.size, bool)
    for s in ik.seed_set:
        if chk.size == 0:
            break
        Q, good, _ = ik.attempt(np.repeat(s[:, None], chk.size, axis=1), T[:, chk])
        diff = np.max(np.abs(Q[list(free)] - Qs[list(free)][:, chk]), axis=0)
        alt |= good & (diff > 1e-5)
    n_alt = int(np.count_nonzero(alt))
    branch = ("continuation from the reference configuration"
              + (f"; loop branch {', '.join(f'{lp.name} {lp.branch:+d}' for lp in mechanism.spec.loops)} (model file)"
                 if mechanism.spec.loops else "")
              + (f"; unique within the limits at {chk.size} checked points" if n_alt == 0
                 else f"; ANOTHER valid solution exists at {n_alt} of {chk.size} checked points"))

    Pg = Pv.reshape(n, n)
    if np.any(ok):
        w = int(np.nanargmin(Pv))
        worst = (float(T[iu, w]), float(T[iv, w]), float(Pv[w]))
    else:
        worst = (math.nan, math.nan, math.nan)
    ref_point = None
    ref_P = None
    if ref_name is not None:
        Tref = np.asarray(mechanism.fk(ref_name))
        pr = Tref[:3, 3]
        on_plane = abs(pr[inorm] - offset) < 1e-6 and (axis is None or np.allclose(Tref[:3, 2], axis, atol=1e-6))
        if on_plane:
            ref_point = (float(pr[iu]), float(pr[iv]))
            ref_P = float(mechanism.analyze(ref_name, eps, distribution, R=R).p_sphere)
    return ProbabilityMap(
        model=mechanism.name,
        u=u,
        v=v,
        P=Pg,
        sigma=sig.reshape(n, n, 3),
        Q=Qs.reshape(nq, n, n),
        limit_margin=margin.reshape(n, n),
        plane=plane,
        offset=float(offset),
        hand_axis=axis,
        R=R,
        distribution=distribution,
        tolerances=dict(zip(mechanism.error_parameters, eps.tolist())),
        tolerance_label=label,
        fixed={names[j]: (val, why) for j, (val, why) in held.items()},
        free_joints=tuple(names[j] for j in free),
        joint_names=tuple(names),
        branch=branch,
        n_alternative_solutions=n_alt,
        n_checked=int(chk.size),
        worst=worst,
        reference=ref_name,
        reference_point=ref_point,
        reference_P=ref_P,
        constraints=tuple(
            f"{c.name}: {math.degrees(c.lower):g} <= "
            + " ".join(f"{'+' if coef > 0 else '-'} {'' if abs(coef) == 1 else f'{abs(coef):g}*'}{jn}" for jn, coef in c.terms.items()).lstrip("+ ")
            + f" <= {math.degrees(c.upper):g} deg"
            for c in mechanism.spec.joint_constraints
        ),
        elapsed_s=time.perf_counter() - t0,
    )


def plot_map(pmap: ProbabilityMap, path=None, ax=None, levels=None):
    """Labelled contour lines of a :class:`ProbabilityMap` (needs matplotlib, extra ``plot``).

    Parameters
    ----------
    pmap : ProbabilityMap
    path : str or path, optional
        Save the figure there (PNG, PDF, ... by suffix).
    ax : matplotlib Axes, optional
    levels : sequence of float, optional
        Contour levels (probabilities); default: steps of 0.05 or 0.1 inside the map's range.

    Returns
    -------
    matplotlib.figure.Figure
    """
    try:
        import matplotlib

        if ax is None and path is not None:
            matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover
        raise ImportError("plot_map needs matplotlib: pip install 'tolsynth[plot]'") from exc

    iu, iv, _ = PLANES[pmap.plane]
    if ax is None:
        fig, ax = plt.subplots(figsize=(8.0, 8.6))
    else:
        fig = ax.figure
    P = pmap.P
    reach = np.isfinite(P)
    if levels is None:
        lo_p, hi_p = np.nanmin(P), np.nanmax(P)
        span = hi_p - lo_p
        step = 0.1 if span > 0.6 else 0.05 if span > 0.2 else 0.02 if span > 0.08 else 0.005 if span > 0.02 else None
        if step is None:  # nearly flat: let matplotlib choose
            from matplotlib.ticker import MaxNLocator

            levels = MaxNLocator(8).tick_values(lo_p, hi_p)
        else:
            levels = np.arange(math.floor(lo_p / step) * step + step, hi_p, step)
        levels = levels[(levels > lo_p) & (levels < hi_p)]
        if levels.size == 0:
            levels = [0.5 * (lo_p + hi_p)]
    digits = max(2, int(math.ceil(-math.log10(max(np.min(np.diff(levels)) if len(levels) > 1 else 0.01, 1e-12)))))
    U, V = np.meshgrid(pmap.u, pmap.v)
    # the reachable region: light fill, its boundary, then the labelled contours of P inside it
    # the boundary is the zero contour of the joint-limit margin (smooth where a limit binds)
    mg = np.where(np.isfinite(pmap.limit_margin), pmap.limit_margin, -1.0)
    mg = np.where(reach, np.maximum(mg, 0.0), np.minimum(mg, -1e-12))  # the margin's sign = reachability
    ax.contourf(U, V, mg, levels=[0.0, np.inf], colors=["#eef3fa"])
    ax.contour(U, V, mg, levels=[0.0], colors="0.35", linewidths=1.2)
    cs = ax.contour(U, V, P, levels=levels, cmap="viridis_r", linewidths=1.1)
    ax.clabel(cs, fmt=lambda x: f"{x:.{digits}f}", fontsize=8, inline=True)
    wu, wv, wp = pmap.worst
    ax.plot([wu], [wv], marker="v", color="crimson", ms=9, ls="none",
            label=f"lowest P on the map: {wp:.3f} at ({wu:.0f}, {wv:.0f}) mm")
    if pmap.reference_point is not None:
        ru, rv = pmap.reference_point
        ax.plot([ru], [rv], marker="*", color="black", ms=12, ls="none",
                label=f"configuration '{pmap.reference}' ({ru:.0f}, {rv:.0f}) mm, P = {pmap.reference_P:.3f}")
    an, bn = _AXIS_NAMES[iu], _AXIS_NAMES[iv]
    ax.set_xlabel(f"{an}0 (mm)")
    ax.set_ylabel(f"{bn}0 (mm)")
    ax.set_aspect("equal")
    ax.grid(True, color="0.9", lw=0.5)
    ax.set_title(f"{pmap.model}: P(|dr| <= {pmap.R:g} mm), {pmap.distribution} errors, tolerances "
                 f"'{pmap.tolerance_label}'\nlinear + Gaussian model (Eq. 5); blank = not reachable", fontsize=10)
    deg = lambda x: f"{math.degrees(x):g} deg"  # noqa: E731
    axis_txt = ("hand z axis " + "(" + ", ".join(f"{c:g}" for c in pmap.hand_axis) + ")"
                + (" = vertical, up" if pmap.hand_axis is not None and np.allclose(pmap.hand_axis, [0, 0, 1]) else "")
                if pmap.hand_axis is not None else "hand orientation free")
    lines = [
        f"plane {pmap.plane} at {'XYZ'[PLANES[pmap.plane][2]]}0 = {pmap.offset:g} mm; {axis_txt}",
        "held: " + ("; ".join(f"{k} = {deg(v)} ({why})" for k, (v, why) in pmap.fixed.items()) or "none"),
        "IK on the fk graph (Levenberg-Marquardt), branch: " + pmap.branch,
        "reachable = IK solution inside all joint limits" + (" and " + "; ".join(pmap.constraints) if pmap.constraints else ""),
    ]
    import textwrap

    text = "\n".join(textwrap.fill(line, 110, subsequent_indent="   ") for line in lines)
    fig.text(0.02, 0.01, text, fontsize=7, va="bottom", ha="left", family="monospace")
    ax.legend(loc="upper left", fontsize=8, framealpha=0.9)
    fig.subplots_adjust(bottom=0.2, top=0.92)
    if path is not None:
        fig.savefig(path, dpi=130)
    return fig


# ---------------------------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------------------------
def _cmd_map(args) -> int:
    from .cli import emit_json, parse_tolerances
    from .mechanism import load_model

    mech = load_model(args.model)
    eps = parse_tolerances(mech, args.tolerances)
    label = args.tolerances
    extent = None
    if args.extent:
        try:
            extent = [float(x) for x in args.extent.split(",")]
        except ValueError:
            raise InputError("--extent", f"{args.extent!r}", "umin,umax,vmin,vmax in mm") from None
    axis = None if args.hand_axis == "free" else [float(x) for x in args.hand_axis.split(",")]
    pm = probability_map(mech, eps, R=args.R, distribution=args.dist, n=args.n, plane=args.plane,
                         offset=args.offset, hand_axis=axis, extent=extent,
                         progress=False if args.quiet else None)
    pm = ProbabilityMap(**{**pm.__dict__, "tolerance_label": label})
    if args.out:
        import matplotlib

        matplotlib.use("Agg")
        plot_map(pm, path=args.out)
    if args.json:
        out = {k: v for k, v in pm.to_dict().items() if k not in ("Q", "sigma")}
        out["out"] = args.out
        emit_json(out)
    else:
        rch = pm.reachable
        print(f"map          {mech.name}, plane {pm.plane}, {args.n} x {args.n} points, {int(rch.sum())} reachable")
        print(f"extent       {pm.u[0]:.1f} .. {pm.u[-1]:.1f} x {pm.v[0]:.1f} .. {pm.v[-1]:.1f} mm")
        print(f"P(dr<=R)     {np.nanmin(pm.P):.4f} .. {np.nanmax(pm.P):.4f}  (R = {pm.R:g} mm, {pm.distribution})")
        print(f"lowest P     {pm.worst[2]:.4f} at ({pm.worst[0]:.1f}, {pm.worst[1]:.1f}) mm")
        print(f"branch       {pm.branch}")
        print("held         " + "; ".join(f"{k} = {math.degrees(v):g} deg ({w})" for k, (v, w) in pm.fixed.items()))
        print(f"time         {pm.elapsed_s:.2f} s")
        if args.out:
            print(f"figure       {args.out}")
    return 0


def _cmd_worst(args) -> int:
    from .cli import emit_json, parse_tolerances
    from .mechanism import load_model

    mech = load_model(args.model)
    eps = parse_tolerances(mech, args.tolerances)
    w = worst_pose(mech, eps, criterion=args.criterion, R=args.R, distribution=args.dist, grid=args.grid,
                   reference=args.reference if args.reference != "none" else None)
    if args.json:
        emit_json(w.to_dict())
    else:
        print(w.report(mech.joint_names))
    return 0


def register(sub) -> None:
    """Add ``tolsynth map`` and ``tolsynth worst-pose`` to the sub-command parser."""
    p = sub.add_parser("map", help="P(dr <= R) over the reachable part of a plane (the paper's Figure 3)")
    p.add_argument("--model", required=True, help="bundled model name or path to a .toml file")
    p.add_argument("--tolerances", default="figure3", help="SET | name=value,... | SET,name=value,...")
    p.add_argument("--dist", choices=["uniform", "normal"], default="uniform")
    p.add_argument("--R", type=float, default=0.2, help="radius of the accuracy sphere (mm)")
    p.add_argument("--n", type=int, default=100, help="grid points per axis")
    p.add_argument("--plane", choices=sorted(PLANES), default="xz")
    p.add_argument("--offset", type=float, default=0.0, help="offset of the plane along its normal (mm)")
    p.add_argument("--hand-axis", default="0,0,1", help="hand z axis in the base frame, or 'free'")
    p.add_argument("--extent", default=None, help="umin,umax,vmin,vmax (mm); default: the reachable box")
    p.add_argument("--out", default=None, help="figure file (.png, .pdf, ...)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_map)

    p = sub.add_parser("worst-pose", help="search the joint space for the pose of worst accuracy")
    p.add_argument("--model", required=True, help="bundled model name or path to a .toml file")
    p.add_argument("--tolerances", default="figure3", help="SET | name=value,... | SET,name=value,...")
    p.add_argument("--dist", choices=["uniform", "normal"], default="uniform")
    p.add_argument("--criterion", choices=["sigma", "probability"], default="sigma")
    p.add_argument("--R", type=float, default=None, help="radius (mm); needed for --criterion probability")
    p.add_argument("--grid", type=int, default=None, help="grid points per searched joint")
    p.add_argument("--reference", default="worst", help="configuration to report beside the result, or 'none'")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_worst)
