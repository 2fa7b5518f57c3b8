"""Monte Carlo through the full nonlinear kinematics, and validation of an optimum.

The analytic model of the paper (section 3) is linear in the errors and treats the hand error as
Gaussian.  :func:`monte_carlo` checks both approximations: it samples the error parameters
(uniform within ``+-eps``, or normal with ``3 sigma = eps``), pushes every sample through the
model's own CasADi forward-kinematics graph (``graphs.position`` -- never a second copy of the
formula), and reports the covariance and the probabilities ``P(|w_j| <= R)`` along the analytic
principal directions and ``P(|dr| <= R)`` in the sphere, each with a confidence interval, next to
the analytic values of :meth:`tolsynth.Mechanism.analyze`.

Speed: the CasADi SX graph is evaluated on whole NumPy batches by
:class:`tolsynth.kinematics.numpy_eval.NumpyEvaluator`, a small interpreter of the graph's instruction list
(one NumPy ufunc per CasADi operation, the sub-graph that does not depend on the sampled errors
evaluated once).  On one core this runs the
paper's robot at several million samples per second; ``benchmarks/bench_montecarlo.py`` compares
it with CasADi's own ``map`` evaluation and with per-sample calls.  Samples are drawn and
evaluated in batches of fixed size, so memory does not grow with ``n``.

The validation of an optimum against the ``p`` asked for is :func:`tolsynth.analysis.validation.validate`
(also importable from here).

Units: mm and rad; tolerances in each error parameter's tolerance unit; covariances in mm^2.

>>> import tolsynth
>>> m = tolsynth.load_model("xu_zhang_1988")
>>> r = tolsynth.monte_carlo(m, "worst", "figure3", R=0.2, n=200_000, seed=1)
>>> bool(r.p_sphere_ci[0] <= r.p_sphere <= r.p_sphere_ci[1])
True
"""

from __future__ import annotations

import math
import time
from statistics import NormalDist
from typing import Callable

import casadi as ca
import numpy as np

from tolsynth.analysis.montecarlo_result import MonteCarloResult
from tolsynth.checks import check_count, check_half_angle, check_seed
from tolsynth.errors import InputError, LoopClosureError, OutOfRangeError
from tolsynth.kinematics.numpy_eval import NumpyEvaluator
from tolsynth.probability.stats import check_positive, check_probability, principal
from tolsynth.progress import Progress, make_bar  # noqa: F401  (make_bar: re-exported for older imports)
from tolsynth.units import units_label

__all__ = [
    "NumpyEvaluator",
    "MonteCarloResult",
    "monte_carlo",
    "exact_linear",
    "wilson_interval",
]

#: the readings of the linear model a run's analytic probabilities can be in
ANALYTIC = ("gaussian", "exact")
DEFAULT_BATCH = 1 << 14  # samples per batch: a few MB of work arrays, whatever n is
MAX_BATCH = 1 << 20  # a few hundred MB of work arrays


# =============================================================================================
# statistics helpers
# =============================================================================================
def wilson_interval(k, n: int, confidence: float = 0.95) -> np.ndarray:
    """Wilson score interval of a binomial proportion ``k / n``.

    Parameters
    ----------
    k : int or array of int
        Successes.
    n : int
        Trials (> 0).
    confidence : float
        Two-sided confidence level, 0 < confidence < 1.

    Returns
    -------
    ndarray, shape ``(..., 2)``
        Lower and upper bounds.  Unlike the normal approximation, the interval stays inside
        [0, 1] and does not collapse to a point at ``k = 0`` or ``k = n``.
    """
    confidence = check_probability(confidence, "confidence")
    z = NormalDist().inv_cdf(0.5 + 0.5 * confidence)
    k = np.asarray(k, dtype=float)
    ph = k / n
    den = 1.0 + z * z / n
    centre = (ph + z * z / (2 * n)) / den
    half = z * np.sqrt(ph * (1 - ph) / n + z * z / (4.0 * n * n)) / den
    # at k = 0 and k = n the end is exactly 0 and 1 (centre -+ half cancel), which rounding misses
    lo = np.where(k <= 0, 0.0, np.clip(centre - half, 0, 1))
    hi = np.where(k >= n, 1.0, np.clip(centre + half, 0, 1))
    return np.stack([lo, hi], axis=-1)


def _check_n(n, field: str = "n") -> int:
    """Samples (up to 1e12) or a batch size (up to MAX_BATCH: its work arrays must fit in memory)."""
    return check_count(n, field, 1, MAX_BATCH if field == "batch" else 10**12)


