"""The lean cvxpy + Clarabel model of tolsynth's problem: the reference of every speed ratio.

This is the model a competent cvxpy user writes for the paper's tolerance synthesis (Eq. 20, 22,
23: the per-component accuracy at a set of poses, the power-law cost, the bounds), with the data
taken from tolsynth's public API only (``load_model``, ``Mechanism.sensitivity``, ``.k``,
``.bounds``, ``.distribution``, ``.locks``, ``z_of_p``).

With ``v_i = eps_i^2`` and ``t_i = c_i (R / z)^2`` (``c_i`` the variance divisor of parameter i's
error shape: 3 uniform, 9 normal with 3 sigma = eps, 6 triangular; ``z = z_of_p(p)``), the
variables are ``w_i = v_i / t_i`` and the problem is

    minimise    sum_i K_i w_i^(-alpha_i / 2),      K_i = k_i t_i^(-alpha_i / 2)
    subject to  S_j diag(w) S_j^T <= I             (a 3x3 LMI per pose j)
                lower_i^2 / t_i <= w_i <= upper_i^2 / t_i

with ``S_j`` the 3 x n position sensitivity at pose j.  ``k eps^-alpha = K w^(-alpha/2)``, so the
objective is the paper's cost in its own units.  R, p, the error shapes and k enter only ``K`` and
the bounds on ``w``, which are cvxpy Parameters: a sweep over k, the bounds, a lock, R or p sets
them and re-solves the Problem built once (cvxpy keeps its canonicalisation).  A lock is the bound
``lower = upper``.  The exponent is different: ``cp.power(w, -alpha/2)`` needs a constant exponent
(a Parameter there is not DPP), so a new alpha rebuilds the Problem, which is what a cvxpy user
has to do too.  The powers are exact power cones (``approx=False``).

Clarabel runs with its defaults.  Where they fail (on 1000-pose sets they sometimes stop with
InsufficientProgress at a relative gap of 1e-3) the solve is repeated with shorter steps
(``FALLBACK``), both attempts counting in its time, and the result says so (``retried``).  At
its default tolerances Clarabel's cost lies up to about 1e-6 above the optimum (30-pose panda
sets, against tolsynth's certified lower bound); tightening them to 1e-10 takes about 1.8x the
iterations there, so the reference keeps the defaults.

Run ``python benchmarks/lean_cvxpy.py`` to check the model against ``tolsynth.synthesize`` (the
paper's column with a change of every kind, puma560 and panda at 10 random poses).
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

import tolsynth

__all__ = ["LeanModel", "LeanResult", "divisors", "random_poses"]

#: Clarabel settings of the second attempt when its defaults fail
FALLBACK = {"max_step_fraction": 0.9}

#: variance divisors eps^2 / Var(delta) of the error shapes with a closed form
_DIVISORS = {"uniform": 3.0, "normal": 9.0, "triangular": 6.0}


def _divisor(name: str) -> float:
    """``eps^2 / Var(delta)`` of one shape name: uniform 3, normal 9 (3 sigma = eps), triangular 6,
    ``truncnormal(beta)`` (sigma = eps / beta cut at +-eps; beta 2 by default) from the variance of
    a standard normal truncated at +-beta, ``1 - 2 beta phi(beta) / erf(beta / sqrt 2)``."""
    key = str(name).strip().lower().replace(" ", "")
    if key in _DIVISORS:
        return _DIVISORS[key]
    if key.startswith("truncnormal"):
        beta = 2.0 if key == "truncnormal" else float(key[len("truncnormal(") : -1])
        phi = math.exp(-0.5 * beta * beta) / math.sqrt(2 * math.pi)
        return beta * beta / (1.0 - 2.0 * beta * phi / math.erf(beta / math.sqrt(2.0)))
    raise ValueError(f"distribution: unknown shape {name!r}")


def divisors(mech, distribution=None) -> np.ndarray:
    """One variance divisor per error parameter: ``distribution`` is a shape name or a mapping name
    -> shape (``"*"`` the default of the others); None: the model file's (``mech.distribution``)."""
    dist = mech.distribution if distribution is None else distribution
    if isinstance(dist, Mapping):
        c = np.full(mech.n, _divisor(dist.get("*", "uniform")))
        for name, shp in dist.items():
            if name != "*":
                c[mech.index(name)] = _divisor(shp)
        return c
    return np.full(mech.n, _divisor(dist))


