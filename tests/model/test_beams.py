"""Flexible links as beams (closedloop.model.beams) against independent references.

References: the closed forms of a clamped cantilever (written here in beam axes, and a
coordinate-free form for round sections), a direct-stiffness frame finite-element model
written in this file (12x12 3D Euler-Bernoulli elements, one per member: exact for nodal
loads), the superposition J K_q^-1 J^T + sum of transported beam compliances on a UR5,
and the nonlinear equilibrium solver.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from helpers import UR5_BEAM_ENDS, assert_close_in_norm

import closedloop as cl
from closedloop.elastostatics.compliance import energy_shares
from closedloop.elastostatics.statics import solve_equilibrium
from closedloop.exceptions import ModelFileError
from closedloop.io.loader import load_model, robot_data_dir
from closedloop.model.beam_section import Shape, geometry_section
from closedloop.model.beams import BeamError, map_configuration

# Library vs closed form / FEM: the same beam theory through different algebra (6x6
# inverses, Cholesky, SVD of the spring factor, transports); cond of the stiffness up to
# ~1e8 (slender members): rounding ~1e-12 relative, the issue asks for 1e-9.
RTOL_EXACT = 1e-9
# A difference of two compliances (Timoshenko - Euler-Bernoulli) vs its closed form: the
# rounding of C (~1e-12 of its largest entry, a rotational one in rad/(N m)) relative to
# the shear term in m/N, ~1e4 times smaller here.
RTOL_DIFFERENCE = 1e-7
# Nonlinear statics at small loads vs C w: second-order terms ~ the rotations (<= 1e-6).
RTOL_SMALL_LOAD = 1e-5

STEEL = {"E": 2.1e11, "G": 8.1e10}
ALU = {"E": 7.0e10, "G": 2.6e10}


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def urdf_of(tmp_path, name: str, links: list[str], joints: list[tuple]) -> str:
    """A URDF file of massive links and joints (name, parent, child, xyz, rpy, type, axis)."""
    body = [f'<robot name="{name}">']
    inertial = (
        '<inertial><mass value="1.0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" '
        'ixy="0" ixz="0" iyz="0"/></inertial>'
    )
    body += [f'<link name="{n}">{inertial}</link>' for n in links]
    for jn, parent, child, xyz, rpy, kind, axis in joints:
        body.append(
            f'<joint name="{jn}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{" ".join(map(str, xyz))}" rpy="{" ".join(map(str, rpy))}"/>'
            + (f'<axis xyz="{" ".join(map(str, axis))}"/>' if axis else "")
            + ('<limit lower="-3" upper="3" effort="1" velocity="1"/>' if kind != "fixed" else "")
            + "</joint>"
        )
    path = tmp_path / f"{name}.urdf"
    path.write_text("\n".join([*body, "</robot>"]))
    return str(path)


# ------------------------------------------------------------------------ cantilever
def cantilever_compliance_beam_axes(L, E, G, A, Iy, Iz, J, kappa=None):
    """Tip compliance of a clamped beam in its axes (x along it), written out directly."""
    C = np.zeros((6, 6))
    C[0, 0] = L / (E * A)
    C[3, 3] = L / (G * J)
    C[1, 1] = L**3 / (3 * E * Iz) + (L / (kappa * G * A) if kappa else 0.0)
    C[5, 5] = L / (E * Iz)
    C[1, 5] = C[5, 1] = L**2 / (2 * E * Iz)  # f_y turns the tip about +z
    C[2, 2] = L**3 / (3 * E * Iy) + (L / (kappa * G * A) if kappa else 0.0)
    C[4, 4] = L / (E * Iy)
    C[2, 4] = C[4, 2] = -(L**2) / (2 * E * Iy)  # f_z turns the tip about -y
    return C


def round_tip_compliance(L, e, E, G, A, I) -> np.ndarray:
    """Tip compliance of a clamped beam of round section (Iy = Iz = I, J = 2 I) along the
    unit vector e, in any axes at the tip: no section axes needed. From the beam-axes
    forms: v = -L^2/(2EI) [e]x n, theta = L^2/(2EI) [e]x f for the bending coupling."""
    P = np.eye(3) - np.outer(e, e)
    return np.block([
        [L / (E * A) * np.outer(e, e) + L**3 / (3 * E * I) * P, -(L**2) / (2 * E * I) * _skew(e)],
        [L**2 / (2 * E * I) * _skew(e), L / (G * 2 * I) * np.outer(e, e) + L / (E * I) * P],
    ])  # fmt: skip


AXIS = np.array([1.0, 2.0, 2.0]) / 3.0  # along no axis of the link frame
Y_AXIS = np.array([0.0, 0.0, 1.0])  # made orthogonal to AXIS: the section's y


def beam_frame() -> np.ndarray:
    y = Y_AXIS - (Y_AXIS @ AXIS) * AXIS
    y /= np.linalg.norm(y)
    return np.column_stack([AXIS, y, np.cross(AXIS, y)])


def cantilever(tmp_path, section: dict, theory="euler-bernoulli", length=0.7):
    """A beam on link 'ground' (the root) to a fixed joint at length * AXIS with rotated
    axes; the tip link 'tip' is loaded. Returns the model and its neutral configuration."""
    path = urdf_of(
        tmp_path,
        "cantilever",
        ["ground", "tip"],
        [("tip_joint", "ground", "tip", length * AXIS, (0.3, -0.5, 1.1), "fixed", None)],
    )
    spec = {"end": "tip_joint", **STEEL, "section": section, "theory": theory}
    clm = load_model(path, beams={"ground": spec}, geometry=False)
    return clm, pin.neutral(clm.model)


@pytest.mark.parametrize("theory", ["euler-bernoulli", "timoshenko"])
def test_cantilever_rectangle_all_six_directions(tmp_path, theory):
    b, h, L = 0.02, 0.05, 0.7
    section = {"shape": "rectangle", "b": b, "h": h, "y_axis": Y_AXIS.tolist()}
    clm, q = cantilever(tmp_path, section, theory, L)
    assert clm.model.nv == 6 and set(clm.spring_blocks) == {"ground_beam"}
    a, c = max(b, h), min(b, h)
    J = a * c**3 * (1 / 3 - 0.21 * (c / a) * (1 - c**4 / (12 * a**4)))  # Roark
    nu = STEEL["E"] / (2 * STEEL["G"]) - 1
    kappa = 10 * (1 + nu) / (12 + 11 * nu) if theory == "timoshenko" else None
    Cb = cantilever_compliance_beam_axes(L, **STEEL, A=b * h, Iy=b * h**3 / 12,
                                         Iz=h * b**3 / 12, J=J, kappa=kappa)  # fmt: skip
    C = cl.compliance(clm, q, "tip").C  # world axes = link axes at the tip point
    R6 = np.kron(np.eye(2), beam_frame())  # beam axes in the world
    for i in range(6):  # a unit force or moment along each beam axis
        twist_beam_axes = R6.T @ C @ R6[:, i]
        assert_close_in_norm(twist_beam_axes, Cb[:, i], RTOL_EXACT)


def test_cantilever_tube_coordinate_free(tmp_path):
    d, t, L = 0.04, 0.004, 0.5
    clm, q = cantilever(tmp_path, {"shape": "tube", "d": d, "t": t}, length=L)
    ri = d / 2 - t
    A, I = math.pi * ((d / 2) ** 2 - ri**2), math.pi * ((d / 2) ** 4 - ri**4) / 4
    expected = round_tip_compliance(L, AXIS, STEEL["E"], STEEL["G"], A, I)
    assert_close_in_norm(cl.compliance(clm, q, "tip").C, expected, RTOL_EXACT)


def test_timoshenko_tube_adds_cowper_shear(tmp_path):
    d, t, L = 0.05, 0.01, 0.3  # a short thick tube: shear matters
    sec = {"shape": "tube", "d": d, "t": t}
    eb, q = cantilever(tmp_path, sec, "euler-bernoulli", L)
    ti, _ = cantilever(tmp_path, sec, "timoshenko", L)
    m, nu = (d - 2 * t) / d, STEEL["E"] / (2 * STEEL["G"]) - 1
    kappa = (
        6 * (1 + nu) * (1 + m**2) ** 2 / ((7 + 6 * nu) * (1 + m**2) ** 2 + (20 + 12 * nu) * m**2)
    )  # Cowper (1966)
    A = math.pi * ((d / 2) ** 2 - (d / 2 - t) ** 2)
    shear = L / (kappa * STEEL["G"] * A) * (np.eye(3) - np.outer(AXIS, AXIS))
    diff = cl.compliance(ti, q, "tip").C - cl.compliance(eb, q, "tip").C
    expected = np.zeros((6, 6))
    expected[:3, :3] = shear  # shear adds to the transverse deflection under a force only
    assert_close_in_norm(diff, expected, RTOL_DIFFERENCE)


def test_a_y_axis_given_as_an_array_is_the_same_as_its_list(tmp_path):
    """From Python, y_axis may be a NumPy array (it was refused as "expected 3 numbers")."""
    rect = {"shape": "rectangle", "b": 0.02, "h": 0.05}
    listed = cantilever(tmp_path, {**rect, "y_axis": Y_AXIS.tolist()})[0]
    array = cantilever(tmp_path, {**rect, "y_axis": Y_AXIS})[0]
    np.testing.assert_array_equal(array.spring_blocks["ground_beam"],
                                  listed.spring_blocks["ground_beam"])  # fmt: skip


def test_stiffness_6x6_equals_its_beam(tmp_path):
    clm, q = cantilever(tmp_path, {"shape": "circle", "d": 0.03})
    K = clm.spring_blocks["ground_beam"]
    tip = ("tip_joint", "ground", "tip", 0.7 * AXIS, (0.3, -0.5, 1.1), "fixed", None)
    path = urdf_of(tmp_path, "c2", ["ground", "tip"], [tip])
    given = load_model(path, beams={"ground": {"stiffness_6x6": K.tolist()}}, geometry=False)
    spec = {"compliance_6x6": np.linalg.inv(K)}
    comp = load_model(path, beams={"ground": spec}, geometry=False)
    C = cl.compliance(clm, q, "tip").C
    assert_close_in_norm(cl.compliance(given, q, "tip").C, C, RTOL_EXACT)
    assert_close_in_norm(cl.compliance(comp, q, "tip").C, C, RTOL_EXACT)


# ------------------------------------------------------------------------ section: geometry
def shape_axes(i: int) -> np.ndarray:
    """(3, 3) axes of a URDF shape (columns, link frame) whose axis i lies along AXIS."""
    R = beam_frame()  # columns AXIS, y, z
    return np.roll(R, i, axis=1)  # column i is AXIS


def geometry_urdf(tmp_path, elements: str, length=0.7) -> str:
    """The cantilever's URDF with ``elements`` (collision / visual XML) on link 'ground'."""
    xyz = " ".join(map(str, length * AXIS))
    path = tmp_path / "shaped.urdf"
    path.write_text(
        f'<robot name="shaped"><link name="ground">{elements}</link><link name="tip">'
        '<inertial><mass value="1.0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" '
        'ixz="0" iyz="0"/></inertial></link><joint name="tip_joint" type="fixed">'
        f'<parent link="ground"/><child link="tip"/><origin xyz="{xyz}" rpy="0.3 -0.5 1.1"/>'
        "</joint></robot>"
    )
    return str(path)


