"""The front door: :func:`synthesize` (one solver) and :func:`compare` (IPOPT against SUMT).

>>> import tolsynth
>>> m = tolsynth.load_model("xu_zhang_1988")
>>> res = tolsynth.synthesize(m, R=0.5, p=0.99, distribution="uniform", alpha=0.7)
>>> res.success, round(res.tolerances["h3"], 3)  # doctest: +SKIP
(True, 0.2...)
"""

from __future__ import annotations

import numpy as np

from tolsynth.analysis.design_pose import resolve_design_pose
from tolsynth.checks import TINY, check_count, check_mapping, check_options, check_seed, check_time_limit, check_vector
from tolsynth.errors import InputError, TimeLimitError
from tolsynth.kinematics.mechanism import as_mechanism
from tolsynth.problem.nlp import ToleranceNLP
from tolsynth.problem.result import Status, SynthesisResult
from tolsynth.problem.specification import ALPHA_DEFAULT, SPHERE_NODES, make_specification
from tolsynth.progress import time_limit as deadline
from tolsynth.solvers.exact import PROBABILITIES
from tolsynth.synthesis.options import DesignSpec, accepts_groups

__all__ = ["synthesize", "SOLVERS"]


def _auto(nlp, eps0, options):
    from tolsynth.solvers.fast import solve_auto

    return solve_auto(nlp, eps0, **options)


def _ipopt(nlp, eps0, options):
    from tolsynth.solvers.ipopt import solve_ipopt

    return solve_ipopt(nlp, eps0, **options)


def _sumt(nlp, eps0, options):
    from tolsynth.solvers.sumt import solve_sumt

    return solve_sumt(nlp, eps0, **options)


def _without_warm_start(options, solver: str, probability: str):
    """``options``; ``warm_start`` where no earlier optimum is kept (only IPOPT and the compiled
    method of the Gaussian reading keep one) refused, saying why."""
    if (
        not isinstance(options, dict)
        or "warm_start" not in options
        or "warm_start" in _solver_defaults(solver, probability)
    ):
        return options
    why = (
        "the exact interior-point solve keeps nothing between solves (each starts from this problem's Gaussian optimum)"
        if probability == "exact"
        else "SUMT + Powell keeps nothing between solves (each starts from scratch)"
    )
    raise InputError(
        "options['warm_start']",
        f"given with probability={probability!r}, solver={solver!r}: {why}",
        f"{', '.join(_solver_defaults(solver, probability))}; warm_start only with probability='gaussian' and "
        "solver 'auto' or 'ipopt'",
    )


def _solver_defaults(solver: str, probability: str = "gaussian") -> dict:
    """The options a solver accepts, with their defaults."""
    if probability == "exact":
        from tolsynth.solvers.exact import DEFAULT_OPTIONS
    elif solver in ("auto", "ipopt"):  # auto: IPOPT's options (it may run IPOPT)
        from tolsynth.solvers.ipopt import DEFAULT_OPTIONS
    else:
        from tolsynth.solvers.sumt import DEFAULT_OPTIONS
    return DEFAULT_OPTIONS


#: largest allowed difference between the NLP's fixed sphere quadrature and stats.p_ball
SPHERE_QUADRATURE_TOL = 1e-9

#: final step of the worst-pose searches that only pick the next pose of synthesize_workspace
COARSE_STEP_TOL = 1e-4

#: the probability a design meets when none is named
DEFAULT_PROBABILITY = "exact"

#: solver name -> private entry point (each solver lives in its own module)
SOLVERS = {"auto": _auto, "ipopt": _ipopt, "sumt": _sumt}
#: the solvers that start from a given x0 whatever the problem ("auto" may run the compiled
#: method, which has its own start): the sweeps pass the previous optimum on to these only
STARTING_SOLVERS = ("ipopt", "sumt")


