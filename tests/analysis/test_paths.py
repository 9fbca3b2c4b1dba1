"""A path under a load (issue #42): the loaded equilibria, the exact and the first-order
compensation, against closed forms (a serial arm with joint springs, a Stewart platform),
the continuation of the statics and the equilibrium written from Pinocchio's kinematics
alone; errors that name the point and keep the points before it."""

from __future__ import annotations

import signal
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pinocchio as pin
import pytest
from mechanisms import stewart, stewart_inverse_jacobian
from pinocchio_statics import gaps, placement, unbalance
from scipy.spatial.transform import Rotation

import closedloop as cl
from closedloop.analysis import path_points
from closedloop.analysis.interrupts import Interrupted
from closedloop.io.loader import load_urdf
from closedloop.kinematics.frame_task import pose_error, target_placement, xyzquat

#: Distinct joint springs of the UR5 [N m/rad] (a single value would hide a mixed-up joint).
UR5_SPRINGS = (8e3, 1.2e4, 9e3, 3e3, 2.5e3, 1.5e3)
UR5_START = np.array([0.0, -1.0, 1.5, -0.5, 1.2, 0.3])
WRENCH = np.array([30.0, -20.0, -60.0, 2.0, -1.0, 3.0])
GRAVITY = np.array([0.0, 0.0, -9.80665])
#: Closure and task rows of an equilibrium or a compensation [m per L, rad], with a factor
#: 2 for recomputing them here.
ATOL = 2e-12
#: Agreement of two equilibria of one branch [rad, m]: each balances to FORCE_RTOL
#: (1e-11) of its forces, the tangent stiffness within a factor 3 of the springs', the
#: deflections 1e-2 rad: 1e-12 rad, with a factor 100.
ATOL_SAME = 1e-10
#: Unbalance of an equilibrium, relative to its forces: 1e-11 from the solver; with
#: closures, the closure Jacobian by central differences (pinocchio_statics.GAP_STEP)
#: adds 1e-10 of the closure forces.
RTOL_UNBALANCE = 1e-9


@pytest.fixture(scope="module")
def ur5(ur5_urdf):
    joints = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
              "wrist_2_joint", "wrist_3_joint")  # fmt: skip
    springs = dict(zip(joints, UR5_SPRINGS, strict=True))
    return load_urdf(ur5_urdf, springs=springs, geometry=False)


def _line(M: pin.SE3, n: int, step) -> np.ndarray:
    """(n, 7) poses moved from M by k step (3,) [m], k = 0..n-1, orientation kept."""
    return np.array([xyzquat(pin.SE3(M.rotation, M.translation + k * np.asarray(step)))
                     for k in range(n)])  # fmt: skip


@pytest.fixture(scope="module")
def ur5_path(ur5):
    path = _line(placement(ur5.model, UR5_START, "tool0"), 4, (0.01, 0.02, -0.01))
    return path, cl.follow_path(ur5, "tool0", path, wrench=WRENCH, gravity=GRAVITY, q0=UR5_START)


def _jacobian_and_weight(model, theta):
    """(tool0's Jacobian (6, 6), world axes at its origin; the generalised gravity G (6,)
    [N m]) at theta, from Pinocchio."""
    fid = model.getFrameId("tool0")
    J = pin.computeFrameJacobian(model, model.createData(), theta, fid, pin.LOCAL_WORLD_ALIGNED)
    heavy = pin.Model(model)
    heavy.gravity = pin.Motion(np.r_[GRAVITY, np.zeros(3)])
    return J, pin.computeGeneralizedGravity(heavy, heavy.createData(), theta)


def test_serial_arm_compensation_is_the_closed_form(ur5, ur5_path):
    """With springs on its actuators only, a serial arm holds the target pose at the
    unloaded configuration itself, with theta_cmd = theta - K^-1 (J^T w - G(theta))."""
    path, r = ur5_path
    model = ur5.model
    for i, theta in enumerate(r.q_target):
        J, G = _jacobian_and_weight(model, theta)
        expected = theta - (J.T @ WRENCH - G) / np.array(UR5_SPRINGS)
        np.testing.assert_allclose(r.commands[i], expected, rtol=0, atol=ATOL_SAME)
        np.testing.assert_allclose(r.q_compensated[i], theta, rtol=0, atol=ATOL)
        target = target_placement(path[i])
        error = pose_error(placement(model, theta, "tool0"), target)
        np.testing.assert_allclose(error, 0.0, atol=ATOL * ur5.length)
    np.testing.assert_allclose(r.residual, 0.0, atol=ATOL * ur5.length)


