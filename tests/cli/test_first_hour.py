"""What a new user meets first: poses outside the joint limits (degrees), models without
springs, name errors, ``closedloop info`` and ``closedloop deflect``, rounding noise in
printed numbers."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest
from helpers import REPO

import closedloop as cl
from closedloop import data
from closedloop.cli.app import main
from closedloop.common.rounding import ROUNDING_RTOL, without_rounding
from closedloop.kinematics.driving import assemble_within_limits

UR5_Q = [0.0, -1.0, 1.5, -0.5, 1.2, 0.3]  # [rad]
UR5_DEGREES = [0, -57, 86, -29, 69, 17]  # the same pose typed in degrees
UR5_K = 1e4  # [N m/rad]
# C = J K^-1 J^T by two routes (closedloop's factor, Pinocchio's plain Jacobian): a few
# ulps of the largest entry
RTOL_EXACT = 1e-10


def run(capsys, *args) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def one_error_line(err: str) -> str:
    assert err.startswith("closedloop: error: ") and err.count("\n") == 1, err
    return err


# ------------------------------------------------------------------------ joint limits
def test_no_limits_drives_the_actuated_values_on_the_start_mode(capsys):
    """--no-limits changes only the limits check: --actuated still drives the crank from the
    file's configuration in steps (one direct solve lands the bundled four-bar on its other
    assembly mode at crank 1.0 rad, rocker -3.17 rad)."""
    runs = [
        run(capsys, "stiffness", "fourbar", "--frame", "P", "--actuated", "1.0", "--json", *flag)
        for flag in ((), ("--no-limits",))
    ]
    (code, out, _), (code_free, out_free, _) = runs
    assert code == code_free == 1  # planar: K does not exist, C does
    q, q_free = (np.array(json.loads(o)["q"]) for o in (out, out_free))
    np.testing.assert_allclose(q_free, q, rtol=0, atol=1e-9)  # the assembly's tolerance
    robot = cl.load_model(data.path("fourbar.urdf"), data.path("fourbar.yaml"))
    neutral = pin.neutral(robot.model)
    direct = assemble_within_limits(robot, [1.0], neutral).q  # one solve: the other mode
    assert np.max(np.abs(direct - q)) > 1.0


def test_degrees_are_refused_naming_joint_value_limits(ur5):
    clm, _ = ur5
    with pytest.raises(cl.OutsideLimitsError, match=r"elbow_joint = 86 \(limits \[-3.14159") as e:
        cl.compliance(clm, UR5_DEGREES, "tool0")
    assert "degrees?" in str(e.value) and "check_limits=False" in str(e.value)
    np.testing.assert_allclose(e.value.joints["elbow_joint"], (86.0, -np.pi, np.pi), rtol=1e-11)
    assert isinstance(e.value, cl.InvalidInputError)  # bad input: exit status 2
    with pytest.raises(cl.OutsideLimitsError):
        cl.Configuration(clm, UR5_DEGREES)
    with pytest.raises(cl.OutsideLimitsError) as e:
        cl.compliances(clm, np.array([UR5_Q, UR5_DEGREES]), "tool0")
    assert "at configuration 1 of Q" in e.value.__notes__


def test_just_outside_a_limit_has_no_degrees_hint(ur5):
    """The elbow at 3.2 rad (limit pi): outside, and no 'degrees?' below 2 pi."""
    clm, _ = ur5
    q = np.array(UR5_Q)
    q[2] = 3.2
    with pytest.raises(cl.OutsideLimitsError, match=r"elbow_joint = 3\.2 ") as e:
        cl.compliance(clm, q, "tool0")
    assert "degrees?" not in str(e.value)


def test_the_opt_out_queries_the_pose_as_given(ur5):
    """check_limits=False: the compliance at the angles as radians, which is Pinocchio's
    J K^-1 J^T there."""
    clm, _ = ur5
    res = cl.compliance(clm, UR5_DEGREES, "tool0", check_limits=False)
    model = clm.model
    J = pin.computeFrameJacobian(
        model, model.createData(), np.array(UR5_DEGREES, float), model.getFrameId("tool0"),
        pin.LOCAL_WORLD_ALIGNED,
    )  # fmt: skip
    C = J @ J.T / UR5_K
    np.testing.assert_allclose(res.C, C, rtol=0, atol=RTOL_EXACT * np.abs(C).max())
    batch = cl.compliances(clm, np.array([UR5_DEGREES]), "tool0", check_limits=False)
    np.testing.assert_allclose(batch.C[0], C, rtol=0, atol=RTOL_EXACT * np.abs(C).max())
    state = cl.Configuration(clm, UR5_DEGREES, check_limits=False)
    np.testing.assert_allclose(cl.compliance(state, "tool0").C, res.C, rtol=0, atol=0)


def test_unlimited_joints_are_never_refused(ur5):
    """Limits set to +-inf (a model without limits) and to 1e300 (unbounded defaults)."""
    clm, _ = ur5
    model = clm.model.copy()
    model.lowerPositionLimit[:] = -np.inf
    model.upperPositionLimit[:] = 1e300
    free = cl.ClosedLoopModel(model, actuated=clm.actuated, springs=clm.springs)
    assert cl.compliance(free, UR5_DEGREES, "tool0").rank == 6


def test_a_passive_angle_wound_by_a_turn_is_within(fourbar):
    """The four-bar's coupler (passive) wound by 2 turns counts by its placement; the
    crank (actuated) wound by one turn is refused."""
    clm, q = fourbar
    wound = q.copy()
    wound[clm.model.joints[clm.joint_id("coupler")].idx_q] += 4 * np.pi
    np.testing.assert_allclose(
        cl.compliance(clm, wound, "P").C, cl.compliance(clm, q, "P").C, rtol=1e-9, atol=1e-15
    )
    wound = q.copy()
    wound[clm.model.joints[clm.joint_id("crank")].idx_q] += 2 * np.pi
    with pytest.raises(cl.OutsideLimitsError, match=r"crank = 6\.58"):
        cl.compliance(clm, wound, "P")


def test_cli_refuses_degrees_and_takes_no_limits(capsys, ur5_urdf):
    base = ["stiffness", ur5_urdf, "--frame", "tool0", "--joint-stiffness", UR5_K]
    code, out, err = run(capsys, *base, "--q", *UR5_DEGREES)
    assert code == 2 and out == ""
    assert "elbow_joint = 86" in one_error_line(err) and "--no-limits" in err
    code, out, err = run(capsys, *base, "--q", *UR5_DEGREES, "--no-limits")
    assert code == 0 and err == "" and "stiffness K" in out
    code, out, err = run(capsys, *base, "--actuated", *UR5_DEGREES)
    assert code == 2 and "outside their limits" in one_error_line(err)


def test_the_files_own_configuration_is_taken_as_drawn(capsys, panda_urdf):
    """The Panda's neutral configuration (its file's) has joints 4 and 6 at 0, outside
    their limits: typed as --q it is refused, taken from the file (no --q) it is not."""
    base = ["stiffness", panda_urdf, "--frame", "panda_hand", "--joint-stiffness", UR5_K]
    code, out, err = run(capsys, *base)
    assert code in (0, 1) and err == "" and "compliance C" in out
    code, out, err = run(capsys, *base, "--q", *[0] * 8)
    assert code == 2 and out == "" and "panda_joint4 = 0 " in one_error_line(err)


def test_view_refuses_degrees_and_draws_them_with_no_limits(capsys, ur5_urdf, tmp_path):
    base = ["view", ur5_urdf, "--frame", "tool0", "--joint-stiffness", UR5_K, "--q",
            *UR5_DEGREES, "--force", 0, 0, -10, "--html", tmp_path / "v.html"]  # fmt: skip
    code, out, err = run(capsys, *base)
    assert code == 2 and out == "" and "degrees?" in one_error_line(err)
    assert not (tmp_path / "v.html").exists()
    code, out, err = run(capsys, *base, "--no-limits")
    assert code == 0 and err == "" and (tmp_path / "v.html").is_file()


# ------------------------------------------------------------------------ no springs
def test_no_spring_is_named_with_the_way_to_give_springs(capsys, ur5_urdf):
    bare = cl.load_model(ur5_urdf)
    res = cl.compliance(bare, UR5_Q, "tool0")
    assert res.rank == 0 and "no joint, beam or closure of the model has a spring" in res.note
    with pytest.raises(cl.RigidDirectionsError, match="joint_stiffness="):
        _ = res.K
    code, out, err = run(capsys, "stiffness", ur5_urdf, "--frame", "tool0", "--q", *UR5_Q)
    assert code == 1 and err == ""
    assert "has a spring" in out and "--joint-stiffness" in out and "--springs" in out
    code, out, _ = run(capsys, "stiffness", ur5_urdf, "--frame", "tool0", "--json")
    assert code == 1 and "--joint-stiffness" in json.loads(out)["note"]


def test_springs_that_do_not_reach_the_frame_are_named(ur5):
    """The UR5's base: springs exist, none moves it."""
    clm, q = ur5
    res = cl.compliance(clm, q, "base_link")
    assert res.rank == 0 and "none of the model's springs moves this frame" in res.note
    assert cl.compliance(clm, q, "tool0").note == ""


