"""A model without visual geometry is drawn as its skeleton: a sphere at every joint, rods
between the joints' origins, moved with the deflection like any visual model.

The expected points come from Pinocchio's forward kinematics and from the drawn link
motions of :func:`helpers.rigid_link_poses` (central differences); the drawn ones are read
back from the exported page's meshcat commands.
"""

from __future__ import annotations

import re

import numpy as np
import pinocchio as pin
import pytest
from helpers import commands, json_matrix, rigid_link_poses, robot_groups, robots_object

from closedloop.cli.app import main as closedloop_main
from closedloop.io.loader import load_model
from closedloop.kinematics.assembly import assemble
from closedloop.viewer.scene import deflection_scene
from closedloop.viewer.skeleton import JOINT_FRACTION, ROD_FRACTION
from closedloop.viewer.viewer import DeflectionViewer

FOURBAR_WRENCH = [3.0, 0.0, -20.0, 0.0, 0.0, 0.0]  # [N, N m] at P
#: Placements through msgpack as float64 and products of a few 4x4 matrices: rounding.
ATOL_PLACEMENT = 1e-12
#: Drawn placements [m] against :func:`helpers.rigid_link_poses` (twists from central
#: differences, relative error ~ 1e-10, on drawn motions of at most a model size).
ATOL_DRAWN = 1e-8


@pytest.fixture(scope="module")
def bare_fourbar(fourbar_urdf, fourbar_yaml):
    """The four-bar loaded without its visual geometry, assembled at crank 0.3 rad."""
    clm = load_model(fourbar_urdf, fourbar_yaml, geometry=False)
    assert clm.visual_model is None or clm.visual_model.ngeoms == 0
    return clm, assemble(clm, [0.3]).q


@pytest.fixture(scope="module")
def page(bare_fourbar, tmp_path_factory):
    """(scene, page HTML, its meshcat commands, whether drawn as a skeleton)."""
    clm, q = bare_fourbar
    scene = deflection_scene(clm, q, "P", FOURBAR_WRENCH)
    with DeflectionViewer(clm) as viewer:
        viewer.show(scene)
        path = viewer.save_html(tmp_path_factory.mktemp("skeleton") / "skeleton.html")
    html = path.read_text(encoding="utf-8")
    return scene, html, commands(html), viewer.skeleton


def _shapes(cmds: list[dict], root: str) -> dict[str, list]:
    """Per three.js geometry type: (world matrix (4, 4), geometry) of each of the robot
    ``root``'s meshes (its group's placement times the mesh's own matrix)."""
    obj = robots_object(cmds)
    geometries = {g["uuid"]: g for g in obj["geometries"]}
    out: dict[str, list] = {}
    for group in robot_groups(obj, root).values():
        (mesh,) = group["children"]
        geometry = geometries[mesh["geometry"]]
        out.setdefault(geometry["type"], []).append((json_matrix(group) @ json_matrix(mesh),
                                                     geometry))  # fmt: skip
    return out


def _rod_ends(T: np.ndarray, geometry: dict) -> np.ndarray:
    """(2, 3) world ends of a three.js cylinder (axis y, centred) placed by T."""
    h = 0.5 * geometry["height"]
    return np.array([(T @ [0.0, s * h, 0.0, 1.0])[:3] for s in (-1.0, 1.0)])


def _reference_size(clm) -> float:
    """Diagonal [m] of the box of the joint and frame origins at the reference configuration."""
    data = clm.model.createData()
    pin.framesForwardKinematics(clm.model, data, clm.reference_configuration())
    p = np.array([*(m.translation for m in data.oMi[1:]), *(f.translation for f in data.oMf)])
    return float(np.linalg.norm(p.max(axis=0) - p.min(axis=0)))


