"""Command line ``cahyman``: JSON output, unit conversions, exit status on bad input."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cahyman_pin import api
from cahyman_pin.cli import main

REPO = Path(__file__).resolve().parent.parent
#: Same computation through the CLI and the API: only the deg/mm -> SI conversion
#: differs (one rounding of the inputs), amplified by cond(C) ~ 1e7 at most; K entries
#: reach ~1e6 SI, hence the absolute part of its tolerance.
SAME_RTOL = 1e-9
#: Table 3 pose in the paper's units.
TABLE3_ARGS = ["--alpha", "45", "60", "75", "--alpha4", "45", "--s4", "0"]


def run(capsys, *argv: str) -> tuple[int, str, str]:
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def test_stiffness_json_has_the_documented_keys(capsys):
    status, out, err = run(capsys, "stiffness", "--json")
    assert (status, err) == (0, "")
    doc = json.loads(out)
    assert {"K", "C", "det_K", "platform", "inputs", "units"} <= set(doc)
    assert np.array(doc["K"]).shape == (6, 6)
    assert np.array(doc["C"]).shape == (6, 6)
    assert {"H_m", "R"} <= set(doc["platform"])
    # defaults: Table 1, alpha_k = 90 deg puts H at height b + h = 0.13 m, plate level
    assert doc["inputs"]["alpha_deg"] == [90.0, 90.0, 90.0]
    assert doc["inputs"]["alpha4_deg"] == 90.0
    assert doc["inputs"]["s4_mm"] == 50.0
    np.testing.assert_allclose(doc["platform"]["H_m"], [0.0, 0.0, 0.13], atol=1e-12)
    np.testing.assert_allclose(doc["platform"]["R"], np.eye(3), atol=1e-12)


def test_stiffness_converts_paper_units_to_si(capsys):
    status, out, _ = run(capsys, "stiffness", *TABLE3_ARGS, "--json")
    assert status == 0
    doc = json.loads(out)
    ref = api.stiffness(np.radians([45.0, 60.0, 75.0]), np.radians(45.0), 0.0)
    np.testing.assert_allclose(doc["C"], ref.C, rtol=SAME_RTOL, atol=0)
    np.testing.assert_allclose(doc["K"], ref.K, rtol=SAME_RTOL, atol=SAME_RTOL * 1e6)
    np.testing.assert_allclose(doc["det_K"], ref.det_K, rtol=SAME_RTOL)


def test_printed_ks_is_selectable(capsys):
    _, out, _ = run(capsys, "stiffness", "--ks", "printed", "--json")
    doc = json.loads(out)
    assert doc["inputs"]["K_s_N_per_m"] == 0.697
    # Table 1: the arm is vertical, so s_4's compliance 1/K_s appears in C_zz
    assert doc["C"][2][2] > 1.0 / 0.697


def test_deflect_json_reports_both_units(capsys):
    status, out, _ = run(
        capsys, "deflect", *TABLE3_ARGS, "--force", "1", "2", "3", "--torque", "0.1", "0", "0",
        "--json",
    )  # fmt: skip
    assert status == 0
    doc = json.loads(out)
    w = np.array([1.0, 2.0, 3.0, 0.1, 0.0, 0.0])
    d = api.stiffness(np.radians([45.0, 60.0, 75.0]), np.radians(45.0), 0.0).deflection(w)
    for key, twist in (("M", d.M), ("platform", d.H)):
        part = doc[key]
        np.testing.assert_allclose(part["displacement_m"], twist[:3], rtol=SAME_RTOL)
        np.testing.assert_allclose(part["rotation_rad"], twist[3:], rtol=SAME_RTOL)
        np.testing.assert_allclose(
            part["displacement_mm"], 1e3 * np.array(part["displacement_m"]), rtol=1e-15
        )
        np.testing.assert_allclose(
            part["rotation_deg"], np.degrees(part["rotation_rad"]), rtol=1e-15
        )


def test_readable_outputs_name_their_units(capsys):
    _, out, _ = run(capsys, "stiffness")
    assert "det K" in out and "N^6/rad^3" in out and "mm" in out
    _, out, _ = run(capsys, "deflect", "--force", "1", "1", "1")
    assert "mm" in out and "deg" in out and "platform" in out


@pytest.mark.parametrize(
    "argv",
    [
        ["stiffness", "--alpha", "1", "2"],  # wrong count
        ["stiffness", "--alpha", "nan", "60", "60"],  # NaN
        ["stiffness", "--alpha4", "inf"],  # infinite
        ["stiffness", "--alpha", "90", "-90", "90"],  # unreachable pose
        ["stiffness", "--s4", "80"],  # beyond the 50 mm stroke
        ["stiffness", "--ks", "wrong"],  # unknown preset
        ["stiffness", "--backend", "nope"],  # unknown backend
        ["deflect", "--force", "1", "2"],  # wrong count
        ["deflect", "--torque", "a", "b", "c"],  # not numbers
        ["frobnicate"],  # unknown subcommand
        [],  # no subcommand
    ],
)
def test_bad_input_exits_2_with_one_line(capsys, argv):
    status, out, err = run(capsys, *argv)
    assert status == 2
    assert out == ""
    assert err.startswith("cahyman: error: ")
    assert err.count("\n") == 1


def test_help_exits_0(capsys):
    status, out, _ = run(capsys, "stiffness", "--help")
    assert status == 0
    assert "--alpha" in out


def _subprocess(*argv: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    return subprocess.run(
        [sys.executable, "-m", "cahyman_pin", *argv],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=env,
        timeout=120,
        check=False,
    )


def test_module_entry_point_in_a_subprocess():
    ok = _subprocess("stiffness", "--json")
    assert ok.returncode == 0, ok.stderr
    assert np.array(json.loads(ok.stdout)["K"]).shape == (6, 6)
    bad = _subprocess("stiffness", "--alpha", "90", "-90", "90")
    assert bad.returncode == 2
    assert bad.stderr.startswith("cahyman: error: ")
    assert "Traceback" not in bad.stderr
    assert bad.stderr.count("\n") == 1
