"""Deflection viewer: scene maths against independent routes, the exported page's commands.

The static page embeds every meshcat command as a base64 msgpack blob; the tests decode
them and check what the scene holds (both robots in one object with each mesh once, their
materials and placements, arrows, ellipsoids, grid, camera, animation) and the legend's
text, not only that a file was written. The command lines are in ``test_viewer_cli.py``,
the page in a real browser in ``test_browser.py``.
"""

from __future__ import annotations

import asyncio
import json
import re
import urllib.request
from collections import Counter

import numpy as np
import pinocchio as pin
import pytest
from helpers import (
    UR5_BEAM_ENDS,
    UR5_Q,
    commands,
    json_matrix,
    rigid_link_poses,
    robot_groups,
    robots_object,
)
from tornado.websocket import websocket_connect

from cahyman_pin.model import cahyman_model
from closedloop.elastostatics.compliance import compliance
from closedloop.elastostatics.statics import solve_equilibrium
from closedloop.exceptions import EquilibriumError, InvalidInputError
from closedloop.io.loader import load_model
from closedloop.kinematics.assembly import ASSEMBLY_TOL, assemble
from closedloop.kinematics.constraints import closure_residual
from closedloop.model.beams import map_configuration
from closedloop.viewer.ellipsoids import ELLIPSOID_MAX_FRACTION, LEVER_FRACTION
from closedloop.viewer.mesh import node_name
from closedloop.viewer.motion import AUTO_FRACTION, ROTATION_CAP
from closedloop.viewer.page import legend_rows
from closedloop.viewer.scene import deflection_scene
from closedloop.viewer.viewer import (
    CAMERA_MARGIN,
    ELLIPSOID_MIN_FRACTION,
    GHOST_RGBA,
    DeflectionViewer,
    colormap,
    ellipsoid_box,
    grid_step,
    legend_info,
)

#: Central differences of positions (metre-sized links, unit-sized dq) with step FD_STEP:
#: truncation ~ FD_STEP^2, rounding ~ 1e-16 / FD_STEP; both far below FD_RTOL.
FD_STEP, FD_RTOL = 1e-6, 1e-7
#: Quantities computed along two exact routes (rounding only).
RTOL_EXACT = 1e-9
#: Placements sent to meshcat go through msgpack as float64: exact to rounding.
ATOL_PLACEMENT = 1e-12
#: Drawn placements [m] against :func:`helpers.rigid_link_poses` (twists from central
#: differences, relative error ~ 1e-10, on drawn motions of at most a model size).
ATOL_DRAWN = 1e-8
#: Closure gap [m] that the first-order amplified four-bar pose at scale 150 exceeds: the
#: gap is of second order, ~ (s |dq|)^2 / L, some centimetres here (0.095 m measured).
OPEN_GAP = 1e-3
FOURBAR_WRENCH = [3.0, 0.0, -20.0, 0.0, 0.0, 0.0]  # [N, N m] at P
UR5_WRENCH = [10.0, -5.0, -40.0, 0.0, 0.0, 2.0]
PANDA_Q = [0.0, -0.5, 0.0, -2.0, 0.0, 1.6, 0.8, 0.02]  # the second finger mimics the first
#: The issue's bound for the UR5 page (18.7 MB with every mesh twice as Collada text).
UR5_MAX_PAGE_BYTES = 10_000_000
EXTERNAL = re.compile(r"<(?:script|link|img|iframe)\b[^>]*\b(?:src|href)\s*=\s*[\"']?https?:", re.I)


def by_path(cmds: list[dict], kind: str) -> dict[str, dict]:
    return {c["path"]: c for c in cmds if c["type"] == kind}


def matrix(c: dict) -> np.ndarray:
    """(4, 4) transform of a set_transform command (meshcat sends it column-major)."""
    return np.array(c["matrix"], dtype=float).reshape(4, 4).T


def properties(cmds: list[dict], path: str) -> dict:
    return {
        c["property"]: c["value"] for c in cmds if c["type"] == "set_property" and c["path"] == path
    }


def geometry_placements(clm, q) -> dict[str, np.ndarray]:
    """Geometry name -> (4, 4) world placement at q, from Pinocchio directly."""
    data, gdata = clm.model.createData(), clm.visual_model.createData()
    pin.forwardKinematics(clm.model, data, q)
    pin.updateGeometryPlacements(clm.model, data, clm.visual_model, gdata)
    return {
        g.name: gdata.oMg[i].homogeneous for i, g in enumerate(clm.visual_model.geometryObjects)
    }


def drawn_placements(clm, scene, poses=None) -> dict[str, np.ndarray]:
    """Geometry name -> (4, 4) world placement as drawn: carried by its joint body moved
    rigidly along its twist (:func:`helpers.rigid_link_poses`), or at the given ``poses``."""
    if poses is None:
        poses = rigid_link_poses(clm.model, scene.q, scene.dq, scene.scale)
    return {
        g.name: poses[g.parentJoint] @ g.placement.homogeneous
        for g in clm.visual_model.geometryObjects
    }


def rotation_angles(poses, nominal) -> np.ndarray:
    """(njoints,) angle [rad] of each drawn joint body's rotation from its nominal one."""
    return np.array(
        [
            np.linalg.norm(pin.log3(P[:3, :3] @ N[:3, :3].T))
            for P, N in zip(poses, nominal, strict=True)
        ]
    )


