"""The actuated inputs driven to their values within the joints' limits: the assembly of
a map's points and of the command line's ``--actuated``, on the assembly mode of a start
configuration.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from closedloop.exceptions import AssemblyError, InvalidInputError, SingularConfigurationError
from closedloop.kinematics.assembly import (
    INPUT_STEP,
    Assembly,
    check_actuated,
    close_loops,
    coordinate_scale,
)
from closedloop.kinematics.limits import degrees_hint, describe_limits, joints_outside_limits
from closedloop.model.closed_loop import ClosedLoopModel

__all__ = [
    "INPUT_STEP",
    "MAX_INPUT_STEPS",
    "assemble_connected",
    "assemble_within_limits",
    "input_scale",
]


def assemble_within_limits(
    clm: ClosedLoopModel,
    actuated: np.ndarray,
    q0: np.ndarray | None = None,
    *,
    jacobian: bool = True,
    check_limits: bool = True,
) -> Assembly:
    """:func:`closedloop.kinematics.assembly.assemble` of actuated values (n_act,) [rad, m] inside
    the position limits of their joints (the rule of :func:`joints_outside_limits`), from q0
    (nq,; default: neutral, as ``assemble``); ``jacobian`` as for ``assemble``;
    ``check_limits`` False: wherever the values are (the command line's ``--no-limits``).

    Raises:
        InvalidInputError: bad ``actuated`` or ``q0`` (as for ``assemble``), or an
            actuated value outside its joint's limits with ``check_limits`` (an ``invalid``
            point of a map: the robot cannot be driven there).
        AssemblyError: the loops cannot be closed.
        SingularConfigurationError: they close at a singular configuration only.
    """
    q = clm.check_configuration(pin.neutral(clm.model) if q0 is None else q0)
    origin = None if q0 is None else q.copy()  # an assembled q0: its branch is followed
    clm.set_actuated(q, check_actuated(clm, actuated))
    bad = {n: v for n, v in joints_outside_limits(clm, q).items() if n in clm.actuated}
    if bad and check_limits:
        raise InvalidInputError(
            f"actuated joints outside their limits: {describe_limits(bad)}"
            + degrees_hint(clm, bad, "actuated values are")
        )
    return close_loops(clm, q, jacobian=jacobian, origin=origin)


#: Most steps of :func:`assemble_connected` (a longer way takes longer steps).
MAX_INPUT_STEPS = 1000


def input_scale(clm: ClosedLoopModel) -> np.ndarray:
    """(n_act,) the unit of each actuated value in :data:`INPUT_STEP` (the largest change
    of an actuated value per step of :func:`assemble_connected`): L [m] for a length, 1 for
    an angle (once per model)."""
    return clm.memo("input_scale", lambda: coordinate_scale(clm)[clm.actuated_v_indices])


def assemble_connected(
    clm: ClosedLoopModel,
    actuated: np.ndarray,
    q0: np.ndarray | None = None,
    *,
    jacobian: bool = True,
    check_limits: bool = True,
) -> Assembly:
    """:func:`assemble_within_limits` on the assembly mode of q0 (default: neutral): the
    actuated values go from q0's to ``actuated`` (n_act,) [rad, m] in steps of at most
    :data:`INPUT_STEP`, each assembled from the last, as the robot is driven there.

    One Gauss-Newton solve from far away may land on another mode: the bundled four-bar
    solved at once from crank 0 is on the other mode at crank 1.0, not at 1.5. Where a step
    cannot be assembled (q0's mode ends on the way, at a singular position, or the way
    leaves the limits), the direct assembly from q0 is taken. A model without loops has
    its actuated values set (:func:`closedloop.kinematics.assembly.assemble`).
    ``check_limits`` as for :func:`assemble_within_limits`, on the way too.

    Raises:
        As :func:`assemble_within_limits`.
    """
    q = clm.check_configuration(pin.neutral(clm.model) if q0 is None else q0)
    target = check_actuated(clm, actuated)
    start = clm.actuated_values(q)
    with np.errstate(over="ignore"):  # inputs near the float range: one step, refused there
        steps = float(np.max(np.abs(target - start) / input_scale(clm), initial=0)) / INPUT_STEP
    n = min(MAX_INPUT_STEPS, math.ceil(steps)) if math.isfinite(steps) else 1
    path = q
    try:
        for k in range(1, n):
            path = assemble_within_limits(clm, start + k / n * (target - start), path,
                                          jacobian=False, check_limits=check_limits).q  # fmt: skip
    except (AssemblyError, InvalidInputError, SingularConfigurationError):
        path = q
    return assemble_within_limits(clm, target, path, jacobian=jacobian, check_limits=check_limits)
