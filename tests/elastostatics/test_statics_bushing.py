"""The nonlinear statics of a stiff coupled 6x6 bushing against an exact answer (#45).

A link on a pin (a revolute joint about a tilted axis u) is also tied to the ground by an
elastic '6d' closure whose frames A (on the ground) and B (on the link) sit on the pin's
axis, tilted against it: a 6x6 spring in A's axes, STIFF in five directions and SOFT
[N m/rad] about u, coupled in A's axes. The pin lets the link turn about u only, and such
a turn moves B relative to A by exactly that rotation at A's origin, so the bushing's
deflection is theta (0, u_A) (log6 of a rotation about an axis through the origin) and
its energy SOFT theta^2 / 2 at any theta. Under a moment n and a dead force f at a point
p of the link the equilibrium is then the root of the scalar equation

    SOFT theta = u . n + u . ((R_u(theta) (p - o)) x f)        (o on the axis),

exact for any load, solved here by scipy's brentq. The coupled spring used to be
evaluated as the product K e, whose rounding (eps |K| |e| on every direction: 5e7 eps of
the soft force at 1e9 against 20) left Newton's steps at 1e-10 rad: the statics failed
with the defaults, and their advice (a smaller max_increment) did not help.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest
from scipy.optimize import brentq

import closedloop as cl
from closedloop.elastostatics.newton import FORCE_RTOL
from closedloop.io.loader import load_model

EPS = np.finfo(float).eps
#: The bushing's stiffness about the pin [N m/rad].
SOFT = 20.0
#: The pin's axis, world axes, through the origin; A and B at AXIS_POINT on it [m].
AXIS = np.array([0.3, 0.5, 0.8]) / np.linalg.norm([0.3, 0.5, 0.8])
AXIS_POINT = 0.3 * AXIS
#: The loaded frame's origin on the link at rest [m], world axes.
TIP = np.array([0.5, 0.1, 0.2])
#: A's (and B's) orientation against the world, roll-pitch-yaw [rad]: the pin's axis is
#: along none of A's axes, so that the 6x6 in A's axes is coupled.
TILTS = [(0.3, -0.5, 0.8), (1.2, 0.4, -0.7), (np.pi / 2, 0.0, 0.3)]


def rtol_theta(stiff: float) -> float:
    """Relative error of theta: Newton balances the forces on each coordinate to
    FORCE_RTOL of the largest, here the soft spring's, and the turn moves the pin and up
    to three of the bushing's coordinates: 8 FORCE_RTOL (measured 1.6 FORCE_RTOL at 1e3
    and 3 rad). And the soft stiffness of a 6x6 given to rounding in its entries, as its
    eigensolver reads it, is known to ~eps STIFF: 16 times that (measured 1.1 eps STIFF /
    SOFT in theta at 1e9, 0.4 at 1e10)."""
    return 8.0 * FORCE_RTOL + 16.0 * EPS * stiff / SOFT


def _origin(M: pin.SE3) -> str:
    xyz = " ".join(repr(float(x)) for x in M.translation)
    rpy = " ".join(repr(float(x)) for x in pin.rpy.matrixToRpy(M.rotation))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def pinned(tmp_path, tilt, stiff: float) -> tuple:
    """(model, q at rest, u in A's axes) of the pin held by the tilted bushing."""
    A = pin.SE3(pin.rpy.rpyToMatrix(*tilt), AXIS_POINT)
    inertial = ('<inertial><mass value="1"/><inertia ixx="1e-3" iyy="1e-3" izz="1e-3" '
                'ixy="0" ixz="0" iyz="0"/></inertial>')  # fmt: skip
    axis = " ".join(repr(float(x)) for x in AXIS)
    (tmp_path / "pin.urdf").write_text(f"""<robot name="pinned">
<link name="ground"/><link name="link">{inertial}</link><link name="A"/><link name="B"/>
<link name="tip"/>
<joint name="pin" type="revolute"><parent link="ground"/><child link="link"/>
<axis xyz="{axis}"/><limit lower="-10" upper="10" effort="1" velocity="1"/></joint>
<joint name="A_joint" type="fixed"><parent link="ground"/><child link="A"/>{_origin(A)}</joint>
<joint name="B_joint" type="fixed"><parent link="link"/><child link="B"/>{_origin(A)}</joint>
<joint name="tip_joint" type="fixed"><parent link="link"/><child link="tip"/>
{_origin(pin.SE3(np.eye(3), TIP))}</joint>
</robot>""")
    u = A.rotation.T @ AXIS
    K = np.zeros((6, 6))
    K[:3, :3] = stiff * np.eye(3)
    K[3:, 3:] = stiff * np.eye(3) + (SOFT - stiff) * np.outer(u, u)
    (tmp_path / "pin.yaml").write_text("closed_loop: [[A, B]]\ntype: ['6d']\nname_mot: []\n")
    clm = load_model(
        tmp_path / "pin.urdf",
        tmp_path / "pin.yaml",
        geometry=False,
        closure_springs={0: K.tolist()},
    )
    return clm, clm.reference_configuration(), u


def exact_turn(moment: float, force: np.ndarray) -> float:
    """theta [rad] of the pin under the moment ``moment`` AXIS [N m] and the dead force
    ``force`` (3,) [N] at the tip, the root of the module's equation."""
    arm = TIP - AXIS_POINT

    def unbalanced(theta):
        turned = pin.exp3(theta * AXIS) @ arm
        return SOFT * theta - moment - AXIS @ np.cross(turned, force)

    # |u . (R r x f)| <= |r| |f| < SOFT (the loads below): rising, one root, within
    # (|moment| + |r| |f|) / SOFT
    reach = 1.01 * (abs(moment) + np.linalg.norm(arm) * np.linalg.norm(force)) / SOFT
    return brentq(unbalanced, -reach, reach, xtol=1e-300, rtol=4 * EPS)


@pytest.mark.parametrize("tilt", TILTS)
@pytest.mark.parametrize("stiff", [1e3, 1e9, 1e10])
@pytest.mark.parametrize(
    ("moment", "force"),
    [(1e-3, np.zeros(3)), (1.0, np.zeros(3)), (60.0, np.zeros(3)), (30.0, [4.0, -7.0, 3.0])],
)
def test_a_pin_held_by_a_tilted_bushing_turns_as_the_closed_form(
    tmp_path, tilt, stiff, moment, force
):
    """With the defaults, small and large loads (theta = 5e-5 to 3 rad): the pin's turn is
    the exact one, and the bushing's deflection theta (0, u_A) (its stiff directions at
    rest), for bushings of 5e1 to 5e8 between stiff and soft (a 6x6 resolves its soft
    directions down to 1e-9 of the stiffest, :data:`closedloop.model.elastic_closures
    .NULL_RTOL`; below, they are free)."""
    clm, q, u = pinned(tmp_path, tilt, stiff)
    wrench = np.r_[force, moment * AXIS]
    eq = cl.solve_equilibrium(clm, q, "tip", wrench)
    theta = exact_turn(moment, np.asarray(force, float))
    expected = theta * np.r_[1.0, np.zeros(3), u]  # (pin, bushing's twist in A's axes)
    np.testing.assert_allclose(
        eq.joint_deflection, expected, rtol=0, atol=rtol_theta(stiff) * abs(theta)
    )


def test_rounding_that_stalls_newton_is_called_so(tmp_path):
    """The spring forces evaluated as the product K e (as they were): Newton's steps stall
    at the rounding (1e-9 rad at 1e10 against 20; the convergence test wants 1e-12), in
    every increment; the error says so and proposes neither more iterations nor smaller
    increments, which do not help (max_increment 0.01 fails alike)."""
    clm, q, _ = pinned(tmp_path, TILTS[0], 1e10)
    clm.spring_forces = lambda dq: clm.spring_matrix @ dq
    for options in ({}, {"max_increment": 0.01}):
        with pytest.raises(cl.EquilibriumError, match="Newton stalls at the rounding") as err:
            cl.solve_equilibrium(clm, q, "tip", np.r_[0.0, 0.0, 0.0, 20.0 * AXIS], **options)
        assert not err.value.limit_load and "try" not in str(err.value)
