"""Deflection viewer at its edges: one-dof robots, geometry that does not move, an MJCF
floor plane, models of millimetres and of hundreds of metres, a nonlinear view's frame
displacement, and a meshcat server that cannot start.

Every page is checked through the meshcat commands it embeds (decoded as in
``test_viewer.py``): every number in them must be finite.
"""

from __future__ import annotations

import math
import re
import sys

import numpy as np
import pytest
import umsgpack
from test_viewer import export, matrix, properties

from closedloop.cli.app import main as closedloop_main
from closedloop.exceptions import ViewerError
from closedloop.io.loader import load_model
from closedloop.kinematics.assembly import assemble
from closedloop.viewer import server as viewer_server
from closedloop.viewer.mesh import DEFLECTED, ROBOTS
from closedloop.viewer.motion import point_displacements
from closedloop.viewer.page import legend_rows
from closedloop.viewer.scene import deflection_scene
from closedloop.viewer.viewer import CAMERA_MARGIN, DeflectionViewer, legend_info

CAMERA = "/Cameras/default/rotated/<object>"  # meshcat's camera (three.js, y up)
#: float32 / float64 array extension types of meshcat's msgpack (meshcat.geometry).
EXT_FLOAT = {0x17: np.float32, 0x18: np.float64}
INERTIAL = (
    '<inertial><mass value="0.1"/>'
    '<inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>'
)


def arm_urdf(joints: int, arm_visual: bool) -> str:
    """A base plate and ``joints`` revolute links in a row (0.2 m each, about y), frame
    ``tip`` at the end; the links carry a box each (centred on the link) when
    ``arm_visual``."""
    box = '<visual><origin xyz="0.1 0 0"/><geometry><box size="0.2 0.02 0.02"/></geometry></visual>'
    links, parent = [], "base"
    for k in range(joints):
        links.append(
            f'<joint name="j{k}" type="revolute"><parent link="{parent}"/>'
            f'<child link="l{k}"/><origin xyz="{0.2 if k else 0.0} 0 0.05"/>'
            '<axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>'
            f'<link name="l{k}">{INERTIAL}{box if arm_visual else ""}</link>'
        )
        parent = f"l{k}"
    return (
        '<?xml version="1.0"?><robot name="arm"><link name="base"><visual><geometry>'
        '<box size="0.3 0.3 0.02"/></geometry></visual></link>' + "".join(links) + ""
        f'<joint name="tip_joint" type="fixed"><parent link="{parent}"/><child link="tip"/>'
        '<origin xyz="0.2 0 0"/></joint><link name="tip"/></robot>'
    )


def non_finite(cmds: list[dict]) -> list[str]:
    """Paths of the non-finite numbers (plain or in packed float arrays) of commands."""
    bad = []

    def walk(x, path):
        if isinstance(x, float) and not math.isfinite(x):
            bad.append(path)
        elif isinstance(x, dict):
            for k, v in x.items():
                walk(v, f"{path}.{k}")
        elif isinstance(x, (list, tuple)):
            for i, v in enumerate(x):
                walk(v, f"{path}[{i}]")
        elif isinstance(x, umsgpack.Ext) and x.type in EXT_FLOAT:
            if not np.all(np.isfinite(np.frombuffer(x.data, dtype=EXT_FLOAT[x.type]))):
                bad.append(path)

    for c in cmds:
        walk(c, f"{c['type']} {c['path']}")
    return bad


def robot_materials(cmds: list[dict]) -> list[dict]:
    (robots,) = [c for c in cmds if c["type"] == "set_object" and c["path"] == f"/meshcat/{ROBOTS}"]
    return robots["object"]["materials"]


def scaled_fourbar(fourbar_urdf, factor: float, folder):
    """The four-bar with every length times ``factor`` (springs as they are)."""
    text = fourbar_urdf.read_text(encoding="utf-8")

    def scale(m):
        return f'{m[1]}="{" ".join(repr(float(x) * factor) for x in m[2].split())}"'

    path = folder / f"fourbar_{factor:g}.urdf"
    path.write_text(re.sub(r'(?<!<axis )\b(xyz|size|radius|length)="([^"]*)"', scale, text))
    return path


