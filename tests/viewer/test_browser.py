"""The viewer in a real browser: headless Chromium renders the pages (WebGL on the CPU).

Chromium loads the exported pages from file URLs and the live page from the meshcat
server on 127.0.0.1; the tests drive it over the DevTools protocol (a websocket, with
tornado's client): they wait, in real time, until the page script reports the scene
loaded, read the scene from JavaScript (the opacity of every ghost mesh material, the
distance between the nominal and deflected meshes, the legend's text and box, the
animation's state) and take a screenshot. Pages: the four-bar (primitives), the UR5
(Collada meshes) and CaHyMan with the legend on.
Without Chromium the tests are skipped with the reason shown (pytest -ra); a Chromium
that runs but renders nothing fails them.
"""

from __future__ import annotations

import asyncio
import base64
import json
import os
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import coal
import meshcat
import numpy as np
import pinocchio as pin
import pytest
from helpers import FLAGS, UR5_Q, browser, devtools_caller, devtools_page
from PIL import Image
from test_viewer_edges import scaled_fourbar

from cahyman_pin.model import cahyman_model
from closedloop.io.loader import load_model
from closedloop.kinematics.assembly import assemble
from closedloop.viewer.mesh import DEFLECTED, GHOST, node_name
from closedloop.viewer.page import LOOP_PING_PONG, SLIDER_RANGE
from closedloop.viewer.scene import deflection_scene
from closedloop.viewer.viewer import DeflectionViewer

BROWSER_TIMEOUT = 60.0  # [s] per page
VIEWPORT = (800, 600)  # [CSS px]
#: Browsers run at the same time (each renders on the CPU).
WORKERS = max(1, min(4, os.cpu_count() or 1))
#: Top rows hidden by meshcat's "Open Controls" bar (an HTML element, not WebGL).
CONTROLS_ROWS = 30
#: A rendered scene: grey-level standard deviation [0..255] well above a flat page.
MIN_STD = 10.0
#: Drawn content (mean deviation from each row's median colour; the background gradient
#: is constant along rows) must exceed that of an empty meshcat scene by this much [0..255].
MIN_EXTRA_CONTENT = 1.0
#: A pixel "changes" when a channel differs by more than CHANGE_LEVEL [0..255]; the
#: deflected scene must change at least MIN_CHANGED of the pixels (outside the legend).
CHANGE_LEVEL, MIN_CHANGED = 10, 0.002
#: The same scene from the file and from the live server: mean difference [0..255].
MAX_SAME_SCENE_DIFF = 1.0
#: Distances read back from three.js (float32 buffers and matrices) against Pinocchio's.
ATOL_BROWSER = 1e-5
FOURBAR_WRENCH = [3.0, 0.0, -20.0, 0.0, 0.0, 0.0]  # [N, N m] at P
UR5_WRENCH = [10.0, -5.0, -40.0, 0.0, 0.0, 2.0]  # at tool0
CAHYMAN_WRENCH = [0.0, 0.0, 0.0, 0.0, 0.0, 5.0]  # at M: the torque-only case
#: [ms] the probe waits after "ready" (frames drawn; a playing ramp moves), and at most.
PROBE_DELAY_MS, PROBE_TIMEOUT_MS = 500, 30000
#: [ms] given to meshcat's empty page (no page script to say it is ready).
EMPTY_WAIT_MS = 1000
#: Evaluated in the page: a promise of the JSON report (null fields: never ready).
PROBE = """new Promise(function (resolve) {
  function materials(o) { return Array.isArray(o.material) ? o.material : [o.material]; }
  function report() {
    var out = {title: document.title, ready: document.body.dataset.closedloop || null};
    var node = viewer.scene_tree.children["meshcat"];
    node = node && node.children["robots"];
    node = node && node.children["<object>"];
    if (node) {
      var root = node.object, pos = {}, quat = {}, ghost = [];
      root.updateMatrixWorld(true);
      root.traverse(function (o) {
        if (!o.isMesh) return;
        var p = new o.position.constructor(), r = new o.quaternion.constructor();
        o.parent.getWorldPosition(p);
        o.parent.getWorldQuaternion(r);
        pos[o.parent.name] = p.toArray();
        quat[o.parent.name] = r.toArray();
        if (o.parent.parent.name === "GHOST")
          materials(o).forEach(function (m) { ghost.push([m.opacity, m.transparent]); });
      });
      out.positions = pos;
      out.quaternions = quat;
      out.ghost = ghost;
    }
    var slider = document.getElementById("closedloop-slider");
    if (slider) {
      var b = slider.getBoundingClientRect();
      out.slider = [b.left, b.top, b.right, b.bottom];
    }
    var legend = document.getElementById("closedloop-legend");
    if (legend) {
      var r = legend.getBoundingClientRect();
      out.legend = {text: legend.innerText, box: [r.left, r.top, r.right, r.bottom]};
    }
    var a = viewer.animator;
    out.animation = {playing: a.playing, duration: a.duration,
                     times: a.actions.map(function (x) { return x.time; }),
                     loops: a.actions.map(function (x) { return x.loop; })};
    return JSON.stringify(out);
  }
  var t0 = performance.now();
  var wait = setInterval(function () {
    var ready = document.body.dataset.closedloop === "ready";
    if (!ready && performance.now() - t0 < WAIT) return;
    clearInterval(wait);
    setTimeout(function () {
      try { resolve(report()); } catch (e) { resolve(JSON.stringify({error: String(e)})); }
    }, DELAY);
  }, 20);
})"""
PROBE = PROBE.replace("GHOST", GHOST).replace("DELAY", str(PROBE_DELAY_MS))


