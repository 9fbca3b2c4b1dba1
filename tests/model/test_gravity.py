"""Gravity and payloads as preloads: sag and tangent compliance against independent solves."""

import warnings

import mechanisms as mech
import numpy as np
import pinocchio as pin
import pytest
import scipy.optimize
from helpers import assert_close_in_norm

import closedloop as cl
from closedloop.elastostatics.equilibrium import frame_displacement
from closedloop.io.loader import load_urdf
from closedloop.model.gravity import GravityLoad, Payload

G = np.array([0.0, 0.0, -9.81])  # m/s^2
UR5_K = 1e3  # N m/rad: every joint, soft enough for a visible sag
UR5_POSES = (
    np.array([0.0, -1.0, 1.5, -0.5, 1.2, 0.3]),
    np.array([0.4, -0.6, 0.9, -1.2, -1.0, 0.8]),
)
#: Newton on K (q - q0) + G(q) = 0 and the engine both converge to rounding; the
#: reference's dG/dq by central differences (step 1e-6 rad) carries ~1e-10 relative,
#: amplified by the condition of K + dG/dq (~10): 1e-7 leaves a wide margin.
RTOL_UR5 = 1e-7
#: Finite differences of the nonlinear equilibrium: central, wrench step H_WRENCH; the
#: truncation error is O(h^2 |d3 q / dw3|) ~ 1e-8 relative here, far below 1e-5.
RTOL_FD = 1e-5
H_WRENCH = 1e-2  # N or N m


@pytest.fixture(scope="module")
def soft_ur5(ur5_urdf):
    """The UR5 with UR5_K on every joint."""
    return load_urdf(ur5_urdf, joint_stiffness=UR5_K)


def _gravity_torques(model, q):
    model.gravity = pin.Motion(np.r_[G, 0, 0, 0])
    return pin.computeGeneralizedGravity(model, model.createData(), q)


def _ur5_reference(clm, q0):
    """q_eq from Newton on K (q - q0) + G(q) = 0, and J (K + dG/dq)^-1 J^T there, with
    Pinocchio's generalised gravity and central differences for dG/dq."""
    model, K = pin.Model(clm.model), UR5_K * np.eye(6)

    def dG(q, h=1e-6):
        cols = [(_gravity_torques(model, q + h * e) - _gravity_torques(model, q - h * e)) / (2 * h)
                for e in np.eye(6)]  # fmt: skip
        return np.array(cols).T

    q = q0.copy()
    for _ in range(50):
        r = K @ (q - q0) + _gravity_torques(model, q)
        if np.max(np.abs(r)) < 1e-12:
            break
        q = q - np.linalg.solve(K + dG(q), r)
    data = model.createData()
    J = pin.computeFrameJacobian(model, data, q, model.getFrameId("tool0"), pin.LOCAL_WORLD_ALIGNED)
    return q, J @ np.linalg.solve(K + dG(q), J.T)


@pytest.mark.parametrize("pose", [0, 1])
def test_ur5_sag_and_tangent_compliance_under_its_own_weight(soft_ur5, pose):
    clm, q0 = soft_ur5, UR5_POSES[pose]
    q_ref, C_ref = _ur5_reference(clm, q0)
    res = cl.compliance(clm, q0, "tool0", gravity=G)
    np.testing.assert_allclose(res.q, q_ref, rtol=0, atol=RTOL_UR5 * np.abs(q_ref - q0).max())
    assert_close_in_norm(res.C, C_ref, RTOL_UR5)
    sag = frame_displacement(clm, q_ref, q0, "tool0")
    assert_close_in_norm(res.sag, sag, RTOL_UR5)
    assert np.linalg.norm(sag[:3]) > 1e-3  # m: a real sag at 1e3 N m/rad
    assert_close_in_norm(res.spring_forces, UR5_K * (q_ref - q0), RTOL_UR5)
    doc = res.to_dict()
    assert doc["weight"]["gravity_m_s2"] == G.tolist() and len(doc["sag"]) == 6
    base = clm.model.inertias[0].mass  # the UR5's base link, 4 kg: fixed, it loads no spring
    assert base > 1.0
    moving = sum(I.mass for I in clm.model.inertias) - base
    np.testing.assert_allclose(doc["weight"]["mass_kg"], moving, rtol=1e-12)


