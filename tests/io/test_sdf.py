"""SDF files: the reader of closedloop.io.sdf on a four-bar twin of the URDF one, on loop
closures of each joint type, on Cassie (example-robot-data), and on malformed files."""

from __future__ import annotations

import math
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm
from scipy.spatial.transform import Rotation

import closedloop as cl
from closedloop.cli.app import main
from closedloop.common.conditioning import RANK_RTOL
from closedloop.exceptions import ModelFileError
from closedloop.io import sdf
from closedloop.io.loader import load_model, robot_data_dir
from closedloop.kinematics.constraints import nullspace
from closedloop.kinematics.limits import joints_outside_limits

# The SDF and URDF four-bars are one mechanism written twice: the SDF is drawn at the
# assembled pose (closed-form angles, 17 digits), the URDF assembled by Newton to 1e-12.
RTOL_TWIN = 1e-9
# Link placements: the file's 5-digit numbers composed by the reader vs read directly.
ATOL_POSE = 1e-12
# Cassie's numbers are rounded to about 5 digits of 1 m: points the file means to
# coincide miss each other by up to ~5e-5 m, and the legs mirror each other to ~1e-3.
ATOL_FILE_ROUNDING = 1e-4
RTOL_MIRROR = 1e-3
# Issue 13's bound on the closure residual of an assembled pose [m].
TOL_ASSEMBLED = 1e-10
# Compliance vs central differences of the nonlinear equilibrium (wrench 1e-3 N, N m):
# truncation ~ (1e-3 * C)^2 curvature terms, ~1e-9 relative here; 1e-5 asked by the issue.
RTOL_FD = 1e-5
FD_WRENCH = 1e-3

FOURBAR_ANGLES = (0.5, -0.687929053398771, 0.2883841948951434)  # crank, coupler, rocker
CASSIE = "cassie_description/robots/cassie_v2.sdf"
MOTORS = ("roll", "yaw", "pitch", "knee", "foot")
K_MOTOR = 1e4  # [N m/rad]


def numbers(values) -> str:
    """Space-separated floats, 17 significant digits (what an SDF file holds)."""
    return " ".join(repr(float(v)) for v in values)


def write(tmp_path: Path, text: str, name: str = "robot.sdf") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def pose(x, z, pitch) -> str:
    return f"{float(x)!r} 0 {float(z)!r} 0 {float(pitch)!r} 0"


def fourbar_sdf(version: str = "1.6", closing: str = "ball") -> str:
    """The four-bar of urdf/fourbar.urdf drawn at crank = 0.5 rad (assembled).

    SDF 1.6: every link pose in the model frame. SDF 1.7: link poses ``relative_to``
    the link before, axes ``expressed_in`` the model frame.
    """
    a, b, c = FOURBAR_ANGLES
    B = 0.1 * np.array([math.sin(a), math.cos(a)])
    D = np.array([0.3, 0.0])
    E = D + 0.15 * np.array([math.sin(c), math.cos(c)])  # rocker end = C
    P = B + np.array([[math.cos(a + b), math.sin(a + b)], [-math.sin(a + b), math.cos(a + b)]]) @ [
        0.15,
        0.05,
    ]
    new = version >= "1.7"

    def link(name, model_pose, rel):
        p = f'<pose relative_to="{rel[0]}">{rel[1]}</pose>' if new else f"<pose>{model_pose}</pose>"
        return f'<link name="{name}">{p}<inertial><mass>0.1</mass></inertial></link>'

    def joint(name, kind, parent, child, axis=None, k=None, world_axis=None):
        dyn = f"<dynamics><spring_stiffness>{k}</spring_stiffness></dynamics>" if k else ""
        if axis is None:
            ax = ""
        elif new and world_axis is not None:
            ax = f'<axis><xyz expressed_in="__model__">{world_axis}</xyz>{dyn}</axis>'
        else:
            ax = f"<axis><xyz>{axis}</xyz>{dyn}</axis>"
        return (
            f'<joint name="{name}" type="{kind}"><parent>{parent}</parent>'
            f"<child>{child}</child>{ax}</joint>"
        )

    sa, ca, sc, cc = math.sin(a), math.cos(a), math.sin(c), math.cos(c)
    links = [
        link("ground", "0 0 0 0 0 0", ("__model__", "0 0 0 0 0 0")),
        link("crank_link", pose(0.0, 0.0, a), ("ground", pose(0.0, 0.0, a))),
        link("crank_end", pose(B[0], B[1], a), ("crank_link", "0 0 0.1 0 0 0")),
        link("coupler_link", pose(B[0], B[1], a + b), ("crank_end", pose(0.0, 0.0, b))),
        link("P", pose(P[0], P[1], a + b), ("coupler_link", "0.15 0 0.05 0 0 0")),
        link("rocker_link", pose(0.3, 0.0, c), ("ground", pose(0.3, 0.0, c))),
        link("rocker_end", pose(E[0], E[1], c), ("rocker_link", "0 0 0.15 0 0 0")),
    ]
    joints = [
        joint("crank", "revolute", "ground", "crank_link", "0 1 0", 50.0, "0 1 0"),
        joint(
            "crank_axial", "prismatic", "crank_link", "crank_end", "0 0 1", 1e5, f"{sa!r} 0 {ca!r}"
        ),
        joint("coupler", "revolute", "crank_end", "coupler_link", "0 1 0", None, "0 1 0"),
        joint("P_joint", "fixed", "coupler_link", "P"),
        joint("rocker", "revolute", "ground", "rocker_link", "0 1 0", None, "0 1 0"),
        joint(
            "rocker_axial",
            "prismatic",
            "rocker_link",
            "rocker_end",
            "0 0 1",
            2e5,
            f"{sc!r} 0 {cc!r}",
        ),
    ]
    axis = "0 1 0" if closing in ("revolute", "continuous") else None
    closing_joint = joint("C_joint", closing, "rocker_end", "coupler_link", axis)
    closing_joint = closing_joint.replace("<parent>", "<pose>0.3 0 0 0 0 0</pose><parent>")
    body = "".join([*links, *joints, closing_joint])
    return f'<sdf version="{version}"><model name="fourbar">{body}</model></sdf>'


