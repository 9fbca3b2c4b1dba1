"""The consistent closed form and the generic Pinocchio backend: two independent
implementations of the same machine, compared on C (and the plate twist) at random poses."""

import numpy as np
import pytest
from helpers import assert_close_in_norm

from cahyman_pin.api import stiffness
from cahyman_pin.backends.consistent import consistent_compliance
from cahyman_pin.backends.registry import backend_names
from cahyman_pin.params import DEFAULT_PARAMS
from closedloop.exceptions import InvalidInputError

#: Agreement required by the project on C between the two backends. Both are exact linear
#: theory; their differences are rounding (measured ~1e-14 relative), so 1e-8 leaves room
#: for ill-conditioning without hiding a modelling difference (those show up at 1e-3).
RTOL_BACKENDS = 1e-8
N_POSES = 100


def random_poses(rng: np.random.Generator, n: int):
    alpha = np.deg2rad(rng.uniform(30.0, 90.0, (n, 3)))
    alpha4 = np.deg2rad(rng.uniform(0.0, 90.0, n))
    s4 = rng.uniform(0.0, DEFAULT_PARAMS.s4_max, n)
    return alpha, alpha4, s4


def test_consistent_equals_generic_at_random_poses():
    alpha, alpha4, s4 = random_poses(np.random.default_rng(20261122), N_POSES)
    C_batch = consistent_compliance(alpha, alpha4, s4, DEFAULT_PARAMS)
    for i in range(N_POSES):
        generic = stiffness(alpha[i], alpha4[i], s4[i], backend="generic")
        assert_close_in_norm(C_batch[i], generic.C, RTOL_BACKENDS)


def test_backends_agree_with_other_dimensions_and_platform_twist():
    rng = np.random.default_rng(7)
    params = DEFAULT_PARAMS.replace(a=0.25, b=0.07, h=0.06, r_e=0.12, r_p=0.09, HQ=0.04,
                                    L=0.2, K_b=1.5e6, K_d=3.5e6, K_T=3e3)  # fmt: skip
    alpha, alpha4, s4 = random_poses(rng, 10)
    for i in range(10):
        g = stiffness(alpha[i], alpha4[i], s4[i], params=params, backend="generic")
        c = stiffness(alpha[i], alpha4[i], s4[i], params=params, backend="consistent")
        assert_close_in_norm(c.C, g.C, RTOL_BACKENDS)
        assert_close_in_norm(c.C_platform, g.C_platform, RTOL_BACKENDS)
        np.testing.assert_allclose(c.pose.M, g.pose.M, rtol=0, atol=1e-12)


def test_backend_registry():
    assert set(backend_names()) >= {"generic", "consistent", "published"}
    with pytest.raises(InvalidInputError, match=r"unknown backend 'nope'.*generic"):
        stiffness(np.deg2rad([60, 60, 60]), 1.0, 0.01, backend="nope")


def test_published_backend_is_marked_nonsymmetric():
    r = stiffness(np.deg2rad([45, 60, 75]), np.deg2rad(45), 0.0, backend="published")
    assert r.indices is None  # its C is not symmetric: no symmetric-matrix indices
    assert not np.allclose(r.C, r.C.T)
    np.testing.assert_allclose(r.K @ r.C, np.eye(6), atol=1e-9)