def element(source: str, geometry: str, axes: np.ndarray) -> str:
    rpy = " ".join(f"{v:.17g}" for v in pin.rpy.matrixToRpy(axes))
    return (
        f'<{source}><origin xyz="0.1 0 0" rpy="{rpy}"/><geometry>{geometry}</geometry></{source}>'
    )


def geometry_block(path, section="geometry", theory="euler-bernoulli") -> np.ndarray:
    spec = {"end": "tip_joint", **STEEL, "section": section, "theory": theory}
    return load_model(path, beams={"ground": spec}, geometry=False).spring_blocks["ground_beam"]


@pytest.mark.parametrize("theory", ["euler-bernoulli", "timoshenko"])
def test_geometry_cylinder_is_a_circle_of_its_diameter(tmp_path, theory):
    """The collision cylinder (along the beam, its own rotation about its axis arbitrary)
    is used, not the visual box."""
    axes = shape_axes(2) @ pin.rpy.rpyToMatrix(0.0, 0.0, 0.4)  # turned about its own axis
    shapes = element("collision", '<cylinder radius="0.015" length="0.3"/>', axes) + element(
        "visual", '<box size="0.1 0.1 0.1"/>', shape_axes(0)
    )
    path = geometry_urdf(tmp_path, shapes)
    expected = geometry_block(path, {"shape": "circle", "d": 0.03}, theory)
    assert_close_in_norm(geometry_block(path, theory=theory), expected, 1e-12)


@pytest.mark.parametrize("along", [0, 1, 2])
def test_geometry_box_is_its_rectangle_across_the_beam(tmp_path, along):
    """A visual box (no collision element) of sides 0.01, 0.02, 0.05 m along its axes,
    axis ``along`` along the beam: the rectangle of the other two sides, the side along box
    axis along + 1 as b (section y), the one along along + 2 as h; equivalently the same
    rectangle turned by 90 degrees (b and h swapped, y along the other box axis)."""
    sizes = np.array([0.01, 0.02, 0.05])
    axes = shape_axes(along)
    size = " ".join(map(str, sizes))
    path = geometry_urdf(tmp_path, element("visual", f'<box size="{size}"/>', axes))
    j, k = (along + 1) % 3, (along + 2) % 3
    rect = {"shape": "rectangle", "b": sizes[j], "h": sizes[k], "y_axis": axes[:, j].tolist()}
    turned = {"shape": "rectangle", "b": sizes[k], "h": sizes[j], "y_axis": axes[:, k].tolist()}
    K = geometry_block(path)
    assert_close_in_norm(K, geometry_block(path, rect), 1e-12)
    assert_close_in_norm(K, geometry_block(path, turned), 1e-9)  # other algebra: rounding


