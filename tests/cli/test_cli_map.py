"""``closedloop map`` and ``closedloop identify`` from the command line."""

import json
import logging
import subprocess
import sys

import numpy as np
import pytest

import closedloop as cl
from closedloop.cli.app import main

CRANKS = np.linspace(0.2, 1.4, 5)
#: The map's poses (each assembled from its neighbour) against those assembled here: both
#: close the loop to the assembly tolerance (1e-12 L), the passive joints then to about
#: 5e-12 rad, which moves C and its indices by about as much relative (measured 2.2e-13):
#: as tests/analysis/test_maps.py's chunks, 1e-9.
ASSEMBLED_RTOL = 1e-9


def test_map_of_the_fourbar(tmp_path, fourbar_urdf, fourbar_yaml, capsys):
    out = tmp_path / "map"
    code = main(["map", str(fourbar_urdf), "--closures", str(fourbar_yaml), "--frame", "P",
                 "--sweep", "crank=0.2:1.4:5", "--index", "min_translational",
                 "--force", "3", "0", "-2", "--out", str(out)])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "5 points: 5 rank_deficient" in captured.out
    assert "about" in captured.err and "map points: 5/5" in captured.err  # estimate, progress
    data = np.load(out / "map.npz")
    np.testing.assert_allclose(data["crank"], CRANKS, rtol=1e-15)
    clm = cl.load_model(fourbar_urdf, fourbar_yaml)
    q = clm.reference_configuration()
    for i, crank in enumerate(CRANKS):
        q = cl.assemble(clm, actuated=[crank], q0=q).q
        res = cl.StiffnessIndices.from_result(cl.compliance(clm, q, "P"))
        np.testing.assert_allclose(data["min_translational"][i],
                                   res.min_translational_stiffness.value,
                                   rtol=ASSEMBLED_RTOL)  # fmt: skip
    assert (out / "map.png").stat().st_size > 10_000 and (out / "map.csv").exists()


def test_map_sweep_takes_a_list_of_values(tmp_path, fourbar_urdf, fourbar_yaml, capsys):
    """JOINT=V1,V2,... (the value forms of cahyman map): the same map as START:STOP:NUM."""
    base = ["map", str(fourbar_urdf), "--closures", str(fourbar_yaml), "--frame", "P"]
    assert main([*base, "--sweep", "crank=0.2:1.4:5", "--out", str(tmp_path / "a")]) == 0
    listed = ",".join(repr(float(c)) for c in CRANKS)
    assert main([*base, "--sweep", f"crank={listed}", "--out", str(tmp_path / "b")]) == 0
    capsys.readouterr()
    a, b = np.load(tmp_path / "a" / "map.npz"), np.load(tmp_path / "b" / "map.npz")
    np.testing.assert_array_equal(a["crank"], b["crank"])
    np.testing.assert_array_equal(a["det_K"], b["det_K"])


def test_map_errors_are_one_line(tmp_path, fourbar_urdf, fourbar_yaml, capsys):
    base = ["map", str(fourbar_urdf), "--closures", str(fourbar_yaml), "--frame", "P"]
    (tmp_path / "file").write_text("")
    (tmp_path / "nan.txt").write_text("0.5\nnan\n")
    (tmp_path / "inf.txt").write_text("0.5, 0.7\n-inf\n")
    (tmp_path / "grouped.txt").write_text("0.5\n0_7\n")  # Python's float() reads 0.7
    for extra, match in (
        (["--points", str(tmp_path / "nan.txt")], "finite actuated values (['crank']), got row 1 "
         "is [nan]"),
        (["--points", str(tmp_path / "inf.txt")], "expected rows of numbers"),
        (["--points", str(tmp_path / "grouped.txt")], "expected rows of numbers"),
        (["--sweep", "crank=0_1:1:3"], "'0_1' is not a number"),
        (["--sweep", "crank=0:1:3", "--fixed", "x=\u0663"], "'\u0663' is not a number"),
        (["--sweep", "crank=0.1,0.1"], "the values of swept joint 'crank' must be distinct"),
        (["--sweep", "crank=0:1:3", "--chunk", "0"], "--chunk: '0': expected an integer >= 1"),
        (["--sweep", "crank=0:1:3", "--workers", "0"], "--workers: '0': expected an integer"),
        (["--sweep", "crank=0:1"], "'0:1' is not START:STOP:NUM (numbers, NUM an integer)"),
        (["--sweep", "0:1:3"], "expected JOINT=START:STOP:NUM"),
        (["--sweep", "crank=0:nan:3"], "has non-finite values"),
        (["--sweep", "crank=0:1:3", "--fixed", "x=nan"], "is not a finite number"),
        (["--sweep", "crank=0:1:3", "--force", "0", "1e999", "0"], "beyond the floating point"),
        (["--sweep", "nope=0:1:3"], "'nope' is not an actuated joint"),
        (["--sweep", "crank=0:1:3", "--out", str(tmp_path / "file")], "is a file"),
        (["--sweep", "crank=0:1:3", "--scheduler", "tcp://127.0.0.1:9"],
         "cannot reach the Dask scheduler"),
    ):  # fmt: skip
        code = main([*base, *extra])
        err = capsys.readouterr().err
        last = err.strip().splitlines()[-1]  # argparse puts its usage lines first
        assert code == 2 and match in last and "Traceback" not in err, (extra, err)


