"""Edge cases of the statics under load and weight: spring-free links that the weight
acts on, and link inertias that weigh nothing sensible.

Expected values: a sprung hinge carrying a link on a passive hinge, in closed form, and
central differences of the nonlinear equilibrium solver.
"""

from __future__ import annotations

import warnings

import numpy as np
import pinocchio as pin
import pytest

import closedloop as cl
from closedloop.elastostatics.equations import EquilibriumEquations
from closedloop.elastostatics.preload import require_stable
from closedloop.elastostatics.statics import solve_equilibrium
from closedloop.exceptions import EquilibriumError, InvalidInputError
from closedloop.model.gravity import GravityLoad

#: Sprung hinge [N m/rad]; its own link (mass, centre of mass on the link axis) and the
#: passive link hung from its tip (mass, distance of its centre of mass from the pivot).
K_HINGE, TIP = 400.0, 0.5
M_LINK, C_LINK = 1.0, 0.25
M_DANGLE, C_DANGLE = 2.0, 0.3
G = 9.81
# Closed form against the engine: both exact to rounding (measured 3e-16).
RTOL_CLOSED_FORM = 1e-10
# Central differences of the solver, moment step H_MOMENT [N m]: truncation (h / K)^2 ~
# 1e-11 and solver rounding 1e-16 rad / h ~ 1e-13 relative to the response (measured 3e-14).
RTOL_FD, H_MOMENT = 1e-7, 1e-3


def _body(mass: float, z: float) -> pin.Inertia:
    """A body of ``mass`` [kg] with its centre of mass at (0, 0, z) [m]."""
    return pin.Inertia(mass, np.array([0.0, 0.0, z]), 1e-3 * np.eye(3))


def hinge_with_dangling_link(upright: bool = False) -> tuple[cl.ClosedLoopModel, np.ndarray]:
    """(model, q0): a hinge about y with a spring and a link along +z (frame 'tip' at its
    end), carrying at the tip a second link on a passive hinge about y, hanging down (its
    centre of mass at -z), or balanced upright. A locked support keeps nv > 1."""
    m = pin.Model()
    support = m.addJoint(0, pin.JointModelPZ(), pin.SE3.Identity(), "support")
    hinge = m.addJoint(support, pin.JointModelRY(), pin.SE3.Identity(), "hinge")
    m.appendBodyToJoint(hinge, _body(M_LINK, C_LINK), pin.SE3.Identity())
    tip = pin.SE3(np.eye(3), np.array([0.0, 0.0, TIP]))
    m.addFrame(pin.Frame("tip", hinge, tip, pin.OP_FRAME))
    dangle = m.addJoint(hinge, pin.JointModelRY(), tip, "dangle")
    m.appendBodyToJoint(dangle, _body(M_DANGLE, -C_DANGLE), pin.SE3.Identity())
    clm = cl.ClosedLoopModel(m, actuated=["hinge"], springs={"hinge": K_HINGE}, locked=["support"])
    return clm, np.array([0.0, 0.0, np.pi if upright else 0.0])


def test_a_link_hanging_on_a_passive_joint_settles_in_the_preloaded_compliance():
    """Turned by a moment, the hinge tilts and the passive link keeps hanging: its weight
    acts at the pivot, K = k - g (m1 c1 + m2 TIP). The preloaded compliance held the
    passive link rigid to the hinge (K = k - g (m1 c1 + m2 (TIP - c2)), 1.5 % stiffer)."""
    clm, q0 = hinge_with_dangling_link()
    res = cl.compliance(clm, q0, "tip", gravity=(0.0, 0.0, -G))
    K = K_HINGE - G * (M_LINK * C_LINK + M_DANGLE * TIP)
    np.testing.assert_allclose(res.C[4, 4], 1.0 / K, rtol=RTOL_CLOSED_FORM)
    np.testing.assert_allclose(res.stability_margin, K / K_HINGE, rtol=RTOL_CLOSED_FORM)

    def tilt(moment):
        w = np.array([0.0, 0.0, 0.0, 0.0, moment, 0.0])
        return solve_equilibrium(clm, q0, "tip", w, gravity=(0.0, 0.0, -G)).q

    up, down = tilt(H_MOMENT), tilt(-H_MOMENT)
    np.testing.assert_allclose(res.C[4, 4], (up[1] - down[1]) / (2 * H_MOMENT), rtol=RTOL_FD)
    # the joint deflection of the compliance includes the passive link's counter-turn
    np.testing.assert_allclose(res.G[:, 4], (up - down) / (2 * H_MOMENT), rtol=RTOL_FD,
                               atol=RTOL_FD * abs(res.C[4, 4]))  # fmt: skip


