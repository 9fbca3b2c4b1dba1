"""The fast paths of the compliance (serial, partitioned) against the general null space."""

from pathlib import Path

import mechanisms as mech
import numpy as np
import pytest

import closedloop as cl
from closedloop.io import load_urdf, robot_data_dir

REPO = Path(__file__).resolve().parent.parent

#: Both paths compute the same C from the same Jacobians, in a different order of
#: operations: they agree to rounding on well-conditioned mechanisms.
RTOL_PATHS = 1e-12


def _fourbar():
    m = cl.load_model(REPO / "urdf/fourbar.urdf", REPO / "urdf/fourbar.yaml")
    return m, cl.assemble(m, actuated=[0.3]).q, "P"


def _cahyman():
    from cahyman_pin.model import cahyman_model

    m = cahyman_model()
    return m.clm, m.assemble(np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.01), "M"


def _ur5():
    m = load_urdf(robot_data_dir() / "ur_description/urdf/ur5_robot.urdf", joint_stiffness=1e4)
    return m, np.array([0.3, -1.2, 1.4, -0.6, 1.1, 0.2]), "tool0"


def _mechanism(build):
    m = build()
    return m.clm, m.q, m.frame


CASES = {
    "fourbar": (_fourbar, "partitioned"),
    "cahyman": (_cahyman, "partitioned"),
    "ur5": (_ur5, "serial"),
    "stewart": (lambda: _mechanism(lambda: mech.stewart(position=(0.05, -0.02, 1.1),
                                                        psi=0.2, tilt=(0.1, -0.05))),
                "partitioned"),
    "rrr3": (lambda: _mechanism(lambda: mech.rrr3((0.02, -0.01, 0.1))), "partitioned"),
    "fivebar": (lambda: _mechanism(lambda: mech.fivebar((0.02, 0.35))), "partitioned"),
    # the rods spin about their axes: the passive joints are not determined
    "delta": (lambda: _mechanism(lambda: mech.delta(k_rod=2e5)), "null-space"),
}  # fmt: skip


@pytest.mark.parametrize("name", sorted(CASES))
def test_fast_path_equals_the_null_space_path(name):
    build, expected_path = CASES[name]
    clm, q, frame = build()
    fast = cl.compliance(clm, q, frame)
    assert fast.path == expected_path
    general = cl.compliance(clm, q, frame, path="null-space")
    assert general.path == "null-space"
    scale = np.abs(general.C).max()
    np.testing.assert_allclose(fast.C, general.C, rtol=0, atol=RTOL_PATHS * scale)
    w = np.array([1.0, -2.0, 0.5, 0.1, 0.3, -0.2])
    dq_f, dq_g = fast.joint_deflection(w), general.joint_deflection(w)
    np.testing.assert_allclose(dq_f, dq_g, rtol=0, atol=RTOL_PATHS * np.abs(dq_g).max())
    assert (fast.rank, fast.is_full_rank) == (general.rank, general.is_full_rank)
    if fast.is_full_rank:
        np.testing.assert_allclose(
            fast.K, general.K, rtol=0, atol=1e3 * RTOL_PATHS * np.abs(general.K).max()
        )
    np.testing.assert_allclose(fast.condition_number, general.condition_number, rtol=1e-9)


def test_unknown_path_is_refused():
    clm, q, frame = _fourbar()
    with pytest.raises(cl.InvalidInputError, match=r"path 'fast'; expected one of"):
        cl.compliance(clm, q, frame, path="fast")
