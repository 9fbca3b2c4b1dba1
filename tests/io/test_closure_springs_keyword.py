"""``load_model(closure_springs=)`` on MJCF and SDF models: the four-bar's closure at C
made an elastic ball (translation springs, rotations free) in the MJCF and SDF twins of
urdf/fourbar.urdf equals the URDF twin with the same spring in its closure file, read by
another parser; the models' stored start configurations carry the joints at the cut."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import assert_close_in_norm
from test_sdf import FOURBAR_ANGLES, fourbar_sdf, slider_crank_sdf, write

import closedloop as cl
from closedloop.exceptions import InvalidInputError
from closedloop.io.loader import load_model

#: The twins agree to rounding (test_sdf.RTOL_TWIN: assembly to 1e-12 of the length,
#: compliance of condition ~1e6).
RTOL_TWIN = 1e-9
#: An isotropic spring at C [N/m], rotations free: the twins' frames at C need not share
#: their axes.
BALL = [3e4, 3e4, 3e4, 0.0, 0.0, 0.0]


@pytest.fixture(scope="module")
def urdf_twin(tmp_path_factory, fourbar_urdf, fourbar_yaml):
    """The URDF four-bar with :data:`BALL` in its closure file, at crank 0.5 rad."""
    side = tmp_path_factory.mktemp("twin") / "fourbar.yaml"
    side.write_text(fourbar_yaml.read_text() + f"closure_springs: {{0: {BALL}}}\n")
    twin = load_model(fourbar_urdf, side, geometry=False)
    return twin, cl.assemble(twin, [FOURBAR_ANGLES[0]], twin.reference_configuration()).q


def _same_as_twin(clm, urdf_twin) -> None:
    state = cl.Configuration(clm, clm.reference_configuration())
    assert state.closure_error <= 1e-12  # the stored start, cut joints included, is closed
    twin, q_twin = urdf_twin
    C = cl.compliance(state, "P").C
    assert_close_in_norm(C, cl.compliance(twin, q_twin, "P").C, RTOL_TWIN)
    cut = {n: np.inf for n in twin.springs if "<->" in n}  # the cut's joints locked
    rigid = cl.compliance(twin.with_springs({**twin.springs, **cut}), q_twin, "P").C
    assert C[0, 0] > 1.01 * rigid[0, 0]  # the spring at C counts


def test_an_mjcf_connect_made_elastic_equals_the_urdf_twin(fourbar_mjcf, urdf_twin):
    clm = load_model(fourbar_mjcf, geometry=False, closure_springs={0: BALL})
    assert len(clm.reference_configuration()) == clm.model.nq
    _same_as_twin(clm, urdf_twin)


def test_an_sdf_ball_made_elastic_equals_the_urdf_twin(tmp_path, urdf_twin):
    path = write(tmp_path, fourbar_sdf("1.7"))
    clm = load_model(path, geometry=False, actuated=["crank"], closure_springs={0: BALL})
    _same_as_twin(clm, urdf_twin)


def test_a_keyword_spring_at_an_sdf_loop_joint_with_its_own_spring_is_refused(tmp_path):
    path = write(tmp_path, slider_crank_sdf(False, pin_k=300.0))
    with pytest.raises(InvalidInputError, match=r"loops \[0\] \(\['pin'\]\).*a spring in the file"):
        load_model(path, geometry=False, closure_springs={0: BALL})


def test_a_keyword_index_out_of_range_names_the_file(fourbar_mjcf):
    with pytest.raises(InvalidInputError, match=r"fourbar.xml.*closure_springs index 1; expect"):
        load_model(fourbar_mjcf, geometry=False, closure_springs={1: BALL})
