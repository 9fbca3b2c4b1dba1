"""MJCF files that Pinocchio's parser reads silently wrong: repeated names, unnamed springs,
zero axes, several actuators on one joint, joint limits (``ref``, degrees), inactive or
scattered equalities. Each file is read as MuJoCo reads it, or refused with a message that
names the value and the file."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from helpers import frame_placement
from scipy.spatial.transform import Rotation

import closedloop as cl
from closedloop.analysis.maps import stiffness_map
from closedloop.cli.app import main
from closedloop.exceptions import InvalidInputError, ModelFileError
from closedloop.io.loader import load_model

INERTIAL = '<inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>'
RADIAN = '<compiler angle="radian"/>'
#: Placements built by Pinocchio (Eigen) and here (scipy, numpy) from the same doubles, with
#: entries of order 1: they differ by a few ulps (~1e-16); the misreadings fixed here were
#: off by more than 1e-2.
PLACEMENT_TOL = 1e-12


def body(name: str, joints: str, children: str = "", attributes: str = "") -> str:
    return f'<body name="{name}" {attributes}>{joints}{INERTIAL}{children}</body>'


def mujoco(bodies: str, head: str = RADIAN, tail: str = "") -> str:
    return f'<mujoco model="t">{head}<worldbody>{bodies}</worldbody>{tail}</mujoco>'


def write(tmp_path: Path, text: str, name: str = "t.xml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def refused(path: Path, match: str) -> str:
    """The message of the ModelFileError that loading ``path`` raises; it names the file."""
    with pytest.raises(ModelFileError, match=match) as info:
        load_model(path, geometry=False)
    assert str(path) in str(info.value)
    return str(info.value)


def limits(robot, joint: str) -> tuple[float, float]:
    """(lower, upper) position limit of a one-coordinate joint [rad or m]."""
    q = robot.model.joints[robot.joint_id(joint)].idx_q
    return robot.model.lowerPositionLimit[q], robot.model.upperPositionLimit[q]


def fourbar_with(fourbar_mjcf: Path, tmp_path: Path, old: str, new: str) -> Path:
    text = fourbar_mjcf.read_text()
    assert old in text
    return write(tmp_path, text.replace(old, new, 1))


# --------------------------------------------------------------------- repeated names
@pytest.mark.parametrize(
    ("bodies", "tail", "kind", "name"),
    [  # another joint is lost; a joint is renamed; a closure is lost
        (body("a", '<joint name="j"/>', body("b", '<joint name="j"/>')), "", "joint", "j"),
        (body("a", '<joint name="j"/>', body("a", '<joint name="k"/>')), "", "body", "a"),
        (
            body("a", '<joint name="j"/>', body("b", '<freejoint name="j"/>')),
            "",
            "joint",
            "j",
        ),
        (
            body("a", '<joint name="j"/>', body("b", '<joint name="k"/>')),
            '<equality><connect name="c" body1="b" anchor="0 0 1"/>'
            '<weld name="c" body1="a" body2="b"/></equality>',
            "equality",
            "c",
        ),
    ],
)
def test_repeated_names_are_refused(tmp_path, bodies, tail, kind, name):
    refused(write(tmp_path, mujoco(bodies, tail=tail)), f"repeated {kind} name '{name}'")


def test_a_joint_may_share_its_body_name(tmp_path):
    """MuJoCo's names are unique per kind only."""
    robot = load_model(write(tmp_path, mujoco(body("a", '<joint name="a"/>'))), geometry=False)
    assert robot.model.names[1] == "a"


# --------------------------------------------------------------- springs without name
@pytest.mark.parametrize(
    ("head", "joint"),
    [
        (RADIAN, '<joint type="slide" stiffness="1e4"/>'),
        (RADIAN + '<default><joint stiffness="20"/></default>', "<joint/>"),
        (
            RADIAN + '<default><default class="k"><joint stiffness="20"/></default></default>',
            '<joint class="k"/>',
        ),
    ],
)
def test_unnamed_joint_with_a_spring_is_refused(tmp_path, head, joint):
    text = mujoco(body("arm", joint), head=head)
    refused(write(tmp_path, text), r"joint of body 'arm' has stiffness '(1e4|20)' but no name")


def test_unnamed_joint_with_zero_stiffness_loads(tmp_path):
    head = RADIAN + '<default><joint stiffness="0"/></default>'
    text = mujoco(body("arm", "<joint/>", body("b", '<joint name="j" stiffness="5"/>')), head)
    robot = load_model(write(tmp_path, text), actuated=[], geometry=False)
    np.testing.assert_array_equal(robot.stiffness, [0.0, 5.0])


