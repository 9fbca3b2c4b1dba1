"""CaHyMan stiffness as published: the paper's eqs. (3) to (19), implemented as printed.

K_CaHyMan^-1 = K_PAR^-1 + K_SER^-1 (3), K_SER = R_SP Kss As^-1 (4-8),
K_PAR = M_FT^-1 M_FN K_P C_P^-1 A_d^-1 (9-19). Several places are damaged (see the
project's reference model, "Known damage", items 1 to 8); at each one this module makes
the smallest choice that lets the formula run, listed in :data:`CHOICES` and switchable
through :class:`PublishedOptions` (defaults = as published). With
``PublishedOptions.consistent()`` every switch takes its consistent value and the result
equals :func:`cahyman_pin.backends.consistent.consistent_compliance`.

Coordinates (defaults). Load F_M = (F_e, T_e) [N, N m], the same six numbers fed to both
chains as eq. (3) does (M_FT reads them in the arm frame, K_SER in world axes for forces).
Displacement = (dx, dy, dz [m], three rotations [rad]): the translations are those of H
(plate, eq. 9) plus those of M (arm); the rotations are the plate's rotation vector in
world axes (A_d from the Jacobian) plus the arm's planar angle about -y_p. With
``a_d="jacobian_euler"`` or ``"printed"`` the plate rotations are the paper's
(dphi, dtheta, dpsi) of R = Rz(theta) Ry(pi/2 - phi) Rz(psi); the tables print them in the
order dphi, dpsi, dtheta. K maps that displacement to F_M; C = K^-1.

One pose at a time (alpha (3,), scalar alpha4 and s4).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Literal

import numpy as np

from cahyman_pin.angles import COS_PHI_MIN, euler_rate_matrix
from cahyman_pin.backends import consistent as bc
from cahyman_pin.geometry import DELTA, PlatePose, extremity, leg_plane_coordinates, plate_pose
from cahyman_pin.params import DEFAULT_PARAMS, K_S_PRINTED, CaHyManParams
from closedloop.exceptions import InvalidInputError, SingularConfigurationError

#: Gravity and its sixth as printed in eq. (11) [m/s^2].
G_PRINTED, G_SIXTH_PRINTED = 9.81, 1.635
#: Condition number above which a printed matrix is treated as singular.
COND_MAX = 1e12

#: (place, choice) for every damaged place, defaults first, alternatives after ";".
CHOICES: tuple[tuple[str, str], ...] = (
    ("K_s (section 4)", "0.697 N/m as printed; ks='params' takes params.K_s"),
    ("eq. 4, 3x3 in 6x6 (damage 1)", "the arm model (x, z, angle) fills the (x_p, z_p, "
     "rotation about -y_p) slots, as alpha_4 turns x_p towards z_p; arm_rotation_axis='+y_p'"),
    ("eqs. 4, 7, 8, As^-1 (damage 2)", "As and Kss are singular: Moore-Penrose "
     "pseudo-inverses for As^-1 and K_SER^-1 (SI units); serial_form='series' uses "
     "As diag(1/K_4, 1/K_s, 1/K_T4) As^T"),
    ("eqs. 4, 5, R_SP", "left factor as printed (forces rotated, moments not), so "
     "K_SER^-1 = K_plate^+ R_SP^T; serial_frame='world' rotates both blocks congruently"),
    ("eq. 3, sum of compliances (damage 3)", "plate displacement at H added to the arm's at M "
     "without lever arm; lever_arm=True transports the plate twist from H to M"),
    ("eq. 11, weight terms (damage 4)", "9.81 and 1.635 as printed; a term whose load "
     "component is 0 (or no load given) is set to 0, 1/F_ej being infinite; weights=False"),
    ("eqs. 14, 15, beta_k, gamma_k (damage 5)", "undefined, taken as 0; "
     "beta_gamma='alpha' takes beta_k = alpha_k (parallelogram), gamma_k = 0, which makes "
     "K_pkk's first 2x2 singular everywhere and the full K_pkk singular at alpha_k = 60 deg"),
    ("eqs. 13, 16, first 2x2 (damage 5)", "first 2x2 blocks of K_pkk and C_pkk as printed "
     "(drops K_Tk); leg_block='3x3' keeps K_Tk (2x2 force block of C_pkk K_pkk^-1), "
     "'consistent' uses the three-spring leg of the reference model"),
    ("eqs. 18, 19, A_d (damage 6)", "Jacobian of the closed-form kinematics (the paper's "
     "alternative), plate rotation as a world rotation vector; a_d='jacobian_euler' "
     "(paper's angles, singular at phi = 90 deg) or 'printed' (Delta := pose coordinates, "
     "l := 1, Delta Delta_l := Delta y_1 in C_x and Delta z_1 in C_psi = 2 z_1 - z_2 - z_3, "
     "C_z unused; singular at the tables 1, 2 poses)"),
    ("eq. 12, M_FN (damage 7)", "columns read interleaved (R_x1, R_z1, R_x2, ...) as printed, "
     "matching Delta v; r_k = r_p; signs as printed; m_fn='consistent' uses G^T"),
    ("eq. 10, M_FT (damage 8)", "as printed (det -1: the reaction -[[Ra, 0], [r x Ra, Ra]], "
     "Ra = Ry(pi/2 - alpha_4), load in the arm frame); m_ft='transport' uses the world-axes "
     "wrench transport M -> H"),
)  # fmt: skip

_OPTION_VALUES = {
    "ks": ("printed", "params"),
    "arm_rotation_axis": ("-y_p", "+y_p"),
    "serial_form": ("pinv", "series"),
    "serial_frame": ("printed", "world"),
    "lever_arm": (False, True),
    "weights": (True, False),
    "beta_gamma": ("zero", "alpha"),
    "leg_block": ("2x2", "3x3", "consistent"),
    "a_d": ("jacobian", "jacobian_euler", "printed"),
    "m_fn": ("printed", "consistent"),
    "m_ft": ("printed", "transport"),
}


@dataclass(frozen=True)
class PublishedOptions:
    """Switches for the damaged places (defaults = as published; see :data:`CHOICES`)."""

    ks: Literal["printed", "params"] = "printed"
    arm_rotation_axis: Literal["-y_p", "+y_p"] = "-y_p"
    serial_form: Literal["pinv", "series"] = "pinv"
    serial_frame: Literal["printed", "world"] = "printed"
    lever_arm: bool = False
    weights: bool = True
    beta_gamma: Literal["zero", "alpha"] = "zero"
    leg_block: Literal["2x2", "3x3", "consistent"] = "2x2"
    a_d: Literal["jacobian", "jacobian_euler", "printed"] = "jacobian"
    m_fn: Literal["printed", "consistent"] = "printed"
    m_ft: Literal["printed", "transport"] = "printed"

    def __post_init__(self) -> None:
        for name, valid in _OPTION_VALUES.items():
            value = getattr(self, name)
            if not any(value == v and type(value) is type(v) for v in valid):
                raise InvalidInputError(f"option {name}={value!r}; expected one of {valid}")

    @classmethod
    def consistent(cls) -> PublishedOptions:
        """Every switch at its consistent value (reproduces the consistent backend)."""
        return cls("params", "-y_p", "series", "world", True, False, "zero", "consistent",
                   "jacobian", "consistent", "transport")  # fmt: skip


def r_par(phi: float, theta: float, psi: float) -> np.ndarray:
    """(3, 3) plate orientation R_PAR of eq. (6), world from plate."""
    cf, sf, ct, st, cs, ss = (np.cos(phi), np.sin(phi), np.cos(theta), np.sin(theta),
                              np.cos(psi), np.sin(psi))  # fmt: skip
    return np.array([
        [-st * ss + sf * ct * cs, -st * cs - sf * ct * ss, ct * cf],
        [ct * ss + sf * st * cs, ct * cs - sf * st * ss, st * cf],
        [-cf * cs, cf * ss, sf],
    ])  # fmt: skip


def kss(alpha4: float, s4: float, p: CaHyManParams, K_s: float) -> np.ndarray:
    """(3, 3) Kss of eq. (7), columns (dL [m], ds_4 [m], d alpha_4 [rad]), rows (x, z, angle)."""
    c, s, kt = np.cos(alpha4), np.sin(alpha4), p.K_T4 / (p.L + s4)
    return np.array([[p.K_4 * c, K_s * c, -kt * s], [p.K_4 * s, K_s * s, kt * c],
                     [0.0, 0.0, p.K_T4]])  # fmt: skip


def a_s(alpha4: float, s4: float, p: CaHyManParams) -> np.ndarray:
    """(3, 3) As of eq. (8): (dL, ds_4 [m], d alpha_4 [rad]) -> (dx, dz [m], d angle [rad])."""
    c, s, ls = np.cos(alpha4), np.sin(alpha4), p.L + s4
    return np.array([[c, c, -ls * s], [s, s, ls * c], [0.0, 0.0, 1.0]])


def weight_terms(alpha4: float, s4: float, p: CaHyManParams, load) -> np.ndarray:
    """(6, 6) eq. (11) terms C_1j..C_4j placed in rows 3 and 5 of M_FT (zero if no load)."""
    out = np.zeros((6, 6))
    if load is None:
        return out
    w = G_PRINTED * p.total_arm_mass / 6.0
    arm = (
        G_SIXTH_PRINTED
        * np.cos(alpha4)
        * (-p.m_M5 * (0.5 * s4 + p.L) - 0.5 * p.m_M4 * p.L - p.m_MM2 * p.L)
    )
    nonzero = load != 0.0
    inv = np.divide(1.0, load, out=np.zeros(6), where=nonzero)  # 1/F_ej := 0 if F_ej = 0
    out[2], out[4] = w * inv, arm * inv
    return out


def m_ft_printed(alpha4: float, s4: float, p: CaHyManParams) -> np.ndarray:
    """(6, 6) M_FT of eq. (10) without weights: F_M (arm frame) -> F_H (plate axes)."""
    c, s, ls, hq = np.cos(alpha4), np.sin(alpha4), p.L + s4, p.HQ
    return np.array([
        [-s, 0.0, -c, 0.0, 0.0, 0.0],
        [0.0, -1.0, 0.0, 0.0, 0.0, 0.0],
        [c, 0.0, -s, 0.0, 0.0, 0.0],
        [0.0, ls * s + hq, 0.0, -s, 0.0, -c],
        [-ls - hq * s, 0.0, -hq * c, 0.0, -1.0, 0.0],
        [0.0, -ls * c, 0.0, c, 0.0, -s],
    ])  # fmt: skip


def m_fn_printed(p: CaHyManParams) -> np.ndarray:
    """(6, 6) M_FN of eq. (12): (R_x1, R_z1, R_x2, R_z2, R_x3, R_z3) [N] -> F_H [N, N m]."""
    out = np.zeros((6, 6))
    r = p.r_p  # r_k := r_p
    for k, d in enumerate(DELTA):
        out[:, 2 * k] = [np.sin(d), np.cos(d), 0.0, 0.0, 0.0, r]
        out[:, 2 * k + 1] = [0.0, 0.0, 1.0, r * np.sin(d), r * np.cos(d), 0.0]
    return out


def k_pkk(alpha: np.ndarray, p: CaHyManParams, beta_is_alpha: bool = False) -> np.ndarray:
    """(3, 3, 3) K_pkk of eqs. (14, 15) per leg, gamma_k = 0, beta_k = 0 (or alpha_k).

    Columns (db [m], dd [m], d alpha [rad]), rows (R_x [N], R_z [N], moment [N m]).
    """
    out = np.zeros((3, 3, 3))
    c, h, kb, kd, kt = p.a, p.h, p.K_b, p.K_d, p.K_T / p.b
    for k, a in enumerate(alpha):
        beta, gamma = (a if beta_is_alpha else 0.0), 0.0
        r_b = (c / 2) * np.sin(a + gamma) + h * np.cos(a + gamma)
        r_d = -(c / 2) * np.sin(a + beta) + h * np.cos(a + beta)
        r_T = (c / 2) * np.cos(a - gamma) + h * np.sin(a - gamma)
        out[k] = [[kb * np.cos(a), kd * np.cos(beta), -kt * np.sin(a)],
                  [kb * np.sin(a), kd * np.sin(beta), kt * np.cos(a)],
                  [kb * r_b, -kd * r_d, kt * r_T]]  # fmt: skip
    return out


def c_pkk(alpha: np.ndarray, p: CaHyManParams) -> np.ndarray:
    """(3, 3, 3) C_pkk of eq. (17) per leg: (db, dd [m], d alpha [rad]) -> (dy, dz [m], angle)."""
    c, h, b = p.a, p.h, p.b
    q, r = (c - 2 * h) / (2 * c), (3 * c - 2 * h) / (2 * c)
    return np.array([[[np.cos(a) - q * np.sin(a), q * np.sin(a), -b * r],
                      [r * np.sin(a), -q * np.sin(a), b * r],
                      [np.sin(a) / c, -np.sin(a) / c, b / c]] for a in alpha])  # fmt: skip


def a_d_printed(alpha: np.ndarray, pose: PlatePose, p: CaHyManParams) -> np.ndarray:
    """(6, 6) A_d of eqs. (18, 19), its C terms at the pose's own coordinates.

    Raises:
        SingularConfigurationError: a divisor of eq. (19) is zero at this pose.
    """
    y, z = leg_plane_coordinates(alpha, p)
    f, t, s, rp = float(pose.phi), float(pose.theta), float(pose.psi), p.r_p
    c_psi, c_theta = 2 * z[0] - z[1] - z[2], 1.5 * rp * (1 + np.sin(f))
    for name, value in (("Delta y_1", y[0]), ("Delta y_2", y[1]), ("C_psi", c_psi)):
        if abs(value) < 1e-12:
            raise SingularConfigurationError(
                f"printed A_d divides by {name} = {value:.3g} at alpha="
                f"{np.rad2deg(alpha).round(6).tolist()} deg"
            )
    c_x = -(rp / (2 * y[0])) * (1 - np.sin(f)) * np.cos(s - t)
    c_y = -(rp / y[1]) * (np.sin(f) * np.cos(f) + np.cos(s) * np.sin(f) * np.sin(t))
    c_phi, q, r3 = 1.0 / y[0], 2 / (3 * rp), np.sqrt(3.0)
    return np.array([
        [c_x, 0.0, -1 / r3, 0.0, 1 / r3, 0.0],
        [1.0, 0.0, c_y, 0.0, 0.0, 0.0],
        [0.0, 1 / 3, 0.0, 1 / 3, 0.0, 1 / 3],
        [c_phi, -q, 0.0, q, 0.0, q],
        [0.0, 0.0, 0.0, -r3 / c_psi, 0.0, -r3 / c_psi],
        [1 / c_theta, 0.0, 1 / c_theta, r3 / c_psi, 1 / c_theta, -r3 / c_psi],
    ])  # fmt: skip


def _blocks(b: np.ndarray) -> np.ndarray:
    out = np.zeros((6, 6))
    for k in range(3):
        out[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = b[k]
    return out


def _inv(A: np.ndarray, name: str) -> np.ndarray:
    if np.linalg.cond(A) > COND_MAX:
        raise SingularConfigurationError(f"{name} is singular (condition {np.linalg.cond(A):.3g})")
    return np.linalg.inv(A)


def _euler_matrix(pose: PlatePose) -> np.ndarray:
    if abs(np.cos(pose.phi)) < COS_PHI_MIN:
        raise SingularConfigurationError(
            f"phi={np.rad2deg(pose.phi):.6g} deg: (dphi, dtheta, dpsi) are singular at 90 deg"
        )
    return euler_rate_matrix(pose.phi, pose.theta)


@dataclass(frozen=True)
class PublishedResult:
    """Every matrix of eqs. (3) to (19) at one pose (read-only arrays, SI units).

    Attributes:
        options, pose, load: inputs (load (6,) or None; it only enters the weight terms).
        R_PAR: (3, 3) eq. (6).
        R_SP: (6, 6) eq. (5).
        Kss, As: (3, 3) eqs. (7, 8), planar arm.
        K_SER: (6, 6) R_SP [Kss As^+] embedded (eq. 4, plate slots; rank <= 2).
        C_SER: (6, 6) the arm term K_SER^-1 of eq. (3) actually used.
        M_FT: (6, 6) eq. (10) incl. weight terms (or the transport).
        M_FN: (6, 6) eq. (12) (or G^T).
        K_pkk, C_pkk: (3, 3, 3) eqs. (14, 17).
        K_P, C_P: (6, 6) their first 2x2 blocks (eqs. 13, 16, as printed).
        leg_compliance: (3, 2, 2) the leg blocks used, (R_xk, R_zk) [N] -> (dy_k, dz_k) [m].
        A_d: (6, 6) eq. (18) or Jacobian.
        C_PAR: (6, 6) K_PAR^-1 = A_d C_P K_P^-1 M_FN^-1 M_FT, plate displacement at H.
        K_PAR: (6, 6) eq. (9).
        C_PAR_M: the plate term of eq. (3) (= C_PAR, or transported).
        C, K: (6, 6) K_CaHyMan^-1 and K_CaHyMan (eq. 3); coordinates in the module docstring.
    """

    options: PublishedOptions
    pose: PlatePose
    load: np.ndarray | None
    R_PAR: np.ndarray
    R_SP: np.ndarray
    Kss: np.ndarray
    As: np.ndarray
    K_SER: np.ndarray
    C_SER: np.ndarray
    M_FT: np.ndarray
    M_FN: np.ndarray
    K_pkk: np.ndarray
    C_pkk: np.ndarray
    K_P: np.ndarray
    C_P: np.ndarray
    leg_compliance: np.ndarray
    A_d: np.ndarray
    C_PAR: np.ndarray
    K_PAR: np.ndarray
    C_PAR_M: np.ndarray
    C: np.ndarray
    K: np.ndarray

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray):
                value.setflags(write=False)

    def displacement(self, load=None) -> np.ndarray:
        """(6,) displacement C F_M for ``load`` (default: the load given at construction)."""
        load = self.load if load is None else np.asarray(load, float)
        if load is None or load.shape != (6,):
            raise InvalidInputError(f"load must have shape (6,) [N, N m], got {load!r}")
        return self.C @ load


def published_stiffness(
    alpha,
    alpha4,
    s4,
    params: CaHyManParams = DEFAULT_PARAMS,
    options: PublishedOptions | None = None,
    load=None,
) -> PublishedResult:
    """The paper's stiffness matrix K_CaHyMan at one pose, with every intermediate matrix.

    Args:
        alpha: (3,) crank angles [rad]. alpha4: arm angle [rad]. s4: arm stroke [m].
        params: parameters. options: switches (default: as published).
        load: (6,) F_M [N, N m] for the weight terms of eq. (11) (None: no weight terms).

    Raises:
        InvalidInputError: bad input. SingularConfigurationError: a printed matrix that the
            chosen options need is singular at this pose.
    """
    o = PublishedOptions() if options is None else options
    alpha, alpha4, s4 = bc.check_pose_inputs(alpha, alpha4, s4, params)
    if alpha4.shape != ():
        raise InvalidInputError(f"one pose at a time: alpha has shape {alpha.shape}, expected (3,)")
    alpha4, s4 = float(alpha4), float(s4)
    if load is not None:
        load = np.asarray(load, float)
        if load.shape != (6,) or not np.all(np.isfinite(load)):
            raise InvalidInputError(f"load must be a finite (6,) array [N, N m], got {load!r}")
    pose = plate_pose(alpha, params)
    K_s = K_S_PRINTED if o.ks == "printed" else params.K_s  # choice: K_s as printed
    _, M = extremity(pose, alpha4, s4, params)
    T = bc.twist_transport_H_to_M(M - pose.H)
    # Arm (eqs. 4 to 8).
    R_PAR = r_par(pose.phi, pose.theta, pose.psi)
    R_SP = np.eye(6)
    R_SP[:3, :3] = R_PAR
    P = np.zeros((6, 3))  # damage 1: (x, z, angle) -> (x_p, z_p, rotation about -y_p)
    P[0, 0], P[2, 1], P[4, 2] = 1.0, 1.0, -1.0 if o.arm_rotation_axis == "-y_p" else 1.0
    Kss_, As_ = kss(alpha4, s4, params, K_s), a_s(alpha4, s4, params)
    K_SER = R_SP @ P @ Kss_ @ np.linalg.pinv(As_) @ P.T
    if o.serial_form == "pinv":  # damage 2: pseudo-inverses where As^-1, K_SER^-1 do not exist
        C_plate = P @ np.linalg.pinv(Kss_ @ np.linalg.pinv(As_)) @ P.T
    else:
        C_plate = P @ As_ @ np.diag([1 / params.K_4, 1 / K_s, 1 / params.K_T4]) @ As_.T @ P.T
    if o.serial_frame == "printed":
        C_SER = C_plate @ R_SP.T  # R_SP as printed: (R_SP K)^-1 = K^-1 R_SP^T
    else:
        R6 = np.kron(np.eye(2), R_PAR)
        C_SER = R6 @ C_plate @ R6.T
    # Parallel chain (eqs. 9 to 19).
    if o.m_ft == "printed":
        M_FT = m_ft_printed(alpha4, s4, params)  # damage 8: kept as printed (det -1)
        if o.weights:  # damage 4: eq. 11 terms, 0 where the load component is 0
            M_FT = M_FT + weight_terms(alpha4, s4, params, load)
    else:
        M_FT = T.T  # wrench at M (world) -> wrench at H (world)
    G = bc.twist_H_to_leg_displacements(pose.R, params)
    M_FN = m_fn_printed(params) if o.m_fn == "printed" else G.T  # damage 7: interleaved
    K_pkk_ = k_pkk(alpha, params, o.beta_gamma == "alpha")  # damage 5: beta, gamma := 0
    C_pkk_ = c_pkk(alpha, params)
    K_P, C_P = _blocks(K_pkk_[:, :2, :2]), _blocks(C_pkk_[:, :2, :2])
    if o.leg_block == "3x3":
        legs = np.array([(C_pkk_[k] @ _inv(K_pkk_[k], f"K_p{k + 1}{k + 1}"))[:2, :2]
                         for k in range(3)])  # fmt: skip
    elif o.leg_block == "2x2":  # damage 5: "first 2x2 submatrix" as printed, drops K_Tk
        legs = np.array([C_pkk_[k, :2, :2] @ _inv(K_pkk_[k, :2, :2], f"K_p{k + 1} (first 2x2)")
                         for k in range(3)])  # fmt: skip
    else:
        legs = bc.leg_compliance(alpha, params)
    if o.a_d == "printed":  # damage 6: default is the Jacobian, the paper's alternative
        A_d = a_d_printed(alpha, pose, params)
    else:
        A_d = np.linalg.inv(G)
        if o.a_d == "jacobian_euler":  # rotation vector -> (dphi, dtheta, dpsi)
            A_d[3:] = np.linalg.solve(_euler_matrix(pose), A_d[3:])
    C_PAR = A_d @ _blocks(legs) @ _inv(M_FN, "M_FN") @ M_FT
    K_PAR = _inv(C_PAR, "K_PAR^-1")
    C_PAR_M = C_PAR  # damage 3: plate displacement at H added without lever arm
    if o.lever_arm:
        E = np.eye(6)
        if o.a_d != "jacobian":
            E[3:, 3:] = _euler_matrix(pose)
        C_PAR_M = T @ E @ C_PAR
    C = C_PAR_M + C_SER
    return PublishedResult(o, pose, load, R_PAR, R_SP, Kss_, As_, K_SER, C_SER, M_FT, M_FN,
                           K_pkk_, C_pkk_, K_P, C_P, legs, A_d, C_PAR, K_PAR, C_PAR_M, C,
                           _inv(C, "K_CaHyMan^-1"))  # fmt: skip
