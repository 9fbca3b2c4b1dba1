"""Tests of the preloaded compliance (closedloop.elastostatics.preload).

Expected values: finite differences of the nonlinear equilibrium solver (the preloaded
compliance), the linear compliance (no preload) and a pendulum in closed form. The
second-order pieces (closedloop.elastostatics.tangent) are tested in test_tangent.py.
"""

from __future__ import annotations

import mechanisms as mech
import numpy as np
import pinocchio as pin
import pytest
from helpers import (
    assert_close_in_norm,
    frame_placement,
    pendulum,
    spherical_fourbar,
    welded_fourbar,
)

from closedloop.elastostatics.compliance import compliance
from closedloop.elastostatics.preload import preloaded_compliance, require_stable
from closedloop.elastostatics.statics import JointLimitWarning, solve_equilibrium
from closedloop.exceptions import EquilibriumError, SingularConfigurationError
from closedloop.kinematics.configuration import Configuration

# Preloaded compliance vs central differences of the solver: the brief's bound. Measured
# 3e-7 (four-bar) to 5e-9 (UR5), 4e-6 (Delta); the error is (h/W)^2 with W the load at
# which the response turns nonlinear (W ~ 500 N, 100 N m), plus solver noise 1e-12 |x| / h.
RTOL_PRELOAD_FD = 1e-4
# Closed-form pendulum and the identities of the module (local axes, K C = I): rounding.
RTOL_ROUNDING = 1e-10
# Same mechanism with its closure pairs written the other way round: the same equations
# up to the sign of the rows, hence the same numbers up to rounding (measured 2e-14).
RTOL_ORDER = 1e-10
# Stability margin from the solver's failure vs from the preloaded compliance at the same
# equilibrium: two routes (an SVD of sqrt(k) N vs spring_subspace), rounding ~1e-12.
RTOL_MARGIN = 1e-8
#: Axial rod springs of the Delta [N/m] (the rods then carry the rod-end anchors on a
#: prismatic joint that spins with them).
DELTA_K_ROD = 2e5


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
        Mp = frame_placement(clm, solve_equilibrium(clm, q_rest, frame, w0 + e).q, frame)
        Mm = frame_placement(clm, solve_equilibrium(clm, q_rest, frame, w0 - e).q, frame)
        twist = np.r_[Mp.translation - Mm.translation, pin.log3(Mp.rotation @ Mm.rotation.T)]
        C[:, i] = twist / (2 * h)
    return C


# ---------------------------------------------------------------------------- preloads
@pytest.mark.parametrize("mechanism", ["fourbar", "ur5", "spherical", "welded", "delta"])
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
    elif mechanism == "welded":  # weld (6 rows of rank 3): curvature by differences
        clm, q0, frame = welded_fourbar(fourbar[0], fourbar[1]), fourbar[1], "P"
        w0, h = np.array([150.0, 0, -200.0, 0, 10.0, 0]), (1.0, 0.05)
    else:  # free spin of the rods (internal mobilities), world-axes rod forces
        m = mech.delta(k_rod=DELTA_K_ROD)
        clm, q0, frame = m.clm, m.q, m.frame
        w0, h = np.array([300.0, -150.0, -200.0, 5.0, -3.0, 2.0]), (2.0, 0.1)
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


def test_a_preloaded_compliance_keeps_the_configurations_length(ur5):
    """compliance(state, frame, preload=...) of a Configuration with its own length L:
    the preloaded result (a zero preload: the linear one) is scaled with that L, as the
    unloaded one. It was scaled with the model's length (the scaled condition number of
    `cahyman stiffness --gravity` was that of L = 0.51 m, labelled L = 0.78 m)."""
    clm, q0 = ur5
    state = Configuration(clm, q0, length=7.0 * clm.length)
    for preload in (np.zeros(6), np.array([5.0, 0, -3.0, 0, 0.5, 0])):
        pre = compliance(state, "tool0", preload=preload)
        assert pre.length == state.length
        if not preload.any():
            lin = compliance(state, "tool0")
            assert pre.condition_number == lin.condition_number
    assert compliance(clm, q0, "tool0").condition_number != lin.condition_number