def _segments(model: pin.Model, poses: np.ndarray, frames=("P", "closedloop1_A")) -> list:
    """(2, 3) world ends [m] of the rods the skeleton must hold with the joints placed at
    ``poses`` (njoints, 4, 4): from each joint's parent's origin to the joint's origin,
    and from a joint's origin to the origin of each of ``frames`` it carries (the coupler
    has no child joint: its loaded frame and its closure frame), those of some length."""
    ends = [
        (model.parents[j], model.jointPlacements[j].translation) for j in range(1, model.njoints)
    ]
    for name in frames:
        f = model.frames[model.getFrameId(name)]
        ends.append((f.parentJoint, f.placement.translation))
    return [np.array([poses[p][:3, 3], (poses[p] @ [*t, 1.0])[:3]]) for p, t in ends
            if np.linalg.norm(t) > 1e-9]  # fmt: skip


def _assert_drawn(segments: list, rods: list) -> None:
    """Every segment is one of the rods (its ends either way round)."""
    for seg in segments:
        assert any(
            np.allclose(ends, seg, rtol=0, atol=ATOL_DRAWN)
            or np.allclose(ends[::-1], seg, rtol=0, atol=ATOL_DRAWN)
            for ends in rods
        ), (seg, rods)


def test_a_model_without_visuals_is_drawn_as_its_skeleton(bare_fourbar, page):
    """Nominal pose: a sphere on every joint's origin, a rod from every joint's parent's
    origin to its own (the crank, the coupler, the rocker, the ground between the pivots),
    of the documented radii; the legend says so."""
    clm, q = bare_fourbar
    _, html, cmds, skeleton = page
    assert skeleton
    data = clm.model.createData()
    pin.framesForwardKinematics(clm.model, data, q)
    origins = np.array([m.translation for m in data.oMi])
    shapes = _shapes(cmds, "nominal")
    assert set(shapes) == {"SphereGeometry", "CylinderGeometry"}
    centres = np.array(sorted(T[:3, 3].tolist() for T, _ in shapes["SphereGeometry"]))
    np.testing.assert_allclose(centres, np.array(sorted(origins[1:].tolist())), atol=ATOL_PLACEMENT)
    size = _reference_size(clm)
    for T, sphere in shapes["SphereGeometry"]:
        radius = sphere["radius"] * np.cbrt(abs(np.linalg.det(T[:3, :3])))
        np.testing.assert_allclose(radius, JOINT_FRACTION * size, rtol=1e-12)
    rods = [_rod_ends(T, g) for T, g in shapes["CylinderGeometry"]]
    for _, rod in shapes["CylinderGeometry"]:
        np.testing.assert_allclose(rod["radiusTop"], ROD_FRACTION * size, rtol=1e-12)
    segments = _segments(clm.model, np.array([m.homogeneous for m in data.oMi]))
    assert len(segments) == 5  # ground, crank, rocker; the coupler to P and to its end
    _assert_drawn(segments, rods)
    frames = np.array([f.translation for f in data.oMf])
    for ends in rods:  # and every rod ends on joint or frame origins
        for end in ends:
            assert np.min(np.linalg.norm(np.vstack([origins, frames]) - end, axis=1)) < ATOL_DRAWN
    assert "no visual geometry: drawn as its skeleton" in html


def test_the_skeleton_moves_with_the_deflection(bare_fourbar, page):
    """Deflected pose: the spheres on the drawn joint origins (each link moved rigidly
    along its own amplified twist), the rods carried by their links; the last key of the
    load-ramp animation is that pose."""
    clm, q = bare_fourbar
    scene, _, cmds, _ = page
    poses = rigid_link_poses(clm.model, q, scene.dq, scene.scale)
    drawn = np.array([P[:3, 3] for P in poses])
    shapes = _shapes(cmds, "deflected")
    centres = np.array(sorted(T[:3, 3].tolist() for T, _ in shapes["SphereGeometry"]))
    np.testing.assert_allclose(centres, np.array(sorted(drawn[1:].tolist())), atol=ATOL_DRAWN)
    nominal = np.array([T[:3, 3] for T, _ in _shapes(cmds, "nominal")["SphereGeometry"]])
    moved = np.linalg.norm(np.sort(centres, axis=0) - np.sort(nominal, axis=0), axis=1)
    assert np.max(moved) > 0.01 * scene.size  # the deflection shows

    rods = [_rod_ends(T, g) for T, g in shapes["CylinderGeometry"]]
    _assert_drawn(_segments(clm.model, poses), rods)  # each carried by its link
    (anim,) = [c for c in cmds if c["type"] == "set_animation"]
    tracks = {t["name"]: t for a in anim["animations"] for t in a["clip"]["tracks"]}
    for j in range(1, clm.model.njoints):
        name = "deflected_joint_" + re.sub(r"[\[\]\.:/\s]", "_", clm.model.names[j])
        last = tracks[f"{name}.position"]["keys"][-1]["value"]
        np.testing.assert_allclose(last, drawn[j], atol=ATOL_DRAWN)