# ------------------------------------------------------------------------- zero axis
@pytest.mark.parametrize(
    ("head", "joint", "shown"),
    [
        (RADIAN, '<joint name="j" axis="0 0 0"/>', "joint 'j'"),
        (RADIAN, '<joint name="j" type="slide" axis="0 0 0"/>', "joint 'j'"),
        (RADIAN, '<joint type="slide" axis="0 0 0"/>', "slide joint of body 'arm'"),
        (RADIAN + '<default><joint axis="0 0 0"/></default>', '<joint name="j"/>', "joint 'j'"),
    ],
)
def test_zero_axis_is_refused(tmp_path, head, joint, shown):
    text = mujoco(body("arm", joint), head=head)
    refused(write(tmp_path, text), f"{shown}: axis '0 0 0' is the zero vector; expected a")


def test_ball_joint_ignores_its_axis(tmp_path):
    text = mujoco(body("arm", '<joint name="b" type="ball" axis="0 0 0"/>'))
    assert load_model(write(tmp_path, text), actuated=[], geometry=False).model.nq == 4


# -------------------------------------------------------------- actuators on one joint
@pytest.mark.filterwarnings("ignore:.*<position> actuator")  # its kp: test_loading_edges
def test_each_driven_joint_is_actuated_once(fourbar_mjcf, tmp_path):
    path = fourbar_with(
        fourbar_mjcf,
        tmp_path,
        '<motor name="crank_motor" joint="crank"/>',
        '<position joint="crank"/><velocity joint="rocker"/><velocity joint="crank"/>',
    )
    robot = load_model(path, geometry=False)
    assert robot.actuated == ("crank", "rocker")
    single = load_model(
        fourbar_with(fourbar_mjcf, tmp_path, "</actuator>", '<velocity joint="crank"/></actuator>'),
        geometry=False,
    )
    assert single.actuated == ("crank",)
    assert cl.assemble(single, [0.5]).q.shape == (single.model.nq,)


# ---------------------------------------------------------------------- joint limits
def written_range(path: Path, joint: str) -> np.ndarray:
    """The range the file writes for ``joint``, as numbers (file units)."""
    element = ET.parse(path).getroot().find(f".//joint[@name='{joint}']")
    return np.array(element.get("range").split(), dtype=float)


def test_fourbar_limits_are_the_ranges_of_the_file(fourbar_mjcf, fourbar_urdf, fourbar_yaml):
    """fourbar.xml (radian) writes ref next to every hinge range: q is MuJoCo's qpos, the
    range is not shifted. The URDF twin has the same limits."""
    mj = load_model(fourbar_mjcf, geometry=False)
    urdf = load_model(fourbar_urdf, fourbar_yaml, geometry=False)
    for joint in ("crank", "crank_axial", "coupler", "rocker", "rocker_axial"):
        np.testing.assert_array_equal(limits(mj, joint), written_range(fourbar_mjcf, joint))
        np.testing.assert_array_equal(limits(mj, joint), limits(urdf, joint))


@pytest.mark.parametrize(
    ("head", "to_rad"),
    [(RADIAN, 1.0), ('<compiler angle="degree"/>', np.pi / 180), ("", np.pi / 180)],
)
def test_hinge_range_in_the_angle_unit_slide_range_in_metres(tmp_path, head, to_rad):
    hinge, slide = ("-10", "20"), ("-0.01", "0.02")
    joints = (
        f'<joint name="h" ref="5" range="{" ".join(hinge)}"/>'
        f'<joint name="s" type="slide" ref="0.005" range="{" ".join(slide)}"/>'
    )  # two joints on one body: a Pinocchio composite joint
    text = mujoco(
        body("arm", '<joint range="-1 2"/>', body("b", joints)), head=head
    )  # an unnamed hinge first
    robot = load_model(write(tmp_path, text), actuated=[], geometry=False)
    lower, upper = robot.model.lowerPositionLimit, robot.model.upperPositionLimit
    np.testing.assert_array_equal([lower[0], upper[0]], np.array([-1.0, 2.0]) * to_rad)
    np.testing.assert_array_equal([lower[1], upper[1]], np.array(hinge, dtype=float) * to_rad)
    np.testing.assert_array_equal([lower[2], upper[2]], np.array(slide, dtype=float))
    q0 = robot.reference_configuration()
    np.testing.assert_array_equal(q0, [0.0, 5.0 * to_rad, 0.005])  # q = MuJoCo's qpos


def test_ranges_of_default_classes(tmp_path):
    head = (
        RADIAN + '<default><joint range="-1 1" ref="0.2"/>'
        '<default class="wide"><joint range="-2 3"/></default></default>'
    )
    text = mujoco(
        body(
            "a", '<joint name="h"/>', body("b", '<joint name="g"/>', attributes='childclass="wide"')
        ),
        head=head,
    )
    robot = load_model(write(tmp_path, text), actuated=[], geometry=False)
    assert limits(robot, "h") == (-1.0, 1.0)
    assert limits(robot, "g") == (-2.0, 3.0)


