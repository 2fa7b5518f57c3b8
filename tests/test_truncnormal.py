"""The truncated normal's fast characteristic function against independent computations: direct
quadrature of the density for phi, central differences of phi for s phi' and s (s phi')'."""

import math

import numpy as np
import pytest

from tolsynth.probability.truncnormal import cf3


def _density_cf(s, beta):
    """E cos(sY) by composite Gauss-Legendre quadrature of the truncated density on [-1, 1]
    (400 panels of 20 nodes: exact to rounding for s up to 1000)."""
    g, gw = np.polynomial.legendre.leggauss(20)
    edges = np.linspace(-1.0, 1.0, 401)
    mid, half = 0.5 * (edges[1:] + edges[:-1]), 0.5 * np.diff(edges)
    x = (mid[:, None] + half[:, None] * g[None, :]).ravel()
    w = (half[:, None] * gw[None, :]).ravel()
    f = np.exp(-0.5 * (beta * x) ** 2)
    f /= np.sum(w * f)
    return np.array([np.sum(w * f * np.cos(si * x)) for si in np.atleast_1d(s)])


@pytest.mark.parametrize("beta", [0.5, 2.0, 3.0, 8.0])
def test_phi_against_the_density(beta):
    s = np.concatenate([np.linspace(0.0, 40.0, 161), [77.7, 150.0, 400.0, 1000.0]])
    phi, _, _ = cf3(s, beta)
    assert np.max(np.abs(phi - _density_cf(s, beta))) < 1e-12


@pytest.mark.parametrize("beta", [0.5, 2.0, 8.0])
def test_derivatives_against_central_differences(beta):
    # on both sides of the switch between the two forms (y = 5 is s = 5 beta sqrt 2)
    s = np.concatenate(
        [np.linspace(0.3, 25.0, 40), 5.0 * beta * math.sqrt(2.0) + np.array([-0.01, 0.01]), [60.0, 300.0, 2500.0]]
    )
    phi, d1, d2 = cf3(s, beta, 2)
    h = 1e-5
    fp, _, _ = cf3(s + h, beta)
    fm, _, _ = cf3(s - h, beta)
    assert np.allclose(d1, s * (fp - fm) / (2 * h), rtol=1e-6, atol=1e-7)
    _, d1p, _ = cf3(s + h, beta, 1)
    _, d1m, _ = cf3(s - h, beta, 1)
    assert np.allclose(d2, s * (d1p - d1m) / (2 * h), rtol=1e-6, atol=1e-7 * np.maximum(1.0, s / beta))
    _, d1o, d2o = cf3(s, beta, 1)
    assert d2o is None and np.array_equal(d1o, d1)  # the order asked changes what is returned, not the values


def test_phi_is_even_and_one_at_zero():
    phi, d1, d2 = cf3(np.array([0.0, -3.0, 3.0]), 2.0, 2)
    assert phi[0] == pytest.approx(1.0, abs=1e-15) and d1[0] == 0.0 and d2[0] == 0.0
    assert phi[1] == phi[2]


@pytest.mark.parametrize("beta", [0.5, 1.0, 2.0, 3.0, 8.0])
def test_far_envelope_bounds_the_characteristic_function(beta):
    """The exact series' far bound |phi(s)| <= a / s + c / s^2 (two integrations by parts) holds
    against the density's own quadrature, and is far below the envelope 2 f(0) / s for large s."""
    from tolsynth.probability.distributions import shape
    from tolsynth.solvers.exact_series import _far_factor

    sh = shape(f"truncnormal({beta})")
    a, c = _far_factor(sh)
    s = np.concatenate([np.linspace(0.5, 60.0, 400), np.geomspace(60.0, 1000.0, 200)])
    phi = _density_cf(s, beta)
    assert np.all(np.abs(phi) <= a / s + c / s**2 + 1e-13)
    # tight: the bound's leading term is the jump at the truncation point, reached as s grows
    assert a < 2.0 * sh.peak and np.max(np.abs(phi[s > 200] * s[s > 200])) > 0.9 * a
