"""``synthesize(..., verify=...)``: the loop closed by the nonlinear Monte Carlo.

At the optimum, :func:`tolsynth.monte_carlo` samples the full nonlinear kinematics at every pose
of the specification (each error from its own shape) and estimates the probability the designer
asked for: ``P(|u . dr| <= R)`` along each constrained direction (the principal axes of a Gaussian
design, the worst direction and the principal axes of an exact one) or ``P(|dr| <= R)`` for the
sphere.  The smallest of these is the achieved probability, with its two-sided Wilson interval at
``confidence`` (default 99 %).

**Sample size**: ``n = z^2 p (1 - p) / h^2`` with ``h = (1 - p) / 10`` (the interval's half-width
a tenth of the miss probability), at least 20,000 and at most 4,000,000; or the ``n`` given.

**Stopping rule**: if the interval's lower end is below ``p``, the design target is raised by the
shortfall, ``p_target <- p_target + (p - lower)``, the problem is solved again and sampled again
with a new seed; the loop stops when the lower end reaches ``p`` (``verified``) or after
``max_rounds`` (default 6; then ``verified`` is False and the report says so).  Each round's
interval holds at its own confidence level; the rounds are not a sequential test.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from statistics import NormalDist

import numpy as np

from tolsynth.tabular import Tabular

__all__ = ["Verification", "sample_size", "closed_loop"]

N_MIN, N_MAX = 20_000, 4_000_000


def sample_size(p: float, confidence: float = 0.99) -> int:
    """``z^2 p (1 - p) / h^2`` with ``h = (1 - p) / 10``, clipped to [20,000, 4,000,000]."""
    z = NormalDist().inv_cdf(0.5 + 0.5 * confidence)
    h = (1.0 - p) / 10.0
    return int(min(N_MAX, max(N_MIN, math.ceil(z * z * p * (1.0 - p) / (h * h)))))


@dataclass(frozen=True)
class Verification(Tabular):
    """The closed loop's outcome: the achieved probability (smallest over the constrained poses
    and directions) with its interval, the design target that achieved it, and every round."""

    p: float
    R: float
    criterion: str
    achieved: float
    ci: np.ndarray
    confidence: float
    verified: bool
    p_target: float
    n: int
    rounds: list = field(default_factory=list)

    def to_dict(self) -> dict:
        out = dict(self.__dict__)
        out["ci"] = np.asarray(self.ci).tolist()
        return out

    def report(self) -> str:
        lo, hi = self.ci
        pct = round(100 * self.confidence)
        lines = [
            f"verify       p = {self.p:g} asked, R = {self.R:g} mm, {self.criterion}; nonlinear Monte Carlo, "
            f"n = {self.n} per pose, {pct}% Wilson intervals",
            f"achieved     {self.achieved:.5f} [{lo:.5f}, {hi:.5f}]  "
            + ("verified: the lower end reaches p" if self.verified else "NOT verified: the lower end is below p"),
            f"design       target p = {self.p_target:.6g} after {len(self.rounds)} round(s)",
        ]
        for r in self.rounds:
            lines.append(
                f"  round {r['round']}: target {r['p_target']:.6g}, cost {r['cost']:.6g}, "
                f"P {r['estimate']:.5f} [{r['ci'][0]:.5f}, {r['ci'][1]:.5f}] at pose {r['pose']}"
            )
        return "\n".join(lines)


def _achieved(mechanism, result, R, distribution, n, seed, confidence):
    """Smallest Monte Carlo probability over the result's poses and constrained directions."""
    from tolsynth.analysis.montecarlo import monte_carlo

    sphere = result.spec.criterion == "sphere"
    best = None
    for k, (label, q) in enumerate(result.spec.poses.items()):
        dirs = None
        if not sphere:
            cols = [b.directions for b in result.constraints if b.pose == label and b.kind.startswith("position")]
            dirs = np.column_stack(cols) if cols else None
        mc = monte_carlo(
            mechanism,
            q,
            result.x,
            distribution,
            R=R,
            n=n,
            seed=seed + k,
            directions=dirs,
            confidence=confidence,
            check_limits=False,
        )
        if sphere:
            vals, cis = np.array([mc.p_sphere]), np.array([mc.p_sphere_ci])
        else:
            vals, cis = mc.p_directions, mc.p_directions_ci
        j = int(np.argmin(cis[:, 0]))
        if best is None or cis[j, 0] < best[1][0]:
            best = (float(vals[j]), np.asarray(cis[j], dtype=float), label)
    return best


def closed_loop(
    solve,
    mechanism,
    result,
    *,
    p: float,
    R: float,
    distribution,
    n=None,
    seed: int = 0,
    confidence: float = 0.99,
    max_rounds: int = 6,
):
    """Run the loop of the module docstring; ``solve(p_target)`` re-solves the same problem with
    another probability.  Returns the last result with its :class:`Verification` attached."""
    from tolsynth.checks import check_count

    n = sample_size(p, confidence) if n is None or n is True else check_count(n, "verify", lower=1000)
    rounds = []
    p_target = p
    for rnd in range(max_rounds):
        est, ci, pose = _achieved(mechanism, result, R, distribution, n, seed + 1000 * rnd, confidence)
        rounds.append(
            {
                "round": rnd,
                "p_target": p_target,
                "cost": result.cost,
                "estimate": est,
                "ci": ci.tolist(),
                "pose": pose,
                "success": result.success,
            }
        )
        if ci[0] >= p or not result.feasible:  # (FEASIBLE: met, optimality not proven, as the sphere's)
            break
        if rnd == max_rounds - 1:
            break
        p_target = min(p_target + (p - ci[0]), 1.0 - 1e-9)
        result = solve(p_target)
    last = rounds[-1]
    ver = Verification(
        p=p,
        R=R,
        criterion=result.spec.criterion,
        achieved=last["estimate"],
        ci=np.array(last["ci"]),
        confidence=confidence,
        verified=bool(last["ci"][0] >= p),
        p_target=p_target,
        n=n,
        rounds=rounds,
    )
    return replace(result, verification=ver)
