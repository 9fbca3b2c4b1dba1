"""Tests of the anchors' kinematics kept between calls at the same configuration
(closedloop.elastostatics.point_closures.anchor_kinematics): what the gap and the curvature
read from it equals what they compute without it (in a thread of its own, whose workspace
and cache are new), a configuration that differs in one bit or a model that differs is not
served from it, and threads do not see each other's.

The values themselves are tested against Pinocchio's frames and central differences in
test_tangent.py; here the reference is the same computation without the kept arrays.
"""

from __future__ import annotations

import threading

import numpy as np
import pinocchio as pin
import pytest

from closedloop.elastostatics.compensation import held_model
from closedloop.elastostatics.point_closures import anchor_kinematics
from closedloop.elastostatics.tangent import closure_curvature, closure_gap
from closedloop.kinematics.constraints import update_kinematics

# The same arithmetic on the same inputs in another thread: equal to rounding of
# metre-scale kinematics (the kernels are the same; the margin is for a BLAS that splits
# a product differently by thread).
RTOL_SAME = 1e-14


def _in_new_thread(f):
    """f() in a thread of its own (a new workspace of the model, nothing kept yet)."""
    out = []
    t = threading.Thread(target=lambda: out.append(f()))
    t.start()
    t.join()
    return out[0]


def _gap_and_curvature(clm, q, lam):
    c, A = closure_gap(clm, q)
    return c, A, closure_curvature(clm, q, lam, update=False)


@pytest.fixture(scope="module")
def case(cahyman):
    """CaHyMan away from closure (six point closures, nv = 27), two configurations and
    multipliers."""
    clm, rng = cahyman.clm, np.random.default_rng(11)
    q0 = cahyman.assemble(np.radians([60.0, 60.0, 60.0]), np.radians(45.0), 0.025)
    q1 = pin.integrate(clm.model, q0, rng.normal(scale=0.05, size=clm.model.nv))
    q2 = pin.integrate(clm.model, q0, rng.normal(scale=0.05, size=clm.model.nv))
    return clm, q1, q2, rng.normal(size=clm.n_constraints) * 50.0


def test_kept_kinematics_equal_a_fresh_evaluation(case):
    """The gap then the curvature at one q (the second reads the kept arrays) equal both
    computed in a new thread, and the curvature alone there (nothing kept before it)."""
    clm, q1, _, lam = case
    c, A = closure_gap(clm, q1)
    kept = anchor_kinematics(clm, q1)
    assert anchor_kinematics(clm, q1.copy()) is kept  # same bits: served from the cache
    H = closure_curvature(clm, q1, lam, update=False)
    c_new, A_new, H_new = _in_new_thread(lambda: _gap_and_curvature(clm, q1, lam))
    H_alone = _in_new_thread(lambda: closure_curvature(clm, q1, lam))
    np.testing.assert_allclose(c, c_new, rtol=RTOL_SAME, atol=0.0)
    np.testing.assert_allclose(A, A_new, rtol=RTOL_SAME, atol=RTOL_SAME * np.abs(A).max())
    scale = np.abs(H_new).max()
    np.testing.assert_allclose(H, H_new, rtol=RTOL_SAME, atol=RTOL_SAME * scale)
    np.testing.assert_allclose(H_alone, H_new, rtol=RTOL_SAME, atol=RTOL_SAME * scale)
    assert not any(a.flags.writeable for a in kept)  # shared: read-only


def test_another_configuration_is_not_served_from_the_cache(case):
    """After the kinematics of q1, those of q2 and of q1 with one entry one ulp away are
    computed anew, and equal a fresh evaluation at their own q."""
    clm, q1, q2, _ = case
    closure_gap(clm, q1)
    kept = anchor_kinematics(clm, q1)
    c2, A2 = closure_gap(clm, q2)
    assert anchor_kinematics(clm, q2) is not kept
    c2_new, A2_new = _in_new_thread(lambda: closure_gap(clm, q2))
    np.testing.assert_allclose(c2, c2_new, rtol=RTOL_SAME, atol=0.0)
    np.testing.assert_allclose(A2, A2_new, rtol=RTOL_SAME, atol=RTOL_SAME * np.abs(A2).max())
    assert np.abs(c2 - closure_gap(clm, q1)[0]).max() > 1e-4  # q1 and q2 differ
    closure_gap(clm, q1)
    kept = anchor_kinematics(clm, q1)
    q_ulp = q1.copy()
    q_ulp[0] = np.nextafter(q_ulp[0], np.inf)
    update_kinematics(clm, q_ulp)
    assert anchor_kinematics(clm, q_ulp) is not kept


def test_another_model_is_not_served_from_the_cache(case):
    """A model with other springs on the same Pinocchio model (its own workspace) at the
    same q gets arrays of its own."""
    clm, q1, _, _ = case
    other = held_model(clm)
    assert other.model is clm.model
    closure_gap(clm, q1)
    kept = anchor_kinematics(clm, q1)
    closure_gap(other, q1)
    assert anchor_kinematics(other, q1) is not kept
    A = closure_gap(clm, q1)[1]
    np.testing.assert_allclose(
        closure_gap(other, q1)[1], A, rtol=RTOL_SAME, atol=RTOL_SAME * np.abs(A).max()
    )


def test_threads_keep_their_own(case):
    """Threads that evaluate the gap and the curvature at their own q at once get what
    one thread gets for that q alone."""
    clm, q1, q2, lam = case
    expected = [_in_new_thread(lambda q=q: _gap_and_curvature(clm, q, lam)) for q in (q1, q2)]
    results, barrier = {}, threading.Barrier(4)

    def work(i):
        q = (q1, q2)[i % 2]
        barrier.wait()
        results[i] = [_gap_and_curvature(clm, q, lam) for _ in range(20)]

    threads = [threading.Thread(target=work, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for i, runs in results.items():
        for got in runs:
            for a, b in zip(got, expected[i % 2], strict=True):
                np.testing.assert_allclose(a, b, rtol=RTOL_SAME, atol=RTOL_SAME * np.abs(b).max())
    assert len(results) == 4