def export(clm, scene, tmp_path, name="scene.html", **show) -> tuple[str, list[dict]]:
    with DeflectionViewer(clm) as viewer:
        viewer.show(scene, **show)
        path = viewer.save_html(tmp_path / name)
    html = path.read_text(encoding="utf-8")
    return html, commands(html)


@pytest.fixture(scope="module")
def fourbar(fourbar_urdf, fourbar_yaml):
    clm = load_model(fourbar_urdf, fourbar_yaml)
    return clm, assemble(clm, [0.3]).q


@pytest.fixture(scope="module")
def ur5(ur5_urdf):
    return load_model(ur5_urdf, joint_stiffness=1e4), np.array(UR5_Q)


@pytest.fixture(scope="module")
def panda(panda_urdf):
    return load_model(panda_urdf, joint_stiffness=1e4), np.array(PANDA_Q)


@pytest.fixture(scope="module")
def cahyman():
    model = cahyman_model()
    return model.clm, model.assemble(np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.0)


@pytest.fixture(scope="module")
def fourbar_export(fourbar, tmp_path_factory):
    clm, q = fourbar
    scene = deflection_scene(clm, q, "P", FOURBAR_WRENCH, rotational=True)
    html, cmds = export(clm, scene, tmp_path_factory.mktemp("fourbar"))
    return scene, html, cmds


# ------------------------------------------------------------------ scene maths
def fd_displacements(clm, q, frame, dq) -> np.ndarray:
    """Central-difference displacements of the joint origins and of ``frame`` along dq."""
    model, data, fid = clm.model, clm.model.createData(), clm.model.getFrameId(frame)

    def points(eps):
        pin.framesForwardKinematics(model, data, pin.integrate(model, q, eps * dq))
        return np.array([*(m.translation for m in data.oMi[1:]), data.oMf[fid].translation])

    return (points(FD_STEP) - points(-FD_STEP)) / (2.0 * FD_STEP)


def bbox_diagonal(clm, q) -> float:
    data = clm.model.createData()
    pin.framesForwardKinematics(clm.model, data, q)
    p = np.array([*(m.translation for m in data.oMi[1:]), *(f.translation for f in data.oMf)])
    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))


@pytest.mark.parametrize("robot", ["fourbar", "ur5"])
def test_auto_scale_caps_the_drawn_displacement_and_rotation(robot, request):
    """s = min(AUTO_FRACTION L / d_max, ROTATION_CAP / w_max), d_max and w_max from
    central differences of the forward kinematics (the four-bar's rotation cap binds, the
    UR5's displacement cap)."""
    clm, q = request.getfixturevalue(robot)
    frame, w = ("P", FOURBAR_WRENCH) if robot == "fourbar" else ("tool0", UR5_WRENCH)
    scene = deflection_scene(clm, q, frame, w)
    dq = compliance(clm, q, frame).G @ np.array(w)
    np.testing.assert_allclose(scene.dq, dq, rtol=RTOL_EXACT, atol=0.0)
    d_max = np.max(np.linalg.norm(fd_displacements(clm, q, frame, dq), axis=1))
    nominal = rigid_link_poses(clm.model, q, dq, 0.0)
    w_max = np.max(rotation_angles(rigid_link_poses(clm.model, q, dq, 1.0), nominal))
    size = bbox_diagonal(clm, q)
    np.testing.assert_allclose(scene.size, size, rtol=RTOL_EXACT)
    np.testing.assert_allclose(scene.max_displacement, d_max, rtol=FD_RTOL)
    np.testing.assert_allclose(scene.max_rotation, w_max, rtol=FD_RTOL)
    expected = min(AUTO_FRACTION * size / d_max, ROTATION_CAP / w_max)
    np.testing.assert_allclose(scene.scale, expected, rtol=FD_RTOL)
    assert (ROTATION_CAP / w_max < AUTO_FRACTION * size / d_max) == (robot == "fourbar")
    assert scene.auto_scaled
    drawn = rotation_angles(scene.poses_deflected, nominal)
    assert np.max(drawn) <= ROTATION_CAP * (1 + FD_RTOL)
    np.testing.assert_allclose(
        scene.q_deflected, pin.integrate(clm.model, q, scene.scale * dq), rtol=0, atol=1e-15
    )


def test_given_scale_is_kept_and_zero_shows_the_nominal_pose(fourbar):
    clm, q = fourbar
    scene = deflection_scene(clm, q, "P", FOURBAR_WRENCH, scale=0.0)
    assert (scene.scale, scene.auto_scaled) == (0.0, False)
    np.testing.assert_array_equal(scene.q_deflected, q)
    np.testing.assert_array_equal(scene.point_deflected, scene.point)


def test_close_loops_reassembles_with_the_passive_joints(fourbar):
    clm, q = fourbar
    kwargs = {"scale": 150.0, "frames": 3}  # over-amplified: first order opens the loop
    opened = deflection_scene(clm, q, "P", FOURBAR_WRENCH, **kwargs)
    closed = deflection_scene(clm, q, "P", FOURBAR_WRENCH, close_loops=True, **kwargs)
    assert np.max(np.abs(closure_residual(clm, opened.q_deflected))) > OPEN_GAP
    for q_opened, q_closed in zip(opened.ramp_q, closed.ramp_q, strict=True):
        assert np.max(np.abs(closure_residual(clm, q_closed))) < ASSEMBLY_TOL
        springs = clm.stiffness != 0.0  # spring, actuated and locked: kept (1-dof joints)
        np.testing.assert_array_equal(q_closed[springs], q_opened[springs])


