"""Compliance of peer mechanisms (Stewart 6-UPS, 3-RRR, 5-bar, Delta) against hand derivations.

The builders and their references are in ``tests/mechanisms.py``; each reference is
numpy on the input geometry (inverse Jacobians, static condensation, an independent
Newton solve), never the engine. C is compared after scaling its rotational rows and
columns by a length L of the mechanism (every entry then in m/N), so that one relative
tolerance means the same for translations and rotations.
"""

from __future__ import annotations

import mechanisms as mech
import numpy as np
import pinocchio as pin
import pytest
import scipy.optimize
from helpers import assert_close_in_norm
from scipy.spatial.transform import Rotation

from closedloop.elastostatics.compliance import compliance
from closedloop.elastostatics.statics import solve_equilibrium
from closedloop.exceptions import EquilibriumError, MechanismError
from closedloop.kinematics.assembly import assemble, free_coordinates
from closedloop.kinematics.constraints import closure_residual, update_kinematics

# Engine vs hand formula: the engine goes through a QR null space of 3 to 18 closure rows
# (nv 4 to 33) and an eigen-decomposition, the reference through one 6x6 (or 3x3)
# inverse; both are within ~cond * eps of the truth, cond <= 2e2 here after the length
# scaling (measured agreement 1e-16 to 3e-14). 1e-9 leaves a margin of 1e4, while any
# modelling error (a lever arm, a sign, the block layout, a spring) shows at >= 1e-3.
HAND_RTOL = 1e-9
# Orthonormal bases of rigid directions: projectors agree to ~cond * eps as well.
SPAN_ATOL = 1e-9
# Builders compute q by closed-form inverse kinematics; Pinocchio's SE3 products must put
# every frame at the hand position and close every loop to a few ulps of 1 m.
POSITION_ATOL = 1e-13
# Re-assembly from a perturbed start: closure tolerance 1e-12 m (ASSEMBLY_TOL), amplified
# in the frame positions by the forward-kinematics conditioning (~1e3 near Fichter's
# singularity at delta = 1e-3; measured 3e-11 there, 2e-13 elsewhere).
ASSEMBLED_ATOL = 1e-10
# Near a singularity the problem itself loses accuracy: the smallest eigenvalue of K is
# known to eps * |K|, so C is known to ~eps * cond(K) relative (measured: 0.1 to 0.3 eps
# cond for delta = 1e-1 .. 1e-5); 10 eps cond is the tolerance, never below HAND_RTOL.
NEAR_SINGULAR_FACTOR = 10.0
# Nonlinear statics, engine vs reference root finder: both are Newton-like and converge to
# ~1e-15 of the load (the engine to FORCE_RTOL = 1e-11 or a 1e-12 step); measured
# agreement 5e-15 to 8e-14 of the displacement, so 1e-8 has a wide margin.
STATICS_RTOL = 1e-8
# Same mechanism, closure pairs written the other way round: other constraint rows, same
# admissible subspace; differences are roundoff through different null-space bases.
ORDER_RTOL = 1e-9
# Finite-difference check of a reference Jacobian, central differences with step H_FD:
# truncation ~H_FD^2 / l^2 ~ 1e-12 relative, roundoff ~eps / H_FD ~ 1e-10.
H_FD = 1e-6
FD_RTOL = 1e-8

PLANAR = [0, 1, 5]  # dx, dy, rz
OUT_OF_PLANE = [2, 3, 4]  # dz, rx, ry
ROTATIONS = [3, 4, 5]
STEWART_L, RRR_L, FIVEBAR_L, DELTA_L = 0.5, 0.12, 0.3, 0.05  # scaling lengths [m]


def lengths(length, labels=range(6)) -> np.ndarray:
    """The scale of a compliance block with twist rows (wrench columns) ``labels``: the
    rotational ones times ``length`` [m], for :func:`helpers.assert_close_in_norm`."""
    return np.where(np.isin(list(labels), ROTATIONS), length, 1.0)


def assert_same_span(V, W):
    """The columns of V and W (orthonormal) span the same subspace: equal projectors."""
    np.testing.assert_allclose(V @ V.T, W @ W.T, atol=SPAN_ATOL)


def unit(*labels):
    """(6, n) orthonormal twist (or wrench) axes of the given indices."""
    return np.eye(6)[:, list(labels)]


