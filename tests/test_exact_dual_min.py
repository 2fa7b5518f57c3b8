"""The lower bound's one-dimensional minimisations for costs other than the power law: each value
is a valid lower bound of ``min over [a, b] of c(u) + w u`` and, where c is convex in u, equal to
it; checked against SciPy's bounded scalar minimiser (an independent algorithm) on the cost
models a process choice produces (Chase, exponential, the tabulated hull of processes)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tolsynth.model.cost import Chase, Exponential, PowerLaw
from tolsynth.model.process import Process
from tolsynth.solvers.exact_certify import _one_dim_min
from tolsynth.synthesis.processes import _hull_model

minimize_scalar = pytest.importorskip("scipy.optimize").minimize_scalar


class _Costs:
    """The two attributes of a CostSet that the minimisation reads."""

    def __init__(self, models):
        self.models = models

    def power_law(self):
        return None


def test_values_are_lower_bounds_and_exact_where_convex():
    hull = _hull_model(
        [
            Process("turning", Chase(1.0, 0.02, 1.0), 0.0285, 0.18),
            Process("grinding", Chase(2.0, 0.01, 1.0), 0.0125, 0.0285),
            Process("lapping", Chase(4.0, 0.004, 1.0), 0.0065, 0.0125),
        ]
    )[0]
    models = [Chase(1.0, 0.02, 1.0), Exponential(12.0, 20.0), hull, Chase(3.0, 0.3, 1.0), PowerLaw(1.5, 0.7), hull]
    lu = np.full(6, math.log(0.005))
    uu = np.full(6, math.log(0.18))
    lu[[2, 5]], uu[[2, 5]] = math.log(hull.eps[0]), math.log(hull.eps[-1])
    rng = np.random.default_rng(1)
    for _ in range(60):
        w = rng.exponential(1.0, 6) * 10 ** rng.uniform(-3, 2, 6)
        val, arg, _ = _one_dim_min(_Costs(models), w, lu, uu)
        for i, m in enumerate(models):

            def f(x, m=m, wi=w[i]):
                return float(m.value(x)) + wi * x

            r = minimize_scalar(f, bounds=(lu[i], uu[i]), method="bounded", options={"xatol": 1e-12})
            ref = min(r.fun, f(lu[i]), f(uu[i]))
            assert val[i] <= ref + 1e-12 * abs(ref)  # a valid lower bound, always
            assert lu[i] <= arg[i] <= uu[i]
            if m.convex_in_u(math.exp(lu[i]), math.exp(uu[i])):  # and the minimum itself
                assert val[i] == pytest.approx(ref, rel=1e-9, abs=1e-12)
