"""Compliance of serial robots and of the four-bar against independent references."""

from __future__ import annotations

import functools

import numpy as np
import pinocchio as pin
import pytest
from helpers import REPO, assert_close_in_norm
from hypothesis import example, given, settings
from hypothesis import strategies as st

from closedloop.elastostatics.compliance import compliance
from closedloop.exceptions import (
    InvalidInputError,
    MechanismError,
    NameNotFoundError,
    RigidDirectionsError,
)
from closedloop.io.loader import load_urdf, robot_data_dir
from closedloop.kinematics.assembly import assemble
from closedloop.model.closed_loop import ClosedLoopModel

# Serial C = J K^-1 J^T: both sides are a few 6x6 products of the same Jacobian entries,
# so they agree to a few ulps of the largest entry; 1e-10 leaves a wide margin.
SERIAL_RTOL = 1e-10
# Four-bar against the hand derivation: the code goes through an SVD null space and an
# eigen-decomposition (conditioning ~1e3 here), the hand formula through a 2x2 solve.
HAND_RTOL = 1e-9
# Same mechanism closed in different ways: different null-space bases, same subspace.
REDUNDANT_RTOL = 1e-9
# Rigid transport of C between two frames: exact algebra, roundoff only.
TRANSPORT_RTOL = 1e-10
# Positions computed by hand (trigonometry) and by Pinocchio (SE3 products) [m].
POSITION_ATOL = 1e-13
# Smallest eigenvalue of a PSD matrix may be negative by roundoff, relative to the largest.
PSD_RTOL = 1e-12
# Linearity of the deflection: one matrix-vector product each side, roundoff only.
LINEAR_RTOL = 1e-12

# ---------------------------------------------------------------- four-bar, by hand
# Link lengths and spring constants as documented in urdf/fourbar.urdf and fourbar.yaml.
L_CRANK, L_COUPLER, L_ROCKER, GROUND = 0.1, 0.3, 0.15, 0.3  # [m]
P_IN_COUPLER = (0.15, 0.05)  # P in the coupler frame, (x, z) [m]
SPRINGS = {"crank": 50.0, "crank_axial": 1.0e5, "rocker_axial": 2.0e5}
SPRING_ORDER = ("crank", "crank_axial", "rocker_axial")  # spring coordinates s
IN_PLANE = [0, 2, 4]  # dx, dz, ry
OUT_OF_PLANE = [1, 3, 5]  # dy, rx, rz


def u(a):
    """x axis of a frame turned by a about y, in the (x, z) plane."""
    return np.array([np.cos(a), -np.sin(a)])


def n(a):
    """z axis of a frame turned by a about y, in the (x, z) plane (d/da n = u, d/da u = -n)."""
    return np.array([np.sin(a), np.cos(a)])


def fourbar_by_hand(theta, branch=1, e1=0.0, e3=0.0):
    """Configuration, position of P and Jacobian d(P_x, P_z, ry)/ds of the four-bar.

    B = (L1 + e1) n(theta); the coupler (absolute angle phi) reaches C = B + L2 u(phi) and
    the rocker (angle psi) C = D + (L3 + e3) n(psi): C is a crossing of two circles. The
    closure F(s, p) = B + L2 u(phi) - D - (L3 + e3) n(psi) = 0, with springs s = (theta,
    e1, e3) and passive p = (phi, psi), gives dp/ds = -F_p^-1 F_s.
    """
    L1, L3, D = L_CRANK + e1, L_ROCKER + e3, np.array([GROUND, 0.0])
    B = L1 * n(theta)
    d = D - B
    rho = np.linalg.norm(d)
    a = (L_COUPLER**2 - L3**2 + rho**2) / (2 * rho)
    h = np.sqrt(L_COUPLER**2 - a**2)
    C = B + a * d / rho + branch * h * np.array([-d[1], d[0]]) / rho
    phi = np.arctan2(-(C - B)[1], (C - B)[0])
    psi = np.arctan2((C - D)[0], (C - D)[1])
    px, pz = P_IN_COUPLER
    P = B + px * u(phi) + pz * n(phi)
    F_s = np.column_stack([L1 * u(theta), n(theta), -n(psi)])
    F_p = np.column_stack([-L_COUPLER * n(phi), -L3 * u(psi)])
    dphi = -np.linalg.solve(F_p, F_s)[0]
    dP = np.column_stack([L1 * u(theta), n(theta), np.zeros(2)])
    dP += np.outer(-px * n(phi) + pz * u(phi), dphi)
    q = np.array([theta, e1, phi - theta, psi, e3])
    return q, P, C, np.vstack([dP, dphi])


