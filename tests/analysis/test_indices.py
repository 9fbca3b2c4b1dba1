"""Stiffness indices against closed forms, definitions and invariances."""

from __future__ import annotations

import functools
import itertools
import json

import numpy as np
import pinocchio as pin
import pytest
from helpers import INDEX_GETTERS, REPO, assert_close_in_norm
from scipy.spatial.transform import Rotation

from closedloop.analysis.batch_indices import BATCH_INDICES, batch_indices
from closedloop.analysis.indices import StiffnessIndices
from closedloop.elastostatics.compliance import compliance
from closedloop.exceptions import InvalidInputError, RigidDirectionsError
from closedloop.io.loader import load_urdf, robot_data_dir
from closedloop.kinematics.assembly import assemble

# Closed forms and definitions evaluated on matrices of condition ~1e5 (mixed units):
# inverting them costs ~cond * eps ~ 1e-11 relative; 1e-9 leaves a margin.
INDEX_RTOL = 1e-9
# Eigenvectors of a well separated spectrum (gaps > 10 % here): error ~ eps * cond / gap.
DIRECTION_ATOL = 1e-9
# Unit vectors or lines that coincide, distance [m] or angle [rad]: roundoff only.
GEOMETRY_ATOL = 1e-9

K_T, K_R = np.array([1e5, 2e5, 5e5]), np.array([50.0, 80.0, 300.0])  # [N/m], [N m/rad]
T, R = slice(0, 3), slice(3, 6)


#: The shared scaled comparison at this module's tolerance: entries agree to INDEX_RTOL,
#: near-zero ones to INDEX_RTOL times the largest entry.
close = functools.partial(assert_close_in_norm, rtol=INDEX_RTOL)


def same_axis(u, v):
    """Unit vectors equal up to sign."""
    np.testing.assert_allclose(np.outer(u, u), np.outer(v, v), atol=DIRECTION_ATOL)


def decoupled(rng):
    """Stiffness at the origin: principal springs K_T along, K_R about, the columns of Q."""
    Q = Rotation.random(random_state=rng).as_matrix()
    K = np.zeros((6, 6))
    K[T, T], K[R, R] = Q @ np.diag(K_T) @ Q.T, Q @ np.diag(K_R) @ Q.T
    return K, Q


def random_stiffness(rng):
    """Coupled SPD stiffness with realistic magnitudes (1e5 N/m, 1e2 N m/rad)."""
    A = rng.normal(size=(6, 6))
    D = np.sqrt(np.r_[np.full(3, 1e5), np.full(3, 1e2)])
    return D[:, None] * (A @ A.T + 0.5 * np.eye(6)) * D


def changed(K, M):
    """K expressed at another point and in other axes: M = placement of the new frame."""
    X = M.inverse().toActionMatrix()  # twist_new = X twist_old (Pinocchio: linear first)
    return np.linalg.inv(X @ np.linalg.inv(K) @ X.T)


# ---------------------------------------------------------------- closed forms
def test_decoupled_stiffness_closed_forms():
    K, Q = decoupled(np.random.default_rng(0))
    s = StiffnessIndices.from_stiffness(K)
    assert s.rank == 6
    close(s.eigenvalues, np.sort(np.r_[K_T, K_R]))
    close(s.determinant, np.prod(K_T) * np.prod(K_R))
    close(s.condition_number, K_T.max() / K_R.min())
    for free, blocked, expected in (
        (s.translational_stiffness, s.translational_stiffness_blocked, K[T, T]),
        (s.rotational_stiffness, s.rotational_stiffness_blocked, K[R, R]),
    ):
        close(free, expected)  # decoupled: free and blocked coincide
        close(blocked, expected)
    for got, value, axis in (
        (s.min_translational_stiffness, K_T[0], Q[:, 0]),
        (s.max_translational_stiffness, K_T[2], Q[:, 2]),
        (s.min_rotational_stiffness, K_R[0], Q[:, 0]),
        (s.max_rotational_stiffness, K_R[2], Q[:, 2]),
    ):
        close(got.value, value)
        same_axis(got.direction, axis)


