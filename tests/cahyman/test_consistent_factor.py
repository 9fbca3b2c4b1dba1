"""The consistent closed form's stiffnesses come from square-root factors, not from inv(C).

C = T C_H T^T + C_ser sums the springs' compliances; with springs many orders apart its
smallest eigenvalues, hence K = C^-1 and det K, kept only eps cond(K_s) of their value
(det K 1e-3 off at cond 5e12). K at M now comes from the SVD of the factor B (C = B B^T),
the plate stiffness K_H from the minors of the leg factors. References: the generic
Pinocchio backend (an independent model and algorithm), and the compliance summed spring
by spring and inverted in 50 digits (mpmath) from the kinematic maps of the closed form.
"""

from __future__ import annotations

import mpmath as mp
import numpy as np
import pytest
from helpers import assert_close_in_norm

from cahyman_pin.api import stiffness
from cahyman_pin.backends.consistent import (
    arm_jacobian,
    consistent_breakdown,
    consistent_compliance,
    leg_jacobian,
    plate_stiffness,
    twist_H_to_leg_displacements,
    twist_transport_H_to_M,
)
from cahyman_pin.geometry import extremity, plate_pose
from cahyman_pin.params import DEFAULT_PARAMS

EPS = np.finfo(float).eps
#: K from the SVD of a factor: its smallest singular value carries eps times the largest,
#: i.e. eps sqrt(cond(K_s)) relative, twice that in K_s ~ U diag(beta^-2) U^T, and the
#: singular vectors about as much; det K from six eigenvalues each as accurate. Measured:
#: up to 0.5 eps sqrt(cond) in K, 1.5 in det K (OpenBLAS's Haswell, SandyBridge and
#: Nehalem kernels); K from the formed C (the old code) erred by eps cond, 1e6 times this
#: bound at cond 5e12.
ULPS_SQRT_COND = 8
#: Default springs (cond(K_s) ~ 3e3): the two backends agree on K and det K to rounding.
DEFAULT_RTOL = 1e-12
#: K_H = G^T blockdiag(K_leg) G: K_leg from the minors of the leg factor (a few
#: roundings), then two products with cond(G) ~ 14: rounding times 1e3 at most.
PLATE_RTOL = 1e-13

POSES = {
    "table3": (np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.02),
    "skewed": (np.deg2rad([50.0, 70.0, 80.0]), np.deg2rad(20.0), 0.04),
}
P = DEFAULT_PARAMS
#: Springs 1e6 .. 1e12 apart (scaled condition numbers 2e2 .. 2e13): full rank for the
#: closed form's rank rule at both poses (K_T x 1e-12 is not at the skewed one: 2e14).
SPREADS = {
    "K_b, K_d x 1e-6": {"K_b": P.K_b * 1e-6, "K_d": P.K_d * 1e-6},
    "K_T4 x 1e8": {"K_T4": P.K_T4 * 1e8},
    "K_T4 x 1e-6": {"K_T4": P.K_T4 * 1e-6},
    "K_T4 x 1e-9": {"K_T4": P.K_T4 * 1e-9},
    "K_b, K_d x 1e9": {"K_b": P.K_b * 1e9, "K_d": P.K_d * 1e9},
    "K_s x 1e-12": {"K_s": P.K_s * 1e-12},
    "K_T x 1e-11": {"K_T": P.K_T * 1e-11},
    "K_T4 x 1e12": {"K_T4": P.K_T4 * 1e12},
}


def _scale(params) -> np.ndarray:
    """(6,) diag(L, L, L, 1, 1, 1): K scaled to uniform units (N m/rad)."""
    return np.r_[np.full(3, params.length), np.ones(3)]


def _tolerance(result) -> float:
    return ULPS_SQRT_COND * EPS * np.sqrt(result.indices.scaled_condition_number)


def _reference_compliance(alpha, alpha4, s4, params):
    """C at M (mpmath, 50 digits): sum over the 12 springs of c c^T / k, c the twist at M
    per unit deflection of the spring (leg Jacobian, G^-1, transport H -> M, arm
    Jacobian), with G^-1 and the sum in high precision."""
    mp.mp.dps = 50
    pose = plate_pose(alpha, params)
    _, M = extremity(pose, alpha4, s4, params)
    J = leg_jacobian(alpha, params)
    TA = mp.matrix(twist_transport_H_to_M(M - pose.H).tolist()) * mp.inverse(
        mp.matrix(twist_H_to_leg_displacements(pose.R, params).tolist())
    )
    A_s = arm_jacobian(pose.R, alpha4, s4, params)
    legs, arm = (params.K_T, params.K_b, params.K_d), (params.K_4, params.K_s, params.K_T4)
    springs = [(TA[:, 2 * k] * J[k, 0, j] + TA[:, 2 * k + 1] * J[k, 1, j], k_j)
               for k in range(3) for j, k_j in enumerate(legs)]  # fmt: skip
    springs += [(mp.matrix(A_s[:, j].tolist()), k_j) for j, k_j in enumerate(arm)]
    C = mp.zeros(6, 6)
    for c, k_j in springs:
        C += c * c.T / k_j
    return mp, C


