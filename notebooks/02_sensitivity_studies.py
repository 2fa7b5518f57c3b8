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
# # 02 · Sensitivity studies
#
# How do the optimal tolerances of the Xu & Zhang robot respond to the specification?  This
# notebook sweeps the accuracy radius `R`, the probability `p`, the cost exponent `alpha` and the
# error distribution, asks which parameter fills which part of the error budget at the optimum,
# and checks the paper's central simplification: imposing the accuracy constraints at one
# "pose of largest error" only.
#
# Every solve reads the paper's criterion (`probability="gaussian"`: each principal component read
# as normal), so the studies answer the paper's questions; the library's default, the exact
# probabilities, is compared with it in notebook 11.  All solves take a few ms each, with the
# model's default bounds and cost factors.
# Units: `R` in mm; length tolerances in mm, angular ones in 1e-2 rad (the paper's printed unit);
# cost `sum k_i eps_i^-alpha` in the paper's units (evaluated on those numbers, so costs at
# different `alpha` are not comparable with each other).

# %%
import math

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import FuncFormatter
from tqdm import tqdm

import tolsynth
from tolsynth import plot_map, probability_map, worst_pose

m = tolsynth.load_model("xu_zhang_1988")
names = m.error_parameters
lengths = [i for i, p in enumerate(m.parameters) if p.kind == "length"]
angles = [i for i, p in enumerate(m.parameters) if p.kind == "angle"]
BASE = dict(R=0.5, p=0.99, alpha=0.7)  # the paper's Table 1 middle column
print(m)
print("base case:", BASE, "| bounds (lower, upper):", {n: (lo, hi) for n, lo, hi in zip(names, *m.bounds)})

# %% [markdown]
# ## 1. Sweeps of R, p and alpha, for both distributions
#
# One helper solves a grid of specifications and stacks the tolerances and costs; each solve must
# report success (a failed solve is never plotted as an optimum).

# %%
DISTS = ("uniform", "normal")


def sweep(param, values, **fixed):
    """Optimal tolerances (len(values), n) and cost (len(values),) for each distribution."""
    out = {}
    for dist in DISTS:
        X, cost, active = [], [], []
        for v in values:
            spec = {**BASE, **fixed, param: v}
            res = tolsynth.synthesize(m, spec["R"], spec["p"], dist, spec["alpha"], probability="gaussian")
            assert res.success, (param, v, dist, res.status, res.message)
            X.append(res.x)
            cost.append(res.cost)
            active.append(sorted(res.bounds_active))
        out[dist] = (np.array(X), np.array(cost), active)
    return out


R_values = np.geomspace(0.01, 2.0, 40)
p_values = 1 - np.geomspace(0.5, 0.001, 40)  # denser towards p = 1, where the cost rises steeply
alpha_values = np.linspace(0.4, 1.2, 33)
sweeps = {}
for param, values in tqdm([("R", R_values), ("p", p_values), ("alpha", alpha_values)], desc="sweeps"):
    sweeps[param] = (values, sweep(param, values, probability="gaussian"))
print("solves:", sum(len(v) for v, _ in sweeps.values()) * len(DISTS))


# %%
def label_log_ticks(axis):
    """Plain numbers on a log axis spanning about a decade: 0.02, 0.03, 0.05, 0.1, ..."""

    def fmt(v, _):
        mant = v / 10 ** math.floor(math.log10(v))
        return f"{v:g}" if any(abs(mant - k) < 1e-6 for k in (1, 2, 3, 5)) else ""

    axis.set_major_formatter(FuncFormatter(fmt))
    axis.set_minor_formatter(FuncFormatter(fmt))


