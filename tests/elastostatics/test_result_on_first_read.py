"""Fields a compliance result computes on their first read (closedloop.common.arrays.
OnFirstRead): K of the serial and partitioned paths, G of the serial path with one spring a
coordinate. Each is computed once, read-only, the value the query computed before it was
deferred (the same arithmetic: np.testing.assert_array_equal against that arithmetic
written out here from Pinocchio's Jacobian), the inverse of C and the statics' map (to
their conditioning), the same array in every thread that reads it first, and kept by a
pickled or copied result."""

from __future__ import annotations

import copy
import dataclasses
import pickle
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pinocchio as pin
import pytest
from helpers import Calls, assert_close_in_norm
from mechanisms import cahyman_case

import closedloop as cl
import closedloop.elastostatics.query as query_module
import closedloop.elastostatics.unloaded as unloaded
from closedloop.common.conditioning import spectrum_from_factor, twist_scaling

#: The fields computed on first read.
ON_FIRST_READ = ("stiffness_matrix", "G")
#: Threads that read a result's fields first at once.
THREADS = 8
#: K from the SVD of the factor against inv(C): both within eps cond(K_s) of K_s
#: (relative, scaled), a margin of 100 for the 6 x 6 products and solves.
INVERSE_MARGIN = 100.0
#: K_q G w = J^T w (the springs balance the wrench): one product per entry of G, then
#: J^T w and K_q dq of about max |J| |w| each, relative to it.
BALANCE_RTOL = 1e-13


def poses(q: np.ndarray, n: int, seed: int = 2) -> list[np.ndarray]:
    """n UR5 poses around q, inside the joints' limits [rad]."""
    rng = np.random.default_rng(seed)
    return [q + rng.uniform(-0.4, 0.4, q.size) for _ in range(n)]


def test_k_and_g_are_computed_on_their_first_read_once(monkeypatch, ur5):
    clm, q = ur5
    K_calls = Calls(monkeypatch, unloaded, "stiffness_from_factor")
    G_calls = Calls(monkeypatch, query_module, "_transposed_product")
    result = cl.ComplianceQuery(clm, "tool0")(q)
    assert result.path == "serial"
    assert (K_calls.n, G_calls.n) == (0, 0)
    assert not set(ON_FIRST_READ) & set(vars(result))  # not computed yet
    K, G = result.K, result.G
    assert (K_calls.n, G_calls.n) == (1, 1)
    assert result.stiffness_matrix is K and result.K is K and result.G is G
    assert (K_calls.n, G_calls.n) == (1, 1)


def test_a_partitioned_result_computes_k_on_first_read(monkeypatch):
    clm, q, frame = cahyman_case()
    K_calls = Calls(monkeypatch, unloaded, "stiffness_from_factor")
    result = cl.compliance(clm, q, frame)
    assert result.path == "partitioned" and result.is_full_rank
    assert K_calls.n == 0 and "G" in vars(result)  # G is computed with the partition
    assert result.K is result.stiffness_matrix
    assert K_calls.n == 1


def eager_fields(clm, q: np.ndarray, length: float) -> dict:
    """K, G and C of the UR5 at q written out from Pinocchio's Jacobian, computed at once:
    B = J P with P = diag(1 / sqrt(k)) (revolute joints: s_q = 1), B_s = D B; K from the
    eager spectrum (closedloop.common.conditioning.spectrum_from_factor, what the query
    computed before K was deferred), G = P B^T and C = B B^T, one product an entry."""
    model, data = clm.model, clm.model.createData()
    P = 1.0 / np.sqrt(clm.stiffness)
    pin.computeJointJacobians(model, data, q)
    J = pin.getFrameJacobian(model, data, model.getFrameId("tool0"), pin.LOCAL_WORLD_ALIGNED)
    B = J * P
    d = twist_scaling(length)
    K = spectrum_from_factor(B * d[:, None], length).K
    return {"stiffness_matrix": K, "G": P[:, None] * B.T, "C": B.dot(B.T), "J": J, "d": d}


def test_values_read_later_are_those_of_the_eager_arithmetic(ur5):
    """K and G read later are the eager arithmetic's bit for bit (:func:`eager_fields`); K
    inverts C and K_q G w = J^T w (the springs balance the wrench)."""
    clm, q = ur5
    query = cl.ComplianceQuery(clm, "tool0")
    for q_i in [q, *poses(q, 5)]:
        result = query(q_i)
        eager = eager_fields(clm, q_i, result.length)
        np.testing.assert_array_equal(result.K, eager["stiffness_matrix"], strict=True)
        np.testing.assert_array_equal(result.G, eager["G"], strict=True)
        np.testing.assert_array_equal(result.C, eager["C"], strict=True)
        rtol = INVERSE_MARGIN * np.finfo(float).eps * result.condition_number
        assert_close_in_norm(result.K, np.linalg.inv(result.C), rtol, scale=1.0 / eager["d"])
        w = np.array([10.0, -20.0, 5.0, 1.0, -2.0, 0.5])
        assert_close_in_norm(clm.stiffness * (result.G @ w), eager["J"].T @ w, BALANCE_RTOL)


