"""Tests of the paper's closed form as published, its documented choices and switches."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from helpers import assert_close_in_norm
from scipy.spatial.transform import Rotation

from cahyman_pin import geometry
from cahyman_pin.backends.consistent import consistent_compliance
from cahyman_pin.backends.published import (
    CHOICES,
    PublishedOptions,
    published_stiffness,
)
from cahyman_pin.params import DEFAULT_PARAMS, K_S_PRINTED
from closedloop.exceptions import InvalidInputError, SingularConfigurationError

TABLE_POSES = {
    "table1": (np.deg2rad([90.0, 90.0, 90.0]), np.deg2rad(90.0), 0.050),
    "table2": (np.deg2rad([30.0, 30.0, 30.0]), np.deg2rad(30.0), 0.0),
    "table3": (np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.0),
}
T3 = TABLE_POSES["table3"]
#: Masses [kg] to exercise the weight terms of eq. (11).
MASSES = {"m_HQ": 0.2, "m_QM": 0.3, "m_MM2": 0.1, "m_M4": 0.5, "m_M5": 0.4}
LOAD = np.ones(6)

# Hand-written entries against the implementation: a few operations on numbers of order
# one, so they agree to round-off.
ENTRY_RTOL = 1e-13
# Central differences (step 1e-6) of smooth kinematics: error ~1e-10 relative.
STEP = 1e-6
FD_RTOL = 1e-7
FD_ATOL = 1e-9
# The consistent switches reproduce the consistent backend up to round-off in a chain of
# a few 6x6 products and inverses (condition numbers up to ~1e7 with mixed units).
BACKEND_RTOL = 1e-8
# A switch "changes the result" if the compliance moves by more than this, relative.
CHANGE_MIN = 1e-6


def rel_change(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


def test_shapes_of_every_matrix():
    r = published_stiffness(*T3)
    shapes = {
        "R_PAR": (3, 3), "R_SP": (6, 6), "Kss": (3, 3), "As": (3, 3), "K_SER": (6, 6),
        "C_SER": (6, 6), "M_FT": (6, 6), "M_FN": (6, 6), "K_pkk": (3, 3, 3),
        "C_pkk": (3, 3, 3), "K_P": (6, 6), "C_P": (6, 6), "leg_compliance": (3, 2, 2),
        "A_d": (6, 6), "C_PAR": (6, 6), "K_PAR": (6, 6), "C_PAR_M": (6, 6), "C": (6, 6),
        "K": (6, 6),
    }  # fmt: skip
    for name, shape in shapes.items():
        assert getattr(r, name).shape == shape, name
        assert np.all(np.isfinite(getattr(r, name))), name
    with pytest.raises(ValueError):
        r.C[0, 0] = 0.0  # read-only


def rz_ry_rz(phi: float, theta: float, psi: float) -> np.ndarray:
    """Rz(theta) Ry(pi/2 - phi) Rz(psi), the model document's reading of eq. (6)."""
    return (
        Rotation.from_euler("z", theta).as_matrix()
        @ Rotation.from_euler("y", np.pi / 2 - phi).as_matrix()
        @ Rotation.from_euler("z", psi).as_matrix()
    )


def test_R_PAR_is_rz_ry_rz_and_R_SP_embeds_it():
    rng = np.random.default_rng(2)
    r = published_stiffness(*T3)
    pose = r.pose
    np.testing.assert_allclose(r.R_PAR, rz_ry_rz(pose.phi, pose.theta, pose.psi), atol=ENTRY_RTOL)
    np.testing.assert_array_equal(r.R_SP[:3, :3], r.R_PAR)
    np.testing.assert_array_equal(r.R_SP[3:, 3:], np.eye(3))
    np.testing.assert_array_equal(r.R_SP[:3, 3:], np.zeros((3, 3)))
    # and eq. (6) with explicit sines at random angles
    from cahyman_pin.backends.published import r_par

    for _ in range(5):
        f, t, s = rng.uniform(-3, 3, 3)
        np.testing.assert_allclose(r_par(f, t, s), rz_ry_rz(f, t, s), atol=ENTRY_RTOL)


