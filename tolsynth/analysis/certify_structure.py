"""What a certified worst-pose search may leave out, each fact proven on the model's own graph.

The search bounds functions of the position sensitivity at zero error, ``A(q)`` (3 x n, mm per
tolerance unit; the rows dx, dy, dz of the ``sensitivity`` graph at ``delta = 0``).  Before it
splits a single box it reads four facts off that graph:

* **error parameters without effect**: columns of ``A`` that are structurally zero (CasADi's
  sparsity, no numbers involved), e.g. a roll angle of the last frame that turns the hand point
  about itself.  They add nothing to any probability or standard deviation and are dropped.
* **joints without effect**: joints on which ``A`` does not depend structurally (a hand roll
  joint whose axis holds the hand point).  They are held at any value.
* **periodic joints**: a joint that enters ``A`` only through sine and cosine of itself plus
  constants changes nothing over a full turn, so a range wider than 2 pi is searched over one
  period.
* **a joint that turns the error distribution rigidly about the base z axis** (the waist of the
  paper's robot and of most arms): ``A(q) = Rz(q_j + k) A(q with Rz = I)`` for every pose.  Then
  every principal standard deviation and every per-direction probability is the same at every
  value of ``q_j`` (a rotation of the directions), and the search holds that joint.  The proof:
  the graph is rebuilt with ``cos(q_j + k)``, ``sin(q_j + k)`` replaced by symbols ``C, S``,
  every other sine and cosine by its own pair of symbols and every other non-polynomial
  operation (square root, arc cosine, a division by a variable, ...) by a symbol of its own.
  What is left is a polynomial with the graph's own floating-point constants as exact rational
  coefficients.  The difference ``D = A(C, S) - Rz(C, S) A(1, 0)`` must vanish identically; it
  is checked to have degree at most one in each group of symbols (structurally), and a
  polynomial of that kind vanishes identically when it vanishes on the grid of corner points of
  its groups, which is evaluated in exact rational arithmetic.  An identity in independent
  symbols holds a fortiori when the symbols are the functions of ``q`` they stand for.

Everything here is about the real-valued function the graph defines; nothing is sampled.  A fact
that cannot be proven is simply not used (the search is then slower, never wrong).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from fractions import Fraction

import casadi as ca
import numpy as np

from tolsynth.analysis.interval_ops import BINARY, UNARY
from tolsynth.errors import InputError

__all__ = ["Structure", "structure", "position_sensitivity"]


_POLY_UNARY = {ca.OP_NEG, ca.OP_SQ, ca.OP_TWICE, ca.OP_ASSIGN}
_POLY_BINARY = {ca.OP_ADD, ca.OP_SUB, ca.OP_MUL}


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
    notes : tuple of str
        What was proven and what could not be, in words.
    """

    A: ca.Function
    columns: tuple
    joints: tuple
    rotation: int | None
    periodic: tuple
    notes: tuple


_CACHE: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def position_sensitivity(mech) -> ca.Function:
    """``A(q)``, the rows dx, dy, dz of the mechanism's sensitivity graph at zero error, as an SX
    Function of the joints (constant folding removes what the zero errors switch off)."""
    S = mech.graphs.sensitivity
    if not isinstance(S, ca.Function):
        raise InputError("mechanism", f"{mech.name}: no sensitivity graph", "a model with CasADi graphs")
    try:
        S = S if S.is_a("SXFunction") else S.expand()
    except RuntimeError as err:
        raise InputError("mechanism", f"{mech.name}: its sensitivity graph cannot be expanded to scalar "
                         f"operations ({err})", "a serial chain or loops solved in closed form") from None
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
    out = Structure(A, columns, joints, rotation, periodic, tuple(notes))
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
            elif op == ca.OP_ASSIGN or (op in (ca.OP_ADD, ca.OP_SUB) and sum(uses) == 1
                                        and all(a in consts for a, u in zip(args, uses) if not u)
                                        and (op == ca.OP_ADD or uses[0])):
                new_angle = True
            else:
                return False
        angle.discard(out)
        consts.pop(out, None)
        if new_angle:
            angle.add(out)
    return True


