"""Contributor report: which parameter makes the error.

At tolerances ``eps`` the hand-position covariance is ``V = sum_i eps_i^2 a_i a_i^T / c`` (``a_i``
the position sensitivity of parameter i, ``c`` = 3 uniform, 9 normal).  Along a principal
direction ``d_j`` the variance ``sigma_j^2 = d_j^T V d_j = sum_i eps_i^2 (a_i . d_j)^2 / c`` is a
sum of one term per parameter, so each parameter's *share* of each principal variance is exact
(the shares add up to 1), and so is its share of the total variance ``tr V``.
Where principal variances coincide (at the paper's optimum two are active and equal) the principal
directions within that eigenspace are arbitrary, and so is the split of the shares between them;
their sum over the eigenspace is well defined.

The sphere probability's loss ``1 - P(|dr| <= R)`` is not additive; its shares are the normalised
elasticities ``d(1 - P)/d ln eps_i`` (first-order attribution: the share of the loss removed by
tightening all tolerances by the same small fraction), computed on the CasADi graph of
:func:`tolsynth.problem.nlp.sphere_graph` (exact derivatives).

>>> import tolsynth
>>> m = tolsynth.load_model("xu_zhang_1988")
>>> res = tolsynth.synthesize(m, R=0.5, p=0.99)
>>> report = tolsynth.contributions(res)
>>> round(float(report.shares[0].sum(axis=0)[0]), 12)
1.0
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from tolsynth.errors import InputError

__all__ = ["contributions", "Contributions", "StackUp"]


def _frame(rows: list[dict]):
    """``rows`` as a pandas DataFrame where pandas is installed (an optional extra), else as they are."""
    try:
        import pandas as pd
    except ImportError:
        return rows
    return pd.DataFrame(rows)


@dataclass(frozen=True)
class Contributions:
    """Each parameter's share of the error at one set of tolerances, per pose.

    Attributes
    ----------
    names, units : tuple of str
        Parameters and their tolerance units.
    tolerances : ndarray
        ``eps_i`` (tolerance units).
    poses : tuple of str
        Pose labels.
    sigma : ndarray, (m, 3)
        Principal standard deviations of the hand position (mm), descending, per pose.
    directions : ndarray, (m, 3, 3)
        Principal directions (columns, base frame).
    shares : ndarray, (m, n, 3)
        ``shares[b, i, j]``: parameter i's share of principal variance j at pose b (columns sum to 1).
    total_share : ndarray, (m, n)
        Share of the total variance ``tr V``.
    sphere_share : ndarray (m, n) or None
        Share of the sphere probability's loss ``1 - P(|dr| <= R)`` (normalised elasticities),
        when ``R`` is known.
    P_sphere : ndarray (m,) or None
        ``P(|dr| <= R)`` per pose (the graph's quadrature).
    R : float or None
        mm.
    """

    names: tuple
    units: tuple
    tolerances: np.ndarray
    poses: tuple
    sigma: np.ndarray
    directions: np.ndarray
    shares: np.ndarray
    total_share: np.ndarray
    sphere_share: np.ndarray | None = None
    P_sphere: np.ndarray | None = None
    R: float | None = None

    def rows(self) -> list[dict]:
        """One dict per (pose, parameter): the table as plain data."""
        out = []
        for b, pose in enumerate(self.poses):
            for i, name in enumerate(self.names):
                row = {
                    "pose": pose,
                    "parameter": name,
                    "unit": self.units[i],
                    "tolerance": float(self.tolerances[i]),
                    "share_sigma1": float(self.shares[b, i, 0]),
                    "share_sigma2": float(self.shares[b, i, 1]),
                    "share_sigma3": float(self.shares[b, i, 2]),
                    "share_total": float(self.total_share[b, i]),
                }
                if self.sphere_share is not None:
                    row["share_sphere_loss"] = float(self.sphere_share[b, i])
                out.append(row)
        return out

    def table(self):
        """A pandas DataFrame of :meth:`rows` if pandas is installed, else the list of dicts."""
        return _frame(self.rows())

    def ranking(self, pose: int = 0) -> list[str]:
        """Parameters by decreasing share of the largest principal variance at one pose."""
        return [self.names[i] for i in np.argsort(-self.shares[pose, :, 0], kind="stable")]

    def format(self) -> str:
        """Readable table per pose: principal sigma, then each parameter's shares in %, largest first."""
        lines = []
        for b, pose in enumerate(self.poses):
            s = ", ".join(f"{v:.4g}" for v in self.sigma[b])
            lines.append(
                f"pose {pose}: principal sigma ({s}) mm"
                + (f", P(|dr| <= {self.R:g}) = {self.P_sphere[b]:.6f}" if self.P_sphere is not None else "")
            )
            head = (
                f"  {'parameter':>10} {'tolerance':>19} {'sigma1 %':>9} {'sigma2 %':>9} {'sigma3 %':>9} {'total %':>8}"
            )
            lines.append(head + (f" {'1-P %':>7}" if self.sphere_share is not None else ""))
            for i in np.argsort(-self.shares[b, :, 0], kind="stable"):
                row = (
                    f"  {self.names[i]:>10} {self.tolerances[i]:>9.4g} {self.units[i]:<9}"
                    + " ".join(f"{100 * v:>9.2f}" for v in self.shares[b, i])
                    + f" {100 * self.total_share[b, i]:>8.2f}"
                )
                if self.sphere_share is not None:
                    row += f" {100 * self.sphere_share[b, i]:>7.2f}"
                lines.append(row)
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.format()

    def plot(self, pose: int = 0, ax=None):
        """Grouped bar chart of the shares at one pose (matplotlib, imported lazily)."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, ax = plt.subplots(figsize=(max(5.0, 0.7 * len(self.names)), 3.2))
        series = [(f"sigma{j + 1}^2", self.shares[pose, :, j]) for j in range(3)]
        if self.sphere_share is not None:
            series.append(("1 - P(sphere)", self.sphere_share[pose]))
        x = np.arange(len(self.names))
        width = 0.8 / len(series)
        for s, (label, vals) in enumerate(series):
            ax.bar(x + (s - (len(series) - 1) / 2) * width, 100 * vals, width, label=label)
        ax.set_xticks(x, self.names)
        ax.set_ylabel("share, %")
        ax.set_title(f"contributions at pose {self.poses[pose]}")
        ax.legend(fontsize="small")
        return ax

    def to_dict(self) -> dict:
        """Plain dict (R, poses, sigma, :meth:`rows`) for JSON."""
        return {"R": self.R, "poses": list(self.poses), "sigma": self.sigma.tolist(), "rows": self.rows()}


@dataclass(frozen=True)
class StackUp:
    """A worst-case design's contributions: at each pose, the terms ``|u . a_i| eps_i`` (mm) of the
    arithmetic stack-up along the direction ``u`` of the farthest point of the error zonotope; they
    add up to the largest hand error ``h`` over every error in its band.

    Attributes: ``names``, ``units``, ``tolerances``, ``poses`` as :class:`Contributions`;
    ``terms`` (m, n) mm; ``directions`` (m, 3) the unit u per pose; ``worst`` (m,) h in mm;
    ``R`` mm."""

    names: tuple
    units: tuple
    tolerances: np.ndarray
    poses: tuple
    terms: np.ndarray
    directions: np.ndarray
    worst: np.ndarray
    R: float | None = None

    def rows(self) -> list[dict]:
        """One dict per (pose, parameter): its term (mm) and its share of the worst case."""
        return [
            {
                "pose": pose,
                "parameter": name,
                "unit": self.units[i],
                "tolerance": float(self.tolerances[i]),
                "term_mm": float(self.terms[b, i]),
                "share_worst_case": float(self.terms[b, i] / self.worst[b]) if self.worst[b] > 0 else 0.0,
            }
            for b, pose in enumerate(self.poses)
            for i, name in enumerate(self.names)
        ]

    def table(self):
        """A pandas DataFrame of :meth:`rows` if pandas is installed, else the list of dicts."""
        return _frame(self.rows())

    def ranking(self, pose: int = 0) -> list[str]:
        """Parameters by decreasing term at one pose."""
        return [self.names[i] for i in np.argsort(-self.terms[pose], kind="stable")]

    def format(self) -> str:
        """Readable table per pose: the worst case and its direction, then each term, largest first."""
        lines = []
        for b, pose in enumerate(self.poses):
            d = ", ".join(f"{v:.4f}" for v in self.directions[b])
            lines.append(
                f"pose {pose}: worst case |dr| = {self.worst[b]:.6g} mm"
                + (f" = {self.worst[b] / self.R:.6f} R" if self.R else "")
                + f" along ({d})"
            )
            lines.append(f"  {'parameter':>10} {'tolerance':>19} {'term mm':>11} {'share %':>8}")
            for i in np.argsort(-self.terms[b], kind="stable"):
                share = 100 * self.terms[b, i] / self.worst[b] if self.worst[b] > 0 else 0.0
                lines.append(
                    f"  {self.names[i]:>10} {self.tolerances[i]:>9.4g} {self.units[i]:<9}"
                    f" {self.terms[b, i]:>11.5g} {share:>8.2f}"
                )
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.format()

    def to_dict(self) -> dict:
        """Plain dict (R, poses, worst, directions, :meth:`rows`) for JSON."""
        return {
            "R": self.R,
            "poses": list(self.poses),
            "worst_case_mm": self.worst.tolist(),
            "directions": self.directions.tolist(),
            "rows": self.rows(),
        }


def _stack_up(source, mats, distribution, R) -> StackUp:
    """The worst-case design's terms at each pose (:class:`StackUp`): the direction of the farthest
    point of the zonotope (:func:`tolsynth.solvers.worst_case_zonotope.zonotope_max`), where each
    error sits at the end of its band that moves the hand along it."""
    from tolsynth.solvers.worst_case_zonotope import zonotope_max

    if distribution is not None:  # no shape enters the worst case
        raise InputError(
            "distribution",
            f"{distribution!r} with a worst-case result (every error anywhere in its band, whatever its shape)",
            "no distribution",
        )
    eps = np.asarray(source.x, dtype=float)
    terms, dirs, worst = [], [], []
    for _, A in mats:
        C = np.asarray(A, dtype=float) * eps
        h, _, u = zonotope_max(C)
        terms.append(np.abs(u @ C))
        dirs.append(u)
        worst.append(h)
    names = tuple(source.tolerances)
    return StackUp(
        names,
        tuple(source.units[nm] for nm in names),
        eps,
        tuple(p for p, _ in mats),
        np.array(terms),
        np.array(dirs),
        np.array(worst),
        source.spec.R if R is None else R,
    )


def _position_rows(spec) -> list[tuple[str, np.ndarray]]:
    """(pose label, 3 x n position sensitivity) from a specification's blocks."""
    out, seen = [], set()
    for block in tuple(getattr(spec, "blocks", ())) + tuple(getattr(spec, "sphere_blocks", ())):
        if getattr(block, "kind", "position") in ("position", "sphere") and block.pose not in seen:
            seen.add(block.pose)
            # the blocks hold A scaled for a per-parameter distribution (Specification.col_scale)
            out.append((block.pose, np.asarray(block.A, dtype=float) / getattr(spec, "col_scale", 1.0)))
    return out


def contributions(
    source, tolerances=None, *, pose=None, poses=None, distribution=None, R=None, mechanism=None
) -> Contributions:
    """Each parameter's share of each principal variance (and of the sphere probability's loss).

    Parameters
    ----------
    source : SynthesisResult, Mechanism or str
        A result (its tolerances, poses, distribution and R are used), or a mechanism / model name
        with ``tolerances``.
    tolerances : dict, sequence or str, optional
        For a mechanism: the tolerances (tolerance units), as accepted by
        :meth:`Mechanism.tolerances`.
    pose, poses : optional
        For a mechanism: the pose(s) (default the model's design pose, the one
        :func:`tolsynth.synthesize` takes: :func:`tolsynth.analysis.design_pose.default_design_pose`);
        for a result, ``mechanism`` with ``poses`` overrides the result's poses.
    distribution : str or dict, optional
        As :func:`tolsynth.synthesize`.
        Default: the result's, or ``"uniform"``.
    R : float, optional
        mm; adds the sphere loss shares (default: the result's R).
    mechanism : Mechanism, optional
        With a result: evaluate the sensitivities at ``poses`` on it instead of the result's poses.

    Returns
    -------
    Contributions, or for a worst-case result (``probability="worst_case"``) :class:`StackUp`: the
    terms ``|u . a_i| eps_i`` of the arithmetic stack-up along the direction u of the largest error,
    which add up to it (no variance and no distribution enter there).
    """
    from tolsynth.analysis.design_pose import resolve_design_pose
    from tolsynth.kinematics.mechanism import Mechanism, as_mechanism
    from tolsynth.probability.stats import check_positive, principal, variance_divisor
    from tolsynth.problem.result import SynthesisResult

    if not isinstance(source, (SynthesisResult, Mechanism, str, os.PathLike)):
        raise InputError(
            "source",
            f"got {type(source).__name__}",
            "a SynthesisResult, or a Mechanism / model name / path followed by its tolerances: "
            "contributions(mechanism, tolerances)",
        )
    if mechanism is not None and not isinstance(mechanism, Mechanism):
        raise InputError("mechanism", f"got {type(mechanism).__name__}", "a Mechanism (with a result and poses)")
    if isinstance(source, SynthesisResult):
        spec = source.spec
        names = tuple(source.tolerances)
        units = tuple(source.units[nm] for nm in names)
        eps = source.x
        worst_case = (source.inputs or {}).get("probability") == "worst_case"
        distribution = distribution if worst_case else distribution or spec.distribution
        R = spec.R if R is None else R
        if mechanism is not None and poses is not None:
            mats = [
                (str(i) if not isinstance(q, str) else q, mechanism.sensitivity(q, check_limits=False)[:3])
                for i, q in enumerate(poses)
            ]
        else:
            mats = _position_rows(spec)
            if not mats:
                raise InputError(
                    "source",
                    "the result has no position constraint to attribute",
                    "a result with a position specification, or a mechanism and poses",
                )
        if worst_case:
            return _stack_up(source, mats, distribution, R)
    else:
        mech = as_mechanism(source, "source")
        if tolerances is None:
            raise InputError("tolerances", "missing", "the tolerances to analyse (name -> value, or a list)")
        eps = mech.tolerances(tolerances)
        names, units = tuple(mech.error_parameters), tuple(mech.units)
        from tolsynth.probability.distributions import resolve

        distribution = resolve(distribution, mech)
        # no pose given: the design pose a design of this model is made at (one rule, design_pose.py)
        pose, _ = resolve_design_pose(mech, pose, poses)
        plist = list(poses) if poses is not None else [pose]
        mats = [
            (_pose_label(mech, q, i, poses), mech.sensitivity(mech.joints(q), check_limits=False)[:3])
            for i, q in enumerate(plist)
        ]
    c = variance_divisor(distribution, names)
    if np.ndim(c):  # per-parameter divisors: scale the columns to one divisor (3)
        mats = [(lbl, A * np.sqrt(3.0 / c)) for lbl, A in mats]
        c = 3.0
    if R is not None:
        R = check_positive(R, "R")
    y = np.asarray(eps, dtype=float) ** 2 / c
    m, n = len(mats), len(names)
    sigma, dirs = np.zeros((m, 3)), np.zeros((m, 3, 3))
    shares, total = np.zeros((m, n, 3)), np.zeros((m, n))
    sphere, Pb = (np.zeros((m, n)), np.zeros(m)) if R is not None else (None, None)
    for b, (_, A) in enumerate(mats):
        V = (A * y) @ A.T
        sig, d = principal(V)
        sigma[b], dirs[b] = sig, d
        proj = (d.T @ A) ** 2 * y  # 3 x n: the terms of d_j^T V d_j
        with np.errstate(divide="ignore", invalid="ignore"):
            shares[b] = np.where(proj.sum(axis=1, keepdims=True) > 0, proj / proj.sum(axis=1, keepdims=True), 0.0).T
        col = (A**2).sum(axis=0) * y
        total[b] = col / col.sum() if col.sum() > 0 else 0.0
        if R is not None:
            sphere[b], Pb[b] = _sphere_shares(A, eps, c, R)
    return Contributions(
        names, units, np.asarray(eps, dtype=float), tuple(p for p, _ in mats), sigma, dirs, shares, total, sphere, Pb, R
    )


def _pose_label(mech, q, i: int, poses) -> str:
    """A configuration's name; a joint vector of a list by its place, the design pose by its values."""
    if isinstance(q, str):
        return q
    return f"#{i}" if poses is not None else mech.format_joints(q)


def _sphere_shares(A: np.ndarray, eps: np.ndarray, c: float, R: float) -> tuple[np.ndarray, float]:
    """Normalised elasticities of ``1 - P(|dr| <= R)`` in ``ln eps_i`` (CasADi, exact derivatives)."""
    import casadi as ca

    from tolsynth.problem.nlp import sphere_graph

    n = len(eps)
    g = sphere_graph(n, 1)
    u = ca.SX.sym("u", n)
    Ps = ca.SX.sym("Ps", 1 + 1 + 3 * n)
    P = g(u, Ps)
    grad = ca.Function("sphere_grad", [u, Ps], [P, ca.gradient(P, u)])
    val, gr = grad(np.log(eps), np.concatenate([[c, R], A.ravel(order="F")]))
    loss = -np.array(gr).ravel()  # d(1 - P)/d ln eps_i >= 0
    s = loss.sum()
    return (loss / s if s > 0 else np.zeros(n)), float(val)