def test_loaded_equilibria_are_the_continuation_of_the_statics(ur5, ur5_path):
    """Each point's equilibrium (the first by the continuation, the next from the last
    point's) is the branch from rest of solve_equilibrium, and balances the forces written
    from Pinocchio alone, as does the compensated one with the springs at the commands."""
    _, r = ur5_path
    for i, theta in enumerate(r.q_target):
        eq = cl.solve_equilibrium(ur5, theta, "tool0", WRENCH, gravity=GRAVITY)
        np.testing.assert_allclose(r.q_loaded[i], eq.q, rtol=0, atol=ATOL_SAME)
        error = pose_error(
            placement(ur5.model, r.q_loaded[i], "tool0"), placement(ur5.model, theta, "tool0")
        )
        np.testing.assert_allclose(r.error[i], error, rtol=0, atol=1e-15)
        assert unbalance(ur5, r.q_loaded[i], theta, "tool0", WRENCH, GRAVITY) <= RTOL_UNBALANCE
        rest = r.commands[i]
        assert unbalance(ur5, r.q_compensated[i], rest, "tool0", WRENCH, GRAVITY) <= RTOL_UNBALANCE


def test_first_order_compensation_mirrors_the_linear_deflection(ur5, ur5_path):
    """The first-order commands put the unloaded frame at the programmed pose moved back by
    the linear deflection J K^-1 (J^T w - G) (written here); under the load they leave a
    residual, the second-order error the exact compensation removes."""
    _, r = ur5_path
    model = ur5.model
    for i, theta in enumerate(r.q_target):
        J, G = _jacobian_and_weight(model, theta)
        twist = J @ ((J.T @ WRENCH - G) / np.array(UR5_SPRINGS))
        np.testing.assert_allclose(r.deflection_first_order[i], twist, rtol=1e-10, atol=0)
        P = placement(model, theta, "tool0")
        mirrored = pin.SE3(pin.exp3(-twist[3:]) @ P.rotation, P.translation - twist[:3])
        at = placement(model, r.commands_first_order[i], "tool0")
        np.testing.assert_allclose(pose_error(at, mirrored), 0.0, atol=ATOL * ur5.length)
        eq = cl.solve_equilibrium(ur5, r.commands_first_order[i], "tool0", WRENCH, gravity=GRAVITY)
        residual = pose_error(placement(model, eq.q, "tool0"), P)
        np.testing.assert_allclose(r.residual_first_order[i], residual, rtol=0, atol=1e-12)
    error = np.linalg.norm(r.error[:, :3], axis=1)
    first = np.linalg.norm(r.residual_first_order[:, :3], axis=1)
    assert np.all(first < 0.01 * error) and np.all(first > 1e-6 * error)


def test_stewart_legs_in_closed_form():
    """Compensated, the platform is at the target: its legs have the lengths
    l_i = |p + R a_i - b_i|, their tensions t = J^-T w (J the rows [u_i, r_i x u_i]) and the
    commands l - t / k (all by hand)."""
    start = stewart(position=(0.0, 0.0, 1.0))
    clm, g = start.clm, start.geometry
    poses = [(np.array([0.0, 0.0, 1.0]), np.zeros(3)),
             (np.array([0.03, -0.02, 1.05]), np.array([0.02, -0.03, 0.05])),
             (np.array([0.06, -0.04, 1.1]), np.array([0.04, -0.06, 0.1]))]  # fmt: skip
    path = [xyzquat(pin.SE3(Rotation.from_rotvec(v).as_matrix(), p)) for p, v in poses]
    w = np.array([150.0, -80.0, 400.0, 20.0, -30.0, 15.0])
    r = cl.follow_path(clm, "platform", path, wrench=w, q0=start.q)
    legs = [clm.model.joints[clm.joint_id(f"leg{i}")].idx_q for i in range(6)]
    for i, (p, v) in enumerate(poses):
        R = Rotation.from_rotvec(v).as_matrix()
        rr = g["a"] @ R.T
        leg = p + rr - g["b"]
        lengths = np.linalg.norm(leg, axis=1)
        tension = np.linalg.solve(stewart_inverse_jacobian(leg / lengths[:, None], rr).T, w)
        np.testing.assert_allclose(r.q_compensated[i][legs], lengths, atol=ATOL * clm.length)
        np.testing.assert_allclose(r.q_target[i][legs], lengths, atol=ATOL * clm.length)
        np.testing.assert_allclose(r.commands[i], lengths - tension / g["k"], rtol=1e-10)
        for q in (r.q_target[i], r.q_loaded[i], r.q_compensated[i]):
            np.testing.assert_allclose(gaps(clm, q), 0.0, atol=ATOL * clm.length)
        assert unbalance(clm, r.q_loaded[i], r.q_target[i], "platform", w) <= RTOL_UNBALANCE
        rest = np.array(r.q_target[i])
        rest[legs] = r.commands[i]
        assert unbalance(clm, r.q_compensated[i], rest, "platform", w) <= RTOL_UNBALANCE


