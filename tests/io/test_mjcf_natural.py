"""MJCF as written for MuJoCo: six UPS legs and a free-jointed platform, all direct
children of <worldbody>, against the URDF twin and the closed-form Stewart stiffness."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from helpers import REPO, assert_close_in_norm
from scipy.spatial.transform import Rotation

import closedloop as cl
from closedloop.io.loader import load_model
from closedloop.io.mjcf import WORLD_BODY

# Two parsers read one mechanism from 17-digit numbers; the MJCF anchors are computed at
# qpos0, the URDF configuration assembled by Newton to 1e-12 m: rounding, amplified by
# cond(J) ~ 10, well below 1e-9 (the tolerance).
RTOL_TWIN = 1e-9
K_LEG = 1e6  # [N/m], every prismatic leg
BASE_ANGLES = np.array([0.2, 1.9, 2.3, 4.0, 4.4, 6.1])  # [rad], radius 0.5 m, z = 0
TOP_ANGLES = np.array([0.9, 1.2, 3.0, 3.3, 5.1, 5.4])  # [rad], radius 0.3 m, platform frame
PLATFORM_XYZ = np.array([0.02, -0.01, 0.8])  # [m]
PLATFORM_RPY = np.array([0.05, -0.03, 0.1])  # [rad]


def numbers(values) -> str:
    return " ".join(repr(float(v)) for v in np.ravel(values))


def geometry():
    """Base points b (6, 3), platform points p (6, 3) in the platform frame, platform
    rotation R (3, 3), leg directions u (6, 3) and lengths l (6,) [m]."""
    b = 0.5 * np.c_[np.cos(BASE_ANGLES), np.sin(BASE_ANGLES), np.zeros(6)]
    p = 0.3 * np.c_[np.cos(TOP_ANGLES), np.sin(TOP_ANGLES), np.zeros(6)]
    R = Rotation.from_euler("xyz", PLATFORM_RPY).as_matrix()
    d = PLATFORM_XYZ + p @ R.T - b
    lengths = np.linalg.norm(d, axis=1)
    return b, p, R, d / lengths[:, None], lengths


def z_to(u: np.ndarray) -> Rotation:
    """A rotation taking +z to the unit vector u."""
    axis = np.cross([0.0, 0.0, 1.0], u)
    return Rotation.from_rotvec(axis / np.linalg.norm(axis) * np.arccos(u[2]))


def natural_mjcf() -> str:
    b, _, R, u, lengths = geometry()
    inertial = '<inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>'
    legs, connects = [], []
    for i in range(6):
        w, x, y, z = np.roll(z_to(u[i]).as_quat(), 1)  # MuJoCo: w x y z
        legs.append(
            f'<body name="leg{i}" pos="{numbers(b[i])}" quat="{numbers([w, x, y, z])}">'
            f'<joint name="leg{i}_x" type="hinge" axis="1 0 0"/>{inertial}'
            f'<body name="leg{i}_b"><joint name="leg{i}_y" type="hinge" axis="0 1 0"/>{inertial}'
            f'<body name="rod{i}"><joint name="leg{i}_slide" type="slide" axis="0 0 1" '
            f'stiffness="{K_LEG}"/>{inertial}</body></body></body>'
        )
        connects.append(
            f'<connect body1="rod{i}" body2="platform" anchor="{numbers([0, 0, lengths[i]])}"/>'
        )
    w, x, y, z = np.roll(Rotation.from_matrix(R).as_quat(), 1)
    platform = (
        f'<body name="platform" pos="{numbers(PLATFORM_XYZ)}" quat="{numbers([w, x, y, z])}">'
        f'<freejoint name="platform_free"/>{inertial}</body>'
    )
    return (
        '<mujoco model="hexapod"><compiler angle="radian"/><worldbody>'
        f'<geom type="plane" size="1 1 0.1"/>{"".join(legs)}{platform}</worldbody>'
        f"<equality>{''.join(connects)}</equality></mujoco>"
    )


def urdf_twin() -> tuple[str, str]:
    """(URDF, closure file) of the same hexapod: the platform on a floating joint."""
    b, p, _, u, lengths = geometry()
    inertial = (
        '<inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" '
        'ixz="0" iyz="0"/></inertial>'
    )
    limit = '<limit lower="-1" upper="1" effort="1" velocity="1"/>'
    parts = [
        '<robot name="hexapod"><link name="ground"/>',
        f'<link name="platform">{inertial}</link>',
    ]
    parts.append(
        '<joint name="platform_free" type="floating"><parent link="ground"/>'
        '<child link="platform"/></joint>'
    )
    for i in range(6):
        rpy = z_to(u[i]).as_euler("xyz")
        parts += [
            f'<link name="leg{i}">{inertial}</link><link name="leg{i}_b">{inertial}</link>',
            f'<link name="rod{i}">{inertial}</link><link name="end{i}"/><link name="pp{i}"/>',
            f'<joint name="leg{i}_x" type="revolute"><parent link="ground"/>'
            f'<child link="leg{i}"/><origin xyz="{numbers(b[i])}" rpy="{numbers(rpy)}"/>'
            f'<axis xyz="1 0 0"/>{limit}</joint>',
            f'<joint name="leg{i}_y" type="revolute"><parent link="leg{i}"/>'
            f'<child link="leg{i}_b"/><axis xyz="0 1 0"/>{limit}</joint>',
            f'<joint name="leg{i}_slide" type="prismatic"><parent link="leg{i}_b"/>'
            f'<child link="rod{i}"/><axis xyz="0 0 1"/>{limit}</joint>',
            f'<joint name="end{i}_joint" type="fixed"><parent link="rod{i}"/><child link="end{i}"/>'
            f'<origin xyz="{numbers([0, 0, lengths[i]])}"/></joint>',
            f'<joint name="pp{i}_joint" type="fixed"><parent link="platform"/><child link="pp{i}"/>'
            f'<origin xyz="{numbers(p[i])}"/></joint>',
        ]
    closures = (
        f"closed_loop: {[[f'end{i}', f'pp{i}'] for i in range(6)]}\n"
        f"type: {['3d'] * 6}\n"
        f"springs: {{{', '.join(f'leg{i}_slide: {K_LEG}' for i in range(6))}}}\n"
    )
    return "".join(parts) + "</robot>", closures


@pytest.fixture(scope="module")
def hexapods(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hexapod")
    (folder / "hexapod.xml").write_text(natural_mjcf())
    urdf, closures = urdf_twin()
    (folder / "hexapod.urdf").write_text(urdf)
    (folder / "hexapod.yaml").write_text(closures)
    mj = load_model(folder / "hexapod.xml")
    ur = load_model(folder / "hexapod.urdf", folder / "hexapod.yaml", geometry=False)
    return mj, ur


def test_every_root_body_is_kept(hexapods):
    mj, _ = hexapods
    assert len(mj.closures) == 6 and mj.model.nq == 6 * 3 + 7
    names = {f.name for f in mj.model.frames}
    assert {"platform", WORLD_BODY} | {f"rod{i}" for i in range(6)} <= names
    # the free joint's qpos0 is the platform's pose in the world, as MuJoCo has it
    state = cl.Configuration(mj, mj.reference_configuration())
    M = state.frame_placement("platform")
    np.testing.assert_allclose(M.translation, PLATFORM_XYZ, atol=1e-15)
    np.testing.assert_allclose(M.rotation, geometry()[2], atol=1e-15)
    assert state.closure_error < 1e-14


def test_sites_of_the_world_and_of_a_lone_root_body_without_joint_are_kept(tmp_path):
    """Pinocchio dropped the sites of <worldbody> and took a lone root body without joint
    for the world: its site was lost and its pose dropped from the bodies under it. Site w
    at (0.5, 0, 0) turned 90 deg about y; base at (1, 2, 3) turned 90 deg about z; site s
    at (0.1, 0.2, 0.3) in it, turned 90 deg about x; arm at (0, 0, 1) in it. Entries of
    order 1 from degrees: a few ulps."""
    text = (
        '<mujoco model="t"><worldbody><site name="w" pos="0.5 0 0" axisangle="0 1 0 90"/>'
        '<body name="base" pos="1 2 3" axisangle="0 0 1 90">'
        '<site name="s" pos="0.1 0.2 0.3" axisangle="1 0 0 90"/>'
        '<body name="arm" pos="0 0 1"><joint name="j" axis="0 1 0"/>'
        '<inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/></body>'
        "</body></worldbody></mujoco>"
    )
    (tmp_path / "t.xml").write_text(text)
    state = cl.Configuration(load_model(tmp_path / "t.xml", actuated=[], geometry=False), [0.0])
    expected = {  # (rotation, translation): Ry(90); Rz(90) Rx(90), (1, 2, 3) + Rz(90) s; Rz(90)
        "w": ([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], [0.5, 0, 0]),
        "s": ([[0, 0, 1], [1, 0, 0], [0, 1, 0]], [0.8, 2.1, 3.3]),
        "arm": ([[0, -1, 0], [1, 0, 0], [0, 0, 1]], [1, 2, 4]),
    }
    for frame, (rotation, translation) in expected.items():
        M = state.frame_placement(frame)
        np.testing.assert_allclose(M.rotation, rotation, atol=1e-15)
        np.testing.assert_allclose(M.translation, translation, atol=1e-15)


def test_natural_mjcf_equals_its_urdf_twin_and_the_stewart_formula(hexapods):
    mj, ur = hexapods
    C_mj = cl.compliance(mj, mj.reference_configuration(), "platform").C
    q0 = ur.reference_configuration()
    free = ur.model.joints[ur.joint_id("platform_free")].idx_q
    R = geometry()[2]
    q0[free : free + 7] = np.r_[PLATFORM_XYZ, Rotation.from_matrix(R).as_quat()]
    q_ur = cl.assemble(ur, q0=q0).q
    C_ur = cl.compliance(ur, q_ur, "platform").C
    assert_close_in_norm(C_mj, C_ur, RTOL_TWIN)
    # Stewart-Gough: leg rates dl = u.(v + w x r) = [u, r x u] (v, w); K = J^T k J
    _, p, R, u, _ = geometry()
    r = p @ R.T
    J = np.c_[u, np.cross(r, u)]
    assert np.linalg.cond(J) < 100  # a generic, well-conditioned pose
    assert_close_in_norm(C_mj, np.linalg.inv(K_LEG * J.T @ J), RTOL_TWIN)


def test_assets_of_the_copy_are_found(tmp_path):
    """Pinocchio reads a copy in a temporary folder: a relative meshdir still resolves."""
    (tmp_path / "meshes").mkdir()
    text = natural_mjcf().replace(
        '<compiler angle="radian"/>', '<compiler angle="radian" meshdir="meshes"/>'
    )
    # an ASCII STL of one triangle, on the platform
    (tmp_path / "meshes" / "tri.stl").write_text(
        "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 0.1 0 0\n"
        "vertex 0 0.1 0\nendloop\nendfacet\nendsolid t\n"
    )
    text = text.replace(
        "<worldbody>", '<asset><mesh name="tri" file="tri.stl"/></asset><worldbody>'
    )
    text = text.replace(
        '<freejoint name="platform_free"/>',
        '<freejoint name="platform_free"/><geom type="mesh" mesh="tri"/>',
    )
    (tmp_path / "hexapod.xml").write_text(text)
    robot = load_model(tmp_path / "hexapod.xml")
    meshes = [g.meshPath for g in robot.visual_model.geometryObjects if g.meshPath.endswith(".stl")]
    assert meshes and all(m.startswith(str(tmp_path / "meshes")) for m in meshes)


def pendulum_with_welded_platform(quat: str) -> str:
    """A 0.5 m pendulum (hinge, 20 N m/rad) and a free platform welded to its end."""
    return (
        '<mujoco model="p"><compiler angle="radian"/><worldbody>'
        '<body name="arm"><joint name="hinge" type="hinge" axis="0 1 0" stiffness="20"/>'
        '<inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/></body>'
        f'<body name="platform" pos="0 0 0.5" quat="{quat}"><freejoint name="platform_free"/>'
        '<inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/></body></worldbody>'
        '<equality><weld body1="platform" body2="arm"/></equality></mujoco>'
    )


def test_rotated_free_body_is_where_the_file_puts_it(tmp_path):
    """Pinocchio 4.1 misplaces a rotated free body (closedloop.io.mjcf.place_free_joints):
    corrected, the platform sits at its pos and the weld, re-anchored, carries it rigidly
    on the pendulum: the compliance does not depend on the platform's orientation."""
    C = {}
    for quat in ("1 0 0 0", "0.9 0.1 0.3 -0.2"):
        (tmp_path / "p.xml").write_text(pendulum_with_welded_platform(quat))
        robot = load_model(tmp_path / "p.xml", geometry=False)
        state = cl.Configuration(robot, robot.reference_configuration())
        np.testing.assert_allclose(state.frame_placement("platform").translation, [0, 0, 0.5])
        assert state.closure_error < 1e-14
        C[quat] = cl.compliance(state, "platform").C
    assert_close_in_norm(C["0.9 0.1 0.3 -0.2"], C["1 0 0 0"], 1e-12)
    assert C["1 0 0 0"][0, 0] == pytest.approx(0.5**2 / 20, rel=1e-12)  # dx = L^2 fx / k