@functools.cache
def fourbar():
    return load_urdf(REPO / "urdf/fourbar.urdf", REPO / "urdf/fourbar.yaml")


@functools.cache
def ur5():
    return load_urdf(robot_data_dir() / "ur_description/urdf/ur5_robot.urdf", joint_stiffness=1e4)


@functools.cache
def panda():
    path = robot_data_dir() / "panda_description/urdf/panda.urdf"
    return load_urdf(path, springs={f"panda_joint{i}": 1e4 for i in range(1, 8)})


def place(clm, q, frame):
    """World placement of ``frame`` at q, computed with Pinocchio only."""
    data = clm.model.createData()
    pin.framesForwardKinematics(clm.model, data, q)
    return data.oMf[clm.model.getFrameId(frame)]


def serial_reference(clm, q, frame, reference_frame):
    """J K_q^-1 J^T over the spring coordinates, locked ones left out."""
    J = pin.computeFrameJacobian(
        clm.model, clm.model.createData(), q, clm.model.getFrameId(frame), reference_frame
    )
    compliance_q = np.where(np.isinf(clm.stiffness), 0.0, 1.0 / clm.stiffness)
    return (J * compliance_q) @ J.T


def random_configuration(clm, rng):
    lo, hi = clm.model.lowerPositionLimit, clm.model.upperPositionLimit
    return rng.uniform(np.maximum(lo, -np.pi), np.minimum(hi, np.pi))


# ---------------------------------------------------------------- serial robots
@pytest.mark.parametrize(
    ("robot", "frame", "seed"), [(ur5, "tool0", 1), (panda, "panda_hand_tcp", 2)]
)
@pytest.mark.parametrize(
    ("axes", "reference_frame"), [("world", pin.LOCAL_WORLD_ALIGNED), ("local", pin.LOCAL)]
)
def test_serial_compliance_is_J_Kinv_JT(robot, frame, seed, axes, reference_frame):
    clm = robot()
    rng = np.random.default_rng(seed)
    for _ in range(5):
        q = random_configuration(clm, rng)
        result = compliance(clm, q, frame, axes)
        assert_close_in_norm(
            result.C, serial_reference(clm, q, frame, reference_frame), SERIAL_RTOL
        )


def test_panda_fingers_are_locked():
    np.testing.assert_array_equal(panda().stiffness[7:], np.inf)
    np.testing.assert_array_equal(panda().stiffness[:7], 1e4)


# ---------------------------------------------------------------- four-bar
CRANK_ANGLES = [-2.6, -1.2, 0.0, 0.4, 1.3, 2.9]