@pytest.mark.parametrize(
    "shapes, match",
    [
        ("", r"beam 'ground': section geometry: the link has no collision or visual geometry"),
        ('<collision><geometry><mesh filename="arm.stl"/></geometry></collision>',
         r"the link's collision geometry is \['mesh'\]; expected exactly one cylinder or box"),
        ('<visual><geometry><sphere radius="0.02"/></geometry></visual>',
         r"the link's visual geometry is \['sphere'\]; expected exactly one cylinder or box"),
        (2 * '<collision><geometry><cylinder radius="0.01" length="0.1"/></geometry></collision>',
         r"collision geometry is \['cylinder', 'cylinder'\]; expected exactly one"),
        ('<collision><geometry><cylinder radius="0.01" length="0.1"/></geometry></collision>',
         r"the collision cylinder's axis \[0.0, 0.0, 1.0\] \(link frame\) is at 48.2 deg "
         r"from the beam \[0.333333, 0.666667, 0.666667\]; expected along it"),  # acos(2/3)
        (element("collision", '<cylinder radius="-0.01" length="0.1"/>', shape_axes(2)),
         r"beam 'ground': section d is -0.02; expected a finite number > 0"),
    ],
)  # fmt: skip
def test_bad_geometry_sections_are_refused(tmp_path, shapes, match):
    with pytest.raises(BeamError, match=match):
        geometry_block(geometry_urdf(tmp_path, shapes))


@pytest.mark.parametrize(
    ("kind", "sizes", "rpy", "attribute", "text"),
    [  # Python's float read 0.015 m, 0.015 m, rpy (0, 0, 0)
        ("cylinder", {"radius": "0_015"}, "0 0 0", "<cylinder> radius", "0_015"),
        ("cylinder", {"radius": "0.0\u0661\u0665"}, "0 0 0", "<cylinder> radius",
         "0.0\u0661\u0665"),  # Arabic-Indic digits
        ("box", {"size": "0.01 0.01 0.3"}, "0 0 0_0", "<origin> rpy", "0 0 0_0"),
        ("cylinder", {"radius": "nan"}, "0 0 0", "<cylinder> radius", "nan"),
    ],
)  # fmt: skip
def test_geometry_numbers_are_ascii_decimals(kind, sizes, rpy, attribute, text):
    """A size or rpy of the URDF shape (:func:`urdf_shapes`) that is not finite numbers in
    ASCII decimal notation is refused naming the file, the link, the element and the value.
    (Loading such a URDF, Pinocchio's parser refuses it first; ``apply_beams`` may be
    given any URDF file.)"""
    shape = Shape("collision", kind, sizes, rpy, "robot file 'r.urdf': link 'ground'")
    with pytest.raises(ModelFileError) as info:
        geometry_section("ground", [shape], np.array([0.0, 0.0, 1.0]))
    assert str(info.value) == (
        f"robot file 'r.urdf': link 'ground': <collision> {attribute} is {text!r}; expected "
        f"{3 if 'rpy' in attribute else 1} finite numbers in ASCII decimal notation"
    )


def test_geometry_section_needs_the_urdf(tmp_path):
    shapes = element("collision", '<cylinder radius="0.015" length="0.3"/>', shape_axes(2))
    clm = load_model(geometry_urdf(tmp_path, shapes), geometry=False)
    spec = {"end": "tip_joint", **STEEL, "section": "geometry"}
    with pytest.raises(BeamError, match=r"beam 'ground': section geometry is read from the link"):
        clm.with_beams({"ground": spec})


# ------------------------------------------------------------------------ frame FEM
def element_stiffness(p1, p2, E, G, A, I, J) -> np.ndarray:
    """(12, 12) 3D Euler-Bernoulli frame element, round section (Iy = Iz = I), global axes,
    dofs (u, theta) of node 1 then node 2 (the textbook direct stiffness element)."""
    L = np.linalg.norm(p2 - p1)
    x = (p2 - p1) / L
    y = np.cross([0.0, 0.0, 1.0], x) if abs(x[2]) < 0.9 else np.cross([1.0, 0, 0], x)
    y /= np.linalg.norm(y)
    lam = np.vstack([x, y, np.cross(x, y)])  # rows: local axes in global
    k = np.zeros((12, 12))
    EA, GJ, EI = E * A / L, G * J / L, E * I
    for a, b, s in ((1, 5, 1.0), (2, 4, -1.0)):  # (v_y, th_z) and (v_z, th_y) planes
        idx = [a, b, a + 6, b + 6]
        kb = EI / L**3 * np.array([
            [12, 6 * L * s, -12, 6 * L * s],
            [6 * L * s, 4 * L**2, -6 * L * s, 2 * L**2],
            [-12, -6 * L * s, 12, -6 * L * s],
            [6 * L * s, 2 * L**2, -6 * L * s, 4 * L**2],
        ])  # fmt: skip
        k[np.ix_(idx, idx)] += kb
    for a, v in ((0, EA), (3, GJ)):
        k[np.ix_([a, a + 6], [a, a + 6])] += v * np.array([[1, -1], [-1, 1]])
    T = np.kron(np.eye(4), lam)
    return T.T @ k @ T


