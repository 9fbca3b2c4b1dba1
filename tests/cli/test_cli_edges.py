"""Edges of both command lines: each bad input is one line naming the bad value, a
non-zero exit, no traceback, checked before any work; never exit 0 with a wrong answer."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time

import numpy as np
import pytest
from helpers import REPO, UR5_JOINTS, UR5_Q
from helpers import one_error_line as one_line

import closedloop as cl
import closedloop.cli.map as cli_map
from cahyman_pin.api import stiffness
from cahyman_pin.cli import main as cahyman_main
from cahyman_pin.params import DEFAULT_PARAMS
from cahyman_pin.sweep import grid, sweep
from closedloop.analysis.maps import grid_points
from closedloop.analysis.measurements import read_measurements
from closedloop.cli.app import main
from closedloop.cli.map_options import MAX_MAP_POINTS, index_line
from closedloop.elastostatics.compliance import energy_shares
from closedloop.exceptions import InvalidInputError

UR5 = ["stiffness", "ur5", "--frame", "tool0", "--q", *map(str, UR5_Q), "--joint-stiffness"]
#: A probe's estimate and the map's own time agree within this factor (the probe is a
#: few hundred points; a loaded machine slows both).
ESTIMATE_FACTOR = 5.0


def run(entry, capsys, *argv) -> tuple[int, str, str]:
    code = entry([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def fourbar_map(tmp_path, *extra) -> list:
    return ["map", "fourbar", "--frame", "P", *extra, "--out", tmp_path / "out"]


# ------------------------------------------------------------------ maps
@pytest.mark.parametrize("address", ["notanaddress", "tcp://host:x", "tls://host:", "foo://host:1"])
def test_a_scheduler_address_without_port_is_one_line(tmp_path, capsys, address):
    """Refused before any Dask client exists (a client left half started by a malformed
    address blocked the next one's start)."""
    code, _, err = run(main, capsys, *fourbar_map(tmp_path, "--sweep", "crank=0:1:3",
                                                  "--scheduler", address))  # fmt: skip
    assert code == 2 and f"--scheduler {address!r} is not a Dask address" in one_line(err)
    code, _, err = run(cahyman_main, capsys, "map", "--alpha", "30:90:5", "--scheduler",
                       address, "--out", tmp_path / "c")  # fmt: skip
    assert code == 2 and f"--scheduler {address!r}" in one_line(err, "cahyman")


@pytest.mark.parametrize(("content", "match"), [(b"\xff\xfe\x00", "not a text file"),
                                                (b"\n  \n", "has no points")])  # fmt: skip
def test_a_points_file_that_is_not_text_or_empty_is_one_line(tmp_path, capsys, content, match):
    (tmp_path / "p.txt").write_bytes(content)
    code, _, err = run(main, capsys, *fourbar_map(tmp_path, "--points", tmp_path / "p.txt"))
    line = one_line(err)
    assert code == 2 and "p.txt" in line and match in line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("extra", "match"),
    [(["--sweep", "crank=0:1:3", "--sweep", "crank=0.5:0.7:3"], "--sweep crank=... given 2 times"),
     (["--sweep", "crank=0:1:3", "--fixed", "crank=5"], "--fixed crank=5: joint 'crank' is swept"),
     (["--points", "POINTS", "--fixed", "crank=5"], "--fixed crank=5 with --points"),
     (["--sweep", "crank=0:1:3", "--index", "deflection_translation"],
      "--index deflection_translation needs --force and/or --torque"),
     (["--sweep", f"crank=0:1:{MAX_MAP_POINTS + 1}"],
      f"NUM must be from 1 to {MAX_MAP_POINTS}")],
)  # fmt: skip
def test_map_options_that_would_be_ignored_are_refused_before_any_work(
    tmp_path, capsys, monkeypatch, extra, match
):
    def no_map(*args, **kwargs):
        raise AssertionError("a map ran before its options were checked")

    monkeypatch.setattr(cli_map, "stiffness_map", no_map)
    (tmp_path / "p.txt").write_text("0.5\n0.7\n")
    extra = [str(tmp_path / "p.txt") if a == "POINTS" else a for a in extra]
    code, out, err = run(main, capsys, *fourbar_map(tmp_path, *extra))
    assert code == 2 and match in one_line(err) and out == ""
    assert not (tmp_path / "out").exists()  # no empty output folder left behind