# --------------------------------------------------------------- gallery: Stewart 6-UPS
GALLERY_K = np.array([1.0, 1.4, 1.8, 2.2, 2.6, 3.0]) * 1e5  # [N/m], scripts/gallery_spatial.py


def test_gallery_files_are_up_to_date():
    script = REPO / "scripts" / "generate_gallery.py"
    done = subprocess.run([sys.executable, str(script), "--check"], capture_output=True)
    assert done.returncode == 0, done.stderr.decode()


def test_gallery_stewart_mjcf_urdf_and_formula_agree():
    """urdf/stewart.xml (natural MJCF) and urdf/stewart.urdf + .yaml against
    K = J^T diag(k) J, the geometry restated from scripts/gallery_spatial.py."""
    mj = load_model(REPO / "urdf" / "stewart.xml", geometry=False)
    ur = load_model(REPO / "urdf" / "stewart.urdf", REPO / "urdf" / "stewart.yaml", geometry=False)
    C_mj = cl.compliance(mj, mj.reference_configuration(), "platform").C
    q0 = ur.reference_configuration()
    free = ur.model.joints[ur.joint_id("platform_free")].idx_q
    q0[free : free + 3] = [0.0, 0.0, 1.0]  # start at the drawn platform pose
    C_ur = cl.compliance(ur, cl.assemble(ur, q0=q0).q, "platform").C
    assert_close_in_norm(C_ur, C_mj, RTOL_TWIN)

    def circle(radius: float, half_angle_deg: float) -> np.ndarray:  # 120 k -/+ half angle
        a = np.deg2rad(np.repeat([0.0, 120.0, 240.0], 2) + np.tile([-1, 1], 3) * half_angle_deg)
        return radius * np.c_[np.cos(a), np.sin(a), np.zeros(6)]

    b, r = circle(1.0, 15.0), circle(0.5, 45.0)  # base; platform anchors (level platform)
    legs = np.array([0.0, 0.0, 1.0]) + r - b
    u = legs / np.linalg.norm(legs, axis=1)[:, None]
    J = np.c_[u, np.cross(r, u)]
    assert_close_in_norm(C_mj, np.linalg.inv(J.T @ np.diag(GALLERY_K) @ J), RTOL_TWIN)