def plot_sweep(param, xlabel, logx=False, logy_cost=False):
    values, data = sweeps[param]
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.3))
    for dist, ls in zip(DISTS, ("-", "--")):
        X, cost, _ = data[dist]
        for k, (idx, ax) in enumerate(((lengths, axes[0]), (angles, axes[1]))):
            for c, i in enumerate(idx):
                ax.plot(values, X[:, i], ls, color=f"C{c}", label=names[i] if dist == "uniform" else None)
        axes[2].plot(values, cost, ls, color="k", label=dist)
    axes[0].set_ylabel("length tolerance eps (mm)")
    axes[1].set_ylabel("angular tolerance eps (1e-2 rad)")
    axes[2].set_ylabel("cost sum k eps^-alpha (paper's units)")
    for ax in axes:
        ax.set_xlabel(xlabel)
        if logx:
            ax.set_xscale("log")
        ax.grid(True, which="both", color="0.92")
    axes[0].set_yscale("log")
    axes[1].set_yscale("log")
    if not logx:  # tolerances span about a decade: label the minor ticks too
        label_log_ticks(axes[0].yaxis)
        label_log_ticks(axes[1].yaxis)
    if logy_cost:
        axes[2].set_yscale("log")
        if not logx:
            label_log_ticks(axes[2].yaxis)
    axes[0].legend(fontsize=7, ncol=2, title="solid uniform, dashed normal", title_fontsize=7)
    axes[1].legend(fontsize=7)
    axes[2].legend(fontsize=8)
    axes[0].set_title(f"length tolerances vs {param}")
    axes[1].set_title(f"angular tolerances vs {param}")
    axes[2].set_title(f"optimal cost vs {param}")
    fig.suptitle(
        f"Optimal tolerances against {param} (others: "
        + ", ".join(f"{k} = {v:g}" for k, v in BASE.items() if k != param)
        + ")",
        y=1.02,
    )
    fig.tight_layout()
    plt.show()


plot_sweep("R", "accuracy radius R (mm)", logx=True, logy_cost=True)

# %% [markdown]
# **R.**  With no bound active the constraint depends on `eps` only through `eps z(p) / R`, so
# every tolerance is proportional to `R` and the cost to `R^-alpha`: straight lines on the log-log
# axes.  Below some `R` the lower bounds (0.001 mm for lengths) start to bind, the lines kink,
# and the remaining parameters have to tighten faster; a little further down no tolerances inside
# the bounds meet the specification at all (`InfeasibleSpecificationError`).
#
# Two pairs of lines lie on top of each other: `h'2 = h'4` and `s1 = a` at every optimum (their
# sensitivity columns are equal up to sign, notebook 01).

# %%
values, data = sweeps["R"]
for dist in DISTS:
    X, cost, active = data[dist]
    free = np.array([not a for a in active])
    slope = np.polyfit(np.log(values[free]), np.log(cost[free]), 1)[0]
    first = next((v, a) for v, a in zip(values, active) if a) if not free.all() else None
    print(
        f"{dist:>7}: log-log slope of cost vs R with no bound active = {slope:.6f} (exact: -alpha = {-BASE['alpha']})"
    )
    if first:
        print(f"         bounds active below R = {values[~free].max():.4g} mm: {first[1]} at R = {first[0]:.4g} mm")
    ratio = X[free] / values[free, None]
    print(f"         eps / R constant to {np.max(np.ptp(ratio, axis=0) / ratio.mean(axis=0)):.1e} (relative)")
try:
    tolsynth.synthesize(m, 0.005, BASE["p"], "uniform", BASE["alpha"], probability="gaussian")
except tolsynth.InfeasibleSpecificationError as exc:
    print("R = 0.005 mm:", exc)
print(
    "pairs equal: max |h'2 - h'4| / h'2 =",
    f"{max(np.max(np.abs(d[0][:, m.index('hp2')] / d[0][:, m.index('hp4')] - 1)) for _, dd in sweeps.values() for d in dd.values()):.1e},",
    "max |s1 - a| / a =",
    f"{max(np.max(np.abs(d[0][:, m.index('s1')] / d[0][:, m.index('a')] - 1)) for _, dd in sweeps.values() for d in dd.values()):.1e}",
)