def test_homogenised_indices_with_characteristic_length():
    K = np.diag([4e5, 4e5, 4e5, 100.0, 100.0, 100.0])
    length = np.sqrt(100.0 / 4e5)  # rotation stiffness / length^2 = translation stiffness
    s = StiffnessIndices.from_stiffness(K, length=length)
    close(s.homogenised_eigenvalues(), np.full(6, 4e5))
    close(s.homogenised_condition_number(), 1.0)
    close(s.homogenised_eigenvalues(2 * length), np.r_[np.full(3, 1e5), np.full(3, 4e5)])
    close(s.condition_number, 4e3)


def test_decoupled_eigenscrews_closed_form():
    # K x = lambda Delta x with x = (v q, w q): k v = lambda w, a w = lambda v, so
    # lambda = +-sqrt(k a), pitch v / w = lambda / k = +-sqrt(a / k), axis q through 0.
    K, Q = decoupled(np.random.default_rng(1))
    screws = StiffnessIndices.from_stiffness(K).eigenscrews
    expected = sorted(
        (sign * np.sqrt(k * a), sign * np.sqrt(a / k), i)
        for sign in (1, -1)
        for i, (k, a) in enumerate(zip(K_T, K_R, strict=True))
    )
    for screw, (lam, pitch, i) in zip(screws, expected, strict=True):
        close(screw.eigenvalue, lam)
        close(screw.pitch, pitch)
        same_axis(screw.direction, Q[:, i])
        np.testing.assert_allclose(screw.point, 0.0, atol=GEOMETRY_ATOL)


# ---------------------------------------------------------------- definitions
def test_schur_complements_match_their_definitions():
    K = random_stiffness(np.random.default_rng(2))
    C = np.linalg.inv(K)
    s = StiffnessIndices.from_compliance(C)

    def schur(M, a, b):
        return M[a, a] - M[a, b] @ np.linalg.solve(M[b, b], M[b, a])

    close(s.translational_stiffness, schur(K, T, R))
    close(s.rotational_stiffness, schur(K, R, T))
    close(s.translational_stiffness_blocked, np.linalg.inv(schur(C, T, R)))
    close(s.rotational_stiffness_blocked, np.linalg.inv(schur(C, R, T)))
    # "rotations free": a pure force f gives a translation d with f = K_t d
    f = np.array([3.0, -1.0, 2.0])
    d = (C @ np.r_[f, 0, 0, 0])[T]
    close(s.translational_stiffness @ d, f)


def test_principal_translational_stiffness_bounds_every_direction():
    rng = np.random.default_rng(3)
    s = StiffnessIndices.from_stiffness(random_stiffness(rng))
    Kt = s.translational_stiffness
    lo, hi = s.min_translational_stiffness, s.max_translational_stiffness
    for p in (lo, hi):
        close(np.linalg.norm(p.direction), 1.0)
        close(Kt @ p.direction, p.value * p.direction)
    u = rng.normal(size=(3, 2000))
    u /= np.linalg.norm(u, axis=0)
    rayleigh = np.einsum("in,ij,jn->n", u, Kt, u)
    assert lo.value * (1 - INDEX_RTOL) <= rayleigh.min()
    assert rayleigh.max() <= hi.value * (1 + INDEX_RTOL)


def test_eigenscrews_of_a_coupled_stiffness():
    K = random_stiffness(np.random.default_rng(4))
    s = StiffnessIndices.from_stiffness(K)
    total = np.zeros((6, 6))
    for screw in s.eigenscrews:
        u, p, h = screw.direction, screw.point, screw.pitch
        twist = np.r_[h * u + np.cross(p, u), u]  # unit rotation about the axis, at 0
        wrench = np.r_[u, h * u + np.cross(p, u)]  # unit force on the same axis, at 0
        close(K @ twist, screw.eigenvalue * wrench)
        np.testing.assert_allclose(p @ u, 0.0, atol=GEOMETRY_ATOL)  # nearest point
        assert np.sign(screw.eigenvalue) == np.sign(h)
        close(screw.spring, screw.eigenvalue / (2 * h))
        total += screw.spring * np.outer(wrench, wrench)
    close(total, K)
    assert sorted(np.sign([x.eigenvalue for x in s.eigenscrews])) == [-1] * 3 + [1] * 3
    close(s.determinant, -np.prod([x.eigenvalue for x in s.eigenscrews]))


