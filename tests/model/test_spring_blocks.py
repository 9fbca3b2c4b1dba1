"""Coupled springs of multi-dof joints (SPD blocks of K_q) through compliance, statics, preload.

Expected values come from outside the library's factorisations: the closed form
C = J K_q^-1 J^T of a serial chain (J from Pinocchio), C = J N (N^T K_q N)^-1 N^T J^T with
N from scipy's null space of Pinocchio's closure Jacobian, finite differences of the
spring forces and of the nonlinear equilibrium solver.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import scipy.linalg
from helpers import assert_close_in_norm, frame_placement
from mechanisms import serial_with_block, spd_block

from closedloop.elastostatics.compliance import compliance
from closedloop.elastostatics.preload import preloaded_compliance
from closedloop.elastostatics.statics import solve_equilibrium
from closedloop.elastostatics.tangent import spring_hessian
from closedloop.exceptions import InvalidInputError
from closedloop.kinematics.assembly import assemble
from closedloop.kinematics.constraints import closure_jacobian
from closedloop.model.closed_loop import ClosedLoopModel, Closure

# Closed form vs the library: the same C from the same Jacobian through different
# factorisations (a 6x6 inverse vs Cholesky + SVD); cond(K_q) ~1e4 here: rounding 1e-12.
RTOL_CLOSED_FORM = 1e-10
# Fast (serial, partitioned) path vs the null-space path: the brief's bound.
RTOL_PATHS = 1e-12
# Nonlinear statics at small loads vs C w: the second-order terms are ~ the rotations
# (<= 1e-6 rad here) relative to the first-order ones.
RTOL_SMALL_LOAD = 1e-5
# Preloaded compliance vs central differences of the solver (as in test_preload.py).
RTOL_PRELOAD_FD = 1e-4
# Central difference of the spring forces at rest with step 1e-6: exact for a quadratic
# energy up to rounding eps |K| / h ~ 1e-10 relative.
RTOL_SPRING_FD = 1e-7
EPS = np.finfo(float).eps
# Spring forces in the blocks' eigenbasis against the product K dq: eigh's backward error,
# p(n) eps |K| for the 6x6 blocks (measured 5.1 eps |K|_2 |dq|_2 on OpenBLAS's Haswell,
# SandyBridge and Nehalem kernels): 64.
EIGENBASIS_ULPS = 64.0


def block_stiffness(clm: ClosedLoopModel, springs: dict) -> np.ndarray:
    """(nv, nv) K_q assembled in the test from the spring specification."""
    K = np.zeros((clm.model.nv, clm.model.nv))
    for name, value in springs.items():
        v = clm.joint_v_slice(name)
        n = v.stop - v.start
        K[v, v] = value if np.ndim(value) == 2 else np.diag(np.broadcast_to(value, (n,)))
    return K


def pin_jacobian(clm: ClosedLoopModel, q, frame: str) -> np.ndarray:
    d = clm.model.createData()
    J = pin.computeFrameJacobian(clm.model, d, q, clm.frame_id(frame), pin.LOCAL_WORLD_ALIGNED)
    return np.asarray(J)


def test_serial_block_matches_closed_form():
    clm, q, springs = serial_with_block()
    K = block_stiffness(clm, springs)
    J = pin_jacobian(clm, q, "tool")
    expected = J @ np.linalg.solve(K, J.T)
    fast = compliance(clm, q, "tool")
    general = compliance(clm, q, "tool", path="null-space")
    assert fast.path == "serial"
    assert_close_in_norm(fast.C, expected, RTOL_CLOSED_FORM)
    assert_close_in_norm(fast.C, general.C, RTOL_PATHS)
    assert_close_in_norm(fast.G, np.linalg.solve(K, J.T), RTOL_CLOSED_FORM)
    assert_close_in_norm(fast.K, np.linalg.inv(expected), RTOL_CLOSED_FORM)


def test_model_exposes_blocks():
    clm, _, springs = serial_with_block()
    K = block_stiffness(clm, springs)
    assert_close_in_norm(clm.spring_matrix, K, 1e-15)  # symmetrised: rounding
    assert_close_in_norm(clm.stiffness, np.diag(K), 1e-15)
    assert set(clm.spring_blocks) == {"flex", "wrist"}
    R = clm.spring_root
    assert_close_in_norm(R.T @ R, K, 1e-14)
    assert not clm.spring_matrix.flags.writeable and not clm.spring_blocks["flex"].flags.writeable
    dq = np.arange(clm.model.nv, dtype=float)
    # taken in each block's eigenbasis: K dq of a matrix within the eigensolver's backward
    # error of K, a few eps |K| (measured 5.1 eps |K| |dq| on 200 deflections)
    np.testing.assert_allclose(
        clm.spring_forces(dq),
        K @ dq,
        rtol=0,
        atol=EIGENBASIS_ULPS * EPS * np.linalg.norm(K, 2) * np.linalg.norm(dq),
    )


def test_diagonal_block_equals_vector_springs():
    clm, q, springs = serial_with_block()
    k6 = np.array([1e6, 2e6, 3e6, 1e4, 2e4, 3e4])
    a = clm.with_springs({**springs, "flex": np.diag(k6)})
    b = clm.with_springs({**springs, "flex": k6})
    assert a.spring_blocks and "flex" not in b.spring_blocks
    assert_close_in_norm(compliance(a, q, "tool").C, compliance(b, q, "tool").C, RTOL_PATHS)


def closed_loop_with_block(seed: int = 5) -> tuple[ClosedLoopModel, np.ndarray, dict]:
    """A plate on a 6-dof flexible joint (6x6 block) and an actuated revolute (spring),
    held by a passive three-revolute leg closed to the plate by a point closure.

    The passive leg has exactly three coordinates for the three closure rows: the
    partitioned fast path applies. Assembled at q0 by construction (the plate-side anchor
    is placed where the leg's tip is at q0).
    """
    rng = np.random.default_rng(seed)
    m = pin.Model()
    m.name = "plate_on_block"
    turn = m.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "turn")
    plate = m.addJoint(
        turn, pin.JointModelFreeFlyer(), pin.SE3(np.eye(3), np.array([0, 0, 0.5])), "plate"
    )
    a = m.addJoint(0, pin.JointModelRZ(), pin.SE3(np.eye(3), np.array([0.6, 0.0, 0.0])), "a")
    b = m.addJoint(a, pin.JointModelRY(), pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.2])), "b")
    c = m.addJoint(b, pin.JointModelRY(), pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.3])), "c")
    for j in (turn, plate, a, b, c):
        m.appendBodyToJoint(j, pin.Inertia.FromSphere(1.0, 0.05), pin.SE3.Identity())
    m.addFrame(pin.Frame("tip", c, pin.SE3(np.eye(3), np.array([0.0, 0.0, 0.25])), pin.OP_FRAME))
    m.addFrame(pin.Frame("P", plate, pin.SE3(np.eye(3), np.array([0.1, 0.1, 0.05])), pin.OP_FRAME))
    q0 = pin.neutral(m)
    q0[m.joints[b].idx_q], q0[m.joints[c].idx_q] = -0.4, 0.9
    d = m.createData()
    pin.framesForwardKinematics(m, d, q0)
    tip = d.oMf[m.getFrameId("tip")]
    anchor = d.oMi[plate].inverse() * tip
    closure = pin.PointAnchorConstraintModel(
        m, m.frames[m.getFrameId("tip")].parentJoint, m.frames[m.getFrameId("tip")].placement,
        plate, anchor,
    )  # fmt: skip
    springs = {"turn": 5e3, "plate": spd_block(rng, 6, 1e6, 1e4)}
    clm = ClosedLoopModel(m, [Closure(closure, "tip<->plate")], ["turn"], springs)
    return clm, q0, springs


def test_closed_loop_block_matches_null_space_reference():
    clm, q0, springs = closed_loop_with_block()
    q = np.array(assemble(clm, [0.2], q0=q0).q)
    K = block_stiffness(clm, springs)
    J = pin_jacobian(clm, q, "P")
    N = scipy.linalg.null_space(closure_jacobian(clm, q))
    expected = J @ N @ np.linalg.solve(N.T @ K @ N, N.T @ J.T)
    fast = compliance(clm, q, "P")
    general = compliance(clm, q, "P", path="null-space")
    assert fast.path == "partitioned"
    assert_close_in_norm(fast.C, expected, RTOL_CLOSED_FORM)
    assert_close_in_norm(fast.C, general.C, RTOL_PATHS)
    assert_close_in_norm(fast.G, general.G, RTOL_PATHS)


def test_spring_hessian_is_derivative_of_block_forces():
    clm, q, springs = serial_with_block()
    K = block_stiffness(clm, springs)
    h, nv = 1e-6, clm.model.nv

    def forces(x):
        return pin.dDifference(clm.model, q, x, pin.ARG1).T @ (K @ pin.difference(clm.model, q, x))

    fd = np.column_stack(
        [(forces(pin.integrate(clm.model, q, h * e)) - forces(pin.integrate(clm.model, q, -h * e)))
         / (2 * h) for e in np.eye(nv)]
    )  # fmt: skip
    assert_close_in_norm(spring_hessian(clm, q, q), fd, RTOL_SPRING_FD)


def _balance(clm, eq, K):
    """Unbalanced virtual work of a serial equilibrium (no closure, no locked joint),
    computed from the test's own K_q and Pinocchio's Jacobian, relative to max |J^T w|."""
    m, q, q0 = clm.model, eq.q, eq.q_rest
    g = pin.dDifference(m, q0, q, pin.ARG1).T @ (K @ pin.difference(m, q0, q))
    load = pin_jacobian(clm, q, eq.frame).T @ eq.wrench
    return np.abs(g - load).max() / np.abs(load).max()


def _spherical():
    return serial_with_block(wrist="spherical")


@pytest.mark.parametrize("build, frame", [(_spherical, "tool"), (closed_loop_with_block, "P")])
def test_small_load_statics_agree_with_compliance(build, frame):
    clm, q0, springs = build()
    q = q0 if not clm.closures else np.array(assemble(clm, [0.2], q0=q0).q)
    w = np.array([3.0, -2.0, 1.5, 0.2, -0.1, 0.3]) * 1e-3  # deflections <= 2e-6 m, rad
    eq = solve_equilibrium(clm, q, frame, w)
    C = compliance(clm, q, frame).C
    assert_close_in_norm(eq.displacement, C @ w, RTOL_SMALL_LOAD)
    if not clm.closures:  # the balance at a finite load (rotations ~1e-2 rad), on the
        # test's own K_q and Jacobian: the solver's own bound (helpers.RTOL_BALANCE)
        eq = solve_equilibrium(clm, q, frame, w * 3e3)
        assert _balance(clm, eq, block_stiffness(clm, springs)) <= 1e-10


@pytest.mark.parametrize("wrist", ["spherical", "universal"])
def test_preloaded_compliance_with_block_matches_differences(wrist):
    """Against central differences of the nonlinear statics; the universal wrist's second
    derivatives come from closedloop.common.derivatives (Pinocchio's assume a constant motion
    subspace)."""
    clm, q, _ = serial_with_block(wrist=wrist)
    w0 = np.array([400.0, -300.0, 200.0, 0.0, 0.0, 0.0])
    pre = preloaded_compliance(clm, solve_equilibrium(clm, q, "tool", w0))
    assert pre.stability_margin < 1.0  # the preload is felt
    C = np.zeros((6, 6))
    for i in range(6):
        e = np.zeros(6)
        e[i] = 2.0 if i < 3 else 0.2
        Mp = frame_placement(clm, solve_equilibrium(clm, q, "tool", w0 + e).q, "tool")
        Mm = frame_placement(clm, solve_equilibrium(clm, q, "tool", w0 - e).q, "tool")
        twist = np.r_[Mp.translation - Mm.translation, pin.log3(Mp.rotation @ Mm.rotation.T)]
        C[:, i] = twist / (2 * e[i])
    assert_close_in_norm(pre.C, C, RTOL_PRELOAD_FD)
    zero = preloaded_compliance(clm, solve_equilibrium(clm, q, "tool", np.zeros(6)))
    assert_close_in_norm(zero.C, compliance(clm, q, "tool").C, RTOL_PATHS)


@pytest.mark.parametrize(
    "block, match",
    [
        (np.ones((6, 6)), "not positive definite"),
        (np.triu(np.ones((6, 6))) + 6 * np.eye(6), "not symmetric"),
        (np.eye(3), r"shape \(3, 3\); expected \(6, 6\)"),
        (np.diag([1, 1, 1, 1, 1, np.inf]), "non-finite"),
        (-np.eye(6), "not positive definite"),
    ],
)
def test_bad_blocks_are_refused(block, match):
    clm, _, springs = serial_with_block()
    with pytest.raises(InvalidInputError, match=f"joint 'flex'.*{match}"):
        clm.with_springs({**springs, "flex": block})
