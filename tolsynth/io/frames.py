"""The table builders of :mod:`tolsynth.io.tables`: one ``DataFrame`` per result type, with the
``attrs`` that module's docstring lists (rows and columns described there)."""

from __future__ import annotations

import numpy as np

from tolsynth.errors import InputError
from tolsynth.tabular import (
    _synthesis_inputs,
    jsonable,
    make_frame,
    synthesis_summary,
)
from tolsynth.units import joint_values, units_label

# ---------------------------------------------------------------------------------------------
# inputs of a synthesis
# ---------------------------------------------------------------------------------------------


def _joint_units(result, n: int) -> tuple[str, ...]:
    """Each joint column's unit: the result's own ("mm" for a joint that slides), else rad."""
    return tuple(getattr(result, "joint_units", ()) or ("rad",) * n)


def _synthesis_frame(res):
    spec = res.spec
    rows = []
    for i, (name, eps) in enumerate(res.tolerances.items()):
        row = {"parameter": name, "unit": res.units[name], "tolerance": eps}
        if spec is not None:
            model = spec.costs.models[i]
            # k and alpha of the cost model the solve used (a process's or a cost= model's, not the
            # model file's k); NaN where that model is not the power law k eps^-alpha
            power = model.kind == "power"
            row.update(
                lower=float(spec.lower[i]),
                upper=float(spec.upper[i]),
                k=float(model.k) if power else float("nan"),
                alpha=float(model.alpha) if power else float("nan"),
                cost_model=model.describe(),
                cost=float(model.cost(eps)),
            )
        row["bound_active"] = res.bounds_active.get(name, "")
        row["bound_multiplier"] = float(res.bound_multipliers.get(name, 0.0))
        rows.append(row)
    constraints = [
        {"label": b.label, "kind": b.kind, "values": b.values, "active": b.active, "multipliers": b.multipliers}
        for b in res.constraints
    ]
    summary = synthesis_summary(res)
    summary["constraints"] = constraints
    if res.validation is not None:  # synthesize(validate=N): the Monte Carlo check at the optimum
        summary["validation"] = res.validation.to_dict()
    ws = getattr(res, "workspace", None)
    if ws is not None and ws.computed:  # the sampled workspace check, once read (never run here)
        summary["workspace_check"] = ws.to_dict()
    if getattr(res, "statistical", None) is not None:  # a worst-case design's statistical comparison
        summary["statistical"] = res.statistical
    return make_frame(
        rows,
        type(res).__name__,
        _synthesis_inputs(res),
        summary,
        {
            "tolerance": "unit column",
            "lower": "unit column",
            "upper": "unit column",
            "cost": "the paper's cost units",
            "bound_multiplier": "cost units per tolerance unit",
        },
    )


def _comparison_frame(c):
    i, s = c.ipopt, c.sumt
    rows = []
    for name, v in i.tolerances.items():
        vs = s.tolerances[name]
        rows.append(
            {
                "parameter": name,
                "unit": i.units[name],
                "ipopt": v,
                "sumt": vs,
                "rel_diff": abs(vs - v) / abs(v) if v else float("nan"),
                "ipopt_bound": i.bounds_active.get(name, ""),
                "sumt_bound": s.bounds_active.get(name, ""),
            }
        )
    inputs = _synthesis_inputs(i)
    inputs["solver"] = "ipopt and sumt"
    inputs["options"] = {"ipopt": (i.inputs or {}).get("options"), "sumt": (s.inputs or {}).get("options")}
    summary = {
        "ipopt": synthesis_summary(i),
        "sumt": synthesis_summary(s),
        "cost_rel_diff": c.cost_rel_diff,
        "time_ratio": c.time_ratio,
    }
    return make_frame(rows, "Comparison", inputs, summary, {"ipopt": "unit column", "sumt": "unit column"})


