# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#       format_version: '1.3'
#       jupytext_version: 1.19.6
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # 07 · A designer's cost: processes, locks, budgets, contributors
#
# The paper prices every tolerance with one curve, `k eps^-alpha`. A shop instead picks a
# **process** for each dimension, and each process has its own cost curve and the range of
# tolerances it can hold. This notebook works an example on the paper's robot (Xu & Zhang 1988),
# with three processes per length and two per angle:
#
# | process | tolerance range (half-width) | cost model (Chase et al. 1990: `A + B/eps`) |
# |---|---|---|
# | turning | IT7 to IT11: 0.0285 to 0.18 mm | A = 1, B = 0.02 mm |
# | grinding | IT5 to IT7: 0.0125 to 0.0285 mm | A = 2, B = 0.01 mm |
# | lapping | IT3 to IT5: 0.0065 to 0.0125 mm | A = 4, B = 0.004 mm |
# | angle, standard | 0.05 to 1.0 (1e-2 rad) | A = 1, B = 0.05 |
# | angle, precision | 0.005 to 0.05 (1e-2 rad) | A = 3, B = 0.02 |
#
# **Sources, and what is assumed.** The tolerance ranges are ISO 286-1 standard tolerance grades
# for nominal sizes 315-400 mm (IT3 = 13 µm, IT5 = 25 µm, IT7 = 57 µm, IT11 = 360 µm; half of
# each is the half-width `eps`). The grades a process holds are taken from the usual
# process-capability charts: turning IT7-IT11, grinding IT5-IT7, lapping IT3-IT5. The cost form
# `A + B/eps^k` is Chase, Greenwood, Loosli & Hauglund (1990), with `k = 1`. Its coefficients here
# are **illustrative relative costs**, chosen only so that a finer process costs more. They are not
# measured shop data; use your own. The angle ranges and costs are assumed in the same way.

# %%
import time

import matplotlib.pyplot as plt

import tolsynth
from tolsynth.model.cost import Chase
from tolsynth.model.process import Process

m = tolsynth.load_model("xu_zhang_1988")
IT = {3: 0.013, 5: 0.025, 7: 0.057, 11: 0.36}  # mm, ISO 286-1, 315-400 mm
half = {grade: value / 2 for grade, value in IT.items()}
turning = Process("turning", Chase(1.0, 0.02, 1.0), half[7], half[11])
grinding = Process("grinding", Chase(2.0, 0.01, 1.0), half[5], half[7])
lapping = Process("lapping", Chase(4.0, 0.004, 1.0), half[3], half[5])
standard = Process("standard", Chase(1.0, 0.05, 1.0), 0.05, 1.0)
precision = Process("precision", Chase(3.0, 0.02, 1.0), 0.005, 0.05)
processes = {
    name: ([turning, grinding, lapping] if unit == "mm" else [standard, precision])
    for name, unit in zip(m.error_parameters, m.units)
}

# %% [markdown]
# ## The proven cheapest process per parameter
#
# With 8 lengths and 3 angles there are 3^8 · 2^3 = 52,488 process combinations. Branch and
# bound solves a few dozen continuous problems. A node's lower bound is a Lagrangian bound, valid
# for any multipliers, and it uses each process's exact cost curve. Every other combination is
# pruned by a certified bound, so the result is **proven** optimal. It is not merely a good choice.
#
# This search reads the paper's Gaussian criterion (`probability="gaussian"`): with the exact
# probabilities, the library's default, each node's certificate over the processes' tabulated
# cost curves takes about a second, and the search of a few dozen nodes takes minutes.

# %%
t0 = time.perf_counter()
best = tolsynth.synthesize_processes(m, R=0.2, p=0.99, processes=processes, probability="gaussian")
print(best.summary())
print(f"{time.perf_counter() - t0:.1f} s")
assert best.proven

# %% [markdown]
# The shortcut, rounding the continuous relaxation to the nearest process, is shown in the first
# line of the summary. When it is feasible at all, it costs more than the proven optimum:

# %%
print(
    f"proven optimum {best.cost:.4f}; rounded {best.rounded['cost']:.4f} "
    f"(+{100 * (best.rounded['cost'] / best.cost - 1):.1f} %)"
)

# %% [markdown]
# ## Who contributes to the error at that optimum
#
# Along each principal direction, each parameter's share of the variance is exact, and the
# shares add up to 1. For the sphere probability `P(|dr| <= R)`, the loss `1 - P` is shared out
# by elasticities.

# %%
rep = tolsynth.contributions(best.result)
print(rep.format())
rep.plot()
plt.show()

# %% [markdown]
# ## A supplier fixes a tolerance
#
# Suppose the parallelogram link `h3` comes from a supplier at ±0.05 mm. The other parameters are
# re-optimised around it. A lock that alone breaks the specification is refused, with an error
# that names it.

# %%
free = tolsynth.synthesize(m, R=0.5, p=0.99)
locked = tolsynth.synthesize(m, R=0.5, p=0.99, locks={"h3": 0.05})
print(f"free: cost {free.cost:.3f}, h3 = {free.tolerances['h3']:.4f} mm")
print(f"h3 locked at 0.05 mm: cost {locked.cost:.3f} (certified, gap {locked.gap:.1e})")
try:
    tolsynth.synthesize(m, R=0.5, p=0.99, locks={"h3": 1.0})
except tolsynth.InfeasibleSpecificationError as err:
    print(err)

# %% [markdown]
# ## What a budget buys, and the cost against R
#
# The optimal cost falls as R grows. So the smallest R that a budget buys lies in a bracket
# between a point the budget certainly affords and a point whose certified lower bound exceeds it.
# The front below is a warm-started sweep, and the paper's printed Table 1 columns are marked on it.

# %%
buy = tolsynth.best_accuracy(m, free.cost, p=0.99)
print(
    f"budget {free.cost:.3f} buys R in [{buy.bracket[0]:.5f}, {buy.bracket[1]:.5f}] mm "
    f"({buy.solves} solves, certified: {buy.certified})"
)
front = tolsynth.pareto_front(m, R=[0.25, 0.35, 0.5, 0.7, 1.0, 1.4, 2.0], p=0.99)
print(front.table())
front.plot()
plt.show()
