"""Closed loops of flexible links against OpenSees' linear statics (openseespy).

Each case is one mechanism written twice: for the library (a URDF tree with its closure
file, or an MJCF file; links as Euler-Bernoulli beams, round steel rods) and for OpenSees
(nodes, ``elasticBeamColumn`` elements, constraints). The library's compliance C (6x6,
world axes, at the output frame's origin) is compared column by column with the
displacements of the output node under six unit loads there (1 N along x, y, z, then
1 N m about x, y, z), one linear static analysis each. At the configuration of each case
(neutral; an MJCF file's ``qpos0``, which places a free body at its ``pos``) the loops are
closed and every link frame is world-aligned (both checked), so a node's position is its
frame's and every joint axis a world axis, as ``equalDOF`` needs.

Cases: a planar four-bar closed by a revolute closure, by two point ('3d') closures, by a
sprung revolute closure and by a weld freed into the same sprung pin (elastic closures);
a spatial four-bar closed by a universal and by a cylindrical closure; a slider-crank
closed by a prismatic closure; a spatial frame closed by a weld, rigid or elastic along y
and about x; a rigid platform (a ternary link) on three flexible legs, two closed at the
ground by points or welds, and the same platform flexible; the planar four-bar as an
MJCF file closed by a ``<connect>``, its rocker a beam to a tip body or to the
``<connect>``'s anchor; an MJCF mechanism of three legs (sprung hip, passive knee) whose
flexible platform, a free body, is closed to the legs' tips by three ``<connect>``
closures (or ``<weld>`` closures).

How each part of the library's model is modelled in OpenSees:

==============================  ==========================================================
library                         OpenSees
==============================  ==========================================================
beam link (round rod, E, G)     one ``elasticBeamColumn`` from the link's origin to its
                                ``end`` joint: A, E, G, J = 2 I, Iy = Iz = I (exact for
                                loads at nodes: no mesh)
joint to the ground             a node with ``fix`` at the joint, tied to the child's
                                first node as below
revolute joint                  two coincident nodes, ``equalDOF`` on the three
                                translations and the two rotations it does not free
sprung revolute joint           the same, and a ``zeroLength`` element with a
                                ``uniaxialMaterial Elastic`` (k) on the free rotation
fixed joint                     one node shared by both links
'revolute' closure              ``equalDOF`` between the two tips, all dofs but the
                                rotation about the axis
two '3d' closures on one axis   the pin about that axis (below)
'prismatic' closure against     the slider's node held by ``fix`` in all but the
the ground                      translation along the axis, the coupler pinned to it
'cylindrical' closure           ``equalDOF``, all but the rotation about and the
                                translation along the axis
'universal' closure             ``equalDOF``, all but the rotations about its two axes
'6d' closure (weld)             ``equalDOF`` on all six dofs
'3d' closure (one point),       ``equalDOF`` on the three translations
MJCF ``<connect>``
free joint (MJCF ``freejoint``) nothing: the body's nodes are held by its closures
elastic closure direction       the direction left out of the ``equalDOF``, and a
                                ``zeroLength`` + ``uniaxialMaterial Elastic`` on it
rigid link (the platform) and   ``rigidLink beam`` from one node of the body (retained)
rigid offsets (output nodes)    to each other (constrained): exact, where a stiff
                                element would cost accuracy as its stiffness ratio
==============================  ==========================================================

OpenSees' ``Transformation`` handler silently drops a constraint when a node is both
retained by one multi-point constraint and constrained by another; every model is built
so that no node does both (the direction of each ``equalDOF`` is chosen for it, e.g. the
slider-crank's coupler retains its pin to the crank), and :class:`Structure` checks it for
every model. The rule also shapes two models: two '3d' closures cannot be written as two
points (each point's second node would be constrained twice), so OpenSees gets the pin
they make; and a rigid body can hold a joint only through a node its ``rigidLink``
constrains, which then cannot retain that joint, so the platform's legs are welded to it
and closed at their ground ends. OpenSees' ``rigidLink bar`` is not a ball joint on a
rigid body (it ties the translations only, without the body's rotation) and is not used.

A link may also be several beams (a list under its name in ``beams``): the flexible
platform, from its origin to its centre and from there to its two other legs, is three
``elasticBeamColumn`` elements between those nodes; the MJCF platform's three beams, from
its centre to its three closures' anchors (``anchor:C<i>``), are three elements from the
centre node, each pinned (or welded) to its leg's tip.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm, opensees
from mechanisms import mjcf_fourbar, xyz_text

import closedloop as cl
from closedloop.kinematics.constraints import closure_residual

E, G, D = 2.1e11, 8.1e10, 0.01  # steel [Pa], rod diameter [m]
A_ROD, I_ROD = math.pi * D**2 / 4, math.pi * D**4 / 64
K_CRANK, K_CUT = 400.0, 20.0  # [N m/rad]
#: The same linear structure solved by two codes (the library's reduced stiffness and its
#: transports, OpenSees' assembled stiffness with its constraints transformed out), both
#: exact for Euler-Bernoulli rods loaded at nodes: they differ by rounding times the
#: condition of the stiffness (E A / L over the softest bending or spring term, up to ~1e7
#: here), ~1e-16 * 1e7 = 1e-9 of the largest scaled entry of C (measured: 3e-11 at most,
#: the MJCF platform).
RTOL_OPENSEES = 1e-9
#: Rotations times a length of the mechanisms [m] before comparing, so that the tolerance
#: weighs translations and rotations alike (assert_close_in_norm's scale).
SCALE = np.array([1.0, 1.0, 1.0, 0.3, 0.3, 0.3])
Y = np.array([0.0, 1.0, 0.0])
R_ZY = pin.rpy.rpyToMatrix(math.pi / 2, 0.0, 0.0)  # z along -y
R_ZX = pin.rpy.rpyToMatrix(0.0, math.pi / 2, 0.0)  # z along +x


# ----------------------------------------------------------------------------- OpenSees
class Structure:
    """An OpenSees model (3D, 6 dofs a node) that records its multi-point constraints."""

    def __init__(self, ops):
        self.ops, self.n, self.retained, self.constrained = ops, 0, set(), set()
        ops.wipe()
        ops.model("basic", "-ndm", 3, "-ndf", 6)

    def node(self, xyz, fixed=()) -> int:
        """A node at ``xyz`` [m], its dofs ``fixed`` (1-6, or True for all) held at zero."""
        self.n += 1
        self.ops.node(self.n, *map(float, xyz))
        if fixed:
            fixed = range(1, 7) if fixed is True else fixed
            self.ops.fix(self.n, *[int(d in fixed) for d in range(1, 7)])
        return self.n

    def beam(self, i: int, j: int) -> None:
        """A steel rod from node i to node j."""
        self.n += 1
        axis = np.subtract(self.ops.nodeCoord(j), self.ops.nodeCoord(i))
        vecxz = np.eye(3)[np.argmin(np.abs(axis))]  # any axis off the rod: a round section
        self.ops.geomTransf("Linear", self.n, *vecxz)
        self.ops.element("elasticBeamColumn", self.n, i, j, A_ROD, E, G, 2 * I_ROD, I_ROD,
                         I_ROD, self.n)  # fmt: skip

    def joint(self, r: int, c: int, free=(), springs=None) -> None:
        """Node c tied to node r in every dof but ``free`` (1-6: ux uy uz rx ry rz, world),
        with ``springs`` {dof: k} on freed dofs."""
        self.ops.equalDOF(r, c, *[d for d in range(1, 7) if d not in free])
        self.retained.add(r)
        self.constrained.add(c)
        for dof, k in (springs or {}).items():
            self.n += 1
            self.ops.uniaxialMaterial("Elastic", self.n, k)
            self.ops.element("zeroLength", self.n, r, c, "-mat", self.n, "-dir", dof)

    def rigid(self, r: int, c: int) -> None:
        """Node c moved rigidly with node r."""
        self.ops.rigidLink("beam", r, c)
        self.retained.add(r)
        self.constrained.add(c)

    def displacement(self, node: int, load) -> np.ndarray:
        """(6,) displacement [m, rad] of ``node`` under ``load`` (6,) [N, N m] there."""
        ops = self.ops
        ops.timeSeries("Linear", 1)
        ops.pattern("Plain", 1, 1)
        ops.load(node, *map(float, load))
        ops.constraints("Transformation")
        ops.numberer("Plain")
        ops.system("FullGeneral")
        ops.algorithm("Linear")
        ops.integrator("LoadControl", 1.0)
        ops.analysis("Static")
        assert ops.analyze(1) == 0
        return np.array(ops.nodeDisp(node))


def opensees_compliance(build) -> np.ndarray:
    """(6, 6) compliance [m/N, m/(N m), rad/N, rad/(N m)] at the output node, world axes:
    ``build(structure)`` makes the model and returns the output node."""
    ops, C = opensees(), np.zeros((6, 6))
    for k in range(6):
        s = Structure(ops)
        out = build(s)
        both = s.retained & s.constrained
        assert not both, f"nodes {sorted(both)} both retained and constrained"
        C[:, k] = s.displacement(out, np.eye(6)[k])
    ops.wipe()
    return C


def test_a_node_retained_and_constrained_is_refused():
    """The check every model passes: a chain of two ties through one node fails it."""

    def chain(s: Structure) -> int:
        a, b, c = s.node((0, 0, 0), fixed=True), s.node((0.1, 0, 0)), s.node((0.2, 0, 0))
        s.beam(a, b)
        s.joint(b, c)
        s.rigid(c, s.node((0.3, 0, 0)))  # c both constrained and retained
        return b

    with pytest.raises(AssertionError, match=r"nodes \[3\] both retained and constrained"):
        opensees_compliance(chain)


# ------------------------------------------------------------------------------ library
def rod(end: str) -> dict:
    return {"E": E, "G": G, "section": {"shape": "circle", "d": D}, "end": end}


def write_urdf(path: Path, joints) -> None:
    """A URDF of ``joints``: (name, parent, child, child origin [m] world, child rotation
    (3, 3) world or None, type, axis world or None), parents before children."""
    pose = {"ground": pin.SE3.Identity()}
    body = "".join(f'<link name="{n}"/>' for n in ["ground", *(j[2] for j in joints)])
    for name, parent, child, xyz, R, kind, axis in joints:
        pose[child] = pin.SE3(np.eye(3) if R is None else R, np.asarray(xyz, float))
        local = pose[parent].actInv(pose[child])
        xyz_text = " ".join(map(repr, map(float, local.translation)))
        rpy_text = " ".join(map(repr, map(float, pin.rpy.matrixToRpy(local.rotation))))
        body += (
            f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{xyz_text}" rpy="{rpy_text}"/>'
        )
        if axis is not None:
            local_axis = pose[child].rotation.T @ axis
            body += f'<axis xyz="{" ".join(map(repr, map(float, local_axis)))}"/>'
            body += '<limit lower="-3" upper="3" effort="1" velocity="1"/>'
        body += "</joint>"
    path.write_text(f'<robot name="{path.stem}">{body}</robot>')


def library_compliance(clm, frame: str) -> np.ndarray:
    """(6, 6) compliance of ``frame`` at the reference configuration (neutral; an MJCF
    file's qpos0), which must be closed and world-aligned."""
    q = clm.reference_configuration()
    np.testing.assert_allclose(closure_residual(clm, q), 0.0, atol=1e-14)
    data = clm.model.createData()
    pin.framesForwardKinematics(clm.model, data, q)
    rotation = data.oMf[clm.model.getFrameId(frame)].rotation
    np.testing.assert_allclose(rotation, np.eye(3), atol=1e-15)
    return cl.compliance(clm, q, frame).C


def urdf_model(tmp_path, name, joints, closures, beams, springs, closure_springs=None):
    """The library's model of :func:`write_urdf`'s ``joints``: ``closures`` [(frame A,
    frame B, type)], ``beams`` {link: end joint, or a list of (start or None, end) of
    several beams on the link}, ``springs`` {joint: k}, and
    ``closure_springs`` the closure file's entry (YAML text)."""
    write_urdf(tmp_path / f"{name}.urdf", joints)
    pairs = [[a, b] for a, b, _ in closures]
    types = ", ".join(f"'{t}'" for _, _, t in closures)
    text = f"closed_loop: {pairs}\ntype: [{types}]\nname_mot: []\nsprings: {springs}\n"
    if closure_springs is not None:
        text += f"closure_springs: {closure_springs}\n"
    (tmp_path / f"{name}.yaml").write_text(text)
    beams = {
        link: rod(end) if isinstance(end, str)
        else [rod(e) | ({} if a is None else {"start": a}) for a, e in end]
        for link, end in beams.items()
    }  # fmt: skip
    return cl.load_model(tmp_path / f"{name}.urdf", tmp_path / f"{name}.yaml", beams=beams)


# ----------------------------------------------------------------------------- four-bar
#: Crank A-B (sprung at A), coupler B-C, rocker D-C, pins about y; the output P on the
#: coupler's tip, offset from C. "spatial" moves D off the x-z plane.
A_, B_, C_, P_ = (np.array(p) for p in ((0, 0, 0), (0, 0, 0.12), (0.3, 0, 0.18),
                                         (0.25, 0, 0.22)))  # fmt: skip
D_PLANAR, D_SPATIAL = np.array([0.34, 0.0, 0.0]), np.array([0.34, 0.08, 0.0])
#: closure -> (its frames' rotations A, B; dofs OpenSees frees at the cut).
FOURBAR_CUTS = {
    "revolute": ((R_ZY, R_ZY), (5,)),
    "3d": ((None, None), (5,)),  # two points on the y axis: the pin about y
    "universal": ((R_ZY, R_ZX), (4, 5)),
    "cylindrical": ((R_ZY, R_ZY), (2, 5)),
    "6d": ((R_ZY, R_ZY), ()),
}
BALL = (4, 5, 6)  # one point: the three rotations free


def fourbar(tmp_path, kind: str, d, closure_springs=None):
    (RA, RB), _ = FOURBAR_CUTS[kind]
    joints = [
        ("crank", "ground", "crank", A_, None, "revolute", Y),
        ("coupler", "crank", "coupler", B_, None, "revolute", Y),
        ("cA_joint", "coupler", "cA", C_, RA, "fixed", None),
        ("P_joint", "cA", "P", P_, None, "fixed", None),
        ("rocker", "ground", "rocker", d, None, "revolute", Y),
        ("cB_joint", "rocker", "cB", C_, RB, "fixed", None),
    ]
    closures = [("cA", "cB", kind)]
    if kind == "3d":  # the second point, 0.02 m along y
        joints += [("cA2_joint", "cA", "cA2", C_ + 0.02 * Y, None, "fixed", None),
                   ("cB2_joint", "cB", "cB2", C_ + 0.02 * Y, None, "fixed", None)]  # fmt: skip
        closures.append(("cA2", "cB2", "3d"))
    beams = {"crank": "coupler", "coupler": "cA_joint", "rocker": "cB_joint"}
    name = f"fourbar_{kind}" + ("_sprung" if closure_springs else "")
    return urdf_model(tmp_path, name, joints, closures, beams, {"crank": K_CRANK},
                      closure_springs)  # fmt: skip


def fourbar_opensees(free, d, cut_springs=None):
    """The four-bar in OpenSees, ``free`` (1-6) the dofs its cut frees."""

    def build(s: Structure) -> int:
        a = s.node(A_)
        s.joint(s.node(A_, fixed=True), a, free=(5,), springs={5: K_CRANK})
        b_tip, b = s.node(B_), s.node(B_)
        s.beam(a, b_tip)
        s.joint(b_tip, b, free=(5,))
        c_coupler = s.node(C_)
        s.beam(b, c_coupler)
        rocker = s.node(d)
        s.joint(s.node(d, fixed=True), rocker, free=(5,))
        c_rocker = s.node(C_)
        s.beam(rocker, c_rocker)
        s.joint(c_coupler, c_rocker, free=free, springs=cut_springs)
        p = s.node(P_)
        s.rigid(c_coupler, p)
        return p

    return build


CASES = {  # name -> (four-bar closure, rocker pivot)
    "planar four-bar, revolute closure": ("revolute", D_PLANAR),
    "planar four-bar, two point closures": ("3d", D_PLANAR),
    "spatial four-bar, universal closure": ("universal", D_SPATIAL),
    "spatial four-bar, cylindrical closure": ("cylindrical", D_SPATIAL),
}


@pytest.mark.parametrize("case", CASES)
def test_fourbar_against_opensees(tmp_path, case):
    kind, d = CASES[case]
    C = library_compliance(fourbar(tmp_path, kind, d), "P")
    assert_close_in_norm(
        C, opensees_compliance(fourbar_opensees(FOURBAR_CUTS[kind][1], d)), RTOL_OPENSEES, SCALE
    )


#: The closure file's elastic closure: B's motion relative to A in A's axes (dx, dy, dz,
#: rx, ry, rz), rigid but for a torsion spring K_CUT about A's z (world -y).
PIN_WITH_SPRING = f"{{0: [.inf, .inf, .inf, .inf, .inf, {K_CUT}]}}"


@pytest.mark.parametrize("kind", ["revolute", "6d"])
def test_torsion_spring_at_a_cut_against_opensees(tmp_path, kind):
    """A revolute closure given a spring about its axis, and a weld freed into the same
    sprung pin: both the pin of OpenSees with a zeroLength spring about y."""
    clm = fourbar(tmp_path, kind, D_PLANAR, closure_springs=PIN_WITH_SPRING)
    C = library_compliance(clm, "P")
    expected = opensees_compliance(fourbar_opensees((5,), D_PLANAR, {5: K_CUT}))
    assert_close_in_norm(C, expected, RTOL_OPENSEES, SCALE)
    rigid_cut = library_compliance(fourbar(tmp_path, "revolute", D_PLANAR), "P")
    assert np.linalg.norm(C - rigid_cut) > 1e-3 * np.linalg.norm(C)  # the spring counts


# ------------------------------------------------------------------------- slider-crank
S_ = np.array([0.3, 0.0, 0.05])  # the slider's pin; it slides along x


def test_slider_crank_with_a_prismatic_closure_against_opensees(tmp_path):
    """Crank A-B sprung at A, coupler B-S, a rigid slider pinned at S and closed against
    the ground by a prismatic closure along x; the output at B on the coupler."""
    joints = [
        ("crank", "ground", "crank", A_, None, "revolute", Y),
        ("coupler", "crank", "coupler", B_, None, "revolute", Y),
        ("B_joint", "coupler", "B", B_, None, "fixed", None),  # on the coupler's start
        ("slider_pin", "coupler", "slider", S_, None, "revolute", Y),
        ("sA_joint", "slider", "sA", S_, R_ZX, "fixed", None),
        ("sB_joint", "ground", "sB", S_, R_ZX, "fixed", None),
    ]
    clm = urdf_model(tmp_path, "slider_crank", joints, [("sA", "sB", "prismatic")],
                     {"crank": "coupler", "coupler": "slider_pin"}, {"crank": K_CRANK})  # fmt: skip

    def build(s: Structure) -> int:
        a, b_tip, b, s_tip = s.node(A_), s.node(B_), s.node(B_), s.node(S_)
        s.joint(s.node(A_, fixed=True), a, free=(5,), springs={5: K_CRANK})
        s.beam(a, b_tip)
        s.joint(b, b_tip, free=(5,))  # the coupler's start retained: it is loaded
        s.beam(b, s_tip)
        s.joint(s.node(S_, fixed=(2, 3, 4, 5, 6)), s_tip, free=(5,))  # slider: x only
        return b

    C = library_compliance(clm, "B")
    assert_close_in_norm(C, opensees_compliance(build), RTOL_OPENSEES, SCALE)


# ------------------------------------------------------------------------- welded frame
FRAME_NODES = np.array([[0, 0, 0], [0, 0, 0.4], [0.5, 0, 0.4], [0.5, 0.3, 0.4], [0.5, 0.3, 0]])


#: Elastic directions of the weld at D (A = the frame's end, world-aligned): none, or a
#: spring along y [N/m] and one about x [N m/rad].
WELD_SPRINGS = {"rigid weld": {}, "elastic weld": {2: 3.0e4, 4: 50.0}}


@pytest.mark.parametrize("weld", WELD_SPRINGS)
def test_spatial_frame_closed_by_a_weld_against_opensees(tmp_path, weld):
    """Four beam links A-B-C-E-D in series, clamped at A, welded to the ground at D by a
    '6d' closure, rigid or elastic in some directions; the output at C."""
    links = ["m0", "m1", "m2", "m3", "end"]
    joints = [(f"j{i}", (["ground", *links])[i], links[i], FRAME_NODES[i], None, "fixed", None)
              for i in range(5)]  # fmt: skip
    joints.append(("ja", "ground", "anchor", FRAME_NODES[4], None, "fixed", None))
    beams = {f"m{i}": f"j{i + 1}" for i in range(4)}
    springs = WELD_SPRINGS[weld]
    values = ", ".join(str(springs.get(d, ".inf")) for d in range(1, 7))
    clm = urdf_model(tmp_path, weld.replace(" ", "_"), joints, [("end", "anchor", "6d")],
                     beams, {}, f"{{0: [{values}]}}" if springs else None)  # fmt: skip

    def build(s: Structure) -> int:
        nodes = [s.node(FRAME_NODES[0], fixed=True)] + [s.node(p) for p in FRAME_NODES[1:]]
        for i, j in itertools.pairwise(nodes):
            s.beam(i, j)
        s.joint(s.node(FRAME_NODES[4], fixed=True), nodes[4], free=springs, springs=springs)
        return nodes[2]

    C = library_compliance(clm, "m2")
    assert_close_in_norm(C, opensees_compliance(build), RTOL_OPENSEES, SCALE)


# ----------------------------------------------------------------------------- platform
#: Three legs, bases -> tips [m]: leg 0 clamped at the ground; a rigid platform (a ternary
#: link) welded to its tip; legs 1 and 2 welded under the platform, down to their bases,
#: closed against the ground there by a ball ('3d') or a weld ('6d'); the output O on the
#: platform.
BASES = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.1, 0.25, 0.0]])
TIPS = np.array([[0.05, 0.03, 0.3], [0.25, 0.02, 0.3], [0.12, 0.2, 0.32]])
O_ = np.array([0.15, 0.1, 0.36])
BASE_CUTS = {"3d": (4, 5, 6), "6d": ()}  # the dofs OpenSees frees at a base


