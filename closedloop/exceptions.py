"""Exceptions raised by :mod:`closedloop`.

Every message names the offending value and what was expected, so that a command-line
front end can print it on one line.
"""

from __future__ import annotations

from collections.abc import Iterable

#: Most names a :class:`NameNotFoundError` lists (every one of a robot's joints and frames;
#: beyond, ``closedloop info MODEL`` lists them).
LISTED_NAMES = 100
#: Similarity (difflib's ratio) from which a name is offered as "did you mean".
CLOSE_NAME_RATIO = 0.6


class ClosedLoopError(Exception):
    """Base class of every error raised by :mod:`closedloop`."""


def close_names(name, valid: Iterable[str]) -> list[str]:
    """The names of ``valid`` closest to ``name``, closest first, at most three (difflib's
    ratio from :data:`CLOSE_NAME_RATIO`, case ignored: ``'3D'`` is ``'3d'``); [] for a
    ``name`` that is not a str."""
    if not isinstance(name, str):
        return []
    import difflib  # on demand: an error's, not every import's

    by_case: dict[str, list[str]] = {}
    for n in valid:
        by_case.setdefault(n.casefold(), []).append(n)
    close = difflib.get_close_matches(name.casefold(), by_case, n=3, cutoff=CLOSE_NAME_RATIO)
    return [n for key in close for n in by_case[key]][:3]


def did_you_mean(name, valid: Iterable[str]) -> str:
    """``" (did you mean 'a' or 'b'?)"`` with the :func:`close_names` of ``name``, or
    ``""``: the hint of every message that refuses a name."""
    close = close_names(name, valid)
    return f" (did you mean {' or '.join(map(repr, close))}?)" if close else ""


def _choices(names: list[str], limit: int = LISTED_NAMES) -> str:
    shown = ", ".join(repr(n) for n in names[:limit])
    return shown + (
        f", ... ({len(names)} in all; closedloop info MODEL lists them)"
        if len(names) > limit
        else ""
    )


class NameNotFoundError(ClosedLoopError, KeyError):
    """A joint or frame name that the model does not have; the message offers the closest
    names (``did you mean``) and lists the valid ones.

    Attributes:
        kind, name: what was looked for (``"frame"``, ``"joint"``) and the name given.
        close: the valid names closest to ``name``, closest first (difflib).
    """

    def __init__(self, kind: str, name: str, valid: Iterable[str], hint: str = ""):
        self.kind, self.name = kind, name
        valid = list(dict.fromkeys(valid))  # once each, in the model's order
        self.close = close_names(name, valid)
        hint = f" ({hint})" if hint else ""
        near = did_you_mean(name, valid)
        super().__init__(f"unknown {kind} {name!r}{hint}{near}; expected one of: {_choices(valid)}")

    def __str__(self) -> str:  # KeyError would quote the message
        return self.args[0]


class InvalidInputError(ClosedLoopError, ValueError):
    """A numerical input with the wrong shape, sign or value (NaN, negative stiffness...)."""


class BeamError(InvalidInputError):
    """A beam specification that cannot be used; the message names the beam and the value."""

    def __init__(self, beam: str, message: str):
        self.beam = beam
        super().__init__(f"beam {beam!r}: {message}")


class ModelFileError(ClosedLoopError, ValueError):
    """An input file (robot, closure, springs, measurement file, a mesh) that is missing,
    larger than its kind allows, declares XML entities, or cannot be parsed."""


class ExpressionError(ModelFileError):
    """An expression of a parametric model file refused or without a value: a closure
    file's ``${expr}`` placeholder, a xacro file's ``${expr}`` or ``$(arg NAME)``
    (:mod:`closedloop.io.expressions`, :mod:`closedloop.io.xacro_files`). An unknown name, a
    missing argument, a result that is not a finite real number, or what the whitelist of
    the files' arithmetic does not hold (attribute access, calls of other functions).

    Attributes:
        file: the file, as given (str).
        line: the line of the expression (1-based).
        name: the unknown or missing name, or None.
        expression: the expression's text (inside ``${...}``), or None.
    """

    def __init__(self, message: str, file: str, line: int, name: str | None = None,
                 expression: str | None = None):  # fmt: skip
        self.file, self.line, self.name, self.expression = file, line, name, expression
        super().__init__(message)


class AssemblyError(ClosedLoopError):
    """The loop closures cannot be satisfied for the given inputs (unreachable pose)."""

    def __init__(self, message: str, residual: float):
        self.residual = residual
        super().__init__(f"{message} (closure residual reached: {residual:.3e})")


class UnreachableError(AssemblyError):
    """Inverse kinematics: the frame cannot reach its target on the start's branch (the
    way there leaves the workspace or crosses a singular pose).

    Attributes:
        distance: (distance [m], angle [rad]) left between the pose reached and the target,
            in the components the task fixes.
        fraction: the fraction of the way from the start's pose that was reached (0 to 1).
        residual: infinity norm of the residual rows (closures and task) left at the pose
            reached [m, rad].
    """

    def __init__(
        self, message: str, distance: tuple[float, float], fraction: float, residual: float
    ):
        self.distance, self.fraction = (float(distance[0]), float(distance[1])), float(fraction)
        self.residual = float(residual)
        ClosedLoopError.__init__(self, message)


class OpenLoopError(InvalidInputError):
    """A configuration that does not close the loops (assemble it first).

    Attributes:
        residual: scaled closure residual (infinity norm; metres divided by the
            characteristic length, radians as they are).
        tolerance: the tolerance it exceeds
            (:data:`closedloop.kinematics.configuration.CLOSURE_TOL`).
    """

    def __init__(self, message: str, residual: float, tolerance: float):
        self.residual, self.tolerance = residual, tolerance
        super().__init__(message)