# --------------------------------------------------------------------------- four-bar
@pytest.mark.parametrize("version", ["1.6", "1.7"])
def test_fourbar_sdf_equals_its_urdf_twin(tmp_path, fourbar_urdf, fourbar_yaml, version):
    robot = load_model(write(tmp_path, fourbar_sdf(version)))
    assert [c.name for c in robot.closures] == ["C_joint"]
    state = cl.Configuration(robot, robot.reference_configuration())
    assert state.closure_error <= 1e-15  # drawn at an assembled pose
    twin = load_model(fourbar_urdf, fourbar_yaml)
    q_twin = cl.assemble(twin, actuated=[FOURBAR_ANGLES[0]]).q
    for joint in ("crank", "crank_axial", "rocker_axial", "coupler", "rocker"):
        assert (
            robot.stiffness[robot.joint_v_slice(joint)] == twin.stiffness[twin.joint_v_slice(joint)]
        )
    C = cl.compliance(state, "P").C
    assert_close_in_norm(C, cl.compliance(twin, q_twin, "P").C, RTOL_TWIN)
    # SDF angles count from the drawing (q = 0), the twin's from its links along +z
    np.testing.assert_array_equal(state.q, 0.0)
    for joint, angle in zip(("crank", "coupler", "rocker"), FOURBAR_ANGLES, strict=True):
        assert q_twin[twin.model.joints[twin.joint_id(joint)].idx_q] == pytest.approx(angle)


def test_revolute_closure_leaves_only_its_axis_free(tmp_path):
    """A link hung on a ball joint and closed to the ground at the same point: a revolute
    (or continuous) closure leaves one rotation free, about its axis (0.6, 0, 0.8) given
    in the model frame; a ball closure all three, a fixed one none."""
    axis = np.array([0.6, 0.0, 0.8])
    free = {}
    for kind in ("revolute", "ball", "fixed", "continuous"):
        ax = f'<axis><xyz expressed_in="__model__">{" ".join(map(str, axis))}</xyz></axis>'
        text = (
            '<sdf version="1.7"><model name="m"><link name="g"/>'
            '<link name="b"><pose>0.2 0.1 0.3 0.4 -0.2 0.7</pose></link>'
            '<joint name="hang" type="ball"><parent>g</parent><child>b</child>'
            "<pose>0.1 0 0 0 0 0</pose></joint>"
            f'<joint name="close" type="{kind}"><parent>g</parent><child>b</child>'
            f"<pose>0.1 0 0 0.3 0.2 0.1</pose>{ax if kind in ('revolute', 'continuous') else ''}"
            "</joint></model></sdf>"
        )
        robot = load_model(write(tmp_path, text), geometry=False)
        state = cl.Configuration(robot, pin.neutral(robot.model))
        N, _ = nullspace(state.closure_jacobian() / state.length)
        free[kind] = N.shape[1]
        if kind == "revolute":
            # the ball's tangent is its angular velocity in the link's axes
            R = state.data.oMi[robot.joint_id("hang")].rotation
            np.testing.assert_allclose(abs(R @ N[:, 0]), axis, atol=1e-12)
    assert free == {"revolute": 1, "ball": 3, "fixed": 0, "continuous": 1}


def test_spring_reference_is_the_rest_configuration(tmp_path, fourbar_urdf, fourbar_yaml):
    """A crank spring at rest at 0.25 rad from the drawing: the rest configuration is the
    four-bar assembled at crank = 0.5 + 0.25 rad, P where the URDF twin puts it."""
    text = fourbar_sdf().replace(
        "<spring_stiffness>50.0</spring_stiffness>",
        "<spring_stiffness>50.0</spring_stiffness><spring_reference>0.25</spring_reference>",
    )
    robot = load_model(write(tmp_path, text))
    rest = robot.reference_configuration()
    assert rest[robot.model.joints[robot.joint_id("crank")].idx_q] == 0.25
    # assembly keeps the spring at rest and closes the loop with the passive joints
    q = cl.assemble(robot, q0=rest).q
    assert q[robot.model.joints[robot.joint_id("crank")].idx_q] == 0.25
    twin = load_model(fourbar_urdf, fourbar_yaml)
    q_twin = cl.assemble(twin, actuated=[FOURBAR_ANGLES[0] + 0.25]).q
    P_twin = cl.Configuration(twin, q_twin).frame_placement("P")
    P = cl.Configuration(robot, q).frame_placement("P")
    np.testing.assert_allclose(P.translation, P_twin.translation, atol=1e-12)
    np.testing.assert_allclose(P.rotation, P_twin.rotation, atol=1e-12)


def test_free_base(tmp_path):
    robot = load_model(cassie_path(), free_base=True, geometry=False)
    assert robot.model.names[1] == "root_joint" and robot.model.nq == 7 + 22
    # the file's configuration: its tarsus crank and foot joints at 0, outside their
    # limits [-2.44, -0.61] rad; the placement of the pelvis is what is checked here
    q = robot.reference_configuration()
    state = cl.Configuration(robot, q, check_limits=False)
    np.testing.assert_allclose(state.frame_placement("pelvis").translation, [0, 0, 1.01])
    with pytest.raises(ModelFileError, match="free_base: SDF only"):
        load_model(write(tmp_path, "<robot/>", "r.urdf"), free_base=True)


def test_pinocchio_parser_is_used_when_available(tmp_path, monkeypatch):
    """With SDFormat in Pinocchio its tree and closures are taken; the springs and their
    rest are read from the XML (Pinocchio keeps neither)."""
    path = write(
        tmp_path,
        fourbar_sdf().replace(
            "50.0</spring_stiffness>",
            "50.0</spring_stiffness><spring_reference>0.1</spring_reference>",
        ),
    )
    own = sdf.read_sdf(path, geometry=False)
    calls = []

    def fake(filename, **options):
        calls.append((filename, options))
        return own.model, [c.constraint for c in own.closures], None, None

    monkeypatch.setattr(pin, "WITH_SDFORMAT", True, raising=False)
    monkeypatch.setattr(pin, "buildModelsAndConstraintsFromSdf", fake)
    assert sdf.load_sdf(path, geometry=False).closing_joints == ("C_joint",)
    robot = load_model(path, geometry=False)
    assert calls and calls[0][0] == str(path) and calls[0][1]["root_joint"] is None
    assert robot.stiffness[robot.joint_v_slice("crank_axial")] == 1e5
    assert robot.reference_configuration()[robot.model.joints[robot.joint_id("crank")].idx_q] == 0.1


