"""Exception classes of tolsynth (and nothing else).

Every error names the offending field and, where there is one, the allowed range, so that a
caller can correct the input without reading the source.  All inherit from :class:`TolsynthError`;
the input errors also inherit from :class:`ValueError` so that generic ``except ValueError``
handlers keep working.
"""

from __future__ import annotations

__all__ = [
    "TolsynthError",
    "InputError",
    "UnknownNameError",
    "OutOfRangeError",
    "ModelFileError",
    "LoopClosureError",
    "InfeasibleSpecificationError",
    "SolverError",
    "MissingDependencyError",
    "UnsupportedJointError",
    "TimeLimitError",
    "WorkspaceWarning",
    "CertificationWarning",
]


class TolsynthError(Exception):
    """Base class of every error raised by tolsynth."""


class InputError(TolsynthError, ValueError):
    """A value given by the caller is not acceptable.

    Attributes
    ----------
    field : str
        Name of the offending argument or field.
    allowed : str
        Human-readable statement of what is allowed.
    """

    def __init__(self, field: str, message: str, allowed: str | None = None):
        self.field = field
        self.allowed = allowed
        text = f"{field}: {message}"
        if allowed:
            text += f" (allowed: {allowed})"
        super().__init__(text)


class UnknownNameError(InputError, KeyError):
    """A model, parameter, configuration or tolerance-set name that does not exist."""

    def __str__(self) -> str:  # KeyError would otherwise quote the message
        return self.args[0]


class OutOfRangeError(InputError):
    """A number outside its allowed range (R <= 0, p outside (0, 1), a joint past its limit...)."""


class ModelFileError(TolsynthError, ValueError):
    """A mechanism declaration is malformed: a missing field, an unknown unit, an inconsistency."""

    def __init__(self, path: str, field: str, message: str):
        self.path = path
        self.field = field
        super().__init__(f"{path}: {field}: {message}")


class LoopClosureError(TolsynthError, ValueError):
    """A closed loop cannot be assembled for the given dimensions and joint values."""


class InfeasibleSpecificationError(TolsynthError):
    """The accuracy specification cannot be met inside the tolerance bounds.

    Attributes
    ----------
    constraint : str
        The constraint that fails even at the tightest tolerances allowed.
    value : float
        Its value at the tightest tolerances, in the problem's reading: ``sigma * z / R``
        (Gaussian) or ``(1 - P) / (1 - p)`` (exact); it must be <= 1.
    """

    def __init__(self, constraint: str, value: float, message: str):
        self.constraint = constraint
        self.value = value
        super().__init__(message)


class SolverError(TolsynthError):
    """A solver failed in a way that leaves no result to report (not used for non-convergence,
    which is reported as ``success == False`` on the result)."""


class TimeLimitError(TolsynthError):
    """A run passed its time limit (``synthesize(..., time_limit=...)``) inside a long evaluation.
    The solvers catch it and return a result with ``Status.TIME_LIMIT``; it reaches a caller only
    from a computation that has no result to return.

    Attributes
    ----------
    what : str
        The computation that was stopped.
    limit : float
        The limit, seconds.
    """

    def __init__(self, what: str, limit: float):
        self.what = what
        self.limit = limit
        super().__init__(f"{what}: stopped at the time limit of {limit:g} s (time_limit)")


class MissingDependencyError(TolsynthError, ImportError):
    """An optional package that a feature needs is not installed (pandas for tables, Dask for a
    cluster sweep...).

    Attributes
    ----------
    package : str
        The missing package.
    install : str
        The command that installs it.
    """

    def __init__(self, package: str, what: str, install: str):
        self.package = package
        self.install = install
        super().__init__(f"{what} needs {package}, which is not installed (install it with: {install})")


class UnsupportedJointError(ModelFileError):
    """A URDF joint on the chain whose type tolsynth cannot model (floating, planar, a mimic joint).

    Attributes
    ----------
    joint : str
        The joint's name in the URDF.
    joint_type : str
        Its type.
    """

    def __init__(self, path: str, joint: str, joint_type: str, message: str):
        self.joint = joint
        self.joint_type = joint_type
        super().__init__(path, f"joint {joint!r}", message)


class WorkspaceWarning(UserWarning):
    """A design made for some poses is over its specification elsewhere in the workspace (by a
    quick sampled check, :class:`tolsynth.analysis.validation.WorkspaceCheck`); the message points
    to :func:`tolsynth.synthesize_workspace`, which designs for every pose."""


class CertificationWarning(UserWarning):
    """A certified search was asked for where its proof has not been seen to close in minutes (the
    exact reading over five or more searched joints); the search runs, and its result says whether
    it closed."""
