"""The viewer in a real browser: headless Chromium renders the pages (WebGL on the CPU).

Chromium loads the exported page from a file URL and the live page from the meshcat
server on 127.0.0.1, and takes screenshots. Without Chromium the tests are skipped with
the reason shown (pytest -ra); a Chromium that runs but renders nothing fails them.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess

import meshcat
import numpy as np
import pytest
from PIL import Image

from closedloop.assembly import assemble
from closedloop.io import load_model
from closedloop.viewer import DeflectionViewer
from closedloop.viewer_scene import deflection_scene

BROWSERS = ("chromium", "chromium-browser", "google-chrome")
#: Headless Chromium with software WebGL and no background traffic (closed network).
FLAGS = (
    "--headless", "--no-sandbox", "--use-gl=angle", "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader", "--disable-gpu", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--window-size=800,600", "--virtual-time-budget=5000",
)  # fmt: skip
BROWSER_TIMEOUT = 60.0  # [s] per screenshot
#: Top rows hidden by meshcat's "Open Controls" bar (an HTML element, not WebGL).
CONTROLS_ROWS = 30
#: A rendered scene: grey-level standard deviation [0..255] well above a flat page.
MIN_STD = 10.0
#: Drawn content (mean deviation from each row's median colour; the background gradient
#: is constant along rows) must exceed that of an empty meshcat scene by this much [0..255].
MIN_EXTRA_CONTENT = 1.0
#: A pixel "changes" when a channel differs by more than CHANGE_LEVEL [0..255]; the
#: deflected scene must change at least MIN_CHANGED of the pixels.
CHANGE_LEVEL, MIN_CHANGED = 10, 0.002
#: The same scene from the file and from the live server: mean difference [0..255].
MAX_SAME_SCENE_DIFF = 1.0
WRENCH = [3.0, 0.0, -20.0, 0.0, 0.0, 0.0]  # [N, N m] at P of the four-bar


def browser() -> str:
    for name in BROWSERS:
        if path := shutil.which(name):
            return path
    pytest.skip(
        f"real-browser tests skipped: no Chromium on PATH (looked for {', '.join(BROWSERS)}); "
        "install the Debian package 'chromium' to run them"
    )


def screenshot(target: str, png, profile) -> np.ndarray:
    """(600, 800, 3) RGB screenshot [0..255] of ``target`` (a file or http URL)."""
    cmd = [browser(), *FLAGS, f"--user-data-dir={profile}", f"--screenshot={png}", target]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True
    )
    try:
        _, err = proc.communicate(timeout=BROWSER_TIMEOUT)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)  # the browser's own process group only
        proc.communicate()
        pytest.fail(f"Chromium did not finish within {BROWSER_TIMEOUT} s on {target}")
    assert proc.returncode == 0 and png.is_file(), err[-2000:]
    return np.asarray(Image.open(png).convert("RGB"), dtype=float)


def content(img: np.ndarray) -> float:
    body = img[CONTROLS_ROWS:]
    return float(np.mean(np.abs(body - np.median(body, axis=1, keepdims=True))))


@pytest.fixture(scope="module")
def shots(fourbar_urdf, fourbar_yaml, tmp_path_factory):
    """Screenshots: empty scene, deflection at scale 0 and automatic (file), automatic (live)."""
    browser()
    tmp = tmp_path_factory.mktemp("browser")
    clm = load_model(fourbar_urdf, fourbar_yaml)
    q = assemble(clm, [0.3]).q
    out = {}
    empty = meshcat.Visualizer()
    try:
        (tmp / "empty.html").write_text(empty.static_html(), encoding="utf-8")
    finally:
        empty.window.server_proc.kill()
        empty.window.server_proc.wait()
    out["empty"] = screenshot((tmp / "empty.html").as_uri(), tmp / "empty.png", tmp / "p0")
    with DeflectionViewer(clm) as viewer:
        for name, scale in (("nominal", 0.0), ("deflected", None)):
            viewer.show(deflection_scene(clm, q, "P", WRENCH, scale=scale), label=False)
            page = viewer.save_html(tmp / f"{name}.html")
            out[name] = screenshot(page.as_uri(), tmp / f"{name}.png", tmp / f"p-{name}")
        assert viewer.url.startswith("http://127.0.0.1:")
        out["live"] = screenshot(viewer.url, tmp / "live.png", tmp / "p-live")
    return out


@pytest.mark.parametrize("name", ["nominal", "deflected", "live"])
def test_page_renders_a_scene(shots, name):
    img = shots[name]
    assert img.shape == (600, 800, 3)
    assert img.mean(axis=2).std() > MIN_STD
    assert content(img) > content(shots["empty"]) + MIN_EXTRA_CONTENT


def test_deflection_changes_the_picture(shots):
    changed = np.any(np.abs(shots["deflected"] - shots["nominal"]) > CHANGE_LEVEL, axis=2)
    assert changed.mean() > MIN_CHANGED


def test_live_server_shows_the_exported_scene(shots):
    assert np.mean(np.abs(shots["live"] - shots["deflected"])) < MAX_SAME_SCENE_DIFF
