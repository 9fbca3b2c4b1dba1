"""The one rank rule: boundaries, unit invariance, square-root factors, singular sweeps."""

import mechanisms as mech
import numpy as np
import pinocchio as pin
import pytest

from closedloop import (
    ILL_CONDITIONED,
    RANK_RTOL,
    ClosedLoopModel,
    Configuration,
    MechanismError,
    SingularConfigurationError,
    StiffnessIndices,
    compliance,
)
from closedloop.common.conditioning import (
    batch_rank,
    characteristic_length,
    scaled_asymmetry,
    spectrum_from_compliance,
    spectrum_from_factor,
)
from closedloop.io.loader import load_urdf, robot_data_dir

EPS = np.finfo(float).eps
#: C and K agree with a reference to this many ulps times the condition number of the
#: scaled K (the rounding of the kinematics, amplified by the conditioning).
COND_ULPS = 10.0
#: Exact arithmetic up to a few roundings.
RTOL_EXACT = 1e-12
UR5_Q = np.array([0.3, -1.0, 0.0, -0.5, 1.2, 0.3])  # elbow (q[2]) set per test
UR5_K = 1e4  # N m/rad, every joint


def orthogonal(n, seed):
    return np.linalg.qr(np.random.default_rng(seed).normal(size=(n, n)))[0]


# ---------------------------------------------------------------- the rule itself
def test_documented_thresholds():
    # The docs promise an eigenvalue ratio of 1e-14 for rank and 1e8 for the flag.
    assert RANK_RTOL**2 == pytest.approx(1e-14, rel=1e-12)
    assert ILL_CONDITIONED == 1e8


@pytest.mark.parametrize(("factor", "rank"), [(10.0, 6), (0.1, 5)])
def test_rank_boundary_of_a_factor(factor, rank):
    # Singular values of the factor at 10x and 0.1x the threshold of the largest.
    beta = np.array([1.0, 0.7, 0.5, 0.3, 0.2, factor * RANK_RTOL])
    B = orthogonal(6, 1) @ np.diag(beta) @ orthogonal(6, 2)
    s = spectrum_from_factor(B, 1.0)
    assert s.rank == rank
    if rank == 6:
        # beta_min = 1e-6 carries the SVD's absolute error eps: 4e-10 relative in cond
        np.testing.assert_allclose(s.condition_number, (1.0 / beta[-1]) ** 2, rtol=1e-9)
        assert s.ill_conditioned
        # K = U diag(beta^-2) U^T exactly; from the factor it keeps eps sqrt(cond) ~ 1e-10
        U = orthogonal(6, 1)
        K = U @ np.diag(beta**-2.0) @ U.T
        np.testing.assert_allclose(s.K, K, rtol=0, atol=1e-9 * np.abs(K).max())
    else:
        assert s.K is None and s.rigid_directions.shape == (6, 1)
        U = orthogonal(6, 1)
        np.testing.assert_allclose(abs(s.rigid_directions[:, 0] @ U[:, 5]), 1.0, rtol=1e-12)
        np.testing.assert_allclose(s.condition_number, (1.0 / beta[-2]) ** 2, rtol=RTOL_EXACT)


@pytest.mark.parametrize(("factor", "rank"), [(10.0, 6), (0.1, 5)])
def test_rank_boundary_of_a_matrix_and_of_a_batch(factor, rank):
    # The same rule on eigenvalues (RANK_RTOL^2) when only C is known.
    mu = np.array([1.0, 0.7, 0.5, 0.3, 0.2, factor * RANK_RTOL**2])
    U = orthogonal(6, 3)
    C = U @ np.diag(mu) @ U.T
    assert spectrum_from_compliance(C, 1.0).rank == rank
    assert StiffnessIndices.from_compliance(C).rank == rank
    ranks, cond, psd = batch_rank(np.stack([C, C]), 1.0)
    assert list(ranks) == [rank, rank] and psd.all()
    # over the rank; from C itself an eigenvalue is known to eps |C|: 2e-3 relative at 1e-13
    np.testing.assert_allclose(cond, 1.0 / mu[rank - 1], rtol=1e-2)