@accepts_groups  # spec= and solver=SolverOptions(...) merged with the keywords passed
def synthesize(
    mechanism,
    R: float | None = None,
    p: float | None = None,
    distribution=None,
    alpha=ALPHA_DEFAULT,
    solver: str = "auto",
    *,
    k=None,
    bounds=None,
    pose=None,
    poses=None,
    Phi: float | None = None,
    p_orientation: float | None = None,
    criterion: str = "components",
    cost=None,
    locks=None,
    x0=None,
    options: dict | None = None,
    validate: int | None = None,
    seed: int = 0,
    probability: str | None = None,
    verify=None,
    time_limit: float | None = None,
    spec: DesignSpec | None = None,
) -> SynthesisResult:
    """Cheapest tolerances meeting the accuracy specification (the paper's Eq. 23).

    minimise ``sum_i k_i eps_i**-alpha_i`` subject to ``sigma_j z(p) / R <= 1`` for the three
    principal standard deviations of the hand position at every pose (Eq. 20), optionally
    ``sigma_j z(p_orientation) / Phi <= 1`` for the orientation (Eq. 21), and
    ``lower_i <= eps_i <= upper_i`` (Eq. 22).

    Parameters
    ----------
    mechanism : Mechanism or str
        A loaded model or a model name / path.
    R : float
        Radius of the position accuracy specification, mm (R1 = R2 = R3 = R).
    p : float
        Probability per principal component, 0 < p < 1.
    distribution : str or dict, optional
        Distribution of each error inside its band: one shape for every error -- "uniform" (variance
        eps^2/3), "normal" (3 sigma = eps, eps^2/9), "triangular" (eps^2/6), "truncnormal" or
        "truncnormal(beta)" (sigma = eps/beta, cut at +-eps) -- or a dict name -> shape ("*" the
        default; :mod:`tolsynth.probability.distributions`); default: the model file's, else uniform.
    alpha : float, sequence or dict
        Cost exponent(s) alpha_i > 0: one for all, one per parameter, or a dict name -> exponent
        for some parameters (the others keep 0.7, the paper's; a model file carries no alpha).
    solver : {"auto", "ipopt", "sumt"}
        ``"auto"`` (default): the compiled interior-point method of :mod:`tolsynth.solvers.fast`
        where it applies (per-component criterion, power-law costs, Gaussian probability), IPOPT
        elsewhere; ``"ipopt"``: IPOPT with exact derivatives always; ``"sumt"``: the paper's SUMT +
        Powell.  Every result is certified the same way (feasibility checked, dual gap <= 1e-6).
        Under ``probability="exact"`` (the default) it only finds the Gaussian optimum from which
        the exact interior-point method (:mod:`tolsynth.solvers.exact`) solves the problem, as
        ``result.solver`` says (all-normal errors: the named solver solves the problem).
    k : float, sequence or dict, optional
        Cost factors (default: the model's).
    bounds : (lower, upper) or dict name -> (lower, upper), optional
        Tolerance bounds in tolerance units (default: the model's).
    pose, poses : configuration name or joint vector (rad), or a list of them
        Where the constraints are imposed: one pose, or several; not both (an
        :class:`InputError`, whatever their values).  Default: the model's default design pose,
        its ``worst`` configuration, else the worst-pose search's pose
        (:func:`tolsynth.analysis.design_pose.default_design_pose`; ``pose="worst"`` means the same).
    Phi, p_orientation : float, optional
        Orientation specification (rad) and its probability (default p).
    criterion : {"components", "sphere"}
        ``"components"`` (the paper's Eq. 20: ``P(|w_j| <= R) >= p`` for every principal
        component, a convex problem with a certificate) or ``"sphere"`` (beyond the paper:
        ``P(|dr| <= R) >= p`` itself, Eq. 5/13; smooth but not known to be convex, so
        ``lower_bound`` is the components optimum, which it contains).  The sphere probability is
        a fixed quadrature inside the NLP, checked at the result against the error-controlled
        :func:`tolsynth.probability.stats.p_ball` and refined (re-solved with more nodes) until they agree
        to 1e-9.
    cost : CostModel, dict, list or dict name -> model, optional
        Cost model per parameter (:mod:`tolsynth.model.cost`: power law, Chase, exponential, tabulated);
        parameters without one keep ``k eps^-alpha``.  Where a cost is not convex in eps^2 the
        result claims no certificate (its ``lower_bound`` stays valid; see ``result.message``).
    locks : dict name -> tolerance, optional
        Tolerances fixed at given values (e.g. by a supplier); the others are optimised around
        them.  Raises :class:`InfeasibleSpecificationError` naming the locked parameters if they
        alone break the specification.
    x0 : sequence, optional
        Starting tolerances (default: a strictly feasible interior point), read by IPOPT and SUMT
        (``solver="ipopt"`` or ``"sumt"``, and ``"auto"`` where it runs IPOPT).  Where ``"auto"``
        solves by the compiled interior-point method, which starts from its own interior point,
        an ``x0`` is refused (an :class:`InputError`) rather than ignored.
    options : dict, optional
        Solver options.  ``probability="exact"``: max_rounds, max_iter, max_patches (see
        :mod:`tolsynth.solvers.exact`); ``"gaussian"``: IPOPT's and the compiled method's tol,
        constr_viol_tol, max_iter, feas_tol, max_rounds and warm_start (default False: from
        scratch, so that the answer depends on nothing run before it in the process; True: start
        from the last solve of the same poses in this process, faster, but the optimum is then
        reached only to the solver's tolerance and the answer depends on what ran before), SUMT's
        see solve_sumt.
    validate : int, optional
        Run this many Monte Carlo samples through the nonlinear kinematics at the optimum and
        attach the achieved probabilities as ``result.validation``.
    seed : int
        Seed of that Monte Carlo run (and of ``verify``'s): an integer >= 0.
    probability : {"exact", "gaussian", "worst_case"}
        ``"exact"`` (default): the exact probabilities of the linear error model as the
        constraints, along every direction (per component) or in the sphere
        (:mod:`tolsynth.solvers.exact`), with a certificate of global optimality for symmetric
        log-concave shapes; ``"gaussian"``: the paper's criterion, each principal component read
        as normal (where every error is normal the two are the same problem);
        ``"worst_case"``: every error anywhere in its band.
    verify : int or True, optional
        Close the loop (:mod:`tolsynth.analysis.verify`): the nonlinear Monte Carlo at the optimum (this many
        samples per pose; True: chosen from p), and while its 99 % lower bound is below ``p``,
        a tighter target and a new solve; ``result.verification`` reports the achieved
        probability with its interval.
    time_limit : float, optional
        Seconds the solve may take (default :data:`tolsynth.checks.DEFAULT_TIME_LIMIT`, 600 s:
        far beyond any solve of the bundled models, so it only ends one that would not end).  At
        the limit the result has ``status = Status.TIME_LIMIT`` and ``success = False`` (the last
        iterate, or the start point if the solver stopped inside an evaluation).  IPOPT gets it as
        its ``max_wall_time``; the exchange, SUMT and exact-probability loops check it each round.

    spec : DesignSpec, optional
        The specification's fields as one object (:mod:`tolsynth.synthesis.options`); ``solver``
        may likewise be a :class:`SolverOptions`.  A group's field at its default is not given there;
        one given both ways (a keyword passed, even at its default value) must agree.

    Returns
    -------
    SynthesisResult
        ``.success`` is False (with the solver's reason) if the solver did not converge.

    Raises
    ------
    InfeasibleSpecificationError
        If no tolerances inside the bounds can meet the specification.
    OutOfRangeError, InputError, UnknownNameError
        For bad inputs, naming the field.
    """
    if pose is not None and poses is not None:  # one of them would be dropped without a word
        raise InputError(
            "pose",
            f"given together with poses ({pose!r} and {poses!r})",
            "pose= (one pose) or poses= (a list, each constrained), not both",
        )
    seed = check_seed(seed)
    readings = PROBABILITIES + ("worst_case",)
    if probability is not None and (not isinstance(probability, str) or probability not in readings):
        raise InputError("probability", f"got {probability!r}", ", ".join(repr(s) for s in readings))
    if probability == "worst_case":  # every error anywhere in its band: no p or distribution needed
        from tolsynth.synthesis.worst_case import refuse_unread

        refuse_unread(p, distribution, criterion, Phi, p_orientation)
        mechanism = as_mechanism(mechanism)
        pose, chosen = resolve_design_pose(mechanism, pose, poses)  # as the statistical solve below chooses it
        return _worst_case(
            mechanism,
            R,
            p,
            distribution,
            alpha,
            "ipopt" if solver == "auto" else solver,
            k,
            bounds,
            pose,
            poses,
            Phi,
            p_orientation,
            criterion,
            cost,
            locks,
            x0,
            options,
            validate,
            verify,
            time_limit,
            chosen,
        )
    if R is None or p is None:
        missing = "R" if R is None else "p"
        raise InputError(missing, "missing", f"a value for {missing} (a keyword, or spec=DesignSpec({missing}=...))")
    if probability is None:
        probability = DEFAULT_PROBABILITY
    mechanism = as_mechanism(mechanism)
    pose, chosen = resolve_design_pose(mechanism, pose, poses)
    if not isinstance(solver, str) or solver not in SOLVERS:
        raise InputError("solver", f"unknown solver {solver!r}", " or ".join(repr(s) for s in SOLVERS))
    again = dict(
        k=k,
        bounds=bounds,
        pose=pose,
        poses=poses,
        Phi=Phi,
        p_orientation=p_orientation,
        criterion=criterion,
        cost=cost,
        locks=locks,
        options=options,
        probability=probability,
        time_limit=time_limit,
    )

    if not isinstance(probability, str) or probability not in PROBABILITIES:
        raise InputError("probability", f"got {probability!r}", " or ".join(repr(s) for s in PROBABILITIES))
    if options is not None:  # (None: every default)
        options = check_options(
            _without_warm_start(options, solver, probability), _solver_defaults(solver, probability)
        )
    if validate is not None and validate is not False:
        validate = check_count(validate, "validate", lower=0)
    limit = check_time_limit(time_limit)
    cost, locks, bounds = _costs_and_locks(mechanism, cost, locks, bounds)
    spec = make_specification(
        mechanism, R, p, distribution, alpha, k, bounds, pose, poses, Phi, p_orientation, criterion, cost
    )
    nlp = ToleranceNLP(spec)
    refute = None
    if probability == "exact":  # the Gaussian pre-checks only screen: the exact values decide
        from tolsynth.solvers.exact_refute import exact_refuter

        refute = exact_refuter(spec)
    if locks:
        from tolsynth.model.locks import check_locks

        check_locks(nlp, mechanism.joint_error_parameters, refute)
    nlp.check_feasible(refute)
    eps0 = None if x0 is None else check_vector(mechanism.tolerances(x0, "x0"), "x0", lower=TINY)
    if eps0 is not None and solver == "auto":
        from tolsynth.solvers.fast import applies

        if applies(nlp) is None:
            raise InputError(
                "x0",
                "solver 'auto' solves this problem by the compiled interior-point method, which starts "
                "from its own interior point and does not read x0",
                f"x0 with solver {' or '.join(repr(s) for s in STARTING_SOLVERS)} (each starts from it), or no x0",
            )
    with deadline(limit):
        try:
            if probability == "exact":
                from tolsynth.solvers.exact import solve_exact

                result = solve_exact(nlp, spec.shapes, solver, eps0, options)
            else:
                result = SOLVERS[solver](nlp, eps0, dict(options or {}))
            if probability == "gaussian" and spec.sphere_blocks:
                result = _refine_sphere(nlp, spec, result, solver, options)
        except TimeLimitError as exc:  # stopped inside an evaluation: no iterate to report
            result = _timed_out(nlp, solver, eps0, exc)
    from dataclasses import replace

    # the solver's fresh result gets its inputs in place of a dataclasses.replace (which runs
    # __init__ over every field again: ~3 % of a warm solve)
    object.__setattr__(
        result, "inputs", _run_inputs(mechanism, solver, options, locks, x0, validate, seed, probability, verify)
    )
    if chosen is not None:
        result.inputs["default_pose"] = chosen
    if result.feasible:
        from tolsynth.analysis.validation import WorkspaceCheck

        # computed only when read (summary, reports, the command line): a sweep pays nothing
        object.__setattr__(result, "workspace", WorkspaceCheck(mechanism, result, distribution))
    if validate:
        from tolsynth.analysis.validation import validate as mc_validate

        report = mc_validate(  # at every pose of the design, the worst one reported first
            mechanism,
            result,
            R=R,
            p=p,
            distribution=distribution,
            pose=[pose] if poses is None else list(poses),
            n=int(validate),
            seed=seed,
        )
        result = replace(result, validation=report)
    if verify is not None and verify is not False:
        from tolsynth.analysis.verify import closed_loop

        def solve(p_target):
            start = result.x if solver in STARTING_SOLVERS else None
            return synthesize(mechanism, R, p_target, distribution, alpha, solver, x0=start, **again)

        result = closed_loop(
            solve,
            mechanism,
            result,
            p=p,
            R=R,
            distribution=distribution,
            n=None if verify is True else verify,
            seed=seed,
        )
        result = replace(result, inputs={**(result.inputs or {}), "verify": verify})  # the re-solves' record it not
    return result