# %%
plot_sweep("p", "probability per principal component p (dimensionless)", logy_cost=True)

# %% [markdown]
# **p.**  `p` enters only through the two-sided normal quantile `z(p)`, so every tolerance is
# proportional to `1 / z(p)`: relaxing `p` from 0.99 to 0.7 widens every tolerance by
# `z(0.99) / z(0.7)`, and the cost grows without bound as `p -> 1`.

# %%
values, data = sweeps["p"]
zs = np.array([tolsynth.z_of_p(p) for p in values])
for dist in DISTS:
    X = data[dist][0]
    prod = X * zs[:, None]
    print(
        f"{dist:>7}: eps * z(p) constant to {np.max(np.ptp(prod, axis=0) / prod.mean(axis=0)):.1e} (relative); "
        f"widening from p = 0.99 to 0.7: z(0.99)/z(0.7) = {tolsynth.z_of_p(0.99) / tolsynth.z_of_p(0.7):.4f}"
    )

# %%
plot_sweep("alpha", "cost exponent alpha (dimensionless)")

# %% [markdown]
# **alpha.**  The paper concludes that the cost exponent matters little: the tolerances shrink
# slightly as `alpha` grows.  The sweep agrees that the *spread* is small over the paper's range
# 0.6-1.0, but the direction is not the same for every parameter: the constraint fixes the
# principal sigma, so when one tolerance tightens another may loosen.  (The cost curve itself is
# not comparable across `alpha`: the cost function changes with it.)

# %%
values, data = sweeps["alpha"]
sel = (values >= 0.6 - 1e-9) & (values <= 1.0 + 1e-9)
X = data["uniform"][0][sel]
print(f"uniform, alpha from {values[sel][0]:.2f} to {values[sel][-1]:.2f}: tolerance at alpha = 1 / at alpha = 0.6")
for i, n in enumerate(names):
    print(f"  {n:>7} {X[-1, i] / X[0, i]:7.3f}")

# %% [markdown]
# **Distribution.**  The normal reading (`3 sigma = eps`, variance `eps^2 / 9`) and the uniform one
# (variance `eps^2 / 3`) differ by a constant factor in the variance, so with the bounds inactive
# every normal tolerance is exactly `sqrt(3)` times the uniform one and the cost ratio is
# `3^(-alpha/2)`.  Over all three sweeps:

# %%
for param, (values, data) in sweeps.items():
    (XU, CU, AU), (XN, CN, AN) = data["uniform"], data["normal"]
    free = np.array([not a and not b for a, b in zip(AU, AN)])
    r = XN[free] / XU[free]
    alphas = values[free] if param == "alpha" else np.full(free.sum(), BASE["alpha"])
    cr = CN[free] / CU[free] / 3.0 ** (-alphas / 2)
    print(
        f"sweep {param:>5}: normal/uniform tolerance ratio in [{r.min():.6f}, {r.max():.6f}] (sqrt(3) = "
        f"{math.sqrt(3):.6f}); cost ratio / 3^(-alpha/2) in [{cr.min():.6f}, {cr.max():.6f}]"
    )

# %% [markdown]
# ## 2. Who fills the error budget?  Shares of the principal variances
#
# At the optimum the position covariance at the worst pose is `V = sum_i eps_i^2 a_i a_i^T / c`
# (`a_i` the sensitivity column of parameter `i`, `c = 3` uniform, 9 normal).  Along a principal
# direction `d_j` its variance is `lambda_j = sum_i eps_i^2 (d_j . a_i)^2 / c`, so each parameter's
# share of `lambda_j` is `eps_i^2 (d_j . a_i)^2 / c / lambda_j`.  The constraint values
# `sigma_j z / R` and their multipliers (the marginal cost of tightening each principal sigma) come
# with the result.
#
# One subtlety: at this optimum the two largest principal sigma are *equal* (both constraints
# active), so any pair of orthogonal directions in their plane is a valid pair of principal
# directions, and an eigen-solver returns an arbitrary one (the paper's closed-form appendix
# assumes distinct eigenvalues).  Inside such a degenerate plane we pick the pair that also
# diagonalises the covariance of the angular parameters alone; here that separates the `y`
# direction (angles) from the in-plane one (lengths).