# ---------------------------------------------------------------- invariances
def test_point_and_axes_invariants():
    rng = np.random.default_rng(5)
    K = random_stiffness(rng)
    M = pin.SE3(Rotation.random(random_state=rng).as_matrix(), rng.normal(size=3) * 0.2)
    a, b = StiffnessIndices.from_stiffness(K), StiffnessIndices.from_stiffness(changed(K, M))
    close(b.determinant, a.determinant)
    Rt = M.rotation.T
    close(b.rotational_stiffness, Rt @ a.rotational_stiffness @ M.rotation)
    for sa, sb in zip(a.eigenscrews, b.eigenscrews, strict=True):
        close(sb.eigenvalue, sa.eigenvalue)
        close(sb.pitch, sa.pitch)
        same_axis(sb.direction, Rt @ sa.direction)
        on_axis = Rt @ (sa.point - M.translation)  # a point of the same line, new frame
        np.testing.assert_allclose(
            np.cross(on_axis - sb.point, sb.direction), 0.0, atol=GEOMETRY_ATOL
        )


def in_mm(C):
    """The same compliance in mm: twist_mm = S t, wrench_mm = W w, C_mm = S C W^-1."""
    S, W = np.diag([1e3] * 3 + [1.0] * 3), np.diag([1.0] * 3 + [1e3] * 3)
    return S @ C @ np.linalg.inv(W)


def test_length_unit_invariants():
    rng = np.random.default_rng(6)
    C = np.linalg.inv(random_stiffness(rng))
    screw = np.r_[0.3, -0.2, 0.1, 0.5, 0.4, -0.7]  # a rigid direction mixing d and r
    P = np.eye(6) - np.outer(screw, screw) / (screw @ screw)
    m, mm = (StiffnessIndices.from_compliance(c) for c in (P @ C @ P, in_mm(P @ C @ P)))
    assert m.rank == mm.rank == 5
    same_axis(m.rigid_directions[:, 0], screw / np.linalg.norm(screw))
    m = StiffnessIndices.from_compliance(C, length=0.1)
    mm = StiffnessIndices.from_compliance(in_mm(C), length=100.0)
    close(mm.determinant, m.determinant)
    close(mm.homogenised_condition_number(), m.homogenised_condition_number())
    close([x.pitch for x in mm.eigenscrews], [1e3 * x.pitch for x in m.eigenscrews])


# ---------------------------------------------------------------- rank deficiency
def test_rank_deficient_compliance_returns_what_exists():
    rng = np.random.default_rng(7)
    A = rng.normal(size=(3, 3)) * [[1e-2], [1e-2], [1e-1]]
    plane = [0, 2, 4]  # dx, dz, ry: a planar mechanism
    C = np.zeros((6, 6))
    C[np.ix_(plane, plane)] = A @ A.T * 1e-3
    s = StiffnessIndices.from_compliance(C)
    assert s.rank == 3
    expected = np.zeros((6, 6))
    expected[[1, 3, 5], [1, 3, 5]] = 1.0
    close(s.rigid_directions @ s.rigid_directions.T, expected)
    for name in ("K", "determinant", "eigenvalues", "condition_number", "eigenscrews"):
        with pytest.raises(RigidDirectionsError, match=r"rank 3 < 6.*dy.*rx.*rz"):
            getattr(s, name)
    with pytest.raises(
        RigidDirectionsError,
        match=r"max translational stiffness does not exist.*rank 2 < 3.*\+1\.00 dy\]$",
    ):
        _ = s.max_translational_stiffness
    c, V = np.linalg.eigh(C[np.ix_([0, 2], [0, 2])])  # the in-plane translations alone
    close(s.min_translational_stiffness.value, 1 / c[-1])
    same_axis(s.min_translational_stiffness.direction, [V[0, -1], 0.0, V[1, -1]])
    close(s.min_rotational_stiffness.value, 1 / C[4, 4])
    out = json.loads(json.dumps(s.to_dict()))
    assert out["K"] is None and "rank 3 < 6" in out["missing"]["K"]
    assert out["min_translational_stiffness"]["value"] == s.min_translational_stiffness.value
    assert set(out["missing"]) == {
        "K", "determinant", "eigenvalues", "condition_number", "eigenscrews",
        "translational_stiffness", "translational_stiffness_blocked", "rotational_stiffness",
        "rotational_stiffness_blocked", "max_translational_stiffness", "max_rotational_stiffness",
    }  # fmt: skip