def _timed_out(nlp, solver: str, eps0, exc: TimeLimitError) -> SynthesisResult:
    """The honest result of a solve stopped inside an evaluation: the start point (not a design),
    its Gaussian constraint values, and the bound of zero multipliers (the cheapest tolerances
    inside the bounds: valid, loose)."""
    from tolsynth.solvers.common import assemble

    eps = nlp.start_point() if eps0 is None else np.asarray(eps0, dtype=float)
    zero = np.zeros((len(nlp.spec.blocks), 3, 3))
    return assemble(
        solver,
        nlp,
        eps,
        zero,
        np.zeros(nlp.spec.n),
        Status.TIME_LIMIT,
        f"{exc}; the tolerances are the start point, not a design",
        0,
        0,
        exc.limit,
        [],
        relaxation_bound=lambda n: n.dual_bound(zero),
    )


def _worst_case(
    mechanism,
    R,
    p,
    distribution,
    alpha,
    solver,
    k,
    bounds,
    pose,
    poses,
    Phi,
    p_orientation,
    criterion,
    cost,
    locks,
    x0,
    options,
    validate,
    verify,
    time_limit=None,
    chosen=None,
):
    """``probability="worst_case"`` (:mod:`tolsynth.synthesis.worst_case`), with the statistical
    design at the same R and p beside it when p is given; ``time_limit`` bounds both solves (the
    worst case's ``options["time_limit"]``); ``chosen`` is the default pose's note, as recorded."""
    from tolsynth.synthesis.worst_case import synthesize_worst_case

    if R is None:
        raise InputError("R", "missing", "a value for R (mm)")
    if time_limit is not None:
        if isinstance(options, dict) and "time_limit" in options:
            raise InputError("time_limit", "given twice: time_limit= and options['time_limit']", "one of the two")
        time_limit = check_time_limit(time_limit)
        options = (
            {**(options if isinstance(options, dict) else {}), "time_limit": time_limit}
            if options is None or isinstance(options, dict)
            else options
        )
    for name, value in (("validate", validate), ("verify", verify)):
        if value is not None and value is not False:
            raise InputError(
                name,
                "given with probability='worst_case' (it reads no probability)",
                "no Monte Carlo check, or a statistical probability ('gaussian' or 'exact')",
            )
    mechanism = as_mechanism(mechanism)
    given = dict(k=k, bounds=bounds, pose=pose, poses=poses, Phi=Phi, cost=cost, locks=locks)
    cost, locks, bounds = _costs_and_locks(mechanism, cost, locks, bounds)

    def statistical():
        return synthesize(
            mechanism,
            R,
            p,
            distribution,
            alpha,
            solver,
            p_orientation=p_orientation,
            criterion=criterion,
            time_limit=time_limit,
            **given,
        )

    return synthesize_worst_case(
        mechanism,
        R,
        p=p,
        alpha=alpha,
        solver=solver,
        k=k,
        bounds=bounds,
        pose=pose,
        poses=poses,
        Phi=Phi,
        cost=cost,
        x0=x0,
        options=options,
        statistical=statistical,
        inputs={
            **_run_inputs(mechanism, solver, options, locks, x0, None, 0, "worst_case"),
            **({"default_pose": chosen} if chosen is not None else {}),
        },
    )