# ------------------------------------------------------------------------ names, info
def test_a_wrong_frame_name_offers_the_closest_and_lists_all(ur5):
    clm, _ = ur5
    with pytest.raises(cl.NameNotFoundError) as e:
        clm.frame_id("tool")
    text = str(e.value)
    assert "(did you mean 'tool0'?)" in text and e.value.close[0] == "tool0"
    assert all(repr(f.name) in text for f in clm.model.frames)  # all 22, tool0 the last
    with pytest.raises(cl.NameNotFoundError, match="did you mean 'elbow_joint'"):
        clm.joint_id("elbow")


def test_info_lists_joints_frames_closures(capsys, fourbar_urdf, fourbar_yaml):
    code, out, err = run(capsys, "info", fourbar_urdf, "--closures", fourbar_yaml, "--json")
    assert code == 0 and err == ""
    info = json.loads(out)
    clm = cl.load_model(fourbar_urdf, fourbar_yaml)
    assert (info["nq"], info["nv"]) == (clm.model.nq, clm.model.nv)
    np.testing.assert_allclose(info["length"], clm.length, rtol=0, atol=0)
    assert [j["name"] for j in info["joints"]] == list(clm.model.names)[1:]
    roles = {j["name"]: j["role"] for j in info["joints"]}
    assert roles == {"crank": "actuated", "crank_axial": "sprung", "coupler": "passive",
                     "rocker": "passive", "rocker_axial": "sprung"}  # fmt: skip
    crank = info["joints"][0]
    assert crank["type"] == "revolute" and crank["spring"] == [50.0]
    np.testing.assert_allclose(crank["limits"], [-6.3, 6.3], rtol=0, atol=0)
    assert info["closures"] == [{"name": c.name, "type": c.kind} for c in clm.closures]
    assert [f["name"] for f in info["frames"]] == [f.name for f in clm.model.frames]
    code, text, _ = run(capsys, "info", fourbar_urdf, "--closures", fourbar_yaml)
    assert code == 0 and "crank_axial" in text and "(3d)" in text and "nq 5, nv 5" in text


