"""Tests of the nonlinear static equilibrium (closedloop.elastostatics.statics): the equilibria it
finds.

Expected values come from independent computations: the linear compliance (small
loads), a constrained minimum of the potential energy (scipy SLSQP / BFGS, pure forces),
the virtual-work balance written out in the test (Pinocchio's anchor Jacobian, scipy's
null space), the force balance of a platform, and a one-joint pendulum in closed form.
Refusals (bad inputs, limit loads, solver arguments) and joint limits are tested in
test_statics_limits.py.
"""

from __future__ import annotations

import mechanisms as mech
import numpy as np
import pinocchio as pin
import pytest
from helpers import (
    RTOL_BALANCE,
    assert_balanced,
    assert_close_in_norm,
    frame_placement,
    pendulum,
    spherical_fourbar,
    welded_fourbar,
)
from scipy.optimize import brentq, minimize

import closedloop as cl
from closedloop.elastostatics.compliance import compliance
from closedloop.elastostatics.equilibrium import potential_energy
from closedloop.elastostatics.statics import CLOSURE_TOL as STATICS_CLOSURE_TOL
from closedloop.elastostatics.statics import solve_equilibrium
from closedloop.kinematics.assembly import ASSEMBLY_TOL, assemble
from closedloop.kinematics.constraints import closure_jacobian, closure_residual, frame_jacobian

# Small loads: |w| = 1e-3 deflects the four-bar by ~1e-6 rad, so the second-order terms
# left out of C w are ~1e-6 relative (measured 1e-6 to 2e-6, UR5 3e-8); 1e-5 is the
# brief's bound. Compared in norm (atol = rtol * |C w|): some components are exactly 0.
RTOL_SMALL_LOAD = 1e-5
# Energy minimum vs equilibrium: SLSQP / BFGS stop at a relative gradient ~1e-10 to 1e-12;
# the deflections they return agree to ~1e-9 relative with the Newton solution.
RTOL_ENERGY = 1e-7
# Closed-form pendulum: brentq to 1e-15 rad against Newton converged to rounding.
RTOL_CLOSED_FORM = 1e-10
# Pendulum past its fold: the stable equilibrium (2.25 rad) from brentq (xtol 1e-15)
# against Newton's [rad]: both converged to rounding (measured 4e-16).
ATOL_FOLD_BRANCH = 1e-12
# The two orders of the closure pairs of a mechanism: same equations up to the sign of
# the rows, so the same iterates up to rounding (measured 1e-15, equal iteration counts);
# the first release (residual in side-1 axes) took 125 iterations as written against 31
# swapped on this Delta.
RTOL_ORDER = 1e-10
ITERATIONS_SLACK = 2
#: Delta of the order test: platform at (0, 0, -0.7) m, axial rod springs [N/m] (the rod
#: ends ride on prismatic joints that spin with the rods).
DELTA_POSITION, DELTA_K_ROD = (0.0, 0.0, -0.7), 2e5


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
    atol = RTOL_BALANCE * np.abs(load).max()  # 166 N m of load: 1.7e-7 N m
    np.testing.assert_allclose(1e4 * (eq.q - q0), load, rtol=0, atol=atol)
    assert_balanced(clm, eq)
    M, M0 = frame_placement(clm, eq.q, "tool0"), frame_placement(clm, q0, "tool0")
    np.testing.assert_allclose(eq.translation, M.translation - M0.translation, atol=1e-15)
    np.testing.assert_allclose(pin.exp3(eq.rotation) @ M0.rotation, M.rotation, atol=1e-14)


def _anchor_jacobian(clm, q, frame) -> np.ndarray:
    d = clm.model.createData()
    pin.computeJointJacobians(clm.model, d, q)
    pin.updateFramePlacements(clm.model, d)
    return pin.getFrameJacobian(clm.model, d, clm.frame_id(frame), pin.LOCAL_WORLD_ALIGNED)[:3]


def test_fourbar_equilibrium_balances_virtual_work_and_multipliers(fourbar):
    """On the four-bar: K dq - J^T w + (J_B - J_A)^T lambda = 0, lambda a world-axes force.

    lambda is the force that the rocker side (B) exerts on the coupler side (A) at C. The
    rocker carries only the closure force -lambda: its axial spring balances the
    component of -lambda along the rocker.
    """
    clm, q0 = fourbar
    w = np.array([30.0, 0.0, -20.0, 0.0, 1.5, 0.0])
    eq = solve_equilibrium(clm, q0, "P", w)
    assert_balanced(clm, eq)
    k, load = clm.stiffness, frame_jacobian(clm, eq.q, "P").T @ w
    gap_jacobian = _anchor_jacobian(clm, eq.q, "closedloop1_B") - _anchor_jacobian(
        clm, eq.q, "closedloop1_A"
    )
    F = k * (eq.q - q0) - load + gap_jacobian.T @ eq.multipliers
    np.testing.assert_allclose(F, 0.0, atol=RTOL_BALANCE * np.abs(load).max())
    d = clm.model.createData()
    pin.framesForwardKinematics(clm.model, d, eq.q)
    axis = d.oMi[clm.joint_id("rocker_axial")].rotation[:, 2]
    spring = k[clm.joint_v_slice("rocker_axial")][0] * eq.joint_deflection[4]
    assert spring == pytest.approx(-eq.multipliers @ axis, rel=RTOL_BALANCE)


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
        assert_balanced(clm, eq)
        expected = [L * np.sin(q), 0, L * np.cos(q) - L, 0, q, 0]
        np.testing.assert_allclose(eq.displacement, expected, rtol=RTOL_CLOSED_FORM, atol=1e-15)