def _equilibrium_displacements(clm, q0, frame, gravity, payloads, w0):
    """(6, 6) central finite differences of the frame's equilibrium pose per wrench unit."""
    base = cl.solve_equilibrium(clm, q0, frame, w0, gravity=gravity, payloads=payloads)
    cols = []
    for e in np.eye(6):
        plus, minus = (
            cl.solve_equilibrium(
                clm, q0, frame, w0 + s * H_WRENCH * e, gravity=gravity, payloads=payloads
            )
            for s in (1.0, -1.0)
        )
        d = frame_displacement(clm, plus.q, base.q, frame) - frame_displacement(
            clm, minus.q, base.q, frame
        )
        cols.append(d / (2 * H_WRENCH))
    return base, np.array(cols).T


def test_fourbar_with_a_heavy_coupler_matches_finite_differences(fourbar):
    # 5 kg on the coupler, 0.1 m off its frame: the loop multipliers carry the weight,
    # and their curvature term changes the compliance (checked below against no gravity)
    clm, q0 = fourbar
    payloads = [Payload(5.0, "coupler_link", np.array([0.05, 0.0, 0.1]))]
    res = cl.compliance(clm, q0, "P", gravity=G, payloads=payloads)
    base, C_fd = _equilibrium_displacements(clm, q0, "P", G, payloads, np.zeros(6))
    np.testing.assert_allclose(res.q, base.q, rtol=0, atol=1e-12)
    assert_close_in_norm(res.C, C_fd, RTOL_FD)
    unloaded = cl.compliance(clm, q0, "P")
    assert np.abs(res.C - unloaded.C).max() > 1e3 * RTOL_FD * np.abs(unloaded.C).max()
    assert np.abs(base.multipliers).max() > 1.0  # N: the loop carries part of the weight


@pytest.mark.parametrize("table", [0, 1, 2])
def test_cahyman_with_masses_matches_finite_differences(table):
    # the paper's five masses (0.5 kg each, an illustration) at the three table poses
    from cahyman_pin.model import CaHyManModel
    from cahyman_pin.paper.data import TABLE_POSES
    from cahyman_pin.params import DEFAULT_PARAMS

    masses = dict.fromkeys(("m_HQ", "m_QM", "m_MM2", "m_M4", "m_M5"), 0.5)
    model = CaHyManModel(DEFAULT_PARAMS.replace(**masses))
    q0 = model.assemble(*TABLE_POSES[table].si)
    with warnings.catch_warnings():  # a stroke at its end may sag past it: flagged
        warnings.simplefilter("ignore", cl.JointLimitWarning)
        res = cl.compliance(model.clm, q0, "M", gravity=G)
        _, C_fd = _equilibrium_displacements(model.clm, q0, "M", G, (), np.zeros(6))
    assert_close_in_norm(res.C, C_fd, RTOL_FD)
    assert np.linalg.norm(res.sag[:3]) > 0.0


def test_payload_beyond_a_limit_load_is_refused():
    # the general Stewart platform pushed along its compression direction: limit load
    # ~2.5e4 N (see test_mechanisms); a payload weighing 1.2 times that
    m = mech.stewart(position=(0.1, -0.05, 0.9), psi=0.3, tilt=(0.1, -0.15),
                     anchors=mech.perturbed_anchors(seed=0))  # fmt: skip
    down = np.array([0.05, 0.1, -1.0]) / np.linalg.norm([0.05, 0.1, -1.0])
    heavy = Payload(1.2 * 2.5e4 / 9.81, m.frame)
    with pytest.raises(cl.EquilibriumError, match="limit load") as err:
        cl.compliance(m.clm, m.q, m.frame, gravity=9.81 * down, payloads=[heavy])
    assert err.value.limit_load
    light = Payload(0.5 * 2.5e4 / 9.81, m.frame)  # half the limit: found, and stable
    assert cl.compliance(m.clm, m.q, m.frame, gravity=9.81 * down, payloads=[light]).is_stable


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"gravity": (0.0, np.nan, -9.81)}, r"gravity \[m/s\^2\] must be 3 finite numbers"),
        ({"gravity": (0.0, -9.81)}, r"gravity \[m/s\^2\] must be 3 finite numbers"),
        ({"payloads": [Payload(1.0, "P")]}, r"payloads weigh nothing without gravity"),
    ],
)
def test_bad_gravity_is_refused(fourbar, kwargs, match):
    clm, q0 = fourbar
    with pytest.raises(cl.InvalidInputError, match=match):
        cl.solve_equilibrium(clm, q0, "P", np.zeros(6), **kwargs)