def test_map_on_a_dask_cluster_equals_the_serial_map(tmp_path, fourbar_urdf, fourbar_yaml):
    from dask.distributed import LocalCluster

    args = ["map", str(fourbar_urdf), "--closures", str(fourbar_yaml), "--frame", "P",
            "--sweep", "crank=0.2:1.4:7", "--chunk", "2"]  # fmt: skip
    assert main([*args, "--out", str(tmp_path / "serial")]) == 0
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None, silence_logs=logging.ERROR) as cluster:  # fmt: skip
        assert main([*args, "--scheduler", cluster.scheduler_address,
                     "--out", str(tmp_path / "dask")]) == 0  # fmt: skip
    a, b = np.load(tmp_path / "serial/map.npz"), np.load(tmp_path / "dask/map.npz")
    for key in a.files:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_identify_from_the_command_line(tmp_path, fourbar_urdf, fourbar_yaml, capsys):
    clm = cl.load_model(fourbar_urdf, fourbar_yaml)
    rng = np.random.default_rng(2)
    lines = ["frame: P", "measurements:"]
    for crank in (0.3, 0.8, 1.3):
        q = cl.assemble(clm, actuated=[crank]).q
        C = cl.compliance(clm, q, "P").C
        for w in 10 * rng.normal(size=(2, 6)):
            lines += [f"  - q: {q.tolist()}", f"    wrench: {w.tolist()}",
                      f"    twist: {(C @ w).tolist()}", "    sd: 1e-7"]  # fmt: skip
    (tmp_path / "m.yaml").write_text("\n".join(lines) + "\n")
    (tmp_path / "k.yaml").write_text("crank: 20\ncrank_axial: 3e5\nrocker_axial: 1e5\n")
    out = subprocess.run(
        [sys.executable, "-m", "closedloop", "identify", str(fourbar_urdf), "--closures",
         str(fourbar_yaml), "--springs", str(tmp_path / "k.yaml"), "--measurements",
         str(tmp_path / "m.yaml"), "--fit", "crank", "crank_axial", "rocker_axial", "--json"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert doc["n_measurements"] == 6 and doc["unidentifiable"] == []
    for name, value in (("crank", 50.0), ("crank_axial", 1e5), ("rocker_axial", 2e5)):
        np.testing.assert_allclose(doc["estimates"][name], value, rtol=1e-6)
    assert set(doc) >= {"estimates", "std_errors", "unidentifiable", "residual_rms"}
    tied = [
        "identify",
        str(fourbar_urdf),
        "--closures",
        str(fourbar_yaml),
        "--measurements",
        str(tmp_path / "m.yaml"),
        "--fit",
        "crank",
        "crank_axial+rocker_axial",
        "--json",
    ]
    assert main(tied) == 1  # one value for springs of 1e5 and 2e5 N/m: the model misfits
    out, err = capsys.readouterr()
    doc = json.loads(out)
    assert "crank_axial+rocker_axial" in doc["estimates"] and doc["consistent"] is False
    assert "the model does not fit the data" in err


@pytest.mark.parametrize(
    ("content", "match"),
    [("frame: P\nmeasurements: []\n", "'measurements' must be a non-empty list"),
     ("frame: P\nmeasurements:\n  - {q: [0], wrench: [1, 2], twist: [0,0,0,0,0,0], sd: 1}\n",
      "measurement 0 of")],
)  # fmt: skip
def test_identify_bad_measurement_files(tmp_path, fourbar_urdf, fourbar_yaml, capsys,
                                        content, match):  # fmt: skip
    (tmp_path / "m.yaml").write_text(content)
    code = main(["identify", str(fourbar_urdf), "--closures", str(fourbar_yaml),
                 "--measurements", str(tmp_path / "m.yaml"), "--fit", "crank"])  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2 and match in err and "Traceback" not in err


def test_map_no_limits_computes_the_points_outside_the_limits(tmp_path, fourbar_urdf,
                                                               fourbar_yaml, capsys):  # fmt: skip
    """Cranks of 6.5 and 7 rad (its limit 6.3): invalid, or with --no-limits computed, and
    the same as a whole turn less (the crank turns fully: the same mechanism)."""
    base = ["map", str(fourbar_urdf), "--closures", str(fourbar_yaml), "--frame", "P",
            "--index", "min_translational", "--force", "3", "0", "-2"]  # fmt: skip
    assert main([*base, "--sweep", "crank=6.0,6.5,7.0", "--out", str(tmp_path / "a")]) == 0
    assert "3 points: 2 invalid, 1 rank_deficient" in capsys.readouterr().out
    assert main([*base, "--sweep", "crank=6.0,6.5,7.0", "--no-limits",
                 "--out", str(tmp_path / "b")]) == 0  # fmt: skip
    assert "3 points: 3 rank_deficient" in capsys.readouterr().out
    turned = ",".join(repr(c - 2 * np.pi) for c in (6.0, 6.5, 7.0))
    assert main([*base, "--sweep", f"crank={turned}", "--out", str(tmp_path / "c")]) == 0
    capsys.readouterr()
    b, c = np.load(tmp_path / "b" / "map.npz"), np.load(tmp_path / "c" / "map.npz")
    # two assemblies to 1e-12 of one pose (angles 2 pi apart: rounding 1e-15): 1e-9 holds
    np.testing.assert_allclose(b["min_translational"], c["min_translational"], rtol=1e-9)
