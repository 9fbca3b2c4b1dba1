"""Stiffness indices at the edges: near-singular poses against references built from the
kinematic factor (not from the library's C or K), non-symmetric and indefinite
compliances, stiffnesses symmetric only to rounding; central differences without columns.
"""

from __future__ import annotations

import types

import mechanisms as mech
import numpy as np
import pinocchio as pin
import pytest
from test_indices import DET_RTOL_PER_SQRT_COND

import closedloop as cl
from closedloop.analysis.batch_indices import batch_indices
from closedloop.analysis.indices import StiffnessIndices
from closedloop.analysis.screws import DELTA
from closedloop.common.derivatives import central_differences
from closedloop.elastostatics.compliance import compliance
from closedloop.exceptions import InvalidInputError
from closedloop.io.loader import load_urdf, robot_data_dir

UR5_JOINTS = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")
#: Two routes to the same K (an LU solve of the scaled C, numpy's inv of C) and their
#: 2-norm condition numbers or determinants: each to about eps cond(K) = 1e-14 here.
ROUNDING_RTOL = 1e-12


def ur5_near_singular(k_arm, k_wrist, elbow):
    """(result, J (6, 6) world-aligned Jacobian of tool0, k (6,)) of the UR5 with springs
    k_arm on the first three joints and k_wrist on the wrist, elbow angle ``elbow``."""
    k = np.array([k_arm] * 3 + [k_wrist] * 3)
    clm = load_urdf(
        robot_data_dir() / "ur_description/urdf/ur5_robot.urdf",
        springs={f"{n}_joint": v for n, v in zip(UR5_JOINTS, k, strict=True)},
    )
    q = np.array([0.3, -1.2, elbow, -0.6, 1.1, 0.2])
    result = compliance(clm, q, "tool0", axes="world")
    J = pin.computeFrameJacobian(
        clm.model, clm.model.createData(), q, clm.model.getFrameId("tool0"), pin.LOCAL_WORLD_ALIGNED
    )
    return result, J, k


NEAR_SINGULAR = [(1e4, 1e4, 1e-5), (1e9, 1e2, 1e-5)]  # scaled cond 1.2e12 and 3.2e18


@pytest.mark.parametrize(("k_arm", "k_wrist", "elbow"), NEAR_SINGULAR)
def test_homogenised_indices_near_singular_poses(k_arm, k_wrist, elbow):
    """K_h = T^-1 K T^-1 at L = the result's length is K_s / L^2: its eigenvalues are
    1 / sigma^2 of the factor T J diag(k)^-1/2 of C_h, and its condition number is the
    scaled one. The eigenvalues of the formed K_h lost the smallest (7e-6 relative at
    cond 1.2e12; at 3.2e18 the condition number came out negative, -1.1 times the true);
    now each to about eps sqrt(cond), as the SI eigenvalues."""
    result, J, k = ur5_near_singular(k_arm, k_wrist, elbow)
    L = result.length
    s = StiffnessIndices.from_result(result, length=L)
    T = np.r_[np.ones(3), np.full(3, L)]
    sigma = np.linalg.svd(T[:, None] * J / np.sqrt(k), compute_uv=False)
    rtol = DET_RTOL_PER_SQRT_COND * sigma[0] / sigma[-1]
    np.testing.assert_allclose(s.homogenised_eigenvalues(), np.sort(1 / sigma**2), rtol=rtol)
    cond = s.homogenised_condition_number()
    np.testing.assert_allclose(cond, (sigma[0] / sigma[-1]) ** 2, rtol=2 * rtol)
    np.testing.assert_allclose(cond, s.scaled_condition_number, rtol=2 * rtol)