def _platform_on_legs(kind: str) -> tuple[list, list]:
    """(joints, closures) of a platform on three legs: leg 0 carries it, legs 1 and 2
    hang from it and are closed to the ground at their bases by a ``kind`` closure."""
    joints = [("base0", "ground", "leg0", BASES[0], None, "fixed", None),
              ("top0", "leg0", "platform", TIPS[0], None, "fixed", None),
              ("O_joint", "platform", "O", O_, None, "fixed", None)]  # fmt: skip
    for i in (1, 2):
        joints += [(f"top{i}", "platform", f"leg{i}", TIPS[i], None, "fixed", None),
                   (f"base{i}", f"leg{i}", f"b{i}", BASES[i], None, "fixed", None),
                   (f"ground{i}", "ground", f"g{i}", BASES[i], None, "fixed", None)]  # fmt: skip
    return joints, [(f"b{i}", f"g{i}", kind) for i in (1, 2)]


@pytest.mark.parametrize("kind", BASE_CUTS)
def test_rigid_platform_on_flexible_legs_against_opensees(tmp_path, kind):
    joints, closures = _platform_on_legs(kind)
    beams = {"leg0": "top0", "leg1": "base1", "leg2": "base2"}
    clm = urdf_model(tmp_path, f"platform_{kind}", joints, closures, beams, {})

    def build(s: Structure) -> int:
        platform = s.node(TIPS[0])  # leg 0's tip
        s.beam(s.node(BASES[0], fixed=True), platform)
        for i in (1, 2):
            top, base = s.node(TIPS[i]), s.node(BASES[i])
            s.rigid(platform, top)
            s.beam(top, base)
            s.joint(s.node(BASES[i], fixed=True), base, free=BASE_CUTS[kind])
        out = s.node(O_)
        s.rigid(platform, out)
        return out

    C = library_compliance(clm, "O")
    assert_close_in_norm(C, opensees_compliance(build), RTOL_OPENSEES, SCALE)


