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
# # 03 · IPOPT against SUMT + Powell on the paper's 18 columns
#
# The paper solved its model (Eq. 23) with SUMT, an interior penalty method, each unconstrained
# minimisation by Powell's derivative-free direction-set method.  tolsynth keeps that method as a
# cross-check, next to IPOPT with exact derivatives.  Both read the same CasADi graphs of the same
# convex problem (in log-tolerances, with the accuracy constraint as a matrix inequality), so they
# must find the same optimum; the question is how fast and how they get there.
#
# * **IPOPT**: primal-dual interior point, Newton steps on the exact Hessian;
# * **SUMT + Powell**: minimise `f(u) + r * barrier(u)` for a decreasing sequence of `r`
#   (`r -> r / 10`), each from the previous minimiser; stop when the barrier's duality-gap bound
#   `r * nu` is below `1e-8` of the cost.
#
# Every column of Tables 1-3 is solved once by each, both from scratch (`tolsynth.compare` does not
# let IPOPT start from an earlier column's optimum; a few to tens of ms a column for either, so
# this cell takes a second or two).  Units: cost in the paper's units; tolerances in mm and
# 1e-2 rad; times in ms.

# %%
import matplotlib.pyplot as plt
import numpy as np
from tqdm import tqdm

import tolsynth

m = tolsynth.load_model("xu_zhang_1988")
refs = m.spec.reference_results
comparisons = [tolsynth.compare(m, r.R, r.p, r.distribution, r.alpha) for r in tqdm(refs, desc="IPOPT + SUMT")]
labels = [f"T{r.table[-1]} R={r.R:g} p={r.p:g} a={r.alpha:g} {r.distribution[0].upper()}" for r in refs]
print("all converged:", all(c.ipopt.success and c.sumt.success for c in comparisons))

# %% [markdown]
# ## 1. One column in detail
#
# Table 1, `R = 0.5 mm`, uniform, the paper's reference case:

# %%
c = comparisons[2]
print(labels[2])
print(c.table())
print()
print("IPOPT:", c.ipopt.message)
print("SUMT: ", c.sumt.message)

# %% [markdown]
# ## 2. All 18 columns
#
# Cost of each solver, their relative difference, the largest relative difference of a tolerance,
# the duality gap each result certifies (`cost - lower bound`; the problem is convex, so a gap near 0
# proves the point globally optimal), iterations (IPOPT: Newton iterations; SUMT: Powell sweeps
# summed over the outer loop), function evaluations and wall time.

# %%
head = (
    f"{'column':<28} {'IPOPT cost':>11} {'SUMT cost':>11} {'cost diff':>9} {'tol diff':>9} "
    f"{'gap I':>8} {'gap S':>8} {'it I':>5} {'it S':>5} {'ev I':>5} {'ev S':>7} {'ms I':>6} {'ms S':>7} {'S/I':>5}"
)
print(head)
for lab, c in zip(labels, comparisons):
    i, s = c.ipopt, c.sumt
    print(
        f"{lab:<28} {i.cost:11.6f} {s.cost:11.6f} {c.cost_rel_diff:9.1e} {max(c.tolerance_rel_diff.values()):9.1e} "
        f"{i.gap:8.1e} {s.gap:8.1e} {i.iterations:5d} {s.iterations:5d} {i.function_evaluations:5d} "
        f"{s.function_evaluations:7d} {i.wall_time * 1e3:6.1f} {s.wall_time * 1e3:7.0f} {c.time_ratio:5.2f}"
    )
cd = np.array([c.cost_rel_diff for c in comparisons])
td = np.array([max(c.tolerance_rel_diff.values()) for c in comparisons])
tr = np.array([c.time_ratio for c in comparisons])
ev = np.array([c.sumt.function_evaluations / c.ipopt.function_evaluations for c in comparisons])
print(f"\ncost agreement: max relative difference {cd.max():.1e}; tolerances: max {td.max():.1e}")
print(
    f"SUMT / IPOPT: wall time x{np.median(tr):.2f} (median; range {tr.min():.2f}-{tr.max():.2f}), "
    f"evaluations x{np.median(ev):.0f} (median)"
)
fallback = [lab for lab, c in zip(labels, comparisons) if ";" in c.ipopt.message]
print("IPOPT columns solved on the fallback strategy:", fallback or "none")

# %%
x = np.arange(len(comparisons))
fig, axes = plt.subplots(1, 3, figsize=(15, 4.6))
w = 0.4
for k, (name, get) in enumerate((("IPOPT", lambda c: c.ipopt), ("SUMT + Powell", lambda c: c.sumt))):
    axes[0].bar(x + (k - 0.5) * w, [get(c).wall_time * 1e3 for c in comparisons], w, label=name)
    axes[1].bar(x + (k - 0.5) * w, [get(c).function_evaluations for c in comparisons], w, label=name)
    axes[2].bar(x + (k - 0.5) * w, [get(c).iterations for c in comparisons], w, label=name)