def test_Kss_entries_at_table3():
    p = DEFAULT_PARAMS
    s4 = T3[2]
    K = published_stiffness(*T3).Kss
    kt = p.K_T4 / (p.L + s4)
    c = s = np.sqrt(0.5)  # alpha_4 = 45 deg
    expected = [[p.K_4 * c, K_S_PRINTED * c, -kt * s], [p.K_4 * s, K_S_PRINTED * s, kt * c],
                [0.0, 0.0, p.K_T4]]  # fmt: skip
    np.testing.assert_allclose(K, expected, rtol=ENTRY_RTOL)


def test_As_is_the_planar_arm_jacobian():
    """eq. (8): d(x, z, angle)/d(L, s_4, alpha_4) of the planar tip x = (L + s_4) cos alpha_4."""
    p = DEFAULT_PARAMS
    _, a4, s4 = T3

    def tip(L, s, a):
        return np.array([(L + s) * np.cos(a), (L + s) * np.sin(a), a])

    x0 = np.array([p.L, s4, a4])
    J = np.column_stack([(tip(*(x0 + STEP * e)) - tip(*(x0 - STEP * e))) / (2 * STEP)
                         for e in np.eye(3)])  # fmt: skip
    np.testing.assert_allclose(published_stiffness(*T3).As, J, rtol=FD_RTOL, atol=FD_ATOL)


def test_M_FN_entries():
    r_p = DEFAULT_PARAMS.r_p
    M = published_stiffness(*T3).M_FN
    s120, c120 = np.sqrt(3) / 2, -0.5
    s240, c240 = -np.sqrt(3) / 2, -0.5
    np.testing.assert_allclose(M[:, 0], [0, 1, 0, 0, 0, r_p], atol=ENTRY_RTOL)  # R_x1
    np.testing.assert_allclose(M[:, 2], [s120, c120, 0, 0, 0, r_p], rtol=ENTRY_RTOL)  # R_x2
    np.testing.assert_allclose(  # R_z3
        M[:, 5], [0, 0, 1, r_p * s240, r_p * c240, 0], rtol=ENTRY_RTOL, atol=ENTRY_RTOL
    )


def test_M_FT_is_the_negated_transport_with_the_load_in_an_arm_frame():
    """Finding: eq. (10) = -[[Ra, 0], [r x Ra, Ra]], Ra = Ry(pi/2 - alpha_4), r = M - H.

    Its 3x3 blocks have determinant -1 because of the reaction sign, not a typo in one entry.
    """
    p = DEFAULT_PARAMS
    _, a4, s4 = T3
    M_FT = published_stiffness(*T3).M_FT
    Ra = Rotation.from_euler("y", np.pi / 2 - a4).as_matrix()
    r = np.array([(p.L + s4) * np.cos(a4), 0.0, p.HQ + (p.L + s4) * np.sin(a4)])  # plate axes
    rx = np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
    expected = -np.block([[Ra, np.zeros((3, 3))], [rx @ Ra, Ra]])
    np.testing.assert_allclose(M_FT, expected, atol=ENTRY_RTOL)
    assert np.linalg.det(M_FT[:3, :3]) == pytest.approx(-1.0, rel=ENTRY_RTOL)


def test_weight_terms_add_the_weight_over_the_nonzero_load_components():
    p = DEFAULT_PARAMS.replace(**MASSES)
    _, a4, s4 = T3
    weight = 9.81 * sum(MASSES.values())
    arm = 9.81 * np.cos(a4) * (-0.4 * (0.5 * s4 + p.L) - 0.5 * 0.5 * p.L - 0.1 * p.L)
    no_w = published_stiffness(*T3, p, PublishedOptions(weights=False), load=LOAD).M_FT
    for load, share in ((LOAD, 1.0), (np.array([1.0, 1, 1, 0, 0, 0]), 0.5)):
        M_FT = published_stiffness(*T3, p, load=load).M_FT
        extra = (M_FT - no_w) @ load
        np.testing.assert_allclose(extra, [0, 0, share * weight, 0, share * arm, 0], atol=1e-12)