# ------------------------------------------------------------------------------ Cassie
def cassie_path() -> Path:
    return robot_data_dir() / CASSIE


def motor_springs(k=K_MOTOR, sides=("left", "right")) -> dict[str, float]:
    return {f"{s}-{m}-op": k for s in sides for m in MOTORS}


def spring_dict() -> dict[str, float]:
    return {
        f"{s}-{n}": k
        for s in ("left", "right")
        for n, k in (("knee-shin-joint", 1500.0), ("tarsus-spring-joint", 1250.0))
    }


# The Cassie tests query the file's drawing, q = 0, outside the limits of foot-op and
# tarsus-crank-joint (the file counts their zero elsewhere, issue 13): check_limits=False.
@pytest.fixture(scope="module")
def cassie():
    return load_model(cassie_path(), springs=motor_springs(), geometry=False)


def file_elements(tag: str) -> list[ET.Element]:
    return ET.parse(cassie_path()).getroot().findall(f"model/{tag}")


def test_cassie_loads_as_in_the_file(cassie):
    joints = file_elements("joint")
    closing = [j.get("name") for j in joints if j.get("type") == "ball"]  # ball = loop
    assert sorted(c.name for c in cassie.closures) == sorted(closing) and len(closing) == 4
    tree = {j.get("name") for j in joints} - set(closing)
    assert set(cassie.model.names[1:]) == tree and cassie.model.nq == cassie.model.nv == 22
    springs = {
        j.get("name"): float(j.findtext("axis/dynamics/spring_stiffness"))
        for j in joints
        if j.find("axis/dynamics/spring_stiffness") is not None
    }
    assert springs == spring_dict()
    for name, k in springs.items():
        assert cassie.stiffness[cassie.joint_v_slice(name)] == k
    # q = 0 (the drawing) lies outside the limits of exactly these joints (issue 13)
    bad = joints_outside_limits(cassie, np.zeros(22))
    assert sorted(bad) == sorted(
        f"{s}-{n}" for s in ("left", "right") for n in ("foot-op", "tarsus-crank-joint")
    )


def test_cassie_link_placements_are_the_file_poses(cassie):
    state = cl.Configuration(cassie, np.zeros(22), check_limits=False)
    for link in file_elements("link"):
        v = [float(t) for t in link.findtext("pose").split()]
        M = state.frame_placement(link.get("name"))
        np.testing.assert_allclose(M.translation, v[:3], atol=ATOL_POSE)
        R = Rotation.from_euler("xyz", v[3:]).as_matrix()  # extrinsic x, y, z = Rz Ry Rx
        np.testing.assert_allclose(M.rotation, R, atol=ATOL_POSE)


def test_cassie_joint_poses_are_relative_to_the_child(cassie):
    """SDF 1.6: the ball joint at the top of each achilles rod is posed in the hip-pitch
    link (its child) and lands on the rod's origin (its parent) to the file's rounding;
    read relative to the parent it would be 0.045 m away."""
    state = cl.Configuration(cassie, np.zeros(22), check_limits=False)
    for side, sign in (("left", 1), ("right", -1)):
        ball = state.frame_placement(f"{side}-hip-pitch").act(np.array([0, 0, 0.045 * sign]))
        rod = state.frame_placement(f"{side}-achilles-rod").translation
        assert np.linalg.norm(ball - rod) < ATOL_FILE_ROUNDING


def test_cassie_flat_foot_fourbar_rows_are_dependent(cassie):
    """Each foot four-bar is nearly flat: its third closure row is ~1e-12 (right) and
    ~1e-14 (left) of the largest, below RANK_RTOL, hence dependent; each leg keeps 11
    joints - 3 (achilles ball) - 2 (planar foot loop) = 6 motions."""
    state = cl.Configuration(cassie, np.zeros(22), check_limits=False)
    Jc = state.closure_jacobian() / state.length
    names = [c.name for c in cassie.closures]
    for side in ("left", "right"):
        i = names.index(f"{side}-plantar-foot-joint")
        s = np.linalg.svd(Jc[3 * i : 3 * i + 3], compute_uv=False)
        assert s[2] < RANK_RTOL * s[0] < s[1]
    assert nullspace(Jc)[1] == 10
    assert cl.compliance(state, "left-foot").mobility == 12


def test_cassie_assembles_with_the_motors_held():
    """From a start with every passive joint moved by up to 0.02 rad and the left foot
    motor turned by -0.05 rad, assembly with the motors held and the springs at rest
    (their spring_reference, 0 in the file) closes the loops to 1e-10 m."""
    clm = load_model(cassie_path(), springs=motor_springs(math.inf), geometry=False)
    rest = clm.reference_configuration()
    np.testing.assert_array_equal(rest, 0.0)
    passive = clm.stiffness == 0
    assert passive.sum() == 22 - 10 - 4  # motors locked, 4 springs
    start = rest + np.random.default_rng(13).uniform(-0.02, 0.02, 22) * passive
    foot = clm.model.joints[clm.joint_id("left-foot-op")].idx_q
    start[foot] = -0.05  # the crank and the plantar rod follow
    a = cl.assemble(clm, q0=start, tol=TOL_ASSEMBLED)
    assert a.residual <= TOL_ASSEMBLED
    np.testing.assert_array_equal(a.q[~passive], start[~passive])  # motors, springs held
    assert cl.Configuration(clm, a.q, check_limits=False).is_closed


def test_cassie_legs_mirror_each_other(cassie):
    state = cl.Configuration(cassie, np.zeros(22), check_limits=False)
    M = np.diag([1.0, -1, 1, -1, 1, -1])  # y -> -y: dy, and the rotations rx, rz flip
    left, right = (cl.compliance(state, f"{s}-foot").C for s in ("left", "right"))
    assert_close_in_norm(M @ left @ M, right, RTOL_MIRROR)


def test_cassie_compliance_matches_the_nonlinear_equilibrium(cassie):
    q = np.zeros(22)
    C = cl.compliance(cassie, q, "left-foot", check_limits=False).C
    columns = []
    for i in range(6):
        w = FD_WRENCH * np.eye(6)[i]
        twist = []
        for s in (1.0, -1.0):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", cl.JointLimitWarning)  # q = 0 is outside
                eq = cl.solve_equilibrium(cassie, q, "left-foot", s * w, tol=1e-13)
            twist.append(np.r_[eq.translation, eq.rotation])
        columns.append((twist[0] - twist[1]) / (2 * FD_WRENCH))
    np.testing.assert_allclose(np.array(columns).T, C, rtol=0, atol=RTOL_FD * np.abs(C).max())