class _Rebuilt:
    """The graph of ``f(q)`` rebuilt as a polynomial in symbols (module docstring)."""

    def __init__(self, f: ca.Function, j: int | None, atoms: bool = True):
        self.ok, self.why = False, ""
        self.allow_atoms = atoms
        self.pairs: dict = {}  # (joint, exact offset) -> (C, S)
        self.groups: list[list[ca.SX]] = []  # symbols, one group per pair or atom
        self.cs = None  # (key, (C, S)) of joint j
        self.atoms: dict = {}  # (operation, argument key) -> symbol
        self.constants: dict = {}  # name -> (symbol, exact value) of constants CasADi cannot hold
        try:
            self.expr = self._walk(f, j)
            self.ok = self.expr is not None
        except _NoProof as err:
            self.why = str(err)

    def _pair(self, pairs: dict, key, j: int):
        if key[0] == j and self.cs is not None and self.cs[0] != key:
            raise _NoProof("the joint enters with two different offsets")
        if key not in pairs:
            pairs[key] = (ca.SX.sym(f"c{len(pairs)}"), ca.SX.sym(f"s{len(pairs)}"))
            self.groups.append(list(pairs[key]))
            if key[0] == j:
                self.cs = (key, pairs[key])
        return pairs[key]

    def _variable(self, key, j: int) -> ca.SX:
        """q_i + offset used polynomially: a symbol of its own (never the joint j)."""
        jj, off = key
        if jj == j:
            raise _NoProof("the joint enters other than through sin and cos of itself")
        if Fraction(float(off)) != off:
            raise _NoProof("an offset not exactly representable")
        v = ca.SX.sym(f"q{jj}")
        self.groups.append([v])
        return v + float(off) if off else v

    def _walk(self, f: ca.Function, j: int | None):
        pairs = self.pairs
        val: dict = {}  # work slot -> SX
        ang: dict = {}  # work slot -> (joint, exact offset) for q_i + constant
        outs_ = {}
        for k in range(f.n_instructions()):
            op, ins, outs = f.instruction_id(k), f.instruction_input(k), f.instruction_output(k)
            if op == ca.OP_OUTPUT:
                outs_[outs[1]] = self._variable(ang[ins[0]], j) if ins[0] in ang else val[ins[0]]
                continue
            res_val = res_ang = None
            if op == ca.OP_INPUT:
                res_ang = (ins[1], Fraction(0))
            elif op == ca.OP_CONST:
                res_val = ca.SX(f.instruction_constant(k))
            else:
                unary = op in UNARY or op == ca.OP_ASSIGN
                args = ins[:1] if unary else ins[:2]
                a_ang = [a in ang for a in args]
                if op == ca.OP_ASSIGN:
                    res_ang, res_val = (ang[args[0]], None) if a_ang[0] else (None, val[args[0]])
                elif a_ang[0] and op in (ca.OP_SIN, ca.OP_COS):
                    cs = self._pair(pairs, ang[args[0]], j)
                    res_val = cs[0 if op == ca.OP_COS else 1]
                elif (op in (ca.OP_ADD, ca.OP_SUB) and sum(a_ang) == 1 and val[args[a_ang.index(False)]].is_constant()
                      and (op == ca.OP_ADD or a_ang[0])):
                    jj, off = ang[args[a_ang.index(True)]]
                    c = Fraction(float(val[args[a_ang.index(False)]]))
                    res_ang = (jj, off + c if op == ca.OP_ADD else off - c)
                else:
                    xs = [self._variable(ang[a], j) if u else val[a] for a, u in zip(args, a_ang)]
                    res_val = self._operation(op, xs, unary)
            ang.pop(outs[0], None)
            val.pop(outs[0], None)
            if res_ang is not None:
                ang[outs[0]] = res_ang
            else:
                val[outs[0]] = res_val
        if self.cs is None and j is not None:
            raise _NoProof("the joint does not enter through sin and cos")
        sp = f.sparsity_out(0)
        out = ca.SX(sp.size1(), sp.size2())
        for kk, (r, c) in enumerate(zip(*sp.get_triplet())):
            out[r, c] = outs_[kk]
        return out

    def _operation(self, op, xs, unary) -> ca.SX:
        if all(x.is_constant() for x in xs):
            return self._constant(op, xs)
        if op in _POLY_UNARY or op in _POLY_BINARY or (op == ca.OP_DIV and xs[1].is_constant()):
            return ca.SX.unary(op, xs[0]) if unary else ca.SX.binary(op, xs[0], xs[1])
        if op not in UNARY and op not in BINARY:
            raise _NoProof(f"operation {op} has no symbolic treatment here")
        cs = ca.vertcat(*self.cs[1]) if self.cs is not None else None
        if op == ca.OP_DIV and cs is not None and not ca.depends_on(xs[1], cs):
            # x / y = x * (1 / y), the reciprocal an atom of y alone
            return xs[0] * self._atom((ca.OP_INV, _key(xs[1])))
        if cs is not None and any(ca.depends_on(x, cs) for x in xs):
            raise _NoProof("the joint enters a non-polynomial operation")
        return self._atom((op,) + tuple(_key(x) for x in xs))  # a non-polynomial operation of variables

    def _constant(self, op, xs) -> ca.SX:
        """An operation of constants, which CasADi would fold in floating point: its exact rational
        value as a symbol with that value (polynomial operations), else an atom."""
        v = [Fraction(float(x)) for x in xs]
        exact = {ca.OP_ADD: lambda: v[0] + v[1], ca.OP_SUB: lambda: v[0] - v[1], ca.OP_MUL: lambda: v[0] * v[1],
                 ca.OP_NEG: lambda: -v[0], ca.OP_SQ: lambda: v[0] * v[0], ca.OP_TWICE: lambda: 2 * v[0],
                 ca.OP_ASSIGN: lambda: v[0]}
        if op == ca.OP_DIV and v[1] != 0:
            value = v[0] / v[1]
        elif op in exact:
            value = exact[op]()
        else:
            return self._atom((op,) + tuple(x.hex() for x in map(float, v)))
        if Fraction(float(value)) == value:
            return ca.SX(float(value))
        sym = ca.SX.sym(f"k{len(self.constants)}")
        self.constants[sym.name()] = (sym, value)
        return sym

    def _atom(self, key) -> ca.SX:
        """The symbol standing for one non-polynomial value; the same operation of structurally
        equal arguments (the graph may compute a value twice) is the same symbol."""
        if not self.allow_atoms:
            raise _NoProof("a non-polynomial operation of the joints")
        if key not in self.atoms:
            self.atoms[key] = ca.SX.sym(f"t{len(self.groups)}")
            self.groups.append([self.atoms[key]])
        return self.atoms[key]


