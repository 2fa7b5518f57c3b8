"""Distributions of the errors inside their tolerance bands, one per error parameter.

An error ``delta_i`` with tolerance ``eps_i`` is written ``delta_i = eps_i * Y_i`` with ``Y_i`` a
zero-mean, symmetric variable of one of these shapes (``eps`` is the half-width of the band):

============================  =====================================  =====================  ==============
shape                          ``Y``                                  ``Var(delta)``          source
============================  =====================================  =====================  ==============
``"uniform"``                  uniform on [-1, 1]                     ``eps^2 / 3``           paper, Eq. 2
``"normal"``                   normal, ``3 sigma = eps`` (unbounded)  ``eps^2 / 9``           paper, Eq. 3
``"triangular"``               triangular on [-1, 1] (mode 0)         ``eps^2 / 6``           sum of 2 uniforms
``"truncnormal"``              normal with ``sigma = eps / beta``,    ``eps^2 v(beta)``       screened process
                               truncated at +-eps (default beta = 2)
============================  =====================================  =====================  ==============

``v(beta) = (1 - 2 beta phi(beta) / erf(beta / sqrt 2)) / beta^2`` (the variance of a standard normal
truncated at +-beta, divided by beta^2); ``"truncnormal(3)"`` sets beta = 3 (a 3-sigma process whose
out-of-tolerance parts are rejected; nearly ``"normal"``), ``"truncnormal"`` is beta = 2 (a process
of capability Cp = 2/3, screened at the tolerance).

For the exact probabilities of :mod:`tolsynth.probability.exact` each shape also gives its characteristic
function ``phi(s) = E cos(s Y)`` (real: Y is symmetric) and an envelope ``|phi(s)| <= env(s)``,
non-increasing in s, used for rigorous truncation bounds; for the Monte Carlo a sampler.  The
characteristic functions are written once and evaluated on NumPy arrays or as CasADi expressions.

``distribution=`` in the API and in model files is one shape name for every parameter, or a
mapping ``name -> shape`` (the others default to ``"uniform"``, the paper's single-piece case).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from functools import lru_cache
from typing import Mapping, Sequence

import numpy as np

from tolsynth.errors import InputError, OutOfRangeError, UnknownNameError

__all__ = [
    "Shape",
    "SHAPES",
    "shape",
    "shapes_of",
    "divisors",
    "divisor_of",
    "resolve",
    "describe",
    "label",
    "DEFAULT_SHAPE",
]

DEFAULT_SHAPE = "uniform"
_EXACT_DIVISORS = {"uniform": 3.0, "normal": 9.0, "triangular": 6.0}
#: the names accepted (``truncnormal(beta)`` with 0.5 <= beta <= 8 as well)
SHAPES = ("uniform", "normal", "triangular", "truncnormal")
_TRUNC = re.compile(r"^truncnormal\(\s*([0-9.eE+-]+)\s*\)$")


@dataclass(frozen=True)
class Shape:
    """One error shape: ``delta = eps * Y``."""

    name: str  # canonical: "uniform", "normal", "triangular", "truncnormal(2)"
    kind: str  # "uniform", "normal", "triangular", "truncnormal"
    beta: float = 0.0  # truncnormal: eps / sigma

    # -- moments --------------------------------------------------------------------------------
    @property
    def variance(self) -> float:
        """``Var(Y)``: ``Var(delta) = variance * eps^2``."""
        if self.kind == "uniform":
            return 1.0 / 3.0
        if self.kind == "normal":
            return 1.0 / 9.0
        if self.kind == "triangular":
            return 1.0 / 6.0
        b = self.beta
        phi = math.exp(-0.5 * b * b) / math.sqrt(2 * math.pi)
        return (1.0 - 2.0 * b * phi / math.erf(b / math.sqrt(2.0))) / (b * b)

    @property
    def divisor(self) -> float:
        """``eps^2 / Var(delta)``: 3 uniform, 9 normal, 6 triangular."""
        exact = _EXACT_DIVISORS.get(self.kind)
        return exact if exact is not None else 1.0 / self.variance

    @property
    def bounded(self) -> bool:
        """True if ``|Y| <= 1`` (every shape but the normal)."""
        return self.kind != "normal"

    @property
    def peak(self) -> float:
        """The density of Y at 0 (its maximum: every shape is symmetric and unimodal)."""
        if self.kind == "uniform":
            return 0.5
        if self.kind == "normal":
            return 3.0 / math.sqrt(2 * math.pi)
        if self.kind == "triangular":
            return 1.0
        b = self.beta
        return b / (math.sqrt(2 * math.pi) * math.erf(b / math.sqrt(2.0)))

    def describe(self) -> str:
        if self.kind == "uniform":
            return "uniform within +-eps (variance eps^2/3)"
        if self.kind == "normal":
            return "normal, 3 sigma = eps (variance eps^2/9)"
        if self.kind == "triangular":
            return "triangular on +-eps (variance eps^2/6)"
        return f"normal with sigma = eps/{self.beta:g} truncated at +-eps (variance eps^2/{self.divisor:.6g})"

    # -- characteristic function ---------------------------------------------------------------
    def cf(self, s, lib=np):
        """``E cos(s Y)`` for ``s >= 0`` (NumPy arrays, or CasADi expressions with ``lib=casadi``).

        uniform ``sin s / s``; normal ``exp(-s^2/18)``; triangular ``(sin(s/2) / (s/2))^2``;
        truncated normal: see :func:`_cf_truncnormal` (a fixed 48-node rule, whatever s).
        """
        if self.kind == "normal":
            return lib.exp(-s * s / 18.0)
        if self.kind == "uniform":
            return _sinc(s, lib)
        if self.kind == "triangular":
            h = _sinc(0.5 * s, lib)
            return h * h
        return _cf_truncnormal(s, self.beta, lib)

    def envelope(self, s: np.ndarray) -> np.ndarray:
        """A non-increasing upper bound on ``|cf(s)|`` for ``s >= 0``.

        uniform ``min(1, 1/s)``; triangular ``min(1, 4/s^2)``; truncated normal ``min(1, 2 f(0)/s)``
        (integration by parts: ``|E cos sY| <= TV(f)/s = 2 f(0)/s`` for a symmetric unimodal density);
        normal: ``cf`` itself.
        """
        s = np.asarray(s, dtype=float)
        with np.errstate(divide="ignore"):
            if self.kind == "normal":
                return np.exp(-s * s / 18.0)
            if self.kind == "uniform":
                return np.minimum(1.0, 1.0 / s)
            if self.kind == "triangular":
                return np.minimum(1.0, 4.0 / (s * s))
            return np.minimum(1.0, 2.0 * self.peak / s)

    @property
    def decay(self) -> int:
        """The power of s in the envelope's decay (0 for the normal, which decays faster than any)."""
        return {"uniform": 1, "triangular": 2, "truncnormal": 1, "normal": 0}[self.kind]

    # -- sampling -------------------------------------------------------------------------------
    def sample(self, rng: np.random.Generator, size) -> np.ndarray:
        """Samples of Y."""
        if self.kind == "uniform":
            return rng.uniform(-1.0, 1.0, size)
        if self.kind == "normal":
            return rng.standard_normal(size) / 3.0
        if self.kind == "triangular":
            return rng.uniform(-0.5, 0.5, size) + rng.uniform(-0.5, 0.5, size)
        # truncated normal: normals with sigma = 1/beta, those outside [-1, 1] drawn again
        # (acceptance erf(beta/sqrt2): 0.38 at beta 0.5, 0.95 at 2)
        out = rng.standard_normal(size) / self.beta
        bad = np.abs(out) > 1.0
        while bad.any():
            out[bad] = rng.standard_normal(int(bad.sum())) / self.beta
            bad = np.abs(out) > 1.0
        return out


