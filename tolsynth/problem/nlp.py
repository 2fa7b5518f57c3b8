"""The tolerance-synthesis problem of the paper's Eq. 23, built once as CasADi graphs.

Decision variables are ``u_i = ln eps_i`` (``eps_i`` in the tolerance unit of parameter i).  In
these variables

* the cost ``f(u) = sum_i k_i exp(-alpha_i u_i)`` (Eq. 11-12, the paper's units) is convex;
* the accuracy demand of Eq. 20, "every principal sigma_j of the hand position satisfies
  sigma_j z(p) / R <= 1", is the matrix inequality

      G(u) = I - (z/R)^2 V(eps) >= 0  (positive semi-definite),
      V(eps) = sum_i eps_i^2 a_i a_i^T / c,   c = 3 (uniform) or 9 (normal),

  and ``eps_i^2 a_i a_i^T = exp(2 u_i) a_i a_i^T`` is matrix-convex in u, so the feasible set is
  convex.  Eq. 21 (orientation, with Phi) is the same with the orientation rows;
* the bounds of Eq. 22 are a box in u.

So the problem is convex and any KKT point is the global optimum; :meth:`ToleranceNLP.dual_bound`
turns the multiplier matrix of the LMI into a rigorous lower bound on the optimal cost (a
certificate).  The specification (R, z(p), Phi, c, alpha, k, the sensitivities at each pose) enters
as CasADi *parameters*, so a sweep re-solves the same graph without rebuilding it.

Both solvers read the graphs of this module: IPOPT the cost and ``G`` (through the factor form
``G = L L^T``), SUMT the cost and ``-ln det G`` (the interior penalty; see
:mod:`tolsynth.solvers.sumt`).

Beyond the paper, ``criterion="sphere"`` asks for ``P(|dr| <= R) >= p`` itself (the sphere of Eq.
5/13, which the paper replaces by the per-component Eq. 14/20).  Its probability is a smooth
function of the covariance, ``P = mean over unit v of F_3(R / sqrt(v^T V v))`` (``F_3`` the chi
CDF; no eigen-decomposition), written as a CasADi expression with a fixed product quadrature over
the hemisphere (:func:`sphere_graph`) and checked a posteriori against :func:`tolsynth.probability.stats.p_ball`.
That problem is not known to be convex; its lower bound is the optimum of the per-component
problem with the same p, which contains it (the sphere lies inside every component's slab).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property, lru_cache

import casadi as ca
import numpy as np

from tolsynth.errors import InfeasibleSpecificationError
from tolsynth.probability.stats import chi3_cdf, covariance_graph
from tolsynth.problem.specification import SPHERE_NODES, Specification

__all__ = ["ToleranceNLP", "NLPGraphs", "cost_graph", "nlp_graphs", "sphere_graph", "eigh"]


# ---------------------------------------------------------------------------------------------
# the graphs (built once per problem size, cached)
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class NLPGraphs:
    n: int
    m: int  # number of 3x3 blocks
    cost: ca.Function  # (u, theta) -> f (tolsynth.model.cost: one model per parameter)
    lmi: ca.Function  # (u, P) -> G (3 x 3m, blocks side by side)
    params: int  # length of the parameter vector P


def cost_graph(n: int, cost_signature: tuple | None = None) -> ca.Function:
    """``cost(u, theta) -> f = sum_i c_i(u_i)`` in ``u = ln eps``, one model per parameter
    (:mod:`tolsynth.model.cost`; ``cost_signature`` is :attr:`CostSet.signature`, default the paper's
    ``k eps^-alpha``, Eq. 11-12, for every parameter); the models' numbers are the parameter ``theta``
    (:attr:`ToleranceNLP.theta`)."""
    from tolsynth.model.cost_set import _cost_graph

    return _cost_graph(cost_signature if cost_signature is not None else (("power", 2),) * n)


@lru_cache(maxsize=None)
def nlp_graphs(n: int, m: int, cost_signature: tuple | None = None) -> NLPGraphs:
    """Cost and LMI graphs for n parameters and m accuracy blocks.

    Parameter vector ``P = [c, scale_1..scale_m, vec(A_1)..vec(A_m)]`` with ``A_b`` 3 x n.
    ``G_b = I - scale_b^2 Vb(eps)``, with ``Vb`` from the shared covariance graph of
    :mod:`tolsynth.probability.stats`.
    """
    u = ca.SX.sym("u", n)
    cost = cost_graph(n, cost_signature)

    P = ca.SX.sym("P", 1 + m + 3 * n * m)
    c = P[0]
    eps = ca.exp(u)
    cov = covariance_graph(n)
    blocks = []
    for b in range(m):
        scale = P[1 + b]
        A = ca.reshape(P[1 + m + 3 * n * b : 1 + m + 3 * n * (b + 1)], 3, n)
        S6 = ca.vertcat(A, ca.SX.zeros(3, n))
        Vb, _ = cov(S6, eps, c)
        blocks.append(ca.SX.eye(3) - scale**2 * Vb)
    G = ca.horzcat(*blocks)
    lmi = ca.Function("lmi", [u, P], [G], ["u", "P"], ["G"])
    return NLPGraphs(n=n, m=m, cost=cost, lmi=lmi, params=1 + m + 3 * n * m)


@lru_cache(maxsize=None)
def sphere_graph(n: int, m: int, nodes: int = SPHERE_NODES) -> ca.Function:
    """``sphere(u, Ps) -> P`` (m x 1): ``P(|dr| <= R_b)`` at m poses, a smooth CasADi expression.

    ``Ps = [c, R_1..R_m, vec(A_1)..vec(A_m)]``.  With ``w ~ N(0, V)`` written ``w = V^(1/2) r v``
    (``r`` chi-distributed with 3 degrees of freedom, ``v`` uniform on the unit sphere),
    ``|w|^2 = r^2 v^T V v``, so ``P = mean_v F_3(R / sqrt(v^T V v))``: Gauss-Legendre in ``v_z`` on
    the upper hemisphere (``v`` and ``-v`` give the same term) times the trapezoid rule in the
    azimuth (periodic), ``nodes`` x ``2 nodes`` points.  V comes from the shared covariance graph.
    """
    u = ca.SX.sym("u", n)
    Ps = ca.SX.sym("Ps", 1 + m + 3 * n * m)
    c = Ps[0]
    cov = covariance_graph(n)
    x, w = np.polynomial.legendre.leggauss(nodes)
    z, wz = 0.5 * (x + 1.0), 0.5 * w
    phi = 2 * math.pi * np.arange(2 * nodes) / (2 * nodes)
    s = np.sqrt(1.0 - z**2)
    dirs = np.stack([np.outer(s, np.cos(phi)).ravel(), np.outer(s, np.sin(phi)).ravel(), np.repeat(z, 2 * nodes)])
    weights = np.repeat(wz, 2 * nodes) / (2 * nodes)
    out = []
    for b in range(m):
        A = ca.reshape(Ps[1 + m + 3 * n * b : 1 + m + 3 * n * (b + 1)], 3, n)
        Vb, _ = cov(ca.vertcat(A, ca.SX.zeros(3, n)), ca.exp(u), c)
        q = ca.sum1(dirs * ca.mtimes(Vb, ca.DM(dirs)))  # v^T V v for every node, 1 x N
        xr = Ps[1 + b] / ca.sqrt(q)
        F = chi3_cdf(xr, ca.erf, ca.exp)
        out.append(ca.mtimes(F, ca.DM(weights)))
    return ca.Function("sphere", [u, Ps], [ca.vertcat(*out) if out else ca.SX(0, 1)], ["u", "Ps"], ["P"])


class ToleranceNLP:
    """The problem of one specification: its graphs, parameter values and helpers.

    The per-block LMI graph (:func:`nlp_graphs`, read by SUMT) is built on first use only: at
    hundreds of poses its SX graph is large, and IPOPT's exchange method never needs it.  The
    constraint values of *all* blocks are evaluated at once by :meth:`block_values` (the shared
    covariance graph on a batch, through :class:`tolsynth.kinematics.numpy_eval.NumpyEvaluator`).
    """

    def __init__(self, spec: Specification, sphere_nodes: int = SPHERE_NODES):
        self.spec = spec
        self.costs = spec.costs
        self.lu = np.log(spec.lower)
        self.uu = np.log(spec.upper)
        self.sphere_nodes = sphere_nodes
        self.p_sphere = np.array([b.p for b in spec.sphere_blocks]) if spec.sphere_blocks else np.zeros(0)
        # scaled rows of every block, (m, 3, n): block b's constraint is lambda_max(As V As^T) <= 1
        self.scales = np.array([b.scale for b in spec.blocks])
        self.As = (
            self.scales[:, None, None] * np.array([b.A for b in spec.blocks]).reshape(-1, 3, spec.n)
            if spec.blocks
            else np.zeros((0, 3, spec.n))
        )
        self._graphs = None
        self._values_memo = None  # (eps bytes, block_values at eps): the last point asked

    @property
    def theta(self) -> np.ndarray:
        """The cost models' numbers, the parameter of :func:`cost_graph` (the interior-point
        method reads the power law's arrays instead)."""
        return self.costs.theta

    # the graphs' parameter vectors, built on first use (IPOPT's exchange method reads neither)
    @cached_property
    def P(self) -> np.ndarray:
        """``[c, scale_1..scale_m, vec(A_1)..vec(A_m)]``, the parameter of :func:`nlp_graphs`' LMI."""
        spec = self.spec
        return np.concatenate([[spec.c], [b.scale for b in spec.blocks]] + [b.A.ravel(order="F") for b in spec.blocks])

    @cached_property
    def sphere(self) -> ca.Function:
        """``P(|dr| <= R_b)`` of the sphere blocks (:func:`sphere_graph`)."""
        return sphere_graph(self.spec.n, len(self.spec.sphere_blocks), self.sphere_nodes)

    @cached_property
    def Ps(self) -> np.ndarray:
        """``[c, R_1..R_m, vec(A_1)..vec(A_m)]`` of the sphere blocks, the parameter of :attr:`sphere`."""
        sb = self.spec.sphere_blocks
        return np.concatenate([[self.spec.c], [b.R for b in sb]] + [b.A.ravel(order="F") for b in sb])

    @property
    def graphs(self) -> "NLPGraphs":
        """Cost and LMI graphs of this problem's size (built on first use)."""
        if self._graphs is None:
            self._graphs = nlp_graphs(self.spec.n, len(self.spec.blocks), self.costs.signature)
        return self._graphs

    # -- evaluations (NumPy in, NumPy out) ----------------------------------------------------
    def cost(self, eps: np.ndarray, u: np.ndarray | None = None) -> float:
        """The cost at ``eps`` (``u = ln eps`` if the caller has it): NumPy for the paper's power law
        (:meth:`CostSet.total`, the same expression as the graph's), else the cost graph the
        solvers read."""
        u = np.log(eps) if u is None else u
        f = self.costs.total(u)
        return f if f is not None else float(cost_graph(self.spec.n, self.costs.signature)(u, self.theta))

    def G(self, eps: np.ndarray) -> list[np.ndarray]:
        Gm = np.array(self.graphs.lmi(np.log(eps), self.P))
        return [Gm[:, 3 * b : 3 * b + 3] for b in range(len(self.spec.blocks))]

    def block_covariances(self, eps: np.ndarray) -> np.ndarray:
        """``scale_b^2 V_b(eps)`` of every block, shape (m, 3, 3) (block b's constraint is
        ``lambda_max <= 1``): the covariance ``S diag(eps^2 / c) S^T`` of
        :func:`tolsynth.probability.stats.covariance_graph` on the whole stack of blocks at once (one einsum;
        the tests check it against that graph)."""
        w = np.asarray(eps, dtype=float) ** 2 / self.spec.c
        return (self.As * w) @ self.As.transpose(0, 2, 1)  # tiny matrices: matmul beats einsum's path search

    def block_values(self, eps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``sigma_j z / R`` (or ``/ Phi``) of every block, descending, shape (m, 3), and the
        principal directions (m, 3, 3; columns), by NumPy's batched symmetric eigensolver.

        The last point's answer is remembered (the exchange's check, the result's constraint values
        and the certificate all ask at the solver's point): callers must not modify the arrays."""
        eps = np.asarray(eps, dtype=float)
        key = eps.tobytes()
        memo = self._values_memo
        if memo is not None and memo[0] == key:
            return memo[1]
        # eigh reads the lower triangle only (V is symmetric by construction; no symmetrising)
        lam, vec = eigh(self.block_covariances(eps))
        out = np.sqrt(np.maximum(lam[:, ::-1], 0.0)), vec[:, :, ::-1]
        self._values_memo = (key, out)
        return out

    def constraint_values(self, eps: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per block: the paper's ``sigma_j * z / R`` (descending) and the principal directions."""
        vals, dirs = self.block_values(eps)
        return list(zip(vals, dirs))

    def sphere_quadrature(self, eps: np.ndarray) -> np.ndarray:
        """``P(|dr| <= R)`` per sphere block by the graph's fixed quadrature (what the solvers see)."""
        return np.array(self.sphere(np.log(eps), self.Ps)).ravel()

    def sphere_values(self, eps: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, float]]:
        """Per sphere block: ``[(1 - P) / (1 - p)]`` (<= 1 meets it), the principal directions and
        P itself, with P by the error-controlled quadrature of :func:`tolsynth.probability.stats.p_ball`."""
        out = []
        if not self.spec.sphere_blocks:
            return out
        from tolsynth.probability.stats import p_ball, principal

        cov = covariance_graph(self.spec.n)
        for b in self.spec.sphere_blocks:
            V, _ = cov(np.vstack([b.A, np.zeros_like(b.A)]), eps, self.spec.c)
            sig, dirs = principal(np.array(V))
            P = p_ball(sig**2, b.R)
            out.append((np.array([(1.0 - P) / (1.0 - b.p)]), dirs, P))
        return out

    def all_values(self, eps: np.ndarray) -> list[np.ndarray]:
        """Constraint values of every block (LMI blocks, then sphere blocks); each <= 1 to meet it."""
        return [v for v, _ in self.constraint_values(eps)] + [v for v, _, _ in self.sphere_values(eps)]

    # -- feasibility ----------------------------------------------------------------------------
    def check_feasible(self, refute=None) -> None:
        """Raise :class:`InfeasibleSpecificationError` if even the tightest tolerances (all at
        their lower bounds) violate a constraint: V grows with every eps, so nothing else can
        do better.  ``refute`` (the exact reading's, see :func:`tolsynth.model.locks.check_locks`):
        a block the Gaussian values break is refused only if ``refute(block index, lower)`` proves
        it, with the exact value in the message."""
        spec = self.spec
        # lambda_max(A_b diag(lower^2) A_b^T) is free of z/R and c: remembered by the blocks' rows
        # and the lower bounds (a sweep over R, p or the distribution checks the same again)
        key = (b"".join(b.A.tobytes() for b in spec.blocks), spec.lower.tobytes())
        raw = _LOWER_RAW.get(key)
        if raw is None:
            worst = self.block_values(spec.lower)[0][:, 0]
            if len(_LOWER_RAW) >= 256:
                _LOWER_RAW.clear()
            _LOWER_RAW[key] = (worst / self.scales) ** 2 * spec.c
        else:
            worst = np.sqrt(raw * self.scales**2 / spec.c)
        spheres = self.sphere_values(spec.lower) if spec.sphere_blocks else []
        bad = [(float(worst[i]), i) for i in (worst > 1.0).nonzero()[0]]
        bad += [(float(v[0]), len(spec.blocks) + j) for j, (v, _, _) in enumerate(spheres) if v[0] > 1.0]
        if refute is not None:  # the most violated first: the likeliest to be proven
            bad.sort(reverse=True)
        for value, i in bad:
            if i >= len(spec.blocks):
                block = spec.sphere_blocks[i - len(spec.blocks)]
                text = f"P = {spheres[i - len(spec.blocks)][2]:.6g} < p = {block.p:g}"
                relax = "R or p"
            else:
                block = spec.blocks[i]
                text = f"largest principal sigma*{'z/R' if block.kind == 'position' else 'z/Phi'} = {value:.6g} > 1"
                relax = "R/Phi or p"
            if refute is not None:
                proof = refute(i, spec.lower)
                if proof is None:  # the Gaussian reading's failure, not the exact one's
                    continue
                value, text = proof
            raise InfeasibleSpecificationError(
                block.label,
                float(value),
                f"infeasible specification: the {block.label} fails even with every tolerance at its "
                f"lower bound: {text}.  Lower the bounds, or relax {relax}.",
            )

    def interior_start(self, target: float = 0.5) -> np.ndarray:
        """A strictly feasible point, strictly inside the bounds: ``eps_i = lower_i^(1-t) upper_i^t``
        with every constraint value squared ``<= target``, where the target is raised towards 1
        when even the lower bounds give more than it (a specification close to its limit R0 is
        still strictly feasible, just with less room).  t by bisection (V is monotone in t); used
        by SUMT, whose barrier needs an interior start (IPOPT does not: see :meth:`start_point`).
        """
        lo, hi = self.lu, self.uu

        def worst(t):
            eps = np.exp(lo + t * (hi - lo))
            return max(float(v[0]) ** 2 for v in self.all_values(eps))

        w0 = worst(0.0)
        target = max(target, 0.5 * (w0 + 1.0)) if w0 < 1.0 else target
        if worst(0.5) <= target:
            t = 0.5
        else:
            a, b = 0.0, 0.5
            for _ in range(60):
                mid = 0.5 * (a + b)
                if worst(mid) <= target:
                    a = mid
                else:
                    b = mid
            t = a if a > 0 else 0.5 * b
        return np.exp(lo + t * (hi - lo))

    def start_point(self) -> np.ndarray:
        """A cheap start for IPOPT (which needs no interior point): the geometric middle of the
        bounds scaled as a whole so that the largest ``sigma z / R`` is about 1/2 (V is homogeneous
        of degree 2 in eps: one eigen-decomposition, no bisection), then clipped to the bounds."""
        mid = np.exp(0.5 * (self.lu + self.uu))
        if self.As.shape[0] == 0:
            return mid
        worst = float(np.max(self.block_values(mid)[0][:, 0]))
        t = 0.5 / worst if worst > 0 else 1.0
        return np.clip(mid * t, self.spec.lower, self.spec.upper)

    # -- certificate ------------------------------------------------------------------------------
    def kkt_multipliers(self, eps: np.ndarray, active_tol: float = 1e-6) -> list[np.ndarray]:
        """LMI multipliers recomputed from the primal point alone (least squares on stationarity).

        On each block, Z_b lives on the span of its active principal directions (complementary
        slackness), ``Z_b = D_b Y_b D_b^T``; stationarity in every u_i not at a bound,
        ``alpha_i k_i eps_i^-alpha_i = 2 eps_i^2 sum_b scale_b^2 a_bi^T Z_b a_bi / c``, is linear in
        the entries of the symmetric Y_b.  Independent of any solver's multipliers, so the dual
        bound from these certifies the returned point whichever solver found it.
        """
        spec = self.spec
        eps = np.asarray(eps, dtype=float)
        m = len(spec.blocks)
        Z = np.zeros((m, 3, 3))
        free = (eps > spec.lower * (1 + active_tol)) & (eps < spec.upper * (1 - active_tol))
        vals, dirs = self.block_values(eps)
        r_of = np.count_nonzero(vals >= 1.0 - active_tol, axis=1)  # values descend: active first
        blocks = np.nonzero(r_of)[0]
        if not len(blocks):
            return list(Z)
        cols, layout = [], []
        scale = 2.0 * eps**2 / spec.c
        for b in blocks:
            r = int(r_of[b])
            D = dirs[b][:, :r]
            proj = D.T @ self.As[b]  # r x n: components of scale_b a_bi along the active directions
            i, j = _TRIU[r]
            cols.append(np.where(i == j, 1.0, 2.0)[:, None] * proj[i] * proj[j] * scale)
            layout.append((b, r, D))
        M = np.concatenate(cols).T[free]
        rhs = -self.costs.du(np.log(eps))[free]
        y, *_ = np.linalg.lstsq(M, rhs, rcond=None)
        pos = 0
        for b, r, D in layout:
            i, j = _TRIU[r]
            Y = np.zeros((r, r))
            Y[i, j] = y[pos : pos + len(i)]
            Y[j, i] = Y[i, j]
            pos += len(i)
            Z[b] = D @ Y @ D.T
        return list(Z)

    def dual_weights(self, Z: Sequence[np.ndarray]) -> tuple[np.ndarray, float]:
        """``(w, tr)`` of the Lagrangian ``f(u) - sum_b tr(Z_b G_b(u)) = sum_i [c_i(u_i) + w_i e^{2u_i}]
        - tr`` for LMI multipliers ``Z_b`` (each projected onto the PSD cone first)."""
        m, n = self.As.shape[0], self.spec.n
        if m == 0:
            return np.zeros(n), 0.0
        Zs = np.asarray(Z, dtype=float).reshape(m, 3, 3)
        Zp = 0.5 * (Zs + Zs.transpose(0, 2, 1))
        lam, vec = eigh(Zp)
        if lam.min() < 0.0:  # the PSD projection (a PSD Z is its own)
            lam = np.maximum(lam, 0.0)
            Zp = (vec * lam[:, None, :]) @ vec.transpose(0, 2, 1)
        # w_i = sum_b (scale_b a_bi)^T Zp_b (scale_b a_bi) / c; tr Zp_b = sum of its eigenvalues
        w = ((Zp @ self.As) * self.As).sum(axis=(0, 1)) / self.spec.c
        return w, float(lam.sum())

    def dual_bound(self, Z: Sequence[np.ndarray]) -> float:
        """Lagrangian lower bound on the optimal cost for LMI multipliers ``Z_b`` (3x3).

        ``Z_b`` is projected onto the positive semi-definite cone first (any PSD Z gives a valid
        bound, weak duality), then ``min over the box of f(u) - sum_b tr(Z_b G_b(u))`` separates per
        parameter: ``c_i(u) + w_i e^{2u}`` (:meth:`dual_weights`), minimised by
        :meth:`tolsynth.model.cost.CostModel.dual_min` (closed form for the power law; exact where the cost
        is convex in eps^2, a rigorous lower bound otherwise).
        """
        return self.lagrangian_bound(*self.dual_weights(Z))

    def lagrangian_bound(self, w: np.ndarray, trace: float) -> float:
        """``min over the box of sum_i [c_i(u_i) + w_i e^{2u_i}] - trace``: the Lagrangian lower bound
        of :meth:`dual_bound` from its weights (``w >= 0``, the weights of PSD multipliers)."""
        vals, _ = self.costs.dual_min(w, self.lu, self.uu)
        return math.fsum(vals.tolist()) - trace


try:  # NumPy's LAPACK gufunc behind np.linalg.eigh (numpy/linalg/_umath_linalg, NumPy 1.8 to 2.x)
    from numpy.linalg import _umath_linalg

    _EIGH_LO = _umath_linalg.eigh_lo
except (ImportError, AttributeError):  # pragma: no cover - another NumPy: its public eigh
    _EIGH_LO = None


def eigh(V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.linalg.eigh(V)`` of a stack of real symmetric matrices (lower triangle read).

    NumPy's own gufunc is called directly: the public wrapper's type and shape checks take 5 of
    its 8 us on one 3x3 matrix, and every solve's feasibility check and certificate ask for this.
    Where the gufunc does not give finite eigenvalues (NaN input, LAPACK not converging) or is
    missing, ``np.linalg.eigh`` itself answers (and raises ``LinAlgError`` as before)."""
    if _EIGH_LO is not None and V.dtype == np.float64 and V.ndim >= 2:
        lam, vec = _EIGH_LO(V)
        if math.isfinite(lam.sum()):
            return lam, vec
    return np.linalg.eigh(V)


#: ToleranceNLP.check_feasible's lambda_max(A_b diag(lower^2) A_b^T) per block, by (A_b bytes, lower bytes)
_LOWER_RAW: dict = {}

#: upper-triangle index pairs of an r x r matrix, r = 0..3 (the entries of Y_b in kkt_multipliers)
_TRIU = {r: np.triu_indices(r) for r in range(4)}
