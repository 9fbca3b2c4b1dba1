"""Tests of the nonlinear statics (closedloop.elastostatics.statics) with springs far apart, huge or
tiny.

A serial robot (no closure) has the free coordinates themselves as its admissible motions,
each solved for through the square root of its own spring: springs 1e22 apart, beyond
closedloop.elastostatics.springs.SPREAD_RESOLVED (which the statics used to refuse), deflect as the
springs say. With closures the limit stays, the refusal naming the two springs.

Expected values: each joint's deflection (J^T w)_i / k_i at small loads (Pinocchio's
frame Jacobian at rest; the joints of a serial chain are decoupled by the springs), and
at moderate loads a minimum of the potential energy by scipy's BFGS, written out here.
"""

from __future__ import annotations

import mechanisms as mech
import numpy as np
import pinocchio as pin
import pytest
from helpers import UR5_JOINTS
from scipy.optimize import minimize

from closedloop.elastostatics.compliance import compliance
from closedloop.elastostatics.springs import SPREAD_RESOLVED
from closedloop.elastostatics.statics import solve_equilibrium
from closedloop.exceptions import SingularConfigurationError
from closedloop.model.closed_loop import ClosedLoopModel

#: The soft and the stiff springs, times a robot's nominal one: 1e22 apart.
SOFT, STIFF = 1e-10, 1e12
#: Largest deflection theta of the small loads [rad, and lengths per the robot's size].
THETA_SMALL = 1e-8
#: The terms of second order left out of (J^T w)_i / k_i are up to ~5 theta relative
#: (measured 4.6 theta on the chain): compared to SECOND_ORDER theta, plus the rounding
#: of a deflection solved for to eps (measured 4e-16 where theta is 1e-21).
SECOND_ORDER, RTOL_ROUNDING = 20.0, 1e-14
#: A deflection is the difference of two doubles, q and q_rest: the rounding of q (half
#: an ulp of q_rest) and of Newton's last step, not taken up below an ulp, leave up to
#: ULPS of q_rest (measured 1.1); 1e-26 rad beside 1.4 rad is 0.
ULPS = 2.0
#: Largest deflection of the moderate loads [rad, per the size]: far from linear.
THETA_MODERATE = 0.3
#: BFGS stops where the scaled energy (unit springs) no longer decreases in double
#: precision: at a gradient of 7e-15 to 1e-9 (measured; GRADIENT_ATOL refuses a stop far
#: from the minimum), its deflections then agree with Newton's to 4e-14 to 5e-10
#: (measured), and so do the stiff joints' that follow from them; RTOL_ENERGY as in
#: test_statics.py.
RTOL_ENERGY, GRADIENT_ATOL = 1e-7, 1e-8


def chain(s: float, k) -> tuple[ClosedLoopModel, str]:
    """Five joints RZ, RY, PX, RX, RY in a chain of size ~s [m], each placed turned
    (generic at q = 0), with springs k (5,): revolute ones [N m/rad] as given, the
    prismatic one k / s^2 [N/m] (its deflection per load is then s times a revolute
    one's). Frame ``tip`` on the last joint."""
    model = pin.Model()
    kinds = (pin.JointModelRZ, pin.JointModelRY, pin.JointModelPX, pin.JointModelRX,
             pin.JointModelRY)  # fmt: skip
    parent = 0
    for i, kind in enumerate(kinds):
        offset = s * np.array([0.4, 0.1, -0.2]) if i else np.zeros(3)
        place = pin.SE3(pin.exp3(np.array([0.3, -0.2, 0.1]) * i), offset)
        parent = model.addJoint(parent, kind(), place, f"j{i}")
    tip = pin.SE3(np.eye(3), s * np.array([0.2, 0.1, 0.3]))
    model.addFrame(pin.Frame("tip", parent, tip, pin.OP_FRAME))
    k = np.asarray(k, float) * np.where(np.arange(5) == 2, 1.0 / s**2, 1.0)
    return ClosedLoopModel(model, springs={f"j{i}": k[i] for i in range(5)}, name="chain"), "tip"