def test_gallery_fivebar_mjcf_urdf_and_formula_agree():
    """urdf/fivebar5.xml and urdf/fivebar5.urdf + .yaml against the planar Jacobian of the
    five-bar, the geometry restated from scripts/gallery_planar.py: dtheta_i = w_i . dE /
    (n_i . w_i), n_i = z x (B_i - A_i), w_i the unit distal direction; rz of distal 0 is
    (z x w_0) . (dE - dtheta_0 n_0) / l2."""
    mj = load_model(REPO / "urdf" / "fivebar5.xml", geometry=False)
    ur = load_model(
        REPO / "urdf" / "fivebar5.urdf", REPO / "urdf" / "fivebar5.yaml", geometry=False
    )
    assert mj.actuated == ur.actuated == ("leg0", "leg1")
    C_mj = cl.compliance(mj, np.zeros(4), "E").C
    C_ur = cl.compliance(ur, np.zeros(4), "E").C
    assert_close_in_norm(C_ur, C_mj, RTOL_TWIN)
    A, E, l1, l2 = np.array([[-0.15, 0.0], [0.15, 0.0]]), np.array([0.03, 0.38]), 0.2, 0.3
    B = []
    for a, elbow in zip(A, (1.0, -1.0), strict=True):  # elbows outward (law of cosines)
        d = E - a
        gamma = np.arccos((l1**2 + d @ d - l2**2) / (2 * l1 * np.linalg.norm(d)))
        t = np.arctan2(d[1], d[0]) + elbow * gamma
        B.append(a + l1 * np.array([np.cos(t), np.sin(t)]))
    perp = np.array([[0.0, -1.0], [1.0, 0.0]])  # z x (.)
    n = [perp @ (b - a) for a, b in zip(A, B, strict=True)]
    w = [(E - b) / l2 for b in B]
    dtheta_dE = np.array([w[i] / (n[i] @ w[i]) for i in range(2)])  # (2, 2)
    dE_dtheta = np.linalg.inv(dtheta_dE)
    rz = (perp @ w[0]) @ (dE_dtheta - np.outer(n[0], [1.0, 0.0])) / l2
    Jp = np.vstack([dE_dtheta, rz])  # (dx, dy, rz) per (dtheta_0, dtheta_1)
    C_planar = Jp @ np.diag([1 / 100.0, 1 / 150.0]) @ Jp.T
    plane = [0, 1, 5]
    assert_close_in_norm(C_mj[np.ix_(plane, plane)], C_planar, RTOL_TWIN)
    out_of_plane = np.delete(np.delete(C_mj, plane, 0), plane, 1)
    np.testing.assert_allclose(out_of_plane, 0.0, atol=1e-12 * np.abs(C_mj).max())


