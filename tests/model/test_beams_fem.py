"""Flexible links (closedloop.model.beams) against a direct-stiffness frame FEM written here.

The reference is a textbook 3D frame model: one 12-dof element per member (Timoshenko's
element with Phi = 12 E I / (kappa G A L^2), Euler-Bernoulli at Phi = 0: exact for loads
at the nodes), principal axes from the section's y axis, assembled in world axes. Joints
are constraints on the nodal unknowns: a revolute joint ties two coincident nodes in
everything but the rotation about its axis (an extra unknown, with the joint's spring), a
rigid offset moves a node with another, a weld or ball support fixes all or the three
translations. Its compliance at a node (world axes, at the node) is compared with
``closedloop.compliance`` at the frame there. Geometry (link frames in the world) is
composed here from the URDF's xyz / rpy, not read from the model.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm

import closedloop as cl
from closedloop.io.loader import load_model

# Library vs FEM: the same beam theory through different algebra (6x6 inverses and
# transports vs an assembled stiffness); cond of these structures' stiffness <= ~1e9:
# rounding ~1e-12..1e-10 relative.
RTOL_FEM = 1e-9
STEEL = {"E": 2.1e11, "G": 8.1e10}
ALU = {"E": 7.0e10, "G": 2.6e10}


def rpy_matrix(rpy) -> np.ndarray:
    """URDF roll-pitch-yaw: Rz(yaw) Ry(pitch) Rx(roll), written out."""
    (cr, sr), (cp, sp), (cy, sy) = ((math.cos(a), math.sin(a)) for a in rpy)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def skew(v) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


# ------------------------------------------------------------------------ sections
def tube(d, t):
    r, ri = d / 2, d / 2 - t
    m2 = (ri / r) ** 2
    I = math.pi * (r**4 - ri**4) / 4

    def kappa(nu):  # Cowper (1966)
        return 6 * (1 + nu) * (1 + m2) ** 2 / ((7 + 6 * nu) * (1 + m2) ** 2 + (20 + 12 * nu) * m2)

    return {"A": math.pi * (r**2 - ri**2), "Iy": I, "Iz": I, "J": 2 * I, "kappa": kappa}


def rectangle(b, h):
    """b along the section's y, h along z; Roark's torsion constant; Cowper's kappa."""
    a, c = max(b, h), min(b, h)
    J = a * c**3 * (1 / 3 - 0.21 * (c / a) * (1 - c**4 / (12 * a**4)))

    def kappa(nu):  # Cowper (1966)
        return 10 * (1 + nu) / (12 + 11 * nu)

    return {"A": b * h, "Iy": b * h**3 / 12, "Iz": h * b**3 / 12, "J": J, "kappa": kappa}


# ------------------------------------------------------------------------ frame FEM
def _axes(p1, p2, y_hint) -> tuple[float, np.ndarray]:
    """A member's length and (3, 3) local axes (rows: x along it, the section's y and z
    in world axes); y is ``y_hint`` made orthogonal to the member."""
    L = float(np.linalg.norm(p2 - p1))
    x = (p2 - p1) / L
    y = y_hint - (y_hint @ x) * x
    y /= np.linalg.norm(y)
    return L, np.vstack([x, y, np.cross(x, y)])


