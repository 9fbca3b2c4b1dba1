"""Tests of the conversions between small rotation vectors and the paper's angles."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from cahyman_pin.angles import euler_rate_matrix, rotvec_to_euler_increments, yaw_tilt_increments
from cahyman_pin.geometry import plate_rotation
from closedloop.exceptions import InvalidInputError, SingularConfigurationError

# Central differences of plate_rotation with this step: truncation ~ step^2 = 1e-12,
# round-off ~ 1e-16 / step = 1e-10 (rotation matrices have entries of order 1).
STEP = 1e-6
# 1e-8 bounds the finite-difference error above (away from phi = 90 deg, where 1/cos phi
# amplifies it by at most 1/cos(80 deg) ~ 6).
FD_ATOL = 1e-8
# Increments (dphi, dtheta, dpsi) divide by cos phi >= cos(80 deg) ~ 0.17 in the samples.
INCREMENT_ATOL = FD_ATOL / np.cos(np.deg2rad(80.3))


def fd_rotvec(angles: np.ndarray, rates: np.ndarray) -> np.ndarray:
    """World rotation vector per unit step along (dphi, dtheta, dpsi), by central differences."""
    Rp = plate_rotation(*(angles + STEP * rates))
    Rm = plate_rotation(*(angles - STEP * rates))
    return Rotation.from_matrix(Rp @ Rm.T).as_rotvec() / (2 * STEP)


def test_round_trip_with_finite_differences_of_plate_rotation():
    rng = np.random.default_rng(21)
    for _ in range(20):
        phi = rng.uniform(-1.4, 1.4)  # |phi| <= 80.3 deg
        angles = np.array([phi, rng.uniform(-np.pi, np.pi), rng.uniform(-np.pi, np.pi)])
        rates = rng.normal(size=3)
        omega = fd_rotvec(angles, rates)
        np.testing.assert_allclose(
            euler_rate_matrix(angles[0], angles[1]) @ rates, omega, atol=FD_ATOL
        )
        np.testing.assert_allclose(
            rotvec_to_euler_increments(omega, angles[0], angles[1]), rates, atol=INCREMENT_ATOL
        )
        d_yaw, d_tilt = yaw_tilt_increments(omega, angles[0], angles[1])
        np.testing.assert_allclose(d_yaw, rates[1] + rates[2], atol=INCREMENT_ATOL)
        normal_rate = (
            plate_rotation(*(angles + STEP * rates))[:, 2]
            - plate_rotation(*(angles - STEP * rates))[:, 2]
        ) / (2 * STEP)
        np.testing.assert_allclose(d_tilt, np.linalg.norm(normal_rate), atol=FD_ATOL)


def test_batch_matches_single():
    rng = np.random.default_rng(4)
    omega = rng.normal(size=(5, 3))
    phi, theta = rng.uniform(-1.0, 1.0, 5), rng.uniform(-3.0, 3.0, 5)
    batch = rotvec_to_euler_increments(omega, phi, theta)
    for i in range(5):
        np.testing.assert_array_equal(
            batch[i], rotvec_to_euler_increments(omega[i], phi[i], theta[i])
        )


@pytest.mark.parametrize("phi", [np.pi / 2, -np.pi / 2])
def test_singular_phi_raises(phi):
    with pytest.raises(SingularConfigurationError, match="phi"):
        rotvec_to_euler_increments(np.array([0.1, 0.2, 0.3]), phi, 0.4)


def test_yaw_and_tilt_work_at_phi_90_deg():
    rng = np.random.default_rng(9)
    for theta in (0.0, 1.0, np.pi, -2.5):
        angles = np.array([np.pi / 2, theta, rng.uniform(-np.pi, np.pi)])
        d_theta, d_psi, tilt = rng.normal(), rng.normal(), abs(rng.normal())
        omega = fd_rotvec(angles, np.array([-tilt, d_theta, d_psi]))  # the elevation can only drop
        d_yaw, d_tilt = yaw_tilt_increments(omega, angles[0], angles[1])
        np.testing.assert_allclose(d_yaw, d_theta + d_psi, atol=FD_ATOL)
        np.testing.assert_allclose(d_tilt, tilt, atol=FD_ATOL)
        # and the result does not depend on the arbitrary split of theta + psi there
        d_yaw2, d_tilt2 = yaw_tilt_increments(omega, angles[0], angles[1] + 0.7)
        np.testing.assert_allclose([d_yaw2, d_tilt2], [d_yaw, d_tilt], atol=FD_ATOL)


def test_bad_input_raises():
    with pytest.raises(InvalidInputError, match="omega"):
        rotvec_to_euler_increments(np.array([0.1, np.nan, 0.0]), 0.2, 0.3)
    with pytest.raises(InvalidInputError, match="omega"):
        yaw_tilt_increments(np.ones(2), 0.2, 0.3)
    with pytest.raises(InvalidInputError, match="phi"):
        yaw_tilt_increments(np.ones(3), np.nan, 0.3)