def reference_eigenscrews(J, k):
    """(lambda (6,), pitch (6,)) of K = J^-T diag(k) J^-1 from the kinematic factors:
    ``K x = lambda Delta x`` with x = J y gives diag(k) y = lambda J^T Delta J y, the
    eigenvalues 1 / lambda of B^T Delta B (B = J diag(k)^-1/2, twist B z; resolves the
    soft screws) and lambda of F^T Delta F (F = J^-T diag(k)^1/2, twist Delta F z; the
    stiff ones, J^-1 to eps cond(J) <= 1e-10 here); each taken on its side of the
    geometric mean of the extremes (no lambda lies near it in these cases)."""
    B, F = J / np.sqrt(k), np.linalg.inv(J).T * np.sqrt(k)
    nu, Z_C = np.linalg.eigh(B.T @ DELTA @ B)
    lam_K, Z_K = np.linalg.eigh(F.T @ DELTA @ F)
    mean = np.sqrt(np.abs(lam_K).max() / np.abs(nu).max())
    soft, stiff = np.abs(1 / nu) < mean, np.abs(lam_K) >= mean
    lam = np.r_[1 / nu[soft], lam_K[stiff]]
    X = np.c_[B @ Z_C[:, soft], DELTA @ F @ Z_K[:, stiff]]
    order = np.argsort(lam)
    X = X[:, order]
    pitch = np.einsum("ij,ij->j", X[3:], X[:3]) / np.einsum("ij,ij->j", X[3:], X[3:])
    return lam[order], pitch


@pytest.mark.parametrize(("k_arm", "k_wrist", "elbow"), NEAR_SINGULAR)
def test_eigenscrews_near_singular_poses(k_arm, k_wrist, elbow):
    """Eigenvalues and pitches of the eigenscrews against the kinematic reference, to
    about eps sqrt(cond): a Cholesky factorisation of K lost the soft ones (5e-6 relative
    at cond 1.2e12) and failed at 3.2e18 (numpy's LinAlgError, K positive definite)."""
    result, J, k = ur5_near_singular(k_arm, k_wrist, elbow)
    screws = StiffnessIndices.from_result(result).eigenscrews
    lam, pitch = reference_eigenscrews(J, k)
    rtol = DET_RTOL_PER_SQRT_COND * np.sqrt(result.condition_number)
    np.testing.assert_allclose([x.eigenvalue for x in screws], lam, rtol=rtol)
    np.testing.assert_allclose([x.pitch for x in screws], pitch, rtol=rtol)
    # the weights, k = lambda / (2 h) > 0 [N/m], from the same numbers
    np.testing.assert_array_equal([x.spring for x in screws],
                                  [x.eigenvalue / (2 * x.pitch) for x in screws])  # fmt: skip


SYMMETRIC_ONLY = (
    "eigenvalues", "min_translational_stiffness", "max_translational_stiffness",
    "min_rotational_stiffness", "max_rotational_stiffness", "eigenscrews",
)  # fmt: skip


def test_nonsymmetric_preloaded_compliance(ur5):
    """A preload moment makes C non-symmetric: the eigenvalues, principal stiffnesses and
    eigenscrews of a symmetric K were computed from C's or K's lower triangle, silently
    (smallest eigenvalue 2776.46 for 2775.58, say); now a typed error names the
    asymmetry, as the maps leave them NaN. The condition number is the 2-norm one of the
    maps (the eigenvalue ratio of the lower triangle was 77.198 for 77.223), the
    determinant det(C^-1)."""
    clm, q0 = ur5
    pre = compliance(clm, q0, "tool0", preload=[100.0, 0, -50.0, 20.0, 30.0, -10.0])
    s = StiffnessIndices.from_result(pre)
    assert not s.is_symmetric
    for name in SYMMETRIC_ONLY:
        with pytest.raises(InvalidInputError, match=r"symmetric compliance only.*asymmetry \d"):
            getattr(s, name)
    batch = batch_indices(pre.C[None], np.array([6]), pre.length, symmetric=np.array([False]))
    np.testing.assert_allclose(s.condition_number, np.linalg.cond(np.linalg.inv(pre.C)),
                               rtol=ROUNDING_RTOL)  # fmt: skip
    np.testing.assert_allclose(s.condition_number, batch["condition_number_si"][0],
                               rtol=ROUNDING_RTOL)  # fmt: skip
    np.testing.assert_allclose(s.determinant, batch["det_K"][0], rtol=ROUNDING_RTOL)
    out = s.to_dict()
    assert set(SYMMETRIC_ONLY) <= set(out["missing"]) and out["eigenvalues"] is None