def element(p1, p2, y_hint, E, G, s, theory, N=0.0) -> np.ndarray:
    """(12, 12) frame element in world axes, dofs (u, theta) of node 1 then node 2, with
    the consistent geometric stiffness of an axial force N [N] (tension > 0; the cubic's
    N/(30 L) [36, 3L; 3L, 4L^2] pattern, Euler-Bernoulli)."""
    L, lam = _axes(p1, p2, y_hint)
    k = np.zeros((12, 12))
    kappa = s["kappa"](E / (2 * G) - 1) if theory == "timoshenko" else math.inf
    # (v_y, theta_z) with Iz and (v_z, theta_y) with Iy, the latter's coupling reversed
    for a, b, inertia, sgn in ((1, 5, s["Iz"], 1.0), (2, 4, s["Iy"], -1.0)):
        phi = 12 * E * inertia / (kappa * G * s["A"] * L**2)
        c = E * inertia / ((1 + phi) * L**3)
        kb = c * np.array([
            [12, 6 * L * sgn, -12, 6 * L * sgn],
            [6 * L * sgn, (4 + phi) * L**2, -6 * L * sgn, (2 - phi) * L**2],
            [-12, -6 * L * sgn, 12, -6 * L * sgn],
            [6 * L * sgn, (2 - phi) * L**2, -6 * L * sgn, (4 + phi) * L**2],
        ])  # fmt: skip
        kg = N / (30 * L) * np.array([
            [36, 3 * L * sgn, -36, 3 * L * sgn],
            [3 * L * sgn, 4 * L**2, -3 * L * sgn, -(L**2)],
            [-36, -3 * L * sgn, 36, -3 * L * sgn],
            [3 * L * sgn, -(L**2), -3 * L * sgn, 4 * L**2],
        ])  # fmt: skip
        idx = [a, b, a + 6, b + 6]
        k[np.ix_(idx, idx)] += kb + kg
    for a, v in ((0, E * s["A"] / L), (3, G * s["J"] / L)):
        k[np.ix_([a, a + 6], [a, a + 6])] += v * np.array([[1, -1], [-1, 1]])
    T = np.kron(np.eye(4), lam)
    return T.T @ k @ T


class Frame:
    """A frame structure: nodes (n, 3) [m]; members (i, j, y_hint, E, G, section, theory);
    ``ties``: node j moves with node i (rigid offset), but for a ``hinge`` axis (world)
    about which it turns freely, or against a spring k [N m/rad]; ``supports``: node ->
    "weld" (6 dofs fixed) or "ball" (translations fixed)."""

    def __init__(self, nodes):
        self.nodes = np.asarray(nodes, dtype=float)
        self.members, self.ties, self.supports = [], [], {}

    def member(self, i, j, y_hint, section, theory="euler-bernoulli", material=STEEL):
        self.members.append((i, j, np.asarray(y_hint, float), section, theory, material))

    def tie(self, i, j, hinge=None, k=0.0):
        self.ties.append((i, j, hinge, k))

    def _reduced(self, forces) -> tuple[np.ndarray, np.ndarray]:
        """(T, K_r): the map (6 n, m) from the unknowns to the nodal dofs and the reduced
        stiffness (m, m), with the members' axial forces ``forces`` [N] (or none)."""
        n = len(self.nodes)
        hinged = [k for _, _, hinge, k in self.ties if hinge is not None]
        slaves = {j for _, j, _, _ in self.ties}
        sizes = {"weld": 0, "ball": 3, None: 6}
        size = [0 if i in slaves else sizes[self.supports.get(i)] for i in range(n)]
        first = np.cumsum([0, *size])
        T = np.zeros((6 * n, first[-1] + len(hinged)))
        for i in range(n):  # a ball support keeps the node's rotations only
            T[6 * i + 6 - size[i] : 6 * i + 6, first[i] : first[i + 1]] = np.eye(size[i])
        column = iter(range(first[-1], T.shape[1]))
        for i, j, hinge, _ in self.ties:  # in order: a master is set before its slaves
            r = self.nodes[j] - self.nodes[i]
            move = np.block([[np.eye(3), -skew(r)], [np.zeros((3, 3)), np.eye(3)]])
            T[6 * j : 6 * j + 6] = move @ T[6 * i : 6 * i + 6]
            if hinge is not None:
                T[6 * j + 3 : 6 * j + 6, next(column)] += hinge
        K = np.zeros((6 * n, 6 * n))
        forces = np.zeros(len(self.members)) if forces is None else forces
        for (i, j, y, section, theory, material), N in zip(self.members, forces, strict=True):
            dofs = [*range(6 * i, 6 * i + 6), *range(6 * j, 6 * j + 6)]
            K[np.ix_(dofs, dofs)] += element(self.nodes[i], self.nodes[j], y, material["E"],
                                             material["G"], section, theory, N)  # fmt: skip
        Kr = T.T @ K @ T
        Kr[first[-1] :, first[-1] :] += np.diag(hinged)
        return T, Kr

    def compliance(self, node, forces=None) -> np.ndarray:
        """(6, 6) compliance at ``node``: its twist (u, theta) per wrench (f, n) there,
        with the members' axial forces ``forces`` (the geometric stiffness; or none)."""
        T, Kr = self._reduced(forces)
        Tn = T[6 * node : 6 * node + 6]
        return Tn @ np.linalg.solve(Kr, Tn.T)

    def axial_forces(self, node, wrench) -> np.ndarray:
        """The members' axial forces [N] (tension > 0) under ``wrench`` at ``node``
        (the linear solution)."""
        T, Kr = self._reduced(None)
        Tn = T[6 * node : 6 * node + 6]
        u = T @ np.linalg.solve(Kr, Tn.T @ wrench)
        out = []
        for i, j, _, section, _, material in self.members:
            chord = self.nodes[j] - self.nodes[i]
            stretch = chord @ (u[6 * j : 6 * j + 3] - u[6 * i : 6 * i + 3])  # times L
            out.append(material["E"] * section["A"] * stretch / (chord @ chord))
        return np.array(out)


