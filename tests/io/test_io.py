"""Loading URDF + closure files, MJCF with <connect>, serial robots, and every error path."""

from __future__ import annotations

import math
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
import yaml
from helpers import assert_close_in_norm

from closedloop.elastostatics.compliance import compliance
from closedloop.exceptions import InvalidInputError, ModelFileError, NameNotFoundError
from closedloop.io.closure_file import read_closure_file, read_springs_file
from closedloop.io.loader import load_model, load_urdf
from closedloop.kinematics.assembly import assemble
from closedloop.kinematics.constraints import closure_residual

# The MJCF and URDF four-bars are the same mechanism read by two parsers; their models
# differ only by rounding (joint placements rebuilt from 16-digit angles, anchors computed
# at qpos0), i.e. ~1e-16 relative, amplified by the assembly and the pseudo-inverse.
RTOL_TWIN = 1e-9
# Closed-form assembled angles vs the 16 digits written in fourbar.xml [rad, m].
ATOL_QPOS0 = 1e-14

# Four-bar dimensions [m], from the comment at the top of urdf/fourbar.urdf.
CRANK, COUPLER, ROCKER, GROUND = 0.1, 0.3, 0.15, 0.3


def fourbar_angles(crank: float) -> tuple[float, float]:
    """(coupler, rocker) joint angles closing the four-bar, upper branch, closed form.

    Joint angles turn about +y: a link along +z at zero points to (sin a, cos a) in
    (x, z); the coupler, along +x of its frame, points to (cos b, -sin b) with b the sum
    of the crank and coupler angles.
    """
    B = CRANK * np.array([math.sin(crank), math.cos(crank)])
    D = np.array([GROUND, 0.0])
    d = np.linalg.norm(D - B)
    a = (COUPLER**2 - ROCKER**2 + d**2) / (2 * d)
    u = (D - B) / d
    C = B + a * u + math.sqrt(COUPLER**2 - a**2) * np.array([-u[1], u[0]])
    coupler = math.atan2(-(C - B)[1], (C - B)[0]) - crank
    rocker = math.atan2((C - D)[0], (C - D)[1])
    return coupler, rocker


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def stiffness_of(clm, joint: str) -> float:
    return float(clm.stiffness[clm.joint_v_slice(joint)][0])


# --------------------------------------------------------------------------- four-bar
def test_fourbar_urdf_and_yaml_as_in_the_files(fourbar_urdf, fourbar_yaml):
    spec = yaml.safe_load(fourbar_yaml.read_text())
    clm = load_urdf(fourbar_urdf, fourbar_yaml)
    assert [(c.name, c.kind) for c in clm.closures] == [
        ("<->".join(spec["closed_loop"][0]), spec["type"][0])
    ]
    assert clm.actuated == tuple(spec["name_mot"])
    for joint, k in spec["springs"].items():
        assert stiffness_of(clm, joint) == float(k)  # YAML 1.1 leaves 1.0e5 a string
    for joint in ("coupler", "rocker"):  # not in the file: passive
        assert stiffness_of(clm, joint) == 0.0
    assert clm.visual_model is not None and clm.visual_model.ngeoms > 0


def test_joint_stiffness_fills_only_actuated_joints_without_spring(fourbar_urdf, tmp_path):
    closures = write(
        tmp_path,
        "c.yaml",
        "closed_loop: [[closedloop1_A, closedloop1_B]]\ntype: ['3d']\n"
        "name_mot: [crank, rocker]\nsprings: {crank: 5.0}\n",
    )
    clm = load_urdf(fourbar_urdf, closures, joint_stiffness=7.0)
    assert stiffness_of(clm, "crank") == 5.0  # given a spring by the file: kept
    assert stiffness_of(clm, "rocker") == 7.0
    assert stiffness_of(clm, "coupler") == 0.0  # not actuated: untouched


