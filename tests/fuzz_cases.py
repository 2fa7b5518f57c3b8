"""The fuzz cases, shared by ``tests/test_fuzz.py`` (hypothesis, the invariant as an
assertion) and ``tests/fuzz_counts.py`` (the same cases, outcomes counted per category).

The invariant for every case: it either succeeds with finite, independently checked numbers, or
raises a :class:`tolsynth.TolsynthError` naming the field.  Never an untyped exception, never a
hang (each case runs under a ``signal`` alarm), never a numerical warning from inside the package,
never a traceback on the command line, and never a silent acceptance of a model file that has an
unknown key, a NaN, an infinity or a duplicate.

Only the public API (and ``tolsynth.errors``) is used, so the same cases run against older
versions of the package (the "before" counts).
"""

from __future__ import annotations

import contextlib
import copy
import io
import math
import signal
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
from hypothesis import strategies as st

import tolsynth
from model_text import model_dict, toml_text
from tolsynth.errors import TolsynthError

MODELS = ("planar_2r", "puma560", "xu_zhang_1988")
CASE_SECONDS = (
    60  # a case that takes longer is a hang (the slowest valid cases take ~12 s alone, 20+ s on a loaded machine)
)


class Hang(BaseException):
    """Raised by the alarm: the case ran longer than CASE_SECONDS."""


class BadNumbers(AssertionError):
    """A call that succeeded returned numbers that are not finite or fail the independent check."""


class Silent(AssertionError):
    """A defect that must be rejected was accepted."""


# ---------------------------------------------------------------------------------------------
# running one case and classifying its outcome
# ---------------------------------------------------------------------------------------------
#: (category, description) of every case that broke the invariant, for reports
FAILURES: list[tuple[str, str]] = []


def outcome(fn) -> str:
    """See :func:`_outcome`; cases that break the invariant are recorded in FAILURES."""
    exc_box: list = []
    cat = _outcome(fn, exc_box)
    if cat not in GOOD:
        FAILURES.append((cat, "".join(exc_box[:1]) or cat))
    return cat


def _outcome(fn, box) -> str:
    """Run ``fn`` and classify: "ok", "typed" (a TolsynthError naming its field), "unnamed" (a
    TolsynthError whose message lacks its field), "untyped", "hang", "warning", "bad_numbers",
    "silent"."""

    def alarm(signum, frame):
        raise Hang()

    previous = signal.signal(signal.SIGALRM, alarm)
    # repeating: an alarm that lands where an exception is swallowed (a gc callback) fires again
    signal.setitimer(signal.ITIMER_REAL, CASE_SECONDS, 1.0)
    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            warnings.filterwarnings("error", module=r"tolsynth")
            # the sampled workspace check's warning, and the certified search's that its proof may
            # not close, are the package telling the truth, not a defect
            for name in ("WorkspaceWarning", "CertificationWarning"):  # (absent in older versions)
                if getattr(tolsynth.errors, name, None) is not None:
                    warnings.filterwarnings("ignore", category=getattr(tolsynth.errors, name))
            fn()
        return "ok"
    except Hang:
        box.append(_where())
        return "hang"
    except BadNumbers as exc:
        box.append(f"{exc}")
        return "bad_numbers"
    except Silent as exc:
        box.append(f"{exc}")
        return "silent"
    except TolsynthError as exc:
        field = getattr(exc, "field", None)
        if field is not None and (not isinstance(field, str) or field not in str(exc)):
            box.append(f"{type(exc).__name__}: {exc}")
            return "unnamed"
        return "typed"
    except Warning as exc:
        box.append(f"{type(exc).__name__}: {exc} {_where()}")
        return "warning"
    except Exception as exc:
        box.append(f"{type(exc).__name__}: {str(exc)[:200]} {_where()}")
        return "untyped"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


GOOD = ("ok", "typed")


def _where() -> str:
    """Innermost tolsynth frame of the exception being handled."""
    import sys
    import traceback

    frames = [
        f for f in traceback.extract_tb(sys.exc_info()[2]) if "tolsynth" in f.filename and "tests" not in f.filename
    ]
    return f"at {Path(frames[-1].filename).name}:{frames[-1].lineno}" if frames else ""


def finite(*values) -> None:
    for v in values:
        if v is None:
            continue
        arr = np.asarray(v, dtype=float)
        if not np.all(np.isfinite(arr)):
            raise BadNumbers(f"non-finite value {v!r}")


def probability(*values) -> None:
    for v in values:
        if v is None:
            continue
        arr = np.asarray(v, dtype=float)
        if not np.all((arr >= 0) & (arr <= 1)):
            raise BadNumbers(f"probability outside [0, 1]: {v!r}")


