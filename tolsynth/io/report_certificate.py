"""The design report's certificate over the whole joint space: what a certified search proved.

Two sources, each shown when the report has it: the certified exchange of a workspace design
(:func:`tolsynth.synthesize_workspace` with ``certify=True``, given to :func:`tolsynth.report` as
its source), and the certified worst-pose search of the report itself (``report(...,
certify=True)``, :func:`tolsynth.worst_pose` with ``certify=True``).  The text never claims more
than the certificate holds: a search stopped by its box, time or round limit is shown as not
proven, with the bound it reached (which still holds, only looser).
"""

from __future__ import annotations

__all__ = ["certificate_blocks", "exact_certificate", "shortfall"]


def shortfall(P: float, p: float) -> float:
    """``(1 - P) / (1 - p)``: a probability P read against the p asked (<= 1 meets it)."""
    return (1.0 - P) / (1.0 - p)


def _pose(mech, q) -> str:
    return mech.format_joints(q) if q is not None else "-"


def _search_rows(cert, z: float, R: float) -> list:
    """Rows of one certified search (:class:`tolsynth.analysis.certify.Certificate`)."""
    rows = [["certified", "yes" if cert.certified else "NO (" + (cert.reason or "gap not closed") + ")"]]
    if cert.upper_bound is not None:
        rows.append(["largest principal sigma, proven upper bound (mm)", f"{cert.upper_bound:.6g}"])
        rows.append(["same, as sigma z / R", f"{cert.upper_bound * z / R:.6f}"])
    if cert.probability_lower_bound is not None:
        rows.append(
            [
                f"smallest component probability, proven lower bound ({cert.probability})",
                f"{cert.probability_lower_bound:.8f}",
            ]
        )
    best = cert.best_value if cert.criterion == "sigma" else None
    if best is not None:
        rows.append(["largest principal sigma found (mm)", f"{best:.6g}"])
    rows.append(["boxes bounded", f"{cert.boxes}"])
    rows.append(["time (s)", f"{cert.elapsed_s:.1f}"])
    if cert.held:
        rows.append(["joints held (proven without effect)", "; ".join(f"{k}: {v}" for k, v in cert.held.items())])
    if cert.searched:
        rows.append(["joints searched", ", ".join(cert.searched)])
    if cert.half_turn:
        rows.append(["searched over half a turn (the other half the same, proven)", ", ".join(cert.half_turn)])
    for sym, joint in cert.symmetries:
        rows.append([f"{joint} searched over half its range (a symmetry, proven)", sym])
    return rows