def test_zero_wrench_has_unit_scale_and_no_ellipsoid(fourbar):
    clm, q = fourbar
    scene = deflection_scene(clm, q, "P", np.zeros(6), rotational=True)
    assert (scene.scale, scene.max_displacement, scene.ellipsoids) == (1.0, 0.0, ())


def test_ellipsoids_follow_the_documented_scaling(ur5):
    clm, q = ur5
    f, n = np.array(UR5_WRENCH[:3]), np.array(UR5_WRENCH[3:])
    scene = deflection_scene(clm, q, "tool0", UR5_WRENCH, rotational=True)
    C, s = compliance(clm, q, "tool0").C, scene.scale
    trans, rot = scene.ellipsoids
    for e, block, length in (
        (trans, C[:3, :3], s * np.linalg.norm(f)),
        (rot, C[3:, 3:], s * np.linalg.norm(n) * LEVER_FRACTION * scene.size),
    ):
        # the ellipsoid {A u : |u| = 1} with A = length * block: A A^T = axes diag(r^2) axes^T
        shape = e.axes @ np.diag(e.radii**2) @ e.axes.T
        expected = (length * block) @ (length * block)
        np.testing.assert_allclose(
            shape, expected, rtol=RTOL_EXACT, atol=RTOL_EXACT * np.max(expected)
        )
        np.testing.assert_allclose(e.centre, scene.point, rtol=0, atol=0)


def test_amplified_displacement_under_a_pure_force_lies_on_the_ellipsoid(ur5):
    clm, q = ur5
    w = np.array([10.0, -5.0, -40.0, 0.0, 0.0, 0.0])
    scene = deflection_scene(clm, q, "tool0", w)
    (e,) = scene.ellipsoids
    x = scene.scale * scene.compliance.C[:3] @ w  # first-order amplified displacement [m]
    local = e.axes.T @ x / e.radii
    np.testing.assert_allclose(local @ local, 1.0, rtol=RTOL_EXACT)


def test_nonlinear_option_uses_the_static_solver(fourbar):
    clm, q = fourbar
    w = np.array([0.0, 0.0, -200.0, 0.0, 0.0, 0.0])  # large enough to be nonlinear
    scene = deflection_scene(clm, q, "P", w, nonlinear=True, frames=5)
    for t, q_shown in zip(scene.ramp, scene.ramp_q, strict=True):
        dq = solve_equilibrium(clm, q, "P", t * w).joint_deflection
        np.testing.assert_allclose(
            q_shown, pin.integrate(clm.model, q, scene.scale * dq), rtol=0, atol=1e-12
        )
    linear = deflection_scene(clm, q, "P", w).dq
    assert scene.nonlinear
    assert np.linalg.norm(scene.dq - linear) > 0.1 * np.linalg.norm(linear)


def test_a_nonlinear_view_beyond_the_limit_load_names_the_wrench_given(fourbar):
    """The ramp solved its first fraction first: the error named 1/24 of the wrench."""
    clm, q = fourbar
    w = np.array([1e6, 0.0, -2e6, 0.0, 0.0, 0.0])
    with pytest.raises(EquilibriumError, match=r"wrench \[1000000.0, 0.0, -2000000.0, 0.0"):
        deflection_scene(clm, q, "P", w, nonlinear=True)


def test_bad_inputs_raise(fourbar):
    clm, q = fourbar
    for kwargs in ({"scale": -1.0}, {"scale": np.inf}, {"frames": 1}):
        with pytest.raises(InvalidInputError):
            deflection_scene(clm, q, "P", FOURBAR_WRENCH, **kwargs)
    with pytest.raises(InvalidInputError, match="wrench"):
        deflection_scene(clm, q, "P", [0.0, np.nan, 0.0, 0.0, 0.0, 0.0])


def test_overflowing_load_is_refused(fourbar):
    clm, q = fourbar
    with pytest.raises(InvalidInputError, match="too large"):
        deflection_scene(clm, q, "P", [1.7e308, 1.7e308, 0.0, 0.0, 0.0, 0.0])  # |f| = inf


def test_large_ellipsoids_are_shrunk_to_a_fraction_of_the_model(cahyman):
    clm, q = cahyman
    scene = deflection_scene(clm, q, "M", [0.0, 0.0, 0.0, 0.0, 0.0, 5.0], rotational=True)
    assert {e.kind for e in scene.ellipsoids} == {"translation", "rotation"}
    for e in scene.ellipsoids:
        assert np.max(e.radii) > ELLIPSOID_MAX_FRACTION * scene.size  # the case
        np.testing.assert_allclose(np.max(e.drawn_radii), ELLIPSOID_MAX_FRACTION * scene.size)
        assert 0.0 < e.shrink < 1.0


@pytest.mark.parametrize(
    ("size", "step"), [(0.524, 0.05), (1.0, 0.1), (0.0123, 0.002), (3.0, 0.5), (70.0, 10.0)]
)
def test_grid_step_is_a_round_length_near_an_eighth_of_the_size(size, step):
    assert grid_step(size) == pytest.approx(step, rel=1e-12)


# ------------------------------------------------------------------ exported page
def test_static_page_is_self_contained_and_titled(fourbar_export):
    _, html, cmds = fourbar_export
    assert "<script" in html and EXTERNAL.search(html) is None
    assert "<title>fourbar: deflection at P (closedloop viewer)</title>" in html
    assert len(cmds) > 10


