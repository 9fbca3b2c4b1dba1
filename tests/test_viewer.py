"""Deflection viewer: scene maths against independent routes, the exported page's commands.

The static page embeds every meshcat command as a base64 msgpack blob; the tests decode
them and check what the scene holds (objects, colours, placements, animation), not only
that a file was written.
"""

from __future__ import annotations

import base64
import json
import re
import urllib.request

import numpy as np
import pinocchio as pin
import pytest
import umsgpack
from helpers import UR5_Q

from cahyman_pin.cli import main as cahyman_main
from cahyman_pin.model import cahyman_model
from closedloop.assembly import ASSEMBLY_TOL, assemble
from closedloop.cli import main as closedloop_main
from closedloop.compliance import compliance
from closedloop.exceptions import InvalidInputError
from closedloop.io import load_model
from closedloop.kinematics import closure_residual
from closedloop.statics import solve_equilibrium
from closedloop.viewer import ELLIPSOID_MIN_FRACTION, GHOST_RGBA, DeflectionViewer
from closedloop.viewer_scene import AUTO_FRACTION, LEVER_FRACTION, deflection_scene

#: Central differences of positions (metre-sized links, unit-sized dq) with step FD_STEP:
#: truncation ~ FD_STEP^2, rounding ~ 1e-16 / FD_STEP; both far below FD_RTOL.
FD_STEP, FD_RTOL = 1e-6, 1e-7
#: Quantities computed along two exact routes (rounding only).
RTOL_EXACT = 1e-9
#: Placements sent to meshcat go through msgpack as float64: exact to rounding.
ATOL_PLACEMENT = 1e-12
#: Closure gap [m] that the first-order amplified four-bar pose at scale 150 exceeds: the
#: gap is of second order, ~ (s |dq|)^2 / L, some centimetres here (0.095 m measured).
OPEN_GAP = 1e-3
FOURBAR_WRENCH = [3.0, 0.0, -20.0, 0.0, 0.0, 0.0]  # [N, N m] at P
UR5_WRENCH = [10.0, -5.0, -40.0, 0.0, 0.0, 2.0]
BLOB = re.compile(r"data:application/octet-binary;base64,([A-Za-z0-9+/=]+)")
EXTERNAL = re.compile(r"<(?:script|link|img|iframe)\b[^>]*\b(?:src|href)\s*=\s*[\"']?https?:", re.I)


def commands(html: str) -> list[dict]:
    """The meshcat commands embedded in a static page, in order."""
    return [umsgpack.unpackb(base64.b64decode(b)) for b in BLOB.findall(html)]


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
def test_auto_scale_makes_the_largest_displacement_a_tenth_of_the_size(robot, request):
    clm, q = request.getfixturevalue(robot)
    frame, w = ("P", FOURBAR_WRENCH) if robot == "fourbar" else ("tool0", UR5_WRENCH)
    scene = deflection_scene(clm, q, frame, w)
    dq = compliance(clm, q, frame).G @ np.array(w)
    np.testing.assert_allclose(scene.dq, dq, rtol=RTOL_EXACT, atol=0.0)
    d_max = np.max(np.linalg.norm(fd_displacements(clm, q, frame, dq), axis=1))
    size = bbox_diagonal(clm, q)
    np.testing.assert_allclose(scene.size, size, rtol=RTOL_EXACT)
    np.testing.assert_allclose(scene.max_displacement, d_max, rtol=FD_RTOL)
    np.testing.assert_allclose(scene.scale, AUTO_FRACTION * size / d_max, rtol=FD_RTOL)
    assert scene.auto_scaled
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


def test_bad_inputs_raise(fourbar):
    clm, q = fourbar
    for kwargs in ({"scale": -1.0}, {"scale": np.inf}, {"frames": 1}):
        with pytest.raises(InvalidInputError):
            deflection_scene(clm, q, "P", FOURBAR_WRENCH, **kwargs)
    with pytest.raises(InvalidInputError, match="wrench"):
        deflection_scene(clm, q, "P", [0.0, np.nan, 0.0, 0.0, 0.0, 0.0])