def test_info_of_a_robot_without_springs_says_so(capsys, ur5_urdf):
    code, out, _ = run(capsys, "info", ur5_urdf)
    assert code == 0 and "rigid (no spring)" in out and "no spring" in out
    assert "tool0" in out
    code, out, _ = run(capsys, "info", ur5_urdf, "--joint-stiffness", UR5_K, "--json")
    assert all(j["spring"] == [UR5_K] for j in json.loads(out)["joints"])


def test_info_columns_stay_aligned_with_long_joint_names(capsys, tmp_path, fourbar_urdf):
    """An elastic closure's joints have long names ("<A><->B_px"): the table widens."""
    side = tmp_path / "fourbar.yaml"
    side.write_text((fourbar_urdf.parent / "fourbar.yaml").read_text()
                    + "closure_springs: {0: [2.0e+5, 2.0e+5, 2.0e+5, 0, 0, 0]}\n")  # fmt: skip
    code, out, _ = run(capsys, "info", fourbar_urdf, "--closures", side)
    table = out.split("joints (")[1].split("\n\n")[0].splitlines()[1:]
    assert code == 0 and any("<->" in row for row in table)
    assert len({row.index(" revolute ") if " revolute " in row else row.index(" prismatic ")
                for row in table[1:]}) == 1  # fmt: skip