def test_rotations_rigid():
    # a translational platform (rotations locked): C_rr = 0 exactly
    s = StiffnessIndices.from_compliance(np.diag([1e-5, 2e-5, 3e-5, 0.0, 0.0, 0.0]))
    assert s.rank == 3
    close(s.rigid_directions @ s.rigid_directions.T, np.diag([0.0, 0, 0, 1, 1, 1]))
    close(s.translational_stiffness, np.diag([1e5, 5e4, 1e5 / 3]))
    close(s.min_translational_stiffness.value, 1e5 / 3)
    same_axis(s.min_translational_stiffness.direction, [0.0, 0.0, 1.0])
    with pytest.raises(RigidDirectionsError, match=r"min rotational stiffness .* rank 0 < 3"):
        _ = s.min_rotational_stiffness


def test_full_rank_dict_and_constructors_agree():
    K = random_stiffness(np.random.default_rng(8))
    a = StiffnessIndices.from_stiffness(K, length=0.2)
    b = StiffnessIndices.from_compliance(np.linalg.inv(K), length=0.2)
    out = json.loads(json.dumps(a.to_dict()))
    assert out["missing"] == {} and out["rank"] == 6 and len(out["eigenscrews"]) == 6
    close(out["K"], K)
    close(b.K, K)
    close(out["homogenised_condition_number"], b.homogenised_condition_number())


# ---------------------------------------------------------------- from a mechanism
def test_ur5_determinant_from_joint_stiffness_and_jacobian():
    # 6-dof serial robot: C = J K_q^-1 J^T, so det K = prod(k) / det(J)^2; det J does not
    # depend on the reference point or axes (the change matrices have determinant 1).
    clm = load_urdf(robot_data_dir() / "ur_description/urdf/ur5_robot.urdf", joint_stiffness=1e4)
    q = np.array([0.3, -1.2, 1.4, -0.6, 1.1, 0.2])
    s = StiffnessIndices.from_result(compliance(clm, q, "tool0", axes="local"))
    J = pin.computeJointJacobian(clm.model, clm.model.createData(), q, 6)  # joint 6 frame
    close(s.determinant, 1e4**6 / np.linalg.det(J) ** 2)
    # near the stretched-arm singularity (scaled cond(K) 1.5e12 at 1e-5: full rank; 1.5e8 at
    # 1e-7: below the rule's 1e-14 eigenvalue ratio, rank deficient), and at it
    for elbow, rank in ((1e-5, 6), (1e-7, 5), (0.0, 5)):
        result = compliance(clm, np.r_[q[:2], elbow, q[3:]], "tool0")
        s = StiffnessIndices.from_result(result)
        assert s.rank == result.rank == rank
        assert s.is_full_rank == result.is_full_rank


@pytest.mark.parametrize(("k", "length"), [(1e49, 1e5), (1e-51, 1e-2)])
def test_determinant_near_the_float_limits_from_joint_stiffness_and_jacobian(k, length):
    """det K = prod(k) / det(J)^2 of 1.4e296 and 1.4e-304, resolved (scaled condition
    1e4..1e12), while det K_s = det K L^6 leaves the float range: the single indices gave
    inf and 0 (the product of the scaled eigenvalues first), the batched ones the value."""
    clm = load_urdf(robot_data_dir() / "ur_description/urdf/ur5_robot.urdf", joint_stiffness=k)
    q = np.array([0.3, -1.2, 1.4, -0.6, 1.1, 0.2])
    result = compliance(clm, q, "tool0", axes="local", length=length)
    J = pin.computeJointJacobian(clm.model, clm.model.createData(), q, 6)
    expected = k**6 / np.linalg.det(J) ** 2
    assert 1e-305 < expected < 1e297
    s = StiffnessIndices.from_result(result)
    np.testing.assert_allclose(s.determinant, expected, rtol=DET_RTOL_PER_SQRT_COND * 1e6)
    batched = batch_indices(result.C[None], np.array([6]), length)["det_K"][0]
    np.testing.assert_allclose(s.determinant, batched, rtol=DET_RTOL_PER_SQRT_COND * 1e6)
    # a diagonal K of determinant 1e300, scaled (L = 1e5) to 1e330
    big = StiffnessIndices.from_stiffness(1e50 * np.eye(6), length=1e5)
    np.testing.assert_allclose(big.determinant, 1e300, rtol=1e-14)