def test_model_without_geometry_is_refused(fourbar_urdf, fourbar_yaml):
    clm = load_model(fourbar_urdf, fourbar_yaml, geometry=False)
    with pytest.raises(InvalidInputError, match="visual geometry"):
        DeflectionViewer(clm)


# ------------------------------------------------------------------ exported page
def test_static_page_is_self_contained(fourbar_export):
    _, html, cmds = fourbar_export
    assert "<script" in html and EXTERNAL.search(html) is None
    assert len(cmds) > 50


def test_page_holds_ghost_and_deflected_poses(fourbar, fourbar_export):
    clm, q = fourbar
    scene, _, cmds = fourbar_export
    objects, transforms = by_path(cmds, "set_object"), by_path(cmds, "set_transform")
    for root, q_root in (("nominal", q), ("deflected", scene.q_deflected)):
        for name, placement in geometry_placements(clm, q_root).items():
            path = f"/meshcat/{root}/visuals/{name}"
            assert path in objects
            np.testing.assert_allclose(matrix(transforms[path]), placement, atol=ATOL_PLACEMENT)
            colour = properties(cmds, path).get("color")
            if root == "nominal":
                np.testing.assert_allclose(colour, GHOST_RGBA)
            else:
                assert colour is None  # the model's own colours
    assert properties(cmds, "/meshcat/deflected")["amplification"] == scene.scale


def test_page_holds_arrows_ellipsoids_and_label(fourbar_export):
    scene, _, cmds = fourbar_export
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
        floor = ELLIPSOID_MIN_FRACTION * scene.size
        r = np.maximum(e.radii, floor)
        np.testing.assert_allclose(M @ M.T, e.axes @ np.diag(r**2) @ e.axes.T, atol=1e-12)
        np.testing.assert_allclose(T[:3, 3], scene.point, atol=ATOL_PLACEMENT)
    texts = [
        o["object"]["textures"][0]["text"]
        for p, o in objects.items()
        if p.startswith("/meshcat/label/")
    ]
    assert f"deflection x{scene.scale:.4g} (auto)" in texts


def test_page_holds_the_load_ramp_animation(fourbar, fourbar_export):
    clm, _ = fourbar
    scene, _, cmds = fourbar_export
    (anim,) = [c for c in cmds if c["type"] == "set_animation"]
    clips = {a["path"]: a["clip"] for a in anim["animations"]}
    name = clm.visual_model.geometryObjects[0].name
    last = geometry_placements(clm, scene.ramp_q[-1])[name]
    (position,) = [
        t for t in clips[f"/meshcat/deflected/visuals/{name}"]["tracks"] if t["name"] == ".position"
    ]
    assert len(position["keys"]) == len(scene.ramp)
    np.testing.assert_allclose(position["keys"][-1]["value"], last[:3, 3], atol=ATOL_PLACEMENT)
    (grow,) = [t for t in clips["/meshcat/load"]["tracks"] if t["name"] == ".scale"]
    np.testing.assert_allclose(grow["keys"][-1]["value"], [1.0, 1.0, 1.0])


def test_ur5_page_recolours_its_mesh_ghost(ur5, tmp_path):
    clm, q = ur5
    scene = deflection_scene(clm, q, "tool0", UR5_WRENCH, rotational=True)
    _, cmds = export(clm, scene, tmp_path)
    objects = by_path(cmds, "set_object")
    for g in clm.visual_model.geometryObjects:
        assert objects[f"/meshcat/deflected/visuals/{g.name}"]["object"]["object"]["type"] == (
            "_meshfile_object"
        )
        np.testing.assert_allclose(
            properties(cmds, f"/meshcat/nominal/visuals/{g.name}")["color"], GHOST_RGBA
        )
    assert {"/meshcat/compliance/translation", "/meshcat/compliance/rotation"} <= set(objects)
    assert {"/meshcat/load/torque/head0", "/meshcat/load/torque/head1"} <= set(objects)