def test_mjcf_fourbar_reads_actuator_stiffness_and_connect(
    fourbar_mjcf, fourbar_urdf, fourbar_yaml
):
    mj = load_model(fourbar_mjcf)
    ur = load_model(fourbar_urdf, fourbar_yaml)
    assert mj.actuated == ur.actuated == ("crank",)
    assert list(mj.model.names) == list(ur.model.names)
    np.testing.assert_array_equal(mj.stiffness, ur.stiffness)
    assert [(c.name, c.kind) for c in mj.closures] == [("closedloop1", "3d")]
    assert mj.model.existFrame("P")


def test_mjcf_qpos0_is_the_closed_form_assembled_pose(fourbar_mjcf):
    clm = load_model(fourbar_mjcf, geometry=False)
    q0 = clm.reference_configuration()
    coupler, rocker = fourbar_angles(0.5)
    np.testing.assert_allclose(q0, [0.5, 0.0, coupler, rocker, 0.0], rtol=0, atol=ATOL_QPOS0)
    assert np.max(np.abs(closure_residual(clm, q0))) < ATOL_QPOS0


@pytest.mark.parametrize("crank", [0.5, 0.2, 0.8, 1.2])
@pytest.mark.parametrize("axes", ["world", "local"])
def test_mjcf_and_urdf_fourbars_have_the_same_compliance(
    fourbar_mjcf, fourbar_urdf, fourbar_yaml, crank, axes
):
    mj = load_model(fourbar_mjcf, geometry=False)
    ur = load_model(fourbar_urdf, fourbar_yaml, geometry=False)
    start = mj.reference_configuration()
    q_mj = assemble(mj, [crank], start).q
    q_ur = assemble(ur, [crank], start).q
    coupler, rocker = fourbar_angles(crank)  # same joint coordinates in both files
    np.testing.assert_allclose(q_mj[[2, 3]], [coupler, rocker], rtol=0, atol=1e-10)
    np.testing.assert_allclose(q_ur[[2, 3]], [coupler, rocker], rtol=0, atol=1e-10)
    C_mj = compliance(mj, q_mj, "P", axes).C
    C_ur = compliance(ur, q_ur, "P", axes).C
    assert np.max(np.abs(C_ur)) > 1e-6  # a real compliance, not an all-zero match
    assert_close_in_norm(C_mj, C_ur, RTOL_TWIN)


def test_mjcf_side_file_overrides_actuators_and_springs(fourbar_mjcf, tmp_path):
    side = write(
        tmp_path, "s.yaml", "name_mot: [rocker]\nsprings: {crank: 10.0}\nlocked: [coupler]"
    )
    clm = load_model(fourbar_mjcf, side)
    assert clm.actuated == ("rocker",)
    assert stiffness_of(clm, "crank") == 10.0
    assert stiffness_of(clm, "crank_axial") == 1e5  # from the MJCF, not overridden
    assert stiffness_of(clm, "coupler") == math.inf
    assert stiffness_of(clm, "rocker") == math.inf  # actuated, no spring: rigid