def test_joint_without_range_stays_unlimited(tmp_path):
    text = mujoco(body("a", '<joint name="h" ref="0.3"/>'))
    robot = load_model(write(tmp_path, text), actuated=[], geometry=False)
    assert limits(robot, "h") == (-np.inf, np.inf)


def test_compiler_elements_merge_in_order(tmp_path):
    """MuJoCo merges the <compiler> elements, later attributes winning; Pinocchio reads only
    the first (here: degrees for ref and range)."""
    head = '<compiler autolimits="true"/><compiler angle="radian"/>'
    text = mujoco(body("a", '<joint name="h" ref="0.5" range="-1 1"/>'), head=head)
    robot = load_model(write(tmp_path, text), actuated=[], geometry=False)
    assert limits(robot, "h") == (-1.0, 1.0)
    assert robot.reference_configuration()[0] == 0.5


@pytest.mark.parametrize(
    ("joint_range", "match"),
    [
        ("-1 one", "range of joint 'h' is '-1 one'; expected 2 finite numbers"),
        ("1 -1", r"range of joint 'h' is '1 -1': lower above upper; expected lower <= upper"),
    ],
)
def test_bad_range_is_refused(tmp_path, joint_range, match):
    text = mujoco(body("a", f'<joint name="h" range="{joint_range}"/>'))
    refused(write(tmp_path, text), match)


@pytest.mark.parametrize(
    ("head", "attribute", "expected"),
    [
        (RADIAN, 'limited="false"', (-np.inf, np.inf)),
        (RADIAN + '<default><joint limited="false"/></default>', "", (-np.inf, np.inf)),
        (RADIAN + '<default><joint limited="false"/></default>', 'limited="true"', (-1.0, 2.0)),
        (RADIAN, 'limited="auto"', (-1.0, 2.0)),
    ],
)
def test_limited_false_ignores_the_range(tmp_path, head, attribute, expected):
    """MuJoCo ignores the range of a joint with limited="false" (own or from its class);
    Pinocchio kept it as limits."""
    text = mujoco(body("a", f'<joint name="h" range="-1 2" {attribute}/>'), head=head)
    robot = load_model(write(tmp_path, text), actuated=[], geometry=False)
    assert limits(robot, "h") == expected


def test_bad_limited_value_is_refused(tmp_path):
    text = mujoco(body("a", '<joint name="h" range="-1 2" limited="no"/>'))
    refused(write(tmp_path, text), "joint 'h' has limited='no'; expected 'true', 'false' or")


# ------------------------------------------------------------------------ equalities
INACTIVE = (
    '<connect name="off" active="false" body1="crank_end" body2="rocker_end" anchor="0 0 0"/>'
)


@pytest.mark.parametrize(
    ("head", "equality"),
    [
        ("", INACTIVE),
        (
            '<default><default class="off"><equality active="false"/></default></default>',
            INACTIVE.replace('active="false"', 'class="off"'),
        ),
    ],
)
def test_inactive_equality_is_no_closure(fourbar_mjcf, tmp_path, head, equality):
    """An inactive connect that would pin the crank end to the rocker end (and so stiffen
    the four-bar) is not a closure: the compliance is the four-bar's."""
    path = fourbar_with(fourbar_mjcf, tmp_path, "<equality>", "<equality>" + equality)
    path.write_text(path.read_text().replace("<worldbody>", head + "<worldbody>", 1))
    robot, fourbar = load_model(path, geometry=False), load_model(fourbar_mjcf, geometry=False)
    assert [c.name for c in robot.closures] == [c.name for c in fourbar.closures]
    C = [cl.compliance(r, r.reference_configuration(), "P").C for r in (robot, fourbar)]
    np.testing.assert_array_equal(C[0], C[1])


def test_bad_active_value_is_refused(fourbar_mjcf, tmp_path):
    path = fourbar_with(
        fourbar_mjcf, tmp_path, "<equality>", "<equality>" + INACTIVE.replace('"false"', '"0"')
    )
    refused(path, r"<connect> 'off' has active='0'; expected 'true' or 'false'")


def pendulums(equalities: str) -> str:
    """Two 1 m pendulums side by side (x = 0 and x = 0.5 m), closed by ``equalities``."""
    left = body("a", '<joint name="ja" axis="0 1 0"/>', body("a_tip", "", attributes='pos="0 0 1"'))
    right = body("b", '<joint name="jb" axis="0 1 0"/>', attributes='pos="0.5 0 0"')
    return mujoco(body("ground", "", left + right), tail=equalities)


def anchor_of(closure) -> np.ndarray:
    return closure.constraint.joint1_placement.translation