@pytest.fixture(scope="module")
def drilling(cahyman):
    """CaHyMan's tool along a straight line, axis fixed, 60 N of thrust along the axis."""
    q = np.array(cahyman.assemble(np.radians([60.0, 60.0, 60.0]), np.radians(45.0), 0.025))
    T = placement(cahyman.clm.model, q, "tool")
    path = _line(T, 3, (0.0, 0.01, 0.0))
    w = np.r_[-60.0 * T.rotation[:, 2], 0.0, 0.0, 0.0]
    return q, path, w, cl.follow_path(cahyman.clm, "tool", path, wrench=w, task="tool-axis", q0=q)


def test_cahyman_tool_axis_compensation(cahyman, drilling):
    """At every point of a 5-axis line: the loops close, the compensated tool meets the
    programmed position and axis, the equilibria balance (Pinocchio alone) and the commands
    assembled and loaded by the continuation of the statics give the same equilibrium."""
    clm, L = cahyman.clm, cahyman.clm.length
    _, path, w, r = drilling
    assert r.held == "tool-axis"
    for i in range(r.n):
        for q in (r.q_target[i], r.q_loaded[i], r.q_compensated[i]):
            np.testing.assert_allclose(gaps(clm, q), 0.0, atol=ATOL * L)
        target = target_placement(path[i])
        T0 = placement(clm.model, r.q_target[i], "tool")
        np.testing.assert_allclose(T0.translation, target.translation, atol=ATOL * L)
        np.testing.assert_allclose(T0.rotation[:, 2], target.rotation[:, 2], atol=ATOL)
        Tc = placement(clm.model, r.q_compensated[i], "tool")
        np.testing.assert_allclose(Tc.translation, T0.translation, atol=ATOL * L)
        np.testing.assert_allclose(Tc.rotation[:, 2], T0.rotation[:, 2], atol=ATOL)
        assert unbalance(clm, r.q_loaded[i], r.q_target[i], "tool", w) <= RTOL_UNBALANCE
        rest = cl.assemble(clm, r.commands[i], r.q_target[i]).q
        assert unbalance(clm, r.q_compensated[i], rest, "tool", w) <= RTOL_UNBALANCE
        eq = cl.solve_equilibrium(clm, rest, "tool", w)
        np.testing.assert_allclose(
            pin.difference(clm.model, eq.q, r.q_compensated[i]), 0.0, atol=ATOL_SAME
        )
        loaded = cl.solve_equilibrium(clm, r.q_target[i], "tool", w)
        np.testing.assert_allclose(
            pin.difference(clm.model, loaded.q, r.q_loaded[i]), 0.0, atol=ATOL_SAME
        )
    tilt = r.held_rotation(r.residual[:, 3:])
    np.testing.assert_allclose(tilt, 0.0, atol=ATOL)
    assert np.all(r.held_rotation(r.error[:, 3:]) > 1e-5)  # the thrust does tilt it


# ---------------------------------------------------------------- errors and interruptions
def test_unreachable_point_is_named_and_the_points_before_it_kept(ur5, ur5_path):
    path = np.array(ur5_path[0])
    path[2, :3] = (3.0, 0.0, 0.5)
    with pytest.raises(cl.UnreachableError) as info:
        cl.follow_path(ur5, "tool0", path, wrench=WRENCH, q0=UR5_START)
    e = info.value
    assert str(e).startswith("path point 2 of 4 (target [3.0, 0.0, 0.5")
    assert e.point == 2 and e.partial.n == 2
    np.testing.assert_allclose(e.partial.targets, path[:2])
    assert not e.partial.commands.flags.writeable


@pytest.fixture(scope="module")
def fold(cahyman):
    """CaHyMan near a leg singularity, the load growing along U (tests/elastostatics/
    test_statics_folds.py: the branch from rest folds at 0.337 U), the pose held."""
    q = np.array(cahyman.assemble(np.radians([2.0, 60.0, 75.0]), np.radians(45.0), 0.0))
    M = placement(cahyman.clm.model, q, "M")
    U = np.array([0.0217, 0.138, -0.1868, -0.4642, 0.7863, 0.3345])
    s = np.array([0.25, 0.3, 0.34])
    return q, np.tile(xyzquat(M), (len(s), 1)), s[:, None] * U


