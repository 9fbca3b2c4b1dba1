"""One rule for the assembly mode (#45): cl.assemble and the command line continue from the
model's reference configuration; assembly_modes lists the modes found; --start and --near
pick another; a closure file's start: key; a spring on a passive joint has a way out."""

from __future__ import annotations

import json
import math

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm

import closedloop as cl
from closedloop import data
from closedloop.cli.app import main
from closedloop.exceptions import InvalidInputError, ModelFileError, NameNotFoundError
from closedloop.kinematics.assembly import ASSEMBLY_TOL
from closedloop.kinematics.assembly_modes import passive_values, scaled_difference

# Link lengths of urdf/fourbar.urdf [m]: crank AB, coupler BC, rocker DC, ground AD.
L_CRANK, L_COUPLER, L_ROCKER, GROUND = 0.1, 0.3, 0.15, 0.3
#: Two configurations of one mode, each closed to ASSEMBLY_TOL L (1e-12 L, 3e-13 m here),
#: differ by that over the smallest singular value of the passive Jacobian, about the
#: rocker (0.15 m) times the sine of the transmission angle (above 0.3 at crank 1.0): some
#: 1e-12 rad; a thousand times that is still far below the 3.7 rad between the two modes.
SAME_MODE = 1e-9
#: Two compliances of one mode: their configurations agree to some 1e-12 rad, to which C
#: is sensitive in proportion (about 1 per rad here), and each is computed to its scaled
#: condition number (below 1e3 on the four-bar) times the rounding: a margin of 100 at least.
SAME_C = 1e-9


def fourbar(closures: str = "fourbar.yaml"):
    return cl.load_model(data.path("fourbar.urdf"), data.path(closures))


def closed_form(crank: float) -> list[tuple[float, float]]:
    """(coupler, rocker) angles [rad] of both assembly modes of the four-bar at ``crank``,
    C above the line B-D first (elbow up), then below, from the intersection of two
    circles in the x-z plane (law of cosines): C at L_COUPLER from B = L_CRANK (sin c,
    cos c) and at L_ROCKER from D = (GROUND, 0). A rotation by t about y takes z to
    (sin t, cos t) and x to (cos t, -sin t) in (x, z)."""
    B = L_CRANK * np.array([math.sin(crank), math.cos(crank)])
    D = np.array([GROUND, 0.0])
    d = np.linalg.norm(D - B)
    along = (d**2 + L_COUPLER**2 - L_ROCKER**2) / (2 * d)  # from B towards D
    across = math.sqrt(L_COUPLER**2 - along**2)
    u = (D - B) / d
    out = []
    for side in (1.0, -1.0):
        C = B + along * u + side * across * np.array([-u[1], u[0]])
        rocker = math.atan2(C[0] - GROUND, C[1])
        coupler = math.atan2(-(C[1] - B[1]), C[0] - B[0]) - crank
        out.append((coupler, rocker))
    return out


def wrapped(x: float) -> float:
    return (x + math.pi) % (2 * math.pi) - math.pi


def run(capsys, *args) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


# ---------------------------------------------------------------------- the modes found
def test_the_fourbar_has_two_modes_at_crank_1_both_found_and_closed():
    """assembly_modes finds both modes of the four-bar at crank 1.0 rad (C above and below
    the line B-D), each closed, each one of the two closed-form solutions, the default
    assembly first."""
    robot = fourbar()
    modes = cl.assembly_modes(robot, [1.0])
    assert len(modes) == 2
    solutions = closed_form(1.0)
    matched = []
    for a in modes:
        assert a.residual <= ASSEMBLY_TOL * robot.length
        coupler, rocker = a.q[2], a.q[3]
        errors = [max(abs(wrapped(coupler - c)), abs(wrapped(rocker - r))) for c, r in solutions]
        assert min(errors) <= SAME_MODE, errors
        matched.append(int(np.argmin(errors)))
        np.testing.assert_allclose(a.q[[1, 4]], 0.0, atol=0)  # sprung axial joints held at rest
    assert sorted(matched) == [0, 1]
    default = cl.assemble(robot, [1.0]).q
    assert np.max(np.abs(scaled_difference(robot, modes[0].q, default))) <= SAME_MODE
    assert abs(wrapped(default[3] - solutions[0][1])) <= SAME_MODE  # elbow up, as the start


