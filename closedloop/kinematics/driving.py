"""The actuated inputs driven to their values within the joints' limits: the assembly of
a map's points and of the command line's ``--actuated``, on the assembly mode of a start
configuration (:func:`closedloop.kinematics.assembly.drive`, the rule of
:func:`closedloop.kinematics.assembly.assemble` with the limits checked).
"""

from __future__ import annotations

import numpy as np

from closedloop.exceptions import InvalidInputError
from closedloop.kinematics.assembly import (
    INPUT_STEP,
    MAX_INPUT_STEPS,
    Assembly,
    check_actuated,
    close_at,
    drive,
    input_scale,
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


def _limits(clm: ClosedLoopModel, check_limits: bool):
    """The ``check`` of :func:`closedloop.kinematics.assembly.drive` that refuses actuated
    values outside their joints' limits (the rule of :func:`joints_outside_limits`), or
    None without ``check_limits``."""

    def check(q: np.ndarray) -> None:
        bad = {n: v for n, v in joints_outside_limits(clm, q).items() if n in clm.actuated}
        if bad:
            raise InvalidInputError(
                f"actuated joints outside their limits: {describe_limits(bad)}"
                + degrees_hint(clm, bad, "actuated values are")
            )

    return check if check_limits else None


def assemble_within_limits(
    clm: ClosedLoopModel,
    actuated: np.ndarray,
    q0: np.ndarray | None = None,
    *,
    jacobian: bool = True,
    check_limits: bool = True,
) -> Assembly:
    """One solve of actuated values (n_act,) [rad, m] inside the position limits of their
    joints (the rule of :func:`joints_outside_limits`) from q0 (nq,; default: the
    reference configuration), a step of a sweep; ``jacobian`` as for
    :func:`closedloop.kinematics.assembly.assemble`; ``check_limits`` False: wherever the
    values are (the command line's ``--no-limits``).

    Raises:
        InvalidInputError: bad ``actuated`` or ``q0`` (as for ``assemble``), or an
            actuated value outside its joint's limits with ``check_limits`` (an ``invalid``
            point of a map: the robot cannot be driven there).
        AssemblyError: the loops cannot be closed.
        SingularConfigurationError: they close at a singular configuration only.
    """
    q = clm.check_configuration(clm.reference_configuration() if q0 is None else q0)
    return close_at(clm, q, check_actuated(clm, actuated), jacobian=jacobian,
                    check=_limits(clm, check_limits))  # fmt: skip


def assemble_connected(
    clm: ClosedLoopModel,
    actuated: np.ndarray,
    q0: np.ndarray | None = None,
    *,
    jacobian: bool = True,
    check_limits: bool = True,
) -> Assembly:
    """:func:`closedloop.kinematics.assembly.assemble` of actuated values (n_act,) [rad, m]
    from q0 (nq,; default: the reference configuration), driven there in steps of at most
    :data:`INPUT_STEP` on the assembly mode of q0, with their joints' limits checked on
    the way and at the target (``check_limits`` as for :func:`assemble_within_limits`:
    where a step leaves the limits, the one solve from q0 is taken).

    Raises:
        As :func:`assemble_within_limits`.
    """
    q = clm.check_configuration(clm.reference_configuration() if q0 is None else q0)
    return drive(clm, q, check_actuated(clm, actuated), jacobian=jacobian,
                 check=_limits(clm, check_limits))  # fmt: skip
