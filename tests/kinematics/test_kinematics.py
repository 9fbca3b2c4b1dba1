"""Constrained kinematics against finite differences and null-space definitions."""

from __future__ import annotations

import functools

import numpy as np
import pinocchio as pin
import pytest
from helpers import REPO

from closedloop.exceptions import InvalidInputError, SingularConfigurationError
from closedloop.io.loader import load_urdf, robot_data_dir
from closedloop.kinematics.assembly import assemble
from closedloop.kinematics.constraints import (
    admissible_motions,
    closed_loop_jacobian,
    closure_jacobian,
    closure_residual,
    frame_jacobian,
    nullspace,
)
from closedloop.model.closed_loop import ClosedLoopModel

# Central differences with step FD_STEP: truncation ~ FD_STEP^2 * |third derivative|
# (~1e-12 here, lengths ~0.1-1 m) plus roundoff ~ eps / FD_STEP ~ 1e-10.
FD_STEP = 1e-6
FD_ATOL = 1e-8
# Differences of assembled poses: each assembly closes to 1e-12 m, divided by 2 * step.
ASSEMBLY_STEP = 1e-5
ASSEMBLY_FD_ATOL = 1e-6
# Null-space identities: one SVD, roundoff relative to the largest singular value.
NULL_ATOL = 1e-12


@functools.cache
def fourbar(closures="urdf/fourbar.yaml"):
    """The four-bar with a closure file given relative to the repository."""
    return load_urdf(REPO / "urdf/fourbar.urdf", REPO / closures)


@functools.cache
def anchored_ur5(kind):
    """UR5 whose tool0 is tied to a fixed world placement (3D point or 6D weld): non-planar."""
    model = pin.buildModelFromUrdf(str(robot_data_dir() / "ur_description/urdf/ur5_robot.urdf"))
    tool = model.frames[model.getFrameId("tool0")]
    target = pin.SE3(pin.rpy.rpyToMatrix(0.3, -0.2, 0.5), np.array([0.4, 0.1, 0.3]))
    anchor = {"3d": pin.PointAnchorConstraintModel, "6d": pin.FrameAnchorConstraintModel}[kind]
    return ClosedLoopModel(model, [anchor(model, tool.parentJoint, tool.placement, 0, target)])


def numerical_closure_jacobian(clm, q):
    nv = clm.model.nv
    columns = []
    for i in range(nv):
        dv = np.zeros(nv)
        dv[i] = FD_STEP
        plus = closure_residual(clm, pin.integrate(clm.model, q, dv))
        minus = closure_residual(clm, pin.integrate(clm.model, q, -dv))
        columns.append((plus - minus) / (2 * FD_STEP))
    return np.column_stack(columns)


CASES = [
    (lambda: fourbar(), "3d"),
    (lambda: fourbar("tests/data/fourbar_weld.yaml"), "6d"),
    (lambda: anchored_ur5("3d"), "3d"),
    (lambda: anchored_ur5("6d"), "6d"),
]


@pytest.mark.parametrize(
    ("make", "kind"), CASES, ids=["fourbar-3d", "fourbar-6d", "ur5-3d", "ur5-6d"]
)
def test_closure_jacobian_matches_finite_differences_away_from_closure(make, kind):
    clm = make()
    assert [c.kind for c in clm.closures] == [kind]
    rng = np.random.default_rng(21)
    for _ in range(4):
        q = rng.uniform(-np.pi, np.pi, clm.model.nq)  # random: the loops are open
        assert np.max(np.abs(closure_residual(clm, q))) > 1e-3
        np.testing.assert_allclose(
            closure_jacobian(clm, q), numerical_closure_jacobian(clm, q), atol=FD_ATOL
        )


def test_closure_jacobian_matches_finite_differences_at_closure():
    clm = fourbar()
    q = assemble(clm, [0.7]).q
    np.testing.assert_allclose(
        closure_jacobian(clm, q), numerical_closure_jacobian(clm, q), atol=FD_ATOL
    )


def frame_pose(clm, q, frame):
    data = clm.model.createData()
    pin.framesForwardKinematics(clm.model, data, q)
    return data.oMf[clm.model.getFrameId(frame)]