# ---------------------------------------------------------------- the builders themselves
STEWART_POSES = {
    "home": {},
    "translated": {"position": (0.12, -0.08, 1.1)},
    "turned": {"position": (0.0, 0.05, 0.8), "psi": 0.6},
    "general": {  # anchors without symmetry, platform tilted, turned and translated
        "position": (0.1, -0.05, 0.9),
        "psi": 0.3,
        "tilt": (0.1, -0.15),
        "anchors": mech.perturbed_anchors(seed=0),
    },
}
BUILDS = {
    "stewart_general": lambda: mech.stewart(**STEWART_POSES["general"]),
    "stewart_spherical": lambda: mech.stewart(base_joint="spherical", psi=0.4),
    "stewart_near_singular": lambda: mech.stewart_near_singular(1e-3),
    "rrr3": lambda: mech.rrr3((0.03, -0.02, 0.15)),
    "fivebar": mech.fivebar,
    "delta": lambda: mech.delta((0.08, -0.05, -0.45)),
    "delta_sprung_swapped": lambda: mech.delta(k_rod=2e5, closure_order="swapped"),
}


@pytest.mark.parametrize("name", BUILDS)
def test_builder_closes_its_loops_where_the_hand_geometry_says(name):
    m = BUILDS[name]()
    assert np.max(np.abs(closure_residual(m.clm, m.q))) < POSITION_ATOL
    update_kinematics(m.clm, m.q)
    assert m.frame in m.positions
    checked = [n for n in m.positions if m.clm.model.existFrame(n)]
    assert len(checked) >= len(m.clm.closures)
    for frame in checked:
        np.testing.assert_allclose(
            m.clm.data.oMf[m.clm.frame_id(frame)].translation, m.positions[frame],
            atol=POSITION_ATOL, err_msg=frame,
        )  # fmt: skip
    assert all(m.clm.model.inertias[j].mass > 0 for j in range(1, m.clm.model.njoints))
    # assemble() from a perturbed start (passive coordinates moved by up to 1e-2 rad or m)
    # finds the same configuration again, up to the internal mobilities (rod spins)
    v = np.zeros(m.clm.model.nv)
    free = free_coordinates(m.clm)
    v[free] = np.random.default_rng(1).uniform(-1e-2, 1e-2, free.size)
    q0 = pin.integrate(m.clm.model, m.q, v)
    q = assemble(m.clm, actuated=m.q[m.clm.actuated_q_indices], q0=q0).q
    update_kinematics(m.clm, q)
    for frame in checked:
        np.testing.assert_allclose(
            m.clm.data.oMf[m.clm.frame_id(frame)].translation, m.positions[frame],
            atol=ASSEMBLED_ATOL, err_msg=frame,
        )  # fmt: skip


# ---------------------------------------------------------------- Stewart 6-UPS
def displaced_legs(g, x):
    """(6, 3) leg vectors and platform anchors relative to the platform origin [m], world
    axes, with the platform moved by x = (dp [m], phi [rad]): p += dp, R = exp(phi) R."""
    r = g["a"] @ (Rotation.from_rotvec(x[3:]).as_matrix() @ g["R"]).T
    return g["p"] + x[:3] + r - g["b"], r


def displaced_leg_lengths(g, x):
    """(6,) leg lengths [m] with the platform moved by x (:func:`displaced_legs`)."""
    return np.linalg.norm(displaced_legs(g, x)[0], axis=1)


def stewart_equilibrium(g, force):
    """(6,) platform displacement x = (dp [m], phi [rad]) under a dead-load force [N].

    Independent model: leg i pulls the platform with k_i (l_i(x) - l_i0) along -u_i, so
    the balance of forces and of moments about the platform origin (where the force acts)
    is sum_i k_i (l_i - l_i0) [u_i, r_i x u_i] = [f, 0]; scipy's ``root`` (hybrid Powell)
    solves it, the load growing in 10 steps to stay on the branch that starts at rest.
    """

    def residual(x, f):
        legs, r = displaced_legs(g, x)
        lengths = np.linalg.norm(legs, axis=1)
        J = mech.stewart_inverse_jacobian(legs / lengths[:, None], r)
        return (J.T @ (g["k"] * (lengths - g["lengths"])) - np.r_[f, 0, 0, 0]) / np.max(g["k"])

    x = np.zeros(6)
    for fraction in np.linspace(0.1, 1.0, 10):
        x = scipy.optimize.root(residual, x, args=(fraction * force,), tol=1e-15).x
    worst = np.max(np.abs(residual(x, force)))  # [m]
    assert worst < 1e-15 * max(1.0, np.linalg.norm(force) / np.max(g["k"])), worst
    return x


