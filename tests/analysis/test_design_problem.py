"""Design problems: the file's form and its errors, a design's evaluation (mass from the files,
worst values over the workspace, feasibility with its reason)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from helpers import REPO

from closedloop.analysis.design_evaluation import evaluate_design
from closedloop.analysis.design_optimizer import optimize_design
from closedloop.analysis.design_problem import design_problem
from closedloop.analysis.maps import stiffness_map
from closedloop.exceptions import InvalidInputError, ModelFileError, NameNotFoundError
from closedloop.io.loader import load_model

DATA = REPO / "tests" / "data"
FOURBAR = str(REPO / "urdf" / "fourbar.urdf")
BEAMS = str(DATA / "xacro" / "fourbar_beams.yaml")
RHO = 2700.0


def fourbar_problem(**changes) -> dict:
    problem = {
        "model": FOURBAR, "closures": BEAMS, "frame": "P", "parameters": {"d": [0.005, 0.05]},
        "workspace": {"sweep": {"crank": "0.2:1.2:6"}}, "load": {"force": [0, 0, -100]},
        "objectives": [{"index": "mass"}, {"index": "deflection_translation"}],
        "constraints": [{"index": "min_translational", "min": 5.0e3}],
    }  # fmt: skip
    return {**problem, **changes}


def test_a_problem_file_with_paths_relative_to_it(tmp_path):
    (tmp_path / "models").mkdir()
    for name in ("fourbar.urdf.xacro", "materials.xacro", "fourbar_beams.yaml"):
        (tmp_path / "models" / name).write_text((DATA / "xacro" / name).read_text())
    path = tmp_path / "problem.yaml"
    path.write_text("""\
model: models/fourbar.urdf.xacro
closures: models/fourbar_beams.yaml
frame: P
parameters: {d: [0.005, 0.05], crank: [0.08, 0.12]}
args: {coupler: 0.3}
workspace: {sweep: {crank: "0.2:1.2:6"}}  # the joint crank, not the argument
load: {force: [0, 0, -100]}
objectives:
  - {index: mass, goal: minimize}
constraints:
  - {index: min_translational, min: 2e4, tolerance: 1.0e-4}
""")
    problem = design_problem(path)
    assert problem.model == str(tmp_path / "models" / "fourbar.urdf.xacro")
    assert problem.names == ("d", "crank") and problem.args == (("coupler", 0.3),)
    assert problem.sweeps == (("crank", tuple(np.linspace(0.2, 1.2, 6))),)
    assert problem.constraints[0].min == 2e4 and problem.constraints[0].tolerance == 1e-4
    assert problem.wrench == (0.0, 0.0, -100.0, 0.0, 0.0, 0.0)
    assert design_problem(problem.to_dict()) == problem  # the dict form is the file's


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"frames": "P"}, r"unknown key\(s\) \['frames'\]"),
        ({"model": None}, "model: missing"),
        (
            {"parameters": {"d": [0.05, 0.005]}},
            r"parameters: d: \[0.05, 0.005\]; expected low < high",
        ),
        ({"parameters": {"d": 0.05}}, r"expected \[low, high\]"),
        ({"objectives": [{"index": "stiffness"}]}, "index 'stiffness'; expected one of"),
        ({"objectives": [{"index": "mass", "goal": "lowest"}]}, "goal 'lowest'"),
        ({"objectives": []}, "expected one or more"),
        ({"load": None}, "load: missing; the index 'deflection_translation' needs a force"),
        ({"constraints": [{"index": "mass"}]}, "expected min and/or max"),
        ({"workspace": {"sweep": {"crank": "0.2:x:6"}}}, r"crank: '0.2:x:6': 'x' is not a"),
        ({"workspace": {"sweep": {}, "points": [[0.1]]}}, "either sweep"),
        ({"args": {"d": 0.01}}, r"\['d'\] are parameters too"),
        ({"check_limits": "no"}, "check_limits: 'no'; expected true or false"),
    ],
)
def test_problem_errors_name_the_key(changes, match):
    with pytest.raises(InvalidInputError, match=match) as info:
        design_problem(fourbar_problem(**changes))
    assert "\n" not in str(info.value)


def test_problem_file_errors_name_the_file(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text("model: m.urdf\nframe: P\nparameters: {d: [1, 0]}\nobjectives: []\n")
    with pytest.raises(ModelFileError, match=r"design problem '.*p.yaml': parameters: d"):
        design_problem(path)
    path.write_text("model: [m.urdf\n")
    with pytest.raises(ModelFileError, match="is not valid YAML"):
        design_problem(path)


def test_mass_is_every_body_of_the_file_and_the_beams():
    """The URDF's inertial masses (read here from the file) plus rho A L of each tube."""
    d = 0.02
    urdf = sum(float(m.get("value")) for m in ET.parse(FOURBAR).getroot().iter("mass"))
    lengths = (0.1, 0.3, 0.15)  # crank, coupler, rocker [m]
    tubes = RHO * math.pi / 4 * (d**2 - (0.8 * d) ** 2) * sum(lengths)
    e = evaluate_design(design_problem(fourbar_problem()), {"d": d})
    np.testing.assert_allclose(e.values["mass"], urdf + tubes, rtol=1e-14)


