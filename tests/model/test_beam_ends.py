"""Beams that end at a frame of their link (an MJCF site) or at a closure's anchor.

A link whose far end is only a ``<connect>`` anchor (the bundled four-bar's coupler) is a
beam to ``end: anchor:<closure name>``; a link whose child joint sits at its origin (a
Stewart platform's cylinder, its piston sliding from the cylinder's base) is a beam to a
site at its far end, the piston staying on the beam's start.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm

import closedloop as cl
from closedloop.exceptions import BeamError
from closedloop.io.loader import load_model
from closedloop.model.beam_joints import inserted_beams
from closedloop.model.beams import map_configuration

#: The same beam theory through different algebra (6x6 inverses, transports, the
#: closure's reduction); condition of the stiffness ~1e8: rounding ~1e-12 relative.
RTOL_EXACT = 1e-9
STEEL = {"E": 2.1e11, "G": 8.1e10}
D_ROD = 0.004  # [m]
REPO = Path(__file__).resolve().parents[2] / "urdf"


def rod(end: str) -> dict:
    return {"end": end, **STEEL, "section": {"shape": "circle", "d": D_ROD}}


def _skew(v):
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def round_tip_compliance(L, e, E, G, d) -> np.ndarray:
    """Tip compliance (6, 6) [m/N, rad/N, rad/(N m)] of a clamped round rod of diameter d
    along the unit vector e, in the axes of e, at the tip: axial L / (E A), bending
    L^3 / (3 E I), L / (E I) and their coupling L^2 / (2 E I), torsion L / (G J)."""
    A, I = np.pi * d**2 / 4, np.pi * d**4 / 64
    P = np.eye(3) - np.outer(e, e)
    return np.block([
        [L / (E * A) * np.outer(e, e) + L**3 / (3 * E * I) * P, -(L**2) / (2 * E * I) * _skew(e)],
        [L**2 / (2 * E * I) * _skew(e), L / (G * 2 * I) * np.outer(e, e) + L / (E * I) * P],
    ])  # fmt: skip


# --------------------------------------------------------------------- anchor end
def fourbar_compliance(path: Path, beams: dict) -> np.ndarray:
    """(6, 6) compliance at P of the four-bar at ``path`` with ``beams``, crank at 0.5 rad."""
    clm = load_model(path, beams=beams, geometry=False)
    plain = load_model(path, geometry=False)
    q = cl.assemble(plain, [0.5], plain.reference_configuration()).q
    q = cl.assemble(clm, [0.5], map_configuration(plain.model, clm.model, q)).q
    return cl.compliance(clm, q, "P").C


def tip_file(tmp_path) -> Path:
    """The bundled four-bar with a body ``coupler_tip`` at the ``<connect>``'s anchor on
    the coupler, the connect on that body."""
    text = (REPO / "fourbar.xml").read_text()
    connect = (
        '<connect name="closedloop1" body1="coupler_link" body2="rocker_end" anchor="0.3 0 0"/>'
    )
    site = '<site name="P" pos="0.15 0 0.05"/>'
    assert connect in text and site in text
    tip = tmp_path / "fourbar_tip.xml"
    moved = connect.replace("coupler_link", "coupler_tip").replace("0.3 0 0", "0 0 0")
    body = '<body name="coupler_tip" pos="0.3 0 0"/>'
    tip.write_text(text.replace(site, site + body).replace(connect, moved))
    return tip


def test_coupler_to_the_connect_anchor_is_the_coupler_to_a_tip_body(tmp_path):
    """The bundled MJCF four-bar's coupler, whose far end is only the ``<connect>``
    anchor, as a beam to that anchor; the same mechanism written with a body at the anchor
    (the connect on it) is a beam to that body's fixed joint, as before."""
    tip = tip_file(tmp_path)
    C = fourbar_compliance(REPO / "fourbar.xml", {"coupler_link": rod("anchor:closedloop1")})
    expected = fourbar_compliance(tip, {"coupler_link": rod("coupler_tip_fixed")})
    rigid = fourbar_compliance(REPO / "fourbar.xml", {})
    assert np.max(np.abs(C - rigid)) > 1e-3 * np.max(np.abs(rigid))  # the rod is felt
    assert_close_in_norm(C, expected, RTOL_EXACT, scale=[1, 1, 1, 0.3, 0.3, 0.3])