def test_cassie_stiff_motors_leave_the_springs_compliance(cassie):
    q = np.zeros(22)
    springs_only = cl.compliance(
        cassie.with_springs({**spring_dict(), **motor_springs(math.inf)}),
        q,
        "left-foot",
        check_limits=False,
    )
    assert springs_only.rank == 1  # the achilles loop's one spring-borne motion
    for factor, rtol in ((1e6, 1e-5), (1e9, 1e-8)):
        stiff = cassie.with_springs({**spring_dict(), **motor_springs(K_MOTOR * factor)})
        C = cl.compliance(stiff, q, "left-foot", check_limits=False).C
        assert_close_in_norm(C, springs_only.C, rtol)


def test_cassie_command_line(tmp_path, capsys):
    motors = write(
        tmp_path, "".join(f"{n}: 1.0e+4\n" for n in motor_springs(sides=("left",))), "m.yaml"
    )
    assert (
        main(
            [
                "stiffness",
                str(cassie_path()),
                "--frame",
                "left-foot",
                "--springs",
                str(motors),
                "--json",
            ]
        )
        == 0
    )
    import json

    doc = json.loads(capsys.readouterr().out)
    assert doc["rank"] == 6 and doc["closure_residual"] < 1e-14
    locked = write(
        tmp_path, "".join(f"{n}: .inf\n" for n in motor_springs(sides=("left",))), "l.yaml"
    )
    assert (
        main(["stiffness", str(cassie_path()), "--frame", "left-foot", "--springs", str(locked)])
        == 1
    )
    assert "rigid directions" in capsys.readouterr().out


def test_cassie_visual_meshes_are_found():
    robot = load_model(cassie_path())
    uris = [u.text.split("/")[-1] for u in ET.parse(cassie_path()).getroot().iter("uri")]
    meshes = [Path(g.meshPath) for g in robot.visual_model.geometryObjects]
    assert sorted(m.name for m in meshes) == sorted(uris) and all(m.is_file() for m in meshes)


# ------------------------------------------------------------------------ malformed files
MALFORMED = [
    (
        'type="prismatic"><parent>crank_link',
        'type="gearbox"><parent>crank_link',
        r"joint 'crank_axial' has type 'gearbox'; expected one of revolute, continuous",
    ),
    (
        "<parent>ground</parent><child>crank_link</child>",
        "<child>crank_link</child>",
        r"joint 'crank' has no <parent>$",
    ),
    (
        "<parent>ground</parent><child>crank_link</child>",
        "<parent>nowhere</parent><child>crank_link</child>",
        r"joint 'crank' has parent 'nowhere'; expected one of the links \['ground', ",
    ),
    (
        '<pose relative_to="crank_link">0 0 0.1 0 0 0</pose>',
        '<pose relative_to="crank_link">0 0 0.1 0 0</pose>',
        r"pose of link 'crank_end' has 5 value\(s\) '0 0 0.1 0 0'; expected 6 finite numbers",
    ),
    (
        '<pose relative_to="crank_link">0 0 0.1 0 0 0</pose>',
        '<pose relative_to="crank_link">0 0 x 0 0 0</pose>',
        r"pose of link 'crank_end' is '0 0 x 0 0 0'; expected 6 numbers",
    ),
    (
        '<pose relative_to="crank_link">0 0 0.1 0 0 0</pose>',
        '<pose relative_to="nowhere">0 0 0.1 0 0 0</pose>',
        r"pose relative to unknown frame 'nowhere'; expected a link, joint or frame",
    ),
    (
        'name="C_joint" type="ball"',
        'name="C_joint" type="prismatic"',
        r"joint 'C_joint' has no <axis>; expected <axis><xyz>x y z</xyz>",
    ),
    (
        '<joint name="P_joint"',
        '<link name="stray"/><joint name="P_joint"',
        r"links \['ground', 'stray'\] have no parent joint; expected exactly one root link",
    ),
    (
        '<xyz expressed_in="__model__">0 1 0</xyz>',
        '<xyz expressed_in="__model__">0 0 0</xyz>',
        r"<axis> of joint 'crank' is the zero vector; expected a direction",
    ),
    (
        "<spring_stiffness>50.0<",
        "<spring_stiffness>-50.0<",
        r"joint 'crank' has spring_stiffness -50.0; expected a number >= 0",
    ),
    ("</model>", '<model name="inner"/></model>', r"nested <model> elements are not supported"),
    (
        "</model>",
        '<frame name="f" attached_to="nowhere"/></model>',
        r"frame 'f' is attached to unknown 'nowhere'; expected a link, joint or frame",
    ),
    (
        "</model>",
        '<frame name="f" attached_to="h"/><frame name="h" attached_to="f"/></model>',
        r"frames attached to each other in a cycle: f -> h -> f",
    ),
    ("</model>", '<frame name="crank"/></model>', r"name 'crank' is used twice"),
    ("</model>", '<frame name="universe"/></model>', r"frame 'universe' has the name of a frame"),
    (
        '<model name="fourbar"',
        '<model name="fourbar" canonical_link="nowhere"',
        r"canonical_link 'nowhere' is not a link; expected one of \['ground'",
    ),
    (
        "</model>",
        '<frame name="f"><pose rotation_format="quat_xyzw">0 0 0 0 0 0 0</pose></frame></model>',
        r"pose of frame 'f' has the quaternion 0 0 0 0; expected a rotation",
    ),
    ("</model></sdf>", "", r"is not valid XML"),
    # numbers in ASCII decimal notation only (Python's float read 50, 0 and version 17)
    (
        "<spring_stiffness>50.0</spring_stiffness>",
        "<spring_stiffness>5_0</spring_stiffness>",
        r"joint 'crank' <spring_stiffness> is '5_0'; expected 1 numbers in ASCII decimal",
    ),
    (
        '"crank_link">0 0 0.1 0 0 0</pose>',
        '"crank_link">0 0 0.1 0 0 \u0660</pose>',  # an Arabic-Indic zero
        r"pose of link 'crank_end' is '0 0 0.1 0 0 \u0660'; expected 6 numbers in ASCII",
    ),
    ('<sdf version="1.7">', '<sdf version="1_7">', r"version '1_7'; expected numbers such as"),
    (  # SDF 1.11: a coupling that would be lost, leaving the joint free
        '<xyz expressed_in="__model__">0 1 0</xyz>',
        '<xyz expressed_in="__model__">0 1 0</xyz><mimic joint="rocker"/>',
        r"<axis> of joint 'crank' has a <mimic>, which is not read",
    ),
]