# ---------------------------------------------------------------------------------------------
# model files
# ---------------------------------------------------------------------------------------------
MUTATIONS = (
    "delete",
    "type",
    "nan",
    "inf",
    "huge",
    "negative",
    "unknown_key",
    "duplicate",
    "empty",
    "truncated",
    "binary",
)
#: mutations that must always be rejected (a NaN, an infinity, an unknown key are never valid)
MUST_REJECT = ("nan", "inf", "unknown_key")
#: lists whose items must be distinct (a duplicate there doubles a sensitivity, a loop, a joint)
DISTINCT_LISTS = ("perturbs", "loops", "joints", "error_parameters", "joint_constraints", "waive", "links")
WRONG_TYPES = (True, "text", [1.0, 2.0], {"a": 1}, 1.5, 7, [], {})


def _paths(obj, prefix=()):
    """Every path (tuple of keys / indices) to a value inside ``obj``."""
    out = []
    if isinstance(obj, dict):
        for k, v in obj.items():
            out.append(prefix + (k,))
            out.extend(_paths(v, prefix + (k,)))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            out.append(prefix + (i,))
            out.extend(_paths(v, prefix + (i,)))
    return out


def _parent(data, path):
    t = data
    for key in path[:-1]:
        t = t[key]
    return t


def mutate(draw, model: str, kind: str):
    """A mutated model file: (bytes, must_reject)."""
    data = copy.deepcopy(model_dict(model))
    paths = _paths(data)
    if kind in ("truncated", "binary"):
        text = toml_text(data).encode()
        if kind == "truncated":
            return text[: draw(st.integers(0, len(text) - 1))], False
        at = draw(st.integers(0, len(text)))
        junk = draw(st.binary(min_size=1, max_size=8))
        return text[:at] + junk + text[at:], False
    if kind == "empty":
        path = draw(st.sampled_from(paths))
        parent = _parent(data, path)
        value = parent[path[-1]]
        parent[path[-1]] = type(value)() if isinstance(value, (dict, list, str)) else []
        return toml_text(data).encode(), False
    if kind == "delete":
        path = draw(st.sampled_from(paths))
        parent = _parent(data, path)
        del parent[path[-1]]
        return toml_text(data).encode(), False
    if kind == "unknown_key":
        tables = [()] + [p for p in paths if isinstance(_parent(data, p + ("x",)), dict)]
        path = draw(st.sampled_from(tables))
        table = _parent(data, path + ("x",))
        valid = list(table)
        word = draw(st.sampled_from(valid)) if valid else "name"
        # a misspelling of a valid key (drop the last letter, or add one) or a made-up key
        bad = draw(st.sampled_from([word[:-1] or "z", word + "s", word + "_x", "titel", "colour"]))
        if bad in table:
            bad = bad + "_typo"
        table[bad] = draw(st.sampled_from([1.0, "x", [1.0], {"a": 1.0}]))
        # a symbol, a tolerance-set value or a configuration's joint value may have any name: a new
        # key there is a new symbol (rejected when unused), a new set, a new configuration
        free = path in ((),) or (path and path[-1] in ("symbols", "tolerance_sets", "configurations"))
        return toml_text(data).encode(), not free or path[-1:] == ("symbols",)
    numeric = [p for p in paths if not isinstance(_parent(data, p)[p[-1]], (dict, list))]
    path = draw(st.sampled_from(numeric))
    parent = _parent(data, path)
    if kind == "type":
        parent[path[-1]] = draw(st.sampled_from(WRONG_TYPES))
        return toml_text(data).encode(), False
    if kind == "nan":
        parent[path[-1]] = math.nan
    elif kind == "inf":
        parent[path[-1]] = draw(st.sampled_from([math.inf, -math.inf]))
    elif kind == "huge":
        parent[path[-1]] = draw(st.sampled_from([1e300, -1e300, 1e155, 10**40, 1e10]))
    elif kind == "negative":
        v = parent[path[-1]]
        parent[path[-1]] = -v if isinstance(v, (int, float)) and not isinstance(v, bool) and v else -1.0
    elif kind == "duplicate":
        lists = [p for p in paths if isinstance(_parent(data, p)[p[-1]], list) and _parent(data, p)[p[-1]]]
        path = draw(st.sampled_from(lists))
        lst = _parent(data, path)[path[-1]]
        lst.append(copy.deepcopy(lst[draw(st.integers(0, len(lst) - 1))]))
        return toml_text(data).encode(), path[-1] in DISTINCT_LISTS
    return toml_text(data).encode(), kind in MUST_REJECT


@st.composite
def model_mutations(draw, kinds=MUTATIONS):
    model = draw(st.sampled_from(MODELS))
    kind = draw(st.sampled_from(kinds))
    blob, must_reject = mutate(draw, model, kind)
    return model, kind, blob, must_reject


