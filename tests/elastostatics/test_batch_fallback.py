"""The fall-back of closedloop.compliances to the single query when the stacked path fails
(a LAPACK error): every configuration answered as the single query does, the valid
characteristic length kept (the maps compute their unit-free indices with it).

The stacked path is forced to fail by replacing closedloop.elastostatics.batch.stacked_compliances
in the test only: the fall-back is the code under test, and the references are the single
query and the map computed without the failure.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import UR5_JOINTS, UR5_Q, assert_close_in_norm

import closedloop as cl
import closedloop.elastostatics.batch
from closedloop.analysis.maps import stiffness_map

#: The single query, or the stacked path, against the single query: the same formulas
#: with LAPACK calls in another order of operations (1e-16 measured at these regular
#: poses, condition numbers ~1e2; the stacked tests of test_batch.py allow 1e-12).
RTOL_SAME_QUERY = 1e-12
#: Elbow angles of the map [rad]: regular poses of the UR5.
ELBOW = (1.0, 1.5)


def _fail(*args, **kwargs):
    raise np.linalg.LinAlgError("SVD did not converge")


@pytest.fixture
def ur5():
    return cl.load_model(cl.data.robot_file("ur5"), joint_stiffness=1e4)


@pytest.mark.parametrize("length", [None, 0.4])
def test_a_failed_stacked_path_keeps_the_length(ur5, monkeypatch, length):
    Q = np.array([UR5_Q, UR5_Q + 0.1])
    monkeypatch.setattr(closedloop.elastostatics.batch, "stacked_compliances", _fail)
    batch = cl.compliances(ur5, Q, "tool0", length=length)
    assert batch.length == (ur5.length if length is None else length)
    assert not batch.stacked.any()
    for i, q in enumerate(Q):
        single = cl.compliance(ur5, q, "tool0", length=length)
        assert_close_in_norm(batch.C[i], single.C, RTOL_SAME_QUERY)
        assert batch.rank[i] == single.rank
        assert batch.condition_number[i] == pytest.approx(single.condition_number,
                                                          rel=RTOL_SAME_QUERY)  # fmt: skip


def test_a_map_whose_stacked_path_fails_has_the_same_indices(ur5, monkeypatch):
    """Before, the length became NaN: det_K NaN at every point, with status ok."""
    fixed = dict(zip(UR5_JOINTS, UR5_Q, strict=True))
    fixed.pop("elbow_joint")
    reference = stiffness_map(ur5, "tool0", sweeps={"elbow_joint": ELBOW}, fixed=fixed)
    monkeypatch.setattr(closedloop.elastostatics.batch, "stacked_compliances", _fail)
    fallen = stiffness_map(ur5, "tool0", sweeps={"elbow_joint": ELBOW}, fixed=fixed)
    assert list(fallen.status) == list(reference.status) == ["ok", "ok"]
    np.testing.assert_array_equal(fallen.data.length, reference.data.length)
    for name, values in reference.indices.items():
        assert np.all(np.isfinite(fallen.indices[name])), name
        np.testing.assert_allclose(fallen.indices[name], values, rtol=RTOL_SAME_QUERY,
                                   err_msg=name)  # fmt: skip