@pytest.mark.parametrize(("old", "new", "match"), MALFORMED)
def test_malformed_sdf_one_line_errors(tmp_path, old, new, match):
    text = fourbar_sdf("1.7")
    assert old in text
    with pytest.raises(ModelFileError, match=match) as err:
        load_model(write(tmp_path, text.replace(old, new, 1)), geometry=False)
    assert "\n" not in str(err.value) and str(err.value).startswith("SDF file '")


def test_a_side_file_locks_a_joint_the_sdf_gives_a_spring(tmp_path):
    """The side file's lock replaces the file's spring (it used to be refused as both)."""
    side = write(tmp_path, "locked: [crank_axial]\n", "side.yaml")
    robot = load_model(write(tmp_path, fourbar_sdf("1.7")), side, geometry=False)
    assert robot.stiffness[robot.joint_v_slice("crank_axial")][0] == math.inf
    assert robot.springs == {"crank": 50.0, "rocker_axial": 2e5}


def test_loop_closing_pin_with_a_spring_equals_the_sprung_pin_in_the_tree(tmp_path):
    """The slider-crank's pin C with a 300 N m/rad spring, closing the loop (a spring at the
    cut) or in the tree (the slide closing it): the same compliance at the drawing."""
    cut = load_model(write(tmp_path, slider_crank_sdf(False, pin_k=300.0), "c.sdf"),
                     geometry=False)  # fmt: skip
    tree = load_model(write(tmp_path, slider_crank_sdf(True, pin_k=300.0), "t.sdf"),
                      geometry=False)  # fmt: skip
    assert cut.springs["pin_rz"] == 300.0 and tree.springs["pin"] == 300.0
    a = cl.Configuration(cut, cut.reference_configuration())
    b = cl.Configuration(tree, tree.reference_configuration())
    for frame in ("slider", "rod_end"):
        assert_close_in_norm(cl.compliance(a, frame).C, cl.compliance(b, frame).C, RTOL_TWIN)
    free = load_model(write(tmp_path, slider_crank_sdf(False), "f.sdf"), geometry=False)
    C_free = cl.compliance(cl.Configuration(free, free.reference_configuration()), "rod_end").C
    # the spring counts: the rod's rotation at C, 0.4% stiffer than without it
    assert abs(C_free[4, 4] - cl.compliance(a, "rod_end").C[4, 4]) > 1e-3 * C_free[4, 4]


def test_loop_closing_universal_joint_with_springs_holds_the_link_by_them(tmp_path):
    """A link hung on a ball joint at the origin and closed to the ground there by a
    universal joint, axis x (3 N m/rad) and axis2 y (5 N m/rad): the link turns about x
    and y against those springs and not about z, the cross axis. Closed form at the
    drawing (the link's frame is the world's): C = diag(0, 0, 0, 1/3, 1/5, 0)."""
    text = (
        '<sdf version="1.7"><model name="m"><link name="g"/><link name="b"/>'
        '<joint name="hang" type="ball"><parent>g</parent><child>b</child></joint>'
        '<joint name="u" type="universal"><parent>g</parent><child>b</child>'
        "<axis><xyz>1 0 0</xyz><dynamics><spring_stiffness>3</spring_stiffness></dynamics>"
        "</axis><axis2><xyz>0 1 0</xyz><dynamics><spring_stiffness>5</spring_stiffness>"
        "</dynamics></axis2></joint></model></sdf>"
    )
    robot = load_model(write(tmp_path, text), geometry=False)
    assert robot.springs == {"u_rz": 3.0, "u_rx": 5.0}
    q = robot.reference_configuration()
    C = cl.compliance(robot, q, "b").C
    np.testing.assert_allclose(C, np.diag([0, 0, 0, 1 / 3, 1 / 5, 0]), atol=1e-12)


def test_cycle_of_tree_joints_is_refused(tmp_path):
    text = (
        '<sdf version="1.6"><model name="m"><link name="g"/><link name="a"/><link name="b"/>'
        '<joint name="ab" type="ball"><parent>a</parent><child>b</child></joint>'
        '<joint name="ba" type="ball"><parent>b</parent><child>a</child></joint>'
        "</model></sdf>"
    )
    with pytest.raises(ModelFileError, match=r"links \['a', 'b'\] are not connected to the root"):
        load_model(write(tmp_path, text), geometry=False)


def test_missing_mesh_is_named(tmp_path):
    text = fourbar_sdf().replace(
        '<link name="ground">',
        '<link name="ground"><visual name="v"><geometry><mesh><uri>model://nope/x.stl</uri>'
        "</mesh></geometry></visual>",
    )
    match = r"visual 0 of link 'ground': mesh 'model://nope/x.stl' not found"
    with pytest.raises(ModelFileError, match=match):
        load_model(write(tmp_path, text))
    assert load_model(write(tmp_path, text), geometry=False).visual_model is None


@pytest.mark.parametrize("link", ["ground", "crank_link"])
def test_a_negative_mass_is_refused(tmp_path, link):
    text = fourbar_sdf()
    at = text.index(f'<link name="{link}">')
    start = text.index("<mass>", at)
    end = text.index("</mass>", start)
    bad = text[:start] + "<mass>-2" + text[end:]
    with pytest.raises(ModelFileError, match=r"have mass -2 kg; expected masses >= 0"):
        load_model(write(tmp_path, bad), geometry=False)


def test_a_mesh_that_cannot_be_loaded_is_named(tmp_path):
    """A file that exists but is no mesh: coal's ValueError was a traceback."""
    (tmp_path / "junk.stl").write_bytes(np.random.default_rng(0).bytes(3000))
    text = fourbar_sdf().replace(
        '<link name="ground">',
        '<link name="ground"><visual name="v"><geometry><mesh><uri>junk.stl</uri>'
        "</mesh></geometry></visual>",
    )
    with pytest.raises(ModelFileError, match=r"visual 0 of link 'ground': mesh '.*junk.stl' "
                       r"cannot be loaded"):  # fmt: skip
        load_model(write(tmp_path, text))