def test_a_chain_to_the_connect_anchor_is_the_chain_to_a_tip_body(tmp_path):
    """Two beams on the coupler, from its origin to the site P and from P on to the
    ``<connect>`` anchor (a list of beams): the same as the chain to a body written at
    the anchor, the anchor carried by the first beam's tip to the second's start."""
    tip = tip_file(tmp_path)
    anchor = [rod("P"), {**rod("anchor:closedloop1"), "start": "P"}]
    body_end = [rod("P"), {**rod("coupler_tip_fixed"), "start": "P"}]
    C = fourbar_compliance(REPO / "fourbar.xml", {"coupler_link": anchor})
    expected = fourbar_compliance(tip, {"coupler_link": body_end})
    for path, beams, last in ((REPO / "fourbar.xml", anchor, "anchor:closedloop1"),
                              (tip, body_end, "coupler_tip_fixed")):  # fmt: skip
        clm = load_model(path, beams={"coupler_link": beams}, geometry=False)
        anchor_on = clm.closures[0].constraint  # the coupler's anchor: at the chain's tip
        assert clm.model.names[anchor_on.joint1_id] == f"coupler_link_beam_{last}"
        assert anchor_on.joint1_placement.isApprox(pin.SE3.Identity(), 1e-12)
    one = fourbar_compliance(REPO / "fourbar.xml", {"coupler_link": rod("anchor:closedloop1")})
    assert np.max(np.abs(C - one)) > 1e-3 * np.max(np.abs(one))  # the chain is not one rod
    assert_close_in_norm(C, expected, RTOL_EXACT, scale=[1, 1, 1, 0.3, 0.3, 0.3])


def test_an_anchor_of_another_link_is_refused():
    with pytest.raises(BeamError, match=r"end 'anchor:closedloop1' is not a child joint of the "
                       r"link.*expected one of \['crank_axial'\]"):  # fmt: skip
        cl.load_model(REPO / "fourbar.xml", beams={"crank_link": rod("anchor:closedloop1")})


# ---------------------------------------------------------------------- site end
AXIS = np.array([1.0, 2.0, 2.0]) / 3.0  # the cylinder's axis in its frame
L_CYL, K_PISTON = 0.4, 3e4  # [m], [N/m]
ROTATION = pin.rpy.rpyToMatrix(0.3, -0.5, 1.1)  # the cylinder's frame in the world

CYLINDER = """<mujoco model="cylinder">
  <worldbody>
    <body name="base">
      <body name="cylinder" pos="0.1 -0.2 0.3" quat="{quat}">
        <site name="top" pos="{top}"/>
        <body name="rod">
          <joint name="piston" type="slide" axis="{axis}" stiffness="{k}"/>
          <site name="rod_end" pos="{top}"/>
        </body>
      </body>
    </body>
  </worldbody>
</mujoco>"""


def cylinder(tmp_path, end: str):
    q = pin.Quaternion(ROTATION)
    text = CYLINDER.format(quat=f"{q.w} {q.x} {q.y} {q.z}", top=" ".join(map(str, L_CYL * AXIS)),
                           axis=" ".join(map(str, AXIS)), k=K_PISTON)  # fmt: skip
    (tmp_path / "cylinder.xml").write_text(text)
    return cl.load_model(tmp_path / "cylinder.xml", beams={"cylinder": rod(end)}, geometry=False)