def test_cahyman_map_refuses_a_chunk_size_of_zero(tmp_path, capsys):
    code, _, err = run(cahyman_main, capsys, "map", "--alpha", "30:90:5", "--chunk-size", "0",
                       "--workers", "1", "--out", tmp_path)  # fmt: skip
    assert code == 2 and "--chunk-size: '0': expected an integer >= 1" in one_line(err, "cahyman")
    pts = grid({"alpha": np.deg2rad([40.0, 50.0])}, alpha4=0.5, s4=0.02, params=DEFAULT_PARAMS)
    with pytest.raises(InvalidInputError, match="chunk_size must be a positive integer, got 0"):
        sweep(pts, executor="serial", chunk_size=0)


def test_the_first_points_of_a_grid_without_building_it(ur5_urdf, monkeypatch):
    clm = cl.load_model(ur5_urdf, joint_stiffness=1e4)
    sweeps = {UR5_JOINTS[1]: np.linspace(-1, 1, 1000), UR5_JOINTS[2]: np.linspace(0, 2, 1000)}
    fixed = {n: 0.1 for n in UR5_JOINTS if n not in sweeps}
    full = grid_points(clm, sweeps, fixed)[0]
    built = []

    def counting(clm, sweeps, fixed):
        built.append(int(np.prod([len(v) for v in sweeps.values()])))
        return grid_points(clm, sweeps, fixed)

    monkeypatch.setattr(cl.analysis.maps, "grid_points", counting)
    for k in (3, 30, 2500):
        np.testing.assert_array_equal(cli_map._first(clm, {"sweeps": sweeps, "fixed": fixed}, k),
                                      full[:k])  # fmt: skip
    assert built == [1000, 1000, 3000]  # the rows holding the first k points, not 10^6


def test_the_estimate_of_a_long_map_is_its_time(tmp_path, capsys):
    t0 = time.perf_counter()
    code, _, err = run(main, capsys, *fourbar_map(tmp_path, "--sweep", "crank=0.2:1.4:20000"))
    elapsed = time.perf_counter() - t0
    assert code == 0, err
    estimate = float(re.search(r"20000 points, about (\S+) s", err).group(1))
    assert elapsed / ESTIMATE_FACTOR < estimate < ESTIMATE_FACTOR * elapsed, (estimate, elapsed)


def test_a_map_without_any_value_says_so(tmp_path, capsys):
    code, out, err = run(main, capsys, *fourbar_map(tmp_path, "--sweep", "crank=0.2:1.4:3"))
    assert code == 0, err
    assert "det_K: no value at any of the 3 points (the plot is empty)" in out


def test_the_index_line_counts_the_points_without_a_value():
    assert index_line("det_K", np.array([2.0, np.nan, 1.0]), "N") == (
        "det_K: min 1, max 2 [N] (1 points without a value)"
    )
    assert index_line("det_K", np.array([2.0, 1.0]), "N") == "det_K: min 1, max 2 [N]"