def test_page_holds_ghost_and_deflected_poses(fourbar, fourbar_export):
    clm, q = fourbar
    scene, _, cmds = fourbar_export
    obj = robots_object(cmds)
    materials = {m["uuid"]: m for m in obj["materials"]}
    for root, placements, atol in (
        ("nominal", geometry_placements(clm, q), ATOL_PLACEMENT),
        ("deflected", drawn_placements(clm, scene), ATOL_DRAWN),
    ):
        groups = robot_groups(obj, root)
        for g in clm.visual_model.geometryObjects:
            group = groups[node_name(root, g.name)]
            np.testing.assert_allclose(json_matrix(group), placements[g.name], atol=atol)
            (mesh,) = group["children"]
            m = materials[mesh["material"]]
            if root == "nominal":
                assert (m["transparent"], m["opacity"]) == (True, GHOST_RGBA[3])
                assert m["depthWrite"] is False
            else:  # primitives: one colour, the displacement at the origin (colour test)
                assert (m["transparent"], m["opacity"]) == (False, 1.0)
    assert properties(cmds, "/meshcat/robots")["amplification"] == scene.scale


@pytest.mark.parametrize("robot", ["ur5", "panda"])
@pytest.mark.parametrize("coloured", [True, False])
def test_dae_robot_page_embeds_each_mesh_once_with_a_translucent_ghost(
    robot, coloured, request, tmp_path
):
    """One buffer a mesh file (model colours) or a geometry object (vertex colours: the
    Panda's two fingers share finger.dae but not their colours), each used by both robots."""
    clm, q = request.getfixturevalue(robot)
    frame = "tool0" if robot == "ur5" else "panda_hand"
    scene = deflection_scene(clm, q, frame, UR5_WRENCH, rotational=True)
    html, cmds = export(clm, scene, tmp_path, colour_by_displacement=coloured)
    obj = robots_object(cmds)
    paths = [g.meshPath for g in clm.visual_model.geometryObjects]
    assert all(f.endswith(".dae") for f in paths)
    uses = Counter(
        mesh["geometry"]
        for root in ("nominal", "deflected")
        for group in robot_groups(obj, root).values()
        for mesh in group["children"]
    )
    assert set(uses) == {geo["uuid"] for geo in obj["geometries"]}
    if coloured:
        assert sorted(uses.values()) == [2] * len(paths)
    else:
        assert sorted(uses.values()) == sorted(2 * paths.count(f) for f in set(paths))
    materials = {m["uuid"]: m for m in obj["materials"]}
    for group in robot_groups(obj, "nominal").values():
        (mesh,) = group["children"]
        assert materials[mesh["material"]]["opacity"] < 1.0
        assert materials[mesh["material"]]["transparent"]
    assert not any(c["type"] == "set_property" and c["property"] == "color" for c in cmds)
    if robot == "ur5":
        assert len(html.encode()) < UR5_MAX_PAGE_BYTES


def rgb_of(m: dict) -> np.ndarray:
    return np.array([(m["color"] >> k & 0xFF) / 255 for k in (16, 8, 0)])


def fd_surface_displacements(clm, q, dq, g_index, local) -> np.ndarray:
    """|displacement| [m] of points ``local`` (n, 3) of a geometry object, central
    differences of its placement along dq (an independent route from the Jacobians)."""

    def world(eps):
        data, gdata = clm.model.createData(), clm.visual_model.createData()
        pin.forwardKinematics(clm.model, data, pin.integrate(clm.model, q, eps * dq))
        pin.updateGeometryPlacements(clm.model, data, clm.visual_model, gdata)
        M = gdata.oMg[g_index]
        return local @ M.rotation.T + M.translation

    return np.linalg.norm((world(FD_STEP) - world(-FD_STEP)) / (2.0 * FD_STEP), axis=1)


def test_model_colours_on_request(fourbar, tmp_path):
    clm, q = fourbar
    scene = deflection_scene(clm, q, "P", FOURBAR_WRENCH)
    html, cmds = export(clm, scene, tmp_path, colour_by_displacement=False)
    obj = robots_object(cmds)
    materials = {m["uuid"]: m for m in obj["materials"]}
    groups = robot_groups(obj, "deflected")
    for g in clm.visual_model.geometryObjects:
        (mesh,) = groups[node_name("deflected", g.name)]["children"]
        np.testing.assert_allclose(
            rgb_of(materials[mesh["material"]]), g.meshColor[:3], atol=0.5 / 255
        )
    assert "model colours" in html and "colour bar" not in html


def test_deflected_colours_follow_the_real_surface_displacement(ur5, fourbar, tmp_path):
    """UR5: vertex colours of the meshes; four-bar: one colour a primitive (its origin)."""
    for (clm, q), frame, w in ((ur5, "tool0", UR5_WRENCH), (fourbar, "P", FOURBAR_WRENCH)):
        scene = deflection_scene(clm, q, frame, w)
        html, cmds = export(clm, scene, tmp_path, name=f"{clm.name}.html")
        obj = robots_object(cmds)
        buffers = {geo["uuid"]: geo for geo in obj["geometries"]}
        materials = {m["uuid"]: m for m in obj["materials"]}
        groups = robot_groups(obj, "deflected")
        seen, expected = [], []
        for i, g in enumerate(clm.visual_model.geometryObjects):
            (mesh,) = groups[node_name("deflected", g.name)]["children"]
            attributes = buffers[mesh["geometry"]].get("data", {}).get("attributes", {})
            if "color" in attributes:  # a mesh: its vertices
                local = np.frombuffer(attributes["position"]["array"].data, np.float32)
                colours = np.frombuffer(attributes["color"]["array"].data, np.float32)
                assert materials[mesh["material"]]["vertexColors"] == 2  # three.js enum
                seen.append(colours.reshape(-1, 3))
                expected.append(fd_surface_displacements(clm, q, scene.dq, i, local.reshape(-1, 3)))
            else:  # a primitive: its origin
                seen.append(rgb_of(materials[mesh["material"]])[None])
                expected.append(fd_surface_displacements(clm, q, scene.dq, i, np.zeros((1, 3))))
        top = max(float(np.max(e)) for e in expected)
        for colours, d in zip(seen, expected, strict=True):
            atol = 1e-5 if colours.shape[0] > 1 else 0.5 / 255 + 1e-6  # float32 / 8-bit colour
            np.testing.assert_allclose(colours, colormap(d / top), atol=atol)
        assert f"(0 to {1e3 * top:.4g} mm)" in html