def load_mutated(tmp: Path, blob: bytes, must_reject: bool):
    """Load the mutated bytes; a model that loads is used (FK and sensitivities at every named
    configuration must be finite, or a typed error)."""
    path = tmp / "fuzz.toml"
    path.write_bytes(blob)
    m = tolsynth.load_model(path)
    if must_reject:
        raise Silent("a defect that must be rejected was accepted")
    for name in m.configurations:
        try:
            T = m.fk(name)
            S = m.sensitivity(name)
        except TolsynthError:
            continue
        finite(T, S)
    # and used: an analysis with its first tolerance set, and a synthesis (checked independently)
    for name in list(m.configurations)[:1]:
        for tset in list(m.tolerance_sets)[:1]:
            a = m.analyze(name, tset, R=0.5)
            finite(a.covariance, a.p_sphere)
            probability(a.p_components, a.p_sphere)
        res = tolsynth.synthesize(m, 0.5, 0.99, pose=name)
        _check_synthesis(m, res, 0.5, 0.99, "uniform", [name])


# ---------------------------------------------------------------------------------------------
# API arguments
# ---------------------------------------------------------------------------------------------
BAD = (
    0,
    -1,
    -0.0,
    1e-300,
    -1e-300,
    1e300,
    -1e300,
    1e155,
    math.nan,
    math.inf,
    -math.inf,
    1 - 1.1e-16,
    2**70,
    True,
    None,
    "1",
    "",
    [],
    [1.0],
    {},
    np.float64("nan"),
    1e-12,
    0.5,
    3,
)


def _mech(name):
    return tolsynth.load_model(name)


def _divisors(mech, distribution):
    """eps^2 / variance per parameter, from the shapes' textbook variances (uniform on +-eps: eps^2/3;
    normal with 3 sigma = eps: eps^2/9; triangular: eps^2/6). ``None`` is the model's own shapes;
    names are case-blind; a mapping names parameters, with ``"*"`` for the rest."""
    table = {"uniform": 3.0, "normal": 9.0, "triangular": 6.0}
    return np.array([table[s] for s in _shape_names(mech, distribution)])


def _shape_names(mech, distribution) -> list[str]:
    """The shape of every error parameter: ``None`` is the model's own; a mapping names parameters, with
    ``"*"`` for the rest."""
    if distribution is None:
        distribution = getattr(mech, "distribution", "uniform")
    if isinstance(distribution, str):
        return [distribution.lower()] * len(mech.error_parameters)
    default = distribution.get("*", "uniform")
    return [distribution.get(n, default).lower() for n in mech.error_parameters]


def _samples(shapes: list[str], n: int, rng) -> np.ndarray:
    """n draws of the standardised errors (on [-1, 1]; the normal with 3 sigma = 1) by NumPy."""
    draw = {
        "uniform": lambda: rng.uniform(-1.0, 1.0, n),
        "normal": lambda: rng.normal(0.0, 1.0 / 3.0, n),
        "triangular": lambda: rng.triangular(-1.0, 0.0, 1.0, n),
    }
    return np.stack([draw[s]() for s in shapes], axis=1)


def _check_exact(mech, eps, R, p, distribution, poses):
    """An exact design meets p along every direction: a NumPy Monte Carlo of the linear error model
    (100 000 draws) along the principal axes and 300 spread directions, each within four binomial
    standard errors of p or above it."""
    rng = np.random.default_rng(2024)
    n = 100_000
    U = _samples(_shape_names(mech, distribution), n, rng) * eps
    i = np.arange(300) + 0.5
    z = 1 - 2 * i / 300
    W = np.stack(
        [np.sqrt(1 - z**2) * np.cos(np.pi * (1 + 5**0.5) * i), np.sqrt(1 - z**2) * np.sin(np.pi * (1 + 5**0.5) * i), z],
        1,
    )
    slack = 4 * math.sqrt(p * (1 - p) / n) + 1e-9
    for q in poses:
        S = mech.sensitivity(q, check_limits=False)[:3]
        dr = U @ S.T
        axes = np.linalg.eigh(S @ np.diag(eps**2) @ S.T)[1].T
        P = (np.abs(dr @ np.vstack([axes, W]).T) <= R).mean(axis=0)
        if P.min() < p - slack:
            raise BadNumbers(f"exact optimum below p along a direction: {P.min()} < {p} - {slack:.1e}")


