"""Models as robot files and users give them: continuous joints, mimic joints, the world
joint, closures of one body, zero axes, repeated names, values out of range. Each bad
input is a typed error naming it; each odd but valid one gives the right model."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

import closedloop as cl
from closedloop.common.arrays import decimal
from closedloop.exceptions import (
    AssemblyError,
    InvalidInputError,
    ModelFileError,
    NameNotFoundError,
)
from closedloop.io.closure_file import read_springs_file
from closedloop.io.sdf import load_sdf

#: C = J K^-1 J^T computed two ways (Pinocchio's Jacobian here, the library's path):
#: the same products in another order.
RTOL_PRODUCT = 1e-12


def _hinge_model(axis=(0.0, 0.0, 1.0)) -> pin.Model:
    model = pin.Model()
    model.addJoint(0, pin.JointModelRevoluteUnaligned(np.array(axis)), pin.SE3.Identity(), "j")
    model.addFrame(pin.Frame("tip", 1, pin.SE3(np.eye(3), np.array([0.5, 0, 0])),
                             pin.FrameType.OP_FRAME))  # fmt: skip
    return model


def test_continuous_joints_are_actuated_springs_of_a_serial_robot():
    """The Kinova arm's joints 1, 4 and 6 are continuous (q = cos, sin): they are actuated
    and sprung like the others, and C = J K^-1 J^T with Pinocchio's own frame Jacobian."""
    clm = cl.load_model(cl.data.robot_file("kinova"), joint_stiffness=1e4, geometry=False)
    model = clm.model
    kinds = [model.joints[clm.joint_id(n)].nq for n in clm.actuated]
    assert len(clm.actuated) == 6 and kinds.count(2) == 3
    np.testing.assert_array_equal(clm.stiffness, np.full(6, 1e4))
    angles = np.array([0.3, 2.9, 1.2, -0.7, 0.9, 0.4])
    q = clm.reference_configuration()
    clm.set_actuated(q, angles)
    np.testing.assert_allclose(clm.actuated_values(q), angles, rtol=0, atol=1e-15)
    assert pin.isNormalized(model, q)
    frame = model.frames[-1].name
    data = model.createData()
    J = pin.computeFrameJacobian(model, data, q, model.getFrameId(frame), pin.LOCAL_WORLD_ALIGNED)
    np.testing.assert_allclose(
        cl.compliance(clm, q, frame).C, J @ J.T / 1e4, rtol=RTOL_PRODUCT, atol=0
    )
    a = cl.assemble(clm, angles, clm.reference_configuration())  # no loop: the inputs as set
    np.testing.assert_allclose(clm.actuated_values(a.q), angles, rtol=0, atol=1e-15)


@pytest.mark.parametrize("option", ["actuated", "springs", "locked"])
def test_the_world_joint_is_not_a_joint_of_the_model(fourbar_urdf, fourbar_yaml, option):
    value = {"actuated": ["universe"], "springs": {"universe": 5.0}, "locked": ["universe"]}
    model = cl.load_model(fourbar_urdf, fourbar_yaml, geometry=False).model
    kwargs = {"actuated": ["crank"], option: value[option]}
    with pytest.raises(NameNotFoundError, match=r"'universe' .joint 0, the world"):
        cl.ClosedLoopModel(model, **kwargs)


def test_a_fixed_joint_is_named_as_such(fourbar_urdf, fourbar_yaml):
    with pytest.raises(NameNotFoundError, match=r"'coupler_end_joint' .a fixed joint"):
        cl.load_model(fourbar_urdf, fourbar_yaml, springs={"coupler_end_joint": 100.0})


