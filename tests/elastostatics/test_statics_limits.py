"""Tests of the refusals and limits of the nonlinear statics (closedloop.elastostatics.statics).

Bad inputs and solver arguments, mechanisms without an equilibrium, loads past a limit
load (a fold), Newton failures that are not one, and joint limits flagged or enforced.
Expected values: the messages and fields of the errors, the joint limits of the model
files, and the virtual-work balance of the equilibria that are returned (helpers).
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from helpers import assert_balanced, pendulum

from closedloop import data
from closedloop.elastostatics.equilibrium import potential_energy
from closedloop.elastostatics.statics import JointLimitError, JointLimitWarning, solve_equilibrium
from closedloop.exceptions import (
    EquilibriumError,
    InvalidInputError,
    MechanismError,
    NameNotFoundError,
    OpenLoopError,
)
from closedloop.io.loader import load_model
from closedloop.kinematics.limits import joints_outside_limits


# ---------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    "wrench", [np.zeros(5), np.zeros((2, 6)), [1.0, 0, 0, np.nan, 0, 0], [np.inf, 0, 0, 0, 0, 0]]
)
def test_bad_wrench_is_rejected(fourbar, wrench):
    clm, q0 = fourbar
    with pytest.raises(InvalidInputError, match="wrench must be 6 finite values"):
        solve_equilibrium(clm, q0, "P", wrench)


def test_bad_rest_configuration_is_rejected(fourbar):
    clm, q0 = fourbar
    with pytest.raises(OpenLoopError, match=r"does not close the loops of 'fourbar'"):
        solve_equilibrium(clm, q0 + 0.01, "P", np.ones(6))
    with pytest.raises(InvalidInputError, match="expected nq=5"):
        solve_equilibrium(clm, q0[:4], "P", np.ones(6))
    with pytest.raises(NameNotFoundError, match="unknown frame 'Q'"):
        solve_equilibrium(clm, q0, "Q", np.ones(6))
    with pytest.raises(InvalidInputError, match="force must be 3 finite values"):
        potential_energy(clm, q0, q0, "P", np.ones(6))
    with pytest.raises(InvalidInputError, match=r"force must be 3 finite values .* \[nan, 0.0"):
        potential_energy(clm, q0, q0, "P", [np.nan, 0.0, 0.0])  # was a NaN energy


def test_mechanism_has_no_equilibrium(fourbar):
    clm, q0 = fourbar
    free_crank = clm.with_springs({"crank": 0.0, "crank_axial": 1e5, "rocker_axial": 2e5})
    with pytest.raises(MechanismError, match="still a mechanism"):
        solve_equilibrium(free_crank, q0, "P", [1.0, 0, 0, 0, 0, 0])


def test_past_the_limit_load_no_equilibrium_is_found(fourbar):
    """The four-bar loaded along (1, 0, -1) has a limit load near 993 N (toggle)."""
    clm, q0 = fourbar
    with pytest.raises(EquilibriumError, match=r"beyond 0\.3\d* of the load: a limit load") as err:
        solve_equilibrium(clm, q0, "P", [3000.0, 0, -3000.0, 0, 0, 0])
    assert 0.25 < err.value.load_fraction < 0.34  # 993 N / 3000 N
    assert err.value.limit_load
    assert err.value.force_residual > 0


def test_a_newton_failure_is_not_called_a_limit_load(fourbar):
    """Too few iterations: the tangent stiffness is still far from singular (margin ~1)."""
    clm, q0 = fourbar
    with pytest.raises(EquilibriumError, match=r"failed to converge .* not a limit load .*: "
                       r"try a larger max_iter \(Newton was still converging") as err:  # fmt: skip
        solve_equilibrium(clm, q0, "P", [300.0, 0, -300.0, 0, 0, 0], max_iter=1, max_halvings=0)
    assert err.value.load_fraction == 0.0
    assert err.value.residual > 1e-12
    assert not err.value.limit_load
    assert err.value.stability_margin == pytest.approx(1.0)  # unloaded: K_t = K_q
    assert err.value.iterations == 1
    with pytest.raises(EquilibriumError, match=r"Newton failed at .* iterations in all") as err:
        solve_equilibrium(clm, q0, "P", [300.0, 0, -300.0, 0, 0, 0], max_iter=2, max_halvings=2)
    assert 0.0 < err.value.load_fraction < 1.0 and not err.value.limit_load
    assert 0.5 < err.value.stability_margin < 1.0


def test_a_load_far_beyond_the_springs_is_called_so(ur5):
    """1e20 N on springs of 1e4 N m/rad: the continuation stalls after the arm has turned
    towards the force; no step size helps, and the advice says so (it suggested a smaller
    max_increment). The elbow had turned 1.4 rad (any joint past 1 rad triggers it)."""
    clm, q = ur5
    for force in (1e20, 1e300):
        with pytest.raises(EquilibriumError, match=r"not a limit load .*: the part of the load "
                           r"reached already turns joint '\w+' by [\d.e+]+ rad from rest: the "
                           r"load is far beyond what the springs hold") as err:  # fmt: skip
            solve_equilibrium(clm, q, "tool0", [force, 0, 0, 0, 0, 0])
        assert "max_increment" not in str(err.value)


def test_few_iterations_and_endless_halvings_still_bracket_the_limit_load(fourbar):
    """Three Newton iterations an increment and no bound on the halvings: the increments
    approach the limit load by halves and bracket it as the default settings do (they
    were once halved until they vanished, 'no progress', without locating it)."""
    clm, q0 = fourbar
    w = [3000.0, 0, -3000.0, 0, 0, 0]
    with pytest.raises(EquilibriumError, match="a limit load") as err:
        solve_equilibrium(clm, q0, "P", w, max_iter=3, max_halvings=10**4)
    with pytest.raises(EquilibriumError, match="a limit load") as default:
        solve_equilibrium(clm, q0, "P", w)
    assert err.value.limit_load and default.value.limit_load
    (lo, hi), (lo_d, hi_d) = err.value.fold_bracket, default.value.fold_bracket
    assert err.value.load_fraction == lo and 0.25 < lo < 0.34
    assert max(lo, lo_d) <= min(hi, hi_d)  # the two brackets hold the same fold


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("max_increment", 0.0, r"max_increment must be a number > 0 .*got 0.0"),
        ("max_increment", -0.1, r"max_increment must be a number > 0 .*got -0.1"),
        ("max_increment", np.nan, r"max_increment must be a number > 0 .*got nan"),
        ("max_step", 0.0, r"max_step must be a number > 0 .*got 0.0"),
        ("max_step", np.float64("nan"), r"max_step must be a number > 0 .*got nan"),
        ("tol", 0.0, r"tol must be a number finite and > 0 \[m, rad\], got 0.0"),
        ("tol", -1e-12, r"tol must be a number finite and > 0 .*got -1e-12"),
        ("tol", np.nan, r"tol must be a number finite and > 0 .*got nan"),
        ("tol", np.inf, r"tol must be a number finite and > 0 .*got inf"),
        ("tol", "1e-9", r"tol must be a number finite and > 0 .*got '1e-9'"),
        ("max_iter", 0, r"max_iter must be an integer >= 1, got 0"),
        ("max_iter", 2.5, r"max_iter must be an integer >= 1, got 2.5"),
        ("max_iter", True, r"max_iter must be an integer >= 1, got True"),
        ("max_halvings", np.int64(-1), r"max_halvings must be an integer >= 0, got -1"),
        ("max_halvings", np.nan, r"max_halvings must be an integer >= 0, got nan"),
    ],
)
def test_bad_solver_arguments_are_rejected(fourbar, option, value, message):
    clm, q0 = fourbar
    with pytest.raises(InvalidInputError, match=message):
        solve_equilibrium(clm, q0, "P", [1.0, 0, 0, 0, 0, 0], **{option: value})


def test_infinite_increment_and_step_are_allowed(fourbar):
    clm, q0 = fourbar
    eq = solve_equilibrium(clm, q0, "P", [30.0, 0, -30.0, 0, 0, 0], max_increment=np.inf)
    assert eq.load_steps == 1
    assert_balanced(clm, eq)
    assert_balanced(
        clm, solve_equilibrium(clm, q0, "P", [30.0, 0, -30.0, 0, 0, 0], max_step=np.inf)
    )


# ---------------------------------------------------------------------------- joint limits
# From urdf/fourbar.urdf: the axial joints of crank and rocker are limited to +-0.01 m.
FOURBAR_AXIAL_LIMIT = 0.01


def test_equilibrium_outside_the_joint_limits_is_flagged_and_warned(fourbar):
    clm, q0 = fourbar
    w = [-3000.0, 0, 3000.0, 0, 0, 0]
    with pytest.warns(JointLimitWarning, match=r"outside the joint limits: crank_axial = "):
        eq = solve_equilibrium(clm, q0, "P", w)
    assert_balanced(clm, eq)
    outside = [
        n for n in ("crank_axial", "rocker_axial")
        if abs(eq.q[clm.model.joints[clm.joint_id(n)].idx_q]) > FOURBAR_AXIAL_LIMIT
    ]  # fmt: skip
    assert eq.limits_violated == tuple(outside) == ("crank_axial", "rocker_axial")


def test_enforced_limits_refuse_the_load_where_a_joint_leaves_them(fourbar):
    clm, q0 = fourbar
    w = np.array([-3000.0, 0, 3000.0, 0, 0, 0])
    with pytest.raises(JointLimitError, match=r"beyond their limits .*crank_axial") as err:
        solve_equilibrium(clm, q0, "P", w, enforce_limits=True)
    assert isinstance(err.value, EquilibriumError) and not err.value.limit_load
    assert "crank_axial" in err.value.joints
    t = err.value.load_fraction
    assert 0.0 < t < 1.0
    with warnings.catch_warnings():
        warnings.simplefilter("error", JointLimitWarning)  # within the limits up to t
        assert solve_equilibrium(clm, q0, "P", t * w).limits_violated == ()


def test_a_passive_angle_wound_by_turns_is_within_its_limits(fourbar):
    """The coupler (passive, limits [-6.3, 6.3] rad) wound by two turns is the same
    placement, and the same equilibrium: not flagged, where the first release warned of
    a joint outside its limits. The crank (actuated) is driven to its value: wound by a
    turn, 6.58 rad, it is outside."""
    clm, q0 = fourbar
    coupler = clm.model.joints[clm.joint_id("coupler")].idx_q
    crank = clm.model.joints[clm.joint_id("crank")].idx_q
    wound = q0.copy()
    wound[coupler] += 4.0 * np.pi
    assert abs(wound[coupler]) > 6.3
    w = [1.0, 0, 2.0, 0, 0, 0]
    with warnings.catch_warnings():
        warnings.simplefilter("error", JointLimitWarning)
        eq = solve_equilibrium(clm, wound, "P", w)
        ref = solve_equilibrium(clm, q0, "P", w)
    assert eq.limits_violated == ()
    # the two solves differ by the rounding of the wound angle's sine and cosine (1e-15),
    # within the solver's tolerance (1e-10 relative): the same deflection to 1e-9
    np.testing.assert_allclose(eq.displacement, ref.displacement, rtol=1e-9, atol=1e-15)
    turned = q0.copy()
    turned[crank] += 2.0 * np.pi
    with pytest.warns(JointLimitWarning, match=r"crank = 6\.58"):
        assert solve_equilibrium(clm, turned, "P", w).limits_violated == ("crank",)


def test_a_passive_angle_with_one_bound_is_never_outside(fourbar):
    """With one finite bound, some whole turn brings any passive angle within it: the
    coupler (passive) is not flagged however far past its one bound; the crank (actuated)
    with the same one bound is."""
    clm, q0 = fourbar
    model = clm.model
    coupler = model.joints[clm.joint_id("coupler")].idx_q
    crank = model.joints[clm.joint_id("crank")].idx_q
    lower, upper = model.lowerPositionLimit.copy(), model.upperPositionLimit.copy()
    try:
        for i in (coupler, crank):  # only an upper bound, 0.5 rad below the angle
            model.lowerPositionLimit[i] = -np.finfo(float).max
            model.upperPositionLimit[i] = q0[i] - 0.5
        out = joints_outside_limits(clm, q0)
        assert list(out) == ["crank"]
        assert out["crank"] == (q0[crank], -np.finfo(float).max, q0[crank] - 0.5)
        for i in (coupler, crank):  # only a lower bound, 10 rad above the angle
            model.lowerPositionLimit[i] = q0[i] + 10.0
            model.upperPositionLimit[i] = np.finfo(float).max
        assert list(joints_outside_limits(clm, q0)) == ["crank"]
    finally:
        model.lowerPositionLimit[:], model.upperPositionLimit[:] = lower, upper


def test_limits_set_after_a_first_check_are_read():
    """The joints to check are found once per model, their limits read at each check."""
    clm = pendulum(40.0, 0.5)
    q = np.array([0.2, 0.3])
    assert joints_outside_limits(clm, q) == {}
    clm.model.lowerPositionLimit[1], clm.model.upperPositionLimit[1] = -0.1, 0.1
    assert joints_outside_limits(clm, q) == {"hinge": (0.3, -0.1, 0.1)}


def test_limits_of_pinocchio_defaults_and_empty_ranges_are_ignored():
    """A hinge built without limits (+-1.8e308) and one with [0, 0] (a URDF <limit>
    without lower/upper) have none; a real range [-0.1, 0.1] rad is checked."""
    k, L, w = 40.0, 0.5, [30.0, 0, 20.0, 0, 0, 0]  # deflects the hinge by 0.29 rad
    for lower, upper, flagged in ((None, None, ()), (0.0, 0.0, ()), (-0.1, 0.1, ("hinge",))):
        clm = pendulum(k, L)
        if lower is not None:
            clm.model.lowerPositionLimit[1], clm.model.upperPositionLimit[1] = lower, upper
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            eq = solve_equilibrium(clm, [0.2, 0.0], "tip", w)
        assert eq.limits_violated == flagged
        assert len(caught) == len(flagged)
        assert abs(eq.q[1]) > 0.2  # rad: outside [-0.1, 0.1]


def test_cahyman_telescope_below_its_stop_is_flagged_and_refused(cahyman):
    """CaHyMan at s_4 = 0 (its lower limit): a push towards the base shortens the
    telescope s_4 below 0, which the first release returned silently (-143 m at 1e8 N)."""
    model = cahyman
    q = model.assemble(np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.0)
    i = model.clm.model.joints[model.clm.joint_id("s_4")].idx_q
    w = np.array([-100.0, -100.0, -100.0, 0, 0, 0])
    with pytest.warns(JointLimitWarning, match=r"s_4 = -0.000\d+ \(limits \[0, 0.05\]\)"):
        eq = solve_equilibrium(model.clm, q, "M", w)
    assert eq.q[i] < -1e-4 and eq.limits_violated == ("s_4",)
    with pytest.raises(JointLimitError, match="s_4") as err:
        solve_equilibrium(model.clm, q, "M", 1e6 * w, enforce_limits=True)
    assert err.value.load_fraction == 0.0 and err.value.joints == ("s_4",)


def test_a_load_needing_thousands_of_increments_is_refused_in_seconds(fourbar):
    """A deflection of a million increments (max_increment 1e-7 rad against a motion of
    about 0.1 rad): the continuation stops after MAX_LOAD_STEPS increments with a typed
    error, where a 1e10 kg payload on CaHyMan's telescope ran for about ten minutes."""
    clm, q0 = fourbar
    with pytest.raises(
        EquilibriumError,
        match=r"1000 load increments reached only .*: give a smaller load or a larger max_incr",
    ) as err:
        solve_equilibrium(clm, q0, "P", [1.0, 0, 2.0, 0, 0, 0], max_increment=1e-7)
    assert "smaller max_increment" not in str(err.value)  # it once advised both
    assert_balanced(clm, solve_equilibrium(clm, q0, "P", [1.0, 0, 2.0, 0, 0, 0]))  # the advice


@pytest.mark.parametrize("max_step", [1e-13, 1e-9])
def test_steps_cut_to_a_tiny_max_step_are_not_taken_for_convergence(max_step):
    """A Newton step cut to max_step is small whatever the distance to the solution: with
    max_step = 1e-13 the UR5 came back 'converged' after one iteration, 2.9e-3 rad off,
    with 28 N m unbalanced. Now the solver stops with an EquilibriumError, or finds the
    equilibrium (the default's, to its tolerance)."""
    ur5 = load_model(data.robot_file("ur5"), joint_stiffness=1e4, geometry=False)
    q0 = np.array([0.0, -1.0, 1.5, -0.5, 1.2, 0.3])
    w = [0.0, 0.0, 1e3, 0.0, 0.0, 0.0]
    reference = solve_equilibrium(ur5, q0, "tool0", w)
    try:
        eq = solve_equilibrium(ur5, q0, "tool0", w, max_step=max_step)
    except EquilibriumError as err:  # the advice, a larger max_step, gives the reference
        assert "try a larger max_step" in str(err)
        return
    np.testing.assert_allclose(eq.q, reference.q, atol=1e-9)  # rad: both converged to 1e-12