@pytest.mark.parametrize("branch", [1, -1])
@pytest.mark.parametrize("theta", CRANK_ANGLES)
def test_fourbar_compliance_matches_hand_derivation(theta, branch):
    clm = fourbar()
    np.testing.assert_array_equal(clm.stiffness, [50.0, 1e5, 0.0, 0.0, 2e5])
    q, P, C_point, J = fourbar_by_hand(theta, branch)
    # the hand geometry is the URDF's: both closure frames at C, P where computed
    for frame, expected in (("closedloop1_A", C_point), ("closedloop1_B", C_point), ("P", P)):
        np.testing.assert_allclose(
            place(clm, q, frame).translation, [expected[0], 0.0, expected[1]], atol=POSITION_ATOL
        )
    k = np.array([SPRINGS[name] for name in SPRING_ORDER])
    result = compliance(clm, q, "P")
    assert_close_in_norm(result.C[np.ix_(IN_PLANE, IN_PLANE)], (J / k) @ J.T, HAND_RTOL)
    np.testing.assert_allclose(result.C[OUT_OF_PLANE], 0.0, atol=HAND_RTOL * np.abs(result.C).max())
    assert result.rank == 3
    with pytest.raises(RigidDirectionsError, match=r"(?=.*\bdy\b)(?=.*\brx\b)(?=.*\brz\b)") as err:
        _ = result.K
    V = err.value.directions
    expected = np.zeros((6, 6))
    expected[OUT_OF_PLANE, OUT_OF_PLANE] = 1.0
    np.testing.assert_allclose(V @ V.T, expected, atol=HAND_RTOL)  # same subspace


# ---------------------------------------------------------------- redundant closures
def variant(clm, closures, model=None):
    return ClosedLoopModel(model or clm.model, closures, clm.actuated, SPRINGS)


def weld_variant(clm):
    """The same loop closed by a 6D weld at C, with a passive pin at C on the rocker side."""
    model = pin.Model(clm.model)
    pin_joint = model.addJoint(
        model.getJointId("rocker_axial"), pin.JointModelRY(), pin.SE3.Identity(), "pin_C"
    )
    frame = model.frames[model.getFrameId("closedloop1_A")]
    weld = pin.FrameAnchorConstraintModel(
        model, frame.parentJoint, frame.placement, pin_joint, pin.SE3.Identity()
    )
    return variant(clm, [weld], model)


@pytest.mark.parametrize("theta", CRANK_ANGLES[::2])
def test_redundant_closures_give_the_same_compliance(theta):
    clm = fourbar()
    q, *_ = fourbar_by_hand(theta)
    reference = compliance(clm, q, "P").C
    twice = variant(clm, list(clm.closures) * 2)
    assert_close_in_norm(compliance(twice, q, "P").C, reference, REDUNDANT_RTOL)
    welded = weld_variant(clm)
    q_weld = np.r_[q, q[0] + q[2] - q[3]]  # pin angle = coupler angle - rocker angle
    result = compliance(welded, q_weld, "P")
    assert result.closure_residual < POSITION_ATOL
    assert_close_in_norm(result.C, reference, REDUNDANT_RTOL)


# ---------------------------------------------------------------- frame covariance
def transport(C_a, p_a, p_b):
    """C at point b from C at point a (world axes): twist_b = X twist_a, wrench_a = X^T wrench_b."""
    r = p_b - p_a
    X = np.eye(6)
    X[:3, 3:] = -pin.skew(r)  # d_b = d_a + rot x r
    return X @ C_a @ X.T


@pytest.mark.parametrize(
    ("robot", "frame_a", "frame_b"),
    [
        (ur5, "wrist_3_link", "tool0"),
        (ur5, "ee_link", "wrist_3_link"),
        (fourbar, "closedloop1_A", "P"),
    ],
)
def test_compliance_transports_rigidly_between_frames_of_one_body(robot, frame_a, frame_b):
    clm = robot()
    rng = np.random.default_rng(7)
    for _ in range(3):
        if clm is fourbar():
            q, *_ = fourbar_by_hand(rng.uniform(-np.pi, np.pi))
        else:
            q = random_configuration(clm, rng)
        a, b = compliance(clm, q, frame_a), compliance(clm, q, frame_b)
        M_a, M_b = place(clm, q, frame_a), place(clm, q, frame_b)
        assert_close_in_norm(b.C, transport(a.C, M_a.translation, M_b.translation), TRANSPORT_RTOL)
        Rb = np.kron(np.eye(2), M_b.rotation)  # world <- local, for twists and wrenches
        local = compliance(clm, q, frame_b, axes="local")
        assert_close_in_norm(local.C, Rb.T @ b.C @ Rb, TRANSPORT_RTOL)