def test_page_holds_arrows_ellipsoids_grid_and_legend(fourbar, fourbar_export):
    clm, _ = fourbar
    scene, html, cmds = fourbar_export
    objects, transforms = by_path(cmds, "set_object"), by_path(cmds, "set_transform")
    np.testing.assert_allclose(matrix(transforms["/meshcat/load"])[:3, 3], scene.point_deflected)
    f = scene.wrench[:3] / np.linalg.norm(scene.wrench[:3])
    R = matrix(transforms["/meshcat/load/force"])[:3, :3]
    np.testing.assert_allclose(R @ [0.0, 1.0, 0.0], f, atol=RTOL_EXACT)  # arrows along y
    for part in ("shaft", "head0"):
        assert objects[f"/meshcat/load/force/{part}"]["object"]["geometries"][0]["type"] == (
            "CylinderGeometry"
        )
    assert not any(p.startswith("/meshcat/load/torque") for p in objects)  # no moment applied
    for e in scene.ellipsoids:
        path = f"/meshcat/compliance/{e.kind}"
        drawn = np.array(objects[path]["object"]["object"]["matrix"]).reshape(4, 4).T
        T = matrix(transforms[path])
        M = T[:3, :3] @ drawn[:3, :3]  # unit sphere -> drawn ellipsoid
        r = np.maximum(e.drawn_radii, ELLIPSOID_MIN_FRACTION * scene.size)
        np.testing.assert_allclose(M @ M.T, e.axes @ np.diag(r**2) @ e.axes.T, atol=1e-12)
        np.testing.assert_allclose(T[:3, 3], scene.point, atol=ATOL_PLACEMENT)
    # grid: meshcat's 20 m grid hidden, ours of squares of grid_step(L)
    assert properties(cmds, "/Grid")["visible"] is False
    step = grid_step(scene.size)
    points = objects["/meshcat/grid"]["object"]["geometries"][0]["data"]["attributes"]
    xyz = np.frombuffer(points["position"]["array"].data, dtype=np.float32).reshape(-1, 3)
    np.testing.assert_allclose(np.diff(np.unique(xyz[:, 0].round(9))), step, rtol=1e-5)
    # legend: the rows in the page, numbers from the scene
    info_rows = legend_rows(legend_info(clm, scene))  # the rows above the colour key
    assert all(row in html for row in info_rows)
    mm = 1e3 * scene.max_displacement
    assert f"largest point displacement {mm:.4g} mm (real)" in html
    twist_mm = 1e3 * np.linalg.norm(scene.frame_twist[:3])
    assert f"(norm {twist_mm:.4g} mm)" in html
    assert f"\u00d7{scene.scale:.4g} (automatic; linear deflection)" in html
    assert f"grid: squares of {step:.3g} m" in html
    assert "force arrow (one head)" in html and "moment arrow" not in html


def test_each_primitive_is_drawn_with_its_own_shape(cahyman, tmp_path):
    """CaHyMan's page drew every cylinder with the fixed plate's disc (primitives keyed by
    the id of a freed Python wrapper, which the next one reused): each group's geometry
    has its own object's dimensions."""
    clm, q = cahyman
    _, cmds = export(clm, deflection_scene(clm, q, "M", [0, 0, 0, 0, 0, 5.0]), tmp_path)
    obj = robots_object(cmds)
    geometries = {g["uuid"]: g for g in obj["geometries"]}
    shapes = Counter()
    for root in ("nominal", "deflected"):
        groups = robot_groups(obj, root)
        for g in clm.visual_model.geometryObjects:
            (mesh,) = groups[node_name(root, g.name)]["children"]
            drawn, shape = geometries[mesh["geometry"]], g.geometry
            kind = type(shape).__name__
            shapes[kind] += 1
            if kind == "Cylinder":
                got = (drawn["radiusTop"], drawn["radiusBottom"], drawn["height"])
                want = (shape.radius, shape.radius, 2 * shape.halfLength)
            elif kind == "Sphere":
                got, want = (drawn["radius"],), (shape.radius,)
            else:
                got = sorted((drawn["width"], drawn["height"], drawn["depth"]))
                want = sorted(2 * np.asarray(shape.halfSide))
            np.testing.assert_allclose(got, want, rtol=RTOL_EXACT, err_msg=g.name)
    assert shapes == {"Cylinder": 2 * 17, "Sphere": 2 * 17, "Box": 2 * 6}


