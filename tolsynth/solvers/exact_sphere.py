"""``criterion="sphere"`` with exact probabilities: ``P(|dr| <= R) >= p`` at every pose.

``P(|dr| <= R)`` is the mean over unit directions ``v`` of the sphere kernel series of
:mod:`tolsynth.probability.exact` (the Radon identity), here on a fixed hemisphere rule
(``nodes`` Gauss-Legendre in ``v_z`` x ``2 nodes`` azimuths), or, for an error in a plane, on the
planar rule of :mod:`tolsynth.probability.exact_sphere` (azimuths in the plane, radial pieces at
the break points of the design the solve starts from): a weighted sum of per-direction series, so
the interior-point method of :mod:`.exact_newton` reads its value, gradient and Hessian in
``u = ln eps`` like those of a direction cut.  The rules converge algebraically (the integrand is
only as smooth as the density of ``v . dr``), so after each solve the sphere probability is
recomputed by the error-controlled :func:`tolsynth.probability.exact.ball_probability`, and the
next solve's target is p plus the rule's error read at that design, until the independent value
lies in ``[p - SPHERE_TOL / 2, p + SPHERE_TOL]``: met, and not over-tight.  A design that met p
is kept should a later round miss it.

The sphere problem is not known to be convex.  Its lower bound is the certified optimum of the
per-component problem at the same p and poses (the sphere lies inside every slab
``|w . dr| <= R``, so its feasible set is inside that problem's), reported with its gap.  A design
that meets the sphere by the independent check has status ``FEASIBLE`` (``success`` False): it is
usable, but nothing proves it optimal, and the gap (10 to 30 % of the cost on the paper's robot)
bounds how much cheaper a design could be.  (The Gaussian criterion's tighter box relaxation of
:mod:`.sphere_bound` needs independent principal components, which only normal errors have.)
"""

from __future__ import annotations

import time

import numpy as np

from tolsynth.probability.exact_parts import part_of
from tolsynth.probability.exact_sphere import azimuths, planar_part, radial_nodes
from tolsynth.problem.nlp import ToleranceNLP
from tolsynth.problem.result import ConstraintBlock, Status, SynthesisResult, optimality_gap
from tolsynth.solvers.exact_newton import Barrier, cost_function
from tolsynth.solvers.exact_series import derivatives

__all__ = ["solve_sphere", "SPHERE_TOL"]

#: the independent sphere probability meets p to this accuracy (its own error estimate 1e-7)
SPHERE_TOL = 1e-6
NODES = 12
#: the per-direction series' truncation tolerance (the rule's weights sum to at most 1)
SERIES_TOL = 1e-9
#: azimuths of the planar rule (directions in the error's plane) and nodes per radial piece: on the
#: planar 2R arm's design within 3e-7 of the independent value, and within 3e-7 again after a 2 %
#: change of the tolerances (the radial rule's 24 nodes change nothing in the seventh digit)
AZIMUTHS = 32
RADIAL = 12


class _Sphere:
    """The sphere blocks' margins ``(P - target) / (1 - p)`` on a rule fixed by :meth:`fix`."""

    def __init__(self, blocks, shapes, nodes: int):
        from tolsynth.probability.exact import _hemisphere

        self.dirs, self.weights = _hemisphere(nodes)
        self.blocks = blocks
        self.shapes = shapes
        self.parts = tuple(part_of(s) for s in shapes)
        self.p = np.array([p for _, _, p in blocks])
        self.target = self.p.copy()
        self.rules: list = []

    def fix(self, eps) -> None:
        """The rule of each block at ``eps``: ``P = const + sum w Q(c e^u, radius)``.  Where the
        error lies in a plane (to within a change of the sphere's probability below SPHERE_TOL / 10,
        the independent check's own test) the planar rule of
        :mod:`tolsynth.probability.exact_sphere`: the hemisphere's directions near the plane's
        normal see a very narrow distribution, whose kernel needs thousands of series terms, and
        its piecewise smooth integrand converges slowly.  Its radial pieces follow the break points
        at ``eps``, so the rule is fixed again before each solve."""
        self.rules = []
        for A, R, _ in self.blocks:
            plane = planar_part(A * eps, self.parts, SPHERE_TOL)
            if plane is None:
                self.rules.append((np.abs(self.dirs @ A), R, self.weights, 0.0, "hemisphere"))
                continue
            C = np.abs(azimuths(AZIMUTHS) @ (plane[1].T @ A))  # per tolerance unit, (azimuths, n)
            row, radii, w = radial_nodes(C * eps, self.parts, R, RADIAL)
            self.rules.append((C[row], radii, w, 1.0 - w.sum(), "planar"))

    def __call__(self, u, order):
        g, J, H = [], [], []
        bounded = all(pt.bounded for pt in self.parts)
        for C, R, w, const, _ in self.rules:
            # a direction whose bounded terms cannot reach its radius has Q = 1 near u exactly (all
            # mass inside, no density at the radius): the narrow ones, whose series are the longest
            R = np.broadcast_to(R, w.shape)
            live = C @ np.exp(u) >= R if bounded else np.ones(w.shape, dtype=bool)
            P, G, Hs, _, _ = derivatives(C[live], u, self.shapes, R[live], SERIES_TOL, order >= 2, ball=True)
            wl = w[live]
            g.append(const + w[~live].sum() + wl @ P)
            J.append(wl @ G)
            if order >= 2:
                H.append(np.einsum("d,dij->ij", wl, Hs))
        s = 1.0 / (1.0 - self.p)
        g = (np.array(g) - self.target) * s
        if order == 0:
            return g, None, None
        return g, np.array(J) * s[:, None], np.array(H) * s[:, None, None]

    def describe(self) -> str:
        kinds = {rule[-1] for rule in self.rules}
        return " and ".join(
            f"a {NODES} x {2 * NODES} hemisphere rule" if k == "hemisphere" else f"a planar rule ({AZIMUTHS} azimuths)"
            for k in sorted(kinds)
        )


