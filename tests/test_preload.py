"""Tests of the preloaded tangent stiffness and compliance (closedloop.preload).

Expected values: finite differences of Pinocchio's frame and closure Jacobians (the
second-order pieces), finite differences of the nonlinear equilibrium solver (the
preloaded compliance), the linear compliance (no preload) and a pendulum in closed form.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from test_statics import (
    UR5_JOINTS,
    UR5_Q,
    assert_close_in_norm,
    pendulum,
    spherical_fourbar,
    welded_fourbar,
)

from closedloop.assembly import assemble
from closedloop.compliance import compliance
from closedloop.exceptions import InvalidInputError, SingularConfigurationError
from closedloop.io import load_urdf
from closedloop.kinematics import closure_jacobian, frame_jacobian
from closedloop.model import ClosedLoopModel, Closure
from closedloop.preload import (
    closure_curvature,
    geometric_stiffness,
    preloaded_compliance,
    tangent_stiffness,
)
from closedloop.statics import solve_equilibrium

# Central differences of analytic Jacobians with h = 1e-6: truncation h^2/6 |J'''| ~ 1e-13
# and rounding eps |J| / h ~ 1e-10 for links of metre scale: compare at 1e-7 of the
# largest entry.
RTOL_HESSIAN_FD = 1e-7
# Preloaded compliance vs central differences of the solver: the brief's bound. Measured
# 3e-7 (four-bar) to 5e-9 (UR5); the error is (h/W)^2 with W the load at which the
# response turns nonlinear (W ~ 500 N, 100 N m), plus solver noise 1e-12 |x| / h.
RTOL_PRELOAD_FD = 1e-4
# Closed-form pendulum and the identities of the module (local axes, K C = I): rounding.
RTOL_ROUNDING = 1e-10


def _hessian_fd(model, fun, q, h=1e-6):
    """(n, nv) central differences of fun (n,) along pin.integrate(q, h e_b)."""
    cols = []
    for b in range(model.nv):
        e = np.zeros(model.nv)
        e[b] = h
        cols.append((fun(pin.integrate(model, q, e)) - fun(pin.integrate(model, q, -e))) / (2 * h))
    return np.array(cols).T


def _pose(clm, q, frame) -> pin.SE3:
    d = clm.model.createData()
    pin.framesForwardKinematics(clm.model, d, q)
    return d.oMf[clm.frame_id(frame)].copy()


def compliance_by_differences(clm, q_rest, frame, w0, h_force, h_moment) -> np.ndarray:
    """(6, 6) central differences of the equilibrium pose of ``frame`` about preload w0.

    Column i: twist (translation [m], rotation vector [rad], world axes) from the pose
    under w0 - h e_i to the pose under w0 + h e_i, divided by 2 h; the rotation
    log3(R+ R-^T) is a central difference of the world-axes rotation, error O(h^3).
    """
    C = np.zeros((6, 6))
    for i in range(6):
        h = h_force if i < 3 else h_moment
        e = np.zeros(6)
        e[i] = h
        Mp = _pose(clm, solve_equilibrium(clm, q_rest, frame, w0 + e).q, frame)
        Mm = _pose(clm, solve_equilibrium(clm, q_rest, frame, w0 - e).q, frame)
        twist = np.r_[Mp.translation - Mm.translation, pin.log3(Mp.rotation @ Mm.rotation.T)]
        C[:, i] = twist / (2 * h)
    return C


# ---------------------------------------------------------------------------- mechanisms
@pytest.fixture(scope="module")
def fourbar(fourbar_urdf, fourbar_yaml):
    clm = load_urdf(fourbar_urdf, fourbar_yaml)
    return clm, np.array(assemble(clm, [0.3]).q)


@pytest.fixture(scope="module")
def ur5(ur5_urdf):
    return load_urdf(ur5_urdf, springs=dict.fromkeys(UR5_JOINTS, 1e4)), UR5_Q.copy()


@pytest.fixture(scope="module")
def panda(panda_urdf):
    clm = load_urdf(panda_urdf)
    assert clm.model.nv == 9  # 7 arm joints and 2 fingers: nv != 6 exposes a wrong layout
    return clm


# ---------------------------------------------------------------------------- 2nd order
def test_geometric_stiffness_matches_differences_of_jacobian_panda(panda):
    """K_G[i, k] = d(J^T w)_i/dq_k, and the kinematic-Hessian layout, on nv = 9."""
    rng = np.random.default_rng(7)
    m = panda.model
    for _ in range(3):
        q = pin.randomConfiguration(m)
        w = rng.normal(size=6) * [50, 50, 50, 5, 5, 5]
        K = geometric_stiffness(panda, q, "panda_hand_tcp", w)
        K_fd = _hessian_fd(m, lambda x, w=w: frame_jacobian(panda, x, "panda_hand_tcp").T @ w, q)
        assert_close_in_norm(K, K_fd, RTOL_HESSIAN_FD)
        # the test is sensitive: Pinocchio's array read in numpy's default layout is wrong
        pin.computeJointKinematicHessians(m, panda.data, q)
        raw = pin.getFrameKinematicHessian(
            m, panda.data, m.getFrameId("panda_hand_tcp"), pin.LOCAL_WORLD_ALIGNED
        )
        naive = np.einsum("r,rik->ik", w, np.asarray(raw))
        assert np.abs(naive - K_fd).max() > 100 * RTOL_HESSIAN_FD * np.abs(K_fd).max()


def test_geometric_stiffness_is_symmetric_for_a_force_only(panda):
    q = pin.randomConfiguration(panda.model)
    K = geometric_stiffness(panda, q, "panda_hand_tcp", [30.0, -20.0, 10.0, 0, 0, 0])
    np.testing.assert_allclose(K, K.T, rtol=0, atol=RTOL_ROUNDING * np.abs(K).max())
    K = geometric_stiffness(panda, q, "panda_hand_tcp", [0, 0, 0, 3.0, -2.0, 1.0])
    assert np.abs(K - K.T).max() > 1e-3 * np.abs(K).max()  # a world-fixed moment is not


def _lie_group_loop() -> ClosedLoopModel:
    """Free-flyer body and spherical + revolute chain joined by a point closure."""
    m = pin.Model()
    rng_placement = [
        pin.SE3(pin.exp3(np.array(r)), np.array(p))
        for r, p in (
            ([0.1, 0.2, 0.3], [0.0, 0.1, 0.2]),
            ([-0.3, 0.1, 0.2], [0.2, 0.0, 0.1]),
            ([0.2, -0.1, 0.4], [0.1, 0.3, 0.0]),
        )
    ]
    ff = m.addJoint(0, pin.JointModelFreeFlyer(), rng_placement[0], "plate")
    sph = m.addJoint(0, pin.JointModelSpherical(), rng_placement[1], "ball")
    rev = m.addJoint(sph, pin.JointModelRY(), rng_placement[2], "elbow")
    closure = pin.PointAnchorConstraintModel(
        m, rev, pin.SE3(np.eye(3), np.array([0.3, 0.0, 0.1])), ff, pin.SE3.Identity()
    )
    return ClosedLoopModel(m, [Closure(closure, "tip")])


@pytest.mark.parametrize("case", ["fourbar", "fourbar_unassembled", "lie_groups", "weld"])
def test_closure_curvature_matches_differences_of_closure_jacobian(fourbar, case):
    """sum_j lambda_j Hess c_j = d(J_c^T lambda)/dq, also away from closure (d != 0)."""
    rng = np.random.default_rng(11)
    clm, q0 = fourbar
    q = q0
    if case == "fourbar_unassembled":
        q = q0 + rng.normal(scale=0.05, size=q0.size)
    elif case == "lie_groups":
        clm = _lie_group_loop()
        q = pin.randomConfiguration(clm.model, -np.ones(clm.model.nq), np.ones(clm.model.nq))
    elif case == "weld":
        clm = welded_fourbar(clm, q0)
    lam = rng.normal(size=clm.n_constraints) * 20.0
    H = closure_curvature(clm, q, lam)
    H_fd = _hessian_fd(clm.model, lambda x: closure_jacobian(clm, x).T @ lam, q)
    # weld rows: the library itself differences with h = 1e-5 (error ~1e-10 relative)
    assert_close_in_norm(H, H_fd, RTOL_HESSIAN_FD)


def test_self_stress_does_not_enter_the_restricted_curvature():
    """mu in the left null space of J_c (redundant rows): N^T Hess(mu . c) N = 0."""
    clm, q0 = spherical_fourbar()
    U, s, Vt = np.linalg.svd(closure_jacobian(clm, q0))
    assert s[2] < 1e-12 * s[0]  # the radial row is redundant
    H = closure_curvature(clm, q0, 100.0 * U[:, 2])
    N = Vt[2:].T
    assert np.abs(H).max() > 1.0  # the full Hessian is not zero...
    np.testing.assert_allclose(N.T @ H @ N, 0.0, atol=RTOL_ROUNDING * np.abs(H).max())


# ---------------------------------------------------------------------------- preloads
@pytest.mark.parametrize("mechanism", ["fourbar", "ur5", "spherical", "welded"])
def test_preloaded_compliance_matches_differences_of_solver(fourbar, ur5, mechanism):
    """C(w0) against central differences of the nonlinear equilibrium under w0 +- h e_i."""
    if mechanism == "fourbar":
        (clm, q0), frame = fourbar, "P"
        w0, h = np.array([20.0, 0, -10.0, 0, 0.8, 0]), (0.5, 0.05)
    elif mechanism == "ur5":  # a world-fixed moment: C is not symmetric
        (clm, q0), frame = ur5, "tool0"
        w0, h = np.array([150.0, -80.0, 200.0, 30.0, -40.0, 25.0]), (1.0, 0.25)
    elif mechanism == "spherical":  # redundant spatial closure (3 rows of rank 2)
        (clm, q0), frame = spherical_fourbar((30.0, 20.0, 80.0)), "tool"
        w0, h = np.array([3.0, -2.0, 4.0, 0.5, -0.4, 0.3]), (0.1, 0.01)
    else:  # weld closure (6 rows of rank 3): curvature by differences inside the library
        clm, q0, frame = welded_fourbar(fourbar[0], fourbar[1]), fourbar[1], "P"
        w0, h = np.array([150.0, 0, -200.0, 0, 10.0, 0]), (1.0, 0.05)
    eq = solve_equilibrium(clm, q0, frame, w0)
    C = preloaded_compliance(clm, eq).C
    C_fd = compliance_by_differences(clm, q0, frame, w0, *h)
    assert_close_in_norm(C, C_fd, RTOL_PRELOAD_FD)
    # the check is sensitive: the preload changes C by far more than the tolerance
    C_lin = compliance(clm, q0, frame).C
    assert np.abs(C_lin - C_fd).max() > 10 * RTOL_PRELOAD_FD * np.abs(C_fd).max()


def test_zero_preload_equals_linear_compliance_exactly(fourbar, ur5):
    for clm, q0, frame in ((*fourbar, "P"), (*ur5, "tool0")):
        for axes in ("world", "local"):
            eq = solve_equilibrium(clm, q0, frame, np.zeros(6))
            pre, lin = preloaded_compliance(clm, eq, axes), compliance(clm, q0, frame, axes)
            for name in ("C", "G", "point", "q", "rigid_directions"):
                np.testing.assert_array_equal(getattr(pre, name), getattr(lin, name))
            assert (pre.rank, pre.mobility, pre.stability_margin) == (lin.rank, lin.mobility, 1.0)


def test_tiny_preload_tends_to_linear_compliance(fourbar):
    """The general path (no zero short cut) is continuous at zero preload."""
    clm, q0 = fourbar
    eq = solve_equilibrium(clm, q0, "P", [1e-6, 0, -1e-6, 0, 1e-7, 0])
    C, C_lin = preloaded_compliance(clm, eq).C, compliance(clm, q0, "P").C
    assert 0.0 < np.abs(C - C_lin).max() < 1e-7 * np.abs(C_lin).max()  # effect ~ load


def test_pendulum_buckling_matches_closed_form():
    """Hinge k under a compressive tip force F: K_t = k - F L, critical load F = k / L."""
    k, L = 40.0, 0.5
    clm = pendulum(k, L)
    q0 = np.array([0.2, 0.0])
    for F in (20.0, 60.0, 120.0):
        eq = solve_equilibrium(clm, q0, "tip", [0, 0, -F, 0, 0, 0])
        np.testing.assert_array_equal(eq.q, q0)  # the force passes through the hinge
        pre = preloaded_compliance(clm, eq)
        kt = k - F * L
        expected = np.zeros((6, 6))
        expected[np.ix_([0, 4], [0, 4])] = np.array([[L * L, L], [L, 1.0]]) / kt
        np.testing.assert_allclose(pre.C, expected, rtol=RTOL_ROUNDING, atol=1e-16)
        assert pre.stability_margin == pytest.approx(1.0 - F * L / k, rel=RTOL_ROUNDING)
        assert pre.is_stable == (F * L < k)
    eq = solve_equilibrium(clm, q0, "tip", [0, 0, -k / L, 0, 0, 0])
    with pytest.raises(SingularConfigurationError, match="critical load"):
        preloaded_compliance(clm, eq)


def test_moment_preload_gives_a_nonsymmetric_compliance_and_its_inverse(ur5):
    clm, q0 = ur5
    eq = solve_equilibrium(clm, q0, "tool0", [100.0, 0, -50.0, 20.0, 30.0, -10.0])
    pre = preloaded_compliance(clm, eq)
    assert np.abs(pre.C - pre.C.T).max() > 1e-3 * np.abs(pre.C).max()
    np.testing.assert_allclose(pre.K @ pre.C, np.eye(6), rtol=0, atol=RTOL_ROUNDING)
    np.testing.assert_allclose(pre.deflection(np.eye(6)[0]), pre.C[:, 0])
    assert pre.to_dict()["preload"] == [100.0, 0, -50.0, 20.0, 30.0, -10.0]
    eq = solve_equilibrium(clm, q0, "tool0", [100.0, 0, -50.0, 0, 0, 0])
    pre = preloaded_compliance(clm, eq)
    np.testing.assert_array_equal(pre.C, pre.C.T)  # a dead force is conservative


def test_local_axes_are_the_world_result_rotated(ur5):
    clm, q0 = ur5
    eq = solve_equilibrium(clm, q0, "tool0", [100.0, 0, -50.0, 20.0, 30.0, -10.0])
    world, local = preloaded_compliance(clm, eq), preloaded_compliance(clm, eq, "local")
    R = _pose(clm, eq.q, "tool0").rotation
    A = np.kron(np.eye(2), R)  # local components -> world components
    assert_close_in_norm(local.C, A.T @ world.C @ A, RTOL_ROUNDING)
    np.testing.assert_allclose(world.point, _pose(clm, eq.q, "tool0").translation)


def test_tangent_stiffness_is_the_jacobian_of_the_equilibrium_equations(fourbar):
    """d/dq of K_q dq - J^T w + J_c^T lambda (lambda held) by differences, at a preload."""
    clm, q0 = fourbar
    w = np.array([20.0, 0, -10.0, 0, 0.8, 0])
    eq = solve_equilibrium(clm, q0, "P", w)
    k = np.where(np.isinf(clm.stiffness), 0.0, clm.stiffness)

    def forces(q):
        Jf, Jc = frame_jacobian(clm, q, "P"), closure_jacobian(clm, q)
        return k * (q - q0) - Jf.T @ w + Jc.T @ eq.multipliers

    K = tangent_stiffness(clm, eq.q, q0, "P", w, eq.multipliers)
    assert_close_in_norm(K, _hessian_fd(clm.model, forces, eq.q), RTOL_HESSIAN_FD)


# ---------------------------------------------------------------------------- errors
def test_bad_inputs_are_rejected(fourbar):
    clm, q0 = fourbar
    with pytest.raises(InvalidInputError, match="one per closure row"):
        closure_curvature(clm, q0, np.ones(2))
    with pytest.raises(InvalidInputError, match="wrench must be 6 finite values"):
        geometric_stiffness(clm, q0, "P", [np.nan, 0, 0, 0, 0, 0])
    with pytest.raises(InvalidInputError, match="wrench must be 6 finite values"):
        geometric_stiffness(clm, q0, "P", np.ones(3))