def ur5(k) -> tuple[ClosedLoopModel, str]:
    clm, _, frame = mech.ur5_case()
    return clm.with_springs(dict(zip(UR5_JOINTS, k, strict=True))), frame


def jacobian(clm: ClosedLoopModel, q, frame: str) -> np.ndarray:
    """(6, nv) Pinocchio's frame Jacobian, world axes at the frame origin."""
    data = clm.model.createData()
    fid = clm.model.getFrameId(frame)
    return pin.computeFrameJacobian(clm.model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)


def origin(clm: ClosedLoopModel, q, frame: str) -> np.ndarray:
    data = clm.model.createData()
    pin.framesForwardKinematics(clm.model, data, q)
    return data.oMf[clm.model.getFrameId(frame)].translation.copy()


def assert_deflection(actual, expected, q_rest, rtol: float, atol: float = 0.0) -> None:
    """|actual - expected| <= rtol |expected| + atol + ULPS ulp(q_rest), entry by entry
    (see ULPS). Compared as (actual, expected) / (|expected| + (atol + ULPS ulp) / rtol)
    to rtol."""
    scale = np.abs(expected) + (atol + ULPS * np.spacing(np.abs(q_rest))) / rtol
    np.testing.assert_allclose(actual / scale, expected / scale, rtol=0.0, atol=rtol)


def scaled_wrench(size: float, theta: float, clm, q, frame) -> np.ndarray:
    """A generic wrench (force and moment) scaled so that the largest linear joint
    deflection (J^T w)_i / k_i is theta [rad, or size for the prismatic joint]."""
    w = np.array([0.6, -0.3, 0.5, 0.2 * size, 0.1 * size, -0.3 * size])
    dq = jacobian(clm, q, frame).T @ w / clm.stiffness
    return w * theta / np.max(np.abs(dq) / np.where(clm.linear_coordinates, size, 1.0))


def energy_minimum(clm, q_rest, frame, force, moving) -> np.ndarray:
    """(nq,) the q that minimises 1/2 sum k_i dq_i^2 - f . (p(q) - p(q_rest)) over the
    coordinates ``moving`` (1-dof joints, q = q_rest + dq), the others held at rest, by
    BFGS on z = dq sqrt(k / k_max) (the energy per k_max: unit springs, gradient
    z - J^T f / sqrt(k k_max) from Pinocchio's Jacobian)."""
    k = clm.stiffness[moving]
    top = k.max()
    root = np.sqrt(k / top)
    p0 = origin(clm, q_rest, frame)

    def at(z):
        q = q_rest.copy()
        q[moving] += z / root
        return q

    def energy(z):
        q = at(z)
        e = 0.5 * z @ z - force @ (origin(clm, q, frame) - p0) / top
        return e, z - jacobian(clm, q, frame)[:3, moving].T @ force / (top * root)

    res = minimize(energy, np.zeros(moving.size), jac=True, method="BFGS", options={"gtol": 1e-13})
    assert np.abs(res.jac).max() < GRADIENT_ATOL, res.message
    return at(res.x)


def spread_cases() -> list:
    """(model, frame, q_rest, size [m], stiff mask): springs SOFT and STIFF times a
    nominal one, the stiff joints at rest 0 (their deflections, 1e-22 of the soft ones,
    are then representable in q), or not (UR5 at a generic pose: they round to 0)."""
    cases = []
    pose = np.array([0.3, 0.0, 1.4, 0.0, 1.1, 0.0])
    stiff = np.arange(6) % 2 == 1
    k = 1e4 * np.where(stiff, STIFF, SOFT)
    cases += [
        pytest.param(*ur5(k), pose, 1.0, stiff, id="ur5"),
        pytest.param(*ur5(k), mech.ur5_case()[1], 1.0, stiff, id="ur5-generic-pose"),
    ]
    stiff = np.array([False, True, True, False, False])
    for s in (1e-3, 1e3):
        clm, frame = chain(s, 50.0 * np.where(stiff, STIFF, SOFT))
        rest = np.array([0.3, 0.0, 0.0, 0.7, -0.4])
        cases.append(pytest.param(clm, frame, rest, s, stiff, id=f"{s:g}m"))
    return cases