def test_K_pkk_and_C_pkk_entries_at_table3_leg1():
    p = DEFAULT_PARAMS
    c, h, b = p.a, p.h, p.b
    a = np.deg2rad(45.0)
    r = published_stiffness(*T3)
    r_b = (c / 2) * np.sin(a) + h * np.cos(a)  # gamma = 0
    r_d = -(c / 2) * np.sin(a) + h * np.cos(a)  # beta = 0
    np.testing.assert_allclose(r.K_pkk[0][:, 1], [p.K_d, 0.0, -p.K_d * r_d], atol=ENTRY_RTOL)
    assert r.K_pkk[0][2, 0] == pytest.approx(p.K_b * r_b, rel=ENTRY_RTOL)
    assert r.C_pkk[0][1, 0] == pytest.approx((3 * c - 2 * h) / (2 * c) * np.sin(a), rel=ENTRY_RTOL)
    assert r.C_pkk[0][0, 2] == pytest.approx(-b * (3 * c - 2 * h) / (2 * c), rel=ENTRY_RTOL)


def test_first_2x2_drops_the_leg_motors():
    p = DEFAULT_PARAMS
    soft = p.replace(K_T=p.K_T / 10)
    base = published_stiffness(*T3, p).C
    np.testing.assert_array_equal(published_stiffness(*T3, soft).C, base)
    for leg_block in ("3x3", "consistent"):
        o = PublishedOptions(leg_block=leg_block)
        c_nom = published_stiffness(*T3, p, o).C
        assert rel_change(published_stiffness(*T3, soft, o).C, c_nom) > CHANGE_MIN


def test_beta_equal_alpha_makes_the_printed_leg_blocks_singular():
    o = PublishedOptions(beta_gamma="alpha")
    with pytest.raises(SingularConfigurationError, match=r"K_p1 \(first 2x2\)"):
        published_stiffness(*T3, options=o)
    with pytest.raises(SingularConfigurationError, match="K_p22"):  # leg 2 at 60 deg
        published_stiffness(*T3, options=dataclasses.replace(o, leg_block="3x3"))
    published_stiffness(*TABLE_POSES["table2"], options=dataclasses.replace(o, leg_block="3x3"))


def test_printed_A_d_reproduces_x_H_and_z_H_and_is_singular_at_tables_1_and_2():
    p = DEFAULT_PARAMS
    r = published_stiffness(*T3, options=PublishedOptions(a_d="printed"))
    y, z = p.b * np.cos(T3[0]), p.b * np.sin(T3[0]) + p.h  # ball k in the plane of leg k
    v = np.ravel(np.column_stack([y, z]))  # (y1, z1, y2, z2, y3, z3), pose coordinates
    np.testing.assert_allclose(r.A_d[[0, 2]] @ v, r.pose.H[[0, 2]], rtol=ENTRY_RTOL)
    for case, divisor in (("table1", "Delta y_1"), ("table2", "C_psi")):
        with pytest.raises(SingularConfigurationError, match=divisor):
            published_stiffness(*TABLE_POSES[case], options=PublishedOptions(a_d="printed"))


def test_A_d_in_paper_angles_matches_finite_differences_of_plate_pose():
    p = DEFAULT_PARAMS
    alpha = T3[0]
    A_d = published_stiffness(*T3, options=PublishedOptions(a_d="jacobian_euler")).A_d
    for k in range(3):
        da = np.zeros(3)
        da[k] = STEP
        pp, pm = geometry.plate_pose(alpha + da, p), geometry.plate_pose(alpha - da, p)
        fd = np.concatenate([pp.H - pm.H, [pp.phi - pm.phi, pp.theta - pm.theta, pp.psi - pm.psi]])
        dv = np.zeros(6)
        dv[2 * k : 2 * k + 2] = p.b * np.array([-np.sin(alpha[k]), np.cos(alpha[k])])
        np.testing.assert_allclose(A_d @ dv, fd / (2 * STEP), rtol=FD_RTOL, atol=FD_ATOL)
    with pytest.raises(SingularConfigurationError, match="phi"):
        published_stiffness(*TABLE_POSES["table1"], options=PublishedOptions(a_d="jacobian_euler"))


