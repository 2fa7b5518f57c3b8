"""Validation of an optimum: the probability achieved, by Monte Carlo, against the ``p`` asked for.

:func:`validate` runs :func:`tolsynth.analysis.montecarlo.monte_carlo` at the optimum's tolerances and
compares the achieved ``P(|w_j| <= R)`` (the paper's Eq. 14/20) and ``P(|dr| <= R)`` with the
probability asked for, with confidence intervals.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from tolsynth.analysis.montecarlo import ANALYTIC, DEFAULT_BATCH, MonteCarloResult, monte_carlo
from tolsynth.analysis.montecarlo_result import ANALYTIC_TEXT
from tolsynth.checks import is_real
from tolsynth.errors import InputError, WorkspaceWarning
from tolsynth.kinematics.mechanism import as_mechanism
from tolsynth.probability.stats import check_probability
from tolsynth.tabular import Tabular

__all__ = ["ValidationResult", "validate", "WorkspaceCheck"]


@dataclass(frozen=True)
class ValidationResult(Tabular):
    """Probabilities achieved at a set of tolerances, by Monte Carlo, against the ``p`` asked for.

    Attributes
    ----------
    p : float
        Probability asked for (per principal component, the paper's Eq. 14/20).
    p_components, p_components_ci : ndarray
        Achieved ``P(|w_j| <= R)`` and interval.
    components_met : ndarray of bool
        Point estimate >= p.
    components_short : ndarray of bool
        Significantly short: the interval's upper end < p.
    p_sphere, p_sphere_ci : float, ndarray
        Achieved ``P(|dr| <= R)`` (the sphere is not the constraint of Eq. 20; it is reported so
        that the stricter reading can be judged).
    sphere_met : bool
    montecarlo : MonteCarloResult
        The full run (analytic values, kurtosis, ...).
    """

    p: float
    R: float
    distribution: str
    pose: Any
    tolerances: dict
    p_components: np.ndarray
    p_components_ci: np.ndarray
    p_components_analytic: np.ndarray
    components_met: np.ndarray
    components_short: np.ndarray
    p_sphere: float
    p_sphere_ci: np.ndarray
    p_sphere_analytic: float
    sphere_met: bool
    n: int
    seed: int
    montecarlo: MonteCarloResult
    #: with several poses (``pose=[...]``): every pose's result, this one (the worst) among them
    per_pose: tuple = field(default=(), repr=False)

    @property
    def met(self) -> bool:
        """All three components reach p (point estimates)."""
        return bool(np.all(self.components_met))

    def to_dict(self) -> dict:
        """Plain dict (arrays as lists) for JSON, with :attr:`met`."""
        out = {
            k: (v.tolist() if isinstance(v, np.ndarray) else v)
            for k, v in self.__dict__.items()
            if k not in ("montecarlo", "per_pose")
        }
        out["pose"] = self.pose if isinstance(self.pose, str) else np.asarray(self.pose).tolist()
        out["met"] = self.met
        if len(self.per_pose) > 1:
            out["per_pose"] = [{**v.to_dict(), "per_pose": None} for v in self.per_pose]
        return out

    def report(self) -> str:
        """Readable table: achieved probabilities with intervals against ``p`` and the analytic values."""
        pct = int(round(100 * self.montecarlo.confidence))
        analytic = "exact linear" if self.montecarlo.analytic == "exact" else "Gaussian"
        lines = [
            f"validation   p = {self.p:g} asked, R = {self.R:g} mm, {self.distribution}, n = {self.n}, seed = {self.seed}; "
            f"{analytic}: {ANALYTIC_TEXT[self.montecarlo.analytic]}"
        ]
        for j in range(3):
            lo, hi = self.p_components_ci[j]
            state = (
                "met" if self.components_met[j] else ("SHORT" if self.components_short[j] else "below p (within noise)")
            )
            lines.append(
                f"P(|w{j + 1}|<=R)  {self.p_components[j]:.5f} [{lo:.5f}, {hi:.5f}] ({pct}%)  {analytic} "
                f"{self.p_components_analytic[j]:.5f}  {state}"
            )
        lo, hi = self.p_sphere_ci
        lines.append(
            f"P(|dr|<=R)  {self.p_sphere:.5f} [{lo:.5f}, {hi:.5f}]  {analytic} {self.p_sphere_analytic:.5f}  "
            + ("met" if self.sphere_met else "below p (sphere is stricter than Eq. 20)")
        )
        if len(self.per_pose) > 1:
            lines[0] += f"; the worst of {len(self.per_pose)} poses shown ({_label(self)})"
            for v in self.per_pose:
                lines.append(
                    f"  pose {_label(v)}: lowest P(|w_j|<=R) {float(np.min(v.p_components)):.5f}, "
                    f"{'met' if v.met else 'NOT met'}"
                )
        return "\n".join(lines)


def _label(v: ValidationResult) -> str:
    """The pose of a validation as a person reads it: its name, else each joint in its own unit
    (a strut in mm), as its Monte Carlo run recorded it from the mechanism."""
    if isinstance(v.pose, str):
        return v.pose
    return v.montecarlo.pose_text or "(" + ", ".join(f"{math.degrees(x):.4g}" for x in np.ravel(v.pose)) + ") deg"


def _attr(obj, name):
    for o in (obj, getattr(obj, "spec", None), getattr(obj, "problem", None)):
        if o is not None and getattr(o, name, None) is not None:
            return getattr(o, name)
    return None


def _designed_poses(mechanism, obj):
    """The poses a result was designed at (its own, or its inner ``result``'s, specification): one
    pose, or a list of them; a pose named by a configuration keeps its name.  None for plain
    tolerances or an object that records no poses."""
    for o in (obj, getattr(obj, "result", None)):
        designed = getattr(getattr(o, "spec", None), "poses", None)
        if isinstance(designed, Mapping) and designed:
            break
    else:
        return None
    known = getattr(mechanism, "configurations", {})
    out = [
        label
        if label in known and np.array_equal(np.asarray(known[label], dtype=float), np.asarray(q, dtype=float))
        else q
        for label, q in designed.items()
    ]
    return out[0] if len(out) == 1 else out


def validate(
    mechanism,
    tolerances_or_result,
    R: float | None = None,
    p: float | None = None,
    distribution: str | None = None,
    pose=None,
    n: int = 1_000_000,
    seed: int = 0,
    batch: int = DEFAULT_BATCH,
    confidence: float = 0.95,
    progress=None,
    Phi: float | None = None,
    probability: str | None = None,
) -> ValidationResult:
    """Monte Carlo check of an optimum: the probability achieved against the ``p`` asked for.

    Parameters
    ----------
    mechanism : Mechanism
    tolerances_or_result : dict, array, str or object with a ``.tolerances`` dict
        The tolerances (tolerance units), e.g. the result of ``tolsynth.synthesize``.
    R : float
        Radius (mm).  If None, taken from ``result.R`` or ``result.spec.R`` when present.
    p : float
        Probability asked for, 0 < p < 1 (same fallback).
    distribution : str or dict, optional
        Same fallback; default "uniform".
    pose : str, array, or a list of them, optional
        Where to check.  Not given: for a result, every pose it was designed at (``result.spec.poses``);
        for plain tolerances, the pose a design is made at by default
        (:func:`tolsynth.analysis.design_pose.default_design_pose`: the model's ``worst``
        configuration, else the worst-pose search's pose).  Given, it is used as it is: a
        configuration name or a joint vector (rad; mm for a sliding joint); ``"worst"`` is read as
        ``synthesize`` reads it, the model's ``worst`` configuration, else its default design pose.
        With several poses each is run (seeds ``seed``, ``seed + 1``, ...) and the worst (lowest
        ``P(|w_j| <= R)`` against p) is returned, every pose's in ``per_pose``.
    n, seed, batch, confidence, progress
        As for :func:`monte_carlo`.
    Phi : float, optional
        Orientation half-angle (rad): the run then also samples the orientation probabilities
        (``montecarlo.p_orientation_components``, ``montecarlo.p_cone``).
    probability : {"gaussian", "exact"}, optional
        The reading of the linear model the analytic column is in (:func:`monte_carlo`'s
        ``analytic``).  Not given: the design's own (``result.probability_kind``: exact
        probabilities for an exact design), else the Gaussian one for plain tolerances.

    Returns
    -------
    ValidationResult

    Examples
    --------
    >>> import tolsynth
    >>> m = tolsynth.load_model("xu_zhang_1988")
    >>> v = tolsynth.validate(m, "figure3", R=0.5, p=0.9, n=100_000, seed=3)
    >>> v.p_components.shape
    (3,)
    """
    tol = tolerances_or_result
    if probability is None:  # a design is compared with the linear model in its own reading
        kind = getattr(tol, "probability_kind", None) if not isinstance(tol, (str, Mapping)) else None
        probability = "exact" if kind == "exact" else "gaussian"
    elif not isinstance(probability, str) or probability not in ANALYTIC:
        raise InputError("probability", f"got {probability!r}", " or ".join(repr(a) for a in ANALYTIC))
    if not isinstance(tol, (str, Mapping, np.ndarray, list, tuple)) and hasattr(tol, "tolerances"):
        R = R if R is not None else _attr(tol, "R")
        p = p if p is not None else _attr(tol, "p")
        distribution = distribution if distribution is not None else _attr(tol, "distribution")
        tol = tol.tolerances
    if R is None:
        raise InputError("R", "no radius given", "a finite number > 0 (mm)")
    if p is None:
        raise InputError("p", "no probability given", "0 < p < 1")
    p = check_probability(p, "p")
    mechanism = as_mechanism(mechanism)  # a model name too; anything else an InputError naming it
    if pose is None:
        pose = _designed_poses(mechanism, tolerances_or_result)
    if pose is None or (isinstance(pose, str) and pose == "worst"):
        from tolsynth.analysis.design_pose import default_design_pose

        pose = default_design_pose(mechanism)[0]
    if isinstance(pose, list) and pose and not all(is_real(v) for v in pose):
        runs = [
            validate(mechanism, tol, R, p, distribution, q, n, seed + k, batch, confidence, progress, Phi, probability)
            for k, q in enumerate(pose)
        ]
        worst = min(runs, key=lambda v: float(np.min(v.p_components)) - v.p)
        from dataclasses import replace

        return replace(worst, per_pose=tuple(runs))
    # distribution None: the model's own shapes, as everywhere
    mc = monte_carlo(
        mechanism,
        pose,
        tol,
        distribution,
        R=R,
        n=n,
        seed=seed,
        batch=batch,
        confidence=confidence,
        progress=progress,
        Phi=Phi,
        analytic=probability,
    )
    return ValidationResult(
        p=p,
        R=mc.R,
        distribution=mc.distribution,
        pose=pose,
        tolerances=mc.tolerances,
        p_components=mc.p_components,
        p_components_ci=mc.p_components_ci,
        p_components_analytic=mc.p_components_analytic,
        components_met=mc.p_components >= p,
        components_short=mc.p_components_ci[:, 1] < p,
        p_sphere=mc.p_sphere,
        p_sphere_ci=mc.p_sphere_ci,
        p_sphere_analytic=mc.p_sphere_analytic,
        sphere_met=bool(mc.p_sphere >= p),
        n=mc.n,
        seed=mc.seed,
        montecarlo=mc,
    )


# ---------------------------------------------------------------------------------------------
# how a design made at some poses does over the workspace: a quick sampled check
# ---------------------------------------------------------------------------------------------
class WorkspaceCheck:
    """The largest constraint value of a design over ``n`` joint configurations drawn uniformly
    inside the joint limits (and joint constraints), seed ``seed``: ``sigma_1 z / R`` (the
    per-component criterion) or ``(1 - P) / (1 - p)`` with ``P = P(|dr| <= R)`` (the sphere), in the
    linear Gaussian model (:mod:`tolsynth.kinematics.batch_stats`).  A design made for the exact
    probabilities is checked in them, ``(1 - P) / (1 - p)`` with ``P`` the smallest exact
    probability over directions (or in the sphere), at the :attr:`EXACT` sampled poses of largest
    Gaussian value (where the two differ, the Gaussian value would report a pose as over that the
    exact probabilities pass, or the other way round).  A worst-case design
    (``probability="worst_case"``) is checked in its own quantity, the largest worst-case
    ``|dr| / R`` over every error in its band (with Phi, ``max(|dr| / R, |dphi| / Phi)``: the
    zonotope maximum of :func:`tolsynth.analysis.worst_case_pose.worst_case_at`) at every sampled
    pose.  Not a certificate (a sample can miss the worst pose; :func:`tolsynth.synthesize_workspace`
    designs for every pose and certifies it); a value above 1 is a pose where the design is over
    its specification.

    Computed when first read (:attr:`worst`, :meth:`line`, :meth:`to_dict`; reports and the
    command line's ``solve`` read it), not by ``synthesize`` itself nor by ``result.summary()``,
    which shows it once computed; it then warns (:class:`tolsynth.errors.WorkspaceWarning`) if the
    largest value exceeds ``1 + WARN``.  The same answer every time (a fixed seed).
    """

    N = 300
    SEED = 0
    WARN = 1e-3
    #: how many sampled poses an exact-probability design is checked at (each ~0.1-0.3 s)
    EXACT = 5

    def __init__(self, mechanism, result, distribution=None, n: int = N, seed: int = SEED):
        self.mechanism, self.result, self.distribution = mechanism, result, distribution
        self.n, self.seed = int(n), int(seed)
        self._value = None

    def _samples(self) -> np.ndarray:
        from tolsynth.kinematics.joint_space import _feasible, _limits

        lo, hi = _limits(self.mechanism)
        rng = np.random.default_rng(self.seed)
        got, tries = [], 0
        while sum(q.shape[1] for q in got) < self.n and tries < 20:
            Q = lo[:, None] + (hi - lo)[:, None] * rng.random((len(lo), self.n))
            got.append(Q[:, _feasible(self.mechanism, Q)])
            tries += 1
        return np.concatenate(got, axis=1)[:, : self.n]

    def _compute(self) -> tuple[float, np.ndarray | None, int]:
        if self._value is not None:
            return self._value
        from tolsynth.kinematics.batch_stats import principal_std_batch

        spec = self.result.spec
        Q = self._samples()
        worst, q = math.nan, None
        if Q.shape[1] and self.worst_case:
            from tolsynth.analysis.worst_case_pose import worst_case_at

            eps = self.result.x
            vals = np.array([worst_case_at(self.mechanism, q_, eps, spec.R, spec.Phi) for q_ in Q.T])
        elif Q.shape[1]:
            sig = principal_std_batch(self.mechanism, Q, self.result.x, self.distribution)
            if spec.sphere_blocks:
                from tolsynth.probability.stats import p_ball

                P = np.array([p_ball(np.square(s), spec.R) if np.all(np.isfinite(s)) else np.nan for s in sig])
                vals = (1.0 - P) / (1.0 - spec.p)
            else:
                vals = sig[:, 0] * spec.z / spec.R
            if self.exact and np.any(np.isfinite(vals)):
                vals = self._exact_values(Q, vals)
        if Q.shape[1] and np.any(np.isfinite(vals)):
            k = int(np.nanargmax(vals))
            worst, q = float(vals[k]), Q[:, k]
        self._value = (worst, q, int(Q.shape[1]))
        if self.exceeds:
            warnings.warn(WorkspaceWarning(self.line()), stacklevel=3)
        return self._value

    @property
    def computed(self) -> bool:
        """Whether the sample has been evaluated (reading any value evaluates it once)."""
        return self._value is not None

    @property
    def exact(self) -> bool:
        """The design was made for the exact probabilities, and is checked in them."""
        return getattr(self.result, "probability_kind", "gaussian") == "exact"

    @property
    def worst_case(self) -> bool:
        """The design was made for the worst case, and is checked in it (no probability)."""
        return getattr(self.result, "probability_kind", "gaussian") == "worst_case"

    def _exact_values(self, Q: np.ndarray, gaussian: np.ndarray) -> np.ndarray:
        """``(1 - P) / (1 - p)`` in the exact probabilities.  Per component: every sampled pose
        screened (principal axes, bisectors and a lattice of directions, one batch), then the EXACT
        poses of largest screened value searched over all directions; the sphere: at the EXACT
        poses of largest Gaussian value (NaN elsewhere, and where the exact evaluation fails).  The
        Gaussian ranking alone missed the exact worst pose: its order is not the exact one."""
        from tolsynth.probability.exact import ExactProbabilityError, worst_direction
        from tolsynth.probability.exact_sphere import ball_probability

        spec, eps = self.result.spec, self.result.x
        out = np.full(len(gaussian), np.nan)
        rank = gaussian
        if not spec.sphere_blocks:
            from tolsynth.analysis.exact_pose_search import _position_sensitivities, screen_directions

            ok = np.flatnonzero(np.isfinite(gaussian))
            M = _position_sensitivities(self.mechanism, Q[:, ok]) * eps
            good = np.all(np.isfinite(M), axis=(1, 2))
            ok, M = ok[good], M[good]
            if ok.size:
                out[ok] = (1.0 - screen_directions(M, spec.shapes, spec.R)[1]) / (1.0 - spec.p)
            rank = out
        order = np.argsort(np.where(np.isfinite(rank), rank, -np.inf))[::-1][: self.EXACT]
        for k in order:
            A = np.asarray(self.mechanism.sensitivity(Q[:, k], check_limits=False))[:3]
            try:
                if spec.sphere_blocks:
                    P = ball_probability(A, eps, spec.shapes, spec.R)
                else:
                    P = worst_direction(A, eps, spec.shapes, spec.R, grid=100, local=2)[1]
            except ExactProbabilityError:
                continue
            out[k] = np.fmax(out[k], (1.0 - P) / (1.0 - spec.p))  # the screen's value where it is the larger
        return out

    @property
    def worst(self) -> float:
        """The largest constraint value over the sample (NaN if no sampled pose could be evaluated)."""
        return self._compute()[0]

    @property
    def q(self):
        """The sampled joint vector (rad) where it is reached."""
        return self._compute()[1]

    @property
    def n_poses(self) -> int:
        return self._compute()[2]

    @property
    def exceeds(self) -> bool:
        """The design is over its specification somewhere in the sample (by more than WARN)."""
        return bool(self._compute()[0] > 1.0 + self.WARN)

    def line(self) -> str:
        """One line for summaries and the command line."""
        worst, q, n = self._compute()
        sphere = bool(self.result.spec.sphere_blocks)
        if self.worst_case:
            ori = self.result.spec.Phi is not None
            what = "worst-case " + ("max(|dr|/R, |dphi|/Phi)" if ori else "|dr|/R")
            how = f"{n} sampled poses, every error anywhere in its band"
        elif self.exact:
            what = "exact (1-P)/(1-p) " + ("in the sphere" if sphere else "along the worst direction")
            how = (
                f"{n} sampled poses, exact probabilities at the {self.EXACT} of largest Gaussian value"
                if sphere
                else f"{n} sampled poses screened in exact probabilities, the {self.EXACT} lowest searched"
            )
        else:
            what, how = ("(1-P)/(1-p) in the sphere" if sphere else "sigma z/R"), f"{n} sampled poses, Gaussian"
        if not math.isfinite(worst):
            return f"workspace check: no sampled pose could be evaluated ({n} drawn)"
        where = self.mechanism.format_joints(q)
        text = f"workspace check ({how}): largest {what} {worst:.4f} at q = {where}"
        if worst > 1.0 + self.WARN:
            return (
                text + f": {100 * (worst - 1):.3g} % over the specification there; the design meets it only at "
                "the poses it was made for (tolsynth.synthesize_workspace, or solve --everywhere, designs for "
                "every pose)"
            )
        if self.exact and not sphere:
            checked = f"every sampled pose (a screen of directions; the {self.EXACT} lowest searched over all)"
        else:
            checked = f"each of the {self.EXACT} poses checked" if self.exact else "every sampled pose"
        within = (
            f"within the tolerance {self.WARN:g} of the specification ({worst - 1:.1e} over 1)"
            if worst > 1.0
            else "within the specification"
        )
        return text + f": {within} at {checked} (a sample, not a proof)"

    def to_dict(self) -> dict:
        """Plain dict for JSON: the largest value (None where no sampled pose could be evaluated),
        its pose (the key naming its unit: :func:`tolsynth.units.joint_values`), the sample, and the
        verdict in words (:meth:`line`)."""
        from tolsynth.units import joint_values

        worst, q, n = self._compute()
        return {
            "worst": worst if math.isfinite(worst) else None,
            "line": self.line(),
            **joint_values(None if q is None else np.asarray(q).tolist(), self.mechanism.joint_value_units),
            "n_poses": n,
            "exceeds": self.exceeds,
            "seed": self.seed,
            "probabilities": "worst_case" if self.worst_case else "exact" if self.exact else "gaussian",
        }
