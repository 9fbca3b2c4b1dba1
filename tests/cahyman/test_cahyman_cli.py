"""Command line ``cahyman``: JSON output, unit conversions, exit status on bad input."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from helpers import REPO, closed_pipe_run

from cahyman_pin import api
from cahyman_pin.backends import registry
from cahyman_pin.cli import main

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
        ["stiffness", "--s4", "80"],  # beyond the 50 mm stroke
        ["stiffness", "--ks", "wrong"],  # unknown preset
        ["stiffness", "--backend", "nope"],  # unknown backend
        ["deflect", "--force", "1", "2"],  # wrong count
        ["deflect", "--torque", "a", "b", "c"],  # not numbers
        ["frobnicate"],  # unknown subcommand
    ],  # no subcommand: its commands listed too (tests/cli/test_cli_input.py)
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
    assert bad.returncode == 3  # unreachable pose: the computation failed
    assert bad.stderr.startswith("cahyman: error: ")
    assert "Traceback" not in bad.stderr
    assert bad.stderr.count("\n") == 1


# ------------------------------------------------------------------ exit status
@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (
            ["stiffness", "--alpha", "90", "-90", "90"],
            "plate cannot be assembled at alpha=[90, -90",
        ),
        # singular: cranks on couplers, refused by the assembly (branches meet there)
        (["stiffness", "--alpha", "0", "0", "0"], "a singular configuration"),
        (["stiffness", "--alpha", "0", "0", "0", "--backend", "consistent"], "singular"),
        # one whole angle: not all like radians, no note on stderr
        (["deflect", "--alpha", "0", "1e-7", "1e-7", "--force", "1", "0", "0"], "singular"),
    ],
)
def test_computation_failures_exit_3_with_one_line(capsys, argv, match):
    status, out, err = run(capsys, *argv)
    assert (status, out) == (3, "")
    assert err.startswith("cahyman: error: ") and err.count("\n") == 1
    assert match in err


def test_help_documents_exit_status_backends_and_defaults(capsys):
    status, out, _ = run(capsys, "stiffness", "--help")
    assert status == 0
    flat = " ".join(out.split())
    assert "{consistent,generic,published}" in flat and "(default: generic)" in flat
    assert "(default: assumed)" in flat
    assert "0 ok; 1 rank deficient (K does not exist); 2 bad input; 3 computation failed" in flat
    status, out, _ = run(capsys, "--help")
    assert status == 0 and "3 computation failed" in " ".join(out.split())


def test_version(capsys):
    import closedloop

    status, out, _ = run(capsys, "--version")
    assert (status, out) == (0, f"cahyman {closedloop.__version__}\n")


def test_negative_numbers_in_e_notation_are_values(capsys):
    status, out, err = run(
        capsys, "deflect", "--force", "0", "0", "-1e5", "--torque", "-.5", "0", "-2E-1", "--json"
    )
    assert (status, err) == (0, "")
    doc = json.loads(out)
    assert doc["wrench"] == {"force_N": [0.0, 0.0, -1e5], "torque_N_m": [-0.5, 0.0, -0.2]}
    status, _, err = run(capsys, "stiffness", "--alpha4", "-inf")
    assert status == 2 and "'-inf' is not a finite number" in err  # a value, refused as such


# ------------------------------------------------------------------ published backend
def test_published_backend_text_mode_names_its_coordinates(capsys):
    status, out, err = run(capsys, "stiffness", "--backend", "published")
    assert (status, err) == (0, "")
    assert "backend published" in out and "det K" in out
    assert "coordinates of the paper" in out and "at M, world axes" not in out


def test_published_backend_honours_ks_and_does_not_claim_world_axes(capsys):
    from cahyman_pin.backends.published import PublishedOptions, published_stiffness
    from cahyman_pin.params import K_S_ASSUMED, K_S_PRINTED

    docs = {}
    for ks in ("assumed", "printed"):
        status, out, _ = run(capsys, "stiffness", *TABLE3_ARGS, "--backend", "published",
                             "--ks", ks, "--json")  # fmt: skip
        assert status == 0
        docs[ks] = json.loads(out)
    assert docs["assumed"]["inputs"]["K_s_N_per_m"] == K_S_ASSUMED
    assert docs["printed"]["inputs"]["K_s_N_per_m"] == K_S_PRINTED
    pose = (np.radians([45.0, 60.0, 75.0]), np.radians(45.0), 0.0)
    # --ks printed is the paper's formulation exactly as printed (its defaults)
    np.testing.assert_allclose(
        docs["printed"]["C"], published_stiffness(*pose).C, rtol=SAME_RTOL, atol=0
    )
    # --ks assumed is the same formulation with K_s = 0.697e6 N/m, a different C
    assumed = published_stiffness(*pose, options=PublishedOptions(ks="params")).C
    np.testing.assert_allclose(docs["assumed"]["C"], assumed, rtol=SAME_RTOL, atol=0)
    assert not np.allclose(assumed, published_stiffness(*pose).C, rtol=1e-3)
    for doc in docs.values():
        assert doc["axes"] != "world" and "paper" in doc["axes"]
    status, out, _ = run(capsys, "stiffness", "--json")
    assert json.loads(out)["axes"] == "world"
    status, out, _ = run(capsys, "deflect", "--backend", "published", "--force", "1", "0", "0",
                         "--json")  # fmt: skip
    doc = json.loads(out)
    assert status == 0 and doc["axes"] != "world" and doc["units"].endswith(doc["axes"])
    assert "(plate), world axes" not in doc["units"]
    status, out, _ = run(capsys, "deflect", "--backend", "published", "--force", "1", "0", "0")
    assert status == 0 and "at M, world axes" not in out and "M_FT in the arm frame" in out


# ------------------------------------------------------------------ closed pipe
@pytest.mark.parametrize("argv", [["stiffness", "--json"], ["deflect", "--force", "1", "0", "0"]])
def test_closed_pipe_ends_quietly(argv):
    done = closed_pipe_run("cahyman_pin", *argv)
    assert (done.returncode, done.stderr) == (141, "")


# ------------------------------------------------------------------ report output folder
@pytest.mark.parametrize(
    ("out", "match"),
    [
        ("/proc/x", "--out '/proc/x': cannot create or write this folder"),
        ("{tmp}/file", "is a file; expected a folder"),
        ("{tmp}/file/sub", "cannot create or write this folder"),
    ],
)
def test_report_bad_out_is_one_line_before_any_work(capsys, tmp_path, monkeypatch, out, match):
    import cahyman_pin.cli.report as report

    def no_work(*args, **kwargs):
        raise AssertionError("the report was computed before the output folder was checked")

    monkeypatch.setattr(report, "build_report", no_work)
    (tmp_path / "file").write_text("")
    status, stdout, err = run(capsys, "report", "--out", out.format(tmp=tmp_path))
    assert (status, stdout) == (2, "")
    assert err.startswith("cahyman: error: ") and err.count("\n") == 1 and match in err


def test_rank_deficient_compliance_exits_1(capsys, monkeypatch):
    """A backend whose compliance has rank 3 (the planar four-bar's, at M): K does not
    exist, which ``cahyman stiffness`` prints (and says in JSON) and signals with status 1."""
    import closedloop as cl
    from cahyman_pin.model import closed_form_pose
    from closedloop import data

    clm = cl.load_model(data.path("fourbar.urdf"), data.path("fourbar.yaml"))
    planar = cl.compliance(cl.Configuration(clm, cl.assemble(clm, actuated=[0.3]).q), "P")

    def rigid(params, alpha, alpha4, s4):
        pose = closed_form_pose(alpha, alpha4, s4, params)
        return registry.BackendResult(C=planar.C, pose=pose, details={"compliance": planar})

    monkeypatch.setitem(registry._BACKENDS, "rigid", rigid)
    status, out, err = run(capsys, "stiffness", "--backend", "rigid")
    assert (status, err) == (1, "")
    assert "K does not exist: compliance rank 3 < 6" in out
    status, out, _ = run(capsys, "stiffness", "--backend", "rigid", "--json")
    doc = json.loads(out)
    assert (status, doc["K"], doc["rank"]) == (1, None, 3)


# ------------------------------------------------------------------ start-up
LAZY_MODULES = ("matplotlib", "cahyman_pin.paper.report", "cahyman_pin.cli.map",
                "cahyman_pin.cli.view", "cahyman_pin.sweep.engine", "cahyman_pin.paper.figures",
                "closedloop.viewer.viewer")  # fmt: skip


@pytest.mark.parametrize(
    "argv",
    [["stiffness", "--json"], ["deflect", "--force", "1", "0", "0"], ["--help"], ["--version"]],
)
def test_pose_subcommands_and_help_import_no_plotting_or_sweep_module(argv):
    code = (
        "import contextlib, io, sys\n"
        "from cahyman_pin.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    assert main({argv!r}) == 0\n"
        f"print(sorted(m for m in {LAZY_MODULES!r} if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=REPO, timeout=120, check=False)  # fmt: skip
    assert (done.returncode, done.stdout) == (0, "[]\n"), done.stderr


def test_help_lists_every_subcommand_without_importing_them(capsys):
    status, out, _ = run(capsys, "--help")
    assert status == 0
    for name in ("stiffness", "deflect", "report", "map", "view"):
        assert f"    {name}" in out
    status, out, _ = run(capsys, "map", "--help")  # the module itself when it is asked for
    assert status == 0 and "--param NAME=SPEC" in out


# ------------------------------------------------------------------ report parameters
def parameter_rows(markdown: str) -> dict[str, tuple[str, str]]:
    """name -> (value, source) of the report's parameter table (first, second, last cell)."""
    table = markdown.split("| parameter | value (SI) |", 1)[1].split("\n\n", 1)[0]
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in table.splitlines()[2:]]
    return {c[0]: (c[1], c[-1]) for c in cells}


