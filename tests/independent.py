"""Independent references shared by the tests: the probability of a weighted sum of independent
uniform errors by FFT convolution of their densities, and evenly spread directions on the sphere.
They share nothing with tolsynth's series of the characteristic function."""

from __future__ import annotations

import numpy as np


def fft_probabilities(X, R, n=1 << 12):
    """P(|sum_i X[k, i] U_i| <= R) for each row k, U_i independent uniform on [-1, 1], by FFT
    convolution of the uniform densities discretised as cell masses on one grid (error ~ 1e-5)."""
    X = np.atleast_2d(np.asarray(X, dtype=float))
    half = float(np.abs(X).sum(1).max()) * 1.05
    h = 2 * half / n
    grid = (np.arange(n) - n // 2) * h
    lo, hi = grid - h / 2, grid + h / 2
    spectrum = np.ones((X.shape[0], n // 2 + 1), complex)
    for xi in np.abs(X).T:
        xi = np.maximum(xi, 1e-300)[:, None]
        mass = np.clip(np.minimum(hi, xi) - np.maximum(lo, -xi), 0, None)
        mass /= mass.sum(1, keepdims=True)
        spectrum *= np.fft.rfft(np.fft.ifftshift(mass, axes=1), axis=1)
    dens = np.fft.fftshift(np.fft.irfft(spectrum, n, axis=1), axes=1)
    return dens[:, np.abs(grid) <= R].sum(1)


def fibonacci_directions(n):
    """n unit vectors spread evenly over the sphere (the Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z**2)
    phi = np.pi * (1 + 5**0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
