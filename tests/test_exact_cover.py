"""The exact solver's branch and bound over directions (solvers.exact_certify.cover), against the
reference evaluator of tolsynth.probability.exact on dense grids of directions: what it proves
holds on the grid, it finds the directions below a level it cannot prove, and a pose symmetric
under a reflection (half of its directions covered) gives the same verdict as the full sphere."""

import numpy as np
import pytest

import tolsynth
from tolsynth.probability.exact import direction_probability
from tolsynth.solvers.exact_certify import _mirror, cover

R = 0.5


@pytest.fixture(scope="module")
def design():
    m = tolsynth.load_model("xu_zhang_1988")
    r = tolsynth.synthesize(m, R=R, p=0.9, probability="exact")
    A = m.sensitivity(m.joints("worst"))[:3]
    return A * r.x, tuple(r.spec.shapes)


def _grid(m=6000, seed=11):
    D = np.random.default_rng(seed).normal(size=(m, 3))
    return D / np.linalg.norm(D, axis=1, keepdims=True)


def test_the_papers_worst_pose_is_a_mirror_and_a_random_one_is_not(design):
    M, _ = design
    axis, delta = _mirror(M)
    assert axis == 1 and np.max(delta) <= 1e-12 * np.abs(M).max()
    # the reflection leaves every row |w . m_i| the same up to delta
    D = _grid(200)
    S = np.diag([1.0, -1.0, 1.0])
    assert np.max(np.abs(np.abs(D @ S @ M) - np.abs(D @ M)) - delta) <= 1e-15
    assert _mirror(np.random.default_rng(2).normal(size=(3, 11)))[0] is None


def test_what_the_cover_proves_holds_on_a_dense_grid(design):
    """Certified at p = 0.9 - 1e-7 with half of the sphere (the mirror) and with all of it: the
    same verdict, and the reference evaluator on 6000 directions is never below the proven level."""
    M, sh = design
    half = cover(M, sh, R, 0.9, 1e-7, 3e-8)
    M_broken = M.copy()
    M_broken[1, 0] += 1e-6 * np.abs(M).max()  # no longer a mirror: the whole sphere is covered
    assert _mirror(M_broken)[0] is None
    full = cover(M_broken, sh, R, 0.9, 1e-7, 3e-8)
    assert half.certified and full.certified
    assert half.patches < 0.6 * full.patches
    P = direction_probability(_grid() @ M, sh, R)
    assert P.min() >= half.proven - 1e-12
    assert P.min() <= 0.9 + 1e-3  # the design is at p along its worst directions


def test_a_level_above_the_worst_direction_is_not_proven(design):
    """p raised by 1e-6 above the design's worst direction: no cover exists, and the directions
    the search reports are below the level by the reference evaluator, on both halves' account."""
    M, sh = design
    cv = cover(M, sh, R, 0.9 + 1e-6, 1e-7, 3e-8)
    assert not cv.certified and cv.violations
    W = np.array([w for w, _ in cv.violations])
    assert np.all(direction_probability(W @ M, sh, R) < 0.9 + 1e-6 - 3e-8)


def test_tangent_bases_are_orthonormal_and_tangent():
    """The cuts' tangent bases at 2000 random directions and at the axes (both signs of z, where
    the branch-free formula switches): orthonormal and orthogonal to the direction, to rounding."""
    from tolsynth.solvers.exact_cuts import _tangent

    W = _grid(2000, seed=3)
    W = np.vstack([W, np.eye(3), -np.eye(3), [[0.0, 0.6, -0.8]]])
    E = _tangent(W)
    assert np.max(np.abs(np.einsum("mxa,mxb->mab", E, E) - np.eye(2))) < 1e-14
    assert np.max(np.abs(np.einsum("mxa,mx->ma", E, W))) < 1e-14