@pytest.mark.filterwarnings("ignore::closedloop.JointLimitWarning")
@pytest.mark.parametrize("executor", [None, "threads"])
def test_limit_load_is_named_and_the_points_before_it_kept(cahyman, fold, executor):
    """The fold at 0.337 U ends the path at its point 2 (0.34 U), also when that point is
    computed in a chunk of an executor (its error carried back)."""
    q, path, wrenches = fold
    options = {"wrench": wrenches, "task": "position", "q0": q, "check_limits": False}
    with ThreadPoolExecutor(2) if executor else _nothing() as pool:
        with pytest.raises(cl.EquilibriumError) as info:
            cl.follow_path(cahyman.clm, "M", path, executor=pool, chunk=2, **options)
    e = info.value
    assert e.limit_load and e.point == 2 and e.partial.n == 2
    assert str(e).startswith("path point 2 of 3")


def test_compensation_beyond_a_joint_limit_is_named(cahyman, fold):
    """At s_4 = 0 (the end of its stroke) the compensation needs the telescope shorter."""
    q, path, wrenches = fold
    with pytest.raises(cl.JointLimitError, match="s_4") as info:
        cl.follow_path(cahyman.clm, "M", path[:1], wrench=wrenches[:1], task="position", q0=q)
    assert info.value.point == 0 and info.value.partial.n == 0


def test_sigterm_keeps_the_points_computed(ur5, ur5_path, monkeypatch):
    """A SIGTERM while the third point is computed stops the path: Interrupted, with the
    two points before it."""
    solve, calls = path_points.PathStatics.solve, []

    def solve_then_signal(self, *args):
        calls.append(1)
        if len(calls) == 3:
            signal.raise_signal(signal.SIGTERM)
        return solve(self, *args)

    monkeypatch.setattr(path_points.PathStatics, "solve", solve_then_signal)
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(Interrupted) as info:
        cl.follow_path(ur5, "tool0", ur5_path[0], wrench=WRENCH, q0=UR5_START)
    assert info.value.signum == signal.SIGTERM
    assert info.value.partial.n == 2 and info.value.progress == (2, 4)
    assert signal.getsignal(signal.SIGTERM) is before


def test_executor_chunks_give_the_serial_results(ur5, ur5_path):
    path, serial = ur5_path
    with ThreadPoolExecutor(2) as pool:
        r = cl.follow_path(ur5, "tool0", path, wrench=WRENCH, gravity=GRAVITY, q0=UR5_START,
                           executor=pool, chunk=2)  # fmt: skip
    for name in ("q_target", "q_loaded", "q_compensated", "commands", "commands_first_order"):
        np.testing.assert_allclose(getattr(r, name), getattr(serial, name), atol=ATOL_SAME)


class _nothing:
    def __enter__(self):
        return None

    def __exit__(self, *exc):
        return False


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"path": np.zeros((3, 6))}, cl.InvalidInputError, r"\(n, 7\) rows"),
        ({"path": [[0.5, 0.1, 0.4, 0, 0, 0, 3.0]]}, cl.InvalidInputError, "path row 0"),
        ({"wrench": np.zeros((2, 6))}, cl.InvalidInputError, r"\(1, 6\)"),
        ({"task": "orientation"}, cl.InvalidInputError, "expected one of"),
        ({"stiffest": True}, cl.InvalidInputError, "leaves the frame's pose free"),
        ({"payloads": [cl.Payload(1.0, "tool0")]}, cl.InvalidInputError, "without gravity"),
        ({"workers": 2}, cl.InvalidInputError, "ModelSource"),
        ({"frame": "tool9"}, cl.NameNotFoundError, "tool0"),
    ],
)
def test_bad_input(ur5, kwargs, error, message):
    args = {"frame": "tool0", "path": [[0.5, 0.1, 0.4, 0, 0, 0, 1.0]], **kwargs}
    with pytest.raises(error, match=message):
        cl.follow_path(ur5, args.pop("frame"), args.pop("path"), q0=UR5_START, **args)


def test_stiffest_needs_six_actuators(cahyman):
    with pytest.raises(cl.InvalidInputError, match="5"):
        cl.follow_path(cahyman.clm, "tool", [[0.1, 0, 0.3, 0, 0, 0, 1]], task="tool-axis",
                       stiffest=True)  # fmt: skip