@pytest.mark.parametrize(
    "tail",
    [  # names out of alphabetical order; no names; two <equality> sections
        '<equality><connect name="z" body1="a" body2="b" anchor="0.1 0 0"/>'
        '<connect name="a" body1="a" body2="b" anchor="0.2 0 0"/></equality>',
        '<equality><connect body1="a" body2="b" anchor="0.1 0 0"/>'
        '<connect body1="a" body2="b" anchor="0.2 0 0"/></equality>',
        '<equality><connect name="z" body1="a" body2="b" anchor="0.1 0 0"/></equality>'
        '<equality><connect name="a" body1="a" body2="b" anchor="0.2 0 0"/></equality>',
    ],
)
def test_every_equality_is_a_closure_with_its_own_name(tmp_path, tail):
    """Pinocchio orders equalities by name, keeps one of each name and reads only the first
    <equality> section: every closure is kept, named as in the file."""
    robot = load_model(write(tmp_path, pendulums(tail)), actuated=[], geometry=False)
    element = [e for e in ET.fromstring(pendulums(tail)).iter() if e.tag == "connect"]
    names = [e.get("name") or f"connect{i}" for i, e in enumerate(element)]
    assert [c.name for c in robot.closures] == names
    for closure, e in zip(robot.closures, element, strict=True):
        np.testing.assert_array_equal(anchor_of(closure), np.array(e.get("anchor").split(), float))


def test_site_equality_is_refused(tmp_path):
    tail = '<equality><connect site1="s" site2="t"/></equality>'
    refused(write(tmp_path, pendulums(tail)), "<connect> 'connect0' names no body1")


# ------------------------------------------------------------------ file structure
def test_several_worldbody_sections_are_one(tmp_path):
    text = pendulums("").replace(
        "</worldbody>",
        "</worldbody><worldbody>" + body("c", '<joint name="jc"/>') + "</worldbody>",
        1,
    )
    robot = load_model(write(tmp_path, text), actuated=[], geometry=False)
    assert {"ja", "jb", "jc"} <= set(robot.model.names)


@pytest.mark.parametrize(
    "bodies", ['body1="a" body2="a"', 'body1="world"', 'body1="world" body2="world"']
)
def test_an_equality_joining_a_body_to_itself_is_refused(tmp_path, bodies):
    equality = f'<equality><connect {bodies} anchor="0 0 0"/></equality>'
    text = mujoco(body("a", '<joint name="h"/>'), tail=equality)
    refused(write(tmp_path, text), "joins body '(a|world)' to itself")


@pytest.mark.parametrize("held", ['<geom size="0.01"/>', body("b", '<joint name="g"/>')])
def test_what_a_replicate_holds_is_refused(tmp_path, held):
    """Pinocchio's parser drops it: a geom's mass was silently missing."""
    replicate = f'<replicate count="2" offset="0 0 0.1">{held}</replicate>'
    text = mujoco(body("a", '<joint name="h"/>', replicate))
    refused(write(tmp_path, text), "<replicate> is not supported")


def test_an_inertial_in_a_frame_is_refused(tmp_path):
    frame = f'<frame name="f" pos="0 0 1">{INERTIAL}</frame>'
    text = mujoco('<body name="a"><joint name="h"/><geom size="0.01"/>' + frame + "</body>")
    refused(write(tmp_path, text), "<frame> 'f' holds an <inertial>; expected it in its body")


@pytest.mark.parametrize("setting", ["boundmass", "boundinertia", "settotalmass"])
def test_compiler_mass_settings_are_refused(tmp_path, setting):
    """MuJoCo changes the masses by them; Pinocchio's parser ignored them."""
    head = f'<compiler angle="radian" {setting}="0.5"/>'
    text = mujoco(body("a", '<joint name="h"/>', '<geom size="0.01"/>'), head=head)
    refused(write(tmp_path, text), f"<compiler> {setting}='0.5' changes MuJoCo's masses")


def test_a_geom_outside_the_inertia_groups_is_recorded(tmp_path):
    """MuJoCo leaves its mass out; Pinocchio's parser did not: the body is recorded as
    unweighed. A world geom (no mass) and the geoms of a body with an <inertial> (MuJoCo's
    default inertiafromgeom="auto") do not count."""
    head = '<compiler angle="radian" inertiagrouprange="0 2"/>'
    world = '<geom name="floor" type="plane" size="1 1 0.1" group="4"/>'
    geoms = '<geom name="g0" size="0.01"/><geom name="g3" size="0.01" group="3"/>'
    a = f'<body name="a"><joint name="h"/>{geoms}</body>'
    text = mujoco(world + a, head=head)
    robot = load_model(write(tmp_path, text), geometry=False)
    assert list(robot.unweighed_bodies) == ["a"]
    assert robot.unweighed_bodies["a"].startswith(
        "geom 'g3' has group '3', outside <compiler> inertiagrouprange='0 2'"
    )
    robot = load_model(write(tmp_path, text.replace('group="3"', 'group="2"')), geometry=False)
    assert robot.unweighed_bodies == {}
    robot = load_model(write(tmp_path, mujoco(world + body("a", '<joint name="h"/>', geoms), head)))
    assert robot.unweighed_bodies == {}