for ax, ylabel, title in zip(
    axes,
    ("wall time (ms)", "function evaluations (count)", "iterations (count)"),
    ("solver time per column", "function evaluations per column", "iterations per column (SUMT: Powell sweeps)"),
):
    ax.set_yscale("log")
    ax.set_xticks(x, labels, rotation=70, ha="right", fontsize=7)
    ax.set_xlabel("published column")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=8)
    ax.grid(True, axis="y", which="both", color="0.92")
fig.tight_layout()
plt.show()

# %%
fig, axes = plt.subplots(1, 2, figsize=(12, 4.6))
ip = np.concatenate([c.ipopt.x for c in comparisons])
su = np.concatenate([c.sumt.x for c in comparisons])
kinds = np.tile([p.kind for p in m.parameters], len(comparisons))
for kind, marker in (("length", "o"), ("angle", "s")):
    sel = kinds == kind
    unit = "mm" if kind == "length" else "1e-2 rad"
    axes[0].loglog(ip[sel], su[sel], marker, ms=4, mfc="none", label=f"{kind} tolerances ({unit})")
lim = [ip.min() / 1.5, ip.max() * 1.5]
axes[0].plot(lim, lim, "k-", lw=0.7, label="equal")
axes[0].set_xlabel("IPOPT optimum eps (mm or 1e-2 rad)")
axes[0].set_ylabel("SUMT + Powell optimum eps (mm or 1e-2 rad)")
axes[0].set_title(f"Tolerances of all 18 columns ({ip.size} values)")
axes[0].legend(fontsize=8)
rel = np.abs(su / ip - 1)
axes[1].hist(np.log10(np.maximum(rel, 1e-16)), bins=30, color="C2")
axes[1].set_xlabel("log10 |SUMT / IPOPT - 1| per tolerance (dimensionless)")
axes[1].set_ylabel("number of tolerances (count)")
axes[1].set_title("Relative difference of the two solvers' tolerances")
fig.tight_layout()
plt.show()

# %% [markdown]
# Both solvers stop at a certified optimum (dual gap near 0, table above).  The tolerances agree
# less closely than the costs because the cost is flat at the optimum: a tolerance error `d`
# changes the cost only by `O(d^2)`.
#
# From scratch, on one pose, the compiled SUMT + Powell is the faster of the two here (the `S/I`
# column): IPOPT's exchange method spends about ten rounds closing in on the double principal
# sigma at the optimum.  IPOPT's speed is in re-solves, which start from a remembered optimum
# (under a millisecond, about ten times faster than SUMT: `benchmarks/bench_synthesis.py`), and
# in many poses (1000 poses in about a third of a second there).
#
# ## 3. Convergence histories
#
# ### SUMT: the outer loop
#
# Each outer iteration minimises the penalty function at one `r`; the cost of that minimiser
# approaches the optimum from above, and its largest `sigma_j z / R` approaches 1 from below (an
# interior method never leaves the feasible set).  For a log-barrier the cost excess is bounded by
# `r * nu` (`nu = 3` per pose block plus `2 * 0.01` per bound); every column follows that line.

# %%
from tolsynth.solvers.sumt import DEFAULT_OPTIONS

nu = 3 * DEFAULT_OPTIONS["w_acc"] + 2 * m.n * DEFAULT_OPTIONS["w_bnd"]
fig, axes = plt.subplots(1, 2, figsize=(13, 4.8), layout="constrained")
for k, c in enumerate(comparisons):
    h = c.sumt.history
    r = np.array([e["r"] for e in h])
    excess = np.array([e["cost"] for e in h]) - c.ipopt.cost
    slack = 1 - np.array([e["max_constraint"] for e in h])
    color = plt.cm.viridis(k / (len(comparisons) - 1))
    axes[0].loglog(r, np.maximum(excess, 1e-13), "o-", ms=3, lw=0.8, color=color)
    axes[1].loglog(r, np.maximum(slack, 1e-16), "o-", ms=3, lw=0.8, color=color)
rr = np.geomspace(
    min(e["r"] for c in comparisons for e in c.sumt.history),
    max(e["r"] for c in comparisons for e in c.sumt.history),
    10,
)
axes[0].loglog(rr, rr * nu, "k--", lw=1.2, label="barrier bound r * nu")
axes[0].set_xlabel("penalty weight r (cost units)")
axes[0].set_ylabel("cost - optimal cost (cost units)")
axes[0].set_title("SUMT outer iterations: cost excess over the optimum")
axes[0].legend(fontsize=8)
axes[1].set_xlabel("penalty weight r (cost units)")
axes[1].set_ylabel("1 - largest sigma_j z / R (dimensionless)")
axes[1].set_title("SUMT outer iterations: distance to the constraint")
for ax in axes:
    ax.invert_xaxis()
    ax.grid(True, which="both", color="0.92")
sm = plt.cm.ScalarMappable(cmap="viridis", norm=plt.Normalize(0, len(comparisons) - 1))
fig.colorbar(sm, ax=axes, label="column index (0-17, order of Tables 1-3)", pad=0.01)
plt.show()
print("outer iterations per column:", [len(c.sumt.history) for c in comparisons])