def _check_synthesis(mech, res, R, p, distribution, poses):
    """Independent check of a converged optimum: for the paper's Gaussian criterion the covariance
    rebuilt with NumPy from the sensitivities, whose eigenvalues must not exceed (R / z)^2; for the
    exact probabilities (the default) a Monte Carlo of the linear error model along directions."""
    from statistics import NormalDist

    if res is None:
        raise BadNumbers("no result")
    if not res.success:
        return
    eps = np.array([res.tolerances[n] for n in mech.error_parameters])
    finite(eps, res.cost)
    if not np.all(eps > 0):
        raise BadNumbers("a tolerance <= 0")
    if res.probability_kind == "exact":
        _check_exact(mech, eps, R, p, distribution, poses)
        return
    c = _divisors(mech, distribution)
    z = NormalDist().inv_cdf(0.5 + 0.5 * p)
    for q in poses:
        S = mech.sensitivity(q, check_limits=False)[:3]
        V = S @ np.diag(eps**2 / c) @ S.T
        lam = np.linalg.eigvalsh(V)
        if lam.max() > (R / z) ** 2 * (1 + 1e-5) + 1e-300:
            raise BadNumbers(f"optimum violates the specification: {lam.max()} > {(R / z) ** 2}")


def accepted(**values) -> None:
    """Called after a call returned normally: a NaN or an infinity among its arguments must have
    been rejected (no argument accepts one), so its acceptance is a silent failure."""
    for name, v in values.items():
        if isinstance(v, (float, np.floating)) and not math.isfinite(v):
            raise Silent(f"{name} = {v} was accepted")


def _args(draw, defaults: dict, pool: dict | None = None, k: int = 2) -> dict:
    """``defaults`` with 1..k arguments replaced by bad or extreme values."""
    args = dict(defaults)
    names = draw(st.lists(st.sampled_from(sorted(defaults)), min_size=1, max_size=k, unique=True))
    for name in names:
        choices = list(BAD) + list((pool or {}).get(name, ()))
        args[name] = draw(st.sampled_from(choices))
    return args


def case_synthesize(draw):
    mech = _mech(draw(st.sampled_from(["planar_2r", "xu_zhang_1988"])))
    pose = "worst"
    args = _args(
        draw,
        {
            "R": 0.5,
            "p": 0.99,
            "distribution": "uniform",
            "alpha": 0.7,
            "k": None,
            "bounds": None,
            "x0": None,
            "options": None,
            "criterion": "components",
            "Phi": None,
        },
        {
            "distribution": ["normal", "Uniform"],
            "criterion": ["sphere", "sphre"],
            "options": [
                {"tol": -1},
                {"tol": 1e-8},
                {"max_iter": 0},
                {"max_iter": 2.5},
                {"nope": 1},
                {"tol": math.nan},
                "tol",
            ],
            "x0": [
                np.zeros(mech.n),
                np.full(mech.n, 1e155),
                np.full(mech.n, 0.01),
                [1.0],
                np.full(mech.n, 1e8),
                np.full(mech.n, 1e-12),
            ],
            "bounds": [(1e-3, 1e300), (0.0, 1.0), (2.0, 1.0), {"zz": (1, 2)}, ("a", "b")],
            "alpha": [{"x": 1}, np.full(mech.n, 0.7), 1e9, 50.0],
            "k": [1e155, np.full(mech.n, -1.0), {"zz": 1}],
            "R": [1e-9, 1e6],
            "p": [0.999999, 1e-9],
            "Phi": [0.01, -0.01],
        },
    )

    def run():
        res = tolsynth.synthesize(mech, pose=pose, **args)
        accepted(**args)
        if args.get("criterion") == "components" and args.get("Phi") is None:
            R = args["R"] if not isinstance(args["R"], str) else float(args["R"].removesuffix("mm"))  # '1' or '1mm'
            _check_synthesis(mech, res, R, args["p"], args["distribution"], [pose])
        elif res.feasible:  # (the sphere's designs: feasible, optimality not proven)
            finite(res.cost, list(res.tolerances.values()))

    return run


def case_synthesize_valid(draw):
    """A valid specification with random numbers: an optimum that passes the independent check,
    an honest non-convergence, or InfeasibleSpecificationError."""
    mech = _mech(draw(st.sampled_from(MODELS)))
    pose = draw(st.sampled_from(sorted(mech.configurations)))
    R = draw(st.floats(1e-3, 20.0))
    p = draw(st.floats(0.5, 0.9999))
    dist = draw(st.sampled_from(["uniform", "normal"]))
    alpha = draw(st.floats(0.2, 2.0))

    def run():
        res = tolsynth.synthesize(mech, R, p, dist, alpha, pose=pose)
        _check_synthesis(mech, res, R, p, dist, [pose])

    return run