@pytest.mark.parametrize("kind", BASE_CUTS)
def test_flexible_platform_of_three_beams_against_opensees(tmp_path, kind):
    """The platform on the three legs above, flexible: three beams on one link, from its
    origin (leg 0's tip) to its centre O, and from O to the tips of legs 1 and 2."""
    joints, closures = _platform_on_legs(kind)
    platform = [(None, "O_joint"), ("O_joint", "top1"), ("O_joint", "top2")]
    beams = {"leg0": "top0", "platform": platform, "leg1": "base1", "leg2": "base2"}
    clm = urdf_model(tmp_path, f"flexible_platform_{kind}", joints, closures, beams, {})
    assert len(clm.spring_blocks) == 6

    def build(s: Structure) -> int:
        origin, out = s.node(TIPS[0]), s.node(O_)
        s.beam(s.node(BASES[0], fixed=True), origin)
        s.beam(origin, out)
        for i in (1, 2):
            top, base = s.node(TIPS[i]), s.node(BASES[i])
            s.beam(out, top)
            s.beam(top, base)
            s.joint(s.node(BASES[i], fixed=True), base, free=BASE_CUTS[kind])
        return out

    C = library_compliance(clm, "O")
    assert_close_in_norm(C, opensees_compliance(build), RTOL_OPENSEES, SCALE)
    del beams["platform"]  # the platform rigid: its beams are felt
    rigid = library_compliance(urdf_model(tmp_path, "rigid", joints, closures, beams, {}), "O")
    assert np.max(np.abs(C - rigid)) > 1e-2 * np.max(np.abs(rigid))


