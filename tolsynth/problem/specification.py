"""The specification of one tolerance problem: what is asked (R, p, criterion, poses) and of what
(the parameters, their bounds and cost models), resolved into plain arrays and constraint blocks.

:func:`make_specification` checks and resolves a user's inputs; :class:`tolsynth.problem.nlp.ToleranceNLP`
builds the CasADi graphs from a :class:`Specification`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from tolsynth.checks import HUGE, TINY, check_half_angle, check_real, check_vector
from tolsynth.errors import InputError, OutOfRangeError
from tolsynth.model.cost_set import CostSet, cost_set, refuse_unread_power_law
from tolsynth.probability.distributions import resolve, shape, shapes_of
from tolsynth.probability.stats import check_positive, check_probability, z_of_p

__all__ = [
    "Specification",
    "Block",
    "SphereBlock",
    "make_specification",
    "CRITERIA",
]

#: accuracy criteria for the position: the paper's per-principal-component form, or the sphere
CRITERIA = ("components", "sphere")
#: largest cost exponent: k eps**-alpha stays finite for eps >= 1e-12 (the paper: alpha <= 1)
ALPHA_MAX = 10.0
#: the cost exponent of a parameter given none (the paper's; a model file carries no alpha)
ALPHA_DEFAULT = 0.7
#: what alpha and k take, said by every error about them (type or range)
ALPHA_ALLOWED = (
    f"the cost's exponent, {TINY:g} <= alpha <= {ALPHA_MAX:g} (the paper: alpha <= 1, typically 0.7): "
    f"a number, a dict name -> number (the others {ALPHA_DEFAULT:g}), or one number per parameter"
)
K_ALLOWED = (
    f"the cost factor, {TINY:g} <= k <= {HUGE:g} (the paper: k >= 1): "
    "a number, a dict name -> number (the others the model's), or one number per parameter"
)
SPHERE_NODES = 24  # Gauss-Legendre nodes in v_z (twice as many in the azimuth); refined if needed


@dataclass(frozen=True)
class Block:
    """One matrix constraint: the position (or orientation) accuracy at one pose."""

    pose: str
    kind: str  # "position" or "orientation"
    scale: float  # z/R (1/mm) or z/Phi (1/rad)
    A: np.ndarray  # 3 x n sensitivity rows (per tolerance unit)

    @property
    def label(self) -> str:
        return f"{self.kind} at pose {self.pose!r}"


@dataclass(frozen=True)
class SphereBlock:
    """The sphere criterion at one pose: ``P(|dr| <= R) >= p`` (position, Eq. 5/13)."""

    pose: str
    R: float  # mm
    p: float
    A: np.ndarray  # 3 x n sensitivity rows (per tolerance unit)
    kind: str = "sphere"

    @property
    def label(self) -> str:
        return f"sphere P(|dr| <= R) at pose {self.pose!r}"


@dataclass(frozen=True)
class Specification:
    """A validated accuracy specification and cost model.

    Units: ``R`` mm; ``Phi`` rad; ``lower``/``upper`` in the tolerance units of the parameters.
    """

    names: tuple[str, ...]
    units: tuple[str, ...]
    R: float
    p: float
    z: float
    distribution: str
    c: float
    alpha: np.ndarray
    k: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    blocks: tuple[Block, ...]
    poses: dict[str, np.ndarray] = field(default_factory=dict)
    Phi: float | None = None
    p_orientation: float | None = None
    criterion: str = "components"
    sphere_blocks: tuple[SphereBlock, ...] = ()
    cost: CostSet | None = None  # per-parameter cost models (tolsynth.model.cost); None: k eps^-alpha
    #: one error shape per parameter (tolsynth.probability.distributions); () means every one is `distribution`
    shapes: tuple = ()
    #: the blocks hold ``A * col_scale`` with ``col_scale = sqrt(c / c_i)`` (c_i the parameter's own
    #: variance divisor), so ``A diag(eps^2 / c) A^T`` is the covariance for mixed shapes too; 1.0
    #: when every parameter has the same shape
    col_scale: np.ndarray | float = 1.0
    #: each joint value's unit in ``poses``, "rad" or "mm" (a joint that slides); empty: all "rad"
    joint_units: tuple = ()

    @property
    def costs(self) -> CostSet:
        """The cost model of every parameter (the paper's power law from ``k``, ``alpha`` unless
        ``cost`` was given)."""
        return self.cost if self.cost is not None else cost_set(None, self.names, k=self.k, alpha=self.alpha)

    @property
    def convex(self) -> bool:
        """True if every cost is convex in eps^2 on its range (then the problem is convex)."""
        if self.costs.power_law() is not None:  # the paper's power law: convex in eps^2 everywhere
            return True
        return bool(self.costs.convex(self.lower, self.upper).all())

    @property
    def n(self) -> int:
        return len(self.names)

    def relaxed(self) -> "Specification":
        """The per-component problem with the same p at the same poses: for the sphere criterion
        its feasible set contains this one, so its optimum is a lower bound."""
        from dataclasses import replace

        extra = tuple(Block(b.pose, "position", z_of_p(b.p) / b.R, b.A) for b in self.sphere_blocks)
        return replace(self, blocks=extra + self.blocks, sphere_blocks=(), criterion="components")


# ---------------------------------------------------------------------------------------------
# validation of the user's specification
# ---------------------------------------------------------------------------------------------
def _per_parameter(value, names: Sequence[str], index, field_name: str, allowed: str, default) -> np.ndarray:
    """One number per parameter from one number, a dict name -> number (the others ``default``,
    one number or one per parameter) or a vector; ``allowed`` (what the argument takes) goes into
    every error (the caller checks each value's range)."""
    n = len(names)
    if value is None:
        if isinstance(default, np.ndarray) and default.shape == (n,):  # the model's own (checked on load)
            return np.array(default, dtype=float)
        value = default
    if isinstance(value, float) and -HUGE <= value <= HUGE:  # the common case: one number for all
        return np.full(n, value)
    if isinstance(value, Mapping):
        out = np.array(np.broadcast_to(np.asarray(default, dtype=float), (n,)))
        for key, v in value.items():
            out[index(key, f"{field_name}[{key}]")] = check_real(v, f"{field_name}[{key}]", allowed=allowed)
        return out
    if np.ndim(value) == 0:
        return np.full(n, check_real(value, field_name, allowed=allowed))
    arr = check_vector(value, field_name, n, names=names, allowed=allowed)
    if arr.shape != (n,):
        raise InputError(field_name, f"expected {n} values, got shape {arr.shape}", allowed)
    return arr.astype(float)


def _outside(x: np.ndarray, lower, upper: float) -> list[int]:
    """Indices of the entries of ``x`` (a few numbers) that are not in ``[lower, upper]`` (NaN is
    not; ``lower`` a number or one per entry)."""
    lo = lower.tolist() if isinstance(lower, np.ndarray) else [lower] * len(x)
    return [i for i, (v, a) in enumerate(zip(x.tolist(), lo)) if not a <= v <= upper]


#: z(p) of a validated probability (remembered: a sweep and a warm solve ask again)
_z_of_p = lru_cache(maxsize=1024)(z_of_p)


def make_specification(
    mechanism,
    R: float,
    p: float,
    distribution=None,
    alpha=ALPHA_DEFAULT,
    k=None,
    bounds=None,
    pose="worst",
    poses=None,
    Phi: float | None = None,
    p_orientation: float | None = None,
    criterion: str = "components",
    cost=None,
) -> Specification:
    """Validate the inputs of :func:`tolsynth.synthesize` and evaluate the sensitivities.

    Raises typed errors naming the field: ``R`` <= 0, ``p`` outside (0, 1), ``alpha`` <= 0,
    ``k`` <= 0, a lower bound <= 0 or above its upper bound, an unknown pose.
    """
    R = check_positive(R, "R")
    p = check_probability(p, "p")
    distribution = resolve(distribution, mechanism)
    if isinstance(distribution, str):  # one shape for every parameter (checked by resolve)
        shp = shape(distribution)
        shapes, c, col_scale = (shp,) * mechanism.n, float(shp.divisor), 1.0
    else:
        shapes = shapes_of(distribution, mechanism.error_parameters, mechanism.index)
        divisors = [s.divisor for s in shapes]
        if len(set(divisors)) == 1:
            c, col_scale = float(divisors[0]), 1.0
        else:  # mixed shapes: one divisor (3) for the graphs, the columns scaled to it
            c, col_scale = 3.0, np.sqrt(3.0 / np.array(divisors))
    if criterion not in CRITERIA:
        raise InputError("criterion", f"unknown criterion {criterion!r}", " or ".join(repr(c) for c in CRITERIA))
    names = mechanism.error_parameters
    alpha_v = _per_parameter(alpha, names, mechanism.index, "alpha", ALPHA_ALLOWED, default=ALPHA_DEFAULT)
    for i in _outside(alpha_v, TINY, ALPHA_MAX):
        raise OutOfRangeError(f"alpha[{names[i]}]", f"got {alpha_v[i]}", ALPHA_ALLOWED)
    k_v = _per_parameter(k, names, mechanism.index, "k", K_ALLOWED, default=mechanism.k)
    for i in _outside(k_v, TINY, HUGE):
        raise OutOfRangeError(f"k[{names[i]}]", f"got {k_v[i]}", K_ALLOWED)
    if bounds is None:
        lo, hi = mechanism.bounds  # copies
    elif isinstance(bounds, Mapping):
        lo, hi = mechanism.bounds
        for key, pair in _plain_pairs(bounds, mechanism, lo, hi):
            try:
                a, b = pair
            except (TypeError, ValueError):
                raise InputError(f"bounds[{key}]", f"got {pair!r}", "a pair (lower, upper)") from None
            i = mechanism.index(key, f"bounds[{key}]")
            unit = mechanism.units[i]  # a bound written with a unit ("5um") in the parameter's own
            lo[i], hi[i] = check_real(a, f"bounds[{key}].lower", unit), check_real(b, f"bounds[{key}].upper", unit)
    else:
        try:
            lo, hi = (np.asarray(b, dtype=float) * np.ones(len(names)) for b in bounds)
        except (TypeError, ValueError, OverflowError):
            raise InputError(
                "bounds",
                f"got {bounds!r}",
                "(lower, upper), each a number or one per parameter, or a dict name -> (lower, upper)",
            ) from None
    units = tuple(mechanism.units)
    if len(_outside(lo, TINY, HUGE)) or len(_outside(hi, lo, HUGE)):  # name the first offender
        for nm, a, b, u in zip(names, lo, hi, units):
            if not (math.isfinite(a) and TINY <= a <= HUGE):
                raise OutOfRangeError(
                    f"bounds[{nm}].lower", f"got {a} {u}", f"{TINY:g} <= lower <= upper <= {HUGE:g} ({u})"
                )
            if not (math.isfinite(b) and a <= b <= HUGE):
                raise OutOfRangeError(
                    f"bounds[{nm}]", f"lower {a}, upper {b} ({u})", f"{TINY:g} <= lower <= upper <= {HUGE:g} ({u})"
                )
    costs = cost_set(cost, names, mechanism.index, k=k_v, alpha=alpha_v, units=mechanism.units)
    refuse_unread_power_law(costs, names, mechanism.index, k, alpha, k_v, alpha_v)
    costs.check_ranges(names, lo, hi)
    z = _z_of_p(p)
    if Phi is not None:
        Phi = check_half_angle(Phi)
        p_orientation = p if p_orientation is None else check_probability(p_orientation, "p_orientation")
        z_o = _z_of_p(p_orientation)
    elif p_orientation is not None:
        raise InputError("p_orientation", "given without Phi", "give Phi (rad) with it")

    # a list may mix configuration names and joint vectors (np.ndim of such a list raises)
    if poses is not None and not (
        isinstance(poses, (list, tuple)) or (isinstance(poses, np.ndarray) and poses.ndim >= 1)
    ):
        raise InputError("poses", f"got {poses!r}", "a list of configuration names or joint vectors (rad)")
    pose_list = list(poses) if poses is not None else [pose]
    if not pose_list:
        raise InputError("poses", "empty", "at least one pose")
    blocks, sphere, qs = [], [], {}
    for label, q, pos, ori in _pose_rows(mechanism, pose_list, col_scale):
        qs[label] = q
        if criterion == "sphere":
            sphere.append(SphereBlock(label, R, p, pos))
        else:
            blocks.append(Block(label, "position", z / R, pos))
        if Phi is not None:
            blocks.append(Block(label, "orientation", z_o / Phi, ori))
    return Specification(
        names=tuple(names),
        units=units,
        R=R,
        p=p,
        z=z,
        distribution=distribution,
        c=c,
        alpha=alpha_v,
        k=k_v,
        lower=lo,
        upper=hi,
        blocks=tuple(blocks),
        poses=qs,
        Phi=Phi,
        p_orientation=p_orientation,
        criterion=criterion,
        sphere_blocks=tuple(sphere),
        cost=costs,  # built once here (the power law from k, alpha when no cost was given)
        shapes=shapes,
        col_scale=col_scale,
        joint_units=mechanism.joint_value_units,
    )


def _plain_pairs(bounds: Mapping, mechanism, lo: np.ndarray, hi: np.ndarray) -> list:
    """Write the pairs of ``bounds`` that are plain finite floats (what
    :func:`tolsynth.model.locks.apply_locks` gives, a lock sweep's every step) into ``lo``, ``hi``
    at once; the others are returned for the checks of the caller, which name the field."""
    rest = []
    for key, pair in bounds.items():
        if (
            type(pair) is tuple
            and len(pair) == 2
            and type(pair[0]) is float
            and type(pair[1]) is float
            and -HUGE <= pair[0] <= HUGE
            and -HUGE <= pair[1] <= HUGE
        ):
            i = mechanism.index(key, f"bounds[{key}]")
            lo[i], hi[i] = pair
        else:
            rest.append((key, pair))
    return rest


#: pose lists at least this long are remembered per mechanism (a sweep re-solves the same poses)
POSE_CACHE_MIN = 8
#: ... at most this many lists per mechanism
POSE_CACHE_SIZE = 16


def _pose_rows(mechanism, pose_list: list, col_scale) -> list[tuple]:
    """``(label, q, position rows, orientation rows)`` per pose: the joints checked by
    :meth:`Mechanism.joints`, the sensitivities (times ``col_scale``).  Remembered on the mechanism
    for long pose lists (a sweep over R, p, k or the bounds checks and evaluates the same poses);
    the arrays are then shared between specifications and read-only."""
    key = None
    if len(pose_list) >= POSE_CACHE_MIN:
        try:
            key = (
                tuple(ps if isinstance(ps, str) else np.asarray(ps, dtype=float).tobytes() for ps in pose_list),
                col_scale.tobytes() if isinstance(col_scale, np.ndarray) else col_scale,
            )
        except (TypeError, ValueError):  # not numbers: Mechanism.joints names the problem below
            key = None
        cache = mechanism.__dict__.setdefault("_pose_rows_cache", {})
        if key is not None and key in cache:
            return cache[key]
    out = []
    for i, ps in enumerate(pose_list):
        label = ps if isinstance(ps, str) else f"#{i}"
        q = mechanism.joints(ps)
        S = mechanism.sensitivity_at(q)  # a copy of the remembered one
        if isinstance(col_scale, np.ndarray):  # mixed shapes
            S *= col_scale
        pos, ori = S[:3].copy(), S[3:].copy()
        if key is not None:
            for a in (q, pos, ori):
                a.setflags(write=False)
        out.append((label, q, pos, ori))
    if key is not None:
        if len(cache) >= POSE_CACHE_SIZE:
            cache.pop(next(iter(cache)))
        cache[key] = out
    return out