def case_analyze(draw):
    mech = _mech(draw(st.sampled_from(MODELS)))
    args = _args(
        draw,
        {"q": "worst", "tolerances": next(iter(mech.tolerance_sets)), "distribution": "uniform", "R": 0.5, "Phi": None},
        {
            "q": [np.zeros(len(mech.joint_names)), [np.nan] * len(mech.joint_names), "nowhere"],
            "tolerances": [
                np.full(mech.n, 1e155),
                np.zeros(mech.n),
                np.full(mech.n, -1.0),
                {"x": 1},
                np.full(mech.n, 1e-300),
            ],
            "R": [1e-12, 1e-9, 1e9],
            "Phi": [1e-12, 0.01],
        },
    )

    def run():
        a = mech.analyze(**args)
        accepted(**args)
        finite(
            a.position,
            a.sensitivity,
            a.covariance,
            a.principal_std,
            a.p_components,
            a.p_sphere,
            a.p_cone,
            a.p_orientation_components,
        )
        probability(a.p_components, a.p_sphere, a.p_cone, a.p_orientation_components)

    return run


def case_monte_carlo(draw):
    mech = _mech(draw(st.sampled_from(["planar_2r", "xu_zhang_1988"])))
    args = _args(
        draw,
        {
            "q": "worst",
            "tolerances": next(iter(mech.tolerance_sets)),
            "distribution": "uniform",
            "R": 0.5,
            "n": 2000,
            "seed": 0,
            "batch": 1000,
            "Phi": None,
            "confidence": 0.95,
        },
        {
            "n": [1, 10**13, 2.5, 1e4],
            "seed": [-1, 1.5, 2**70],
            "batch": [1, 10**13],
            "tolerances": [np.full(mech.n, 1e155), np.zeros(mech.n)],
        },
    )

    def run():
        r = tolsynth.monte_carlo(mech, **args)
        accepted(**args)
        finite(r.p_components, r.p_sphere)
        probability(r.p_components, r.p_sphere)

    return run


def case_validate(draw):
    mech = _mech("planar_2r")
    args = _args(
        draw,
        {
            "tolerances_or_result": "coarse",
            "R": 0.5,
            "p": 0.9,
            "distribution": "uniform",
            "pose": "worst",
            "n": 2000,
            "seed": 0,
        },
        {"tolerances_or_result": [np.full(mech.n, 1e155), object()], "n": [10**13, 2.5]},
    )

    def run():
        v = tolsynth.validate(mech, **args)
        accepted(**args)
        probability(v.p_components, v.p_sphere)

    return run


def case_worst_pose(draw):
    mech = _mech(draw(st.sampled_from(["planar_2r", "xu_zhang_1988"])))
    args = _args(
        draw,
        {
            "tolerances": next(iter(mech.tolerance_sets)),
            "criterion": "sigma",
            "R": 0.5,
            "distribution": "uniform",
            "grid": 4,
            "starts": 2,
            "step_tol": 1e-4,
            "max_grid_points": 100,
            "seed": 0,
            "reference": "worst",
            "fixed": None,
        },
        {
            "criterion": ["probability", "sigmaa"],
            "grid": [1, 2, 10**6],
            "starts": [10**6, 2.5],
            "max_grid_points": [1, 10**12],
            "step_tol": [1e-7, 1.0, 2.0],
            "fixed": [{"nope": 0.0}, {mech.joint_names[0]: math.nan}, {mech.joint_names[0]: "a"}],
            "reference": ["nowhere", [0.0], [math.nan] * len(mech.joint_names)],
        },
    )

    def run():
        w = tolsynth.worst_pose(mech, **args)
        accepted(**args)
        finite(w.q, w.value, w.position)

    return run


def case_probability_map(draw):
    mech = _mech("planar_2r")
    args = _args(
        draw,
        {
            "tolerances": "coarse",
            "R": 0.5,
            "distribution": "uniform",
            "n": 6,
            "plane": "xy",
            "offset": 0.0,
            "hand_axis": None,
            "extent": None,
            "reference": "worst",
            "seeds": 1,
            "check_points": 3,
        },
        {
            "n": [5, 10**6, 4.0],
            "plane": ["xz", "ab"],
            "extent": [(0, 1, 0, 1), (1, 0, 0, 1), (math.nan, 1, 0, 1), (0, 1e300, 0, 1)],
            "hand_axis": [(0, 0, 0), (0, 0, 1)],
            "seeds": [10**9, -1],
            "check_points": [10**9, -1],
        },
    )

    def run():
        pm = tolsynth.probability_map(mech, progress=False, **args)
        accepted(**args)
        P = np.asarray(pm.P, dtype=float)
        probability(P[np.isfinite(P)])

    return run


def case_synthesize_workspace(draw):
    mech = _mech("planar_2r")
    args = _args(
        draw,
        {
            "R": 0.5,
            "p": 0.99,
            "distribution": "uniform",
            "tol": 1e-3,
            "max_rounds": 2,
            "search": {"grid": 4, "max_grid_points": 100},
        },
        {"max_rounds": [0, -1, 10**9, 1.5], "tol": [-1.0, 0.0], "search": [{"grid": 10**6}, {"x": 1}, "a"]},
    )

    def run():
        ws = tolsynth.synthesize_workspace(mech, pose="elbow90", **args)
        accepted(**args)
        if ws.result is None:
            raise BadNumbers("result is None")
        if ws.success:
            finite(ws.result.cost)

    return run


