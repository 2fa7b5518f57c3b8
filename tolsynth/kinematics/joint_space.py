"""Joint-space helpers shared by the pose search and the workspace map: joint limits, joint
constraints (the interference limit), wrapping of revolute joints, the distance to the limits,
and the resolution of a reference configuration.  Units: rad.
"""

from __future__ import annotations

import math

import numpy as np

from tolsynth.errors import OutOfRangeError, UnknownNameError

__all__ = ["MODEL_REFERENCE", "model_reference", "tangent_directions", "hold_fixed", "scaled_joints"]


class _ModelReference:
    """Default of ``reference=``: the model's own reference pose (see :func:`model_reference`)."""

    _instance = None

    def __new__(cls):
        if cls._instance is None:
            cls._instance = super().__new__(cls)
        return cls._instance

    def __repr__(self) -> str:
        return "MODEL_REFERENCE"

    def __reduce__(self):
        return (_ModelReference, ())


#: ``reference=MODEL_REFERENCE`` (the default): the model's reference pose, or none if it has none
MODEL_REFERENCE = _ModelReference()


#: the joint-space pattern searches (worst pose, exact worst pose): successes in a row at one step
#: size that double it (up to the first step).  A step only ever halved crept along a ridge of tiny
#: gains for millions of polls (puma560's single-pose design, step_tol 1e-7); doubling at every
#: success made the exchanges' searches twice as long
STREAK = 4


def model_reference(mech) -> str | None:
    """The model's reference pose: the configuration its file names as ``reference`` (when the
    format has that field), else its configuration ``worst`` (the paper's pose of largest error),
    else None -- a model without one works everywhere, with no pose marked or compared.  It is what
    searches and maps compare with; the pose a design is made at without one given is
    :func:`tolsynth.analysis.design_pose.default_design_pose`."""
    name = getattr(mech.spec, "reference", None)
    if isinstance(name, str) and name in mech.configurations:
        return name
    return "worst" if "worst" in mech.configurations else None


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
    slides = mech.spec.length_joints  # a slide moved by 2 pi mm is another pose
    for j, name in enumerate(mech.joint_names):
        if name in slides:
            continue
        v = Q[j]
        k = np.ceil((lo[j] - v) / (2 * math.pi))  # smallest shift that reaches the lower limit
        w = v + 2 * math.pi * k
        Q[j] = np.where(w <= hi[j], w, v)
    return Q


def _reference(mech, reference) -> tuple[str | None, np.ndarray | None]:
    """``(name, joints)`` of a reference: ``MODEL_REFERENCE``, None, a configuration name or
    joint values (rad); the name is ``"given"`` for joint values, None for no reference."""
    if reference is MODEL_REFERENCE:
        reference = model_reference(mech)
    if reference is None:
        return None, None
    if isinstance(reference, str):
        if reference not in mech.configurations:
            raise UnknownNameError(
                "reference", f"unknown configuration {reference!r}", "one of " + ", ".join(mech.configurations)
            )
        return reference, mech.joints(reference)
    return "given", mech.joints(reference)


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


def tangent_directions(mech, free: list[int], scale: np.ndarray) -> np.ndarray:
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


def hold_fixed(mech, fixed: dict, lo: np.ndarray, hi: np.ndarray, held: dict) -> None:
    """Add the joints of ``fixed`` (name -> value, rad; checked numbers) to ``held`` (index ->
    value), each inside its limits."""
    from tolsynth.errors import OutOfRangeError, UnknownNameError

    names = list(mech.joint_names)
    for name, v in fixed.items():
        if name not in names:
            raise UnknownNameError("fixed", f"unknown joint {name!r}", "one of " + ", ".join(names))
        j = names.index(name)
        if not lo[j] <= float(v) <= hi[j]:
            raise OutOfRangeError(
                f"fixed[{name}]", f"{math.degrees(v):g} deg", f"{math.degrees(lo[j]):g} to {math.degrees(hi[j]):g} deg"
            )
        held[j] = float(v)


def scaled_joints(U: np.ndarray, held: dict, free: list, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Joint vectors (nq, N) from coordinates ``U`` (k, N) scaled to [0, 1] over the free joints'
    limits (the limit itself at 1, not a rounding below it), the held joints at their values."""
    Q = np.empty((len(lo), U.shape[1]))
    for j, v in held.items():
        Q[j] = v
    for i, j in enumerate(free):
        Q[j] = np.where(U[i] >= 1.0, hi[j], lo[j] + (hi[j] - lo[j]) * U[i])
    return Q


def grid_and_compass(mech, evaluate, free, lo, hi, grid, max_grid_points, starts, step_tol, max_points, grid_tol):
    """The worst-pose search over the ``free`` joints, scaled to [0, 1]: a coarse grid, then from
    the ``starts`` best, mutually separated grid points a generating-set search (compass search
    with complete polling, tangents of the linear joint constraints among its directions, the step
    halved on failure down to ``step_tol``, doubled after a run of successes).  ``evaluate(U,
    tol)`` gives the values to maximise at the columns of U (-inf where infeasible; ``tol`` the
    error allowed, ``grid_tol`` on the grid).  Returns ``(best_u, grid points per joint, feasible
    grid points, starts)``."""
    k = len(free)
    # (2) coarse grid
    if k == 0:
        U = np.zeros((0, 1))
        vals = evaluate(U)
        g = 1
    else:
        g = int(grid) if grid is not None else max(5, int(math.floor(max_grid_points ** (1.0 / k))))
        if g < 2:
            raise OutOfRangeError("grid", f"got {grid}", "an integer >= 2")
        if g**k > max_points:
            raise OutOfRangeError(
                "grid",
                f"{g}**{k} searched joints = {g**k} points",
                f"at most {max_points} points (grid <= {int(max_points ** (1 / k))})",
            )
        axes = [np.linspace(0.0, 1.0, g)] * k
        U = np.array([a.ravel() for a in np.meshgrid(*axes, indexing="ij")])
        vals = evaluate(U, grid_tol)  # the grid only ranks the starts
    feasible = np.isfinite(vals)
    if not np.any(feasible):
        raise OutOfRangeError(
            "joint limits",
            "no grid point satisfies every joint limit and constraint",
            "a non-empty feasible joint space",
        )
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
        D = tangent_directions(mech, free, hi[free] - lo[free])
        X = U[:, picked].copy()  # (k, S)
        F = vals[picked].copy()
        h = np.full(len(picked), 0.5 * h0)
        streak = np.zeros(len(picked), dtype=int)
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
                    streak[s] += 1
                    if streak[s] >= STREAK:  # a run of successes doubles the step: no creep along a ridge
                        h[s], streak[s] = min(2.0 * h[s], 0.5 * h0), 0
                else:
                    h[s] *= 0.5
                    streak[s] = 0
        b = int(np.argmax(F))
        best_u = X[:, b]
    return best_u, g, n_grid, len(picked)