def test_indefinite_stiffness_of_an_unstable_equilibrium():
    """A symmetric K with a negative eigenvalue (past a limit load): the eigenscrews do
    not exist (a typed error, not numpy's LinAlgError of a failed Cholesky) and both
    condition numbers are max |lambda| / min |lambda| (the homogenised one was
    lambda_max / lambda_min = -3)."""
    Q = np.linalg.qr(np.random.default_rng(0).normal(size=(6, 6)))[0]
    lam = np.array([-2.0, 1.0, 3.0, 4.0, 5.0, 6.0])
    K, C = (Q * lam) @ Q.T, (Q / lam) @ Q.T
    result = types.SimpleNamespace(C=0.5 * (C + C.T), rank=6, rigid_directions=np.zeros((6, 0)),
                                   condition_number=6.0, length=1.0,
                                   stiffness_matrix=0.5 * (K + K.T), is_full_rank=True)  # fmt: skip
    s = StiffnessIndices.from_result(result, length=1.0)
    with pytest.raises(InvalidInputError, match=r"positive definite K; .* from -2"):
        _ = s.eigenscrews
    # eigenvalues of a formed matrix of condition 6: a few eps
    np.testing.assert_allclose(s.eigenvalues, np.sort(lam), rtol=1e-14)
    np.testing.assert_allclose(s.condition_number, 6.0, rtol=1e-14)
    np.testing.assert_allclose(s.homogenised_condition_number(), 6.0, rtol=1e-14)


def test_stiffness_symmetric_to_rounding_is_taken():
    """K = inv(inv(K0)) of a symmetric K0 with force x uncoupled from rotation z: the
    entries (0, 5) and (5, 0), zero in K0, come back as -6e-11 and -1e-13, and an
    entry-wise relative test refused K as not symmetric. Symmetry is judged on the
    scaled K_s, relative to its largest entry (the rule of the compliances); a real
    asymmetry is still refused, its size named."""
    rng = np.random.default_rng(0)
    D = np.sqrt(np.r_[np.full(3, 1e5), np.full(3, 1e2)])
    A = rng.normal(size=(6, 6))
    K0 = D[:, None] * (A @ A.T + 6.0 * np.eye(6)) * D  # scaled eigenvalues >= 6
    K0[0, 5] = K0[5, 0] = 0.0
    K = np.linalg.inv(np.linalg.inv(K0))
    assert K[0, 5] != K[5, 0]
    # two inversions at cond(K0) ~ 1e5: about eps cond of the largest entry
    np.testing.assert_allclose(StiffnessIndices.from_stiffness(K).K, K0, rtol=0,
                               atol=1e-10 * np.abs(K0).max())  # fmt: skip
    K[0, 1] *= 1.0 + 1e-6
    with pytest.raises(InvalidInputError, match=r"not symmetric: scaled asymmetry .* = \d"):
        StiffnessIndices.from_stiffness(K)


def test_central_differences_without_columns():
    """No column to differentiate along (a model without degrees of freedom, or an empty
    list): an (n, nv) zero derivative, not None."""
    empty = pin.Model()
    np.testing.assert_array_equal(
        central_differences(empty, pin.neutral(empty), lambda q: np.ones(3)), np.zeros((3, 0))
    )
    one = pin.Model()
    one.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "rz")
    got = central_differences(one, pin.neutral(one), lambda q: np.r_[np.sin(q), q], columns=[])
    np.testing.assert_array_equal(got, np.zeros((2, 1)))


def test_a_block_of_rounding_beside_a_compliant_one_is_rigid():
    """The Delta's platform cannot turn (rank 3): its rotational compliance block is
    rounding (1e-32 beside 1e-4), whose principal stiffnesses read 6e31 and 1e33 N m/rad
    in the single query and in the maps, judged on the block alone. Rigid now, in both;
    the translational ones unchanged and equal."""
    m = mech.delta()
    res = cl.compliance(m.clm, m.q, m.frame)
    assert res.rank == 3
    ind = cl.StiffnessIndices.from_result(res)
    for name in ("min_rotational_stiffness", "max_rotational_stiffness"):
        with pytest.raises(cl.RigidDirectionsError, match="rotational stiffness does not exist"):
            getattr(ind, name)
    batch = batch_indices(res.C[None], np.array([res.rank]), res.length)
    assert np.isnan(batch["min_rotational"][0]) and np.isnan(batch["max_rotational"][0])
    np.testing.assert_allclose(
        [batch["min_translational"][0], batch["max_translational"][0]],
        [ind.min_translational_stiffness.value, ind.max_translational_stiffness.value],
        rtol=1e-12,  # two eigen-solvers of the same 3x3 block: rounding
    )