def _vector(value, mech, default) -> np.ndarray:
    """A number, one per parameter, or a mapping name -> value over ``default``."""
    if value is None:
        return np.array(default, dtype=float)
    if isinstance(value, Mapping):
        out = np.array(default, dtype=float)
        for name, v in value.items():
            out[mech.index(name)] = float(v)
        return out
    return np.broadcast_to(np.asarray(value, dtype=float), (mech.n,)).copy()


def random_poses(mech, N: int, rng) -> list[np.ndarray]:
    """N joint vectors (rad) drawn uniformly inside the joint limits, kept when the mechanism
    accepts them (its joint constraints too: ``Mechanism.joints`` raises OutOfRangeError)."""
    lo = np.array([j.lower for j in mech.spec.joints])
    hi = np.array([j.upper for j in mech.spec.joints])
    out = []
    while len(out) < N:
        q = lo + (hi - lo) * rng.random(len(lo))
        try:
            out.append(mech.joints(q))
        except tolsynth.OutOfRangeError:
            continue
    return out


@dataclass(frozen=True)
class LeanResult:
    """One solve: Clarabel's status (through cvxpy), the optimal cost (paper's units), the
    tolerances ``eps`` (tolerance units), Clarabel's own time (s) and iterations."""

    status: str
    cost: float
    eps: np.ndarray
    solve_time: float
    iterations: int
    retried: bool = False  # the defaults failed and FALLBACK solved it

    @property
    def success(self) -> bool:
        """Clarabel's optimum, also at its reduced accuracy ("optimal_inaccurate": on 1000 poses
        the cost still agrees with tolsynth's certified one to about 1e-8)."""
        return self.status in ("optimal", "optimal_inaccurate")