def test_a_closure_of_one_body_is_refused(tmp_path, fourbar_urdf):
    """Two frames of one link (or one frame twice) can hold nothing: refused, naming them."""
    closures = tmp_path / "self.yaml"
    closures.write_text("closed_loop: [[closedloop1_A, coupler_end]]\ntype: ['3d']\n"
                        "name_mot: [crank]\n")  # fmt: skip
    with pytest.raises(InvalidInputError, match=r"closedloop1_A<->coupler_end.*both ends on"):
        cl.load_model(fourbar_urdf, closures, geometry=False)
    model = _hinge_model()
    same = pin.PointAnchorConstraintModel(model, 1, pin.SE3.Identity(), 1, pin.SE3.Identity())
    with pytest.raises(InvalidInputError, match=r"both ends on the body of joint 'j'"):
        cl.ClosedLoopModel(model, [same], springs={"j": 1.0})


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"closures": [1]}, "closure 0 is a int; expected a Closure"),
        ({"closures": "abc"}, "closures must be a list"),
        ({"actuated": "j"}, r"actuated joints must be a list of joint names, got 'j' \(str\)"),
        ({"actuated": ["j", "j"]}, r"actuated joints \['j'\] are listed more than once"),
        ({"locked": "j"}, r"locked joints must be a list of joint names, got 'j'"),
        ({"springs": {"j": True}}, "stiffness of joint 'j' is True; expected a number"),
        ({"springs": {"j": [1.0, 2.0]}}, "has 2 values; expected 1$"),
        (  # was numpy's ValueError
            {"springs": {"j": [[1.0, 2.0], [3.0]]}},
            r"^stiffness of joint 'j' must be real numbers, got \[\[1.0, 2.0\], \[3.0\]\] "
            r"\(ragged list\)$",
        ),
    ],
)
def test_wrong_arguments_of_a_model_are_typed_errors(kwargs, match):
    with pytest.raises(InvalidInputError, match=match):
        cl.ClosedLoopModel(_hinge_model(), **kwargs)


def test_a_model_that_is_not_a_pinocchio_model_is_refused():
    with pytest.raises(InvalidInputError, match=r"must be a pinocchio.Model, got NoneType"):
        cl.ClosedLoopModel(None)


def test_a_zero_joint_axis_is_refused(tmp_path, fourbar_urdf, fourbar_yaml):
    with pytest.raises(InvalidInputError, match=r"joint 'j' .* moves nothing"):
        cl.ClosedLoopModel(_hinge_model((0.0, 0.0, 0.0)), springs={"j": 1.0})
    text = fourbar_urdf.read_text()
    start = text.index('<joint name="crank"')
    axis = text.index("<axis", start)
    end = text.index("/>", axis) + 2
    path = tmp_path / "zero.urdf"
    path.write_text(text[:axis] + '<axis xyz="0 0 0"/>' + text[end:])
    with pytest.raises(InvalidInputError, match=r"joint 'crank' .* moves nothing"):
        cl.load_model(path, fourbar_yaml, geometry=False)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"actuated": "crank"}, r"actuated joints must be a list of joint names, got 'crank'"),
        ({"actuated": ["crank", "crank"]}, r"actuated joints \['crank'\] are listed more"),
        ({"joint_stiffness": True}, "joint stiffness True; expected a number >= 0"),
        ({"beams": [{"end": "x"}]}, "beams must be a mapping link name -> beam, got list"),
    ],
)
def test_wrong_keywords_of_load_model_are_typed_errors(fourbar_urdf, fourbar_yaml, kwargs, match):
    with pytest.raises(InvalidInputError, match=match):
        cl.load_model(fourbar_urdf, fourbar_yaml, geometry=False, **kwargs)


def test_assembly_without_passive_coordinates_is_an_assembly_error(fourbar_urdf, fourbar_yaml):
    every = {"crank": 50.0, "crank_axial": 1e5, "coupler": 10.0, "rocker": 10.0,
             "rocker_axial": 2e5}  # fmt: skip
    clm = cl.load_model(fourbar_urdf, fourbar_yaml, springs=every, geometry=False)
    with pytest.raises(AssemblyError, match=r"no passive coordinate to move"):
        cl.assemble(clm, [0.3])  # the start (crank 0.5, closed) held, another crank angle


