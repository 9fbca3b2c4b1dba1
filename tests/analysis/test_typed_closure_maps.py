"""Stiffness maps of the spatial four-bar closed by a typed or an elastic closure at its pin
C, against the same maps of the four-bar written with the joint at C kept in the tree (the
loop welded in the rocker: no code of the typed closure on that side). From Python
(:func:`closedloop.analysis.maps.stiffness_map`) and from ``closedloop map``."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_close_in_norm
from spatial_fourbar import PIN, PIN_CUT, fourbar_as, fourbar_files, mapped_configuration

from closedloop.analysis.maps import StiffnessMap, stiffness_map
from closedloop.cli.app import main
from closedloop.kinematics.driving import assemble_connected

#: The maps of two descriptions of one mechanism: each point assembled to 1e-12 L from the
#: previous one, the indices from factorisations of K of condition below 1e3 (the
#: ``condition_number`` of these maps): they agree to rounding, ~1e-13 measured.
RTOL_SAME = 1e-8
SCALE = [1, 1, 1, 0.1, 0.1, 0.1]  # P's twist: rotations weighed by 0.1 m
WRENCH = np.array([3.0, 2.0, -4.0, 0.3, -0.2, 0.1])  # [N, N m] at P, for the deflections
CRANKS = np.linspace(-0.3, 1.0, 6)  # [rad], both sides of the drawing (crank 0)
#: A typed closure at C and its joints kept in the tree. A prismatic closure at C locks the
#: crank (it assembles at the drawing only), so it has no map.
TYPED_AND_TREE = [
    ("revolute closure", "pin in the tree, rocker welded"),
    ("cylindrical closure", "cylindrical in the tree, rocker welded"),
]


def assert_same_maps(smap: StiffnessMap, expected: StiffnessMap) -> None:
    """Every point computed on both, the same statuses, compliances and indices (NaN on
    both where an index is not defined, e.g. det K of a compliance of rank < 6)."""
    np.testing.assert_array_equal(smap.status, expected.status)
    assert smap.ok.all()
    for C, C_expected in zip(smap.C, expected.C, strict=True):
        assert_close_in_norm(C, C_expected, RTOL_SAME, scale=SCALE)
    defined = 0
    for name, values in expected.indices.items():
        np.testing.assert_array_equal(np.isnan(smap.indices[name]), np.isnan(values), name)
        np.testing.assert_allclose(smap.indices[name], values, rtol=RTOL_SAME, err_msg=name)
        defined += int(np.isfinite(values).all())
    assert defined >= 5  # condition number, stiffnesses and deflections: not all NaN


@pytest.mark.parametrize(("closure", "tree"), TYPED_AND_TREE)
def test_a_map_over_a_typed_closure_equals_the_map_over_the_tree(fourbars, closure, tree):
    """With the lowest natural frequency (the links' masses are the same on both)."""
    smap, expected = (
        stiffness_map(fourbars[d][0], "P", sweeps={"crank": CRANKS}, wrench=WRENCH, modes=True)
        for d in (closure, tree)
    )
    np.testing.assert_array_equal(smap.inputs[:, 0], CRANKS)
    assert np.all(smap.indices["lowest_frequency"] > 1.0)  # [Hz]
    assert_same_maps(smap, expected)


def test_closedloop_map_of_a_revolute_closure_file_equals_the_map_over_the_tree(
    tmp_path, fourbars, capsys
):
    """Two worker processes, each loading the revolute closure from its files."""
    urdf, closures = fourbar_files(tmp_path, "revolute closure")
    code = main(["map", str(urdf), "--closures", str(closures), "--frame", "P",
                 "--sweep", "crank=-0.3:1.0:6", "--force", *map(str, WRENCH[:3]),
                 "--torque", *map(str, WRENCH[3:]), "--index", "deflection_translation",
                 "--workers", "2", "--chunk", "3", "--out", str(tmp_path / "map")])  # fmt: skip
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "6 points: 6 rank_deficient" in captured.out  # rank 3: no K, the other indices
    data = np.load(tmp_path / "map" / "map.npz")
    np.testing.assert_allclose(data["crank"], CRANKS, rtol=1e-15)
    expected = stiffness_map(fourbars["pin in the tree, rocker welded"][0], "P",
                             sweeps={"crank": CRANKS}, wrench=WRENCH)  # fmt: skip
    for C, C_expected in zip(data["C"], expected.C, strict=True):
        assert_close_in_norm(C, C_expected, RTOL_SAME, scale=SCALE)
    for name, values in expected.indices.items():
        np.testing.assert_allclose(data[name], values, rtol=RTOL_SAME, err_msg=name)


def test_a_map_over_the_sprung_pin_at_a_revolute_cut_equals_the_sprung_pin_in_the_tree(
    tmp_path, fourbars
):
    """The issue's pin (``closure_springs`` PIN: 20 N m/rad about the cut's z) on a
    'revolute' closure, against the pin in the tree with the same spring. A map's assembly
    holds the springs where it starts (the pin in the tree as a joint spring, the closure
    as if rigid: docs/guide/elastic_closures.md), so each point starts from the tree's
    assembly with the pin free (driven from the drawing, on its branch), carried over (the
    pin's angle, minus it at the cut)."""
    free = fourbars["pin in the tree, rocker welded"][0]

    def start(clm, points):
        Q = [assemble_connected(free, p).q for p in points]
        return np.array([mapped_configuration(clm, free, q, PIN_CUT) for q in Q])

    sprung = fourbar_as(tmp_path, "revolute closure", closure_springs={0: PIN})
    tree = fourbar_as(tmp_path, "pin in the tree, rocker welded", springs={"pin_C": 20.0})
    smap, expected = (
        stiffness_map(m, "P", sweeps={"crank": CRANKS}, wrench=WRENCH, start=start)
        for m in (sprung, tree)
    )
    assert_same_maps(smap, expected)
    # the spring counts: without it the revolute closure deflects otherwise
    bare = stiffness_map(fourbars["revolute closure"][0], "P", sweeps={"crank": CRANKS},
                         wrench=WRENCH)  # fmt: skip
    change = np.abs(bare.indices["deflection_translation"] / smap.indices["deflection_translation"])
    assert np.all(np.abs(change - 1.0) > 0.01)