# ------------------------------------------------------------------------ URDF
def write_urdf(tmp_path, name, joints) -> str:
    """A URDF of massive links joined by ``joints`` (name, parent, child, xyz, rpy, type,
    axis); the links are the ones the joints name."""
    links = dict.fromkeys(n for _, p, c, *_ in joints for n in (p, c))
    inertial = (
        '<inertial><mass value="1.0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" '
        'ixy="0" ixz="0" iyz="0"/></inertial>'
    )
    body = [f'<robot name="{name}">', *(f'<link name="{n}">{inertial}</link>' for n in links)]
    for jn, parent, child, xyz, rpy, kind, axis in joints:
        body.append(
            f'<joint name="{jn}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{" ".join(map(repr, map(float, xyz)))}" '
            f'rpy="{" ".join(map(repr, map(float, rpy)))}"/>'
            + (f'<axis xyz="{" ".join(map(str, axis))}"/>' if axis is not None else "")
            + ('<limit lower="-3" upper="3" effort="1" velocity="1"/>' if kind != "fixed" else "")
            + "</joint>"
        )
    path = tmp_path / f"{name}.urdf"
    path.write_text("\n".join([*body, "</robot>"]))
    return str(path)


def world_frames(joints) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Link name -> (position, rotation) in the world at q = 0, composed from the joints'
    origins (the first joint's parent is the world)."""
    out = {joints[0][1]: (np.zeros(3), np.eye(3))}
    for _, parent, child, xyz, rpy, *_ in joints:
        p, R = out[parent]
        out[child] = (p + R @ np.asarray(xyz, float), R @ rpy_matrix(rpy))
    return out


def y_default(R_link, axis_world) -> np.ndarray:
    """The default section y axis (world): the link frame axis most orthogonal to the beam."""
    return R_link[:, int(np.argmin(np.abs(R_link.T @ axis_world)))]


# ------------------------------------------------------------------------ open chain
CHAIN = [  # a clamped l0, a sprung hinge h1, l1 with a rigid side branch, l2, the tool
    ("j0", "ground", "l0", (0.1, -0.2, 0.05), (0.4, 0.2, -0.3), "fixed", None),
    ("h1", "l0", "l1", (0.25, 0.3, 0.35), (-0.7, 0.1, 0.9), "revolute", (0, 0, 1)),
    ("t1", "l1", "l2", (0.4, -0.1, 0.2), (0.2, 0.3, 0.1), "fixed", None),
    ("side", "l1", "branch", (-0.05, 0.2, 0.1), (0.0, 0.5, 0.0), "fixed", None),
    ("t2", "l2", "tool", (0.05, 0.3, -0.15), (1.0, -0.4, 0.6), "fixed", None),
]
RECT_Y = (0.2, -1.0, 0.4)  # l0's section y axis, in l0's frame
HINGE_K = 3.0e4  # [N m/rad]


@pytest.mark.parametrize("theory", ["euler-bernoulli", "timoshenko"])
def test_open_chain_with_a_sprung_hinge_matches_the_fem(tmp_path, theory):
    """Three beams in series with a hinge spring (series compliances add, through the
    chain's levers): a rectangle whose principal axes are along no link or world axis
    (y_axis given), ending at the moving hinge; a tube beside a rigid side branch; a
    rectangle of the default y axis, on a merged link with turned axes. At the tool, at
    the second beam's tip (the third link's frame) and on the branch (rigid with the
    second link's start: it sees the first beam and the hinge only)."""
    path = write_urdf(tmp_path, "chain", CHAIN)
    spec = {**ALU, "theory": theory}
    rect = {"shape": "rectangle", "b": 0.012, "h": 0.03}
    rect2 = {"shape": "rectangle", "b": 0.02, "h": 0.01}
    beams = {
        "l0": {**spec, "end": "h1", "section": {**rect, "y_axis": list(RECT_Y)}},
        "l1": {**spec, "end": "t1", "section": {"shape": "tube", "d": 0.03, "t": 0.003}},
        "l2": {**spec, "end": "t2", "section": rect2},
    }
    clm = load_model(path, beams=beams, springs={"h1": HINGE_K}, geometry=False)
    q = pin.neutral(clm.model)

    w = world_frames(CHAIN)
    (p0, R0), (p1, R1), (p2, R2) = w["l0"], w["l1"], w["l2"]
    nodes = [p0, p1, p1, p2, w["tool"][0], w["branch"][0]]
    fem = Frame(nodes)
    fem.supports[0] = "weld"
    fem.member(0, 1, R0 @ np.array(RECT_Y), rectangle(0.012, 0.03), theory, ALU)
    fem.tie(1, 2, hinge=R1[:, 2], k=HINGE_K)
    fem.member(2, 3, y_default(R1, p2 - p1), tube(0.03, 0.003), theory, ALU)
    fem.member(3, 4, y_default(R2, nodes[4] - p2), rectangle(0.02, 0.01), theory, ALU)
    fem.tie(2, 5)
    for frame, node in (("tool", 4), ("l2", 3), ("branch", 5)):
        C = cl.compliance(clm, q, frame).C
        assert_close_in_norm(C, fem.compliance(node), RTOL_FEM)


# ------------------------------------------------------------------------ four-bar
PLANE_RPY = (0.3, -0.2, 0.5)  # the four-bar's plane turned in the world
A, B, C, D = (np.array(p) for p in ([0, 0, 0], [0.1, 0.15, 0], [0.35, 0.2, 0], [0.3, 0, 0]))
MID = np.array([0.12, 0.02, 0.01])  # a frame on the coupler, in its frame (origin B)
CRANK_K = 500.0  # [N m/rad]
Z = (0, 0, 1)


def fourbar_files(tmp_path) -> tuple[str, str]:
    """The four-bar ABCD of flexible links (plane points A..D, hinges along the plane's
    z): crank AB (sprung, actuated), coupler BC, rocker DC, the loop cut by a 6d closure
    at C between the coupler's tip and the rocker's pin."""
    R = rpy_matrix(PLANE_RPY)
    joints = [
        ("A", "ground", "crank", R @ A, PLANE_RPY, "revolute", Z),
        ("B", "crank", "coupler", B - A, (0, 0, 0), "revolute", Z),
        ("ctip", "coupler", "coupler_tip", C - B, (0, 0, 0), "fixed", None),
        ("mid_joint", "coupler", "mid", MID, (0, 0, 0), "fixed", None),
        ("D", "ground", "rocker", R @ D, PLANE_RPY, "revolute", Z),
        ("Cr", "rocker", "pin", C - D, (0, 0, 0), "revolute", Z),
    ]
    urdf = write_urdf(tmp_path, "fourbar", joints)
    closure = tmp_path / "fourbar.yaml"
    closure.write_text(
        "closed_loop: [[coupler_tip, pin]]\ntype: ['6d']\nname_mot: [A]\n"
        f"springs: {{A: {CRANK_K}}}\nbeams:\n"
        "  crank: {end: B, E: 7.0e10, G: 2.6e10, section: {shape: tube, d: 0.02, t: 0.002}}\n"
        "  coupler: {end: ctip, E: 7.0e10, G: 2.6e10, theory: timoshenko,\n"
        "            section: {shape: rectangle, b: 0.01, h: 0.025, y_axis: [0, 0, 1]}}\n"
        "  rocker: {end: Cr, E: 7.0e10, G: 2.6e10, section: {shape: circle, d: 0.012}}\n"
    )
    return urdf, str(closure)


def test_fourbar_of_flexible_links_matches_the_fem(tmp_path):
    """A closed loop of three beams (a tube, a Timoshenko rectangle turned about its
    axis, a rod) with hinges: the loop shares the load between its branches (not a sum
    of compliances). At the coupler's tip C and at a frame rigid with its start."""
    clm = load_model(*fourbar_files(tmp_path), geometry=False)
    q = pin.neutral(clm.model)
    assert cl.assemble(clm, [0.0], q).q == pytest.approx(q, abs=1e-12)  # assembled at rest
    R = rpy_matrix(PLANE_RPY)
    z = R[:, 2]
    nodes = [R @ p for p in (A, A, B, B, C, D, D, C, B + MID)]
    fem = Frame(nodes)
    fem.supports.update({0: "weld", 5: "weld"})
    fem.tie(0, 1, hinge=z, k=CRANK_K)
    fem.member(1, 2, z, tube(0.02, 0.002), material=ALU)
    fem.tie(2, 3, hinge=z)
    fem.member(3, 4, z, rectangle(0.01, 0.025), "timoshenko", ALU)
    fem.tie(5, 6, hinge=z)
    fem.member(6, 7, z, tube(0.012, 0.006), material=ALU)
    fem.tie(7, 4, hinge=z)
    fem.tie(3, 8)
    for frame, node in (("coupler_tip", 4), ("pin", 4), ("mid", 8)):
        assert_close_in_norm(cl.compliance(clm, q, frame).C, fem.compliance(node), RTOL_FEM)


# ------------------------------------------------------------------------ welded frames
def welded_chain(tmp_path, nodes, sections, closure: str | None, theory="euler-bernoulli"):
    """Members 'm<i>' from nodes[i] to nodes[i + 1] (world, the first node clamped),
    welded by fixed joints, in a plane turned by PLANE_RPY (link frames turned with it);
    ``sections[i]``: the beam's section (y_axis in its link frame); ``closure``: the last
    node closed to a ground frame 'anchor' there ('6d' weld or '3d' ball), or None."""
    R = rpy_matrix(PLANE_RPY)
    names = ["ground", *(f"m{i}" for i in range(len(nodes) - 1)), "end"]
    joints = [("j0", "ground", "m0", nodes[0], PLANE_RPY, "fixed", None)]
    for i in range(1, len(nodes)):
        joints.append((f"j{i}", names[i], names[i + 1], R.T @ (nodes[i] - nodes[i - 1]),
                       (0, 0, 0), "fixed", None))  # fmt: skip
    if closure:
        joints.append(("ja", "ground", "anchor", nodes[-1], PLANE_RPY, "fixed", None))
    urdf = write_urdf(tmp_path, "frame", joints)
    beams = {
        f"m{i}": {**ALU, "end": f"j{i + 1}", "section": s, "theory": theory}
        for i, s in enumerate(sections)
    }
    closures = None
    if closure:
        closures = tmp_path / "frame.yaml"
        closures.write_text(f"closed_loop: [[end, anchor]]\ntype: ['{closure}']\nname_mot: []\n")
    return load_model(urdf, closures, beams=beams, geometry=False)


def test_triangle_pinned_at_its_closing_corner_matches_the_fem(tmp_path):
    """A triangle of Timoshenko rectangles, clamped at A and closed on a ball at A (a 3d
    closure: the last member's end turns freely), its members' principal axes turned
    differently (y_axis out of the plane, in it, and the default): statically
    indeterminate, in and out of its plane."""
    R = rpy_matrix(PLANE_RPY)
    local = [np.array(p) for p in ([0, 0, 0], [0.6, 0, 0], [0.2, 0, 0.4], [0, 0, 0])]
    nodes = [R @ p for p in local]
    ys = [(0, 1, 0), (0.3, 0.2, 1.0), None]
    sizes = [(0.01, 0.03), (0.02, 0.015), (0.012, 0.02)]
    sections = [
        {"shape": "rectangle", "b": b, "h": h, **({"y_axis": list(y)} if y else {})}
        for (b, h), y in zip(sizes, ys, strict=True)
    ]
    clm = welded_chain(tmp_path, nodes, sections, "3d", "timoshenko")
    fem = Frame(nodes)
    fem.supports.update({0: "weld", 3: "ball"})
    for i, ((b, h), y) in enumerate(zip(sizes, ys, strict=True)):
        hint = R @ y if y else y_default(R, nodes[i + 1] - nodes[i])
        fem.member(i, i + 1, hint, rectangle(b, h), "timoshenko", ALU)
    q = pin.neutral(clm.model)
    for frame, node in (("m1", 1), ("m2", 2)):
        assert_close_in_norm(cl.compliance(clm, q, frame).C, fem.compliance(node), RTOL_FEM)


# ------------------------------------------------------------------------ preload
#: The library's tangent at the deflected equilibrium vs the FEM's, linearised about the
#: unloaded frame with the linear axial forces: they differ at the order of the members'
#: strains N / (E A) <= 1e-4, amplified by 1 / (1 - P / P_cr) <= 2 here.
RTOL_PRELOAD = 5e-4


@pytest.mark.parametrize(
    "load", [(0.0, 0.0, -200.0), (0.0, 0.0, 200.0), (400.0, 0.0, -100.0)],
    ids=["both-compressed", "both-stretched", "one-of-each"],
)  # fmt: skip
def test_preloaded_v_frame_is_the_fem_with_geometric_stiffness(tmp_path, load):
    """Two rods welded at an apex, clamped at their feet (a closed loop, 6d), under a dead
    load at the apex in their plane: the members carry axial forces (compression, tension
    or one of each) and the tangent compliance at the apex is the FEM's with each
    member's geometric stiffness N/(30 L) [36, 3L; 3L, 4L^2] (the shortening form of
    closedloop.model.elastic, in each member's own axes). The preload changes C by 15-45 %."""
    R = rpy_matrix(PLANE_RPY)
    nodes = [R @ np.array(p) for p in ([-0.3, 0, 0], [0, 0, 0.5], [0.3, 0, 0])]
    circle = {"shape": "circle", "d": 0.01}
    clm = welded_chain(tmp_path, nodes, [circle, circle], "6d")
    fem = Frame(nodes)
    fem.supports.update({0: "weld", 2: "weld"})
    for i in range(2):
        fem.member(i, i + 1, R[:, 1], tube(0.01, 0.005), material=ALU)
    wrench = np.r_[R @ np.array(load), 0.0, 0.0, 0.0]
    forces = fem.axial_forces(1, wrench)
    expected = fem.compliance(1, forces)
    assert np.abs(expected - fem.compliance(1)).max() > 0.15 * np.abs(expected).max()
    res = cl.compliance(clm, pin.neutral(clm.model), "m1", preload=wrench)
    assert_close_in_norm(res.C, expected, RTOL_PRELOAD)