# ----------------------------------------------------------------- pose and axis forms
PENDULUM = (
    '<sdf version="{v}"><model name="m"><link name="g"/>{frame}'
    '<link name="b"><pose{rel}>{pose}</pose></link>'
    '<joint name="j" type="revolute"><parent>g</parent><child>b</child>'
    "<pose>0 0 -0.2 0 0 0</pose><axis><xyz{xin}>{axis}</xyz>{upm}"
    "<limit><lower>-1e16</lower><upper>0.5</upper></limit></axis></joint></model></sdf>"
)
RPY = (0.3, -0.4, 1.1)
POSE = "0.1 0.2 0.5 " + " ".join(map(str, RPY))
QUAT = Rotation.from_euler("xyz", RPY).as_quat()  # x y z w
R_WORLD = Rotation.from_euler("xyz", RPY).as_matrix()
AXIS_LOCAL = np.array([0.0, 0.6, 0.8])
AXIS_WORLD = R_WORLD @ AXIS_LOCAL


def quaternion_form(scale: float = 1.0) -> dict:
    """The pose as a quaternion (x y z w) times ``scale`` (SDF 1.9)."""
    return dict(v="1.9", rel=' rotation_format="quat_xyzw"', axis="0 0.6 0.8",
                pose="0.1 0.2 0.5 " + numbers(scale * QUAT))  # fmt: skip


def degrees_form(flag: str) -> dict:
    """The pose in degrees, ``degrees="flag"`` (SDF 1.9)."""
    return dict(v="1.9", rel=f' degrees="{flag}"', axis="0 0.6 0.8",
                pose="0.1 0.2 0.5 " + " ".join(repr(math.degrees(a)) for a in RPY))  # fmt: skip


def model_axis_form(version: str, flag: str | None) -> dict:
    """The axis in the model frame: ``use_parent_model_frame`` = flag, or by default."""
    upm = "" if flag is None else f"<use_parent_model_frame>{flag}</use_parent_model_frame>"
    return dict(v=version, pose=POSE, axis=numbers(AXIS_WORLD), upm=upm)


FORMS = {
    "rpy, axis in the joint frame": dict(v="1.6", pose=POSE, axis="0 0.6 0.8"),
    "quaternion": quaternion_form(),
    "degrees": degrees_form("true"),
    "use_parent_model_frame": model_axis_form("1.6", "true"),
    "SDF 1.4: the axis in the model frame by default": model_axis_form("1.4", None),
    "booleans in any case": model_axis_form("1.6", "True"),
    "degrees='1'": degrees_form("1"),
    "quaternion of norm 1e-200": quaternion_form(1e-200),
    "quaternion of norm 1e200": quaternion_form(1e200),
    "an empty pose relative to a <frame>": dict(
        v="1.7",
        rel=' relative_to="f"',
        frame=f'<frame name="f" attached_to="g"><pose>{POSE}</pose></frame>',
        pose="",
        axis="0 0.6 0.8",
    ),
    "expressed_in and a <frame>": dict(
        v="1.7",
        rel=' relative_to="f"',
        xin=' expressed_in="__model__"',
        frame='<frame name="f" attached_to="g"><pose>0.1 0 0 0 0 0</pose></frame>',
        pose="0 0.2 0.5 " + " ".join(map(str, RPY)),
        axis=numbers(AXIS_WORLD),
    ),
}


@pytest.mark.parametrize("form", FORMS)
def test_pose_and_axis_forms_agree(tmp_path, form):
    fields = {"rel": "", "xin": "", "upm": "", "frame": "", **FORMS[form]}
    robot = load_model(write(tmp_path, PENDULUM.format(**fields)), geometry=False)
    state = cl.Configuration(robot, [0.0])
    M = state.frame_placement("b")
    np.testing.assert_allclose(M.translation, [0.1, 0.2, 0.5], atol=ATOL_POSE)
    np.testing.assert_allclose(M.rotation, R_WORLD, atol=ATOL_POSE)
    J = state.frame_jacobian("b")[:, 0]  # rotation about the world axis through the joint
    joint_origin = M.act(np.array([0, 0, -0.2]))
    np.testing.assert_allclose(J[3:], AXIS_WORLD, atol=ATOL_POSE)
    np.testing.assert_allclose(
        J[:3], np.cross(AXIS_WORLD, M.translation - joint_origin), atol=1e-12
    )
    assert (robot.model.lowerPositionLimit[0], robot.model.upperPositionLimit[0]) == (
        -math.inf,
        0.5,
    )


def test_frames_are_loaded_frames(tmp_path):
    """A <frame> is a frame of the model, fixed to the link it is attached to (directly,
    through a joint's child link or another frame, or the canonical link by default), at
    its pose: a 0.5 m pendulum on a spring k about y, frames on it at distances d from the
    axis, each with the compliance d^2 / k across the arm (a rigid lever)."""
    k = 10.0  # [N m/rad]
    text = (
        '<sdf version="1.7"><model name="m"><link name="g"/>'
        '<link name="b"><pose>0 0 -0.5 0 0 0</pose></link>'
        '<joint name="j" type="revolute"><parent>g</parent><child>b</child><axis><xyz>0 1 0'
        f"</xyz><dynamics><spring_stiffness>{k}</spring_stiffness></dynamics></axis></joint>"
        '<frame name="tip" attached_to="b"><pose>0 0 -0.5 0 0 0</pose></frame>'
        '<frame name="tip2" attached_to="tip"><pose>0 0 -0.5 0 0 0</pose></frame>'
        '<frame name="side" attached_to="j"><pose>0.2 0 0 0 0 0</pose></frame>'
        '<frame name="ground_mark"><pose>1 0 0 0 0 0</pose></frame>'
        "</model></sdf>"
    )
    robot = load_model(write(tmp_path, text), geometry=False)
    expected = {  # frame: (origin [m] at q = 0, axis of its motion, distance to the axis [m])
        "tip": ([0, 0, -1.0], 0, 0.5),
        "tip2": ([0, 0, -1.5], 0, 1.0),
        "side": ([0.2, 0, -0.5], 2, 0.2),
    }
    for frame, (origin, axis, d) in expected.items():
        assert robot.model.frames[robot.model.getFrameId(frame)].parentJoint == 1
        np.testing.assert_allclose(
            cl.Configuration(robot, [0.0]).frame_placement(frame).translation, origin,
            atol=ATOL_POSE,
        )  # fmt: skip
        C = cl.compliance(robot, [0.0], frame).C
        np.testing.assert_allclose(C[axis, axis], d**2 / k, rtol=1e-12)
    mark = robot.model.frames[robot.model.getFrameId("ground_mark")]
    assert mark.parentJoint == 0  # the canonical link, the ground: it does not move
    np.testing.assert_allclose(mark.placement.translation, [1.0, 0.0, 0.0], atol=ATOL_POSE)
    assert cl.compliance(robot, [0.0], "ground_mark").rank == 0