def test_live_server_serves_the_viewer_on_localhost(fourbar):
    clm, q = fourbar
    lines = []
    with DeflectionViewer(clm) as viewer:
        viewer.show(deflection_scene(clm, q, "P", FOURBAR_WRENCH))
        assert viewer.url.startswith("http://127.0.0.1:")
        direct = urllib.request.build_opener(urllib.request.ProxyHandler({}))  # no proxy
        with direct.open(viewer.url, timeout=10) as page:
            assert b"<script" in page.read()
        viewer.serve(duration=0.0, out=lines.append)
        proc = viewer.viewer.window.server_proc
    assert proc is None or proc.poll() is not None  # closed with the viewer
    assert lines == [f"meshcat viewer at {viewer.url} (Ctrl-C to stop)"]


# ------------------------------------------------------------------ command lines
def run(main, capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_closedloop_view_writes_the_page(fourbar_urdf, fourbar_yaml, tmp_path, capsys):
    html = tmp_path / "fourbar.html"
    code, out, err = run(
        closedloop_main,
        capsys,
        "view",
        fourbar_urdf,
        "--closures",
        fourbar_yaml,
        "--frame",
        "P",
        "--actuated",
        0.3,
        "--force",
        0,
        0,
        -20,
        "--scale",
        50,
        "--html",
        html,
    )
    assert (code, err) == (0, "")
    assert "amplified x50 (given" in out and f"wrote {html}" in out
    cmds = commands(html.read_text(encoding="utf-8"))
    assert properties(cmds, "/meshcat/deflected")["amplification"] == 50.0


def test_cahyman_view_writes_the_page(tmp_path, capsys):
    html = tmp_path / "cahyman.html"
    code, out, err = run(cahyman_main, capsys, "view", "--force", 10, 0, -20, "--html", html)
    assert (code, err) == (0, "")
    assert out.endswith(f"wrote {html}\n")
    objects = by_path(commands(html.read_text(encoding="utf-8")), "set_object")
    names = [g.name for g in cahyman_model().clm.visual_model.geometryObjects]
    for root in ("nominal", "deflected"):
        assert all(f"/meshcat/{root}/visuals/{n}" in objects for n in names)
    assert "/meshcat/compliance/translation" in objects


def test_cahyman_view_json_goes_to_stdout(tmp_path, capsys):
    html = tmp_path / "cahyman.html"
    code, out, err = run(cahyman_main, capsys, "view", "--scale", 30, "--json", "--html", html)
    assert code == 0 and f"wrote {html}" in err
    doc = json.loads(out)
    assert (doc["scale"], doc["auto_scaled"], doc["html"]) == (30.0, False, str(html))


@pytest.mark.parametrize(
    "argv",
    [
        ["--frame", "nowhere"],
        ["--frame", "P", "--scale", "-2"],
        ["--frame", "P", "--force", "nan", "0", "0"],
        ["--frame", "P", "--html", "/no/such/folder/page.html"],
    ],
)
def test_closedloop_view_bad_input_exits_2_with_one_line(
    fourbar_urdf, fourbar_yaml, capsys, tmp_path, argv
):
    argv = [a.replace("/no/such", str(tmp_path / "missing")) for a in argv]
    if "--html" not in argv:
        argv += ["--html", str(tmp_path / "page.html")]
    code, out, err = run(
        closedloop_main, capsys, "view", fourbar_urdf, "--closures", fourbar_yaml, *argv
    )
    assert code == 2 and out == ""
    assert len(err.splitlines()) == 1 and err.startswith("closedloop: error: ")
    assert not (tmp_path / "page.html").exists()


@pytest.mark.parametrize("argv", [["--backend", "consistent"], ["--scale", "inf"], ["--s4", "999"]])
def test_cahyman_view_bad_input_exits_2_with_one_line(capsys, tmp_path, argv):
    code, out, err = run(cahyman_main, capsys, "view", *argv, "--html", tmp_path / "x.html")
    assert code == 2 and out == ""
    assert len(err.splitlines()) == 1 and err.startswith("cahyman: error: ")
