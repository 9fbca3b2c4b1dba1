"""A link whose elastic body is several straight beams between named points of the link
(``beams: {link: [ {end: ...}, {start: ..., end: ...} ]}``): a ternary link with two
flexible arms, a mid-span load frame, each against the cantilever's closed form."""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm
from test_beams import STEEL, _skew, round_tip_compliance, urdf_of

import closedloop as cl
from closedloop.exceptions import BeamError
from closedloop.io.loader import load_model
from closedloop.model.beam_joints import inserted_beams
from closedloop.model.beams import map_configuration
from closedloop.model.elastic import beam_joints

#: The same beam theory through different algebra (6x6 inverses and transports of a
#: stiffness of condition ~1e8): rounding ~1e-12 relative.
RTOL_EXACT = 1e-9
D = 0.01  # [m], the rods' diameter
A, I = np.pi * D**2 / 4, np.pi * D**4 / 64
E_A = np.array([1.0, 2.0, 2.0]) / 3.0  # the arms' directions, along no axis
E_B = np.array([-2.0, 1.0, 2.0]) / 3.0
L_A, L_B = 0.5, 0.3  # [m]


def rod(end: str, **more) -> dict:
    return {"end": end, **STEEL, "section": {"shape": "circle", "d": D}, **more}


def closed_form(L: float, e: np.ndarray) -> np.ndarray:
    return round_tip_compliance(L, e, STEEL["E"], STEEL["G"], A, I)


def cross_compliance(clm, q, a: str, b: str) -> np.ndarray:
    """(6, 6) twist of frame a (world axes, at its origin) per wrench on frame b, from the
    tree's Jacobians and its springs: J_a K^-1 J_b^T (no closures, every joint a spring)."""
    model, data = clm.model, clm.model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    J = {
        f: pin.getFrameJacobian(model, data, model.getFrameId(f), pin.LOCAL_WORLD_ALIGNED)
        for f in (a, b)
    }
    return J[a] @ np.linalg.solve(clm.spring_matrix, J[b].T)


def ternary(tmp_path, beams=None):
    path = urdf_of(
        tmp_path, "ternary", ["hub", "a", "b"],
        [("ja", "hub", "a", L_A * E_A, (0.3, -0.5, 1.1), "fixed", None),
         ("jb", "hub", "b", L_B * E_B, (-0.7, 0.2, 0.4), "fixed", None)],
    )  # fmt: skip
    beams = beams if beams is not None else {"hub": [rod("ja"), rod("jb")]}
    clm = load_model(path, beams=beams, geometry=False)
    return clm, pin.neutral(clm.model)


def test_ternary_link_arms_are_two_uncoupled_cantilevers(tmp_path):
    clm, q = ternary(tmp_path)
    assert set(clm.spring_blocks) == {"hub_beam_ja", "hub_beam_jb"}
    for frame, L, e in (("a", L_A, E_A), ("b", L_B, E_B)):
        C = cl.compliance(clm, q, frame).C
        assert_close_in_norm(C, closed_form(L, e), RTOL_EXACT)
        by_jacobians = cross_compliance(clm, q, frame, frame)  # the formula used below
        assert_close_in_norm(by_jacobians, C, RTOL_EXACT)
    # a wrench on one arm's tip does not move the other's: exactly zero (block structure)
    np.testing.assert_array_equal(cross_compliance(clm, q, "a", "b"), np.zeros((6, 6)))
    beams = {b.name: b for b in inserted_beams(clm.model)}
    assert set(beams) == {"hub_beam_ja", "hub_beam_jb"}
    hub = clm.model.getFrameId("hub", pin.BODY)
    assert all(b.link_frame == hub for b in beams.values())
    np.testing.assert_allclose(np.linalg.norm(beams["hub_beam_ja"].rest.translation), L_A)


def mid_span(tmp_path, beams: dict):
    L, e = 0.8, E_A
    path = urdf_of(
        tmp_path, "rod", ["ground", "mid", "tip"],
        [("mid_joint", "ground", "mid", L / 2 * e, (0.1, 0.2, 0.3), "fixed", None),
         ("tip_joint", "ground", "tip", L * e, (-0.4, 0.5, 0.6), "fixed", None)],
    )  # fmt: skip
    clm = load_model(path, beams=beams, geometry=False)
    return clm, pin.neutral(clm.model), L, e


