"""A parallel robot's kinematics as CasADi graphs: closed-form inverse kinematics, forward
kinematics by Newton's method on the graph, and the error model by the implicit function theorem.

The legs' closure equations (:mod:`tolsynth.model.parallel`) are ``f(x, q, delta) = 0`` with ``x``
the platform pose (its ``dof`` coordinates, mm and rad), ``q`` the actuators and ``delta`` the
error parameters (tolerance units): ``f_i = |C_i - B_i| - (q_i + offset_i)`` for a prismatic leg,
``f_i = |C_i - A_i(q_i)| - link_i`` for a revolute one.

Forward kinematics (``fk``, ``position``, ``pose``)
    Newton's method unrolled in the graph: from the home pose (solved once, from the file's
    assembly pose) along the straight line in actuator space from the home actuators to ``q``, in
    ``STAGES`` stages of ``STAGE_STEPS`` steps, then ``FINAL_STEPS`` steps at ``q``; the
    error-free pose found so depends on ``q`` only, and ``ERROR_STEPS`` more steps with the
    errors (a few microns against a metre: quadratic convergence from there) give the pose with
    errors.  The path follows the assembly mode of the home pose.  ``closure`` is the residual
    ``max |f|`` in units of ``residual_tol`` and the ratio of ``det df/dx`` to its home value: the
    platform is assembled, on the home pose's branch, iff both entries lie in ``[-1, 1]``.  Where
    it is not, every pose output is NaN (a sampler counts it as a failure, a search as infeasible),
    and :meth:`ParallelGraphs.check` raises a :class:`~tolsynth.errors.LoopClosureError`.
``sensitivity``
    ``dx/ddelta = -(df/dx)^-1 df/ddelta`` at the solved pose (both Jacobians exact, by CasADi's
    algorithmic differentiation of ``f``; no finite differences), mapped to the hand point's
    displacement and the platform's small rotation as :mod:`tolsynth.kinematics.graphs` does for
    a serial chain.
``ik``
    The actuators of a pose in closed form: a strut's length, or for a revolute leg
    ``phi = atan2(w.e, w.d0) + branch acos(K / |(w.d0, w.e)|)`` with ``w`` the platform anchor
    seen from the base anchor; the branch of each leg is the home configuration's.

Units: mm and rad; ``delta`` in each error parameter's tolerance unit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from tolsynth.errors import InputError, LoopClosureError, ModelFileError
from tolsynth.model.parallel import POSE_COORDINATES, ParallelSpec

__all__ = ["ParallelGraphs", "build_parallel_graphs", "COND_LIMIT"]

#: continuation stages from the home actuators to q, Newton steps per stage, at q, and with errors
STAGES, STAGE_STEPS, FINAL_STEPS, ERROR_STEPS = 4, 2, 4, 3
#: largest closure residual accepted, relative to the robot's largest dimension
RESIDUAL_REL = 1e-9
#: smallest det(df/dx) accepted, relative to its home value (a sign change is another branch)
DET_RATIO_MIN = 1e-9
#: largest condition number of df/dx (rotations scaled by the platform's radius) accepted before a
#: pose counts as singular: the error model's sensitivities grow as the condition number does
COND_LIMIT = 1e8


def _rotation(rx, ry, rz) -> ca.SX:
    """``Rz(rz) Ry(ry) Rx(rx)``."""
    cx, sx, cy, sy, cz, sz = ca.cos(rx), ca.sin(rx), ca.cos(ry), ca.sin(ry), ca.cos(rz), ca.sin(rz)
    return ca.vertcat(
        ca.horzcat(cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx),
        ca.horzcat(sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx),
        ca.horzcat(-sy, cy * sx, cy * cx),
    )


def _platform(spec: ParallelSpec, x):
    """Position and rotation of the platform frame for the pose vector ``x`` (its ``dof``)."""
    c = {d: 0.0 for d in POSE_COORDINATES}
    c.update({d: x[i] for i, d in enumerate(spec.dof)})
    return ca.vertcat(c["x"], c["y"], c["z"]), _rotation(c["rx"], c["ry"], c["rz"])


def _values(spec: ParallelSpec, delta) -> dict:
    """Every leg dimension with its error added (mm, rad), and under each actuated joint's name its
    servo error (rad; :mod:`tolsynth.model.joint_errors`), 0 without one."""
    value = {s: ca.SX(v) for s, v in spec.symbols.items()}
    value.update({j.name: ca.SX(0.0) for j in spec.joints})
    for i, par in enumerate(spec.error_parameters):
        for sym in par.perturbs:
            value[sym] = value[sym] + par.scale * delta[i]
        if par.at_joint is not None:
            value[par.at_joint[0]] = value[par.at_joint[0]] + par.scale * delta[i]
    return value


def _check_joint_errors(spec: ParallelSpec) -> None:
    """Joint errors of a parallel robot: the servo errors of its revolute actuators only."""
    prismatic = set(spec.length_joints)
    for par in spec.error_parameters:
        if par.at_joint is None:
            continue
        joint, op = par.at_joint
        if op != "q":
            raise InputError(
                f"joint_errors[{par.name}]",
                "a parallel robot's legs have ball joints, not modelled clearances",
                "kind 'servo' on a revolute actuator",
            )
        if joint in prismatic:
            raise InputError(
                f"joint_errors[{par.name}]",
                f"{joint!r} is a strut: its length error is the leg's offset parameter",
                "kind 'servo' on a revolute actuator",
            )


def _anchors(leg, value):
    v = lambda f: value[leg.symbol(f)]  # noqa: E731
    return ca.vertcat(v("bx"), v("by"), v("bz")), ca.vertcat(v("px"), v("py"), v("pz"))


def _arm_end(leg, value, B, q):
    """The end of a revolute leg's arm at actuator angle ``q``."""
    d0, a = np.array(leg.zero), np.array(leg.axis)
    e = np.cross(a, d0)
    phi = q + value[leg.symbol("offset")]
    return B + value[leg.symbol("arm")] * (ca.cos(phi) * ca.DM(d0) + ca.sin(phi) * ca.DM(e))