def test_pendulum_follows_the_stable_branch_past_the_fold():
    """Regression: a dead load (10, 0, -240) N at the tip, ramped up from rest, buckles the
    pendulum onto its far stable branch; the solver once jumped across the fold to the
    unstable equilibrium near -0.062 rad.

    V = 1/2 k t^2 - f.p with p = (L sin t, 0, L cos t): V' = 0 is k t = 5 cos t + 120 sin t
    and V'' = k + 5 sin t - 120 cos t > 0 on the stable branch (brentq, independently).
    """
    k, L, q0 = 40.0, 0.5, [0.2, 0.0]
    fx, fz = 10.0, -240.0

    def dV(t):  # k t - L (fx cos t - fz sin t)
        return 40.0 * t - 5.0 * np.cos(t) - 120.0 * np.sin(t)

    def d2V(t):  # k + L (fx sin t + fz cos t)
        return 40.0 + 5.0 * np.sin(t) - 120.0 * np.cos(t)

    assert dV(1.5) < 0.0 < dV(3.0)
    theta = brentq(dV, 1.5, 3.0, xtol=1e-15)
    assert theta == pytest.approx(2.2519095, abs=1e-7)
    assert d2V(theta) > 0.0  # a minimum of V: the stable branch (V'' = 119 N m/rad)
    assert d2V(0.0) < 0.0  # the unloaded rest is unstable under the full load: a fold
    eq = solve_equilibrium(pendulum(k, L), q0, "tip", [fx, 0, fz, 0, 0, 0])
    assert eq.q[0] == q0[0]  # the locked support
    assert abs(eq.q[1] - theta) <= ATOL_FOLD_BRANCH, (eq.q[1], theta)


def test_zero_wrench_returns_the_rest_configuration_exactly(fourbar):
    clm, q0 = fourbar
    eq = solve_equilibrium(clm, q0, "P", np.zeros(6))
    np.testing.assert_array_equal(eq.q, q0)
    np.testing.assert_array_equal(eq.multipliers, 0.0)
    np.testing.assert_allclose(eq.displacement, 0.0, atol=1e-16)  # log3(R R^T): rounding
    assert (eq.iterations, eq.load_steps) == (0, 1)
    assert not eq.q.flags.writeable


def test_a_loosely_closed_rest_is_closed_again_first(fourbar):
    """A q_rest whose loop closes only to 3e-7 of L (accepted: CLOSURE_TOL is 1e-6): its
    passive coordinates are re-solved before the load. Before, that re-closing counted as
    displacement: 3e-7 rad under no load at all, and 5-12 % of a small load's."""
    from closedloop.kinematics.assembly import free_coordinates

    clm, q0 = fourbar
    loose = q0.copy()
    loose[free_coordinates(clm)[0]] += 3e-7  # a passive joint (nq = nv)
    assert 1e-7 < cl.Configuration(clm, loose).closure_error < cl.CLOSURE_TOL
    still = solve_equilibrium(clm, loose, "P", np.zeros(6))
    np.testing.assert_allclose(still.displacement, 0.0, atol=1e-15)
    # the one closed rest: q0 closes the loop to ASSEMBLY_TOL L, the re-closed one to the
    # statics' CLOSURE_TOL L; their passive joints agree to the sum over the smallest
    # singular value of the passive closure rows (over L): 5e-12 rad (measured 1e-13)
    free = free_coordinates(clm)
    sigma = np.linalg.svd(closure_jacobian(clm, q0)[:, free] / clm.length, compute_uv=False)
    atol = (ASSEMBLY_TOL + STATICS_CLOSURE_TOL) / sigma[sigma > 0.0].min()
    np.testing.assert_allclose(still.q_rest, q0, rtol=0, atol=atol)
    w = 1e-3 * np.array([1.0, 0.0, 2.0, 0.0, 0.3, 0.0])
    ref, got = (solve_equilibrium(clm, q, "P", w).displacement for q in (q0, loose))
    # to the solver's tolerance, 1e-12 L (the displacement is 2e-7 L: 1e-6 of it)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * clm.length)


def test_large_load_is_followed_in_increments(fourbar):
    clm, q0 = fourbar
    eq = solve_equilibrium(clm, q0, "P", [300.0, 0, -300.0, 0, 0, 0])
    assert eq.load_steps > 1
    assert np.abs(eq.joint_deflection).max() > 0.5  # rad: far from the linear regime
    assert_balanced(clm, eq)