def test_camera_frames_robots_arrows_and_ellipsoids(cahyman, tmp_path):
    clm, q = cahyman
    scene = deflection_scene(clm, q, "M", [0.0, 0.0, 0.0, 0.0, 0.0, 5.0], rotational=True)
    html, cmds = export(clm, scene, tmp_path)
    transforms = by_path(cmds, "set_transform")
    centre = -matrix(transforms["/meshcat"])[:3, 3]
    eye = matrix(transforms["/Cameras/default/rotated/<object>"])[:3, 3]
    radius = np.linalg.norm(eye) / CAMERA_MARGIN  # the drawn content lies in this sphere
    floor = ELLIPSOID_MIN_FRACTION * scene.size
    for e in scene.ellipsoids:
        lo, hi = ellipsoid_box(e, floor)
        assert np.linalg.norm(np.maximum(np.abs(lo - centre), np.abs(hi - centre))) <= (
            radius * (1 + RTOL_EXACT)
        )
    tip = scene.point_deflected + LEVER_FRACTION * scene.size * np.array([0.0, 0.0, 1.0])
    assert np.linalg.norm(tip - centre) <= radius
    assert "shrunk \u00d7" in html and "moment arrow (two heads)" in html


def test_page_holds_the_load_ramp_animation(fourbar, fourbar_export):
    clm, _ = fourbar
    scene, html, cmds = fourbar_export
    (anim,) = [c for c in cmds if c["type"] == "set_animation"]
    assert anim["options"]["play"] is False  # the page script plays it once loaded
    clips = {a["path"]: a["clip"] for a in anim["animations"]}
    for g in clm.visual_model.geometryObjects:
        last = drawn_placements(clm, scene)[g.name]
        name = node_name("deflected", g.name)
        (position,) = [
            t for t in clips["/meshcat/robots"]["tracks"] if t["name"] == f"{name}.position"
        ]
        assert len(position["keys"]) == len(scene.ramp)
        np.testing.assert_allclose(position["keys"][-1]["value"], last[:3, 3], atol=ATOL_DRAWN)
    (grow,) = [t for t in clips["/meshcat/load"]["tracks"] if t["name"] == ".scale"]
    np.testing.assert_allclose(grow["keys"][-1]["value"], [1.0, 1.0, 1.0])
    assert '"autoplay": false' in html and '"meshes": 14' in html  # 2 x 7 geometry objects


def test_live_server_serves_the_page_with_the_legend_on_localhost(fourbar):
    clm, q = fourbar
    lines = []
    with DeflectionViewer(clm) as viewer:
        viewer.show(deflection_scene(clm, q, "P", FOURBAR_WRENCH))
        assert viewer.url.startswith("http://127.0.0.1:")
        direct = urllib.request.build_opener(urllib.request.ProxyHandler({}))  # no proxy
        with direct.open(viewer.url, timeout=10) as page:
            text = page.read().decode("utf-8")
        assert '<div id="closedloop-legend">' in text and "<title>fourbar: deflection" in text
        viewer.serve(duration=0.0, out=lines.append)
        proc = viewer._server
    assert viewer._server is None and proc.poll() is not None  # stopped with the viewer
    assert lines == [f"meshcat viewer at {viewer.url} (Ctrl-C to stop)"]


def test_live_page_slider_sends_the_amplification_to_the_viewer(fourbar):
    """The live page's slider posts ``{"type": "closedloop", "amplification": s}`` on the
    viewer's websocket (as this test does); serving hands it to ``on_amplification``."""
    clm, q = fourbar
    chosen = 12.5
    with DeflectionViewer(clm) as viewer:
        viewer.show(deflection_scene(clm, q, "P", FOURBAR_WRENCH))
        direct = urllib.request.build_opener(urllib.request.ProxyHandler({}))
        with direct.open(viewer.url, timeout=10) as page:
            assert 'id="closedloop-slider"' in page.read().decode("utf-8")
        assert 'id="closedloop-slider"' not in viewer.static_html()  # no server offline

        async def slide():
            url = viewer.url.replace("http://", "ws://").replace("/static/", "/")
            ws = await websocket_connect(url)
            await ws.write_message(json.dumps({"type": "closedloop", "amplification": chosen}))
            await asyncio.sleep(0.3)  # the server reads it
            ws.close()

        asyncio.run(slide())
        seen = []
        viewer.serve(duration=1.0, out=lambda _: None, on_amplification=seen.append)
        assert seen == [chosen]
        assert viewer.poll_control() == {}  # fetched once


# ------------------------------------------------------------------ beams drawn bent
#: A steel rod of diameter ROD_D, length ROD_L [m], along world x, clamped at link 'post'.
ROD_L, ROD_D, STEEL = 0.6, 0.02, {"E": 2.1e11, "G": 8.1e10}
#: Tip force [N] along y: tip deflection F L^3 / (3 E I) = 4.4e-7 m, tip slope 1.1e-6 rad.
ROD_FORCE = 1e-2
#: Hermite curve vs the Euler-Bernoulli deflection line at scale 1: second-order terms,
#: ~ the tip slope (1e-6) relative.
RTOL_FIRST_ORDER = 1e-5