# ------------------------------------------------------------------ identification
def _measurements(path, wrench=None, sd=None):
    """Four exact four-bar measurements; measurement 1 with ``wrench`` and ``sd``."""
    clm = cl.load_model(cl.data.path("fourbar.urdf"), cl.data.path("fourbar.yaml"))
    rng = np.random.default_rng(0)
    lines = ["frame: P", "measurements:"]
    for i, crank in enumerate((0.3, 0.3, 0.8, 0.8)):
        q = cl.assemble(clm, actuated=[crank]).q
        w = 10 * rng.normal(size=6)
        d = cl.compliance(clm, q, "P").C @ w
        lines += [f"  - q: {q.tolist()}", f"    twist: {d.tolist()}",
                  f"    wrench: {wrench if i == 1 and wrench else w.tolist()}",
                  f"    sd: {sd if i == 1 and sd else '1e-7'}"]  # fmt: skip
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize(
    ("wrench", "sd", "match"),
    [("[1e308, 1e308, 1e308, 1e308, 1e308, 1e308]", None,
      "measurement 1: its weighted deflection (C w - d) / sd overflows (wrench [1e+308"),
     (None, "1e-308", "measurement 1: its weighted deflection (C w - d) / sd reaches")],
)  # fmt: skip
@pytest.mark.parametrize("json", [[], ["--json"]])
def test_measurements_that_overflow_are_named(tmp_path, capsys, wrench, sd, match, json):
    path = _measurements(tmp_path / "m.yaml", wrench, sd)
    code, out, err = run(main, capsys, "identify", "fourbar", "--measurements", path, "--fit",
                         "crank", "crank_axial", "rocker_axial", *json)  # fmt: skip
    line = one_line(err)
    assert code == 2 and match in line and out == "", line
    assert sd is None or "sd [1e-308" in line


def test_a_csv_file_with_a_header_only_says_it_has_no_rows(tmp_path):
    (tmp_path / "m.csv").write_text("frame,q_0,fx,fy,fz,nx,ny,nz,dx,dy,dz,rx,ry,rz,sd\n")
    with pytest.raises(cl.ModelFileError, match="has a header and no measurement rows"):
        read_measurements(tmp_path / "m.csv")


# ------------------------------------------------------------------ stiffness
@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full (Linux)")
@pytest.mark.parametrize(
    ("module", "argv"),
    [("closedloop", [*UR5, "1e4"]), ("cahyman_pin", ["stiffness", "--json"]),
     ("closedloop", ["--version"])],
)  # fmt: skip
def test_a_full_stdout_is_one_line_and_a_failure(module, argv):
    with open("/dev/full", "w") as full:
        done = subprocess.run([sys.executable, "-m", module, *argv], stdout=full,
                              stderr=subprocess.PIPE, text=True, timeout=120, cwd=REPO,
                              env={**os.environ, "PYTHONPATH": str(REPO)})  # fmt: skip
    prog = "cahyman" if module == "cahyman_pin" else "closedloop"
    assert done.returncode == 3
    assert "cannot write the output (No space left on device)" in one_line(done.stderr, prog)


def test_matrices_keep_a_separator_at_three_digit_exponents(capsys):
    code, out, err = run(main, capsys, *UR5, "1e300")
    assert code == 0, err
    rows = [ln.split() for ln in out.splitlines() if re.match(r"  (d|r|f|n)[x-z] ", ln)]
    assert len(rows) == 12 and all(len(r) == 7 for r in rows), out
    assert all(abs(float(v)) < 1e-290 or abs(float(v)) > 1e-20 for r in rows for v in r[1:])


def test_energy_shares_of_a_huge_wrench_are_finite(capsys):
    code, out, err = run(main, capsys, *UR5, "1e4", "--wrench", "1e200", 0, 0, 0, 0, 0)
    shares = [float(m) for m in re.findall(r"energy share\s+(\S+)%", out)]
    assert code == 0 and len(shares) == 6, (out, err)
    assert np.all(np.isfinite(shares)) and sum(shares) == pytest.approx(100.0, abs=0.05)