#: Relative error of det K per unit of sqrt(cond(K_s)): the eigenvalues of the formed C_s
#: and K_s that it multiplies are each known to about eps sqrt(cond) relative (the
#: determinant's docstring); 1e-14 leaves a factor of 50 for the six of them and the
#: reference's det(J) (cond(J) = sqrt(cond(K_s)) / spread at most).
DET_RTOL_PER_SQRT_COND = 1e-14


@pytest.mark.parametrize("axes", ["local", "world"])
@pytest.mark.parametrize(
    ("k_arm", "k_wrist", "elbow"),
    [(1e4, 1e4, 1e-5), (1e9, 1e2, 1e-3), (1e9, 1e2, 1e-5), (1e12, 10.0, 1e-5), (10.0, 1e12, 1e-3)],
)
def test_ur5_determinant_near_singular_poses_and_across_springs(k_arm, k_wrist, elbow, axes):
    """det K against prod(k) / det(J)^2 at scaled condition numbers from 1e12 to 3e22
    (springs 1e1..1e12 and the arm near stretched): accurate to about eps sqrt(cond); an
    LU determinant of K was off by a factor of 2 to 1e11 from cond 3e18. The eigenvalues
    of K and its SI condition number likewise (those of the formed K lost the smallest)."""
    ur5 = robot_data_dir() / "ur_description/urdf/ur5_robot.urdf"
    names = ("shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3")
    k = [k_arm] * 3 + [k_wrist] * 3
    clm = load_urdf(ur5, springs={f"{n}_joint": v for n, v in zip(names, k, strict=True)})
    q = np.array([0.3, -1.2, elbow, -0.6, 1.1, 0.2])
    result = compliance(clm, q, "tool0", axes=axes)
    assert result.rank == 6
    J = pin.computeJointJacobian(clm.model, clm.model.createData(), q, 6)
    expected = np.prod(k) / np.linalg.det(J) ** 2
    rtol = DET_RTOL_PER_SQRT_COND * np.sqrt(result.condition_number)
    s = StiffnessIndices.from_result(result)
    np.testing.assert_allclose(s.determinant, expected, rtol=rtol, atol=0)
    # the SI eigenvalues of K: 1 / sigma^2 of the factor J_tool0 diag(k)^-1/2 of C (SVD:
    # each sigma to eps sigma_max, i.e. eps sqrt(cond_SI) relative), same point and axes
    frame = {"local": pin.LOCAL, "world": pin.LOCAL_WORLD_ALIGNED}[axes]
    J_tool = pin.computeFrameJacobian(
        clm.model, clm.model.createData(), q, clm.model.getFrameId("tool0"), frame
    )
    sigma = np.linalg.svd(J_tool / np.sqrt(k), compute_uv=False)
    reference = np.sort(1.0 / sigma**2)
    rtol_si = DET_RTOL_PER_SQRT_COND * (sigma[0] / sigma[-1])
    np.testing.assert_allclose(s.eigenvalues, reference, rtol=rtol_si, atol=0)
    np.testing.assert_allclose(
        s.condition_number, (sigma[0] / sigma[-1]) ** 2, rtol=2 * rtol_si, atol=0
    )


def test_fourbar_indices_from_result():
    clm = load_urdf(REPO / "urdf/fourbar.urdf", REPO / "urdf/fourbar.yaml")
    result = compliance(clm, assemble(clm, [0.4]).q, "P")
    s = StiffnessIndices.from_result(result)
    assert s.rank == 3
    close(
        s.rigid_directions @ s.rigid_directions.T,
        result.rigid_directions @ result.rigid_directions.T,
    )
    c = np.linalg.eigvalsh(result.C[np.ix_([0, 2], [0, 2])])  # in-plane translations
    close(s.min_translational_stiffness.value, 1 / c[-1])
    with pytest.raises(RigidDirectionsError, match=r"dy"):
        _ = s.translational_stiffness


