"""CaHyMan Pinocchio model against the closed-form geometry: assembly, pose, inverse."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import LEG_T as T
from helpers import LEG_U as U
from helpers import rot_y

from cahyman_pin import geometry
from cahyman_pin.model import CaHyManModel, cahyman_model, closed_form_pose
from cahyman_pin.params import DEFAULT_PARAMS
from closedloop.exceptions import AssemblyError, InvalidInputError

#: Positions [m]: the closed form and the tree both evaluate ~10 products of O(0.1 m)
#: terms, so they agree to a few 1e-16 m; 1e-12 m leaves room for the Newton tolerance.
POSITION_TOL = 1e-12
#: Rotation-matrix entries (dimensionless), same reasoning.
ROTATION_TOL = 1e-12
#: Rotation matrices from their angles, here and by scipy (quaternions): entries of
#: products of up to three rotations of sines and cosines, each to an ulp or so (numpy's
#: SIMD sin and cos differ by a few ulp between CPUs), through two formulas: 16 eps
#: (measured 1.5 eps).
ATOL_ROTATION_ROUNDING = 16 * np.finfo(float).eps
#: Closure residual after assembly [m]: the assembly tolerance.
RESIDUAL_TOL = 1e-12
#: Paper angles [rad] away from the phi = 90 deg singularity (cos phi > COS_PHI_MIN):
#: the extraction amplifies 1e-16 errors by 1/cos(phi) <= 1e3.
ANGLE_TOL = 1e-9
COS_PHI_MIN = 1e-3
#: Newton iterations from the closed-form guess (it is exact up to rounding).
MAX_COLD_ITERATIONS = 3
#: Newton iterations from a neighbouring pose (a few degrees away).
MAX_WARM_ITERATIONS = 6

N_POSES = 200


def random_inputs(rng: np.random.Generator, n: int):
    """n random (alpha (3,) [rad], alpha_4 [rad], s_4 [m]) in the issue's ranges."""
    alpha = np.deg2rad(rng.uniform(30.0, 90.0, size=(n, 3)))
    alpha4 = np.deg2rad(rng.uniform(0.0, 90.0, size=n))
    s4 = rng.uniform(0.0, 0.05, size=n)
    return alpha, alpha4, s4


def wrap(angle):
    """Angle difference wrapped to (-pi, pi]."""
    return np.angle(np.exp(1j * np.asarray(angle)))


@pytest.fixture(scope="module")
def model() -> CaHyManModel:
    return cahyman_model(DEFAULT_PARAMS)