def test_a_partitioned_k_read_later_is_the_null_space_paths(ur5):
    """CaHyMan's K, read after the query (partitioned path), against the general path's
    (null-space, computed at once, another factorisation of the same springs) and against
    inv(C): each within eps cond(K_s) times the margin, scaled."""
    clm, q, frame = cahyman_case()
    result = cl.compliance(clm, q, frame)
    general = cl.compliance(clm, q, frame, path="null-space")
    assert (result.path, general.path) == ("partitioned", "null-space")
    assert "stiffness_matrix" in vars(general) and "stiffness_matrix" not in vars(result)
    rtol = INVERSE_MARGIN * np.finfo(float).eps * result.condition_number
    scale = 1.0 / twist_scaling(result.length)
    assert_close_in_norm(result.K, general.K, rtol, scale=scale)
    assert_close_in_norm(result.K, np.linalg.inv(result.C), rtol, scale=scale)


def test_the_fields_are_read_only(ur5):
    clm, q = ur5
    result = cl.compliance(clm, q, "tool0")
    for name in ON_FIRST_READ:
        value = getattr(result, name)
        assert not value.flags.writeable, name
        with pytest.raises(ValueError, match="read-only"):
            value[0, 0] = 1.0


def test_a_rank_deficient_result_has_no_k_and_computes_g_on_first_read(ur5):
    clm, q = ur5
    straight = q.copy()
    straight[2] = 0.0  # the elbow stretched: a singular pose
    result = cl.compliance(clm, straight, "tool0")
    assert result.rank == 5 and result.stiffness_matrix is None
    assert "G" not in vars(result)
    with pytest.raises(cl.RigidDirectionsError):
        result.K  # noqa: B018
    assert result.G.shape == (6, 6) and not result.G.flags.writeable


def test_threads_reading_first_at_once_get_one_array(ur5):
    """8 threads wait at a barrier, then read K and G of one result at once: each field is
    one array (the first kept), equal to that of the same query read in one thread."""
    clm, q = ur5
    query = cl.ComplianceQuery(clm, "tool0")
    Q = poses(q, 40)
    with ThreadPoolExecutor(max_workers=THREADS) as pool:
        for q_i in Q:
            result, twin = query(q_i), query(q_i)
            barrier = threading.Barrier(THREADS)

            def read(_, result=result, barrier=barrier):
                barrier.wait()
                return [getattr(result, name) for name in ON_FIRST_READ]

            seen = list(pool.map(read, range(THREADS)))
            for i, name in enumerate(ON_FIRST_READ):
                assert all(values[i] is getattr(result, name) for values in seen), name
                np.testing.assert_array_equal(
                    getattr(result, name), getattr(twin, name), strict=True
                )


def test_a_pickled_or_copied_result_carries_the_fields(ur5):
    """Pickled before any read (a map's workers send their results so) or after, copied,
    deep-copied: the fields are the eager arithmetic's (:func:`eager_fields`), read-only,
    and the summary and repr are those of a result made by the constructor."""
    clm, q = ur5
    eager = eager_fields(clm, q, cl.compliance(clm, q, "tool0").length)
    unread = cl.compliance(clm, q, "tool0")
    state = unread.__getstate__()
    assert "_on_first_read" not in state and set(ON_FIRST_READ) <= set(state)
    copies = [pickle.loads(pickle.dumps(unread)), copy.copy(cl.compliance(clm, q, "tool0")),
              copy.deepcopy(cl.compliance(clm, q, "tool0"))]  # fmt: skip
    read = cl.compliance(clm, q, "tool0")
    read.K, read.G  # noqa: B018 (read first, then pickled)
    copies.append(pickle.loads(pickle.dumps(read)))
    made = dataclasses.replace(read)  # by the constructor: every field given
    for other in copies:
        assert "_on_first_read" not in vars(other)
        for name in ON_FIRST_READ:
            value = getattr(other, name)
            np.testing.assert_array_equal(value, eager[name], strict=True)
            assert not value.flags.writeable, name
        assert other.to_dict() == made.to_dict()
        assert repr(other) == repr(made)


def test_a_zero_preload_gives_the_fields_of_the_unloaded_result(ur5):
    clm, q = ur5
    preloaded = cl.compliance(clm, q, "tool0", preload=np.zeros(6))
    unloaded_result = cl.compliance(clm, q, "tool0")
    for name in ON_FIRST_READ:
        np.testing.assert_array_equal(
            getattr(preloaded, name), getattr(unloaded_result, name), strict=True
        )
