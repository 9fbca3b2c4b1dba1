"""Tests of the nonlinear static equilibrium (closedloop.statics).

Expected values come from independent computations: the linear compliance (small
loads), a constrained minimum of the potential energy (scipy SLSQP / BFGS, pure forces),
the virtual-work balance written out in the test, and a one-joint pendulum in closed form.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import brentq, minimize

from closedloop.assembly import assemble
from closedloop.compliance import compliance
from closedloop.exceptions import InvalidInputError, MechanismError, NameNotFoundError
from closedloop.io import load_urdf
from closedloop.kinematics import closure_jacobian, closure_residual, frame_jacobian
from closedloop.model import ClosedLoopModel, Closure
from closedloop.statics import (
    EquilibriumError,
    potential_energy,
    solve_equilibrium,
)

# Small loads: |w| = 1e-3 deflects the four-bar by ~1e-6 rad, so the second-order terms
# left out of C w are ~1e-6 relative (measured 1e-6 to 2e-6, UR5 3e-8); 1e-5 is the
# brief's bound. Compared in norm (atol = rtol * |C w|): some components are exactly 0.
RTOL_SMALL_LOAD = 1e-5
# Energy minimum vs equilibrium: SLSQP / BFGS stop at a relative gradient ~1e-10 to 1e-12;
# the deflections they return agree to ~1e-9 relative with the Newton solution.
RTOL_ENERGY = 1e-7
# Residual of the virtual-work balance, relative to the applied generalised forces: the
# solver stops at 1e-11 relative; rounding in k (q - q_rest) adds ~1e-13.
RTOL_BALANCE = 1e-9
# Closed-form pendulum: brentq to 1e-15 rad against Newton converged to rounding.
RTOL_CLOSED_FORM = 1e-10

UR5_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
UR5_Q = np.array([0.0, -1.0, 1.5, -0.5, 1.2, 0.3])


def assert_close_in_norm(actual, expected, rtol):
    """Element-wise comparison with an absolute floor rtol * max|expected| (zeros exist)."""
    np.testing.assert_allclose(actual, expected, rtol=rtol, atol=rtol * np.abs(expected).max())


# ---------------------------------------------------------------------------- mechanisms
@pytest.fixture(scope="module")
def fourbar(fourbar_urdf, fourbar_yaml):
    clm = load_urdf(fourbar_urdf, fourbar_yaml)
    return clm, np.array(assemble(clm, [0.3]).q)


@pytest.fixture(scope="module")
def ur5(ur5_urdf):
    return load_urdf(ur5_urdf, springs=dict.fromkeys(UR5_JOINTS, 1e4)), UR5_Q.copy()


def _z_to(a: np.ndarray) -> np.ndarray:
    """Rotation matrix taking the z axis to the unit vector a."""
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(z, a)
    return pin.exp3(v / np.linalg.norm(v) * np.arctan2(np.linalg.norm(v), z @ a))


def spherical_fourbar(springs=(300.0, 200.0, 800.0)) -> tuple[ClosedLoopModel, np.ndarray]:
    """Spherical four-bar: four revolute axes through the origin, closed by a 3D point.

    Every point of the mechanism stays on its sphere about the origin, so the point
    closure has 3 rows of rank 2 (a redundant spatial closure). Assembled by construction
    at q = 0, then driven to crank = 0.4 rad. Returns the model (springs on the crank, the
    coupler and the rocker [N m/rad]) and the assembled configuration.
    """
    a2, a3, a4 = (np.array(v) / np.linalg.norm(v) for v in ([0.6, 0, 0.8], [5, 6, 6], [-2, 7, 7]))
    m = pin.Model()  # crank axis: z
    m.name = "spherical_fourbar"
    crank = m.addJoint(0, pin.JointModelRZ(), pin.SE3(np.eye(3), np.zeros(3)), "crank")
    coupler = m.addJoint(crank, pin.JointModelRZ(), pin.SE3(_z_to(a2), np.zeros(3)), "coupler")
    rocker = m.addJoint(0, pin.JointModelRZ(), pin.SE3(_z_to(a4), np.zeros(3)), "rocker")
    for j, R, name in ((coupler, _z_to(a2), "C_coupler"), (rocker, _z_to(a4), "C_rocker")):
        m.addFrame(pin.Frame(name, j, pin.SE3(np.eye(3), R.T @ (0.2 * a3)), pin.OP_FRAME))
        m.appendBodyToJoint(j, pin.Inertia.FromSphere(0.1, 0.01), pin.SE3.Identity())
    tool = pin.SE3(pin.exp3(np.array([0.3, -0.2, 0.5])), np.array([0.09, 0.06, 0.1]))
    m.addFrame(pin.Frame("tool", coupler, tool, pin.OP_FRAME))
    fa, fb = m.frames[m.getFrameId("C_coupler")], m.frames[m.getFrameId("C_rocker")]
    closure = pin.PointAnchorConstraintModel(
        m, fa.parentJoint, fa.placement, fb.parentJoint, fb.placement
    )
    clm = ClosedLoopModel(m, [Closure(closure, "C")], actuated=["crank"], springs={"crank": 1.0})
    q0 = np.array(assemble(clm, [0.4], q0=np.zeros(3)).q)
    k = dict(zip(("crank", "coupler", "rocker"), springs, strict=True))
    return clm.with_springs(k), q0


def welded_fourbar(fourbar_clm, q0) -> ClosedLoopModel:
    """The four-bar with its point closure replaced by a weld (6 rows of rank 3).

    The weld placement on the rocker side is that of the coupler-side frame at q0, so q0
    stays assembled; the coupler is then rigidly fixed to the rocker (a triangle).
    """
    m, d = fourbar_clm.model, fourbar_clm.model.createData()
    pin.framesForwardKinematics(m, d, q0)
    fa = m.frames[m.getFrameId("closedloop1_A")]
    fb = m.frames[m.getFrameId("closedloop1_B")]
    placement_b = d.oMi[fb.parentJoint].inverse() * d.oMf[m.getFrameId("closedloop1_A")]
    weld = pin.FrameAnchorConstraintModel(
        m, fa.parentJoint, fa.placement, fb.parentJoint, placement_b
    )
    springs = {"crank": 50.0, "crank_axial": 1e5, "rocker_axial": 2e5}
    return ClosedLoopModel(m, [Closure(weld, "weld")], ["crank"], springs, name="welded")


def pendulum(k: float = 40.0, length: float = 0.5) -> ClosedLoopModel:
    """A hinge about y with a spring k [N m/rad] and a frame 'tip' at (0, 0, L) on it.

    The hinge sits on a locked prismatic joint (a support along z), which also keeps
    nv = 2 (with nv = 1 Pinocchio returns Jacobians as 1-D arrays).
    """
    m = pin.Model()
    support = m.addJoint(0, pin.JointModelPZ(), pin.SE3.Identity(), "support")
    j = m.addJoint(support, pin.JointModelRY(), pin.SE3.Identity(), "hinge")
    m.addFrame(pin.Frame("tip", j, pin.SE3(np.eye(3), np.array([0, 0, length])), pin.OP_FRAME))
    return ClosedLoopModel(
        m, actuated=["hinge"], springs={"hinge": k}, locked=["support"], name="pendulum"
    )


def random_wrenches(rng, n, scale, planar=False):
    w = rng.normal(size=(n, 6))
    if planar:  # the four-bar moves in the x-z plane: fx, fz, ny
        w[:, [1, 3, 5]] = 0.0
    return scale * w / np.linalg.norm(w, axis=1, keepdims=True)


# ---------------------------------------------------------------------------- small loads
@pytest.mark.parametrize("seed", [0, 1])
def test_small_load_matches_linear_compliance_fourbar(fourbar, seed):
    clm, q0 = fourbar
    C = compliance(clm, q0, "P").C
    for w in random_wrenches(np.random.default_rng(seed), 3, 1e-3, planar=True):
        eq = solve_equilibrium(clm, q0, "P", w)
        assert_close_in_norm(eq.displacement, C @ w, RTOL_SMALL_LOAD)


@pytest.mark.parametrize("seed", [0, 1])
def test_small_load_matches_linear_compliance_ur5(ur5, seed):
    clm, q0 = ur5
    C = compliance(clm, q0, "tool0").C
    for w in random_wrenches(np.random.default_rng(seed), 3, 1e-3):
        eq = solve_equilibrium(clm, q0, "tool0", w)
        assert_close_in_norm(eq.displacement, C @ w, RTOL_SMALL_LOAD)


def test_small_load_matches_linear_compliance_spherical_redundant_closure():
    clm, q0 = spherical_fourbar()
    assert np.linalg.matrix_rank(closure_jacobian(clm, q0)) == 2  # 3 rows, rank 2
    C = compliance(clm, q0, "tool").C
    for w in random_wrenches(np.random.default_rng(2), 3, 1e-3):
        eq = solve_equilibrium(clm, q0, "tool", w)
        assert_close_in_norm(eq.displacement, C @ w, RTOL_SMALL_LOAD)


# ---------------------------------------------------------------------------- large loads
def test_force_equilibrium_is_constrained_energy_minimum_fourbar(fourbar):
    """SLSQP on 1/2 sum k dq^2 - f.dp with the two in-plane closure rows (x, z)."""
    clm, q0 = fourbar
    f = np.array([40.0, 0.0, -25.0])
    eq = solve_equilibrium(clm, q0, "P", np.r_[f, 0, 0, 0])
    k, fid = clm.stiffness, clm.frame_id("P")
    m, d = clm.model, clm.model.createData()

    def energy(q):
        pin.framesForwardKinematics(m, d, q)
        return 0.5 * np.sum(k * (q - q0) ** 2) - f @ d.oMf[fid].translation

    def gradient(q):
        pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacements(m, d)
        Jv = pin.getFrameJacobian(m, d, fid, pin.LOCAL_WORLD_ALIGNED)[:3]
        return k * (q - q0) - Jv.T @ f

    rows = [0, 2]  # the y row of a planar loop closed by a point is identically zero
    res = minimize(
        energy,
        q0,
        jac=gradient,
        method="SLSQP",
        constraints={
            "type": "eq",
            "fun": lambda q: closure_residual(clm, q)[rows],
            "jac": lambda q: closure_jacobian(clm, q)[rows],
        },
        options={"ftol": 1e-15, "maxiter": 500},
    )
    assert res.success, res.message
    assert_close_in_norm(eq.q - q0, res.x - q0, RTOL_ENERGY)
    expected = res.fun - energy(q0)  # potential_energy is 0 at q0
    assert potential_energy(clm, eq.q, q0, "P", f) == pytest.approx(expected, rel=RTOL_ENERGY)


def test_force_equilibrium_is_energy_minimum_ur5(ur5):
    clm, q0 = ur5
    f = np.array([120.0, -60.0, 150.0])
    eq = solve_equilibrium(clm, q0, "tool0", np.r_[f, 0, 0, 0])
    res = minimize(
        lambda q: potential_energy(clm, q, q0, "tool0", f),
        q0,
        jac=lambda q: 1e4 * (q - q0) - frame_jacobian(clm, q, "tool0")[:3].T @ f,
        method="BFGS",
        options={"gtol": 1e-10},
    )
    assert_close_in_norm(eq.q - q0, res.x - q0, RTOL_ENERGY)


def test_ur5_wrench_equilibrium_balances_virtual_work(ur5):
    """Serial robot, moment included: k (q - q0) = J(q)^T w at the solution."""
    clm, q0 = ur5
    w = np.array([150.0, -80.0, 200.0, 30.0, -40.0, 25.0])
    eq = solve_equilibrium(clm, q0, "tool0", w)
    load = frame_jacobian(clm, eq.q, "tool0").T @ w
    assert np.abs(eq.q - q0).max() > 1e-2  # a finite, not a linear, deflection
    np.testing.assert_allclose(1e4 * (eq.q - q0), load, rtol=0, atol=RTOL_BALANCE * 1e4)
    M, M0 = _placement(clm, eq.q, "tool0"), _placement(clm, q0, "tool0")
    np.testing.assert_allclose(eq.translation, M.translation - M0.translation, atol=1e-15)
    np.testing.assert_allclose(pin.exp3(eq.rotation) @ M0.rotation, M.rotation, atol=1e-14)


def test_fourbar_equilibrium_balances_virtual_work_and_multipliers(fourbar):
    """On the four-bar: N^T (K dq - J^T w) = 0; lambda is the force on the coupler side.

    The rocker carries only the closure force at C: its axial spring balances the
    component along the rocker of the force F2 = -R1 lambda that the coupler exerts on it.
    """
    clm, q0 = fourbar
    w = np.array([30.0, 0.0, -20.0, 0.0, 1.5, 0.0])
    eq = solve_equilibrium(clm, q0, "P", w)
    k = clm.stiffness
    F = k * (eq.q - q0) - frame_jacobian(clm, eq.q, "P").T @ w
    Jc = closure_jacobian(clm, eq.q)
    np.testing.assert_allclose(F + Jc.T @ eq.multipliers, 0.0, atol=RTOL_BALANCE * np.abs(F).max())
    c = clm.closures[0].constraint
    d = clm.data
    pin.framesForwardKinematics(clm.model, d, eq.q)
    R1 = (d.oMi[c.joint1_id] * c.joint1_placement).rotation
    axis = d.oMi[clm.joint_id("rocker_axial")].rotation[:, 2]
    spring = k[clm.joint_v_slice("rocker_axial")][0] * eq.joint_deflection[4]
    assert spring == pytest.approx(-(R1 @ eq.multipliers) @ axis, rel=RTOL_BALANCE)


def test_pendulum_matches_closed_form():
    """k q = L (fx cos q - fz sin q): torque of a dead force at the tip of a hinge about y."""
    k, L = 40.0, 0.5
    clm = pendulum(k, L)
    for fx, fz in ((30.0, 20.0), (-50.0, -60.0), (10.0, 150.0)):
        eq = solve_equilibrium(clm, [0.2, 0.0], "tip", [fx, 0, fz, 0, 0, 0])

        def torque(t, fx=fx, fz=fz):
            return k * t - L * (fx * np.cos(t) - fz * np.sin(t))

        q = brentq(torque, -3.0, 3.0, xtol=1e-15)
        np.testing.assert_allclose(eq.q, [0.2, q], rtol=RTOL_CLOSED_FORM)
        expected = [L * np.sin(q), 0, L * np.cos(q) - L, 0, q, 0]
        np.testing.assert_allclose(eq.displacement, expected, rtol=RTOL_CLOSED_FORM, atol=1e-15)


def test_zero_wrench_returns_the_rest_configuration_exactly(fourbar):
    clm, q0 = fourbar
    eq = solve_equilibrium(clm, q0, "P", np.zeros(6))
    np.testing.assert_array_equal(eq.q, q0)
    np.testing.assert_array_equal(eq.multipliers, 0.0)
    np.testing.assert_allclose(eq.displacement, 0.0, atol=1e-16)  # log3(R R^T): rounding
    assert (eq.iterations, eq.load_steps) == (0, 1)
    assert not eq.q.flags.writeable


def test_large_load_is_followed_in_increments(fourbar):
    clm, q0 = fourbar
    eq = solve_equilibrium(clm, q0, "P", [300.0, 0, -300.0, 0, 0, 0])
    assert eq.load_steps > 1
    assert eq.closure_residual <= 1e-12
    assert np.abs(eq.joint_deflection).max() > 0.5  # rad: far from the linear regime


# ---------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    "wrench", [np.zeros(5), np.zeros((2, 6)), [1.0, 0, 0, np.nan, 0, 0], [np.inf, 0, 0, 0, 0, 0]]
)
def test_bad_wrench_is_rejected(fourbar, wrench):
    clm, q0 = fourbar
    with pytest.raises(InvalidInputError, match="wrench must be 6 finite values"):
        solve_equilibrium(clm, q0, "P", wrench)


def test_bad_rest_configuration_is_rejected(fourbar):
    clm, q0 = fourbar
    with pytest.raises(InvalidInputError, match="violates the closures"):
        solve_equilibrium(clm, q0 + 0.01, "P", np.ones(6))
    with pytest.raises(InvalidInputError, match="expected nq=5"):
        solve_equilibrium(clm, q0[:4], "P", np.ones(6))
    with pytest.raises(NameNotFoundError, match="unknown frame 'Q'"):
        solve_equilibrium(clm, q0, "Q", np.ones(6))
    with pytest.raises(InvalidInputError, match="force must be 3 values"):
        potential_energy(clm, q0, q0, "P", np.ones(6))


def test_mechanism_has_no_equilibrium(fourbar):
    clm, q0 = fourbar
    free_crank = clm.with_springs({"crank": 0.0, "crank_axial": 1e5, "rocker_axial": 2e5})
    with pytest.raises(MechanismError, match="still a mechanism"):
        solve_equilibrium(free_crank, q0, "P", [1.0, 0, 0, 0, 0, 0])


def test_past_the_limit_load_no_equilibrium_is_found(fourbar):
    """The four-bar loaded along (1, 0, -1) has a limit load near 993 N (toggle)."""
    clm, q0 = fourbar
    with pytest.raises(EquilibriumError, match="no static equilibrium found") as err:
        solve_equilibrium(clm, q0, "P", [3000.0, 0, -3000.0, 0, 0, 0])
    assert 0.25 < err.value.load_fraction < 0.34  # 993 N / 3000 N
    assert err.value.force_residual > 0


def test_iteration_budget_exhausted(fourbar):
    clm, q0 = fourbar
    with pytest.raises(EquilibriumError, match=r"closure residual reached: \S+") as err:
        solve_equilibrium(clm, q0, "P", [300.0, 0, -300.0, 0, 0, 0], max_iter=1, max_halvings=0)
    assert err.value.load_fraction == 0.0
    assert err.value.residual > 1e-12


def _placement(clm, q, frame) -> pin.SE3:
    d = clm.model.createData()
    pin.framesForwardKinematics(clm.model, d, q)
    return d.oMf[clm.frame_id(frame)].copy()