def test_modes_found_are_reproducible_and_the_starts_are_checked():
    robot = fourbar()
    a = cl.assembly_modes(robot, [1.0], samples=8, seed=3)
    b = cl.assembly_modes(robot, [1.0], samples=8, seed=3)
    assert [m.q.tolist() for m in a] == [m.q.tolist() for m in b]
    only = cl.assembly_modes(robot, [1.0], samples=0)  # the default assembly alone
    assert len(only) == 1
    np.testing.assert_array_equal(only[0].q, cl.assemble(robot, [1.0]).q)
    lower = closed_form(1.0)[1]
    start = np.array([1.0, 0.0, lower[0] + 0.2, lower[1] - 0.2, 0.0])
    both = cl.assembly_modes(robot, [1.0], starts=[start], samples=0)
    assert len(both) == 2 and abs(wrapped(both[1].q[3] - lower[1])) <= SAME_MODE
    with pytest.raises(InvalidInputError, match=r"starts\[0\]: q has 3 values; expected nq=5"):
        cl.assembly_modes(robot, [1.0], starts=[[1.0, 0.0, 0.0]])
    with pytest.raises(InvalidInputError, match="samples must be an integer >= 0"):
        cl.assembly_modes(robot, [1.0], samples=-1)


def test_a_model_without_loops_has_one_mode(ur5):
    clm, q = ur5
    modes = cl.assembly_modes(clm, clm.actuated_values(q), samples=4)
    assert len(modes) == 1


def test_an_idle_rod_spin_is_not_another_mode():
    """The MJCF Delta's rods are free bodies between two balls: each spins about its own
    axis freely. Random starts leave the spins anywhere; the mode of the default assembly
    is found once, not once per spin."""
    delta = cl.load_model(data.path("delta.xml"))
    modes = cl.assembly_modes(delta, [0.0, 0.0, 0.0], samples=12)
    default = cl.assemble(delta).q
    platform = delta.model.joints[delta.model.getJointId("platform_free")].idx_q
    same = [
        m
        for m in modes
        if np.allclose(m.q[platform : platform + 7], default[platform : platform + 7], atol=1e-9)
    ]
    assert len(same) == 1


# ------------------------------------------------------- one rule: Python and the CLI
def test_python_and_the_command_line_give_the_same_mode_and_compliance(capsys):
    """cl.assemble put the four-bar's rocker at -3.169 rad at crank 1.0 (one solve from
    neutral, C_xx 1.34e-4 m/N) where --actuated 1.0 put it at 0.518 (C_xx 4.01e-5 m/N):
    both now drive from the model's start, and the output names the passive joints."""
    robot = fourbar()
    q = cl.assemble(robot, actuated=[1.0]).q
    C = cl.compliance(robot, q, "P").C
    code, out, _ = run(capsys, "stiffness", "fourbar", "--frame", "P", "--actuated", 1.0, "--json")
    doc = json.loads(out)
    assert code == 1  # planar: K does not exist
    np.testing.assert_allclose(doc["q"], q, rtol=0, atol=1e-12)  # one computation, twice
    assert_close_in_norm(doc["C"], C, SAME_C)
    assert doc["passive"] == passive_values(robot, q)
    coupler, rocker = closed_form(1.0)[0]  # elbow up, the mode of the start
    np.testing.assert_allclose([q[2], q[3]], [coupler, rocker], rtol=0, atol=SAME_MODE)
    _, text, _ = run(capsys, "stiffness", "fourbar", "--frame", "P", "--actuated", 1.0)
    shown = f"coupler {coupler:.6g}, rocker {rocker:.6g} [rad, m]"
    assert f"assembly mode: passive joints {shown}" in text
    assert "--near JOINT=VALUE" in text


@pytest.mark.parametrize("how", ["near", "start"])
def test_start_and_near_pick_the_other_mode(capsys, how):
    robot = fourbar()
    lower = cl.assembly_modes(robot, [1.0])[1]
    if how == "near":
        options = ["--near", "rocker=-2.5"]
    else:
        options = ["--start", *[wrapped(x) for x in lower.q]]
    code, out, _ = run(capsys, "stiffness", "fourbar", "--frame", "P", "--actuated", 1.0,
                       "--json", *options)  # fmt: skip
    doc = json.loads(out)
    assert code == 1
    assert np.max(np.abs(scaled_difference(robot, lower.q, np.array(doc["q"])))) <= SAME_MODE
    C = cl.compliance(robot, lower.q, "P").C
    assert_close_in_norm(doc["C"], C, SAME_C)
    coupler, rocker = closed_form(1.0)[1]  # elbow down
    assert abs(wrapped(doc["q"][3] - rocker)) <= SAME_MODE
    code, out, _ = run(capsys, "deflect", "fourbar", "--frame", "P", "--actuated", 1.0,
                       "--force", 1, 0, 0, *options)  # fmt: skip
    assert f"assembly mode: passive joints coupler {coupler:.6g}, rocker" in out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--near", "crank=0.2"], "'crank' is actuated; give its value with --actuated"),
        (["--near", "rocker=1,2"], "2 value(s); joint 'rocker' has 1 configuration value"),
        (["--near", "rockr=1"], "unknown joint 'rockr' (did you mean 'rocker'?)"),
        (["--near", "rocker"], "expected JOINT=VALUE or JOINT=V1,V2,..."),
        (["--start", "1", "2"], "--start: q has 2 values; expected nq=5"),
        (["--q", "0", "0", "0", "0", "0", "--start", *"00000"], "--start with --q"),
    ],
)
def test_bad_starts_are_one_line_and_exit_2(capsys, argv, message):
    code, out, err = run(capsys, "stiffness", "fourbar", "--frame", "P", *argv)
    assert code == 2 and out == "" and err.count("\n") == 1
    assert message in err