@pytest.mark.parametrize(
    "text, match",
    [
        ("crank: 5\ncrank: 7\n", "key 'crank' is given twice"),
        ("crank: 1.0e+400\n", "number 1.0e[+]400 is beyond the floating point range"),
        ("crank: 1e400\n", "'1e400', beyond the floating point range"),
        # each of the next was a Python traceback (TypeError, OverflowError, ValueError,
        # RecursionError) from the command line, exit 1
        ("crank: 50\n? [a, b]\n: 3\n", r"key \['a', 'b'\] is a list; expected a name"),
        ("crank: " + "9" * 400 + "\n", "number 9999.*... is beyond the floating point range"),
        ("crank: " + "9" * 5000 + "\n", "number 9999.*... is beyond the floating point range"),
        ("other: " + "[" * 3000 + "]" * 3000 + "\n", "nested too deep for the reader"),
    ],
)
def test_springs_files_refuse_repeated_joints_and_overflowing_numbers(tmp_path, text, match):
    path = tmp_path / "springs.yaml"
    path.write_text(text)
    with pytest.raises(ModelFileError, match=match):
        read_springs_file(path)


def test_yaml_infinity_still_locks_a_joint(tmp_path):
    path = tmp_path / "springs.yaml"
    path.write_text("crank: .inf\nrocker: 0\n")
    assert read_springs_file(path) == {"crank": math.inf, "rocker": 0.0}


def _sdf_chain(n: int, version: str = "1.7") -> str:
    links = "".join(f'<link name="l{i}"><pose>0 0 {0.01 * i} 0 0 0</pose></link>'
                    for i in range(n))  # fmt: skip
    joints = "".join(
        f'<joint name="j{i}" type="revolute"><parent>l{i - 1}</parent><child>l{i}</child>'
        "<axis><xyz>0 1 0</xyz></axis></joint>"
        for i in range(1, n)
    )
    return f'<sdf version="{version}"><model name="chain">{links}{joints}</model></sdf>'


def test_sdf_version_and_depth_faults_are_model_file_errors(tmp_path):
    path = tmp_path / "chain.sdf"
    path.write_text(_sdf_chain(3, version="1.x"))
    with pytest.raises(ModelFileError, match=r"version '1.x'; expected numbers such as '1.6'"):
        load_sdf(path, geometry=False)
    path.write_text(_sdf_chain(2000))
    with pytest.raises(ModelFileError, match=r"nested too deep for the reader"):
        load_sdf(path, geometry=False)


def test_a_urdf_limit_with_lower_above_upper_is_refused(tmp_path, fourbar_urdf, fourbar_yaml):
    text = fourbar_urdf.read_text()
    start = text.index("<limit", text.index('<joint name="crank"'))
    end = text.index("/>", start) + 2
    path = tmp_path / "limits.urdf"
    path.write_text(text[:start] + '<limit lower="1" upper="-1" effort="1" velocity="1"/>'
                    + text[end:])  # fmt: skip
    with pytest.raises(ModelFileError, match=r"joint 'crank' has lower limit \[1.0\] above"):
        cl.load_model(path, fourbar_yaml, geometry=False)