def _compare_with_closed_form(m: CaHyManModel, alpha, alpha4, s4):
    """Assemble with Pinocchio; check the points against the model document and the plate
    pose against the closed-form direct kinematics of geometry.py."""
    p = m.params
    asm = m.assemble(alpha, alpha4, s4, full_output=True)
    got = m.pose(asm.q)
    plate = geometry.plate_pose(alpha, p)
    np.testing.assert_allclose(got.H, plate.H, rtol=0, atol=POSITION_TOL)
    np.testing.assert_allclose(got.R, plate.R, rtol=0, atol=ROTATION_TOL)
    # ball k: at r_p u_k in the plate frame, at (b cos alpha_k, b sin alpha_k + h) in the
    # plane (t_k, z) of leg k (base O_k = r_e u_k), at stroke s_k = u_k . H_k - r_e
    np.testing.assert_allclose(got.H_k, got.H + p.r_p * U @ plate.R.T, rtol=0, atol=POSITION_TOL)
    leg = got.H_k - p.r_e * U
    np.testing.assert_allclose(
        np.einsum("ki,ki->k", T, leg), p.b * np.cos(alpha), rtol=0, atol=POSITION_TOL
    )
    np.testing.assert_allclose(leg[:, 2], p.b * np.sin(alpha) + p.h, rtol=0, atol=POSITION_TOL)
    np.testing.assert_allclose(got.s, np.einsum("ki,ki->k", U, leg), rtol=0, atol=POSITION_TOL)
    # arm: Q = H + HQ z_p, M = Q + (L + s_4) w, w = cos(alpha_4) x_p + sin(alpha_4) z_p;
    # the link carrying M is the plate turned by alpha_4 about -y_p
    R = plate.R
    w = np.cos(alpha4) * R[:, 0] + np.sin(alpha4) * R[:, 2]
    Q = plate.H + p.HQ * R[:, 2]
    np.testing.assert_allclose(got.Q, Q, rtol=0, atol=POSITION_TOL)
    np.testing.assert_allclose(got.M, Q + (p.L + s4) * w, rtol=0, atol=POSITION_TOL)
    np.testing.assert_allclose(got.R_M, R @ rot_y(-alpha4), rtol=0, atol=ROTATION_TOL)
    assert asm.residual <= RESIDUAL_TOL
    assert m.residual(asm.q) <= RESIDUAL_TOL
    assert asm.iterations <= MAX_COLD_ITERATIONS
    if np.cos(plate.phi) > COS_PHI_MIN:
        np.testing.assert_allclose(got.phi, plate.phi, rtol=0, atol=ANGLE_TOL)
        np.testing.assert_allclose(wrap(got.theta - plate.theta), 0.0, atol=ANGLE_TOL)
        np.testing.assert_allclose(wrap(got.psi - plate.psi), 0.0, atol=ANGLE_TOL)


def test_assembly_matches_closed_form_at_random_poses(model):
    alpha, alpha4, s4 = random_inputs(np.random.default_rng(20240611), N_POSES)
    for i in range(N_POSES):
        _compare_with_closed_form(model, alpha[i], alpha4[i], s4[i])


def test_other_dimensions_rebuild_the_model():
    # a parameter sweep rebuilds the tree: longer cranks, smaller plate, longer arm
    params = DEFAULT_PARAMS.replace(b=0.11, h=0.07, r_p=0.08, HQ=0.03, L=0.2, a=0.25)
    m = CaHyManModel(params)
    alpha, alpha4, s4 = random_inputs(np.random.default_rng(7), 10)
    for i in range(10):
        _compare_with_closed_form(m, alpha[i], alpha4[i], s4[i])


@pytest.mark.parametrize(
    ("alpha4_deg", "w_plate"),
    [(0.0, (1.0, 0.0, 0.0)), (90.0, (0.0, 0.0, 1.0)), (45.0, (0.5**0.5, 0.0, 0.5**0.5))],
)
def test_arm_direction_convention(model, alpha4_deg, w_plate):
    # alpha_4 is measured from x_p towards z_p; M's x axis is the arm direction w
    q = model.assemble(np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(alpha4_deg), 0.02)
    pose = model.pose(q)
    w = pose.R @ np.array(w_plate)
    np.testing.assert_allclose(pose.R_M[:, 0], w, atol=ROTATION_TOL)
    np.testing.assert_allclose(pose.M - pose.Q, (DEFAULT_PARAMS.L + 0.02) * w, atol=POSITION_TOL)
    np.testing.assert_allclose(pose.Q - pose.H, DEFAULT_PARAMS.HQ * pose.R[:, 2], atol=POSITION_TOL)


def test_home_pose_is_level_at_height_b_plus_h(model):
    # doc: alpha_k = 90 deg gives a level plate at height b + h, strokes r_p - r_e
    p = DEFAULT_PARAMS
    pose = model.pose(model.assemble(np.deg2rad([90.0, 90.0, 90.0]), 0.0, 0.0))
    np.testing.assert_allclose(pose.H, [0.0, 0.0, p.b + p.h], atol=POSITION_TOL)
    np.testing.assert_allclose(pose.R, np.eye(3), atol=ROTATION_TOL)
    np.testing.assert_allclose(pose.s, np.full(3, p.r_p - p.r_e), atol=POSITION_TOL)
    np.testing.assert_allclose(pose.phi, np.pi / 2, atol=ANGLE_TOL)