# ------------------------------------------------------------- a spring on a passive joint
def test_a_sprung_passive_joint_gets_its_rest_value_from_the_command_line(capsys, tmp_path):
    """A spring on the rocker holds it at its start value: the loop closed at one crank
    angle only, exit 3 with no way out. The message names the options, and --near gives
    the rest value that closes it, for a query and a map."""
    springs = tmp_path / "springs.yaml"
    springs.write_text("rocker: 10.0\n")
    coupler, rocker = closed_form(1.0)[0]
    common = ["fourbar", "--springs", springs, "--frame", "P"]
    code, out, err = run(capsys, "stiffness", *common, "--actuated", 1.0)
    assert code == 3 and out == ""
    assert "keep their start values" in err and "--near JOINT=VALUE or --start Q" in err
    code, out, err = run(capsys, "stiffness", *common, "--actuated", 1.0, "--json",
                         "--near", f"rocker={rocker!r}")  # fmt: skip
    assert code == 1, err  # planar: K does not exist, C does
    q = np.array(json.loads(out)["q"])
    np.testing.assert_allclose([q[2], q[3]], [coupler, rocker], rtol=0, atol=SAME_MODE)
    points = tmp_path / "points.txt"
    points.write_text("1.0\n")
    assembled = "1 points: 1 rank_deficient"  # assembled; planar: K does not exist
    for near, status in (
        ([], "1 points: 1 unreachable"),
        (["--near", f"rocker={rocker!r}"], assembled),
    ):
        code, out, err = run(capsys, "map", *common, "--points", points, "--index", "det_K",
                             "--out", tmp_path / "map", *near)  # fmt: skip
        assert code == 0, err
        assert status in out


# ------------------------------------------------------------ start: and the twins
TWINS = ("fourbar", "fivebar5", "rrr3", "delta", "stewart")


@pytest.mark.parametrize("name", TWINS)
def test_urdf_and_mjcf_twins_assemble_in_the_same_mode(name):
    """The bundled URDF and its MJCF twin assemble at their reference configurations in
    the same mode: every frame both have at the same placement. The URDF Delta had its
    platform 0.556 m above the base (its rods start at the origin, pointing up), the MJCF
    Delta 0.8 m below; the URDF four-bar started at crank 0, its twin at 0.5."""
    urdf = cl.load_model(*(data.path(f) for f in data.BUNDLED_MODELS[name]))
    mjcf = cl.load_model(data.path(data.BUNDLED_MODELS[f"{name}_mjcf"][0]))
    placements = []
    for clm in (urdf, mjcf):
        d = clm.model.createData()
        pin.framesForwardKinematics(
            clm.model, d, cl.assemble(clm, None, clm.reference_configuration()).q
        )
        placements.append({f.name: d.oMf[i].homogeneous for i, f in enumerate(clm.model.frames)})
    common = set(placements[0]) & set(placements[1]) - {"universe"}
    assert len(common) >= 4
    for frame in sorted(common):  # 1e-9: a few thousand times the closure tolerance
        np.testing.assert_allclose(placements[0][frame], placements[1][frame], rtol=0,
                                   atol=1e-9, err_msg=frame)  # fmt: skip
    if name == "delta":
        assert placements[0]["platform"][2, 3] < -0.5


def test_the_bundled_cahyman_starts_on_the_mode_of_its_closed_form_geometry():
    """The bundled CaHyMan URDF started at neutral, a singular configuration (no mode);
    its start: is the closed-form pose of Table 1, the pose the cahyman command assembles
    by its own rule (the closed-form guess), on the same mode."""
    from cahyman_pin.model import cahyman_model
    from cahyman_pin.paper.data import TABLE_POSES
    from cahyman_pin.params import DEFAULT_PARAMS

    urdf = cl.load_model(*(data.path(f) for f in data.BUNDLED_MODELS["cahyman"]))
    machine = cahyman_model(DEFAULT_PARAMS)
    alpha, alpha4, s4 = TABLE_POSES[0].si
    np.testing.assert_allclose(urdf.actuated_values(urdf.reference_configuration()),
                               [*alpha, alpha4, s4], rtol=0, atol=1e-15)  # fmt: skip
    for pose in TABLE_POSES:
        alpha, alpha4, s4 = pose.si
        q = cl.assemble(urdf, [*alpha, alpha4, s4]).q
        expected = machine.assemble(alpha, alpha4, s4)
        for j in range(1, urdf.model.njoints):
            a = urdf.model.joints[j]
            b = machine.clm.model.joints[machine.clm.model.getJointId(urdf.model.names[j])]
            got, want = q[a.idx_q : a.idx_q + a.nq], expected[b.idx_q : b.idx_q + b.nq]
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


