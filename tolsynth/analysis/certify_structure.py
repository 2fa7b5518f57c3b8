"""What a certified worst-pose search may leave out, each fact proven on the model's own graph.

The search bounds functions of the position sensitivity at zero error, ``A(q)`` (3 x n, mm per
tolerance unit; the rows dx, dy, dz of the ``sensitivity`` graph at ``delta = 0``).  Before it
splits a single box it reads six facts off that graph:

* **error parameters without effect**: columns of ``A`` that are structurally zero (CasADi's
  sparsity, no numbers involved), e.g. a roll angle of the last frame that turns the hand point
  about itself.  They add nothing to any probability or standard deviation and are dropped.
* **joints without effect**: joints on which ``A`` does not depend structurally (a hand roll
  joint whose axis holds the hand point).  They are held at any value.
* **periodic joints**: a joint that enters ``A`` only through sine and cosine of itself plus
  constants changes nothing over a full turn, so a range wider than 2 pi is searched over one
  period.
* **half-turn joints**: a periodic joint such that every kept column of ``A``, read as an exact
  polynomial (below), has monomials of one parity in that joint's cosines and sines.  Half a turn
  negates each of them, so each column keeps or flips its sign: ``A W A^T`` and every probability
  (the errors are symmetric) are unchanged, and a range wider than pi is searched over half a turn
  (the hand roll of the Puma 560, the UR5 and the KR 6 R900, whose last link's offsets turn with it).
* **symmetries**: maps of the joints, each kept, turned by half a turn (``q + pi``) or mirrored
  (``-q``, ``pi - q``), that change every kept column of ``A`` only by its sign, ``A`` itself
  possibly turned by half a turn about the base z axis (which changes no principal sigma and no
  smallest probability over directions): the two solutions of a spherical wrist (the Puma 560's
  and the KR 6 R900's ``q4 + pi, -q5``), a mirrored shoulder (the Panda's ``-q2, q3 + pi``), the
  whole arm mirrored (the UR5's ``-q2, -q3, pi - q4, -q5, -q6``).  The twists' constants are rounded
  (``cos(fl(pi/2)) = 6e-17``), so such an identity holds only to about 1e-16 of each column: the
  proof reads the exact polynomial, takes each column's sign from most of its coefficients and
  bounds the rest (the residual), which the search adds to its bound.  A joint the map turns or
  mirrors is then searched over half its range (:func:`tolsynth.analysis.certify_domain.domain`).
* **a joint that turns the error distribution rigidly about the base z axis** (the waist of the
  paper's robot and of most arms): ``A(q) = Rz(q_j + k) A(q with Rz = I)`` for every pose.  Then
  every principal standard deviation and every per-direction probability is the same at every
  value of ``q_j`` (a rotation of the directions), and the search holds that joint.  The proof
  reads the graph's own instructions as exact polynomials (:class:`_PolyWalk`): ``cos(q_j + k)``,
  ``sin(q_j + k)`` become variables ``C, S``, every other sine and cosine a pair of its own, every
  other non-polynomial operation (square root, arc cosine, a division by a variable, ...) a
  variable of its own (the same operation of the same exact arguments the same variable), and
  the graph's floating-point constants exact rationals.  The identity ``A(C, S) = Rz(C, S) A(1, 0)``
  must then hold term by term; an identity in independent variables holds a fortiori when the
  variables are the functions of ``q`` they stand for.

The same reading gives, for a serial chain, ``A`` as an exact polynomial of degree one in each
joint's ``(cos, sin)`` (:func:`trig_polynomial`), which the bounds of
:mod:`tolsynth.analysis.certify_bounds` use.

Everything here is about the real-valued function the graph defines; nothing is sampled.  A fact
that cannot be proven is simply not used (the search is then slower, never wrong).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from fractions import Fraction

import casadi as ca
import numpy as np

from tolsynth.analysis.certify_symmetry import symmetries as _symmetries
from tolsynth.analysis.interval_ops import BINARY, UNARY
from tolsynth.errors import InputError
from tolsynth.model.parallel import is_parallel

__all__ = ["Structure", "check_certifiable", "structure", "position_sensitivity"]


@dataclass(frozen=True)
class Structure:
    """What the certified search may leave out (see the module docstring).

    Attributes
    ----------
    A : casadi.Function
        ``A(q)``: the position rows of the sensitivity at zero error, 3 x n (SX).
    columns : tuple of int
        Error parameters whose column of ``A`` is not structurally zero.
    joints : tuple of int
        Joints ``A`` depends on structurally.
    rotation : int or None
        The joint proven to turn the error distribution rigidly about the base z axis.
    periodic : tuple of int
        Joints entering ``A`` only through sin and cos of the joint plus constants.
    half_turn : tuple of int
        Periodic joints whose half turn changes no column of ``A`` but its sign (proven).
    symmetries : tuple of Symmetry
        Maps of the joints (each kept, turned by half a turn or mirrored) that change every kept
        column of ``A`` only by its sign, proven up to a bounded residual
        (:class:`tolsynth.analysis.certify_symmetry.Symmetry`).
    notes : tuple of str
        What was proven and what could not be, in words.
    """

    A: ca.Function
    columns: tuple
    joints: tuple
    rotation: int | None
    periodic: tuple
    notes: tuple
    half_turn: tuple = ()
    symmetries: tuple = ()


_CACHE: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def check_certifiable(mech) -> None:
    """Raise :class:`InputError` for a mechanism the certified search cannot bound (a parallel
    robot), before any work is spent on it."""
    if is_parallel(mech.spec):
        # the interval extension of the unrolled Newton steps and their assembly test is not finite,
        # even on a box 1e-6 rad wide: the branch and bound would split until its box limit
        raise InputError(
            "certify",
            f"{mech.name} is a parallel robot: its sensitivities come from Newton's method "
            "unrolled from the home pose, which interval arithmetic cannot bound, so the certified "
            "search cannot prove anything",
            "certify=False, the sampled worst-pose search (on the command line: without --certify)",
        )


def position_sensitivity(mech) -> ca.Function:
    """``A(q)``, the rows dx, dy, dz of the mechanism's sensitivity graph at zero error, as an SX
    Function of the joints (constant folding removes what the zero errors switch off)."""
    check_certifiable(mech)
    S = mech.graphs.sensitivity
    if not isinstance(S, ca.Function):
        raise InputError("mechanism", f"{mech.name}: no sensitivity graph", "a model with CasADi graphs")
    try:
        S = S if S.is_a("SXFunction") else S.expand()
    except RuntimeError as err:
        raise InputError(
            "mechanism",
            f"{mech.name}: its sensitivity graph cannot be expanded to scalar operations ({err})",
            "a serial chain or loops solved in closed form",
        ) from None
    nq = S.nnz_in(0)
    q = ca.SX.sym("q", nq)
    A = ca.densify(S.call([q, ca.DM.zeros(S.nnz_in(1))])[0][:3, :])
    return ca.Function("position_sensitivity", [q], [A], ["q"], ["A"])


def structure(mech) -> Structure:
    """The facts of the module docstring for one mechanism (computed once per mechanism)."""
    hit = _CACHE.get(mech)
    if hit is not None:
        return hit
    A = position_sensitivity(mech)
    nq = A.nnz_in(0)
    q = A.sx_in(0)
    expr = A.call([q])[0]
    n = expr.size2()
    columns = tuple(i for i in range(n) if ca.densify(expr[:, i]).nnz() and _nonzero(expr[:, i]))
    dep = np.array(ca.DM(ca.jacobian(ca.vec(expr), q).sparsity(), 1)).sum(axis=0) if n else np.zeros(nq)
    joints = tuple(int(j) for j in range(nq) if dep[j] > 0)
    periodic = tuple(j for j in joints if _periodic(A, j))
    notes = []
    rotation = None
    names = list(getattr(mech, "joint_names", [f"q{j + 1}" for j in range(nq)]))
    constrained = {names.index(jn) for c in getattr(mech.spec, "joint_constraints", ()) for jn in c.terms}
    for j in joints:
        if j in constrained or not _looks_like_rotation(A, j):
            continue
        ok, why = _rotation_proof(A, j)
        if ok:
            rotation = j
            notes.append(f"{names[j]} turns the error distribution rigidly about the base z axis (proven)")
            break
        if why:
            notes.append(f"{names[j]}: {why}")
    try:
        pw = _PolyWalk(A, None, atoms=False)
    except _NoProof:
        pw = None
    half_turn = _half_turn(pw, periodic, columns)
    notes += [f"{names[j]}: half a turn changes no column of A but its sign (proven)" for j in half_turn]
    symmetries = _symmetries(A, pw, periodic, joints, rotation, half_turn, columns)
    notes += [
        f"{sym.describe(names)} changes no column of A but its sign, to the rounding of the twists "
        "(proven, the rest bounded)"
        for sym in symmetries
    ]
    out = Structure(A, columns, joints, rotation, periodic, tuple(notes), half_turn, symmetries)
    _CACHE[mech] = out
    return out


def _looks_like_rotation(f: ca.Function, j: int) -> bool:
    """A cheap screen before the proof: at a few poses, turning q_j by t turns A by Rz(t)
    (to rounding).  Only the proof counts; this only saves proving what is plainly false."""
    rng = np.random.default_rng(0)
    nq = f.nnz_in(0)
    for _ in range(3):
        q = rng.uniform(-3.0, 3.0, nq)
        t = rng.uniform(0.3, 2.0)
        q2 = q.copy()
        q2[j] += t
        a, b = np.array(f(q)), np.array(f(q2))
        c, s = np.cos(t), np.sin(t)
        Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        if not np.all(np.isfinite(a)) or np.max(np.abs(Rz @ a - b)) > 1e-9 * (1.0 + np.max(np.abs(a))):
            return False
    return True


def _nonzero(col) -> bool:
    return any(not col.nz[i].is_zero() for i in range(col.nnz()))


# ---------------------------------------------------------------------------------------------
# walking a graph: which operations a joint feeds
# ---------------------------------------------------------------------------------------------
def _periodic(f: ca.Function, j: int) -> bool:
    """Whether q_j reaches the outputs only as sin or cos of q_j plus constants."""
    angle: set = set()  # work slots holding q_j + constant
    consts: dict = {}
    for k in range(f.n_instructions()):
        op, ins, outs = f.instruction_id(k), f.instruction_input(k), f.instruction_output(k)
        if op == ca.OP_OUTPUT:
            if ins[0] in angle:
                return False
            continue
        out = outs[0]
        if op == ca.OP_INPUT:
            angle.discard(out)
            consts.pop(out, None)
            if ins[1] == j:
                angle.add(out)
            continue
        if op == ca.OP_CONST:
            angle.discard(out)
            consts[out] = f.instruction_constant(k)
            continue
        args = ins[:1] if op in UNARY or op == ca.OP_ASSIGN else ins[:2]
        uses = [a in angle for a in args]
        new_angle = False
        if any(uses):
            if op in (ca.OP_SIN, ca.OP_COS):
                pass
            elif op == ca.OP_ASSIGN or (
                op in (ca.OP_ADD, ca.OP_SUB)
                and sum(uses) == 1
                and all(a in consts for a, u in zip(args, uses) if not u)
                and (op == ca.OP_ADD or uses[0])
            ):
                new_angle = True
            else:
                return False
        angle.discard(out)
        consts.pop(out, None)
        if new_angle:
            angle.add(out)
    return True


class _NoProof(Exception):
    pass


def _half_turn(pw, periodic, columns) -> tuple:
    """The periodic joints whose half turn changes no column of ``A`` but its sign: read as exact
    polynomials (``pw``, a :class:`_PolyWalk`), every monomial of a column's three entries has the
    same parity of degree in that joint's cosines and sines, which half a turn negates.  Empty where
    the graph is not a polynomial in sines and cosines (``pw`` None)."""
    if pw is None:
        return ()
    out = []
    for j in periodic:
        if any(d[0] == "q" and d[1] == j for d in pw.vars):
            continue  # the joint enters other than through sin and cos of itself
        own = {i for key, pair in pw.pairs.items() if key[0] == j for i in pair}
        parities = (
            {
                sum(power for v, power in mono if v in own) % 2
                for r in range(3)
                for mono in (pw.outputs[3 * c + r] or {})
            }
            for c in columns
        )
        if own and all(len(par) <= 1 for par in parities):
            out.append(j)
    return tuple(out)


#: largest number of terms of one expanded node
MAX_TERMS = 50000


def _padd(a: dict, b: dict, sign: int = 1) -> dict:
    r = dict(a)
    for m, c in b.items():
        v = r.get(m, 0) + sign * c
        if v:
            r[m] = v
        else:
            r.pop(m, None)
    return r


def _pmul(a: dict, b: dict) -> dict:
    r: dict = {}
    for ma, ca_ in a.items():
        for mb, cb in b.items():
            if not ma:
                m = mb
            elif not mb:
                m = ma
            else:
                d = dict(ma)
                for v, e in mb:
                    d[v] = d.get(v, 0) + e
                m = tuple(sorted(d.items()))
            c = r.get(m, 0) + ca_ * cb
            if c:
                r[m] = c
            else:
                r.pop(m, None)
    if len(r) > MAX_TERMS:
        raise _NoProof(f"the expansion exceeds {MAX_TERMS} terms")
    return r


def _constant(p: dict):
    """The value of a constant polynomial, else None."""
    return p.get((), Fraction(0)) if set(p) <= {()} else None


class _PolyWalk:
    """The graph of ``f(q)`` read as exact polynomials (module docstring): every node a sparse
    polynomial ``{monomial: Fraction}`` (a monomial a sorted tuple of (variable, power)) in
    variables that stand for ``cos`` and ``sin`` of a joint plus a constant (a pair per joint and
    offset), a joint used otherwise, or an atom: a non-polynomial operation of polynomial
    arguments, one variable per operation and exact arguments.  The graph's own instructions are
    read, so nothing is rounded or re-associated on the way."""

    def __init__(self, f: ca.Function, target: int | None = None, atoms: bool = True):
        self.target, self.allow_atoms = target, atoms
        self.vars: list = []  # description of each variable
        self._index: dict = {}
        self.pairs: dict = {}  # (joint, offset) -> (index of cos, index of sin)
        self.outputs = self._walk(f)

    def var(self, desc) -> int:
        if desc not in self._index:
            self._index[desc] = len(self.vars)
            self.vars.append(desc)
        return self._index[desc]

    def _pair(self, key):
        j, off = key
        if j == self.target and any(k[0] == j and k != key for k in self.pairs):
            raise _NoProof("the joint enters with two different offsets")
        if key not in self.pairs:
            self.pairs[key] = (self.var(("cos", j, off)), self.var(("sin", j, off)))
        return self.pairs[key]

    def _joint(self, key) -> dict:
        """q_j + offset used other than in sin and cos: the joint as a variable (never the target)."""
        j, off = key
        if j == self.target:
            raise _NoProof("the joint enters other than through sin and cos of itself")
        p = {((self.var(("q", j)), 1),): Fraction(1)}
        return _padd(p, {(): off}) if off else p

    def _target_vars(self) -> set:
        return {i for k, pair in self.pairs.items() if k[0] == self.target for i in pair}

    def _atom(self, op, args) -> dict:
        if not self.allow_atoms:
            raise _NoProof("a non-polynomial operation of the joints")
        tv = self._target_vars()
        if any(v in tv for a in args for m in a for v, _ in m):
            raise _NoProof("the joint enters a non-polynomial operation")
        key = ("atom", op) + tuple(frozenset(a.items()) for a in args)
        return {((self.var(key), 1),): Fraction(1)}

    def _walk(self, f: ca.Function) -> list:
        w: dict = {}  # work slot -> ("ang", (joint, offset)) or ("p", polynomial)
        out = [None] * f.nnz_out(0)
        for k in range(f.n_instructions()):
            op, ins, outs = f.instruction_id(k), f.instruction_input(k), f.instruction_output(k)
            if op == ca.OP_OUTPUT:
                t, v = w[ins[0]]
                out[outs[1]] = self._joint(v) if t == "ang" else v
                continue
            if op == ca.OP_INPUT:
                r = ("ang", (ins[1], Fraction(0)))
            elif op == ca.OP_CONST:
                c = Fraction(f.instruction_constant(k))
                r = ("p", {(): c} if c else {})
            elif op == ca.OP_ASSIGN:
                r = w[ins[0]]
            else:
                args = [w[i] for i in (ins[:1] if op in UNARY else ins[:2])]
                r = self._operation(op, args)
            w[outs[0]] = r
        return out

    def _operation(self, op, args):
        kinds = [t for t, _ in args]
        if kinds[0] == "ang" and op in (ca.OP_SIN, ca.OP_COS):
            c, s = self._pair(args[0][1])
            return ("p", {((c if op == ca.OP_COS else s, 1),): Fraction(1)})
        if op in (ca.OP_ADD, ca.OP_SUB) and kinds.count("ang") == 1:
            i = kinds.index("ang")
            other = _constant(args[1 - i][1])
            if other is not None and (op == ca.OP_ADD or i == 0):
                j, off = args[i][1]
                return ("ang", (j, off + other if op == ca.OP_ADD else off - other))
        ps = [self._joint(v) if t == "ang" else v for t, v in args]
        if op == ca.OP_ADD:
            return ("p", _padd(ps[0], ps[1]))
        if op == ca.OP_SUB:
            return ("p", _padd(ps[0], ps[1], -1))
        if op == ca.OP_MUL:
            return ("p", _pmul(ps[0], ps[1]))
        if op == ca.OP_SQ:
            return ("p", _pmul(ps[0], ps[0]))
        if op == ca.OP_NEG:
            return ("p", {m: -c for m, c in ps[0].items()})
        if op == ca.OP_TWICE:
            return ("p", {m: 2 * c for m, c in ps[0].items()})
        if op == ca.OP_DIV:
            d = _constant(ps[1])
            if d:
                return ("p", {m: c / d for m, c in ps[0].items()})
            # x / y = x * (1 / y), the reciprocal an atom of y alone
            return ("p", _pmul(ps[0], self._atom(ca.OP_INV, [ps[1]])))
        if op not in UNARY and op not in BINARY:
            raise _NoProof(f"operation {op} has no symbolic treatment here")
        return ("p", self._atom(op, ps))


def _substitute(p: dict, values: dict) -> dict:
    """The polynomial with the variables of ``values`` set to exact numbers."""
    r: dict = {}
    for mono, c in p.items():
        keep = []
        for v, e in mono:
            if v in values:
                c = c * values[v] ** e
            else:
                keep.append((v, e))
        if c:
            m = tuple(keep)
            r[m] = r.get(m, 0) + c
            if not r[m]:
                del r[m]
    return r


def _rotation_proof(f: ca.Function, j: int) -> tuple[bool, str]:
    """Whether ``A(q) = Rz(q_j + k) A(q_j = -k)`` holds identically (module docstring): with ``C, S``
    the variables of ``cos, sin(q_j + k)``, the polynomial identity ``A(C, S) = Rz(C, S) A(1, 0)``
    in independent variables, checked in exact arithmetic."""
    try:
        pw = _PolyWalk(f, target=j)
    except _NoProof as err:
        return False, str(err)
    pair = [v for k, v in pw.pairs.items() if k[0] == j]
    if not pair:
        return False, "the joint does not enter through sin and cos"
    C, S = pair[0]
    A = pw.outputs  # column-major 3 x n
    try:
        for col in range(len(A) // 3):
            x, y, zz = A[3 * col : 3 * col + 3]
            x1, y1, z1 = (_substitute(p, {C: 1, S: 0}) for p in (x, y, zz))
            cv, sv = {((C, 1),): Fraction(1)}, {((S, 1),): Fraction(1)}
            # Rz(C, S) (x1, y1, z1) - (x, y, z) must vanish term by term
            dx = _padd(_padd(_pmul(cv, x1), _pmul(sv, y1), -1), x, -1)
            dy = _padd(_padd(_pmul(sv, x1), _pmul(cv, y1)), y, -1)
            dz = _padd(z1, zz, -1)
            if dx or dy or dz:
                return False, "the sensitivity does not turn rigidly with the joint"
    except _NoProof as err:
        return False, str(err)
    return True, ""


@dataclass(frozen=True)
class TrigPolynomial:
    """``A(q)`` as a polynomial in ``cos(q_j + k_j), sin(q_j + k_j)`` of the searched joints, of
    degree at most one in each pair (a serial chain), with exact coefficients.

    ``coefficients`` has shape ``(3 m, 3, ..., 3)`` (one axis per searched joint, index 0, 1, 2
    for the factors 1, cos, sin); ``offsets`` the exact ``k_j``; the held joints sit at
    ``q_j = -k_j`` (cos 1, sin 0).  ``A``'s entries are column-major over the kept columns.
    """

    coefficients: np.ndarray  # exact rationals as Python Fractions (object array)
    offsets: tuple


def trig_polynomial(st: Structure, free, held_rotation) -> TrigPolynomial | None:
    """The exact trigonometric polynomial of ``A`` over the joints ``free`` (None where the graph
    is not one: closed loops, joint values outside sine and cosine, two offsets of one joint)."""
    cols = list(st.columns)
    try:
        pw = _PolyWalk(st.A, None, atoms=False)
    except _NoProof:
        return None
    by_joint: dict = {}
    for (jj, off), cs in pw.pairs.items():
        if jj in by_joint:
            return None
        by_joint[jj] = (off, cs)
    free = list(free)
    if any(jj not in free and jj != held_rotation for jj in by_joint) or any(j not in by_joint for j in free):
        return None
    if any(d[0] == "q" for d in pw.vars):
        return None
    fixed = {}
    if held_rotation is not None and held_rotation in by_joint:
        c, s = by_joint[held_rotation][1]
        fixed = {c: 1, s: 0}  # the held rotation at its zero: cos 1, sin 0
    axis = {}
    for i, j in enumerate(free):
        c, s = by_joint[j][1]
        axis[c], axis[s] = (i, 1), (i, 2)
    k = len(free)
    entries = [pw.outputs[3 * c + r] for c in cols for r in range(3)]
    T = np.full((len(entries),) + (3,) * k, Fraction(0), dtype=object)
    for e, poly in enumerate(entries):
        for mono, coef in _substitute(poly or {}, fixed).items():
            idx = [0] * k
            for v, power in mono:
                i, which = axis[v]
                if power != 1 or idx[i] != 0:
                    return None  # not of degree one in the pair
                idx[i] = which
            T[(e, *idx)] = coef
    return TrigPolynomial(T, tuple(by_joint[j][0] for j in free))