# ---------------------------------------------------------------- input errors
@pytest.mark.parametrize(
    ("matrix", "constructor", "match"),
    [
        (np.eye(5), "from_compliance", r"must be a \(6, 6\) matrix, got shape \(5, 5\)"),
        (np.diag([1.0, np.nan, 1, 1, 1, 1]), "from_stiffness", r"stiffness contains non-finite"),
        (np.eye(6) + np.triu(np.ones((6, 6)), 1), "from_compliance", r"not symmetric"),
        (np.eye(6) + np.triu(np.ones((6, 6)), 1), "from_stiffness", r"not symmetric"),
        (np.diag([1.0, -1, 1, 1, 1, 1]), "from_compliance", r"not positive semi-definite"),
        (np.ones((6, 6)) - 0.5 * np.eye(6), "from_compliance", r"not positive semi-definite"),
        (np.diag([1.0, 0, 1, 1, 1, 1]), "from_stiffness", r"not positive definite"),
    ],
)
def test_invalid_matrices(matrix, constructor, match):
    with pytest.raises(InvalidInputError, match=match):
        getattr(StiffnessIndices, constructor)(matrix)


def test_a_stiffness_beyond_the_float_resolution_is_refused_whatever_the_rounding():
    """K = Q diag(1 .. 1e17) Q^T (positive definite in exact arithmetic; its smallest
    eigenvalue below the rounding of its largest): from two random Q, one was refused as
    not positive definite and the other accepted (rank 5), as a Cholesky factorisation
    failed or not. Both are refused now, naming the eigenvalues; at 1 .. 1e13 both are
    taken, and K comes back to the rounding of its condition number."""
    for seed, (top, refused) in itertools.product((17, 117), ((17.0, True), (13.0, False))):
        rng = np.random.default_rng(seed)
        Q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
        K = (Q * np.logspace(0.0, top, 6)) @ Q.T
        K = 0.5 * (K + K.T)
        if refused:
            with pytest.raises(InvalidInputError, match=r"not positive definite to working pre"):
                StiffnessIndices.from_stiffness(K)
        else:
            s = StiffnessIndices.from_stiffness(K)
            assert s.rank == 6
            # K from the factor: each entry to about eps cond(K) = 1e-3 of the largest
            np.testing.assert_allclose(s.K, K, rtol=0, atol=1e-3 * np.abs(K).max())


def test_a_stiffness_whose_scaled_form_overflows_is_refused():
    """K = 1e300 I at L = 1e5 m: K L^2 = 1e310 for the translations. The stiffness came
    back with inf on its diagonal; now a typed error says why. At L = 1 it is taken."""
    K = 1e300 * np.eye(6)
    with pytest.raises(InvalidInputError, match=r"L = 100000 m .* leaves the float range"):
        StiffnessIndices.from_stiffness(K, length=1e5)
    np.testing.assert_allclose(StiffnessIndices.from_stiffness(K).K, K, rtol=1e-14)


@pytest.mark.parametrize("length", [0.0, -1.0, np.nan, np.inf])
def test_invalid_length(length):
    with pytest.raises(InvalidInputError, match=r"characteristic length must be finite and > 0"):
        StiffnessIndices.from_stiffness(np.eye(6), length=length)


def test_homogenised_index_needs_a_length():
    with pytest.raises(InvalidInputError, match=r"characteristic length \[m\] is needed"):
        StiffnessIndices.from_stiffness(np.eye(6)).homogenised_condition_number()


# ---------------------------------------------------------------- batched
@pytest.mark.parametrize("length", [1e-7, 1e-4, 1.0, 1e3])
def test_batched_determinant_follows_the_scaled_condition(length):
    """det K of a map from the scaled eigenvalues: a mechanism of 0.1 um has an SI
    condition number of 1e14 for a scaled one of 10; 1 / det(C) lost it to a NaN (or
    eps cond_SI of it). Reference: det(D)^2 / det(C_s), C_s = U diag(mu) U^T built with
    known eigenvalues mu, and the single query's determinant."""
    rng = np.random.default_rng(5)
    U = np.linalg.qr(rng.normal(size=(6, 6)))[0]
    mu = np.array([1.0, 2.0, 3.0, 5.0, 7.0, 10.0]) * 1e-4  # rad/(N m), scaled
    d = np.r_[np.full(3, 1.0 / length), np.ones(3)]
    C = (U * mu) @ U.T / np.outer(d, d)
    expected = np.prod(d) ** 2 / np.prod(mu)
    got = batch_indices(C[None], np.array([6]), length)
    # the six eigenvalues of a formed C_s (itself rounded) to a few eps of the largest,
    # eps mu_max / mu_min = 10 eps relative each: 6 * 16 eps * 10 (measured 2.7e-14)
    rtol = 6 * 16 * np.finfo(float).eps * mu.max() / mu.min()
    np.testing.assert_allclose(got["det_K"][0], expected, rtol=rtol)
    single = StiffnessIndices.from_compliance(C, length=length).determinant
    np.testing.assert_allclose(got["det_K"][0], single, rtol=rtol)


