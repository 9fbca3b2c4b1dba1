"""The files of a map as another tool reads them: the CSV and NPZ name their units and
read back to the map's numbers (NaN and a reason where a point failed), a grid of one row
is drawn, and an earlier map's CSV does not outlive a map too large for one."""

import csv
import json

import mechanisms as mech
import numpy as np
import pytest
from helpers import assert_close_in_norm

import closedloop as cl
import closedloop.analysis.maps as maps
from cahyman_pin.sweep import engine
from cahyman_pin.sweep.engine import pose_list, sweep
from closedloop.analysis.maps import stiffness_map

WRENCH = np.array([1.0, 0.0, -2.0, 0.0, 0.3, 0.0])
#: A map point against a direct query assembled from the reference configuration: the
#: assembly's closure tolerance (1e-12 of the size) times the sensitivity of C (as
#: tests/analysis/test_maps.py's Stewart grid).
RTOL_QUERY = 1e-9


@pytest.fixture(scope="module")
def stewart():
    return mech.stewart()


def leg_map(m, leg0, leg1):
    """A grid of the Stewart platform's legs 0 and 1 (offsets [m] from the reference)."""
    lengths = m.geometry["lengths"]
    fixed = {f"leg{i}": lengths[i] for i in range(2, 6)}
    axes = {"leg0": lengths[0] + np.asarray(leg0), "leg1": lengths[1] + np.asarray(leg1)}
    return stiffness_map(m.clm, m.frame, sweeps=axes, fixed=fixed, wrench=WRENCH)


def test_csv_and_npz_name_their_units_and_read_back(stewart, tmp_path):
    """Columns named with their units (no unit before), a reason per failed point (none
    before), every number read back exactly, each equal to a direct query."""
    m = leg_map(stewart, [-0.02, 5.0, 0.0], [0.0, 0.02])  # a 5 m longer leg 0: unreachable
    npz, path = m.save(tmp_path, "min_translational")[:2]
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 6
    assert list(rows[0])[:2] == ["leg0_m", "leg1_m"]
    columns = {"det_K": "det_K_N^6_per_rad^3", "condition_number": "condition_number",
               "min_translational": "min_translational_N_per_m",
               "max_rotational": "max_rotational_Nm_per_rad",
               "deflection_rotation": "deflection_rotation_rad"}  # fmt: skip
    for name, column in columns.items():
        read = np.array([float(r[column]) for r in rows])
        np.testing.assert_array_equal(read, m.indices[name])  # repr: exact, nan as NaN
    np.testing.assert_array_equal([float(r["leg0_m"]) for r in rows], m.inputs[:, 0])
    for i, row in enumerate(rows):
        assert row["status"] == m.status[i] and row["reason"] == m.reasons[i]
        if row["status"] == "unreachable":
            assert "cannot close the loops" in row["reason"]
            assert np.isnan(float(row["min_translational_N_per_m"]))
            continue
        q = cl.assemble(stewart.clm, m.inputs[i], stewart.q).q  # independent of the map
        res = cl.compliance(stewart.clm, q, stewart.frame)
        assert_close_in_norm(m.C[i], res.C, RTOL_QUERY)
        s = cl.StiffnessIndices.from_result(res)
        assert float(row["min_translational_N_per_m"]) == pytest.approx(
            s.min_translational_stiffness.value, rel=RTOL_QUERY
        )
    assert [r["status"] for r in rows].count("unreachable") == 2
    with np.load(npz, allow_pickle=False) as f:
        units = json.loads(str(f["units"]))
        assert units["leg0"] == "m" and units["inputs"] == ["m"] * 6
        assert units["det_K"] == "N^6/rad^3" and units["C"].startswith("m/N")
        assert set(units) <= set(f.files) and set(m.indices) <= set(units)


def test_a_grid_of_one_row_or_column_is_drawn_as_a_curve(stewart, tmp_path, monkeypatch):
    """A heat map of one row had cells of no height: the picture was empty. Now the curve
    along the axis with several values, the other joint's value in the title."""
    figures = []
    monkeypatch.setattr(maps, "save_figure", lambda fig, path: figures.append(fig))
    for leg0, leg1, axis in (([0.0], [-0.02, 0.0, 0.02], "leg1"), ([0.02, -0.02], [0.0], "leg0")):
        m = leg_map(stewart, leg0, leg1)
        m.save(tmp_path, "min_translational")
        ax = figures[-1].axes[0]
        assert ax.get_xlabel() == f"{axis} [m]" and ax.get_ylabel().startswith("min_transl")
        (line,) = ax.get_lines()
        x = m.inputs[:, m.joints.index(axis)]
        np.testing.assert_array_equal(line.get_xdata(), np.sort(x))
        np.testing.assert_array_equal(
            line.get_ydata(), m.indices["min_translational"][np.argsort(x)]
        )
        other = "leg0" if axis == "leg1" else "leg1"
        assert f"{other} = " in ax.get_title()


def test_a_larger_map_leaves_no_csv_of_an_earlier_one(tmp_path, monkeypatch, fourbar):
    """A map too large for a CSV, written where a smaller one was: its map.csv stayed,
    the numbers of another map beside the new map.npz."""
    small = stiffness_map(fourbar[0], "P", sweeps={"crank": [0.3]})
    assert (tmp_path / "map.csv") in small.save(tmp_path)
    monkeypatch.setattr(maps, "CSV_MAX_POINTS", 1)
    large = stiffness_map(fourbar[0], "P", sweeps={"crank": [0.3, 0.4]})
    assert [p.name for p in large.save(tmp_path)] == ["map.npz", "map.png"]
    assert not (tmp_path / "map.csv").exists()

    res = sweep(pose_list(np.deg2rad([[60.0, 65.0, 70.0]] * 2), 0.7, [0.01, 0.02]),
                backend="consistent", executor="serial")  # fmt: skip
    res.save(tmp_path, "s")
    monkeypatch.setattr(engine, "CSV_MAX_POINTS", 1)
    assert [p.name for p in res.save(tmp_path, "s")] == ["s.npz"]
    assert not (tmp_path / "s.csv").exists()


def test_cahyman_files_name_the_units_of_indices_and_design_values(tmp_path):
    pts = pose_list(np.deg2rad([[60.0, 65.0, 70.0], [50.0, 60.0, 70.0]]), np.deg2rad(45.0),
                    0.01, design={"L": [0.15, 0.2], "K_T": [30.0, 40.0]})  # fmt: skip
    res = sweep(pts, backend="consistent", wrench=WRENCH, executor="serial")
    npz, path = res.save(tmp_path, "s")
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    assert {"L_m", "K_T_Nm_per_rad", "det_K_N^6_per_rad^3", "min_translational_N_per_m",
            "condition_number", "deflection_translation_m"} <= set(rows[0])  # fmt: skip
    np.testing.assert_array_equal([float(r["det_K_N^6_per_rad^3"]) for r in rows],
                                  res.indices["det_K"])  # fmt: skip
    with np.load(npz, allow_pickle=False) as f:
        units = json.loads(str(f["meta"]))["units"]
    assert units["design_L"] == "m" and units["design_K_T"] == "N m/rad"
    assert units["length"] == "m" and "[m]" in units["deflection"] and "[N]" in units["wrench"]
