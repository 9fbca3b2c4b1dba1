"""Inverse kinematics of closed-loop models: an assembled configuration whose frame meets a
target pose (:mod:`closedloop.kinematics.frame_task`), serial, parallel or hybrid alike.

The unknowns are the actuated and the passive coordinates; the joints with a spring (not
actuated) and the locked ones keep their values of the start (their rest values). The
equations are the closures and the task's rows, solved together by the assembly's
Gauss-Newton steps (:func:`closedloop.kinematics.assembly.descend`: minimum-norm
least-squares steps, halved until the residual falls), to :data:`IK_TOL` (metres per
characteristic length L, radians), the assembly's own tolerance.

**The branch followed.** The frame goes from its pose at the start q0, assembled, to the
target along a straight way (the position on the segment, the orientation turned about
one axis; :func:`closedloop.kinematics.frame_task.interpolate`), in steps of at most
:data:`TARGET_STEP` (in L and rad), each solved from the last, halved where one does not
converge: the answer is the configuration continuous from q0 along that way, the same
branch (elbow up or down, a leg's assembly mode) as q0. A way that leaves the workspace
or crosses a singular pose ends there: the error says where and how far the target was.
With a task that leaves the frame's pose free in part (``"tool-axis"``, ``"position"``)
the free components move as little as the minimum-norm steps move them.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pinocchio as pin

from closedloop.common.conditioning import rule_rank, svd
from closedloop.exceptions import (
    OutsideLimitsError,
    SingularConfigurationError,
    UnreachableError,
)
from closedloop.kinematics.assembly import (
    ASSEMBLY_TOL,
    INPUT_STEP,
    Assembly,
    close_loops,
    coordinate_scale,
    descend,
    free_coordinates,
    within,
)
from closedloop.kinematics.constraints import frame_jacobian_rows, jacobian_rows, residual_rows
from closedloop.kinematics.frame_task import (
    FrameTask,
    check_task,
    distance,
    interpolate,
    target_placement,
)
from closedloop.kinematics.limits import describe_limits, joints_outside_limits
from closedloop.model.closed_loop import ClosedLoopModel

#: Tolerance of the inverse kinematics, closures and task rows alike: metres per
#: characteristic length L, radians (the assembly's).
IK_TOL = ASSEMBLY_TOL
#: Largest move of the target per continuation step: INPUT_STEP L of the position and
#: INPUT_STEP rad of the orientation (the assembly's step of the inputs).
TARGET_STEP = INPUT_STEP
#: Gauss-Newton iterations per continuation step.
MAX_ITER = 30
#: A continuation step that does not converge is halved, one that converges doubles the
#: next (up to TARGET_STEP); the target counts as unreachable when a step falls below
#: 2^-MAX_HALVINGS TARGET_STEP (5e-5 L) or after MAX_FAILURES steps that failed (a way
#: that creeps up to the workspace's boundary in ever smaller steps).
MAX_HALVINGS, MAX_FAILURES = 10, 30


def inverse_kinematics(
    model: ClosedLoopModel,
    frame: str,
    target,
    *,
    task: str = "pose",
    q0: np.ndarray | None = None,
    check_limits: bool = True,
) -> Assembly:
    """An assembled configuration whose ``frame`` meets ``target`` (module docstring).

    Args:
        model: the model (closures, actuated joints, springs).
        frame: the frame that meets the target (its origin and axes).
        target: (7,) XYZQUAT pose (x, y, z [m], qx, qy, qz, qw), world axes, or a
            ``pinocchio.SE3``.
        task: ``"pose"`` (6 conditions), ``"tool-axis"`` (the position and the direction
            of the frame's z axis: 5; the rotation about z is free) or ``"position"`` (3).
        q0: (nq,) start: its branch is followed (default: the model's reference
            configuration, :meth:`ClosedLoopModel.reference_configuration`), assembled first
            with its own actuated values.
        check_limits: refuse an answer outside the joints' position limits.

    Returns:
        The :class:`~closedloop.kinematics.assembly.Assembly`: q closes every loop and
        meets the task's rows to :data:`IK_TOL` (``iterations``: the Gauss-Newton
        iterations of the whole way).

    Raises:
        UnreachableError: the way from q0 to the target ends before it (the workspace's
            boundary, or a singular pose on the way); the message and the error's
            ``distance`` give what was left.
        SingularConfigurationError: the target is met at a singular pose (the task's rows
            lose rank there: the branch is not determined), or q0 is singular.
        OutsideLimitsError: ``check_limits`` and the answer has joints outside their
            limits (named, with their values).
        AssemblyError: q0 cannot be assembled.
        InvalidInputError, NameNotFoundError: a bad target, task, q0 or frame.
    """
    clm = model
    clm.frame_id(frame)
    goal = FrameTask(check_task(task), target_placement(target))
    q = clm.check_configuration(clm.reference_configuration() if q0 is None else q0)
    return reach(clm, frame, goal, np.array(close_loops(clm, q).q), check_limits=check_limits)


class _Rows:
    """The equations of the inverse kinematics: the closures, then the task's rows."""

    def __init__(self, clm: ClosedLoopModel, frame: str, task: FrameTask, tol: float):
        self.clm, self.frame, self.fid, self.task = clm, frame, clm.frame_id(frame), task
        L = clm.length
        rows = np.where(np.concatenate([clm.linear_rows, task.linear]), tol * L, tol)
        self.tols = (rows, float(rows.min()), float(rows.max()))

    def residual(self, q: np.ndarray) -> tuple[np.ndarray, float, bool]:
        clm = self.clm
        data, datas = clm.workspace()
        pin.computeJointJacobians(clm.model, data, q)
        M = pin.updateFramePlacement(clm.model, data, self.fid)
        r = np.concatenate([residual_rows(clm, data, datas), self.task.residual(M)])
        return (r, *within(r, self.tols))

    def jacobian(self) -> np.ndarray:
        clm = self.clm
        data, datas = clm.workspace()
        J = frame_jacobian_rows(clm, data, self.frame, "world")
        task = self.task.jacobian(data.oMf[self.fid], J)
        return np.vstack([jacobian_rows(clm, data, datas, calc=False), task])

    def placement(self) -> pin.SE3:
        """The frame's placement at the q last evaluated."""
        return self.clm.workspace()[0].oMf[self.fid].copy()


