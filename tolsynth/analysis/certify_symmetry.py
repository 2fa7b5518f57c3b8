"""Symmetries of the position sensitivity ``A(q)``, proven on its exact polynomial.

A symmetry is a map of the joints, each kept, turned by half a turn (``q + pi``) or mirrored
(``-q``, ``pi - q``), that changes every kept column of ``A`` only by its sign, ``A`` itself possibly
turned by half a turn about the base z axis; every principal standard deviation is then the same at
a pose and at its image, up to the residual the twists' rounded constants leave (bounded here).
:func:`tolsynth.analysis.certify_domain.domain` cuts joints to half their range with them.  The
exact polynomial is :class:`tolsynth.analysis.certify_structure._PolyWalk`'s, passed in.
"""

from __future__ import annotations

import itertools
from fractions import Fraction
from typing import NamedTuple

import casadi as ca
import numpy as np

__all__ = ["Symmetry", "symmetries", "KEEP", "TURN", "MIRROR", "MIRROR_TURN"]

#: a symmetry is used where what breaks it is at most this share of each column's coefficients: the
#: twists' rounded constants (cos(fl(pi/2)) = 6e-17) leave 1e-16, a map that is no symmetry O(1)
SYMMETRY_RESIDUAL = 1e-12
#: what a symmetry does to one joint: unchanged, turned by half a turn, mirrored, mirrored about pi / 2
KEEP, TURN, MIRROR, MIRROR_TURN = 0, 1, 2, 3
OP_NAMES = {TURN: "{} + pi", MIRROR: "-{}", MIRROR_TURN: "pi - {}"}


class Symmetry(NamedTuple):
    """A map of the joints that changes every kept column of ``A`` only by its sign (and, with
    ``turn``, turns ``A`` by half a turn about the base z axis), up to ``residual``: the 3 x
    kept-columns bounds (mm per tolerance unit) of what the twists' rounded constants leave."""

    ops: tuple  # per joint: KEEP, TURN (q + pi), MIRROR (-q) or MIRROR_TURN (pi - q)
    turn: bool
    residual: tuple

    def describe(self, names) -> str:
        parts = [OP_NAMES[op].format(names[j]) for j, op in enumerate(self.ops) if op]
        return ", ".join(parts) + ("; A turned by half a turn about z" if self.turn else "")


def symmetries(f: ca.Function, pw, periodic, joints, rotation, half_turn, columns) -> tuple:
    """Maps of the joints, each joint kept, turned by half a turn, mirrored or mirrored about pi/2,
    that change every column of ``A`` only by its sign, ``A`` itself possibly turned by half a turn
    about the base z axis (which changes no principal sigma and no smallest probability over
    directions): the two solutions of a spherical wrist (``q4 + pi, -q5, q6 + pi``), a shoulder
    mirrored (the Panda's ``-q2, q3 + pi``), a whole arm mirrored (the UR5's ``-q2 .. -q6``).
    Screened at three poses over every such map (NumPy), then proven on the exact polynomials
    ``pw``: the map negates cosines and sines by joint (mirroring needs the offset 0), so each
    monomial keeps or flips its sign; in each column the sign of most weight is the column's, and
    the monomials of the other sign, at most their coefficients' sum as every cosine and sine is at
    most 1 in size, form twice the residual."""
    if pw is None or any(d[0] == "q" for d in pw.vars):
        return ()  # a joint value outside sine and cosine: no bound of a monomial by 1
    out = []
    for ops, turn in _screen(f, periodic, joints, rotation, half_turn):
        sign: dict = {}
        for (j, off), (ci, si) in pw.pairs.items():
            op = ops[j]
            if op == TURN:
                sign[ci], sign[si] = -1, -1
            elif op in (MIRROR, MIRROR_TURN):
                if off != 0:
                    break  # cos(-q + k) is no multiple of cos(q + k)
                sign[ci], sign[si] = (1, -1) if op == MIRROR else (-1, 1)
        else:
            rho = (-1, -1, 1) if turn else (1, 1, 1)
            residual = np.zeros((3, len(columns)))
            for n, col in enumerate(columns):
                mass = {1: Fraction(0), -1: Fraction(0)}
                terms = []
                for r in range(3):
                    for mono, coef in (pw.outputs[3 * col + r] or {}).items():
                        s_m = rho[r]
                        for v, power in mono:
                            if power % 2:
                                s_m *= sign.get(v, 1)
                        mass[s_m] += abs(coef)
                        terms.append((r, s_m, abs(coef)))
                keep = 1 if mass[1] >= mass[-1] else -1
                bad = [Fraction(0)] * 3
                for r, s_m, coef in terms:
                    if s_m != keep:
                        bad[r] += coef
                if sum(bad) > SYMMETRY_RESIDUAL * mass[keep]:
                    break
                residual[:, n] = [_up_fraction(2 * x) for x in bad]
            else:
                out.append(Symmetry(tuple(ops), bool(turn), tuple(map(tuple, residual))))
    return tuple(out)


def _up_fraction(x: Fraction) -> float:
    """The smallest float at or above the rational x."""
    v = float(x)
    return v if Fraction(v) >= x else float(np.nextafter(v, np.inf))


def _screen(f: ca.Function, periodic, joints, rotation, half_turn) -> list:
    """The maps (ops, turn) that change each column of A only by its sign at three random poses,
    to rounding: a cheap screen before the proof.  The base rotation is kept (turning it is the
    ``turn``); a half-turn joint is not turned (that changes nothing); a map that only mirrors
    half-turn joints is left out (it cuts nothing a half turn has not)."""
    nq = f.nnz_in(0)
    choices = []
    for j in range(nq):
        if j not in periodic or j not in joints or j == rotation:
            choices.append((KEEP,))
        elif j in half_turn:
            choices.append((KEEP, MIRROR))
        else:
            choices.append((KEEP, TURN, MIRROR, MIRROR_TURN))
    pats = [p for p in itertools.product(*choices) if any(op and j not in half_turn for j, op in enumerate(p))]
    if not pats:
        return []
    P = np.array(pats)
    rng = np.random.default_rng(0)
    Q = rng.uniform(-3.0, 3.0, (3, nq))
    A0 = [np.array(f(q)) for q in Q]
    keep = {False: np.ones(len(P), bool), True: np.ones(len(P), bool)}
    for q, A in zip(Q, A0):
        X = np.where(P == TURN, q + np.pi, np.where(P == MIRROR, -q, np.where(P == MIRROR_TURN, np.pi - q, q)))
        B = np.stack(np.hsplit(np.array(f.map(len(P))(X.T)), len(P)))  # (pattern, 3, n)
        scale = 1e-9 * (1.0 + np.abs(A).max())
        for turn in (False, True):
            C = B * (np.array([-1.0, -1.0, 1.0])[None, :, None] if turn else 1.0)
            change = np.minimum(np.abs(C - A).max(axis=1), np.abs(C + A).max(axis=1)).max(axis=1)
            keep[turn] &= np.isfinite(change) & (change <= scale)
    return [(tuple(int(v) for v in P[i]), turn) for turn in (False, True) for i in np.flatnonzero(keep[turn])]