def fem_compliance(nodes, members, fixed, loaded, section) -> np.ndarray:
    """(6, 6) compliance of node ``loaded`` (global axes) of a frame of round members."""
    n = len(nodes)
    K = np.zeros((6 * n, 6 * n))
    for i, j in members:
        dofs = [*range(6 * i, 6 * i + 6), *range(6 * j, 6 * j + 6)]
        K[np.ix_(dofs, dofs)] += element_stiffness(nodes[i], nodes[j], **section)
    free = [d for d in range(6 * n) if d // 6 not in fixed]
    C = np.linalg.inv(K[np.ix_(free, free)])
    at = [free.index(d) for d in range(6 * loaded, 6 * loaded + 6)]
    return C[np.ix_(at, at)]


def round_section(d):
    r = d / 2
    A, I = math.pi * r**2, math.pi * r**4 / 4
    return {**STEEL, "A": A, "I": I, "J": 2 * I}


def frame_files(tmp_path, name, nodes, closure_to_ground: bool, d=0.03):
    """URDF + closure file of a frame: member i is link 'm<i>' from node i to node i+1,
    joined by fixed joints; with ``closure_to_ground`` the last node is welded ('6d') to a
    ground frame at the same place."""
    links = ["ground"] + [f"m{i}" for i in range(len(nodes) - 1)] + ["end"]
    joints = [("j0", "ground", "m0", nodes[0], (0, 0, 0), "fixed", None)]
    for i in range(len(nodes) - 1):
        child = f"m{i + 1}" if i + 2 < len(nodes) else "end"
        joints.append((f"j{i + 1}", f"m{i}", child, nodes[i + 1] - nodes[i], (0, 0, 0), "fixed",
                       None))  # fmt: skip
    if closure_to_ground:
        links.append("anchor")
        joints.append(("ja", "ground", "anchor", nodes[-1], (0, 0, 0), "fixed", None))
    urdf = urdf_of(tmp_path, name, links, joints)
    beams = "\n".join(
        f"  m{i}: {{end: j{i + 1}, E: 2.1e11, G: 8.1e10, section: {{shape: circle, d: {d}}}}}"
        for i in range(len(nodes) - 1)
    )  # numbers written 2.1e11: strings for a YAML 1.1 parser
    closure = "closed_loop: [[end, anchor]]\ntype: ['6d']\n" if closure_to_ground else ""
    yaml_path = tmp_path / f"{name}.yaml"
    yaml_path.write_text(f"{closure}name_mot: []\nbeams:\n{beams}\n")
    return urdf, str(yaml_path)


def test_closed_portal_frame_matches_fem(tmp_path):
    H, W = 1.2, 0.8
    nodes = np.array([[0, 0, 0], [0, 0, H], [W, 0, H], [W, 0, 0]], dtype=float)
    urdf, closures = frame_files(tmp_path, "portal", nodes, closure_to_ground=True)
    clm = load_model(urdf, closures, geometry=False)
    assert clm.model.nv == 18 and len(clm.closures) == 1
    q = pin.neutral(clm.model)
    fem_B = fem_compliance(nodes, [(0, 1), (1, 2), (2, 3)], {0, 3}, 1, round_section(0.03))
    fem_C = fem_compliance(nodes, [(0, 1), (1, 2), (2, 3)], {0, 3}, 2, round_section(0.03))
    res_B, res_C = cl.compliance(clm, q, "m1"), cl.compliance(clm, q, "m2")  # nodes B, C
    assert_close_in_norm(res_B.C, fem_B, RTOL_EXACT)
    assert_close_in_norm(res_C.C, fem_C, RTOL_EXACT)
    general = cl.compliance(clm, q, "m2", path="null-space")
    assert_close_in_norm(general.C, res_C.C, 1e-12)


def test_spatial_frame_with_torsion_matches_fem(tmp_path):
    nodes = np.array([[0, 0, 0], [0, 0, 1.0], [0.6, 0, 1.0], [0.6, 0.5, 1.0], [0.6, 0.5, 0.6]])
    urdf, closures = frame_files(tmp_path, "spatial", nodes, closure_to_ground=False, d=0.02)
    clm = load_model(urdf, closures, geometry=False)
    fem = fem_compliance(nodes, [(i, i + 1) for i in range(4)], {0}, 4, round_section(0.02))
    assert_close_in_norm(cl.compliance(clm, pin.neutral(clm.model), "end").C, fem, RTOL_EXACT)


# ------------------------------------------------------------------------ UR5
TUBE = (0.06, 0.004)  # d, t [m]


@pytest.fixture(scope="module")
def ur5_beams():
    urdf = robot_data_dir() / "ur_description/urdf/ur5_robot.urdf"
    k = [2e4, 1.5e4, 1e4, 3e3, 2e3, 1e3]
    base = load_model(urdf, springs=dict(zip(
        [f"{n}" for n in ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                          "wrist_1_joint", "wrist_2_joint", "wrist_3_joint")], k, strict=True)),
        geometry=False)  # fmt: skip
    tube = {**ALU, "section": {"shape": "tube", "d": TUBE[0], "t": TUBE[1]}}
    beams = {link: {**tube, "end": end} for link, end in UR5_BEAM_ENDS.items()}
    return base, base.with_beams(beams), np.array([0.3, -1.0, 1.5, -0.5, 1.2, 0.3])


def ur5_by_hand(base, q):
    """(J, [(beam joint, Ad, C_b)]): the rigid UR5's Jacobian of ee_link (world axes, at
    its origin) and, per tube, its tip compliance C_b (world axes, at the end joint) and
    the transport Ad of a tip twist to ee_link: C = J K_q^-1 J^T + sum Ad C_b Ad^T."""
    m, d = base.model, base.model.createData()
    pin.framesForwardKinematics(m, d, q)
    fid = m.getFrameId("ee_link")
    J = pin.computeFrameJacobian(m, d, q, fid, pin.LOCAL_WORLD_ALIGNED)
    E, G = ALU["E"], ALU["G"]
    r = TUBE[0] / 2
    A, I = math.pi * (r**2 - (r - TUBE[1]) ** 2), math.pi * (r**4 - (r - TUBE[1]) ** 4) / 4
    p_tool, parts = d.oMf[fid].translation, []
    for link, end in UR5_BEAM_ENDS.items():
        start = d.oMf[m.getFrameId(link)].translation
        tip = d.oMf[m.getFrameId(end)].translation
        L = np.linalg.norm(tip - start)
        Cb = round_tip_compliance(L, (tip - start) / L, E, G, A, I)
        Ad = np.block([[np.eye(3), -_skew(p_tool - tip)], [np.zeros((3, 3)), np.eye(3)]])
        parts.append((f"{link}_beam", Ad, Cb))
    return J, parts


def test_ur5_tubes_superpose(ur5_beams):
    base, flex, q = ur5_beams
    assert flex.model.nv == 42
    J, parts = ur5_by_hand(base, q)
    C = J @ np.diag(1 / base.stiffness) @ J.T + sum(Ad @ Cb @ Ad.T for _, Ad, Cb in parts)
    qb = map_configuration(base.model, flex.model, q)
    res = cl.compliance(flex, qb, "ee_link")
    assert res.path == "serial"
    assert_close_in_norm(res.C, C, RTOL_EXACT)
    general = cl.compliance(flex, qb, "ee_link", path="null-space")
    assert_close_in_norm(general.C, res.C, 1e-12)


def test_ur5_energy_shares_by_hand(ur5_beams):
    base, flex, q = ur5_beams
    J, parts = ur5_by_hand(base, q)
    w = np.array([30.0, -10.0, 20.0, 1.0, -2.0, 0.5])
    res = cl.compliance(flex, map_configuration(base.model, flex.model, q), "ee_link")
    shares = energy_shares(flex, res, w)
    work = w @ res.C @ w
    tau = J.T @ w  # joint torques of the rigid arm
    expected = {n: tau[i] ** 2 / base.stiffness[i] / work for i, n in
                enumerate(base.model.names[1:])}  # fmt: skip
    expected |= {n: (Ad.T @ w) @ Cb @ (Ad.T @ w) / work for n, Ad, Cb in parts}
    assert set(shares) == set(expected)
    for name, share in expected.items():
        assert shares[name] == pytest.approx(share, rel=RTOL_EXACT, abs=1e-12)
    assert sum(shares.values()) == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("size", [1e-300, 1e200, 1e308])
def test_energy_shares_do_not_depend_on_the_size_of_the_load(ur5_beams, size):
    """Shares are ratios of energies, quadratic in the load: the same for a load of any
    size, tiny ones (energies below the smallest double) and huge ones (above the largest)."""
    base, flex, q = ur5_beams
    w = np.array([30.0, -10.0, 20.0, 1.0, -2.0, 0.5])
    res = cl.compliance(flex, map_configuration(base.model, flex.model, q), "ee_link")
    reference = energy_shares(flex, res, w)
    shares = energy_shares(flex, res, w * (size / 30.0))
    assert shares.keys() == reference.keys()
    np.testing.assert_allclose(list(shares.values()), list(reference.values()), rtol=1e-14)


def test_ur5_beams_keep_kinematics_and_weight(ur5_beams):
    base, flex, q = ur5_beams
    qb = map_configuration(base.model, flex.model, q)
    d0, d1 = base.model.createData(), flex.model.createData()
    pin.framesForwardKinematics(base.model, d0, q)
    pin.framesForwardKinematics(flex.model, d1, qb)
    for f in base.model.frames:
        M0, M1 = d0.oMf[base.model.getFrameId(f.name)], d1.oMf[flex.model.getFrameId(f.name)]
        np.testing.assert_allclose(M1.homogeneous, M0.homogeneous, atol=1e-12)
    g0 = pin.computeGeneralizedGravity(base.model, d0, q)
    g1 = pin.computeGeneralizedGravity(flex.model, d1, qb)
    idx = [flex.joint_v_slice(n).start for n in base.model.names[1:]]
    np.testing.assert_allclose(g1[idx], g0, rtol=1e-12, atol=1e-12)