MJCF_DEFAULTS = """<mujoco model="arm">
  <default>
    <joint stiffness="3"/>
    <default class="stiff"><joint stiffness="7"/></default>
  </default>
  <worldbody>
    <body name="base">
      <body name="l1"><joint name="j1" axis="0 0 1"/>
        <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
        <body name="l2" pos="1 0 0" childclass="stiff"><joint name="j2" axis="0 0 1"/>
          <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
          <body name="l3" pos="1 0 0"><joint name="j3" axis="0 0 1" stiffness="0"/>
            <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_mjcf_stiffness_resolves_default_classes(tmp_path):
    clm = load_model(write(tmp_path, "arm.xml", MJCF_DEFAULTS), geometry=False)
    assert clm.actuated == ()
    np.testing.assert_array_equal(clm.stiffness, [3.0, 7.0, 0.0])


# ----------------------------------------------------------------------- serial robots
def urdf_moving_joints(path: Path) -> list[str]:
    """Names of the revolute/prismatic joints of a URDF, read with ElementTree."""
    joints = ET.parse(path).getroot().findall("joint")
    return [j.get("name") for j in joints if j.get("type") in ("revolute", "prismatic")]


def test_ur5_every_joint_actuated(ur5_urdf):
    clm = load_model(ur5_urdf, joint_stiffness=1e4)
    assert sorted(clm.actuated) == sorted(urdf_moving_joints(ur5_urdf))
    assert clm.model.nv == 6
    np.testing.assert_array_equal(clm.stiffness, np.full(6, 1e4))
    assert clm.visual_model.ngeoms > 0  # package:// meshes resolved
    np.testing.assert_array_equal(clm.reference_configuration(), np.zeros(6))


def test_panda_arm_actuated_fingers_locked(panda_urdf):
    clm = load_model(panda_urdf, joint_stiffness=1e4, geometry=False)
    fingers = [n for n in urdf_moving_joints(panda_urdf) if "finger" in n]
    arm = [n for n in urdf_moving_joints(panda_urdf) if "finger" not in n]
    assert len(arm) == 7 and len(fingers) == 2
    assert sorted(clm.actuated) == sorted(arm)
    for n in arm:
        assert stiffness_of(clm, n) == 1e4
    leader, follower = fingers  # the second finger mimics the first: no coordinate of its own
    assert stiffness_of(clm, leader) == math.inf
    assert clm.model.joints[clm.joint_id(follower)].nv == 0


MIMIC_URDF = """<robot name="mimic">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.5 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/>
    <mimic joint="j1" multiplier="2" offset="0.1"/></joint>
  <joint name="jt" type="fixed"><parent link="l2"/><child link="tip"/>
    <origin xyz="0.5 0 0"/></joint>