def test_report_reads_a_parameter_file_and_states_the_sources(capsys, tmp_path, default_report):
    from cahyman_pin.params import DEFAULT_PARAMS

    # 1.6e-1: a YAML string; a: the default value, given: not "assumed"
    (tmp_path / "p.yaml").write_text("K_s: 0.697\nb: 0.09\nL: 1.6e-1\na: 0.2\n")
    out = tmp_path / "report"
    status, stdout, err = run(capsys, "report", "--params", str(tmp_path / "p.yaml"),
                              "--out", str(out))  # fmt: skip
    assert (status, err.count("error")) == (0, 0) and "report written" in stdout
    assert (out / "report.html").is_file()
    text = (out / "report.md").read_text()
    rows = parameter_rows(text)
    assert rows["b"] == ("0.09", "given") and rows["L"] == ("0.16", "given")
    assert rows["K_s"] == ("0.697", "given (the paper's printed value)")
    assert rows["a"] == ("0.2", "given")  # the default value, from the file
    assert rows["h"] == ("0.05", "assumed: the paper gives no dimensions")
    assert rows["K_T"] == ("4672", "paper")
    assert "ASSUMED" not in text.split("| a |")[1].split("\n")[0]
    assert f"the parameter file {str(tmp_path / 'p.yaml')!r}" in text
    text = (default_report[0] / "report.md").read_text()  # no --params
    rows = parameter_rows(text)
    assert rows["K_s"][0] == "697000"
    assert rows["K_s"][1].startswith("assumed: 0.697e6 N/m, the printed 0.697 N/m times 1e6")
    assert rows["b"][0] == "0.08" and rows["b"][1].startswith("assumed")
    assert "no parameter file" in text
    # the values reach the computations: the consistent and generic columns change
    assert (out / "report.md").read_text().split("## Tables")[1] != text.split("## Tables")[1]
    assert DEFAULT_PARAMS.b == 0.08