# %%
res = tolsynth.synthesize(m, BASE["R"], BASE["p"], "uniform", BASE["alpha"], probability="gaussian")
print(res.summary())
S = m.sensitivity("worst")[:3]  # mm per tolerance unit
c = 3.0
eps = res.x
V = (S * eps**2 / c) @ S.T
lam, D = np.linalg.eigh(V)
lam, D = lam[::-1], D[:, ::-1]
print("\nprincipal variances (mm^2):", lam, " relative gap lambda1 - lambda2:", f"{(lam[0] - lam[1]) / lam[0]:.1e}")
if (lam[0] - lam[1]) / lam[0] < 1e-6:  # degenerate: rotate inside the plane of d1, d2
    V_ang = (S[:, angles] * eps[angles] ** 2 / c) @ S[:, angles].T
    E = D[:, :2]
    _, Rot = np.linalg.eigh(E.T @ V_ang @ E)
    D[:, :2] = E @ Rot[:, ::-1]
    lam = np.einsum("ij,ik,kj->j", D, V, D)
share = (eps[None, :] ** 2 * (D.T @ S) ** 2 / c) / lam[:, None]  # (3 directions, n parameters)
block = res.constraints[0]
print(
    "sigma_j z / R from these directions:",
    (np.sqrt(lam) * tolsynth.z_of_p(BASE["p"]) / BASE["R"]).round(6),
    " from the result:",
    block.values.round(6),
)
print("shares sum to 1 per direction:", share.sum(axis=1).round(12))
print(f"\n{'param':>7}" + "".join(f"   d{j + 1} = ({', '.join(f'{v:+.3f}' for v in D[:, j])})" for j in range(3)))
for i, n in enumerate(names):
    print(f"{n:>7}" + "".join(f"{100 * share[j, i]:>30.1f}%" for j in range(3)))

# %%
fig, ax = plt.subplots(figsize=(10, 3.8))
left = np.zeros(3)
sig_ratio = np.sqrt(lam) * tolsynth.z_of_p(BASE["p"]) / BASE["R"]
ylabels = [
    f"w{j + 1}: d = ({', '.join(f'{v:+.2f}' for v in D[:, j])}), sigma z/R = {sig_ratio[j]:.3f}" for j in range(3)
]
for i, n in enumerate(names):
    ax.barh(range(3), 100 * share[:, i], left=left, color=plt.cm.tab20(i), label=n)
    for j in range(3):
        if share[j, i] > 0.06:
            ax.text(left[j] + 50 * share[j, i], j, n, ha="center", va="center", fontsize=8)
    left += 100 * share[:, i]
ax.set_yticks(range(3), ylabels, fontsize=8)
ax.invert_yaxis()
ax.set_xlim(0, 100)
ax.set_xlabel("share of the principal variance lambda_j (%)")
ax.set_ylabel("principal direction (base frame)")
ax.set_title(
    f"Error budget at the optimum, worst pose (R = {BASE['R']} mm, p = {BASE['p']}, uniform, alpha = {BASE['alpha']})"
)
ax.legend(ncol=6, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.22))
fig.tight_layout()
plt.show()

# %% [markdown]
# The two largest principal sigma are active (at 1) and carry positive multipliers; the third is
# slack.  The `y` direction is filled by the three angular tolerances only, the in-plane directions
# by the lengths only, as the block structure of the sensitivities demands.

# %% [markdown]
# ## 3. The worst pose moves when the tolerances change
#
# The paper imposes Eq. 20 only at one pose, found beforehand with *other* tolerances.  But the
# pose of largest error depends on the tolerances themselves.  `tolsynth.worst_pose`
# searches the whole joint space (inside the joint limits and the interference limit) for the
# largest principal sigma, which is exactly the quantity the constraint bounds.  For several
# tolerance sets:

