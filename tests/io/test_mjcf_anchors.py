"""MJCF ``<connect>`` and ``<weld>`` on bodies without a joint of their own: Pinocchio 4.1
anchors them at the parent joint's origin (closedloop.io.mjcf.anchor_equalities places
them where MuJoCo does). Each file is checked against the same four-bar written with the
equality on the bodies carrying the joints, the anchor moved by hand."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm
from mechanisms import mjcf_fourbar

import closedloop as cl
from closedloop.io.loader import load_model

#: The loop's closing point in the world at the reference configuration [m], the origin of
#: the jointless bodies coupler_tip and rocker_tip of :func:`mechanisms.mjcf_fourbar`
#: (crank hinge at the origin, coupler's at (0, 0, 0.12), rocker's at (0.34, 0, 0)).
CLOSING_POINT = np.array([0.3, 0.0, 0.18])
#: Placements and compliances of one model computed along two descriptions from the same
#: doubles of order 1 (compliance ~1e-5 m/N, relative): a few ulps apart; the misplaced
#: anchor was off by 0.07 m and made the four-bar a mechanism.
TOL = 1e-12


def fourbar(tmp_path: Path, equality: str, name: str):
    path = tmp_path / f"{name}.xml"
    path.write_text(mjcf_fourbar(equality))
    robot = load_model(path, geometry=False)
    return robot, cl.Configuration(robot, robot.reference_configuration())


def world_ends(robot, q) -> tuple[pin.SE3, pin.SE3]:
    """World placements of the two ends of the robot's only closure at q."""
    (closure,) = robot.closures
    c = closure.constraint
    data = robot.model.createData()
    pin.forwardKinematics(robot.model, data, q)
    return data.oMi[c.joint1_id] * c.joint1_placement, data.oMi[c.joint2_id] * c.joint2_placement


def test_connect_on_jointless_bodies_is_anchored_at_their_origin(tmp_path):
    tips, at_tips = fourbar(
        tmp_path, '<connect name="C" body1="coupler_tip" body2="rocker_tip" anchor="0 0 0"/>', "a"
    )
    _, at_joints = fourbar(  # the same point, from the bodies carrying the joints
        tmp_path, '<connect name="C" body1="coupler" body2="rocker" anchor="0.3 0 0.06"/>', "b"
    )
    for end in world_ends(tips, at_tips.q):
        np.testing.assert_allclose(end.translation, CLOSING_POINT, atol=TOL)
    assert at_tips.closure_error < TOL
    assert_close_in_norm(cl.compliance(at_tips, "P").C, cl.compliance(at_joints, "P").C, TOL)


def test_connect_anchor_is_in_body1_frame_and_body2_follows(tmp_path):
    """A nonzero anchor is in body1's frame (rocker_tip: it is the rocker hinge); body2's
    point is where that point is at qpos0."""
    tips, at_tips = fourbar(
        tmp_path,
        '<connect name="C" body1="rocker_tip" body2="coupler_tip" anchor="0.04 0 -0.18"/>',
        "a",
    )
    end1, end2 = world_ends(tips, at_tips.q)
    np.testing.assert_allclose(end1.translation, [0.34, 0, 0], atol=TOL)  # the rocker hinge
    np.testing.assert_allclose(end2.translation, [0.34, 0, 0], atol=TOL)


@pytest.mark.parametrize("relpose", ["", ' relpose="0.1 0 0 1 0 0 0"'])
def test_weld_on_jointless_bodies_is_anchored_at_their_frames(tmp_path, relpose):
    """A weld's anchor is in body2's frame; an explicit relpose (pose in body1's frame of
    the frame welded to body2's anchor, here the one at qpos0) in body1's. Both ends are
    0.1 m along x from the closing point."""
    tips, at_tips = fourbar(
        tmp_path,
        f'<weld name="W" body1="coupler_tip" body2="rocker_tip" anchor="0.1 0 0"{relpose}/>',
        "a",
    )
    joints, at_joints = fourbar(
        tmp_path, '<weld name="W" body1="coupler" body2="rocker" anchor="0.06 0 0.18"/>', "b"
    )
    assert at_tips.closure_error < TOL
    for end, twin in zip(world_ends(tips, at_tips.q), world_ends(joints, at_joints.q), strict=True):
        np.testing.assert_allclose(end.homogeneous, twin.homogeneous, atol=TOL)
        np.testing.assert_allclose(end.translation, CLOSING_POINT + np.array([0.1, 0, 0]), atol=TOL)
