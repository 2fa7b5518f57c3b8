"""Designs that meet the specification at every reachable pose, not one: :func:`synthesize_workspace`.

The semi-infinite problem by an exchange method: optimise at a finite set of poses, search the
workspace for the worst pose at that optimum, add it, repeat.
"""

from __future__ import annotations

import warnings

import numpy as np

from tolsynth.checks import check_count, check_half_angle, check_mapping, check_positive
from tolsynth.errors import CertificationWarning, InputError
from tolsynth.kinematics.joint_space import MODEL_REFERENCE, model_reference
from tolsynth.probability.stats import z_of_p
from tolsynth.problem.specification import ALPHA_DEFAULT
from tolsynth.synthesis.single import COARSE_STEP_TOL, synthesize
from tolsynth.synthesis.workspace_result import WorkspaceSynthesis

__all__ = ["synthesize_workspace", "WorkspaceSynthesis"]


def synthesize_workspace(
    mechanism,
    R: float,
    p: float | None = None,
    distribution=None,
    alpha=ALPHA_DEFAULT,
    *,
    pose=MODEL_REFERENCE,
    tol: float = 1e-3,
    max_rounds: int | None = None,
    search: dict | None = None,
    certify: bool = False,
    certify_options: dict | None = None,
    progress=None,
    **kwargs,
) -> WorkspaceSynthesis:
    """Optimal tolerances with Eq. 20 imposed at *every* reachable pose, not one.

    The paper imposes the accuracy constraint at one pose, found beforehand with other
    tolerances; but the pose of largest error moves with the tolerances.  This is the
    semi-infinite problem, solved by an exchange method: optimise at a finite set of poses, search
    the workspace (joint limits and joint constraints) for the pose of largest principal sigma at
    that optimum (:func:`tolsynth.worst_pose`), add it, and repeat until the worst pose
    found meets ``sigma z / R <= 1 + tol``.  Each round's optimum is certified (convex problem);
    the worst-pose search is a grid plus local search, so "everywhere" means "everywhere that
    search looks" (its grid is in ``search``, keyword arguments of ``worst_pose``).

    With ``probability="exact"`` each round's optimum has the exact probabilities at its poses
    (:mod:`tolsynth.solvers.exact`), and the search minimises the exact per-direction probability
    itself over joints and directions
    (:func:`tolsynth.analysis.exact_pose_search.worst_exact_pose`, started from the sigma search's
    pose and a grid ranked by it): ``worst_value = (1 - P) / (1 - p)``.  (The sphere criterion's
    search still ranks poses by the linear model, its Gaussian sphere probability, and judges the
    pose it finds exactly.)

    For the paper's robot at R = 0.5 mm, p = 0.99, uniform, alpha = 0.7 on the Gaussian reading
    this takes 5 rounds and costs 5 % more than the optimum at the paper's pose, which violates
    the specification elsewhere by a factor 1.14; with the exact probabilities (the default), 4
    rounds, 3.1 % more, and the optimum at the paper's pose misses p elsewhere by a factor 1.91
    in ``(1 - P) / (1 - p)``.

    ``max_rounds``: the exchange's rounds before it gives up; default 20, and 30 in the certified
    exchange's Gaussian reading without a margin, whose sampled stage goes on further.

    ``pose`` is where the exchange starts (a configuration name or joint values, rad); by default
    the model's reference pose (its ``worst`` configuration), and for a model without one, as for
    None, the worst pose the search finds at tolerances in the middle of the bounds.  There is no
    ``poses``: the exchange chooses the poses itself (``poses=`` is an :class:`InputError` saying so).

    With ``probability="worst_case"`` the search maximises the worst case itself, the largest
    ``|dr| / R`` (with ``Phi`` also ``|dphi| / Phi``) over every error in its band
    (:func:`tolsynth.analysis.worst_case_pose.worst_case_pose`), and ``worst_value`` is that; ``p``,
    ``distribution`` and ``certify`` are refused there (none is read, and the certified search proves
    the Gaussian and exact readings only).  Planar 2R at R = 0.5 mm: the design at its reference pose
    exceeds R by 0.8 % at q2 = 14.5 deg; the exchange's, 0.4 % dearer, meets it in 3 rounds.

    With ``certify=True`` the sampled search is replaced by the certified one
    (:func:`tolsynth.analysis.certify.certify_worst_pose`): after each solve a branch and bound over
    the whole continuous joint space proves a bound (Gaussian: of ``max z sigma_1 / R``; exact: of
    the smallest per-component probability) and returns the worst pose it found, which joins the
    imposed poses unless the bound already meets the specification to ``tol`` (exact: the
    probability to ``p - 1e-6``); then ``certified`` is True.  When the round limit is reached, or
    the search cannot close its gap within its box limit, the result says so (``converged`` False,
    ``reason``) with the bound reached.  ``certify_options``: ``rtol``, ``tol``, ``max_boxes``
    (>= 1), ``time_limit`` (seconds > 0, as ``--certify-time-limit``; 0 is refused, None is no
    limit) and ``workers`` (processes, an integer >= 1; default the cores) of each certified search (the
    exact reading's on five or more searched joints, where its proof has not been seen to close,
    stops after :data:`EXACT_WIDE_SECONDS` unless a time or box limit is given), and
    ``margin`` (relative, default 0): design at ``R / (1 + margin)`` and prove at ``R``, and
    ``through="sigma"``: the exact reading proven through ``sigma_1`` (:func:`_through_sigma`).  The proof
    needs room between the design's largest error and ``1 + tol``; an exchange's design is nearly
    flat (on a six-joint arm within 1e-3 of its maximum over a few percent of the joint space), so
    without a margin that room is at most ``tol``: the Gaussian reading's sampled stage then goes
    on until the worst pose it finds is within a tenth of ``tol``, and the proof takes 35 000 to
    50 000 boxes, 20-40 s, on a six-joint arm (the Panda's 290 000, 4.2 min).  A margin buys room for cost: ``lower_bound`` then
    comes from a solve at ``R`` at the final poses, so ``gap`` shows what the margin cost (Puma
    560: a margin of 3e-3, +0.2 %, in 16 s).  ``progress``: a progress bar on stderr, of
    the exchange's rounds (with ``certify``: of each certified search's boxes); None shows it on a
    terminal for runs over a couple of seconds.  The sphere criterion is not certified.
    """
    from tolsynth.analysis.pose_search import worst_pose
    from tolsynth.kinematics.mechanism import as_mechanism

    if "poses" in kwargs:  # the exchange chooses the poses itself; synthesize would get them twice
        raise InputError(
            "poses",
            f"synthesize_workspace chooses the poses itself (the exchange adds the worst pose found each round), "
            f"got poses={kwargs['poses']!r}",
            "pose= (where the exchange starts: a configuration name or joint values, rad), or nothing",
        )
    mechanism = as_mechanism(mechanism)
    if pose is MODEL_REFERENCE:
        pose = model_reference(mechanism)
    R = check_positive(R, "R", "mm")  # a number in mm or a string with its unit, as synthesize reads it
    worst_case = kwargs.get("probability") == "worst_case"
    if worst_case:
        _check_worst_case(p, distribution, certify, certify_options)
        Phi = None if kwargs.get("Phi") is None else check_half_angle(kwargs["Phi"])
    z = None if worst_case else z_of_p(p)
    tol = check_positive(tol, "tol", "relative", upper=1.0)
    if max_rounds is not None:
        max_rounds = check_count(max_rounds, "max_rounds", lower=1, upper=1000)
    search = check_mapping(search, "search", "keyword arguments of tolsynth.worst_pose")
    if certify_options and not certify:  # options of a search that would not run
        raise InputError("certify_options", "given without certify=True", "certify=True, or no certify_options")
    if certify:  # before the first solve or search, not when the first certified search starts
        _check_certify_options(certify_options)
    allowed = ("grid", "reference", "fixed", "starts", "step_tol", "max_grid_points", "seed")
    for key in search or {}:  # the search's own arguments; the others are set here
        if key not in allowed:
            raise InputError("search", f"unknown key {key!r}", ", ".join(allowed))
    sphere = kwargs.get("criterion", "components") == "sphere"
    if kwargs.get("probability") is None:  # the library's default, named so every round reads the same
        from tolsynth.synthesis.single import DEFAULT_PROBABILITY

        kwargs["probability"] = DEFAULT_PROBABILITY
    exact = kwargs["probability"] == "exact"
    if pose is None and worst_case:  # no starting pose: the worst case's at the middle of the bounds
        from tolsynth.analysis.worst_case_pose import worst_case_pose

        lo, hi = mechanism.bounds
        pose = worst_case_pose(mechanism, np.sqrt(lo * hi), R, Phi, **(search or {})).q
    elif pose is None:  # no starting pose: the worst pose found at tolerances in the middle of the bounds
        lo, hi = mechanism.bounds
        pose = worst_pose(
            mechanism, np.sqrt(lo * hi), criterion="sigma", distribution=distribution, reference=None, **(search or {})
        ).q
    poses = [mechanism.joints(pose)]
    rounds = []
    converged = False
    res = None

    def search_at(eps, opts, R=R):
        if worst_case:  # the farthest point of the error zonotope, not a Gaussian sigma
            from tolsynth.analysis.worst_case_pose import worst_case_pose

            w = worst_case_pose(mechanism, eps, R, Phi, **opts)
            return w, w.value
        if sphere:  # the worst pose is the one of lowest P(|dr| <= R)
            w = worst_pose(mechanism, eps, criterion="probability", R=R, distribution=distribution, **opts)
            g = (1.0 - w.value) / (1.0 - p)
        else:
            w = worst_pose(mechanism, eps, criterion="sigma", distribution=distribution, **opts)
            g = w.value * z / R
        if exact and not sphere:
            # the pose of largest sigma need not be the pose of lowest exact probability: search for
            # the exact one itself, from the sigma search's pose and a grid ranked by it
            from tolsynth.analysis.exact_pose_search import worst_exact_pose

            keys = ("fixed", "seed", "step_tol")
            e = worst_exact_pose(
                mechanism, eps, R, p, distribution, x0=[w.q], **{k: opts[k] for k in keys if k in opts}
            )
            return e, e.margin
        if exact:  # the sphere's search ranks poses by the linear model; the pose found is judged exactly
            from tolsynth.solvers.exact import exact_margin

            g = exact_margin(mechanism, w.q, eps, distribution, R, p, "sphere")
        return w, g

    # a pose to add needs no more than a coarse local search (final step 1e-4 of each joint's
    # range); the search that decides convergence is the full one (puma560: most of the time was
    # the pattern search's last halvings, round after round)
    full = dict(search or {})
    coarse = full if "step_tol" in full else {**full, "step_tol": COARSE_STEP_TOL}
    if certify and certify_options and "through" in certify_options:
        return _through_sigma(
            mechanism, R, p, distribution, alpha, pose, tol, max_rounds, search, certify_options, progress, kwargs
        )
    if certify:
        return _certified_exchange(
            mechanism,
            R,
            p,
            z,
            distribution,
            alpha,
            poses,
            tol,
            max_rounds,
            certify_options,
            progress,
            sphere,
            kwargs,
            lambda eps, radius, fine=False: search_at(eps, full if fine else coarse, radius),
        )
    from tolsynth.progress import Progress

    max_rounds = ROUNDS if max_rounds is None else max_rounds
    reason = f"round limit ({max_rounds}) reached"
    bar = Progress(progress, max_rounds, f"workspace exchange ({mechanism.name})", "round")
    try:
        for k in range(max_rounds):
            res = synthesize(mechanism, R, p, distribution, alpha, poses=poses, **kwargs)
            if not res.feasible:  # (the sphere's designs are FEASIBLE: met, optimality not proven)
                reason = f"the solve at {len(poses)} pose(s) did not succeed: {res.message}"
                break
            w, g = search_at(res.x, coarse)
            if g <= 1 + tol and coarse is not full:
                w, g = search_at(res.x, full)
            rounds.append(
                {
                    "n_poses": len(poses),
                    "cost": res.cost,
                    "worst_value": g,
                    "worst_q": w.q,
                    "worst_position": w.position,
                }
            )
            bar.update(k + 1, 1)
            if g <= 1 + tol:
                converged, reason = True, ""
                break
            poses = poses + [w.q]
    finally:
        bar.close()
    if not converged and rounds and reason.startswith("round limit"):
        reason += f"; the last design misses the specification by {rounds[-1]['worst_value'] - 1:.3g} at a pose found"
    return WorkspaceSynthesis(
        res, poses, rounds, converged, reason=reason, joint_units=mechanism.joint_value_units, tol=tol
    )