# ------------------------------------------------------------------ models
def test_one_dof_robot_is_drawn(tmp_path):
    """Pinocchio gives a one-dof model's joint Jacobians as (6,) vectors: the point and
    surface displacements (a matrix product with dq) failed with a ValueError."""
    path = tmp_path / "arm1.urdf"
    path.write_text(arm_urdf(1, arm_visual=True))
    clm = load_model(path, joint_stiffness=10.0, geometry=True)
    q = np.zeros(1)
    w = [0.0, 0.0, -1.0, 0.0, 0.0, 0.0]
    d = point_displacements(clm, q, "tip", [0.1])
    # the tip 0.2 m from the joint, the joint 0.05 m above its base: 0.02 m down, exactly
    np.testing.assert_allclose(d, [[0.0, 0.0, 0.0], [0.0, 0.0, -0.02]], atol=1e-15)
    scene = deflection_scene(clm, q, "tip", w)
    _, cmds = export(clm, scene, tmp_path)
    assert non_finite(cmds) == []
    assert len(robot_materials(cmds)) == 3  # ghost; base and arm in their colour-map colours


def test_geometry_that_does_not_move_keeps_the_model_colours(tmp_path):
    """Geometry on the base only: the surface displacement is 0 everywhere while joints
    move; colouring by it divided 0 by 0 (NaN colours, a ValueError)."""
    path = tmp_path / "arm2.urdf"
    path.write_text(arm_urdf(2, arm_visual=False))
    clm = load_model(path, joint_stiffness=10.0, geometry=True)
    scene = deflection_scene(clm, np.zeros(2), "tip", [0.0, 0.0, -1.0, 0.0, 0.0, 0.0])
    assert scene.max_displacement > 0.0
    html, cmds = export(clm, scene, tmp_path)
    assert non_finite(cmds) == []
    assert "model colours" in html and "|displacement| of the deflected surface" not in html


def test_floor_plane_is_not_drawn(fourbar_mjcf, tmp_path):
    """An MJCF floor (a coal Halfspace, bounds +-1.8e308) made the drawn box, the camera
    and the grid NaN; it is left out (the grid is the floor)."""
    text = fourbar_mjcf.read_text(encoding="utf-8").replace(
        "<worldbody>",
        '<worldbody><geom name="floor" type="plane" size="1 1 0.1" rgba="0.8 0.8 0.8 1"/>',
        1,
    )
    path = tmp_path / "fourbar_floor.xml"
    path.write_text(text)
    clm = load_model(path, geometry=True)
    assert "floor" in [g.name for g in clm.visual_model.geometryObjects]
    scene = deflection_scene(clm, assemble(clm, [0.5]).q, "P", [0, 0, -5, 0, 0, 0])
    _, cmds = export(clm, scene, tmp_path)
    assert non_finite(cmds) == []
    (robots,) = [c for c in cmds if c["type"] == "set_object" and c["path"] == f"/meshcat/{ROBOTS}"]
    deflected = next(g for g in robots["object"]["object"]["children"] if g["name"] == DEFLECTED)
    names = [g["name"] for g in deflected["children"]]
    assert len(names) == clm.visual_model.ngeoms - 1 and not any("floor" in n for n in names)