_check_seed = check_seed


class _Sampler:
    """One pose, one set of tolerances: draws error batches and evaluates the hand position
    (and, with ``orientation``, the hand rotation) through the model's graphs."""

    def __init__(self, mechanism, q: np.ndarray, eps: np.ndarray, distribution: str, orientation: bool):
        self.mech = mechanism
        self.eps = eps
        self.distribution = distribution
        self.active = np.flatnonzero(eps > 0)  # zero tolerance: that error is exactly 0
        g = mechanism.graphs
        qs = ca.SX.sym("q", len(q))
        ds = ca.SX.sym("delta", mechanism.n)
        outs = [g.position(qs, ds), g.closure(qs, ds)]
        if orientation:
            T = g.fk(qs, ds)
            outs.append(ca.vec(T[:3, :3]))
        f = ca.Function("mc_eval", [qs, ds], outs, ["q", "delta"], ["p", "c", "R"][: len(outs)])
        # one SX graph built from the model's graphs; cse merges what position/closure/fk share
        if hasattr(ca, "cse"):
            f = ca.Function("mc_eval", [qs, ds], [ca.cse(o) for o in outs])
        self.evaluator = NumpyEvaluator(f)
        varying_d = np.zeros(mechanism.n, bool)
        varying_d[self.active] = True
        self.program = self.evaluator.bind([q, np.zeros(mechanism.n)], [np.zeros(len(q), bool), varying_d])
        nominal = self.evaluator([q, np.zeros(mechanism.n)])
        self.p0 = nominal[0]
        self.R0 = nominal[2].reshape(3, 3, order="F") if orientation else None
        from tolsynth.probability.distributions import shapes_of

        shapes = shapes_of(distribution, mechanism.error_parameters, mechanism.index)
        act = [shapes[i] for i in self.active]
        # rows of the same shape are drawn together; the paper's two shapes keep their fast paths
        self.groups = {}
        for j, s in enumerate(act):
            self.groups.setdefault(s, []).append(j)
        self.groups = {s: np.array(ix) for s, ix in self.groups.items()}
        self.scale = eps[self.active].astype(float)
        self._rows = None

    def draw(self, rng: np.random.Generator, batch: int) -> np.ndarray:
        if self._rows is None or self._rows.shape[1] != batch:
            self._rows = np.empty((self.active.size, batch))
        rows = self._rows
        if len(self.groups) == 1 and next(iter(self.groups)).kind in ("uniform", "normal"):
            if next(iter(self.groups)).kind == "uniform":
                rng.random(out=rows)  # [0, 1)
                rows *= 2.0
                rows -= 1.0
            else:
                rng.standard_normal(out=rows)
                rows *= 1.0 / 3.0  # 3 sigma = eps
        else:
            for s, ix in self.groups.items():
                rows[ix] = s.sample(rng, (ix.size, batch))
        rows *= self.scale[:, None]
        return rows

    def evaluate(self, rows: np.ndarray) -> list[np.ndarray]:
        return self.program(rows)


def exact_linear(S, eps, shapes, R: float, U: np.ndarray, axis=None) -> tuple[np.ndarray, float]:
    """The linear error model's exact probabilities for the rows ``S`` (3 x n, per tolerance unit):
    ``P(|u_j . d| <= R)`` along each column ``u_j`` of ``U`` (the Monte Carlo's own directions) and
    ``P(|d| <= R)`` in the sphere, or with ``axis`` (the hand axis; ``S`` the rotation rows) in the
    cone of half-angle R about it.  The sphere's or cone's value is NaN where its error estimate
    exceeds 5e-6 (the tables show 5 decimals)."""
    from tolsynth.probability.exact import ball_probability, cone_probability, direction_probability

    S = np.asarray(S, dtype=float)
    P, _ = direction_probability(np.abs(U.T @ S) * eps, shapes, R, return_error=True)
    if axis is None:
        whole, err = ball_probability(S, eps, shapes, R, tol=1e-6, return_error=True)
    else:  # to first order the axis turns by the rotation components perpendicular to it
        a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
        e1 = np.cross(a, np.eye(3)[int(np.argmin(np.abs(a)))])
        e1 /= np.linalg.norm(e1)
        E = np.column_stack([e1, np.cross(a, e1)])
        whole, err = cone_probability(E.T @ S, eps, shapes, R, tol=1e-6, return_error=True)
    return np.asarray(P, dtype=float), float(whole) if err <= 5e-6 else math.nan


