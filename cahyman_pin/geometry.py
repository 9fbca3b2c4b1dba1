"""Closed-form kinematics of CaHyMan (no Pinocchio), vectorised over poses.

Conventions (world frame at the centre of the fixed plate, z up, x towards leg 1):
leg k has delta_k = 0, 120, 240 deg, radial unit u_k, tangential t_k = z x u_k. The
point H_k (ball-joint centre of leg k) has in-plane coordinates y_k = t_k . (H_k - O_k)
= b cos(alpha_k) and z_k = b sin(alpha_k) + h. The plate orientation is
R = Rz(theta) Ry(pi/2 - phi) Rz(psi) (the paper's eq. 6); its origin H is the centroid of
the ball centres, which sit at p_k = r_p u_k in the plate frame.

Every function accepts arrays with a leading batch shape ``(...)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cahyman_pin.params import CaHyManParams
from closedloop.exceptions import AssemblyError, InvalidInputError

#: Leg angles delta_k [rad].
DELTA = np.deg2rad([0.0, 120.0, 240.0])
#: (3, 3) radial unit vectors u_k, one per row, world axes.
U = np.stack([np.cos(DELTA), np.sin(DELTA), np.zeros(3)], axis=1)
#: (3, 3) tangential unit vectors t_k = z x u_k, one per row, world axes.
T = np.stack([-np.sin(DELTA), np.cos(DELTA), np.zeros(3)], axis=1)
EZ = np.array([0.0, 0.0, 1.0])
_SQ3 = np.sqrt(3.0)


def _rotation(angle: np.ndarray, i: int, j: int) -> np.ndarray:
    """(..., 3, 3) rotation by ``angle`` [rad] in the plane of axes i -> j (the third axis
    fixed): entries (i, i) = (j, j) = cos, (j, i) = sin, (i, j) = -sin."""
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros((*np.shape(c), 3, 3))
    R[..., i, i] = R[..., j, j] = c
    R[..., j, i], R[..., i, j] = s, -s
    R[..., 3 - i - j, 3 - i - j] = 1.0
    return R


def rot_z(angle: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation about z by ``angle`` [rad]."""
    return _rotation(angle, 0, 1)