@pytest.mark.parametrize("factor", [0.01, 1000.0])
def test_camera_clipping_follows_the_size_of_the_model(fourbar_urdf, fourbar_yaml, tmp_path,
                                                       factor):  # fmt: skip
    """meshcat's camera clips at 0.01 m and 100 m: a four-bar of 3.7 mm, seen from 8 mm,
    was not drawn at all, one of 367 m beyond 100 m neither."""
    clm = load_model(scaled_fourbar(fourbar_urdf, factor, tmp_path), fourbar_yaml, geometry=True)
    scene = deflection_scene(clm, assemble(clm, [0.3]).q, "P", [0, 0, -20, 0, 0, 0])
    _, cmds = export(clm, scene, tmp_path)
    camera = [c for c in cmds if c["type"] == "set_transform" and c["path"] == CAMERA][-1]
    distance = float(np.linalg.norm(matrix(camera)[:3, 3]))
    radius = distance / CAMERA_MARGIN  # the sphere about everything drawn
    assert radius == pytest.approx(0.5 * 0.367 * factor, rel=0.5)  # it is the model's size
    clip = {"near": 0.01, "far": 100.0, **properties(cmds, CAMERA)}  # meshcat's defaults
    assert clip["near"] < distance - radius and clip["far"] > distance + radius


def test_nonlinear_legend_gives_the_finite_displacement_of_the_frame(fourbar_urdf, fourbar_yaml):
    """The legend gave J dq of the finite deflection, 7 mm down where P goes 52 mm down
    under 1 kN; it gives the equilibrium's displacement."""
    clm = load_model(fourbar_urdf, fourbar_yaml, geometry=True)
    scene = deflection_scene(
        clm, assemble(clm, [0.3]).q, "P", [0, 0, -1000.0, 0, 0, 0], nonlinear=True, frames=2
    )
    np.testing.assert_array_equal(scene.frame_twist, scene.equilibrium.displacement)
    assert scene.frame_twist[2] < -0.04  # far from the first-order -0.007 m
    row = legend_rows(legend_info(clm, scene))[-1]
    assert row.startswith("P moves (57.96, 0, -51.76) mm") and row.endswith("nonlinear equilibrium")


# ------------------------------------------------------------------ the server
@pytest.fixture
def broken_python(tmp_path, monkeypatch):
    """``sys.executable`` replaced by a script (the server runs as ``sys.executable``)."""

    def use(body: str):
        script = tmp_path / "python"
        script.write_text(f"#!/bin/sh\n{body}\n")
        script.chmod(0o755)
        monkeypatch.setattr(sys, "executable", str(script))

    return use


@pytest.mark.skipif(sys.platform == "win32", reason="a shell script as the interpreter")
def test_a_server_that_exits_is_a_one_line_error(broken_python, fourbar_urdf, fourbar_yaml,
                                                 tmp_path, capsys):  # fmt: skip
    """A RuntimeError (a traceback at the command line) without the server's message."""
    broken_python("echo \"ModuleNotFoundError: No module named 'meshcat'\" >&2; exit 1")
    clm = load_model(fourbar_urdf, fourbar_yaml, geometry=True)
    with pytest.raises(ViewerError, match=r"exited with code 1 .*No module named 'meshcat'"):
        DeflectionViewer(clm)
    html = tmp_path / "page.html"
    argv = ["view", str(fourbar_urdf), "--closures", str(fourbar_yaml), "--frame", "P"]
    code = closedloop_main([*argv, "--force", "0", "0", "-1", "--html", str(html)])
    out, err = capsys.readouterr()
    assert code == 3 and out == "" and not html.exists()
    assert len(err.splitlines()) == 1 and err.startswith("closedloop: error: no meshcat viewer")


def test_a_missing_interpreter_is_a_typed_error(broken_python, fourbar_urdf, fourbar_yaml,
                                                monkeypatch):  # fmt: skip
    monkeypatch.setattr(sys, "executable", "/no/such/python")
    clm = load_model(fourbar_urdf, fourbar_yaml, geometry=True)
    with pytest.raises(ViewerError, match=r"cannot run '/no/such/python'"):
        DeflectionViewer(clm)


@pytest.mark.skipif(sys.platform == "win32", reason="a shell script as the interpreter")
def test_a_server_that_never_starts_times_out(broken_python, monkeypatch):
    """START_TIMEOUT was documented but not used: a hung server hung the command."""
    broken_python("exec sleep 30")
    monkeypatch.setattr(viewer_server, "START_TIMEOUT", 0.5)
    with pytest.raises(RuntimeError, match=r"no address within 0\.5 s"):
        viewer_server.start_server()