def test_a_urdf_without_visual_elements_is_viewed_from_the_command_line(
    fourbar_urdf, fourbar_yaml, tmp_path, capsys
):
    """``closedloop view`` of the four-bar's URDF with its <visual> elements removed writes
    the page of the skeleton (it refused the model)."""
    text = fourbar_urdf.read_text(encoding="utf-8")
    bare = re.sub(r"<visual>.*?</visual>", "", text, flags=re.S)
    assert "<visual" in text and "<visual" not in bare
    urdf = tmp_path / "fourbar.urdf"
    urdf.write_text(bare, encoding="utf-8")
    html = tmp_path / "fourbar.html"
    argv = ["view", urdf, "--closures", fourbar_yaml, "--frame", "P", "--actuated", "0.3",
            "--force", "0", "0", "-20", "--html", html]  # fmt: skip
    code = closedloop_main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert (code, err) == (0, ""), err
    assert f"wrote {html}" in out
    page = html.read_text(encoding="utf-8")
    assert "no visual geometry: drawn as its skeleton" in page
    shapes = _shapes(commands(page), "deflected")
    assert set(shapes) == {"SphereGeometry", "CylinderGeometry"}


#: A double pendulum in MJCF without any geom: masses in <inertial>, springs on the joints.
BARE_MJCF = """<mujoco model="bare">
  <worldbody>
    <body name="upper" pos="0 0 1">
      <joint name="j1" type="hinge" axis="0 1 0" stiffness="100"/>
      <inertial pos="0 0 -0.25" mass="1" diaginertia="0.01 0.01 0.01"/>
      <body name="lower" pos="0 0 -0.5">
        <joint name="j2" type="hinge" axis="0 1 0" stiffness="100"/>
        <inertial pos="0 0 -0.25" mass="1" diaginertia="0.01 0.01 0.01"/>
        <site name="tip" pos="0 0 -0.5"/>
      </body>
    </body>
  </worldbody>
</mujoco>
"""


def test_an_mjcf_without_geoms_is_drawn_as_its_skeleton(tmp_path):
    """The world to the first joint, the upper link, the lower link to its site: three rods
    on the joints' and the site's origins, two spheres."""
    path = tmp_path / "bare.xml"
    path.write_text(BARE_MJCF, encoding="utf-8")
    clm = load_model(path)
    q = np.array([0.3, 0.4])
    scene = deflection_scene(clm, q, "tip", [1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    with DeflectionViewer(clm) as viewer:
        viewer.show(scene)
        cmds = commands(viewer.static_html())
    assert viewer.skeleton
    data = clm.model.createData()
    pin.framesForwardKinematics(clm.model, data, q)
    shapes = _shapes(cmds, "nominal")
    centres = np.array(sorted(T[:3, 3].tolist() for T, _ in shapes["SphereGeometry"]))
    expected = sorted(m.translation.tolist() for m in data.oMi[1:])
    np.testing.assert_allclose(centres, np.array(expected), atol=ATOL_PLACEMENT)
    rods = [_rod_ends(T, g) for T, g in shapes["CylinderGeometry"]]
    segments = _segments(clm.model, np.array([m.homogeneous for m in data.oMi]), frames=("tip",))
    assert len(segments) == len(rods) == 3
    _assert_drawn(segments, rods)
