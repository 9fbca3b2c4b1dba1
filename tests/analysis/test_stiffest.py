"""The stiffest posture (issue #42): the rotation about the tool axis chosen against a
brute-force scan whose deflection is written in closed form (a serial arm: the linear
deflection J K^-1 J^T w from Pinocchio's Jacobian), the bounded change between neighbouring
points, and the gain against the default path."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from pinocchio_statics import placement

import closedloop as cl
from closedloop.io.loader import load_urdf
from closedloop.kinematics.frame_task import xyzquat

UR5_JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
              "wrist_2_joint", "wrist_3_joint")  # fmt: skip
#: Springs stiffer at the base than at the wrist [N m/rad], as on a real arm.
SPRINGS = (4e4, 4e4, 2e4, 6e3, 6e3, 6e3)
START = np.array([0.3, -1.4, 1.8, -1.9, -1.57, 0.2])
#: A milling force across the spindle's axis [N].
WRENCH = np.array([-50.0, 60.0, 0.0, 0.0, 0.0, 0.0])
#: Brute-force scan of the whole turn: its step [rad].
SCAN_STEP = np.radians(1.0)
#: The chosen angle is the refined optimum (to 1e-6 rad): it deflects no more than the
#: scan's best angle, up to rounding (1e-9 of the deflection).
RTOL_DEFLECTION = 1e-9


@pytest.fixture(scope="module")
def spindle(ur5_urdf):
    """The UR5 with a spindle whose axis is parallel to the flange's, 12 cm off it and 10 cm
    beyond: a turn about the spindle's axis swings the wrist around it."""
    ur5 = load_urdf(ur5_urdf, springs=dict(zip(UR5_JOINTS, SPRINGS, strict=True)), geometry=False)
    model = pin.Model(ur5.model)
    f = model.frames[model.getFrameId("tool0")]
    head = pin.SE3(np.eye(3), np.array([0.12, 0.0, 0.1]))
    model.addFrame(
        pin.Frame("spindle", f.parentJoint, f.parentFrame, f.placement * head, pin.OP_FRAME)
    )
    return cl.ClosedLoopModel(model, actuated=ur5.actuated, springs=ur5.springs, name="spindle")


def _deflection(clm, q) -> float:
    """|J K^-1 J^T w|_xyz [m] at q, from Pinocchio's Jacobian (a serial arm)."""
    data = clm.model.createData()
    J = pin.computeFrameJacobian(
        clm.model, data, q, clm.model.getFrameId("spindle"), pin.LOCAL_WORLD_ALIGNED
    )
    return float(np.linalg.norm((J @ ((J.T @ WRENCH) / np.array(SPRINGS)))[:3]))


def _targets(clm, n: int, step=(0.0, 0.01, 0.0)) -> np.ndarray:
    M = placement(clm.model, START, "spindle")
    R = pin.utils.rotate("x", np.pi)  # the spindle's axis down
    return np.array([xyzquat(pin.SE3(R, M.translation + k * np.array(step))) for k in range(n)])


def test_one_point_is_the_best_of_a_scan_of_the_whole_turn(spindle):
    target = _targets(spindle, 1)
    r = cl.follow_path(spindle, "spindle", target, wrench=WRENCH, task="tool-axis", q0=START,
                       stiffest=True)  # fmt: skip
    default = cl.inverse_kinematics(spindle, "spindle", target[0], task="tool-axis", q0=START)
    M = placement(spindle.model, default.q, "spindle")
    scanned = {}
    for sign in (1.0, -1.0):  # walked from the default posture, each from the last
        q = default.q
        for psi in sign * np.arange(0.0, np.pi, SCAN_STEP):
            pose = xyzquat(pin.SE3(M.rotation @ pin.utils.rotate("z", psi), M.translation))
            try:
                q = cl.inverse_kinematics(spindle, "spindle", pose, q0=q).q
            except cl.ClosedLoopError:
                break
            scanned[psi] = _deflection(spindle, q)
    best = min(scanned, key=scanned.get)
    chosen = r.stiffest.free[0, 0]
    assert r.stiffest.deflection[0] <= scanned[best] * (1 + RTOL_DEFLECTION)
    assert abs(chosen - best) <= SCAN_STEP
    np.testing.assert_allclose(r.stiffest.deflection[0], _deflection(spindle, r.q_target[0]),
                               rtol=1e-10)  # fmt: skip
    np.testing.assert_allclose(r.stiffest.default_deflection[0], scanned[0.0], rtol=1e-10)
    assert max(scanned.values()) > 1.2 * scanned[best]  # the turn matters: a real choice


def test_path_changes_by_at_most_max_change_and_deflects_less_in_all(spindle):
    targets = _targets(spindle, 4)
    r = cl.follow_path(spindle, "spindle", targets, wrench=WRENCH, task="tool-axis", q0=START,
                       stiffest=True, max_change=0.05)  # fmt: skip
    free = r.stiffest.free[:, 0]
    assert np.all(np.abs(np.diff(free)) <= 0.05 + 1e-12)
    assert r.stiffest.deflection.sum() <= r.stiffest.default_deflection.sum()
    q = START
    for i, target in enumerate(targets):  # the default path, and the chosen one's poses
        q = cl.inverse_kinematics(spindle, "spindle", target, task="tool-axis", q0=q).q
        np.testing.assert_allclose(r.stiffest.default_deflection[i], _deflection(spindle, q),
                                   rtol=1e-10)  # fmt: skip
        M, C = placement(spindle.model, q, "spindle"), placement(spindle.model, r.q_target[i],
                                                                 "spindle")  # fmt: skip
        np.testing.assert_allclose(C.translation, M.translation, atol=1e-12)
        turn = pin.log3(M.rotation.T @ C.rotation)
        np.testing.assert_allclose(turn, [0.0, 0.0, free[i]], atol=1e-10)
    np.testing.assert_allclose(r.residual, 0.0, atol=1e-12)


def test_position_task_turns_the_orientation(spindle):
    """A 'position' task leaves the whole orientation free: the first point's search
    starts at the default posture, so it deflects no more."""
    r = cl.follow_path(spindle, "spindle", _targets(spindle, 1), wrench=WRENCH,
                       task="position", q0=START, stiffest=True)  # fmt: skip
    assert r.stiffest.free.shape == (1, 3)
    assert r.stiffest.deflection[0] <= r.stiffest.default_deflection[0]
    np.testing.assert_allclose(r.stiffest.deflection[0], _deflection(spindle, r.q_target[0]),
                               rtol=1e-10)  # fmt: skip


def test_max_change_must_be_positive(spindle):
    with pytest.raises(cl.InvalidInputError, match="max_change"):
        cl.follow_path(spindle, "spindle", _targets(spindle, 1), task="tool-axis",
                       stiffest=True, max_change=0.0)  # fmt: skip
