"""Wrong types at the Python API: the project's typed errors, naming the argument."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import closedloop as cl
from cahyman_pin.api import stiffness
from closedloop import data
from closedloop.exceptions import InvalidInputError, ModelFileError, NameNotFoundError


@pytest.fixture(autouse=True)
def warnings_are_errors():
    """A ComplexWarning (imaginary part dropped) would fail the test instead of passing it."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


def test_load_model_paths_must_be_paths():
    with pytest.raises(InvalidInputError, match=r"load_model: path must be a file path .* None"):
        cl.load_model(None)
    with pytest.raises(InvalidInputError, match=r"load_model: closures must be .*got 5"):
        cl.load_model(data.path("fourbar.urdf"), 5)


@pytest.mark.parametrize(
    ("springs", "match"),
    [
        ({"crank": "abc"}, r"stiffness of joint 'crank' must be real numbers, got 'abc' \(str\)"),
        ({"crank": 1 + 2j}, r"stiffness of joint 'crank' must be real numbers.*\(complex\)"),
        ({"crank": None}, r"stiffness of joint 'crank' must be real numbers, got None"),
        ({3: 1.0}, r"joint name must be a str, got 3 \(int\)"),
        (["crank"], r"springs must be a mapping joint name -> stiffness, got list"),
    ],
)
def test_spring_values_and_names(springs, match):
    with pytest.raises(InvalidInputError, match=match):
        cl.load_model(data.path("fourbar.urdf"), data.path("fourbar.yaml"), springs=springs)


def test_frame_and_joint_names_must_be_str(fourbar):
    clm, q = fourbar
    with pytest.raises(InvalidInputError, match=r"frame name must be a str, got 3 \(int\)"):
        cl.compliance(clm, q, 3)
    with pytest.raises(InvalidInputError, match=r"joint name must be a str, got None"):
        clm.joint_id(None)
    with pytest.raises(NameNotFoundError, match=r"unknown frame 'Q'; expected one of"):
        cl.compliance(clm, q, "Q")  # a str that is no frame: still the name error


@pytest.mark.parametrize(
    ("actuated", "match"),
    [
        ("abc", r"actuated must be real numbers, got 'abc' \(str\)"),
        ([0.3 + 1j], r"actuated must be real numbers, got \[\(0.3\+1j\)\] \(complex\)"),
        ([[1.0], [1.0, 2.0]], r"actuated must be real numbers, .* \(ragged list\)"),
        ([None], r"actuated must be real numbers, got \[None\]"),
    ],
)
def test_assemble_actuated_values(fourbar, actuated, match):
    with pytest.raises(InvalidInputError, match=match):
        cl.assemble(fourbar[0], actuated)


def test_complex_configurations_and_wrenches(fourbar):
    clm, q = fourbar
    with pytest.raises(InvalidInputError, match=r"q must be real numbers, .*\(complex\)"):
        cl.compliance(clm, q + 0j, "P")  # even a zero imaginary part: no silent cast
    with pytest.raises(InvalidInputError, match=r"q must be real numbers"):
        cl.Configuration(clm, q + 1e-3j)
    with pytest.raises(InvalidInputError, match=r"wrench must be real numbers.*\(complex\)"):
        cl.solve_equilibrium(clm, q, "P", np.full(6, 1j))
    with pytest.raises(InvalidInputError, match=r"wrench must be real numbers"):
        cl.compliance(clm, q, "P").deflection(["1", 0, 0, 0, 0, 0])
    with pytest.raises(InvalidInputError) as info:
        cl.Configuration(clm, q + 1j)
    assert "\n" not in str(info.value)  # one line, even for an array


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"alpha": [1.0, 1.0, 1j]}, r"alpha must be real numbers, got \[1.0, 1.0, 1j\]"),
        ({"alpha4": "abc"}, r"alpha4 must be real numbers, got 'abc' \(str\)"),
        ({"s4": None}, r"s4 must be real numbers, got None"),
        ({"backend": ["generic"]}, r"unknown backend \['generic'\]; expected one of \['con"),
        ({"params": {"K_s": 1.0}}, r"params must be a CaHyManParams, got dict"),
    ],
)
def test_cahyman_stiffness_arguments(kwargs, match):
    args = {"alpha": np.deg2rad([60.0, 60.0, 60.0]), "alpha4": 0.5, "s4": 0.01, **kwargs}
    with pytest.raises(InvalidInputError, match=match):
        stiffness(args.pop("alpha"), args.pop("alpha4"), args.pop("s4"), **args)


def test_bundled_files_by_name_from_anywhere(monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    robot = cl.load_model(data.path("fourbar.urdf"), data.path("fourbar.yaml"))
    assert robot.name == "fourbar" and len(robot.closures) == 1
    near = r"\(did you mean 'fourbar.urdf' or .*\)"
    with pytest.raises(
        ModelFileError, match=rf"no bundled file 'fourbar.sdf' {near}; expected one"
    ):
        data.path("fourbar.sdf")
    with pytest.raises(
        ModelFileError,
        match=r"unknown robot 'ur6' \(did you mean 'ur5' or 'ur3'\?\); expected one of .*'ur5'",
    ):
        data.robot_file("ur6")
    ur5 = cl.load_model(data.robot_file("ur5"), joint_stiffness=1e4)
    assert ur5.model.nq == 6 and ur5.actuated[0] == "shoulder_pan_joint"


def test_data_dir_prefers_the_wheel_layout(monkeypatch, tmp_path):
    """An installed wheel has the files in closedloop/_data/urdf (pyproject force-include);
    a source tree has urdf/ beside the package."""
    assert data.data_dir() == data._PACKAGE.parent / "urdf"  # this source tree
    wheel = tmp_path / "site" / "closedloop"
    (wheel / "_data" / "urdf").mkdir(parents=True)
    (wheel / "_data" / "urdf" / "fourbar.urdf").write_text("<robot/>")
    monkeypatch.setattr(data, "_PACKAGE", wheel)
    assert data.path("fourbar.urdf") == wheel / "_data" / "urdf" / "fourbar.urdf"
    monkeypatch.setattr(data, "_PACKAGE", tmp_path / "nowhere" / "closedloop")
    with pytest.raises(ModelFileError, match=r"no bundled model folder"):
        data.path("fourbar.urdf")


def test_public_face_reaches_the_bundled_files():
    assert cl.data is data and "data" in cl.__all__
    robot = cl.load_model(cl.data.path("fourbar.xml"))  # the MJCF twin, loops from the file
    assert len(robot.closures) == 1 and robot.actuated == ("crank",)


@pytest.mark.parametrize("name, value", [("K_s", 1e-308), ("b", 1e308), ("m_M4", 1e300)])
def test_parameters_that_would_overflow_are_refused_by_name(name, value):
    """Huge or tiny parameters overflow products of several of them (K x length^2,
    mass x gravity x length): refused naming the parameter, not an internal quantity."""
    from cahyman_pin.params import CaHyManParams

    with pytest.raises(InvalidInputError, match=rf"CaHyMan parameter {name}=.* outside the range"):
        CaHyManParams().replace(**{name: value})