#: A 0.1 m cube as a Wavefront OBJ mesh: its corners, then two triangles a face.
CUBE = "\n".join(
    [f"v {x} {y} {z}" for z in (0, 0.1) for x, y in ((0, 0), (0.1, 0), (0.1, 0.1), (0, 0.1))]
    + [f"f {a} {b} {c}" for a, b, c in ((1, 4, 3), (1, 3, 2), (5, 6, 7), (5, 7, 8), (1, 2, 6),
       (1, 6, 5), (2, 3, 7), (2, 7, 6), (3, 4, 8), (3, 8, 7), (4, 1, 5), (4, 5, 8))]
)  # fmt: skip


@pytest.mark.parametrize("geom_mass", ["", 'mass="0"', 'density="2000"'])
def test_a_mesh_giving_a_body_its_inertia_is_recorded(tmp_path, geom_mass):
    """Pinocchio's parser gives a mesh geom 1 kg and 1 kg m^2 about each axis, whatever its
    shape and mass (MuJoCo: a 0.1 m cube of 1000 kg/m^3, 1 kg and 1.7e-3 kg m^2): the body
    is recorded as unweighed; with an <inertial> in the body (MuJoCo's default
    inertiafromgeom="auto") the mesh has no mass."""
    (tmp_path / "cube.obj").write_text(CUBE)
    asset = '<asset><mesh name="cube" file="cube.obj"/></asset>'
    geom = f'<geom name="c" type="mesh" mesh="cube" {geom_mass}/>'
    text = mujoco(f'<body name="a"><joint name="h"/>{geom}</body>', head=RADIAN + asset)
    robot = load_model(write(tmp_path, text), geometry=False)
    assert dict(robot.unweighed_bodies) == {
        "a": "geom 'c' is a mesh, to which Pinocchio's parser gives 1 kg and 1 kg m^2 "
        "whatever its shape"
    }
    two = cl.ClosedLoopModel(robot.model, unweighed_bodies={"a": "why a", "b": "why b"})
    with pytest.raises(InvalidInputError, match=r"^the weight cannot be computed: Pinocchio's "
                       r"inertias of bodies 'a' \(why a\), 'b' \(why b\) are not the robot "
                       r"file's; give each of these bodies an <inertial>"):  # fmt: skip
        two.require_inertias("the weight")
    robot = load_model(write(tmp_path, text.replace(geom, INERTIAL + geom)), geometry=False)
    assert robot.unweighed_bodies == {}
    robot.require_inertias("the weight")  # nothing to refuse
    np.testing.assert_allclose(robot.model.inertias[1].mass, 0.1, rtol=1e-15)  # INERTIAL's


#: The coupler's <inertial> in urdf/fourbar.xml, and the geom that follows it.
COUPLER = (
    '<inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>\n'
    '            <geom type="cylinder" pos="0.15 0 0"'
)
#: The fourbar's coupler given its inertia by a mesh geom, or by a geom outside the inertia
#: groups: (compiler and assets, the geom, the words of the reason).
UNWEIGHED = {
    "mesh": ('<compiler angle="radian"/><asset><mesh name="cube" file="cube.obj"/></asset>',
             '<geom name="m" type="mesh" mesh="cube"/>', "geom 'm' is a mesh"),
    "group": ('<compiler angle="radian" inertiagrouprange="0 2"/>',
              '<geom name="m" size="0.01" group="3"/>', "geom 'm' has group '3'"),
}  # fmt: skip


def unweighed_fourbar(fourbar_mjcf: Path, tmp_path: Path, case: str, inertial: bool) -> Path:
    """urdf/fourbar.xml with the ``case`` geom in the coupler, whose <inertial> is kept
    (``inertial``: its inertia is the file's) or removed (it then comes from the geoms)."""
    head, geom, _ = UNWEIGHED[case]
    (tmp_path / "cube.obj").write_text(CUBE)
    text = fourbar_mjcf.read_text().replace('<compiler angle="radian"/>', head)
    assert COUPLER in text
    kept = COUPLER.split("\n")[0] if inertial else ""
    text = text.replace(COUPLER, kept + geom + COUPLER.split("\n", 1)[1])
    return write(tmp_path, text, f"{case}_{inertial}.xml")