def case_compare(draw):
    mech = _mech("planar_2r")
    args = _args(
        draw,
        {"R": 0.5, "p": 0.99, "distribution": "uniform", "alpha": 0.7, "options": None},
        {"options": [{"ipopt": {"tol": -1}}, {"sumt": {"x": 1}}, {"ipopt": "a"}, [1]]},
    )

    def run():
        c = tolsynth.compare(mech, pose="elbow90", **args)
        accepted(**args)
        finite(c.ipopt.cost, c.sumt.cost)

    return run


def case_mechanism(draw):
    mech = _mech(draw(st.sampled_from(MODELS)))
    nq = len(mech.joint_names)
    method = draw(st.sampled_from(["fk", "sensitivity", "joints", "deltas", "tolerances", "index", "with_units"]))
    pool = {
        "fk": [np.zeros(nq), [math.nan] * nq, [1e300] * nq, "nowhere", [0.0], None, 5],
        "sensitivity": [np.zeros(nq), [math.inf] * nq, "worst", {}, [[0.0] * nq]],
        "joints": [np.zeros(nq), [1e300] * nq, ["a"] * nq, None, 3.0],
        "deltas": [
            {"zz": 1.0},
            {mech.error_parameters[0]: "a"},
            np.full(mech.n, 1e300),
            [1.0],
            "x",
            {mech.error_parameters[0]: math.nan},
        ],
        "tolerances": [
            {mech.error_parameters[0]: "a"},
            np.full(mech.n, 1e155),
            "nope",
            5,
            None,
            {mech.error_parameters[0]: None},
        ],
        "index": ["nope", ["a"], None, 3],
        "with_units": [
            {mech.error_parameters[0]: "furlong"},
            {mech.error_parameters[0]: 3},
            "mm",
            {"nope": "mm"},
            [("a", "mm")],
        ],
    }
    value = draw(st.sampled_from(pool[method] + list(BAD)))

    def run():
        if method in ("fk", "sensitivity"):
            out = (
                getattr(mech, method)("worst", deltas=value)
                if isinstance(value, dict)
                else getattr(mech, method)(value)
            )
            finite(out)
        elif method == "with_units":
            m2 = mech.with_units(value)
            finite(m2.bounds)
        else:
            out = getattr(mech, method)(value)
            if not isinstance(out, int):
                finite(out)
        accepted(value=value)

    return run


def case_stats(draw):
    fn = draw(st.sampled_from(["z_of_p", "p_ball", "p_components", "p_cone"]))
    a = draw(
        st.sampled_from(
            list(BAD) + [[1.0, 2.0, 3.0], [1e300, 1.0, 1e-300], [0.0, 0.0, 0.0], [[1.0]], np.eye(3), [1.0, -1.0]]
        )
    )
    b = draw(st.sampled_from(list(BAD) + [0.5, 1e-12, 1e9]))

    def run():
        if fn == "z_of_p":
            out = tolsynth.z_of_p(a)
        elif fn == "p_ball":
            out = tolsynth.p_ball(a, b)
        elif fn == "p_components":
            out = tolsynth.p_components(a, b)
        else:
            out = tolsynth.p_cone(np.eye(3) * 1e-6 if isinstance(a, (int, float)) else a, (0, 0, 1), b)
        finite(out)
        if fn != "z_of_p":
            probability(out)
        accepted(**({"a": a} if fn == "z_of_p" else {"b": b} if fn == "p_cone" else {"a": a, "b": b}))

    return run


def _log_uniform(draw, lo, hi):
    return float(10.0 ** draw(st.floats(math.log10(lo), math.log10(hi))))