# ------------------------------------------------------------------------------- MJCF
#: The four-bar above (planar) in MJCF (:func:`mechanisms.mjcf_fourbar`), closed at C by a
#: ``<connect>`` (a '3d' closure, a ball), the crank's spring as its hinge's ``stiffness``.
FOURBAR_POINTS = {"B": B_, "C": C_, "D": D_PLANAR, "P": P_}


def test_mjcf_fourbar_with_beams_against_opensees(tmp_path):
    """The anchor given on the coupler and rocker bodies, at their beams' tips (jointless
    bodies carry the tips and P)."""
    connect = f'<connect name="C" body1="coupler" body2="rocker" anchor="{xyz_text(C_ - B_)}"/>'
    path = tmp_path / "fourbar_beams.xml"
    path.write_text(mjcf_fourbar(connect, K_CRANK, points=FOURBAR_POINTS))
    beams = {"crank": rod("coupler"), "coupler": rod("coupler_tip_fixed"),
             "rocker": rod("rocker_tip_fixed")}  # fmt: skip
    clm = cl.load_model(path, beams=beams)
    assert [c.kind for c in clm.closures] == ["3d"]
    C = library_compliance(clm, "P")
    assert_close_in_norm(
        C, opensees_compliance(fourbar_opensees(BALL, D_PLANAR)), RTOL_OPENSEES, SCALE
    )