def solve_sphere(
    nlp: ToleranceNLP, shapes: tuple, solver: str, comp: SynthesisResult, eps_start, opts: dict, t0: float
) -> SynthesisResult:
    """The sphere problem from ``eps_start`` (shrunk until it meets the sphere); ``comp`` is the
    certified per-component result at the same p, whose lower bound is this one's."""
    from tolsynth.probability.exact import ball_probability

    spec = nlp.spec
    scale = spec.col_scale
    blocks = [(np.asarray(b.A) / scale, float(b.R), float(b.p)) for b in spec.sphere_blocks]
    sph = _Sphere(blocks, shapes, NODES)
    cost_fn = cost_function(nlp)
    lu, uu = nlp.lu, nlp.uu
    free = uu - lu > 1e-12
    u = np.log(np.asarray(eps_start, dtype=float))
    history, iters, ok, message = [], 0, False, ""
    P_exact = np.zeros(len(blocks))
    kept = None  # the last design that met p: what a later round that misses it falls back to
    for rnd in range(int(opts["max_rounds"])):
        sph.fix(np.exp(u))
        if rnd:  # the new rule's error at the last design, read against the independent value there,
            # is nearly its error at the next one: aim at p + SPHERE_TOL / 4, from either side
            rule_P = sph(u, 0)[0] * (1.0 - sph.p) + sph.target
            sph.target = np.minimum(sph.p + 0.25 * SPHERE_TOL + rule_P - P_exact, 1 - 1e-12)
        s = 0.0
        for _ in range(80):  # a strictly feasible start: every tolerance shrunk by one factor
            v = np.where(free, np.clip(u - s, lu, uu), lu)
            if np.all(sph(v, 0)[0] > 1e-3):
                break
            s = 1e-3 if s == 0 else 2 * s
        res = Barrier(cost_fn, sph, lu, uu).solve(v, None, max_iter=int(opts["max_iter"]))
        iters += res.iterations
        u, ok, message = res.u, res.ok, res.message
        eps = np.exp(u)
        P_exact = np.array(
            [ball_probability(A, eps, shapes, R, tol=1e-7, max_nodes=128, return_error=True)[0] for A, R, _ in blocks]
        )
        history.append(
            {
                "round": rnd,
                "newton": res.iterations,
                "cost": nlp.cost(eps),
                "P": P_exact.tolist(),
                "target": sph.target.tolist(),
            }
        )
        if not ok:
            break
        if np.all(P_exact >= sph.p - 0.5 * SPHERE_TOL):
            kept = (u, P_exact, message, sph.describe())
            if np.all(P_exact <= sph.p + SPHERE_TOL):
                break
    rule = sph.describe()
    if kept is not None and not (ok and np.all(P_exact >= sph.p - 0.5 * SPHERE_TOL)):
        u, P_exact, message, rule = kept
        ok = True
    eps = np.minimum(np.maximum(np.exp(u), spec.lower), spec.upper)
    cost = nlp.cost(eps)
    lower = comp.lower_bound if comp.success else -np.inf  # an uncertified component solve bounds nothing
    cblocks = tuple(
        ConstraintBlock(
            b.label,
            b.pose,
            "sphere (exact)",
            np.array([(1 - P) / (1 - b.p)]),
            np.zeros((3, 1)),
            np.array([(1 - P) / (1 - b.p) >= 1 - 1e-6]),
            np.zeros(1),
        )
        for b, P in zip(spec.sphere_blocks, P_exact)
    )
    met = bool(np.all(P_exact >= sph.p - SPHERE_TOL))
    detail = (
        f"sphere probability by {rule}, checked by the error-controlled "
        f"quadrature (P = {', '.join(f'{P:.7f}' for P in P_exact)}); lower bound: the certified optimum of the "
        f"per-component problem at the same p ({comp.cost:.8g}, {comp.status}); the sphere problem is not known "
        f"to be convex, so the gap {cost - lower:.4g} is not a certificate; {message}"
    )
    if ok and met:
        status = Status.FEASIBLE
        text = (
            "exact probabilities, sphere criterion met, optimality not proven (a local optimum; gap "
            f"{(cost - lower) / cost:.1%} of the cost): " + detail
        )
    elif not ok and message.startswith("iteration limit"):  # a limit the caller can raise, not a failure
        status = Status.ITERATION_LIMIT
        text = (
            "exact probabilities, sphere criterion: the interior-point solve stopped at its iteration limit "
            f"(max_iter={opts['max_iter']}) before converging: " + detail
        )
    else:
        status = Status.NUMERICAL_ERROR
        text = "exact probabilities, sphere criterion: " + ("not met: " if not met else "not converged: ") + detail
    return SynthesisResult(
        solver=solver,
        status=status,
        success=False,
        message=text,
        tolerances=dict(zip(spec.names, map(float, eps))),
        units=dict(zip(spec.names, spec.units)),
        cost=cost,
        constraints=cblocks,
        bounds_active={},
        bound_multipliers={},
        lower_bound=lower,
        gap=optimality_gap(cost, lower),
        iterations=iters,
        function_evaluations=0,
        wall_time=time.perf_counter() - t0,
        spec=spec,
        history=history,
    )