def test_springs_of_any_ratio_are_springs_and_no_spring_is_none():
    """Two sliders x, y with springs k_x and k_y = k_x (f RANK_RTOL)^2: whatever f, both
    are springs and C = diag(1/k_x, 1/k_y) on both paths; without the spring on y its
    motion is spring-free and moves the tip (MechanismError naming 'y')."""
    model = pin.Model()
    jx = model.addJoint(0, pin.JointModelPX(), pin.SE3.Identity(), "x")
    jy = model.addJoint(jx, pin.JointModelPY(), pin.SE3.Identity(), "y")
    model.appendBodyToJoint(jy, pin.Inertia.Random(), pin.SE3.Identity())
    model.addFrame(pin.Frame("tip", jy, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    kx = 1e6
    for factor in (10.0, 0.1, 1e-3):
        ky = kx * (factor * RANK_RTOL) ** 2
        clm = ClosedLoopModel(model, springs={"x": kx, "y": ky})
        for path in ("auto", "null-space"):
            res = compliance(clm, np.zeros(2), "tip", path=path)
            np.testing.assert_allclose(np.diag(res.C)[:2], [1 / kx, 1 / ky], rtol=RTOL_EXACT)
            assert res.rank == 2 and res.condition_number == pytest.approx(kx / ky, rel=1e-9)
            assert res.ill_conditioned  # 1e12 and more over the range of C
    passive = ClosedLoopModel(model, springs={"x": kx, "y": 0.0})
    for path in ("auto", "null-space"):
        with pytest.raises(MechanismError, match=r"no restoring spring.*'y'"):
            compliance(passive, np.zeros(2), "tip", path=path)


def test_rank_and_condition_do_not_depend_on_the_length_unit():
    # The same near-singular Stewart platform in metres and in millimetres.
    for delta in (1e-3, 1e-5):
        m = mech.stewart_near_singular(delta)
        res_m = compliance(m.clm, m.q, m.frame)
        mm = mech.stewart(
            position=1e3 * np.asarray(m.geometry["p"]),
            psi=np.pi / 2 - delta,
            anchors=(1e3 * mech.STEWART_BASE, 1e3 * mech.STEWART_PLATFORM),
            k=mech.STEWART_K / 1e3,  # N/mm
        )
        res_mm = compliance(mm.clm, mm.q, mm.frame)
        assert res_mm.rank == res_m.rank == 6
        np.testing.assert_allclose(res_mm.length, 1e3 * res_m.length, rtol=RTOL_EXACT)
        np.testing.assert_allclose(res_mm.condition_number, res_m.condition_number, rtol=1e-6)
        assert res_mm.ill_conditioned == res_m.ill_conditioned


def test_characteristic_length():
    assert characteristic_length([[0, 0, 0], [3, 4, 0]]) == 5.0
    assert characteristic_length([[1, 1, 1]]) == 1.0  # one point has no size
    assert characteristic_length([[2, 2, 2], [2, 2, 2]]) == 1.0


def test_characteristic_length_is_the_diameter_at_any_size_place_and_orientation():
    """The largest distance between two points: a cube's is its space diagonal, turned or
    not (a bounding box turned with the cube grew by up to sqrt(3)), 1e155 or 1e-160 m
    across (the squares of the distances leave the doubles: L fell back to 1 m), and 1e6
    m from the origin (rounding eps 1e6 / sqrt(3) = 1.3e-10 there)."""
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    R = pin.exp3(np.array([0.3, -1.1, 0.7]))
    for points in (corners, corners @ R.T, corners @ R.T + 1e6):
        np.testing.assert_allclose(characteristic_length(points), np.sqrt(3.0), rtol=1e-9)
    for scale in (1e155, 1e-160):
        np.testing.assert_allclose(
            characteristic_length(scale * corners), scale * np.sqrt(3.0), rtol=1e-15
        )


# ---------------------------------------------------------------- towards singularities
@pytest.mark.parametrize("delta", [10.0**-e for e in range(2, 13)])
def test_stewart_towards_its_rotation_singularity(delta):
    m = mech.stewart_near_singular(delta)
    try:
        res = compliance(m.clm, m.q, m.frame)
    except MechanismError as e:  # refused, with a reason: only very close to it
        assert delta < 1e-6 and "singular configuration" in str(e)
        return
    assert np.all(np.isfinite(res.C)) and res.rank == 6
    K_ref = mech.stewart_stiffness(m.geometry)
    Jinv = np.linalg.inv(mech.stewart_inverse_jacobian(m.geometry["u"], m.geometry["r"]))
    C_ref = Jinv @ np.diag(1 / m.geometry["k"]) @ Jinv.T
    np.linalg.cholesky(res.K)  # positive definite
    tol = COND_ULPS * EPS * res.condition_number
    L = res.length
    d = np.r_[np.full(3, 1 / L), np.ones(3)]
    scaled = np.outer(d, d)
    np.testing.assert_allclose(
        res.C * scaled, C_ref * scaled, rtol=0, atol=tol * np.abs(C_ref * scaled).max()
    )
    np.testing.assert_allclose(
        res.K / scaled, K_ref / scaled, rtol=0, atol=tol * np.abs(K_ref / scaled).max()
    )
    assert res.ill_conditioned == (res.condition_number > ILL_CONDITIONED)
    # the flag of the reference's scaled K (cond ~ 83 / delta^2 at L = 1.93 m)
    assert res.ill_conditioned == (np.linalg.cond(K_ref / scaled) > ILL_CONDITIONED)


def _ur5():
    return load_urdf(robot_data_dir() / "ur_description/urdf/ur5_robot.urdf", joint_stiffness=UR5_K)


def _ur5_reference(clm, q):
    """J^-T K_q J^-1 at tool0 (world axes) and the expected rank by the rule, from
    Pinocchio's frame Jacobian directly."""
    data = clm.model.createData()
    J = pin.computeFrameJacobian(
        clm.model, data, q, clm.model.getFrameId("tool0"), pin.LOCAL_WORLD_ALIGNED
    )
    L = characteristic_length([M.translation for M in data.oMi])
    s = np.linalg.svd(np.r_[np.full(3, 1 / L), np.ones(3)][:, None] * J, compute_uv=False)
    Jinv = np.linalg.inv(J)
    return UR5_K * Jinv.T @ Jinv, 6 if s[-1] > RANK_RTOL * s[0] else 5


@pytest.mark.parametrize(("elbow", "rank"), [(1e-4, 6), (1e-5, 6), (1e-6, None), (1e-8, 5)])
def test_ur5_near_the_stretched_arm(elbow, rank):
    # K from the square-root factor keeps 1e-6 where inv(C) lost up to 96 %.
    clm = _ur5()
    q = UR5_Q.copy()
    q[2] = elbow
    K_ref, expected = _ur5_reference(clm, q)
    res = compliance(clm, q, "tool0")
    assert res.rank == expected == (rank or expected)
    indices = StiffnessIndices.from_result(res)
    assert indices.rank == res.rank and indices.is_full_rank == res.is_full_rank
    if res.is_full_rank:
        np.testing.assert_allclose(res.K, K_ref, rtol=0, atol=1e-6 * np.abs(K_ref).max())
        np.testing.assert_allclose(indices.K, res.K, rtol=0, atol=0)
        assert res.ill_conditioned


@pytest.mark.parametrize("elbow", [1e-6, 1e-10])
def test_ur5_rank_at_elbow(elbow):
    clm = _ur5()
    q = UR5_Q.copy()
    q[2] = elbow
    _, expected = _ur5_reference(clm, q)
    assert compliance(clm, q, "tool0").rank == expected == 5  # cond(K_s) ~ 1.5e14 at 1e-6


@pytest.mark.parametrize("alpha1_deg", [1e-1, 1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-8])
@pytest.mark.parametrize("side", ["zero", "pi"])
def test_cahyman_crank_towards_its_coupler(alpha1_deg, side):
    from cahyman_pin.api import stiffness

    a1 = np.deg2rad(alpha1_deg if side == "zero" else 180.0 - alpha1_deg)
    alpha = np.array([a1, np.deg2rad(60.0), np.deg2rad(75.0)])
    results = {}
    for backend in ("generic", "consistent"):
        try:
            results[backend] = stiffness(alpha, 0.3, 0.01, backend=backend)
        except (MechanismError, SingularConfigurationError) as e:
            results[backend] = e
    g, c = results["generic"], results["consistent"]
    if isinstance(g, Exception) or isinstance(c, Exception):
        # refused by either: only where the scaled eigenvalues span more than ~1e12
        assert alpha1_deg <= 1e-5
        return
    np.linalg.cholesky(g.K)
    assert np.all(np.isfinite(g.C))
    cond = g.indices.scaled_condition_number
    d = np.r_[np.full(3, 1 / g.params.length), np.ones(3)]
    tol = COND_ULPS * EPS * cond
    np.testing.assert_allclose(
        g.C * np.outer(d, d), c.C * np.outer(d, d), rtol=0, atol=max(tol, 1e-8) * np.abs(c.C).max()
    )
    assert g.indices.ill_conditioned == (cond > ILL_CONDITIONED)
    assert g.indices.ill_conditioned == c.indices.ill_conditioned or abs(np.log10(cond) - 8) < 0.1


def test_configuration_scale_is_used_by_the_compliance():
    clm = _ur5()
    state = Configuration(clm, UR5_Q, length=2.0)
    assert compliance(state, "tool0").length == 2.0


@pytest.mark.parametrize("elbow", [1e-4, 1e-5, 1e-6, 1e-8])
def test_ur5_decision_is_the_same_in_the_api_the_indices_the_cli_and_the_json(elbow, capsys):
    import json

    from closedloop.cli.app import main

    clm = _ur5()
    q = UR5_Q.copy()
    q[2] = elbow
    res = compliance(clm, q, "tool0")
    path = str(robot_data_dir() / "ur_description/urdf/ur5_robot.urdf")
    code = main(["stiffness", path, "--frame", "tool0", "--q", *map(repr, q.tolist()),
                 "--joint-stiffness", repr(UR5_K), "--json"])  # fmt: skip
    doc = json.loads(capsys.readouterr().out)
    assert code == (0 if res.is_full_rank else 1)
    assert doc["rank"] == res.rank == StiffnessIndices.from_result(res).rank
    assert doc["ill_conditioned"] == res.ill_conditioned
    assert (doc["K"] is None) == (not res.is_full_rank)


def test_scaled_asymmetry_sees_through_rounding_of_zero_entries():
    """A compliance symmetric but for rounding in entries that vanish (+-1e-25 where the
    others are 1e-6) has a scaled asymmetry of rounding; an entry-by-entry test called it
    non-symmetric. A real asymmetry (a preload moment) is seen, at each of n lengths."""
    C = np.diag([1e-6, 2e-6, 3e-6, 1e-4, 2e-4, 3e-4])
    C[0, 5], C[5, 0] = 1e-25, -1e-25
    assert scaled_asymmetry(C, 0.5) < 1e-18
    skew = C.copy()
    skew[0, 4] = 1e-7  # [m/(N m)], against its transpose 0
    values = scaled_asymmetry(np.array([C, skew]), np.array([0.5, 2.0]))
    assert values.shape == (2,) and values[0] < 1e-18
    np.testing.assert_allclose(values[1], 1e-7 / 2.0 / (3e-4), rtol=1e-12)  # / L, / max C_s
    assert scaled_asymmetry(np.zeros((6, 6)), 1.0) == 0.0