def _residual(spec: ParallelSpec, x, q, value) -> ca.SX:
    """The closure equations ``f(x, q, delta)`` (mm), one per leg."""
    p, R = _platform(spec, x)
    out = []
    for i, leg in enumerate(spec.legs):
        B, c = _anchors(leg, value)
        C = p + ca.mtimes(R, c)
        if leg.actuation == "prismatic":
            out.append(ca.norm_2(C - B) - (q[i] + value[leg.symbol("offset")]))
        else:
            arm_end = _arm_end(leg, value, B, q[i] + value[leg.joint])
            out.append(ca.norm_2(C - arm_end) - value[leg.symbol("link")])
    return ca.vertcat(*out)


def _ik(spec: ParallelSpec, x, value, branches, lower):
    """Closed-form inverse kinematics: actuators (wrapped into ``[lower, lower + 2 pi)`` for a
    revolute leg) and, per leg, the cosine argument (reachable iff in ``[-1, 1]``; 0 for a strut)."""
    p, R = _platform(spec, x)
    q, c = [], []
    for i, leg in enumerate(spec.legs):
        B, cp = _anchors(leg, value)
        w = p + ca.mtimes(R, cp) - B
        if leg.actuation == "prismatic":
            q.append(ca.norm_2(w) - value[leg.symbol("offset")])
            c.append(ca.SX(0.0))
            continue
        d0, a = ca.DM(leg.zero), ca.DM(np.cross(leg.axis, leg.zero))
        u, v = ca.dot(w, d0), ca.dot(w, a)
        arm, link = value[leg.symbol("arm")], value[leg.symbol("link")]
        k = (ca.dot(w, w) + arm**2 - link**2) / (2 * arm)
        ci = k / ca.sqrt(u**2 + v**2)
        theta = ca.atan2(v, u) + branches[i] * ca.acos(ci) - value[leg.symbol("offset")] - value[leg.joint]
        two_pi = 2 * math.pi
        q.append(theta - two_pi * ca.floor((theta - lower[i]) / two_pi))
        c.append(ci)
    return ca.vertcat(*q), ca.vertcat(*c)