class LeanModel:
    """The lean cvxpy + Clarabel model at a fixed set of poses, built once.

    ``LeanModel(mechanism, poses=("worst",), distribution=None, alpha=0.7)``: ``mechanism`` a
    Mechanism or a bundled model's name; ``poses`` configuration names or joint vectors (rad);
    ``distribution`` a shape name or mapping name -> shape (None: the model's); ``alpha`` the cost
    exponent(s) the Problem is built with.  Construction evaluates the sensitivities and builds
    the cvxpy Problem; the first :meth:`solve` also canonicalises it (a cold solve is both).

    ``solve(R, p, k=None, alpha=None, lower=None, upper=None, locks=None)``: R in mm, p the
    per-component probability (Gaussian, ``z = tolsynth.z_of_p(p)``), k, alpha, lower and upper a
    number, one per parameter or a mapping name -> value (None: the model's, and alpha the
    current one), locks a mapping name -> tolerance (None: the model's own locks).  Everything but
    a new alpha only sets Parameters; a new alpha rebuilds the Problem (counted in ``rebuilds``).
    """

    def __init__(self, mechanism, poses=("worst",), distribution=None, alpha=0.7):
        self.mech = mech = tolsynth.load_model(mechanism) if isinstance(mechanism, str) else mechanism
        if mech.cost_models:
            raise ValueError("the lean model has the power-law cost only; this model declares other cost models")
        self.S = [mech.sensitivity(q)[:3] for q in poses]  # position rows, per tolerance unit
        self.B = [(S[:, None, :] * S[None, :, :]).reshape(9, mech.n) for S in self.S]
        self.c = divisors(mech, distribution)
        self.rebuilds = 0
        self.alpha = None
        self._build(_vector(alpha, mech, np.zeros(mech.n)))

    def _build(self, alpha: np.ndarray) -> None:
        n = self.mech.n
        self.alpha = alpha
        self.w = w = cp.Variable(n)
        self.K = cp.Parameter(n, nonneg=True)  # k t^(-alpha/2)
        self.lo = cp.Parameter(n, nonneg=True)  # lower^2 / t
        self.hi = cp.Parameter(n, nonneg=True)  # upper^2 / t
        terms = []
        for a in np.unique(alpha):  # one vector power per distinct exponent
            idx = np.nonzero(alpha == a)[0]
            if len(idx) == n:
                terms.append(self.K @ cp.power(w, -a / 2, approx=False))
            else:
                terms.append(self.K[idx] @ cp.power(w[idx], -a / 2, approx=False))
        # S diag(w) S^T as one 9 x n matrix times w (rows s_k * s_l): the same matrix as
        # S @ cp.diag(w) @ S.T, which cvxpy canonicalises about 1.3x slower
        I3 = np.eye(3)
        cons = [cp.reshape(B @ w, (3, 3), order="C") << I3 for B in self.B]
        cons += [w >= self.lo, w <= self.hi]
        self.problem = cp.Problem(cp.Minimize(cp.sum(terms) if len(terms) > 1 else terms[0]), cons)
        self.rebuilds += 1

    def solve(self, R, p, k=None, alpha=None, lower=None, upper=None, locks=None) -> LeanResult:
        mech = self.mech
        if alpha is not None:
            a = _vector(alpha, mech, self.alpha)
            if not np.array_equal(a, self.alpha):
                self._build(a)
        t = self.c * (R / tolsynth.z_of_p(p)) ** 2
        lo0, hi0 = mech.bounds
        lo, hi = _vector(lower, mech, lo0), _vector(upper, mech, hi0)
        locks = {**mech.locks, **mech.fixed_joint_errors} if locks is None else {**mech.fixed_joint_errors, **locks}
        for name, v in locks.items():
            i = mech.index(name)
            lo[i] = hi[i] = float(v)
        self.K.value = _vector(k, mech, mech.k) * t ** (-self.alpha / 2)
        self.lo.value = lo**2 / t
        self.hi.value = hi**2 / t
        retried = False
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # cvxpy's "solution may be inaccurate": the status says it
            try:
                self.problem.solve(solver="CLARABEL")
            except cp.error.SolverError:
                # Clarabel's defaults stall now and then on large pose sets (InsufficientProgress
                # at a gap of 1e-3, 1000 poses); shorter steps get through
                retried = True
                try:
                    self.problem.solve(solver="CLARABEL", **FALLBACK)
                except cp.error.SolverError as exc:
                    return LeanResult(f"solver error: {exc}", math.nan, np.full(mech.n, math.nan), math.nan, 0, True)
        w = self.w.value
        eps = np.sqrt(np.maximum(w, 0.0) * t) if w is not None else np.full(mech.n, math.nan)
        stats = self.problem.solver_stats
        value = self.problem.value
        return LeanResult(
            self.problem.status,
            float(value) if value is not None else math.nan,
            eps,
            float(stats.solve_time or math.nan),
            int(stats.num_iters or 0),
            retried,
        )


# -- the check against tolsynth ----------------------------------------------------------------
def _compare(label, lean_res, ts_res, rtol=1e-6):
    rel = abs(lean_res.cost - ts_res.cost) / abs(ts_res.cost)
    ok = lean_res.success and ts_res.success and rel <= rtol
    print(
        f"  {label:<52} tolsynth {ts_res.cost:.10g}  lean {lean_res.cost:.10g}  rel.diff {rel:.1e}  "
        f"{'ok' if ok else 'MISMATCH'} ({lean_res.status}, {lean_res.iterations} Clarabel iterations)"
    )
    return ok


