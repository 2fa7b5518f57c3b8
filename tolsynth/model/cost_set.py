"""The cost models of all of a mechanism's parameters as one CasADi graph (the solvers' objective).

:class:`CostSet` holds one :mod:`tolsynth.model.cost` model per parameter (mixed kinds allowed),
evaluates the total cost, its derivatives in ``u = ln eps`` and the dual minimum the certificates
use; :func:`cost_set` builds one from what a user gives.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import Mapping, Sequence

import casadi as ca
import numpy as np

from tolsynth.errors import InputError
from tolsynth.model.cost import MODELS, CostModel, PowerLaw, Tabulated, _power_du, _power_dual_min, cost_model

__all__ = ["CostSet", "cost_set"]


# ---------------------------------------------------------------------------------------------
# one model per parameter
# ---------------------------------------------------------------------------------------------
@lru_cache(maxsize=None)
def _cost_graph(signature: tuple) -> ca.Function:
    """``cost(u, theta) -> f``: the sum of the parameters' costs, built once per structure."""
    n = len(signature)
    u = ca.SX.sym("u", n)
    theta = ca.SX.sym("theta", sum(s[1] if s[0] != "tabulated" else s[1] * 5 - 4 for s in signature))
    f, pos = 0, 0
    for i, (kind, size) in enumerate(signature):
        if kind == "tabulated":
            length = 5 * size - 4
            f += Tabulated._graph(u[i], theta[pos : pos + length], size)
        else:
            length = size
            f += MODELS[kind][0]._expr(u[i], theta[pos : pos + length], ca)
        pos += length
    return ca.Function("cost", [u, theta], [f], ["u", "theta"], ["f"])