def _workspace_frame(w):
    res = w.result
    rows = []
    for k, r in enumerate(w.rounds):
        row = {"round": k, "n_poses": r["n_poses"], "cost": r["cost"], "worst_value": r["worst_value"]}
        for j, qj in enumerate(np.asarray(r["worst_q"], dtype=float)):
            row[f"worst_q{j + 1}"] = qj
        for axis, x in zip("xyz", np.asarray(r["worst_position"], dtype=float)):
            row[f"worst_{axis}"] = x
        for key in ("upper_bound", "probability_lower_bound", "certified", "boxes"):  # with certify=True
            if key in r:
                row[key] = r[key]
        rows.append(row)
    summary = synthesis_summary(res)
    if w.certified is not None:
        summary.update(
            certified=w.certified,
            upper_bound=w.upper_bound,
            probability_lower_bound=w.probability_lower_bound,
            reason=w.reason,
        )
    summary.update(
        converged=w.converged,
        tolerances=res.tolerances,
        **joint_values(w.poses, _joint_units(w, 1), "poses"),
        worst_value=w.worst_value if w.rounds else None,
        max_violation=w.max_violation if w.rounds else None,
    )
    inputs = _synthesis_inputs(res)
    inputs.update(getattr(w, "inputs", None) or {})
    return make_frame(
        rows,
        "WorkspaceSynthesis",
        inputs,
        summary,
        {
            "worst_value": w.worst_quantity,
            **{f"worst_q{j + 1}": u for j, u in enumerate(_joint_units(w, len(w.poses[0]) if w.poses else 0))},
            "worst_x": "mm",
            "worst_y": "mm",
            "worst_z": "mm",
        },
    )


def _montecarlo_frame(r):
    rows = []

    def add(name, mc, ci, analytic, in_ci, unit=""):
        rows.append(
            {
                "quantity": name,
                "monte_carlo": float(mc),
                "ci_low": float(ci[0]) if ci is not None else np.nan,
                "ci_high": float(ci[1]) if ci is not None else np.nan,
                "analytic": float(analytic),
                "diff": float(mc) - float(analytic),
                "analytic_in_ci": bool(in_ci) if in_ci is not None else None,
                "unit": unit,
            }
        )

    for j in range(3):
        add(
            f"p_component_{j + 1}",
            r.p_components[j],
            r.p_components_ci[j],
            r.p_components_analytic[j],
            r.p_components_analytic_in_ci[j],
        )
    add("p_sphere", r.p_sphere, r.p_sphere_ci, r.p_sphere_analytic, r.p_sphere_analytic_in_ci)
    if r.Phi is not None and r.p_orientation_components is not None:
        for j in range(3):
            a = r.p_orientation_components_analytic[j]
            ci = r.p_orientation_components_ci[j]
            add(f"p_orientation_component_{j + 1}", r.p_orientation_components[j], ci, a, ci[0] <= a <= ci[1])
        add("p_cone", r.p_cone, r.p_cone_ci, r.p_cone_analytic, r.p_cone_ci[0] <= r.p_cone_analytic <= r.p_cone_ci[1])
    for j in range(3):
        add(f"principal_std_{j + 1}", r.principal_std[j], None, r.principal_std_analytic[j], None, "mm")
    for j in range(3):
        lo, hi = r.mean_ci[j]
        add(f"mean_{'xyz'[j]}", r.mean[j], (lo, hi), 0.0, lo <= 0.0 <= hi, "mm")
    inputs = {
        "model": r.model,
        **joint_values(r.q, _joint_units(r, len(r.q))),
        "distribution": r.distribution,
        "tolerances": r.tolerances,
        "R_mm": r.R,
        "Phi_rad": r.Phi,
        "n": r.n,
        "seed": r.seed,
        "batch": r.batch,
        "confidence": r.confidence,
        "ci_method": r.ci_method,
    }
    summary = {
        "position_mm": r.position,
        "n_loop_failures": r.n_loop_failures,
        "covariance_mm2": r.covariance,
        "covariance_analytic_mm2": r.covariance_analytic,
        "kurtosis": r.kurtosis,
        "kurtosis_se": r.kurtosis_se,
        "elapsed_s": r.elapsed_s,
        "samples_per_s": r.samples_per_s,
    }
    return make_frame(rows, "MonteCarloResult", inputs, summary, {"monte_carlo": "unit column"})


def _map_frame(pm):
    ny, nx = pm.P.shape
    U, V = np.meshgrid(pm.u, pm.v)
    cols = {"u": U.ravel(), "v": V.ravel(), "P": pm.P.ravel(), "reachable": np.isfinite(pm.P).ravel()}
    for j in range(pm.sigma.shape[-1]):
        cols[f"sigma{j + 1}"] = pm.sigma[..., j].ravel()
    cols["limit_margin"] = pm.limit_margin.ravel()
    units_q = _joint_units(pm, len(pm.joint_names))
    for name, q in zip(pm.joint_names, pm.Q):
        cols[f"q_{name}"] = np.asarray(q).ravel()
    inputs = {
        "model": pm.model,
        "plane": pm.plane,
        "offset_mm": pm.offset,
        "hand_axis": pm.hand_axis,
        "R_mm": pm.R,
        "distribution": pm.distribution,
        "probability": pm.probability,
        "tolerances": pm.tolerances,
        "tolerance_label": pm.tolerance_label,
        "reference": pm.reference,
        "n_u": nx,
        "n_v": ny,
    }
    summary = {
        "worst": pm.worst,
        "reference_point": pm.reference_point,
        "reference_P": pm.reference_P,
        "fixed": {k: [v, w] for k, (v, w) in pm.fixed.items()},
        "branch": pm.branch,
        "n_alternative_solutions": pm.n_alternative_solutions,
        "elapsed_s": pm.elapsed_s,
    }
    units = {
        "u": "mm",
        "v": "mm",
        "sigma1": "mm",
        "sigma2": "mm",
        "sigma3": "mm",
        "limit_margin": units_label(units_q),
        **{f"q_{n}": u for n, u in zip(pm.joint_names, units_q)},
    }
    return make_frame(cols, "ProbabilityMap", inputs, summary, units)