def test_stewart_reference_jacobian_is_the_derivative_of_the_leg_lengths():
    g = mech.stewart(**STEWART_POSES["general"]).geometry
    np.testing.assert_allclose(
        displaced_leg_lengths(g, np.zeros(6)), g["lengths"], atol=POSITION_ATOL
    )
    J = mech.stewart_inverse_jacobian(g["u"], g["r"])
    fd = np.column_stack(
        [(displaced_leg_lengths(g, H_FD * e) - displaced_leg_lengths(g, -H_FD * e)) / (2 * H_FD)
         for e in np.eye(6)]
    )  # fmt: skip
    np.testing.assert_allclose(J, fd, rtol=FD_RTOL, atol=FD_RTOL)


@pytest.mark.parametrize("pose", STEWART_POSES)
def test_stewart_compliance_is_the_inverse_of_JT_k_J(pose):
    m = mech.stewart(**STEWART_POSES[pose])
    result = compliance(m.clm, m.q, m.frame)
    assert (result.rank, result.mobility, result.internal_mobilities) == (6, 6, 0)
    C_ref = np.linalg.inv(mech.stewart_stiffness(m.geometry))
    assert_close_in_norm(result.C, C_ref, HAND_RTOL, scale=lengths(STEWART_L))


def test_stewart_ball_base_joints_add_six_leg_spins_and_change_nothing():
    universal, ball = (mech.stewart(psi=0.4, base_joint=j) for j in ("universal", "spherical"))
    a, b = (compliance(m.clm, m.q, m.frame) for m in (universal, ball))
    assert (b.mobility, b.internal_mobilities, b.rank) == (12, 6, 6)
    assert_close_in_norm(b.C, a.C, ORDER_RTOL, scale=lengths(STEWART_L))


def singular_value_ratio(m):
    s = np.linalg.svd(
        mech.stewart_inverse_jacobian(m.geometry["u"], m.geometry["r"]), compute_uv=False
    )
    return s[-1] / s[0]


@pytest.mark.parametrize("height", [0.7, 1.0, 1.4])
def test_fichter_singularity_at_psi_90_deg(height):
    # the reference J is singular at delta = 0 (at any height) and its smallest singular
    # value grows linearly with delta
    assert singular_value_ratio(mech.stewart_near_singular(0.0, height)) < 1e-14
    ratios = [singular_value_ratio(mech.stewart_near_singular(d, height)) for d in (1e-3, 1e-4)]
    np.testing.assert_allclose(ratios[1] / ratios[0], 0.1, rtol=1e-3)
    m = mech.stewart_near_singular(0.0, height)  # no leg spring resists the singular twist
    with pytest.raises(MechanismError, match="still a mechanism at frame 'platform'"):
        compliance(m.clm, m.q, m.frame)


@pytest.mark.parametrize("delta", [1e-1, 1e-2, 1e-3, 1e-4, 1e-5])
def test_stewart_near_fichter_singularity(delta):
    m = mech.stewart_near_singular(delta)
    K = mech.stewart_stiffness(m.geometry)
    s = np.where(np.isin(range(6), ROTATIONS), 1.0 / STEWART_L, 1.0)
    cond = np.linalg.cond(K * np.outer(s, s))  # of the scaled stiffness
    assert cond > 10 / delta**2  # the compliance really blows up as delta^-2
    result = compliance(m.clm, m.q, m.frame)
    assert result.rank == 6
    rtol = max(HAND_RTOL, NEAR_SINGULAR_FACTOR * np.finfo(float).eps * cond)
    assert_close_in_norm(result.C, np.linalg.inv(K), rtol, scale=lengths(STEWART_L))


TENSION = np.array([0.2, 0.1, 1.0]) / np.linalg.norm([0.2, 0.1, 1.0])
COMPRESSION = np.array([0.05, 0.1, -1.0]) / np.linalg.norm([0.05, 0.1, -1.0])
#: Limit load [N] of the general Stewart pushed along COMPRESSION: the smallest eigenvalue
#: of the energy Hessian on the branch from rest reaches 0 between 2.500e4 and 2.505e4 N
#: (continuation of the reference in steps of 50 N).
COMPRESSION_LIMIT = 2.5e4