@dataclass(frozen=True)
class CostSet:
    """The cost models of a mechanism's n parameters, one each (mixed kinds allowed)."""

    models: tuple

    @property
    def n(self) -> int:
        return len(self.models)

    # computed once per set (the models are frozen): every solve asks for them several times
    @cached_property
    def signature(self) -> tuple:
        return tuple(m.signature for m in self.models)

    @cached_property
    def theta(self) -> np.ndarray:
        th = np.concatenate([m.theta() for m in self.models]) if self.models else np.zeros(0)
        th.setflags(write=False)
        return th

    @property
    def graph(self) -> ca.Function:
        """``cost(u, theta) -> f`` (CasADi); feed :attr:`theta` as its parameter."""
        return _cost_graph(self.signature)

    def expr(self, u):
        """The total cost as a CasADi expression of the symbol ``u`` (n x 1)."""
        return self.graph(u, self.theta)

    def cost(self, eps) -> float:
        eps = np.asarray(eps, dtype=float)
        return float(sum(m.cost(e) for m, e in zip(self.models, eps)))

    def costs(self, eps) -> np.ndarray:
        return np.array([float(m.cost(e)) for m, e in zip(self.models, np.asarray(eps, dtype=float))])

    def total(self, u) -> float | None:
        """``sum_i c_i(u_i)`` at ``u = ln eps`` by NumPy in one vectorised expression (the models'
        own :meth:`CostModel._expr`, the graph's formula) when every model is the paper's power
        law; None otherwise (then evaluate :attr:`graph`)."""
        pl = self.power_law()
        if pl is None:
            return None
        return math.fsum(
            PowerLaw._expr(np.asarray(u, dtype=float), pl, np).tolist()
        )  # fsum: faster than .sum() on a few

    def du(self, u) -> np.ndarray:
        """``dc_i/du_i`` per parameter at ``u`` (for the stationarity condition)."""
        pl = self.power_law()
        if pl is not None:  # vectorised: the same formula as PowerLaw.du, on every parameter at once
            return _power_du(np.asarray(u, dtype=float), pl[0], pl[1])
        return np.array([float(m.du(x)) for m, x in zip(self.models, np.asarray(u, dtype=float))])

    def convex(self, lower, upper) -> np.ndarray:
        """Per parameter: is its cost convex in ``y = eps^2`` on its range (certificate holds)."""
        if self.power_law() is not None:  # the power law is convex in y everywhere
            return np.ones(self.n, dtype=bool)
        return np.array([m.convex_in_y(a, b) for m, a, b in zip(self.models, lower, upper)])

    def check_ranges(self, names, lower, upper) -> None:
        if self.power_law() is not None:  # defined on every range
            return
        for nm, m, a, b in zip(names, self.models, lower, upper):
            m.check_range(a, b, f"bounds[{nm}]")

    def dual_min(self, w, lu, uu) -> tuple[np.ndarray, np.ndarray]:
        """Per parameter: ``min over [lu_i, uu_i] of c_i(u) + w_i e^{2u}`` and its argmin."""
        pl = self.power_law()
        if pl is not None:  # every parameter the paper's power law: one vectorised closed form
            return _power_dual_min(
                np.asarray(w, dtype=float),
                pl[0],
                pl[1],
                0.0,
                np.asarray(lu, dtype=float),
                np.asarray(uu, dtype=float),
                self._power_consts,
            )
        vals, us = zip(*(m.dual_min(np.asarray(wi, dtype=float), a, b) for m, wi, a, b in zip(self.models, w, lu, uu)))
        return np.array(vals, dtype=float), np.array(us, dtype=float)

    def power_law(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(k, alpha)`` (read-only arrays) if every model is the paper's power law, else None."""
        return self._power_law

    @cached_property
    def _power_law(self) -> tuple[np.ndarray, np.ndarray] | None:
        if all(isinstance(m, PowerLaw) for m in self.models):
            k, alpha = np.array([m.k for m in self.models]), np.array([m.alpha for m in self.models])
            k.setflags(write=False)
            alpha.setflags(write=False)
            return k, alpha
        return None

    @cached_property
    def _power_consts(self) -> tuple[np.ndarray, np.ndarray]:
        """``(ln(alpha k / 2), 1 / (2 + alpha))`` of the power law, for :func:`_power_dual_min`
        (every certificate asks for the dual minimum)."""
        k, alpha = self._power_law
        return np.log(0.5 * alpha * k), 1.0 / (2.0 + alpha)

    def describe(self, names: Sequence[str]) -> dict[str, str]:
        return {nm: f"{m.kind}: {m.describe()}" for nm, m in zip(names, self.models)}


@lru_cache(maxsize=256)
def _power_set(k: tuple, alpha: tuple) -> CostSet:
    """The paper's power law per parameter (memoised: a sweep re-solves with the same k, alpha)."""
    return CostSet(tuple(PowerLaw(a, b) for a, b in zip(k, alpha)))


def cost_set(cost, names: Sequence[str], index=None, k=None, alpha=None, units=None) -> CostSet:
    """The per-parameter models from a user's ``cost`` argument.

    ``cost`` is None (the power law from ``k`` and ``alpha``, per parameter arrays), one model
    (every parameter), a sequence of n models, or a dict name -> model for some parameters (the
    others keep the power law).  A model is a :class:`CostModel` or a dict (see :func:`cost_model`);
    ``units``: each parameter's tolerance unit, into which a dict's suffixed tolerances are read.
    """
    n = len(names)
    unit = (lambda i: None) if units is None else (lambda i: units[i])

    def default(i):
        if k is None or alpha is None:
            raise InputError("cost", f"no cost model for parameter {names[i]!r}", "a model for every parameter")
        return PowerLaw(float(np.broadcast_to(k, (n,))[i]), float(np.broadcast_to(alpha, (n,))[i]))

    if cost is None and k is not None and alpha is not None:
        kk, aa = (np.asarray(x, dtype=float) for x in (k, alpha))
        if kk.shape != (n,) or aa.shape != (n,):
            kk, aa = np.broadcast_to(kk, (n,)), np.broadcast_to(aa, (n,))
        return _power_set(tuple(kk.tolist()), tuple(aa.tolist()))
    if cost is None:
        return CostSet(tuple(default(i) for i in range(n)))
    if isinstance(cost, (CostModel, Mapping)) and not (isinstance(cost, Mapping) and "model" not in cost):
        if isinstance(cost, Mapping):  # read per parameter: a suffixed tolerance takes each one's unit
            return CostSet(tuple(cost_model(cost, unit(i)) for i in range(n)))
        return CostSet(tuple(cost for _ in range(n)))
    if isinstance(cost, Mapping):
        idx = index or (lambda key: list(names).index(key))
        models = [None] * n
        for key, value in cost.items():
            try:
                i = idx(key)
            except ValueError:
                from tolsynth.errors import UnknownNameError

                raise UnknownNameError(f"cost[{key}]", f"no parameter {key!r}", ", ".join(names)) from None
            models[i] = cost_model(value, unit(i))
        return CostSet(tuple(m if m is not None else default(i) for i, m in enumerate(models)))
    if isinstance(cost, (list, tuple)):
        if len(cost) != n:
            raise InputError("cost", f"expected {n} models, got {len(cost)}", f"one per parameter {list(names)}")
        return CostSet(tuple(cost_model(c, unit(i)) for i, c in enumerate(cost)))
    raise InputError("cost", f"got {cost!r}", "a model, a list of n models, or a dict name -> model")


def refuse_unread_power_law(costs: CostSet, names: Sequence[str], index, k, alpha, k_v, alpha_v) -> None:
    """An InputError for ``k[name]`` / ``alpha[name]`` given by name for a parameter that a cost
    model prices: the power law's k and alpha do not enter its cost, so the number would be ignored.

    One number (or one per parameter) for k or alpha is the power law of the parameters without a
    cost model, and is not refused: it names no parameter in particular.  A cost model equal to the
    power law of the k and alpha given reads them, and is not refused either.
    """
    for field_name, value in (("k", k), ("alpha", alpha)):
        if not isinstance(value, Mapping):
            continue
        for key in value:
            i = index(key, f"{field_name}[{key}]")
            model = costs.models[i]
            if model != PowerLaw(float(k_v[i]), float(alpha_v[i])):
                raise InputError(
                    f"{field_name}[{key}]",
                    f"{value[key]!r} for {names[i]}, whose cost model ({type(model).__name__}) sets its cost "
                    f"(k and alpha are the power law's, read only where no cost model is given)",
                    f"no {field_name}[{key}]: set that parameter's cost in its cost model, or give it no "
                    "cost model to price it by k eps^-alpha",
                )