def rot_y(angle: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation about y by ``angle`` [rad]."""
    return _rotation(angle, 2, 0)


def plate_rotation(phi, theta, psi) -> np.ndarray:
    """(..., 3, 3) plate rotation R = Rz(theta) Ry(pi/2 - phi) Rz(psi) (paper eq. 6),
    multiplied out (cos(pi/2 - phi) = sin(phi)): a few operations per entry instead of
    three matrices and two products, which dominate on one pose."""
    angles = [np.asarray(x, float) for x in (phi, theta, psi)]
    if len({x.shape for x in angles}) > 1:
        angles = np.broadcast_arrays(*angles)
    phi, theta, psi = angles
    (ct, st), (cp, sp) = (np.cos(theta), np.sin(theta)), (np.cos(psi), np.sin(psi))
    cb, sb = np.sin(phi), np.cos(phi)  # the middle angle beta = pi/2 - phi
    a, b = cb * cp, cb * sp
    return _last_axis(
        (ct * a - st * sp, -ct * b - st * cp, ct * sb,
         st * a + ct * sp, -st * b + ct * cp, st * sb,
         -sb * cp, sb * sp, cb),
    ).reshape((*phi.shape, 3, 3))  # fmt: skip


def _last_axis(parts) -> np.ndarray:
    """``np.stack(parts, axis=-1)`` for arrays of one shape, filled into one new array
    (np.stack's own checks cost more than the arithmetic on one pose)."""
    out = np.empty((*np.shape(parts[0]), len(parts)))
    for k, part in enumerate(parts):
        out[..., k] = part
    return out


@dataclass(frozen=True)
class PlatePose:
    """Pose of the mobile plate for a batch of leg inputs.

    Attributes:
        H: (..., 3) plate centre [m], world frame.
        R: (..., 3, 3) plate orientation, world from plate.
        phi, theta, psi: (...) the paper's angles [rad] (see module docstring).
        s: (..., 3) strokes s_k of the prismatic joints SJ [m].
    """

    H: np.ndarray
    R: np.ndarray
    phi: np.ndarray
    theta: np.ndarray
    psi: np.ndarray
    s: np.ndarray


def leg_plane_coordinates(alpha: np.ndarray, p: CaHyManParams) -> tuple[np.ndarray, np.ndarray]:
    """In-plane coordinates (y_k, z_k) [m] of the ball centres H_k; alpha (..., 3) [rad]."""
    alpha = np.asarray(alpha, float)
    return p.b * np.cos(alpha), p.b * np.sin(alpha) + p.h


def _check_alpha(alpha: np.ndarray) -> np.ndarray:
    alpha = np.asarray(alpha, float)
    if alpha.shape[-1:] != (3,):
        raise InvalidInputError(f"alpha must have shape (..., 3), got {alpha.shape}")
    if not np.isfinite(alpha).all():
        raise InvalidInputError(f"alpha must be finite, got {alpha}")
    return alpha


def _degrees(alpha: np.ndarray) -> str:
    """Crank angles [rad] of the poses that fail, in degrees for a message: ``[-85, 60, 60]``
    for one pose, ``[-85, 60, 60], [90, -90, 90]`` for several (6 significant digits)."""
    return ", ".join(
        "[" + ", ".join(f"{a:.6g}" for a in row) + "]" for row in np.rad2deg(alpha).reshape(-1, 3)
    )


def plate_pose(alpha, p: CaHyManParams) -> PlatePose:
    """Closed-form direct kinematics of CaPaMan: leg inputs -> plate pose.

    Args:
        alpha: (..., 3) crank angles alpha_1..3 [rad].
        p: parameters.

    Raises:
        AssemblyError: the legs cannot carry the plate (cos phi > 1 or ``|sin(theta+psi)|`` > 1).
    """
    alpha = _check_alpha(alpha)
    y, z = leg_plane_coordinates(alpha, p)
    y1, y2, y3 = y[..., 0], y[..., 1], y[..., 2]
    z1, z2, z3 = z[..., 0], z[..., 1], z[..., 2]
    cphi = np.sqrt((2 * z1 - z2 - z3) ** 2 + 3 * (z2 - z3) ** 2) / (3 * p.r_p)
    bad = cphi > 1.0
    if bad.any():
        raise AssemblyError(
            f"plate cannot be assembled at alpha={_degrees(alpha[bad])} deg: "
            "height differences between legs exceed the plate radius",
            float(np.max(cphi - 1.0) * 3 * p.r_p),
        )
    phi = np.arccos(cphi)
    sphi = np.sin(phi)
    psi = np.arctan2(_SQ3 * (z2 - z3), -(2 * z1 - z2 - z3))
    s_tp = (y1 + y2 + y3) / (1.5 * p.r_p * (1.0 + sphi))
    bad = np.abs(s_tp) > 1.0
    if bad.any():
        raise AssemblyError(
            f"plate cannot be assembled at alpha={_degrees(alpha[bad])} deg: "
            "in-plane leg offsets exceed the plate radius",
            float(np.max(np.abs(s_tp) - 1.0) * 1.5 * p.r_p),
        )
    theta = np.arcsin(s_tp) - psi
    x_H = (y3 - y2) / _SQ3 - 0.5 * p.r_p * (1.0 - sphi) * np.cos(psi - theta)
    y_H = y1 - p.r_p * (np.sin(psi) * np.cos(theta) + sphi * np.cos(psi) * np.sin(theta))
    z_H = (z1 + z2 + z3) / 3.0
    H = _last_axis((x_H, y_H, z_H))
    R = plate_rotation(phi, theta, psi)
    H_k = H[..., None, :] + (R @ (p.r_p * U.T)).swapaxes(-1, -2)
    s = (H_k * U).sum(axis=-1) - p.r_e
    return PlatePose(H=H, R=R, phi=phi, theta=theta, psi=psi, s=s)


def ball_centres(pose: PlatePose, p: CaHyManParams) -> np.ndarray:
    """(..., 3, 3) ball-joint centres H_k [m], world frame, one leg per row."""
    return pose.H[..., None, :] + (pose.R @ (p.r_p * U.T)).swapaxes(-1, -2)


def inverse_legs(z_H, phi, psi, p: CaHyManParams) -> np.ndarray:
    """Closed-form inverse kinematics of CaPaMan: plate height and tilt -> alpha (..., 3).

    Args:
        z_H: (...) plate-centre height [m].
        phi: (...) elevation of the plate normal [rad] (pi/2: plate parallel to FP).
        psi: (...) azimuth of the tilt [rad].
        p: parameters.

    Returns:
        (..., 3) crank angles in [-pi/2, pi/2] [rad] (the branch the paper uses).

    Raises:
        AssemblyError: a crank would have to reach beyond its length b.
    """
    z_H, phi, psi = np.broadcast_arrays(*(np.asarray(x, float) for x in (z_H, phi, psi)))
    rc = p.r_p * np.cos(phi)
    z1 = z_H - rc * np.cos(psi)
    z2 = z_H + 0.5 * rc * np.cos(psi) + 0.5 * _SQ3 * rc * np.sin(psi)
    z3 = z_H + 0.5 * rc * np.cos(psi) - 0.5 * _SQ3 * rc * np.sin(psi)
    sa = (np.stack([z1, z2, z3], axis=-1) - p.h) / p.b
    if np.any(np.abs(sa) > 1.0):
        raise AssemblyError(
            f"pose z_H={z_H.tolist()} m, phi={np.rad2deg(phi).tolist()} deg, "
            f"psi={np.rad2deg(psi).tolist()} deg is out of reach of the cranks: each ball "
            f"centre's height must lie within h +- b = [{p.h - p.b:.6g}, {p.h + p.b:.6g}] m",
            float(np.max(np.abs(sa) - 1.0) * p.b),
        )
    return np.arcsin(sa)


def arm_direction(R: np.ndarray, alpha4) -> np.ndarray:
    """(..., 3) unit arm direction w = cos(alpha_4) x_p + sin(alpha_4) z_p, world axes."""
    alpha4 = np.asarray(alpha4, float)
    return np.cos(alpha4)[..., None] * R[..., :, 0] + np.sin(alpha4)[..., None] * R[..., :, 2]


def arm_rotation(R: np.ndarray, alpha4) -> np.ndarray:
    """(..., 3, 3) orientation of the arm link carrying M: R Ry(-alpha_4) (x axis along w)."""
    return R @ rot_y(-np.asarray(alpha4, float))


def extremity(pose: PlatePose, alpha4, s4, p: CaHyManParams) -> tuple[np.ndarray, np.ndarray]:
    """Points Q and M [m], world frame: Q = H + HQ z_p, M = Q + (L + s_4) w."""
    Q = pose.H + p.HQ * pose.R[..., :, 2]
    M = Q + (p.L + np.asarray(s4, float))[..., None] * arm_direction(pose.R, alpha4)
    return Q, M
