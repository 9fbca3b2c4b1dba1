"""Cartesian compliance and stiffness of a closed-loop mechanism with joint springs: the
query :func:`compliance`, unloaded (:mod:`closedloop.elastostatics.unloaded`, whose method and
numerics its docstring explains; the prepared query of one frame,
:class:`closedloop.elastostatics.query.ComplianceQuery`, whose kernel it shares) or about the
equilibrium under gravity, payloads or a preload (:mod:`closedloop.elastostatics.preload`,
imported only then).
"""

from __future__ import annotations

import numpy as np

from closedloop.common.arrays import check_wrench
from closedloop.elastostatics.query import ComplianceQuery, query_plan, unloaded_compliance
from closedloop.elastostatics.springs import (
    PATHS,
    SpringFactor,
    check_path,
    spring_factor,
    spring_subspace,
)
from closedloop.elastostatics.unloaded import (
    TWIST_LABELS,
    UNITS,
    ComplianceResult,
    compliance_result,
    describe_directions,
    energy_shares,
    finite_product,
)
from closedloop.exceptions import InvalidInputError
from closedloop.kinematics.configuration import Configuration, as_configuration
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.closures import check_name

# the result type, its kernel and the spring factor live in closedloop.elastostatics.unloaded and
# closedloop.elastostatics.springs; their names stay importable from here
__all__ = [
    "PATHS",
    "TWIST_LABELS",
    "UNITS",
    "ComplianceQuery",
    "ComplianceResult",
    "SpringFactor",
    "compliance",
    "compliance_result",
    "describe_directions",
    "energy_shares",
    "finite_product",
    "spring_factor",
    "spring_subspace",
]


def compliance(
    model: ClosedLoopModel | Configuration,
    q: np.ndarray | str | None = None,
    frame: str | None = None,
    axes: str = "world",
    *,
    length: float | None = None,
    path: str = "auto",
    gravity=None,
    payloads=(),
    preload=None,
    check_limits: bool = True,
) -> ComplianceResult:
    """Cartesian compliance of ``frame`` at a configuration (see the module docstring).

    Call as ``compliance(state, frame)`` with a :class:`Configuration`, or as
    ``compliance(model, q, frame)``.

    Args:
        model: a configuration, or a model with closures and springs.
        q: (nq,) assembled configuration with a model (:func:`closedloop.assemble`); with a
            configuration, the frame may be given here.
        frame: name of the loaded frame; the reference point is its origin.
        axes: ``"world"`` (world-aligned axes, default) or ``"local"``.
        length: characteristic length [m] of the unit-free rules, with a model (default:
            that of the configuration, the size of its joint origins).
        path: ``"auto"`` (default: the serial or partitioned fast path where it applies)
            or ``"null-space"`` (the general path, e.g. to cross-check); the path taken is
            in the result.
        gravity: (3,) acceleration [m/s^2], world axes, weighing the model's link inertias
            (and ``payloads``, :class:`closedloop.model.gravity.Payload`); with it, or with
            ``preload`` (6,) (a dead-load wrench at the frame origin [N, N m], world
            axes), q is the springs' rest configuration, the mechanism settles under the
            preload (:func:`closedloop.elastostatics.statics.solve_equilibrium`) and the result is
            the tangent compliance there
            (:class:`closedloop.elastostatics.preload.PreloadedCompliance`, with the sag of the
            frame, q_eq and the spring forces).
        check_limits: with a model, refuse a q outside the joints' position limits
            (default; :class:`closedloop.exceptions.OutsideLimitsError`, which asks
            "degrees?" for revolute values beyond 2 pi); False takes q as it is (a
            :class:`Configuration` is checked when it is made).

    Raises:
        NameNotFoundError: unknown frame.
        OutsideLimitsError: ``check_limits`` and joints of q outside their limits.
        OpenLoopError: q does not close the loops (tolerance ``CLOSURE_TOL``).
        MechanismError: a spring-free motion moves the frame (no static equilibrium).
        SingularConfigurationError: the compliance overflows (springs near 1e-308); on the
            null-space path, springs further apart than
            :data:`closedloop.elastostatics.springs.SPREAD_RESOLVED` (1e20, scaled; the message
            names the softest and the stiffest).
        InvalidInputError: a q, frame name, axes, path, length, gravity or preload that is
            not what the arguments above expect (the message names it).
    """
    if isinstance(model, Configuration):
        if q is not None and frame is None:  # compliance(state, frame): its own q
            q, frame = None, q
        elif isinstance(q, str):  # (state, frame, axes)
            q, frame, axes = None, q, frame
    if frame is None:
        raise InvalidInputError("compliance() needs the name of the loaded frame (a str)")
    check_name("frame", frame)
    check_path(path)
    unloaded = gravity is None and not payloads and preload is None
    if unloaded and isinstance(model, ClosedLoopModel) and q is not None:  # the prepared query's
        return query_plan(model, frame, axes, path, length).query(model, q, check_limits)
    state = as_configuration(model, q, length=length, check_limits=check_limits)
    state.require_closed()
    if not unloaded:
        from closedloop.elastostatics.preload import preloaded_compliance  # on demand: start-up
        from closedloop.elastostatics.statics import solve_equilibrium

        w0 = np.zeros(6) if preload is None else check_wrench(preload, "preload")
        eq = solve_equilibrium(state, frame, w0, gravity=gravity, payloads=payloads)
        return preloaded_compliance(state.model, eq, axes, length=state.length)
    return unloaded_compliance(state, frame, axes, path)