@pytest.mark.parametrize("clm, frame, q, size, stiff", spread_cases())
def test_serial_springs_far_apart_deflect_each_by_its_own(clm, frame, q, size, stiff):
    """Springs 1e22 apart (refused before): at a small load every joint deflects by
    (J^T w)_i / k_i, the stiff ones 1e-22 as little, to the rounding of q (ULPS of
    q_rest: a deflection 1e-8 rad beside 1.4 rad keeps 1e-8 of it, so the virtual work
    balances to that only)."""
    scaled = clm.stiffness * np.where(clm.linear_coordinates, clm.length**2, 1.0)
    assert scaled.max() / scaled.min() >= 10 * SPREAD_RESOLVED
    w = scaled_wrench(size, THETA_SMALL, clm, q, frame)
    eq = solve_equilibrium(clm, q, frame, w)
    expected = jacobian(clm, q, frame).T @ w / clm.stiffness
    rtol = SECOND_ORDER * THETA_SMALL + RTOL_ROUNDING
    assert_deflection(eq.joint_deflection, expected, q, rtol)
    if not np.any(q[stiff]):
        assert np.all(np.abs(eq.joint_deflection[stiff]) > 0.0)


@pytest.mark.parametrize("clm, frame, q, size, stiff", spread_cases())
def test_serial_springs_far_apart_at_a_moderate_load(clm, frame, q, size, stiff):
    """A force that turns the soft joints by up to 0.3 rad: they settle at the energy
    minimum with the stiff joints held (their deflections, 1e-22 of the soft ones, move
    the frame far below the rounding of q); each stiff joint deflects by
    (J(q)^T f)_i / k_i, J at that equilibrium (UR5: the force at tool0 hardly turns the
    last joint, whose axis passes near it: compared to RTOL_ENERGY of the largest)."""
    f = scaled_wrench(size, THETA_MODERATE, clm, q, frame)[:3]
    eq = solve_equilibrium(clm, q, frame, np.r_[f, 0.0, 0.0, 0.0])
    q_min = energy_minimum(clm, q, frame, f, np.flatnonzero(~stiff))
    soft = ~stiff
    np.testing.assert_allclose(eq.q[soft], q_min[soft], rtol=RTOL_ENERGY)
    expected = jacobian(clm, q_min, frame)[:3, stiff].T @ f / clm.stiffness[stiff]
    atol = RTOL_ENERGY * np.abs(expected).max()
    assert_deflection(eq.joint_deflection[stiff], expected, q[stiff], RTOL_ENERGY, atol)


# (spring [N m/rad], largest load [N], size [m]): the deflection f s / k, from 1e-21 to 1e-6
SMALL_LOAD_CASES = [(1e15, 1e6, 1e-3), (1e15, 1e-9, 1e3), (1e15, 1e6, 1e3), (1e-12, 1e-19, 1e-3),
                    (1e-12, 1e-18, 1.0), (1e-12, 1e-22, 1e3)]  # fmt: skip