class OutsideLimitsError(InvalidInputError):
    """A configuration given for a query with joints outside their position limits (the
    limits of :func:`closedloop.kinematics.limits.joints_outside_limits`); ``check_limits=False``
    (command line: ``--no-limits``) queries it anyway.

    Attributes:
        joints: joint name -> (value, lower, upper) [rad or m] of each joint outside.
    """

    def __init__(self, message: str, joints: dict):
        self.joints = dict(joints)
        super().__init__(message)


class MechanismError(ClosedLoopError):
    """The structure still moves without any restoring spring: no static equilibrium."""


class RigidDirectionsError(ClosedLoopError):
    """The compliance is rank deficient: the stiffness matrix does not exist.

    Attributes:
        directions: (6, r) array, orthonormal basis of the rigid directions (twist
            coordinates ordered dx, dy, dz, rx, ry, rz, same frame as the compliance).
    """

    def __init__(self, message: str, directions):
        self.directions = directions
        super().__init__(message)


class SingularConfigurationError(ClosedLoopError):
    """A configuration at which the requested map is singular."""


class EquilibriumError(ClosedLoopError):
    """The static equilibrium could not be found (Newton with load continuation failed).

    Attributes:
        residual: infinity norm of the closure residual reached [m, rad].
        force_residual: infinity norm of the unbalanced generalised force [N m, N].
        load_fraction: fraction of the wrench at which equilibrium was last found.
        limit_load: True when a limit load (a fold, where the tangent stiffness turns
            singular) ends the branch, False for a plain failure of the iterations (None
            when not examined).
        stability_margin: the spring-scaled margin at the last equilibrium (1 unloaded, 0
            at a limit), or None.
        iterations: Newton iterations spent, or None.
        fold_bracket: (lower, upper) load fractions between which the limit load lies
            (lower = ``load_fraction``), or None when it is not a limit load.
    """

    def __init__(
        self,
        message: str,
        residual: float,
        force_residual: float,
        load_fraction,
        *,
        limit_load: bool | None = None,
        stability_margin: float | None = None,
        iterations: int | None = None,
        fold_bracket: tuple[float, float] | None = None,
    ):
        self.residual, self.force_residual = residual, force_residual
        self.fold_bracket = fold_bracket
        self.load_fraction = load_fraction
        self.limit_load, self.stability_margin = limit_load, stability_margin
        self.iterations = iterations
        super().__init__(
            f"{message} (closure residual reached: {residual:.3e}, unbalanced force: "
            f"{force_residual:.3e}, equilibrium found up to {load_fraction:.3g} of the load)"
        )


class JointLimitError(EquilibriumError):
    """``enforce_limits=True`` and the load drives joints beyond their position limits.

    Attributes (besides those of :class:`EquilibriumError`):
        joints: names of the joints outside their limits.
    """

    def __init__(self, message, residual, force_residual, load_fraction, joints):
        super().__init__(message, residual, force_residual, load_fraction, limit_load=False)
        self.joints = tuple(joints)


class JointLimitWarning(UserWarning):
    """An equilibrium lies outside the position limits of some joints."""


class IgnoredFeatureWarning(UserWarning):
    """A model file's element or attribute that changes the mechanism in its own simulator
    and is not read here (an MJCF ``<position>`` actuator's kp, a ``springref`` away from
    ``ref``)."""


class ModelMisfitWarning(UserWarning):
    """:func:`closedloop.analysis.identification.identify`: the model does not fit the
    measurements (a weighted residual RMS far above what their sd allow, ``Fit.consistent``
    False): the standard errors, which assume a fit, do not hold."""


class ModesError(ClosedLoopError):
    """No natural frequency to report: a rigid model (no admissible motion), no mass on
    the admissible motions, or an unstable equilibrium."""


class NumericalError(ClosedLoopError):
    """A result is not finite (NaN or infinity) on finite input: the computation failed."""


class ClusterError(ClosedLoopError):
    """A Dask run failed: a task lost with its workers (``KilledWorker``), a closed
    connection, or no worker connected for longer than the worker timeout."""


class ViewerError(ClosedLoopError):
    """The meshcat viewer could not be started: its server exited, could not be run, or
    did not answer within its start timeout."""


#: Exit status of the command lines (``closedloop``, ``cahyman``): success.
EXIT_OK = 0
#: The analysis succeeded but the compliance is rank deficient: the stiffness does not exist.
EXIT_RANK_DEFICIENT = 1
#: Bad input: usage, file, name, value (the message names it).
EXIT_BAD_INPUT = 2
#: The computation failed on valid input: assembly, equilibrium, singular configuration.
EXIT_FAILED = 3

_FAILURES = (
    AssemblyError,
    ClusterError,
    EquilibriumError,
    MechanismError,
    NumericalError,
    SingularConfigurationError,
    ViewerError,
)


def exit_status(error: ClosedLoopError) -> int:
    """Exit status of a command line that stops on ``error``.

    :data:`EXIT_RANK_DEFICIENT` for :class:`RigidDirectionsError`, :data:`EXIT_FAILED` for
    :class:`AssemblyError`, :class:`ClusterError`, :class:`EquilibriumError` (and
    :class:`JointLimitError`), :class:`MechanismError`, :class:`NumericalError`,
    :class:`SingularConfigurationError` and :class:`ViewerError`,
    :data:`EXIT_BAD_INPUT` for the others (:class:`InvalidInputError`,
    :class:`ModelFileError` and its :class:`ExpressionError`, :class:`NameNotFoundError`,
    :class:`OpenLoopError`).
    """
    if isinstance(error, RigidDirectionsError):
        return EXIT_RANK_DEFICIENT
    if isinstance(error, _FAILURES):
        return EXIT_FAILED
    return EXIT_BAD_INPUT
