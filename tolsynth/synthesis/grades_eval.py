"""Whether given tolerances meet a specification, in each probability's reading: the check that
:func:`tolsynth.synthesis.grades.round_to_grades` applies to every combination of grades."""

from __future__ import annotations

import math

import numpy as np

from tolsynth.solvers.common import FEAS_TOL

__all__ = ["constraint_values", "meets"]


# ---------------------------------------------------------------------------------------------
# the specification at given tolerances
# ---------------------------------------------------------------------------------------------
def constraint_values(spec, probability: str, eps) -> np.ndarray:
    """Every constraint block's value at ``eps`` (``<= 1`` meets it), in the reading of
    ``probability``: Gaussian sigma z / limit (sphere (1 - P)/(1 - p)), exact (1 - P)/(1 - p) along
    the worst direction found (in the sphere: its exact P), or the worst case's max |error| / limit;
    :func:`meets` gives the verdict (for the exact reading a certified one)."""
    return _evaluate(spec, probability, eps)[0]


def meets(spec, probability: str, eps) -> bool:
    """Does ``eps`` meet the specification, checked as the solver of ``probability`` checks an
    optimum: every value within 1e-6 of 1, or for the exact probabilities every direction of
    every pose proven to reach p - 1e-7 (the exact solver's branch and bound over directions)."""
    return _evaluate(spec, probability, eps)[1]


def _evaluate(spec, probability: str, eps) -> tuple[np.ndarray, bool]:
    eps = np.asarray(eps, dtype=float)
    if probability == "worst_case":
        from tolsynth.solvers.worst_case import _blocks, worst_case_values

        vals = np.array([v for v, _, _ in worst_case_values(_blocks(spec), eps)])
        return vals, bool(vals.max() <= 1.0 + FEAS_TOL)
    if probability == "gaussian":
        from tolsynth.problem.nlp import ToleranceNLP

        vals = np.array([float(v[0]) for v in ToleranceNLP(spec).all_values(eps)])
        return vals, bool(vals.max() <= 1.0 + FEAS_TOL)
    from tolsynth.probability import exact as ex
    from tolsynth.solvers.exact import EXACT_TOL
    from tolsynth.solvers.exact_certify import cover

    out, ok = [], True
    for b in spec.blocks:
        limit, p = (spec.R, spec.p) if b.kind == "position" else (spec.Phi, spec.p_orientation)
        A = np.asarray(b.A) / spec.col_scale
        # the value: P along the worst direction found (what the design achieves); the verdict:
        # the certified cover, whose own bound only needs to clear p and is not the achieved P
        P = ex.worst_direction(A, eps, spec.shapes, limit, tol=1e-10)[1]
        ok = ok and cover(A * eps, spec.shapes, limit, p, tol=EXACT_TOL).certified
        out.append((1.0 - P) / (1.0 - p))
    for b in spec.sphere_blocks:
        P = ex.ball_probability(np.asarray(b.A) / spec.col_scale, eps, spec.shapes, b.R, tol=1e-8)
        ok = ok and P >= b.p - EXACT_TOL
        out.append((1.0 - P) / (1.0 - b.p))
    return np.array(out), ok


def _achieved(spec, probability: str, values: np.ndarray) -> float:
    """The smallest probability any block achieves, from its constraint value."""
    if probability == "worst_case":
        return 1.0 if values.max() <= 1.0 + FEAS_TOL else 0.0
    ps = []
    for b, v in zip(spec.blocks, values):
        if probability == "gaussian":
            z = b.scale * (spec.R if b.kind == "position" else spec.Phi)
            ps.append(math.erf(z / (v * math.sqrt(2.0))) if v > 0 else 1.0)
        else:
            ps.append(1.0 - v * (1.0 - (spec.p if b.kind == "position" else spec.p_orientation)))
    for b, v in zip(spec.sphere_blocks, values[len(spec.blocks) :]):
        ps.append(1.0 - v * (1.0 - b.p))
    return float(min(ps))
