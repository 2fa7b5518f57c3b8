"""Validation of an optimum: the probability achieved, by Monte Carlo, against the ``p`` asked for.

:func:`validate` runs :func:`tolsynth.analysis.montecarlo.monte_carlo` at the optimum's tolerances and
compares the achieved ``P(|w_j| <= R)`` (the paper's Eq. 14/20) and ``P(|dr| <= R)`` with the
probability asked for, with confidence intervals.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from tolsynth.errors import InputError
from tolsynth.analysis.montecarlo import DEFAULT_BATCH, MonteCarloResult, monte_carlo
from tolsynth.probability.stats import check_probability
from tolsynth.tabular import Tabular

__all__ = ["ValidationResult", "validate"]


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

    @property
    def met(self) -> bool:
        """All three components reach p (point estimates)."""
        return bool(np.all(self.components_met))

    def to_dict(self) -> dict:
        """Plain dict (arrays as lists) for JSON, with :attr:`met`."""
        out = {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self.__dict__.items() if k != "montecarlo"}
        out["pose"] = self.pose if isinstance(self.pose, str) else np.asarray(self.pose).tolist()
        out["met"] = self.met
        return out

    def report(self) -> str:
        """Readable table: achieved probabilities with intervals against ``p`` and the analytic values."""
        pct = int(round(100 * self.montecarlo.confidence))
        lines = [f"validation   p = {self.p:g} asked, R = {self.R:g} mm, {self.distribution}, n = {self.n}, seed = {self.seed}"]
        for j in range(3):
            lo, hi = self.p_components_ci[j]
            state = "met" if self.components_met[j] else ("SHORT" if self.components_short[j] else "below p (within noise)")
            lines.append(f"P(|w{j + 1}|<=R)  {self.p_components[j]:.5f} [{lo:.5f}, {hi:.5f}] ({pct}%)  analytic "
                         f"{self.p_components_analytic[j]:.5f}  {state}")
        lo, hi = self.p_sphere_ci
        lines.append(f"P(|dr|<=R)  {self.p_sphere:.5f} [{lo:.5f}, {hi:.5f}]  analytic {self.p_sphere_analytic:.5f}  "
                     + ("met" if self.sphere_met else "below p (sphere is stricter than Eq. 20)"))
        return "\n".join(lines)


def _attr(obj, name):
    for o in (obj, getattr(obj, "spec", None), getattr(obj, "problem", None)):
        if o is not None and getattr(o, name, None) is not None:
            return getattr(o, name)
    return None


def validate(
    mechanism,
    tolerances_or_result,
    R: float | None = None,
    p: float | None = None,
    distribution: str | None = None,
    pose="worst",
    n: int = 1_000_000,
    seed: int = 0,
    batch: int = DEFAULT_BATCH,
    confidence: float = 0.95,
    progress=None,
    Phi: float | None = None,
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
    pose : str or array
        Where to check (the paper's pose of largest error by default).
    n, seed, batch, confidence, progress
        As for :func:`monte_carlo`.
    Phi : float, optional
        Orientation half-angle (rad): the run then also samples the orientation probabilities
        (``montecarlo.p_orientation_components``, ``montecarlo.p_cone``).

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
    # distribution None: the model's own shapes, as everywhere
    mc = monte_carlo(mechanism, pose, tol, distribution, R=R, n=n, seed=seed, batch=batch,
                     confidence=confidence, progress=progress, Phi=Phi)
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