@pytest.mark.parametrize("pose", sorted(POSES))
@pytest.mark.parametrize("spread", sorted(SPREADS))
def test_K_and_det_K_equal_the_high_precision_inverse(spread, pose):
    params = P.replace(**SPREADS[spread])
    r = stiffness(*POSES[pose], params=params, backend="consistent")
    mp, C = _reference_compliance(*POSES[pose], params)
    K_ref = np.array(mp.inverse(C).tolist(), dtype=float)
    tol = _tolerance(r)
    assert_close_in_norm(r.K, K_ref, tol, scale=_scale(params))
    np.testing.assert_allclose(r.det_K, float(1 / mp.det(C)), rtol=tol)


@pytest.mark.parametrize("pose", sorted(POSES))
@pytest.mark.parametrize("spread", sorted(SPREADS))
def test_K_and_det_K_equal_the_generic_backend(spread, pose):
    params = P.replace(**SPREADS[spread])
    c = stiffness(*POSES[pose], params=params, backend="consistent")
    g = stiffness(*POSES[pose], params=params, backend="generic")
    tol = _tolerance(c) + _tolerance(g)  # each backend within its own bound
    assert_close_in_norm(c.K, g.K, tol, scale=_scale(params))
    np.testing.assert_allclose(c.det_K, g.det_K, rtol=tol)
    assert c.indices.rank == g.indices.rank == 6
    np.testing.assert_allclose(
        c.indices.scaled_condition_number, g.indices.scaled_condition_number, rtol=tol
    )


def test_default_springs_agree_with_the_generic_backend_to_rounding():
    rng = np.random.default_rng(11)
    for _ in range(10):
        pose = (np.deg2rad(rng.uniform(30.0, 90.0, 3)), np.deg2rad(rng.uniform(0.0, 90.0)),
                rng.uniform(0.0, P.s4_max))  # fmt: skip
        c = stiffness(*pose, backend="consistent")
        g = stiffness(*pose, backend="generic")
        assert_close_in_norm(c.C, g.C, DEFAULT_RTOL, scale=1.0 / _scale(P))
        assert_close_in_norm(c.K, g.K, DEFAULT_RTOL, scale=_scale(P))
        np.testing.assert_allclose(c.det_K, g.det_K, rtol=DEFAULT_RTOL)


@pytest.mark.parametrize("spread", sorted(SPREADS))
def test_plate_stiffness_equals_the_high_precision_inverse(spread):
    """K_H = G^T blockdiag(C_leg^-1) G with each 2x2 C_leg inverted in 50 digits (the
    inverse of the formed C_leg erred by 1e-4 with K_b, K_d 1e12 times the default)."""
    mp.mp.dps = 50
    params = P.replace(**SPREADS[spread])
    alpha = POSES["table3"][0]
    J = leg_jacobian(alpha, params)
    K_leg = mp.zeros(6, 6)
    for k in range(3):
        C_leg = mp.zeros(2, 2)
        for j, k_j in enumerate((params.K_T, params.K_b, params.K_d)):
            col = mp.matrix(J[k, :, j].tolist())
            C_leg += col * col.T / k_j
        K_leg[2 * k : 2 * k + 2, 2 * k : 2 * k + 2] = mp.inverse(C_leg)
    G = mp.matrix(twist_H_to_leg_displacements(plate_pose(alpha, params).R, params).tolist())
    K_H = np.array((G.T * K_leg * G).tolist(), dtype=float)
    assert_close_in_norm(plate_stiffness(alpha, params), K_H, PLATE_RTOL)


def test_the_factor_is_batched_and_gives_C():
    rng = np.random.default_rng(5)
    alpha = np.deg2rad(rng.uniform(40.0, 80.0, (2, 3, 3)))
    alpha4, s4 = np.deg2rad(rng.uniform(0.0, 90.0, (2, 3))), rng.uniform(0.0, 0.05, (2, 3))
    b = consistent_breakdown(alpha, alpha4, s4)
    assert b.B.shape == (2, 3, 6, 12)
    np.testing.assert_array_equal(b.C, consistent_compliance(alpha, alpha4, s4))
    C_sum = b.T @ b.C_H @ b.T.swapaxes(-1, -2) + b.C_ser  # the closed form's sum
    d = 1.0 / _scale(P)
    for i in np.ndindex(2, 3):
        assert_close_in_norm(b.B[i] @ b.B[i].T, C_sum[i], DEFAULT_RTOL, scale=d)
        one = consistent_breakdown(alpha[i], alpha4[i], s4[i])
        np.testing.assert_allclose(one.B, b.B[i], rtol=0, atol=DEFAULT_RTOL * np.abs(one.B).max())