def test_mid_span_frame_is_the_single_beam_at_the_tip_and_half_at_mid(tmp_path):
    chained = {"ground": [rod("mid_joint"), rod("tip_joint", start="mid_joint")]}
    clm, q, L, e = mid_span(tmp_path, chained)
    single, q1, _, _ = mid_span(tmp_path, {"ground": rod("tip_joint")})
    C = cl.compliance(clm, q, "tip").C
    # two Euler-Bernoulli elements of a straight cantilever: the exact tip compliance
    assert_close_in_norm(C, closed_form(L, e), RTOL_EXACT)
    assert_close_in_norm(C, cl.compliance(single, q1, "tip").C, RTOL_EXACT)
    C_mid = cl.compliance(clm, q, "mid").C
    assert_close_in_norm(C_mid, closed_form(L / 2, e), RTOL_EXACT)
    # a wrench at mid moves the tip rigidly with mid: v_tip = v_mid - [d]x w_mid
    T = np.block([[np.eye(3), -_skew(L / 2 * e)], [np.zeros((3, 3)), np.eye(3)]])
    assert_close_in_norm(cross_compliance(clm, q, "tip", "mid"), T @ C_mid, RTOL_EXACT)
    beams = {b.name: b for b in inserted_beams(clm.model)}
    assert set(beams) == {"ground_beam_mid_joint", "ground_beam_tip_joint"}
    mid = clm.model.getFrameId("ground_beam_mid_joint", pin.JOINT)
    assert beams["ground_beam_tip_joint"].link_frame == mid
    for b in beams.values():
        np.testing.assert_allclose(np.linalg.norm(b.rest.translation), L / 2, rtol=1e-12)
    assert len(beam_joints(clm)) == 2  # both beams' energies, with their shortening


@pytest.mark.parametrize(
    ("entry", "match"),
    [
        ([rod("ja"), rod("jb", start="jc")], "start 'jc'"),
        ([rod("ja", start="jb"), rod("jb", start="ja")], "cycle"),
        ([rod("ja"), rod("ja")], "two beams end at 'ja'"),
        ([rod("ja", start="ja")], "cycle"),
        ([], "non-empty list"),
        ([{"E": 1.0}], "with its end"),
    ],
)
def test_bad_beam_lists_are_refused(tmp_path, entry, match):
    with pytest.raises(BeamError, match=match) as info:
        ternary(tmp_path, {"hub": entry})
    assert "hub" in str(info.value)


def test_chained_beams_split_into_elements_keep_the_tip_compliance(tmp_path):
    """Euler-Bernoulli elements of a straight cantilever are exact at the nodes: the chain
    origin -> mid -> tip, each beam in 2 elements, is the cantilever of length L at the tip."""
    two = {"elements": 2}
    chained = {"ground": [rod("mid_joint", **two), rod("tip_joint", start="mid_joint", **two)]}
    clm, q, L, e = mid_span(tmp_path, chained)
    assert_close_in_norm(cl.compliance(clm, q, "tip").C, closed_form(L, e), RTOL_EXACT)
    lengths = [np.linalg.norm(b.rest.translation) for b in inserted_beams(clm.model)]
    np.testing.assert_allclose(lengths, [L / 4] * 4, rtol=1e-12)


def test_drawn_chained_beams_run_origin_mid_tip(tmp_path):
    """The viewer's beam curves (from :func:`inserted_beams`): at rest, straight from the
    origin to mid and from mid to the tip."""
    from closedloop.viewer.beam_curves import beam_curves

    chained = {"ground": [rod("mid_joint"), rod("tip_joint", start="mid_joint")]}
    clm, q, L, e = mid_span(tmp_path, chained)
    data = clm.model.createData()
    pin.forwardKinematics(clm.model, data, q)
    poses = np.array([M.homogeneous for M in data.oMi])
    curves = {c.name: c.points for c in beam_curves(clm.model, poses)}
    for name, (a, b) in {"ground_beam_mid_joint": (0.0, 0.5),
                         "ground_beam_tip_joint": (0.5, 1.0)}.items():  # fmt: skip
        u = np.linspace(a, b, len(curves[name]))[:, None]
        np.testing.assert_allclose(curves[name], u * L * e, atol=1e-12)