def test_ur5_beams_small_load_statics(ur5_beams):
    base, flex, q = ur5_beams
    qb = map_configuration(base.model, flex.model, q)
    w = np.array([1.0, -2.0, 1.5, 0.05, -0.1, 0.02]) * 1e-2  # rotations ~1e-6 rad
    eq = solve_equilibrium(flex, qb, "ee_link", w)
    assert_close_in_norm(eq.displacement, cl.compliance(flex, qb, "ee_link").C @ w,
                         RTOL_SMALL_LOAD)  # fmt: skip


# ------------------------------------------------------------------------ bad input
#: The message of a beam whose tip compliance or stiffness leaves the float range.
BEYOND = r"beam 'arm': E = .* Pa, .* give a tip compliance or stiffness beyond the floating"


def _tip_file(tmp_path):
    return urdf_of(tmp_path, "bad", ["ground", "arm", "tip"], [
        ("hinge", "ground", "arm", (0, 0, 0.1), (0, 0, 0), "revolute", (0, 0, 1)),
        ("tip_joint", "arm", "tip", (0.5, 0, 0), (0, 0, 0), "fixed", None),
    ])  # fmt: skip


@pytest.mark.parametrize(
    "beam, match",
    [
        ({"E": -2.1e11}, r"beam 'arm': E \[Pa\] is -210000000000.0; expected a finite number > 0"),
        ({"G": 0}, r"beam 'arm': G \[Pa\] is 0; expected a finite number > 0"),
        ({"E": True}, r"beam 'arm': E \[Pa\] is True; expected a number > 0"),
        ({"G": 80.0}, r"Poisson ratio E / \(2 G\) - 1 = 1\.312e\+09; expected one in \(-1, 0.5\]"),
        ({"section": {"shape": "circle", "d": -0.01}}, r"beam 'arm': section d is -0.01"),
        ({"section": {"shape": "tube", "d": 0.02, "t": 0.015}},
         r"beam 'arm': tube wall t = 0.015 m is thicker than its radius 0.01 m"),
        ({"section": {"shape": "hexagon", "d": 0.02}}, r"section 'hexagon'.*expected one of"),
        ({"section": {"shape": ["tube"], "d": 0.02, "t": 0.002}},  # was a TypeError
         r"beam 'arm': section shape is \['tube'\]; expected one of \['circle', 'tube'"),
        ({"end": "nowhere"}, r"beam 'arm': end 'nowhere' is not a joint of the model"),
        ({"end": "hinge"}, r"beam 'arm': end 'hinge' is not a child joint of the link"),
        ({"theory": "bernoulli"}, r"theory 'bernoulli'; expected one of"),
        ({"section": {"shape": "circle", "d": 0.02, "y_axis": [2, 0, 0]}},
         r"beam 'arm': section y_axis \[2.0, 0.0, 0.0\] is parallel to the beam"),
        ({"section": {"A": 1e-4, "Iy": 1e-9, "Iz": 1e-9, "J": 2e-9}, "theory": "timoshenko"},
         r"beam 'arm': an explicit section needs kappa_y and kappa_z"),
        ({"section": {"shape": "rectangle", "b": 0.01, "h": 0.02, "y_axis": ["a", 0, 1]}},
         r"beam 'arm': section y_axis is \['a', 0, 1\]; expected 3 numbers"),  # ValueError
        # numpy or float read these as 1 and 2.1e11: a bool among numbers, a grouped number
        ({"section": {"shape": "rectangle", "b": 0.01, "h": 0.02, "y_axis": [0, True, 0]}},
         r"beam 'arm': section y_axis is \[0, True, 0\]; expected 3 numbers"),
        ({"E": None, "G": None, "section": None,
          "stiffness_6x6": [[1e6 if i == j else 0.0 for j in range(6)] for i in range(5)]
          + [[0.0] * 5 + [True]]},
         r"beam 'arm': stiffness_6x6 is .*True\]\]; expected 36 numbers"),
        ({"E": "2_1e11"}, r"beam 'arm': E \[Pa\] is '2_1e11'; expected a number > 0"),
        # sizes and materials beyond the float range: ZeroDivisionError, LinAlgError, a NaN
        # stiffness block (an indefinite one, after transport, by rounding)
        ({"E": 1e-300, "G": 4e-301, "section": {"shape": "circle", "d": 1e-10}}, BEYOND),
        ({"E": 1e300, "G": 4e299, "section": {"shape": "circle", "d": 1e10}}, BEYOND),
        ({"E": 1e-300, "G": 4e-301, "section": {"shape": "circle", "d": 0.01}}, BEYOND),
        ({"E": None, "G": None, "section": None, "compliance_6x6": 1e-320 * np.eye(6)},
         r"beam 'arm': compliance_6x6 .* give a tip compliance or stiffness beyond"),
    ],
)  # fmt: skip
def test_bad_beams_are_refused(tmp_path, beam, match):
    spec = {"end": "tip_joint", **STEEL, "section": {"shape": "circle", "d": 0.02}, **beam}
    spec = {k: v for k, v in spec.items() if v is not None}
    with pytest.raises(BeamError, match=match):
        load_model(_tip_file(tmp_path), beams={"arm": spec}, geometry=False)


def test_bad_link_and_matrix_are_refused(tmp_path):
    path = _tip_file(tmp_path)
    with pytest.raises(BeamError, match=r"beam 'elbow': unknown link; expected one of"):
        load_model(path, beams={"elbow": {**STEEL, "section": {"shape": "circle", "d": 0.02}}})
    bad = np.eye(6)
    bad[0, 1] = bad[1, 0] = 2.0  # symmetric, indefinite
    with pytest.raises(BeamError, match=r"beam 'arm': stiffness_6x6 .* not symmetric positive"):
        load_model(path, beams={"arm": {"stiffness_6x6": bad}}, geometry=False)
    with pytest.raises(BeamError, match=r"beam 'arm': stiffness_6x6 has 35 numbers"):
        load_model(path, beams={"arm": {"stiffness_6x6": [1.0] * 35}}, geometry=False)


def test_beam_on_a_moving_link_and_strings(tmp_path):
    path = _tip_file(tmp_path)
    spec = {"E": "2.1e11", "G": "8.1e10", "section": {"shape": "circle", "d": "0.02"}}
    clm = load_model(path, beams={"arm": spec}, springs={"hinge": 50.0}, geometry=False)
    assert [clm.model.names[j] for j in range(1, clm.model.njoints)] == ["hinge", "arm_beam"]
    q = pin.neutral(clm.model)
    C = cl.compliance(clm, q, "tip").C
    r, L, E = 0.01, 0.5, STEEL["E"]
    I = math.pi * r**4 / 4
    # force along world y at the tip: the hinge (about z) and the bending add up
    assert_close_in_norm(C[1, 1], L**2 / 50.0 + L**3 / (3 * E * I), RTOL_EXACT)