@pytest.mark.parametrize("case", sorted(TABLE_POSES))
def test_consistent_switches_reproduce_the_consistent_backend(case):
    r = published_stiffness(*TABLE_POSES[case], options=PublishedOptions.consistent())
    C = consistent_compliance(*TABLE_POSES[case])
    assert_close_in_norm(r.C, C, BACKEND_RTOL)
    np.testing.assert_allclose(r.K @ C, np.eye(6), atol=BACKEND_RTOL)


def test_choices_listed_and_every_switch_documented():
    assert len(CHOICES) >= 8
    assert all(isinstance(p, str) and isinstance(c, str) and p and c for p, c in CHOICES)
    text = " ".join(c for _, c in CHOICES)
    for f in dataclasses.fields(PublishedOptions):
        assert f.name in text, f.name
    for item in range(1, 9):
        assert any(f"damage {item})" in place for place, _ in CHOICES), item


#: Every non-default value of every switch that runs at Table 3's pose (beta_gamma="alpha"
#: raises there, see test_beta_equal_alpha_makes_the_printed_leg_blocks_singular).
NON_DEFAULT = {
    "ks": ["params"],
    "arm_rotation_axis": ["+y_p"],
    "serial_form": ["series"],
    "serial_frame": ["world"],
    "lever_arm": [True],
    "weights": [False],
    "beta_gamma": [],
    "leg_block": ["3x3", "consistent"],
    "a_d": ["jacobian_euler", "printed"],
    "m_fn": ["consistent"],
    "m_ft": ["transport"],
}
SWITCHES = [(f.name, v) for f in dataclasses.fields(PublishedOptions) for v in NON_DEFAULT[f.name]]


@pytest.mark.parametrize(("name", "value"), SWITCHES)
def test_each_switch_changes_the_result(name, value):
    p = DEFAULT_PARAMS.replace(**MASSES)
    base = published_stiffness(*T3, p, load=LOAD).C
    changed = published_stiffness(*T3, p, PublishedOptions(**{name: value}), load=LOAD).C
    assert rel_change(changed, base) > CHANGE_MIN


def test_switches_without_effect_where_they_should_have_none():
    p = DEFAULT_PARAMS
    base = published_stiffness(*TABLE_POSES["table1"]).C
    # no masses: no weight terms
    same = published_stiffness(*TABLE_POSES["table1"], p, PublishedOptions(weights=False))
    np.testing.assert_array_equal(same.C, base)
    # plate parallel to the base and not turned: R_PAR = I, so the frame of K_SER is moot
    world = published_stiffness(*TABLE_POSES["table1"], p, PublishedOptions(serial_frame="world"))
    np.testing.assert_allclose(world.C, base, atol=ENTRY_RTOL * np.abs(base).max())


def test_displacement_and_bad_input():
    r = published_stiffness(*T3, load=LOAD)
    np.testing.assert_array_equal(r.displacement(), r.C @ LOAD)
    with pytest.raises(InvalidInputError, match="load"):
        published_stiffness(*T3).displacement()
    with pytest.raises(InvalidInputError, match="load"):
        published_stiffness(*T3, load=np.ones(5))
    with pytest.raises(InvalidInputError, match="one pose"):
        published_stiffness(np.ones((2, 3)), np.ones(2), 0.0)
    with pytest.raises(InvalidInputError, match="alpha4"):
        published_stiffness(T3[0], np.nan, 0.0)
    with pytest.raises(InvalidInputError, match="a_d"):
        PublishedOptions(a_d="garbled")
    with pytest.raises(InvalidInputError, match="lever_arm"):
        PublishedOptions(lever_arm=1)