def test_a_wrench_along_the_rigid_directions_has_no_energy_shares(capsys, ur5):
    """At q = 0 the UR5's tool0 cannot roll about x (rank 5). A moment along that rigid
    direction does work of rounding only (w^T C w ~ 1e-26 against 1e-4): its shares were
    rounding split by joint (100 % in wrist_2); now none, and the command says why. A
    small part off the rigid direction has shares again, summing to 1."""
    clm = ur5[0]
    res = cl.compliance(clm, np.zeros(6), "tool0")
    assert res.rank == 5
    rigid = res.rigid_directions[:, 0]
    assert energy_shares(clm, res, 3.0 * rigid) == {}
    off = np.array([0.0, 0.0, 1e-3, 0.0, 0.0, 0.0])  # N, along a compliant direction
    shares = energy_shares(clm, res, rigid + off)
    assert shares and sum(shares.values()) == pytest.approx(1.0, abs=1e-9)
    argv = ["stiffness", "ur5", "--frame", "tool0", "--joint-stiffness", "1e4", "--wrench"]
    code, out, err = run(main, capsys, *argv, *map(str, rigid))
    assert code == 1, err  # rank deficient
    assert "energy share " not in out and "energy shares: none" in out
    code, out, _ = run(main, capsys, *argv, *map(str, rigid), "--json")
    assert json.loads(out)["energy_shares"] == {}


def test_a_mass_given_twice_is_refused(capsys):
    """The last value was taken silently."""
    code, out, err = run(cahyman_main, capsys, "stiffness", "--gravity", "--mass", "m_M4=2",
                         "--mass", "m_M4=3")  # fmt: skip
    assert (code, out) == (2, "")
    assert "--mass m_M4 given twice (2 and 3 kg)" in one_line(err, "cahyman")