@dataclass(frozen=True)
class ParallelGraphs:
    """The named CasADi Functions of a parallel robot (see the module docstring), with the same
    ``fk``, ``sensitivity``, ``closure``, ``position`` as a serial chain's
    :class:`~tolsynth.kinematics.graphs.Graphs`, plus ``pose`` ``(q, delta) -> x``, ``ik``
    ``(x, delta) -> (q, c)`` and ``jacobian`` ``(q, delta) -> df/dx`` at the solved pose."""

    fk: ca.Function
    sensitivity: ca.Function
    closure: ca.Function
    position: ca.Function
    pose: ca.Function
    ik: ca.Function
    jacobian: ca.Function
    home: np.ndarray  # the home configuration's platform pose (dof coordinates, mm and rad)
    branches: tuple  # per leg, the branch of its closed-form inverse kinematics (0 for a strut)
    residual_tol: float  # mm
    radius: float  # mm: the scale of the rotation columns in the condition number
    dof: tuple
    joint_names: tuple

    def conditioning(self, q, delta) -> float:
        """Condition number of ``df/dx`` at the pose (rotation columns times the platform radius,
        so that every column is in mm per mm): how much the error model amplifies leg errors
        beyond their size; infinite at a singularity, NaN where the platform is not assembled."""
        J = np.asarray(self.jacobian(q, delta), dtype=float)
        if not np.all(np.isfinite(J)):
            return math.nan
        scale = np.array([1.0 if len(d) == 1 else self.radius for d in self.dof])
        return float(np.linalg.cond(J / scale[None, :]))

    def check(self, q, delta) -> None:
        """A :class:`~tolsynth.errors.LoopClosureError` unless the platform is assembled at ``q``
        on the home pose's branch, with ``df/dx`` conditioned below ``COND_LIMIT``."""
        c = np.asarray(self.closure(q, delta), dtype=float).ravel()
        where = ", ".join(f"{n} = {v:.6g}" for n, v in zip(self.joint_names, np.asarray(q, dtype=float)))
        if not abs(c[0]) <= 1.0:
            raise LoopClosureError(
                f"the platform cannot be assembled at {where} (mm / rad): outside the workspace reachable from the "
                f"home pose, or at a singularity, where Newton's method does not converge (residual "
                f"{c[0] * self.residual_tol:.3g} mm after the continuation, at most {self.residual_tol:.3g} mm accepted)"
            )
        if not abs(c[1]) <= 1.0:
            raise LoopClosureError(
                f"the platform at {where} (mm / rad) is past a singularity or on another assembly branch "
                f"(det df/dx changed sign or vanished on the way from the home pose)"
            )
        cond = self.conditioning(q, delta)
        if not cond <= COND_LIMIT:
            raise LoopClosureError(
                f"the platform at {where} (mm / rad) is at a singularity: condition number {cond:.3g} of df/dx "
                f"(at most {COND_LIMIT:.0e} accepted); the error model is not defined there"
            )


def _solve_home(spec: ParallelSpec, step: ca.Function, res: ca.Function, q0, zero, tol: float) -> np.ndarray:
    """The home pose by damped Newton from the file's assembly pose (halving a step that does not
    reduce the residual)."""
    x = np.array(spec.assembly, dtype=float)
    r = float(np.max(np.abs(np.asarray(res(x, q0, zero)))))
    for _ in range(200):
        if r <= tol:  # converged: two more full steps take it to rounding level
            for _ in range(2):
                x = np.asarray(step(x, q0, zero), dtype=float).ravel()
            return x
        full = np.asarray(step(x, q0, zero), dtype=float).ravel() - x
        t = 1.0
        while t > 1e-6:
            xt = x + t * full
            rt = float(np.max(np.abs(np.asarray(res(xt, q0, zero)))))
            if rt < r:
                x, r = xt, rt
                break
            t *= 0.5
        else:
            break
    raise ModelFileError(
        spec.path,
        "platform.assembly",
        f"Newton's method from this pose does not assemble the platform at configuration 'home' "
        f"(residual {r:.3g} mm): give a pose closer to the home pose, on the wanted assembly mode",
    )