def test_batched_determinant_without_overflow_of_the_product():
    """Six scaled eigenvalues of 1e-60 (det C_s = 1e-360 underflows): det K = 1e360
    overflows honestly to inf; of 1e-50, 1e300 is returned."""
    for mu, expected in ((1e-60, np.inf), (1e-50, 1e300)):
        got = batch_indices(np.eye(6)[None] * mu, np.array([6]), 1.0)["det_K"][0]
        np.testing.assert_allclose(got, expected, rtol=1e-12)


def test_batched_indices_equal_the_single_ones():
    """batch_indices on a stack (full rank, rank 3, rotations rigid, a NaN row) equals
    StiffnessIndices point by point; a non-symmetric C follows its own definitions."""
    rng = np.random.default_rng(11)
    plane = np.zeros((6, 6))
    A = rng.normal(size=(3, 3)) * [[1e-2], [1e-2], [1e-1]]
    plane[np.ix_([0, 2, 4], [0, 2, 4])] = A @ A.T * 1e-3
    stack = [np.linalg.inv(random_stiffness(rng)) for _ in range(3)]
    stack += [plane, np.diag([1e-5, 2e-5, 3e-5, 0.0, 0.0, 0.0]), np.full((6, 6), np.nan)]
    asym = np.linalg.inv(random_stiffness(rng)) + 1e-7 * rng.normal(size=(6, 6))
    C = np.array([*stack, asym])
    length, w = 0.3, np.array([1.0, -2.0, 0.5, 0.1, 0.0, 0.3])
    single = [StiffnessIndices.from_compliance(c, length=length) for c in stack[:5]]
    rank = np.array([s.rank for s in single] + [-1, 6])
    symmetric = np.array([True] * 6 + [False])
    got = batch_indices(C, rank, length, w, symmetric)
    assert set(got) == set(BATCH_INDICES)
    for i, s in enumerate(single):
        for name, get in INDEX_GETTERS.items():
            try:
                expected = get(s)
            except RigidDirectionsError:
                expected = np.nan
            np.testing.assert_allclose(got[name][i], expected, rtol=INDEX_RTOL,
                                       err_msg=f"{name} at {i}")  # fmt: skip
        d = C[i] @ w
        np.testing.assert_allclose(got["deflection_translation"][i], np.linalg.norm(d[:3]),
                                   rtol=INDEX_RTOL)  # fmt: skip
        np.testing.assert_allclose(got["deflection_rotation"][i], np.linalg.norm(d[3:]),
                                   rtol=INDEX_RTOL)  # fmt: skip
    assert all(np.isnan(v[5]) for v in got.values())  # the NaN row
    K = np.linalg.inv(asym)
    D = np.r_[np.full(3, length), np.ones(3)]
    np.testing.assert_allclose(got["det_K"][6], np.linalg.det(K), rtol=INDEX_RTOL)
    np.testing.assert_allclose(
        got["condition_number_si"][6],
        np.linalg.norm(K, 2) * np.linalg.norm(asym, 2),
        rtol=INDEX_RTOL,
    )
    Ks = D[:, None] * K * D[None, :]
    np.testing.assert_allclose(got["condition_number"][6],
                               np.linalg.norm(Ks, 2) * np.linalg.norm(np.linalg.inv(Ks), 2),
                               rtol=INDEX_RTOL)  # fmt: skip
    assert np.isnan(got["min_translational"][6])
    assert "deflection_rotation" not in batch_indices(C, rank, length)
