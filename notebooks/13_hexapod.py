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
# # 13 · A hexapod's tolerances: anchors against strut lengths, over its whole workspace
#
# A Gough-Stewart platform carries its moving plate on six struts. Its accuracy depends on where
# the twelve spherical joints sit (the *anchors*: three coordinates each, on the base and on the
# platform) and on each strut's length zero (its *offset*). Which of the 42 dimensions deserve
# the tight, expensive tolerances?
#
# The model is `stewart_gough`: the hexapod machine tool of Nategh & Agheli's kinematic-calibration
# study (Int. J. Machine Tools and Manufacture 49, 2009, Table 1): base joints on a circle of
# 325 mm radius, platform joints on one of 125 mm, every strut 604.8652 mm long at home, where the
# platform is level 565.4 mm above the base. The source's 42 kinematic parameters are the 42 error
# parameters here. The forward kinematics is Newton's method on the CasADi graph of the six closure
# equations; the error model is the implicit function theorem on the same graph
# (`d pose / d errors = -(df/dx)^-1 df/d errors`). Specification: R = 0.05 mm, p = 0.99 per
# principal component, uniform errors, alpha = 0.7, with the exact probabilities of uniform errors
# (solved by IPOPT: on these 42 errors the compiled interior-point method stops at its iteration
# limit).

# %%
import matplotlib.pyplot as plt
import numpy as np

import tolsynth

m = tolsynth.load_model("stewart_gough")
SPEC = dict(R=0.05, p=0.99, distribution="uniform", alpha=0.7, probability="exact", solver="ipopt")
print(m)
print("home pose (mm):", np.round(m.fk("home")[:3, 3], 6))
print("condition number of df/dx at home:", round(m.graphs.conditioning(m.joints("home"), np.zeros(m.n)), 3))

# %% [markdown]
# ## The optimum at the home pose
#
# One design, certified: every direction proven to meet p, and the cost within the dual bound. The table groups the 42 tolerances: each strut's base
# anchor, platform anchor and length offset.

# %%
home = tolsynth.synthesize(m, pose="home", **SPEC)
print(home.summary().splitlines()[0])
eps = dict(zip(m.error_parameters, home.x))
legs = [leg.name for leg in m.spec.legs]
rows = []
for leg in legs:
    rows.append([leg] + [eps[f"{leg}.{f}"] for f in ("bx", "by", "bz", "px", "py", "pz", "offset")])
print(f"{'strut':6}" + "".join(f"{h:>9}" for h in ("bx", "by", "bz", "px", "py", "pz", "offset")) + "   (mm)")
for r in rows:
    print(f"{r[0]:6}" + "".join(f"{v:9.4f}" for v in r[1:]))

# %% [markdown]
# ## Who makes the error: anchors or strut lengths?
#
# At the optimum, each parameter's share of the total position variance `tr V` (shares add up to
# 1; `tolsynth.contributions`). Summed by group: base anchors, platform anchors, strut offsets.
# An anchor error moves the strut's end sideways as well as along it, and only the component along
# the strut changes its length to first order, so an anchor tolerance buys less error per mm than
# an offset tolerance does. The optimum spends accordingly.

# %%
c = tolsynth.contributions(home)
share = dict(zip(m.error_parameters, c.total_share[0]))
groups = {
    "base anchors": [n for n in m.error_parameters if n.split(".")[1].startswith("b")],
    "platform anchors": [n for n in m.error_parameters if n.split(".")[1].startswith("p")],
    "strut offsets": [n for n in m.error_parameters if n.endswith(".offset")],
}
for g, names in groups.items():
    mean_eps = np.mean([eps[n] for n in names])
    print(
        f"{g:17}: {len(names):2d} parameters, share of tr V {sum(share[n] for n in names):.3f}, "
        f"mean tolerance {mean_eps:.4f} mm"
    )

fig, ax = plt.subplots(figsize=(8, 3.2))
x = np.arange(len(legs))
bottom = np.zeros(len(legs))
for g, names in groups.items():
    vals = np.array([sum(share[n] for n in names if n.startswith(leg + ".")) for leg in legs])
    ax.bar(x, vals, bottom=bottom, label=g)
    bottom += vals
ax.set_xticks(x, legs)
ax.set_ylabel("share of tr V")
ax.set_title("stewart_gough at home: where the position variance comes from")
ax.legend(frameon=False, ncol=3, fontsize=8)
plt.show()

# %% [markdown]
# ## The whole workspace
#
# The home pose is the easy one. `synthesize_workspace` imposes the specification at every
# actuator vector of the strokes (600 to 640 mm each, a box the model file chose to stay clear of
# singularities: its condition number of df/dx is at most 12, against 6.7 at home) where the platform assembles: optimise at a
# set of poses, search the strut space for the pose of lowest exact per-direction probability at
# that optimum (from the pose of largest principal sigma and a grid ranked by the exact
# probability, then a local search over struts and directions), add it, repeat. The search treats
# a strut vector where Newton's method cannot assemble the platform as outside the workspace. The
# sigma search's coarse grid here is 4 points per strut (4^6 = 4096 strut vectors, then a pattern
# search from the best of them).

# %%
ws = tolsynth.synthesize_workspace(m, pose="home", search={"grid": 4}, **SPEC)
print(ws.summary().splitlines()[0])
print(
    f"cost at home only {home.cost:.2f}, over the workspace {ws.result.cost:.2f} "
    f"(+{100 * (ws.result.cost / home.cost - 1):.1f} %)"
)
worst_q = ws.rounds[-1]["worst_q"]
print("worst pose found: struts", m.format_joints(worst_q), "hand", np.round(ws.rounds[-1]["worst_position"], 2), "mm")
a_home = m.analyze("home", home.x, R=SPEC["R"])
a_worst = m.analyze(worst_q, home.x, R=SPEC["R"])
print(
    f"the home design at the worst pose: largest sigma {a_worst.principal_std[0]:.4f} mm "
    f"(at home {a_home.principal_std[0]:.4f} mm)"
)

# %% [markdown]
# ## The workspace map
#
# `P(|dr| <= R)` at the workspace design over a vertical plane through the base's centre, the
# platform level (its home orientation): the closed-form inverse kinematics gives the struts at
# each grid point, and a point counts as reachable when the struts are inside their strokes and
# the forward kinematics gives the point back.

# %%
pm = tolsynth.probability_map(m, ws.result.x, R=SPEC["R"], n=41, plane="xz", progress=False)
print(
    f"reachable points {int(np.isfinite(pm.P).sum())} of {pm.P.size}; lowest P {pm.worst[2]:.4f} at "
    f"x = {pm.worst[0]:.1f}, z = {pm.worst[1]:.1f} mm"
)
pm.plot()
plt.show()

# %% [markdown]
# ## Monte Carlo through the nonlinear forward kinematics
#
# Errors drawn uniformly within the workspace design's tolerances, pushed through Newton's forward
# kinematics (the graph, evaluated on whole batches), at the worst pose found: the sphere
# probability against the linear model's.

# %%
mc = tolsynth.monte_carlo(m, worst_q, ws.result.x, R=SPEC["R"], n=50_000, seed=1, progress=False)
print(
    f"P(|dr| <= R): Monte Carlo {mc.p_sphere:.4f} [{mc.p_sphere_ci[0]:.4f}, {mc.p_sphere_ci[1]:.4f}], "
    f"linear model, Gaussian reading {mc.p_sphere_analytic:.4f}; samples not assembled: {mc.n_loop_failures}"
)