def test_a_frame_name_shared_by_several_frames(tmp_path):
    """URDF allows a link and a joint of one name, MuJoCo a body and a site: Pinocchio's
    getFrameId then raised "Several frames match" (a traceback). One place (a link and the
    fixed joint that carries it): that frame; different places: refused by name."""
    urdf = tmp_path / "r.urdf"
    urdf.write_text(
        '<robot name="r"><link name="base"/><link name="arm"/><link name="tool"/>'
        '<joint name="j" type="revolute"><parent link="base"/><child link="arm"/>'
        '<axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
        '<joint name="tool" type="fixed"><parent link="arm"/><child link="tool"/>'
        '<origin xyz="1 0 0"/></joint></robot>'
    )
    robot = cl.load_model(urdf, joint_stiffness=3.0)
    C = cl.compliance(robot, [0.0], "tool").C
    assert C[1, 1] == pytest.approx(1.0**2 / 3.0, rel=1e-12)  # a 1 m lever on 3 N m/rad
    model = pin.Model(robot.model)
    joint = model.frames[model.getFrameId("arm")].parentJoint
    model.addFrame(pin.Frame("arm", joint, pin.SE3(np.eye(3), np.ones(3)), pin.FrameType.OP_FRAME))
    moved = cl.ClosedLoopModel(model, springs={"j": 3.0})
    with pytest.raises(InvalidInputError, match=r"frame name 'arm' names 2 frames at different "
                       r"places \(BODY, OP_FRAME\); expected the name of one frame"):  # fmt: skip
        cl.compliance(moved, [0.0], "arm")


# -------------------------------------------------------- numbers, not booleans or text
@pytest.mark.parametrize("value", [np.ones(5, dtype=bool), [True, False, True, False, True]])
def test_a_boolean_configuration_is_refused(fourbar, value):
    """A boolean array as q was read as 1.0 and 0.0 rad."""
    clm, _ = fourbar
    with pytest.raises(InvalidInputError, match=r"^q must be real numbers, got .* \(bool\)$"):
        cl.compliance(clm, value, "P")


@pytest.mark.parametrize("value", [[True], np.array([True]), True, np.bool_(True)])
def test_boolean_actuated_values_are_refused(fourbar, value):
    clm, _ = fourbar
    with pytest.raises(InvalidInputError, match=r"^actuated must be real numbers, .*\(bool\)$"):
        cl.assemble(clm, value)


def test_a_bool_among_numbers_is_refused(fourbar):
    """numpy cast a bool in a list of numbers to 1.0 (a stiffness of 1 N m/rad, a preload
    torque of 1 N m, 1 rad of q); lists of bools alone were already refused."""
    clm, q = fourbar
    model = pin.Model()
    model.addJoint(0, pin.JointModelSpherical(), pin.SE3.Identity(), "ball")
    cases = [
        (lambda: cl.ClosedLoopModel(model, springs={"ball": [1.0, 2.0, True]}),
         "stiffness of joint 'ball'", r"\[1.0, 2.0, True\]"),
        (lambda: cl.ClosedLoopModel(model, springs={"ball": [[1.0, 0, 0], [0, np.True_, 0],
                                                            [0, 0, 1.0]]}),
         "stiffness of joint 'ball'", r"\[\[1.0, 0, 0\], \[0, np.True_, 0\]"),
        (lambda: cl.compliance(clm, q, "P", preload=[1.0, 0, 0, 0, 0, True]), "preload",
         r"\[1.0, 0, 0, 0, 0, True\]"),
        (lambda: cl.compliance(clm, [*q[:-1].tolist(), False], "P"), "q", r"\[.*, False\]"),
    ]  # fmt: skip
    for call, name, shown in cases:
        with pytest.raises(InvalidInputError, match=rf"^{name} must be real numbers, got "
                           rf"{shown}.* \(bool\)$"):  # fmt: skip
            call()


@pytest.mark.parametrize(
    ("text", "value"),
    [("-1e5", -1e5), ("+.5", 0.5), ("2.", 2.0), ("1E-3", 1e-3), ("-inf", -math.inf),
     ("Infinity", math.inf)],
)  # fmt: skip
def test_decimal_reads_ascii_decimal_numbers(text, value):
    assert decimal(text) == value


@pytest.mark.parametrize(
    "text", ["0_3", "1_000.5", "\u0663", "\uff13", "\u0661e2", " 1", "0x10", "", "1e"]
)
def test_decimal_refuses_what_python_s_float_also_reads(text):
    with pytest.raises(ValueError, match="is not a decimal number"):
        decimal(text)