def test_names_pinocchio_takes_and_bad_values_are_refused(tmp_path):
    """A link 'universe' (the world's frame), a joint 'root_joint' beside a free base (its
    spring went onto the six free-flyer coordinates), a boolean that is not one, a
    negative inertia (Pinocchio's RuntimeError was a traceback)."""
    fields = {"v": "1.7", "rel": "", "xin": "", "upm": "", "frame": "", "pose": POSE,
              "axis": "0 0 1"}  # fmt: skip
    text = PENDULUM.format(**fields)
    cases = [
        (text.replace(">g<", ">universe<").replace('"g"', '"universe"'), {},
         r"name 'universe' is taken by Pinocchio's world; expected another name"),
        (text.replace('name="j"', 'name="root_joint"'), {"free_base": True},
         r"name 'root_joint' is taken by Pinocchio's free base joint"),
        (text.replace("<xyz>", "<use_parent_model_frame>yes</use_parent_model_frame><xyz>"), {},
         r"use_parent_model_frame is 'yes'; expected true or false \(or 1 or 0\)"),
        (text.replace("<pose>", '<pose degrees="on">', 1), {},
         r"degrees is 'on'; expected true or false"),
        (text.replace('<link name="b">', '<link name="b"><inertial><inertia><ixx>-1</ixx>'
                      "</inertia></inertial>"), {},
         r"inertial of link 'b' is not a valid inertia .*; expected a positive inertia"),
    ]  # fmt: skip
    for bad, options, match in cases:
        with pytest.raises(ModelFileError, match=match):
            load_model(write(tmp_path, bad), geometry=False, **options)


def test_universal_joint_has_two_sprung_axes(tmp_path):
    text = (
        '<sdf version="1.6"><model name="m"><link name="g"/><link name="b"><pose>0 0 -1 0 0 0'
        '</pose></link><joint name="u" type="universal"><parent>g</parent><child>b</child>'
        "<pose>0 0 1 0 0 0</pose>"
        "<axis><xyz>1 0 0</xyz><dynamics><spring_stiffness>10</spring_stiffness></dynamics></axis>"
        "<axis2><xyz>0 1 0</xyz><dynamics><spring_stiffness>40</spring_stiffness></dynamics>"
        "</axis2></joint></model></sdf>"
    )
    robot = load_model(write(tmp_path, text), geometry=False)
    np.testing.assert_array_equal(robot.stiffness, [10.0, 40.0])
    C = cl.compliance(robot, [0.0, 0.0], "b").C
    # a 1 m pendulum: a force along y turns it about x (k = 10), along x about y (k = 40)
    np.testing.assert_allclose([C[1, 1], C[0, 0]], [1 / 10, 1 / 40], rtol=1e-12)
    with pytest.raises(ModelFileError, match=r"universal joint 'u' has axes .* orthogonal"):
        load_model(write(tmp_path, text.replace("<xyz>0 1 0", "<xyz>1 1 0")), geometry=False)


def test_cassie_which_spring_dominates(cassie):
    """The documentation's reading of Cassie's foot compliance: in the sagittal directions the
    heel spring stores more energy than the knee-shin spring; lateral loads deflect only
    the roll and yaw motors; the near-rigid twist is lateral (dy, rx, rz)."""
    res = cl.compliance(cassie, np.zeros(22), "left-foot", check_limits=False)
    k = cassie.stiffness

    def shares(column: int) -> dict[str, float]:
        dq = res.G[:, column]
        energy = {
            name: 0.5 * k[cassie.joint_v_slice(name)][0] * dq[cassie.joint_v_slice(name)][0] ** 2
            for name in [*motor_springs(sides=("left",)), *spring_dict()]
            if name.startswith("left")
        }
        return {n.removeprefix("left-"): e / sum(energy.values()) for n, e in energy.items()}

    for column in (0, 2, 4):  # fx, fz, ny
        s = shares(column)
        assert s["tarsus-spring-joint"] > 3 * s["knee-shin-joint"] > 0
    for column in (1, 3, 5):  # fy, nx, nz
        s = shares(column)
        assert s["roll-op"] + s["yaw-op"] == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(res.C[[3, 5], [3, 5]], 1 / K_MOTOR, rtol=1e-6)
    w, V = np.linalg.eigh(res.C)
    assert w[0] < 1e-9 * w[-1] and np.linalg.norm(V[[0, 2, 4], 0]) < 1e-3


def test_primitive_visuals(tmp_path):
    visuals = (
        '<visual name="a"><pose>0.1 0 0 0 0 0</pose><geometry><box><size>0.1 0.2 0.3</size>'
        "</box></geometry><material><ambient>1 0 0 1</ambient></material></visual>"
        '<visual name="b"><geometry><cylinder><radius>0.01</radius><length>0.3</length>'
        "</cylinder></geometry></visual>"
        '<visual name="c"><geometry><sphere><radius>0.02</radius></sphere></geometry></visual>'
        '<visual name="d"><geometry><plane><normal>0 0 1</normal></plane></geometry></visual>'
    )
    text = fourbar_sdf().replace('<link name="crank_link">', f'<link name="crank_link">{visuals}')
    robot = load_model(write(tmp_path, text))
    objs = {g.name: g for g in robot.visual_model.geometryObjects}
    assert sorted(objs) == ["crank_link_0", "crank_link_1", "crank_link_2"]  # no plane
    box, cyl, sph = objs["crank_link_0"], objs["crank_link_1"], objs["crank_link_2"]
    np.testing.assert_allclose(2 * box.geometry.halfSide, [0.1, 0.2, 0.3])
    assert (cyl.geometry.radius, 2 * cyl.geometry.halfLength) == (0.01, pytest.approx(0.3))
    assert sph.geometry.radius == 0.02
    np.testing.assert_allclose(box.meshColor, [1, 0, 0, 1])
    state = cl.Configuration(robot, np.zeros(5))
    oMg = state.data.oMi[box.parentJoint] * box.placement  # 0.1 m along the crank's x
    M = state.frame_placement("crank_link")
    np.testing.assert_allclose(oMg.translation, M.act(np.array([0.1, 0, 0])), atol=1e-15)