def main() -> int:
    R, P, ALPHA = 0.5, 0.99, 0.7
    ok = True
    t0 = time.perf_counter()
    m = tolsynth.load_model("xu_zhang_1988")
    lm = LeanModel(m, ["worst"], "uniform", ALPHA)
    print("xu_zhang_1988, pose 'worst', R 0.5 mm, p 0.99, uniform, alpha 0.7 (the paper's column):")
    ts = tolsynth.synthesize(m, R, P, "uniform", ALPHA, probability="gaussian")
    ok &= _compare("paper's column", lm.solve(R, P), ts)
    eps = ts.x
    k2 = m.k * np.linspace(0.8, 1.3, m.n)
    ok &= _compare(
        "k varied per parameter",
        lm.solve(R, P, k=k2),
        tolsynth.synthesize(m, R, P, "uniform", ALPHA, k=k2, probability="gaussian"),
    )
    a2 = np.linspace(0.5, 0.9, m.n)
    ok &= _compare(
        "alpha per parameter (rebuilt)",
        lm.solve(R, P, alpha=a2),
        tolsynth.synthesize(m, R, P, "uniform", a2, probability="gaussian"),
    )
    lm.solve(R, P, alpha=ALPHA)
    names = m.error_parameters
    i = int(np.argmax(eps))
    hi = {names[i]: 0.8 * eps[i]}
    ok &= _compare(
        f"upper bound of {names[i]} at 0.8 x its optimum",
        lm.solve(R, P, upper=hi),
        tolsynth.synthesize(
            m, R, P, "uniform", ALPHA, bounds={names[i]: (m.bounds[0][i], hi[names[i]])}, probability="gaussian"
        ),
    )
    lock = {names[0]: 0.9 * eps[0]}
    ok &= _compare(
        f"{names[0]} locked at 0.9 x its optimum",
        lm.solve(R, P, locks=lock),
        tolsynth.synthesize(m, R, P, "uniform", ALPHA, locks=lock, probability="gaussian"),
    )
    ok &= _compare(
        "R 0.3 mm", lm.solve(0.3, P), tolsynth.synthesize(m, 0.3, P, "uniform", ALPHA, probability="gaussian")
    )
    ok &= _compare(
        "p 0.95", lm.solve(R, 0.95), tolsynth.synthesize(m, R, 0.95, "uniform", ALPHA, probability="gaussian")
    )
    ok &= _compare(
        "normal (3 sigma = eps)",
        LeanModel(m, ["worst"], "normal").solve(R, P),
        tolsynth.synthesize(m, R, P, "normal", ALPHA, probability="gaussian"),
    )
    mixed = {"*": "uniform", names[0]: "normal", names[-1]: "triangular", names[3]: "truncnormal(2.5)"}
    ok &= _compare(
        "mixed shapes (uniform, normal, triangular, truncnormal)",
        LeanModel(m, ["worst"], mixed).solve(R, P),
        tolsynth.synthesize(m, R, P, mixed, ALPHA, probability="gaussian"),
    )

    for name in ("puma560", "panda"):
        mech = tolsynth.load_model(name)
        poses = random_poses(mech, 10, np.random.default_rng(22))
        print(f"{name}, 10 random poses (seed 22), R 0.5 mm, p 0.99, uniform, alpha 0.7:")
        ts = tolsynth.synthesize(mech, R, P, "uniform", ALPHA, poses=poses, probability="gaussian")
        lm = LeanModel(mech, poses, "uniform", ALPHA)
        ok &= _compare("10 poses", lm.solve(R, P), ts)
        ok &= _compare(
            "R 0.2 mm, p 0.999",
            lm.solve(0.2, 0.999),
            tolsynth.synthesize(mech, 0.2, 0.999, "uniform", ALPHA, poses=poses, probability="gaussian"),
        )
    print(f"all agree to 1e-6: {bool(ok)} ({time.perf_counter() - t0:.1f} s)")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