def test_mjcf_side_file_beams_equal_urdf_closure_file_beams(tmp_path):
    """The four-bar's crank as a steel rod, once through the MJCF side file (closures
    prebuilt by the parser, re-anchored by the beams) and once through the URDF closure
    file (closures built after the beams): the same compliance."""
    repo = Path(__file__).resolve().parents[2] / "urdf"
    beam = "beams: {crank_link: {end: crank_axial, E: 2.1e11, G: 8.1e10, " \
        "section: {shape: circle, d: 0.004}}}\n"  # fmt: skip
    side = tmp_path / "side.yaml"
    side.write_text(beam)
    closure = tmp_path / "fourbar.yaml"
    closure.write_text((repo / "fourbar.yaml").read_text() + beam)
    mj = load_model(repo / "fourbar.xml", side, geometry=False)
    ur = load_model(repo / "fourbar.urdf", closure, geometry=False)
    assert "crank_link_beam" in mj.spring_blocks and "crank_link_beam" in ur.spring_blocks
    q_mj = cl.assemble(mj, [0.5], mj.reference_configuration()).q
    q_ur = cl.assemble(ur, [0.5], map_configuration(mj.model, ur.model, q_mj)).q
    C_mj, C_ur = cl.compliance(mj, q_mj, "P").C, cl.compliance(ur, q_ur, "P").C
    plain = load_model(repo / "fourbar.xml", geometry=False)
    q_plain = cl.assemble(plain, [0.5], plain.reference_configuration()).q
    rigid = cl.compliance(plain, q_plain, "P").C
    assert np.max(np.abs(C_mj - rigid)) > 1e-3 * np.max(np.abs(rigid))  # the rod is felt
    assert_close_in_norm(C_mj, C_ur, RTOL_EXACT)


def test_cli_reads_beams_and_prints_energy_shares(tmp_path, capsys):
    """``closedloop stiffness`` on the portal frame: the beams come from the closure file;
    with --wrench the shares of the deflection energy (by hand: 1/2 dq_j K_j dq_j over
    1/2 w C w, from the JSON's C and the beam blocks) sum to 1."""
    import json

    from closedloop.cli.app import main

    H, W = 1.2, 0.8
    nodes = np.array([[0, 0, 0], [0, 0, H], [W, 0, H], [W, 0, 0]], dtype=float)
    urdf, closures = frame_files(tmp_path, "portal", nodes, closure_to_ground=True)
    wrench = [100.0, 0.0, -50.0, 0.0, 10.0, 0.0]
    q = [str(v) for v in pin.neutral(load_model(urdf, closures, geometry=False).model)]
    args = ["stiffness", urdf, "--closures", closures, "--frame", "m2", "--q", *q]
    assert main([*args, "--json", "--wrench", *map(str, wrench)]) == 0
    doc = json.loads(capsys.readouterr().out)
    shares = doc["energy_shares"]
    assert list(shares) == ["m0_beam", "m1_beam", "m2_beam"]
    assert sum(shares.values()) == pytest.approx(1.0, rel=1e-12)
    clm = load_model(urdf, closures, geometry=False)
    res = cl.compliance(clm, pin.neutral(clm.model), "m2")
    dq = res.G @ wrench
    for name, share in shares.items():
        v, K = clm.joint_v_slice(name), clm.spring_blocks[name]
        assert share == pytest.approx(dq[v] @ K @ dq[v] / (wrench @ res.C @ wrench), rel=1e-9)
    np.testing.assert_allclose(doc["C"], res.C, rtol=1e-12, atol=1e-12 * np.abs(res.C).max())
    assert main([*args, "--wrench", *map(str, wrench)]) == 0
    assert "energy share" in capsys.readouterr().out


# ------------------------------------------------------------------------ edges
#: Machine epsilon: C from the beam's stiffness K (6, 6) (the virtual joint's spring, in
#: the end joint's axes, not the beam's) carries the rounding of K's largest entry into
#: its smallest direction: relative error up to cond(K) eps, 2e11 eps for a 10 um wire of
#: 0.7 m (9.8e-8 observed), ~1e-12 for ordinary sections (RTOL_EXACT of test_beams).
EPS = np.finfo(float).eps


@pytest.mark.parametrize("E", [1e3, 1e20])
@pytest.mark.parametrize("d", [1e-5, 1.0])
def test_cantilever_of_any_material_and_size_is_its_closed_form(tmp_path, E, d):
    """Round sections 10 um .. 1 m across, E from a gel to far above diamond (G = E/2.6):
    the tip compliance of the closed form, full rank (a cantilever alone has no rigid
    direction, however stiff or soft: the rank rule is relative)."""
    L, G = 0.7, E / 2.6
    tip = ("tip_joint", "ground", "tip", L * AXIS, (0.3, -0.5, 1.1), "fixed", None)
    path = urdf_of(tmp_path, "cantilever", ["ground", "tip"], [tip])
    spec = {"end": "tip_joint", "E": E, "G": G, "section": {"shape": "circle", "d": d}}
    clm = load_model(path, beams={"ground": spec}, geometry=False)
    res = cl.compliance(clm, pin.neutral(clm.model), "tip")
    A, I = math.pi * d**2 / 4, math.pi * d**4 / 64
    expected = round_tip_compliance(L, AXIS, E, G, A, I)
    assert res.rank == 6
    lam = np.linalg.eigvalsh(expected)
    rtol = max(RTOL_EXACT, 10 * EPS * lam[-1] / lam[0])
    assert_close_in_norm(res.C, expected, rtol)


def test_tube_with_a_wall_of_its_radius_is_the_circle(tmp_path):
    d = 0.03
    circle = cantilever(tmp_path, {"shape": "circle", "d": d})[0].spring_blocks["ground_beam"]
    tube = cantilever(tmp_path, {"shape": "tube", "d": d, "t": d / 2})[0]
    np.testing.assert_allclose(tube.spring_blocks["ground_beam"], circle, rtol=1e-15, atol=0)
    nearly = cantilever(tmp_path, {"shape": "tube", "d": d, "t": d / 2 * (1 - 1e-9)})[0]
    assert_close_in_norm(nearly.spring_blocks["ground_beam"], circle, 1e-9)  # ~ (r_i/r)^4
    with pytest.raises(BeamError, match=r"tube wall t = 0\.0150000\d* m is thicker than its "
                       r"radius 0\.015 m"):  # fmt: skip
        cantilever(tmp_path, {"shape": "tube", "d": d, "t": d / 2 * (1 + 1e-9)})


# ------------------------------------------------------------------------ gravity and inertia
LINKS = ["base", "arm", "tip", "hand", "side"]
JOINTS = [
    ("hinge", "base", "arm", (0, 0, 0.1), (0, 0, 0), "revolute", (0, 1, 0)),
    ("tip_joint", "arm", "tip", (0.5, 0, 0), (0, 0, 0), "fixed", None),
    ("wrist", "tip", "hand", (0.1, 0, 0), (0, 0, 0), "revolute", (0, 1, 0)),
    ("side_joint", "arm", "side", (0, 0.3, 0), (0, 0, 0), "revolute", (0, 1, 0)),
]
SECTION = {"E": 2.1e11, "G": 8.1e10, "section": {"shape": "circle", "d": 0.03}}