@pytest.mark.parametrize("k, f, s", SMALL_LOAD_CASES)
@pytest.mark.parametrize("rest", ["zero", "generic"])
def test_uniform_springs_huge_and_tiny_at_every_scale(k, f, s, rest):
    """Equal springs of 1e15 or 1e-12, loads of 1e-22 to 1e6 N, robots of 1 mm to 1 km:
    each joint deflects by (J^T w)_i / k_i, to the rounding of q (a deflection of 1e-21
    rad beside q = 0.7 rad is 0)."""
    clm, frame = chain(s, [k] * 5)
    q = np.zeros(5) if rest == "zero" else np.array([0.3, -0.5, 0.2 * s, 0.7, -0.4])
    w = f * np.array([0.6, -0.3, 0.5, 0.2 * s, 0.1 * s, -0.3 * s])
    eq = solve_equilibrium(clm, q, frame, w)
    expected = jacobian(clm, q, frame).T @ w / clm.stiffness
    theta = np.max(np.abs(expected) / np.where(clm.linear_coordinates, s, 1.0))
    assert theta < 1e-5  # a small load
    assert_deflection(eq.joint_deflection, expected, q, SECOND_ORDER * theta + RTOL_ROUNDING)


@pytest.mark.parametrize("k, f, s", [(1e-12, 1e-9, 1e-3), (1e-12, 1e-16, 1e3), (1e15, 3e11, 1e3)])
def test_uniform_springs_at_a_moderate_load(k, f, s):
    """Equal springs of 1e-12 or 1e15 loaded to deflections of ~0.1 to 1 rad: the energy
    minimum."""
    clm, frame = chain(s, [k] * 5)
    q = np.array([0.3, -0.5, 0.2 * s, 0.7, -0.4])
    force = f * np.array([0.6, -0.3, 0.5])
    eq = solve_equilibrium(clm, q, frame, np.r_[force, 0.0, 0.0, 0.0])
    q_min = energy_minimum(clm, q, frame, force, np.arange(5))
    np.testing.assert_allclose(
        eq.joint_deflection, q_min - q, rtol=RTOL_ENERGY, atol=RTOL_ENERGY * np.abs(q_min - q).max()
    )


def test_closures_keep_the_limit_naming_the_two_springs():
    """With closures the admissible motions (a null space) mix the coordinates: a soft
    motion's part on a stiff coordinate is known to eps of the soft motion, and the stiff
    springs' deflections lose their digits (measured on the four-bar with crank 1 N m/rad,
    both axial springs spread / L^2: up to 1e-3 at a spread of 1e20, 0.2 at 1e22, 1 to 4
    at 1e24). Refused, naming the softest and the stiffest spring with their values, and
    the limit."""
    unit, _, _ = mech.fourbar_case()
    spread = 1e22
    springs = {"crank": 2.0, "crank_axial": 2.0 * spread / unit.length**2, "rocker_axial": 5e5}
    clm, q, frame = mech.scaled_fourbar(1.0, springs)
    stiff = f"{springs['crank_axial']:.3g}".replace("+", r"\+")
    with pytest.raises(SingularConfigurationError, match=(
        rf"span 1\.0e\+22 .* from 2 N m/rad on 'crank' to {stiff} N/m on 'crank_axial', "
        r"beyond the 1e\+20 that the statics of a mechanism with closures resolves"
    )):  # fmt: skip
        solve_equilibrium(clm, q, frame, [1e-6, 0.0, 0.0, 0.0, 0.0, 0.0])


def test_springs_beyond_the_float_range_apart_are_refused_by_name():
    """Springs 1e330 apart: their spread squared overflowed (a plain OverflowError, which
    stopped a whole map); now the one refusal, from the query and the statics alike."""
    springs = {"crank": 1e200, "crank_axial": 1e-130, "rocker_axial": 1.0}
    clm, q, frame = mech.scaled_fourbar(1.0, springs)
    match = r"span inf .* from 1e-130 N/m on 'crank_axial' to 1e\+200 N m/rad on 'crank'"
    with pytest.raises(SingularConfigurationError, match=match + ".* the general path"):
        compliance(clm, q, frame, path="null-space")
    with pytest.raises(SingularConfigurationError, match=match + ".* the statics"):
        solve_equilibrium(clm, q, frame, [1e-6, 0.0, 0.0, 0.0, 0.0, 0.0])
