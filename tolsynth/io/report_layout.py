"""A design report's content as a list of blocks (headings, tables, text, figures), rendered to
HTML or Markdown by :mod:`tolsynth.io.report_render`: one layout, every format."""

from __future__ import annotations

import json
import math

import numpy as np

from tolsynth.io.report_certificate import certificate_blocks, exact_certificate
from tolsynth.io.report_spec import _is_exact, specification_blocks

PLOT_INSTALL = 'pip install "tolsynth[plot]"'


# ---------------------------------------------------------------------------------------------
# layout: one list of blocks for both formats
# ---------------------------------------------------------------------------------------------
def _num(x, fmt: str) -> str:
    s = format(float(x), fmt)
    return format(0.0, fmt) if float(s) == 0 else s  # no "-0.000"


def _vec(v, fmt=".3f") -> str:
    return "(" + ", ".join(_num(x, fmt) for x in np.asarray(v, dtype=float).ravel()) + ")"


def _layout(rep) -> list[tuple]:
    from tolsynth.probability.distributions import label
    from tolsynth.version import __version__

    mech, res, spec = rep.mechanism, rep.result, rep.result.spec
    B: list[tuple] = []
    B.append(("h", 1, f"Design review: {mech.title}"))
    B.append(
        (
            "p",
            f"Optimal manufacturing tolerances for the model {mech.name}, computed by tolsynth "
            f"{__version__} on {rep.created} in {rep.elapsed_s:.1f} s. Units: lengths mm, angles rad "
            "unless stated; each tolerance in its parameter's own unit; cost in the model's cost units.",
        )
    )
    if not res.feasible:  # (a FEASIBLE design meets the specification; section 3 says what is not proven)
        B.append(
            (
                "note",
                f"The solver did not converge ({res.status}: {res.message}). The numbers below are its "
                "last iterate, not an optimum.",
            )
        )

    # 1. specification
    B += specification_blocks(rep)

    # 2. model
    B.append(("h", 2, "2. Model"))
    path = getattr(mech.spec, "path", None)
    B.append(
        (
            "kv",
            [
                ("name", mech.name),
                ("title", mech.title),
                ("file", str(path) if path else "(in memory)"),
                ("joints", ", ".join(mech.joint_names)),
                ("error parameters", f"{len(mech.error_parameters)}: " + ", ".join(mech.error_parameters)),
            ],
        )
    )
    B.append(("h", 3, "Source"))
    B.append(("p", " ".join(str(mech.source).split())))
    B.append(("h", 3, "Assumptions"))
    B.append(("ul", list(mech.assumptions) or ["(none stated)"]))
    notes = getattr(mech.spec, "notes", "")
    if notes:
        B.append(("h", 3, "Notes"))
        B.append(("p", " ".join(notes.split())))

    # 3. tolerances
    B.append(("h", 2, "3. Optimal tolerances"))
    B.append(
        (
            "p",
            f"Total cost {res.cost:.8g} (cost units). Bounds and tolerances in each parameter's unit; "
            "'active' marks a tolerance held at a bound, 'fixed' one locked by the user or the model.",
        )
    )
    fixed = {n for n, lo, hi in zip(spec.names, spec.lower, spec.upper) if lo == hi}
    models = spec.costs.models
    rows = []
    for i, (name, eps) in enumerate(res.tolerances.items()):
        act = "fixed" if name in fixed else res.bounds_active.get(name, "")
        how = (
            f"{rep.processes[name]} ({models[i].describe()})"
            if rep.processes and name in rep.processes
            else models[i].describe()
        )
        rows.append(
            [
                name,
                f"{eps:.6g}",
                res.units[name],
                f"{spec.lower[i]:.6g}",
                f"{spec.upper[i]:.6g}",
                act,
                how,
                f"{float(models[i].cost(eps)):.6g}",
                f"{res.bound_multipliers.get(name, 0.0):.4g}",
            ]
        )
    B.append(
        (
            "table",
            [
                "parameter",
                "tolerance +-",
                "unit",
                "lower bound",
                "upper bound",
                "active bound",
                "process / cost model",
                "cost",
                "bound multiplier",
            ],
            rows,
            [False, True, False, True, True, False, False, True, True],
            None,
        )
    )
    if rep.process_choice is not None:
        pc = rep.process_choice
        B.append(
            (
                "p",
                f"Processes chosen by branch and bound over {pc.combinations} combinations ({pc.nodes} solves): "
                f"lower bound over every choice {pc.lower_bound:.8g}, "
                + ("proven optimal." if pc.proven else "NOT proven optimal (node limit)."),
            )
        )

    # 4. certificate
    B.append(("h", 2, "4. Certificate"))
    xw = rep.workspace  # an exchange's bound is its own (the last solve's holds at its poses only)
    lower, gap = (xw.lower_bound, xw.gap) if xw is not None else (res.lower_bound, res.gap)
    rel = gap / abs(res.cost) if res.cost else float("nan")
    B.append(
        (
            "kv",
            [
                ("cost", f"{res.cost:.8g}"),
                ("lower bound over every pose" if xw is not None else "dual lower bound", f"{lower:.8g}"),
                ("gap (cost - bound)", f"{gap:.2e}"),
                ("relative gap", f"{rel:.2e}"),
                *(
                    [(f"the last solve's dual bound at its {len(xw.poses)} poses", f"{res.lower_bound:.8g}")]
                    if xw
                    else []
                ),
                (
                    "largest (1-P)/(1-p)" if _is_exact(res) else "largest sigma z / limit",
                    f"{res.max_constraint:.6f} (<= 1 meets the specification)",
                ),
            ],
        )
    )
    if _is_exact(res):
        B.append(exact_certificate(res, spec, rel))
    elif spec.criterion == "sphere":
        B.append(
            (
                "p",
                "The sphere criterion is not known to be convex: the design meets it (checked), but its optimality "
                "is not proven; the bound is the best of the per-component problem at the same p, the box of the "
                "independent principal components and a supporting half-space proven by a branch and bound "
                "(to 1 %), valid but not tight.",
            )
        )
    elif not spec.convex:
        B.append(
            (
                "note",
                "A cost model is not convex in eps^2 on its range: the bound is valid but certifies no global optimum.",
            )
        )
    elif res.success and rel <= 1e-4:
        B.append(
            (
                "ok",
                f"The problem is convex and the gap is {rel:.1e} of the cost: no tolerances inside the "
                "bounds meet the specification at a lower cost (to that margin).",
            )
        )
    crow = []
    for b in res.constraints:
        what = "(1-P)/(1-p)" if b.kind.startswith("sphere") or _is_exact(res) else "sigma z / limit"
        for j, val in enumerate(b.values):
            crow.append(
                [b.label, f"{j + 1}", what, f"{val:.6f}", "yes" if b.active[j] else "", f"{b.multipliers[j]:.4g}"]
            )
    B.append(
        (
            "table",
            ["constraint block", "#", "quantity", "value", "active", "multiplier"],
            crow,
            [False, True, False, True, False, True],
            "values <= 1 meet the specification; multipliers in cost units.",
        )
    )
    ws = getattr(res, "workspace", None)
    if ws is not None:  # how the design does away from the poses it was made for (a sample, not a proof)
        import warnings

        with warnings.catch_warnings():  # the report says it; no second copy on stderr
            warnings.simplefilter("ignore")
            # the section 7 search looks beyond the sample and may find a larger value: say which is which
            beyond = " The worst-pose search of section 7 looks beyond these samples." if rep.worst is not None else ""
            B.append(("note" if ws.exceeds else "p", ws.line() + "." + beyond))

    # 5. contributions
    c = rep.contributions
    B.append(("h", 2, "5. Contributions"))
    B.append(
        (
            "p",
            "Each parameter's share of each principal variance of the hand position (exact: the shares add "
            "to 100 %), of the total variance tr V and, with R, of the Gaussian sphere probability's loss 1 - P(|dr| <= R) "
            "(normalised elasticities). Where two principal sigma coincide (two active constraints) the split "
            "between them is arbitrary; their sum is not.",
        )
    )
    for b, pose in enumerate(c.poses):
        head = f"pose '{pose}': principal sigma {_vec(c.sigma[b], '.4g')} mm"
        exact = rep.linear_exact.get(pose)  # an exact design's exact sphere probability, where computed
        if c.P_sphere is not None:
            head += f", P(|dr| <= {c.R:g} mm) = " + (
                f"{exact[1]:.6f} exact (Gaussian {c.P_sphere[b]:.6f}, the one the last column splits)"
                if exact is not None
                else f"{c.P_sphere[b]:.6f} Gaussian"
            )
        B.append(("h", 3, head))
        rows = []
        for i in np.argsort(-c.shares[b, :, 0], kind="stable"):
            row = (
                [c.names[i], f"{c.tolerances[i]:.4g} {c.units[i]}"]
                + [f"{100 * v:.2f}" for v in c.shares[b, i]]
                + [f"{100 * c.total_share[b, i]:.2f}"]
            )
            if c.sphere_share is not None:
                row.append(f"{100 * c.sphere_share[b, i]:.2f}")
            rows.append(row)
        head_cols = ["parameter", "tolerance", "sigma1^2 %", "sigma2^2 %", "sigma3^2 %", "tr V %"]
        if c.sphere_share is not None:
            head_cols.append("1 - P %")
        B.append(("table", head_cols, rows, [False, True] + [True] * (len(head_cols) - 2), None))
        B.append(
            (
                "fig",
                f"contributions_{b}",
                f"contributions at pose {pose}",
                f"Shares at pose '{pose}', largest principal variance first.",
            )
        )

    # 6. Monte Carlo
    B.append(("h", 2, "6. Monte Carlo validation"))
    if "montecarlo" in rep.skipped:
        B.append(("note", "Monte Carlo: " + rep.skipped["montecarlo"]))
    for lbl, v in rep.validations:
        mc = v.montecarlo
        pct = int(round(100 * mc.confidence))
        B.append(("h", 3, f"pose '{lbl}': hand {_vec(mc.position)} mm"))
        B.append(
            (
                "p",
                f"{v.n} samples of the errors ({label(v.distribution)}, seed {v.seed}) through the nonlinear "
                f"kinematics; {pct} % {mc.ci_method} intervals; {mc.n_loop_failures} loop failures "
                "(counted as outside). The components w_j are along the analytic principal directions.",
            )
        )
        rows = []
        sphere = spec.criterion == "sphere"  # then the sphere is the specification, the components are not
        # the linear model in the design's own reading: exact probabilities for an exact design
        lin_P, lin_sphere = rep.linear_exact.get(lbl, (v.p_components_analytic, v.p_sphere_analytic))
        for j in range(3):
            lo, hi = v.p_components_ci[j]
            rows.append(
                [
                    f"P(|w{j + 1}| <= R)",
                    "-" if sphere else f"{v.p:g}",
                    f"{v.p_components[j]:.5f}",
                    f"[{lo:.5f}, {hi:.5f}]",
                    f"{lin_P[j]:.5f}",
                    "-" if sphere else _verdict(v.p_components[j], hi, v.p),
                ]
            )
        lo, hi = v.p_sphere_ci
        rows.append(
            [
                "P(|dr| <= R)",
                f"{v.p:g}" if sphere else "-",
                f"{v.p_sphere:.5f}",
                f"[{lo:.5f}, {hi:.5f}]",
                f"{lin_sphere:.5f}" if math.isfinite(lin_sphere) else "-",
                _verdict(v.p_sphere, hi, v.p)
                if sphere
                else ("reaches p" if v.sphere_met else "below p (the sphere is stricter than Eq. 20)"),
            ]
        )
        if mc.Phi is not None:
            po = spec.p_orientation
            for j in range(3):
                lo, hi = mc.p_orientation_components_ci[j]
                rows.append(
                    [
                        f"P(|phi{j + 1}| <= Phi)",
                        f"{po:g}",
                        f"{mc.p_orientation_components[j]:.5f}",
                        f"[{lo:.5f}, {hi:.5f}]",
                        f"{mc.p_orientation_components_analytic[j]:.5f}",
                        _verdict(mc.p_orientation_components[j], hi, po),
                    ]
                )
            lo, hi = mc.p_cone_ci
            rows.append(
                [
                    "P(z axis tilt <= Phi)",
                    "-",
                    f"{mc.p_cone:.5f}",
                    f"[{lo:.5f}, {hi:.5f}]",
                    f"{mc.p_cone_analytic:.5f}",
                    "-",
                ]
            )
        B.append(
            (
                "table",
                [
                    "probability",
                    "asked",
                    "Monte Carlo",
                    f"{pct} % interval",
                    "linear model, " + ("exact" if lbl in rep.linear_exact else "Gaussian"),
                    "verdict",
                ],
                rows,
                [False, True, True, True, True, False],
                f"R = {v.R:g} mm"
                + (
                    f"; Phi = {mc.Phi:g} rad, phi_j along the analytic orientation principal directions, the tilt "
                    "is the angle between the actual and nominal hand z axes"
                    if mc.Phi is not None
                    else ""
                )
                + ".",
            )
        )
        srows = [
            [
                f"w{j + 1}",
                _vec(mc.principal_directions[:, j]),
                f"{mc.principal_std[j]:.5f}",
                f"{mc.principal_std_analytic[j]:.5f}",
                f"{mc.kurtosis[j]:+.3f}",
            ]
            for j in range(3)
        ]
        B.append(
            (
                "table",
                ["component", "direction (base frame)", "sigma sampled, mm", "sigma linear, mm", "excess kurtosis"],
                srows,
                [False, False, True, True, True],
                f"Excess kurtosis 0 for a Gaussian (standard error {mc.kurtosis_se:.3f}).",
            )
        )

    ver = getattr(res, "verification", None)
    if ver is not None:  # synthesize(..., verify=...): the closed loop's own Monte Carlo
        lo, hi = ver.ci
        B.append(("h", 3, "Closed loop (verify)"))
        B.append(
            (
                "ok" if ver.verified else "note",
                f"Nonlinear Monte Carlo at the design, n = {ver.n} per pose, {round(100 * ver.confidence)} % Wilson "
                f"interval: achieved {ver.achieved:.5f} [{lo:.5f}, {hi:.5f}] against p = {ver.p:g} asked; "
                + ("verified (the lower end reaches p)" if ver.verified else "NOT verified (the lower end is below p)")
                + f"; design target p = {ver.p_target:.6g} after {len(ver.rounds)} round(s).",
            )
        )
        B.append(
            (
                "table",
                ["round", "target p", "cost", "Monte Carlo P", "interval", "pose"],
                [
                    [
                        f"{r['round']}",
                        f"{r['p_target']:.6g}",
                        f"{r['cost']:.6g}",
                        f"{r['estimate']:.5f}",
                        f"[{r['ci'][0]:.5f}, {r['ci'][1]:.5f}]",
                        str(r["pose"]),
                    ]
                    for r in ver.rounds
                ],
                [True, True, True, True, False, False],
                None,
            )
        )

    # 7. workspace
    B.append(("h", 2, "7. Workspace"))
    if rep.map is not None:
        pm = rep.map
        wu, wv, wp = pm.worst
        B.append(
            (
                "p",
                f"P(|dr| <= {pm.R:g} mm) of the linear, Gaussian model at the optimal tolerances over the "
                f"reachable part of the {pm.plane} plane ({len(pm.u)} x {len(pm.v)} points, "
                f"{int(pm.reachable.sum())} reachable). Lowest on the map: {wp:.4f} at ({wu:.1f}, {wv:.1f}) mm."
                + (
                    f" At the configuration '{pm.reference}': {pm.reference_P:.4f}."
                    if pm.reference_P is not None
                    else ""
                ),
            )
        )
        B.append(("fig", "map", "workspace map", "The map (tolsynth.plot_map); blank = not reachable."))
    else:
        B.append(("note", "Workspace map: " + rep.skipped.get("map", "not drawn")))
    if rep.worst is not None:
        w, judged = rep.worst, rep.worst_judged
        # worst_pose searches the exact per-direction probability itself for an exact components design
        searched_exactly = w.criterion == "components" and rep.result.probability_kind == "exact"
        B.append(("h", 3, "Worst pose"))
        B.append(
            (
                "p",
                f"Search over the joint space inside every limit and constraint ({w.method}) for the "
                + (
                    "lowest sphere probability"
                    if w.criterion == "probability"
                    else "lowest exact per-direction probability (from the pose of largest sigma)"
                    if searched_exactly
                    else "largest principal sigma (the Gaussian ranking)"
                )
                + " at the optimal tolerances, judged in the design's own reading: "
                + judged["quantity"]
                + " (<= 1 meets the specification).",
            )
        )
        rows = [
            [
                "joints",
                mech.format_joints(w.q),
                mech.format_joints(w.reference_q) if w.reference_q is not None else "-",
            ],
            ["hand, mm", _vec(w.position), _vec(w.reference_position) if w.reference_position is not None else "-"],
            [
                "principal sigma, mm",
                _vec(w.principal_std, ".4f"),
                _vec(w.reference_principal_std, ".4f") if w.reference_principal_std is not None else "-",
            ],
            [
                judged["quantity"],
                f"{judged['found']:.4f}",
                f"{judged['reference']:.4f}" if judged["reference"] is not None else "-",
            ],
        ]
        if w.p_sphere is not None:
            rows.append(
                [
                    "P(|dr| <= R), Gaussian",
                    f"{w.p_sphere:.4f}",
                    f"{w.reference_p_sphere:.4f}" if w.reference_p_sphere is not None else "-",
                ]
            )
        B.append(
            (
                "table",
                ["", "worst pose found", f"reference '{w.reference}'"],
                rows,
                [False, True, True],
                "Held: "
                + (", ".join(f"{k} = {math.degrees(v):g} deg" for k, v in w.held_joints.items()) or "none")
                + "; active: "
                + (", ".join(w.active) or "none (interior)")
                + ".",
            )
        )
        # the search ranks poses by sigma (or the Gaussian sphere): in another reading the
        # reference pose can come out worse than the pose found, so the verdict takes both
        found = max(v for v in (judged["found"], judged["reference"]) if v is not None)
        ranked = ""
        if rep.result.probability_kind == "exact" and w.certificate is None:
            ranked = (
                " The search ranks poses by the Gaussian sigma, not by the exact probability: the exact worst pose"
                if not searched_exactly
                else " The exact worst pose of a local search"
            ) + " may lie elsewhere (report --certify proves a bound over the whole joint space)."
        ws = getattr(rep.result, "workspace", None)
        if ws is not None and ws.computed and math.isfinite(ws.worst):
            ranked += (
                f" (Section 4's sampled check found at most {ws.worst:.4f} at its {ws.n_poses} sampled poses; "
                "this search looks beyond them.)"
            )
        if found > 1 + 1e-6:
            B.append(
                (
                    "note",
                    f"At the poses compared (the worst pose found by the search, and the reference) "
                    f"{judged['quantity']} reaches {found:.4f} > 1: the "
                    "specification is met at the specification's pose(s) but not everywhere in the workspace. "
                    "tolsynth solve --everywhere (synthesize_workspace) imposes it at every reachable pose." + ranked,
                )
            )
        else:
            B.append(
                (
                    "ok",
                    f"At the poses compared (the worst pose found by the search, and the reference) "
                    f"{judged['quantity']} is at most {found:.4f} <= 1: the "
                    "specification holds at the poses searched (a search, not a proof)." + ranked,
                )
            )
    else:
        B.append(("note", "Worst pose: " + rep.skipped.get("worst", "not searched")))
    B += certificate_blocks(rep)

    # inputs
    from tolsynth.tabular import _synthesis_inputs, jsonable

    B.append(("h", 2, "Inputs recorded"))
    rec = {"tolsynth_version": __version__, "report_settings": rep.settings, "synthesis": _synthesis_inputs(res)}
    B.append(("pre", json.dumps(jsonable(rec), indent=1)))
    return B


# ---------------------------------------------------------------------------------------------
# figures
# ---------------------------------------------------------------------------------------------
def _verdict(estimate: float, upper: float, p: float) -> str:
    """Met (estimate >= p), SHORT (the interval's upper end < p) or within noise."""
    return "met" if estimate >= p else ("SHORT" if upper < p else "below p (within noise)")