# %% [markdown]
# ### SUMT: Powell inside one outer iteration
#
# The reference column again: the penalty value after every Powell sweep, outer iteration after
# outer iteration (each curve relative to its own final value).  The first minimisation, from the
# interior start, takes the most sweeps; later ones restart from the previous minimiser and
# direction set and need fewer, but each still costs thousands of evaluations of the penalty, because
# every line search in Powell's method is a one-dimensional Brent search.

# %%
c = comparisons[2]
fig, ax = plt.subplots(figsize=(9, 4.5))
start = 0
for k, e in enumerate(c.sumt.history):
    hist = np.array(e["inner_history"])
    its = np.arange(start, start + hist.size)
    ax.semilogy(
        its,
        np.maximum(hist - hist[-1], 1e-14),
        ".-",
        ms=3,
        lw=0.8,
        label=f"r = {e['r']:.1e}: {e['inner_iterations']} sweeps, {e['inner_evaluations']} evaluations",
    )
    start += hist.size
ax.set_xlabel("Powell sweep, counted over all outer iterations (count)")
ax.set_ylabel("penalty - its final value in that outer iteration (cost units)")
ax.set_title(f"SUMT inner minimisations, {labels[2]}")
ax.legend(fontsize=7, ncol=2)
ax.grid(True, which="both", color="0.92")
fig.tight_layout()
plt.show()

# %% [markdown]
# ### IPOPT: objective and infeasibility per iteration
#
# `tolsynth.compare` runs IPOPT from scratch (no cuts or optimum remembered from an earlier
# solve), so these are whole solves.  IPOPT solves a cut NLP per exchange round (the constraint
# `sum_i eps_i^2 C_i(w) <= 1` along a finite set of directions w, found round by round), each
# round starting from the last one's optimum; the x axis counts IPOPT iterations over all rounds.
# Its iterates need not be feasible: `inf_pr` is the violation of the current round's cuts, and
# it jumps up where a round adds new cuts that the last optimum violates.

# %%
fig, axes = plt.subplots(1, 3, figsize=(15, 4.5), layout="constrained")
for k, c in enumerate(comparisons):
    h = c.ipopt.history
    it = range(len(h))  # IPOPT iterations counted over all exchange rounds
    color = plt.cm.viridis(k / (len(comparisons) - 1))
    axes[0].semilogy(it, [max(abs(e["objective"] - c.ipopt.cost), 1e-14) for e in h], lw=0.9, color=color)
    axes[1].semilogy(it, [max(e["inf_pr"], 1e-17) for e in h], lw=0.9, color=color)
    axes[2].semilogy(it, [max(e["inf_du"], 1e-17) for e in h], lw=0.9, color=color)
for ax, ylabel, title in zip(
    axes,
    (
        "|objective - optimal cost| (cost units)",
        "primal infeasibility inf_pr (dimensionless)",
        "dual infeasibility inf_du (cost units)",
    ),
    ("IPOPT objective", "IPOPT primal infeasibility", "IPOPT dual infeasibility"),
):
    ax.set_xlabel("IPOPT iteration, over all exchange rounds (count)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, which="both", color="0.92")
fig.colorbar(sm, ax=axes, label="column index (0-17, order of Tables 1-3)", pad=0.01)
plt.show()
first = []
for c in comparisons:
    h = c.ipopt.history
    ok = [
        k for k, e in enumerate(h) if abs(e["objective"] - c.ipopt.cost) <= 1e-9 * c.ipopt.cost and e["inf_pr"] <= 1e-8
    ]
    first.append((ok[0] if ok else len(h), len(h) - 1))
first = np.array(first)
print(
    f"iterations until cost within 1e-9 and inf_pr <= 1e-8: median {np.median(first[:, 0]):.0f}; "
    f"until IPOPT stops: median {np.median(first[:, 1]):.0f} (max {first[:, 1].max()})"
)

# %% [markdown]
# ## Summary

# %%
print(f"18 columns, both solvers converged: {all(c.ipopt.success and c.sumt.success for c in comparisons)}")
print(f"costs agree to {cd.max():.1e} (relative), tolerances to {td.max():.1e}")
print(
    f"IPOPT: {np.median([c.ipopt.iterations for c in comparisons]):.0f} iterations and "
    f"{np.median([c.ipopt.wall_time for c in comparisons]) * 1e3:.1f} ms per column (median)"
)
print(
    f"SUMT + Powell: {np.median([len(c.sumt.history) for c in comparisons]):.0f} outer iterations, "
    f"{np.median([c.sumt.function_evaluations for c in comparisons]):.0f} evaluations and "
    f"{np.median([c.sumt.wall_time for c in comparisons]):.2f} s per column (median)"
)
print(
    f"total solver time: IPOPT {sum(c.ipopt.wall_time for c in comparisons):.2f} s, "
    f"SUMT {sum(c.sumt.wall_time for c in comparisons):.1f} s"
)