def test_mjcf_fourbar_rocker_to_its_connect_anchor_against_opensees(tmp_path):
    """The same four-bar, its rocker a body whose far end is only the ``<connect>``'s
    anchor (computed by the reader on the rocker): a beam to ``anchor:C``."""
    connect = '<connect name="C" body1="coupler_tip" body2="rocker" anchor="0 0 0"/>'
    path = tmp_path / "fourbar_anchor.xml"
    path.write_text(mjcf_fourbar(connect, K_CRANK, rocker_tip=False, points=FOURBAR_POINTS))
    beams = {"crank": rod("coupler"), "coupler": rod("coupler_tip_fixed"),
             "rocker": rod("anchor:C")}  # fmt: skip
    clm = cl.load_model(path, beams=beams)
    assert "rocker_tip" not in clm.model.names and not clm.model.existFrame("rocker_tip")
    assert clm.closures[0].constraint.joint2_id == clm.model.getJointId("rocker_beam")
    C = library_compliance(clm, "P")
    assert_close_in_norm(
        C, opensees_compliance(fourbar_opensees(BALL, D_PLANAR)), RTOL_OPENSEES, SCALE
    )


#: A spatial mechanism of three legs [m]: leg i a thigh from its hip hinge (about world
#: y, x, y, sprung) at LEG_BASES[i] to its knee hinge (same axis, passive) at
#: LEG_KNEES[i], then a shank to LEG_TIPS[i], all in the leg's plane; a platform (a free
#: body) centred at CENTRE, closed to the three shanks' tips by equalities C0, C1, C2.
CENTRE = np.array([0.0, 0.0, 0.4])
LEG_BASES = np.array([[0.3, 0.0, 0.0], [-0.03, 0.3, 0.0], [-0.3, -0.06, 0.0]])
LEG_KNEES = np.array([[0.25, 0.0, 0.2], [-0.03, 0.26, 0.2], [-0.27, -0.06, 0.21]])
LEG_TIPS = np.array([[0.12, 0.0, 0.38], [-0.03, 0.11, 0.41], [-0.1, -0.06, 0.4]])
LEG_AXES = (5, 4, 5)  # the hinges' axes as the OpenSees dof of their rotation (ry, rx, ry)
K_HIPS = (400.0, 300.0, 500.0)  # [N m/rad]
#: MJCF equality closing the platform -> the dofs OpenSees frees at the legs' tips.
PLATFORM_EQUALITIES = {"connect": BALL, "weld": ()}


