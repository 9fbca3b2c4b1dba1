"""Tests of the consistent closed-form compliance against an independent nonlinear model.

The nonlinear model below is written from the mechanism description only: it solves the
deformed parallelogram of each leg, then the plate pose that puts the ball centres at the
legs' in-plane positions, then the arm. Its finite-difference Jacobian with respect to the
spring coordinates gives the compliance J diag(1/k) J^T with no shared code.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import LEG_T as T
from helpers import LEG_U as U
from helpers import assert_close_in_norm, rot_y
from scipy.optimize import brentq
from scipy.spatial.transform import Rotation

from cahyman_pin import geometry
from cahyman_pin.backends.consistent import (
    arm_compliance,
    consistent_breakdown,
    consistent_compliance,
    leg_compliance,
    leg_jacobian,
    plate_stiffness,
    plate_twist_from_leg_displacements,
    twist_H_to_leg_displacements,
)
from cahyman_pin.params import DEFAULT_PARAMS, CaHyManParams
from closedloop.exceptions import InvalidInputError, SingularConfigurationError

TABLE_POSES = {
    "table1": (np.deg2rad([90.0, 90.0, 90.0]), np.deg2rad(90.0), 0.050),
    "table2": (np.deg2rad([30.0, 30.0, 30.0]), np.deg2rad(30.0), 0.0),
    "table3": (np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.0),
}

# Central differences with these steps have truncation error ~ step^2 (1e-12 relative) and
# round-off ~ 1e-16 / step (1e-9 relative for lengths of 0.1 m); the nonlinear solves are
# converged to ~1e-15 m, i.e. ~1e-8 relative after dividing by 2 * step.
STEP_ANGLE = 1e-6  # [rad]
STEP_LENGTH = 1e-7  # [m]
# Finite-difference Jacobians are good to ~1e-8 relative (see above); 1e-6 leaves margin.
FD_RTOL = 1e-6
# Entries that vanish by symmetry are compared against the largest entry, at FD accuracy.
FD_ATOL_REL = 1e-7
# Pure floating-point identities (products of a few 6x6 matrices).
EXACT_RTOL = 1e-12
# The stiffening limit: the neglected axial terms are 1e-6 of their nominal share (at most
# ~30 % of an entry), plus the FD error of the reference; 1e-5 bounds both.
LIMIT_RTOL = 1e-5
# Residual of the nonlinear plate solve [m]: round-off level for coordinates of ~0.1 m.
NEWTON_TOL = 1e-16
# Normalising length for mixing translations and rotations in one comparison [m].
ELL = 0.1


def ball_centres(H: np.ndarray, R: np.ndarray, p) -> np.ndarray:
    """(3, 3) ball centres H + R r_p u_k [m], one leg per row."""
    return H + p.r_p * U @ R.T


def leg_plane_points(Hk: np.ndarray, p) -> np.ndarray:
    """(6,) (y_1, z_1, ..., z_3): ball k in the plane (t_k, z) of leg k, from O_k."""
    leg = Hk - p.r_e * U
    return np.ravel(np.column_stack([np.einsum("ki,ki->k", T, leg), leg[:, 2]]))


def _e(angle: float) -> np.ndarray:
    return np.array([np.cos(angle), np.sin(angle)])


def nonlinear_leg_point(alpha: float, d_alpha: float, d_b: float, d_d: float, p) -> np.ndarray:
    """In-plane (y, z) of H_k for a deformed parallelogram, solved without linearisation."""
    A, D = np.array([-p.a / 2, 0.0]), np.array([p.a / 2, 0.0])
    B = A + (p.b + d_b) * _e(alpha + d_alpha)

    def gap(beta: float) -> float:
        E = D + (p.b + d_d) * _e(beta)
        return float(np.dot(E - B, E - B) - p.a**2)

    beta = brentq(gap, alpha - 0.3, alpha + 0.3, xtol=1e-15, rtol=4 * np.finfo(float).eps)
    E = D + (p.b + d_d) * _e(beta)
    chord = E - B
    gamma = np.arctan2(chord[1], chord[0])  # coupler angle, 0 when undeformed
    return 0.5 * (B + E) + p.h * np.array([-np.sin(gamma), np.cos(gamma)])


def plate_from_leg_points(yz: np.ndarray, guess: geometry.PlatePose, p):
    """Plate centre and orientation putting ball k at in-plane (y_k, z_k).

    Newton iterations on (H, rotation vector about the guess) with a finite-difference
    Jacobian, until the residual is at round-off level. The guess (the closed-form pose)
    only starts the iterations.
    """

    def residual(x):
        R = Rotation.from_rotvec(x[3:]).as_matrix() @ guess.R
        return leg_plane_points(ball_centres(x[:3], R, p), p) - np.ravel(yz)

    x = np.concatenate([guess.H, np.zeros(3)])
    for _ in range(30):
        r = residual(x)
        if np.abs(r).max() < NEWTON_TOL:
            break
        J = np.column_stack([(residual(x + 1e-7 * e) - r) / 1e-7 for e in np.eye(6)])
        x = x - np.linalg.solve(J, r)
    assert np.abs(residual(x)).max() < NEWTON_TOL
    return x[:3], Rotation.from_rotvec(x[3:]).as_matrix() @ guess.R


def nonlinear_extremity(q: np.ndarray, alpha, alpha4, s4, p, guess):
    """Point M and arm orientation for spring deflections q (12,).

    q = (d alpha_1..3, d b_1..3, d d_1..3, d alpha_4, d s_4 (K_s), d L (K_4)).
    """
    yz = np.array([nonlinear_leg_point(alpha[k], q[k], q[3 + k], q[6 + k], p) for k in range(3)])
    H, R = plate_from_leg_points(yz, guess, p)
    a4 = alpha4 + q[9]
    w = np.cos(a4) * R[:, 0] + np.sin(a4) * R[:, 2]
    M = H + p.HQ * R[:, 2] + (p.L + s4 + q[10] + q[11]) * w
    return M, R @ rot_y(-a4)


def nonlinear_jacobian(alpha, alpha4, s4, p) -> np.ndarray:
    """(6, 12) finite-difference twist of the arm at M per spring coordinate."""
    guess = geometry.plate_pose(alpha, p)
    steps = np.array([STEP_ANGLE] * 3 + [STEP_LENGTH] * 6 + [STEP_ANGLE, STEP_LENGTH, STEP_LENGTH])
    J = np.zeros((6, 12))
    for i, step in enumerate(steps):
        dq = np.zeros(12)
        dq[i] = step
        Mp, Rp = nonlinear_extremity(dq, alpha, alpha4, s4, p, guess)
        Mm, Rm = nonlinear_extremity(-dq, alpha, alpha4, s4, p, guess)
        J[:3, i] = (Mp - Mm) / (2 * step)
        J[3:, i] = Rotation.from_matrix(Rp @ Rm.T).as_rotvec() / (2 * step)
    return J


def spring_compliances(p) -> np.ndarray:
    k = [p.K_T] * 3 + [p.K_b] * 3 + [p.K_d] * 3 + [p.K_T4, p.K_s, p.K_4]
    return 1.0 / np.array(k)


def scaled(C: np.ndarray) -> np.ndarray:
    """Compliance for twist (d/ELL, r) and wrench (f, n/ELL): every entry in 1/N."""
    S_left = np.diag([1 / ELL] * 3 + [1.0] * 3)
    S_right = np.diag([1.0] * 3 + [ELL] * 3)
    return S_left @ C @ S_right


def assert_compliance_close(actual, expected, rtol, atol_rel):
    a, e = scaled(actual), scaled(expected)
    np.testing.assert_allclose(a, e, rtol=rtol, atol=atol_rel * np.max(np.abs(e)))


def random_poses(rng: np.random.Generator, n: int):
    alpha = rng.uniform(np.deg2rad(25.0), np.deg2rad(120.0), (n, 3))
    return alpha, rng.uniform(-np.pi / 2, np.pi, n), rng.uniform(0.0, 0.05, n)


@pytest.mark.parametrize("alpha", [np.deg2rad(30.0), np.deg2rad(63.0), np.deg2rad(90.0), 2.2])
def test_leg_jacobian_matches_nonlinear_parallelogram(alpha):
    p = DEFAULT_PARAMS
    steps = [STEP_ANGLE, STEP_LENGTH, STEP_LENGTH]
    J_fd = np.zeros((2, 3))
    for i, step in enumerate(steps):
        dq = np.zeros(3)
        dq[i] = step
        J_fd[:, i] = (
            nonlinear_leg_point(alpha, *dq, p) - nonlinear_leg_point(alpha, *(-dq), p)
        ) / (2 * step)
    J = leg_jacobian(np.full(3, alpha), p)
    for k in range(3):
        np.testing.assert_allclose(J[k], J_fd, rtol=FD_RTOL, atol=FD_ATOL_REL * np.abs(J_fd).max())
    C_fd = J_fd @ np.diag([1 / p.K_T, 1 / p.K_b, 1 / p.K_d]) @ J_fd.T
    np.testing.assert_allclose(
        leg_compliance(np.full(3, alpha), p)[1],
        C_fd,
        rtol=FD_RTOL,
        atol=FD_ATOL_REL * np.abs(C_fd).max(),
    )


def test_A_d_matches_finite_differences_of_plate_pose():
    p = DEFAULT_PARAMS
    rng = np.random.default_rng(11)
    for alpha in [TABLE_POSES["table3"][0], TABLE_POSES["table1"][0], *random_poses(rng, 3)[0]]:
        A_d = plate_twist_from_leg_displacements(alpha, p)
        guess = geometry.plate_pose(alpha, p)
        for k in range(3):
            da = np.zeros(3)
            da[k] = STEP_ANGLE
            # the plates that put the balls at the legs' points (b cos, b sin + h)
            (Hp, Rp), (Hm, Rm) = (
                plate_from_leg_points(
                    np.column_stack([p.b * np.cos(a), p.b * np.sin(a) + p.h]), guess, p
                )
                for a in (alpha + da, alpha - da)
            )
            twist = np.concatenate([Hp - Hm, Rotation.from_matrix(Rp @ Rm.T).as_rotvec()]) / (
                2 * STEP_ANGLE
            )
            dv = np.zeros(6)  # (dy_k, dz_k) per unit d alpha_k: b (-sin, cos)
            dv[2 * k : 2 * k + 2] = p.b * np.array([-np.sin(alpha[k]), np.cos(alpha[k])])
            np.testing.assert_allclose(A_d @ dv, twist, rtol=FD_RTOL, atol=FD_ATOL_REL)


def test_G_matches_ball_centres_of_a_moved_plate():
    """All six columns of A_d: it inverts the finite-difference map twist -> leg points."""
    p = DEFAULT_PARAMS
    alpha = TABLE_POSES["table3"][0]
    pose = geometry.plate_pose(alpha, p)
    G_fd = np.zeros((6, 6))
    for i in range(6):
        xi = np.zeros(6)
        xi[i] = STEP_ANGLE
        moved = []
        for sign in (1.0, -1.0):
            R = Rotation.from_rotvec(sign * xi[3:]).as_matrix() @ pose.R
            moved.append(leg_plane_points(ball_centres(pose.H + sign * xi[:3], R, p), p))
        G_fd[:, i] = (moved[0] - moved[1]) / (2 * STEP_ANGLE)
    np.testing.assert_allclose(twist_H_to_leg_displacements(pose.R, p), G_fd, atol=FD_ATOL_REL)
    np.testing.assert_allclose(
        plate_twist_from_leg_displacements(alpha, p) @ G_fd, np.eye(6), atol=FD_RTOL
    )


@pytest.mark.parametrize("case", sorted(TABLE_POSES))
def test_compliance_matches_nonlinear_model(case):
    p = DEFAULT_PARAMS
    alpha, alpha4, s4 = TABLE_POSES[case]
    J = nonlinear_jacobian(alpha, alpha4, s4, p)
    C_ref = J @ np.diag(spring_compliances(p)) @ J.T
    assert_compliance_close(
        consistent_compliance(alpha, alpha4, s4, p), C_ref, FD_RTOL, FD_ATOL_REL
    )


def test_compliance_matches_nonlinear_model_at_random_pose_and_params():
    rng = np.random.default_rng(5)
    p = CaHyManParams(
        a=0.23, b=0.07, h=0.06, r_e=0.11, r_p=0.09, HQ=0.04, L=0.17,
        K_T=3e3, K_b=1e6, K_d=4e6, K_T4=500.0, K_s=2e5, K_4=3e6,
    )  # fmt: skip
    alpha, alpha4, s4 = (x[0] for x in random_poses(rng, 1))
    J = nonlinear_jacobian(alpha, alpha4, s4, p)
    C_ref = J @ np.diag(spring_compliances(p)) @ J.T
    assert_compliance_close(
        consistent_compliance(alpha, alpha4, s4, p), C_ref, FD_RTOL, FD_ATOL_REL
    )


@pytest.mark.parametrize("case", sorted(TABLE_POSES))
def test_compliance_is_symmetric_positive_definite(case):
    C = consistent_compliance(*TABLE_POSES[case], DEFAULT_PARAMS)
    np.testing.assert_array_equal(C, C.T)
    assert np.linalg.eigvalsh(C).min() > 0.0


def test_pieces_compose():
    b = consistent_breakdown(*TABLE_POSES["table3"], DEFAULT_PARAMS)
    C = b.T @ np.linalg.inv(b.K_H) @ b.T.T + b.C_ser
    assert_close_in_norm(b.C, C, EXACT_RTOL)
    np.testing.assert_allclose(b.K_H, plate_stiffness(TABLE_POSES["table3"][0]), rtol=EXACT_RTOL)
    assert np.linalg.matrix_rank(b.C_ser, tol=1e-12 * np.abs(b.C_ser).max()) == 2
    with pytest.raises(ValueError):
        b.C[0, 0] = 1.0  # read-only


def test_arm_compliance_along_the_arm_is_the_series_springs():
    p = DEFAULT_PARAMS
    alpha, alpha4, s4 = TABLE_POSES["table3"]
    R = geometry.plate_pose(alpha, p).R
    w = np.cos(alpha4) * R[:, 0] + np.sin(alpha4) * R[:, 2]  # x_p towards z_p
    C = arm_compliance(R, alpha4, s4, p)
    expected = 1 / p.K_4 + 1 / p.K_s
    np.testing.assert_allclose(w @ C[:3, :3] @ w, expected, rtol=EXACT_RTOL)


def test_batch_equals_per_pose():
    rng = np.random.default_rng(3)
    alpha, alpha4, s4 = random_poses(rng, 12)
    C_batch = consistent_compliance(alpha.reshape(3, 4, 3), alpha4.reshape(3, 4), s4.reshape(3, 4))
    assert C_batch.shape == (3, 4, 6, 6)
    for i in range(12):
        C_one = consistent_compliance(alpha[i], alpha4[i], s4[i])
        np.testing.assert_allclose(C_batch.reshape(12, 6, 6)[i], C_one, rtol=EXACT_RTOL)
    # A scalar arm pose broadcasts over a batch of leg inputs.
    C_b = consistent_compliance(alpha, 0.3, 0.01)
    np.testing.assert_allclose(C_b[5], consistent_compliance(alpha[5], 0.3, 0.01), rtol=EXACT_RTOL)


def test_large_batch_runs():
    rng = np.random.default_rng(8)
    alpha, alpha4, s4 = random_poses(rng, 10_000)
    C = consistent_compliance(alpha, alpha4, s4)
    assert C.shape == (10_000, 6, 6)
    assert np.all(np.linalg.eigvalsh(C)[:, 0] > 0.0)


@pytest.mark.parametrize("case", sorted(TABLE_POSES))
def test_stiffening_limit_gives_motors_only_compliance(case):
    p = DEFAULT_PARAMS
    alpha, alpha4, s4 = TABLE_POSES[case]
    stiff = p.replace(K_b=p.K_b * 1e6, K_d=p.K_d * 1e6, K_4=p.K_4 * 1e6, K_s=p.K_s * 1e6)
    J = nonlinear_jacobian(alpha, alpha4, s4, p)[:, [0, 1, 2, 9]]  # the four motors
    C_motors = J @ np.diag([1 / p.K_T] * 3 + [1 / p.K_T4]) @ J.T
    C = consistent_compliance(alpha, alpha4, s4, stiff)
    assert_compliance_close(C, C_motors, LIMIT_RTOL, LIMIT_RTOL)
    # and the nominal machine is measurably softer than the limit
    C_nominal = consistent_compliance(alpha, alpha4, s4, p)
    assert np.trace(scaled(C_nominal - C_motors)) > 1e-3 * np.trace(scaled(C_motors))


@pytest.mark.parametrize(
    ("args", "name"),
    [
        ((np.array([np.nan, 1.0, 1.0]), 0.5, 0.0), "alpha"),
        ((np.ones(3), np.nan, 0.0), "alpha4"),
        ((np.ones(3), 0.5, np.inf), "s4"),
        ((np.ones(2), 0.5, 0.0), "alpha"),
        ((np.ones(3), 0.5, -1.0), "s4"),
        ((np.ones((4, 3)), np.ones(3), 0.0), "alpha4"),
    ],
)
def test_bad_input_raises(args, name):
    with pytest.raises(InvalidInputError, match=name):
        consistent_compliance(*args, DEFAULT_PARAMS)


def test_bad_params_raise():
    with pytest.raises(InvalidInputError, match="params"):
        consistent_compliance(np.ones(3), 0.5, 0.0, {"a": 0.2})


def test_singular_parallelogram_raises():
    with pytest.raises(SingularConfigurationError, match=r"alpha=\[0\.0, 57\.29.*\] deg: a "):
        leg_compliance(np.array([0.0, 1.0, 1.0]))
    batch = np.array([[0.5, 1.0, 1.0], [0.0, 1.0, 1.0]])  # the singular pose named
    with pytest.raises(SingularConfigurationError, match=r"alpha=\[0\.0, 57\.29.*\] deg: a "):
        leg_compliance(batch)


@pytest.mark.parametrize("x", [3.1622776601683795e-09, *np.logspace(-9.0, -8.0, 9)])
def test_a_leg_within_rounding_of_singular_is_a_typed_error(x):
    """A crank at pi - x rad (x of 1e-9 .. 1e-8, sin alpha just above SIN_ALPHA_MIN): its
    leg compliance may be exactly singular in floating point (x = 3.16e-9 here), where
    the plate stiffness leaked numpy's LinAlgError; a typed error either way."""
    alpha = np.array([np.pi - x, np.deg2rad(60.0), np.deg2rad(75.0)])
    for call in (lambda: plate_stiffness(alpha), lambda: consistent_breakdown(alpha, 0.8, 0.01)):
        try:
            K = call()
        except SingularConfigurationError as e:
            assert "alpha" in str(e)
        else:
            K = getattr(K, "K_H", K)
            assert np.all(np.isfinite(K))