@pytest.mark.parametrize(
    ("content", "match"),
    [
        ("zz: 1\n", r"p.yaml': unknown CaHyMan parameter\(s\) \['zz'\]; expected some of"),
        ("b: abc\n", r"p.yaml': CaHyMan parameter b='abc' must be a real number"),
        ("b: -1\n", r"p.yaml': CaHyMan parameter b=-1 must be > 0"),
        ("- b\n", r"p.yaml': expected a mapping field -> value, got list"),
        ("b: [\n", r"p.yaml' is not valid YAML"),
    ],
)
def test_report_parameter_file_errors_exit_2_before_any_work(capsys, tmp_path, content, match):
    import re

    (tmp_path / "p.yaml").write_text(content)
    status, out, err = run(capsys, "report", "--params", str(tmp_path / "p.yaml"),
                           "--out", str(tmp_path / "r"))  # fmt: skip
    assert (status, out) == (2, "") and err.count("\n") == 1
    assert re.search(match, err), err
    assert not (tmp_path / "r").exists()  # nothing computed, nothing written


def test_report_missing_parameter_file(capsys, tmp_path):
    status, _, err = run(capsys, "report", "--params", str(tmp_path / "none.yaml"))
    assert status == 2 and "none.yaml' cannot be read: No such file or directory" in err


