"""The fast paths of the compliance (serial, partitioned) against the general null space."""

import numpy as np
import pytest
from mechanisms import PATH_CASES as CASES

import closedloop as cl

#: Both paths compute the same C from the same Jacobians, in a different order of
#: operations: they agree to rounding on well-conditioned mechanisms.
RTOL_PATHS = 1e-12


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
    clm, q, frame = CASES["fourbar"][0]()
    with pytest.raises(cl.InvalidInputError, match=r"path 'fast'; expected one of"):
        cl.compliance(clm, q, frame, path="fast")
