"""Shared fixtures: paths of the local robot files used by the tests."""

from pathlib import Path

import pytest

from closedloop.io import robot_data_dir

REPO = Path(__file__).resolve().parent.parent


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