def _costs_and_locks(mechanism, cost, locks, bounds):
    """The model file's cost models and locks where none are given; fixed joint errors cost
    nothing and stay locked whatever else is; locks narrow the bounds."""
    if cost is None and mechanism.cost_models:
        cost = mechanism.cost_models  # the model file's
    if mechanism.fixed_joint_errors:  # given, not bought: no cost, whatever cost= says for the others
        from tolsynth.model.joint_errors import with_given_costs

        cost = with_given_costs(mechanism, cost)
    if locks is None and mechanism.locks:
        locks = mechanism.locks
    elif mechanism.fixed_joint_errors:  # fixed joint errors stay locked whatever else is locked
        locks = {**mechanism.fixed_joint_errors, **check_mapping(locks, "locks", "a dict parameter name -> tolerance")}
    if locks:
        from tolsynth.model.locks import apply_locks

        bounds = apply_locks(mechanism, bounds, locks)
    return cost, locks, bounds


def _refine_sphere(nlp, spec, result, solver, options):
    """The NLP's sphere probability is a fixed quadrature: checked at the optimum against the
    error-controlled one, and the solve repeated with twice the nodes until they agree.  A design
    that meets the sphere has status ``FEASIBLE`` (its optimality is not proven; its lower bound and
    gap come from relaxations, :func:`tolsynth.solvers.common.assemble`)."""
    from dataclasses import replace

    while result.feasible:
        exact = np.array([P for _, _, P in nlp.sphere_values(result.x)])
        off = np.max(np.abs(nlp.sphere_quadrature(result.x) - exact))
        if off <= SPHERE_QUADRATURE_TOL:
            break
        if nlp.sphere_nodes >= 4 * SPHERE_NODES:
            return replace(
                result,
                success=False,
                status=Status.NUMERICAL_ERROR,
                message=f"{result.message}; sphere quadrature still off by {off:.1e} with {nlp.sphere_nodes} nodes",
            )
        nlp = ToleranceNLP(spec, sphere_nodes=2 * nlp.sphere_nodes)
        result = SOLVERS[solver](nlp, result.x, dict(options or {}))
    return result


def _run_inputs(mechanism, solver, options, locks, x0, validate, seed, probability="gaussian", verify=None) -> dict:
    """What a result records beyond its specification (see :mod:`tolsynth.io.tables`)."""
    path = getattr(mechanism.spec, "path", None)
    return {
        "model": {"name": mechanism.name, "title": mechanism.title, "file": str(path) if path else None},
        "solver": solver,
        "options": dict(options or {}),
        "locks": dict(locks) if locks else None,
        "probability": probability,
        "verify": None if verify is None or verify is False else verify,
        "x0": None if x0 is None else np.asarray(mechanism.tolerances(x0, "x0"), dtype=float).tolist(),
        "validate": validate or None,
        "seed": seed if validate else None,
        "joint_errors": _joint_error_inputs(mechanism),
    }


def _joint_error_inputs(mechanism) -> dict | None:
    """Name -> joint, transform ("q": the joint variable), unit and fixed value of each joint
    error (:mod:`tolsynth.model.joint_errors`; a model file does not show those added in memory)."""
    out = {
        p.name: {"joint": p.at_joint[0], "transform": p.at_joint[1], "unit": p.unit, "fixed": p.lock}
        for p in mechanism.parameters
        if p.at_joint is not None
    }
    return out or None
