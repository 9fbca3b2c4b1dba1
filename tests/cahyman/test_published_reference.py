"""The as-published backend against the paper's eqs. (3) to (19), retyped here.

Everything below is written from the paper's printed equations and from the project's
reference model (the CaHyMan model document: geometry, closed-form direct kinematics and
the reading of each damaged place), with no call to :mod:`cahyman_pin.geometry` or to the
consistent backend: leg directions, ball positions, rotation matrices, the plate pose,
the map G from the plate twist to the leg-plane displacements, the three-spring leg and
every printed matrix. The backend's full 6x6 C at the three tables' poses must equal this
rebuild for every leg-block option (defaults elsewhere), and so must its intermediate
matrices (K_pkk, C_pkk in full, also the entries that no option uses).
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import LEG_T as T
from helpers import LEG_U as U
from helpers import SQ3
from scipy.optimize import brentq

from cahyman_pin.backends.published import PublishedOptions, published_stiffness
from cahyman_pin.params import DEFAULT_PARAMS

#: The paper's configurations (alpha_1..3 [deg], alpha_4 [deg], s_4 [m]).
POSES = {
    "Table 1": ((90.0, 90.0, 90.0), 90.0, 0.050),
    "Table 2": ((30.0, 30.0, 30.0), 30.0, 0.0),
    "Table 3": ((45.0, 60.0, 75.0), 45.0, 0.0),
}
LEG_BLOCKS = ("2x2", "3x3", "consistent")
#: K_s as printed in the paper's section 4 [N/m].
K_S_PAPER = 0.697
#: Masses [kg] and a load with zero components, for the weight terms of eq. (11).
MASSES = {"m_HQ": 0.2, "m_QM": 0.3, "m_MM2": 0.1, "m_M4": 0.5, "m_M5": 0.4}
LOAD_F = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])

# Same formulas evaluated in a different order: round-off only. The chain has a few 6x6
# inverses with condition numbers up to ~1e7 in mixed units, so entries are compared to
# 1e-12 of themselves with a floor of 1e-12 of the matrix's largest entry.
RTOL = 1e-12
# Central differences of the nonlinear parallelogram (step 1e-7 m or rad on lengths and
# angles of ~0.1): truncation ~1e-12, round-off ~1e-16 / 1e-7 = 1e-9 relative.
STEP = 1e-7
FD_RTOL = 1e-7

#: Leg angles delta_k [deg] (model document; U, T of helpers are their unit vectors).
DELTA_DEG = (0.0, 120.0, 240.0)
EZ = np.array([0.0, 0.0, 1.0])


def assert_close(actual, desired, rtol=RTOL, err_msg=""):
    desired = np.asarray(desired, float)
    np.testing.assert_allclose(
        actual, desired, rtol=rtol, atol=rtol * np.abs(desired).max(), err_msg=err_msg
    )


def si(case):
    alpha_deg, alpha4_deg, s4 = POSES[case]
    return np.deg2rad(alpha_deg), np.deg2rad(alpha4_deg), s4


def rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def plate(alpha, p):
    """(H (3,), R (3, 3), (phi, theta, psi)) from the model document's closed-form direct
    kinematics."""
    y, z = p.b * np.cos(alpha), p.b * np.sin(alpha) + p.h
    z_H = z.sum() / 3
    psi = np.arctan2(SQ3 * (z[1] - z[2]), -(2 * z[0] - z[1] - z[2]))
    phi = np.arccos(np.sqrt((2 * z[0] - z[1] - z[2]) ** 2 + 3 * (z[1] - z[2]) ** 2) / (3 * p.r_p))
    theta = np.arcsin(y.sum() / (1.5 * p.r_p * (1 + np.sin(phi)))) - psi
    x_H = (y[2] - y[1]) / SQ3 - 0.5 * p.r_p * (1 - np.sin(phi)) * np.cos(psi - theta)
    y_H = y[0] - p.r_p * (np.sin(psi) * np.cos(theta) + np.sin(phi) * np.cos(psi) * np.sin(theta))
    R = rz(theta) @ ry(np.pi / 2 - phi) @ rz(psi)
    return np.array([x_H, y_H, z_H]), R, (phi, theta, psi)


def leg_rows(R, p):
    """(6, 6) G: (dy_1, dz_1, ..., dz_3) = G (dH, r), ball k at H + R r_p u_k."""
    rows = []
    for k in range(3):
        rho = R @ (p.r_p * U[k])
        for d in (T[k], EZ):  # d . (dH + r x rho) = d . dH + r . (rho x d)
            rows.append(np.concatenate([d, np.cross(rho, d)]))
    return np.array(rows)


def leg_point(alpha, d_alpha, d_b, d_d, p):
    """(y, z) of H_k in the leg plane for a deformed parallelogram (no linearisation).

    Crank b pivots at y = -a/2, crank d at y = +a/2; the coupler has length a, its
    midpoint carries the bar h along the coupler normal.
    """
    B = np.array([-p.a / 2 + (p.b + d_b) * np.cos(alpha + d_alpha),
                  (p.b + d_b) * np.sin(alpha + d_alpha)])  # fmt: skip

    def tip(beta):
        return np.array([p.a / 2 + (p.b + d_d) * np.cos(beta), (p.b + d_d) * np.sin(beta)])

    beta = brentq(lambda x: np.sum((tip(x) - B) ** 2) - p.a**2, alpha - 0.3, alpha + 0.3,
                  xtol=1e-16, rtol=4 * np.finfo(float).eps)  # fmt: skip
    chord = (tip(beta) - B) / p.a
    return 0.5 * (B + tip(beta)) + p.h * np.array([-chord[1], chord[0]])


def leg_jacobian(alpha, p):
    """(2, 3) d(y, z)/d(alpha_k, extension of b_k, extension of d_k), linearised by hand.

    Rigid coupler: the follower turns by d alpha + cos(alpha) (dd - db) / (b sin alpha),
    the coupler by (dd - db) / (a sin alpha), which moves H_k by -h times that along t_k.
    """
    c, s, turn = np.cos(alpha), np.sin(alpha), p.h / (p.a * np.sin(alpha))
    return np.array([[-p.b * s, c + turn, -turn],
                     [p.b * c, 0.5 * (s - c * c / s), 0.5 * (s + c * c / s)]])  # fmt: skip


def k_pkk(a, p, beta_is_alpha=False):
    """(3, 3) eq. (14), gamma_k = 0, beta_k = 0 (default reading) or alpha_k (parallelogram)."""
    beta, gamma = (a if beta_is_alpha else 0.0), 0.0
    c, h, kt = p.a, p.h, p.K_T / p.b
    r_b = (c / 2) * np.sin(a + gamma) + h * np.cos(a + gamma)
    r_d = -(c / 2) * np.sin(a + beta) + h * np.cos(a + beta)
    r_T = (c / 2) * np.cos(a - gamma) + h * np.sin(a - gamma)
    return np.array([[p.K_b * np.cos(a), p.K_d * np.cos(beta), -kt * np.sin(a)],
                     [p.K_b * np.sin(a), p.K_d * np.sin(beta), kt * np.cos(a)],
                     [p.K_b * r_b, -p.K_d * r_d, kt * r_T]])  # fmt: skip


def c_pkk(a, p):
    """(3, 3) eq. (17)."""
    c, h, b = p.a, p.h, p.b
    q, r = (c - 2 * h) / (2 * c), (3 * c - 2 * h) / (2 * c)
    return np.array([[np.cos(a) - q * np.sin(a), q * np.sin(a), -b * r],
                     [r * np.sin(a), -q * np.sin(a), b * r],
                     [np.sin(a) / c, -np.sin(a) / c, b / c]])  # fmt: skip


def leg_block(a, p, option, beta_is_alpha=False):
    """(2, 2) leg compliance (R_x, R_z) [N] -> (dy, dz) [m] for one leg-block option."""
    K = k_pkk(a, p, beta_is_alpha)
    if option == "2x2":  # "first 2x2 submatrix" of eqs. (13, 16)
        return c_pkk(a, p)[:2, :2] @ np.linalg.inv(K[:2, :2])
    if option == "3x3":
        return (c_pkk(a, p) @ np.linalg.inv(K))[:2, :2]
    J = leg_jacobian(a, p)
    return J @ np.diag([1 / p.K_T, 1 / p.K_b, 1 / p.K_d]) @ J.T


def m_ft(alpha4, s4, p, load=None):
    """(6, 6) eq. (10) with the weight terms of eq. (11) (1/F_ej := 0 where F_ej = 0)."""
    c, s, ls, hq = np.cos(alpha4), np.sin(alpha4), p.L + s4, p.HQ
    M = np.array([
        [-s, 0, -c, 0, 0, 0],
        [0, -1, 0, 0, 0, 0],
        [c, 0, -s, 0, 0, 0],
        [0, ls * s + hq, 0, -s, 0, -c],
        [-ls - hq * s, 0, -hq * c, 0, -1, 0],
        [0, -ls * c, 0, c, 0, -s],
    ], dtype=float)  # fmt: skip
    if load is not None:
        m = p.m_HQ + p.m_QM + p.m_MM2 + p.m_M4 + p.m_M5
        c3 = 1.635 * (-p.m_M5 * (0.5 * s4 + p.L) * c - 0.5 * p.m_M4 * p.L * c - p.m_MM2 * p.L * c)
        for j in range(6):
            if load[j] != 0.0:
                M[2, j] += 9.81 * m / 6 / load[j]  # C_1j (forces), C_2j (moments)
                M[4, j] += c3 / load[j]  # C_3j, C_4j
    return M


def m_fn(p):
    """(6, 6) eq. (12), columns interleaved (R_x1, R_z1, R_x2, ...), r_k = r_p."""
    cols = []
    for d in np.deg2rad(DELTA_DEG):
        cols.append([np.sin(d), np.cos(d), 0, 0, 0, p.r_p])
        cols.append([0, 0, 1, p.r_p * np.sin(d), p.r_p * np.cos(d), 0])
    return np.array(cols, dtype=float).T


def kss(alpha4, s4, p, K_s=K_S_PAPER):
    """(3, 3) eq. (7) (K_s as printed unless given)."""
    c, s, kt = np.cos(alpha4), np.sin(alpha4), p.K_T4 / (p.L + s4)
    return np.array([[p.K_4 * c, K_s * c, -kt * s], [p.K_4 * s, K_s * s, kt * c],
                     [0, 0, p.K_T4]])  # fmt: skip


def a_s(alpha4, s4, p):
    """(3, 3) eq. (8)."""
    c, s, ls = np.cos(alpha4), np.sin(alpha4), p.L + s4
    return np.array([[c, c, -ls * s], [s, s, ls * c], [0, 0, 1]])


def skew(r):
    return np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])


def euler_rates(phi, theta, R):
    """(3, 3) E: rotation vector (world) = E (dphi, dtheta, dpsi) for R = Rz Ry(pi/2 - phi) Rz.

    dtheta turns about z, dpsi about the plate normal z_p, dphi (= -d(pi/2 - phi)) about
    -Rz(theta) y = (sin theta, -cos theta, 0).
    """
    return np.column_stack([[np.sin(theta), -np.cos(theta), 0.0], EZ, R[:, 2]])


def a_d_printed(alpha, angles, p):
    """(6, 6) eqs. (18, 19), Delta := pose coordinates, l := 1, Delta Delta_l := y_1 in C_x
    and z_1 in C_psi (the closed-form psi uses 2 z_1 - z_2 - z_3), C_z unused."""
    y, z = p.b * np.cos(alpha), p.b * np.sin(alpha) + p.h
    phi, theta, psi = angles
    rp, sf = p.r_p, np.sin(phi)
    c_x = -(rp / (2 * y[0])) * (1 - sf) * np.cos(psi - theta)
    c_y = -(rp / y[1]) * (sf * np.cos(phi) + np.cos(psi) * sf * np.sin(theta))
    c_phi, c_psi, c_theta = 1 / y[0], 2 * z[0] - z[1] - z[2], (3 * rp / 2) * (1 + sf)
    q = 2 / (3 * rp)
    return np.array([
        [c_x, 0, -1 / SQ3, 0, 1 / SQ3, 0],
        [1, 0, c_y, 0, 0, 0],
        [0, 1 / 3, 0, 1 / 3, 0, 1 / 3],
        [c_phi, -q, 0, q, 0, q],
        [0, 0, 0, -SQ3 / c_psi, 0, -SQ3 / c_psi],
        [1 / c_theta, 0, 1 / c_theta, SQ3 / c_psi, 1 / c_theta, -SQ3 / c_psi],
    ], dtype=float)  # fmt: skip


#: The backend's defaults (as published), retyped.
DEFAULTS = {
    "ks": "printed", "arm_rotation_axis": "-y_p", "serial_form": "pinv",
    "serial_frame": "printed", "lever_arm": False, "weights": True, "beta_gamma": "zero",
    "leg_block": "2x2", "a_d": "jacobian", "m_fn": "printed", "m_ft": "printed",
}  # fmt: skip


def reference(case, p=DEFAULT_PARAMS, load=None, **switches):
    """Every matrix of the as-published chain, by name, for the given switches."""
    o = {**DEFAULTS, **switches}
    alpha, alpha4, s4 = si(case)
    _, R, angles = plate(alpha, p)
    # Arm, eqs. (4) to (8): (x, z, angle) in the (x_p, z_p, rotation about -y_p) slots.
    K_s = K_S_PAPER if o["ks"] == "printed" else p.K_s
    Kss, As = kss(alpha4, s4, p, K_s), a_s(alpha4, s4, p)
    P = np.zeros((6, 3))
    P[0, 0], P[2, 1], P[4, 2] = 1.0, 1.0, -1.0 if o["arm_rotation_axis"] == "-y_p" else 1.0
    if o["serial_form"] == "pinv":  # pseudo-inverses for the singular As and Kss As^+
        C_plate = P @ np.linalg.pinv(Kss @ np.linalg.pinv(As)) @ P.T
    else:
        C_plate = P @ As @ np.diag([1 / p.K_4, 1 / K_s, 1 / p.K_T4]) @ As.T @ P.T
    if o["serial_frame"] == "printed":  # R_SP as a left factor of K_SER
        R_SP = np.eye(6)
        R_SP[:3, :3] = R
        C_SER = C_plate @ R_SP.T
    else:
        R6 = np.kron(np.eye(2), R)
        C_SER = R6 @ C_plate @ R6.T
    # Twist transport from H to M = H + HQ z_p + (L + s_4) w.
    w = np.cos(alpha4) * R[:, 0] + np.sin(alpha4) * R[:, 2]
    Tr = np.eye(6)
    Tr[:3, 3:] = -skew(p.HQ * R[:, 2] + (p.L + s4) * w)
    # Plate, eqs. (9) to (19).
    if o["m_ft"] == "printed":
        M_FT = m_ft(alpha4, s4, p, load if o["weights"] else None)
    else:
        M_FT = Tr.T
    G = leg_rows(R, p)
    M_FN = m_fn(p) if o["m_fn"] == "printed" else G.T
    beta_is_alpha = o["beta_gamma"] == "alpha"
    legs = np.array([leg_block(a, p, o["leg_block"], beta_is_alpha) for a in alpha])
    blocks = np.zeros((6, 6))
    for k in range(3):
        blocks[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = legs[k]
    E6 = np.eye(6)
    if o["a_d"] == "printed":
        A_d = a_d_printed(alpha, angles, p)
    else:
        A_d = np.linalg.inv(G)
    if o["a_d"] != "jacobian":  # plate rotations as (dphi, dtheta, dpsi)
        E6[3:, 3:] = euler_rates(angles[0], angles[1], R)
        if o["a_d"] == "jacobian_euler":
            A_d[3:] = np.linalg.solve(E6[3:, 3:], A_d[3:])
    C_PAR = A_d @ blocks @ np.linalg.inv(M_FN) @ M_FT
    C_PAR_M = Tr @ E6 @ C_PAR if o["lever_arm"] else C_PAR
    return {
        "R_PAR": R, "Kss": Kss, "As": As, "M_FT": M_FT, "M_FN": M_FN,
        "K_pkk": np.array([k_pkk(a, p, beta_is_alpha) for a in alpha]),
        "C_pkk": np.array([c_pkk(a, p) for a in alpha]), "leg_compliance": legs, "A_d": A_d,
        "C_SER": C_SER, "C_PAR": C_PAR, "C_PAR_M": C_PAR_M, "C": C_PAR_M + C_SER,
    }  # fmt: skip


# ------------------------------------------------------------ the rebuild checks itself
@pytest.mark.parametrize("case", sorted(POSES))
def test_reference_plate_puts_the_balls_on_the_legs(case):
    """The retyped direct kinematics: ball k at (y_k, z_k) of its leg plane, R a rotation."""
    p = DEFAULT_PARAMS
    alpha = si(case)[0]
    H, R, _ = plate(alpha, p)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
    for k in range(3):
        H_k = H + R @ (p.r_p * U[k])
        leg = H_k - p.r_e * U[k]
        np.testing.assert_allclose(
            [T[k] @ leg, leg[2]], [p.b * np.cos(alpha[k]), p.b * np.sin(alpha[k]) + p.h],
            atol=1e-15,
        )  # fmt: skip
        np.testing.assert_allclose([np.cross(EZ, U[k]) @ T[k], U[k] @ T[k]], [1.0, 0.0], atol=1e-15)


@pytest.mark.parametrize("alpha_deg", [30.0, 45.0, 60.0, 75.0, 90.0])
def test_reference_leg_jacobian_against_the_nonlinear_parallelogram(alpha_deg):
    p, a = DEFAULT_PARAMS, np.deg2rad(alpha_deg)
    np.testing.assert_allclose(
        leg_point(a, 0, 0, 0, p), [p.b * np.cos(a), p.b * np.sin(a) + p.h], atol=1e-15
    )
    fd = np.column_stack([(leg_point(a, *(STEP * e), p) - leg_point(a, *(-STEP * e), p))
                          / (2 * STEP) for e in np.eye(3)])  # fmt: skip
    assert_close(leg_jacobian(a, p), fd, FD_RTOL)


# ------------------------------------------------------------------- backend vs rebuild
@pytest.mark.parametrize("option", LEG_BLOCKS)
@pytest.mark.parametrize("case", sorted(POSES))
def test_full_C_equals_the_printed_equations(case, option):
    got = published_stiffness(*si(case), options=PublishedOptions(leg_block=option))
    ref = reference(case, leg_block=option)
    for name, value in ref.items():
        assert_close(getattr(got, name), value, err_msg=f"{case}, {option}: {name}")
    np.testing.assert_allclose(got.K @ ref["C"], np.eye(6), atol=1e-9)


def test_weight_terms_enter_C_as_printed():
    """Eq. (11) with masses and a load with zero moment components (Table 3, each option)."""
    p = DEFAULT_PARAMS.replace(**MASSES)
    for option in LEG_BLOCKS:
        got = published_stiffness(
            *si("Table 3"), p, PublishedOptions(leg_block=option), load=LOAD_F
        )
        ref = reference("Table 3", p, LOAD_F, leg_block=option)
        assert_close(got.M_FT, ref["M_FT"], err_msg=option)
        assert_close(got.C, ref["C"], err_msg=option)


@pytest.mark.parametrize("case", ["Table 1", "Table 2"])
def test_beta_equal_alpha_with_the_3x3_block_as_printed(case):
    """beta_k = alpha_k (the other reading of eq. 15); the full K_pkk is regular here."""
    o = PublishedOptions(beta_gamma="alpha", leg_block="3x3")
    got = published_stiffness(*si(case), options=o)
    ref = reference(case, leg_block="3x3", beta_gamma="alpha")
    for name in ("K_pkk", "leg_compliance", "C"):
        assert_close(getattr(got, name), ref[name], err_msg=name)


def test_the_leg_block_options_differ_at_table3():
    """The three readings are different machines: a test of one does not cover another."""
    C = {o: reference("Table 3", leg_block=o)["C"] for o in LEG_BLOCKS}
    for a, b in (("2x2", "3x3"), ("2x2", "consistent"), ("3x3", "consistent")):
        assert np.abs(C[a] - C[b]).max() > 1e-3 * np.abs(C[b]).max(), (a, b)


#: Every other switch, alone; (dphi, dtheta, dpsi) and the printed A_d need phi != 90 deg.
SWITCHES = [
    ({"ks": "params"}, POSES), ({"arm_rotation_axis": "+y_p"}, POSES),
    ({"serial_form": "series"}, POSES), ({"serial_frame": "world"}, POSES),
    ({"lever_arm": True}, POSES), ({"weights": False}, POSES),
    ({"m_fn": "consistent"}, POSES), ({"m_ft": "transport"}, POSES),
    ({"a_d": "jacobian_euler"}, ["Table 3"]), ({"a_d": "printed"}, ["Table 3"]),
    ({"a_d": "jacobian_euler", "lever_arm": True}, ["Table 3"]),
    ({"a_d": "printed", "lever_arm": True, "leg_block": "3x3"}, ["Table 3"]),
]  # fmt: skip
SWITCH_CASES = [(sw, case) for sw, cases in SWITCHES for case in sorted(cases)]


@pytest.mark.parametrize(("switches", "case"), SWITCH_CASES, ids=str)
def test_each_switch_equals_its_reading(switches, case):
    """With masses and the load (1, ..., 1), so that the weight terms act."""
    p = DEFAULT_PARAMS.replace(**MASSES)
    load = np.ones(6)
    got = published_stiffness(*si(case), p, PublishedOptions(**switches), load=load)
    ref = reference(case, p, load, **switches)
    for name, value in ref.items():
        assert_close(getattr(got, name), value, err_msg=f"{case}, {switches}: {name}")


def test_consistent_reading_equals_the_consistent_switches():
    o = {f: getattr(PublishedOptions.consistent(), f) for f in DEFAULTS}
    assert o == {**DEFAULTS, "ks": "params", "serial_form": "series", "serial_frame": "world",
                 "lever_arm": True, "weights": False, "leg_block": "consistent",
                 "m_fn": "consistent", "m_ft": "transport"}  # fmt: skip
    for case in POSES:
        got = published_stiffness(*si(case), options=PublishedOptions.consistent())
        assert_close(got.C, reference(case, **o)["C"], err_msg=case)


@pytest.mark.parametrize("case", sorted(POSES))
def test_reference_euler_rates_by_differences(case):
    """E of the rebuild: turning R by E (dphi, dtheta, dpsi) is moving the angles."""
    p = DEFAULT_PARAMS
    _, R, (phi, theta, psi) = plate(si(case)[0], p)
    E = euler_rates(phi, theta, R)
    for i, d in enumerate(np.eye(3) * STEP):
        Rp = rz(theta + d[1]) @ ry(np.pi / 2 - phi - d[0]) @ rz(psi + d[2])
        Rm = rz(theta - d[1]) @ ry(np.pi / 2 - phi + d[0]) @ rz(psi - d[2])
        W = (Rp - Rm) @ R.T / (2 * STEP)  # = [r]x
        np.testing.assert_allclose([W[2, 1], W[0, 2], W[1, 0]], E[:, i], atol=FD_RTOL)
