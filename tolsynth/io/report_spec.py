"""The design report's specification section (what was asked, in the design's reading) and the
helpers that tell a design's reading."""

from __future__ import annotations

import numpy as np


def _is_exact(res) -> bool:
    """Whether ``res`` was designed with ``probability="exact"``."""
    return (getattr(res, "inputs", None) or {}).get("probability") == "exact" or any(
        b.kind.endswith("(exact)") for b in res.constraints
    )


def _asked_p(res, spec) -> str:
    """p as asked; after a closed loop (verify) the design's tighter target beside it."""
    ver = getattr(res, "verification", None)
    if ver is None or abs(ver.p - spec.p) <= 1e-15:
        return f"{spec.p:g}"
    return f"{ver.p:g} asked (the design's target after the closed loop: {spec.p:.6g})"


def specification_blocks(rep) -> list[tuple]:
    """Section 1: R, p and what p means in the design's reading, the model of probability, the
    distribution, alpha, the poses and the solver."""
    from tolsynth.probability.distributions import describe, label

    mech, res, spec = rep.mechanism, rep.result, rep.result.spec
    exact = _is_exact(res)
    B: list[tuple] = []
    B.append(("h", 2, "1. Specification"))
    alpha = np.asarray(spec.alpha, dtype=float)
    alpha_txt = (
        f"{alpha[0]:g} (every parameter)"
        if np.all(alpha == alpha[0])
        else ", ".join(f"{n} {a:g}" for n, a in zip(spec.names, alpha))
    )
    kv = [
        ("model", f"{mech.name}: {mech.title}"),
        ("position accuracy R", f"{spec.R:g} mm"),
        (
            "probability p",
            _asked_p(res, spec)
            + (
                " along every direction u at every pose: P(|u . dr| <= R) >= p in the linear error model's exact "
                "distribution"
                if spec.criterion == "components" and exact
                else " per principal component (the paper's Eq. 20)"
                if spec.criterion == "components"
                else " of the sphere P(|dr| <= R)" + (", exact" if exact else ", Gaussian")
            ),
        ),
        ("criterion", spec.criterion),
        (
            "probability model",
            "exact (the linear error model's own probabilities, no Gaussian reading)"
            if exact
            else "gaussian (the paper's: each principal component read as normal)",
        ),
        ("z(p)", f"{spec.z:.6g}" + (" (the Gaussian reading's, not used by this exact design)" if exact else "")),
        ("error distribution", f"{label(spec.distribution)}: {describe(spec.distribution)}"),
        ("cost exponent alpha", alpha_txt),
    ]
    if spec.Phi is not None:
        kv.append(("orientation accuracy Phi", f"{spec.Phi:g} rad, probability {spec.p_orientation:g}"))
    for lbl, q in spec.poses.items():
        kv.append((f"pose '{lbl}'", f"joints {mech.format_joints(q)} ({', '.join(mech.joint_names)})"))
    kv.append(
        (
            "solver",
            f"{res.solver}: {res.status} ({res.message}); {res.iterations} iterations, {res.wall_time * 1e3:.1f} ms",
        )
    )
    locks = (res.inputs or {}).get("locks")
    if locks:
        kv.append(("fixed tolerances", ", ".join(f"{k} = {v:g}" for k, v in locks.items())))
    B.append(("kv", kv))
    return B
