"""CaHyMan model files, joint/spring wiring, stiffness at M and the stiffness API."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pinocchio as pin
import pytest
from helpers import REPO

from cahyman_pin import api
from cahyman_pin.backends import registry
from cahyman_pin.model import CaHyManModel, cahyman_model
from cahyman_pin.params import DEFAULT_PARAMS
from cahyman_pin.urdf_builder import build_closure_yaml, build_urdf
from closedloop.elastostatics.compliance import compliance
from closedloop.elastostatics.equilibrium import frame_displacement
from closedloop.elastostatics.statics import solve_equilibrium
from closedloop.exceptions import InvalidInputError, JointLimitWarning
from closedloop.io.loader import load_urdf
from closedloop.kinematics.assembly import assemble
from closedloop.model.closed_loop import ClosedLoopModel

DEG = np.pi / 180.0
#: The paper's three tables: (alpha_1..3 [rad], alpha_4 [rad], s_4 [m]).
TABLES = {
    "table1": (np.array([90.0, 90.0, 90.0]) * DEG, 90.0 * DEG, 0.050),
    "table2": (np.array([30.0, 30.0, 30.0]) * DEG, 30.0 * DEG, 0.0),
    "table3": (np.array([45.0, 60.0, 75.0]) * DEG, 45.0 * DEG, 0.0),
}
#: Spring joints in a fixed order and their stiffness, from the reference model's table.
SPRING_VALUES = {
    **{f"alpha_{k}": 4.672e3 for k in (1, 2, 3)},
    **{f"b_{k}_axial": 2.625e6 for k in (1, 2, 3)},
    **{f"d_{k}_axial": 2.625e6 for k in (1, 2, 3)},
    "alpha_4": 0.876e3,
    "s_4": 0.697e6,
    "arm_axial": 2.625e6,
}
SPRING_JOINTS = tuple(SPRING_VALUES)
#: Symmetry of K relative to its largest entry: C is symmetrised, K = inv(C) loses
#: cond(C) ~ 1e7 times eps.
SYMMETRY_TOL = 1e-9
#: Same model from the committed files and in memory: same numbers up to rounding.
FILES_RTOL = 1e-12
#: Finite-difference compliance (central differences, step FD_STEP, closures solved to
#: 1e-15 m): truncation ~ FD_STEP^2 and rounding ~ 1e-16 / FD_STEP, both < 1e-8.
FD_STEP = 1e-6
FD_TOL = 1e-7
#: Nonlinear equilibrium under a 1e-3-scale wrench vs the linear C w: the geometric
#: nonlinearity is ~ deflection / size ~ 1e-8 / 0.1; the measured difference of two
#: assembled poses carries ~ 1e-16 m of rounding on a ~1e-9 m deflection.
EQUILIBRIUM_RTOL = 1e-5
WRENCH_SCALE = 1e-3
#: Absolute floor [m, rad] for components whose linear value is ~0: differences of two
#: assembled poses (coordinates ~0.4 m) carry a few 1e-16 of rounding.
ROUNDING_FLOOR = 2e-15
#: Fixed-point iteration stop: spring-force change relative to the spring forces (the
#: finite-difference Jacobian carries ~1e-10 of noise).
FIXED_POINT_RTOL = 1e-8
#: Virtual springs and K_s made STIFFENING times stiffer: their share of the compliance
#: shrinks by that factor (first order in 1/K); margin 2 for the second-order terms.
STIFFENING = 1e6
STIFFENING_MARGIN = 2.0


@pytest.fixture
def model(cahyman) -> CaHyManModel:
    """CaHyMan with the default parameters (the shared fixture, under this module's name)."""
    return cahyman


def scaled(C: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """C in units of ref's diagonal (dimensionless): D^-1/2 C D^-1/2, D = diag(ref)."""
    d = 1.0 / np.sqrt(np.diag(ref))
    return C * np.outer(d, d)


# ------------------------------------------------------------------ files and wiring
def test_committed_files_equal_generator_output():
    assert (REPO / "urdf" / "cahyman.urdf").read_text() == build_urdf(DEFAULT_PARAMS)
    assert (REPO / "urdf" / "cahyman.yaml").read_text() == build_closure_yaml(DEFAULT_PARAMS)


def test_committed_files_load_to_the_same_model(model):
    clm = load_urdf(REPO / "urdf" / "cahyman.urdf", REPO / "urdf" / "cahyman.yaml")
    np.testing.assert_array_equal(clm.stiffness, model.clm.stiffness)
    alpha, alpha4, s4 = TABLES["table3"]
    q = model.assemble(alpha, alpha4, s4)
    C_file = compliance(clm, q, "M").C
    np.testing.assert_allclose(C_file, compliance(model.clm, q, "M").C, rtol=FILES_RTOL)


def test_joint_and_frame_names(model):
    m = model.clm.model
    legs = [f"{j}_{k}" for k in (1, 2, 3) for j in ("alpha", "c", "s", "d")]
    axial = [f"{j}_{k}_axial" for k in (1, 2, 3) for j in ("b", "d")]
    expected = {*legs, *axial, "plate", "alpha_4", "s_4", "arm_axial"}
    assert set(m.names[1:]) == expected
    assert (m.nq, m.nv) == (28, 27)
    assert m.joints[m.getJointId("plate")].shortname() == "JointModelFreeFlyer"
    for frame in ("M", "H", "Q", "H_1", "H_2", "H_3", "ball_1", "ball_2", "ball_3"):
        assert m.existFrame(frame), frame
    assert model.clm.actuated == ("alpha_1", "alpha_2", "alpha_3", "alpha_4", "s_4")
    assert [c.kind for c in model.clm.closures] == ["3d"] * 6


def test_springs_as_in_the_reference_model(model):
    clm = model.clm
    expected = np.zeros(clm.model.nv)
    for name, value in SPRING_VALUES.items():
        expected[clm.joint_v_slice(name)] = value
    np.testing.assert_array_equal(clm.stiffness, expected)


def test_visual_geometry_covers_every_body(model):
    vm = model.clm.visual_model
    links = {vm.geometryObjects[i].name.rsplit("_", 1)[0] for i in range(vm.ngeoms)}
    bodies = {"fixed_plate", "mobile_plate", "arm", "telescope", "M", "Q"}
    bodies |= {f"{n}_{k}" for k in (1, 2, 3) for n in ("crank_b", "coupler", "bar", "crank_d")}
    assert bodies <= links


# ------------------------------------------------------------------ stiffness at M
@pytest.mark.parametrize("table", sorted(TABLES))
def test_K_symmetric_positive_definite_full_rank(table):
    r = api.stiffness(*TABLES[table])
    assert r.indices.rank == 6
    K = r.K
    np.testing.assert_allclose(K, K.T, rtol=0, atol=SYMMETRY_TOL * np.abs(K).max())
    assert np.all(np.linalg.eigvalsh(K) > 0.0)
    np.testing.assert_allclose(K @ r.C, np.eye(6), rtol=0, atol=SYMMETRY_TOL)
    np.testing.assert_allclose(r.det_K, np.linalg.det(K), rtol=1e-9)


def test_full_rank_at_random_poses(model):
    rng = np.random.default_rng(5)
    for _ in range(20):
        alpha = rng.uniform(30.0, 90.0, 3) * DEG
        r = api.stiffness(alpha, rng.uniform(0.0, 90.0) * DEG, rng.uniform(0.0, 0.05))
        assert r.indices.rank == 6
        assert np.all(np.linalg.eigvalsh(r.C) > 0.0)


class SpringCoordinates:
    """The 12 spring coordinates x as independent variables, passive joints solved.

    An independent route to the compliance: every spring coordinate is prescribed,
    closedloop.kinematics.assembly closes the loops, poses are differentiated numerically.
    """

    def __init__(self, m: CaHyManModel, q_rest: np.ndarray):
        tree = m.clm.model
        self.clm = ClosedLoopModel(tree, m.clm.closures, SPRING_JOINTS, name="prescribed")
        self.q_rest = q_rest
        self.x_rest = q_rest[self.clm.actuated_q_indices]
        self.k = np.array(list(SPRING_VALUES.values()))
        self.ids = [tree.getFrameId(f) for f in ("M", "H")]

    def placements(self, x: np.ndarray) -> list[pin.SE3]:
        q = assemble(self.clm, x, self.q_rest, tol=1e-15).q
        d = self.clm.model.createData()
        pin.framesForwardKinematics(self.clm.model, d, q)
        return [d.oMf[i].copy() for i in self.ids]

    def twist(self, a: pin.SE3, b: pin.SE3) -> np.ndarray:
        """Finite twist from b to a: (translation [m], world rotation vector [rad])."""
        return np.r_[a.translation - b.translation, pin.log3(a.rotation @ b.rotation.T)]

    def jacobians(self, x: np.ndarray) -> list[np.ndarray]:
        """(6, 12) central-difference Jacobians of M and H (world axes)."""
        J = [np.zeros((6, x.size)) for _ in self.ids]
        for i in range(x.size):
            e = np.zeros(x.size)
            e[i] = FD_STEP
            plus, minus = self.placements(x + e), self.placements(x - e)
            for Jf, p, m in zip(J, plus, minus, strict=True):
                Jf[:, i] = self.twist(p, m) / (2 * FD_STEP)
        return J

    def equilibrium(self, wrench: np.ndarray) -> list[np.ndarray]:
        """Finite twists of M and H at the nonlinear equilibrium under a dead wrench at M.

        Virtual work: k (x - x_rest) = J_M(x)^T w, J_M at the deformed pose (fixed point).
        """
        x = self.x_rest.copy()
        for _ in range(20):
            x_new = self.x_rest + self.jacobians(x)[0].T @ wrench / self.k
            change, size = np.abs(x_new - x) * self.k, np.abs(x_new - self.x_rest) * self.k
            x = x_new
            if np.max(change) <= FIXED_POINT_RTOL * np.max(size):
                break
        else:
            raise AssertionError("fixed point did not converge")
        rest, loaded = self.placements(self.x_rest), self.placements(x)
        return [self.twist(a, b) for a, b in zip(loaded, rest, strict=True)]


@pytest.mark.parametrize("table", sorted(TABLES))
def test_compliance_matches_finite_differences_of_assembly(model, table):
    r = api.stiffness(*TABLES[table])
    sc = SpringCoordinates(model, r.details["q"])
    J_M, J_H = sc.jacobians(sc.x_rest)
    C_fd = (J_M / sc.k) @ J_M.T
    np.testing.assert_allclose(scaled(C_fd, r.C), scaled(r.C, r.C), rtol=0, atol=FD_TOL)
    C_platform_fd = (J_H / sc.k) @ J_M.T
    np.testing.assert_allclose(
        scaled(C_platform_fd, r.C), scaled(r.C_platform, r.C), rtol=0, atol=FD_TOL
    )


LOADS = {"force": [1, 1, 1, 0, 0, 0], "torque": [0, 0, 0, 1, 1, 1], "both": [1] * 6}


def assert_twists_close(got: np.ndarray, linear: np.ndarray) -> None:
    """Finite twist (6,) vs linear twist, translation and rotation parts separately."""
    for part in (slice(0, 3), slice(3, 6)):
        tol = EQUILIBRIUM_RTOL * np.linalg.norm(linear[part]) + ROUNDING_FLOOR
        np.testing.assert_allclose(got[part], linear[part], rtol=0, atol=tol)


@pytest.mark.parametrize("table", sorted(TABLES))
@pytest.mark.parametrize("load", sorted(LOADS))
def test_nonlinear_equilibrium_matches_linear_deflection(model, table, load):
    r = api.stiffness(*TABLES[table])
    w = WRENCH_SCALE * np.array(LOADS[load], dtype=float)
    twist_M, twist_H = SpringCoordinates(model, r.details["q"]).equilibrium(w)
    d = r.deflection(w)
    assert_twists_close(twist_M, d.M)
    assert_twists_close(twist_H, d.H)


@pytest.mark.parametrize("table", sorted(TABLES))
@pytest.mark.parametrize("load", sorted(LOADS))
def test_statics_solver_matches_linear_deflection(model, table, load):
    r = api.stiffness(*TABLES[table])
    q = r.details["q"]
    w = WRENCH_SCALE * np.array(LOADS[load], dtype=float)
    at_max_stroke = TABLES[table][2] >= model.params.s4_max
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", JointLimitWarning)
        eq = solve_equilibrium(model.clm, q, "M", w)
    # at its full stroke the telescope is pulled past its limit: flagged, by a hair
    assert (
        bool(eq.limits_violated)
        == bool(caught)
        == (at_max_stroke and eq.joint_deflection[model.clm.joint_v_slice("s_4")][0] > 0)
    )
    d = r.deflection(w)
    assert_twists_close(eq.displacement, d.M)
    assert_twists_close(frame_displacement(model.clm, eq.q, q, "H"), d.H)


def test_stiff_virtual_springs_converge_to_motors_only(model):
    alpha, alpha4, s4 = TABLES["table3"]
    p = DEFAULT_PARAMS
    stiff = CaHyManModel(
        p.replace(**{n: getattr(p, n) * STIFFENING for n in ("K_b", "K_d", "K_4", "K_s")})
    )
    q = stiff.assemble(alpha, alpha4, s4)
    motors = {f"alpha_{k}": p.K_T for k in (1, 2, 3)} | {"alpha_4": p.K_T4}
    virtual = [n for n in SPRING_JOINTS if n not in motors]
    C_locked = compliance(model.clm.with_springs(motors, locked=virtual), q, "M").C
    C_stiff = compliance(stiff.clm, q, "M").C
    C_default = compliance(model.clm, q, "M").C
    ref = C_default  # its diagonal sets the units of the comparison
    assert np.linalg.matrix_rank(C_locked, tol=1e-6 * np.abs(C_locked).max()) == 4
    assert np.linalg.matrix_rank(C_stiff, tol=1e-6 * np.abs(C_stiff).max()) == 4
    # the virtual springs add compliance linearly in 1/K: 1e6 times stiffer leaves 1e-6
    # of their contribution at the default values
    default_gap = np.abs(scaled(C_default, ref) - scaled(C_locked, ref)).max()
    assert default_gap > 1e-3  # the default springs matter: the comparison can fail
    np.testing.assert_allclose(
        scaled(C_stiff, ref),
        scaled(C_locked, ref),
        rtol=0,
        atol=STIFFENING_MARGIN / STIFFENING * default_gap,
    )


def test_printed_K_s_adds_its_compliance_along_the_arm():
    # s_4 is the last joint before M and slides along w: a softer K_s adds
    # (1/K_s' - 1/K_s) w w^T to the translation block and nothing else
    alpha, alpha4, s4 = TABLES["table3"]
    r_a = api.stiffness(alpha, alpha4, s4)
    r_p = api.stiffness(alpha, alpha4, s4, params=DEFAULT_PARAMS.with_ks("printed"))
    w = r_a.pose.R_M[:, 0]
    extra = np.zeros((6, 6))
    extra[:3, :3] = (1 / 0.697 - 1 / 0.697e6) * np.outer(w, w)
    np.testing.assert_allclose(r_p.C - r_a.C, extra, rtol=0, atol=1e-9 * np.abs(extra).max())


# ------------------------------------------------------------------ API
def test_deflection_is_C_times_wrench():
    r = api.stiffness(*TABLES["table2"])
    w = np.array([1.0, -2.0, 0.5, 0.1, 0.2, -0.3])
    d = r.deflection(w)
    np.testing.assert_allclose(d.M, r.C @ w, rtol=1e-14)
    np.testing.assert_allclose(d.H, r.C_platform @ w, rtol=1e-14)
    with pytest.raises(InvalidInputError, match="6 finite"):
        r.deflection([1.0, 2.0])


def test_result_is_json_ready_and_read_only():
    r = api.stiffness(*TABLES["table1"])
    out = json.loads(json.dumps(r.to_dict()))
    assert {"K", "C", "det_K", "platform", "inputs", "units"} <= set(out)
    assert np.array(out["K"]).shape == (6, 6)
    with pytest.raises(ValueError, match="read-only"):
        r.C[0, 0] = 1.0


def test_unknown_backend_lists_the_choices():
    with pytest.raises(InvalidInputError, match="generic"):
        api.stiffness(*TABLES["table1"], backend="no_such_backend")


def test_a_registered_backend_is_used(monkeypatch):
    C = np.diag([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])

    def diagonal(params, alpha, alpha4, s4):
        from cahyman_pin.model import closed_form_pose

        return registry.BackendResult(C=C, pose=closed_form_pose(alpha, alpha4, s4, params))

    monkeypatch.setitem(registry._BACKENDS, "diagonal", diagonal)
    r = api.stiffness(*TABLES["table3"], backend="diagonal")
    np.testing.assert_array_equal(r.C, C)
    assert r.backend == "diagonal"
    assert r.deflection(np.ones(6)).H is None
    np.testing.assert_allclose(r.det_K, 1 / 720.0)


def test_models_are_cached_per_parameter_set():
    assert cahyman_model(DEFAULT_PARAMS) is cahyman_model(DEFAULT_PARAMS.replace())
    other = DEFAULT_PARAMS.replace(b=0.09)
    assert cahyman_model(other) is not cahyman_model(DEFAULT_PARAMS)
    assert cahyman_model(other).params.b == 0.09


def test_the_sweeps_assembly_of_checked_inputs_is_assemble():
    """assemble_validated (the sweeps' assembly, inputs checked a chunk at a time) gives
    assemble's configuration, from the closed form and from a warm start, and leaves the
    start as it was."""
    m = cahyman_model()
    alpha, alpha4, s4 = np.deg2rad([50.0, 65.0, 70.0]), np.deg2rad(30.0), 0.02
    inputs = np.array([*alpha, alpha4, s4])
    ref = m.assemble(alpha, alpha4, s4, full_output=True, jacobian=True)
    got = m.assemble_validated(inputs, jacobian=True)
    np.testing.assert_array_equal(got.q, ref.q)
    np.testing.assert_array_equal(got.closure[1], ref.closure[1])
    start = m.assemble(alpha + 0.01, alpha4, s4)
    kept = start.copy()
    warm = m.assemble_validated(inputs, start)
    np.testing.assert_array_equal(warm.q, m.assemble(alpha, alpha4, s4, q0=start))
    np.testing.assert_array_equal(start, kept)
    assert warm.residual <= 1e-12 and warm.iterations >= 1
