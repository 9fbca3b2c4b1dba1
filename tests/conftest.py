"""Shared fixtures: paths of the local robot files, and the models several modules load
(the four-bar, the UR5, CaHyMan)."""

from pathlib import Path

import numpy as np
import pytest
from helpers import REPO, UR5_JOINTS, UR5_Q
from spatial_fourbar import assembled_fourbars, sprung_pins

from closedloop.io.loader import load_urdf, robot_data_dir
from closedloop.kinematics.assembly import assemble


@pytest.fixture(scope="session")
def fourbar_urdf() -> Path:
    """Planar four-bar URDF (loop closed by urdf/fourbar.yaml)."""
    return REPO / "urdf" / "fourbar.urdf"


@pytest.fixture(scope="session")
def fourbar_yaml() -> Path:
    """Closure file of the four-bar: one 3D closure, crank actuated, three springs."""
    return REPO / "urdf" / "fourbar.yaml"


@pytest.fixture(scope="session")
def fourbar_mjcf() -> Path:
    """MJCF twin of the four-bar, loop closed by <connect>, assembled at qpos0."""
    return REPO / "urdf" / "fourbar.xml"


@pytest.fixture(scope="session")
def ur5_urdf() -> Path:
    """UR5 URDF shipped by example-robot-data."""
    return robot_data_dir() / "ur_description" / "urdf" / "ur5_robot.urdf"


@pytest.fixture(scope="session")
def panda_urdf() -> Path:
    """Franka Panda URDF shipped by example-robot-data (two finger joints)."""
    return robot_data_dir() / "panda_description" / "urdf" / "panda.urdf"


# ---------------------------------------------------------------------------- models
# Module scope: one model per test module, as when each module defined its own. The
# viewer and configuration tests define fixtures of the same names that load the model
# another way (load_model; test_viewer's ``cahyman`` is a (model, q) pair); theirs take
# precedence in their modules.
@pytest.fixture(scope="module")
def fourbar(fourbar_urdf, fourbar_yaml):
    """(model, q): the four-bar of urdf/ assembled at crank = 0.3 rad."""
    clm = load_urdf(fourbar_urdf, fourbar_yaml)
    return clm, np.array(assemble(clm, [0.3]).q)


@pytest.fixture(scope="module")
def ur5(ur5_urdf):
    """(model, q): the UR5 with 1e4 N m/rad on every joint, at UR5_Q (a copy)."""
    return load_urdf(ur5_urdf, springs=dict.fromkeys(UR5_JOINTS, 1e4)), UR5_Q.copy()


@pytest.fixture(scope="session")
def cahyman():
    """CaHyMan with the default parameters (cahyman_pin.model.cahyman_model, its cached
    instance: shared by every test, never modified by one)."""
    from cahyman_pin.model import cahyman_model
    from cahyman_pin.params import DEFAULT_PARAMS

    return cahyman_model(DEFAULT_PARAMS)


@pytest.fixture(scope="session")
def default_report(tmp_path_factory):
    """(folder, Document) of the CaHyMan report with the default parameters, built once for
    the tests that read it (the report takes seconds: its fits and figures); never modified
    by a test."""
    from cahyman_pin.paper import report

    out = tmp_path_factory.mktemp("default_report")
    return out, report.build_report(out)


# ------------------------------------------------ the spatial four-bar cut at its pin C
@pytest.fixture(scope="module")
def fourbars(tmp_path_factory):
    """{description: (model, q assembled at crank = 0.4 rad)}: the spatial four-bar in each
    description of :data:`spatial_fourbar.DESCRIPTIONS`."""
    return assembled_fourbars(tmp_path_factory.mktemp("fourbars"))


@pytest.fixture(scope="module")
def pins(tmp_path_factory, fourbars):
    """{description: (model, Q)}: the issue's sprung pin at C on a '6d' and a 'revolute'
    closure and in the tree (:func:`spatial_fourbar.sprung_pins`)."""
    return sprung_pins(tmp_path_factory.mktemp("pins"), fourbars)
