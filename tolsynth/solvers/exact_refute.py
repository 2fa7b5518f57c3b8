"""The exact reading's proofs of infeasibility for the pre-checks of :func:`tolsynth.synthesize`
(locked tolerances alone, every tolerance at its lower bound).

The Gaussian pre-checks (:meth:`tolsynth.problem.nlp.ToleranceNLP.check_feasible`,
:func:`tolsynth.model.locks.check_locks`) screen the blocks; under ``probability="exact"`` a
Gaussian failure is only a suspicion, since bounded errors (uniform, triangular) can meet p where
``sigma_1 z > R``.  :func:`exact_refuter` turns it into a verdict: the lowest exact probability
over directions at the block's pose (:func:`tolsynth.probability.exact.worst_direction`), or the
exact sphere probability, refuses only when it is below p by more than its rigorous error bound.
A single direction with ``P + err < p`` proves infeasibility (P only falls as a tolerance grows).
"""

from __future__ import annotations

import numpy as np

from tolsynth.probability.exact import (
    ExactProbabilityError,
    ball_probability,
    direction_probability,
    worst_direction,
)

__all__ = ["exact_refuter", "verdict"]


def exact_refuter(spec):
    """A function ``refute(i, eps)`` for the blocks of ``spec`` (its LMI blocks, then its sphere
    blocks, the order of :meth:`ToleranceNLP.all_values`): ``None`` unless the exact probability of
    block ``i`` at tolerances ``eps`` is proven below p, else ``(value, text)`` with the constraint
    value ``(1 - P) / (1 - p)`` (> 1) and the exact reading's words for the message."""
    scale = spec.col_scale
    shapes = tuple(spec.shapes)
    blocks = list(spec.blocks)
    spheres = list(spec.sphere_blocks)

    def refute(i: int, eps: np.ndarray):
        eps = np.asarray(eps, dtype=float)
        if i >= len(blocks):
            b = spheres[i - len(blocks)]
            try:
                P, err = ball_probability(np.asarray(b.A) / scale, eps, shapes, b.R, return_error=True)
            except ExactProbabilityError:  # no value to the estimate's accuracy: nothing proven
                return None
            if P + err >= b.p:
                return None
            return verdict(P, b.p, f"exact P(|dr| <= R) = {P:.6g} < p = {b.p:g}")
        b = blocks[i]
        A = np.asarray(b.A) / scale
        R, p, sym = (spec.R, spec.p, "R") if b.kind == "position" else (spec.Phi, spec.p_orientation, "Phi")
        try:
            u, _ = worst_direction(A, eps, shapes, R)
            P, err = direction_probability(np.abs(u @ (A * eps)), shapes, R, return_error=True)
        except ExactProbabilityError:
            return None
        if P + err >= p:
            return None
        what = "dr" if b.kind == "position" else "dtheta"
        along = ", ".join(f"{x:.4g}" for x in u)
        return verdict(P, p, f"exact P(|u . {what}| <= {sym}) = {P:.6g} < p = {p:g} along u = ({along})")

    return refute


def verdict(P: float, p: float, text: str) -> tuple[float, str]:
    """``(value, text)``: the exact constraint value ``(1 - P) / (1 - p)`` (> 1 where p is missed)
    and the message's words with that value quoted, the number the error's ``value`` holds."""
    value = float((1 - P) / (1 - p))
    return value, f"{text}; value (1 - P)/(1 - p) = {value:.4g} > 1"
