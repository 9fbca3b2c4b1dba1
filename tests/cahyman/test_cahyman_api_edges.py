"""Edges of the CaHyMan user API: typed refusals of :meth:`CaHyManModel.inverse`, units
named in the messages, and the reason given when a closed form's C is rank deficient."""

import numpy as np
import pytest

from cahyman_pin.api import stiffness
from cahyman_pin.cli import main
from cahyman_pin.geometry import inverse_legs
from cahyman_pin.model import cahyman_model
from cahyman_pin.params import DEFAULT_PARAMS
from closedloop.common.conditioning import twist_scaling
from closedloop.exceptions import AssemblyError, InvalidInputError, SingularConfigurationError


@pytest.mark.parametrize(
    "args",
    [
        ([0.1, 0.12], 1.5, 0.0),  # ragged: was a bare ValueError
        ("0.12", 1.5, 0.0),  # a string: was read as a number
        (0.12, 1.5 + 0j, 0.0),  # complex: was a TypeError
        (None, 1.5, 0.0),  # was reported as NaN
    ],
)
def test_inverse_refuses_what_is_not_three_real_numbers_by_name(args):
    with pytest.raises(InvalidInputError, match=r"z_H, phi, psi must be real numbers"):
        cahyman_model().inverse(*args)


def test_inverse_refuses_an_azimuth_in_degrees():
    z_H, phi, psi = 0.12, 1.5, 30.0  # psi = 30 deg meant: a reachable pose at 30 rad
    assert np.all(np.isfinite(inverse_legs(z_H, phi, psi, DEFAULT_PARAMS)))  # was answered
    with pytest.raises(InvalidInputError, match=r"psi = 30 rad = 1718.873 deg .*radians"):
        cahyman_model().inverse(z_H, phi, psi)
    cahyman_model().inverse(z_H, phi, -2 * np.pi)  # one turn is still an angle


def test_an_unreachable_height_names_the_reach():
    with pytest.raises(AssemblyError, match=r"within h \+- b = \[-0.03, 0.13\] m"):
        cahyman_model().inverse(130.0, 1.5, 0.0)  # millimetres by mistake


def test_a_stroke_outside_its_range_is_named_in_mm_on_the_command_line(capsys):
    assert main(["stiffness", "--s4", "60"]) == 2
    err = capsys.readouterr().err
    assert "s_4 = 0.06 m = 60 mm is outside the stroke [0, 0.05] m = [0, 50] mm" in err


REGULAR = (np.array([1.0, 1.1, 1.2]), 0.5, 0.02)  # alpha 57..69 deg: far from singular
#: K from a square-root factor keeps about eps sqrt(cond(K_s)) relative; two backends, each
#: so (tests/cahyman/test_consistent_factor.py measured up to 0.5 of it per backend).
ULPS_SQRT_COND = 8


def test_springs_far_apart_are_springs_in_both_backends():
    """Springs 18 orders apart (within the 1e-6..1e12 range) at a regular pose: both
    backends answer, and agree within what the square-root factors resolve (eps sqrt(cond)
    relative). The consistent backend refused them (its rank rule took B, not its
    kinematic part) while the generic one answered."""
    params = DEFAULT_PARAMS.replace(K_T=1e-6, K_b=1e12, K_d=1e12)
    generic = stiffness(*REGULAR, params=params)
    consistent = stiffness(*REGULAR, params=params, backend="consistent")
    assert generic.is_full_rank and consistent.is_full_rank
    cond = generic.indices.scaled_condition_number
    assert cond > 1e14  # far beyond where a rule on B alone would refuse
    tol = ULPS_SQRT_COND * np.finfo(float).eps * np.sqrt(cond)
    np.testing.assert_allclose(consistent.det_K, generic.det_K, rtol=tol)
    d = twist_scaling(params.length)  # K compared unit-free, K_s = D^-1 K D^-1
    K_s, K_s_ref = consistent.K / np.outer(d, d), generic.K / np.outer(d, d)
    np.testing.assert_allclose(K_s, K_s_ref, rtol=0, atol=tol * np.abs(K_s_ref).max())


@pytest.mark.parametrize("params", [DEFAULT_PARAMS, DEFAULT_PARAMS.replace(K_T=2e3)])
def test_a_singular_pose_is_still_called_so(params):
    with pytest.raises(SingularConfigurationError, match="a singular pose"):
        stiffness([1e-7, 1.0, 1.0], 0.5, 0.02, params=params, backend="consistent")