def _worst_frame(w):
    rows = []
    for which, q, pos, val, sd, ps in (
        ("worst", w.q, w.position, w.value, w.principal_std, w.p_sphere),
        (
            "reference",
            w.reference_q,
            w.reference_position,
            w.reference_value,
            w.reference_principal_std,
            w.reference_p_sphere,
        ),
    ):
        if q is None:
            continue
        row = {
            "pose": which if which == "worst" else f"reference {w.reference or ''}".strip(),
            "value": val,
            "p_sphere": ps,
        }
        row.update({f"q{j + 1}": v for j, v in enumerate(np.asarray(q, dtype=float))})
        row.update({axis: x for axis, x in zip("xyz", np.asarray(pos, dtype=float))})
        row.update({f"sigma{j + 1}": v for j, v in enumerate(np.asarray(sd, dtype=float))})
        rows.append(row)
    inputs = {
        "model": w.model,
        "criterion": w.criterion,
        "distribution": w.distribution,
        "R_mm": w.R,
        "tolerances": w.tolerances,
        "reference": w.reference,
    }
    summary = {
        "held_joints": w.held_joints,
        "active": w.active,
        "n_grid": w.n_grid,
        "n_evaluations": w.n_evaluations,
        "elapsed_s": w.elapsed_s,
        "method": w.method,
    }
    return make_frame(
        rows,
        "WorstPose",
        inputs,
        summary,
        {
            "value": "mm (sigma) or probability",
            "x": "mm",
            "y": "mm",
            "z": "mm",
            **{f"q{j + 1}": u for j, u in enumerate(_joint_units(w, len(w.q)))},
        },
    )


def _validation_frame(v):
    frame = _montecarlo_frame(v.montecarlo)
    comp = frame["quantity"].str.startswith("p_component_")
    frame["p_asked"] = np.where(comp, v.p, np.nan)
    frame["met"] = None
    frame["short"] = None
    frame.loc[comp, "met"] = list(np.asarray(v.components_met, dtype=bool))
    frame.loc[comp, "short"] = list(np.asarray(v.components_short, dtype=bool))
    frame.attrs["kind"] = "ValidationResult"
    frame.attrs["inputs"] = dict(frame.attrs["inputs"], p=v.p, pose=jsonable(v.pose))
    frame.attrs["summary"] = dict(frame.attrs["summary"], met=v.met, sphere_met=bool(v.sphere_met))
    return frame


def _grades_frame(g):
    rows = [
        {
            "parameter": n,
            "unit": g.units[n],
            "grade": grade,
            "tolerance": g.tolerances[n],
            "continuous": g.continuous.get(n, float("nan")),
            "size_mm": g.sizes.get(n, float("nan")),
        }
        for n, grade in g.grades.items()
    ]
    summary = {
        k: v for k, v in g.to_dict().items() if k not in ("grades", "tolerances", "units", "continuous", "sizes")
    }
    return make_frame(
        rows,
        "GradeChoice",
        {"probability": g.probability, "sizes_mm": g.sizes},
        summary,
        {"tolerance": "unit column", "continuous": "unit column", "size_mm": "mm"},
    )


_BUILDERS = {
    "GradeChoice": _grades_frame,
    "ValidationResult": _validation_frame,
    "SynthesisResult": _synthesis_frame,
    "Comparison": _comparison_frame,
    "WorkspaceSynthesis": _workspace_frame,
    "MonteCarloResult": _montecarlo_frame,
    "ProbabilityMap": _map_frame,
    "WorstPose": _worst_frame,
}


def _build(result):
    """The table builder of the result's type, or of the nearest base type that has one."""
    for cls in type(result).__mro__:
        if cls.__name__ in _BUILDERS:
            return _BUILDERS[cls.__name__](result)
    raise InputError("result", f"got {type(result).__name__}", "a tolsynth result type: " + ", ".join(_BUILDERS))
