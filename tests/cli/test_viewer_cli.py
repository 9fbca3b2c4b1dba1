"""``closedloop view`` and ``cahyman view``: pages, one-line refusals, the live server's life.

The live-server tests run the command line as a child process, as a user does: the
server must listen on 127.0.0.1 only (read from /proc/net/tcp and tcp6, Linux) and stop
with the command on SIGTERM (``timeout``) or SIGINT (Ctrl-C).
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest
from helpers import REPO

from cahyman_pin.api import stiffness
from cahyman_pin.cli import main as cahyman_main
from closedloop.cli.app import main as closedloop_main

#: Seconds a live view may take to print its URL, and to stop after a signal.
START_TIMEOUT, STOP_TIMEOUT = 60.0, 10.0
LISTEN = "0A"  # TCP state LISTEN in /proc/net/tcp
#: The closed form against the Pinocchio model: they agree to ~1e-14 (README); margin.
RTOL_SAME_QUERY = 1e-9
#: The drawn point is the model moved by 30 dq and closed again: second order in the
#: amplified rotation (~1e-3 rad here), against the first-order 30 C w.
RTOL_AMPLIFIED = 1e-2


def run(main, capsys, *argv) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def fourbar_args(fourbar_urdf, fourbar_yaml) -> list[str]:
    return [str(fourbar_urdf), "--closures", str(fourbar_yaml), "--frame", "P", "--actuated", "0.3"]


def test_closedloop_view_writes_the_page(fourbar_urdf, fourbar_yaml, tmp_path, capsys):
    html = tmp_path / "fourbar.html"
    argv = ["view", *fourbar_args(fourbar_urdf, fourbar_yaml), "--force", 0, 0, -20]
    code, out, err = run(closedloop_main, capsys, *argv, "--scale", 50, "--html", html)
    assert (code, err) == (0, "")
    assert "amplified x50 (given" in out and f"wrote {html}" in out
    page = html.read_text(encoding="utf-8")
    assert "deflection amplified \u00d750 (given; linear deflection)" in page
    assert "load at P (world axes): force (0, 0, -20) N, moment (0, 0, 0) N m" in page


@pytest.mark.parametrize("force", ["1e-300", "1e300"])
def test_closedloop_view_of_a_tiny_or_huge_load(fourbar_urdf, fourbar_yaml, tmp_path, capsys,
                                                force):  # fmt: skip
    """Finite deflections of any magnitude are drawn (coloured by displacement, amplified
    to the same picture); only a load whose deflection is not a finite number is refused."""
    html = tmp_path / "fourbar.html"
    argv = ["view", *fourbar_args(fourbar_urdf, fourbar_yaml), "--force", force, 0, 0]
    code, out, err = run(closedloop_main, capsys, *argv, "--html", html)
    assert (code, err) == (0, ""), err
    assert "(automatic; linear deflection)" in out and html.stat().st_size > 10_000


def test_no_legend_option_leaves_the_legend_out(fourbar_urdf, fourbar_yaml, tmp_path, capsys):
    html = tmp_path / "fourbar.html"
    argv = ["view", *fourbar_args(fourbar_urdf, fourbar_yaml), "--force", 0, 0, -20]
    code, _, _ = run(closedloop_main, capsys, *argv, "--no-legend", "--html", html)
    page = html.read_text(encoding="utf-8")
    assert code == 0 and 'id="closedloop-legend"' not in page and "<script" in page


def test_cahyman_view_writes_the_page_with_its_pose(tmp_path, capsys):
    html = tmp_path / "cahyman.html"
    code, out, err = run(cahyman_main, capsys, "view", "--force", 10, 0, -20, "--html", html)
    assert (code, err) == (0, "")
    assert out.endswith(f"wrote {html}\n")
    page = html.read_text(encoding="utf-8")
    assert "<title>cahyman: deflection at M (closedloop viewer)</title>" in page
    assert "pose: alpha = (90, 90, 90) deg, alpha4 = 90 deg, s4 = 50 mm, K_s assumed" in page
    assert "translation compliance ellipsoid" in page


def test_cahyman_view_json_goes_to_stdout(tmp_path, capsys):
    html = tmp_path / "cahyman.html"
    argv = ["view", "--force", 0, 0, -5, "--scale", 30, "--json", "--html", html]
    code, out, err = run(cahyman_main, capsys, *argv)
    assert code == 0 and f"wrote {html}" in err
    doc = json.loads(out)
    assert (doc["scale"], doc["auto_scaled"], doc["html"]) == (30.0, False, str(html))
    assert len(doc["frame_twist"]) == 6
    # the deflected point is the true one, C w from the stiffness query; the amplified
    # one (x30) is the drawn one. It was the amplified point under the deflected name.
    C = stiffness(np.deg2rad([90.0] * 3), np.deg2rad(90.0), 0.05, backend="consistent").C
    moved = C[:3] @ np.array([0.0, 0.0, -5.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(np.subtract(doc["point_deflected_m"], doc["point_m"]), moved,
                               atol=RTOL_SAME_QUERY * np.linalg.norm(moved))  # fmt: skip
    shown = np.subtract(doc["point_shown_m"], doc["point_m"])
    np.testing.assert_allclose(
        shown, 30.0 * moved, atol=RTOL_AMPLIFIED * 30.0 * np.linalg.norm(moved)
    )


@pytest.mark.parametrize("main", [closedloop_main, cahyman_main])
def test_view_without_load_warns_in_one_line(main, fourbar_urdf, fourbar_yaml, tmp_path, capsys):
    html = tmp_path / "page.html"
    argv = ["view", *fourbar_args(fourbar_urdf, fourbar_yaml)] if main is closedloop_main else []
    code, _, err = run(main, capsys, *(argv or ["view"]), "--html", html)
    prog = "closedloop" if main is closedloop_main else "cahyman"
    assert code == 0 and html.is_file()
    assert (
        err == f"{prog}: warning: no load (--force, --torque): the view shows the unloaded pose\n"
    )
    assert "no load at" in html.read_text(encoding="utf-8")


@pytest.mark.parametrize(
    "argv",
    [
        ["--frame", "nowhere"],
        ["--frame", "P", "--scale", "-2"],
        ["--frame", "P", "--force", "nan", "0", "0"],
        ["--frame", "P", "--force", "1.7e308", "1.7e308", "0"],
        ["--frame", "P", "--torque", "0", "-1.7e308", "1.7e308"],
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


@pytest.mark.parametrize(
    "argv",
    [
        ["--backend", "consistent"],
        ["--scale", "inf"],
        ["--s4", "999"],
        ["--force", "1.7e308", "1.7e308", "0"],
    ],
)
def test_cahyman_view_bad_input_exits_2_with_one_line(capsys, tmp_path, argv):
    code, out, err = run(cahyman_main, capsys, "view", *argv, "--html", tmp_path / "x.html")
    assert code == 2 and out == ""
    assert len(err.splitlines()) == 1 and err.startswith("cahyman: error: ")
    assert not (tmp_path / "x.html").exists()


def test_cahyman_view_offers_only_the_backend_it_draws(capsys):
    """Its help listed consistent and published, which always exited 2."""
    assert cahyman_main(["view", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "[--backend {generic}]" in text and "consistent" not in text
    assert "published" not in text


# ------------------------------------------------------------------ the live server
def listening(port: int) -> list[str]:
    """Local addresses (hex, as in /proc/net/tcp*) listening on ``port``."""
    found = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        with open(table, encoding="ascii") as f:
            for line in f.readlines()[1:]:
                fields = line.split()
                address, hex_port = fields[1].rsplit(":", 1)
                if int(hex_port, 16) == port and fields[3] == LISTEN:
                    found.append(address)
    return found


def refused(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(2.0)
        return s.connect_ex(("127.0.0.1", port)) != 0


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/net (Linux)")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_live_view_listens_on_localhost_and_stops_on_a_signal(fourbar_urdf, fourbar_yaml, sig):
    argv = ["view", *fourbar_args(fourbar_urdf, fourbar_yaml), "--force", "0", "0", "-20"]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "closedloop.cli.app", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
        env=env,
    )
    try:
        deadline, url = time.monotonic() + START_TIMEOUT, None
        while url is None and time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            if line.startswith("meshcat viewer at "):
                url = line.split()[3]
        assert url is not None, proc.stderr.read()
        port = int(url.split(":")[2].split("/")[0])
        # 127.0.0.1 only: 0100007F in /proc/net/tcp; nothing on 0.0.0.0 or [::]
        assert listening(port) == ["0100007F"]
        proc.send_signal(sig)
        code = proc.wait(STOP_TIMEOUT)
        err = proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert code == 0 and "Traceback" not in err, err
    deadline = time.monotonic() + STOP_TIMEOUT
    while not refused(port) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert refused(port) and listening(port) == []