def test_gallery_rrr3_mjcf_urdf_and_formula_agree():
    """urdf/rrr3.xml and urdf/rrr3.urdf + .yaml against the planar 3-RRR stiffness
    K = J^T diag(k) J, dtheta_i = w_i . (v + w z x r_i) / (n_i . w_i) (names of the
    five-bar test; r_i the pin relative to the platform origin), the geometry restated
    from scripts/gallery_planar.py."""
    mj = load_model(REPO / "urdf" / "rrr3.xml", geometry=False)
    ur = load_model(REPO / "urdf" / "rrr3.urdf", REPO / "urdf" / "rrr3.yaml", geometry=False)
    C_mj = cl.compliance(mj, mj.reference_configuration(), "platform").C
    q0 = ur.reference_configuration()
    free = ur.model.joints[ur.joint_id("platform_free")].idx_q
    q0[free : free + 7] = [0.02, 0.01, 0.0, 0.0, 0.0, np.sin(0.05), np.cos(0.05)]
    C_ur = cl.compliance(ur, cl.assemble(ur, q0=q0).q, "platform").C
    assert_close_in_norm(C_ur, C_mj, RTOL_TWIN)
    angles = np.deg2rad(90.0 + 120.0 * np.arange(3))
    ring = np.c_[np.cos(angles), np.sin(angles)]
    c, s = np.cos(0.1), np.sin(0.1)
    r = 0.15 * ring @ np.array([[c, -s], [s, c]]).T  # pins about the platform origin
    A, C = 0.5 * ring, np.array([0.02, 0.01]) + r
    perp = np.array([[0.0, -1.0], [1.0, 0.0]])  # z x (.)
    rows = []
    for a, pin_, ri in zip(A, C, r, strict=True):
        d = pin_ - a
        t = np.arctan2(d[1], d[0]) + np.arccos(np.linalg.norm(d) / 0.6)  # isosceles 0.3 + 0.3
        b = a + 0.3 * np.array([np.cos(t), np.sin(t)])
        w, n = (pin_ - b) / 0.3, perp @ (b - a)
        rows.append(np.r_[w, w @ (perp @ ri)] / (n @ w))  # per (vx, vy, wz)
    J = np.array(rows)
    K_planar = J.T @ np.diag([200.0, 300.0, 400.0]) @ J
    plane = [0, 1, 5]
    assert_close_in_norm(C_mj[np.ix_(plane, plane)], np.linalg.inv(K_planar), RTOL_TWIN)


