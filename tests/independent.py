"""Independent references shared by the tests: the probability of a weighted sum of independent
uniform errors by FFT convolution of their densities (also with R on a cell edge, and the worst
direction by shrinking Fibonacci caps), evenly spread directions on the sphere, and the largest
principal sigma from the model's numeric sensitivity and NumPy's eigensolver, maximised over the
joint space by random poses refined with SciPy's SLSQP.
They share nothing with tolsynth's series of the characteristic function nor its certified bounds."""

from __future__ import annotations

import math

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


def fft_at_edge(X, R, n=1 << 12):
    """P(|X[k] . U| <= R) by tests/independent.py's FFT, with one dummy row (result dropped) that
    sets its grid so that R falls on a cell edge: the cells then sum to the distribution function
    at R itself (error ~ h^2: 5e-7 at n = 4096, 3e-8 at 16384, against 4e-5 and 5e-6 with R
    inside a cell).  The helper's grid: cells of h = 2 half / n centred on multiples of h, with
    half = 1.05 times the largest row sum."""
    X = np.atleast_2d(np.asarray(X, dtype=float))
    s = float(np.abs(X).sum(1).max())
    j = int(math.floor((R * n / (1.05 * s) - 1) / 2))  # R = (j + 1/2) h, the grid still wide enough
    dummy = np.zeros((1, X.shape[1]))
    dummy[0, 0] = R * n / (2 * j + 1) / 1.05  # the largest row sum of every chunk: one grid for all
    chunks = [X[a : a + 500] for a in range(0, X.shape[0], 500)]
    return np.concatenate([fft_probabilities(np.vstack([c, dummy]), R, n)[:-1] for c in chunks])


def _cap(center, radius, m):
    """m Fibonacci directions squeezed into the cap of the given radius (rad) about ``center``."""
    F = fibonacci_directions(m)
    theta = np.arccos(np.clip(F[:, 2], -1, 1)) * radius / math.pi
    phi = np.arctan2(F[:, 1], F[:, 0])
    local = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)
    c = np.asarray(center, dtype=float) / np.linalg.norm(center)
    a = np.eye(3)[int(np.argmin(np.abs(c)))]
    e1 = np.cross(c, a)
    e1 /= np.linalg.norm(e1)
    return local @ np.stack([e1, np.cross(c, e1), c])


def independent_worst(M, R, plane=False, n_final=1 << 14):
    """The lowest P(|u . dr| <= R) over unit u for dr = M Y (M 3 x n, Y uniform), and its u: a
    Fibonacci set over the sphere (in-plane angles for a planar error), then caps of radius
    0.15, 0.03, 0.006 and 0.0012 rad about the best three, the last value at n_final."""
    if plane:
        t = np.linspace(0, math.pi, 361)[:-1]
        U = np.stack([np.cos(t), np.sin(t), 0 * t], axis=1)
    else:
        U = fibonacci_directions(1200)
        U = U[U[:, 2] > 0]  # P is even in u
    P = fft_at_edge(U @ M, R)
    best = []
    for i in np.argsort(P):
        if all(abs(U[i] @ U[b]) < math.cos(0.15) for b in best):
            best.append(i)
        if len(best) == 3:
            break
    out = []
    for b in best:
        u = U[b]
        for r in (0.15, 0.03, 0.006, 0.0012):
            C = _cap(u, r, 60)
            if plane:  # stay in the plane of the error
                C[:, 2] = 0
                C /= np.linalg.norm(C, axis=1, keepdims=True)
            Pc = fft_at_edge(C @ M, R)
            u = C[int(np.argmin(Pc))]
        out.append((float(fft_at_edge((u @ M)[None], R, n_final)[0]), u))
    return min(out, key=lambda t: t[0])


def sigma_max(mech, Q, eps, c=3.0):
    """Largest principal sigma at poses Q (n, nq) (or one pose), variance ``eps^2 / c`` per
    parameter: the model's numeric sensitivity and NumPy's eigensolver."""
    out = []
    for q in np.atleast_2d(Q):
        A = mech.sensitivity(q, check_limits=False)[:3]
        out.append(math.sqrt(max(np.linalg.eigvalsh((A * (eps**2 / c)) @ A.T)[-1], 0.0)))
    return np.array(out)


def dense_then_local(m, eps, n, seed, fixed=None, refine=5):
    """Largest sigma_1 over the joint space: n random poses (``fixed`` joints held), those the
    package's feasibility test accepts, the best ``refine`` refined by SLSQP inside the limits and
    the joint constraints."""
    from scipy.optimize import minimize

    from tolsynth.kinematics.joint_space import _feasible, _limits

    lo, hi = _limits(m)
    rng = np.random.default_rng(seed)
    Q = lo + (hi - lo) * rng.random((n, len(lo)))
    if fixed:
        for j, v in fixed.items():
            Q[:, j] = v
            lo[j] = hi[j] = v
    Q = Q[_feasible(m, Q.T)]
    vals = sigma_max(m, Q, eps)
    names = list(m.joint_names)
    cons = []
    for c in m.spec.joint_constraints:
        a = np.zeros(len(lo))
        for jn, coef in c.terms.items():
            a[names.index(jn)] = coef
        cons += [
            {"type": "ineq", "fun": lambda q, a=a, u=c.upper: u - a @ q},
            {"type": "ineq", "fun": lambda q, a=a, l_=c.lower: a @ q - l_},
        ]
    best = vals.max()
    for q0 in Q[np.argsort(vals)[-refine:]]:
        r = minimize(
            lambda q: -sigma_max(m, q, eps)[0],
            q0,
            bounds=list(zip(lo, hi)),
            constraints=cons,
            method="SLSQP",
            options={"ftol": 1e-14, "maxiter": 300},
        )
        if r.success or r.status in (8, 9):
            q = np.clip(r.x, lo, hi)
            if _feasible(m, q[:, None])[0]:
                best = max(best, sigma_max(m, q, eps)[0])
    return best