@pytest.fixture(scope="module")
def rod(tmp_path_factory):
    """The rod as a beam on link 'post', its tip the fixed joint to link 'tip' at (L, 0, 0);
    visual cylinders (primitives: no mesh files)."""
    path = tmp_path_factory.mktemp("rod") / "rod.urdf"
    inertial = (
        '<inertial><mass value="0.5"/><inertia ixx="1e-3" iyy="1e-3" izz="1e-3" ixy="0" '
        'ixz="0" iyz="0"/></inertial>'
    )
    rod = (
        f'<visual><origin xyz="{ROD_L / 2} 0 0" rpy="0 1.5707963267948966 0"/><geometry>'
        f'<cylinder radius="{ROD_D / 2}" length="{ROD_L}"/></geometry></visual>'
    )
    box = '<visual><geometry><box size="0.05 0.05 0.05"/></geometry></visual>'
    path.write_text(
        f'<robot name="rod"><link name="post">{inertial}{rod}</link><link name="tip">'
        f'{inertial}{box}</link><joint name="tip_joint" type="fixed"><parent link="post"/>'
        f'<child link="tip"/><origin xyz="{ROD_L} 0 0"/></joint></robot>'
    )
    beam = {"end": "tip_joint", **STEEL, "section": {"shape": "circle", "d": ROD_D}}
    clm = load_model(path, beams={"post": beam})
    return clm, pin.neutral(clm.model)


def test_bent_rod_is_the_euler_bernoulli_deflection_line(rod):
    clm, q = rod
    scene = deflection_scene(clm, q, "tip", [0.0, ROD_FORCE, 0.0, 0.0, 0.0, 0.0], scale=1.0)
    (curve,) = scene.beams
    assert curve.name == "post_beam" and curve.points.shape == (13, 3)
    model, data = clm.model, clm.model.createData()
    pin.framesForwardKinematics(model, data, scene.q_deflected)
    tip = data.oMf[model.getFrameId("tip")].translation  # the end's frame, forward kinematics
    np.testing.assert_allclose(curve.points[-1], tip, rtol=0, atol=ATOL_PLACEMENT)
    np.testing.assert_allclose(curve.points[0], [0.0, 0.0, 0.0], rtol=0, atol=ATOL_PLACEMENT)
    EI = STEEL["E"] * np.pi * ROD_D**4 / 64
    x = np.linspace(0.0, ROD_L, 13)  # u evenly spaced: x = u L to first order
    v = ROD_FORCE * x**2 * (3 * ROD_L - x) / (6 * EI)  # clamped beam, tip force
    np.testing.assert_allclose(curve.points[:, 1], v, rtol=RTOL_FIRST_ORDER, atol=0)
    assert curve.points[6, 1] == pytest.approx(
        5 * ROD_FORCE * ROD_L**3 / (48 * EI), rel=RTOL_FIRST_ORDER
    )


@pytest.fixture(scope="module")
def ur5_flex(ur5_urdf):
    tube = {"E": 7.0e10, "G": 2.6e10, "section": {"shape": "tube", "d": 0.06, "t": 0.004}}
    beams = {link: {**tube, "end": end} for link, end in UR5_BEAM_ENDS.items()}
    rigid = load_model(ur5_urdf, joint_stiffness=1e4, geometry=False)
    return rigid, rigid.with_beams(beams)


def test_unloaded_beams_are_straight_from_start_to_tip(ur5_flex):
    """At rest each curve is the segment from the link's origin to its end joint's origin,
    evenly divided, as the rigid UR5's forward kinematics places them."""
    rigid, flex = ur5_flex
    scene = deflection_scene(flex, map_configuration(rigid.model, flex.model, UR5_Q), "ee_link",
                             np.zeros(6))  # fmt: skip
    data = rigid.model.createData()
    pin.framesForwardKinematics(rigid.model, data, UR5_Q)
    assert [c.name for c in scene.beams] == [f"{link}_beam" for link in UR5_BEAM_ENDS]
    for curve, (link, end) in zip(scene.beams, UR5_BEAM_ENDS.items(), strict=True):
        a = data.oMf[rigid.model.getFrameId(link)].translation
        b = data.oMf[rigid.model.getFrameId(end)].translation
        u = np.linspace(0.0, 1.0, len(curve.points))[:, None]
        np.testing.assert_allclose(curve.points, a + u * (b - a), rtol=0, atol=ATOL_PLACEMENT)


def test_loaded_beam_tips_follow_their_virtual_joints(ur5_flex):
    rigid, flex = ur5_flex
    q = map_configuration(rigid.model, flex.model, UR5_Q)
    scene = deflection_scene(flex, q, "ee_link", UR5_WRENCH)
    poses = rigid_link_poses(flex.model, q, scene.dq, scene.scale)  # the drawn links

    def origin(name):
        f = flex.model.frames[flex.model.getFrameId(name)]
        return (poses[f.parentJoint] @ f.placement.homogeneous)[:3, 3]

    for curve, link in zip(scene.beams, UR5_BEAM_ENDS, strict=True):
        # the tip rides on the beam's virtual joint (the end joint's body shares its origin
        # to first order: tests of the joints staying together)
        start, tip = origin(link), origin(f"{link}_beam")
        np.testing.assert_allclose(curve.points[0], start, rtol=0, atol=ATOL_DRAWN)
        np.testing.assert_allclose(curve.points[-1], tip, rtol=0, atol=ATOL_DRAWN)
        chord = tip - start
        off = (
            curve.points
            - start
            - np.outer(curve.points @ chord - start @ chord, chord) / (chord @ chord)
        )
        assert np.max(np.linalg.norm(off, axis=1)) > 1e-6 * np.linalg.norm(chord)  # bent