def arm_angle(d: np.ndarray, e_r: np.ndarray, la: float, lr: float) -> float:
    """Arm angle t in (-0.5, 1.5) rad with |d - la u(t)| = lr, u = cos t e_r - sin t e_z
    (outward and down), by bisection."""
    e_z = np.array([0.0, 0.0, 1.0])

    def gap(t: float) -> float:
        return np.linalg.norm(d - la * (np.cos(t) * e_r - np.sin(t) * e_z)) - lr

    lo, hi = -0.5, 1.5
    assert gap(lo) * gap(hi) < 0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if gap(lo) * gap(mid) <= 0 else (mid, hi)
    return 0.5 * (lo + hi)


def test_gallery_delta_mjcf_urdf_and_formula_agree():
    """urdf/delta.xml and urdf/delta.urdf + .yaml (the URDF at the MJCF's qpos0, joint by
    joint) against the rigid-rod Delta: with r_i the rod vector of arm i (both rods of a
    parallelogram alike), r_i . (dp - l_a du_i/dtheta dtheta_i) = 0, so dtheta_i =
    r_i . dp / (l_a r_i . du_i/dtheta) and C = J^-1 diag(1/k) J^-T for the translations;
    the parallelograms stop every rotation. Geometry: scripts/gallery_spatial.py."""
    mj = load_model(REPO / "urdf" / "delta.xml", geometry=False)
    ur = load_model(REPO / "urdf" / "delta.urdf", REPO / "urdf" / "delta.yaml", geometry=False)
    q_mj = mj.reference_configuration()
    q_ur = ur.reference_configuration()
    for j in range(1, mj.model.njoints):
        a, b = mj.model.joints[j], ur.model.joints[ur.joint_id(mj.model.names[j])]
        q_ur[b.idx_q : b.idx_q + b.nq] = q_mj[a.idx_q : a.idx_q + a.nq]
    res = cl.compliance(mj, q_mj, "platform")
    assert res.rank == 3 and res.internal_mobilities == 6  # the rods' spins
    assert_close_in_norm(
        cl.compliance(ur, cl.assemble(ur, q0=q_ur).q, "platform").C, res.C, RTOL_TWIN
    )
    p, la, lr, k = np.array([0.03, -0.02, -0.8]), 0.3, 0.8, np.array([300.0, 400.0, 500.0])
    rows = []
    for i in range(3):
        phi = np.deg2rad(120.0 * i)
        e_r, e_z = np.array([np.cos(phi), np.sin(phi), 0.0]), np.array([0.0, 0.0, 1.0])
        d = p + (0.05 - 0.2) * e_r  # from the motor axis to the pair's mid anchor
        t = arm_angle(d, e_r, la, lr)
        r = d - la * (np.cos(t) * e_r - np.sin(t) * e_z)
        du = -np.sin(t) * e_r - np.cos(t) * e_z
        rows.append(r / (la * r @ du))
    J = np.array(rows)  # dtheta per dp
    Ji = np.linalg.inv(J)
    assert_close_in_norm(res.C[:3, :3], Ji @ np.diag(1 / k) @ Ji.T, RTOL_TWIN)