def massive_urdf(tmp_path, masses: dict) -> str:
    """The robot of LINKS and JOINTS, link n with mass masses[n] [kg] at (0.05, 0.02, 0)
    in its frame, the others without <inertial> (massless)."""
    path = urdf_of(tmp_path, "massive", [], [
        (n, p, c, xyz, rpy, kind, axis) for n, p, c, xyz, rpy, kind, axis in JOINTS
    ])  # fmt: skip
    text = Path(path).read_text()
    links = []
    for n in LINKS:
        m = masses.get(n)
        inertial = "" if m is None else (
            f'<inertial><origin xyz="0.05 0.02 0"/><mass value="{m}"/><inertia ixx="0.01" '
            'iyy="0.02" izz="0.03" ixy="0" ixz="0" iyz="0"/></inertial>'
        )  # fmt: skip
        links.append(f'<link name="{n}">{inertial}</link>')
    text = text.replace('<robot name="massive">', '<robot name="massive">' + "".join(links))
    Path(path).write_text(text)
    return path


@pytest.mark.parametrize(
    ("masses", "beams"),
    [
        ({}, {"arm": "tip_joint"}),  # massless everywhere
        ({"hand": 2.0}, {"arm": "tip_joint"}),  # only beyond the tip's moving joint
        ({"tip": 1.0}, {"arm": "tip_joint"}),  # only on the fixed (merged) end
        ({"arm": 1.0}, {"arm": "tip_joint"}),  # only on the beam's own link
        ({"base": 3.0, "arm": 1.0, "tip": 1.0}, {"base": "hinge"}),  # the root link
        ({"arm": 1.0, "tip": 1.5, "hand": 1.0, "side": 0.7}, {"arm": "side_joint"}),
        ({"arm": 1.0, "tip": 1.5, "hand": 1.0, "side": 0.7}, {"tip": "wrist"}),  # merged link
    ],
)
def test_undeflected_beams_keep_frames_weight_and_gravity_torques(tmp_path, masses, beams):
    """The rigid robot's frame placements, generalized gravity on its own joints, total
    mass and centre of mass (Pinocchio's RNEA on the model without beams), finite
    everywhere. (With a beam ending at the fixed tip_joint, the frames after the moving
    wrist were moved onto the beam's joint: 'hand' sat 0.1 m off, at the tip.)"""
    path = massive_urdf(tmp_path, masses)
    rigid = load_model(path, geometry=False)
    flex = load_model(path, beams={k: {**SECTION, "end": e} for k, e in beams.items()},
                      geometry=False)  # fmt: skip
    q = np.array([0.3, -0.4, 0.8])
    qb = map_configuration(rigid.model, flex.model, q)
    d0, d1 = rigid.model.createData(), flex.model.createData()
    pin.framesForwardKinematics(rigid.model, d0, q)
    pin.framesForwardKinematics(flex.model, d1, qb)
    for f in rigid.model.frames:
        placed = d1.oMf[flex.model.getFrameId(f.name, f.type)]
        np.testing.assert_allclose(
            placed.homogeneous,
            d0.oMf[rigid.model.getFrameId(f.name, f.type)].homogeneous,
            atol=1e-12,
            err_msg=f.name,
        )
    g0 = pin.computeGeneralizedGravity(rigid.model, d0, q)
    g1 = pin.computeGeneralizedGravity(flex.model, d1, qb)
    assert np.all(np.isfinite(g1))
    assert all(np.all(np.isfinite(i.lever)) for i in flex.model.inertias)
    idx = [flex.joint_v_slice(n).start for n in rigid.model.names[1:]]
    np.testing.assert_allclose(g1[idx], g0, rtol=1e-12, atol=1e-12)
    total = sum(i.mass for i in rigid.model.inertias)
    assert sum(i.mass for i in flex.model.inertias) == pytest.approx(total, rel=1e-14)
    if total > 0:
        np.testing.assert_allclose(pin.centerOfMass(flex.model, d1, qb),
                                   pin.centerOfMass(rigid.model, d0, q), atol=1e-12)  # fmt: skip


@pytest.mark.parametrize("end", ["side_joint", "tip_joint"])
def test_two_beams_on_one_link_are_refused_by_link_name(tmp_path, end):
    """Also the same beam again, whose end now lies at the first beam's joint (it was
    refused as a beam of length 0)."""
    path = massive_urdf(tmp_path, {"arm": 1.0})
    once = load_model(path, beams={"arm": {**SECTION, "end": "tip_joint"}}, geometry=False)
    with pytest.raises(BeamError, match=r"beam 'arm': the link already has a beam"):
        once.with_beams({"arm": {**SECTION, "end": end}})


def test_a_spring_on_a_beam_joint_is_refused_from_the_file_and_the_keyword(tmp_path):
    """The closure file's spring on arm_beam was replaced by the beam's block without a
    word; the keyword's replaced the block by a number. Both are refused now."""
    path = massive_urdf(tmp_path, {"arm": 1.0})
    beam = {"arm": {**SECTION, "end": "tip_joint"}}
    with pytest.raises(
        cl.InvalidInputError, match=r"springs name the beam joint\(s\) \['arm_beam'\]"
    ):
        load_model(path, beams=beam, springs={"arm_beam": 5.0}, geometry=False)
    closures = tmp_path / "c.yaml"
    closures.write_text(
        "closed_loop: []\ntype: []\nname_mot: [hinge]\nsprings: {hinge: 100, arm_beam: 5}\n"
        "beams: {arm: {end: tip_joint, E: 2.1e11, G: 8.1e10, section: {shape: circle, d: 0.03}}}\n"
    )
    with pytest.raises(cl.ModelFileError, match=r"springs name the beam joint\(s\) \['arm_beam'\]"):
        load_model(path, closures, geometry=False)


@pytest.mark.parametrize("frame", ["hand", "tip"])
def test_stiffer_beams_tend_to_the_rigid_link_as_one_over_e(tmp_path, frame):
    """The beam's share of C falls as 1/E, towards the rigid robot's C, at the beam's
    fixed tip and beyond the moving wrist after it. (The frames after the wrist sat on the
    beam's tip: C at 'hand' stayed 66 % off the rigid one whatever E.) The springs on the
    branch joints wrist and side_joint, locked by the serial default, are named by the
    keyword, which unlocks them."""
    path = massive_urdf(tmp_path, {"arm": 1.0})
    rigid = load_model(path, springs={"hinge": 100.0, "wrist": 50.0, "side_joint": 80.0},
                       geometry=False)  # fmt: skip
    q = np.array([0.3, -0.4, 0.8])
    expected = cl.compliance(rigid, q, frame).C
    shares = []
    for E in (2.1e13, 2.1e15):
        flex = rigid.with_beams({"arm": {"E": E, "G": E / 2.6, "section": {"shape": "circle",
                                 "d": 0.03}, "end": "tip_joint"}})  # fmt: skip
        C = cl.compliance(flex, map_configuration(rigid.model, flex.model, q), frame).C
        shares.append(np.abs(C - expected).max() / np.abs(expected).max())
    assert shares[0] < 1e-3  # the beam is 100 times steel: a small share
    np.testing.assert_allclose(shares[0] / shares[1], 100.0, rtol=1e-3)  # 1/E, to rounding