def test_cylinder_to_a_site_is_a_cantilever_and_its_piston_stays_on_the_start(tmp_path):
    """A Stewart-like cylinder, clamped, its piston's slide joint at its origin: a beam to
    the site at its far end has the cantilever's tip compliance there; the piston (and its
    site) stays on the beam's start: only its spring is felt at its end."""
    clm = cylinder(tmp_path, "top")
    q = pin.neutral(clm.model)
    e = ROTATION @ AXIS  # the axis in the world
    C = cl.compliance(clm, q, "top").C  # world axes at the site
    assert_close_in_norm(C, round_tip_compliance(L_CYL, e, **STEEL, d=D_ROD), RTOL_EXACT)
    C_rod = cl.compliance(clm, q, "rod_end").C
    expected = np.zeros((6, 6))
    expected[:3, :3] = np.outer(e, e) / K_PISTON
    assert_close_in_norm(C_rod, expected, RTOL_EXACT)


def test_a_frame_of_another_link_is_refused_naming_the_frames(tmp_path):
    with pytest.raises(BeamError, match=r"end 'rod_end' is not a child joint of the link.*"
                       r"expected one of \['piston', 'top'\]"):  # fmt: skip
        cylinder(tmp_path, "rod_end")


# ---------------------------------------------------------------------- child link end
def _fourbar_urdf_compliance(beams: dict) -> np.ndarray:
    """(6, 6) compliance at P of the bundled URDF four-bar with ``beams``, crank 0.5 rad."""
    plain = load_model(REPO / "fourbar.urdf", REPO / "fourbar.yaml", geometry=False)
    clm = load_model(REPO / "fourbar.urdf", REPO / "fourbar.yaml", beams=beams, geometry=False)
    q = cl.assemble(plain, [0.5], plain.reference_configuration()).q
    q = cl.assemble(clm, [0.5], map_configuration(plain.model, clm.model, q)).q
    return cl.compliance(clm, q, "P").C


@pytest.mark.parametrize(
    ("link", "child", "joint"),
    [("coupler_link", "coupler_end", "coupler_end_joint"),  # a fixed joint's child
     ("crank_link", "crank_end", "crank_axial")],  # a moving joint's child
)  # fmt: skip
def test_an_end_may_name_the_end_joints_child_link(link, child, joint):
    """``end: coupler_end`` is the beam to ``coupler_end_joint``, whose child link it is
    (it was refused: not a child joint of the link, nor one of its frames), alone and in
    a list of beams (its virtual joint named after the end as written)."""
    C = _fourbar_urdf_compliance({link: rod(child)})
    np.testing.assert_array_equal(C, _fourbar_urdf_compliance({link: rod(joint)}))
    assert np.max(np.abs(C - _fourbar_urdf_compliance({}))) > 1e-3 * np.max(np.abs(C))
    listed = load_model(REPO / "fourbar.urdf", REPO / "fourbar.yaml", geometry=False,
                        beams={link: [rod(child)]})  # fmt: skip
    assert f"{link}_beam_{child}" in listed.spring_blocks


def test_a_frame_of_the_link_named_as_a_child_link_is_the_end(tmp_path):
    """A name that is a site of the link (at its far end) and the child link of one of its
    joints (the piston's rod, at its origin; MJCF keeps bodies and sites apart): the
    link's own frame, as before (the rod would be a beam of length 0, refused)."""
    q = pin.Quaternion(ROTATION)
    text = CYLINDER.format(quat=f"{q.w} {q.x} {q.y} {q.z}", top=" ".join(map(str, L_CYL * AXIS)),
                           axis=" ".join(map(str, AXIS)), k=K_PISTON)  # fmt: skip
    top = f'<site name="top" pos="{" ".join(map(str, L_CYL * AXIS))}"/>'
    (tmp_path / "cylinder.xml").write_text(text.replace(top, top.replace("top", "rod"), 1))
    clm = cl.load_model(tmp_path / "cylinder.xml", beams={"cylinder": rod("rod")}, geometry=False)
    (beam,) = inserted_beams(clm.model)
    np.testing.assert_allclose(beam.rest.translation, L_CYL * AXIS, rtol=0.0, atol=1e-12)
