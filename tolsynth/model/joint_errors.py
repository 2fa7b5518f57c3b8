"""Joint errors as error sources (the paper's section 6 "future work").

The paper's error parameters are link dimensions.  A real robot also errs *at its joints*; this
module declares two kinds of joint error and turns each into ordinary error parameters of the
mechanism, so that they enter the SAME CasADi graphs (:mod:`tolsynth.kinematics.graphs`) as the link
errors: their sensitivities are the same algorithmic derivatives, the Monte Carlo samples them
through the same nonlinear kinematics, and the optimiser sees them as columns of the covariance.

Servo / encoder error (``kind = "servo"``)
    An error ``dq`` of an *actuated* joint's value: the controller reads the encoder to a
    resolution, so the joint stands anywhere within ``+- q/2`` of the commanded angle (uniform
    quantisation, tolerance ``value = q/2``), or with a normal servo error (``3 sigma = value``,
    the synthesis' ``distribution="normal"``).  It is added to the joint variable itself, before
    the closed loops are solved, so a servo error of a joint that drives a loop (the paper's
    theta'2) moves the loop's passive joint too.  A servo error of a joint that turns is an angle
    (an angle unit, default mrad); of one that slides (a URDF's prismatic joint) a length (default
    mm), added to the joint's value in mm.  A parallel robot's strut has none: its length error is
    its leg's offset parameter.

Clearance of a revolute joint (``kind = "clearance"``)
    The journal (pin) floats inside its bearing (hole).  The model is the small-displacement
    "clearance link" model of Ting, Zhu & Watkins (2000): a revolute joint with radial clearance
    ``c`` (difference of the hole's and the pin's radii) behaves as the ideal joint plus an
    imaginary link of length ``c`` whose direction is free (``c`` while the pin touches the hole,
    shorter when it floats), so the pin's centre lies in a disc of radius ``c`` about the hole's
    centre, in the plane normal to the axis; Ting et al. use it to bound the worst position and
    direction errors of linkages and manipulators.  Its effect on the hand is, to first order, the
    sum of the small displacements it causes.  In space the pin can also slide along the axis within the
    axial play ``a`` and tilt: a pin of bearing length ``L`` in a hole with radial clearance ``c``
    tilts by at most ``2 c / L`` (the angle at which its two ends touch opposite sides of the
    hole).  This module simplifies that to five *independent* small errors at the joint, each
    within its band and distributed like the link errors (uniform by default):

    ==================  ====================================  ===============
    parameter           error                                 band
    ==================  ====================================  ===============
    ``<joint>.radial_x``  translation along the joint's x axis  ``+- c``
    ``<joint>.radial_y``  translation along the joint's y axis  ``+- c``
    ``<joint>.axial``     translation along the joint's z axis  ``+- a``
    ``<joint>.tilt_x``    rotation about the joint's x axis     ``+- 2c/L``
    ``<joint>.tilt_y``    rotation about the joint's y axis     ``+- 2c/L``
    ==================  ====================================  ===============

    The two radial components inside a square of half-side ``c`` stand for the disc of radius
    ``c`` (the square contains the disc: the model is conservative; uniform on the square gives
    each component the variance ``c^2/3`` where a uniform disc gives ``c^2/4``); the direction of
    the contact (set by the load in the real joint, and the subject of Ting et al.'s worst-case
    analysis) is not modelled, the errors being random and independent.  The transform
    ``Tx(ex) Ty(ey) Tz(ez) Rx(bx) Ry(by)`` is applied in the joint's frame just before the joint's
    rotation ``Rz(theta)`` (the frame of the bearing, fixed to the preceding link: modified D-H
    after ``Tz(s)``, standard D-H at the start of the link), so a tilt turns the distal chain
    about the joint frame's origin.  ``a`` is omitted when not given, the tilt when ``L`` is not
    given.  Clearances of a closed loop's pivots other than the chain's joints are not modelled.

Fixed or designable
    A joint error with a ``value`` is **fixed** (given by the user: the encoder's resolution, a
    bearing's clearance): its parameters are *locked* (:mod:`tolsynth.model.locks`, bounds ``lower =
    upper``), the link tolerances share what is left of the accuracy budget, and if the fixed
    errors alone break the specification :func:`tolsynth.synthesize` raises
    :class:`~tolsynth.errors.InfeasibleSpecificationError` naming them.  A joint error with
    ``bounds`` instead is **designable**: each of its parameters is a design variable with its
    own cost curve (``k eps^-alpha`` or a :mod:`tolsynth.model.cost` model).  A designable clearance
    has radial components only (``axial`` and ``length`` need a fixed clearance): its tilt would be
    tied to the radial clearance, and the optimiser has one variable per parameter; the two
    radial components are then two design variables with the same bounds and cost.

A fixed joint error costs nothing (its cost model is :class:`tolsynth.model.cost.Given`, exactly 0,
whatever ``cost=`` says for the others): the cost reported, and a budget, are those of the
tolerances being chosen.

References
----------
* K.-L. Ting, J. Zhu, D. Watkins, "The effects of joint clearance on position and orientation
  deviation of linkages and manipulators", Mechanism and Machine Theory 35(3):391-401, 2000.
* Xu Weiliang, Zhang Qixian, "Precision optimization design of robot mechanisms", 1988
  (section 6: joint clearances and servo errors as the next error sources).

>>> import tolsynth
>>> m = tolsynth.load_model("xu_zhang_1988").with_joint_errors(
...     [tolsynth.JointError("theta1", "servo", value=0.5, unit="mrad")])
>>> m.error_parameters[-1], m.locks
('theta1.servo', {'theta1.servo': 0.5})
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Mapping, Sequence

from tolsynth.checks import HUGE, check_positive, check_real
from tolsynth.errors import InputError, OutOfRangeError, UnknownNameError

__all__ = ["JointError", "KINDS", "joint_parameters", "add_joint_errors", "with_given_costs"]

#: the kinds of joint error
KINDS = ("servo", "clearance")
#: default tolerance unit of each kind
DEFAULT_UNIT = {"servo": "mrad", "clearance": "mm"}
#: the unit of the tilt parameters of a clearance
TILT_UNIT = "mrad"
#: clearance components: suffix -> elementary transform at the joint (applied in the order
#: Tx Ty Tz Rx Ry: tolsynth.kinematics.graphs.JOINT_OPS)
CLEARANCE_OPS = {"radial_x": "Tx", "radial_y": "Ty", "axial": "Tz", "tilt_x": "Rx", "tilt_y": "Ry"}


@dataclass(frozen=True)
class JointError:
    """One joint error source (see the module docstring for the model).

    Parameters
    ----------
    joint : str
        The joint's name: an actuated joint for ``"servo"``; a joint turned by a link of the chain
        (actuated or a loop's passive joint) for ``"clearance"``.
    kind : {"servo", "clearance"}
    value : float, optional
        A **fixed** error's half-width in ``unit``: the servo error's ``+-`` band (``q/2`` for an
        encoder of resolution ``q``), or the radial clearance ``c``.
    bounds : (lower, upper), optional
        Instead of ``value``: a **designable** error's tolerance bounds in ``unit``.
    unit : str, optional
        Tolerance unit: an angle unit for a servo error (default ``"mrad"``), a length unit for a
        clearance (default ``"mm"``; also the unit of ``axial`` and ``length``).
    axial : float, optional
        Clearance only (fixed): the axial play ``a`` (``+- a`` along the joint axis), in ``unit``.
    length : float, optional
        Clearance only (fixed): the bearing length ``L`` in ``unit``; adds the tilt ``+- 2c/L``
        about the joint's x and y axes (tolerance unit mrad).
    k : float, optional
        A designable error's cost factor of the power law ``k eps^-alpha`` (default 1).  A fixed
        error is given, not bought: it costs nothing (:class:`tolsynth.model.cost.Given`).
    cost : CostModel or dict, optional
        A cost model (:func:`tolsynth.model.cost.cost_model`) for a designable error.
    note : str
        Where the numbers come from (a data sheet, a measurement).
    """

    joint: str
    kind: str
    value: float | None = None
    bounds: tuple[float, float] | None = None
    unit: str | None = None
    axial: float | None = None
    length: float | None = None
    k: float | None = None
    cost: Any = None
    note: str = ""

    @property
    def fixed(self) -> bool:
        """True for a given (fixed) error, False for a designable one."""
        return self.value is not None

    @property
    def names(self) -> tuple[str, ...]:
        """Names of the error parameters it becomes (``<joint>.servo``, ``<joint>.radial_x``, ...)."""
        if self.kind == "servo":
            return (f"{self.joint}.servo",)
        out = [f"{self.joint}.radial_x", f"{self.joint}.radial_y"]
        if self.axial is not None:
            out.append(f"{self.joint}.axial")
        if self.length is not None:
            out += [f"{self.joint}.tilt_x", f"{self.joint}.tilt_y"]
        return tuple(out)


def _check(je: JointError, i: int, spec) -> JointError:
    """Validate one joint error against the mechanism ``spec``; returns it with its unit filled in."""
    from tolsynth.units import unit_kind

    where = f"joint_errors[{i}]"
    if not isinstance(je, JointError):
        raise InputError(where, f"got {je!r:.60}", "a tolsynth.JointError")
    if not isinstance(je.kind, str) or je.kind not in KINDS:
        raise InputError(f"{where}.kind", f"unknown kind {je.kind!r}", " or ".join(repr(k) for k in KINDS))
    actuated = list(spec.joint_names)
    slides = set(getattr(spec, "length_joints", ()))  # prismatic joints: their values are lengths
    chain = [link.theta for link in spec.links]
    allowed = actuated if je.kind == "servo" else [j for j in chain if j not in slides]
    if not isinstance(je.joint, str) or je.joint not in allowed:
        what = "an actuated joint" if je.kind == "servo" else "a revolute joint of a serial chain"
        if not allowed:  # a parallel robot: no serial chain, its legs' ends are ball joints
            why = f"{spec.name} has none (a parallel robot's legs end in ball joints, whose clearance is not modelled)"
        elif je.joint in slides:
            why = "it slides (a prismatic joint): the clearance model is a revolute joint's pin in its bearing"
        else:
            why = ""
        raise UnknownNameError(
            f"{where}.joint",
            f"{je.joint!r} is not {what}" + (f": {why}" if why else ""),
            "one of " + ", ".join(allowed)
            if allowed
            else "kind 'servo' on a revolute actuator"
            if set(actuated) - slides
            else "no joint error (each strut's length error is its leg's offset parameter)",
        )
    slide = je.kind == "servo" and je.joint in slides  # a slide's servo error is a length
    unit = ("mm" if slide else DEFAULT_UNIT[je.kind]) if je.unit is None else je.unit
    want = "angle" if je.kind == "servo" and not slide else "length"
    if not isinstance(unit, str) or unit_kind(unit) != want:
        from tolsynth.units import ANGLE_UNITS, LENGTH_UNITS

        units = ANGLE_UNITS if want == "angle" else LENGTH_UNITS
        raise OutOfRangeError(f"{where}.unit", f"{unit!r} is not a unit of {want}", ", ".join(units))
    if (je.value is None) == (je.bounds is None):
        raise InputError(
            where,
            "give either value (a fixed error) or bounds (a designable one)",
            "value = half-width, or bounds = (lower, upper), in " + unit,
        )
    value = bounds = None
    if je.value is not None:
        value = check_positive(je.value, f"{where}.value", unit)
    else:
        try:
            lo, hi = je.bounds
        except (TypeError, ValueError):
            raise InputError(f"{where}.bounds", f"got {je.bounds!r:.60}", "(lower, upper)") from None
        lo = check_positive(lo, f"{where}.bounds.lower", unit)
        hi = check_real(hi, f"{where}.bounds.upper", unit, lo, HUGE)
        bounds = (lo, hi)
    axial = length = None
    if je.kind == "servo":  # an angle: a servo error of more than a turn is a unit mistake
        from tolsynth.units import to_base

        top = 2 * math.pi / to_base(unit)
        key, v = ("value", value) if value is not None else ("bounds.upper", bounds[1])
        if not slide and v > top * (1 + 1e-12):
            raise OutOfRangeError(f"{where}.{key}", f"{v:g} {unit} is more than a full turn", f"up to {top:g} {unit}")
        for key in ("axial", "length"):
            if getattr(je, key) is not None:
                raise InputError(f"{where}.{key}", "given for a servo error", "clearance errors only")
    else:
        for key in ("axial", "length"):
            if getattr(je, key) is not None and value is None:
                raise InputError(
                    f"{where}.{key}",
                    "given for a designable clearance (bounds)",
                    "a fixed clearance (value) only: the tilt and axial play of a designable "
                    "clearance are not design variables of their own",
                )
        if je.axial is not None:
            axial = check_positive(je.axial, f"{where}.axial", unit)
        if je.length is not None:
            length = check_positive(je.length, f"{where}.length", unit)
            if 2 * value / length > 0.1:
                raise OutOfRangeError(
                    f"{where}.length",
                    f"tilt 2c/L = {2 * value / length:.3g} rad",
                    "a small tilt (2 value / length <= 0.1 rad): the model is first-order",
                )
    from tolsynth.model.cost import CostModel, Given, cost_model

    for key in ("k", "cost"):
        if getattr(je, key) is not None and value is not None:
            raise InputError(
                f"{where}.{key}",
                "given for a fixed joint error (value): it is given, not bought",
                "a cost for a designable joint error (bounds) only",
            )
    k = 1.0 if je.k is None else check_positive(je.k, f"{where}.k")
    cost = je.cost
    if cost is not None and not isinstance(cost, CostModel):
        cost = cost_model(cost)
    if value is not None:
        cost = Given()
    if not isinstance(je.note, str):
        raise InputError(f"{where}.note", f"got {je.note!r:.60}", "a string")
    return replace(je, value=value, bounds=bounds, unit=unit, axial=axial, length=length, k=k, cost=cost)


def joint_parameters(spec, joint_errors: Sequence[JointError]) -> tuple:
    """The error parameters (:class:`tolsynth.model.spec.ErrorParameter`) of the joint errors, checked
    against the mechanism ``spec`` (names unique, also against its link parameters)."""
    from tolsynth.model.spec import ErrorParameter
    from tolsynth.units import to_base, unit_kind

    if isinstance(joint_errors, JointError) or not isinstance(joint_errors, Sequence):
        raise InputError("joint_errors", f"got {joint_errors!r:.60}", "a list of tolsynth.JointError")
    taken = {p.name for p in spec.error_parameters} | {p.alias for p in spec.error_parameters if p.alias}
    out = []
    for i, raw in enumerate(joint_errors):
        je = _check(raw, i, spec)
        for name in je.names:
            if name in taken:
                raise InputError(
                    f"joint_errors[{i}]",
                    f"error parameter {name!r} is declared twice",
                    "one joint error of each kind per joint",
                )
            taken.add(name)
        scale = to_base(je.unit)
        lo, hi = (je.value, je.value) if je.fixed else je.bounds
        common = dict(k=je.k, cost=je.cost, lock=je.value)
        if je.kind == "servo":
            out.append(
                ErrorParameter(
                    name=f"{je.joint}.servo",
                    perturbs=(),
                    unit=je.unit,
                    scale=scale,
                    lower=lo,
                    upper=hi,
                    label=f"servo error of {je.joint}",
                    kind=unit_kind(je.unit),
                    at_joint=(je.joint, "q"),
                    **common,
                )
            )
            continue
        for suffix in ("radial_x", "radial_y", "axial", "tilt_x", "tilt_y"):
            name = f"{je.joint}.{suffix}"
            if name not in je.names:
                continue
            op = CLEARANCE_OPS[suffix]
            if suffix == "axial":
                v = je.axial
            elif suffix.startswith("tilt"):
                v = 2 * je.value / je.length * (1.0 / to_base(TILT_UNIT))  # rad -> mrad
            else:
                out.append(
                    ErrorParameter(
                        name=name,
                        perturbs=(),
                        unit=je.unit,
                        scale=scale,
                        lower=lo,
                        upper=hi,
                        label=f"clearance of {je.joint}: {suffix.replace('_', ' ')}",
                        kind="length",
                        at_joint=(je.joint, op),
                        **common,
                    )
                )
                continue
            unit = TILT_UNIT if suffix.startswith("tilt") else je.unit
            out.append(
                ErrorParameter(
                    name=name,
                    perturbs=(),
                    unit=unit,
                    scale=to_base(unit),
                    lower=v,
                    upper=v,
                    label=f"clearance of {je.joint}: {suffix.replace('_', ' ')}",
                    kind="angle" if suffix.startswith("tilt") else "length",
                    at_joint=(je.joint, op),
                    k=je.k,
                    cost=je.cost,
                    lock=v,
                )
            )
    return tuple(out)


def add_joint_errors(spec, joint_errors: Sequence[JointError]):
    """``spec`` (a :class:`tolsynth.model.spec.MechanismSpec`) with the joint errors' parameters
    appended after its own.

    Tolerance sets get each fixed joint error's values (a designable one has no value, so a model
    with designable joint errors keeps no tolerance sets); the published reference results (for
    the link errors alone) are dropped.
    """
    params = joint_parameters(spec, joint_errors)
    if not params:
        return spec
    sets: dict = {}
    if all(p.lock is not None for p in params):
        sets = {k: {**s, **{p.name: p.lock for p in params}} for k, s in spec.tolerance_sets.items()}
    return replace(
        spec, error_parameters=tuple(spec.error_parameters) + params, tolerance_sets=sets, reference_results=()
    )


def with_given_costs(mechanism, cost):
    """The ``cost`` argument of :func:`tolsynth.synthesize` with the fixed joint errors' costs
    set to :class:`~tolsynth.model.cost.Given` (they are given, not bought), whatever ``cost`` says for
    the others: None, one model for every parameter, a list of n models, or a dict."""
    from tolsynth.model.cost import CostModel, Given

    given = {
        p.name: p.cost
        for p in mechanism.parameters
        if p.at_joint is not None and p.lock is not None and p.cost is not None
    }
    if not given:
        return cost
    names = mechanism.error_parameters
    if cost is None:
        out = dict(mechanism.cost_models)
    elif isinstance(cost, CostModel) or (isinstance(cost, Mapping) and "model" in cost):
        out = {n: cost for n in names}
    elif isinstance(cost, (list, tuple)) and len(cost) == len(names):
        out = dict(zip(names, cost))
    elif isinstance(cost, Mapping):
        out = {names[mechanism.index(k)]: v for k, v in cost.items()}  # aliases -> names
        for name in out:
            if name in given and not isinstance(out[name], Given):  # Given passes: a result's own costs
                raise InputError(
                    f"cost[{name}]",
                    "a cost for a fixed joint error: it is given, not bought",
                    "costs for the design variables only (a designable joint error has bounds)",
                )
    else:
        return cost  # malformed: tolsynth.model.cost.cost_set raises naming it
    out.update(given)
    return out


def _parse_file_entries(r, raw_list, spec) -> list[JointError]:
    """``[[joint_errors]]`` tables of a model file -> JointError (used by :mod:`tolsynth.model.reader`)."""
    out = []
    for i, raw in enumerate(raw_list):
        where = f"joint_errors[{i}]"
        kw: dict[str, Any] = {}
        kw["joint"] = r.get(raw, "joint", where, str)
        kw["kind"] = r.get(raw, "kind", where, str)
        if "value" in raw:
            kw["value"] = r.positive(raw["value"], f"{where}.value")
        if "bounds" in raw:
            kw["bounds"] = r.pair(raw["bounds"], f"{where}.bounds")
        if "unit" in raw:
            kw["unit"] = r.unit(raw["unit"], f"{where}.unit")
        for key in ("axial", "length"):
            if key in raw:
                kw[key] = r.positive(raw[key], f"{where}.{key}")
        if "k" in raw:
            kw["k"] = r.positive(raw["k"], f"{where}.k")
        if "cost" in raw:
            kw["cost"] = r.get(raw, "cost", where, dict)
        if "note" in raw:
            kw["note"] = r.get(raw, "note", where, str)
        out.append(JointError(**kw))
    return out
