"""A design-review report of one synthesis: one HTML file (figures embedded), or Markdown + PNG.

:func:`report` solves (or takes a solved :class:`~tolsynth.SynthesisResult`), then gathers what a
reviewer needs beside the tolerances, each from the module that owns it:

- the specification and the model, with the model file's source and assumptions;
- the optimal tolerance table (units, bounds, active bounds, cost model or process; :mod:`tolsynth.tables`);
- the certificate: dual lower bound and gap (:class:`~tolsynth.SynthesisResult`);
- each parameter's share of the error (:func:`tolsynth.contributions`);
- a Monte Carlo check through the nonlinear kinematics with its confidence intervals
  (:func:`tolsynth.validate`);
- the map of ``P(|dr| <= R)`` over a workspace plane (:func:`tolsynth.probability_map`,
  :func:`tolsynth.plot_map`) and the pose of worst accuracy at the optimum
  (:func:`tolsynth.worst_pose`).

The text and numbers are laid out once (a short list of blocks) and written as HTML or
Markdown; every piece of text is HTML-escaped.  Figures need matplotlib (``pip install
"tolsynth[plot]"``).  The command line's ``tolsynth report`` is a thin wrapper.
"""

from __future__ import annotations

import base64
import datetime as _dt
import html
import io
import json
import math
import os
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import InputError, MissingDependencyError, TolsynthError

__all__ = ["DesignReport", "report", "FORMATS"]

#: output formats: one self-contained HTML file, or Markdown with PNG files beside it
FORMATS = ("html", "md")
PLOT_INSTALL = 'pip install "tolsynth[plot]"'

_CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;max-width:1100px;
margin:2em auto;padding:0 1.2em;color:#1d232b;line-height:1.45}
h1{font-size:1.6em;border-bottom:2px solid #2f5d8a;padding-bottom:.2em}
h2{font-size:1.25em;color:#2f5d8a;margin-top:1.8em;border-bottom:1px solid #d5dde6;padding-bottom:.15em}
h3{font-size:1.05em;margin-top:1.2em}
table{border-collapse:collapse;margin:.6em 0 1em;font-size:.92em}
th,td{border:1px solid #cfd8e3;padding:.25em .6em;text-align:left;vertical-align:top}
th{background:#eef3f8}
table:not(.kv) td{white-space:nowrap}
td.num{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
table.kv th{width:14em}
caption{caption-side:bottom;text-align:left;font-size:.85em;color:#55606e;padding-top:.3em}
figure{margin:1em 0}
figure img{max-width:100%;border:1px solid #d5dde6}
figcaption{font-size:.85em;color:#55606e}
.note{background:#fff7e0;border-left:4px solid #e0a800;padding:.4em .8em;margin:.8em 0}
.ok{background:#eaf6ec;border-left:4px solid #2e8b57;padding:.4em .8em;margin:.8em 0}
pre{background:#f5f7fa;border:1px solid #d5dde6;padding:.6em;overflow-x:auto;font-size:.82em}
footer{margin-top:2.5em;font-size:.82em;color:#55606e}
"""


# ---------------------------------------------------------------------------------------------
# the report
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DesignReport:
    """Everything a design review shows, gathered by :func:`report`; write it with :meth:`write`.

    Attributes
    ----------
    mechanism : Mechanism
    result : SynthesisResult
        The optimum reported.
    processes : dict or None
        Parameter -> chosen process name when the result comes from
        :func:`tolsynth.synthesize_processes` (with ``process_choice`` its search).
    contributions : Contributions
    validations : tuple of ValidationResult
        The Monte Carlo check at each pose of the specification (empty if ``mc_samples=0``).
    map : ProbabilityMap or None
    worst : WorstPose or None
    skipped : dict
        Section -> why it is missing (switched off, or the reason it failed); shown in the report.
    settings : dict
        Monte Carlo samples, seed, confidence, map resolution and plane, worst-pose grid.
    elapsed_s : float
        Seconds spent gathering (solve included when :func:`report` solved).
    """

    mechanism: Any
    result: Any
    contributions: Any
    validations: tuple
    map: Any
    worst: Any
    skipped: dict
    settings: dict
    elapsed_s: float
    processes: dict | None = None
    process_choice: Any = None
    created: str = field(default_factory=lambda: _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"))

    # ------------------------------------------------------------------ layout
    def blocks(self) -> list[tuple]:
        """The report as a list of blocks (heading, paragraph, table, list, figure, note, pre),
        written by :meth:`to_html` and :meth:`to_markdown`."""
        return _layout(self)

    def figures(self, dpi: int = 110) -> dict[str, bytes]:
        """The figures as PNG bytes, name -> data (needs matplotlib)."""
        return _figures(self, dpi)

    def to_html(self, dpi: int = 110) -> str:
        """One self-contained HTML document (figures embedded as base64 PNG)."""
        figs = self.figures(dpi)
        src = {k: "data:image/png;base64," + base64.b64encode(v).decode("ascii") for k, v in figs.items()}
        return _render_html(self.blocks(), src, title=f"Design review: {self.mechanism.name}")

    def to_markdown(self, figure_dir: str = "figures") -> tuple[str, dict[str, bytes]]:
        """Markdown text and its figures ``{relative path: PNG bytes}`` (paths under ``figure_dir``)."""
        figs = self.figures()
        files = {f"{figure_dir}/{k}.png": v for k, v in figs.items()}
        src = {k: f"{figure_dir}/{k}.png" for k in figs}
        return _render_markdown(self.blocks(), src), files

    def write(self, path, format: str | None = None) -> list[str]:
        """Write the report; returns the files written.

        Parameters
        ----------
        path : str or path
            The HTML or Markdown file.  With Markdown the figures go to ``<stem>_files/`` beside it.
        format : {"html", "md"}, optional
            Default: from the suffix (``.md`` / ``.markdown`` Markdown, anything else HTML).
        """
        path = os.fspath(path)
        fmt = check_report_path(path, format)
        if fmt == "html":
            text = self.to_html()
            with open(path, "w", encoding="utf-8") as fh:
                fh.write(text)
            return [path]
        stem = os.path.splitext(os.path.basename(path))[0]
        text, files = self.to_markdown(f"{stem}_files")
        folder = os.path.dirname(os.path.abspath(path))
        written = []
        for rel, data in files.items():
            target = os.path.join(folder, rel)
            os.makedirs(os.path.dirname(target), exist_ok=True)
            with open(target, "wb") as fh:
                fh.write(data)
            written.append(target)
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(text)
        return [path] + written


def check_report_path(path, format: str | None = None, field: str = "path") -> str:
    """The report's format (from ``format`` or the suffix) after checking that the file can be
    written and matplotlib is installed; raises :class:`InputError` / :class:`MissingDependencyError`."""
    path = os.fspath(path)
    suffix = os.path.splitext(path)[1].lower()
    implied = "md" if suffix in (".md", ".markdown") else "html" if suffix in (".html", ".htm") else None
    if format is None:
        format = implied or "html"
    if format not in FORMATS:
        raise InputError("format", f"{format!r}", " or ".join(repr(f) for f in FORMATS))
    if implied is not None and implied != format:  # a Markdown file named .html (or the reverse) misleads
        raise InputError(field, f"{path!r} is named as {implied} but the format asked is {format}",
                         f"a file ending in .{'md' if format == 'md' else 'html'} for format {format!r}")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise InputError(field, f"{path!r}: the folder {folder} does not exist", "a path in an existing folder")
    if os.path.isdir(path) or not os.access(folder, os.W_OK) or (os.path.exists(path) and not os.access(path, os.W_OK)):
        raise InputError(field, f"{path!r} cannot be written", "a writable file path")
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise MissingDependencyError("matplotlib", "the report's figures", PLOT_INSTALL) from None
    return format


# ---------------------------------------------------------------------------------------------
# gathering
# ---------------------------------------------------------------------------------------------
def _is_exact(res) -> bool:
    """Whether ``res`` was designed with ``probability="exact"``."""
    return (getattr(res, "inputs", None) or {}).get("probability") == "exact" or \
        any(b.kind.endswith("(exact)") for b in res.constraints)


def _asked_p(res, spec) -> str:
    """p as asked; after a closed loop (verify) the design's tighter target beside it."""
    ver = getattr(res, "verification", None)
    if ver is None or abs(ver.p - spec.p) <= 1e-15:
        return f"{spec.p:g}"
    return f"{ver.p:g} asked (the design's target after the closed loop: {spec.p:.6g})"


def report(
    source,
    R: float | None = None,
    p: float | None = None,
    distribution=None,
    alpha=0.7,
    *,
    mechanism=None,
    processes=None,
    mc_samples: int = 20_000,
    seed: int = 0,
    confidence: float = 0.95,
    map_n: int = 30,
    map_plane: str = "xz",
    map_hand_axis=(0.0, 0.0, 1.0),
    worst_grid: int | None = None,
    path=None,
    format: str | None = None,
    **kwargs,
) -> DesignReport:
    """A design-review report of an optimum: solve (or take a result) and gather its checks.

    Parameters
    ----------
    source : Mechanism, str, SynthesisResult or ProcessChoice
        A model (loaded, a bundled name or a file path), solved here with ``R``, ``p``,
        ``distribution``, ``alpha`` and ``kwargs`` as :func:`tolsynth.synthesize`; or a result
        already solved (then ``mechanism`` is the model it was solved on; default: the model
        recorded in the result, loaded again by its file or name).
    R, p, distribution, alpha
        As :func:`tolsynth.synthesize` (mm; probability per principal component).
    mechanism : Mechanism, optional
        With a result as ``source``.
    processes : dict or True, optional
        Choose a process per parameter by :func:`tolsynth.synthesize_processes` (True: the model
        file's processes); the table then shows the chosen process.
    mc_samples : int
        Monte Carlo samples at each pose of the specification (0: no Monte Carlo section).
        The default 20 000 gives intervals of about +-0.0015 near p = 0.99.
    seed, confidence
        Of the Monte Carlo run.
    map_n : int
        Points per axis of the workspace map (0: no map; >= 5 otherwise).
    map_plane, map_hand_axis
        As ``plane`` and ``hand_axis`` of :func:`tolsynth.probability_map`.
    worst_grid : int or None
        Grid points per joint of the worst-pose search (0: no search; None: its default).
    path : str or path, optional
        Write the report there (see :meth:`DesignReport.write`).
    format : {"html", "md"}, optional
        Default: from the suffix of ``path``.
    **kwargs
        Further arguments of :func:`tolsynth.synthesize` (solver, k, bounds, pose, poses, Phi,
        p_orientation, criterion, cost, locks, ...).

    Returns
    -------
    DesignReport

    Raises
    ------
    InputError, OutOfRangeError
        For bad inputs, naming the field (checked before the solve where possible).
    MissingDependencyError
        If matplotlib is missing and ``path`` is given.

    Examples
    --------
    >>> import tolsynth
    >>> rep = tolsynth.report("xu_zhang_1988", R=0.5, p=0.99, mc_samples=2000, map_n=0, worst_grid=0)
    >>> rep.result.success, len(rep.validations)
    (True, 1)
    """
    from .checks import check_count
    from .mechanism import as_mechanism
    from .process import ProcessChoice
    from .result import SynthesisResult

    t0 = time.perf_counter()
    if path is not None:
        check_report_path(path, format)
    mc_samples = check_count(mc_samples, "mc_samples", 0)
    map_n = check_count(map_n, "map_n", 0, 2000)
    if 0 < map_n < 5:
        raise InputError("map_n", f"got {map_n}", "0 (no map) or an integer from 5 to 2000")
    if worst_grid is not None:
        worst_grid = check_count(worst_grid, "worst_grid", 0)
        if worst_grid == 1:
            raise InputError("worst_grid", "got 1", "0 (no search), None (the search's default) or an integer >= 2")
    if not (isinstance(confidence, (int, float)) and 0 < confidence < 1):
        raise InputError("confidence", f"got {confidence!r}", "0 < confidence < 1")
    choice = None
    if isinstance(source, (SynthesisResult, ProcessChoice)):
        if R is not None or p is not None or kwargs or processes is not None:
            raise InputError("source", "a solved result was given together with a specification "
                                       "(R, p, processes or synthesize arguments)",
                             "either a result, or a model with R and p")
        if isinstance(source, ProcessChoice):
            choice, result = source, source.result
        else:
            result = source
        mech = mechanism if mechanism is not None else _mechanism_of(result)
    else:
        if mechanism is not None:
            raise InputError("mechanism", "given with a model as source", "a result as source, or no mechanism")
        mech = as_mechanism(source, "source")
        if R is None or p is None:
            raise InputError("R" if R is None else "p", "missing", "R (mm) and p (0 < p < 1) to solve for")
        if processes is not None and processes is not False:
            from .process import synthesize_processes

            procs = None if processes is True else processes
            if procs is None and not mech.processes:
                raise InputError("processes", f"the model {mech.name} declares no processes",
                                 "a dict parameter -> list of Process, or a model file with processes")
            choice = synthesize_processes(mech, R, p, procs, distribution, alpha=alpha, **kwargs)
            result = choice.result
        else:
            from .synthesis import synthesize

            result = synthesize(mech, R, p, distribution, alpha, **kwargs)
    spec = result.spec
    skipped: dict[str, str] = {}
    settings = dict(mc_samples=mc_samples, seed=seed, confidence=confidence, map_n=map_n, map_plane=map_plane,
                    map_hand_axis=None if map_hand_axis is None else [float(x) for x in map_hand_axis],
                    worst_grid=worst_grid)

    from .contributions import contributions

    contrib = contributions(result)
    validations = []
    if mc_samples == 0:
        skipped["montecarlo"] = "switched off (mc_samples = 0)"
    elif not result.success:
        skipped["montecarlo"] = "the solver did not converge; nothing to validate"
    else:
        from .validation import validate

        for label, q in spec.poses.items():
            asked = result.verification.p if getattr(result, "verification", None) is not None else None
            v = validate(mech, result, p=asked, pose=np.asarray(q, dtype=float), n=mc_samples, seed=seed,
                         confidence=confidence, progress=False, Phi=spec.Phi)  # p: as asked, not the loop's target
            validations.append((label, v))
    pmap = None
    if map_n == 0:
        skipped["map"] = "switched off (map_n = 0)"
    else:
        from .workspace_map import probability_map

        try:
            pmap = probability_map(mech, result.tolerances, R=spec.R, distribution=spec.distribution, n=map_n,
                                   plane=map_plane, hand_axis=map_hand_axis, check_points=min(200, 2 * map_n),
                                   progress=False)
            if not pmap.reachable.any():
                skipped["map"] = (f"no point of the {map_plane} plane is reachable with the hand axis "
                                  f"{settings['map_hand_axis']}")
                pmap = None
        except TolsynthError as exc:  # a model the map cannot be drawn for: said in the report
            if isinstance(exc, InputError) and exc.field in ("plane", "hand_axis", "n"):
                raise
            skipped["map"] = f"not drawn: {exc}"
    worst = None
    if worst_grid == 0:
        skipped["worst"] = "switched off (worst_grid = 0)"
    else:
        from .pose_search import worst_pose

        try:
            worst = worst_pose(mech, result.tolerances, criterion="sigma", R=spec.R, distribution=spec.distribution,
                               grid=worst_grid)
        except TolsynthError as exc:
            skipped["worst"] = f"not searched: {exc}"
    procs = dict(choice.processes) if choice is not None else None
    rep = DesignReport(mechanism=mech, result=result, contributions=contrib, validations=tuple(validations),
                       map=pmap, worst=worst, skipped=skipped, settings=settings,
                       elapsed_s=time.perf_counter() - t0, processes=procs, process_choice=choice)
    if path is not None:
        rep.write(path, format)
    return rep


def _mechanism_of(result):
    from .mechanism import load_model

    model = (getattr(result, "inputs", None) or {}).get("model") or {}
    ref = model.get("file") or model.get("name")
    if not ref:
        raise InputError("mechanism", "the result records no model", "the Mechanism the result was solved on")
    if (result.inputs or {}).get("joint_errors"):
        raise InputError("mechanism", "the result has joint errors added in memory (with_joint_errors)",
                         "the Mechanism the result was solved on, as mechanism=")
    return load_model(ref)


# ---------------------------------------------------------------------------------------------
# layout: one list of blocks for both formats
# ---------------------------------------------------------------------------------------------
def _deg(q) -> str:
    return _vec(np.degrees(np.asarray(q, dtype=float)))


def _num(x, fmt: str) -> str:
    s = format(float(x), fmt)
    return format(0.0, fmt) if float(s) == 0 else s  # no "-0.000"


def _vec(v, fmt=".3f") -> str:
    return "(" + ", ".join(_num(x, fmt) for x in np.asarray(v, dtype=float).ravel()) + ")"


def _layout(rep: DesignReport) -> list[tuple]:
    from . import __version__
    from .distributions import describe, label

    mech, res, spec = rep.mechanism, rep.result, rep.result.spec
    B: list[tuple] = []
    B.append(("h", 1, f"Design review: {mech.title}"))
    B.append(("p", f"Optimal manufacturing tolerances for the model {mech.name}, computed by tolsynth "
                   f"{__version__} on {rep.created} in {rep.elapsed_s:.1f} s. Units: lengths mm, angles rad "
                   "unless stated; each tolerance in its parameter's own unit; cost in the model's cost units."))
    if not res.success:
        B.append(("note", f"The solver did not converge ({res.status}: {res.message}). The numbers below are its "
                          "last iterate, not an optimum."))

    # 1. specification
    B.append(("h", 2, "1. Specification"))
    alpha = np.asarray(spec.alpha, dtype=float)
    alpha_txt = f"{alpha[0]:g} (every parameter)" if np.all(alpha == alpha[0]) else \
        ", ".join(f"{n} {a:g}" for n, a in zip(spec.names, alpha))
    kv = [("model", f"{mech.name}: {mech.title}"),
          ("position accuracy R", f"{spec.R:g} mm"),
          ("probability p", _asked_p(res, spec) + (" per principal component (the paper's Eq. 20)"
                                                   if spec.criterion == "components" else " of the sphere P(|dr| <= R)")),
          ("criterion", spec.criterion),
          ("probability model", "exact (the linear error model's own probabilities, no Gaussian reading)"
           if _is_exact(res) else "gaussian (the paper's: each principal component read as normal)"),
          ("z(p)", f"{spec.z:.6g}"),
          ("error distribution", f"{label(spec.distribution)}: {describe(spec.distribution)}"),
          ("cost exponent alpha", alpha_txt)]
    if spec.Phi is not None:
        kv.append(("orientation accuracy Phi", f"{spec.Phi:g} rad, probability {spec.p_orientation:g}"))
    for lbl, q in spec.poses.items():
        kv.append((f"pose '{lbl}'", f"joints {_deg(q)} deg ({', '.join(mech.joint_names)})"))
    kv.append(("solver", f"{res.solver}: {res.status} ({res.message}); {res.iterations} iterations, "
                         f"{res.wall_time * 1e3:.1f} ms"))
    locks = (res.inputs or {}).get("locks")
    if locks:
        kv.append(("fixed tolerances", ", ".join(f"{k} = {v:g}" for k, v in locks.items())))
    B.append(("kv", kv))

    # 2. model
    B.append(("h", 2, "2. Model"))
    path = getattr(mech.spec, "path", None)
    B.append(("kv", [("name", mech.name), ("title", mech.title), ("file", str(path) if path else "(in memory)"),
                     ("joints", ", ".join(mech.joint_names)),
                     ("error parameters", f"{len(mech.error_parameters)}: " + ", ".join(mech.error_parameters))]))
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
    B.append(("p", f"Total cost {res.cost:.8g} (cost units). Bounds and tolerances in each parameter's unit; "
                   "'active' marks a tolerance held at a bound, 'fixed' one locked by the user or the model."))
    fixed = {n for n, lo, hi in zip(spec.names, spec.lower, spec.upper) if lo == hi}
    models = spec.costs.models
    rows = []
    for i, (name, eps) in enumerate(res.tolerances.items()):
        act = "fixed" if name in fixed else res.bounds_active.get(name, "")
        how = f"{rep.processes[name]} ({models[i].describe()})" if rep.processes and name in rep.processes \
            else models[i].describe()
        rows.append([name, f"{eps:.6g}", res.units[name], f"{spec.lower[i]:.6g}", f"{spec.upper[i]:.6g}", act, how,
                     f"{float(models[i].cost(eps)):.6g}", f"{res.bound_multipliers.get(name, 0.0):.4g}"])
    B.append(("table", ["parameter", "tolerance +-", "unit", "lower bound", "upper bound", "active bound",
                        "process / cost model", "cost", "bound multiplier"], rows,
              [False, True, False, True, True, False, False, True, True], None))
    if rep.process_choice is not None:
        pc = rep.process_choice
        B.append(("p", f"Processes chosen by branch and bound over {pc.combinations} combinations ({pc.nodes} solves): "
                       f"lower bound over every choice {pc.lower_bound:.8g}, "
                       + ("proven optimal." if pc.proven else "NOT proven optimal (node limit).")))

    # 4. certificate
    B.append(("h", 2, "4. Certificate"))
    rel = res.gap / abs(res.cost) if res.cost else float("nan")
    B.append(("kv", [("cost", f"{res.cost:.8g}"), ("dual lower bound", f"{res.lower_bound:.8g}"),
                     ("gap (cost - bound)", f"{res.gap:.2e}"), ("relative gap", f"{rel:.2e}"),
                     ("largest (1-P)/(1-p)" if _is_exact(res) else "largest sigma z / limit",
                      f"{res.max_constraint:.6f} (<= 1 meets the specification)")]))
    if _is_exact(res):
        B.append(("note", "Exact probabilities: the problem is not known to be convex, so there is no certificate of "
                          "global optimality; the dual lower bound is the loose peak-density bound. Every pose's exact "
                          "probability at the optimum was checked independently (see the solver's message)."))
    elif spec.criterion == "sphere":
        B.append(("p", "The sphere criterion is not known to be convex: the bound is the optimum of the per-component "
                       "relaxation, valid but not tight."))
    elif not spec.convex:
        B.append(("note", "A cost model is not convex in eps^2 on its range: the bound is valid but certifies no "
                          "global optimum."))
    elif res.success and rel <= 1e-4:
        B.append(("ok", f"The problem is convex and the gap is {rel:.1e} of the cost: no tolerances inside the "
                        "bounds meet the specification at a lower cost (to that margin)."))
    crow = []
    for b in res.constraints:
        what = "(1-P)/(1-p)" if b.kind.startswith("sphere") or _is_exact(res) else "sigma z / limit"
        for j, val in enumerate(b.values):
            crow.append([b.label, f"{j + 1}", what, f"{val:.6f}", "yes" if b.active[j] else "", f"{b.multipliers[j]:.4g}"])
    B.append(("table", ["constraint block", "#", "quantity", "value", "active", "multiplier"], crow,
              [False, True, False, True, False, True], "values <= 1 meet the specification; multipliers in cost units."))

    # 5. contributions
    c = rep.contributions
    B.append(("h", 2, "5. Contributions"))
    B.append(("p", "Each parameter's share of each principal variance of the hand position (exact: the shares add "
                   "to 100 %), of the total variance tr V and, with R, of the sphere probability's loss 1 - P(|dr| <= R) "
                   "(normalised elasticities). Where two principal sigma coincide (two active constraints) the split "
                   "between them is arbitrary; their sum is not."))
    for b, pose in enumerate(c.poses):
        head = f"pose '{pose}': principal sigma {_vec(c.sigma[b], '.4g')} mm"
        if c.P_sphere is not None:
            head += f", P(|dr| <= {c.R:g} mm) = {c.P_sphere[b]:.6f}"
        B.append(("h", 3, head))
        rows = []
        for i in np.argsort(-c.shares[b, :, 0], kind="stable"):
            row = [c.names[i], f"{c.tolerances[i]:.4g} {c.units[i]}"] + [f"{100 * v:.2f}" for v in c.shares[b, i]] \
                + [f"{100 * c.total_share[b, i]:.2f}"]
            if c.sphere_share is not None:
                row.append(f"{100 * c.sphere_share[b, i]:.2f}")
            rows.append(row)
        head_cols = ["parameter", "tolerance", "sigma1^2 %", "sigma2^2 %", "sigma3^2 %", "tr V %"]
        if c.sphere_share is not None:
            head_cols.append("1 - P %")
        B.append(("table", head_cols, rows, [False, True] + [True] * (len(head_cols) - 2), None))
        B.append(("fig", f"contributions_{b}", f"contributions at pose {pose}",
                  f"Shares at pose '{pose}', largest principal variance first."))

    # 6. Monte Carlo
    B.append(("h", 2, "6. Monte Carlo validation"))
    if "montecarlo" in rep.skipped:
        B.append(("note", "Monte Carlo: " + rep.skipped["montecarlo"]))
    for lbl, v in rep.validations:
        mc = v.montecarlo
        pct = int(round(100 * mc.confidence))
        B.append(("h", 3, f"pose '{lbl}': hand {_vec(mc.position)} mm"))
        B.append(("p", f"{v.n} samples of the errors ({label(v.distribution)}, seed {v.seed}) through the nonlinear "
                       f"kinematics; {pct} % {mc.ci_method} intervals; {mc.n_loop_failures} loop failures "
                       "(counted as outside). The components w_j are along the analytic principal directions."))
        rows = []
        sphere = spec.criterion == "sphere"  # then the sphere is the specification, the components are not
        for j in range(3):
            lo, hi = v.p_components_ci[j]
            rows.append([f"P(|w{j + 1}| <= R)", "-" if sphere else f"{v.p:g}", f"{v.p_components[j]:.5f}",
                         f"[{lo:.5f}, {hi:.5f}]", f"{v.p_components_analytic[j]:.5f}",
                         "-" if sphere else _verdict(v.p_components[j], hi, v.p)])
        lo, hi = v.p_sphere_ci
        rows.append(["P(|dr| <= R)", f"{v.p:g}" if sphere else "-", f"{v.p_sphere:.5f}", f"[{lo:.5f}, {hi:.5f}]",
                     f"{v.p_sphere_analytic:.5f}", _verdict(v.p_sphere, hi, v.p) if sphere else
                     ("reaches p" if v.sphere_met else "below p (the sphere is stricter than Eq. 20)")])
        if mc.Phi is not None:
            po = spec.p_orientation
            for j in range(3):
                lo, hi = mc.p_orientation_components_ci[j]
                rows.append([f"P(|phi{j + 1}| <= Phi)", f"{po:g}", f"{mc.p_orientation_components[j]:.5f}",
                             f"[{lo:.5f}, {hi:.5f}]", f"{mc.p_orientation_components_analytic[j]:.5f}",
                             _verdict(mc.p_orientation_components[j], hi, po)])
            lo, hi = mc.p_cone_ci
            rows.append(["P(z axis tilt <= Phi)", "-", f"{mc.p_cone:.5f}", f"[{lo:.5f}, {hi:.5f}]",
                         f"{mc.p_cone_analytic:.5f}", "-"])
        B.append(("table", ["probability", "asked", "Monte Carlo", f"{pct} % interval", "linear model", "verdict"], rows,
                  [False, True, True, True, True, False],
                  f"R = {v.R:g} mm" + (f"; Phi = {mc.Phi:g} rad, phi_j along the analytic orientation principal directions, the tilt "
                                         "is the angle between the actual and nominal hand z axes"
                                       if mc.Phi is not None else "") + "."))
        srows = [[f"w{j + 1}", _vec(mc.principal_directions[:, j]), f"{mc.principal_std[j]:.5f}",
                  f"{mc.principal_std_analytic[j]:.5f}", f"{mc.kurtosis[j]:+.3f}"] for j in range(3)]
        B.append(("table", ["component", "direction (base frame)", "sigma sampled, mm", "sigma linear, mm",
                            "excess kurtosis"], srows, [False, False, True, True, True],
                  f"Excess kurtosis 0 for a Gaussian (standard error {mc.kurtosis_se:.3f})."))

    ver = getattr(res, "verification", None)
    if ver is not None:  # synthesize(..., verify=...): the closed loop's own Monte Carlo
        lo, hi = ver.ci
        B.append(("h", 3, "Closed loop (verify)"))
        B.append(("ok" if ver.verified else "note",
                  f"Nonlinear Monte Carlo at the design, n = {ver.n} per pose, {round(100 * ver.confidence)} % Wilson "
                  f"interval: achieved {ver.achieved:.5f} [{lo:.5f}, {hi:.5f}] against p = {ver.p:g} asked; "
                  + ("verified (the lower end reaches p)" if ver.verified else "NOT verified (the lower end is below p)")
                  + f"; design target p = {ver.p_target:.6g} after {len(ver.rounds)} round(s)."))
        B.append(("table", ["round", "target p", "cost", "Monte Carlo P", "interval", "pose"],
                  [[f"{r['round']}", f"{r['p_target']:.6g}", f"{r['cost']:.6g}", f"{r['estimate']:.5f}",
                    f"[{r['ci'][0]:.5f}, {r['ci'][1]:.5f}]", str(r["pose"])] for r in ver.rounds],
                  [True, True, True, True, False, False], None))

    # 7. workspace
    B.append(("h", 2, "7. Workspace"))
    if rep.map is not None:
        pm = rep.map
        wu, wv, wp = pm.worst
        B.append(("p", f"P(|dr| <= {pm.R:g} mm) of the linear, Gaussian model at the optimal tolerances over the "
                       f"reachable part of the {pm.plane} plane ({len(pm.u)} x {len(pm.v)} points, "
                       f"{int(pm.reachable.sum())} reachable). Lowest on the map: {wp:.4f} at ({wu:.1f}, {wv:.1f}) mm."
                       + (f" At the configuration '{pm.reference}': {pm.reference_P:.4f}." if pm.reference_P is not None
                          else "")))
        B.append(("fig", "map", "workspace map", "The map (tolsynth.plot_map); blank = not reachable."))
    else:
        B.append(("note", "Workspace map: " + rep.skipped.get("map", "not drawn")))
    if rep.worst is not None:
        w = rep.worst
        zr = spec.z / spec.R
        B.append(("h", 3, "Worst pose"))
        B.append(("p", f"Search over the joint space inside every limit and constraint ({w.method}) for the largest "
                       "principal sigma at the optimal tolerances."))
        rows = [["joints, deg", _deg(w.q), _deg(w.reference_q) if w.reference_q is not None else "-"],
                ["hand, mm", _vec(w.position), _vec(w.reference_position) if w.reference_position is not None else "-"],
                ["principal sigma, mm", _vec(w.principal_std, ".4f"),
                 _vec(w.reference_principal_std, ".4f") if w.reference_principal_std is not None else "-"],
                ["largest sigma z / R", f"{w.value * zr:.4f}",
                 f"{w.reference_value * zr:.4f}" if w.reference_value is not None else "-"]]
        if w.p_sphere is not None:
            rows.append(["P(|dr| <= R)", f"{w.p_sphere:.4f}",
                         f"{w.reference_p_sphere:.4f}" if w.reference_p_sphere is not None else "-"])
        B.append(("table", ["", "worst pose found", f"reference '{w.reference}'"], rows, [False, True, True],
                  "Held: " + (", ".join(f"{k} = {math.degrees(v):g} deg" for k, v in w.held_joints.items()) or "none")
                  + "; active: " + (", ".join(w.active) or "none (interior)") + "."))
        if w.value * zr > 1 + 1e-6:
            B.append(("note", f"At the worst pose found the largest sigma z / R is {w.value * zr:.4f} > 1: the "
                              "specification is met at the specification's pose(s) but not everywhere in the workspace. "
                              "tolsynth solve --everywhere (synthesize_workspace) imposes it at every reachable pose."))
        else:
            B.append(("ok", f"At the worst pose found the largest sigma z / R is {w.value * zr:.4f} <= 1: the "
                            "specification holds over the searched workspace."))
    else:
        B.append(("note", "Worst pose: " + rep.skipped.get("worst", "not searched")))

    # inputs
    from .tables import _synthesis_inputs, jsonable

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


def _figures(rep: DesignReport, dpi: int) -> dict[str, bytes]:
    try:
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt
    except ImportError:
        raise MissingDependencyError("matplotlib", "the report's figures", PLOT_INSTALL) from None

    out = {}

    def png(fig) -> bytes:
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
        plt.close(fig)
        return buf.getvalue()

    c = rep.contributions
    for b in range(len(c.poses)):
        fig, ax = plt.subplots(figsize=(min(11.0, max(6.0, 0.75 * len(c.names))), 3.4))
        c.plot(pose=b, ax=ax)
        ax.legend(fontsize="small", ncol=4, loc="upper center", bbox_to_anchor=(0.5, -0.12), frameon=False)
        if len(c.names) > 12:
            ax.tick_params(axis="x", labelrotation=90)
        out[f"contributions_{b}"] = png(fig)
    if rep.map is not None:
        from .plot import plot_map

        from dataclasses import replace

        out["map"] = png(plot_map(replace(rep.map, tolerance_label="optimal")))
    return out


# ---------------------------------------------------------------------------------------------
# writers
# ---------------------------------------------------------------------------------------------
def _render_html(blocks: list[tuple], src: dict[str, str], title: str) -> str:
    e = html.escape
    out = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
           '<meta name="viewport" content="width=device-width, initial-scale=1">',
           f"<title>{e(title)}</title>", f"<style>{_CSS}</style>", "</head>", "<body>"]
    for blk in blocks:
        kind = blk[0]
        if kind == "h":
            out.append(f"<h{blk[1]}>{e(blk[2])}</h{blk[1]}>")
        elif kind == "p":
            out.append(f"<p>{e(blk[1])}</p>")
        elif kind in ("note", "ok"):
            out.append(f'<div class="{kind}">{e(blk[1])}</div>')
        elif kind == "ul":
            out.append("<ul>" + "".join(f"<li>{e(x)}</li>" for x in blk[1]) + "</ul>")
        elif kind == "kv":
            out.append('<table class="kv">' + "".join(f"<tr><th>{e(k)}</th><td>{e(v)}</td></tr>" for k, v in blk[1])
                       + "</table>")
        elif kind == "table":
            _, head, rows, numeric, caption = blk
            t = ["<table>"]
            if caption:
                t.append(f"<caption>{e(caption)}</caption>")
            t.append("<thead><tr>" + "".join(f"<th>{e(h)}</th>" for h in head) + "</tr></thead><tbody>")
            for row in rows:
                t.append("<tr>" + "".join(f'<td class="num">{e(x)}</td>' if numeric[k] else f"<td>{e(x)}</td>"
                                          for k, x in enumerate(row)) + "</tr>")
            t.append("</tbody></table>")
            out.append("".join(t))
        elif kind == "fig":
            _, key, alt, caption = blk
            if key in src:
                out.append(f'<figure><img src="{e(src[key])}" alt="{e(alt)}"><figcaption>{e(caption)}</figcaption></figure>')
        elif kind == "pre":
            out.append(f"<details><summary>as JSON</summary><pre>{e(blk[1])}</pre></details>")
    out.append("<footer>Generated by tolsynth (tolsynth.report). Every number is the library's own; "
               "nothing in this file was edited by hand.</footer>")
    out += ["</body>", "</html>", ""]
    return "\n".join(out)


def _md(text: str) -> str:
    """Markdown-safe inline text: HTML escaped, table pipes and emphasis markers escaped."""
    t = html.escape(str(text), quote=False)
    for ch in "\\`*_[]|#":
        t = t.replace(ch, "\\" + ch)
    return t


def _render_markdown(blocks: list[tuple], src: dict[str, str]) -> str:
    out = []
    for blk in blocks:
        kind = blk[0]
        if kind == "h":
            out.append("#" * blk[1] + " " + _md(blk[2]))
        elif kind == "p":
            out.append(_md(blk[1]))
        elif kind == "note":
            out.append("> **Note.** " + _md(blk[1]))
        elif kind == "ok":
            out.append("> " + _md(blk[1]))
        elif kind == "ul":
            out.append("\n".join("- " + _md(x) for x in blk[1]))
        elif kind == "kv":
            out.append("| | |\n|---|---|\n" + "\n".join(f"| {_md(k)} | {_md(v)} |" for k, v in blk[1]))
        elif kind == "table":
            _, head, rows, numeric, caption = blk
            lines = ["| " + " | ".join(_md(h) or " " for h in head) + " |",
                     "|" + "|".join("---:" if n else "---" for n in numeric) + "|"]
            lines += ["| " + " | ".join(_md(x) for x in row) + " |" for row in rows]
            if caption:
                lines.append("\n" + _md(caption))
            out.append("\n".join(lines))
        elif kind == "fig":
            _, key, alt, caption = blk
            if key in src:
                out.append(f"![{_md(alt)}]({src[key]})\n\n{_md(caption)}")
        elif kind == "pre":
            out.append("```json\n" + blk[1] + "\n```")
    return "\n\n".join(out) + "\n"
