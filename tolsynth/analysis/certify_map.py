"""A certified map: the largest principal standard deviation bounded on each cell of a grid over two joints.

:func:`certified_map` divides the range of two searched joints into ``n x n`` cells, and each
other searched joint into ``slices`` pieces, and bounds ``sigma_1`` on every resulting box at once
with the bounds of the certified search (:mod:`tolsynth.analysis.certify_bounds`, the Gaussian
reading); a box proven to hold no feasible pose (joint constraints, loop closure) is left out.
The value of a cell, the largest bound of its boxes, holds at *every* pose whose two joints lie in
the cell; beside it, the largest value at the boxes' centres, a sampled map on the same grid.  The
bound's excess over the maximum shrinks with the square of the boxes' widths.  Unlike
:func:`tolsynth.analysis.certify.certify_worst_pose` nothing is split where the bound is loose:
one resolution everywhere, a picture rather than a tight bound.  Units: mm and rad.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass

import numpy as np

from tolsynth.analysis.certify_bounds import sigma_bounds
from tolsynth.analysis.certify_domain import domain as _domain
from tolsynth.analysis.certify_structure import structure
from tolsynth.checks import check_count
from tolsynth.errors import InputError, OutOfRangeError, UnknownNameError

__all__ = ["CertifiedMap", "certified_map"]

#: largest number of boxes bounded (memory and time: about 0.1 ms a box on one core)
MAX_MAP_BOXES = 2_000_000
#: boxes bounded per call
CHUNK = 8192


@dataclass(frozen=True)
class CertifiedMap:
    """Outcome of :func:`certified_map`.

    Attributes
    ----------
    joints : tuple of str
        The two joints of the map (columns, rows).
    edges : tuple of ndarray
        Cell edges of each joint (rad).
    upper : ndarray
        Proven upper bound of the largest principal standard deviation (mm) at every pose of each
        cell, shape (rows, columns); NaN where the cell holds no feasible pose (proven).
    sampled : ndarray
        Largest value at the feasible centres of the cell's boxes (mm; NaN where none is feasible).
    boxes : int
        Boxes bounded.
    """

    model: str
    joints: tuple
    edges: tuple
    upper: np.ndarray
    sampled: np.ndarray
    boxes: int
    elapsed_s: float


def certified_map(
    mechanism, tolerances, distribution=None, joints=None, n: int = 40, slices: int = 40, *, base_q=None
) -> CertifiedMap:
    """Proven bounds of sigma_1 on an ``n x n`` grid of cells over two joints (module docstring).

    Parameters
    ----------
    mechanism : Mechanism
    tolerances : str, dict or array
        Tolerance set name or half-widths (tolerance units).
    distribution : str or dict, optional
        As :func:`tolsynth.synthesize` (default: the model file's, else uniform).
    joints : pair of str, optional
        Two searched joints (default: the first two).  Joints proven not to change sigma_1 (held
        by the certified search) cannot be mapped.
    n : int
        Cells per mapped joint, 2 to 1000.
    slices : int
        Pieces of each other searched joint's range, 1 to 1000.
    base_q : array_like, optional
        Values of the held joints (rad), as :func:`~tolsynth.analysis.certify.certify_worst_pose`.

    Examples
    --------
    >>> import numpy as np
    >>> import tolsynth
    >>> from tolsynth.analysis.certify_map import certified_map
    >>> cm = certified_map(tolsynth.load_model("xu_zhang_1988"), "figure3", n=6, slices=6)
    >>> bool(np.all((cm.upper >= cm.sampled) | np.isnan(cm.sampled)))
    True
    """
    t0 = time.perf_counter()
    from tolsynth.kinematics.joint_space import MODEL_REFERENCE, _reference
    from tolsynth.kinematics.mechanism import as_mechanism
    from tolsynth.probability.distributions import resolve
    from tolsynth.probability.stats import variance_divisor

    mech = as_mechanism(mechanism)
    n = check_count(n, "n", 2, 1000)
    slices = check_count(slices, "slices", 1, 1000)
    distribution = resolve(distribution, mech)
    eps = mech.tolerances(tolerances)
    st = structure(mech)
    names = list(mech.joint_names)
    nq = len(names)
    if base_q is None:
        _, ref = _reference(mech, MODEL_REFERENCE)
        base_q = ref if ref is not None else np.zeros(nq)
    dom = _domain(mech, st, np.asarray(base_q, dtype=float), half_turns=False)
    searched = [names[j] for j in dom.free]
    if joints is None:
        if len(searched) < 2:
            raise InputError(
                "joints",
                f"{len(searched)} joint(s) searched ({', '.join(searched) or 'none'})",
                "a mechanism with two joints that change sigma_1",
            )
        joints = searched[:2]
    joints = tuple(joints)
    if len(joints) != 2 or joints[0] == joints[1]:
        raise InputError("joints", f"got {joints!r}", "two different joint names")
    for jn in joints:
        if jn not in searched:
            raise UnknownNameError("joints", f"{jn!r} is not a searched joint", "one of " + ", ".join(searched))
    ia, ib = searched.index(joints[0]), searched.index(joints[1])
    others = [i for i in range(len(searched)) if i not in (ia, ib)]
    total = n * n * slices ** len(others)
    if total > MAX_MAP_BOXES:
        raise OutOfRangeError(
            "n, slices", f"{n}**2 * {slices}**{len(others)} = {total} boxes", f"at most {MAX_MAP_BOXES} boxes"
        )
    c = np.broadcast_to(np.asarray(variance_divisor(distribution, mech), dtype=float), (mech.n,))
    bounds, _ = sigma_bounds(st, dom, nq, (eps**2 / c)[list(st.columns)])
    edges = [np.linspace(dom.lo[i], dom.hi[i], (n if i in (ia, ib) else slices) + 1) for i in range(len(searched))]
    index = np.array(list(itertools.product(*[range(len(e) - 1) for e in edges])))  # (boxes, k)
    upper = np.full(n * n, -np.inf)
    sampled = np.full(n * n, -np.inf)
    cell = index[:, ib] * n + index[:, ia]
    for s in range(0, len(index), CHUNK):
        idx = index[s : s + CHUNK]
        L = np.stack([edges[i][idx[:, i]] for i in range(len(edges))], axis=1)
        H = np.stack([edges[i][idx[:, i] + 1] for i in range(len(edges))], axis=1)
        keep = np.ones(len(L), dtype=bool)
        if dom.constraint_fn is not None:
            g_lo, _ = dom.constraint_fn(L, H)
            keep = ~(np.asarray(g_lo, dtype=float).reshape(len(L), -1) > 0.0).any(axis=1)
        if not keep.any():
            continue
        ub = np.asarray(bounds.bound(L[keep], H[keep])[0], dtype=float)
        ub = np.where(np.isnan(ub), np.inf, ub)
        np.maximum.at(upper, cell[s : s + CHUNK][keep], ub)
        X = 0.5 * (L[keep] + H[keep])
        v = np.asarray(bounds.point(X), dtype=float)
        if dom.constraint_fn is not None:
            _, g_hi = dom.constraint_fn(X, X)
            v = np.where((np.asarray(g_hi, dtype=float).reshape(len(X), -1) <= 0.0).all(axis=1), v, -np.inf)
        np.maximum.at(sampled, cell[s : s + CHUNK][keep], np.where(np.isnan(v), -np.inf, v))
    shape = (n, n)
    upper = np.where(np.isfinite(upper) | (upper == np.inf), upper, np.nan).reshape(shape)
    sampled = np.where(np.isfinite(sampled), sampled, np.nan).reshape(shape)
    return CertifiedMap(mech.name, joints, (edges[ia], edges[ib]), upper, sampled, len(index), time.perf_counter() - t0)