def test_info_names_the_start_and_its_mode(capsys):
    code, out, _ = run(capsys, "info", "fourbar")
    assert code == 0
    assert "assembly start: the closure file's start:" in out
    assert "assembly mode there: passive joints coupler -0.687929, rocker 0.288384" in out
    code, out, _ = run(capsys, "info", "fourbar_mjcf", "--json")
    start = json.loads(out)["start"]
    assert start["source"] == "the MJCF qpos0"
    np.testing.assert_allclose(start["passive"]["rocker"], 0.2883841948951434, atol=1e-12)
    code, out, _ = run(capsys, "info", "ur5")
    assert "assembly start: the neutral configuration" in out


def write(path, text: str):
    path.write_text(text)
    return path


def test_the_start_key_of_a_closure_file(tmp_path):
    """start: names joints and their values (a list for a multi-coordinate joint): the
    reference configuration, found before any other; bad entries name the file and joint."""
    base = data.path("fourbar.yaml").read_text().split("start:")[0]
    good = write(tmp_path / "good.yaml", base + "start: {rocker: -2.9, coupler: [-0.25]}\n")
    robot = cl.load_model(data.path("fourbar.urdf"), good)
    np.testing.assert_array_equal(robot.reference_configuration(), [0, 0, -0.25, -2.9, 0])
    q = cl.assemble(robot, [1.0]).q
    assert abs(wrapped(q[3] - closed_form(1.0)[1][1])) <= SAME_MODE  # elbow down
    cases = [
        ("start: {rocker: [1, 2]}", ModelFileError, r"start of joint 'rocker' has 2 value\(s\)"),
        ("start: {rocker: abc}", ModelFileError, "start of joint 'rocker' is 'abc'; expected"),
        ("start: {rocker: .nan}", ModelFileError, "start of joint 'rocker' is nan"),
        ("start: [rocker]", ModelFileError, "start must be a mapping joint name -> value"),
        ("start: {rockr: 1}", NameNotFoundError, "unknown joint 'rockr'"),
    ]
    for text, error, message in cases:
        bad = write(tmp_path / "bad.yaml", base + text + "\n")
        with pytest.raises(error, match=message) as e:
            cl.load_model(data.path("fourbar.urdf"), bad)
        assert "bad.yaml" in str(e.value)


def test_the_start_key_of_a_side_file_and_its_quaternions(tmp_path):
    side = write(
        tmp_path / "side.yaml", "start: {platform_free: [0.03, -0.02, -0.8, 0, 0, 0, 2]}\n"
    )
    with pytest.raises(ModelFileError, match=r"'platform_free'.*not of norm 1"):
        cl.load_model(data.path("delta.xml"), side)
    write(side, "start: {platform_free: [0.03, -0.02, -0.7, 0, 0, 0, 1]}\n")
    delta = cl.load_model(data.path("delta.xml"), side)
    i = delta.model.joints[delta.model.getJointId("platform_free")].idx_q
    assert delta.reference_configuration()[i + 2] == -0.7  # start: before qpos0
    assert "qpos0" in delta.model.referenceConfigurations


def test_a_map_starts_on_the_mode_of_its_q0():
    """stiffness_map(q0=...) drives its path from q0, on q0's mode (the command line's
    --start and --near): each point's C is that of the lower mode assembled there."""
    from closedloop.analysis.maps import stiffness_map

    robot = fourbar()
    lower = cl.assembly_modes(robot, [1.0])[1].q
    cranks = np.array([[1.0], [1.1], [1.2]])
    result = stiffness_map(robot, "P", points=cranks, q0=lower)
    q = lower
    for crank, C in zip(cranks, result.C, strict=True):
        q = cl.assemble(robot, crank, q).q
        assert abs(wrapped(q[3])) > 2.5  # C below the ground line
        assert_close_in_norm(C, cl.compliance(robot, q, "P").C, SAME_C)
    with pytest.raises(InvalidInputError, match="give a start provider"):
        stiffness_map(robot, "P", points=cranks, q0=lower, start=lambda clm, p: None)
