"""Identification on the spatial four-bar closed by a typed or an elastic closure at its pin
C, from deflections synthesised on the four-bar written with the joint at C kept in the
tree (the loop welded in the rocker: no code of the typed closure makes the data). From
Python (:func:`closedloop.analysis.identification.identify`) and from
``closedloop identify`` with a measurement file."""

from __future__ import annotations

import json

import numpy as np
import pytest
from spatial_fourbar import PIN, SPRINGS, fourbar_files

import closedloop as cl
from closedloop.analysis.identification import identify
from closedloop.analysis.measurements import Measurement
from closedloop.cli.app import main
from closedloop.kinematics.driving import assemble_connected

#: Noise-free data from the tree's compliance, which equals the closure's to rounding
#: (~1e-13, tests/analysis/test_typed_closure_maps.py): the estimates are the true values
#: to that and to the optimiser's stopping tolerance (1e-15 in log k); 1e-13 measured.
RTOL_FIT = 1e-8
SD = 1e-6  # [m, rad] stated standard deviation of the synthetic twists
CRANKS = (0.1, 0.4, 0.8)  # [rad], driven from the drawing (crank 0) on its branch
#: Springs fitted: the crank's (in the plane) and the rocker's tilt about x (out of the
#: plane: it reaches P only through the moment rows of the closure at C).
FITTED = ("crank", "rocker_tilt")


def synthesised(tree: cl.ClosedLoopModel, Q_tree, Q=None, seed: int = 3) -> list[Measurement]:
    """Three random wrenches [N, N m] at P per configuration of ``Q_tree`` and the twists
    C w of the tree there; each measurement at the matching configuration of ``Q`` (the
    model fitted; default: the tree's actuated values)."""
    rng = np.random.default_rng(seed)
    out = []
    for i, q_tree in enumerate(Q_tree):
        C = cl.compliance(tree, q_tree, "P").C
        where = {"actuated": tree.actuated_values(q_tree)} if Q is None else {"q": Q[i]}
        out += [Measurement.of(wrench=w, twist=C @ w, sd=SD, **where)
                for w in rng.normal(size=(3, 6))]  # fmt: skip
    return out


def test_the_spring_of_an_elastic_revolute_closure_is_fitted_from_the_pin_in_the_tree(pins):
    """The issue's pin (PIN: 20 N m/rad about the cut's z) on a 'revolute' closure, fitted
    from 5 N m/rad to the deflections of the pin in the tree with that spring."""
    (clm, Q), (tree, Q_tree) = pins["revolute closure"], pins["tree"]
    fit = identify(clm, synthesised(tree, Q_tree, Q), "P", ["cA<->cB_rz"],
                   start={"cA<->cB_rz": 5.0})  # fmt: skip
    assert fit.consistent and fit.unidentifiable == ()
    np.testing.assert_allclose(fit.estimates["cA<->cB_rz"], 20.0, rtol=RTOL_FIT)


@pytest.mark.parametrize(
    ("closure", "tree"),
    [("revolute closure", "pin in the tree, rocker welded"),
     ("cylindrical closure", "cylindrical in the tree, rocker welded")],
)  # fmt: skip
def test_joint_springs_of_a_loop_closed_by_a_typed_closure_are_fitted_from_the_tree(
    fourbars, closure, tree
):
    clm, twin = fourbars[closure][0], fourbars[tree][0]
    Q_tree = [assemble_connected(twin, [c]).q for c in CRANKS]
    Q = [assemble_connected(clm, [c]).q for c in CRANKS]
    fit = identify(clm, synthesised(twin, Q_tree, Q), "P", list(FITTED),
                   start={n: 3.0 * SPRINGS[n] for n in FITTED})  # fmt: skip
    assert fit.consistent and fit.unidentifiable == ()
    for name in FITTED:
        np.testing.assert_allclose(fit.estimates[name], SPRINGS[name], rtol=RTOL_FIT)


def _measurement_file(path, measurements: list[Measurement]) -> str:
    """A measurement file (YAML, in its JSON form: every float written exactly)."""
    rows = []
    for m in measurements:
        row = {"wrench": m.wrench.tolist(), "twist": m.twist.tolist(), "sd": SD}
        row |= {"q": m.q.tolist()} if m.q is not None else {"actuated": m.actuated.tolist()}
        rows.append(row)
    path.write_text(json.dumps({"frame": "P", "measurements": rows}))
    return str(path)


def test_closedloop_identify_fits_springs_of_typed_and_elastic_closure_files(
    tmp_path, fourbars, pins, capsys
):
    """A revolute closure file, measurements at actuated values (assembled by the command,
    driven from the drawing); the issue's pin on it (``closure_springs``), measurements at
    configurations; start values from ``--springs``."""
    twin = fourbars["pin in the tree, rocker welded"][0]
    Q_tree = [assemble_connected(twin, [c]).q for c in CRANKS]
    (_, Q), (tree, Q_pins) = pins["revolute closure"], pins["tree"]
    runs = [
        ({}, synthesised(twin, Q_tree), FITTED, SPRINGS),
        ({"closure_springs": {0: PIN}}, synthesised(tree, Q_pins, Q), ["cA<->cB_rz"],
         {"cA<->cB_rz": 20.0}),
    ]  # fmt: skip
    for i, (options, measurements, fitted, truth) in enumerate(runs):
        folder = tmp_path / str(i)
        folder.mkdir()
        urdf, closures = fourbar_files(folder, "revolute closure", **options)
        (folder / "start.yaml").write_text("".join(f"'{n}': {0.25 * truth[n]}\n" for n in fitted))
        code = main(["identify", str(urdf), "--closures", str(closures), "--measurements",
                     _measurement_file(folder / "m.yaml", measurements), "--springs",
                     str(folder / "start.yaml"), "--fit", *fitted, "--json"])  # fmt: skip
        captured = capsys.readouterr()
        assert code == 0, captured.err
        doc = json.loads(captured.out)
        assert doc["n_measurements"] == len(measurements) and doc["unidentifiable"] == []
        for name in fitted:
            np.testing.assert_allclose(doc["estimates"][name], truth[name], rtol=RTOL_FIT)