def moved_coordinates(clm: ClosedLoopModel) -> np.ndarray:
    """(p,) tangent indices the inverse kinematics moves: the passive and the actuated
    coordinates (once per model)."""
    return clm.memo(
        "ik_coordinates",
        lambda: np.union1d(free_coordinates(clm), clm.actuated_v_indices),
    )


def _solve(clm: ClosedLoopModel, rows: _Rows, q: np.ndarray):
    """Gauss-Newton on ``rows`` from q: (q, converged, iterations)."""
    moved = moved_coordinates(clm)
    r, size2, ok = rows.residual(q)
    it = 0
    while not ok and it < MAX_ITER:
        found = descend(clm, q, r, size2, moved, None, rows=(rows.residual, rows.jacobian))
        if found is None:
            break
        q, r, size2, ok = found
        it += 1
    return q, ok, it


def reach(
    clm: ClosedLoopModel,
    frame: str,
    task: FrameTask,
    q: np.ndarray,
    *,
    check_limits: bool = True,
    tol: float = IK_TOL,
) -> Assembly:
    """:func:`inverse_kinematics` from an assembled q (nq,) (closed to
    :data:`closedloop.kinematics.configuration.CLOSURE_TOL`), its arguments checked: the
    continuation of the module docstring, then the answer checked (regular, within the
    limits)."""
    rows = _Rows(clm, frame, task, tol)
    generic = _rank_loss(clm, rows, q)[0]  # rows the mechanism never moves (a planar one's z)
    start = rows.placement()
    goal = task.completed(start)
    d_t, d_r = distance(start, goal)
    n = max(1, math.ceil(max(d_t / clm.length, d_r) / TARGET_STEP))
    s, ds, failures, iterations = 0.0, 1.0 / n, 0, 0
    while s < 1.0:
        s_try = 1.0 if s + ds >= 1.0 - 1e-12 else s + ds
        rows.task = task if s_try == 1.0 else task.at(interpolate(start, goal, s_try))
        q_new, ok, it = _solve(clm, rows, q)
        iterations += it
        if ok and not task.flipped(rows.placement()):
            q, s, ds = q_new, s_try, min(2.0 * ds, 1.0 / n)
            continue
        failures += 1
        ds *= 0.5
        if failures > MAX_FAILURES or ds < 0.5**MAX_HALVINGS / n:
            raise _unreachable(clm, rows, task, q, s, generic)
    a = close_loops(clm, q, tol=tol)  # an Assembly, checked regular (not a change point)
    _check_pose(clm, rows, a.q, generic)
    bad = joints_outside_limits(clm, a.q)
    if bad and check_limits:
        raise OutsideLimitsError(
            f"frame {frame!r} of {clm.name!r} meets its target ({_described(task)}) with "
            f"joints outside their limits: {describe_limits(bad)}",
            bad,
        )
    return dataclasses.replace(a, iterations=iterations + a.iterations)