def _check_worst_case(p, distribution, certify, certify_options) -> None:
    """The worst-case exchange's refusals: what it would not read, and the certified search, which
    proves Gaussian and exact readings only."""
    given = (
        ("p", p, "no p (the worst case reads no probability)"),
        ("distribution", distribution, "no distribution (every error anywhere in its band, whatever its shape)"),
        (
            "certify",
            certify or None,
            "certify=False (the certified search proves the Gaussian and exact readings only)",
        ),
        ("certify_options", certify_options, "no certify_options (no certified search with the worst case)"),
    )
    for name, value, allowed in given:
        if value is not None:
            raise InputError(name, f"{value!r} with probability='worst_case'", allowed)


def _through_sigma(mechanism, R, p, distribution, alpha, pose, tol, max_rounds, search, options, progress, kwargs):
    """The exact reading proven through sigma_1: the Gaussian reading's certified exchange at the
    ``z`` where Eaton's bound (:mod:`tolsynth.probability.tail_bound`) proves ``p - EXACT_SLACK``
    once ``z sigma_1 / R <= 1 + tol`` is; the cost's lower bound from the exact reading's solve at
    the poses imposed, so ``gap`` shows what proving it this way cost."""
    import dataclasses

    from tolsynth.probability.distributions import resolve, shapes_of
    from tolsynth.probability.stats import p_components
    from tolsynth.probability.tail_bound import COVERED, covered, probability_lower, z_for

    options = dict(options)
    way = options.pop("through")
    if way != "sigma":
        raise InputError("certify_options['through']", f"got {way!r}", "'sigma'")
    if kwargs["probability"] != "exact" or kwargs.get("criterion", "components") != "components":
        what = "the sphere criterion" if kwargs["probability"] == "exact" else f"the {kwargs['probability']} reading"
        raise InputError(
            "certify_options['through']", f"given with {what}", "the exact reading of the per-component probability"
        )
    dist = resolve(distribution, mechanism)
    if not covered(shapes_of(dist, mechanism.error_parameters, mechanism.index)):
        raise InputError(
            "certify_options['through']", "an error shape Eaton's bound does not cover", ", ".join(COVERED)
        )
    zg = z_for(1.0 - p + EXACT_SLACK) * (1.0 + tol)
    pg = float(p_components(1.0, zg))
    ws = synthesize_workspace(
        mechanism, R, pg, distribution, alpha, pose=pose, tol=tol, max_rounds=max_rounds, search=search,
        certify=True, certify_options=options or None, progress=progress, **{**kwargs, "probability": "gaussian"},
    )  # fmt: skip
    p_lb, certified, reason = None, ws.certified, ws.reason
    if ws.upper_bound is not None:  # sigma_1 <= upper_bound R / z_of_p(pg) everywhere
        p_lb = float(probability_lower(R, ws.upper_bound * R / z_of_p(pg)))
        if certified and p_lb < p - EXACT_SLACK:
            certified, reason = False, f"the proven sigma_1 gives only {p_lb:.9f} < p - {EXACT_SLACK:g}"
    at_R = synthesize(mechanism, R, p, distribution, alpha, poses=ws.poses, **kwargs)
    return dataclasses.replace(
        ws,
        certified=certified,
        converged=ws.converged and certified,
        upper_bound=None,
        probability_lower_bound=p_lb,
        reason=reason,
        bound_at_R=at_R.lower_bound if at_R.success else float("nan"),
        through=z_of_p(pg),
    )