@pytest.mark.parametrize("case", list(UNWEIGHED))
def test_an_unweighed_body_allows_stiffness_and_refuses_inertia(
    fourbar_mjcf, tmp_path, capsys, case
):
    """A body whose inertia Pinocchio reads wrong: the stiffness, which does not depend on
    the inertias, is that of the file with an <inertial> (exactly: the same computation on
    the same numbers); the natural frequencies, the weight and the maps' lowest frequency
    are refused naming the body, on derived models too, and on the command line."""
    path = unweighed_fourbar(fourbar_mjcf, tmp_path, case, inertial=False)
    robot = load_model(path, geometry=False)
    assert list(robot.unweighed_bodies) == ["coupler_link"]
    assert UNWEIGHED[case][2] in robot.unweighed_bodies["coupler_link"]
    weighed = load_model(unweighed_fourbar(fourbar_mjcf, tmp_path, case, True), geometry=False)
    assert weighed.unweighed_bodies == {}
    q = robot.reference_configuration()
    np.testing.assert_array_equal(q, weighed.reference_configuration())
    np.testing.assert_array_equal(cl.compliance(robot, q, "P").C, cl.compliance(weighed, q, "P").C)
    cl.compliance(weighed, q, "P", gravity=(0.0, 0.0, -9.81))  # the same calls, weighed
    cl.modes(weighed, q)
    derived = [
        robot,
        robot.with_springs({**robot.springs, "coupler": 30.0}),
        robot.with_beams({"crank_link": {"E": 2.1e11, "G": 8.1e10, "end": "crank_axial",
                                         "section": {"shape": "circle", "d": 0.03}}}),
        load_model(path, geometry=False, closure_springs={0: [1e6, 1e6, 1e6, 1e3, 1e3, 1e3]}),
    ]  # fmt: skip
    for clm in derived:
        assert dict(clm.unweighed_bodies) == dict(robot.unweighed_bodies)
        start = q if clm.model.nq == q.size else clm.reference_configuration()
        named = r"body 'coupler_link' is not the robot file's \(geom 'm' .*<inertial>"
        with pytest.raises(InvalidInputError, match="the natural frequencies .*" + named):
            cl.modes(clm, start)
        weight = r"the weight of the links \(gravity\) .*" + named
        with pytest.raises(InvalidInputError, match=weight):
            cl.compliance(clm, start, "P", gravity=(0.0, 0.0, -9.81))
        with pytest.raises(InvalidInputError, match=weight):
            cl.solve_equilibrium(clm, start, "P", np.zeros(6), gravity=(0.0, 0.0, -9.81))
        with pytest.raises(InvalidInputError, match=named):
            cl.batch_modes(clm, [start])
        with pytest.raises(InvalidInputError, match=named):
            stiffness_map(clm, "P", points=[[0.5]], modes=True)
        cl.compliance(clm, start, "P")  # the stiffness still, and the statics without weight
        eq = cl.solve_equilibrium(clm, start, "P", [0.0, 0.0, -5.0, 0.0, 0.0, 0.0])
        assert eq.gravity is None and np.abs(eq.translation).max() > 0.0
    assert np.isfinite(stiffness_map(robot, "P", points=[[0.5]]).indices["min_translational"]).all()
    code = main(["modes", str(path)])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and err.startswith("closedloop: error: the natural frequencies")
    assert "'coupler_link'" in err and "<inertial>" in err
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert (
        "inertia not the file's (no modes, no gravity; give it an <inertial>): coupler_link" in out
    )


def test_meshes_of_a_file_without_compiler(tmp_path):
    """Several root bodies, no <compiler>: the copy Pinocchio reads still finds the meshes
    (the compiler it adds comes before the assets)."""
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "tri.stl").write_text(
        "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 0.1 0 0\n"
        "vertex 0 0.1 0\nendloop\nendfacet\nendsolid t\n"
    )
    asset = '<asset><mesh name="tri" file="meshes/tri.stl"/></asset>'
    bodies = body("a", '<joint name="h"/><geom type="mesh" mesh="tri"/>') + body(
        "b", '<joint name="g"/>'
    )
    robot = load_model(write(tmp_path, mujoco(bodies, head=asset)), actuated=["h"])
    meshes = [g.meshPath for g in robot.visual_model.geometryObjects]
    assert meshes == [str(tmp_path / "meshes" / "tri.stl")]


def test_bodies_nested_too_deep_and_unknown_classes_are_model_file_errors(fourbar_mjcf, tmp_path):
    """A RecursionError and Pinocchio's IndexError ('unordered_map::at') came out as
    tracebacks from the command line, exit 1; an unknown class is now named."""
    deep = "".join(f'<body name="b{i}"><joint name="j{i}" type="hinge"/>' for i in range(1200))
    refused(write(tmp_path, mujoco(deep + "</body>" * 1200)), "nested too deep for the reader")
    path = fourbar_with(fourbar_mjcf, tmp_path, 'name="coupler"', 'name="coupler" class="nosuch"')
    refused(path, r"<joint> 'coupler' has class='nosuch'; expected one of the <default> classes")
    path = fourbar_with(fourbar_mjcf, tmp_path, 'name="coupler"', 'name="coupler" childclass="x"')
    refused(path, r"<joint> 'coupler' has childclass='x'; expected one of the <default> classes")


