"""Consistent closed-form compliance of CaHyMan at the arm extremity M (pure numpy).

The paper's structure (legs -> plate -> arm, eqs. 3 to 19) with every damaged place
resolved consistently, in exact linear theory (no preload, analytic derivatives):

* each leg k gives a 2x2 compliance of its ball centre H_k in the leg plane (t_k, z) from
  its three springs (motor K_T at alpha_k, axial K_b along crank b_k, axial K_d along crank
  d_k): C_leg = J_leg diag(1/K_T, 1/K_b, 1/K_d) J_leg^T;
* the plate twist at H maps to the six in-plane leg displacements through G; its inverse
  is A_d, the Jacobian of the closed-form direct kinematics (rotation as a vector);
* plate compliance at H: C_H = A_d blockdiag(C_leg) A_d^T, stiffness K_H = C_H^-1;
* arm springs (K_4 and K_s in series along w, K_T4 at alpha_4):
  C_ser = A_s diag(1/K_4, 1/K_s, 1/K_T4) A_s^T at M, world axes;
* C = T C_H T^T + C_ser, with T the twist transport from H to M (T^T is the wrench
  transport from M to H, eq. 10 without its weight terms).

Every compliance is formed from a square-root factor, one column per spring (its
deflection per unit sqrt(energy)): C_leg = F_leg F_leg^T with F_leg = J_leg
diag(K_leg^-1/2), C_ser = F_arm F_arm^T, and C = B B^T with the (6, 12) factor at M
B = [T A_d blockdiag(F_leg), F_arm]. Stiffnesses come from the factors, never from
the inverse of a formed compliance: C sums the springs' compliances, and its smallest
eigenvalues, hence K and det K, lose cond(K) times the rounding when the springs are many
orders apart. K at M comes from the SVD of B (K = U diag(1/s^2) U^T,
:func:`closedloop.common.conditioning.spectrum_from_factor`, in :mod:`cahyman_pin.api`), whose
singular values keep the small eigenvalues of C to sqrt(cond(K)) times the rounding; the
2x2 leg stiffnesses of K_H come from the minors of their factors (:func:`plate_stiffness`).

Twists are (dx, dy, dz, rx, ry, rz) in world axes, with r the small rotation vector;
wrenches are (fx, fy, fz, nx, ny, nz), conjugate to them. Units are SI: C is in m/N
(translation per force), 1/N (rad/N and m/(N m)) and rad/(N m). The rotation reported at
M is that of the arm link carrying M: the plate rotation plus alpha_4 about -y_p (alpha_4
turns x_p towards z_p). Gravity is not included: masses act as a separate preload.

Every function accepts a leading batch shape ``(...)`` and has no loop over poses.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from cahyman_pin.geometry import EZ, PlatePose, T, U, arm_direction, extremity, plate_pose
from cahyman_pin.params import DEFAULT_PARAMS, CaHyManParams
from closedloop.exceptions import InvalidInputError, SingularConfigurationError

#: ``|sin alpha_k|`` below which the parallelogram is singular (cranks along the coupler).
SIN_ALPHA_MIN = 1e-9


def _skew(r: np.ndarray) -> np.ndarray:
    """(..., 3, 3) cross-product matrix [r]x of r (..., 3)."""
    x, y, z = np.moveaxis(r, -1, 0)
    o = np.zeros_like(x)
    return np.stack(
        [np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], -2
    )


def _check_params(params: CaHyManParams) -> CaHyManParams:
    if not isinstance(params, CaHyManParams):
        raise InvalidInputError(f"params must be a CaHyManParams, got {type(params).__name__}")
    return params


def check_pose_inputs(alpha, alpha4, s4, params: CaHyManParams):
    """Validate and broadcast pose inputs.

    Args:
        alpha: (..., 3) crank angles [rad].
        alpha4: (...) arm angle [rad].
        s4: (...) arm stroke [m].
        params: parameters.

    Returns:
        ``(alpha, alpha4, s4)`` as float arrays broadcast to a common batch shape.

    Raises:
        InvalidInputError: a value is not finite, a shape does not fit, or L + s_4 <= 0.
    """
    _check_params(params)
    alpha = np.asarray(alpha, dtype=float)
    alpha4 = np.asarray(alpha4, dtype=float)
    s4 = np.asarray(s4, dtype=float)
    if alpha.ndim == 0 or alpha.shape[-1] != 3:
        raise InvalidInputError(f"alpha must have shape (..., 3) [rad], got shape {alpha.shape}")
    for name, value in (("alpha", alpha), ("alpha4", alpha4), ("s4", s4)):
        if not np.all(np.isfinite(value)):
            raise InvalidInputError(f"{name} must be finite, got {name}={value.tolist()}")
    try:
        batch = np.broadcast_shapes(alpha.shape[:-1], alpha4.shape, s4.shape)
    except ValueError as err:
        raise InvalidInputError(
            f"batch shapes do not broadcast: alpha {alpha.shape[:-1]} (+ trailing 3), "
            f"alpha4 {alpha4.shape}, s4 {s4.shape}"
        ) from err
    if np.any(params.L + s4 <= 0.0):
        raise InvalidInputError(f"L + s4 must be > 0 m, got s4={s4.tolist()} with L={params.L}")
    alpha = np.broadcast_to(alpha, (*batch, 3))
    return alpha, np.broadcast_to(alpha4, batch), np.broadcast_to(s4, batch)


def _degrees(alpha) -> list:
    """alpha (..., 3) [rad] in degrees for a message: one pose as one list."""
    a = np.rad2deg(np.asarray(alpha, dtype=float)).reshape(-1, 3)
    return a[0].tolist() if len(a) == 1 else a.tolist()


def _check_alpha(alpha, params: CaHyManParams) -> np.ndarray:
    alpha, _, _ = check_pose_inputs(alpha, 0.0, 0.0, params)
    sa = np.sin(alpha)
    if np.any(np.abs(sa) < SIN_ALPHA_MIN):
        raise SingularConfigurationError(
            f"alpha={_degrees(alpha[np.any(np.abs(sa) < SIN_ALPHA_MIN, axis=-1)])} deg: a "
            "crank lies along the coupler "
            "(sin alpha_k = 0), the parallelogram is singular"
        )
    return alpha


def leg_jacobian(alpha, params: CaHyManParams = DEFAULT_PARAMS) -> np.ndarray:
    """Jacobian of the ball centre H_k in its leg plane with respect to the leg springs.

    Rows: (dy_k, dz_k), displacement of H_k along t_k and z [m]. Columns: the spring
    coordinates (d alpha_k [rad], d b_k [m], d d_k [m]): motor rotation of crank b_k,
    extension of crank b_k, extension of crank d_k. The follower angle is passive and the
    coupler (length a) rigid, so a crank extension turns the coupler by
    (dd - db) / (a sin alpha), which moves H_k by h times that along -t_k.

    Args:
        alpha: (..., 3) crank angles [rad].
        params: parameters.

    Returns:
        (..., 3, 2, 3) array, one 2x3 block per leg [m/rad, m/m].
    """
    alpha = _check_alpha(alpha, params)
    a, b, h = params.a, params.b, params.h
    ca, sa = np.cos(alpha), np.sin(alpha)
    rot = h / (a * sa)  # coupler rotation per unit extension, times h
    cot = ca * ca / sa
    row_y = np.stack([-b * sa, ca + rot, -rot], -1)
    row_z = np.stack([b * ca, 0.5 * (sa - cot), 0.5 * (sa + cot)], -1)
    return np.stack([row_y, row_z], -2)


def leg_factor(alpha, params: CaHyManParams = DEFAULT_PARAMS) -> np.ndarray:
    """Square-root factor F_leg = J_leg diag(K_T, K_b, K_d)^-1/2 of each leg compliance.

    Args:
        alpha: (..., 3) crank angles [rad].
        params: parameters.

    Returns:
        (..., 3, 2, 3) array, one 2x3 block per leg: rows (dy_k, dz_k) as
        :func:`leg_jacobian`, columns the springs (K_T, K_b, K_d) [m/sqrt(N m)];
        C_leg = F_leg F_leg^T.
    """
    return leg_jacobian(alpha, params) * _root_compliances(params.K_T, params.K_b, params.K_d)


def factor_root_stiffness(params: CaHyManParams = DEFAULT_PARAMS) -> np.ndarray:
    """(12,) sqrt(k) [sqrt(N m/rad) or sqrt(N/m)] of the spring of each column of the
    factor B (:class:`ConsistentCompliance`): (K_T, K_b, K_d) for legs 1, 2, 3, then
    (K_4, K_s, K_T4). B diag(sqrt(k)) is its kinematic part (the springs taken as 1)."""
    legs = [params.K_T, params.K_b, params.K_d] * 3
    return np.sqrt(np.array([*legs, params.K_4, params.K_s, params.K_T4]))


def _root_compliances(*springs: float) -> np.ndarray:
    """(n,) 1/sqrt(k) of the spring stiffnesses k."""
    return 1.0 / np.sqrt(np.array(springs))


def _gram(F: np.ndarray) -> np.ndarray:
    """(..., m, m) F F^T of factors F (..., m, n), exactly symmetric."""
    return _sym(F @ F.swapaxes(-1, -2))


def leg_compliance(alpha, params: CaHyManParams = DEFAULT_PARAMS) -> np.ndarray:
    """2x2 compliance of each ball centre H_k in its leg plane.

    Args:
        alpha: (..., 3) crank angles [rad].
        params: parameters.

    Returns:
        (..., 3, 2, 2) array [m/N]: for leg k, (dy_k, dz_k) = C_k (f_t, f_z), with the
        force applied at H_k along t_k and z (world axes, leg-plane coordinates).
    """
    return _gram(leg_factor(alpha, params))


def twist_H_to_leg_displacements(R: np.ndarray, params: CaHyManParams = DEFAULT_PARAMS):
    """Map G from the plate twist at H to the in-plane displacements of the ball centres.

    Args:
        R: (..., 3, 3) plate orientation (world from plate).
        params: parameters.

    Returns:
        (..., 6, 6) array G: (dy_1, dz_1, dy_2, dz_2, dy_3, dz_3) [m] = G (dH [m], r [rad]),
        twist of the plate at its centre H in world axes. G^T maps the in-plane leg forces
        (f_t1, f_z1, ...) [N] to the wrench they exert on the plate at H [N, N m].
    """
    r_k = np.einsum("...ij,kj->...ki", np.asarray(R, float), params.r_p * U)  # H_k - H
    dirs = np.stack([T, np.broadcast_to(EZ, (3, 3))], axis=1)  # (3 legs, 2, 3)
    ang = np.cross(r_k[..., :, None, :], dirs)  # (r_k x d)
    G = np.concatenate([np.broadcast_to(dirs, ang.shape), ang], axis=-1)
    return G.reshape(*G.shape[:-3], 6, 6)


def twist_transport_H_to_M(r_HM: np.ndarray) -> np.ndarray:
    """Twist transport from H to M for a rigid body.

    Args:
        r_HM: (..., 3) vector M - H [m], world axes.

    Returns:
        (..., 6, 6) array T: twist at M = T twist at H, i.e. dM = dH + omega x (M - H); the
        wrench transport from M to H is T^T (force unchanged, moment + (M - H) x f).
    """
    r_HM = np.asarray(r_HM, float)
    eye = np.broadcast_to(np.eye(3), (*r_HM.shape[:-1], 3, 3))
    top = np.concatenate([eye, -_skew(r_HM)], axis=-1)
    bottom = np.concatenate([np.zeros_like(eye), eye], axis=-1)
    return np.concatenate([top, bottom], axis=-2)


def arm_jacobian(R: np.ndarray, alpha4, s4, params: CaHyManParams = DEFAULT_PARAMS):
    """Matrix A_s: twist of the arm link at M per unit arm spring deflection.

    Columns: extension of link QM2 (K_4) [m], extension of the linear motor s_4 (K_s) [m],
    rotation of the motor at alpha_4 (K_T4) [rad]. The alpha_4 joint turns the arm about
    -y_p (from x_p towards z_p), so its column is ((L + s_4) dw/d alpha_4, -y_p).

    Args:
        R: (..., 3, 3) plate orientation (world from plate).
        alpha4: (...) arm angle [rad].
        s4: (...) arm stroke [m].
        params: parameters.

    Returns:
        (..., 6, 3) array, twist at M in world axes [m, rad] per spring coordinate.
    """
    R = np.asarray(R, float)
    alpha4, s4 = np.asarray(alpha4, float), np.asarray(s4, float)
    w = arm_direction(R, alpha4)
    dw = -np.sin(alpha4)[..., None] * R[..., :, 0] + np.cos(alpha4)[..., None] * R[..., :, 2]
    axial = np.concatenate([w, np.zeros_like(w)], axis=-1)
    turn = np.concatenate([(params.L + s4)[..., None] * dw, -R[..., :, 1]], axis=-1)
    return np.stack([axial, axial, turn], axis=-1)


def arm_factor(R: np.ndarray, alpha4, s4, params: CaHyManParams = DEFAULT_PARAMS):
    """(..., 6, 3) square-root factor A_s diag(K_4, K_s, K_T4)^-1/2 of the arm compliance:
    twist at M in world axes [m/sqrt(N m), rad/sqrt(N m)] per spring (arguments as
    :func:`arm_jacobian`)."""
    A = arm_jacobian(R, alpha4, s4, params)
    return A * _root_compliances(params.K_4, params.K_s, params.K_T4)


def arm_compliance(R: np.ndarray, alpha4, s4, params: CaHyManParams = DEFAULT_PARAMS):
    """Compliance of the telescopic arm alone (plate rigid) at M.

    Args:
        R: (..., 3, 3) plate orientation (world from plate).
        alpha4: (...) arm angle [rad].
        s4: (...) arm stroke [m].
        params: parameters.

    Returns:
        (..., 6, 6) array C_ser = A_s diag(1/K_4, 1/K_s, 1/K_T4) A_s^T, reference point M,
        world axes, twist/wrench coordinates of the module docstring (rank 2).
    """
    return _gram(arm_factor(R, alpha4, s4, params))


def _block_diag3(blocks: np.ndarray) -> np.ndarray:
    """(..., 3, m, n) -> (..., 3 m, 3 n) block diagonal."""
    m, n = blocks.shape[-2:]
    out = np.zeros((*blocks.shape[:-3], 3 * m, 3 * n))
    for k in range(3):
        out[..., m * k : m * k + m, n * k : n * k + n] = blocks[..., k, :, :]
    return out


def _sym(C: np.ndarray) -> np.ndarray:
    return 0.5 * (C + C.swapaxes(-1, -2))


@dataclass(frozen=True)
class ConsistentCompliance:
    """Every piece of the consistent closed form for a batch of poses (read-only arrays).

    Attributes:
        pose: plate pose from the closed-form direct kinematics.
        M: (..., 3) extremity M [m], world frame.
        leg_compliance: (..., 3, 2, 2) compliance of H_k in its leg plane (t_k, z) [m/N].
        G: (..., 6, 6) plate twist at H -> in-plane leg displacements (see
            :func:`twist_H_to_leg_displacements`).
        A_d: (..., 6, 6) = G^-1, in-plane leg displacements -> plate twist at H, world axes.
        C_H: (..., 6, 6) plate compliance at H, world axes.
        K_H: (..., 6, 6) plate stiffness at H, world axes (G^T blockdiag(C_leg^-1) G, each
            C_leg^-1 from its factor: :func:`plate_stiffness`).
        T: (..., 6, 6) twist transport from H to M (:func:`twist_transport_H_to_M`).
        C_ser: (..., 6, 6) arm compliance at M, world axes.
        B: (..., 6, 12) square-root factor of C, C = B B^T: twist at M, world axes
            [m/sqrt(N m), rad/sqrt(N m)], per unit sqrt(energy) of each spring; columns
            (K_T, K_b, K_d) of legs 1, 2, 3, then (K_4, K_s, K_T4):
            [T A_d blockdiag(F_leg), A_s diag(K_4, K_s, K_T4)^-1/2]
            (:func:`leg_factor`, :func:`arm_factor`). K and det K at M come from its SVD
            (:func:`closedloop.common.conditioning.spectrum_from_factor`), never from inv(C).
        C: (..., 6, 6) total compliance T C_H T^T + C_ser = B B^T at M, world axes.
    """

    pose: PlatePose
    M: np.ndarray
    leg_compliance: np.ndarray
    G: np.ndarray
    A_d: np.ndarray
    C_H: np.ndarray
    K_H: np.ndarray
    T: np.ndarray
    C_ser: np.ndarray
    B: np.ndarray
    C: np.ndarray

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray):
                value.setflags(write=False)


def consistent_breakdown(alpha, alpha4, s4, params: CaHyManParams = DEFAULT_PARAMS):
    """All pieces of the consistent compliance at M (see :class:`ConsistentCompliance`).

    Args:
        alpha: (..., 3) crank angles alpha_1..3 [rad].
        alpha4: (...) arm angle [rad].
        s4: (...) arm stroke [m].
        params: parameters.

    Raises:
        InvalidInputError: non-finite input or wrong shape.
        SingularConfigurationError: a crank lies along its coupler.
        AssemblyError: the plate cannot be assembled.
    """
    pose, M, F_leg, G, A_d, F_H, Tr, B = _factors(alpha, alpha4, s4, params)
    return ConsistentCompliance(
        pose=pose,
        M=M,
        leg_compliance=_gram(F_leg),
        G=G,
        A_d=A_d,
        C_H=_gram(F_H),
        K_H=_plate_stiffness(G, F_leg, alpha),
        T=Tr,
        C_ser=_gram(B[..., 9:]),
        B=B,
        C=_gram(B),
    )


def _plate_stiffness(G: np.ndarray, F_leg: np.ndarray, alpha) -> np.ndarray:
    """(..., 6, 6) K_H = G^T blockdiag(C_leg^-1) G from the leg factors F_leg (..., 3, 2, 3)
    (C_leg = F_leg F_leg^T), or SingularConfigurationError where a leg compliance is
    singular (a crank within rounding of its coupler, alpha (..., 3) [rad]).

    C_leg^-1 = adj(C_leg) / det(C_leg), with det(C_leg) the sum of the squared 2x2 minors
    of F_leg (Cauchy-Binet): positive terms, each a minor of J_leg times 1/sqrt(k_i k_j)
    exactly, so its relative accuracy is that of the kinematics whatever the springs,
    where the determinant of the formed C_leg cancels when they are orders apart.
    """
    f, g = F_leg[..., 0, :], F_leg[..., 1, :]  # rows (dy, dz), (..., 3 legs, 3 springs)
    minors = f * np.roll(g, -1, axis=-1) - np.roll(f, -1, axis=-1) * g  # springs 01, 12, 20
    det = np.sum(minors * minors, axis=-1)
    c_yy, c_zz, c_yz = np.sum(f * f, axis=-1), np.sum(g * g, axis=-1), np.sum(f * g, axis=-1)
    adjugate = np.stack([np.stack([c_zz, -c_yz], -1), np.stack([-c_yz, c_yy], -1)], -2)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        K_leg = adjugate / det[..., None, None]  # inf or NaN where a leg is singular
    if not np.all(np.isfinite(K_leg)):
        raise SingularConfigurationError(
            f"alpha={_degrees(alpha)} deg: a leg's compliance is singular (a crank "
            "nearly along its coupler); the plate stiffness K_H does not exist"
        )
    return _sym(G.swapaxes(-1, -2) @ _block_diag3(K_leg) @ G)


def _factors(alpha, alpha4, s4, params: CaHyManParams):
    """(pose, M, F_leg, G, A_d, F_H, T, B): the square-root factors of the consistent
    compliance (legs F_leg, plate at H F_H = A_d blockdiag(F_leg), at M B) and the maps
    they are built from."""
    alpha, alpha4, s4 = check_pose_inputs(alpha, alpha4, s4, params)
    F_leg = leg_factor(alpha, params)
    pose = plate_pose(alpha, params)
    G = twist_H_to_leg_displacements(pose.R, params)
    A_d = np.linalg.inv(G)
    F_H = A_d @ _block_diag3(F_leg)  # (..., 6, 9), column 3 k + j: spring j of leg k
    _, M = extremity(pose, alpha4, s4, params)
    Tr = twist_transport_H_to_M(M - pose.H)
    B = np.concatenate([Tr @ F_H, arm_factor(pose.R, alpha4, s4, params)], axis=-1)
    return pose, M, F_leg, G, A_d, F_H, Tr, B


def consistent_compliance(alpha, alpha4, s4, params: CaHyManParams = DEFAULT_PARAMS):
    """Cartesian compliance of CaHyMan at the arm extremity M.

    Args:
        alpha: (..., 3) crank angles alpha_1..3 [rad].
        alpha4: (...) arm angle [rad].
        s4: (...) arm stroke [m].
        params: parameters.

    Returns:
        (..., 6, 6) symmetric positive definite compliance C at M, world axes:
        (dM [m], r_arm [rad]) = C (f [N], n [N m]), with r_arm the small rotation vector
        of the arm link carrying M and n the moment about M.

    Raises:
        InvalidInputError: non-finite input or wrong shape.
        SingularConfigurationError: a crank lies along its coupler.
        AssemblyError: the plate cannot be assembled.
    """
    C = _gram(_factors(alpha, alpha4, s4, params)[-1])
    C.setflags(write=False)
    return C


def plate_stiffness(alpha, params: CaHyManParams = DEFAULT_PARAMS) -> np.ndarray:
    """(..., 6, 6) stiffness K_H of the plate on its three legs, at H, world axes.

    (f [N], n [N m]) at H = K_H (dH [m], r [rad]); G^T blockdiag(C_leg^-1) G, each
    C_leg^-1 from the leg's factor (:func:`leg_factor`).
    """
    alpha = _check_alpha(alpha, params)
    G = twist_H_to_leg_displacements(plate_pose(alpha, params).R, params)
    return _plate_stiffness(G, leg_factor(alpha, params), alpha)


def plate_twist_from_leg_displacements(alpha, params: CaHyManParams = DEFAULT_PARAMS):
    """(..., 6, 6) matrix A_d: plate twist at H (world) from (dy_1, dz_1, ..., dz_3) [m].

    Equals the Jacobian of the closed-form direct kinematics with respect to the in-plane
    coordinates (y_k, z_k) of the ball centres, with the rotation as a vector.
    """
    alpha, _, _ = check_pose_inputs(alpha, 0.0, 0.0, params)
    return np.linalg.inv(twist_H_to_leg_displacements(plate_pose(alpha, params).R, params))


__all__ = [
    "ConsistentCompliance",
    "arm_compliance",
    "arm_factor",
    "arm_jacobian",
    "check_pose_inputs",
    "consistent_breakdown",
    "consistent_compliance",
    "leg_compliance",
    "leg_factor",
    "leg_jacobian",
    "plate_stiffness",
    "plate_twist_from_leg_displacements",
    "twist_H_to_leg_displacements",
    "twist_transport_H_to_M",
]