# %%
z99 = tolsynth.z_of_p(BASE["p"])
cases = {"figure3 (paper's Fig. 3)": m.tolerances("figure3")}
for al in (0.6, 0.7, 1.0):
    for dist in DISTS:
        r = tolsynth.synthesize(m, BASE["R"], BASE["p"], dist, al, probability="gaussian")
        cases[f"optimum alpha={al:g} {dist}"] = (r.x, dist)
print(f"{'tolerances':<28} {'worst pose found: joints (deg)':>42} {'hand (mm)':>22} {'sigma1 found/ref.':>18}")
worst_found = {}
for label, val in cases.items():
    tol, dist = (val, "uniform") if isinstance(val, np.ndarray) else val
    w = worst_pose(m, tol, criterion="sigma", distribution=dist)
    worst_found[label] = w
    print(
        f"{label:<28} {str(np.degrees(w.q).round(2).tolist()):>42} {str(w.position[[0, 2]].round(1).tolist()):>22} "
        f"{w.value / w.reference_value:18.4f}"
    )
print("\njoint order:", m.joint_names, "(theta1 and theta5 do not change the statistics and are held)")
print("hand: (X0, Z0); the paper's pose has its hand at", m.fk("worst")[[0, 2], 3].round(1).tolist())

# %% [markdown]
# For every set the worst pose is *not* the paper's pose, and the optimum computed at the paper's
# pose violates the specification elsewhere in the workspace by the factor in the last column.
# (It does not depend on `R`, `p` or the distribution: those only scale all tolerances together.)
#
# ### Beyond the paper: the constraint at every pose
#
# Requiring Eq. 20 at *every* reachable pose is a semi-infinite program.  A simple exchange method
# solves it: optimise at a finite set of poses, search the workspace for the worst pose at the new
# optimum, add it to the set (`synthesize(..., poses=[...])`), and repeat until the worst pose over
# the workspace meets the specification.  `tolsynth.synthesize_workspace` (and
# `tolsynth solve --everywhere`) does exactly that.

# %%
R, p = BASE["R"], BASE["p"]
ws = tolsynth.synthesize_workspace(
    m, R, p, "uniform", BASE["alpha"], probability="gaussian"
)  # the exchange method, built in
assert ws.success
single = tolsynth.synthesize(m, R, p, "uniform", BASE["alpha"], probability="gaussian")  # the paper's: one pose
history = [(r["n_poses"], r["cost"], r["worst_value"], r["worst_q"], r["worst_position"], None) for r in ws.rounds]
history[0] = history[0][:5] + (single,)
history[-1] = history[-1][:5] + (ws.result,)
print(f"{'iter':>4} {'poses':>5} {'cost':>9} {'worst sigma1 z/R over the workspace':>36}   worst pose (deg)")
for k, (npose, cost, g, q, pos, _) in enumerate(history):
    print(f"{k:>4} {npose:>5} {cost:9.4f} {g:36.5f}   {np.degrees(q).round(2).tolist()}")
final = history[-1][5]
print(
    f"\ncost of meeting the spec everywhere: {final.cost:.4f} against {history[0][1]:.4f} at the paper's pose "
    f"(+{100 * (final.cost / history[0][1] - 1):.1f}%)"
)
print(f"{'param':>7} {'paper pose':>11} {'everywhere':>11} {'ratio':>7}")
for n, a, b in zip(names, history[0][5].x, final.x):
    print(f"{n:>7} {a:11.5g} {b:11.5g} {b / a:7.3f}")