@pytest.mark.parametrize(
    ("old", "new", "match"),
    [
        ('pos="0 0 0.1"', 'pos="a 0 0.1"', r"pos of <body> 'crank_end' is 'a 0 0.1'; expected 3"),
        ('pos="0 0 0.1"', 'pos="0 0.1"', r"pos of <body> 'crank_end' is '0 0.1'; expected 3"),
        ('pos="0 0 0.1"', 'pos="0 0 1e999"', r"pos of <body> 'crank_end' is '0 0 1e999'"),
        ('pos="0 0 0.1"', 'pos="0 0 0_1"', r"pos of <body> 'crank_end' is '0 0 0_1'; "
         "expected 3 finite numbers in ASCII decimal notation"),  # Pinocchio read 0 0 0
        ('pos="0 0 0.1"', 'pos="0 0 0.1" quat="0 0 0 0"', r"quat of <body> 'crank_end' is "
         r"'0 0 0 0'; expected a rotation"),
        ('anchor="0.3 0 0"', 'anchor="nan 0 0"', r"anchor of <connect> 'closedloop1' is "),
        ('anchor="0.3 0 0"', 'anchor="0.3,0,0"', r"anchor of <connect> 'closedloop1' is "),
        ('anchor="0.3 0 0"', "", r"<connect> 'closedloop1' has no anchor"),
    ],
)  # fmt: skip
def test_malformed_positions_and_anchors_are_refused(fourbar_mjcf, tmp_path, old, new, match):
    """Pinocchio 4.1 read them as zeros, the largest double or uninitialised memory (a body
    at z = 2.2e243, an anchor at 6.9e-310): the loops then failed to close (exit 3), or
    closed at the wrong point."""
    refused(fourbar_with(fourbar_mjcf, tmp_path, old, new), match)


# ------------------------------------------------------------------ placements, classes
def site_in_world(tmp_path: Path, text: str, q: float) -> np.ndarray:
    """4x4 world placement of site 's' of the one-joint file ``text`` at q."""
    robot = load_model(write(tmp_path, text), actuated=[], geometry=False)
    return frame_placement(robot, np.array([q]), "s").homogeneous


def placement(rotation: Rotation, translation) -> np.ndarray:
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = rotation.as_matrix(), translation
    return M


def test_axisangle_axis_is_normalised(tmp_path):
    """MuJoCo normalises the axis of an axisangle; Pinocchio 4.1 built a placement that is
    not a rotation from a non-unit one (degrees: the compiler's default)."""
    site = '<site name="s" pos="0.1 0 0" axisangle="0 0 2 90"/>'
    text = mujoco(body("b", '<joint name="j"/>', site, 'axisangle="1 1 0 40"'), head="")
    R_b = Rotation.from_rotvec(np.radians(40) * np.array([1, 1, 0]) / np.sqrt(2))
    expected = placement(R_b, [0, 0, 0]) @ placement(
        Rotation.from_euler("z", 90, True), [0.1, 0, 0]
    )
    np.testing.assert_allclose(site_in_world(tmp_path, text, 0.0), expected, atol=PLACEMENT_TOL)


@pytest.mark.parametrize(
    ("defaults", "attributes", "joint", "site"),
    [  # a class of the joint and site: from childclass, their own class, "main"
        ('<default class="a">{}</default>', 'childclass="a"', "", ""),
        ('<default class="a">{}</default>', "", 'class="a"', 'class="a"'),
        ("{}", "", "", ""),
        ("{}", "", 'class="main"', 'class="main"'),
    ],
)
def test_positions_and_orientations_of_default_classes(tmp_path, defaults, attributes, joint, site):
    """Pinocchio ignored a joint's pos and a site's pos and quat given by a class: the hinge
    turned about the body origin and the site sat there, unrotated."""
    given = '<joint pos="0.1 0 0" axis="0 1 0"/><site pos="0.1 0.2 0" quat="0 0 0 1"/>'
    text = mujoco(
        body("b", f'<joint name="j" {joint}/>', f'<site name="s" {site}/>', attributes),
        head=RADIAN + "<default>" + defaults.format(given) + "</default>",
    )
    q, centre = 0.4, np.array([0.1, 0, 0])  # the hinge turns the site about y through centre
    R = Rotation.from_euler("y", q)
    expected = placement(R, centre + R.apply(np.array([0.1, 0.2, 0]) - centre))
    expected[:3, :3] = expected[:3, :3] @ Rotation.from_euler("z", np.pi).as_matrix()
    np.testing.assert_allclose(site_in_world(tmp_path, text, q), expected, atol=PLACEMENT_TOL)