def certificate_blocks(rep) -> list[tuple]:
    """The report blocks of the certificate section (empty when no certified search ran)."""
    mech, spec = rep.mechanism, rep.result.spec
    ws = getattr(rep, "workspace", None)
    worst = rep.worst
    wcert = getattr(worst, "certificate", None) if worst is not None else None
    if (ws is None or ws.certified is None) and wcert is None:
        return []
    z, R = spec.z, spec.R
    B: list[tuple] = [("h", 3, "Certificate over the whole joint space")]
    B.append(
        (
            "p",
            "An interval branch and bound over the continuous joint space, inside every joint limit and "
            "joint constraint, proves a bound of the linear error model at every pose (not a sample); "
            "rounding is accounted for. It says nothing about the nonlinear kinematics at large errors "
            "(the Monte Carlo section does).",
        )
    )
    if ws is not None and ws.certified is not None:
        rows = [["exchange", ("converged" if ws.converged else "NOT converged") + f", {len(ws.rounds)} round(s)"]]
        if ws.upper_bound is not None:
            rows.append(["max sigma z / R over the joint space, proven upper bound", f"{ws.upper_bound:.6f}"])
        if ws.probability_lower_bound is not None:
            rows.append(
                [
                    "smallest component probability over the joint space, proven lower bound",
                    f"{ws.probability_lower_bound:.8f}",
                ]
            )
        searches = [r for r in ws.rounds if r.get("certified") is not None]
        rows.append(
            [
                "certified searches (boxes)",
                f"{len(searches)} (" + ", ".join(str(r["boxes"]) for r in searches) + ")" if searches else "0",
            ]
        )
        rows.append(["poses imposed (binding)", f"{len(ws.poses)} ({len(ws.binding_poses)})"])
        if getattr(ws, "margin", 0.0):
            rows.append(
                [
                    "design margin on R (the designs at R / (1 + margin), the proof at R)",
                    f"{ws.margin:g}: cost {ws.result.cost:.8g}, lower bound at R {ws.lower_bound:.8g}",
                ]
            )
        B.append(("table", ["workspace design", ""], rows, [False, True], ws.certificate_line() + "."))
        if ws.certified:
            B.append(
                (
                    "ok",
                    "The specification is proven to hold at every pose of the joint space (to the exchange's tolerance).",
                )
            )
        else:
            B.append(("note", f"NOT proven everywhere: {ws.reason}. The bound above still holds; it is looser."))
    if wcert is not None:
        rows = _search_rows(wcert, z, R)
        rows.append(["worst pose found", _pose(mech, wcert.q)])
        B.append(("table", ["worst-pose search at these tolerances", ""], rows, [False, True], wcert.method + "."))
        plb = wcert.probability_lower_bound
        if wcert.criterion == "components" and plb is not None and wcert.certified:
            # a design read in these probabilities is judged by them, not by a sigma bound
            ratio = shortfall(plb, spec.p)
            if ratio <= 1.0 + 1e-9:
                B.append(
                    (
                        "ok",
                        f"Proven: P >= {plb:.8f} ({wcert.probability}) along every direction at every pose, "
                        f"(1-P)/(1-p) <= {ratio:.6f}: the specification holds everywhere.",
                    )
                )
            else:
                B.append(
                    (
                        "note",
                        f"Proven: P >= {plb:.8f} ({wcert.probability}) at every pose, and the search found "
                        f"P = {wcert.best_value:.8f}, (1-P)/(1-p) = {shortfall(wcert.best_value, spec.p):.6f}: "
                        "the specification is exceeded somewhere in the workspace (tolsynth solve --everywhere "
                        "--certify designs for every pose).",
                    )
                )
        elif wcert.upper_bound is not None and wcert.certified:
            ratio = wcert.upper_bound * z / R
            if ratio <= 1.0 + 1e-9:
                B.append(
                    ("ok", f"Proven: sigma z / R <= {ratio:.6f} at every pose: the specification holds everywhere.")
                )
            else:
                B.append(
                    (
                        "note",
                        f"Proven: sigma z / R <= {ratio:.6f}, and the search found {wcert.best_value * z / R:.6f}: "
                        f"the specification is exceeded by up to {wcert.best_value * z / R - 1:.2e} somewhere in the "
                        "workspace (tolsynth solve --everywhere --certify designs for every pose).",
                    )
                )
        elif not wcert.certified:
            B.append(
                ("note", f"The worst-pose bound is NOT certified ({wcert.reason}); it holds, the gap did not close.")
            )
    return B


def exact_certificate(res, spec, rel: float) -> tuple:
    """What an exact-probability design's certificate proves, read from the result itself (its
    success, gap and message), so that the report never claims more than the solver proved."""
    said = f"The solver says: {res.status}: {res.message}"
    if spec.criterion == "sphere":
        return (
            "note",
            "Exact probabilities, sphere criterion: the problem is not known to be convex, so the gap is "
            "no certificate of global optimality; the lower bound is the certified optimum of the "
            f"per-component problem at the same p (the sphere lies in every slab). {said}",
        )
    if res.success:
        return (
            "ok",
            f"Exact probabilities, certified optimum: every direction of every pose is proven to meet p "
            f"(to 1e-7), the feasible set is convex (independent errors with symmetric log-concave "
            f"densities), and the lower bound leaves a gap of {rel:.1e} of the cost: no tolerances inside "
            f"the bounds meet the specification at a lower cost (to that margin). {said}",
        )
    return (
        "note",
        f"Exact probabilities, NOT certified: the numbers are the solver's last design and the lower "
        f"bound is not proven tight. {said}",
    )