def test_info_of_a_missing_file_is_one_line(capsys, tmp_path):
    code, out, err = run(capsys, "info", tmp_path / "none.urdf")
    assert code == 2 and out == "" and one_error_line(err)


# ------------------------------------------------------------------------ deflect
def test_deflect_is_pinocchios_twist_under_the_load(capsys, ur5_urdf):
    """UR5, equal springs k: t = J K^-1 J^T w and dq = K^-1 J^T w from Pinocchio's
    Jacobian (world-aligned at tool0)."""
    w = np.array([10.0, -20.0, -100.0, 1.0, 2.0, 0.5])
    code, out, err = run(
        capsys, "deflect", ur5_urdf, "--frame", "tool0", "--q", *UR5_Q, "--joint-stiffness",
        UR5_K, "--force", *w[:3], "--torque", *w[3:], "--json",
    )  # fmt: skip
    assert code == 0 and err == ""
    doc = json.loads(out)
    model = pin.buildModelFromUrdf(str(ur5_urdf))
    J = pin.computeFrameJacobian(model, model.createData(), np.array(UR5_Q),
                                 model.getFrameId("tool0"), pin.LOCAL_WORLD_ALIGNED)  # fmt: skip
    dq = J.T @ w / UR5_K
    t = J @ dq
    np.testing.assert_allclose(doc["twist"], t, rtol=0, atol=RTOL_EXACT * np.abs(t).max())
    got = [d["value"] for d in doc["joint_deflections"]]
    np.testing.assert_allclose(got, dq, rtol=0, atol=RTOL_EXACT * np.abs(dq).max())
    # energy shares: 1/2 k dq_i^2 over the work 1/2 w^T t
    shares = UR5_K * dq**2 / (w @ t)
    np.testing.assert_allclose(list(doc["energy_shares"].values()), shares, rtol=1e-9,
                               atol=1e-12)  # fmt: skip
    code, text, _ = run(
        capsys, "deflect", ur5_urdf, "--frame", "tool0", "--q", *UR5_Q, "--joint-stiffness",
        UR5_K, "--force", *w[:3], "--torque", *w[3:],
    )  # fmt: skip
    assert code == 0 and f"{1e3 * t[2]:.6g}" in text and "shoulder_lift_joint" in text


def test_deflect_of_a_rank_deficient_frame_exits_1(capsys, fourbar_urdf, fourbar_yaml):
    code, out, err = run(capsys, "deflect", fourbar_urdf, "--closures", fourbar_yaml,
                         "--frame", "P", "--actuated", 0.3, "--force", 10, 0, 0)  # fmt: skip
    assert code == 1 and err == "" and "rank of C 3/6" in out


def test_deflect_takes_the_pose_options_and_refuses_bad_ones(capsys, ur5_urdf):
    code, out, err = run(capsys, "deflect", ur5_urdf, "--frame", "tool0", "--q", *UR5_DEGREES,
                         "--joint-stiffness", UR5_K, "--force", 0, 0, -1)  # fmt: skip
    assert code == 2 and out == "" and "degrees?" in one_error_line(err)
    code, out, err = run(capsys, "deflect", ur5_urdf, "--frame", "tool0", "--force", 0, 0)
    assert code == 2 and out == "" and one_error_line(err)


# ------------------------------------------------------------------------ rounding
def test_rounding_noise_is_zero_and_the_rest_kept():
    v = np.array([90.0, 2.08899e-19, -1.31542e-47, -3e-6, np.nan])
    np.testing.assert_array_equal(without_rounding(v), [90.0, 0.0, 0.0, -3e-6, np.nan])
    edge = 90.0 * ROUNDING_RTOL
    np.testing.assert_array_equal(without_rounding([90.0, edge, 2 * edge]), [90.0, 0.0, 2 * edge])
    np.testing.assert_array_equal(without_rounding([0.0, 0.0]), [0.0, 0.0])
    assert without_rounding([-1e-30])[0] == -1e-30  # a vector's only component is its size