def case_valid_extremes(draw):
    """Valid arguments across their whole allowed range (log-uniform: 1e-12 .. 1e9 tolerances,
    radii, probabilities to 1e-12 of 0 and 1): finite numbers, probabilities in [0, 1], no warning."""
    mech = _mech(draw(st.sampled_from(MODELS)))
    fn = draw(st.sampled_from(["analyze", "monte_carlo", "worst_pose", "p_ball", "synthesize"]))
    eps = np.array([_log_uniform(draw, 1e-12, 1e9) for _ in range(mech.n)])
    eps[draw(st.integers(0, mech.n - 1))] = draw(st.sampled_from([0.0, 1e-12, 1e9]))
    R = _log_uniform(draw, 1e-12, 1e9)
    p = draw(st.sampled_from([1e-12, 1e-6, 0.5, 0.99, 1 - 1e-6, 1 - 1e-12]))
    cfg = draw(st.sampled_from(sorted(mech.configurations)))
    # the sphere criterion at extreme R and p refines its quadrature graph, and building the
    # refined IPOPT solver alone takes 10-50 s (a cost, not a hang): only moderate R, p for it here
    criterion = draw(st.sampled_from(["components", "sphere"]))
    if criterion == "sphere":
        R, p = _log_uniform(draw, 1e-2, 1e2), draw(st.sampled_from([0.5, 0.9, 0.99]))

    def run():
        if fn == "analyze":
            a = mech.analyze(cfg, eps, R=R, Phi=_log_uniform(draw, 1e-12, 1e3), check_limits=False)
            finite(a.covariance, a.principal_std, a.p_components, a.p_sphere, a.p_cone)
            probability(a.p_components, a.p_sphere, a.p_cone, a.p_orientation_components)
        elif fn == "monte_carlo":
            r = tolsynth.monte_carlo(mech, cfg, eps, R=R, n=500, check_limits=False)
            probability(r.p_components, r.p_sphere)
        elif fn == "worst_pose":
            # tolerances spanning all 21 decades make the sphere quadrature of every searched pose
            # slow (about 12 s for puma560: many panels for variance ratios near 1e-15), not wrong;
            # the search gets 9 decades here so that each case stays within its time bound
            e = np.clip(eps, 1e-6, 1e3)
            w = tolsynth.worst_pose(
                mech,
                e,
                criterion="probability",
                R=R,
                grid=3,
                starts=1,
                step_tol=1e-3,
                max_grid_points=50,
                reference=None,
            )
            finite(w.q, w.value)
        elif fn == "p_ball":
            probability(tolsynth.p_ball(eps[:3] ** 2, R))
        else:
            bounds = (np.full(mech.n, 1e-12), np.full(mech.n, 1e9))
            res = tolsynth.synthesize(mech, R, p, bounds=bounds, pose=cfg, criterion=criterion, probability="gaussian")
            if criterion == "components":
                _check_synthesis(mech, res, R, p, "uniform", [cfg])
            elif res.feasible:  # the sphere probability reached (status feasible), by the independent quadrature
                from tolsynth.probability.stats import p_ball

                e = np.array([res.tolerances[n] for n in mech.error_parameters])
                S = mech.sensitivity(cfg, check_limits=False)[:3]
                lam = np.linalg.eigvalsh(S @ np.diag(e**2 / 3.0) @ S.T)
                if p_ball(np.clip(lam, 0, None), R) < p - 1e-6:
                    raise BadNumbers("sphere optimum below p")

    return run


def case_sweep(draw):
    """tolsynth.sweep with bad grids (typed errors before any solve), in this process."""
    mech = _mech("planar_2r")
    args = _args(
        draw,
        {
            "R": [0.5, 0.3],
            "p": 0.99,
            "alpha": 0.7,
            "distribution": "uniform",
            "criterion": "components",
            "solver": "ipopt",
        },
        {
            "R": [[], [0.5, -1.0], [0.3, math.nan], ["0.5"], [[0.5]], np.array([0.2, 0.4]), {"a": 1}],
            "p": [[0.9, 1.0], [0.5, 0.99], [math.inf], (0.9,)],
            "alpha": [[0.7, 0.0], [{"x": 1}], [0.5, 11.0], {"h1": 0.5}],
            "distribution": [["uniform", "normal"], ["cauchy"], [], "Normal"],
            "criterion": [["components", "sphere"], "box", [None]],
            "solver": [["ipopt", "snopt"], "powell", [1]],
        },
    )
    client = draw(st.sampled_from(["serial", "serial", "threads", 3, "", "tcp", b"serial"]))
    workers = draw(st.sampled_from([None, None, 0, -1, 2.5, "2", 1e300]))

    def run():
        df = tolsynth.sweep(mech, client=client, workers=workers, pose="elbow90", progress=False, **args)
        accepted(**args)
        typed = {
            c.__name__
            for c in vars(tolsynth.errors).values()
            if isinstance(c, type) and issubclass(c, tolsynth.TolsynthError)
        }
        for err in df.loc[df["status"] == "error", "error"]:  # a row's exception must be typed too
            if err.split(":")[0] not in typed:
                raise Silent(f"untyped error inside a sweep row: {err}")
        ok = df[df["success"]]
        finite(ok["cost"].to_numpy(), ok[[c for c in df.columns if c.startswith("eps_")]].to_numpy())
        for _, row in ok.iterrows():
            if row["criterion"] == "components":
                res = type(
                    "R",
                    (),
                    {
                        "success": True,
                        "cost": row["cost"],
                        "tolerances": {n: row["eps_" + n] for n in mech.error_parameters},
                    },
                )
                _check_synthesis(mech, res, row["R"], row["p"], row["distribution"], ["elbow90"])

    return run


