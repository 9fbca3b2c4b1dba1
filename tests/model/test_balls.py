"""Ball joints declared in a URDF's closure file (``balls:``) against Pinocchio's own."""

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm

import closedloop as cl

URDF = """<robot name="arm">
  <link name="base"/>
  <link name="upper"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"
    ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="lower"/>
  <link name="tip"/>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1"
    velocity="1"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="lower"/>
    <origin xyz="0.3 0 0" rpy="0.2 -0.1 0.4"/><axis xyz="0 1 0"/><limit lower="-3"
    upper="3" effort="1" velocity="1"/></joint>
  <joint name="wrist" type="fixed"><parent link="lower"/><child link="tip"/>
    <origin xyz="0.25 0.05 -0.02"/></joint>
</robot>
"""
#: The same kinematics and springs computed twice: rounding.
RTOL_SAME = 1e-12


def _files(tmp_path, balls="[elbow]", springs="{shoulder: 100.0, elbow: 40.0}"):
    (tmp_path / "arm.urdf").write_text(URDF)
    (tmp_path / "arm.yaml").write_text(
        f"name_mot: [shoulder]\nsprings: {springs}\nballs: {balls}\n"
    )
    return tmp_path / "arm.urdf", tmp_path / "arm.yaml"


def _reference():
    """The same arm built with Pinocchio's spherical joint at the elbow."""
    m = pin.Model()
    j1 = m.addJoint(0, pin.JointModelRZ(), pin.SE3(np.eye(3), np.array([0, 0, 0.1])), "shoulder")
    R = pin.rpy.rpyToMatrix(0.2, -0.1, 0.4)
    j2 = m.addJoint(j1, pin.JointModelSpherical(), pin.SE3(R, np.array([0.3, 0, 0])), "elbow")
    m.addFrame(pin.Frame("tip", j2, pin.SE3(np.eye(3), np.array([0.25, 0.05, -0.02])),
                         pin.FrameType.OP_FRAME))  # fmt: skip
    return cl.ClosedLoopModel(m, actuated=["shoulder"], springs={"shoulder": 100.0,
                                                                  "elbow": 40.0})  # fmt: skip


def test_ball_equals_a_spherical_joint(tmp_path):
    urdf, yaml = _files(tmp_path)
    arm, ref = cl.load_model(urdf, yaml), _reference()
    assert arm.model.joints[arm.joint_id("elbow")].nv == 6  # free flyer, translations locked
    np.testing.assert_array_equal(arm.stiffness[arm.joint_v_slice("elbow")],
                                  [np.inf] * 3 + [40.0] * 3)  # fmt: skip
    rot = pin.exp3(np.array([0.3, -0.2, 0.5]))  # the ball turned
    q = pin.neutral(arm.model)
    q[arm.model.joints[arm.joint_id("elbow")].idx_q + 3 :][:4] = pin.Quaternion(rot).coeffs()
    q_ref = pin.neutral(ref.model)
    q_ref[ref.model.joints[ref.joint_id("elbow")].idx_q :][:4] = pin.Quaternion(rot).coeffs()
    a, b = cl.compliance(arm, q, "tip"), cl.compliance(ref, q_ref, "tip")
    assert_close_in_norm(a.C, b.C, RTOL_SAME)
    assert a.rank == b.rank == 4  # shoulder + three ball rotations
    assert not (tmp_path / ".arm-balls-").exists() and len(list(tmp_path.iterdir())) == 2


def test_ball_springs_and_names_are_checked(tmp_path):
    urdf, yaml = _files(tmp_path, balls="[knee]")
    with pytest.raises(cl.ModelFileError, match=r"balls: 'knee' is not a joint of .*expected"):
        cl.load_model(urdf, yaml)
    urdf, yaml = _files(tmp_path, balls="[elbow, elbow]")  # not "takes ... got 6"
    with pytest.raises(cl.ModelFileError, match=r"balls names \['elbow'\] more than once"):
        cl.load_model(urdf, yaml)
    urdf, yaml = _files(tmp_path, springs="{shoulder: 100.0, elbow: [1.0, 2.0]}")
    with pytest.raises(cl.ModelFileError, match=r"ball joint 'elbow' takes one stiffness or three"):
        cl.load_model(urdf, yaml)
    urdf, yaml = _files(tmp_path, springs="{shoulder: 100.0, elbow: [10.0, 20.0, 30.0]}")
    k = cl.load_model(urdf, yaml).stiffness
    np.testing.assert_array_equal(k[-6:], [np.inf] * 3 + [10.0, 20.0, 30.0])


def test_a_ball_spring_given_as_keyword_acts_on_its_rotations(tmp_path):
    """springs={"elbow": 7.0} made the ball's locked translations 7 N/m springs; three
    values were refused as "expected 1 or 6". The keyword's spring is the file's."""
    urdf, yaml = _files(tmp_path, springs="{shoulder: 100.0}")
    for given, rotations in ((7.0, [7.0] * 3), ([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])):
        k = cl.load_model(urdf, yaml, springs={"elbow": given}).stiffness
        np.testing.assert_array_equal(k[-6:], [np.inf] * 3 + rotations)
    urdf, yaml = _files(tmp_path, springs="{shoulder: 100.0, elbow: 40.0}")
    k = cl.load_model(urdf, yaml, springs={"elbow": 7.0}).stiffness  # over the file's
    np.testing.assert_array_equal(k[-6:], [np.inf] * 3 + [7.0] * 3)
    with pytest.raises(cl.ModelFileError, match=r"load_model springs=: ball joint 'elbow' "
                       r"takes one stiffness or three .*got 2"):  # fmt: skip
        cl.load_model(urdf, yaml, springs={"elbow": [1.0, 2.0]})


def test_a_locked_ball_is_locked_whole(tmp_path):
    """A ball under locked: was refused as "locked and given springs" with none given."""
    urdf, yaml = _files(tmp_path, springs="{shoulder: 100.0}")
    yaml.write_text(yaml.read_text() + "locked: [elbow]\n")
    clm = cl.load_model(urdf, yaml)
    np.testing.assert_array_equal(clm.stiffness[-6:], np.inf)
    res = cl.compliance(clm, pin.neutral(clm.model), "tip")
    assert res.rank == 1  # the shoulder alone
