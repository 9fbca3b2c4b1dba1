"""The path in the viewer (issue #42): the page of ``run_path_view`` shows the robot at the
point of largest deflection, with the path's lines."""

from __future__ import annotations

import numpy as np
import pytest

import closedloop as cl
from closedloop.kinematics.frame_task import xyzquat
from closedloop.viewer.path_view import run_path_view


@pytest.fixture(scope="module")
def five_bar_path():
    """The planar five-bar's frame E through three of its poses, 20 N across."""
    clm = cl.load_model(cl.data.path("fivebar5.urdf"), cl.data.path("fivebar5.yaml"),
                        geometry=True)  # fmt: skip
    q = cl.assemble(clm, None, clm.reference_configuration()).q
    rows = []
    for step in (0.0, 0.05, 0.1):
        qi = cl.assemble(clm, clm.actuated_values(q) + step, q).q
        rows.append(xyzquat(cl.Configuration(clm, qi).frame_placement("E")))
    r = cl.follow_path(clm, "E", rows, wrench=[20.0, 10.0, 0, 0, 0, 0], task="position", q0=q)
    return clm, r


def test_page_shows_the_point_of_largest_deflection(five_bar_path, tmp_path):
    clm, r = five_bar_path
    lines = []
    scene = run_path_view(clm, r, html=tmp_path / "path.html", out=lines.append)
    largest = int(np.argmax(np.linalg.norm(r.error[:, :3], axis=1)))
    np.testing.assert_array_equal(scene.q, r.q_target[largest])
    page = (tmp_path / "path.html").read_text(encoding="utf-8")
    assert f"path point {largest} of 3" in page and "deflected x" in page
    assert lines[-1] == f"wrote {tmp_path / 'path.html'}"


def test_a_point_outside_the_path_is_refused(five_bar_path, tmp_path):
    clm, r = five_bar_path
    with pytest.raises(cl.InvalidInputError, match="expected 0 to 2"):
        run_path_view(clm, r, point=3, html=tmp_path / "path.html")