def test_closed_form_pose_helper_agrees_with_model(model):
    alpha, alpha4, s4 = np.deg2rad([40.0, 55.0, 80.0]), np.deg2rad(30.0), 0.01
    a, b = closed_form_pose(alpha, alpha4, s4), model.pose(model.assemble(alpha, alpha4, s4))
    np.testing.assert_allclose(a.M, b.M, atol=POSITION_TOL)
    np.testing.assert_allclose(a.R_M, b.R_M, atol=ROTATION_TOL)


def test_warm_start_reaches_the_same_configuration(model):
    rng = np.random.default_rng(11)
    alpha, alpha4, s4 = random_inputs(rng, 1)
    q_prev = model.assemble(alpha[0], alpha4[0], s4[0])
    step = np.deg2rad(rng.uniform(-3.0, 3.0, size=3))
    target = np.clip(alpha[0] + step, np.deg2rad(30.0), np.deg2rad(90.0))
    warm = model.assemble(target, alpha4[0] + 0.05, s4[0], q0=q_prev, full_output=True)
    cold = model.assemble(target, alpha4[0] + 0.05, s4[0])
    assert warm.iterations <= MAX_WARM_ITERATIONS
    np.testing.assert_allclose(model.pose(warm.q).M, model.pose(cold).M, atol=POSITION_TOL)
    np.testing.assert_allclose(model.pose(warm.q).R, model.pose(cold).R, atol=ROTATION_TOL)


def test_inverse_kinematics_recovers_the_inputs(model):
    # compare b sin(alpha) (the crank heights): arcsin is ill-conditioned near 90 deg
    alpha, alpha4, s4 = random_inputs(np.random.default_rng(3), 30)
    for i in range(30):
        pose = model.pose(model.assemble(alpha[i], alpha4[i], s4[i]))
        back = model.inverse(pose.H[2], pose.phi, pose.psi)
        np.testing.assert_allclose(
            DEFAULT_PARAMS.b * np.sin(back),
            DEFAULT_PARAMS.b * np.sin(alpha[i]),
            rtol=0,
            atol=POSITION_TOL,
        )


def test_inverse_out_of_reach_raises(model):
    # the plate centre cannot rise above b + h + r_p cos(phi)
    with pytest.raises(AssemblyError, match="out of reach"):
        model.inverse(0.5, np.pi / 2, 0.0)


@pytest.mark.parametrize(
    "alpha_deg",
    [(90.0, -90.0, 90.0), (90.0, 90.0, -90.0), (-90.0, 90.0, 90.0)],
)
def test_unreachable_inputs_raise_assembly_error(model, alpha_deg):
    with pytest.raises(AssemblyError, match="residual"):
        model.assemble(np.deg2rad(alpha_deg), 0.0, 0.0)


def test_unreachable_inputs_from_warm_start_raise_assembly_error(model):
    # Newton itself (no closed-form pre-check) must give up with a typed error
    q0 = model.assemble(np.deg2rad([60.0, 60.0, 60.0]), 0.0, 0.0)
    with pytest.raises(AssemblyError, match="residual") as info:
        model.assemble(np.deg2rad([90.0, -90.0, 90.0]), 0.0, 0.0, q0=q0)
    assert info.value.residual > RESIDUAL_TOL


@pytest.mark.parametrize(
    ("alpha", "alpha4", "s4"),
    [
        ([np.nan, 1.0, 1.0], 0.0, 0.0),
        ([1.0, 1.0], 0.0, 0.0),
        ([1.0, 1.0, 1.0], np.inf, 0.0),
        ([1.0, 1.0, 1.0], 0.0, -0.001),
        ([1.0, 1.0, 1.0], 0.0, 0.051),
        ([1.0, 1.0, 1.0], 0.0, 0.05 * (1 + 1e-12)),  # beyond rounding
        ([1.0, 1.0, 1.0], 0.0, -1e-15),
    ],
)
def test_invalid_inputs_raise(model, alpha, alpha4, s4):
    with pytest.raises(InvalidInputError):
        model.assemble(alpha, alpha4, s4)