#: how far below p the exact probability may be proven and still meet the specification
EXACT_SLACK = 1e-6
#: the share of ``tol`` by which a sampled pose may exceed the specification, in the certified
#: exchange's Gaussian reading without a design margin, before it is imposed: the proof's room is
#: what the design's worst pose leaves below ``1 + tol``, and its boxes grow steeply as the room
#: closes (the Puma 560's proof, q6 over a whole turn: 282 223 boxes at the full tol, 195 811 at a tenth)
SAMPLED_SHARE = 0.1
#: the exchange's default round limits: 20, and with that share 30 (the KR 6 R900 took 20 rounds)
ROUNDS, SHARE_ROUNDS = 20, 30
#: seconds each exact certified search may take by default on five or more searched joints, where
#: its proof has not been seen to close: without a limit one search bounds its 400 000 boxes (over
#: 15 min on the Puma 560), and the exchange should end with the bound it reached in minutes
EXACT_WIDE_SECONDS = 120.0


def _check_certify_options(options) -> dict:
    """``certify_options`` as a dict, or a typed error naming the offending key: the certified
    search's limits by their rules (:func:`tolsynth.analysis.certify.check_limits`: 0 seconds or
    0 boxes refused, a bool is no count), ``margin`` and ``through``."""
    from tolsynth.analysis.certify import LIMITS, check_limits

    options = dict(check_mapping(options, "certify_options", "keyword arguments of the certified search") or {})
    keys = LIMITS + ("margin", "through")
    for key in options:
        if key not in keys:
            raise InputError("certify_options", f"unknown key {key!r}", ", ".join(keys))
    check_limits(lambda key: f"certify_options[{key!r}]", **{k: v for k, v in options.items() if k in LIMITS})
    return options


