"""Small rotations in the paper's angles: R = Rz(theta) Ry(pi/2 - phi) Rz(psi) (eq. 6).

phi is the elevation of the plate normal z_p (pi/2: plate parallel to the fixed plate),
theta its azimuth and psi the spin about it. A small rotation vector r (world axes,
R + dR = (I + [r]x) R) relates to the angle increments through

    r = E(phi, theta) (dphi, dtheta, dpsi),
    E = [ (sin theta, -cos theta, 0), e_z, z_p ]   (columns),

which is singular at phi = +-pi/2, where e_z and z_p coincide and only theta + psi is
defined. There, compare the yaw d(theta + psi) and the tilt of the normal instead
(:func:`yaw_tilt_increments`), which are defined for every phi > -pi/2.

Every function accepts a leading batch shape ``(...)``.
"""

from __future__ import annotations

import numpy as np

from closedloop.exceptions import InvalidInputError, SingularConfigurationError

#: ``|cos phi|`` below which the angle increments are not defined.
COS_PHI_MIN = 1e-9


def _as_angles(omega, phi, theta):
    omega = np.asarray(omega, float)
    if omega.ndim == 0 or omega.shape[-1] != 3:
        raise InvalidInputError(f"omega must have shape (..., 3) [rad], got shape {omega.shape}")
    phi, theta = np.asarray(phi, float), np.asarray(theta, float)
    for name, value in (("omega", omega), ("phi", phi), ("theta", theta)):
        if not np.all(np.isfinite(value)):
            raise InvalidInputError(f"{name} must be finite, got {name}={value.tolist()}")
    return omega, phi, theta


def euler_rate_matrix(phi, theta) -> np.ndarray:
    """(..., 3, 3) matrix E with r = E (dphi, dtheta, dpsi), r in world axes [rad].

    Args:
        phi: (...) elevation of the plate normal [rad].
        theta: (...) azimuth of the plate normal [rad]. (E does not depend on psi.)
    """
    phi, theta = np.broadcast_arrays(np.asarray(phi, float), np.asarray(theta, float))
    cp, sp, ct, st = np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta)
    o, i = np.zeros_like(cp), np.ones_like(cp)
    cols = [
        np.stack([st, -ct, o], -1),
        np.stack([o, o, i], -1),
        np.stack([ct * cp, st * cp, sp], -1),
    ]
    return np.stack(cols, -1)


def rotvec_to_euler_increments(omega, phi, theta) -> np.ndarray:
    """Angle increments (dphi, dtheta, dpsi) [rad] of a small rotation vector.

    Args:
        omega: (..., 3) small rotation vector [rad], world axes.
        phi: (...) elevation of the plate normal at the pose [rad].
        theta: (...) azimuth of the plate normal at the pose [rad].

    Returns:
        (..., 3) array (dphi, dtheta, dpsi) [rad].

    Raises:
        SingularConfigurationError: ``|cos phi|`` < COS_PHI_MIN (only theta + psi is defined).
        InvalidInputError: non-finite input or wrong shape.
    """
    omega, phi, theta = _as_angles(omega, phi, theta)
    cp = np.cos(phi)
    if np.any(np.abs(cp) < COS_PHI_MIN):
        raise SingularConfigurationError(
            f"phi={np.rad2deg(phi).tolist()} deg: the angles (phi, theta, psi) are singular at "
            "phi = +-90 deg (only theta + psi is defined); use yaw_tilt_increments"
        )
    sp, ct, st = np.sin(phi), np.cos(theta), np.sin(theta)
    wx, wy, wz = np.moveaxis(omega, -1, 0)
    horizontal = ct * wx + st * wy  # omega . (cos theta, sin theta, 0)
    d_phi = st * wx - ct * wy
    d_psi = horizontal / cp
    d_theta = wz - sp * d_psi
    return np.stack(np.broadcast_arrays(d_phi, d_theta, d_psi), -1)


def yaw_tilt_increments(omega, phi, theta) -> tuple[np.ndarray, np.ndarray]:
    """Yaw d(theta + psi) and tilt of the plate normal for a small rotation vector.

    Both are defined at phi = 90 deg (plate parallel to the fixed plate), where the
    separate increments are not. The tilt is the angle by which the normal z_p turns,
    ``|omega x z_p|`` >= 0; at phi = 90 deg the elevation increment is dphi = -tilt.

    Args:
        omega: (..., 3) small rotation vector [rad], world axes.
        phi: (...) elevation of the plate normal at the pose [rad], > -pi/2.
        theta: (...) azimuth of the plate normal at the pose [rad] (any value at 90 deg).

    Returns:
        ``(d_yaw, d_tilt)``, each (...) [rad].

    Raises:
        SingularConfigurationError: phi = -90 deg (plate upside down).
    """
    omega, phi, theta = _as_angles(omega, phi, theta)
    cp, sp, ct, st = np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta)
    if np.any(1.0 + sp < COS_PHI_MIN):
        raise SingularConfigurationError(f"phi={np.rad2deg(phi).tolist()} deg: yaw undefined")
    wx, wy, wz = np.moveaxis(omega, -1, 0)
    # d(theta + psi) = omega_z + (1 - sin phi) / cos phi * omega . u, written so that it is
    # smooth at phi = 90 deg: (1 - sin phi) / cos phi = cos phi / (1 + sin phi).
    d_yaw = wz + cp / (1.0 + sp) * (ct * wx + st * wy)
    normal = np.stack(np.broadcast_arrays(ct * cp, st * cp, sp), -1)
    d_tilt = np.linalg.norm(np.cross(omega, normal), axis=-1)
    return d_yaw, d_tilt
