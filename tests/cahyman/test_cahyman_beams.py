"""CaHyMan with its links as beams (CaHyManParams.links_as_beams) against independent routes.

References: the paper's model with its lumped link springs K_b, K_d, K_4 locked (rigid
links, motors only), the closed form of a clamped round tube's tip compliance transported
to M by the arm's geometry (the arm is in series with the rest of the machine: its
compliances add exactly), and the same model loaded from its generated URDF and closure
files by closedloop.io.loader.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm

from cahyman_pin.api import stiffness
from cahyman_pin.model import CaHyManModel, closed_form_pose
from cahyman_pin.paper.beams import beam_rows, beams_section
from cahyman_pin.paper.data import TABLE_POSES
from cahyman_pin.paper.document import Document, Table
from cahyman_pin.params import DEFAULT_PARAMS, CaHyManParams
from cahyman_pin.urdf_builder import VIRTUAL_JOINTS, build_closure_yaml, build_urdf
from closedloop.elastostatics.compliance import compliance
from closedloop.exceptions import InvalidInputError
from closedloop.io.loader import load_model
from closedloop.model.beams import map_configuration

ALPHA, ALPHA4, S4 = np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.025
# Two exact routes to the same compliance (different coordinates, Cholesky of 6x6 blocks
# up to 1e4 times stiffer than aluminium): rounding ~1e-12 relative, cond ~1e6 at most.
RTOL_EXACT = 1e-8
# f D(f) at two stiffness factors f: exact when the compliance is affine in 1/f (the
# links' compliances add up, as in a statically determinate structure); rounding of the
# difference D = C(f) - C_rigid, ~1e-12 of C over D ~ 1e-3 of C.
RTOL_LINEAR = 1e-7


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def tube_tip_compliance(L, e, E, G, d, t) -> np.ndarray:
    """(6, 6) tip compliance of a clamped round tube along unit e (world axes at its tip),
    Euler-Bernoulli: axial L/(EA), torsion L/(G 2I), bending L^3/(3EI), L^2/(2EI), L/(EI)."""
    r, ri = d / 2, d / 2 - t
    A, I = math.pi * (r**2 - ri**2), math.pi * (r**4 - ri**4) / 4
    P = np.eye(3) - np.outer(e, e)
    return np.block([
        [L / (E * A) * np.outer(e, e) + L**3 / (3 * E * I) * P, -(L**2) / (2 * E * I) * _skew(e)],
        [L**2 / (2 * E * I) * _skew(e), L / (G * 2 * I) * np.outer(e, e) + L / (E * I) * P],
    ])  # fmt: skip


def beam_model(stiffer: float = 1.0) -> CaHyManModel:
    p = CaHyManParams(links_as_beams=True)
    return CaHyManModel(p.replace(E_beam=p.E_beam * stiffer, G_beam=p.G_beam * stiffer))


@pytest.fixture(scope="module")
def lumped():
    model = CaHyManModel()
    return model, model.assemble(ALPHA, ALPHA4, S4)


def test_default_keeps_the_papers_lumped_springs(lumped):
    model, _ = lumped
    assert CaHyManParams().links_as_beams is False
    assert not model.clm.spring_blocks and set(VIRTUAL_JOINTS) <= set(model.clm.springs)


def test_beams_keep_the_kinematics(lumped):
    """The same inputs give the same M (the sliding tube's driven end moves back by
    L_MM2, the telescope forward by as much) and the closures hold at the mapped pose."""
    model, q = lumped
    flex = beam_model()
    assert flex.clm.model.nv == model.clm.model.nv + 6 * 17  # 5 beams a leg, QM2, MM2
    qb = map_configuration(model.clm.model, flex.clm.model, q)
    assert flex.residual(qb) < 1e-12
    np.testing.assert_allclose(flex.pose(qb).M, closed_form_pose(ALPHA, ALPHA4, S4).M, atol=1e-12)


def test_the_slider_loads_the_coupler_between_its_two_halves():
    """The coupler is held at both ends (crank b at B_k, crank d at its far end) and loaded
    by the connecting bar at its midpoint C_k: the slider s_k rides on the tip of the beam
    from B_k, where the beam to the far end starts (it rode on B_k, so that the bar's load
    reached B_k rigidly and the coupler bent as a cantilever of length a)."""
    model = beam_model().clm.model
    for k in (1, 2, 3):
        first = model.getJointId(f"coupler_{k}_beam")
        second = model.getJointId(f"coupler_{k}_mid_beam")
        assert model.parents[model.getJointId(f"s_{k}")] == first
        assert model.parents[second] == first
        assert model.frames[model.getFrameId(f"coupler_{k}_end")].parentJoint == second


def test_very_stiff_beams_tend_to_the_rigid_link_model(lumped):
    """D(f) = C(f) - C_rigid, f the beams' stiffness factor: f D(f) the same at f = 1e3
    and 1e4 (D falls as 1/f, to 0), and |D(1e4)| below 0.1% of |C_rigid|."""
    model, q = lumped
    locked = dict.fromkeys(VIRTUAL_JOINTS, np.inf)  # K_b, K_d, K_4 rigid; K_T, K_T4, K_s stay
    C_rigid = compliance(model.clm.with_springs({**model.clm.springs, **locked}), q, "M").C
    scaled = []
    for f in (1e3, 1e4):
        flex = beam_model(f)
        D = compliance(flex.clm, map_configuration(model.clm.model, flex.clm.model, q), "M").C
        scaled.append(f * (D - C_rigid))
    assert_close_in_norm(scaled[1], scaled[0], RTOL_LINEAR)
    assert np.linalg.norm(scaled[1] / 1e4) < 1e-3 * np.linalg.norm(C_rigid)


def test_one_flexible_beam_adds_its_compliance_transported_to_M(lumped):
    """All beams 1e4 times stiffer than aluminium but the arm QM2 (its block from the
    aluminium model): C - C_stiff = Ad (C_b - C_b_stiff) Ad^T, C_b the closed-form tip
    compliance of the arm tube at M2 along the arm, Ad the transport of a twist at M2 to
    M (lever M - M2): the arm is in series with everything else."""
    model, q = lumped
    p, stiff = CaHyManParams(links_as_beams=True), beam_model(1e4)
    nominal = CaHyManModel(p).clm.spring_blocks["arm_beam"]
    one = stiff.clm.with_springs({**stiff.clm.springs, "arm_beam": nominal}, stiff.clm.locked)
    qb = map_configuration(model.clm.model, stiff.clm.model, q)
    added = compliance(one, qb, "M").C - compliance(stiff.clm, qb, "M").C
    pose = model.pose(q)
    data = model.clm.model.createData()
    pin.framesForwardKinematics(model.clm.model, data, q)
    M2 = data.oMf[model.clm.model.getFrameId("M2")].translation
    w = (M2 - pose.Q) / np.linalg.norm(M2 - pose.Q)
    assert np.linalg.norm(M2 - pose.Q) == pytest.approx(p.L, rel=1e-12)
    Cb = tube_tip_compliance(p.L, w, p.E_beam, p.G_beam, p.d_arm, p.t_arm)
    Cb_stiff = tube_tip_compliance(p.L, w, 1e4 * p.E_beam, 1e4 * p.G_beam, p.d_arm, p.t_arm)
    Ad = np.block([[np.eye(3), -_skew(pose.M - M2)], [np.zeros((3, 3)), np.eye(3)]])
    assert_close_in_norm(added, Ad @ (Cb - Cb_stiff) @ Ad.T, RTOL_EXACT)


def test_generated_files_carry_the_beams(lumped, tmp_path):
    """The URDF and closure file of the beam option, loaded by closedloop.io.loader (beams from
    the file's ``beams:``, closures built after them), give the in-memory model's C."""
    model, q = lumped
    p = CaHyManParams(links_as_beams=True)
    (tmp_path / "c.urdf").write_text(build_urdf(p))
    (tmp_path / "c.yaml").write_text(build_closure_yaml(p))
    loaded = load_model(tmp_path / "c.urdf", tmp_path / "c.yaml", geometry=False)
    flex = CaHyManModel(p)
    assert set(loaded.spring_blocks) == set(flex.clm.spring_blocks)
    qb = map_configuration(model.clm.model, flex.clm.model, q)
    C = compliance(flex.clm, qb, "M").C
    ql = map_configuration(model.clm.model, loaded.model, q)
    assert_close_in_norm(compliance(loaded, ql, "M").C, C, RTOL_EXACT)


def test_bad_beam_parameters_are_refused():
    with pytest.raises(InvalidInputError, match=r"links_as_beams=1 must be true or false"):
        CaHyManParams(links_as_beams=1)
    with pytest.raises(InvalidInputError, match=r"d_leg=-0.01 must be > 0"):
        CaHyManParams(d_leg=-0.01)
    for d, t in (("d_leg", "t_leg"), ("d_arm", "t_arm"), ("d_MM2", "t_MM2")):
        wall = getattr(DEFAULT_PARAMS, d) / 2  # the solid rod is allowed, one ulp more is not
        CaHyManParams(**{t: wall})
        with pytest.raises(InvalidInputError, match=rf"{t}=0.0\d+ must be at most {d}/2 = "
                           rf"{wall!r} \(a tube's wall is at most its radius\)"):  # fmt: skip
            CaHyManParams(**{t: float(np.nextafter(wall, 1.0))})


def test_report_section_rows_against_the_closed_form():
    """beam_rows: the lumped rows' diagonal is the consistent closed form's (an independent
    implementation of the paper's model); every row's energy shares sum to 1; the section
    shows the rows."""
    rows = beam_rows(DEFAULT_PARAMS)
    assert [(label, b) for label, b, _, _ in rows] == [
        (pose.label, b) for pose in TABLE_POSES for b in (False, True)
    ]
    poses = [pose for pose in TABLE_POSES for _ in range(2)]
    for (_, as_beams, diag, shares), pose in zip(rows, poses, strict=True):
        assert sum(shares.values()) == pytest.approx(1.0, rel=1e-9)
        if not as_beams:
            C = stiffness(*pose.si, backend="consistent").C
            assert_close_in_norm(diag, np.diag(C), RTOL_EXACT)
    doc = Document("x")
    beams_section(doc, DEFAULT_PARAMS)
    table = next(b for b in doc.blocks if isinstance(b, Table))
    assert table.rows[1][:3] == ("Table 1", "beam links", f"{1e6 * rows[1][2][0]:.4g}")


# Central differences of the potential energy with step 1e-6 (rad, m): truncation
# ~1e-12 relative, rounding ~1e-16 V / 1e-6 over G ~ 1 N m: 1e-7 is a wide margin.
RTOL_GRAVITY_FD = 1e-6


def test_weight_on_beam_links_is_the_gradient_of_the_potential():
    """Leg masses with links as beams: the beams move the far ends' inertias to the beam
    tips; a massless remainder on the beam's start stays a valid inertia (no NaN), the
    total mass is that of the model without beams, and the generalised gravity equals the
    central differences of Pinocchio's potential energy."""
    masses = {"m_HQ": 0.5, "m_QM": 0.5, "m_MM2": 0.5, "m_M4": 0.5, "m_M5": 0.5}
    lumped = CaHyManModel(DEFAULT_PARAMS.replace(**masses)).clm.model
    model = CaHyManModel(DEFAULT_PARAMS.replace(links_as_beams=True, **masses))
    M = model.clm.model
    for i, inertia in enumerate(M.inertias):
        assert np.isfinite(inertia.toDynamicParameters()).all(), M.names[i]
    np.testing.assert_allclose(sum(I.mass for I in M.inertias),
                               sum(I.mass for I in lumped.inertias), rtol=1e-14)  # fmt: skip
    q = model.assemble(ALPHA, ALPHA4, S4)
    G = pin.computeGeneralizedGravity(M, M.createData(), q).copy()
    h, fd, data = 1e-6, np.zeros(M.nv), M.createData()  # one Data: 0.2 s each at nv = 129
    for k in range(M.nv):
        e = np.zeros(M.nv)
        e[k] = h
        up = pin.computePotentialEnergy(M, data, pin.integrate(M, q, e))
        down = pin.computePotentialEnergy(M, data, pin.integrate(M, q, -e))
        fd[k] = (up - down) / (2 * h)
    assert_close_in_norm(G, fd, rtol=RTOL_GRAVITY_FD)


def test_weight_preload_with_beam_links_is_finite_and_sags_down():
    """The report's weight section on a machine with beam links: the sag of M under the
    weight points down and the tangent compliance exists."""
    masses = {"m_HQ": 0.5, "m_QM": 0.5, "m_MM2": 0.5, "m_M4": 0.5, "m_M5": 0.5}
    params = DEFAULT_PARAMS.replace(links_as_beams=True, **masses)
    r = stiffness(ALPHA, ALPHA4, S4, params=params, weight=True)
    sag = r.details["compliance"].sag
    assert np.isfinite(sag).all() and sag[2] < 0
    assert r.is_full_rank and np.isfinite(r.C).all()