_GL48 = np.polynomial.legendre.leggauss(48)
#: below this y the integral is taken over [0, y] directly, above it in the boundary-layer variable
_TN_SPLIT = 5.0
#: the boundary-layer integral is cut at sigma = 50 (remainder < 3e-11 of 1/(2y))
_TN_SIGMA = 50.0


def _cf_truncnormal(s, beta: float, lib=np):
    """``E cos(sY)`` for Y normal with ``sigma = 1/beta`` truncated at +-1.

    ``phi(s) = e^{-s^2/(2 beta^2)} Re erf((beta^2 + i s) / (beta sqrt 2)) / erf(beta / sqrt 2)``, and with
    ``x = beta/sqrt2``, ``y = s/(beta sqrt2)`` and ``Re erf(x + iy) = erf x + (2/sqrt pi) e^{-x^2}
    int_0^y e^{t^2} sin(2xt) dt`` (Abramowitz & Stegun 7.1.3 integrated along the imaginary
    direction):

        phi(s) = e^{-y^2} + 2 e^{-x^2} / (sqrt(pi) erf x) * I(y),   I(y) = int_0^y e^{t^2 - y^2} sin(2xt) dt.

    ``I`` by 48-node Gauss-Legendre: on [0, y] for y <= 5; beyond, in ``sigma = 2y(y - t)``,
    ``I = int_0^{min(2y^2, 50)} e^{-sigma + sigma^2/(4y^2)} sin(2xy - x sigma / y) d sigma / (2y)``
    (the integrand's boundary layer at t = y resolved; the cut at 50 drops < 3e-11 / (2y)).  So the
    cost does not grow with s (checked against direct quadrature of the density in the tests).
    """
    xi, wi = _GL48
    x = beta / math.sqrt(2.0)
    y = s / (beta * math.sqrt(2.0))
    # y <= 5: t = y (1 + xi)/2 on [0, y]
    ys = lib.fmin(y, _TN_SPLIT) if lib is not np else np.minimum(y, _TN_SPLIT)
    small = 0
    for a, w in zip(xi, wi):
        t = 0.5 * ys * (1.0 + a)
        small = small + (0.5 * w) * ys * lib.exp(t * t - ys * ys) * lib.sin(2.0 * x * t)
    # y > 5: sigma on [0, min(2 y^2, 50)] = [0, 50] (2 y^2 >= 50 there)
    yl = lib.fmax(y, _TN_SPLIT) if lib is not np else np.maximum(y, _TN_SPLIT)
    large = 0
    for a, w in zip(xi, wi):
        sg = 0.5 * _TN_SIGMA * (1.0 + a)
        large = large + (0.5 * _TN_SIGMA * w) * lib.exp(-sg + sg * sg / (4.0 * yl * yl)) * lib.sin(
            2.0 * x * yl - x * sg / yl
        )
    large = large / (2.0 * yl)
    if lib is np:
        I = np.where(y <= _TN_SPLIT, small, large)
    else:
        I = lib.if_else(y <= _TN_SPLIT, small, large)
    return lib.exp(-y * y) + (2.0 * math.exp(-x * x) / (math.sqrt(math.pi) * math.erf(x))) * I