API_CASES = {
    "synthesize": case_synthesize,
    "synthesize (valid specs)": case_synthesize_valid,
    "analyze": case_analyze,
    "monte_carlo": case_monte_carlo,
    "validate": case_validate,
    "worst_pose": case_worst_pose,
    "probability_map": case_probability_map,
    "synthesize_workspace": case_synthesize_workspace,
    "compare": case_compare,
    "Mechanism methods": case_mechanism,
    "stats": case_stats,
    "valid extremes": case_valid_extremes,
    "sweep": case_sweep,
}


# ---------------------------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------------------------
CLI_VALUES = (
    "0",
    "-1",
    "nan",
    "inf",
    "1e300",
    "1e-300",
    "",
    "abc",
    "0.99",
    "0.5",
    "1,2",
    ",,,",
    "worst",
    "figure3",
    "figure3,h2=0.1,h2=0.2",
    "figure3,,,",
    "free",
    "0,0,1",
    "-0",
    "0.1mm",
    "5um",
    "1e9m",
    "2mrad",
    "h*=0.01",
    "1:",
    ":0",
    "x.xyz",
    "/nonexistent/dir/x.png",
    "none",
    "0,0,0,0,0",
    "l1=50um",
    "l1=1e-5",
    "o1=2mrad",
    "l1=",
    "/proc/x.csv",
)
#: command -> (fixed arguments that make a valid, quick run, options fuzzed)
CLI_COMMANDS = {
    "analyze": (
        ["--model", "xu_zhang_1988", "--pose", "worst", "--tolerances", "figure3", "--R", "0.5"],
        ["--model", "--pose", "--tolerances", "--R", "--Phi", "--dist"],
    ),
    "solve": (
        ["--model", "planar_2r", "--pose", "elbow90", "--R", "0.5", "--p", "0.99"],
        [
            "--model",
            "--R",
            "--p",
            "--alpha",
            "--k",
            "--bounds",
            "--pose",
            "--Phi",
            "--p-orientation",
            "--criterion",
            "--solver",
            "--lock",
            "--out",
        ],
    ),
    "montecarlo": (
        ["--model", "planar_2r", "--pose", "worst", "--tolerances", "coarse", "--R", "0.5", "--n", "2000", "--quiet"],
        ["--pose", "--tolerances", "--R", "--n", "--seed", "--batch", "--confidence"],
    ),
    "worst-pose": (
        ["--model", "planar_2r", "--tolerances", "coarse", "--grid", "5"],
        ["--tolerances", "--R", "--grid", "--reference", "--criterion"],
    ),
    "map": (
        ["--model", "planar_2r", "--tolerances", "coarse", "--plane", "xy", "--n", "6", "--quiet"],
        ["--R", "--n", "--plane", "--offset", "--hand-axis", "--extent", "--reference", "--out", "--data"],
    ),
    "sweep": (
        ["--model", "planar_2r", "--pose", "elbow90", "--R", "0.5,0.3", "--p", "0.99", "--workers", "1", "--quiet"],
        [
            "--R",
            "--p",
            "--alpha",
            "--dist",
            "--criterion",
            "--solver",
            "--workers",
            "--out",
            "--grid",
            "--k",
            "--bounds",
        ],
    ),
}


@st.composite
def cli_argv(draw):
    cmd = draw(st.sampled_from(sorted(CLI_COMMANDS)))
    base, opts = CLI_COMMANDS[cmd]
    argv = [cmd, *base]
    for opt in draw(st.lists(st.sampled_from(opts), min_size=1, max_size=2, unique=True)):
        argv += [opt, draw(st.sampled_from(CLI_VALUES))]
    return argv


def run_cli(argv) -> None:
    """In-process ``tolsynth.cli.main(argv)``: an int exit status or argparse's SystemExit, and no
    traceback on stderr."""
    from tolsynth.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        try:
            rc = main(list(argv))
        except SystemExit as exc:
            rc = exc.code
    if "Traceback" in err.getvalue():
        raise Silent("traceback on stderr")
    if not isinstance(rc, int):
        raise BadNumbers(f"exit status {rc!r}")


def counts(results) -> dict:
    """Counter of outcomes, with every category present."""
    c = Counter(results)
    return {k: c.get(k, 0) for k in ("ok", "typed", "untyped", "unnamed", "hang", "warning", "bad_numbers", "silent")}


# the first-day surprises (tests/fuzz_surprises.py): URDF, search limits, options, unit strings
from fuzz_surprises import SURPRISE_CASES  # noqa: E402  (it imports this module's helpers)

API_CASES.update(SURPRISE_CASES)