def test_bad_payloads_are_refused(fourbar):
    clm, _ = fourbar
    with pytest.raises(cl.InvalidInputError, match=r"payload mass must be >= 0 \[kg\], got -1"):
        Payload(-1.0, "P")
    for mass in (float("nan"), 10**400):  # an int beyond the float range: OverflowError
        with pytest.raises(cl.InvalidInputError, match=r"payload mass must be a finite number"):
            Payload(mass, "P")
    with pytest.raises(cl.InvalidInputError, match=r"payload offset must be 3 finite"):
        Payload(1.0, "P", np.array([0.0, np.inf, 0.0]))
    with pytest.raises(cl.NameNotFoundError, match=r"unknown frame 'nowhere'"):
        GravityLoad(clm, G, [Payload(1.0, "nowhere")])


def test_energy_of_the_weight_is_minimal_at_the_equilibrium(fourbar):
    # independent of the equations: minimise springs + weight on the closure manifold
    clm, q0 = fourbar
    payloads = [Payload(2.0, "coupler_link")]
    eq = cl.solve_equilibrium(clm, q0, "P", np.zeros(6), gravity=G, payloads=payloads)
    weight = GravityLoad(clm, G, payloads)
    free = np.flatnonzero(clm.stiffness < np.inf)

    def energy(x):
        q = pin.integrate(clm.model, q0, _embed(clm, free, x))
        return cl.elastostatics.equilibrium.potential_energy(clm, q, q0, "P", np.zeros(3), weight)

    # the loop is planar: its out-of-plane closure row is identically zero, left out
    in_plane = np.abs(cl.kinematics.constraints.closure_jacobian(clm, q0)).max(axis=1) > 1e-12

    def closure(x):
        q = pin.integrate(clm.model, q0, _embed(clm, free, x))
        return cl.kinematics.constraints.closure_residual(clm, q)[in_plane]

    def closure_jacobian(x, h=1e-6):  # central differences, as the energy's ('3-point')
        steps = h * np.eye(x.size)
        return np.array([(closure(x + e) - closure(x - e)) / (2 * h) for e in steps]).T

    # with its own forward differences SLSQP stopped 8.6e-7 of max |x0| away from x0,
    # 0.86 of the tolerance; with central ones 1.1e-11 (OpenBLAS's Haswell, SandyBridge)
    x0 = pin.difference(clm.model, q0, eq.q)[free]
    out = scipy.optimize.minimize(
        energy, np.zeros(free.size), jac="3-point", method="SLSQP",
        constraints={"type": "eq", "fun": closure, "jac": closure_jacobian},
        options={"ftol": 1e-15, "maxiter": 500},
    )  # fmt: skip
    assert out.success, out.message
    np.testing.assert_allclose(out.x, x0, rtol=0, atol=1e-6 * np.abs(x0).max())


def _embed(clm, free, x):
    v = np.zeros(clm.model.nv)
    v[free] = x
    return v


@pytest.mark.parametrize(("legs_deg", "alpha4_deg", "s4"), [(30.0, 30.0, 0.0), (90.0, 10.0, 0.05)])
def test_cahyman_masses_sit_where_eq_11_puts_them(legs_deg, alpha4_deg, s4):
    # With the plate level (equal cranks) the weight's moment about the alpha_4 axis is
    # the paper's eq. (11) lever sum g cos(alpha_4) [m_M4 L/2 + m_MM2 L + m_M5 (L + s4/2)]
    from cahyman_pin.model import CaHyManModel
    from cahyman_pin.params import DEFAULT_PARAMS

    p = DEFAULT_PARAMS.replace(m_HQ=0.5, m_QM=0.3, m_MM2=0.4, m_M4=1.2, m_M5=0.8)
    model = CaHyManModel(p)
    a4 = np.deg2rad(alpha4_deg)
    q = model.assemble(np.deg2rad([legs_deg] * 3), a4, s4)
    masses = sum(I.mass for I in model.clm.model.inertias)
    np.testing.assert_allclose(masses, p.m_HQ + p.m_QM + p.m_MM2 + p.m_M4 + p.m_M5, rtol=1e-12)
    torque = GravityLoad(model.clm, G).forces(q)[model.clm.joint_v_slice("alpha_4")][0]
    lever = p.m_M4 * p.L / 2 + p.m_MM2 * p.L + p.m_M5 * (p.L + s4 / 2)
    # positive alpha_4 raises the arm: holding it up against gravity takes +g cos(a4) lever
    np.testing.assert_allclose(torque, 9.81 * np.cos(a4) * lever, rtol=1e-12)