def _sinc(s, lib):
    """``sin(s)/s`` with the removable singularity at 0 handled (NumPy or CasADi)."""
    if lib is np:
        s = np.asarray(s, dtype=float)
        small = np.abs(s) < 1e-4
        safe = np.where(small, 1.0, s)
        return np.where(small, 1.0 - s * s / 6.0, np.sin(safe) / safe)
    small = lib.fabs(s) < 1e-4
    safe = lib.if_else(small, 1.0, s)
    return lib.if_else(small, 1.0 - s * s / 6.0, lib.sin(safe) / safe)


#: the shape names, said by every error about a shape
SHAPES_ALLOWED = "'uniform', 'normal', 'triangular', 'truncnormal' or 'truncnormal(beta)' with 0.5 <= beta <= 8"


def _entry_shape(value, field: str) -> Shape:
    """The shape of one entry of a per-parameter distribution, an error naming the entry's field."""
    try:
        return shape(value)
    except OutOfRangeError:
        raise OutOfRangeError(field, f"got {value!r}", SHAPES_ALLOWED) from None


@lru_cache(maxsize=None)
def shape(name) -> Shape:
    """The :class:`Shape` of a name (``"uniform"``, ``"normal"``, ``"triangular"``,
    ``"truncnormal"``, ``"truncnormal(beta)"``), or an :class:`OutOfRangeError` naming the allowed ones."""
    if isinstance(name, Shape):
        return name
    allowed = SHAPES_ALLOWED
    if not isinstance(name, str):
        raise OutOfRangeError("distribution", f"unknown distribution {name!r}", allowed)
    key = name.strip().lower()
    if key in ("uniform", "normal", "triangular"):
        return Shape(key, key)
    if key == "truncnormal":
        return Shape("truncnormal(2)", "truncnormal", 2.0)
    m = _TRUNC.match(key)
    if m:
        try:
            beta = float(m.group(1))
        except ValueError:
            beta = float("nan")
        if math.isfinite(beta) and 0.5 <= beta <= 8.0:
            return Shape(f"truncnormal({beta:g})", "truncnormal", beta)
        raise OutOfRangeError("distribution", f"truncnormal beta = {m.group(1)}", "0.5 <= beta <= 8 (eps / sigma)")
    raise OutOfRangeError("distribution", f"unknown distribution {name!r}", allowed)


