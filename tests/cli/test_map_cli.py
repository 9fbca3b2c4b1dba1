"""``cahyman map``: files written, paper units converted, bad input refused on one line."""

from __future__ import annotations

import numpy as np
import pytest

from cahyman_pin.cli import main
from cahyman_pin.cli.map import parse_values
from cahyman_pin.params import DEFAULT_PARAMS
from cahyman_pin.sweep import SweepResult, grid, sweep

#: The CLI and the API run the same sweep; only the deg -> rad conversion may round
#: differently (one ulp of the inputs).
SAME_RTOL = 1e-9


def run(capsys, tmp_path, *argv: str) -> tuple[int, str, str]:
    """``cahyman map ARGV --out TMP`` (no process pool unless --workers is given)."""
    workers = [] if "--workers" in argv or "--scheduler" in argv else ["--workers", "1"]
    status = main(["map", *argv, *workers, "--out", str(tmp_path)])
    out, err = capsys.readouterr()
    return status, out, err


def test_value_specifications():
    np.testing.assert_allclose(parse_values("30:90:4"), [30.0, 50.0, 70.0, 90.0])
    np.testing.assert_allclose(parse_values("1,2.5,-3"), [1.0, 2.5, -3.0])
    np.testing.assert_allclose(parse_values("7"), [7.0])


def test_curve_writes_data_and_figure(capsys, tmp_path):
    status, out, err = run(capsys, tmp_path, "--alpha", "40:80:5", "--alpha4", "60", "--s4", "25")
    assert status == 0, err
    assert "5 points (5 ok)" in out
    for name in ("map.npz", "map.csv", "map_det_K.png"):
        assert (tmp_path / name).stat().st_size > 0
    res = SweepResult.load_npz(tmp_path / "map.npz")
    alpha = np.deg2rad([40.0, 50.0, 60.0, 70.0, 80.0])
    np.testing.assert_allclose(res.points.alpha, np.repeat(alpha[:, None], 3, axis=1))
    np.testing.assert_allclose(res.points.s4, 0.025)
    ref = sweep(grid({"alpha": alpha}, alpha4=np.deg2rad(60.0), s4=0.025), executor="serial")
    np.testing.assert_allclose(res.indices["det_K"], ref.indices["det_K"], rtol=SAME_RTOL)


def test_a_second_map_in_the_folder_leaves_no_figure_of_the_first(capsys, tmp_path):
    """map.npz and map.csv are replaced: the first map's figure would show data that are no
    longer there."""
    (tmp_path / "notes.png").write_text("the user's")
    for index in ("det_K", "min_translational"):
        status, _, err = run(capsys, tmp_path, "--alpha", "40:80:3", "--index", index)
        assert status == 0, err
    assert sorted(p.name for p in tmp_path.glob("*.png")) == ["map_min_translational.png",
                                                             "notes.png"]  # fmt: skip


def test_strokes_are_checked_against_the_largest_swept_stroke(capsys, tmp_path):
    """--s4 60 mm with s4_max swept to 0.06 m is a map (its points with the shorter stroke
    are marked invalid), not a typing error; beyond every stroke it is one, in mm."""
    status, _, err = run(capsys, tmp_path, "--alpha", "60", "--s4", "0:60:3",
                           "--param", "s4_max=0.03,0.06")  # fmt: skip
    assert status == 0, err
    res = SweepResult.load_npz(tmp_path / "map.npz")
    assert list(res.status).count("invalid") == 1  # 60 mm with the 30 mm stroke
    status, _, err = run(capsys, tmp_path, "--alpha", "60", "--s4", "0:80:3")
    assert status == 2 and "--s4 80 mm is outside the stroke [0, 50] mm" in err


def test_heat_map_of_a_design_sweep(capsys, tmp_path):
    status, _, err = run(capsys, tmp_path, "--alpha", "45", "60", "75", "--alpha4", "0:90:4",
                           "--param", "b=0.06:0.10:3", "--backend", "consistent",
                           "--index", "min_translational", "--ks", "printed")  # fmt: skip
    assert status == 0, err
    assert (tmp_path / "map_min_translational.png").exists()
    res = SweepResult.load_npz(tmp_path / "map.npz")
    assert res.points.shape == (4, 3) and res.backend == "consistent"
    assert res.points.params == DEFAULT_PARAMS.with_ks("printed")
    np.testing.assert_allclose(res.points.design["b"].reshape(4, 3)[0], [0.06, 0.08, 0.10])
    np.testing.assert_allclose(res.points.alpha[0], np.deg2rad([45.0, 60.0, 75.0]))


def test_deflection_map_with_a_load_and_the_process_pool(capsys, tmp_path):
    status, _, err = run(capsys, tmp_path, "--s4", "0:50:3", "--alpha1", "50,70",
                           "--force", "1", "1", "1", "--index", "deflection_translation",
                           "--workers", "2", "--start", "closed_form")  # fmt: skip
    assert status == 0, err
    res = SweepResult.load_npz(tmp_path / "map.npz")
    np.testing.assert_array_equal(res.wrench, [1, 1, 1, 0, 0, 0])
    assert res.points.shape == (3, 2) and np.all(res.indices["deflection_translation"] > 0)
    assert (tmp_path / "map_deflection_translation.png").exists()