def test_energy_shares_are_refused_under_a_preload(capsys, ur5):
    """Under a preload the shares of the springs summed to 0.297 (the preload's own energy
    terms are not split), printed as if they were the whole; now refused, from the API
    and from the command line (before any computation)."""
    clm = ur5[0]
    res = cl.compliance(clm, UR5_Q, "tool0", preload=[0.0, 0.0, 3e4, 0.0, 0.0, 0.0])
    with pytest.raises(InvalidInputError, match="energy of an unloaded compliance"):
        energy_shares(clm, res, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    for extra in (["--preload", "0", "0", "3e4", "0", "0", "0"], ["--gravity"]):
        code, out, err = run(main, capsys, *UR5, "1e4", "--wrench", "1", "0", "0", "0", "0",
                             "0", *extra)  # fmt: skip
        assert (code, out) == (2, "")
        assert "--wrench splits the deflection energy of the unloaded compliance" in err


def test_an_unknown_path_is_refused_with_a_preload_too(ur5):
    clm = ur5[0]
    for kwargs in ({"gravity": (0.0, 0.0, -9.81)}, {"preload": [1.0, 0, 0, 0, 0, 0]}):
        with pytest.raises(InvalidInputError, match=r"path 'bogus'; expected one of"):
            cl.compliance(clm, UR5_Q, "tool0", path="bogus", **kwargs)


@pytest.mark.parametrize("command", ["stiffness", "deflect"])
def test_cahyman_masses_without_gravity_are_refused(capsys, command):
    code, out, err = run(cahyman_main, capsys, command, "--mass", "m_M4=100", "--json")
    assert code == 2 and out == ""
    assert "--mass m_M4=100 weighs nothing without --gravity" in one_line(err, "cahyman")


@pytest.mark.parametrize(
    ("text", "code", "match"),
    [("s4_max: 0.01\n", 2, "s4_max = 0.01 m: the paper's poses"),
     ("K_T: 1.0e60\n", 3, "span 1.1e+57 (scaled: k L^2 for prismatic joints, L = 0.359 m), from")],
)  # fmt: skip
def test_report_parameters_it_cannot_use_leave_no_output(tmp_path, capsys, text, code, match):
    """A stroke too short for the paper's poses is refused before any work; torsion springs
    too far from the others for the statics of the weight fail: one line each (the NaN
    cells printed numpy's warnings), and no folder or figure of the run is left (a tornado
    figure was)."""
    (tmp_path / "p.yaml").write_text(text)
    status, _, err = run(cahyman_main, capsys, "report", "--params", tmp_path / "p.yaml",
                         "--out", tmp_path / "out")  # fmt: skip
    assert status == code and match in one_line(err, "cahyman")
    assert not (tmp_path / "out").exists()


def test_a_map_refused_after_its_folder_was_made_leaves_none(tmp_path, capsys):
    code, _, err = run(main, capsys, *fourbar_map(tmp_path, "--sweep", "nojoint=0.2:2.8:5"))
    assert code == 2 and "'nojoint' is not an actuated joint" in one_line(err)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", ["stiffness", "deflect"])
def test_cahyman_weight_beyond_what_the_springs_hold_is_refused(capsys, command):
    """The arm upright is an inverted pendulum: 3000 kg at M (m g 0.2 m > K_T4) leaves the
    symmetric equilibrium unstable; it was printed with exit 0 and a negative condition
    number of K."""
    code, out, err = run(cahyman_main, capsys, command, "--gravity", "--mass", "m_M4=3000")
    assert code == 3 and out == ""
    assert "is unstable (stability margin -1.55 <= 0" in one_line(err, "cahyman")
    api = cl_api_stiffness(3000.0)
    lam = np.abs(np.linalg.eigvalsh(api.K))
    assert api.condition_number == pytest.approx(lam.max() / lam.min(), rel=1e-12)


def test_cahyman_warnings_are_one_line_each(capsys):
    """The joint-limit warning of a huge weight, before the error: one line each, no
    Python source line."""
    code, _, err = run(cahyman_main, capsys, "stiffness", "--gravity", "--mass", "m_M4=1e6")
    lines = err.strip().splitlines()
    assert code == 3 and len(lines) == 2, err
    assert lines[0].startswith("cahyman: warning: the equilibrium") and "outside the joint" in err
    assert lines[1].startswith("cahyman: error: ")


def cl_api_stiffness(mass: float):
    """CaHyMan's stiffness at the default pose of the command line under the weight of
    ``mass`` [kg] at M (the API returns an unstable equilibrium, flagged)."""

    params = DEFAULT_PARAMS.replace(m_M4=mass)
    return stiffness(np.deg2rad([90.0, 90.0, 90.0]), np.deg2rad(90.0), 0.05, params=params,
                     weight=True)  # fmt: skip


# ------------------------------------------------------------------ views
@pytest.mark.parametrize(
    ("entry", "argv"),
    [(main, ["view", "fourbar", "--frame", "P", "--actuated", "0.3", "--force", 1, 0, 0,
             "--scale", "1e200"]),
     (main, ["view", "fourbar", "--frame", "P", "--actuated", "0.3", "--force", "1e300", 0, 0,
             "--scale", "1"]),
     (cahyman_main, ["view", "--force", 1, 0, 0, "--scale", "1e308"])],
)  # fmt: skip
def test_a_scale_that_draws_beyond_the_model_is_refused(tmp_path, capsys, entry, argv):
    html = tmp_path / "page.html"
    code, out, err = run(entry, capsys, *argv, "--html", html)
    line = one_line(err, "closedloop" if entry is main else "cahyman")
    assert code == 2 and out == "" and not html.exists()
    assert line.count("--scale") == 1 and "more than 100 model sizes" in line and len(line) < 300


@pytest.mark.parametrize(
    ("entry", "argv"),
    [(main, ["view", "fourbar", "--frame", "P", "--actuated", "0.3"]), (cahyman_main, ["view"])],
)
def test_duration_with_html_is_refused(tmp_path, capsys, entry, argv):
    html = tmp_path / "page.html"
    code, out, err = run(entry, capsys, *argv, "--duration", "3", "--html", html)
    line = one_line(err, "closedloop" if entry is main else "cahyman")
    assert code == 2 and out == "" and not html.exists()
    assert "--duration 3 serves the live page" in line


@pytest.mark.parametrize("value", ["100", "1e+308"])
@pytest.mark.parametrize("command", ["stiffness", "view"])
def test_actuated_values_outside_their_limits_are_refused_as_a_map_marks_them(
    capsys, tmp_path, command, value
):
    """``--actuated 100`` (crank limits +-6.3 rad) answered, while a map marks the same
    point invalid with the same reason: now one line, exit 2, as the map's reason. At
    1e308 the count of input steps to drive there overflowed (OverflowError)."""
    extra = ["--html", str(tmp_path / "v.html")] if command == "view" else []
    code, out, err = run(main, capsys, command, "fourbar", "--frame", "P", "--actuated", value,
                         *extra)  # fmt: skip
    assert (code, out) == (2, "")
    reason = f"actuated joints outside their limits: crank = {value} (limits [-6.3, 6.3])"
    assert reason in one_line(err)
    code, _out, err = run(main, capsys, "map", "fourbar", "--frame", "P", "--sweep",
                          f"crank={value}", "--workers", "1",
                          "--out", str(tmp_path / "m"))  # fmt: skip
    assert code == 0, err
    reasons = np.load(tmp_path / "m" / "map.npz")["reasons"]
    assert any(reason in str(r) for r in reasons), reasons
    code, out, err = run(main, capsys, command, "fourbar", "--frame", "P", "--actuated", "1", "2",
                         *extra)  # fmt: skip
    assert (code, out) == (2, "")
    assert "2 actuated values given; expected 1 for joints ['crank']" in one_line(err)


def test_a_frame_that_no_wrench_moves_reports_no_condition_number(capsys):
    """At the UR5's base C = 0 (rank 0): the text read 'condition number of the scaled K
    1.000e+00', a perfectly conditioned K that does not exist."""
    code, out, _ = run(main, capsys, "stiffness", "ur5", "--frame", "base_link",
                       "--joint-stiffness", "1e4")  # fmt: skip
    assert code == 1 and "rank of C 0/6" in out
    assert "condition number of the scaled K: none (C = 0: no wrench moves the frame)" in out
    code, out, _ = run(main, capsys, "stiffness", "fourbar", "--frame", "P", "--actuated", "0.3")
    assert code == 1 and re.search(r"scaled K \S+ over the rank of C \(lengths per L", out)


def test_results_beyond_the_float_range_are_refused_as_text_too(capsys):
    """1e308 N at M with the printed spring: the displacement of M is 1.4e308 m, 1.4e311 mm
    (inf). The JSON refused it; the text printed inf and exited 0."""
    args = ("deflect", "--ks", "printed", "--force", "1e308", "1e308", "1e308")
    for extra in ((), ("--json",)):
        code, out, err = run(cahyman_main, capsys, *args, *extra)
        assert code == 3 and out == ""
        assert "the result is not finite at M.displacement_mm[2]" in one_line(err, "cahyman")


def test_deflections_of_the_published_backend_say_their_coordinates(capsys):
    """Its twists are in the paper's coordinates (H's z rises under a downward force); the
    text labelled them as the world-axes twists of the other backends."""
    code, out, _ = run(cahyman_main, capsys, "deflect", "--backend", "published",
                       "--force", "0", "0", "-100")  # fmt: skip
    assert code == 0 and "the twists below are in the coordinates of the paper" in out
    code, out, _ = run(cahyman_main, capsys, "deflect", "--force", "0", "0", "-100")
    assert code == 0 and "the twists below" not in out and "at M, world axes" in out


def test_gravity_without_any_mass_warns(capsys):
    """Every mass is 0 by default: --gravity alone gives a zero sag, now with a warning
    (--mass without --gravity was already an error)."""
    code, _, err = run(cahyman_main, capsys, "stiffness", "--gravity")
    assert code == 0 and "cahyman: warning: --gravity: every mass is 0" in err
    code, _, err = run(cahyman_main, capsys, "stiffness", "--gravity", "--mass", "m_b=0.2")
    assert code == 0 and err == ""
