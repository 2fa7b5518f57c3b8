"""The result of a Monte Carlo run through the nonlinear kinematics (:func:`tolsynth.monte_carlo`):
the estimated probabilities with their confidence intervals beside the analytic ones."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from tolsynth.tabular import Tabular, jsonable

__all__ = ["MonteCarloResult", "ANALYTIC_TEXT"]

#: what the analytic probabilities are, per reading of the linear model
ANALYTIC_TEXT = {
    "gaussian": "the linear model's Gaussian approximation (sigma_j, Eq. 6-8)",
    "exact": "the linear model's exact probabilities (no Gaussian approximation)",
}


def _dist_text(distribution) -> str:
    from tolsynth.probability.distributions import describe, label

    return describe(distribution) if isinstance(distribution, str) else label(distribution)


# =============================================================================================
# the sampler
# =============================================================================================
# =============================================================================================
# result types
# =============================================================================================
@dataclass(frozen=True)
class MonteCarloResult(Tabular):
    """Monte Carlo error statistics at one pose, next to the analytic (linear model) ones.

    Every probability has a two-sided confidence interval (``ci_method``, level ``confidence``);
    ``*_analytic`` are the linear model's values in the reading ``analytic`` names (``"gaussian"``:
    those of :meth:`tolsynth.Mechanism.analyze`; ``"exact"``: its exact probabilities) and
    ``*_diff`` the Monte Carlo value minus the analytic one.  ``*_analytic_in_ci`` is False where
    the analytic value lies outside the Monte Carlo interval, i.e. where the linear model (in that
    reading) is off by more than the sampling noise explains.

    Attributes
    ----------
    model : str
    q : ndarray (rad)
        Joint values of the pose.
    position : ndarray (mm)
        Nominal hand position.
    distribution : str
        "uniform" (within +-eps) or "normal" (3 sigma = eps, not truncated).
    tolerances : dict
        Half-widths, name -> value in the parameter's tolerance unit.
    R : float (mm)
    n, seed, batch : int
        Samples, the seed of ``numpy.random.default_rng`` and the batch size.
    n_loop_failures : int
        Samples for which a closed loop could not be assembled.  They are *kept* in ``n`` and
        counted as outside every tolerance zone (conservative); the moments exclude them.
    mean, mean_ci : ndarray (mm)
        Mean position error (3,) and its normal-approximation interval (3, 2).
    covariance, covariance_analytic : ndarray (mm^2)
        Sample covariance of the position error (3, 3), and the linear model's.
    principal_directions : ndarray
        The analytic principal directions (columns, descending sigma); the components ``w_j``
        are the projections of the position error on them.
    principal_std, principal_std_analytic : ndarray (mm)
        Standard deviation of ``w_j`` sampled, and analytic ``sigma_j``.
    kurtosis, kurtosis_se : ndarray
        Excess kurtosis of each ``w_j`` (0 for a normal, -1.2 for one uniform source) and its
        standard error ``sqrt(24 / n)``.  Far from 0 means the Gaussian reading of that direction
        is poor (typically one dominant uniform error source).
    p_components, p_components_ci, p_components_analytic, p_components_diff : ndarray
        ``P(|w_j| <= R)``.
    p_sphere, p_sphere_ci, p_sphere_analytic, p_sphere_diff : float / ndarray
        ``P(|dr| <= R)`` (Eq. 5).
    p_components_analytic_in_ci : ndarray of bool
    p_sphere_analytic_in_ci : bool
    Phi : float (rad) or None
        With ``Phi``: ``p_orientation_components`` (along the analytic orientation principal
        directions, of the rotation vector), ``p_cone`` (angle between the actual and nominal hand
        z axes <= Phi), their intervals and analytic values.
    elapsed_s, samples_per_s : float
        Wall time of the sampling.
    """

    model: str
    q: np.ndarray
    position: np.ndarray
    distribution: str
    tolerances: dict
    R: float
    n: int
    seed: int
    batch: int
    confidence: float
    ci_method: str
    n_loop_failures: int
    mean: np.ndarray
    mean_ci: np.ndarray
    covariance: np.ndarray
    covariance_analytic: np.ndarray
    principal_directions: np.ndarray
    principal_std: np.ndarray
    principal_std_analytic: np.ndarray
    kurtosis: np.ndarray
    kurtosis_se: float
    p_components: np.ndarray
    p_components_ci: np.ndarray
    p_components_analytic: np.ndarray
    p_components_diff: np.ndarray
    p_components_analytic_in_ci: np.ndarray
    p_sphere: float
    p_sphere_ci: np.ndarray
    p_sphere_analytic: float
    p_sphere_diff: float
    p_sphere_analytic_in_ci: bool
    elapsed_s: float
    samples_per_s: float
    Phi: float | None = None
    p_orientation_components: np.ndarray | None = None
    p_orientation_components_ci: np.ndarray | None = None
    p_orientation_components_analytic: np.ndarray | None = None
    p_cone: float | None = None
    p_cone_ci: np.ndarray | None = None
    p_cone_analytic: float | None = None
    #: with ``directions=``: the unit directions (columns) and ``P(|u^T dr| <= R)`` along each, with intervals
    directions: np.ndarray | None = None
    p_directions: np.ndarray | None = None
    p_directions_ci: np.ndarray | None = None
    units: dict = field(
        default_factory=lambda: {
            "position": "mm",
            "mean": "mm",
            "covariance": "mm^2",
            "principal_std": "mm",
            "R": "mm",
            "q": "rad",
            "Phi": "rad",
            "tolerances": "each parameter's tolerance unit",
        }
    )
    #: the pose as a person reads it, each joint in its own unit (a strut's in mm, a revolute's in deg)
    pose_text: str = ""
    #: each joint value's unit, "rad" or "mm" (a joint that slides); empty: all "rad"
    joint_units: tuple = ()
    #: the reading of the linear model the ``*_analytic`` probabilities are in: "gaussian" or "exact"
    analytic: str = "gaussian"

    def to_dict(self) -> dict:
        """Plain dict for JSON (arrays as lists): every field, with NaN and infinities as None
        (NaN where a quantity is undefined (a kurtosis without spread, a sigma of no samples)), so ``json.dumps(..., allow_nan=False)`` takes it."""
        return jsonable(self.__dict__, null=True)

    def _mean_text(self) -> str:
        """The mean error, with why its interval (and the spreads) are missing where they are."""
        assembled = self.n - self.n_loop_failures
        if assembled < 1:
            return "none (no sample closed the loop)"
        text = f"({', '.join(f'{v:+.2e}' for v in self.mean)}) mm"
        if assembled < 2:  # one sample has a mean but no spread
            text += "; one sample: its interval and the sigmas below need n >= 2"
        return text

    def report(self) -> str:
        """A readable table: Monte Carlo vs analytic, with intervals and flags."""
        pct = int(round(100 * self.confidence))
        lines = [
            f"model        {self.model}",
            f"pose         q = {self.pose_text or '(' + ', '.join(f'{math.degrees(v):.4f}' for v in self.q) + ') deg'}; "
            f"hand ({', '.join(f'{v:.3f}' for v in self.position)}) mm",
            f"errors       {_dist_text(self.distribution)}",
            f"samples      n = {self.n}, seed = {self.seed}, batch = {self.batch}; "
            f"{self.samples_per_s / 1e6:.2f} M samples/s; loop failures {self.n_loop_failures}",
            f"intervals    {pct}% {self.ci_method}",
            f"mean error   {self._mean_text()}",
            "",
            f"{'':14}{'Monte Carlo':>12} {pct}% interval{'':9}{'analytic':>10}{'MC-analytic':>13}  flag",
        ]
        for j in range(3):
            lo, hi = self.p_components_ci[j]
            flag = "" if self.p_components_analytic_in_ci[j] else f"{self.analytic} analytic outside CI"
            lines.append(
                f"P(|w{j + 1}|<=R)    {self.p_components[j]:12.5f} [{lo:.5f}, {hi:.5f}]  "
                f"{self.p_components_analytic[j]:10.5f}{self.p_components_diff[j]:+13.5f}  {flag}"
            )
        lo, hi = self.p_sphere_ci
        flag = "" if self.p_sphere_analytic_in_ci else f"{self.analytic} analytic outside CI"
        lines.append(
            f"P(|dr|<=R)    {self.p_sphere:12.5f} [{lo:.5f}, {hi:.5f}]  {self.p_sphere_analytic:10.5f}"
            f"{self.p_sphere_diff:+13.5f}  {flag}"
        )
        lines.append("")
        lines.append(
            f"{'direction':14}{'sigma MC':>12}{'sigma lin.':>12}{'excess kurtosis':>17} (Gaussian 0, +-{self.kurtosis_se:.3f} s.e.)"
        )
        for j in range(3):
            d = self.principal_directions[:, j]
            kurt = self.kurtosis[j]
            if np.isfinite(kurt):
                shown, note = f"{kurt:+17.3f}", "" if abs(kurt) <= 4 * self.kurtosis_se + 0.1 else "  not Gaussian"
            else:  # no spread along w_j (a planar mechanism's normal): no shape to judge
                shown, note = f"{'-':>17}", "  no error along it" if self.principal_std[j] == 0 else ""
            lines.append(
                f"w{j + 1} ({d[0]:+.3f},{d[1]:+.3f},{d[2]:+.3f}) "
                + (f"{self.principal_std[j]:9.5f}" if np.isfinite(self.principal_std[j]) else f"{'-':>9}")
                + f"{self.principal_std_analytic[j]:12.5f}{shown}{note}"
            )
        if self.Phi is not None:
            lines.append("")
            lines.append(f"Phi          {self.Phi:g} rad")
            for j in range(3):
                lo, hi = self.p_orientation_components_ci[j]
                lines.append(
                    f"P(|phi{j + 1}|<=Phi) {self.p_orientation_components[j]:10.5f} [{lo:.5f}, {hi:.5f}]  "
                    f"{self.p_orientation_components_analytic[j]:10.5f}"
                )
            lo, hi = self.p_cone_ci
            lines.append(f"P(cone)       {self.p_cone:12.5f} [{lo:.5f}, {hi:.5f}]  {self.p_cone_analytic:10.5f}")
        lines.append("R = {:g} mm; w_j along the analytic principal directions; sphere = Eq. 5".format(self.R))
        lines.append(f"analytic     {ANALYTIC_TEXT[self.analytic]}")
        return "\n".join(lines)


# =============================================================================================
# monte_carlo
# =============================================================================================