def test_failed_points_are_reported_not_fatal(capsys, tmp_path):
    status, out, err = run(
        capsys, tmp_path, "--alpha1", "90,-80", "--alpha", "90", "--workers", "1"
    )
    assert status == 0, err
    assert "1 unreachable" in out and "cannot be assembled" in out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--alpha", "30:x:3"], "START:STOP:NUM"),
        (["--alpha", "30"], "nothing to sweep: every input has one value"),
        (["--alpha", "80:100:1"], "nothing to sweep: every input has one value"),
        (["--alpha", "1", "2"], "1 or 3 values"),
        (["--alpha", "30:90:3", "--alpha1", "40"], "cannot be combined"),
        (["--alpha", "30:90:3", "--param", "zz=1"], "NAME one of"),
        (["--alpha", "30:90:3", "--index", "deflection_rotation"], "--force"),
        (["--alpha", "30:90:3", "--alpha4", "0,1", "--s4", "0,1"], "one or two inputs"),
        (["--alpha", "30:90:3", "--backend", "nope"], "invalid choice: 'nope'"),
        (["--alpha", "30:90:3", "--s4", "80"], "outside the stroke"),
        (["--alpha", "30:90:3", "--param", "b=-1"], "must be > 0"),
        (["--alpha", "30:90:3", "--s4", "0:60:4"], "outside the stroke"),
        (["--alpha", "60", "--param", "b=-0.1:0.1:3"], "must be > 0"),
        (["--alpha", "30:90:3", "--workers", "0"], "workers"),
        (["--alpha", "30:90:3", "--index", "stiffness"], "invalid choice"),
        (["--alpha", "30:90:3", "--start", "cold"], "invalid choice"),
        (["--alpha", "60", "--param", "m_M4=1:5:3"], "--param m_M4: a map has no weight"),
        (["--alpha", "30:90:3", "--param", "gravity=1.6"], "--param gravity: a map has no"),
        (["--alpha", "30:90:3", "--param", "E_beam=1e9"], "E_beam: a map's links are rigid"),
        (["--alpha", "30:90:3", "--worker-timeout", "5"], "give --scheduler ADDRESS too"),
    ],
)
def test_bad_input_exits_2_with_one_line(capsys, tmp_path, argv, message):
    status, _, err = run(capsys, tmp_path, *argv)
    assert status == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("cahyman: error:"), err
    assert message in lines[0]


def test_failed_points_name_the_swept_values_cleanly_and_count_the_rest(capsys, tmp_path):
    # alpha_1 = -85 deg: the plate cannot be assembled once the cranks are long enough
    status, out, err = run(capsys, tmp_path, "--alpha", "60", "--alpha1", "-85",
                           "--param", "b=0.02:0.12:11")  # fmt: skip
    assert status == 0, err
    res = SweepResult.load_npz(tmp_path / "map.npz")
    failed = np.flatnonzero(res.status != "ok")
    assert len(failed) == 4  # b = 0.09 ... 0.12 m
    lines = [ln for ln in out.splitlines() if ln.startswith("point ")]
    assert len(lines) == 3
    assert lines[0].startswith(f"point {failed[0]} (b = 0.09 m) unreachable: plate cannot be "
                               "assembled at alpha=[-85, 60, 60] deg")  # fmt: skip
    assert "[[" not in out and "9999" not in out and "0000000" not in out
    assert "... and 1 more" in out


def test_bad_out_folder_is_refused_before_the_sweep(capsys, tmp_path, monkeypatch):
    import cahyman_pin.cli.map as map_cli

    def no_sweep(*args, **kwargs):
        raise AssertionError("the sweep ran before the output folder was checked")

    monkeypatch.setattr(map_cli, "sweep", no_sweep)
    (tmp_path / "file").write_text("")
    for out, match in (
        (tmp_path / "file", "is a file; expected a folder"),
        (tmp_path / "file" / "sub", "cannot create or write this folder"),
        ("/proc/x", "cannot create or write this folder"),
    ):
        status = main(["map", "--alpha", "30:90:3", "--workers", "1", "--out", str(out)])
        err = capsys.readouterr().err
        assert status == 2 and err.count("\n") == 1 and match in err, err


def test_backend_choices_in_help(capsys, tmp_path):
    status = main(["map", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert status == 0 and "{consistent,generic,published}" in out and "(default: generic)" in out


def test_dask_cluster_gives_the_serial_map(capsys, tmp_path):
    import logging

    from dask.distributed import LocalCluster

    args = ("--alpha", "40:80:4", "--alpha4", "60", "--s4", "25", "--workers", "1")
    status, _, err = run(capsys, tmp_path / "serial", *args)
    assert status == 0, err
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None, silence_logs=logging.ERROR) as cluster:  # fmt: skip
        status, _, err = run(capsys, tmp_path / "dask", *args[:-2], "--scheduler",
                             cluster.scheduler_address)  # fmt: skip
    assert status == 0, err
    a = SweepResult.load_npz(tmp_path / "serial" / "map.npz")
    b = SweepResult.load_npz(tmp_path / "dask" / "map.npz")
    for name in a.indices:
        np.testing.assert_array_equal(a.indices[name], b.indices[name], err_msg=name)
    status, _, err = run(capsys, tmp_path / "x", *args[:-2], "--scheduler", "tcp://127.0.0.1:9")
    assert status == 2 and "cannot reach the Dask scheduler" in err
