"""Independent references for the exact-probability tests: FFT convolution of the densities on a
fine grid, SciPy quadrature of two-term convolutions, Olds' formula for sums of uniforms in exact
rational arithmetic, and Wilson intervals for Monte Carlo counts.  None of them calls tolsynth's
evaluator."""

from __future__ import annotations

import math
from fractions import Fraction
from itertools import product

import numpy as np
from scipy import integrate, stats


def unit_distribution(name: str):
    """The SciPy distribution of one unit error Y (uniform, normal 3 sigma = 1, triangular,
    truncated normal with sigma = 1/beta on [-1, 1])."""
    key = name.strip().lower()
    if key == "uniform":
        return stats.uniform(-1.0, 2.0)
    if key == "normal":
        return stats.norm(0.0, 1.0 / 3.0)
    if key == "triangular":
        return stats.triang(0.5, -1.0, 2.0)
    beta = 2.0 if key == "truncnormal" else float(key[len("truncnormal(") : -1])
    return stats.truncnorm(-beta, beta, scale=1.0 / beta)


def wilson(hits: int, n: int, z: float = 3.29) -> tuple[float, float]:
    """A 99.9 % Wilson interval for a binomial proportion."""
    p = hits / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return max(c - h - 1e-12, 0.0), min(c + h + 1e-12, 1.0)  # the interval's ends to rounding


def olds(a, R) -> Fraction:
    """``P(|sum_i a_i U_i| <= R)`` for uniforms on [-1, 1], exactly: Olds (1952), the CDF of a sum of
    uniforms ``(1 / (m! prod 2a)) sum over sign vectors of (prod s) (x + sum s_i a_i)_+^m``, in
    rational arithmetic on the floats' exact values."""
    a = [Fraction(x) for x in a]
    R = Fraction(R)
    m = len(a)
    norm = math.factorial(m) * math.prod(2 * x for x in a)

    def cdf(x):
        total = Fraction(0)
        for s in product((1, -1), repeat=m):
            y = x + sum(si * ai for si, ai in zip(s, a))
            if y > 0:
                total += math.prod(s) * y**m
        return total / norm

    return cdf(R) - cdf(-R)


def two_term(b1: float, n1: str, b2: float, n2: str, R: float) -> tuple[float, float]:
    """``P(|b1 Y1 + b2 Y2| <= R)`` and the density of the sum at R, by SciPy quadrature over the
    smaller term's variable (the integrand is then smooth between the given break points)."""
    if b2 > b1:
        b1, n1, b2, n2 = b2, n2, b1, n1
    d1, d2 = unit_distribution(n1), unit_distribution(n2)
    lo, hi = (-12.0, 12.0) if n2 == "normal" else (-1.0, 1.0)
    # where the larger term's CDF has kinks (its support's ends, and the triangular's mode)
    pts = sorted({(e * R - k * b1) / b2 for e in (1, -1) for k in (-1, 0, 1)} | {0.0})
    pts = [x for x in pts if lo < x < hi]

    def fP(z):
        return d2.pdf(z) * (d1.cdf((R - b2 * z) / b1) - d1.cdf((-R - b2 * z) / b1))

    def fD(z):
        return d2.pdf(z) * d1.pdf((R - b2 * z) / b1) / b1

    kw = dict(points=pts or None, epsabs=1e-15, epsrel=1e-13, limit=500)
    return integrate.quad(fP, lo, hi, **kw)[0], integrate.quad(fD, lo, hi, **kw)[0]


def fft_probability(b, names, R, h: float, power: int = 1) -> float:
    """``P(|w| <= R)`` for ``w = sum_i b_i Y_i`` (each term ``power`` times) by FFT convolution of the
    terms' cell probabilities on grids of step h and h/2, Richardson-extrapolated (each grid's
    error is of order ``h^2`` times the number of terms and the density's slope)."""
    return (4.0 * _fft(b, names, R, 0.5 * h, power) - _fft(b, names, R, h, power)) / 3.0


def _fft(b, names, R, h: float, power: int) -> float:
    sig = math.sqrt(sum((x / 3.0) ** 2 for x, nm in zip(b, names) if nm == "normal") * power)
    W = power * sum(x for x, nm in zip(b, names) if nm != "normal") + 12.0 * sig + 2 * h
    N = 1 << int(math.ceil(math.log2(2 * W / h + 8)))
    j = np.arange(N)
    j = np.where(j < N // 2, j, j - N)  # grid points j h, wrapped
    spec = np.ones(N // 2 + 1, dtype=complex)
    for x, nm in zip(b, names):
        if x == 0:
            continue
        d = unit_distribution(nm)
        cells = d.cdf((j + 0.5) * h / x) - d.cdf((j - 0.5) * h / x)
        spec *= np.fft.rfft(cells) ** power
    pmf = np.fft.irfft(spec, N)
    k = np.abs(j * h)
    inside = pmf[k <= R - 0.5 * h].sum()
    edge = pmf[(k > R - 0.5 * h) & (k < R + 0.5 * h)]
    frac = (R - (k[(k > R - 0.5 * h) & (k < R + 0.5 * h)] - 0.5 * h)) / h  # the part of an edge cell inside
    return float(inside + np.sum(edge * frac))


# ----------------------------------------------------------------- the references checked themselves
def test_references_reproduce_closed_forms():
    """The references against closed forms they do not build on: Olds' formula for equal widths is
    Irwin-Hall; the two-term quadrature of two equal uniforms is the triangle; the FFT convolution
    of normals is erf."""
    n, R = 4, 1.3

    def ih(x):
        return sum((-1) ** k * math.comb(n, k) * (x - k) ** n for k in range(int(math.floor(x)) + 1)) / math.factorial(
            n
        )

    assert abs(float(olds([1.0] * n, R)) - (ih((n + R) / 2) - ih((n - R) / 2))) < 1e-15
    P, D = two_term(1.0, "uniform", 1.0, "uniform", 0.6)
    assert abs(P - (1 - 1.4**2 / 4)) < 1e-12 and abs(D - 1.4 / 4) < 1e-12
    s = math.sqrt(1 + 0.25) / 3
    assert abs(fft_probability([1.0, 0.5], ["normal", "normal"], 0.4, 1e-3) - math.erf(0.4 / (s * math.sqrt(2)))) < 1e-7
