"""What a model is: the validated, plain-number description of one mechanism (mm and rad).

The model-file reader (:mod:`tolsynth.model.reader`), the D-H table (:mod:`tolsynth.model.dh`) and the
URDF import (:mod:`tolsynth.model.urdf`) all produce a :class:`MechanismSpec`;
:class:`tolsynth.Mechanism` builds its CasADi graphs from one.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "MechanismSpec",
    "Link",
    "Joint",
    "FourBarLoop",
    "JointConstraint",
    "Configuration",
    "ErrorParameter",
    "ReferenceResult",
    "CONVENTIONS",
    "ELEMENTARY",
]


CONVENTIONS = {
    # name: (fields in the order they are applied, description)
    "modified": (("h", "alpha", "s", "theta"), "Tx(h) . Rx(alpha) . Tz(s) . Rz(theta)"),
    "standard": (("theta", "d", "a", "alpha"), "Rz(theta) . Tz(d) . Tx(a) . Rx(alpha)"),
}


_LENGTH_FIELDS = {"h", "s", "d", "a"}


_ANGLE_FIELDS = {"alpha", "theta_offset"}


ELEMENTARY = {"Tx": "length", "Ty": "length", "Tz": "length", "Rx": "angle", "Ry": "angle", "Rz": "angle"}


@dataclass(frozen=True)
class Link:
    """One D-H link.  Every dimension is a *symbol name*; ``theta`` names a joint."""

    dims: dict[str, str]  # field -> symbol name (h/alpha/s or d/a/alpha)
    theta: str  # joint name (actuated or passive)
    theta_offset: str | None  # symbol name, or None
    #: convention "urdf" only (tolsynth.model.urdf): the joint origin as elementary transforms
    #: ((op, symbol), ...), the rotations that turn z onto the joint axis (with the axis-tilt
    #: symbols), and the joint type ("revolute" turns about the axis, "prismatic" slides along it)
    origin: tuple[tuple[str, str], ...] = ()
    axis: tuple[tuple[str, str], ...] = ()
    motion: str = "revolute"


@dataclass(frozen=True)
class Joint:
    name: str
    lower: float  # rad
    upper: float  # rad


@dataclass(frozen=True)
class FourBarLoop:
    """Planar four-bar that sets a passive joint (see ``tolsynth.kinematics.graphs.four_bar_output``).

    In the plane of the loop, with the common pivot O at the origin: the ground link O->E of length
    ``ground`` lies at angle ``ground_angle``; the crank O->C of length ``crank`` at ``crank_angle``;
    the coupler C->D has length ``coupler``; the lever E->D of length ``lever`` is rigid with the
    next link.  The passive joint is the lever's angle measured from the ground link.
    """

    name: str
    passive_joint: str
    ground: str
    ground_angle: str
    crank: str
    crank_angle: str
    coupler: str
    lever: str
    branch: int  # +1 or -1


@dataclass(frozen=True)
class JointConstraint:
    name: str
    terms: dict[str, float]  # joint name -> coefficient
    lower: float  # rad
    upper: float  # rad


@dataclass(frozen=True)
class Configuration:
    name: str
    q: tuple[float, ...]  # rad, in the order of the actuated joints
    note: str = ""
    waive: tuple[str, ...] = ()  # joint or joint-constraint limits this named pose may violate


@dataclass(frozen=True)
class ErrorParameter:
    name: str
    perturbs: tuple[str, ...]
    unit: str
    scale: float  # one tolerance unit in base units (mm or rad)
    k: float
    lower: float  # default bounds, in the tolerance unit
    upper: float
    label: str = ""
    alias: str | None = None
    kind: str = "length"
    cost: Any = None  # tolsynth.model.cost.CostModel, or None: k eps^-alpha
    processes: tuple = ()  # tolsynth.synthesis.processes.Process, ...
    lock: float | None = None
    #: a joint error (tolsynth.model.joint_errors): (joint name, "q" for the joint variable or the
    #: elementary transform Tx/Ty/Tz/Rx/Ry applied at the joint); ``perturbs`` is then empty
    at_joint: tuple[str, str] | None = None
    #: the error's shape inside its band (tolsynth.probability.distributions); None: whatever ``distribution=`` says
    distribution: str | None = None


@dataclass(frozen=True)
class ReferenceResult:
    """A published optimum (the paper's Tables 1-3): specification and printed tolerances."""

    table: str
    R: float  # mm
    p: float
    alpha: float
    distribution: str
    tolerances: tuple[float, ...]  # in the error parameters' units, in their order


@dataclass(frozen=True)
class MechanismSpec:
    """A validated mechanism declaration: every number in mm or rad."""

    name: str
    title: str
    source: str
    assumptions: tuple[str, ...]
    path: str
    convention: str
    base: tuple[tuple[str, str], ...]  # (elementary transform, symbol)
    tool: tuple[tuple[str, str], ...]
    links: tuple[Link, ...]
    symbols: dict[str, float]  # nominal value in mm or rad
    symbol_kinds: dict[str, str]
    joints: tuple[Joint, ...]
    loops: tuple[FourBarLoop, ...]
    joint_constraints: tuple[JointConstraint, ...]
    configurations: dict[str, Configuration]
    error_parameters: tuple[ErrorParameter, ...]
    tolerance_sets: dict[str, dict[str, float]]
    reference_results: tuple[ReferenceResult, ...] = field(default_factory=tuple)
    notes: str = ""

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def length_joints(self) -> tuple[str, ...]:
        """Joints whose values are lengths (mm): those that slide (a URDF's prismatic joints)."""
        return tuple(link.theta for link in self.links if link.motion == "prismatic")