def energy_hessian(g, x, force, h=1e-4):
    """(6, 6) Hessian of 1/2 sum k (l - l0)^2 - f . dp in x = (dp, phi) [central FD]."""

    def energy(x):
        return 0.5 * g["k"] @ (displaced_leg_lengths(g, x) - g["lengths"]) ** 2 - force @ x[:3]

    E = np.eye(6) * h
    return np.array([[(energy(x + a + b) - energy(x + a - b) - energy(x - a + b)
                       + energy(x - a - b)) / (4 * h * h) for b in E] for a in E])  # fmt: skip


@pytest.mark.parametrize(
    ("direction", "magnitude"),
    [(TENSION, 1e3), (TENSION, 1e4), (TENSION, 1e5), (COMPRESSION, 1e3), (COMPRESSION, 1e4),
     (COMPRESSION, 0.8 * COMPRESSION_LIMIT)],
)  # fmt: skip
def test_stewart_statics_matches_an_independent_newton_solve(direction, magnitude):
    m = mech.stewart(**STEWART_POSES["general"])
    force = magnitude * direction
    expected = stewart_equilibrium(m.geometry, force)
    eq = solve_equilibrium(m.clm, m.q, m.frame, np.r_[force, 0.0, 0.0, 0.0])
    s = np.r_[1.0, 1.0, 1.0, STEWART_L, STEWART_L, STEWART_L]  # rotations as arcs [m]
    np.testing.assert_allclose(
        eq.displacement * s, expected * s, rtol=0, atol=STATICS_RTOL * np.linalg.norm(expected * s)
    )
    assert np.linalg.eigvalsh(energy_hessian(m.geometry, expected, force))[0] > 0  # stable


def test_stewart_statics_finds_no_equilibrium_past_the_limit_load():
    m = mech.stewart(**STEWART_POSES["general"])
    g, lam = m.geometry, {}
    for magnitude in (0.0, COMPRESSION_LIMIT):  # the branch from rest loses its stability
        force = magnitude * COMPRESSION
        lam[magnitude] = np.linalg.eigvalsh(
            energy_hessian(g, stewart_equilibrium(g, force), force)
        )[0]
    assert 0 < lam[COMPRESSION_LIMIT] < 0.05 * lam[0.0]
    force = 1.2 * COMPRESSION_LIMIT * COMPRESSION
    try:
        eq = solve_equilibrium(m.clm, m.q, m.frame, np.r_[force, 0.0, 0.0, 0.0])
    except EquilibriumError:
        return  # as documented: the branch from q_rest ends at the limit load
    lam_eq = np.linalg.eigvalsh(energy_hessian(g, eq.displacement, force))
    pytest.fail(
        f"solve_equilibrium returned an equilibrium at 1.2 x the limit load "
        f"(~{COMPRESSION_LIMIT:.4g} N): displacement {np.round(eq.displacement, 4).tolist()}, "
        f"smallest energy Hessian eigenvalue {lam_eq[0]:.4g} (< 0: unstable, another branch)"
    )


# ---------------------------------------------------------------- 3-RRR
@pytest.mark.parametrize("pose", [(0.0, 0.0, 0.0), (0.03, -0.02, 0.15), (-0.04, 0.05, -0.25)])
def test_3rrr_planar_compliance_and_rigid_out_of_plane_directions(pose):
    m = mech.rrr3(pose)
    result = compliance(m.clm, m.q, m.frame)
    C_ref = np.linalg.inv(mech.rrr3_planar_stiffness(m.geometry))
    assert_close_in_norm(
        result.C[np.ix_(PLANAR, PLANAR)], C_ref, HAND_RTOL, scale=lengths(RRR_L, PLANAR)
    )
    # the point closures hold the platform in the plane: dz, rx, ry are rigid
    np.testing.assert_allclose(result.C[OUT_OF_PLANE], 0.0, atol=HAND_RTOL * np.abs(C_ref).max())
    assert (result.rank, result.mobility, result.internal_mobilities) == (3, 3, 0)
    assert_same_span(result.rigid_directions, unit(*OUT_OF_PLANE))