@pytest.mark.parametrize(
    ("joint", "site", "axis", "turn"),
    [  # the element's class beats childclass; a class's euler beats the site's own quat;
        # the site's own axisangle beats its class's euler
        ('class="b"', "", [0, 0, 1], np.pi / 2),
        ("", 'quat="0 1 0 0"', [1, 0, 0], np.pi / 2),
        ("", 'axisangle="0 0 1 3"', [1, 0, 0], 3.0),
    ],
)
def test_class_rules_of_mujoco(tmp_path, joint, site, axis, turn):
    """MuJoCo applies the element's class instead of the childclass (Pinocchio applied
    both, so the childclass's axis x leaked into the joint of class b), and an alternative
    orientation (euler, axisangle, xyaxes, zaxis) instead of quat, whichever of the class
    and the element gives them (Pinocchio read quat first). The site turns by ``turn``
    about z in the body, the body by q about ``axis``."""
    defaults = (
        '<default><default class="a"><joint axis="1 0 0"/><site euler="0 0 1.5707963267948966"/>'
        '</default><default class="b"><joint ref="0"/></default></default>'
    )
    text = mujoco(
        body("b", f'<joint name="j" {joint}/>', f'<site name="s" {site}/>', 'childclass="a"'),
        head=RADIAN + defaults,
    )
    q = 0.3
    R = Rotation.from_rotvec(q * np.array(axis)) * Rotation.from_euler("z", turn)
    np.testing.assert_allclose(
        site_in_world(tmp_path, text, q), placement(R, [0, 0, 0]), atol=PLACEMENT_TOL
    )


def test_fromto_beats_the_position_of_the_class(tmp_path):
    """A geom's fromto places it, whatever pos its class gives (Pinocchio refuses a geom
    that has both): the capsule from z = 0 to 0.2 is centred at z = 0.1."""
    geom = '<geom type="capsule" size="0.01" fromto="0 0 0 0 0 0.2"/>'
    text = mujoco(
        body("b", '<joint name="j"/>' + geom),
        head=RADIAN + '<default><geom pos="0 0 0.5"/></default>',
    )
    robot = load_model(write(tmp_path, text), actuated=[])
    (capsule,) = robot.visual_model.geometryObjects
    np.testing.assert_allclose(capsule.placement.translation, [0, 0, 0.1], atol=PLACEMENT_TOL)


def test_class_main_loads_as_without_it(tmp_path):
    """MuJoCo's top default class is "main": Pinocchio failed on it ('unordered_map::at')."""
    plain = mujoco(
        body("b", '<joint name="j" stiffness="2"/>', '<site name="s" pos="1 0 0"/>'),
        head=RADIAN + '<default><joint axis="0 1 0"/></default>',
    )
    main = plain.replace('<joint name="j"', '<joint name="j" class="main"')
    robots = [
        load_model(write(tmp_path, text, f"{i}.xml"), actuated=[], geometry=False)
        for i, text in enumerate((plain, main))
    ]
    assert robots[0].springs == robots[1].springs == {"j": 2.0}
    np.testing.assert_array_equal(
        *(frame_placement(r, np.array([0.5]), "s").homogeneous for r in robots)
    )


def test_upper_case_eulerseq_is_refused(tmp_path):
    """MuJoCo's upper-case eulerseq letters are extrinsic axes; Pinocchio read them as
    intrinsic. The equivalent the message gives (intrinsic 'zyx', angles reversed) is
    MuJoCo's extrinsic rotation (scipy's lower case: extrinsic)."""
    site = '<site name="s" euler="{}"/>'
    head = '<compiler angle="degree" eulerseq="{}"/>'
    text = mujoco(body("b", '<joint name="j"/>', site.format("10 20 30")), head.format("XYZ"))
    refused(write(tmp_path, text), r"<compiler> eulerseq='XYZ' has upper-case \(extrinsic\) axes")
    text = mujoco(body("b", '<joint name="j"/>', site.format("30 20 10")), head.format("zyx"))
    expected = placement(Rotation.from_euler("xyz", [10, 20, 30], degrees=True), [0, 0, 0])
    np.testing.assert_allclose(site_in_world(tmp_path, text, 0.0), expected, atol=PLACEMENT_TOL)
    without_euler = mujoco(body("b", '<joint name="j"/>'), head.format("XYZ"))
    assert load_model(write(tmp_path, without_euler), actuated=[], geometry=False).model.nq == 1


def test_spring_on_a_joint_of_a_composite_is_refused(tmp_path):
    """Pinocchio merges the joints of one body into a composite joint named after the
    first: a spring on 's' failed with "unknown joint 's'; expected one of: 'Composite_s'"."""
    joints = '<joint name="s" type="slide" stiffness="300"/><joint name="h" stiffness="5"/>'
    refused(
        write(tmp_path, mujoco(body("b", joints))),
        r"joint 's' has stiffness '300', but Pinocchio merges the joints \['s', 'h'\] of body "
        r"'b' into one composite joint 'Composite_s'",
    )
    # a spring given by keyword (or a side file) on a merged joint: the hint says why
    plain = write(tmp_path, mujoco(body("b", '<joint name="s" type="slide"/><joint name="h"/>')))
    merged = r"\(Pinocchio merges the joints of one MJCF body into a composite joint, \["
    with pytest.raises(cl.NameNotFoundError, match=r"unknown joint 'h' " + merged):
        load_model(plain, springs={"h": 5.0}, geometry=False)