def platform_mjcf(equality: str) -> str:
    """The three-legged mechanism's MJCF text, closed by ``equality`` ("connect" or
    "weld") elements C0, C1, C2 (body1 the platform, body2 the shank); the site O at the
    platform's centre."""
    legs = "".join(
        f"""
      <body name="thigh{i}" pos="{xyz_text(LEG_BASES[i])}">
        <joint name="hip{i}" type="hinge" axis="{xyz_text(np.eye(3)[d - 4])}"
               stiffness="{K_HIPS[i]!r}"/>
        <body name="shank{i}" pos="{xyz_text(LEG_KNEES[i] - LEG_BASES[i])}">
          <joint name="knee{i}" type="hinge" axis="{xyz_text(np.eye(3)[d - 4])}"/>
        </body>
      </body>"""
        for i, d in enumerate(LEG_AXES)
    )
    # a <connect>'s anchor is in body1's frame (the platform's), a <weld>'s in body2's
    origins = [CENTRE] * 3 if equality == "connect" else LEG_KNEES
    closures = "".join(
        f'\n    <{equality} name="C{i}" body1="platform" body2="shank{i}" '
        f'anchor="{xyz_text(LEG_TIPS[i] - origins[i])}"/>'
        for i in range(3)
    )
    return f"""<mujoco model="three_legs">
  <compiler angle="radian"/>
  <worldbody>
    <body name="ground">{legs}
    </body>
    <body name="platform" pos="{xyz_text(CENTRE)}">
      <freejoint name="platform"/>
      <site name="O"/>
    </body>
  </worldbody>
  <equality>{closures}
  </equality>
</mujoco>"""