# ------------------------------------------------------------------------ bundled models
def test_every_bundled_file_has_a_name():
    """Each URDF (with its closure file) and each MJCF of urdf/ is a bundled model."""
    files = {p.name for p in data.data_dir().iterdir() if p.suffix in (".urdf", ".xml")}
    named = {robot for robot, _ in data.BUNDLED_MODELS.values()}
    assert named == files
    for _, side in data.BUNDLED_MODELS.values():
        assert side is None or data.path(side).is_file()


@pytest.mark.parametrize(
    ("name", "actuated"),
    [
        ("stewart", [f"leg{i}" for i in range(6)]),
        ("stewart_mjcf", [f"leg{i}" for i in range(6)]),
        ("delta", ["arm0", "arm1", "arm2"]),
        ("delta_mjcf", ["arm0", "arm1", "arm2"]),
        ("rrr3", ["leg0", "leg1", "leg2"]),
        ("fivebar5_mjcf", ["leg0", "leg1"]),
        ("cahyman", ["alpha_1", "alpha_2", "alpha_3", "alpha_4", "s_4"]),
    ],
)
def test_bundled_models_load_by_name_with_their_actuators(capsys, name, actuated):
    code, out, err = run(capsys, "info", name, "--json")
    assert code == 0 and err == ""
    assert json.loads(out)["actuated"] == actuated


def test_a_bundled_name_works_from_any_folder(tmp_path):
    """From an empty folder, as a subprocess: the Stewart platform by name, driven by its
    six legs (K exists, exit 0)."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    line = [sys.executable, "-m", "closedloop", "stiffness", "stewart", "--frame", "platform",
            "--actuated", "0.01", "0", "0", "0", "0", "-0.01", "--json"]  # fmt: skip
    done = subprocess.run(line, cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=120, check=False)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["rank"] == 6


# ------------------------------------------------------------------------ printed numbers
def test_cahyman_deflect_prints_rounding_as_zero_and_json_keeps_it(capsys):
    """At alpha = alpha4 = 90 deg the plate's theta and M's rz are 0 in exact arithmetic:
    the text shows 0 (it showed -1.31542e-47 deg and 2.08899e-19 deg), the JSON the raw
    values, which are rounding (below ROUNDING_RTOL of their vector)."""
    from cahyman_pin.cli import main as cahyman_main

    line = ["deflect", "--alpha", "90", "90", "90", "--alpha4", "90", "--s4", "50",
            "--force", "1", "1", "-1e2", "--torque", "0", "0", "0"]  # fmt: skip
    assert cahyman_main(line) == 0
    text = capsys.readouterr().out
    assert "phi, theta, psi = ( 90,  0,  0) deg" in text
    assert "e-19" not in text and "e-47" not in text
    assert cahyman_main([*line, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    rot = np.array(doc["M"]["rotation_rad"])
    assert abs(rot[2]) <= ROUNDING_RTOL * np.abs(rot).max()
    np.testing.assert_array_equal(without_rounding(rot), [rot[0], rot[1], 0.0])
    assert rot[0] != 0.0 and rot[1] != 0.0


def test_a_preloaded_query_refuses_the_rest_pose_outside_unless_asked(fourbar):
    """compliance(..., gravity) checks the rest configuration as the plain query does;
    with check_limits=False the statics take it and flag the equilibrium outside the
    limits (JointLimitWarning), their own rule."""
    clm, q = fourbar
    turned = q.copy()
    turned[clm.model.joints[clm.joint_id("crank")].idx_q] += 2 * np.pi
    with pytest.raises(cl.OutsideLimitsError, match=r"crank = 6\.58"):
        cl.compliance(clm, turned, "P", preload=[1.0, 0, 2.0, 0, 0, 0])
    with pytest.warns(cl.JointLimitWarning, match=r"crank = 6\.58"):
        res = cl.compliance(clm, turned, "P", preload=[1.0, 0, 2.0, 0, 0, 0], check_limits=False)
    assert res.equilibrium.limits_violated == ("crank",)