def test_links_welded_to_the_world_weigh_too():
    """The cantilever's base (1.5 kg) is welded to the world: Pinocchio merges it into the
    universe, whose inertia the mass counts."""
    problem = design_problem({
        "model": str(DATA / "xacro" / "cantilever_by_hand.urdf"),
        "closures": str(DATA / "design" / "tube.yaml"), "frame": "tip",
        "parameters": {"d": [0.01, 0.03], "t": [0.001, 0.004]},
        "objectives": [{"index": "mass"}],
    })  # fmt: skip
    d, t = 0.02, 0.002
    e = evaluate_design(problem, {"d": d, "t": t})
    tube = RHO * math.pi / 4 * (d**2 - (d - 2 * t) ** 2) * 0.4
    np.testing.assert_allclose(e.values["mass"], 1.5 + 0.3 + tube, rtol=1e-14)


def test_indices_at_their_worst_over_the_workspace():
    problem = design_problem(fourbar_problem())
    e = evaluate_design(problem, {"d": 0.02})
    clm = load_model(FOURBAR, BEAMS, args={"d": 0.02})
    smap = stiffness_map(clm, "P", sweeps={"crank": np.linspace(0.2, 1.2, 6)},
                         wrench=np.array([0, 0, -100.0, 0, 0, 0]))  # fmt: skip
    k, deflection = smap.indices["min_translational"], smap.indices["deflection_translation"]
    assert e.values["min_translational"] == k.min() and e.worst["min_translational"] == k.argmin()
    assert e.values["deflection_translation"] == deflection.max()
    assert e.feasible and e.reason == "" and e.violation == 0.0


def test_infeasible_designs_keep_their_reason():
    problem = design_problem(fourbar_problem())
    light = evaluate_design(problem, {"d": 0.008})
    assert not light.feasible and 0 < light.violation < 1
    assert light.reason.startswith("5000 <= min_translational not met: min_translational = ")
    thick = design_problem({**fourbar_problem(), "closures": str(DATA / "design" / "tube.yaml"),
                            "model": str(DATA / "xacro" / "cantilever_by_hand.urdf"),
                            "frame": "tip", "workspace": None, "load": None,
                            "parameters": {"d": [0.01, 0.03], "t": [0.001, 0.02]},
                            "objectives": [{"index": "mass"}]})  # fmt: skip
    wall = evaluate_design(thick, {"d": 0.01, "t": 0.006})  # a wall thicker than the radius
    assert not wall.feasible and math.isinf(wall.violation)
    assert wall.reason.startswith("BeamError: beam 'tube'") and "t" in wall.reason
    reach = design_problem({
        "model": str(DATA / "xacro" / "fourbar.urdf.xacro"),
        "closures": str(REPO / "urdf" / "fourbar.yaml"),
        "frame": "P", "parameters": {"rocker": [0.05, 0.2]},
        "workspace": {"sweep": {"crank": "0:3:7"}},
        "objectives": [{"index": "min_translational", "goal": "maximize"}],
    })  # fmt: skip
    short = evaluate_design(reach, {"rocker": 0.05})  # the rocker cannot reach the coupler
    assert not short.feasible and math.isnan(short.values["min_translational"])
    assert short.reason.startswith("workspace point 2 (crank = 1): unreachable: ")
    planar = design_problem({**fourbar_problem(), "closures": str(REPO / "urdf" / "fourbar.yaml"),
                             "parameters": {"crank": [0.08, 0.12]}, "constraints": [],
                             "model": str(DATA / "xacro" / "fourbar.urdf.xacro"),
                             "objectives": [{"index": "max_translational"}]})  # fmt: skip
    flat = evaluate_design(planar, {"crank": 0.1})  # rigid out of its plane: K does not exist
    assert flat.reason == ("workspace point 0 (crank = 0.2): max_translational does not exist "
                           "there (status rank_deficient)")  # fmt: skip


def test_the_problem_is_checked_at_its_first_design():
    with pytest.raises(NameNotFoundError, match="unknown frame 'Q'"):
        optimize_design(fourbar_problem(frame="Q"), budget=4)
    with pytest.raises(InvalidInputError, match="'rocker' is not an actuated joint"):
        optimize_design(fourbar_problem(workspace={"sweep": {"rocker": [0.1]}}), budget=4)