def test_closure_file_takes_a_list_of_beams(tmp_path):
    """The same chain written in a closure file (YAML) as given in Python."""
    chained = {"ground": [rod("mid_joint"), rod("tip_joint", start="mid_joint")]}
    clm, q, _, _ = mid_span(tmp_path, chained)
    text = (
        "closed_loop: []\ntype: []\nname_mot: []\nsprings: {}\nbeams:\n  ground:\n"
        f"    - {rod('mid_joint')}\n    - {rod('tip_joint', start='mid_joint')}\n"
    )
    (tmp_path / "rod.yaml").write_text(text)
    from_file = load_model(tmp_path / "rod.urdf", tmp_path / "rod.yaml", geometry=False)
    np.testing.assert_array_equal(cl.compliance(from_file, q, "tip").C,
                                  cl.compliance(clm, q, "tip").C)  # fmt: skip


def test_a_link_with_beams_takes_no_second_entry(tmp_path):
    """Beams added twice to one link (``with_beams`` on a model that has them): refused,
    naming the existing beam, whatever the form of either entry."""
    clm, _ = ternary(tmp_path)
    with pytest.raises(BeamError, match=r"beam 'hub': the link already has a beam.*'hub_beam_ja'"):
        clm.with_beams({"hub": rod("ja")})
    single, _ = ternary(tmp_path, {"hub": rod("ja")})
    with pytest.raises(BeamError, match=r"beam 'hub': the link already has a beam.*'hub_beam'"):
        single.with_beams({"hub": [rod("jb")]})