def test_command_line_gravity_payload_and_preload(capsys, ur5_urdf, soft_ur5):
    import json

    from closedloop.cli.app import main

    q = UR5_POSES[0]
    args = ["stiffness", str(ur5_urdf),
            "--frame", "tool0", "--q", *map(repr, q.tolist()), "--joint-stiffness", repr(UR5_K),
            "--gravity", "--payload", "2", "0", "0", "0.05", "--preload", "1", "0", "0", "0",
            "0", "0", "--json"]  # fmt: skip
    assert main(args) == 0
    doc = json.loads(capsys.readouterr().out)
    ref = cl.compliance(soft_ur5, q, "tool0", gravity=cl.STANDARD_GRAVITY,  # no values: g_n
                        payloads=[Payload(2.0, "tool0", np.array([0.0, 0.0, 0.05]))],
                        preload=[1.0, 0, 0, 0, 0, 0])  # fmt: skip
    np.testing.assert_allclose(doc["sag"], ref.sag, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(doc["q_eq"], ref.q, rtol=1e-12)
    assert doc["weight"]["payloads"][0]["mass_kg"] == 2.0 and doc["preload"][0] == 1.0
    for bad, match in ((["--payload", "2"], "weighs nothing without --gravity"),
                       (["--gravity", "1", "2"], "--gravity takes 0 or 3 values")):  # fmt: skip
        assert main(args[:13] + bad) == 2
        assert match in capsys.readouterr().err


def test_cahyman_weight_from_the_api_and_the_command_line(capsys):
    import json

    from cahyman_pin.api import stiffness
    from cahyman_pin.cli import main
    from cahyman_pin.model import cahyman_model
    from cahyman_pin.params import DEFAULT_PARAMS

    p = DEFAULT_PARAMS.replace(m_M4=1.2, m_M5=0.8)
    alpha, a4, s4 = np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.02
    r = stiffness(alpha, a4, s4, params=p, weight=True)
    model = r.details["compliance"]
    rest = cl.Configuration(cahyman_model(p).clm, model.equilibrium.q_rest)
    ref = cl.compliance(rest, "M", gravity=(0.0, 0.0, -p.gravity))  # the same, directly
    assert_close_in_norm(r.C, ref.C, 1e-12)
    assert np.linalg.norm(model.sag[:3]) > 1e-5  # m: it does sag
    code = main(["stiffness", "--alpha", "45", "60", "75", "--alpha4", "45", "--s4", "20",
                 "--gravity", "--mass", "m_M4=1.2", "--mass", "m_M5=0.8", "--json"])  # fmt: skip
    doc = json.loads(capsys.readouterr().out)
    assert code == 0
    np.testing.assert_allclose(doc["sag_M"], model.sag, rtol=1e-12, atol=1e-18)
    np.testing.assert_array_equal(r.sag_M, model.sag)
    assert main(["stiffness", "--gravity", "--backend", "consistent"]) == 2
    assert "needs the generic backend" in capsys.readouterr().err


def test_cahyman_text_and_deflect_print_the_sag_of_m(capsys):
    """The sag that --gravity promises is in the text of ``stiffness`` and ``deflect`` (mm,
    the JSON's number) and in ``deflect --json``; without --gravity it is null."""
    import json

    from cahyman_pin.api import stiffness
    from cahyman_pin.cli import main
    from cahyman_pin.params import DEFAULT_PARAMS

    p = DEFAULT_PARAMS.replace(m_M5=10.0)
    sag = stiffness(np.deg2rad([90.0] * 3), np.deg2rad(90.0), 0.05, params=p, weight=True).sag_M
    assert sag[2] < -1e-5  # m: 5 kg at M and 5 kg at M2 press M down
    weight = ["--gravity", "--mass", "m_M5=10"]
    for command in ("stiffness", "deflect"):
        assert main([command, *weight]) == 0
        line = next(s for s in capsys.readouterr().out.splitlines() if s.startswith("sag of M"))
        assert f"{sag[2] * 1e3: .6g}) mm" in line
    assert main(["deflect", *weight, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    np.testing.assert_allclose(doc["sag_M"]["displacement_m"], sag[:3], rtol=1e-12, atol=1e-18)
    assert main(["deflect", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["sag_M"] is None


@pytest.mark.parametrize("given", [{}, {"m_M4": 2.0}])
def test_report_weight_section_is_the_preloaded_compliance(given):
    """The report's numbers recomputed here: the equilibrium under the weight, directly;
    with the illustrative masses, or with those the parameters give (a --params file's
    masses were replaced by the illustrative ones)."""
    from cahyman_pin.model import CaHyManModel
    from cahyman_pin.paper.data import TABLE_POSES
    from cahyman_pin.paper.effects import ILLUSTRATIVE_MASS, NAMED_MASSES
    from cahyman_pin.paper.weight import weight_rows
    from cahyman_pin.params import DEFAULT_PARAMS

    params = DEFAULT_PARAMS.replace(**given)
    masses = given or dict.fromkeys(NAMED_MASSES, ILLUSTRATIVE_MASS)
    model = CaHyManModel(DEFAULT_PARAMS.replace(**masses))
    rows = weight_rows(params)
    assert [r[0] for r in rows] == [p.label for p in TABLE_POSES]
    for (_, sag, change), pose in zip(rows, TABLE_POSES, strict=True):
        q = model.assemble(*pose.si)
        with warnings.catch_warnings():  # a stroke at its end may sag past it: flagged
            warnings.simplefilter("ignore", cl.JointLimitWarning)
            eq = cl.solve_equilibrium(model.clm, q, "M", np.zeros(6), gravity=(0, 0, -9.81))
        np.testing.assert_allclose(sag, eq.displacement, rtol=1e-9, atol=1e-15)
        assert 0.0 < change < 0.1


def test_cahyman_leg_masses_sit_at_the_middle_of_their_links():
    # m_b alone: the weight's moment about each crank's axis is m_b g (b / 2) cos(alpha_k)
    from cahyman_pin.model import CaHyManModel
    from cahyman_pin.params import DEFAULT_PARAMS

    p = DEFAULT_PARAMS.replace(m_b=0.3, m_c=0.2, m_d=0.25, m_h=0.1)
    masses = sum(I.mass for I in CaHyManModel(p).clm.model.inertias)
    np.testing.assert_allclose(masses, 3 * (0.3 + 0.2 + 0.25 + 0.1), rtol=1e-12)
    model = CaHyManModel(DEFAULT_PARAMS.replace(m_b=0.3))
    alpha = np.deg2rad([40.0, 60.0, 75.0])
    q = model.assemble(alpha, 0.3, 0.01)
    G_q = GravityLoad(model.clm, G).forces(q)
    for k, a in enumerate(alpha, start=1):
        torque = G_q[model.clm.joint_v_slice(f"alpha_{k}")][0]
        np.testing.assert_allclose(torque, 0.3 * 9.81 * model.params.b / 2 * np.cos(a),
                                   rtol=1e-12)  # fmt: skip


@pytest.mark.parametrize(
    ("gravity", "mass", "offset"),
    [((0, 0, -1e308), 0.0, 0.0), ((0, 0, -9.81), 1e300, 0.0), ((0, 0, -9.81), 1.0, 1e160)],
)
def test_an_overflowing_weight_is_refused_naming_gravity_and_mass(ur5, gravity, mass, offset):
    """A weight beyond the double range would reach the solver as inf or NaN (LAPACK then
    prints to stdout and fails): refused at once, naming the gravity and the mass; a
    payload's offset is its lever (1 kg at 1e160 m reached LAPACK)."""
    clm, _ = ur5
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(cl.InvalidInputError, match=r"the weight under gravity \[0.0, 0.0, "):
            GravityLoad(clm, gravity, [Payload(mass, "tool0", [offset, 0.0, 0.0])])


def test_gravity_and_payloads_of_the_wrong_type_are_typed_errors(ur5):
    """A string for gravity and one Payload for the sequence raised ValueError and
    TypeError; a mass of numpy integer type was refused, and True taken for 1 kg."""
    clm, q = ur5
    with pytest.raises(cl.InvalidInputError, match=r"gravity \[m/s\^2\] must be real numbers"):
        cl.solve_equilibrium(clm, q, "tool0", np.zeros(6), gravity="down")
    with pytest.raises(cl.InvalidInputError, match=r"payloads must be a sequence of Payload"):
        GravityLoad(clm, G, Payload(1.0, "tool0"))
    with pytest.raises(cl.InvalidInputError, match=r"payload mass must be a finite number"):
        Payload(True, "tool0")
    as_int, as_float = (GravityLoad(clm, G, [Payload(m, "tool0")]) for m in (np.int64(2), 2.0))
    np.testing.assert_array_equal(as_int.forces(q), as_float.forces(q))
