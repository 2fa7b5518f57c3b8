"""A design-review report of one synthesis: one HTML file (figures embedded), or Markdown + PNG.

:func:`report` solves (or takes a solved :class:`~tolsynth.SynthesisResult`), then gathers what a
reviewer needs beside the tolerances, each from the module that owns it:

- the specification and the model, with the model file's source and assumptions;
- the optimal tolerance table (units, bounds, active bounds, cost model or process; :mod:`tolsynth.io.tables`);
- the certificate: dual lower bound and gap (:class:`~tolsynth.SynthesisResult`), and over the whole
  joint space the certified exchange's or worst-pose search's proven bound when there is one
  (:mod:`tolsynth.io.report_certificate`);
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
import os
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tolsynth.checks import check_writable_path
from tolsynth.errors import InputError, MissingDependencyError, TolsynthError
from tolsynth.io.report_certificate import shortfall
from tolsynth.io.report_figures import _figures
from tolsynth.io.report_layout import PLOT_INSTALL, _layout
from tolsynth.io.report_render import _render_html, _render_markdown
from tolsynth.problem.specification import ALPHA_DEFAULT

__all__ = ["DesignReport", "report", "FORMATS"]

#: output formats: one self-contained HTML file, or Markdown with PNG files beside it
FORMATS = ("html", "md")


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
    validations : tuple of (str, ValidationResult)
        The Monte Carlo check at each pose of the specification, as ``(pose label, result)`` pairs
        in the specification's pose order (empty if ``mc_samples=0``).
    map : ProbabilityMap or None
    worst : WorstPose or None
    worst_judged : dict or None
        The worst pose judged in the design's own probability reading: ``quantity`` (its name),
        ``found`` and ``reference`` (the values at the pose found and the reference pose; <= 1
        meets the specification).
    skipped : dict
        Section -> why it is missing (switched off, or the reason it failed); shown in the report.
    settings : dict
        Monte Carlo samples, seed, confidence, map resolution and plane, worst-pose grid.
    elapsed_s : float
        Seconds spent gathering (solve included when :func:`report` solved).
    workspace : WorkspaceSynthesis or None
        The workspace design the report was made of (its certified exchange shown), if one was given.
    linear_exact : dict
        For a design in exact probabilities: pose label -> the linear error model's exact
        ``P(|w_j| <= R)`` along the three principal directions and its exact ``P(|dr| <= R)``,
        shown beside the Monte Carlo values (a Gaussian design shows its Gaussian reading there).
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
    workspace: Any = None
    worst_judged: dict | None = None
    linear_exact: dict = field(default_factory=dict)
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
            Default: from the suffix, ``.html`` / ``.htm`` HTML, ``.md`` / ``.markdown`` Markdown.
            Any other suffix (``.txt``, ``.pdf``, none) raises :class:`InputError`, as does a
            ``format`` that disagrees with the suffix (:func:`check_report_path`); for a PDF, print
            the HTML from a browser.
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
    written and matplotlib is installed; raises :class:`InputError` / :class:`MissingDependencyError`.
    A report is HTML (``.html``, ``.htm``) or Markdown (``.md``, ``.markdown``); any other suffix
    (``.pdf``, ``.docx``, none) is refused rather than written as HTML under a misleading name."""
    path = check_writable_path(path, field)
    suffix = os.path.splitext(path)[1].lower()
    implied = "md" if suffix in (".md", ".markdown") else "html" if suffix in (".html", ".htm") else None
    if format is not None and format not in FORMATS:
        raise InputError("format", f"{format!r}", " or ".join(repr(f) for f in FORMATS))
    if implied is None:
        raise InputError(
            field,
            f"{path!r}: a report cannot be written as {suffix or '(no suffix)'}",
            "a file name ending in .html or .htm (HTML, figures embedded; print it to PDF from a "
            "browser) or .md or .markdown (Markdown, figures as PNG beside it)",
        )
    if format is None:
        format = implied
    if implied != format:  # a Markdown file named .html (or the reverse) misleads
        raise InputError(
            field,
            f"{path!r} is named as {implied} but the format asked is {format}",
            f"a file ending in .{'md' if format == 'md' else 'html'} for format {format!r}",
        )
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise MissingDependencyError("matplotlib", "the report's figures", PLOT_INSTALL) from None
    return format