def test_a_beam_far_stiffer_than_the_joint_spring_is_the_rigid_limit(tmp_path):
    """The beam's share of the compliance is ~1e-15 of the hinge's (E A / L ~ 1e17 N/m
    beside 100 N m/rad): C equals the rigid link's J k^-1 J^T to 1e-9. The beam is still a
    spring: its six directions make C full rank, its stiffness 1e15 and more times the
    hinge's (ill-conditioned)."""
    path = massive_urdf(tmp_path, {"arm": 1.0})
    rigid = load_model(path, springs={"hinge": 100.0, "wrist": 50.0, "side_joint": 80.0},
                       geometry=False)  # fmt: skip
    stiff = {"E": 1e20, "G": 1e20 / 2.6, "section": {"shape": "circle", "d": 0.03}}
    flex = rigid.with_beams({"arm": {**stiff, "end": "tip_joint"}})
    q = np.array([0.3, -0.4, 0.8])
    expected = cl.compliance(rigid, q, "hand")
    res = cl.compliance(flex, map_configuration(rigid.model, flex.model, q), "hand")
    assert expected.rank < 6 and res.rank == 6 and res.ill_conditioned
    assert_close_in_norm(res.C, expected.C, 1e-9)


#: The one-element beam with its geometric stiffness (closedloop.model.elastic: the cubic's
#: shortening) against the beam-column closed forms: its own discretisation error, which
#: grows with P L^2 / EI (0.2 % at 1, 2.4 % at 2 in compression; 0.07 % at -1 and 0.5 %
#: at -4 in tension): 1 % up to |P| = EI / L^2.
RTOL_BEAM_COLUMN = 0.01
#: The one-element beam buckles at P L^2 / EI = (26 - sqrt(496)) / 1.5 = 2.486, 0.75 %
#: above Euler's pi^2 / 4 (the root of det(K_b - P H_s) on the bending plane).
ONE_ELEMENT_BUCKLING = (26.0 - math.sqrt(496.0)) / 1.5


def _rod(tmp_path):
    """The clamped circular rod of the beam-column tests: model, q, EI [N m^2], L [m]."""
    d, L = 0.01, 0.5
    clm, q = cantilever(tmp_path, {"shape": "circle", "d": d}, length=L)
    return clm, q, STEEL["E"] * math.pi * d**4 / 64, L


def _across_compliance(clm, q, P: float):
    """The rod's transverse tip compliance [m/N] under the axial compression P [N] (a
    tension if negative), and the preloaded result."""
    res = cl.compliance(clm, q, "tip", preload=np.r_[-P * AXIS, np.zeros(3)])
    across = beam_frame()[:, 1]
    return across @ res.C[:3, :3] @ across, res


@pytest.mark.parametrize("ratio", [0.1, 1.0])
def test_an_axial_compression_softens_a_beam_as_a_beam_column(tmp_path, ratio):
    """A clamped circular rod under an axial compression P at its tip: the transverse tip
    compliance is (tan kL - kL) / (k^3 EI), k = sqrt(P / EI) (Timoshenko & Gere)."""
    clm, q, EI, L = _rod(tmp_path)
    P = ratio * EI / L**2
    kL = math.sqrt(P / EI) * L
    exact = (math.tan(kL) - kL) * L**3 / (kL**3 * EI)
    c, _ = _across_compliance(clm, q, P)
    np.testing.assert_allclose(c, exact, rtol=RTOL_BEAM_COLUMN)
    assert c > L**3 / (3 * EI)  # softer than unloaded: the effect is there


@pytest.mark.parametrize("ratio", [0.1, 1.0])
def test_an_axial_tension_stiffens_a_beam_as_a_beam_column(tmp_path, ratio):
    """Under a tension T the closed form is (kL - tanh kL) / (k^3 EI), k = sqrt(T / EI)."""
    clm, q, EI, L = _rod(tmp_path)
    T = ratio * EI / L**2
    kL = math.sqrt(T / EI) * L
    exact = (kL - math.tanh(kL)) * L**3 / (kL**3 * EI)
    c, _ = _across_compliance(clm, q, -T)
    np.testing.assert_allclose(c, exact, rtol=RTOL_BEAM_COLUMN)
    assert c < L**3 / (3 * EI)


def test_a_compressed_beam_loses_stability_at_the_buckling_load(tmp_path):
    """The stability margin changes sign within 0.5 % of the one-element buckling load,
    which is within 1 % of Euler's pi^2 EI / (4 L^2) for a clamped-free column."""
    clm, q, EI, L = _rod(tmp_path)
    assert ONE_ELEMENT_BUCKLING == pytest.approx(math.pi**2 / 4, rel=0.01)
    below = _across_compliance(clm, q, 0.995 * ONE_ELEMENT_BUCKLING * EI / L**2)[1]
    above = _across_compliance(clm, q, 1.005 * ONE_ELEMENT_BUCKLING * EI / L**2)[1]
    assert below.stability_margin > 0.0 > above.stability_margin


# ------------------------------------------------------------ default section axes
def z_cantilever(tmp_path, end_xyz, section: dict):
    """A 1 m steel beam on link 'ground' to a fixed joint at ``end_xyz`` (near the z axis)."""
    path = urdf_of(
        tmp_path, "zbar", ["ground", "tip"],
        [("tip_joint", "ground", "tip", end_xyz, (0, 0, 0), "fixed", None)],
    )  # fmt: skip
    spec = {"end": "tip_joint", **STEEL, "section": section}
    clm = load_model(path, beams={"ground": spec}, geometry=False)
    return cl.compliance(clm, pin.neutral(clm.model), "tip").C


@pytest.mark.parametrize("end", [(0, 0, 1), (1e-17, 0, 1), (1e-5, -1e-5, 1)])
def test_a_rectangle_along_a_link_axis_asks_for_its_y_axis(tmp_path, end):
    """Along z, x and y tie as 'most orthogonal': rounding (1e-17) used to pick one of them,
    swapping Iy and Iz (a factor 9 for 10 x 30 mm); now the same refusal either way."""
    with pytest.raises(BeamError, match=r"ambiguous.*link axes x and y.*expected a section y_axis"):
        z_cantilever(tmp_path, end, {"shape": "rectangle", "b": 0.01, "h": 0.03})


@pytest.mark.parametrize("end", [(0, 0, 1), (1e-17, 0, 1)])
def test_a_given_y_axis_or_an_axisymmetric_section_needs_no_default(tmp_path, end):
    b, h, L, E = 0.01, 0.03, 1.0, STEEL["E"]
    C = z_cantilever(tmp_path, end, {"shape": "rectangle", "b": b, "h": h, "y_axis": [1, 0, 0]})
    # beam axes: x = link z, y = link x (b along it), z = link y: a force along link x
    # bends about the section's z axis, Iz = h b^3 / 12
    np.testing.assert_allclose(C[0, 0], L**3 / (3 * E * h * b**3 / 12), rtol=1e-9)
    np.testing.assert_allclose(C[1, 1], L**3 / (3 * E * b * h**3 / 12), rtol=1e-9)
    d = 0.02
    I = math.pi * d**4 / 64
    for shape in ({"shape": "circle", "d": d}, {"shape": "tube", "d": d, "t": 0.002},
                  {"shape": "rectangle", "b": d, "h": d}):  # fmt: skip
        C = z_cantilever(tmp_path, end, shape)  # no refusal: the axes do not matter
        if shape["shape"] == "circle":
            np.testing.assert_allclose(C[0, 0], L**3 / (3 * E * I), rtol=1e-9)