@pytest.mark.parametrize("theta", [-2.0, 0.3, 1.9])
def test_closed_loop_jacobian_matches_finite_differences_of_assembly(theta):
    clm = fourbar()
    q = assemble(clm, [theta]).q
    J = closed_loop_jacobian(clm, q, "P", clm.actuated_v_indices)
    plus = frame_pose(clm, assemble(clm, [theta + ASSEMBLY_STEP], q0=q).q, "P")
    minus = frame_pose(clm, assemble(clm, [theta - ASSEMBLY_STEP], q0=q).q, "P")
    twist = np.r_[
        plus.translation - minus.translation,  # world-aligned axes, at P
        pin.log3(plus.rotation @ minus.rotation.T),  # world rotation vector
    ] / (2 * ASSEMBLY_STEP)
    np.testing.assert_allclose(J[:, 0], twist, atol=ASSEMBLY_FD_ATOL)
    assert J.shape == (6, 1)


def test_closed_loop_jacobian_without_enough_inputs():
    clm = fourbar()
    free = ClosedLoopModel(clm.model, clm.closures)  # no spring, no actuator: 3 dof
    with pytest.raises(SingularConfigurationError, match=r"passive joints form a 3-dof mobility"):
        closed_loop_jacobian(free, assemble(clm, [0.3]).q, "P", [])


# ---------------------------------------------------------------- null spaces
@pytest.mark.parametrize(("m", "n", "r"), [(3, 5, 2), (6, 6, 3), (8, 4, 4), (2, 7, 0)])
def test_nullspace_of_matrices_of_known_rank(m, n, r):
    rng = np.random.default_rng(100 * m + n)
    A = rng.normal(size=(m, r)) @ rng.normal(size=(r, n))
    N, rank = nullspace(A)
    assert rank == r and N.shape == (n, n - r)
    np.testing.assert_allclose(A @ N, 0.0, atol=NULL_ATOL * max(1.0, np.abs(A).max()))
    np.testing.assert_allclose(N.T @ N, np.eye(n - r), atol=NULL_ATOL)


def test_nullspace_relative_threshold_and_empty_matrix():
    A = np.diag([1.0, 1e-3, 1e-12])  # the last singular value is below RANK_RTOL * 1
    N, rank = nullspace(A)
    assert rank == 2
    np.testing.assert_allclose(np.abs(N[:, 0]), [0.0, 0.0, 1.0], atol=NULL_ATOL)
    N, rank = nullspace(np.zeros((0, 4)))
    assert rank == 0
    np.testing.assert_array_equal(N, np.eye(4))


@pytest.mark.parametrize(
    ("locked", "mobility"), [((), 3), (("crank",), 2), (("crank", "rocker_axial"), 1)]
)
def test_admissible_motions_of_the_fourbar(locked, mobility):
    springs = {"crank": 50.0, "crank_axial": 1e5, "rocker_axial": 2e5}
    clm = fourbar().with_springs({k: v for k, v in springs.items() if k not in locked}, locked)
    q = assemble(clm, [0.8]).q
    N, rank = admissible_motions(clm, q)
    # 5 coordinates, 2 independent closure rows (planar point: the y row is zero), locks
    assert N.shape == (5, mobility) and rank == 5 - mobility
    np.testing.assert_allclose(closure_jacobian(clm, q) @ N, 0.0, atol=NULL_ATOL)
    for name in locked:
        np.testing.assert_allclose(N[clm.joint_v_slice(name)], 0.0, atol=NULL_ATOL)


def test_frame_jacobian_axes():
    clm = fourbar()
    q = assemble(clm, [0.5]).q
    fid = clm.frame_id("P")
    for axes, reference in (("world", pin.LOCAL_WORLD_ALIGNED), ("local", pin.LOCAL)):
        expected = pin.computeFrameJacobian(clm.model, clm.model.createData(), q, fid, reference)
        np.testing.assert_allclose(frame_jacobian(clm, q, "P", axes), expected, atol=NULL_ATOL)
    with pytest.raises(
        InvalidInputError, match=r"axes 'global'; expected one of \['local', 'world'\]"
    ):
        frame_jacobian(clm, q, "P", "global")