# ---------------------------------------------------------------- properties
SINGULAR_ANGLES = st.sampled_from([0.0, 1e-12, -1e-8, 1e-5, np.pi])
ANGLES = st.floats(-np.pi, np.pi, allow_nan=False, allow_infinity=False)
SEEDS = st.integers(0, 2**32 - 1)


def check_properties(clm, result, frame, rng):
    C, G = result.C, result.G
    assert np.all(np.isfinite(C)) and np.all(np.isfinite(G))
    np.testing.assert_array_equal(C, C.T)
    lam = np.linalg.eigvalsh(C)
    assert lam[0] >= -PSD_RTOL * lam[-1]
    w1, w2 = rng.normal(size=(2, 6)) * [10, 10, 10, 1, 1, 1]
    a, b = rng.normal(size=2)
    d = result.deflection(a * w1 + b * w2)
    expected = a * result.deflection(w1) + b * result.deflection(w2)
    np.testing.assert_allclose(d, expected, rtol=LINEAR_RTOL, atol=LINEAR_RTOL * np.abs(d).max())
    np.testing.assert_array_equal(result.deflection(np.zeros(6)), 0.0)
    np.testing.assert_array_equal(result.joint_deflection(np.zeros(6)), 0.0)
    # the frame deflection is the frame Jacobian applied to the joint deflection
    J = pin.computeFrameJacobian(
        clm.model, clm.model.createData(), result.q, clm.frame_id(frame), pin.LOCAL_WORLD_ALIGNED
    )
    assert_close_in_norm(J @ G, C, SERIAL_RTOL)


# elbow (index 2) and wrist 2 (index 4) also at or near their singular values
UR5_Q = st.tuples(
    ANGLES, ANGLES, ANGLES | SINGULAR_ANGLES, ANGLES, ANGLES | SINGULAR_ANGLES, ANGLES
)


@settings(max_examples=60, deadline=None)
@given(UR5_Q, SEEDS)
@example((0.3, -1.0, 0.0, 0.5, 0.0, 0.2), 0)  # arm stretched and wrist aligned
def test_ur5_compliance_properties(q, seed):
    clm = ur5()
    result = compliance(clm, np.array(q), "tool0")
    check_properties(clm, result, "tool0", np.random.default_rng(seed))


# Crank angles where crank and coupler are aligned (rocker at its extreme positions):
# |AC| = L2 + L1 = 0.4 or L2 - L1 = 0.2 with |DC| = 0.15, |AD| = 0.3 (law of cosines).
DEAD_CENTRES = [
    np.pi / 2 - np.arccos((0.4**2 + 0.3**2 - 0.15**2) / (2 * 0.4 * 0.3)),
    -np.pi / 2 - np.arccos((0.2**2 + 0.3**2 - 0.15**2) / (2 * 0.2 * 0.3)),
]


@settings(max_examples=60, deadline=None)
@given(st.one_of(ANGLES, st.sampled_from(DEAD_CENTRES)), SEEDS)
@example(DEAD_CENTRES[0], 0)
@example(DEAD_CENTRES[1], 1)
def test_fourbar_compliance_properties(theta, seed):
    clm = fourbar()
    q = assemble(clm, [theta]).q
    check_properties(clm, compliance(clm, q, "P"), "P", np.random.default_rng(seed))


# ---------------------------------------------------------------- mechanisms
def test_fourbar_without_springs_is_a_mechanism():
    clm = fourbar()
    free = ClosedLoopModel(clm.model, clm.closures, actuated=(), springs={})
    q, *_ = fourbar_by_hand(0.4)
    with pytest.raises(
        MechanismError, match=r"still a mechanism at frame 'P'.*'(crank|coupler|rocker)"
    ):
        compliance(free, q, "P")