def test_model_pose_and_joint_to_world(tmp_path):
    """A <model><pose> moves every link; a joint with parent 'world' fixes its child there
    (then there is no root link, and no free base)."""
    text = (
        '<sdf version="1.6"><model name="m"><pose>1 2 3 0 0 1.5707963267948966</pose>'
        '<link name="b"><pose>0.5 0 0 0 0 0</pose></link>'
        '<joint name="fix" type="revolute"><parent>world</parent><child>b</child>'
        "<axis><xyz>0 0 1</xyz></axis></joint></model></sdf>"
    )
    robot = load_model(write(tmp_path, text), geometry=False)
    state = cl.Configuration(robot, [0.0])
    np.testing.assert_allclose(state.frame_placement("b").translation, [1, 2.5, 3], atol=1e-15)
    # the joint is at the link origin: a turn about z moves nothing there
    np.testing.assert_allclose(state.frame_jacobian("b")[:, 0], [0, 0, 0, 0, 0, 1], atol=1e-15)
    with pytest.raises(ModelFileError, match=r"joints \['fix'\] fix the model to the world"):
        load_model(write(tmp_path, text), free_base=True, geometry=False)


# ------------------------------------------------ loop-closing prismatic and universal
ROD = np.array([math.sqrt(0.3**2 - 0.1**2), 0.0, -0.1])  # from the crank's end B to C


def slider_crank_sdf(slide_closes: bool, pin_type: str = "revolute", pin_k=None) -> str:
    """A slider-crank drawn assembled: crank (0.1 m, along z, spring 50 N m/rad) at the
    origin, rod (0.3 m, with a sprung axial joint) from B = (0, 0, 0.1) to the slider at
    C on the x axis, slider on a prismatic joint along x. The slider's prismatic joint
    closes the loop (``slide_closes``, listed last) or is a tree joint and the pin
    (``pin_type``, with a spring ``pin_k``) at C closes it."""

    def joint(name, kind, parent, child, axis=None, k=None):
        dyn = f"<dynamics><spring_stiffness>{k}</spring_stiffness></dynamics>" if k else ""
        ax = f"<axis><xyz>{axis}</xyz>{dyn}</axis>" if axis else ""
        return (f'<joint name="{name}" type="{kind}"><parent>{parent}</parent>'
                f"<child>{child}</child>{ax}</joint>")  # fmt: skip

    inertial = "<inertial><mass>0.1</mass></inertial>"
    C = f"{float(ROD[0])!r} 0 0"
    links = [
        f'<link name="ground"/><link name="crank_link">{inertial}</link>',
        f'<link name="rod_link"><pose>0 0 0.1 0 0 0</pose>{inertial}</link>',
        f'<link name="rod_end"><pose>{C} 0 0 0</pose>{inertial}</link>',
        f'<link name="slider"><pose>{C} 0 0 0</pose>{inertial}</link>',
    ]
    axial = " ".join(repr(float(v)) for v in ROD / np.linalg.norm(ROD))
    tree = [
        joint("crank", "revolute", "ground", "crank_link", "0 1 0", 50.0),
        joint("rod", "revolute", "crank_link", "rod_link", "0 1 0"),
        joint("rod_axial", "prismatic", "rod_link", "rod_end", axial, 1e5),
    ]
    slide = joint("slide", "prismatic", "ground", "slider", "1 0 0")
    pin_c = joint("pin", pin_type, "rod_end", "slider", "0 1 0" if pin_type != "ball" else None,
                  pin_k)  # fmt: skip
    order = [*tree, pin_c, slide] if slide_closes else [*tree, slide, pin_c]
    body = "".join([*links, *order])
    return f'<sdf version="1.6"><model name="slider_crank">{body}</model></sdf>'


@pytest.mark.parametrize("pin_type", ["revolute", "ball"])
def test_a_prismatic_loop_joint_equals_the_slider_in_the_tree(tmp_path, pin_type):
    """The slider-crank closed at its slider (a prismatic closure) and closed at the pin C
    with the slider's joint in the tree (a revolute closure, or a ball: the loop is
    planar): the same compliance at the slider and at the rod's end."""
    closed = load_model(write(tmp_path, slider_crank_sdf(True), "p.sdf"), geometry=False)
    tree = load_model(write(tmp_path, slider_crank_sdf(False, pin_type), "t.sdf"),
                      geometry=False)  # fmt: skip
    assert [(c.name, c.kind) for c in closed.closures] == [("slide", "prismatic")]
    assert [c.kind for c in tree.closures] == [{"ball": "3d"}.get(pin_type, pin_type)]
    a = cl.Configuration(closed, closed.reference_configuration())
    b = cl.Configuration(tree, tree.reference_configuration())
    assert a.closure_error <= 1e-15 and b.closure_error <= 1e-15  # drawn assembled
    for frame in ("slider", "rod_end"):
        C = cl.compliance(a, frame).C
        assert C[0, 0] > 0.0
        assert_close_in_norm(C, cl.compliance(b, frame).C, RTOL_TWIN)
    # statics under a push along the slide and across it
    wrench = np.array([40.0, 0.0, 25.0, 0.0, 0.0, 0.0])
    moved = [sdf_displacement(m, wrench) for m in (closed, tree)]
    assert abs(moved[0][0]) > 1e-3
    assert_close_in_norm(moved[0], moved[1], RTOL_TWIN)


def sdf_displacement(robot, wrench) -> np.ndarray:
    from closedloop.elastostatics.statics import frame_displacement

    q = robot.reference_configuration()
    eq = cl.solve_equilibrium(robot, q, "slider", wrench)
    return frame_displacement(robot, eq.q, q, "slider")
