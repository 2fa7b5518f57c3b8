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
# # 11 · The probability the designer asks for: Gaussian, exact and verified designs
#
# The paper reads each principal component of the hand error as a normal variable (Eq. 6-7): with
# uniform errors (single-piece production) the component is a sum of a few bounded terms, and
# `P(|w| <= R)` is not the normal value. tolsynth offers three designs for the same
# specification:
#
# * **Gaussian** (`probability="gaussian"`, the default and the paper's): `z(p) sigma_1 <= R`;
# * **exact** (`probability="exact"`): `P(|u . dr| <= R) >= p` along every direction `u`, with the
#   exact probability of the linear error model (the characteristic function inverted with a
#   rigorous error bound, `tolsynth.probability.exact`), as the NLP's constraints;
# * **verified** (`verify=True`): the nonlinear Monte Carlo at the optimum, and a tighter target
#   until the 99 % lower confidence bound of the achieved probability reaches `p`.
#
# The paper's robot at its worst pose, R = 0.5 mm, uniform errors, alpha = 0.7 (Tables 1-2).

# %%
import time

import matplotlib.pyplot as plt
import numpy as np

import tolsynth
from tolsynth.probability.exact import direction_probability

m = tolsynth.load_model("xu_zhang_1988")
A = m.sensitivity(m.joints("worst"))[:3]
R = 0.5
shapes = ["uniform"] * m.n

# %% [markdown]
# ## Three designs per column
#
# For each p: the cost of each design, and the probability it achieves along the exact design's
# binding direction `w*`, exactly (`direction_probability`) and by a nonlinear Monte Carlo of
# 200,000 samples (99 % Wilson interval).

# %%
rows = []
designs = {}
for p in (0.9, 0.99):
    t0 = time.perf_counter()
    g = tolsynth.synthesize(m, R=R, p=p)
    e = tolsynth.synthesize(m, R=R, p=p, probability="exact")
    v = tolsynth.synthesize(m, R=R, p=p, probability="exact", verify=True, seed=1)
    w = e.constraints[0].directions[:, 0]
    designs[p] = (g, e, v, w)
    for name, r in (("Gaussian", g), ("exact", e), ("verified", v)):
        mc = tolsynth.monte_carlo(m, "worst", r.x, R=R, n=200_000, seed=7, directions=w[:, None], confidence=0.99)
        lo, hi = mc.p_directions_ci[0]
        rows.append((p, name, r.cost, direction_probability(w @ A * r.x, shapes, R), mc.p_directions[0], lo, hi))
    print(f"p = {p}: three designs in {time.perf_counter() - t0:.1f} s")

print(f"\n{'p':>5} {'design':>9} {'cost':>9} {'exact P(w*)':>12} {'MC P(w*)':>9} {'99% interval':>20}")
for p, name, cost, Pe, Pm, lo, hi in rows:
    print(f"{p:5.2f} {name:>9} {cost:9.4f} {Pe:12.6f} {Pm:9.5f} [{lo:.5f}, {hi:.5f}]")

# %% [markdown]
# The exact design sits at `p` along `w*` (the Monte Carlo interval contains p), the verified
# design a little above it (its lower bound reaches p), and the Gaussian design is off: at
# p = 0.99 uniform sums have lighter tails than the normal, so the Gaussian design is dearer than
# needed (84.42 against 82.97 when this was written); at p = 0.9 it falls just short along `w*`
# (0.8995), and at p = 0.8 more so (0.7952, measured when this was written).

# %%
print(designs[0.99][2].verification.report())

# %% [markdown]
# ## Cost against p, and the probability the Gaussian design really achieves

# %%
ps = np.array([0.7, 0.8, 0.9, 0.95, 0.99])
cg, ce, Pg = [], [], []
for p in ps:
    g = tolsynth.synthesize(m, R=R, p=p)
    e = tolsynth.synthesize(m, R=R, p=p, probability="exact")
    cg.append(g.cost)
    ce.append(e.cost)
    Pg.append(tolsynth.worst_direction(A, g.x, shapes, R)[1])

fig, ax = plt.subplots(1, 2, figsize=(11, 4))
ax[0].plot(ps, cg, "o-", label="Gaussian (the paper's)")
ax[0].plot(ps, ce, "s-", label="exact")
ax[0].set_xlabel("p")
ax[0].set_ylabel("cost")
ax[0].legend()
ax[0].set_title("cost of the design")
ax[1].plot(ps, np.array(Pg) - ps, "o-")
ax[1].axhline(0, color="k", lw=0.8)
ax[1].set_xlabel("p asked")
ax[1].set_ylabel("exact P(worst direction) - p")
ax[1].set_title("what the Gaussian design achieves")
fig.tight_layout()
plt.show()

# %% [markdown]
# Below p of about 0.9 the Gaussian design falls short of what it promises along its worst
# direction (the uniform sum is flatter than a normal near its centre); above it, the design is
# more conservative than needed and costs more. The exact design meets `p` at equality either way.
#
# ## Mixed shapes
#
# A distribution per parameter (`distribution={"*": "uniform", "s1": "normal", ...}`): here the
# angles come from a screened batch process (normal truncated at +- eps, beta = 2) and the lengths
# are single pieces (uniform).

# %%
mixed = {"*": "uniform", "alpha1": "truncnormal", "alpha3": "truncnormal", "alpha4": "truncnormal"}
g = tolsynth.synthesize(m, R=R, p=0.99, distribution=mixed)
e = tolsynth.synthesize(m, R=R, p=0.99, distribution=mixed, probability="exact")
print(f"mixed shapes, p = 0.99: Gaussian {g.cost:.4f}, exact {e.cost:.4f} ({100 * (e.cost / g.cost - 1):+.2f} %)")