# %% [markdown]
# Where are these poses?  Below: the sphere probability `P(|dr| <= R)` over the `X0 Z0` plane (hand
# vertical, as in Figure 3) for the tolerances that meet the specification everywhere, with the
# hand points of the worst poses found on the way.  Those poses have their own hand orientation
# (the search leaves the wrist pitch free), so only their positions are comparable with the map.
# Note that the map shows the *sphere* probability of Eq. 5, which is lower than the `p` asked of
# each principal component (Eq. 14/20): the sphere of radius `R` lies inside the zone
# `|w_j| <= R` of every component, so its probability is lower than any component's.

# %%
pmap = probability_map(m, final.tolerances, R=R, distribution="uniform", n=60, progress=False)
fig = plot_map(pmap)
ax = fig.axes[0]
pts = np.array([h[4] for h in history])
ax.plot(
    pts[:, 0],
    pts[:, 2],
    "o",
    color="darkorange",
    mec="k",
    ms=7,
    label="hand points of the worst poses found (any hand orientation)",
)
for k, pt in enumerate(pts):
    ax.annotate(str(k), (pt[0], pt[2]), textcoords="offset points", xytext=(6, 4), fontsize=8)
ax.legend(loc="upper left", fontsize=8, framealpha=0.9)
ax.set_title(
    f"P(|dr| <= {R:g} mm) for the tolerances that meet the spec at every pose (uniform errors)\n"
    "numbers: exchange iteration in which the pose was found",
    fontsize=10,
)
plt.show()

# %% [markdown]
# ## 4. Per component (the paper) or the sphere?
#
# The paper asks `P(|w_j| <= R) >= p` of each principal component (Eq. 14/20) and calls that the
# stricter demand.  It is the weaker one: the sphere `|dr| <= R` lies inside every component's
# slab `|w_j| <= R`, so `P(sphere) <= P(component)`.  `synthesize(..., criterion="sphere")` asks
# `P(|dr| <= R) >= p` itself.  Below, for the paper's R = 0.5 mm, uniform errors, alpha = 0.7: the
# sphere probability the per-component optimum actually reaches, and the cost of each criterion.

# %%
from tolsynth.probability.stats import covariance, p_ball, principal

p_grid = [0.7, 0.8, 0.9, 0.95, 0.99, 0.999]
rows = []
S_worst = m.sensitivity("worst")
for pp in p_grid:
    comp = tolsynth.synthesize(m, BASE["R"], pp, "uniform", BASE["alpha"], probability="gaussian")
    sph = tolsynth.synthesize(m, BASE["R"], pp, "uniform", BASE["alpha"], criterion="sphere", probability="gaussian")
    assert comp.success and sph.feasible  # the sphere: met, its optimality not proven (not convex)
    sig, _ = principal(covariance(S_worst, comp.x, "uniform")[0])
    rows.append((pp, p_ball(sig**2, BASE["R"]), comp.cost, sph.cost))
print(
    f"{'p':>6} {'P(sphere) at the per-component optimum':>40} {'cost components':>16} {'cost sphere':>12} {'extra':>7}"
)
for pp, ps, cc, cs in rows:
    print(f"{pp:>6} {ps:>40.4f} {cc:>16.3f} {cs:>12.3f} {100 * (cs / cc - 1):>6.1f}%")

fig, (a1, a2) = plt.subplots(1, 2, figsize=(12, 4))
a1.plot(p_grid, [r[1] for r in rows], "o-", label="P(|dr| <= R) at the per-component optimum")
a1.plot(p_grid, p_grid, "k--", lw=1, label="p asked")
a1.set_xlabel("p (probability asked)")
a1.set_ylabel("probability")
a1.set_title("the per-component demand leaves the sphere short")
a1.legend()
a2.plot(p_grid, [r[2] for r in rows], "o-", label="per component (paper, Eq. 20)")
a2.plot(p_grid, [r[3] for r in rows], "s-", label="sphere P(|dr| <= R) >= p")
a2.set_xlabel("p (probability asked)")
a2.set_ylabel("cost (sum k eps^-alpha, paper's units)")
a2.set_title(f"optimal cost, R = {BASE['R']} mm, uniform errors")
a2.legend()
plt.show()