def monte_carlo(
    mechanism,
    q,
    tolerances,
    distribution=None,
    *,
    R: float,
    n: int = 1_000_000,
    seed: int = 0,
    batch: int = DEFAULT_BATCH,
    Phi: float | None = None,
    progress: bool | Callable[[int, int], None] | None = None,
    confidence: float = 0.95,
    check_limits: bool = True,
    directions=None,
    analytic: str = "exact",
) -> MonteCarloResult:
    """Monte Carlo of the hand position error through the full nonlinear kinematics.

    Parameters
    ----------
    mechanism : Mechanism
        From :func:`tolsynth.load_model`.
    q : str or array
        Configuration name or joint values (rad).
    tolerances : str, dict or array
        Tolerance set name, or half-widths in each parameter's tolerance unit.
    distribution : str or dict, optional
        As :func:`tolsynth.synthesize`; each error is drawn from its own shape ("normal": 3 sigma =
        eps, not truncated, so that its variance is the analytic ``eps^2 / 9``).
    R : float
        Radius of the accuracy sphere and half-width of each component's zone (mm), > 0.
    n : int
        Number of samples, >= 1 (the probabilities' intervals hold for any n; the mean needs one
        sample, its interval and the covariance, spreads and kurtosis two: NaN below that).
    seed : int
        Seed of ``numpy.random.default_rng`` (recorded in the result); the same seed and batch
        size give the same numbers.
    batch : int
        Samples per batch (memory ~ ``batch * (work slots + errors) * 8`` bytes, not ~ n).
    Phi : float, optional
        Orientation tolerance (rad), a half-angle: 0 < Phi <= pi.  Adds the orientation-component
        and cone probabilities.
    progress : bool, callable or None
        A tqdm bar on stderr (None: on a terminal, shown once the run has taken 2 s), or a
        callable ``progress(done, total)``.
    confidence : float
        Level of the intervals (Wilson score for the probabilities, normal for the mean).
    check_limits : bool
        Check the joint values against the limits (named configurations keep their waivers).
    analytic : {"exact", "gaussian"}
        The reading of the linear model the ``*_analytic`` probabilities are in (default: the
        package's default reading, exact): its Gaussian approximation (:meth:`tolsynth.Mechanism.analyze`), or its exact probabilities
        (:mod:`tolsynth.probability.exact`) along the same principal directions, in the sphere and
        in the cone (NaN where the sphere's or cone's error estimate exceeds 5e-6).  Recorded in
        ``result.analytic``.

    Returns
    -------
    MonteCarloResult

    Raises
    ------
    OutOfRangeError
        ``n <= 0``, ``R <= 0``, negative seed, unknown distribution, a joint past its limit.
    UnknownNameError
        Unknown configuration or tolerance set.
    LoopClosureError
        The loop cannot close at the nominal dimensions.

    Examples
    --------
    >>> import tolsynth
    >>> m = tolsynth.load_model("xu_zhang_1988")
    >>> r = tolsynth.monte_carlo(m, "worst", "figure3", R=0.2, n=100_000, seed=7)
    >>> r.n, r.seed, r.n_loop_failures
    (100000, 7, 0)
    """
    from tolsynth.kinematics.mechanism import as_mechanism
    from tolsynth.probability.distributions import resolve

    mechanism = as_mechanism(mechanism)
    distribution = resolve(distribution, mechanism)
    if not isinstance(analytic, str) or analytic not in ANALYTIC:
        raise InputError("analytic", f"got {analytic!r}", " or ".join(repr(a) for a in ANALYTIC))
    R = check_positive(R, "R")
    n = _check_n(n)
    seed = _check_seed(seed)
    batch = _check_n(batch, "batch")
    confidence = check_probability(confidence, "confidence")
    if Phi is not None:
        Phi = check_half_angle(Phi)
    eps = mechanism.tolerances(tolerances)
    qv = mechanism.joints(q, check_limits)
    Ud = None
    if directions is not None:  # extra unit directions (columns): P(|u . dr| <= R) along each
        from tolsynth.checks import check_vector

        raw = np.asarray(directions, dtype=float) if not isinstance(directions, str) else np.array([])
        if raw.size == 0 or raw.shape[0] != 3 or raw.ndim > 2:
            raise InputError("directions", f"shape {raw.shape}", "a 3-vector or a 3 x d array of directions (columns)")
        Ud = check_vector(raw.ravel(order="F"), "directions").reshape(3, -1, order="F")
        norms = np.linalg.norm(Ud, axis=0)
        if np.any(norms < 1e-12):
            raise OutOfRangeError("directions", "a zero direction", "non-zero 3-vectors (columns)")
        Ud = Ud / norms
    inside_dir = np.zeros(0 if Ud is None else Ud.shape[1], dtype=np.int64)
    ana = mechanism.analyze(qv, eps, distribution, R=R, Phi=Phi, check_limits=False)
    U = ana.principal_directions
    sampler = _Sampler(mechanism, qv, eps, distribution, orientation=Phi is not None)
    if mechanism.spec.loops:
        c0 = np.asarray(mechanism.graphs.closure(qv, np.zeros(mechanism.n))).ravel()
        if not np.all(np.abs(c0) <= 1):
            raise LoopClosureError(
                f"a loop cannot close at the nominal dimensions at q = {mechanism.format_joints(qv)}"
            )
    p0 = sampler.p0
    if Phi is not None:
        Uo = principal(ana.orientation_covariance)[1]
        z0 = sampler.R0[:, 2]

    rng = np.random.default_rng(seed)
    R2 = R * R
    inside_sphere = 0
    inside_comp = np.zeros(3, dtype=np.int64)
    inside_ocomp = np.zeros(3, dtype=np.int64)
    inside_cone = 0
    failures = 0
    m_ok = 0
    shift = None
    s1 = np.zeros(3)
    s2 = np.zeros((3, 3))
    w_shift = None
    wpow = np.zeros((4, 3))  # sums of (w - w_shift)^k, k = 1..4
    bar = Progress(progress, n, "monte carlo")
    t0 = time.perf_counter()
    done = 0
    try:
        while done < n:
            b = min(batch, n - done)
            rows = sampler.draw(rng, b)
            outs = sampler.evaluate(rows)
            p, c = outs[0], outs[1]
            dr = p - p0[:, None]  # (3, b) mm
            ok = np.all(np.abs(c) <= 1.0, axis=0) if c.shape[0] else np.ones(b, bool)
            ok &= np.all(np.isfinite(dr), axis=0)
            nbad = int(b - np.count_nonzero(ok))
            failures += nbad
            if nbad:
                dr = dr[:, ok]
            # probabilities: failures count as outside (numerators over ok samples, denominators n)
            d2 = np.einsum("ib,ib->b", dr, dr)
            inside_sphere += int(np.count_nonzero(d2 <= R2))
            w = U.T @ dr  # (3, b) components along the analytic principal directions
            inside_comp += np.count_nonzero(np.abs(w) <= R, axis=1)
            if Ud is not None:
                inside_dir += np.count_nonzero(np.abs(Ud.T @ dr) <= R, axis=1)
            # moments about a shift (the first batch's mean) for numerical safety
            if dr.shape[1]:
                if shift is None:
                    shift = dr.mean(axis=1)
                    w_shift = U.T @ shift
                x = dr - shift[:, None]
                s1 += x.sum(axis=1)
                s2 += x @ x.T
                y = w - w_shift[:, None]
                y2 = y * y
                wpow[0] += y.sum(axis=1)
                wpow[1] += y2.sum(axis=1)
                wpow[2] += (y2 * y).sum(axis=1)
                wpow[3] += (y2 * y2).sum(axis=1)
                m_ok += dr.shape[1]
            if Phi is not None:
                Rm = outs[2][:, ok].reshape(3, 3, -1, order="F")  # R[i, j, b]
                # small rotation of the hand: dR = R R0^T; rotation vector from its skew part
                dR = np.einsum("ikb,jk->ijb", Rm, sampler.R0)
                s = 0.5 * np.stack([dR[2, 1] - dR[1, 2], dR[0, 2] - dR[2, 0], dR[1, 0] - dR[0, 1]])
                sn = np.sqrt(np.einsum("ib,ib->b", s, s))
                with np.errstate(invalid="ignore", divide="ignore"):
                    fac = np.where(sn > 0, np.arcsin(np.minimum(sn, 1.0)) / np.where(sn > 0, sn, 1.0), 1.0)
                phi = s * fac
                inside_ocomp += np.count_nonzero(np.abs(Uo.T @ phi) <= Phi, axis=1)
                z = Rm[:, 2, :]
                ang = np.arctan2(np.linalg.norm(np.cross(z0, z.T), axis=1), z0 @ z)
                inside_cone += int(np.count_nonzero(ang <= Phi))
            done += b
            bar.update(done, b)
    finally:
        bar.close()
    elapsed = time.perf_counter() - t0

    zc = NormalDist().inv_cdf(0.5 + 0.5 * confidence)
    # the mean needs one assembled sample; a covariance, spread or interval needs two
    mean = shift + s1 / m_ok if m_ok >= 1 else np.full(3, np.nan)
    if m_ok >= 2:
        mx = s1 / m_ok
        cov = (s2 - m_ok * np.outer(mx, mx)) / (m_ok - 1)
        # central moments of w_j
        mu = wpow[0] / m_ok
        c2 = wpow[1] / m_ok - mu**2
        c4 = wpow[3] / m_ok - 4 * mu * wpow[2] / m_ok + 6 * mu**2 * wpow[1] / m_ok - 3 * mu**4
        with np.errstate(invalid="ignore", divide="ignore"):
            kurt = np.where(c2 > 0, c4 / np.where(c2 > 0, c2, 1.0) ** 2 - 3.0, np.nan)
        std_w = np.sqrt(np.maximum(np.diag(U.T @ cov @ U), 0.0))
        se_mean = np.sqrt(np.maximum(np.diag(cov), 0.0) / m_ok)
    else:
        cov = np.full((3, 3), np.nan)
        kurt = np.full(3, np.nan)
        std_w = np.full(3, np.nan)
        se_mean = np.full(3, np.nan)
    p_comp = inside_comp / n
    p_comp_ci = wilson_interval(inside_comp, n, confidence)
    p_sph = inside_sphere / n
    p_sph_ci = wilson_interval(inside_sphere, n, confidence)
    pa, pa_sphere = np.asarray(ana.p_components), float(ana.p_sphere)
    pa_ori, pa_cone = (np.asarray(ana.p_orientation_components), float(ana.p_cone)) if Phi is not None else (None, None)
    if analytic == "exact":
        from tolsynth.probability.distributions import shapes_of

        shapes = shapes_of(distribution, mechanism.error_parameters, mechanism.index)
        pa, pa_sphere = exact_linear(ana.sensitivity[:3], eps, shapes, R, U)
        if Phi is not None:
            pa_ori, pa_cone = exact_linear(ana.sensitivity[3:6], eps, shapes, Phi, Uo, axis=z0)
    extra = {}
    if Ud is not None:
        extra.update(
            directions=Ud, p_directions=inside_dir / n, p_directions_ci=wilson_interval(inside_dir, n, confidence)
        )
    if Phi is not None:
        extra.update(
            Phi=Phi,
            p_orientation_components=inside_ocomp / n,
            p_orientation_components_ci=wilson_interval(inside_ocomp, n, confidence),
            p_orientation_components_analytic=pa_ori,
            p_cone=inside_cone / n,
            p_cone_ci=wilson_interval(inside_cone, n, confidence),
            p_cone_analytic=pa_cone,
        )
    out = MonteCarloResult(
        model=mechanism.name,
        q=qv,
        pose_text=mechanism.format_joints(qv),
        joint_units=mechanism.joint_value_units,
        position=p0.copy(),
        distribution=distribution,
        tolerances=dict(zip(mechanism.error_parameters, eps.tolist())),
        R=R,
        n=n,
        seed=seed,
        batch=batch,
        confidence=confidence,
        ci_method="Wilson score (probabilities), normal approximation (mean)",
        n_loop_failures=failures,
        mean=mean,
        mean_ci=np.stack([mean - zc * se_mean, mean + zc * se_mean], axis=-1),
        covariance=cov,
        covariance_analytic=ana.covariance,
        principal_directions=U,
        principal_std=std_w,
        principal_std_analytic=ana.principal_std,
        kurtosis=kurt,
        kurtosis_se=math.sqrt(24.0 / max(m_ok, 1)),
        p_components=p_comp,
        p_components_ci=p_comp_ci,
        p_components_analytic=pa,
        p_components_diff=p_comp - pa,
        p_components_analytic_in_ci=(p_comp_ci[:, 0] <= pa) & (pa <= p_comp_ci[:, 1]),
        p_sphere=p_sph,
        p_sphere_ci=p_sph_ci,
        p_sphere_analytic=pa_sphere,
        p_sphere_diff=p_sph - pa_sphere,
        p_sphere_analytic_in_ci=bool(p_sph_ci[0] <= pa_sphere <= p_sph_ci[1]),
        analytic=analytic,
        elapsed_s=elapsed,
        samples_per_s=n / elapsed if elapsed > 0 else math.inf,
        **extra,
    )
    out.units["q"] = units_label(mechanism.joint_value_units)  # a strut's length in mm
    return out
