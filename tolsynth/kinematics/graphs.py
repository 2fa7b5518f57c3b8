"""Forward kinematics and exact error sensitivities as named CasADi graphs.

:func:`build_graphs` turns a :class:`~tolsynth.model.spec.MechanismSpec` into CasADi ``Function`` s,
built once per mechanism:

``fk(q, delta) -> T``
    4x4 homogeneous hand pose (mm), with the closed loops solved in closed form inside.
``sensitivity(q, delta) -> S``
    6 x n matrix d(pose)/d(delta) by CasADi's algorithmic differentiation: rows dx, dy, dz (mm)
    and the small rotation dphi_x, dphi_y, dphi_z (rad, base frame, ``dR = [dphi]x R``); column i
    per *one tolerance unit* of error parameter i.
``closure(q, delta) -> c``
    For each loop, the cosine argument of its closed-form solution; the loop closes iff
    ``|c| <= 1``.

``q`` are the actuated joints (rad) in the order of the model's ``[[joints]]``; ``delta`` the
deviations of the error parameters, each in its own tolerance unit.  Nothing here uses finite
differences.

Joint errors (:mod:`tolsynth.model.joint_errors`) are error parameters too: a servo error is added to its
actuated joint's variable before the loops are solved; a clearance is the transform
``Tx Ty Tz Rx Ry`` of its components applied just before its joint's rotation ``Rz(theta)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from tolsynth.model.spec import CONVENTIONS, MechanismSpec

__all__ = ["Graphs", "build_graphs", "four_bar_output", "elementary", "JOINT_OPS"]

#: the transforms of a joint clearance, in the order applied (tolsynth.model.joint_errors)
JOINT_OPS = ("Tx", "Ty", "Tz", "Rx", "Ry")


def elementary(op: str, v) -> ca.SX:
    """4x4 homogeneous matrix of one elementary transform (Tx, Ty, Tz in mm; Rx, Ry, Rz in rad)."""
    T = ca.SX.eye(4)
    if op[0] == "T":
        T[{"x": 0, "y": 1, "z": 2}[op[1]], 3] = v
        return T
    c, s = ca.cos(v), ca.sin(v)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[op[1]]
    T[i, i] = c
    T[j, j] = c
    T[i, j] = -s
    T[j, i] = s
    return T


def four_bar_output(ground, crank, coupler, lever, gamma, branch: int):
    """Closed-form position analysis of a planar four-bar.

    Frame of the ground link: pivot O at the origin, the other ground pivot E at (ground, 0).
    The crank O->C makes the angle ``gamma`` with the ground link; the coupler joins C to D;
    the lever E->D has length ``lever``.  Returns ``(psi, c)``: the lever angle ``psi`` measured
    from the ground link, and the cosine argument ``c`` (the loop closes iff ``|c| <= 1``).

    ``|E + lever*u(psi) - C| = coupler`` gives ``d . u(psi) = K`` with ``d = E - C`` and
    ``K = (coupler^2 - |d|^2 - lever^2) / (2 lever)``, so ``psi = atan2(d) + branch*acos(K/|d|)``.
    For a parallelogram (ground = coupler, crank = lever) and ``branch = +1``, ``psi = gamma``.
    """
    dx = ground - crank * ca.cos(gamma)
    dy = -crank * ca.sin(gamma)
    rho2 = dx**2 + dy**2
    K = (coupler**2 - rho2 - lever**2) / (2 * lever)
    c = K / ca.sqrt(rho2)
    psi = ca.atan2(dy, dx) + branch * ca.acos(c)
    return psi, c


def _urdf_link(link, value, q, clearance) -> ca.SX:
    """One URDF joint: ``origin . A . C . J(q) . A^T`` with ``origin`` the joint's elementary
    transforms (Tx Ty Tz Rz Ry Rx: URDF's ``Trans(xyz) . Rz(yaw) . Ry(pitch) . Rx(roll)``), ``A``
    the rotation that turns z onto the (possibly tilted) joint axis, ``C`` a joint clearance
    (tolsynth.model.joint_errors) and ``J`` = Rz(q) (revolute) or Tz(q) (prismatic)."""
    T = ca.SX.eye(4)
    for op, sym in link.origin:
        T = ca.mtimes(T, elementary(op, value[sym]))
    A = ca.SX.eye(4)
    for op, sym in link.axis:
        A = ca.mtimes(A, elementary(op, value[sym]))
    M = ca.SX.eye(4)
    for op, err in sorted(clearance, key=lambda e: JOINT_OPS.index(e[0])):
        M = ca.mtimes(M, elementary(op, err))
    M = ca.mtimes(M, elementary("Rz" if link.motion == "revolute" else "Tz", q))
    # A is a pure rotation: its inverse is its transpose
    return ca.mtimes([T, A, M, A.T])


@dataclass(frozen=True)
class Graphs:
    fk: ca.Function
    sensitivity: ca.Function
    closure: ca.Function
    position: ca.Function  # (q, delta) -> p (3x1), for vectorised sampling


def build_graphs(spec: MechanismSpec) -> Graphs:
    """Build the named CasADi Functions of one mechanism (see the module docstring)."""
    nq = len(spec.joints)
    ne = len(spec.error_parameters)
    q = ca.SX.sym("q", nq)
    delta = ca.SX.sym("delta", ne)

    value = {s: ca.SX(v) for s, v in spec.symbols.items()}
    servo: dict[str, ca.SX] = {}  # joint -> its servo error (rad)
    at_joint: dict[str, list] = {}  # joint -> [(op, error)] of its clearance
    for i, par in enumerate(spec.error_parameters):
        for sym in par.perturbs:
            value[sym] = value[sym] + par.scale * delta[i]
        if par.at_joint is not None:  # a joint error (tolsynth.model.joint_errors)
            jn, op = par.at_joint
            if op == "q":
                servo[jn] = servo.get(jn, 0) + par.scale * delta[i]
            else:
                at_joint.setdefault(jn, []).append((op, par.scale * delta[i]))

    joint = {j.name: q[i] + servo.get(j.name, 0) for i, j in enumerate(spec.joints)}
    margins = []
    for loop in spec.loops:
        gamma = joint[loop.crank_angle] - joint[loop.ground_angle]
        psi, c = four_bar_output(
            value[loop.ground], value[loop.crank], value[loop.coupler], value[loop.lever], gamma, loop.branch
        )
        joint[loop.passive_joint] = psi
        margins.append(c)

    T = ca.SX.eye(4)
    for op, sym in spec.base:
        T = ca.mtimes(T, elementary(op, value[sym]))
    fields, _ = CONVENTIONS.get(spec.convention, ((), ""))
    ops = {"h": "Tx", "a": "Tx", "s": "Tz", "d": "Tz", "alpha": "Rx", "theta": "Rz"}
    for link in spec.links:
        if spec.convention == "urdf":  # tolsynth.model.urdf: origin, then the motion about/along the axis
            T = ca.mtimes(T, _urdf_link(link, value, joint[link.theta], at_joint.get(link.theta, ())))
            continue
        theta = joint[link.theta]
        if link.theta_offset is not None:
            theta = theta + value[link.theta_offset]
        for fname in fields:
            if fname == "theta":  # a clearance acts in the joint frame, before the joint turns
                for op, err in sorted(at_joint.get(link.theta, ()), key=lambda e: JOINT_OPS.index(e[0])):
                    T = ca.mtimes(T, elementary(op, err))
            v = theta if fname == "theta" else value[link.dims[fname]]
            T = ca.mtimes(T, elementary(ops[fname], v))
    for op, sym in spec.tool:
        T = ca.mtimes(T, elementary(op, value[sym]))

    p = T[:3, 3]
    Rm = T[:3, :3]
    Jp = ca.jacobian(p, delta)  # 3 x ne
    JR = ca.jacobian(ca.vec(Rm), delta)  # 9 x ne, column-major vec
    rows = []
    for i in range(ne):
        dR = ca.reshape(JR[:, i], 3, 3)
        W = ca.mtimes(dR, Rm.T)  # = [dphi]x for a rotation dR = [dphi]x R
        rows.append(ca.vertcat(W[2, 1], W[0, 2], W[1, 0]))
    Jw = ca.horzcat(*rows) if rows else ca.SX(3, 0)
    S = ca.vertcat(Jp, Jw)

    closure = ca.vertcat(*margins) if margins else ca.SX(0, 1)
    return Graphs(
        fk=ca.Function("fk", [q, delta], [T], ["q", "delta"], ["T"]),
        sensitivity=ca.Function("sensitivity", [q, delta], [S], ["q", "delta"], ["S"]),
        closure=ca.Function("closure", [q, delta], [closure], ["q", "delta"], ["c"]),
        position=ca.Function("position", [q, delta], [p], ["q", "delta"], ["p"]),
    )