def shapes_of(distribution, names: Sequence[str], index=None) -> tuple[Shape, ...]:
    """One :class:`Shape` per parameter from ``distribution``: a shape name for all of them, or a
    mapping ``name -> shape`` (``"*"`` sets the default of the others, else ``"uniform"``).

    ``index(name, field)`` maps a parameter name to its position (a mechanism's ``index``, which
    raises a typed error naming ``field``, here ``distribution[name]``, for an unknown name);
    default: exact names.
    """
    names = list(names)
    if isinstance(distribution, (list, tuple)) and not isinstance(distribution, str):
        if len(distribution) != len(names):
            raise InputError(
                "distribution",
                f"{len(distribution)} shapes for {len(names)} parameters",
                "a shape name, a mapping name -> shape, or one shape per parameter",
            )
        return tuple(_entry_shape(value, f"distribution[{nm}]") for nm, value in zip(names, distribution))
    if isinstance(distribution, Mapping):
        if not distribution:
            raise InputError(
                "distribution", "an empty mapping", "a shape name, or a mapping parameter name -> shape name"
            )
        default = _entry_shape(distribution.get("*", DEFAULT_SHAPE), "distribution[*]")
        out = [default] * len(names)
        for key, value in distribution.items():
            if key == "*":
                continue
            if index is None:
                if key not in names:  # as a mechanism's index says it
                    raise UnknownNameError(
                        f"distribution[{key}]", f"unknown error parameter {key!r}", "one of " + ", ".join(names)
                    )
                i = names.index(key)
            else:
                i = index(key, f"distribution[{key}]")
            out[i] = _entry_shape(value, f"distribution[{key}]")
        return tuple(out)
    return (shape(distribution),) * len(names)


def divisors(distribution, names: Sequence[str], index=None) -> np.ndarray:
    """``eps_i^2 / Var(delta_i)`` per parameter (3 uniform, 9 normal, ...)."""
    return np.array([s.divisor for s in shapes_of(distribution, names, index)])


def divisor_of(distribution, mechanism=None):
    """The variance divisor(s) ``eps^2 / Var(delta)`` of a ``distribution`` argument: a float for
    one shape name (3 uniform, 9 normal, ...), an array with one value per error parameter of
    ``mechanism`` for a mapping or a sequence (which need the mechanism's parameter names).
    Raises a typed error naming ``distribution`` (or ``distribution[name]``) for anything else."""
    if isinstance(distribution, (Mapping, list, tuple)) and not isinstance(distribution, str):
        if mechanism is None:
            raise InputError("distribution", "a per-parameter distribution here", "one shape name")
        if hasattr(mechanism, "error_parameters"):
            return divisors(distribution, mechanism.error_parameters, mechanism.index)
        return divisors(distribution, list(mechanism))  # parameter names
    return shape(distribution).divisor


def resolve(distribution, mechanism):
    """``distribution=None`` -> the mechanism's own (its model file's per-parameter shapes, else
    ``"uniform"``); anything else is checked (typed errors naming ``distribution``) and returned."""
    if distribution is None:
        return getattr(mechanism, "distribution", DEFAULT_SHAPE)
    if isinstance(distribution, str):
        shape(distribution)  # validates (remembered)
        return distribution
    divisor_of(distribution, mechanism)  # validates
    return distribution


def label(distribution) -> str:
    """A short label: the shape name, or ``"mixed (uniform: 16, normal: 2)"``-like for a mapping."""
    if isinstance(distribution, Mapping):
        parts = [f"{k} {shape(v).name}" for k, v in distribution.items()]
        return "per parameter (" + ", ".join(parts) + ")"
    if isinstance(distribution, (list, tuple)) and not isinstance(distribution, str):
        counts: dict = {}
        for v in distribution:
            counts[shape(v).name] = counts.get(shape(v).name, 0) + 1
        return "per parameter (" + ", ".join(f"{k}: {c}" for k, c in counts.items()) + ")"
    return shape(distribution).name


def describe(distribution) -> str:
    """A one-line description of a distribution argument (for reports and tables)."""
    if isinstance(distribution, Mapping):
        return ", ".join(f"{k}: {shape(v).name}" for k, v in distribution.items())
    return shape(distribution).describe()