# ---------------------------------------------------------------------------------------------
# gathering
# ---------------------------------------------------------------------------------------------
def report(
    source,
    R: float | None = None,
    p: float | None = None,
    distribution=None,
    alpha=ALPHA_DEFAULT,
    *,
    mechanism=None,
    processes=None,
    mc_samples: int = 20_000,
    seed: int = 0,
    confidence: float = 0.95,
    map_n: int = 30,
    map_plane: str | None = None,
    map_hand_axis=(0.0, 0.0, 1.0),
    worst_grid: int | None = None,
    certify: bool = False,
    path=None,
    format: str | None = None,
    **kwargs,
) -> DesignReport:
    """A design-review report of an optimum: solve (or take a result) and gather its checks.

    Parameters
    ----------
    source : Mechanism, str, SynthesisResult, WorkspaceSynthesis or ProcessChoice
        A model (loaded, a bundled name or a file path), solved here with ``R``, ``p``,
        ``distribution``, ``alpha`` and ``kwargs`` as :func:`tolsynth.synthesize`; or a result
        already solved (then ``mechanism`` is the model it was solved on; default: the model
        recorded in the result, loaded again by its file or name).  A workspace design
        (:func:`tolsynth.synthesize_workspace`) is reported by its last solve, with its certified
        exchange's bound when it has one.
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
    certify : bool
        Also prove a bound of the largest principal sigma over the whole continuous joint space
        (:func:`tolsynth.worst_pose` with ``certify=True``), shown in the certificate section.
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
    from tolsynth.checks import check_count
    from tolsynth.kinematics.mechanism import as_mechanism
    from tolsynth.problem.result import SynthesisResult
    from tolsynth.synthesis.processes import ProcessChoice
    from tolsynth.synthesis.workspace_result import WorkspaceSynthesis

    t0 = time.perf_counter()
    workspace = None
    if isinstance(source, WorkspaceSynthesis):
        workspace, source = source, source.result
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
    # its sections read a probability (p, z, Monte Carlo against p, the probability map, the
    # Gaussian worst pose), which a worst-case design has none of: refused before any solve
    worst_case = kwargs.get("probability") == "worst_case" or (
        isinstance(source, (SynthesisResult, ProcessChoice))
        and ((getattr(source, "result", source).inputs or {}).get("probability") == "worst_case")
    )
    if worst_case:
        raise InputError(
            "source" if isinstance(source, (SynthesisResult, ProcessChoice)) else "probability",
            "a worst-case design: the report's sections read a probability p, which the worst case has none of",
            "a statistical design (probability 'exact' or 'gaussian'); for a worst-case design its summary(), "
            "tolsynth.contributions (the stack-up's terms) and synthesize_workspace (the worst case over the workspace)",
        )
    choice = None
    if isinstance(source, (SynthesisResult, ProcessChoice)):
        if R is not None or p is not None or kwargs or processes is not None:
            raise InputError(
                "source",
                "a solved result was given together with a specification (R, p, processes or synthesize arguments)",
                "either a result, or a model with R and p",
            )
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
            from tolsynth.synthesis.processes import synthesize_processes

            procs = None if processes is True else processes
            if procs is None and not mech.processes:
                raise InputError(
                    "processes",
                    f"the model {mech.name} declares no processes",
                    "a dict parameter -> list of Process, or a model file with processes",
                )
            choice = synthesize_processes(mech, R, p, procs, distribution, alpha=alpha, **kwargs)
            result = choice.result
        else:
            from tolsynth.synthesis.single import synthesize

            result = synthesize(mech, R, p, distribution, alpha, **kwargs)
    spec = result.spec
    skipped: dict[str, str] = {}
    settings = dict(
        mc_samples=mc_samples,
        seed=seed,
        confidence=confidence,
        map_n=map_n,
        map_plane=map_plane,
        map_hand_axis=None if map_hand_axis is None else [float(x) for x in map_hand_axis],
        worst_grid=worst_grid,
    )

    from tolsynth.analysis.contributions import contributions

    contrib = contributions(result)
    validations, linear_exact = [], {}
    if mc_samples == 0:
        skipped["montecarlo"] = "switched off (mc_samples = 0)"
    elif not result.feasible:
        skipped["montecarlo"] = "the solver did not converge; nothing to validate"
    else:
        from tolsynth.analysis.validation import validate

        for label, q in spec.poses.items():
            asked = result.verification.p if getattr(result, "verification", None) is not None else None
            v = validate(
                mech,
                result,
                p=asked,
                pose=np.asarray(q, dtype=float),
                n=mc_samples,
                seed=seed,
                confidence=confidence,
                progress=False,
                Phi=spec.Phi,
            )  # p: as asked, not the loop's target
            validations.append((label, v))
            if result.probability_kind == "exact":  # validate's analytic column is in the design's reading
                linear_exact[label] = (v.p_components_analytic, v.p_sphere_analytic)
    pmap = None
    if map_n == 0:
        skipped["map"] = "switched off (map_n = 0)"
    else:
        from tolsynth.analysis.workspace_map import probability_map

        try:
            pmap = probability_map(
                mech,
                result.tolerances,
                R=spec.R,
                distribution=spec.distribution,
                n=map_n,
                plane=map_plane,
                hand_axis=map_hand_axis,
                check_points=min(200, 2 * map_n),
                progress=False,
            )
            if not pmap.reachable.any():
                skipped["map"] = (
                    f"no point of the {pmap.plane} plane is reachable with the hand axis {settings['map_hand_axis']}"
                )
                pmap = None
        except TolsynthError as exc:  # a model the map cannot be drawn for: said in the report
            if isinstance(exc, InputError) and exc.field in ("plane", "hand_axis", "n"):
                raise
            skipped["map"] = f"not drawn: {exc}"
    worst = worst_judged = None
    if worst_grid == 0:
        skipped["worst"] = "switched off (worst_grid = 0)"
    else:
        from tolsynth.analysis.pose_search import worst_pose

        exact = result.probability_kind == "exact"
        sphere = spec.criterion == "sphere"
        try:
            # searched and judged in the reading the design was made for, as section 4's check
            worst = worst_pose(
                mech,
                result.tolerances,
                criterion=("probability" if not certify else "sigma")
                if sphere
                else ("components" if exact else "sigma"),
                R=spec.R,
                distribution=spec.distribution,
                grid=worst_grid,
                certify=bool(certify),
                probability="exact" if exact and not sphere else None,
                progress=False,
            )
            worst_judged = _judge_worst(mech, result, worst, exact, sphere)
        except TolsynthError as exc:
            worst, worst_judged = None, None
            skipped["worst"] = f"not searched: {exc}"
    procs = dict(choice.processes) if choice is not None else None
    rep = DesignReport(
        mechanism=mech,
        result=result,
        contributions=contrib,
        validations=tuple(validations),
        map=pmap,
        worst=worst,
        worst_judged=worst_judged,
        skipped=skipped,
        settings=settings,
        elapsed_s=time.perf_counter() - t0,
        processes=procs,
        process_choice=choice,
        workspace=workspace,
        linear_exact=linear_exact,
    )
    if path is not None:
        rep.write(path, format)
    return rep


def _judge_worst(mech, result, worst, exact: bool, sphere: bool) -> dict:
    """The worst pose's values in the reading the design was made for (<= 1 meets it): the exact
    per-direction ``(1 - P) / (1 - p)`` (the search's ``value`` is that P), ``sigma z / R`` for the
    Gaussian reading, or the sphere's ``(1 - P) / (1 - p)`` (Gaussian, or exact at the poses found)."""
    spec = result.spec
    if not sphere:
        if exact:
            return dict(
                quantity="exact (1-P)/(1-p) along the worst direction",
                found=shortfall(worst.value, spec.p),
                reference=None if worst.reference_value is None else shortfall(worst.reference_value, spec.p),
            )
        zr = spec.z / spec.R
        return dict(
            quantity="largest sigma z / R",
            found=worst.value * zr,
            reference=None if worst.reference_value is None else worst.reference_value * zr,
        )
    if not exact:
        P, Pref = worst.p_sphere, worst.reference_p_sphere
    else:
        from tolsynth.probability.exact_sphere import ball_probability

        def exact_ball(q):
            A = np.asarray(mech.sensitivity(q, check_limits=False))[:3]
            return ball_probability(A, result.x, spec.shapes, spec.R)

        P = exact_ball(worst.q)
        Pref = None if worst.reference_q is None else exact_ball(worst.reference_q)
    return dict(
        quantity=("exact " if exact else "") + "(1-P)/(1-p), P = P(|dr| <= R)",
        found=shortfall(P, spec.p),
        reference=None if Pref is None else shortfall(Pref, spec.p),
    )


def _mechanism_of(result):
    from tolsynth.kinematics.mechanism import load_model

    model = (getattr(result, "inputs", None) or {}).get("model") or {}
    ref = model.get("file") or model.get("name")
    if not ref:
        raise InputError("mechanism", "the result records no model", "the Mechanism the result was solved on")
    if (result.inputs or {}).get("joint_errors"):
        raise InputError(
            "mechanism",
            "the result has joint errors added in memory (with_joint_errors)",
            "the Mechanism the result was solved on, as mechanism=",
        )
    return load_model(ref)
