"""``closedloop path`` (issue #42): the files it writes, what it prints, one-line errors that
keep the points before a failed one, the Stewart platform on worker processes."""

from __future__ import annotations

import csv
import json

import numpy as np
import pinocchio as pin
import pytest
from helpers import UR5_Q
from pinocchio_statics import placement

import closedloop as cl
from closedloop.cli.app import main
from closedloop.io.data import path as bundled
from closedloop.kinematics.frame_task import xyzquat

HEADER = "x,y,z,qx,qy,qz,qw"
UR5_ARGS = ["--frame", "tool0", "--joint-stiffness", "1e4", "--q", *map(str, UR5_Q)]


def _write(path, rows, header=HEADER):
    path.write_text(header + "\n" + "\n".join(",".join(repr(float(x)) for x in r) for r in rows))
    return str(path)


@pytest.fixture(scope="module")
def ur5_line(ur5):
    """Three targets of the UR5's tool0 along a line, orientation kept."""
    clm, _ = ur5
    M = placement(clm.model, UR5_Q, "tool0")
    return np.array([xyzquat(pin.SE3(M.rotation, M.translation + k * np.array([0.0, 0.01, 0.0])))
                     for k in range(3)])  # fmt: skip


def test_path_writes_its_files_and_summary(tmp_path, ur5, ur5_line, capsys):
    """The stiffest rotation about tool0's axis on the UR5: the files, the JSON summary,
    the numbers of the API."""
    out = tmp_path / "out"
    line = ur5_line[:2]
    argv = ["path", "ur5", *UR5_ARGS, "--path", _write(tmp_path / "p.csv", line),
            "--force", "0", "0", "-50", "--task", "tool-axis", "--stiffest", "--json",
            "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["points"] == 2 and doc["task"] == "tool-axis" and doc["compensated"] == "pose"
    assert doc["stiffest"]["max_change_rad"] == 0.1
    assert doc["residual"]["translation_m"] < 1e-12 < doc["error"]["translation_m"]
    assert str(out / "path.csv") in doc["written"]
    data = np.load(out / "path.npz")
    clm, _ = ur5
    r = cl.follow_path(clm, "tool0", line, wrench=[0, 0, -50, 0, 0, 0], q0=UR5_Q,
                       task="tool-axis", stiffest=True)  # fmt: skip
    for name in ("q_target", "q_loaded", "commands", "error", "residual", "free"):
        np.testing.assert_allclose(data[name], r.arrays()[name], rtol=0, atol=1e-12)
    assert json.loads(str(data["summary"]))["points"] == 2
    with open(out / "path.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0][:4] == ["point", "target_x", "target_y", "target_z"]
    assert "command_elbow_joint_rad" in rows[0] and "free_0_rad" in rows[0] and len(rows) == 3
    for name in ("path_error.png", "path_3d.png"):
        assert (out / name).stat().st_size > 10_000


def test_unreachable_point_writes_the_points_before_it(tmp_path, ur5_line, capsys):
    rows = np.array(ur5_line)
    rows[2, :3] = (3.0, 0.0, 0.5)
    out = tmp_path / "out"
    argv = ["path", "ur5", *UR5_ARGS, "--path", _write(tmp_path / "p.csv", rows),
            "--out", str(out)]  # fmt: skip
    assert main(argv) == 3
    err = capsys.readouterr().err.strip().splitlines()[-1]  # after the progress lines
    assert err.startswith("closedloop: error: path point 2 of 3")
    assert err.endswith(f"the 2 points before it written to {out}")
    assert len(np.load(out / "path.npz")["targets"]) == 2


@pytest.mark.parametrize(
    ("content", "extra", "status", "message"),
    [
        ("x,y,z,qx,qy,qz\n0,0,0,0,0,0", [], 2, "lacks ['qw']"),
        (f"{HEADER}\n0.5,0.1,0.4,0,0,0,one", [], 2, "row 1 column 'qw' is 'one'"),
        (HEADER, [], 2, "no rows below its header"),
        (f"{HEADER}\n0.5,0.1,0.4,0,0,0,1", ["--max-change", "0.2"], 2, "without --stiffest"),
        (
            f"{HEADER}\n0.5,0.1,0.4,0,0,0,1",
            ["--wrenches", "W", "--force", "1", "0", "0"],
            2,
            "give one of them",
        ),
    ],
)
def test_bad_input_is_one_line(tmp_path, capsys, content, extra, status, message):
    (tmp_path / "p.csv").write_text(content)
    (tmp_path / "W").write_text("fx,fy,fz,nx,ny,nz\n1,0,0,0,0,0\n")
    extra = [str(tmp_path / "W") if a == "W" else a for a in extra]
    argv = ["path", "ur5", *UR5_ARGS, "--path", str(tmp_path / "p.csv"), *extra,
            "--out", str(tmp_path / "out")]  # fmt: skip
    assert main(argv) == status
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err
    assert not (tmp_path / "out").exists()


def test_stewart_on_worker_processes_with_wrenches(tmp_path, capsys):
    """The bundled Stewart platform, one wrench a point: two processes, chunks of 2, the
    serial API's numbers."""
    clm = cl.load_model(bundled("stewart.urdf"), bundled("stewart.yaml"))
    q = cl.assemble(clm, None, clm.reference_configuration()).q
    M = placement(clm.model, q, "platform")
    turns = [pin.exp3(np.array([0.0, 0.0, 0.02 * k])) for k in range(5)]
    rows = [xyzquat(pin.SE3(M.rotation @ turn, M.translation + np.array([0.01 * k, 0.0, 0.0])))
            for k, turn in enumerate(turns)]  # fmt: skip
    w = np.array([[100.0 * k, 0.0, -300.0, 0.0, 5.0, 0.0] for k in range(5)])
    (tmp_path / "w.csv").write_text("fx,fy,fz,nx,ny,nz\n" + "\n".join(",".join(map(str, r))
                                                                     for r in w))  # fmt: skip
    out = tmp_path / "out"
    argv = ["path", "stewart", "--frame", "platform", "--path", _write(tmp_path / "p.csv", rows),
            "--wrenches", str(tmp_path / "w.csv"), "--workers", "2", "--chunk", "2",
            "--out", str(out)]  # fmt: skip
    assert main(argv) == 0, capsys.readouterr().err
    data = np.load(out / "path.npz")
    r = cl.follow_path(clm, "platform", rows, wrench=w, q0=q)
    for name in ("q_loaded", "q_compensated", "commands"):
        np.testing.assert_allclose(data[name], getattr(r, name), rtol=0, atol=1e-10)
    np.testing.assert_allclose(data["residual"], 0.0, atol=1e-12)