def _described(task: FrameTask) -> str:
    """The target of a task, for messages: position [m] and, where the task fixes it, the
    orientation or the axis."""
    p = ", ".join(f"{x:.6g}" for x in task.target.translation)
    if task.kind == "position":
        return f"position ({p}) m"
    if task.kind == "tool-axis":
        z = ", ".join(f"{x:.6g}" for x in task.target.rotation[:, 2])
        return f"position ({p}) m, z axis ({z})"
    quat = ", ".join(f"{x:.6g}" for x in pin.Quaternion(task.target.rotation).coeffs())
    return f"position ({p}) m, quaternion ({quat})"


def _rank_loss(clm: ClosedLoopModel, rows: _Rows, q: np.ndarray) -> tuple[int, float]:
    """(rows of the task that the coordinates cannot move at q, smallest relative singular
    value) of the stacked Jacobian, unit-free (rows in metres per L, lengths in L)."""
    rows.residual(q)
    J = rows.jacobian()
    m = clm.n_constraints
    scale_rows = np.where(np.concatenate([clm.linear_rows, rows.task.linear]), 1 / clm.length, 1)
    moved = moved_coordinates(clm)
    if not moved.size:
        return rows.task.size, 0.0
    A = J[:, moved] * scale_rows[:, None] * coordinate_scale(clm)[moved]
    s = svd(A, False)[1]
    closure = rule_rank(svd(A[:m], False)[1]) if m else 0
    full = rule_rank(s) if s.size else 0
    lost = closure + rows.task.size - full
    smallest = float(s[-1] / s[0]) if s.size and s[0] > 0 else 0.0
    return lost, smallest


def _check_pose(clm: ClosedLoopModel, rows: _Rows, q: np.ndarray, generic: int) -> None:
    """Refuse a configuration at which the task's rows lose rank (a singular pose): more of
    them than the ``generic`` ones lost at the start (rows the mechanism moves nowhere near,
    a planar mechanism's out-of-plane ones, are not a singularity)."""
    lost, smallest = _rank_loss(clm, rows, q)
    if lost > generic:
        raise SingularConfigurationError(
            f"frame {rows.frame!r} of {clm.name!r} meets its target ({_described(rows.task)}) "
            f"at a singular pose: the joints cannot move it along {lost - generic} of the task's "
            f"{rows.task.size} directions there (unit-free singular value ratio "
            f"{smallest:.1e}), so the branch is not determined; give a target away from it"
        )


def _unreachable(clm: ClosedLoopModel, rows: _Rows, task: FrameTask, q, s: float, generic: int):
    """The UnreachableError of a way that stops at the fraction s, at q (``generic``: the
    task's rows lost at the start, :func:`_check_pose`)."""
    rows.task = task
    r = rows.residual(q)[0]
    M = rows.placement()
    left = distance(M, task.completed(M))
    lost = _rank_loss(clm, rows, q)[0] - generic
    where = (
        f", at a singular pose (the joints cannot move the frame along {lost} of the task's "
        "directions there: the workspace's boundary or a singularity on the way)"
        if lost > 0
        else ""
    )
    return UnreachableError(
        f"frame {rows.frame!r} of {clm.name!r} cannot reach its target ({_described(task)}) "
        f"from the start's branch: the way stops {s:.3g} of the way there{where}, "
        f"{left[0]:.6g} m and {left[1]:.6g} rad from it; give a reachable target, or a start "
        "q0 on a branch that reaches it",
        left,
        s,
        float(np.max(np.abs(r))),
    )