def test_a_link_balanced_upright_on_a_passive_joint_is_unstable():
    """The weight destabilises the passive link (stiffness -m2 g c2 on no spring): the
    equilibrium is unstable, its margin that stiffness over the hinge's spring. It was
    called stable (margin 0.98, the spring-free link left out)."""
    clm, q0 = hinge_with_dangling_link(upright=True)
    res = cl.compliance(clm, q0, "tip", gravity=(0.0, 0.0, -G))
    np.testing.assert_allclose(
        res.stability_margin, -M_DANGLE * G * C_DANGLE / K_HINGE, rtol=RTOL_CLOSED_FORM
    )
    with pytest.raises(EquilibriumError, match="unstable"):
        require_stable(res)
    # the solver reads the same margin (its fold test and limit-load diagnosis)
    eq = res.equilibrium
    solver = EquilibriumEquations(clm, eq.q_rest, "tip").margin(eq.q, eq.load)
    np.testing.assert_allclose(solver, res.stability_margin, rtol=RTOL_CLOSED_FORM)


def test_a_rod_spinning_freely_still_leaves_the_margin_of_the_springs():
    """A preload that does not act on the spring-free motion (the weight of a link hung
    exactly at its pivot): the motion is left out and the margin is the springs' alone."""
    clm, q0 = hinge_with_dangling_link()
    model = pin.Model(clm.model)
    model.inertias[3] = pin.Inertia(M_DANGLE, np.zeros(3), np.zeros((3, 3)))
    at_pivot = cl.ClosedLoopModel(model, actuated=["hinge"], springs={"hinge": K_HINGE},
                                  locked=["support"])  # fmt: skip
    res = cl.compliance(at_pivot, q0, "tip", gravity=(0.0, 0.0, -G))
    K = K_HINGE - G * (M_LINK * C_LINK + M_DANGLE * TIP)
    np.testing.assert_allclose(res.stability_margin, K / K_HINGE, rtol=RTOL_CLOSED_FORM)
    np.testing.assert_allclose(res.C[4, 4], 1.0 / K, rtol=RTOL_CLOSED_FORM)


@pytest.mark.parametrize(
    ("mass", "com", "shown"),
    [
        (-1.0, (0.0, 0.0, C_LINK), r"mass -1 kg"),
        (np.nan, (0.0, 0.0, C_LINK), r"mass nan kg"),
        (M_LINK, (0.0, 0.0, np.nan), r"centre of mass \[0.0, 0.0, nan\] m"),
    ],
)
def test_a_link_inertia_that_cannot_weigh_is_refused_naming_it(mass, com, shown):
    """A negative link mass was weighed as a lift, a NaN one reported as an overflow, and a
    NaN centre of mass reached LAPACK (LinAlgError, and its message on stdout)."""
    clm, q0 = hinge_with_dangling_link()
    model = pin.Model(clm.model)
    model.inertias[2] = pin.Inertia(mass, np.array(com), 1e-3 * np.eye(3))
    bad = cl.ClosedLoopModel(model, actuated=["hinge"], springs={"hinge": K_HINGE},
                             locked=["support"])  # fmt: skip
    match = rf"the body on joint 'hinge' has .*{shown}.*expected a finite mass >= 0 \[kg\]"
    with pytest.raises(InvalidInputError, match=match):
        GravityLoad(bad, (0.0, 0.0, -G))
    with pytest.raises(InvalidInputError, match=match):
        cl.compliance(bad, q0, "tip", gravity=(0.0, 0.0, -G))


def test_a_wrench_that_overflows_the_equations_is_a_typed_error(fourbar):
    """1e308 N on the four-bar: its generalised forces and stiffness leave the double
    range. It raised numpy's LinAlgError (SVD did not converge) after an overflow warning."""
    clm, q0 = fourbar
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no RuntimeWarning on the way either
        with pytest.raises(InvalidInputError, match=r"wrench \[1e\+308, 0.0.*overflows the "
                           r"equilibrium equations.*expected a far smaller load"):  # fmt: skip
            solve_equilibrium(clm, q0, "P", [1e308, 0.0, 0.0, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("preload", [[1.0, 2.0], [np.nan, 0, 0, 0, 0, 0], "6 N"])
def test_a_bad_preload_is_named_as_the_preload(fourbar, preload):
    """compliance(..., preload=...) names its own argument, not a "wrench"."""
    clm, q0 = fourbar
    with pytest.raises(InvalidInputError, match=r"^preload"):
        cl.compliance(clm, q0, "P", preload=preload)