@pytest.mark.parametrize("mechanism", ["spherical", "welded"])
def test_large_wrench_balances_on_redundant_and_welded_closures(fourbar, mechanism):
    if mechanism == "spherical":  # 3 closure rows of rank 2
        (clm, q0), frame = spherical_fourbar((30.0, 20.0, 80.0)), "tool"
        w = [90.0, -60.0, 120.0, 15.0, -12.0, 9.0]  # deflects the joints by 0.12 rad
    else:  # a weld: 6 rows (log6) of rank 3; the triangle is stiff: 0.028 rad
        clm, q0, frame = welded_fourbar(*fourbar), fourbar[1], "P"
        w = [900.0, 0, -1200.0, 0, 60.0, 0]
    eq = solve_equilibrium(clm, q0, frame, w)
    assert np.abs(eq.joint_deflection).max() > 0.02  # rad or m: a finite deflection
    assert_balanced(clm, eq)


def test_delta_equilibrium_does_not_depend_on_the_closure_order():
    """Delta whose rods (with axial springs) spin freely: pairs written (rod end, platform)
    or (platform, rod end) give the same equilibrium in the same number of iterations.

    The multipliers are world-axes forces: each rod is a two-force member (lambda along
    the rod), and the rod forces on the platform balance the load. As written, lambda_j is
    the force of the platform on rod j, so the rods push the platform with -lambda_j.
    """
    w = np.array([2000.0, -1000.0, -1500.0, 0.0, 0.0, 0.0])
    eqs = {}
    for order in mech.CLOSURE_ORDERS:
        m = mech.delta(DELTA_POSITION, k_rod=DELTA_K_ROD, closure_order=order)
        eqs[order] = eq = solve_equilibrium(m.clm, m.q, m.frame, w)
        assert_balanced(m.clm, eq)
    a, b = eqs["as_written"], eqs["swapped"]
    assert np.abs(a.displacement[:3]).max() > 0.02  # m: a large deflection
    assert_close_in_norm(b.displacement, a.displacement, RTOL_ORDER)
    sprung = m.clm.stiffness > 0.0  # arms and rod springs (the spins are spring-free)
    assert_close_in_norm(b.joint_deflection[sprung], a.joint_deflection[sprung], RTOL_ORDER)
    assert_close_in_norm(b.multipliers, -a.multipliers, RTOL_ORDER)
    assert abs(a.iterations - b.iterations) <= ITERATIONS_SLACK
    d = m.clm.model.createData()
    pin.framesForwardKinematics(m.clm.model, d, a.q)
    lam, force, moment = a.multipliers.reshape(6, 3), w[:3].copy(), w[3:].copy()
    platform = d.oMf[m.clm.frame_id("platform")].translation
    for j in range(6):
        end = d.oMf[m.clm.frame_id(f"rod{j}_end")].translation
        axis = end - d.oMi[m.clm.joint_id(f"rod{j}_ball")].translation
        across = np.cross(lam[j], axis / np.linalg.norm(axis))  # two-force member
        np.testing.assert_allclose(across, 0.0, atol=RTOL_BALANCE * np.abs(lam).max())
        force -= lam[j]
        moment += np.cross(end - platform, -lam[j])
    np.testing.assert_allclose(force, 0.0, atol=RTOL_BALANCE * np.abs(w).max())
    np.testing.assert_allclose(moment, 0.0, atol=RTOL_BALANCE * np.abs(w).max())


@pytest.mark.parametrize("axial", [1e14, 1e20])
def test_springs_far_apart_still_deflect(fourbar, axial):
    """A soft crank spring (1e-3 N m/rad) beside axial springs of 2e9 N/m: the Newton step
    resolves the soft direction (its solve cut stiffnesses below 1e-12 of the largest,
    and the solver returned no motion, the load unbalanced). Axial springs of 1e14 and
    1e20 N/m beside 1 N m/rad (1.1e13 and 1.1e19 apart in units of the four-bar's length
    L = 0.34 m) deflect as C w: every spring is a spring, however far apart (the solver
    once refused them, first comparing N/m with N m/rad, then beyond 1e14 apart)."""
    clm, _ = fourbar
    soft = clm.with_springs({"crank": 1e-3, "crank_axial": 2e9, "rocker_axial": 2e9})
    q0 = assemble(soft, actuated=[0.3]).q
    w = np.array([0, 0, -2e-8, 0, 0, 0])  # |w| lever / k ~ 6e-6: within RTOL_SMALL_LOAD
    Cw = compliance(soft, q0, "P").C @ w
    eq = solve_equilibrium(soft, q0, "P", w)
    np.testing.assert_allclose(eq.displacement, Cw, rtol=0, atol=RTOL_SMALL_LOAD * np.abs(Cw).max())
    apart = clm.with_springs({"crank": 1.0, "crank_axial": axial, "rocker_axial": axial})
    q0 = assemble(apart, actuated=[0.3]).q
    w = np.array([0, 0, -1e-6, 0, 0, 0])  # a small load: the linear response
    Cw = compliance(apart, q0, "P").C @ w
    eq = solve_equilibrium(apart, q0, "P", w)
    np.testing.assert_allclose(eq.displacement, Cw, rtol=0, atol=RTOL_SMALL_LOAD * np.abs(Cw).max())