def build_parallel_graphs(spec: ParallelSpec) -> ParallelGraphs:
    """Build the named CasADi Functions of a parallel robot (see the module docstring)."""
    _check_joint_errors(spec)
    m, nq, ne = len(spec.dof), len(spec.legs), len(spec.error_parameters)
    xs, qs, ds = ca.SX.sym("x", m), ca.SX.sym("q", nq), ca.SX.sym("delta", ne)
    value = _values(spec, ds)
    f = _residual(spec, xs, qs, value)
    Jx = ca.jacobian(f, xs)
    step = ca.Function("newton_step", [xs, qs, ds], [xs - ca.solve(Jx, f)])
    res = ca.Function("residual", [xs, qs, ds], [f])
    jac = ca.Function("jacobians", [xs, qs, ds], [Jx, ca.jacobian(f, ds)])

    lengths = [abs(v) for s, v in spec.symbols.items() if spec.symbol_kinds[s] == "length"]
    residual_tol = RESIDUAL_REL * max([1.0, *lengths])
    radius = max(
        [1.0] + [math.dist((0, 0, 0), [spec.symbols[leg.symbol(f)] for f in ("px", "py", "pz")]) for leg in spec.legs]
    )
    q0 = np.array(spec.configurations["home"].q)
    zero = np.zeros(ne)
    home = _solve_home(spec, step, res, q0, zero, residual_tol)
    det_home = float(np.linalg.det(np.asarray(jac(home, q0, zero)[0])))

    # the branch of each revolute leg's inverse kinematics: the one that gives the home actuators
    lower = [j.lower for j in spec.joints]
    bs = ca.SX.sym("branch", nq)
    ik_of = ca.Function("ik_branches", [xs, ds, bs], list(_ik(spec, xs, value, bs, lower)))
    up, down = (np.asarray(ik_of(home, zero, b * np.ones(nq))[0], dtype=float).ravel() for b in (1.0, -1.0))
    branches = tuple(
        0
        if leg.actuation == "prismatic"
        else (
            1
            if abs(math.remainder(up[i] - q0[i], 2 * math.pi)) <= abs(math.remainder(down[i] - q0[i], 2 * math.pi))
            else -1
        )
        for i, leg in enumerate(spec.legs)
    )

    # forward kinematics: continuation from the home pose, then the errors
    x = ca.SX(ca.DM(home))
    for s in range(1, STAGES + 1):
        qk = ca.DM(q0) + (s / STAGES) * (qs - ca.DM(q0))
        for _ in range(STAGE_STEPS):
            x = step(x, qk, zero)
    for _ in range(FINAL_STEPS):
        x = step(x, qs, zero)
    for _ in range(ERROR_STEPS):
        x = step(x, qs, ds)
    fx = res(x, qs, ds)
    worst = ca.mmax(ca.fabs(fx)) / residual_tol
    Jxs, Jds = jac(x, qs, ds)
    ratio = ca.det(Jxs) / det_home
    det_flag = ca.if_else(ratio > 0, DET_RATIO_MIN / ratio, 2.0)
    ok = ca.logic_and(worst <= 1.0, det_flag <= 1.0)
    nan = lambda e: ca.if_else(ok, e, ca.SX.nan(*e.shape))  # noqa: E731

    p, R = _platform(spec, xs)
    hand = p + ca.mtimes(R, ca.DM(spec.tool_point))
    Tx = ca.vertcat(ca.horzcat(R, hand), ca.DM([[0, 0, 0, 1]]))
    frame = ca.Function("frame", [xs], [Tx, ca.jacobian(hand, xs), ca.jacobian(ca.vec(R), xs)])
    T, Jp_x, JR_x = frame(x)
    D = -ca.solve(Jxs, Jds)  # m x ne: the implicit function theorem
    Rm = T[:3, :3]
    JR = ca.mtimes(JR_x, D)
    cols = []
    for i in range(ne):
        W = ca.mtimes(ca.reshape(JR[:, i], 3, 3), Rm.T)  # [dphi]x for dR = [dphi]x R
        cols.append(ca.vertcat(W[2, 1], W[0, 2], W[1, 0]))
    S = ca.vertcat(ca.mtimes(Jp_x, D), ca.horzcat(*cols) if cols else ca.SX(3, 0))
    qik, cik = ik_of(xs, ds, ca.DM(branches))

    def fn(name, outs, names):
        return ca.Function(name, [qs, ds], outs, ["q", "delta"], names)

    return ParallelGraphs(
        fk=fn("fk", [nan(T)], ["T"]),
        sensitivity=fn("sensitivity", [nan(S)], ["S"]),
        closure=fn("closure", [ca.vertcat(worst, det_flag)], ["c"]),
        position=fn("position", [nan(T[:3, 3])], ["p"]),
        pose=fn("pose", [nan(x)], ["x"]),
        ik=ca.Function("ik", [xs, ds], [qik, cik], ["x", "delta"], ["q", "c"]),
        jacobian=fn("jacobian", [nan(Jxs)], ["J"]),
        home=home,
        branches=branches,
        residual_tol=residual_tol,
        radius=radius,
        dof=spec.dof,
        joint_names=tuple(j.name for j in spec.joints),
    )