def test_page_draws_the_beam_as_segments_of_its_curve(rod, tmp_path):
    clm, q = rod
    scene = deflection_scene(clm, q, "tip", [0.0, 50.0, -30.0, 0.0, 0.0, 0.0])
    _, cmds = export(clm, scene, tmp_path)
    objects, transforms = by_path(cmds, "set_object"), by_path(cmds, "set_transform")
    (curve,) = scene.beams
    ends = np.array([[0.0, -0.5, 0.0, 1.0], [0.0, 0.5, 0.0, 1.0]])  # the unit cylinder's
    for k in range(len(curve.points) - 1):
        path = f"/meshcat/beams/post_beam_{k}"
        assert objects[path]["object"]["geometries"][0]["type"] == "CylinderGeometry"
        drawn = (matrix(transforms[path]) @ ends.T).T[:, :3]
        np.testing.assert_allclose(drawn, curve.points[k : k + 2], rtol=0, atol=ATOL_PLACEMENT)
    (anim,) = [c for c in cmds if c["type"] == "set_animation"]
    clip = {a["path"]: a["clip"] for a in anim["animations"]}["/meshcat/beams"]
    tracks = {t["name"]: t["keys"] for t in clip["tracks"]}
    last = tracks["post_beam_11.position"][-1]["value"]
    np.testing.assert_allclose(last, 0.5 * (curve.points[-2] + curve.points[-1]), atol=1e-12)
    assert len(tracks["post_beam_0.scale"]) == len(scene.ramp)


#: A rod along no axis of its link frame (nor of the world): direction (1, 2, 2)/3, tip
#: frame turned by rpy (0.3, -0.5, 1.1).
ROD_AXIS = np.array([1.0, 2.0, 2.0]) / 3.0


@pytest.fixture(scope="module")
def oblique_rod(tmp_path_factory):
    path = tmp_path_factory.mktemp("oblique") / "rod.urdf"
    inertial = (
        '<inertial><mass value="0.5"/><inertia ixx="1e-3" iyy="1e-3" izz="1e-3" ixy="0" '
        'ixz="0" iyz="0"/></inertial>'
    )
    xyz = " ".join(map(str, ROD_L * ROD_AXIS))
    path.write_text(
        f'<robot name="rod"><link name="post">{inertial}</link><link name="tip">{inertial}'
        '</link><joint name="tip_joint" type="fixed"><parent link="post"/><child link="tip"/>'
        f'<origin xyz="{xyz}" rpy="0.3 -0.5 1.1"/></joint></robot>'
    )
    beam = {"end": "tip_joint", **STEEL, "section": {"shape": "circle", "d": ROD_D}}
    clm = load_model(path, beams={"post": beam})
    n = np.array([0.0, 1.0, -1.0]) / np.sqrt(2.0)  # across the rod
    assert abs(n @ ROD_AXIS) < 1e-15
    return clm, pin.neutral(clm.model), n


def test_oblique_rod_is_the_euler_bernoulli_deflection_line(oblique_rod):
    clm, q, n = oblique_rod
    scene = deflection_scene(clm, q, "tip", [*(ROD_FORCE * n), 0.0, 0.0, 0.0], scale=1.0)
    (curve,) = scene.beams
    EI = STEEL["E"] * np.pi * ROD_D**4 / 64
    x = np.linspace(0.0, ROD_L, 13)
    v = ROD_FORCE * x**2 * (3 * ROD_L - x) / (6 * EI)
    np.testing.assert_allclose(curve.points @ n, v, rtol=RTOL_FIRST_ORDER, atol=1e-20)
    np.testing.assert_allclose(curve.points @ ROD_AXIS, x, rtol=0, atol=ATOL_PLACEMENT)


#: The automatic amplification makes the picture of a load independent of its magnitude
#: (linear deflection): the same to rounding of s and dq (1e-12).
RTOL_SAME_PICTURE = 1e-12


def test_picture_of_a_load_is_the_same_at_any_magnitude(oblique_rod):
    clm, q, n = oblique_rod
    scenes = [deflection_scene(clm, q, "tip", [*(f * n), 0.0, 0.0, 0.0])
              for f in (1e-300, 1e-200, 1.0, 1e200, 1e300)]  # fmt: skip
    for scene in scenes:
        np.testing.assert_allclose(scene.beams[0].points, scenes[2].beams[0].points,
                                   rtol=RTOL_SAME_PICTURE, atol=1e-15)  # fmt: skip
        np.testing.assert_allclose(scene.scale * scene.max_displacement,
                                   scenes[2].scale * scenes[2].max_displacement,
                                   rtol=RTOL_SAME_PICTURE)  # fmt: skip
    bend = scenes[2].beams[0].points @ n
    assert bend[-1] > 1e-2 * ROD_L  # drawn visibly bent
    zero = deflection_scene(clm, q, "tip", np.zeros(6))
    assert zero.scale == 1.0 and zero.max_displacement == 0.0
    x = np.linspace(0.0, ROD_L, 13)[:, None]
    np.testing.assert_allclose(zero.beams[0].points, x * ROD_AXIS, rtol=0, atol=ATOL_PLACEMENT)


@pytest.mark.parametrize("magnitude", [1e-300, 1.0, 1e300])
def test_load_arrows_point_along_loads_of_any_magnitude(magnitude):
    from closedloop.viewer.ellipsoids import unit_vector, vector_norm

    v = magnitude * np.array([3.0, 0.0, -4.0])
    np.testing.assert_allclose(unit_vector(v), [0.6, 0.0, -0.8], rtol=1e-15)
    assert vector_norm(v) == pytest.approx(5.0 * magnitude, rel=1e-15)
