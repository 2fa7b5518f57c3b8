"""The :class:`Mechanism`: a validated model file plus its CasADi graphs and error analysis.

>>> import tolsynth
>>> m = tolsynth.load_model("xu_zhang_1988")
>>> m.fk("worst")[:3, 3].round(3)
array([ 925.,    0., 1225.])
>>> m.error_parameters[:3]
('h2', 'h3', 'h4')
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from functools import cached_property
from typing import Mapping, Sequence, Union

import numpy as np

from tolsynth.checks import HUGE, check_half_angle, check_mapping, check_real, check_vector
from tolsynth.errors import InputError, LoopClosureError, OutOfRangeError, UnknownNameError
from tolsynth.kinematics.graphs import Graphs, build_graphs
from tolsynth.kinematics.parallel import ParallelGraphs, build_parallel_graphs
from tolsynth.model.dh import dh_spec
from tolsynth.model.parallel import is_parallel
from tolsynth.model.reader import model_path, read_model_file
from tolsynth.model.spec import ErrorParameter, MechanismSpec
from tolsynth.model.urdf import urdf_spec
from tolsynth.probability.stats import (
    check_positive,
    covariance,
    p_ball,
    p_components,
    p_cone,
    principal,
    principal_cubic_function,
    variance_divisor,
)

__all__ = ["Mechanism", "load_model", "load_urdf", "Analysis"]

JointInput = Union[str, Sequence[float], np.ndarray]
ToleranceInput = Union[str, Mapping[str, float], Sequence[float], np.ndarray]
#: rad; tolerance of the (inclusive) joint-limit checks against rounding, far below any physical angle
from tolsynth.model.fields import LIMIT_SLACK  # noqa: E402  (one copy: the reader checks a file's own poses with it)


def load_model(name_or_path: str | os.PathLike) -> "Mechanism":
    """Load a bundled model by name (``"xu_zhang_1988"``, ``"puma560"``, ``"planar_2r"``) or a
    model file by path.

    Raises
    ------
    UnknownNameError
        No such bundled model or file.
    ModelFileError
        The file is malformed (missing field, unknown unit, loop that cannot close, ...).
    """
    path = model_path(name_or_path)
    return Mechanism(read_model_file(path))


def load_urdf(path, base_link: str, tip_link: str, **kwargs) -> "Mechanism":
    return Mechanism(urdf_spec(path, base_link, tip_link, **kwargs))


# one copy of the arguments' documentation: the model builder's
load_urdf.__doc__ = "A :class:`Mechanism` from the " + urdf_spec.__doc__.split(" ", 4)[4].replace(
    ", for :func:`tolsynth.load_urdf`", "", 1
)


def as_mechanism(mechanism, field: str = "mechanism") -> "Mechanism":
    """``mechanism`` itself if it is a :class:`Mechanism`, else :func:`load_model` of a bundled
    model name or a model file path; anything else is an :class:`InputError` naming ``field``."""
    if isinstance(mechanism, Mechanism):
        return mechanism
    if isinstance(mechanism, (str, os.PathLike)):
        return load_model(mechanism)
    raise InputError(field, f"got {type(mechanism).__name__}", "a Mechanism, a bundled model name or a model file path")


#: sensitivities remembered per Mechanism (poses x error vectors)
SENSITIVITY_CACHE = 4096


@dataclass(frozen=True)
class Analysis:
    """Linearised, Gaussian error analysis of one pose for one set of tolerances.

    Units: ``position`` mm; ``sensitivity`` mm (rows 0-2) and rad (rows 3-5) per tolerance unit;
    ``covariance`` mm^2; ``principal_std`` mm (descending, NumPy's symmetric eigensolver) with
    ``principal_directions`` as columns, and ``principal_std_cubic`` the same by the paper's
    closed-form cubic (a CasADi expression; the two agree to ~1e-15 relative); ``orientation_covariance`` rad^2; ``R`` mm.
    """

    model: str
    q: np.ndarray
    distribution: str
    tolerances: dict[str, float]
    position: np.ndarray
    sensitivity: np.ndarray
    covariance: np.ndarray
    principal_std: np.ndarray
    principal_directions: np.ndarray
    principal_std_cubic: np.ndarray
    orientation_covariance: np.ndarray
    orientation_principal_std: np.ndarray
    R: float | None = None
    p_components: np.ndarray | None = None
    p_sphere: float | None = None
    Phi: float | None = None
    p_orientation_components: np.ndarray | None = None
    p_cone: float | None = None

    def to_dict(self) -> dict:
        """Plain dict (arrays as lists) for JSON."""
        out = {}
        for key, value in self.__dict__.items():
            out[key] = value.tolist() if isinstance(value, np.ndarray) else value
        return out


class Mechanism:
    """A mechanism declaration with its CasADi graphs (built once, on first use).

    Attributes
    ----------
    name, title, source : str
    assumptions : tuple of str
    error_parameters : tuple of str
        Error-parameter names in the model's order (the design variables).
    parameters : tuple of ErrorParameter
        Their full declarations (unit, cost factor ``k``, default bounds, symbols perturbed).
    configurations : dict
        Named configurations, name -> joint values in rad (order of ``joint_names``).
    joint_names : tuple of str
    """

    def __init__(self, spec: MechanismSpec):
        self.spec = spec
        self.name = spec.name
        self.title = spec.title
        self.source = spec.source
        self.assumptions = spec.assumptions
        self.parameters: tuple[ErrorParameter, ...] = spec.error_parameters
        self.error_parameters: tuple[str, ...] = tuple(p.name for p in spec.error_parameters)
        self.joint_names: tuple[str, ...] = spec.joint_names
        self.configurations: dict[str, np.ndarray] = {
            k: np.array(c.q, dtype=float) for k, c in spec.configurations.items()
        }
        self.tolerance_sets = spec.tolerance_sets
        self._index = {p.name: i for i, p in enumerate(spec.error_parameters)}
        self._index.update({p.alias: i for i, p in enumerate(spec.error_parameters) if p.alias})
        self._check_loops_close()

    @classmethod
    def from_dh(cls, links, convention: str = "standard", **kwargs) -> "Mechanism":
        """A mechanism from a D-H table given in Python, without a model file: see
        :func:`tolsynth.model.dh.from_dh` for the arguments (links, convention, units, base/tool,
        error-parameter selection with k and bounds, named configurations)."""
        return cls(dh_spec(links, convention, **kwargs))

    def __repr__(self) -> str:
        return (
            f"<Mechanism {self.name!r}: {len(self.joint_names)} joints, {len(self.error_parameters)} error parameters>"
        )

    # ------------------------------------------------------------------ graphs
    def __getstate__(self):
        # pickled for worker processes (tolsynth.sweep): without the remembered sensitivities
        state = self.__dict__.copy()
        state.pop("_sensitivity_cache", None)
        state.pop("_per_parameter", None)
        return state

    @cached_property
    def graphs(self) -> Graphs | ParallelGraphs:
        """The named CasADi Functions ``fk``, ``sensitivity``, ``closure``, ``position`` (a parallel
        robot's also ``pose``, ``ik``, ``jacobian``: :mod:`tolsynth.kinematics.parallel`)."""
        return build_parallel_graphs(self.spec) if is_parallel(self.spec) else build_graphs(self.spec)

    @property
    def n(self) -> int:
        """Number of error parameters."""
        return len(self.error_parameters)

    @cached_property
    def _per_parameter(self) -> dict:
        """What the properties below read, derived once from the (frozen) parameter declarations:
        every solve asks for them, and a warm solve takes well under a millisecond.  Arrays are
        read-only; the properties hand out copies (and new dicts)."""
        ps = self.parameters
        out = {
            "units": tuple(p.unit for p in ps),
            "k": np.array([p.k for p in ps], dtype=float),
            "lower": np.array([p.lower for p in ps], dtype=float),
            "upper": np.array([p.upper for p in ps], dtype=float),
            "cost_models": {p.name: p.cost for p in ps if p.cost is not None},
            "locks": {p.name: p.lock for p in ps if p.lock is not None},
            "fixed_joint_errors": {p.name: p.lock for p in ps if p.at_joint is not None and p.lock is not None},
        }
        for key in ("k", "lower", "upper"):
            out[key].setflags(write=False)
        return out

    @property
    def joint_units(self) -> tuple[str, ...]:
        """The unit each joint value is shown and typed in: ``"mm"`` for a joint that slides (a
        parallel robot's struts, a URDF's prismatic joints), ``"deg"`` for the others (the API
        takes mm and rad: :attr:`joint_value_units`)."""
        lengths = self.spec.length_joints
        return tuple("mm" if name in lengths else "deg" for name in self.joint_names)

    @property
    def joint_value_units(self) -> tuple[str, ...]:
        """The unit of each joint value in the API, the model files and tables: ``"mm"`` for a joint
        that slides, ``"rad"`` for the others."""
        return tuple("mm" if u == "mm" else "rad" for u in self.joint_units)

    def format_joints(self, q) -> str:
        """Joint values for a reader: ``(10, 20) deg``, ``(755.6, 755.6) mm``, or each with its unit."""
        units = self.joint_units
        shown = [float(v) if u == "mm" else math.degrees(v) for v, u in zip(np.asarray(q, dtype=float), units)]
        if len(set(units)) == 1:
            return "(" + ", ".join(f"{v:.3f}" for v in shown) + f") {units[0]}"
        return "(" + ", ".join(f"{v:.3f} {u}" for v, u in zip(shown, units)) + ")"

    @property
    def units(self) -> tuple[str, ...]:
        """Tolerance unit of each error parameter."""
        return self._per_parameter["units"]

    @property
    def k(self) -> np.ndarray:
        """Cost factors (the paper's k_i)."""
        return self._per_parameter["k"].copy()

    @property
    def distribution(self):
        """The error shapes the model file declares: ``"uniform"`` (the paper's single-piece
        production) when it declares none, else a mapping name -> shape for every parameter
        (undeclared ones uniform).  Used wherever ``distribution=None`` (the default) is passed."""
        declared = {p.name: p.distribution for p in self.parameters if p.distribution is not None}
        if not declared:
            return "uniform"
        return {p.name: p.distribution or "uniform" for p in self.parameters}

    @property
    def cost_models(self) -> dict:
        """Name -> cost model given in the model file; the others use ``k eps^-alpha``."""
        return dict(self._per_parameter["cost_models"])

    @property
    def processes(self) -> dict:
        """Name -> processes given in the model file (for :func:`tolsynth.synthesize_processes`)."""
        return {p.name: list(p.processes) for p in self.parameters if p.processes}

    @property
    def locks(self) -> dict:
        """Name -> locked tolerance given in the model file."""
        return dict(self._per_parameter["locks"])

    @property
    def joint_error_parameters(self) -> tuple[str, ...]:
        """Names of the error parameters that are joint errors (:mod:`tolsynth.model.joint_errors`)."""
        return tuple(p.name for p in self.parameters if p.at_joint is not None)

    @property
    def fixed_joint_errors(self) -> dict:
        """Name -> locked tolerance of the fixed joint errors (always locked by synthesize)."""
        return dict(self._per_parameter["fixed_joint_errors"])

    def with_joint_errors(self, joint_errors) -> "Mechanism":
        """The same mechanism with joint errors as further error parameters (appended after its
        own, in the same CasADi graphs).

        ``joint_errors`` is a list of :class:`tolsynth.JointError`: a servo error of an actuated
        joint or the clearance of a revolute joint, fixed (``value``: locked, so the link
        tolerances share what is left of the budget) or designable (``bounds``, with its own cost).
        See :mod:`tolsynth.model.joint_errors` for the model.  Tolerance sets get the fixed errors'
        values; the published reference results (link errors alone) are dropped.

        Raises
        ------
        InputError, UnknownNameError, OutOfRangeError
            Naming the field (``joint_errors[i].joint``, ``.value``, ``.unit``, ...).
        """
        from tolsynth.model.joint_errors import add_joint_errors

        return Mechanism(add_joint_errors(self.spec, joint_errors))

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Default tolerance bounds (Eq. 22) in tolerance units."""
        return self._per_parameter["lower"].copy(), self._per_parameter["upper"].copy()

    def index(self, name: str, field: str = "error parameter") -> int:
        """Position of an error parameter by name or alias (``"h2"`` or ``"x1"``); an unknown name
        is an error naming ``field`` (the argument it came in, e.g. ``"bounds[l3]"``)."""
        try:
            return self._index[name]
        except (KeyError, TypeError):
            raise UnknownNameError(
                field, f"unknown error parameter {name!r}", "one of " + ", ".join(self.error_parameters)
            ) from None

    def with_units(self, units: Mapping[str, str]) -> "Mechanism":
        """The same mechanism with other tolerance units for some parameters (name -> unit).

        Bounds and tolerance sets are converted; the cost ``k eps**-alpha`` is then evaluated on
        the numbers in the new unit (this changes the optimum when alpha applies to other numbers,
        which is how the paper's unit choice enters its tables).
        """
        from dataclasses import replace

        from tolsynth.units import to_base, unit_kind

        params = list(self.parameters)
        factors = np.ones(self.n)
        for name, unit in check_mapping(units, "units", "a dict parameter name -> unit").items():
            i = self.index(name, f"units[{name}]")
            par = params[i]
            if unit_kind(unit) != par.kind:
                raise OutOfRangeError(
                    f"units[{name}]", f"{unit!r} is not a unit of {par.kind}", "a unit of " + par.kind
                )
            f = par.scale / to_base(unit)  # old unit -> new unit
            factors[i] = f
            params[i] = replace(
                par,
                unit=unit,
                scale=to_base(unit),
                lower=par.lower * f,
                upper=par.upper * f,
                lock=None if par.lock is None else par.lock * f,
            )
        sets = {k: {n: v * factors[self.index(n)] for n, v in s.items()} for k, s in self.spec.tolerance_sets.items()}
        return Mechanism(replace(self.spec, error_parameters=tuple(params), tolerance_sets=sets, reference_results=()))

    # ------------------------------------------------------------------ inputs
    def joints(self, q: JointInput, check_limits: bool = True) -> np.ndarray:
        """Joint vector (rad) from a configuration name or values, checked against the limits.

        Values may be strings with a unit suffix (``["30deg", "90deg"]``), converted to each
        joint's unit (:attr:`joint_value_units`: rad, or mm for a joint that slides).

        A named configuration may waive limits it declares (the paper's ``worst`` pose lies 0.33
        deg past the interference limit); the same joint values passed as an array get the same
        waiver.  Any other violation raises :class:`OutOfRangeError` naming the joint.
        """
        waive: tuple[str, ...] = ()
        if isinstance(q, str):
            # a named configuration checked before (and unchanged since) passes again
            checked, cfg = self.__dict__.get("_checked_configurations", {}).get(q), self.configurations.get(q)
            if checked is not None and cfg is not None and checked == cfg.tobytes():
                return cfg.copy()
            if q not in self.spec.configurations:
                raise UnknownNameError(
                    "configuration", f"unknown configuration {q!r}", "one of " + ", ".join(self.configurations)
                )
            waive = self.spec.configurations[q].waive
            qv = self.configurations[q].copy()
        else:
            # "30deg" in a list: each joint in its own unit (rad, or mm for a joint that slides)
            qv = check_vector(q, "q", len(self.joint_names), names=self.joint_names, units=self.joint_value_units)
            for cfg in self.spec.configurations.values():
                if cfg.waive and np.array_equal(qv, np.array(cfg.q)):
                    waive = cfg.waive
        if check_limits:
            # limits are inclusive; LIMIT_SLACK only absorbs the rounding of deg -> rad conversions
            # and of the constraint sums (a pose given exactly on a limit in degrees is accepted)
            eps = LIMIT_SLACK
            lengths = self.spec.length_joints  # a parallel robot's struts, a slide, in mm
            for j, v in zip(self.spec.joints, qv):
                if j.name not in waive and not (j.lower - eps <= v <= j.upper + eps):
                    if j.name in lengths:
                        raise OutOfRangeError(
                            f"q[{j.name}]", f"{v:.4f} mm is outside the joint limits", f"{j.lower:g} to {j.upper:g} mm"
                        )
                    raise OutOfRangeError(
                        f"q[{j.name}]",
                        f"{math.degrees(v):.4f} deg is outside the joint limits",
                        f"{math.degrees(j.lower):g} to {math.degrees(j.upper):g} deg",
                    )
            names = list(self.joint_names)
            for c in self.spec.joint_constraints:
                if c.name in waive:
                    continue
                v = sum(coef * qv[names.index(jn)] for jn, coef in c.terms.items())
                if not (c.lower - eps <= v <= c.upper + eps):
                    expr = " ".join(f"{coef:+g}*{jn}" for jn, coef in c.terms.items())
                    raise OutOfRangeError(
                        f"q ({c.name}: {expr})",
                        f"{math.degrees(v):.4f} deg is outside the limit",
                        f"{math.degrees(c.lower):g} to {math.degrees(c.upper):g} deg",
                    )
            if isinstance(q, str):
                self.__dict__.setdefault("_checked_configurations", {})[q] = qv.tobytes()
        return qv

    def deltas(self, deltas: Mapping[str, float] | Sequence[float] | np.ndarray | None) -> np.ndarray:
        """Error vector in tolerance units from a dict name -> value (missing = 0) or a vector."""
        out = np.zeros(self.n)
        if deltas is None:
            return out
        if isinstance(deltas, Mapping):
            for name, value in deltas.items():
                i = self.index(name, f"deltas[{name}]")
                out[i] = check_real(value, f"deltas[{name}]", self.units[i])
        else:
            out[:] = check_vector(deltas, "deltas", self.n, names=self.error_parameters, units=self.units)
        return out

    def tolerances(self, tolerances: ToleranceInput, field: str = "tolerances") -> np.ndarray:
        """Tolerance half-widths (tolerance units) from a set name, a dict (all names) or a vector.

        A value may be a string with a unit suffix (``{"l1": "50um"}``), converted to its
        parameter's tolerance unit (:attr:`units`).  Raises for an unknown set or name, a missing
        parameter, or a negative value, naming ``field`` (the argument they came in, e.g. ``"x0"``).
        """
        if isinstance(tolerances, str):
            if tolerances not in self.tolerance_sets:
                raise UnknownNameError(
                    field,
                    f"unknown tolerance set {tolerances!r}",
                    "one of " + (", ".join(self.tolerance_sets) or "(none in this model)"),
                )
            tolerances = self.tolerance_sets[tolerances]
        if isinstance(tolerances, Mapping):
            out = np.zeros(self.n)
            given = np.zeros(self.n, dtype=bool)
            for name, value in tolerances.items():
                i = self.index(name, f"{field}[{name}]")
                if given[i]:
                    raise InputError(f"{field}[{name}]", "given twice (by name and alias)", "one value per parameter")
                out[i] = check_real(value, f"{field}[{name}]", self.units[i], 0.0, HUGE)
                given[i] = True
            missing = [self.error_parameters[i] for i in np.flatnonzero(~given)]
            if missing:
                raise InputError(field, f"missing value(s) for {missing}", "a value for every error parameter")
        else:
            out = check_vector(tolerances, field, self.n, "", 0.0, HUGE, self.error_parameters, units=self.units)
        return out

    # ------------------------------------------------------------------ kinematics
    def _check_closure(self, qv: np.ndarray, dv: np.ndarray) -> None:
        if is_parallel(self.spec):  # assembled, on the home pose's branch, away from singularities
            self.graphs.check(qv, dv)
            return
        if not self.spec.loops:
            return
        c = np.array(self.graphs.closure(qv, dv)).ravel()
        for loop, value in zip(self.spec.loops, c):
            if not abs(value) <= 1.0:
                raise LoopClosureError(
                    f"loop {loop.name!r} cannot close at q = {np.degrees(qv).round(4).tolist()} deg "
                    f"(cosine argument {value:.6f}, must lie in [-1, 1])"
                )

    def fk(self, q: JointInput, deltas=None, check_limits: bool = True) -> np.ndarray:
        """Hand pose as a 4x4 homogeneous matrix (mm), with the loops closed.

        Parameters
        ----------
        q : str or array
            A configuration name or the actuated joint values in rad.
        deltas : dict, optional
            Error-parameter deviations, name -> value in that parameter's tolerance unit.
        """
        qv = self.joints(q, check_limits)
        dv = self.deltas(deltas)
        self._check_closure(qv, dv)
        return np.array(self.graphs.fk(qv, dv))

    def sensitivity(self, q: JointInput, deltas=None, check_limits: bool = True) -> np.ndarray:
        """6 x n sensitivity d(pose)/d(error) by exact (algorithmic) differentiation.

        Rows: dx, dy, dz (mm) and the small rotation dphi_x, dphi_y, dphi_z (rad, base frame);
        column i per one tolerance unit of error parameter i.
        """
        return self.sensitivity_at(self.joints(q, check_limits), self.deltas(deltas))

    def sensitivity_at(self, qv: np.ndarray, dv: np.ndarray | None = None) -> np.ndarray:
        """:meth:`sensitivity` at joint values and errors already checked (``qv`` from
        :meth:`joints`, ``dv`` from :meth:`deltas`; None: no errors)."""
        if dv is None:
            dv = np.zeros(self.n)
        # a re-solve at the same poses (a sweep, a warm solve) asks again: remembered per
        # (joints, errors); the graphs of a Mechanism never change
        key = (qv.tobytes(), dv.tobytes())
        cache = self.__dict__.setdefault("_sensitivity_cache", {})
        S = cache.get(key)
        if S is None:
            self._check_closure(qv, dv)
            S = np.array(self.graphs.sensitivity(qv, dv))
            if len(cache) >= SENSITIVITY_CACHE:
                cache.pop(next(iter(cache)))
            cache[key] = S
        return S.copy()

    def _check_loops_close(self) -> None:
        """A model whose loops do not close at its named configurations is malformed."""
        from tolsynth.errors import ModelFileError

        zero = np.zeros(self.n)
        if is_parallel(self.spec):
            for name, q in self.configurations.items():
                try:
                    self.graphs.check(q, zero)
                except LoopClosureError as err:
                    raise ModelFileError(self.spec.path, f"configurations.{name}", str(err)) from None
            return
        if not self.spec.loops:
            return
        for name, q in self.configurations.items():
            c = np.array(self.graphs.closure(q, zero)).ravel()
            for loop, value in zip(self.spec.loops, c):
                if not abs(value) <= 1.0:
                    raise ModelFileError(
                        self.spec.path,
                        f"loops.{loop.name}",
                        f"the loop cannot close at configuration {name!r} (cosine argument {value:.4f})",
                    )

    # ------------------------------------------------------------------ analysis
    def analyze(
        self,
        q: JointInput,
        tolerances: ToleranceInput,
        distribution=None,
        R: float | None = None,
        Phi: float | None = None,
        check_limits: bool = True,
    ) -> Analysis:
        """Linearised error analysis (the paper's section 3) at one pose.

        ``R`` (mm) adds the per-component and sphere probabilities; ``Phi`` (rad) the
        orientation-component and cone probabilities for the hand's z axis.
        """
        from tolsynth.probability.distributions import resolve

        distribution = resolve(distribution, self)
        c = np.broadcast_to(np.asarray(variance_divisor(distribution, self), dtype=float), (self.n,)).copy()
        if R is not None:
            R = check_positive(R, "R")
        if Phi is not None:
            Phi = check_half_angle(Phi)
        eps = self.tolerances(tolerances)
        qv = self.joints(q, check_limits)
        T = self.fk(qv, check_limits=False)
        S = self.sensitivity(qv, check_limits=False)
        Vp, Vo = covariance(S, eps, c)
        sig, vec = principal(Vp)
        lam_cubic = np.array(principal_cubic_function()(Vp)).ravel()
        sig_o, _ = principal(Vo)
        extra = {}
        if R is not None:
            extra.update(R=R, p_components=p_components(sig, R), p_sphere=p_ball(sig**2, R))
        if Phi is not None:
            extra.update(Phi=Phi, p_orientation_components=p_components(sig_o, Phi), p_cone=p_cone(Vo, T[:3, 2], Phi))
        return Analysis(
            model=self.name,
            q=qv,
            distribution=distribution,
            tolerances=dict(zip(self.error_parameters, eps.tolist())),
            position=T[:3, 3].copy(),
            sensitivity=S,
            covariance=Vp,
            principal_std=sig,
            principal_directions=vec,
            principal_std_cubic=np.sqrt(np.clip(lam_cubic, 0.0, None)),
            orientation_covariance=Vo,
            orientation_principal_std=sig_o,
            **extra,
        )