@pytest.mark.parametrize(("s4", "end"), [(0.05 * 6 / 6, 0.05), (0.05 - 0.05 * 6 / 6, 0.0)])
def test_a_stroke_beyond_its_end_by_rounding_is_the_end(model, s4, end):
    """0.05 * 6 / 6 is one unit in the last place above the 50 mm stroke."""
    assert s4 != end and abs(s4 - end) < 1e-17
    q = model.assemble(np.deg2rad([45.0, 60.0, 75.0]), 0.3, s4)
    np.testing.assert_array_equal(q, model.assemble(np.deg2rad([45.0, 60.0, 75.0]), 0.3, end))


def test_elementary_rotations_are_scipys():
    """rot_z, rot_y of a batch of angles (and of one) against scipy's rotations."""
    from scipy.spatial.transform import Rotation

    angles = np.array([[0.0, 0.3], [-2.0, np.pi]])
    for rot, axis in ((geometry.rot_z, "z"), (geometry.rot_y, "y")):
        expected = Rotation.from_euler(axis, angles.reshape(-1, 1)).as_matrix()
        np.testing.assert_allclose(
            rot(angles), expected.reshape(2, 2, 3, 3), rtol=0, atol=ATOL_ROTATION_ROUNDING
        )
        np.testing.assert_allclose(rot(0.3), expected[1], rtol=0, atol=ATOL_ROTATION_ROUNDING)


def test_plate_rotation_is_the_product_of_eq_6():
    """plate_rotation (multiplied out) against Rz(theta) Ry(pi/2 - phi) Rz(psi) by scipy's
    intrinsic z-y-z Euler angles, batched (broadcast shapes) and for one pose; rounding of
    a product of three rotations: a few eps."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(3)
    phi, theta = rng.uniform(-4, 4, size=(2, 5, 1))
    psi = rng.uniform(-4, 4, size=4)
    got = geometry.plate_rotation(phi, theta, psi)
    assert got.shape == (5, 4, 3, 3)
    angles = np.stack(np.broadcast_arrays(theta, np.pi / 2 - phi, psi), axis=-1)
    expected = Rotation.from_euler("ZYZ", angles.reshape(-1, 3)).as_matrix().reshape(5, 4, 3, 3)
    np.testing.assert_allclose(got, expected, rtol=0, atol=ATOL_ROTATION_ROUNDING)
    np.testing.assert_allclose(geometry.plate_rotation(0.2, -1.0, 2.5),
                               Rotation.from_euler("ZYZ", [-1.0, np.pi / 2 - 0.2, 2.5]).as_matrix(),
                               rtol=0, atol=ATOL_ROTATION_ROUNDING)  # fmt: skip


def test_one_value_given_as_a_list_or_array_is_that_value(model):
    """alpha_4 and s_4 as [x] or np.array([x]) (numpy 2.4 refuses float() of a 1-element
    array: it was a TypeError); two values are refused by name."""
    alpha = np.deg2rad([45.0, 60.0, 75.0])
    q = model.assemble(alpha, 0.5, 0.01)
    np.testing.assert_array_equal(model.assemble(alpha, [0.5], np.array([0.01])), q)
    with pytest.raises(InvalidInputError, match="s_4 must be one finite stroke"):
        model.assemble(alpha, 0.5, [0.01, 0.02])


@pytest.mark.parametrize("phi", [-1.3, np.pi / 2 + 0.3, 10.0])
def test_inverse_refuses_an_elevation_outside_its_range(model, phi):
    """The closed form reads cos(phi): -1.3 rad gave the cranks of phi = +74.5 deg."""
    with pytest.raises(InvalidInputError, match=r"elevation of the plate normal in \[0, pi/2\]"):
        model.inverse(0.1, phi, 0.2)