@pytest.mark.parametrize("equality", PLATFORM_EQUALITIES)
def test_mjcf_flexible_platform_to_three_closure_anchors_against_opensees(tmp_path, equality):
    """The platform three beams on one link, from its centre (its origin, the output O) to
    the anchors of its three ``<connect>`` (or ``<weld>``) closures, ``anchor:C<i>``; each
    shank a beam to its own anchor of the same closure, each thigh a beam to its knee.
    OpenSees: three beams from the centre node, each pinned (or welded) to a shank's tip."""
    path = tmp_path / "three_legs.xml"
    path.write_text(platform_mjcf(equality))
    beams = {"platform": [rod(f"anchor:C{i}") for i in range(3)]}
    for i in range(3):
        beams |= {f"thigh{i}": rod(f"knee{i}"), f"shank{i}": rod(f"anchor:C{i}")}
    clm = cl.load_model(path, beams=beams)
    assert [c.kind for c in clm.closures] == ["3d" if equality == "connect" else "6d"] * 3
    ends = [(clm.model.names[c.constraint.joint1_id], clm.model.names[c.constraint.joint2_id])
            for c in clm.closures]  # fmt: skip
    assert ends == [(f"platform_beam_anchor:C{i}", f"shank{i}_beam") for i in range(3)]

    def build(s: Structure) -> int:
        out = s.node(CENTRE)
        for i, d in enumerate(LEG_AXES):
            hip = s.node(LEG_BASES[i])
            s.joint(s.node(LEG_BASES[i], fixed=True), hip, free=(d,), springs={d: K_HIPS[i]})
            knee_thigh, knee_shank = s.node(LEG_KNEES[i]), s.node(LEG_KNEES[i])
            s.beam(hip, knee_thigh)
            s.joint(knee_thigh, knee_shank, free=(d,))
            tip_shank, tip_platform = s.node(LEG_TIPS[i]), s.node(LEG_TIPS[i])
            s.beam(knee_shank, tip_shank)
            s.beam(out, tip_platform)
            s.joint(tip_shank, tip_platform, free=PLATFORM_EQUALITIES[equality])
        return out

    C = library_compliance(clm, "O")
    assert_close_in_norm(C, opensees_compliance(build), RTOL_OPENSEES, SCALE)
    del beams["platform"]  # the platform rigid: its beams are felt
    rigid = library_compliance(cl.load_model(path, beams=beams), "O")
    assert np.max(np.abs(C - rigid)) > 1e-2 * np.max(np.abs(rigid))