</robot>"""


def test_a_mimic_joint_follows_its_leader(tmp_path):
    """j2 = 2 j1 + 0.1: one coordinate t, the tip at 0.5 (cos t, sin t) + 0.5 (cos a,
    sin a), a = 3 t + 0.1, and C = J J^T / k with J = d(tip, rotation)/dt by hand."""
    path = tmp_path / "mimic.urdf"
    path.write_text(MIMIC_URDF)
    clm = load_model(path, joint_stiffness=100.0, geometry=False)
    assert clm.actuated == ("j1",) and clm.model.nv == 1
    t = 0.3
    a = 3.0 * t + 0.1
    J = np.array([-0.5 * np.sin(t) - 1.5 * np.sin(a), 0.5 * np.cos(t) + 1.5 * np.cos(a),
                  0.0, 0.0, 0.0, 3.0])  # fmt: skip
    C = compliance(clm, np.array([t]), "tip").C
    expected = np.outer(J, J) / 100.0
    # Pinocchio's kinematics and the library's factor against the hand-written J: each
    # entry to a few eps of the largest, 16 eps (measured 1.4 eps)
    atol = 16 * np.finfo(float).eps * np.abs(expected).max()
    np.testing.assert_allclose(C, expected, rtol=0, atol=atol)
    with pytest.raises(InvalidInputError, match=r"'j2' .* no coordinate of its own"):
        load_model(path, springs={"j2": 5.0}, geometry=False)


def test_tree_branching_at_root_needs_a_closure_file(tmp_path):
    link = '<link name="{0}"><inertial><mass value="1"/><inertia ixx="1" iyy="1" izz="1" '
    link += 'ixy="0" ixz="0" iyz="0"/></inertial></link>'
    joint = '<joint name="{0}" type="revolute"><parent link="base"/><child link="{1}"/>'
    joint += '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>'
    text = '<robot name="y"><link name="base"/>' + link.format("a") + link.format("b")
    text += joint.format("ja", "a") + joint.format("jb", "b") + "</robot>"
    with pytest.raises(ModelFileError, match="branches at its root"):
        load_model(write(tmp_path, "y.urdf", text))


# ------------------------------------------------------------------------- error paths
FOURBAR_CLOSURES = (
    "closed_loop: [[closedloop1_A, closedloop1_B]]\ntype: ['3d']\nname_mot: [crank]\n"
)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("closed_loop: [[a, b]\n", "is not valid YAML"),
        ("- a\n- b\n", "expected a mapping at top level"),
        ("", "expected a mapping at top level, got an empty file"),
        ("closed_loops: []\n", r"unknown key\(s\) \['closed_loops'\]"),
        ("closed_loop: [[closedloop1_A, closedloop1_B]]\ntype: ['4d']\n", "type '4d'"),
        (
            "closed_loop: [[closedloop1_A, closedloop1_B]]\ntype: []\n",
            "one of '3d', '6d', 'revolute', 'prismatic', 'cylindrical', 'universal' per",
        ),
        ("closed_loop: [[a, b, c]]\ntype: ['3d']\n", r"list of \[frameA, frameB\]"),
        ("name_mot: crank\n", "name_mot must be a list of joint names"),
        (FOURBAR_CLOSURES + "springs: [crank]\n", "springs must be a mapping"),
        (FOURBAR_CLOSURES + "springs: {crank: -5}\n", "stiffness of joint 'crank' is -5"),
        (FOURBAR_CLOSURES + "springs: {crank: .nan}\n", "stiffness of joint 'crank' is nan"),
        (FOURBAR_CLOSURES + "springs: {crank: stiff}\n", "'stiff'; expected a number"),
        (FOURBAR_CLOSURES + "springs: {crank: yes}\n", "True; expected a number"),
        # false-like values were read as "none"
        ("closed_loop: 0\n", r"closed_loop must be a list .*got 0"),
        (FOURBAR_CLOSURES + "springs: false\n", "springs must be a mapping"),
        (FOURBAR_CLOSURES + "beams: 0\n", r"beams must be a mapping .*got 0"),
    ],
)
def test_malformed_closure_file(fourbar_urdf, tmp_path, text, match):
    closures = write(tmp_path, "bad.yaml", text)
    with pytest.raises(ModelFileError, match=match) as info:
        load_urdf(fourbar_urdf, closures)
    assert str(closures) in str(info.value)  # the message names the file


def test_missing_files(fourbar_urdf, tmp_path):
    with pytest.raises(ModelFileError, match=r"robot file .*nowhere\.urdf' does not exist"):
        load_model(tmp_path / "nowhere.urdf")
    with pytest.raises(ModelFileError, match=r"closure file .*nowhere\.yaml' does not exist"):
        load_model(fourbar_urdf, tmp_path / "nowhere.yaml")
    with pytest.raises(ModelFileError, match=r"springs file .*nowhere\.yaml' does not exist"):
        read_springs_file(tmp_path / "nowhere.yaml")


def test_unknown_frames_list_the_valid_ones(fourbar_urdf, tmp_path):
    closures = write(tmp_path, "c.yaml", "closed_loop: [[nope_A, nope_B]]\ntype: ['3d']\n")
    with pytest.raises(
        NameNotFoundError, match="unknown frame 'nope_A'; expected one of: 'universe'"
    ):
        load_urdf(fourbar_urdf, closures)


@pytest.mark.parametrize("key", ["springs: {elbow: 1.0}", "name_mot: [elbow]", "locked: [elbow]"])
def test_unknown_joint_lists_the_valid_ones(fourbar_urdf, tmp_path, key):
    closures = write(tmp_path, "c.yaml", key + "\n")
    with pytest.raises(NameNotFoundError, match=r"unknown joint 'elbow'.*'crank'"):
        load_urdf(fourbar_urdf, closures)


@pytest.mark.parametrize("value", [-1.0, math.nan])
def test_bad_stiffness_keywords(fourbar_urdf, fourbar_yaml, value):
    with pytest.raises(InvalidInputError, match="stiffness of joint 'coupler'"):
        load_urdf(fourbar_urdf, fourbar_yaml, springs={"coupler": value})
    with pytest.raises(InvalidInputError, match="joint stiffness"):
        load_urdf(fourbar_urdf, fourbar_yaml, joint_stiffness=value)


def test_springs_file_reads_yaml11_exponent_strings(tmp_path):
    # YAML 1.1 reads 1e5 (no dot) as a string; it is a number here.
    path = write(tmp_path, "k.yaml", "a: 1e5\nb: [1, 2.5]\nc: .inf\n")
    assert read_springs_file(path) == {"a": 1e5, "b": [1.0, 2.5], "c": math.inf}


def test_unparsable_urdf_gives_one_message_and_no_native_output(tmp_path, capfd):
    bad = write(
        tmp_path,
        "bad.urdf",
        '<robot name="x"><link name="a"/><link name="b"/><joint name="j" type="revolute">'
        '<parent link="a"/><child link="b"/></joint></robot>',
    )
    with pytest.raises(ModelFileError, match=r"bad\.urdf' cannot be parsed: .*specify limits"):
        load_model(bad)
    assert capfd.readouterr().err == ""
    with pytest.raises(ModelFileError, match=r"cut\.urdf' is not valid XML: no element found"):
        load_model(write(tmp_path, "cut.urdf", '<robot name="x"><link name="a"/>'))  # as MJCF


@pytest.mark.parametrize(
    ("name", "hint"),
    [("ur5", "cl.load_model(cl.data.robot_file('ur5'))"),
     ("fourbar", "cl.load_model(cl.data.path('fourbar.urdf'), cl.data.path('fourbar.yaml'))")],
)  # fmt: skip
def test_a_robot_name_given_as_a_path_says_how_to_load_it_by_name(name, hint):
    """The command line takes ``ur5``; from Python ``load_model("ur5")`` said only that the
    format '' is unknown."""
    with pytest.raises(ModelFileError, match=re.escape(hint)):
        load_model(name)


@pytest.mark.parametrize("bad", ['<mass value="nan"/>', '<mass value="abc"/>'])
def test_an_element_urdfdom_drops_is_refused(fourbar_urdf, fourbar_yaml, tmp_path, capfd, bad):
    """urdfdom printed its "Error:" lines on stderr and dropped the inertial (the link's
    mass became 0, which changes the weight); now one message, no native output."""
    text = Path(fourbar_urdf).read_text()
    assert '<mass value="0.1"/>' in text
    path = write(tmp_path, "m.urdf", text.replace('<mass value="0.1"/>', bad, 1))
    with pytest.raises(ModelFileError, match=r"cannot be parsed: an element is dropped: "
                       r"Inertial: mass .* is not a float"):  # fmt: skip
        load_model(path, fourbar_yaml)
    assert capfd.readouterr().err == ""


def test_a_negative_mass_is_refused(fourbar_urdf, fourbar_yaml, fourbar_mjcf, tmp_path):
    """Accepted in every format: under gravity the link was pulled up."""
    text = Path(fourbar_urdf).read_text().replace('<mass value="0.1"/>', '<mass value="-2"/>', 1)
    with pytest.raises(ModelFileError, match=r"the links of joint 'crank' have mass -2 kg"):
        load_model(write(tmp_path, "m.urdf", text), fourbar_yaml)
    text = Path(fourbar_mjcf).read_text().replace('mass="0.1"', 'mass="-2"', 1)
    with pytest.raises(ModelFileError, match=r"mass of <inertial> is .-2.; expected >= 0 kg"):
        load_model(write(tmp_path, "m.xml", text))


def test_links_in_a_cycle_away_from_the_root_are_refused(tmp_path):
    """Pinocchio drops links whose parent joints form a cycle not attached to the root:
    the model kept j1 and j2 and answered, without b, c, jx, jy."""
    limit = '<limit lower="-3" upper="3" effort="1" velocity="1"/>'
    joints = "".join(
        f'<joint name="{n}" type="revolute"><parent link="{p}"/><child link="{c}"/>'
        f'<axis xyz="0 0 1"/>{limit}</joint>'
        for n, p, c in (("j1", "base", "a"), ("j2", "a", "tip"), ("jx", "c", "b"), ("jy", "b", "c"))
    )
    links = "".join(f'<link name="{n}"/>' for n in ("base", "a", "tip", "b", "c"))
    path = write(tmp_path, "cyc.urdf", f'<robot name="cyc">{links}{joints}</robot>')
    with pytest.raises(ModelFileError, match=r"links \['b', 'c'\] are not connected to the root"):
        load_model(path)


def test_an_unreadable_robot_file_is_named_as_unreadable(tmp_path, monkeypatch):
    """Pinocchio says "does not exist" of a URDF it cannot read. The file is made
    unreadable by its mode where that holds (not for root, who reads it anyway: there the
    open itself is made to fail as it would)."""
    path = write(tmp_path, "arm.urdf", '<robot name="x"><link name="a"/></robot>')
    path.chmod(0)
    if os.access(path, os.R_OK):
        real = Path.open

        def denied(self, *args, **kwargs):
            if self == path:
                raise PermissionError(13, "Permission denied", str(self))
            return real(self, *args, **kwargs)

        monkeypatch.setattr(Path, "open", denied)
    with pytest.raises(ModelFileError, match=r"arm\.urdf' cannot be read: Permission denied"):
        load_model(path)


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (("<connect ", '<joint joint1="crank" joint2="rocker"/><connect '), "equality <joint>"),
        (('stiffness="50"', 'stiffness="-50"'), "stiffness of joint 'crank' is -50"),
        (("<mujoco", "<<mujoco"), "cannot be parsed|not valid XML"),
    ],
)
def test_malformed_mjcf(fourbar_mjcf, tmp_path, edit, match):
    text = fourbar_mjcf.read_text()
    assert edit[0] in text
    with pytest.raises(ModelFileError, match=match):
        load_model(write(tmp_path, "bad.xml", text.replace(*edit, 1)))


def test_mjcf_side_file_refuses_closures(fourbar_mjcf, tmp_path):
    with pytest.raises(ModelFileError, match=r"unknown key\(s\) \['closed_loop', 'type'\]"):
        load_model(fourbar_mjcf, write(tmp_path, "s.yaml", FOURBAR_CLOSURES))


def test_unknown_suffix(tmp_path):
    with pytest.raises(ModelFileError, match=r"unknown format '\.stl'"):
        load_model(write(tmp_path, "robot.stl", "solid"))


def test_read_closure_file_name_mot_absent_is_none(fourbar_yaml, tmp_path):
    assert read_closure_file(fourbar_yaml).actuated == ("crank",)
    assert read_closure_file(write(tmp_path, "c.yaml", "locked: []\n")).actuated is None


def test_parsed_model_matches_pinocchio(fourbar_urdf, fourbar_yaml):
    # The loader must not alter the kinematic tree Pinocchio builds.
    ref = pin.buildModelFromUrdf(str(fourbar_urdf))
    clm = load_urdf(fourbar_urdf, fourbar_yaml)
    assert [f.name for f in clm.model.frames] == [f.name for f in ref.frames]


def test_mjcf_actuator_without_joint_needs_the_actuated_joints(fourbar_mjcf, tmp_path):
    text = fourbar_mjcf.read_text().replace('joint="crank"/>', 'site="P"/>')
    mjcf = write(tmp_path, "site_actuator.xml", text)
    with pytest.raises(ModelFileError, match=r"actuator\(s\) \['crank_motor'\] drive no joint"):
        load_model(mjcf, geometry=False)
    side = write(tmp_path, "s.yaml", "name_mot: [crank]\n")
    assert load_model(mjcf, side, geometry=False).actuated == ("crank",)
    assert load_model(mjcf, actuated=["rocker"], geometry=False).actuated == ("rocker",)