def _certified_exchange(
    mechanism, R, p, z, distribution, alpha, poses, tol, max_rounds, options, progress, sphere, kwargs, sampled
) -> WorkspaceSynthesis:
    """The exchange of :func:`synthesize_workspace` with the certified search deciding (its docstring).

    A round whose sampled search (``sampled(eps, radius, fine=False) -> (WorstPose, value)``, cheap;
    ``fine`` the full search rather than the coarse one; the value relative to ``radius``) finds
    the specification missed adds that pose, as the uncertified exchange does; only when it finds
    none does the certified search run, which either proves the specification met or returns the
    worst pose it found (within its tolerance of the worst anywhere), to be added in turn."""
    from tolsynth.analysis.certify import certify_worst_pose
    from tolsynth.analysis.certify_structure import check_certifiable
    from tolsynth.synthesis.single import DEFAULT_PROBABILITY

    if sphere:
        raise InputError(
            "certify",
            "the sphere criterion has no certified search",
            "criterion 'components' (the default) with certify=True",
        )
    check_certifiable(mechanism)  # at once, not after rounds of solves (and a warning about the proof)
    options = _check_certify_options(options)
    margin = options.pop("margin", 0.0)
    margin = 0.0 if margin == 0 else check_positive(margin, "certify_options['margin']", "relative", upper=0.5)
    Rd = R / (1.0 + margin)  # the radius designed for; the proof is made at R
    probability = kwargs.get("probability") or DEFAULT_PROBABILITY
    exact = probability == "exact"
    if max_rounds is None:  # the sampled stage goes on to a share of tol without a margin (below)
        max_rounds = ROUNDS if exact or margin else SHARE_ROUNDS
    rounds, res, cert = [], None, None
    converged, reason = False, f"round limit ({max_rounds}) reached"
    ub_ratio = p_lb = None
    # a sampled pose counts as missed where the certified search would count it (the exact goal,
    # p - EXACT_SLACK, is far tighter than tol), and without a margin a little before (the proof's
    # room): a pose found by sampling costs a fraction of a second, one found by the certified
    # search a full search
    missed = 1.0 + (EXACT_SLACK / (2.0 * (1.0 - p)) if exact else tol * (1.0 if margin else SAMPLED_SHARE))
    for k in range(max_rounds):
        res = synthesize(mechanism, Rd, p, distribution, alpha, poses=poses, **kwargs)
        if not res.success:
            reason = f"the solve at {len(poses)} pose(s) did not succeed: {res.message}"
            break
        w, g = sampled(res.x, Rd)
        searched = len(mechanism.joint_names) - len(w.held_joints) if k == 0 and exact else 0
        if searched >= 5:  # said at once, not after minutes of rounds
            limited = "time_limit" not in options and "max_boxes" not in options
            if limited:
                options["time_limit"] = EXACT_WIDE_SECONDS
            warnings.warn(
                CertificationWarning(
                    f"the exact reading's proof has not been seen to close on {searched} searched joints; "
                    "the exchange goes on and says whether it closed"
                    + (
                        f", each certified search stopped after {EXACT_WIDE_SECONDS:g} s (certify_options "
                        "'time_limit' or 'max_boxes', CLI --certify-time-limit, sets another)"
                        if limited
                        else ""
                    )
                    + ". The Gaussian reading certifies six-joint arms in under 40 s, and with a "
                    "design margin in under 30 s: probability='gaussian', certify_options={'margin': 3e-3} "
                    "(CLI: --probability gaussian --margin 3e-3); the Panda, whose design is flatter, "
                    "in 4.2 min, and with that margin in 1.5 min. Or the exact reading proven through sigma_1, at a "
                    "cost premium of about 12 %: certify_options={'through': 'sigma'} (CLI: --through-sigma; "
                    "six-joint arms in 20-40 s, the Panda in 4 min)"
                ),
                stacklevel=3,
            )
        if g <= missed:  # the coarse search found no miss: the full one decides whether to prove
            w, g = sampled(res.x, Rd, True)
        if g > missed and k < max_rounds - 1:  # missed at a sampled pose: no proof needed to go on
            rounds.append(
                {
                    "n_poses": len(poses),
                    "cost": res.cost,
                    "worst_value": g,
                    "worst_q": w.q,
                    "worst_position": w.position,
                    "upper_bound": None,
                    "probability_lower_bound": None,
                    "certified": None,
                    "boxes": 0,
                }
            )
            poses = poses + [w.q]
            continue
        # a decision, not the tightest bound: prove the specification met to tol, or find the worst
        # pose (to the search's tolerance), which joins the imposed poses
        goal = p - EXACT_SLACK if exact else (1.0 + tol) * R / z
        cert = certify_worst_pose(
            mechanism,
            res.x,
            distribution,
            "components" if exact else "sigma",
            R,
            "exact" if exact else "gaussian",
            x0=np.array(poses + [w.q]),
            progress=progress,
            target=goal,
            # a pose found past the goal joins the imposed poses at once, as a sampled one does (with a
            # margin too: a design above R / (1 + margin) but proven at R is certified, and cheaper);
            # the last round searches on, for the bound reached to be reported
            stop_at=goal if k < max_rounds - 1 else None,
            search=False,  # the full sampled search of this round has just run from the same poses
            **options,
        )
        q = cert.q
        if exact:
            p_lb = cert.probability_lower_bound
            worst = (1.0 - cert.best_value) / (1.0 - p)
            meets, violated = p_lb >= p - EXACT_SLACK, cert.best_value < p - EXACT_SLACK / 2
        else:
            ub_ratio = cert.upper_bound * z / R
            p_lb = cert.probability_lower_bound
            worst = cert.best_value * z / Rd  # the rounds' values are relative to the radius designed for
            meets, violated = ub_ratio <= 1 + tol, worst > 1 + tol / 2
        rounds.append(
            {
                "n_poses": len(poses),
                "cost": res.cost,
                "worst_value": worst,
                "worst_q": q,
                "worst_position": np.asarray(mechanism.fk(q, check_limits=False))[:3, 3],
                "upper_bound": ub_ratio,
                "probability_lower_bound": p_lb,
                "certified": cert.certified,
                "boxes": cert.boxes,
            }
        )
        if meets:
            converged, reason = True, ""
            break
        if not violated:
            reason = f"the certified search did not close its gap ({cert.reason or 'bound above the specification'})"
            if exact and len(cert.searched) >= 5:  # the exact bounds are Taylor corners there
                reason += (
                    f"; the exact reading's proof does not close on {len(cert.searched)} searched joints: "
                    "probability='gaussian' closes on six-joint arms (the Panda sooner with a design margin, "
                    "certify_options 'margin': 3e-3), and certify_options 'through': 'sigma' proves the exact "
                    "reading at a cost premium of about 12 %"
                )
            elif not margin:
                reason += "; a design margin (certify_options 'margin', e.g. 3 tol) gives the proof room"
            else:  # the boxes needed fall steeply with the room (the Panda: none 4.2 min, 3e-3 89 s)
                reason += f"; a larger design margin than {margin:g} gives the proof more room"
            break
        poses = poses + [q]
    bound_at_R = None
    if converged and res is not None:
        # the proof over the whole joint space supersedes the quick sampled check a design carries
        # (and its 300 poses' exact probabilities, half a second on the paper's robot)
        object.__setattr__(res, "workspace", None)
    if margin and res is not None:
        # the last solve's dual bound is one at R / (1 + margin), above the cheapest cost at R; a
        # solve at R at the poses imposed (finitely many: a relaxation) bounds that cost, converged
        # or not
        at_R = synthesize(mechanism, R, p, distribution, alpha, poses=poses, **kwargs)
        bound_at_R = at_R.lower_bound if at_R.success else float("nan")
    return WorkspaceSynthesis(
        res,
        poses,
        rounds,
        converged,
        certified=converged,
        upper_bound=ub_ratio,
        probability_lower_bound=p_lb,
        certificate=cert,
        reason=reason,
        margin=margin,
        bound_at_R=bound_at_R,
        joint_units=mechanism.joint_value_units,
        tol=tol,
    )
