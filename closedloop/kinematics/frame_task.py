"""What a frame's pose must meet: a target pose and the task that says which of its
components count, as residual rows and their Jacobian (the equations of
:mod:`closedloop.kinematics.inverse` beside the closures).

A target is a pose in Pinocchio's XYZQUAT convention, (x, y, z [m], qx, qy, qz, qw),
world axes, or a :class:`pinocchio.SE3`. The tasks (:data:`TASKS`):

* ``"pose"``: the position and the orientation, 6 rows: p - p* [m] and the rotation
  vector log3(R R*^T) [rad], world axes;
* ``"tool-axis"``: the position and the direction of the frame's z axis, 5 rows:
  p - p* and (x*.z, y*.z), the components of the frame's z along the target's x and y
  axes (direction cosines, rad to first order); the rotation about z is free;
* ``"position"``: p - p*, 3 rows; the orientation is free.

A task's free components are those its rows do not see: the rotation about the tool axis,
the whole orientation.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import real_array
from closedloop.exceptions import InvalidInputError

#: Task name -> number of conditions (residual rows).
TASKS = {"pose": 6, "tool-axis": 5, "position": 3}
#: Largest departure of a target's quaternion from norm 1 that is normalised away (seven
#: typed digits are within it); a further one is refused.
QUATERNION_NORM_TOL = 1e-6


def check_task(task) -> str:
    """The task name, or InvalidInputError listing :data:`TASKS`."""
    if not isinstance(task, str) or task not in TASKS:
        raise InvalidInputError(f"task {task!r}; expected one of {list(TASKS)}")
    return task


def target_placement(target, name: str = "target") -> pin.SE3:
    """A target pose as a :class:`pinocchio.SE3` (a copy).

    Args:
        target: (7,) XYZQUAT (x, y, z [m], qx, qy, qz, qw), world axes, its quaternion of
            norm 1 to :data:`QUATERNION_NORM_TOL` (normalised), or a ``pinocchio.SE3``.
        name: the argument, for messages.

    Raises:
        InvalidInputError: not 7 finite numbers, a quaternion not of norm 1, an SE3 that
            is not finite.
    """
    if isinstance(target, pin.SE3):
        if not (np.isfinite(target.translation).all() and np.isfinite(target.rotation).all()):
            raise InvalidInputError(f"{name} must be a finite pose, got {target}")
        return target.copy()
    x = real_array(target, name).reshape(-1)
    if x.shape != (7,) or not np.isfinite(x).all():
        raise InvalidInputError(
            f"{name} must be 7 finite numbers x y z [m] qx qy qz qw (XYZQUAT, world axes), "
            f"got {x.tolist()}"
        )
    norm = math.sqrt(float(x[3:] @ x[3:]))
    if abs(norm - 1.0) > QUATERNION_NORM_TOL:
        raise InvalidInputError(
            f"{name}'s quaternion (qx qy qz qw) = {x[3:].tolist()} has norm {norm:.9g}; "
            f"expected 1 (to {QUATERNION_NORM_TOL:g})"
        )
    x[3:] /= norm
    return pin.XYZQUATToSE3(x)


def xyzquat(M: pin.SE3) -> np.ndarray:
    """(7,) XYZQUAT of a placement, its quaternion with qw >= 0."""
    x = np.asarray(pin.SE3ToXYZQUAT(M), dtype=float).copy()
    if x[6] < 0.0:
        x[3:] *= -1.0
    return x


def pose_error(M: pin.SE3, reference: pin.SE3) -> np.ndarray:
    """(6,) pose of M from ``reference``: translation p - p_ref [m], then the rotation
    vector log3(R R_ref^T) [rad], world axes."""
    return np.concatenate(
        [M.translation - reference.translation, pin.log3(M.rotation @ reference.rotation.T)]
    )


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


class FrameTask:
    """A task and its target: the residual rows a frame's pose must zero.

    Args:
        kind: the task (:data:`TASKS`).
        target: the target pose (validated: :func:`target_placement`).

    Attributes:
        kind, target: as given.
        size: the number of rows.
        linear: (size,) read-only bool, True for the rows in metres.
    """

    def __init__(self, kind: str, target: pin.SE3):
        self.kind, self.target = kind, target
        self.size = TASKS[kind]
        self.linear = np.arange(self.size) < 3
        self.linear.flags.writeable = False

    def residual(self, M: pin.SE3) -> np.ndarray:
        """(size,) rows at the frame placement M [m; rad] (module docstring)."""
        p = M.translation - self.target.translation
        if self.kind == "position":
            return p
        if self.kind == "pose":
            return np.concatenate([p, pin.log3(M.rotation @ self.target.rotation.T)])
        return np.concatenate([p, self.target.rotation[:, :2].T @ M.rotation[:, 2]])

    def jacobian(self, M: pin.SE3, J: np.ndarray) -> np.ndarray:
        """(size, nv) Jacobian of :meth:`residual` from the frame's Jacobian J (6, nv)
        (twist at its origin, world-aligned axes, ``pin.LOCAL_WORLD_ALIGNED``).

        The frame turns at w = J[3:] dq (world): R moves to exp(w) R, so R R*^T to
        exp(w) R R*^T = (R R*^T) exp((R R*^T)^T w), whose log3 moves by
        Jlog3(R R*^T) (R R*^T)^T w; the z axis moves by w x z, so x*.z by (z x x*).w.
        """
        if self.kind == "position":
            return J[:3]
        if self.kind == "pose":
            E = M.rotation @ self.target.rotation.T
            return np.vstack([J[:3], pin.Jlog3(E) @ E.T @ J[3:]])
        z = M.rotation[:, 2]
        axes = self.target.rotation[:, :2]
        return np.vstack([J[:3], (_skew(z) @ axes).T @ J[3:]])

    def flipped(self, M: pin.SE3) -> bool:
        """Whether the frame's z axis at M points against the target's (a tool-axis
        task's rows vanish there too, on a branch that is not the task)."""
        return (
            self.kind == "tool-axis" and float(M.rotation[:, 2] @ self.target.rotation[:, 2]) <= 0
        )

    def completed(self, M: pin.SE3) -> pin.SE3:
        """The target with its free components taken from the placement M: for
        ``tool-axis`` the rotation of M followed by the shortest turn of its z axis onto
        the target's; for ``position`` M's orientation; the target itself for ``pose``."""
        if self.kind == "pose":
            return self.target.copy()
        if self.kind == "position":
            return pin.SE3(M.rotation, self.target.translation)
        z, z_goal = M.rotation[:, 2], self.target.rotation[:, 2]
        axis = np.cross(z, z_goal)
        s, c = float(np.linalg.norm(axis)), float(z @ z_goal)
        if s < 1e-12 and c < 0.0:  # opposite: any axis across z
            axis, s = M.rotation[:, 0], 1.0
        turn = pin.exp3(axis / s * math.atan2(s, c)) if s > 0.0 else np.eye(3)
        return pin.SE3(turn @ M.rotation, self.target.translation)

    def at(self, target: pin.SE3) -> FrameTask:
        """The same task with another target."""
        return FrameTask(self.kind, target)


def interpolate(start: pin.SE3, end: pin.SE3, s: float) -> pin.SE3:
    """The pose a fraction s (0 to 1) of the way from ``start`` to ``end``: the position
    on the segment, the orientation turned by s times the rotation between them (world
    axes)."""
    turn = pin.log3(end.rotation @ start.rotation.T)
    p = start.translation + s * (end.translation - start.translation)
    return pin.SE3(pin.exp3(s * turn) @ start.rotation, p)


def distance(a: pin.SE3, b: pin.SE3) -> tuple[float, float]:
    """(distance between the origins [m], angle between the orientations [rad])."""
    return (
        float(np.linalg.norm(a.translation - b.translation)),
        float(np.linalg.norm(pin.log3(a.rotation @ b.rotation.T))),
    )
