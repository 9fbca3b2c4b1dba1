"""Inverse kinematics of closed-loop models (issue #42): the frame meets its target, the loops
close, on the start's branch, checked with Pinocchio's kinematics alone and closed forms
(the Stewart platform's leg lengths); typed errors for what cannot be reached."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from helpers import UR5_JOINTS, UR5_Q
from mechanisms import stewart
from pinocchio_statics import gaps, placement
from scipy.spatial.transform import Rotation

import closedloop as cl
from closedloop.io.loader import load_urdf
from closedloop.kinematics.frame_task import FrameTask, pose_error, target_placement, xyzquat

#: The inverse kinematics' tolerance (closure and task rows, metres per L, radians) with
#: a factor 2 for the rounding of recomputing them here (eps times the joints' distance
#: from the origin, 1e-15 m).
ATOL = 2e-12
#: Central-difference step [rad] of the Jacobian checks, and their tolerance relative to
#: the Jacobian's largest entry: truncation h^2 ~ 1e-12, rounding eps / h ~ 2e-10.
FD_STEP, FD_RTOL = 1e-6, 1e-8
#: Agreement of two inverse kinematics answers for one target on one branch [rad]: each
#: meets the task to 1e-12 and the UR5's Jacobian is well conditioned there (cond < 1e3).
ATOL_SAME = 1e-9


@pytest.fixture(scope="module")
def ur5(ur5_urdf):
    return load_urdf(ur5_urdf, springs=dict.fromkeys(UR5_JOINTS, 1e4), geometry=False)


def _target(clm, q, frame):
    return xyzquat(placement(clm.model, q, frame))


@pytest.mark.parametrize("task", ["pose", "tool-axis", "position"])
def test_task_jacobian_is_the_derivative_of_its_rows(ur5, task):
    target = target_placement(_target(ur5, UR5_Q + 0.3, "tool0"))
    rows = FrameTask(task, target)
    data = ur5.model.createData()
    fid = ur5.model.getFrameId("tool0")
    J = pin.computeFrameJacobian(ur5.model, data, UR5_Q, fid, pin.LOCAL_WORLD_ALIGNED)
    analytic = rows.jacobian(placement(ur5.model, UR5_Q, "tool0"), J)
    columns = []
    for i in range(6):
        e = np.zeros(6)
        e[i] = FD_STEP
        plus = rows.residual(placement(ur5.model, pin.integrate(ur5.model, UR5_Q, e), "tool0"))
        minus = rows.residual(placement(ur5.model, pin.integrate(ur5.model, UR5_Q, -e), "tool0"))
        columns.append((plus - minus) / (2 * FD_STEP))
    np.testing.assert_allclose(analytic, np.array(columns).T, atol=FD_RTOL * np.abs(analytic).max())


def test_ur5_pose_on_the_start_branch(ur5):
    """A start near the configuration gives it back; a start with the elbow bent the other
    way reaches the same pose with the elbow on its side (the start's branch)."""
    target = _target(ur5, UR5_Q, "tool0")
    a = cl.inverse_kinematics(ur5, "tool0", target, q0=UR5_Q + 0.2)
    np.testing.assert_allclose(a.q, UR5_Q, atol=ATOL_SAME)
    flipped = UR5_Q * np.array([1, 1, -1, 1, 1, 1]) + 0.1
    b = cl.inverse_kinematics(ur5, "tool0", target, q0=flipped)
    assert np.sign(b.q[2]) == np.sign(flipped[2]) != np.sign(UR5_Q[2])
    for q in (a.q, b.q):
        error = pose_error(placement(ur5.model, q, "tool0"), target_placement(target))
        np.testing.assert_allclose(error, 0.0, atol=ATOL * ur5.length)


def test_ur5_tool_axis_leaves_the_turn_about_the_axis_where_the_start_had_it(ur5):
    """tool0's z axis is the last joint's: the rows see that joint through the rounding of
    its Jacobian column only, and the minimum-norm steps leave it where it was; the
    position and the axis are met."""
    target = _target(ur5, UR5_Q, "tool0")
    start = UR5_Q + np.array([0.1, -0.1, 0.1, 0.1, -0.1, 0.7])
    a = cl.inverse_kinematics(ur5, "tool0", target, task="tool-axis", q0=start)
    np.testing.assert_allclose(a.q[5], start[5], rtol=0, atol=ATOL)  # its column: rounding
    M, goal = placement(ur5.model, a.q, "tool0"), target_placement(target)
    np.testing.assert_allclose(M.translation, goal.translation, atol=ATOL * ur5.length)
    np.testing.assert_allclose(M.rotation[:, 2], goal.rotation[:, 2], atol=ATOL)


def test_position_task_meets_the_position(ur5):
    target = _target(ur5, UR5_Q + 0.2, "tool0")
    a = cl.inverse_kinematics(ur5, "tool0", target, task="position", q0=UR5_Q)
    M = placement(ur5.model, a.q, "tool0")
    np.testing.assert_allclose(M.translation, target[:3], atol=ATOL * ur5.length)


def test_stewart_leg_lengths_are_the_distances_of_the_anchors():
    """The legs of the 6-UPS platform at a target pose are |p + R a_i - b_i| (by hand);
    the closures close and the platform is at the target."""
    start = stewart(position=(0.0, 0.0, 1.0))
    p, R = np.array([0.05, -0.04, 1.1]), Rotation.from_rotvec([0.05, -0.08, 0.1]).as_matrix()
    target = xyzquat(pin.SE3(R, p))
    a = cl.inverse_kinematics(start.clm, "platform", target, q0=start.q)
    g = start.geometry
    lengths = np.linalg.norm(p + g["a"] @ R.T - g["b"], axis=1)
    legs = [a.q[start.clm.model.joints[start.clm.joint_id(f"leg{i}")].idx_q] for i in range(6)]
    np.testing.assert_allclose(legs, lengths, atol=ATOL * start.clm.length)
    np.testing.assert_allclose(gaps(start.clm, a.q), 0.0, atol=ATOL * start.clm.length)
    error = pose_error(placement(start.clm.model, a.q, "platform"), pin.SE3(R, p))
    np.testing.assert_allclose(error, 0.0, atol=ATOL * start.clm.length)


def test_cahyman_tool_axis_gives_back_the_inputs(cahyman):
    """CaHyMan's 5 inputs fix the tool's position and axis: the inverse kinematics of the
    pose at known inputs, from another pose, returns those inputs."""
    inputs = (np.radians([55.0, 62.0, 70.0]), np.radians(40.0), 0.02)
    q = np.array(cahyman.assemble(*inputs))
    start = np.array(cahyman.assemble(np.radians([60.0, 60.0, 60.0]), np.radians(45.0), 0.03))
    target = _target(cahyman.clm, q, "tool")
    a = cl.inverse_kinematics(cahyman.clm, "tool", target, task="tool-axis", q0=start)
    expected = np.r_[inputs[0], inputs[1], inputs[2]]
    np.testing.assert_allclose(cahyman.clm.actuated_values(a.q), expected, atol=ATOL_SAME)
    L = cahyman.clm.length
    np.testing.assert_allclose(gaps(cahyman.clm, a.q), 0.0, atol=ATOL * L)
    M = placement(cahyman.clm.model, a.q, "tool")
    np.testing.assert_allclose(M.translation, target[:3], atol=ATOL * L)
    np.testing.assert_allclose(M.rotation[:, 2], target_placement(target).rotation[:, 2], atol=ATOL)


def test_unreachable_target_says_how_far(ur5):
    target = np.r_[3.0, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0]
    with pytest.raises(cl.UnreachableError, match="cannot reach its target") as info:
        cl.inverse_kinematics(ur5, "tool0", target, task="position", q0=UR5_Q)
    assert info.value.distance[0] > 2.0  # the UR5 reaches about 0.9 m from its base
    assert 0.0 <= info.value.fraction < 1.0


def test_singular_pose_is_refused(ur5):
    """Wrist 2 at zero lines up the axes of wrists 1 and 3: the pose is met there, but the
    joints cannot turn the tool about one axis."""
    q = UR5_Q.copy()
    q[4] = 0.0
    with pytest.raises(cl.SingularConfigurationError, match="singular pose"):
        cl.inverse_kinematics(ur5, "tool0", _target(ur5, q, "tool0"), q0=q + 0.05)


def test_joint_limits_are_named(ur5_urdf):
    ur5 = load_urdf(ur5_urdf, springs=dict.fromkeys(UR5_JOINTS, 1e4), geometry=False)
    ur5.model.upperPositionLimit[2] = 1.0  # the elbow, at 1.5 rad in UR5_Q
    with pytest.raises(cl.OutsideLimitsError, match="elbow_joint") as info:
        cl.inverse_kinematics(ur5, "tool0", _target(ur5, UR5_Q, "tool0"), q0=UR5_Q - 0.6)
    assert "elbow_joint" in info.value.joints
    a = cl.inverse_kinematics(
        ur5, "tool0", _target(ur5, UR5_Q, "tool0"), q0=UR5_Q - 0.6, check_limits=False
    )
    np.testing.assert_allclose(a.q, UR5_Q, atol=ATOL_SAME)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"task": "orientation"}, "expected one of"),
        ({"target": np.zeros(6)}, "7 finite numbers"),
        ({"target": np.r_[0.5, 0, 0.5, 0, 0, 0, 2.0]}, "norm 2"),
        ({"target": np.r_[np.nan, 0, 0.5, 0, 0, 0, 1.0]}, "7 finite numbers"),
    ],
)
def test_bad_input(ur5, kwargs, message):
    args = {"target": np.r_[0.5, 0.1, 0.4, 0, 0, 0, 1.0], **kwargs}
    with pytest.raises(cl.InvalidInputError, match=message):
        cl.inverse_kinematics(ur5, "tool0", args.pop("target"), q0=UR5_Q, **args)


def test_planar_five_bar_meets_a_position():
    """A planar mechanism never moves its frame out of its plane: that row of the position
    task is no singularity; the inputs of a pose come back."""
    clm = cl.load_model(cl.data.path("fivebar5.urdf"), cl.data.path("fivebar5.yaml"))
    q0 = cl.assemble(clm, None, clm.reference_configuration()).q
    inputs = clm.actuated_values(q0) + np.array([0.1, -0.05])
    q1 = cl.assemble(clm, inputs, q0).q
    a = cl.inverse_kinematics(clm, "E", _target(clm, q1, "E"), task="position", q0=q0)
    np.testing.assert_allclose(clm.actuated_values(a.q), inputs, atol=ATOL_SAME)
