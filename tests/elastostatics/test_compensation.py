"""The exact compensation's iterations (issue #42): the warm start extrapolated from the last
points of a path, and the chord steps on a kept Newton matrix that fall back to a fresh
tangent where they stall; the answers checked with Pinocchio's kinematics alone."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from pinocchio_statics import gaps, placement, unbalance

import closedloop as cl
from closedloop.elastostatics import compensation
from closedloop.elastostatics.compensation import (
    EXTRAPOLATION_LIMIT,
    compensate,
    extrapolated,
    loaded_equilibrium,
)
from closedloop.io.loader import load_urdf
from closedloop.kinematics.frame_task import FrameTask
from closedloop.model.gravity import Load

#: Sums and differences of a few configurations near 1 rad: rounding [rad].
ATOL_ROUNDING = 1e-14
#: Closure and task rows of a compensation [m per L, rad], with a factor 2 for recomputing
#: them here (tests/analysis/test_paths.py).
ATOL = 2e-12
#: Agreement of two compensated equilibria [rad, m]: each balances to FORCE_RTOL (1e-11)
#: of its forces and meets the task to 1e-12, with a factor 100 (test_paths.ATOL_SAME).
ATOL_SAME = 1e-10
#: Unbalance relative to the forces, the closure Jacobian by central differences
#: (tests/analysis/test_paths.py).
RTOL_UNBALANCE = 1e-9


@pytest.fixture(scope="module")
def ur5(ur5_urdf):
    return load_urdf(ur5_urdf, joint_stiffness=1e4, geometry=False)


@pytest.mark.parametrize(
    ("s", "used"), [(1.0, 1.0), (0.5, 0.5), (10.0, EXTRAPOLATION_LIMIT), (-1.0, 0.0)]
)
def test_extrapolated_is_linear_along_the_last_step(ur5, s, used):
    """On revolute joints (q - q' is pin.difference): the deflection d1 of the last point
    plus its change d1 - d0 from the point before times the step to this point along the
    last one, s, clamped to [0, EXTRAPOLATION_LIMIT]."""
    r0 = np.array([0.3, -1.2, 1.4, -0.6, 1.1, 0.2])
    back = np.array([1.0, -2.0, 0.5, 0.0, 1.5, -1.0]) * 1e-3
    r1 = r0 + back
    d0 = np.array([2.0, -1.0, 3.0, 0.5, -0.5, 1.0]) * 1e-4
    d1 = np.array([2.5, -1.5, 2.0, 1.0, 0.0, 0.5]) * 1e-4
    q_rest = r1 + s * back
    got = extrapolated(ur5, q_rest, [(r0, r0 + d0), (r1, r1 + d1)])
    np.testing.assert_allclose(got, q_rest + d1 + used * (d1 - d0), atol=ATOL_ROUNDING)
    # from the last point alone: its deflection carried to q_rest
    got = extrapolated(ur5, q_rest, [(r1, r1 + d1)])
    np.testing.assert_allclose(got, q_rest + d1, atol=ATOL_ROUNDING)


@pytest.fixture(scope="module")
def thrust(cahyman):
    """CaHyMan's tool at a pose, 60 N of thrust along its axis, the tool-axis task there
    and the uncompensated equilibrium (a start off by the whole deflection)."""
    clm = cahyman.clm
    q = np.array(cahyman.assemble(np.radians([60.0, 60.0, 60.0]), np.radians(45.0), 0.025))
    T = placement(clm.model, q, "tool")
    w = np.r_[-60.0 * T.rotation[:, 2], 0.0, 0.0, 0.0]
    loaded, _ = loaded_equilibrium(clm, "tool", q, Load(w))
    return q, T, w, FrameTask("tool-axis", T), loaded


def _check(cahyman, q, T, w, comp) -> None:
    """The compensated equilibrium closes the loops, holds the tool's position and axis
    and balances with the springs at rest at the commands (Pinocchio alone)."""
    clm, L = cahyman.clm, cahyman.clm.length
    np.testing.assert_allclose(gaps(clm, comp.q), 0.0, atol=ATOL * L)
    Tc = placement(clm.model, comp.q, "tool")
    np.testing.assert_allclose(Tc.translation, T.translation, atol=ATOL * L)
    np.testing.assert_allclose(Tc.rotation[:, 2], T.rotation[:, 2], atol=ATOL)
    rest = cl.assemble(clm, comp.commands, q).q
    assert unbalance(clm, comp.q, rest, "tool", w) <= RTOL_UNBALANCE


def test_chord_steps_keep_the_tangent_while_they_contract(cahyman, thrust):
    """From the uncompensated equilibrium the compensation forms one Newton matrix and
    goes on with chord steps on it."""
    q, T, w, task, loaded = thrust
    comp = compensate(cahyman.clm, "tool", task, q, Load(w), loaded)
    _check(cahyman, q, T, w, comp)
    assert comp.matrices == 1 < comp.iterations


def test_a_chord_that_stalls_falls_back_to_a_fresh_tangent(cahyman, thrust, monkeypatch):
    """A chord step must shrink the residual by CHORD_RATE; where none does (a rate of 0)
    every step is a Newton step on a fresh tangent, to the same compensation."""
    q, T, w, task, loaded = thrust
    chords = compensate(cahyman.clm, "tool", task, q, Load(w), loaded)
    monkeypatch.setattr(compensation, "CHORD_RATE", 0.0)
    comp = compensate(cahyman.clm, "tool", task, q, Load(w), loaded)
    _check(cahyman, q, T, w, comp)
    assert comp.matrices >= comp.iterations > 1
    np.testing.assert_allclose(pin.difference(cahyman.clm.model, comp.q, chords.q), 0.0,
                               atol=ATOL_SAME)  # fmt: skip
    np.testing.assert_allclose(comp.commands, chords.commands, atol=ATOL_SAME)


def test_a_compensation_that_does_not_converge_is_an_equilibrium_error(
    cahyman, thrust, monkeypatch
):
    """Out of iterations: EquilibriumError naming the frame and the residual left."""
    q, _, w, task, _ = thrust
    monkeypatch.setattr(compensation, "MAX_ITER", 1)
    with pytest.raises(cl.EquilibriumError, match=r"frame 'tool'.*did not converge in 1 "):
        compensate(cahyman.clm, "tool", task, q, Load(w), q)
