"""Statics of a sprung serial MJCF arm against MuJoCo's equilibrium.

MuJoCo's equilibrium under a wrench at the body ``tool`` (``xfrc_applied``: a force and
torque in world axes at the body's centre of mass, here its origin; gravity off): the
configuration where MuJoCo's net generalised force ``qfrc_smooth`` (its joint springs
``qfrc_spring`` plus the wrench mapped by its own Jacobians) vanishes, with the arm at rest
(``qvel`` = 0: no damping or bias force), found by scipy's root finder on MuJoCo's
``mj_forward`` alone, the coordinates moved by MuJoCo's ``mj_integratePos``. Against it,
the library's nonlinear equilibrium (``cl.solve_equilibrium``) under large loads and its
compliance against MuJoCo's response to small ones. No loop: MuJoCo's equality
constraints are soft in its simulation, the library's closures rigid: for the closed
loops, MuJoCo's constraint residual ``efc_pos`` and Jacobian ``efc_J`` of each
``<connect>`` are taken as rigid constraints with Lagrange multipliers (never its soft
solver), the load mapped by its ``mj_applyFT``.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
import scipy.optimize
from helpers import ATOL_CLOSURE, REPO, assert_close_in_norm
from mujoco_peer import SPRUNG_ARM, compiled, mujoco, to_q
from scipy.spatial.transform import Rotation

import closedloop as cl
from closedloop.io.loader import load_model

#: MuJoCo's equilibria are solved to a net generalised force at rounding: the ulps of the
#: spring forces k (qpos - qpos_spring), 50 N m/rad times 6e-17 rad at the 0.4 rad
#: coordinate (measured: 3e-15 N m at most). This bound [N m, N] leaves an error below
#: 1e-13 rad over the softest spring (15 N m/rad), far under the tolerances below.
ROOT_FORCE_TOL = 1e-12
#: The library's Newton solve stops at an unbalanced force of FORCE_RTOL (1e-11) times the
#: largest spring force; over the softest spring (15 N m/rad) that leaves ~1e-11 rad or m
#: (measured: 3e-12 rad, deflections up to 0.26 rad). Joint coordinates and the tool's
#: motion agree to this [rad, m].
EQUILIBRIUM_TOL = 1e-9
#: Small loads: central differences of MuJoCo's equilibria at +-LOAD_STEP times a unit
#: force or torque (rotations of ~1e-4 rad), whose truncation error is at most of the
#: order of the squared rotation (1e-8) relative to the compliance (measured: 2e-10).
LOAD_STEP = 1e-3
COMPLIANCE_RTOL = 1e-8
#: Characteristic length [m] that scales the rotational rows of the compliance.
ARM_LENGTH = 0.5
WRENCHES = [
    np.array([12.0, -8.0, 15.0, 1.0, -2.0, 0.5]),
    np.array([-20.0, 5.0, -3.0, 0.0, 1.5, -1.0]),
]


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    """(MjModel, MjData, the library's model) of :data:`mujoco_peer.SPRUNG_ARM`."""
    path = tmp_path_factory.mktemp("arm") / "arm.xml"
    path.write_text(SPRUNG_ARM)
    m, d = compiled(path)
    return m, d, load_model(path, geometry=False)


def mujoco_equilibrium(m, d, wrench: np.ndarray) -> np.ndarray:
    """MuJoCo's ``qpos`` (nq,) where ``wrench`` (6,) (N, N m; world axes, at the tool's
    centre of mass) balances the springs, solved from ``qpos0``."""
    mj = mujoco()
    tool = m.body("tool").id

    def qpos(x: np.ndarray) -> np.ndarray:
        out = m.qpos0.copy()
        mj.mj_integratePos(m, out, x, 1.0)
        return out

    def net_force(x: np.ndarray) -> np.ndarray:
        d.qpos[:], d.qvel[:], d.xfrc_applied[:] = qpos(x), 0.0, 0.0
        d.xfrc_applied[tool] = wrench
        mj.mj_forward(m, d)
        return d.qfrc_smooth.copy()

    solution = scipy.optimize.root(net_force, np.zeros(m.nv), method="hybr", tol=1e-15)
    assert np.abs(net_force(solution.x)).max() <= ROOT_FORCE_TOL, solution.message
    return qpos(solution.x)


def tool_motion(m, d, qpos: np.ndarray) -> np.ndarray:
    """MuJoCo's displacement [m] and rotation vector [rad] (6,), world axes, of the
    tool's frame at ``qpos`` from its place at ``qpos0``."""
    mj = mujoco()
    tool = m.body("tool").id
    poses = []
    for q in (m.qpos0, qpos):
        d.qpos[:] = q
        mj.mj_kinematics(m, d)
        poses.append((d.xpos[tool].copy(), d.xmat[tool].reshape(3, 3).copy()))
    (p0, R0), (p, R) = poses
    return np.r_[p - p0, Rotation.from_matrix(R @ R0.T).as_rotvec()]


def test_the_arm_gravity_and_springs_are_as_meant(arm):
    """The comparison's premises: no gravity, every joint sprung at rest at qpos0, the
    tool's centre of mass (where ``xfrc_applied`` acts) at its origin."""
    m, d, clm = arm
    mujoco().mj_kinematics(m, d)
    np.testing.assert_array_equal(d.xipos[m.body("tool").id], d.xpos[m.body("tool").id])
    np.testing.assert_array_equal(m.opt.gravity, 0.0)
    assert np.all(m.jnt_stiffness > 0)
    np.testing.assert_array_equal(m.qpos_spring, m.qpos0)
    assert set(clm.springs) == {m.joint(j).name for j in range(m.njnt)}


@pytest.mark.parametrize("wrench", WRENCHES, ids=["w0", "w1"])
def test_large_load_equilibrium_is_mujocos(arm, wrench):
    m, d, clm = arm
    qpos = mujoco_equilibrium(m, d, wrench)
    eq = cl.solve_equilibrium(clm, clm.reference_configuration(), "tool", wrench)
    assert np.abs(eq.joint_deflection).max() > 0.1  # rotations of 0.1 rad and more
    np.testing.assert_allclose(
        pin.difference(clm.model, to_q(m, clm, qpos), eq.q), 0.0, atol=EQUILIBRIUM_TOL
    )
    np.testing.assert_allclose(
        np.r_[eq.translation, eq.rotation], tool_motion(m, d, qpos), atol=EQUILIBRIUM_TOL
    )


def test_compliance_is_mujocos_small_load_response(arm):
    """Column j of the compliance at the tool is MuJoCo's motion per unit load j, by
    central differences of MuJoCo's equilibria."""
    m, d, clm = arm
    columns = []
    for j in range(6):
        w = LOAD_STEP * np.eye(6)[j]
        plus, minus = (tool_motion(m, d, mujoco_equilibrium(m, d, s * w)) for s in (1, -1))
        columns.append((plus - minus) / (2 * LOAD_STEP))
    C = cl.compliance(cl.Configuration(clm, clm.reference_configuration()), "tool").C
    scale = np.r_[np.ones(3), np.full(3, ARM_LENGTH)]
    assert_close_in_norm(C, np.column_stack(columns), COMPLIANCE_RTOL, scale)


#: Closed MJCF models, their loaded frame (a site, else a body origin) and a wrench (N,
#: N m; world axes, at the frame) that moves their joints by 3e-3 to 6e-2 rad or m. Not the
#: Delta: its rods spin freely about their axes, a motion without spring or load that
#: leaves MuJoCo's full-coordinate equations singular.
LOOPS = {
    "fourbar": ("P", [30.0, 0.0, -20.0, 0.0, 4.0, 0.0]),
    "fivebar5": ("E", [30.0, -20.0, 0.0, 0.0, 0.0, 0.0]),
    "rrr3": ("platform", [30.0, -20.0, 0.0, 0.0, 0.0, 5.0]),
    "stewart": ("platform", [300.0, -200.0, 500.0, 40.0, -30.0, 60.0]),
}


def mujoco_loop_equilibrium(m, d, frame: str, wrench: np.ndarray) -> np.ndarray:
    """MuJoCo's ``qpos`` (nq,) where ``wrench`` at ``frame`` balances the joint springs
    and the rigid equality constraints (``efc_pos`` = 0, forces ``efc_J^T lambda``),
    gravity off, solved from ``qpos0``."""
    mj = mujoco()
    m.opt.gravity[:] = 0.0
    m.opt.jacobian = mj.mjtJacobian.mjJAC_DENSE
    if frame in [m.site(i).name for i in range(m.nsite)]:
        site = m.site(frame).id
        body, point = m.site_bodyid[site], lambda: d.site_xpos[site].copy()
    else:
        body = m.body(frame).id
        point = lambda: d.xpos[body].copy()  # noqa: E731

    def qpos(x: np.ndarray) -> np.ndarray:
        out = m.qpos0.copy()
        mj.mj_integratePos(m, out, x, 1.0)
        return out

    def equations(z: np.ndarray) -> np.ndarray:
        d.qpos[:], d.qvel[:] = qpos(z[: m.nv]), 0.0
        mj.mj_forward(m, d)
        load = np.zeros(m.nv)
        mj.mj_applyFT(m, d, wrench[:3], wrench[3:], point(), body, load)
        J = d.efc_J[: d.ne * m.nv].reshape(d.ne, m.nv)
        return np.r_[d.qfrc_spring + load + J.T @ z[m.nv :], d.efc_pos[: d.ne]]

    d.qpos[:] = m.qpos0
    mj.mj_forward(m, d)
    solution = scipy.optimize.root(equations, np.zeros(m.nv + d.ne), method="hybr", tol=1e-15)
    residual = equations(solution.x)
    assert np.abs(residual[: m.nv]).max() <= ROOT_FORCE_TOL, solution.message
    assert np.abs(residual[m.nv :]).max() <= ATOL_CLOSURE, solution.message
    return qpos(solution.x[: m.nv])


@pytest.mark.parametrize("name", LOOPS)
def test_closed_loop_equilibrium_is_mujocos(name):
    """The bundled closed MJCF models under a load: the library's equilibrium is MuJoCo's
    with its equality constraints held rigid."""
    frame, wrench = LOOPS[name]
    path = REPO / "urdf" / f"{name}.xml"
    (m, d), clm = compiled(path), load_model(path, geometry=False)
    qpos = mujoco_loop_equilibrium(m, d, frame, np.array(wrench))
    eq = cl.solve_equilibrium(clm, clm.reference_configuration(), frame, wrench)
    assert np.abs(eq.joint_deflection).max() > 1e-3
    np.testing.assert_allclose(
        pin.difference(clm.model, to_q(m, clm, qpos), eq.q), 0.0, atol=EQUILIBRIUM_TOL
    )