def test_view_bad_html_path_is_one_line_before_any_work(capsys, tmp_path, monkeypatch):
    import cahyman_pin.cli.view as view

    def no_work(*args, **kwargs):
        raise AssertionError("the model was built before the output path was checked")

    monkeypatch.setattr(view, "cahyman_model", no_work)
    status, out, err = run(capsys, "view", "--html", str(tmp_path / "none" / "v.html"))
    assert (status, out) == (2, "") and err.count("\n") == 1
    assert f"--html '{tmp_path / 'none' / 'v.html'}': folder" in err and "does not exist" in err


@pytest.mark.parametrize("command", [["stiffness"], ["view", "--html", "{tmp}/v.html"],
                                     ["modes", "--mass", "m_HQ=1"]])  # fmt: skip
def test_a_pose_outside_the_limits_names_no_option_cahyman_lacks(command, tmp_path, capsys):
    """A virtual joint's limits moved off its rest value 0 (the pose then assembles outside
    them): one line that names the joint and no --no-limits (cahyman has none)."""
    from cahyman_pin.model import cahyman_model
    from cahyman_pin.params import DEFAULT_PARAMS
    from cahyman_pin.urdf_builder import VIRTUAL_JOINTS

    params = DEFAULT_PARAMS.with_ks("assumed")  # the command's model (cached: the same)
    clm = cahyman_model(params.replace(m_HQ=1.0) if "modes" in command else params).clm
    i = clm.model.joints[clm.joint_id(VIRTUAL_JOINTS[0])].idx_q
    lower, upper = clm.model.lowerPositionLimit.copy(), clm.model.upperPositionLimit.copy()
    clm.model.lowerPositionLimit[i], clm.model.upperPositionLimit[i] = 0.001, 0.002
    try:
        code = main([c.format(tmp=tmp_path) for c in command])
    finally:
        clm.model.lowerPositionLimit, clm.model.upperPositionLimit = lower, upper
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    assert "joints outside their limits" in err and VIRTUAL_JOINTS[0] in err, err
    assert "--no-limits" not in err and "check_limits" not in err, err


@pytest.mark.parametrize("command", ["stiffness", "deflect", "modes"])
def test_alpha_values_that_look_like_radians_get_a_note(capsys, command):
    """--alpha 0.785 1.047 1.309 (45, 60, 75 deg in radians) ran at under 1 deg without a
    word; it still runs, in degrees, with a one-line note."""
    extra = ["--mass", "m_M4=1"] if command == "modes" else []
    status, out, err = run(capsys, command, "--alpha", "0.785", "1.047", "1.309", *extra)
    assert status in (0, 1) and out
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("cahyman: warning: --alpha 0.785 1.047 "
                                                   "1.309"), err  # fmt: skip
    assert "degrees" in lines[0]


@pytest.mark.parametrize("alpha", [["45", "60", "75"], ["0", "0.5", "1"], ["0.5", "1.5", "7"]])
def test_alpha_values_in_degrees_get_no_note(capsys, alpha):
    """A whole number or a value beyond 2 pi among them: degrees, no note."""
    _, _, err = run(capsys, "stiffness", "--alpha", *alpha)
    assert "warning" not in err, err


def test_a_map_of_alpha_values_that_look_like_radians_gets_the_note(capsys, tmp_path):
    status, _, err = run(capsys, "map", "--alpha", "0.6,0.8,1.2", "--out", str(tmp_path / "m"))
    assert status == 0
    assert "cahyman: warning: --alpha 0.6 0.8 1.2: every value is below 2 pi" in err, err