class _NoProof(Exception):
    pass


def _key(x: ca.SX) -> tuple:
    """An exact structural key of a scalar expression: its free symbols' names and its algorithm,
    constants in hexadecimal (printing rounds them).  Equal keys mean the same function."""
    if x.is_constant():
        return ("const", float(x).hex())
    syms = ca.symvar(x)
    f = ca.Function("key", syms, [x])
    body = []
    for k in range(f.n_instructions()):
        op = f.instruction_id(k)
        c = f.instruction_constant(k).hex() if op == ca.OP_CONST else None
        body.append((op, tuple(f.instruction_input(k)), tuple(f.instruction_output(k)), c))
    return (tuple(s.name() for s in syms), tuple(body))


def _rotation_proof(f: ca.Function, j: int) -> tuple[bool, str]:
    """Whether ``A(q) = Rz(q_j + k) A(q_j = -k)`` holds identically (module docstring)."""
    rb = _Rebuilt(f, j)
    if not rb.ok:
        return False, rb.why
    _, (C, S) = rb.cs
    A = rb.expr
    # A at the joint's zero by renamed symbols, set to exactly (1, 0) below: a numeric substitution
    # would fold products of constants in floating point, which is not the graph's arithmetic
    C1, S1 = ca.SX.sym("c_zero"), ca.SX.sym("s_zero")
    A1 = ca.substitute(A, ca.vertcat(C, S), ca.vertcat(C1, S1))
    Rz = ca.SX(3, 3)
    Rz[0, 0], Rz[0, 1], Rz[1, 0], Rz[1, 1], Rz[2, 2] = C, -S, S, C, 1.0
    D = ca.densify(ca.vec(A - ca.mtimes(Rz, A1)))
    consts = list(rb.constants.values())
    syms = [s for g in rb.groups for s in g] + [C1, S1] + [c for c, _ in consts]
    Fd = ca.Function("D", [ca.vertcat(*syms)], [D])
    n_free = len(syms) - len(consts)
    fixed = {n_free - 2: {(): Fraction(1)}, n_free - 1: {}}  # A at (C, S) = (1, 0)
    fixed.update({n_free + i: {(): v} for i, (_, v) in enumerate(consts)})
    try:
        polys = _expand(Fd, fixed)
    except _NoProof as err:
        return False, str(err)
    if any(polys):
        return False, "the sensitivity does not turn rigidly with the joint"
    return True, ""