async def _devtools(target: str, profile, wait_ms: int, actions=None):
    """(PNG, probe report) of ``target`` from a headless Chromium driven over DevTools;
    with ``actions`` (an async function of ``evaluate``), what it returns instead."""
    proc = subprocess.Popen(
        [browser(), *FLAGS, f"--user-data-dir={profile}", target],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + BROWSER_TIMEOUT
        ws = await devtools_page(proc, profile, deadline)
        errors = []  # the page's JavaScript errors (Log.entryAdded), from its start

        def record(message: dict) -> None:
            entry = message.get("params", {}).get("entry", {})
            if message.get("method") == "Log.entryAdded" and entry.get("level") == "error":
                if entry.get("source") == "javascript":
                    errors.append(entry.get("text"))

        call = devtools_caller(ws, record)

        async def evaluate(expression: str):
            """Value of ``expression`` (a promise is awaited) in the loaded page."""
            while True:  # the page may still be navigating: its context then goes away
                message = await call(
                    "Runtime.evaluate", expression=expression, awaitPromise=True, returnByValue=True
                )
                result = message.get("result", {})
                if "error" not in message and "exceptionDetails" not in result:
                    return result["result"].get("value")
                assert time.monotonic() < deadline, f"Chromium: {message}"
                await asyncio.sleep(0.05)

        await call("Log.enable")  # sends the entries logged so far, then each new one
        await call(  # the page's viewport, whatever the headless window's decorations
            "Emulation.setDeviceMetricsOverride",
            width=VIEWPORT[0],
            height=VIEWPORT[1],
            deviceScaleFactor=1,
            mobile=False,
        )
        loaded = "document.readyState === 'complete' && typeof viewer !== 'undefined'"
        while not await evaluate(loaded):
            assert time.monotonic() < deadline, f"{target} did not load"
            await asyncio.sleep(0.05)
        report = json.loads(await evaluate(PROBE.replace("WAIT", str(wait_ms))))
        report["errors"] = errors
        if actions is not None:
            return await actions(evaluate, deadline)
        shot = await call("Page.captureScreenshot", format="png")
        ws.close()
        return base64.b64decode(shot["result"]["data"]), report
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the browser's own process group only
        proc.wait()


def render(target: str, png, profile, wait_ms: int = PROBE_TIMEOUT_MS) -> tuple[np.ndarray, dict]:
    """(600, 800, 3) RGB screenshot [0..255] of ``target`` (file or http URL) and the
    probe's report, taken once the page reports its scene loaded (at most ``wait_ms``)."""
    data, report = asyncio.run(
        asyncio.wait_for(_devtools(target, profile, wait_ms), BROWSER_TIMEOUT)
    )
    assert "error" not in report, report["error"]
    png.write_bytes(data)
    return np.asarray(Image.open(png).convert("RGB"), dtype=float), report


def content(img: np.ndarray) -> float:
    body = img[CONTROLS_ROWS:]
    return float(np.mean(np.abs(body - np.median(body, axis=1, keepdims=True))))


def changed(a: np.ndarray, b: np.ndarray, box=None) -> float:
    """Fraction of the pixels that change between a and b, outside ``box`` (CSS px)."""
    mask = np.any(np.abs(a - b) > CHANGE_LEVEL, axis=2)
    keep = np.ones(mask.shape, dtype=bool)
    if box is not None:
        left, top, right, bottom = (round(x) for x in box)
        keep[max(top, 0) : bottom + 1, max(left, 0) : right + 1] = False
    return float(mask[keep].mean())


def group_distances(report: dict) -> dict[str, float]:
    """Geometry group -> distance [m] between its deflected and nominal positions."""
    pos = report["positions"]
    return {
        name[len(DEFLECTED) + 1 :]: float(
            np.linalg.norm(np.subtract(p, pos[GHOST + name[len(DEFLECTED) :]]))
        )
        for name, p in pos.items()
        if name.startswith(DEFLECTED + "_")
    }


def expected_distances(clm, scene) -> dict[str, float]:
    """The same distances from the scene (geometry placements carried by the nominal and
    the drawn joint placements)."""
    out = {}
    for name, poses in (("nominal", scene.poses), ("deflected", scene.poses_deflected)):
        out[name] = [
            (poses[g.parentJoint] @ g.placement.homogeneous)[:3, 3]
            for g in clm.visual_model.geometryObjects
        ]
    names = [g.name for g in clm.visual_model.geometryObjects]
    return {
        n: float(np.linalg.norm(a - b))
        for n, a, b in zip(names, out["deflected"], out["nominal"], strict=True)
    }


@pytest.fixture(scope="module")
def fourbar_shots(fourbar_urdf, fourbar_yaml, tmp_path_factory):
    """Screenshots: empty scene, deflection at scale 0 and automatic (file), automatic (live)."""
    browser()
    tmp = tmp_path_factory.mktemp("browser")
    clm = load_model(fourbar_urdf, fourbar_yaml)
    q = assemble(clm, [0.3]).q
    empty = meshcat.Visualizer()
    try:
        (tmp / "empty.html").write_text(empty.static_html(), encoding="utf-8")
    finally:
        empty.window.server_proc.kill()
        empty.window.server_proc.wait()
    targets = {"empty": (tmp / "empty.html").as_uri()}
    with DeflectionViewer(clm) as viewer:
        for name, scale in (("nominal", 0.0), ("deflected", None)):
            viewer.show(deflection_scene(clm, q, "P", FOURBAR_WRENCH, scale=scale), legend=False)
            targets[name] = viewer.save_html(tmp / f"{name}.html").as_uri()
        assert viewer.url.startswith("http://127.0.0.1:")
        targets["live"] = viewer.url  # the live page shows the last scene: deflected
        with ThreadPoolExecutor(max_workers=WORKERS) as pool:
            futures = {
                name: pool.submit(
                    render,
                    t,
                    tmp / f"{name}.png",
                    tmp / f"p-{name}",
                    EMPTY_WAIT_MS if name == "empty" else PROBE_TIMEOUT_MS,
                )
                for name, t in targets.items()
            }
            out = {name: future.result() for name, future in futures.items()}
    return out


@pytest.fixture(scope="module")
def robot_pages(ur5_urdf, tmp_path_factory):
    """UR5 and CaHyMan with the legend: scenes, probes and screenshots (run in parallel)."""
    browser()
    tmp = tmp_path_factory.mktemp("robots")
    ur5 = load_model(ur5_urdf, joint_stiffness=1e4)
    cahyman = cahyman_model()
    q_c = cahyman.assemble(np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.0)
    cases = {
        "ur5": (ur5, np.array(UR5_Q), "tool0", UR5_WRENCH),
        "cahyman": (cahyman.clm, q_c, "M", CAHYMAN_WRENCH),
    }
    scenes, pages = {}, {}
    for name, (clm, q, frame, w) in cases.items():
        with DeflectionViewer(clm) as viewer:
            for kind, scale, autoplay in (
                ("deflected", None, False),
                ("nominal", 0.0, False),
                ("autoplay", None, True),
            ):
                scene = deflection_scene(clm, q, frame, w, scale=scale, rotational=True)
                scenes[name, kind] = (clm, scene)
                viewer.show(scene, autoplay=autoplay)
                pages[name, kind] = viewer.save_html(tmp / f"{name}-{kind}.html")
    with ThreadPoolExecutor(max_workers=WORKERS) as pool:
        futures = {
            key: pool.submit(render, page.as_uri(), tmp / f"{key[0]}-{key[1]}.png", tmp / f"p{i}")
            for i, (key, page) in enumerate(pages.items())
        }
        results = {key: future.result() for key, future in futures.items()}
    return scenes, results


# ------------------------------------------------------------------ four-bar (primitives)
@pytest.mark.parametrize("name", ["nominal", "deflected", "live"])
def test_page_renders_a_scene(fourbar_shots, name):
    img, _ = fourbar_shots[name]
    assert img.shape == (600, 800, 3)
    assert img.mean(axis=2).std() > MIN_STD
    assert content(img) > content(fourbar_shots["empty"][0]) + MIN_EXTRA_CONTENT


def test_deflection_changes_the_picture(fourbar_shots):
    assert changed(fourbar_shots["deflected"][0], fourbar_shots["nominal"][0]) > MIN_CHANGED


def test_live_server_shows_the_exported_scene(fourbar_shots):
    (live, report), (static, _) = fourbar_shots["live"], fourbar_shots["deflected"]
    left, top, right, bottom = (round(x) for x in report["slider"])  # live page only
    keep = np.ones(live.shape[:2], dtype=bool)
    keep[max(top, 0) : bottom + 1, max(left, 0) : right + 1] = False
    assert np.mean(np.abs(live - static)[keep]) < MAX_SAME_SCENE_DIFF


def test_a_model_of_millimetres_is_drawn(fourbar_shots, fourbar_urdf, fourbar_yaml, tmp_path):
    """meshcat's camera clips nearer than 0.01 m: the four-bar scaled to 3.7 mm, seen from
    8 mm, was an empty page (the camera's clipping now follows the model's size)."""
    clm = load_model(scaled_fourbar(fourbar_urdf, 0.01, tmp_path), fourbar_yaml, geometry=True)
    scene = deflection_scene(clm, assemble(clm, [0.3]).q, "P", FOURBAR_WRENCH)
    with DeflectionViewer(clm) as viewer:
        viewer.show(scene, legend=False)
        page = viewer.save_html(tmp_path / "tiny.html")
    img, report = render(page.as_uri(), tmp_path / "tiny.png", tmp_path / "p")
    assert report["ready"] == "ready"
    assert content(img) > content(fourbar_shots["empty"][0]) + MIN_EXTRA_CONTENT


def test_a_model_without_visuals_renders_as_its_skeleton(fourbar_shots, fourbar_urdf,
                                                         fourbar_yaml, tmp_path):  # fmt: skip
    """The four-bar loaded without geometry: its page renders the skeleton, each joint's
    sphere moved by as much as the scene moves the joint."""
    clm = load_model(fourbar_urdf, fourbar_yaml, geometry=False)
    scene = deflection_scene(clm, assemble(clm, [0.3]).q, "P", FOURBAR_WRENCH)
    with DeflectionViewer(clm) as viewer:
        viewer.show(scene)
        page = viewer.save_html(tmp_path / "skeleton.html")
    img, report = render(page.as_uri(), tmp_path / "skeleton.png", tmp_path / "p")
    assert report["ready"] == "ready" and report["errors"] == []
    assert content(img) > content(fourbar_shots["empty"][0]) + MIN_EXTRA_CONTENT
    seen = group_distances(report)
    for j in range(1, clm.model.njoints):
        moved = np.linalg.norm(scene.poses_deflected[j][:3, 3] - scene.poses[j][:3, 3])
        key = node_name(DEFLECTED, f"joint {clm.model.names[j]}")[len(DEFLECTED) + 1 :]
        np.testing.assert_allclose(seen[key], moved, atol=ATOL_BROWSER)


# ------------------------------------------------------------------ UR5 (Collada), CaHyMan
@pytest.mark.parametrize("robot", ["ur5", "cahyman"])
def test_robot_page_renders_with_a_translucent_ghost(robot_pages, robot):
    scenes, results = robot_pages
    clm, _ = scenes[robot, "deflected"]
    _, report = results[robot, "deflected"]
    assert report["ready"] == "ready"
    # every material of every ghost mesh translucent (a .dae mesh may carry several)
    assert len(report["ghost"]) >= clm.visual_model.ngeoms
    assert all(opacity < 1.0 and transparent for opacity, transparent in report["ghost"])
    for kind in ("deflected", "nominal"):
        img, _ = results[robot, kind]
        assert img.shape == (600, 800, 3) and img.mean(axis=2).std() > MIN_STD


@pytest.mark.parametrize("robot", ["ur5", "cahyman"])
def test_robot_page_shows_the_legend_and_the_title(robot_pages, robot):
    scenes, results = robot_pages
    clm, scene = scenes[robot, "deflected"]
    _, report = results[robot, "deflected"]
    assert report["title"] == f"{clm.name}: deflection at {scene.frame} (closedloop viewer)"
    text = report["legend"]["text"]
    mm = 1e3 * scene.max_displacement
    for expected in (
        f"{clm.name}: deflection under a load at {scene.frame}",
        f"deflection amplified \u00d7{scene.scale:.4g} (automatic; linear deflection)",
        f"largest point displacement {mm:.4g} mm (real)",
        f"{scene.frame} moves (",
        "nominal pose (unloaded), translucent ghost",
        "translation compliance ellipsoid",
        "grid: squares of",
    ):
        assert expected in text
    assert ("moment arrow (two heads)" in text) and ("shrunk" in text) == (robot == "cahyman")
    # at 800 x 600 the legend (drawn smaller) leaves the robot, centred, in view
    right, bottom = report["legend"]["box"][2:]
    assert right < VIEWPORT[0] / 2 and bottom < VIEWPORT[1] / 2


@pytest.mark.parametrize("robot", ["ur5", "cahyman"])
def test_deflected_robot_differs_from_the_nominal_one(robot_pages, robot):
    scenes, results = robot_pages
    clm, scene = scenes[robot, "deflected"]
    _, report = results[robot, "deflected"]
    # in the page: each deflected mesh where Pinocchio puts it (the ramp rests at full load)
    seen, expected = group_distances(report), expected_distances(clm, scene)
    for name in (g.name for g in clm.visual_model.geometryObjects):
        key = node_name(DEFLECTED, name)[len(DEFLECTED) + 1 :]
        np.testing.assert_allclose(seen[key], expected[name], atol=ATOL_BROWSER)
    assert max(expected.values()) > 0.01 * scene.size
    # on the screen, outside the legend (whose numbers differ between the two pages)
    box = report["legend"]["box"]
    (shot, _), (nominal, _) = results[robot, "deflected"], results[robot, "nominal"]
    assert changed(shot, nominal, box) > MIN_CHANGED


@pytest.mark.parametrize("robot", ["ur5", "cahyman"])
def test_ramp_waits_for_the_scene_and_loops(robot_pages, robot):
    _, results = robot_pages
    (_, still), (_, playing) = results[robot, "deflected"], results[robot, "autoplay"]
    for report in (still, playing):
        anim = report["animation"]
        assert anim["duration"] > 0.0 and len(anim["times"]) == 2
        assert anim["loops"] == [LOOP_PING_PONG] * 2
    assert still["animation"]["playing"] is False
    np.testing.assert_allclose(still["animation"]["times"], still["animation"]["duration"])
    assert playing["animation"]["playing"] is True
    assert all(0.0 < t <= playing["animation"]["duration"] for t in playing["animation"]["times"])


# ------------------------------------------------------------------ CaHyMan, from its CLI
#: The guide's CaHyMan page (docs/guide/viewer.md).
CAHYMAN_VIEW = ("--alpha", "45", "60", "75", "--alpha4", "45", "--torque", "0", "0", "5")


def browser_placement(report: dict, group: str) -> coal.Transform3s:
    """The world placement of a drawn group as three.js holds it (quaternion x, y, z, w)."""
    x, y, z, w = report["quaternions"][group]
    R = pin.Quaternion(w, x, y, z).toRotationMatrix()
    return coal.Transform3s(R, np.array(report["positions"][group], dtype=float))


def test_cahyman_view_keeps_its_plates_apart_in_the_browser(tmp_path):
    """``cahyman view`` at the guide's load: the page loads without a JavaScript error,
    shows each mesh where the scene puts it, and the mobile plate's disc as drawn by
    three.js keeps clear of the fixed plate's (deflected and ghost; coal's distance)."""
    browser()
    page = tmp_path / "cahyman.html"
    run = subprocess.run(
        [sys.executable, "-m", "cahyman_pin", "view", *CAHYMAN_VIEW, "--rotational",
         "--html", str(page)],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr
    _, report = render(page.as_uri(), tmp_path / "cahyman.png", tmp_path / "p")
    assert report["ready"] == "ready" and report["errors"] == []
    model = cahyman_model()
    q = model.assemble(np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.05)
    scene = deflection_scene(model.clm, q, "M", CAHYMAN_WRENCH, rotational=True)
    assert f"\u00d7{scene.scale:.4g}" in report["legend"]["text"]
    seen, expected = group_distances(report), expected_distances(model.clm, scene)
    for name, distance in expected.items():
        key = node_name(DEFLECTED, name)[len(DEFLECTED) + 1 :]
        np.testing.assert_allclose(seen[key], distance, atol=ATOL_BROWSER)
    shapes = {g.name: g.geometry for g in model.clm.visual_model.geometryObjects}

    def gap(a: str, b: str) -> float:
        return coal.distance(
            shapes[a[a.index("_") + 1 :]], browser_placement(report, a),
            shapes[b[b.index("_") + 1 :]], browser_placement(report, b),
            coal.DistanceRequest(), coal.DistanceResult(),
        )  # fmt: skip

    mobile, fixed = "mobile_plate_0", "fixed_plate_0"
    apart = gap(node_name(GHOST, mobile), node_name(GHOST, fixed))
    assert apart > 0.05  # [m] the nominal plates
    for root in (DEFLECTED, GHOST):
        assert gap(node_name(DEFLECTED, mobile), node_name(root, fixed)) > 0.5 * apart


# ------------------------------------------------------------------ live slider
#: [s] the live viewer serves in spells of this until the browser has moved its slider and
#: seen the page redrawn (or its own deadline passed): a loaded machine starts Chromium slowly.
SLIDER_SERVE = 0.5
SLIDE = """(function () {
  var input = document.getElementById("closedloop-amplification");
  input.value = "1";  // the top: SLIDER_RANGE times the amplification shown
  input.dispatchEvent(new Event("change"));
  return true;
})()"""
LEGEND = """(function () {
  var legend = document.getElementById("closedloop-legend");
  return document.body.dataset.closedloop === "ready" && legend ? legend.innerText : "";
})()"""


def test_live_slider_redraws_the_scene_at_the_chosen_amplification(
    fourbar_urdf, fourbar_yaml, tmp_path
):
    browser()
    clm = load_model(fourbar_urdf, fourbar_yaml)
    q = assemble(clm, [0.3]).q
    scene = deflection_scene(clm, q, "P", FOURBAR_WRENCH)
    expected = f"deflection amplified \u00d7{scene.scale * SLIDER_RANGE:.4g} (given"

    async def slide(evaluate, deadline):
        assert await evaluate(SLIDE)
        while expected not in (text := await evaluate(LEGEND)):  # reloaded, redrawn
            assert time.monotonic() < deadline, text
            await asyncio.sleep(0.1)
        return text

    seen = []
    with DeflectionViewer(clm) as viewer, ThreadPoolExecutor(max_workers=1) as pool:
        viewer.show(scene)

        def redraw(value: float) -> None:
            seen.append(value)
            viewer.show(deflection_scene(clm, q, "P", FOURBAR_WRENCH, scale=value))

        page = pool.submit(
            lambda: asyncio.run(_devtools(viewer.url, tmp_path / "p", PROBE_TIMEOUT_MS, slide))
        )
        while not page.done():
            viewer.serve(duration=SLIDER_SERVE, out=lambda _: None, on_amplification=redraw)
        text = page.result()
    np.testing.assert_allclose(seen, [scene.scale * SLIDER_RANGE], rtol=1e-3)  # 4 digits
    assert expected in text
