"""The ``closedloop`` command, in-process through ``main`` and as a real subprocess."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from helpers import REPO, assert_close_in_norm, closed_pipe_run

from closedloop.cli.app import main

UR5_Q = [0.0, -1.0, 1.5, -0.5, 1.2, 0.3]  # the documented example [rad]
UR5_K = 1e4  # joint stiffness of the example [N m/rad]
# C = J K^-1 J^T is a product of O(1) numbers computed along two routes (compliance via
# a null-space basis, reference via the plain Jacobian): agreement to a few ulps, scaled
# by the largest entry since exact zeros are ~1e-17 noise in one route.
RTOL_EXACT = 1e-10
# The text report prints 6 significant digits (format .5e).
RTOL_PRINTED = 1e-5
JSON_KEYS = {"K", "C", "frame", "axes", "point", "units", "rank", "rigid_directions"}


def run(capsys, *args: str) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def ur5_reference(ur5_urdf: Path, q, frame: str = "tool0", rf=pin.LOCAL_WORLD_ALIGNED):
    """(C, J, point) of the UR5 with equal joint springs, straight from Pinocchio."""
    model = pin.buildModelFromUrdf(str(ur5_urdf))
    data = model.createData()
    fid = model.getFrameId(frame)
    J = pin.computeFrameJacobian(model, data, np.array(q), fid, rf)
    pin.framesForwardKinematics(model, data, np.array(q))
    return J @ J.T / UR5_K, J, data.oMf[fid].translation


def stiffness_args(ur5_urdf: Path, q=UR5_Q, *extra) -> list:
    return [
        "stiffness",
        ur5_urdf,
        "--frame",
        "tool0",
        "--q",
        *q,
        "--joint-stiffness",
        UR5_K,
        *extra,
    ]


# ------------------------------------------------------------------------ UR5 example
def test_ur5_example_json_matches_J_Kinv_JT(ur5_urdf, capsys):
    code, out, err = run(capsys, *stiffness_args(ur5_urdf, UR5_Q, "--json"))
    assert (code, err) == (0, "")
    doc = json.loads(out)
    assert JSON_KEYS <= set(doc)
    C_ref, _, point = ur5_reference(ur5_urdf, UR5_Q)
    assert_close_in_norm(doc["C"], C_ref, RTOL_EXACT)
    # K = C^-1: C is well conditioned here (cond ~ 80), so the inverse keeps ~1e-14.
    assert_close_in_norm(doc["K"], np.linalg.inv(C_ref), RTOL_EXACT)
    assert_close_in_norm(doc["point"], point, RTOL_EXACT)
    assert (doc["frame"], doc["axes"], doc["rank"], doc["rigid_directions"]) == (
        "tool0",
        "world",
        6,
        [],
    )
    assert "m/N" in doc["units"]["C"]


def test_ur5_example_local_axes(ur5_urdf, capsys):
    code, out, _ = run(capsys, *stiffness_args(ur5_urdf, UR5_Q, "--json", "--axes", "local"))
    assert code == 0
    C_ref, _, _ = ur5_reference(ur5_urdf, UR5_Q, rf=pin.LOCAL)
    assert_close_in_norm(json.loads(out)["C"], C_ref, RTOL_EXACT)


def parse_matrix(text: str, title: str) -> np.ndarray:
    """The 6x6 matrix printed under the line starting with ``title`` (after its header)."""
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith(title)) + 2
    return np.array([[float(v) for v in ln.split()[1:]] for ln in lines[start : start + 6]])


def test_ur5_example_text_report(ur5_urdf, capsys):
    code, out, err = run(capsys, *stiffness_args(ur5_urdf))
    assert (code, err) == (0, "")
    C_ref, _, _ = ur5_reference(ur5_urdf, UR5_Q)
    assert_close_in_norm(parse_matrix(out, "compliance C"), C_ref, RTOL_PRINTED)
    assert_close_in_norm(parse_matrix(out, "stiffness K"), np.linalg.inv(C_ref), RTOL_PRINTED)
    assert "[m/N" in out and "[N/m" in out and "world-aligned" in out


def test_ur5_springs_file(ur5_urdf, tmp_path, capsys):
    k = np.array([1e4, 2e4, 3e4, 4e3, 5e3, 6e3])
    names = ["shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3"]
    springs = tmp_path / "k.yaml"
    springs.write_text("".join(f"{n}_joint: {float(v)!r}\n" for n, v in zip(names, k, strict=True)))
    code, out, _ = run(
        capsys,
        "stiffness",
        ur5_urdf,
        "--frame",
        "tool0",
        "--q",
        *UR5_Q,
        "--springs",
        springs,
        "--json",
    )
    assert code == 0
    _, J, _ = ur5_reference(ur5_urdf, UR5_Q)
    assert_close_in_norm(json.loads(out)["C"], (J / k) @ J.T, RTOL_EXACT)


# -------------------------------------------------------------- rigid directions: exit 1
def test_ur5_neutral_names_rigid_direction_and_refuses_K(ur5_urdf, capsys):
    zeros = [0.0] * 6
    code, out, err = run(capsys, *stiffness_args(ur5_urdf, zeros))
    assert (code, err) == (1, "")
    assert "rank of C 5/6" in out
    assert "rigid directions" in out and "[+1.00 rx]" in out
    assert "K: does not exist" in out
    assert re.search(r"\b(nan|inf)\b", out, re.IGNORECASE) is None  # no NaN/inf matrix
    assert "stiffness K = C^-1" not in out  # no matrix for K

    code, out, _ = run(capsys, *stiffness_args(ur5_urdf, zeros, "--json"))
    doc = json.loads(out)
    assert (code, doc["K"], doc["rank"]) == (1, None, 5)
    # Independent: the rigid direction is the left null vector of J (J^T u = 0).
    _, J, _ = ur5_reference(ur5_urdf, zeros)
    u = np.linalg.svd(J)[0][:, -1]
    (rigid,) = doc["rigid_directions"]
    np.testing.assert_allclose(abs(np.dot(u, rigid)), 1.0, rtol=RTOL_EXACT)


# ------------------------------------------------------------------- closed loops
FOURBAR = {
    "urdf": [REPO / "urdf" / "fourbar.urdf", "--closures", REPO / "urdf" / "fourbar.yaml"],
    "mjcf": [REPO / "urdf" / "fourbar.xml"],
}


@pytest.mark.parametrize("kind", ["urdf", "mjcf"])
def test_fourbar_actuated_is_assembled(kind, capsys):
    code, out, err = run(
        capsys, "stiffness", *FOURBAR[kind], "--frame", "P", "--actuated", 0.8, "--json"
    )
    doc = json.loads(out)
    # Planar: only dx, dz, ry are compliant; exit 1 because K does not exist in 6D.
    assert (code, err, doc["rank"], doc["K"]) == (1, "", 3, None)
    assert doc["q"][0] == 0.8 and doc["closure_residual"] < 1e-12


def test_fourbar_urdf_and_mjcf_agree_through_the_cli(capsys):
    common = ["--frame", "P", "--actuated", 0.8, "--json"]
    C_urdf = json.loads(run(capsys, "stiffness", *FOURBAR["urdf"], *common)[1])["C"]
    C_mjcf = json.loads(run(capsys, "stiffness", *FOURBAR["mjcf"], *common)[1])["C"]
    assert_close_in_norm(C_mjcf, C_urdf, 1e-9)  # same tolerance as RTOL_TWIN in test_io.py


# ---------------------------------------------------------------------- errors: exit 2
# Command lines ({ur5}, {fourbar}, {tmp} substituted) and a part of the expected message.
ERRORS = {
    "missing-file": ("{tmp}/none.urdf --frame P", "robot file '{tmp}/none.urdf' does not exist"),
    "unknown-frame": (
        "{ur5} --frame tool9",
        "unknown frame 'tool9' (did you mean 'tool0'?); expected one of:",
    ),
    "malformed-closures": ("{fourbar} --closures {tmp}/bad.yaml --frame P", "bad.yaml': type '4d'"),
    "unknown-joint": ("{ur5} --frame tool0 --springs {tmp}/k.yaml", "unknown joint 'elbow'"),
    "q-count": ("{ur5} --frame tool0 --q 0 0 0 0 0", "q has 5 values; expected nq=6"),
    "q-nan": ("{ur5} --frame tool0 --q 0 0 nan 0 0 0", "--q: 'nan' is not a finite number"),
    "wrench-inf": (
        "{ur5} --frame tool0 --wrench 0 0 -1e400 0 0 0",
        "'-1e400' is beyond the floating point range",
    ),
    "usage": ("{ur5} --frame tool0 --axes up", "argument --axes: invalid choice: 'up'"),
    "negative-stiffness": ("{ur5} --frame tool0 --joint-stiffness -1", "expected a number >= 0"),
    "nan-stiffness": ("{ur5} --frame tool0 --joint-stiffness nan", "expected a number >= 0"),
    "q-not-assembled": (
        "{fourbar} --closures {yaml} --frame P --q 0 0 0 0 0",
        "--q: configuration does not close the loops of 'fourbar'",
    ),
}


@pytest.mark.parametrize(("line", "match"), ERRORS.values(), ids=ERRORS.keys())
def test_errors_one_line_exit_2(ur5_urdf, tmp_path, capsys, line, match):
    (tmp_path / "bad.yaml").write_text(
        "closed_loop: [[closedloop1_A, closedloop1_B]]\ntype: ['4d']\n"
    )
    (tmp_path / "k.yaml").write_text("elbow: 1.0\n")
    names = {
        "ur5": ur5_urdf,
        "tmp": tmp_path,
        "fourbar": FOURBAR["urdf"][0],
        "yaml": FOURBAR["urdf"][2],
    }
    code, out, err = run(capsys, "stiffness", *line.format(**names).split())
    assert code == 2 and out == ""
    assert err.startswith("closedloop: error: ") and err.count("\n") == 1
    assert match.format(**names) in err and "Traceback" not in err


def test_help_documents_exit_codes(capsys):
    code, out, _ = run(capsys, "stiffness", "--help")
    assert code == 0 and "Exit status" in out and "--joint-stiffness" in out


def test_q_and_actuated_are_exclusive(ur5_urdf, capsys):
    code, _, err = run(capsys, "stiffness", ur5_urdf, "--frame", "tool0", "--q", 0, "--actuated", 0)
    assert code == 2 and "not allowed with" in err


# ------------------------------------------------------------------------- subprocess
def python_m(*args, cwd=REPO) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run(
        [sys.executable, "-m", "closedloop", *map(str, args)],
        capture_output=True,
        text=True,
        env=env,
        cwd=cwd,
        timeout=120,
        check=False,
    )


def test_subprocess_example_and_error(ur5_urdf, tmp_path):
    done = python_m(*stiffness_args(ur5_urdf, UR5_Q, "--json"))
    assert (done.returncode, done.stderr) == (0, "")
    C_ref, _, _ = ur5_reference(ur5_urdf, UR5_Q)
    assert_close_in_norm(json.loads(done.stdout)["C"], C_ref, RTOL_EXACT)

    done = python_m("stiffness", tmp_path / "missing.urdf", "--frame", "tool0")
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.startswith("closedloop: error: robot file") and done.stderr.count("\n") == 1
    assert "Traceback" not in done.stderr


# ------------------------------------------------------------ exit status 3, names, pipes
WELD = REPO / "tests" / "data" / "fourbar_weld.yaml"  # a weld the four-bar cannot reach


def test_loops_that_cannot_be_closed_exit_3(capsys):
    code, out, err = run(
        capsys, "stiffness", "fourbar", "--closures", WELD, "--frame", "P", "--actuated", 0.3
    )
    assert (code, out) == (3, "")
    assert err.startswith("closedloop: error: cannot close the loops") and err.count("\n") == 1


def test_help_and_version(capsys):
    import closedloop

    code, out, _ = run(capsys, "--version")
    assert (code, out) == (0, f"closedloop {closedloop.__version__}\n")
    code, out, _ = run(capsys, "stiffness", "--help")
    flat = " ".join(out.split())
    assert code == 0 and "2 bad input; 3 the computation failed" in flat
    assert "ur5" in flat and "fourbar" in flat  # MODEL may be a name


def test_negative_numbers_in_e_notation_are_values(ur5_urdf, capsys):
    q = ["0", "-1e0", "1.5", "-5E-1", "1.2", "3e-1"]
    code, out, err = run(capsys, *stiffness_args(ur5_urdf, q, "--json"))
    assert (code, err) == (0, "")
    np.testing.assert_array_equal(json.loads(out)["q"], UR5_Q)


def test_models_by_name_from_an_empty_folder(ur5_urdf, tmp_path):
    by_name = python_m(*stiffness_args("ur5", UR5_Q, "--json"), cwd=tmp_path)
    assert (by_name.returncode, by_name.stderr) == (0, "")
    C_ref, _, _ = ur5_reference(ur5_urdf, UR5_Q)
    assert_close_in_norm(json.loads(by_name.stdout)["C"], C_ref, RTOL_EXACT)
    fourbar = python_m("stiffness", "fourbar", "--frame", "P", "--actuated", 0.8, "--json",
                       cwd=tmp_path)  # fmt: skip
    files = python_m("stiffness", *FOURBAR["urdf"], "--frame", "P", "--actuated", 0.8, "--json")
    assert fourbar.returncode == files.returncode == 1  # planar: rank 3, K does not exist
    assert json.loads(fourbar.stdout)["C"] == json.loads(files.stdout)["C"]
    panda = python_m("stiffness", "panda", "--frame", "panda_hand", "--joint-stiffness", 1e4,
                     "--q", 0, -0.5, 0, -2, 0, 1.5, 0.8, 0, "--json", cwd=tmp_path)  # fmt: skip
    assert panda.returncode == 0 and json.loads(panda.stdout)["rank"] == 6


def test_unknown_model_name_lists_the_names(capsys):
    code, _, err = run(capsys, "stiffness", "ur6", "--frame", "tool0")
    assert code == 2 and err.count("\n") == 1
    assert "model 'ur6' is neither a file nor a known name" in err and "'ur5'" in err


@pytest.mark.parametrize(
    ("html", "match"),
    [
        ("/proc/x/view.html", "folder '/proc/x' does not exist"),
        ("{tmp}", "is a folder; expected a file"),
        ("{tmp}/file.txt/view.html", "is not a folder"),
    ],
)
def test_bad_html_path_exits_2_before_any_work(tmp_path, capsys, monkeypatch, html, match):
    (tmp_path / "file.txt").write_text("")
    import closedloop.cli.options as cli

    def no_work(*args, **kwargs):
        raise AssertionError("the model was loaded before the output path was checked")

    monkeypatch.setattr(cli, "load_model", no_work)
    line = ["view", "fourbar", "--frame", "P", "--html", html.format(tmp=tmp_path)]
    code, out, err = run(capsys, *line)
    assert (code, out) == (2, "")
    assert err.startswith("closedloop: error: --html ") and err.count("\n") == 1
    assert match in err


def test_a_read_only_html_file_exits_2_before_any_work(tmp_path, capsys, monkeypatch):
    """Refused before the model is loaded, not by the writer after the work. Root may
    write any file: the check is os.access, patched here."""
    import os

    import closedloop.cli.options as cli

    path = tmp_path / "view.html"
    path.write_text("old")
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, m: False if str(p) == str(path) else real(p, m))

    def no_work(*args, **kwargs):
        raise AssertionError("the model was loaded before the output path was checked")

    monkeypatch.setattr(cli, "load_model", no_work)
    code, out, err = run(capsys, "view", "fourbar", "--frame", "P", "--html", str(path))
    assert (code, out) == (2, "") and err.count("\n") == 1
    assert f"--html '{path}' is read-only; expected a writable file" in err
    assert path.read_text() == "old"


def test_closed_pipe_ends_quietly(ur5_urdf):
    done = closed_pipe_run("closedloop", *stiffness_args(ur5_urdf))
    assert (done.returncode, done.stderr) == (141, "")