def sleeve_variant(clm):
    """A sleeve on the coupler, free to spin about the coupler line BC, carries C.

    Its spin keeps C (on the spin axis) and does not move the coupler, hence P: an
    internal mobility. A passive joint between the ground and P would rotate P even with
    its axis through P, which makes a mechanism, not an internal mobility.
    """
    model = pin.Model(clm.model)
    sleeve = model.addJoint(
        model.getJointId("coupler"), pin.JointModelRX(), pin.SE3.Identity(), "sleeve"
    )
    closure = pin.PointAnchorConstraintModel(
        model,
        sleeve,
        pin.SE3(np.eye(3), np.array([L_COUPLER, 0.0, 0.0])),
        model.getJointId("rocker_axial"),
        pin.SE3.Identity(),
    )
    return variant(clm, [closure], model)


def test_internal_mobility_is_tolerated_and_reported():
    clm = fourbar()
    q, *_ = fourbar_by_hand(0.4)
    result = compliance(sleeve_variant(clm), np.r_[q, 0.7], "P")
    assert result.internal_mobilities == 1
    assert_close_in_norm(result.C, compliance(clm, q, "P").C, REDUNDANT_RTOL)


def test_serial_joint_beyond_the_frame_is_an_internal_mobility():
    clm = ur5()
    loose = clm.with_springs(
        {name: 1e4 for name in list(clm.model.names)[1:6]} | {"wrist_3_joint": 0.0}
    )
    q = random_configuration(clm, np.random.default_rng(3))
    result = compliance(loose, q, "wrist_2_link")
    assert result.internal_mobilities == 1
    assert_close_in_norm(
        result.C, serial_reference(clm, q, "wrist_2_link", pin.LOCAL_WORLD_ALIGNED), SERIAL_RTOL
    )


# ---------------------------------------------------------------- error paths
def test_unknown_frame():
    q, *_ = fourbar_by_hand(0.4)
    with pytest.raises(NameNotFoundError, match=r"unknown frame 'nope'; expected one of: .*'P'"):
        compliance(fourbar(), q, "nope")


@pytest.mark.parametrize(
    ("springs", "error", "match"),
    [
        ({"nope": 1.0}, NameNotFoundError, r"unknown joint 'nope'; expected one of: 'crank'"),
        (
            {"crank": -1.0},
            InvalidInputError,
            r"stiffness of joint 'crank' is \[-1.0\]; expected values >= 0",
        ),
        (
            {"rocker_axial": np.nan},
            InvalidInputError,
            r"stiffness of joint 'rocker_axial' is \[nan\]",
        ),
        ({"crank": [1.0, 2.0]}, InvalidInputError, r"has 2 values; expected 1$"),
    ],
)
def test_bad_springs(springs, error, match):
    with pytest.raises(error, match=match):
        load_urdf(REPO / "urdf/fourbar.urdf", REPO / "urdf/fourbar.yaml", springs=springs)


@pytest.mark.parametrize(
    ("q", "match"),
    [
        (np.zeros(4), r"q has 4 values; expected nq=5"),
        ([0.4, 0, np.nan, 0, 0], r"q contains non-finite values"),
    ],
)
def test_bad_configuration(q, match):
    with pytest.raises(InvalidInputError, match=match):
        compliance(fourbar(), q, "P")


def test_bad_axes_and_wrench():
    q, *_ = fourbar_by_hand(0.4)
    with pytest.raises(
        InvalidInputError, match=r"axes 'body'; expected one of \['local', 'world'\]"
    ):
        compliance(fourbar(), q, "P", axes="body")
    with pytest.raises(InvalidInputError, match=r"wrench must be 6 finite values"):
        compliance(fourbar(), q, "P").deflection([1.0, 2.0, np.nan, 0.0, 0.0, 0.0])