# ---------------------------------------------------------------- 5-bar
@pytest.mark.parametrize("point", [(0.03, 0.35), (-0.08, 0.30), (0.10, 0.42)])
def test_fivebar_compliance_and_its_rigid_directions(point):
    m = mech.fivebar(point)
    result = compliance(m.clm, m.q, m.frame)
    C_ref = mech.fivebar_planar_compliance(m.geometry)
    block = result.C[np.ix_(PLANAR, PLANAR)]
    assert_close_in_norm(block[:2, :2], C_ref[:2, :2], HAND_RTOL, scale=lengths(FIVEBAR_L, [0, 1]))
    # rz, the rotation of distal link 0 carrying the frame, is compliant but tied to the
    # translation, rz = grad . (dx, dy): the in-plane block has rank 2, and the wrench
    # (fx, fy, mz) = (-grad, 1), doing no work on any admissible motion, moves nothing
    assert_close_in_norm(block, C_ref, HAND_RTOL, scale=lengths(FIVEBAR_L, PLANAR))
    np.testing.assert_allclose(result.C[OUT_OF_PLANE], 0.0, atol=HAND_RTOL * np.abs(C_ref).max())
    assert (result.rank, result.mobility, result.internal_mobilities) == (2, 2, 0)
    grad = C_ref[2, :2] @ np.linalg.inv(C_ref[:2, :2])
    idle = np.zeros(6)
    idle[PLANAR] = np.r_[-grad, 1.0] / np.linalg.norm(np.r_[-grad, 1.0])
    assert_same_span(result.rigid_directions, np.column_stack([unit(*OUT_OF_PLANE), idle]))


# ---------------------------------------------------------------- Delta
DELTA_POSITIONS = [(0.0, 0.0, -0.5), (0.08, -0.05, -0.45), (-0.1, 0.06, -0.6)]
K_ROD = 2e5  # axial stiffness of each rod [N/m]


@pytest.mark.parametrize("order", mech.CLOSURE_ORDERS)
@pytest.mark.parametrize("position", DELTA_POSITIONS)
def test_delta_with_rigid_rods_only_translates(position, order):
    m = mech.delta(position, closure_order=order)
    result = compliance(m.clm, m.q, m.frame)
    C_ref = mech.delta_translational_compliance(m.geometry)
    assert_close_in_norm(result.C[:3, :3], C_ref, HAND_RTOL, scale=lengths(DELTA_L, [0, 1, 2]))
    np.testing.assert_allclose(result.C[ROTATIONS], 0.0, atol=HAND_RTOL * np.abs(C_ref).max())
    # 3 platform translations + 6 rod spins, which move nothing
    assert (result.rank, result.mobility, result.internal_mobilities) == (3, 9, 6)
    assert_same_span(result.rigid_directions, unit(*ROTATIONS))


@pytest.mark.parametrize("order", mech.CLOSURE_ORDERS)
@pytest.mark.parametrize("position", DELTA_POSITIONS)
def test_delta_with_axial_rod_springs_matches_static_condensation(position, order):
    m = mech.delta(position, k_rod=K_ROD, closure_order=order)
    result = compliance(m.clm, m.q, m.frame)
    C_ref = mech.delta_sprung_compliance(m.geometry)
    assert_close_in_norm(result.C, C_ref, HAND_RTOL, scale=lengths(DELTA_L))
    assert (result.rank, result.mobility, result.internal_mobilities) == (6, 15, 6)
    # the two hand derivations agree: the translational block tends to the rigid-rod one,
    # the gap (rods in series with the arms) shrinking as 1 / k_rod
    rigid = mech.delta_translational_compliance(m.geometry)
    gaps = [
        np.abs(
            mech.delta_sprung_compliance(dict(m.geometry, k_rod=np.full(6, k)))[:3, :3] - rigid
        ).max()
        / np.abs(rigid).max()
        for k in (1e9, 1e10)
    ]
    assert gaps[0] < 1e-4
    np.testing.assert_allclose(gaps[0] / gaps[1], 10.0, rtol=0.02)


@pytest.mark.parametrize("k_rod", [None, K_ROD])
def test_delta_closure_order_does_not_change_the_compliance(k_rod):
    built = [
        mech.delta(DELTA_POSITIONS[1], k_rod=k_rod, closure_order=o) for o in mech.CLOSURE_ORDERS
    ]
    assert [b.clm.closures[0].name for b in built] == [
        "rod0_end<->platform_anchor0",
        "platform_anchor0<->rod0_end",
    ]
    np.testing.assert_array_equal(built[0].q, built[1].q)
    a, b = (compliance(d.clm, d.q, d.frame) for d in built)
    assert_close_in_norm(b.C, a.C, ORDER_RTOL, scale=lengths(DELTA_L))
    assert a.internal_mobilities == b.internal_mobilities == 6
