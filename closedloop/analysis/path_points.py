"""The statics of a path's points, one after the other, each warm-started from the last: the
loaded equilibrium with the actuators at the unloaded commands, the exact compensation and
the first-order one (:mod:`closedloop.elastostatics.compensation`).

At each point, with q_t the unloaded configuration that meets the target (the inverse
kinematics) and P its frame's pose (the programmed pose):

* ``q_loaded``: the equilibrium under the load with the actuators at q_t's values; the
  ``error`` is its frame's pose from P;
* ``commands``, ``q_compensated``: the exact compensation, whose frame meets the compensated
  rows (:func:`compensated_rows`) at P; the ``residual`` is its pose from P;
* the first-order compensation: the deflection of the linear model at q_t (C w for a wrench
  alone, :func:`~closedloop.elastostatics.compensation.linear_deflection`) mirrored, P moved
  against it, and its inverse kinematics: ``commands_first_order``; the equilibrium there
  leaves ``residual_first_order``, a second-order error that the exact compensation removes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.elastostatics.compensation import (
    branch_sign,
    compensate,
    extrapolated,
    linear_deflection,
    loaded_equilibrium,
    rest_at,
)
from closedloop.exceptions import EquilibriumError, JointLimitError
from closedloop.kinematics.constraints import frame_jacobian, update_kinematics
from closedloop.kinematics.frame_task import FrameTask, pose_error
from closedloop.kinematics.inverse import reach
from closedloop.kinematics.limits import describe_limits, joints_outside_limits
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.gravity import GravityLoad, Load

#: Actuated joints from which the compensation holds the whole pose of the frame (the
#: rotation a task leaves free included); with fewer, it holds the task's rows.
WHOLE_POSE_ACTUATORS = 6


def compensated_rows(clm: ClosedLoopModel, task: str) -> str:
    """The task the compensation meets: ``"pose"`` (the whole programmed pose, the free
    rotation of a ``tool-axis`` or ``position`` task as the inverse kinematics chose it)
    when the model has :data:`WHOLE_POSE_ACTUATORS` actuated joints or more, else the
    path's task (a 5-axis machine holds the tool's position and axis, not the rotation
    about it)."""
    return "pose" if len(clm.actuated) >= WHOLE_POSE_ACTUATORS else task


def placement(clm: ClosedLoopModel, q: np.ndarray, frame: str) -> pin.SE3:
    """The frame's placement at q (nq,) (a copy; the kinematics of q left in ``clm.data``)."""
    update_kinematics(clm, q)
    return clm.data.oMf[clm.frame_id(frame)].copy()


@dataclass(frozen=True)
class PointStatics:
    """A path point's statics (arrays of :class:`~closedloop.analysis.path_results.PathResult`
    for one point; SI, world axes, at the frame origin)."""

    q_loaded: np.ndarray
    error: np.ndarray
    commands: np.ndarray
    q_compensated: np.ndarray
    residual: np.ndarray
    commands_first_order: np.ndarray
    deflection_first_order: np.ndarray
    residual_first_order: np.ndarray


class PathStatics:
    """The statics of consecutive path points (module docstring), each Newton started from
    the last two points' answers extrapolated along the path
    (:func:`~closedloop.elastostatics.compensation.extrapolated`).

    Args:
        clm: the model.
        frame: the loaded frame.
        held: the task the compensation meets (:func:`compensated_rows`).
        weight: the weight of the links and payloads, or None.
        check_limits: refuse equilibria and commands outside the joints' limits
            (:class:`~closedloop.exceptions.JointLimitError`).
    """

    def __init__(
        self,
        clm: ClosedLoopModel,
        frame: str,
        held: str,
        weight: GravityLoad | None = None,
        check_limits: bool = True,
    ):
        self.clm, self.frame, self.held = clm, frame, held
        self.weight, self.check_limits = weight, check_limits
        # the last two points' q_target, q_loaded, q_compensated and tau, the older first
        self._last: list[tuple] = []

    def solve(self, q_target: np.ndarray, wrench: np.ndarray) -> PointStatics:
        """The statics of the point whose unloaded configuration is q_target (nq,),
        assembled, under ``wrench`` (6,) [N, N m] (and the weight).

        Raises:
            EquilibriumError: a limit load, or iterations that fail;
                :class:`JointLimitError` with ``check_limits``.
            MechanismError, SingularConfigurationError: as the statics.
        """
        clm, frame, last = self.clm, self.frame, self._last
        load = Load(np.asarray(wrench, dtype=float), self.weight)
        P = placement(clm, q_target, frame)
        warm, sign = (
            (None, None)
            if not last
            else (extrapolated(clm, q_target, [(x[0], x[1]) for x in last]), last[-1][3])
        )
        q_loaded, tau = loaded_equilibrium(
            clm, frame, q_target, load, warm, sign=sign, enforce_limits=self.check_limits
        )
        task = FrameTask(self.held, P)
        start = extrapolated(clm, q_target, [(x[0], x[2]) for x in last]) if last else q_loaded
        comp = compensate(clm, frame, task, q_target, load, start)
        rest = rest_at(clm, q_target, comp.commands)
        if branch_sign(clm, frame, rest, comp.q, load) * tau <= 0.0:
            raise EquilibriumError(
                f"the deflection of frame {frame!r} of {clm.name!r} cannot be compensated on "
                "the branch from rest: the compensated equilibrium lies past a singular "
                "configuration of the loaded mechanism (its tangent stiffness changes sign)",
                comp.closure_residual,
                comp.force_residual,
                1.0,
            )
        if self.check_limits:
            self._check_limits(comp.q, rest, comp.closure_residual)
        twist = frame_jacobian(clm, q_target, frame) @ linear_deflection(clm, q_target, frame, load)
        mirrored = pin.SE3(pin.exp3(-twist[3:]) @ P.rotation, P.translation - twist[:3])
        first = np.array(reach(clm, frame, task.at(mirrored), q_target, check_limits=False).q)
        q_first, _ = loaded_equilibrium(  # near the compensated one, on its branch
            clm, frame, first, load, comp.q, enforce_limits=False, stability=False
        )
        self._last = [*last[-1:], (q_target, q_loaded, comp.q, tau)]
        return PointStatics(
            q_loaded=q_loaded,
            error=pose_error(placement(clm, q_loaded, frame), P),
            commands=comp.commands,
            q_compensated=comp.q,
            residual=pose_error(placement(clm, comp.q, frame), P),
            commands_first_order=clm.actuated_values(first),
            deflection_first_order=twist,
            residual_first_order=pose_error(placement(clm, q_first, frame), P),
        )

    def _check_limits(self, q: np.ndarray, rest: np.ndarray, closure: float) -> None:
        """JointLimitError when the compensated equilibrium q or its commands (the rest
        configuration ``rest``) leave the joints' limits."""
        bad = joints_outside_limits(self.clm, q)
        bad.update(
            (n, v) for n, v in joints_outside_limits(self.clm, rest).items()
            if n in self.clm.actuated
        )  # fmt: skip
        if bad:
            raise JointLimitError(
                f"the compensation of frame {self.frame!r} of {self.clm.name!r} drives joints "
                f"beyond their limits: {describe_limits(bad)}",
                closure,
                0.0,
                1.0,
                bad,
            )