def test_tiny_preload_tends_to_linear_compliance(fourbar):
    """The general path (no zero short cut) is continuous at zero preload."""
    clm, q0 = fourbar
    eq = solve_equilibrium(clm, q0, "P", [1e-6, 0, -1e-6, 0, 1e-7, 0])
    C, C_lin = preloaded_compliance(clm, eq).C, compliance(clm, q0, "P").C
    assert 0.0 < np.abs(C - C_lin).max() < 1e-7 * np.abs(C_lin).max()  # effect ~ load


def test_pendulum_buckling_matches_closed_form():
    """Hinge k under a compressive tip force F: K_t = k - F L, critical load F = k / L; a
    pulling force (F < 0) stiffens it (margin above 1)."""
    k, L = 40.0, 0.5
    clm = pendulum(k, L)
    q0 = np.array([0.2, 0.0])
    for F in (-1e3, -20.0, 20.0, 60.0, 120.0):
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
    R = frame_placement(clm, eq.q, "tool0").rotation
    A = np.kron(np.eye(2), R)  # local components -> world components
    assert_close_in_norm(local.C, A.T @ world.C @ A, RTOL_ROUNDING)
    np.testing.assert_allclose(world.point, frame_placement(clm, eq.q, "tool0").translation)


def test_preloaded_compliance_does_not_depend_on_the_closure_order():
    """Delta, rods spinning freely: pairs (rod end, platform) or (platform, rod end)."""
    w0 = np.array([300.0, -150.0, -200.0, 5.0, -3.0, 2.0])
    results = []
    for order in mech.CLOSURE_ORDERS:
        m = mech.delta(k_rod=DELTA_K_ROD, closure_order=order)
        results.append(preloaded_compliance(m.clm, solve_equilibrium(m.clm, m.q, m.frame, w0)))
    a, b = results
    assert_close_in_norm(a.C, b.C, RTOL_ORDER)
    assert a.stability_margin == pytest.approx(b.stability_margin, rel=RTOL_ORDER)
    C_lin = compliance(m.clm, m.q, m.frame).C
    assert np.abs(a.C - C_lin).max() > 1e-3 * np.abs(C_lin).max()  # the preload matters
    assert a.stability_margin < 0.99


def test_limit_load_margin_is_the_preloaded_stability_margin(fourbar):
    """The margin the solver reports at its last equilibrium, past the four-bar's limit
    load, is that of the preloaded compliance there, and it is near zero."""
    clm, q0 = fourbar
    w = np.array([3000.0, 0, -3000.0, 0, 0, 0])
    with pytest.raises(EquilibriumError, match="a limit load") as err:
        solve_equilibrium(clm, q0, "P", w)
    t = err.value.load_fraction
    with pytest.warns(JointLimitWarning, match="crank_axial"):  # 2.6 cm out, limit 1 cm
        eq = solve_equilibrium(clm, q0, "P", t * w)
    pre = preloaded_compliance(clm, eq)
    assert err.value.stability_margin == pytest.approx(pre.stability_margin, rel=RTOL_MARGIN)
    assert 0.0 < pre.stability_margin < 0.1


def test_a_large_pulling_preload_is_stable_not_critical(ur5):
    """A tension of 1e16 N stiffens the arm along it about 1e13 times beyond its springs
    while the other motions keep their springs: the scaled tangent stiffness spans 1e13,
    within the rank rule, and its smallest value stays that of the springs (was refused as
    a critical load, its condition number taken for singularity)."""
    clm, q = ur5
    pre = compliance(clm, q, "tool0", preload=[1e16, 0, 0, 0, 0, 0])
    assert pre.is_stable and pre.stability_margin >= 1.0 - RTOL_MARGIN


def test_require_stable_refuses_an_unstable_equilibrium():
    """The pendulum past its critical force F = k / L: the API's result (flagged unstable)
    is refused by require_stable, which the command lines apply; a stable one passes."""
    k, L = 40.0, 0.5
    clm = pendulum(k, L)
    q0 = np.array([0.2, 0.0])
    stable = preloaded_compliance(clm, solve_equilibrium(clm, q0, "tip", [0, 0, -20.0, 0, 0, 0]))
    assert require_stable(stable) is stable
    beyond = preloaded_compliance(clm, solve_equilibrium(clm, q0, "tip", [0, 0, -120.0, 0, 0, 0]))
    with pytest.raises(EquilibriumError, match=r"unstable \(stability margin -0.5 <= 0"):
        require_stable(beyond)
