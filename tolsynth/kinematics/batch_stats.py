"""The analytic (linear, Gaussian) error statistics on whole batches of poses.

:func:`principal_std_batch` gives the same numbers as ``Mechanism.analyze(q, ...).principal_std``
for thousands of poses at once, by evaluating the model's sensitivity graph and the package's
covariance graph with :class:`tolsynth.kinematics.numpy_eval.NumpyEvaluator` (not second copies of either).
The evaluators are cached per mechanism.  Used by the pose search and the workspace map.
Units: mm and rad; tolerances in each parameter's tolerance unit.
"""

from __future__ import annotations

import weakref

import numpy as np

from tolsynth.kinematics.numpy_eval import NumpyEvaluator
from tolsynth.probability.stats import covariance_graph, p_ball_batch, variance_divisor

__all__ = ["principal_std_batch"]

_CACHE: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _cache(mech) -> dict:
    c = _CACHE.get(mech)
    if c is None:
        c = _CACHE[mech] = {}
    return c


def _evaluator(mech, name: str) -> NumpyEvaluator:
    c = _cache(mech)
    if name not in c:
        if name == "covariance":
            c[name] = NumpyEvaluator(covariance_graph(mech.n))
        else:
            c[name] = NumpyEvaluator(getattr(mech.graphs, name))
    return c[name]


#: batches up to this size are evaluated by CasADi's own virtual machine (about 11 us per pose for
#: xu_zhang_1988) rather than the NumPy interpreter (about 1.6 ms per call plus 0.8 us per pose):
#: the pattern search's polls are a few dozen poses each
SMALL_BATCH = 128


def _small_maps(mech, N: int):
    """The sensitivity and covariance graphs mapped over N poses (cached per mechanism and N)."""
    c = _cache(mech)
    key = ("small_maps", N)
    if key not in c:
        c[key] = (mech.graphs.sensitivity.map(N), covariance_graph(mech.n).map(N))
    return c[key]


def principal_std_batch(mechanism, Q: np.ndarray, tolerances, distribution=None) -> np.ndarray:
    """Principal standard deviations (mm, descending) of the linearised position error at many poses.

    Parameters
    ----------
    mechanism : Mechanism
    Q : ndarray, shape (n_joints, N)
        Joint values (rad), one pose per column.  Not checked against the limits.
    tolerances : str, dict or array
        Tolerance set name or half-widths in tolerance units.
    distribution : str or dict, optional
        As :func:`tolsynth.synthesize` (default: the model file's, else uniform).

    Returns
    -------
    ndarray, shape (N, 3)
        The same numbers as ``mechanism.analyze(q, ...).principal_std`` for each column.
    """
    from tolsynth.probability.distributions import resolve

    eps = mechanism.tolerances(tolerances)
    distribution = resolve(distribution, mechanism)  # None: the model's own shapes (was an error)
    c = np.broadcast_to(np.asarray(variance_divisor(distribution, mechanism), dtype=float), (mechanism.n,))
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    sens = _evaluator(mechanism, "sensitivity")
    cov = _evaluator(mechanism, "covariance")
    out = np.empty((Q.shape[1], 3))
    chunk = 20000
    for a in range(0, Q.shape[1], chunk):
        Qc = Q[:, a : a + chunk]
        if Qc.shape[1] <= SMALL_BATCH:  # CasADi's own evaluation of the same graphs (a map)
            sm, cm = _small_maps(mechanism, Qc.shape[1])
            S = np.asarray(sm(Qc, np.zeros(mechanism.n)))  # (6, n N): the S side by side
            V = np.asarray(cm(S, eps, c)[0]).reshape(3, -1, 3).transpose(1, 0, 2)  # (N, 3, 3) mm^2
        else:
            S = sens.dense(0, sens([Qc, np.zeros(mechanism.n)])[0])  # (6, n, N)
            S = S.transpose(1, 0, 2).reshape(6 * mechanism.n, -1)  # column-major vec of each S
            V = cov.dense(0, cov([S, eps, c])[0]).transpose(2, 0, 1)  # (N, 3, 3) mm^2
        # a parallel robot's sensitivities are NaN where the platform is not assembled: NaN sigmas
        good = np.all(np.isfinite(V), axis=(1, 2))
        lam = np.full((V.shape[0], 3), np.nan)
        lam[good] = np.linalg.eigvalsh(0.5 * (V[good] + V[good].transpose(0, 2, 1)))[:, ::-1]
        floor = 1e-15 * np.maximum(lam[:, :1], 0.0)
        lam = np.where(lam <= floor, 0.0, lam)
        out[a : a + chunk] = np.sqrt(lam)
    return out


def _criterion_batch(mech, Q, eps, distribution, criterion, R, tol: float = 1e-12):
    """Values to be *maximised* (sigma_1, or -P), plus sigma (N,3) and P (N,) for the report.
    ``tol``: the error allowed in P (p_ball_batch's; a search may screen with a looser one)."""
    sig = principal_std_batch(mech, Q, eps, distribution)
    if criterion == "sigma":
        return sig[:, 0], sig, None
    P = np.full(sig.shape[0], np.nan)
    good = np.all(np.isfinite(sig), axis=1)
    P[good] = p_ball_batch(sig[good] ** 2, R, tol=tol)
    return -P, sig, P