def test_an_ordinary_joint_named_like_a_beam_is_no_beam(tmp_path):
    """A link's own revolute joint ``arm_beam_x`` was taken for a beam's virtual joint: a
    preloaded compliance failed on its one coordinate and a beam on ``arm`` was refused as
    a second one. It is an ordinary joint: the results are those of the same robot with the
    joint named ``elbow`` (the same arithmetic: equal to the last bit)."""
    robots = {}
    for name in ("elbow", "arm_beam_x"):
        path = urdf_of(
            tmp_path, name, ["base", "arm", "tip"],
            [("shoulder", "base", "arm", (0, 0, 0), (0, 0, 0), "revolute", (0, 0, 1)),
             (name, "arm", "tip", (0.5, 0, 0), (0, 0, 0), "revolute", (0, 1, 0))],
        )  # fmt: skip
        robots[name] = load_model(path, springs={"shoulder": 100.0, name: 50.0}, geometry=False)
    plain, named = robots["elbow"], robots["arm_beam_x"]
    assert inserted_beams(named.model) == [] and beam_joints(named) == ()
    q, preload = np.array([0.3, 0.2]), np.array([1.0, 2.0, 3.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(
        cl.compliance(named, q, "tip", preload=preload).C,
        cl.compliance(plain, q, "tip", preload=preload).C,
    )
    beamed, beamed_plain = (
        named.with_beams({"arm": rod("arm_beam_x")}),
        plain.with_beams({"arm": rod("elbow")}),
    )
    assert [b.name for b in inserted_beams(beamed.model)] == ["arm_beam"]
    q_beam = map_configuration(named.model, beamed.model, q)
    np.testing.assert_array_equal(
        cl.compliance(beamed, q_beam, "tip", preload=preload).C,
        cl.compliance(beamed_plain, q_beam, "tip", preload=preload).C,
    )


#: The one-element beam-column's error at P L^2 / EI = 1 (tests/model/test_beams.py: 0.2 %):
#: two elements of the chain err less (measured: 0.015 %).
RTOL_BEAM_COLUMN = 2e-3


def test_chained_beams_under_compression_are_a_beam_column(tmp_path):
    """origin -> mid -> tip under an axial compression P = EI / L^2 at the tip: both beams'
    energies with their shortening give the beam-column's transverse tip compliance
    (tan kL - kL) / (k^3 EI) (Timoshenko & Gere), as one beam in two elements does."""
    chained = {"ground": [rod("mid_joint"), rod("tip_joint", start="mid_joint")]}
    clm, q, L, e = mid_span(tmp_path, chained)
    split, q2, _, _ = mid_span(tmp_path, {"ground": rod("tip_joint", elements=2)})
    EI = STEEL["E"] * I
    P = EI / L**2
    kL = math.sqrt(P / EI) * L
    exact = (math.tan(kL) - kL) * L**3 / (kL**3 * EI)
    across = np.cross(e, [0.0, 0.0, 1.0])
    across /= np.linalg.norm(across)
    preload = np.r_[-P * e, np.zeros(3)]
    C = cl.compliance(clm, q, "tip", preload=preload).C
    np.testing.assert_allclose(across @ C[:3, :3] @ across, exact, rtol=RTOL_BEAM_COLUMN)
    C2 = cl.compliance(split, q2, "tip", preload=preload).C
    assert_close_in_norm(C, C2, RTOL_EXACT)


#: Each end's (mass [kg], centre of mass [m] and rotational inertia about it [kg m^2], in
#: the end link's frame), the end joints' placements on the massless hub (xyz [m], rpy).
END_MASSES = {
    "a": (1.0, [0.01, -0.02, 0.03], [0.01, 0.02, 0.03], [0.4, -0.1, 0.2], [0.3, -0.5, 1.1]),
    "b": (2.5, [0.0, 0.04, 0.0], [0.05, 0.04, 0.06], [-0.1, 0.3, 0.1], [-0.7, 0.2, 0.4]),
}


def massless_hub(tmp_path, chained: bool) -> str:
    """A massless link ``hub`` on a hinge, its fixed child links ``a`` and ``b`` carrying
    the masses of :data:`END_MASSES` (``chained``: b's joint on a, else on the hub)."""
    links, joints = ['<link name="base"/><link name="hub"/>'], []
    for n, (m, c, I, xyz, rpy) in END_MASSES.items():
        links.append(
            f'<link name="{n}"><inertial><origin xyz="{" ".join(map(str, c))}"/><mass '
            f'value="{m}"/><inertia ixx="{I[0]}" iyy="{I[1]}" izz="{I[2]}" ixy="0" ixz="0" '
            'iyz="0"/></inertial></link>'
        )
        parent = "a" if chained and n == "b" else "hub"
        joints.append(
            f'<joint name="j{n}" type="fixed"><parent link="{parent}"/><child link="{n}"/>'
            f'<origin xyz="{" ".join(map(str, xyz))}" rpy="{" ".join(map(str, rpy))}"/></joint>'
        )
    hinge = (
        '<joint name="hinge" type="revolute"><parent link="base"/><child link="hub"/>'
        '<axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
    )
    path = tmp_path / "hub.urdf"
    path.write_text(f'<robot name="hub">{"".join(links)}{hinge}{"".join(joints)}</robot>')
    return str(path)


@pytest.mark.parametrize("chained", [False, True])
def test_a_massless_link_with_beams_to_masses_loads_them_on_the_tips(tmp_path, chained):
    """A massless link whose beams end at fixed links with masses: two beams, a and b
    each at the tip of its own, or one beam to a that carries b beyond it (``chained``).
    Each virtual joint (placed at its end joint, in its axes) carries the mass, centre of
    mass and inertia of its end link as the URDF gives them (with b's beyond it), the
    link's joint none (it was Pinocchio's RuntimeError "The 3d inertia should be positive",
    from the rounding left on the massless link)."""
    path = massless_hub(tmp_path, chained)
    beams = {"hub": rod("ja") if chained else [rod("ja"), rod("jb")]}
    model = load_model(path, beams=beams, geometry=False).model
    hinge = model.inertias[model.getJointId("hinge")]
    # rounding of the subtraction of the tips' inertias about the hinge (~0.5 kg m^2)
    np.testing.assert_allclose(hinge.mass, 0.0, atol=1e-12)
    np.testing.assert_allclose(hinge.inertia, np.zeros((3, 3)), atol=1e-12)
    if chained:  # b by hand: its inertial in the frame of a (the tip), about a's origin
        (m_a, c_a, I_a, _, _), (m_b, c_b, I_b, xyz, rpy) = END_MASSES.values()
        M = pin.SE3(pin.rpy.rpyToMatrix(*rpy), np.array(xyz))
        c_b = M.act(np.array(c_b))
        c = (m_a * np.array(c_a) + m_b * c_b) / (m_a + m_b)
        I_b = M.rotation @ np.diag(I_b) @ M.rotation.T
        parallel = lambda m, r: m * (r @ r * np.eye(3) - np.outer(r, r))  # noqa: E731
        I = np.diag(I_a) + parallel(m_a, c_a - c) + I_b + parallel(m_b, c_b - c)
        expected = {"hub_beam": (m_a + m_b, c, I)}
    else:
        expected = {f"hub_beam_j{n}": (m, c, np.diag(I)) for n, (m, c, I, _, _) in
                    END_MASSES.items()}  # fmt: skip
    for joint, (m, c, I) in expected.items():
        inertia = model.inertias[model.getJointId(joint)]
        np.testing.assert_allclose(inertia.mass, m, rtol=1e-12)
        np.testing.assert_allclose(inertia.lever, c, atol=1e-12)
        np.testing.assert_allclose(inertia.inertia, I, atol=1e-12)