#: largest number of terms of one expanded node in the rotation proof
MAX_TERMS = 50000


def _expand(f: ca.Function, fixed: dict) -> list:
    """The outputs of a polynomial SX Function as sparse polynomials in its inputs, with exact
    rational coefficients: ``{monomial: Fraction}``, a monomial a sorted tuple of (input, power).
    Inputs in ``fixed`` are replaced by the given polynomials.  Nothing is rounded."""
    w: dict = {}
    out = [None] * f.nnz_out(0)

    def mul(a, b):
        r: dict = {}
        for ma, ca_ in a.items():
            for mb, cb in b.items():
                if len(ma) == 0:
                    m = mb
                elif len(mb) == 0:
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

    def add(a, b, sign=1):
        r = dict(a)
        for m, c in b.items():
            v = r.get(m, 0) + sign * c
            if v:
                r[m] = v
            else:
                r.pop(m, None)
        return r

    for k in range(f.n_instructions()):
        op, ins, outs = f.instruction_id(k), f.instruction_input(k), f.instruction_output(k)
        if op == ca.OP_INPUT:
            i = ins[1]
            r = fixed[i] if i in fixed else {((i, 1),): Fraction(1)}
        elif op == ca.OP_OUTPUT:
            out[outs[1]] = w[ins[0]]
            continue
        elif op == ca.OP_CONST:
            c = Fraction(f.instruction_constant(k))
            r = {(): c} if c else {}
        elif op == ca.OP_ASSIGN:
            r = w[ins[0]]
        elif op == ca.OP_ADD:
            r = add(w[ins[0]], w[ins[1]])
        elif op == ca.OP_SUB:
            r = add(w[ins[0]], w[ins[1]], -1)
        elif op == ca.OP_MUL:
            r = mul(w[ins[0]], w[ins[1]])
        elif op == ca.OP_SQ:
            r = mul(w[ins[0]], w[ins[0]])
        elif op == ca.OP_NEG:
            r = {m: -c for m, c in w[ins[0]].items()}
        elif op == ca.OP_TWICE:
            r = {m: 2 * c for m, c in w[ins[0]].items()}
        elif op == ca.OP_DIV and set(w[ins[1]]) <= {()} and w[ins[1]]:
            d = w[ins[1]][()]
            r = {m: c / d for m, c in w[ins[0]].items()}
        else:
            raise _NoProof(f"operation {op} in what should be a polynomial")
        w[outs[0]] = r
    return out


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
    f = ca.Function("A_kept", [st.A.sx_in(0)], [st.A.call([st.A.sx_in(0)])[0][:, list(st.columns)]])
    rb = _Rebuilt(f, None, atoms=False)
    if not rb.ok or rb.constants:
        return None
    by_joint: dict = {}
    for (jj, off), cs in rb.pairs.items():
        if jj in by_joint:
            return None
        by_joint[jj] = (off, cs)
    free = list(free)
    if any(jj not in free and jj != held_rotation for jj in by_joint) or any(j not in by_joint for j in free):
        return None
    syms = [s for j in free for s in by_joint[j][1]]
    fixed = {}
    extra = []
    if held_rotation is not None and held_rotation in by_joint:
        extra = list(by_joint[held_rotation][1])
        fixed = {len(syms): {(): Fraction(1)}, len(syms) + 1: {}}
    expr = ca.densify(ca.vec(rb.expr))
    F = ca.Function("A_poly", [ca.vertcat(*(syms + extra))], [expr])
    if F.n_instructions() and any(F.instruction_id(k) not in (ca.OP_INPUT, ca.OP_OUTPUT, ca.OP_CONST, ca.OP_ASSIGN,
                                                              *(_POLY_UNARY | _POLY_BINARY), ca.OP_DIV)
                                  for k in range(F.n_instructions())):
        return None
    try:
        polys = _expand(F, fixed)
    except _NoProof:
        return None
    k = len(free)
    T = np.full((len(polys),) + (3,) * k, Fraction(0), dtype=object)
    for e, poly in enumerate(polys):
        for mono, c in (poly or {}).items():
            idx = [0] * k
            for v, power in mono:
                joint, which = divmod(v, 2)
                if power != 1 or idx[joint] != 0:
                    return None  # not of degree one in the pair
                idx[joint] = 1 + which
            T[(e, *idx)] = c
    return TrigPolynomial(T, tuple(by_joint[j][0] for j in free))
