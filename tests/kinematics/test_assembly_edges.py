"""Edges of the assembly (closedloop.kinematics.assembly, closedloop.kinematics.limits) and of the
ball joints (closedloop.model.balls): the border of the workspace, starts at and near singular
configurations and the branch a sweep follows, the size of the mechanism, quaternions of
any norm and either sign.

Every closure is checked from scratch: the world positions of the two anchors of each
closure from Pinocchio's forward kinematics on a fresh Data, not the constraint residual
the assembly iterates on.
"""

from __future__ import annotations

import re

import numpy as np
import pinocchio as pin
import pytest
from helpers import assert_close_in_norm
from mechanisms import FIVEBAR_BASE, FIVEBAR_LENGTHS, fivebar, fourbar_chain, scaled_fourbar

import closedloop as cl
from closedloop.exceptions import AssemblyError, InvalidInputError
from closedloop.kinematics.assembly import ASSEMBLY_TOL, assemble
from closedloop.kinematics.driving import assemble_connected, assemble_within_limits

#: A point closure met to ASSEMBLY_TOL in the max norm of its 3 rows (metres / L) leaves
#: a world gap of at most sqrt(3) times that.
GAP_TOL = np.sqrt(3) * ASSEMBLY_TOL
#: Passive angles of a configuration closed to ASSEMBLY_TOL L against their closed form
#: [rad]: the closure error (5e-13 m on the 0.5 m parallelogram) over the smallest singular
#: value of the passive Jacobian 0.025 rad from the change point (about 4e-3 m/rad) is
#: 1.3e-10 rad.
ATOL_BRANCH = 1e-9
#: The same kinematics and springs computed twice, the quaternion's sign aside: rounding.
RTOL_SAME = 1e-12
#: Two configurations of the same rotation computed alike [rad]: rounding.
ATOL_SAME_Q = 1e-12


def closure_gap(clm: cl.ClosedLoopModel, q: np.ndarray) -> float:
    """Largest distance [m] between the two anchors of a point closure at q, from a fresh
    forward kinematics (each anchor: its joint's world placement times its placement)."""
    data = clm.model.createData()
    pin.forwardKinematics(clm.model, data, q)
    gaps = []
    for c in clm.closures:
        m = c.constraint
        a = data.oMi[m.joint1_id] * m.joint1_placement
        b = data.oMi[m.joint2_id] * m.joint2_placement
        gaps.append(np.linalg.norm(a.translation - b.translation))
    return float(max(gaps))


# ------------------------------------------------------------ border of the workspace
def fivebar_at_reach(gap: float) -> np.ndarray:
    """Base angles (2,) [rad] of the 5-bar whose elbows are d0 + d1 - gap apart [m]
    (gap < 0: beyond reach by -gap), leg 0 at 2.07 rad: the intersection of the elbow
    circle of leg 1 (centre A1, radius p1) with the circle about the elbow B0 of leg 0,
    the one on the right of the line from A1 to B0 (leg 1 at 0.52 rad, near its 0.86 rad
    in the 5-bar's default pose)."""
    (p0, d0), (p1, d1) = FIVEBAR_LENGTHS
    A0, A1 = FIVEBAR_BASE[:, :2]
    t0 = np.pi / 2 + 0.5
    B0 = A0 + p0 * np.array([np.cos(t0), np.sin(t0)])
    R, v = d0 + d1 - gap, B0 - A1
    dist = np.linalg.norm(v)
    along = (p1**2 - R**2 + dist**2) / (2 * dist)  # from A1 towards B0
    across = np.sqrt(p1**2 - along**2)
    u, n = v / dist, np.array([v[1], -v[0]]) / dist
    B1 = A1 + along * u + across * n
    return np.array([t0, np.arctan2(B1[1] - A1[1], B1[0] - A1[0])])


@pytest.mark.parametrize("gap", [1e-3, 1e-9])
def test_the_border_of_the_workspace(gap):
    """Just inside the reach of the 5-bar (its distal links gap short of straight) the
    loop closes; just outside, AssemblyError names the inputs and reports a residual that
    is the gap (the closest the two distal ends come), not less."""
    m = fivebar()
    clm, L = m.clm, m.clm.length
    a = assemble(clm, fivebar_at_reach(gap), m.q)
    assert closure_gap(clm, a.q) <= GAP_TOL * L
    beyond = fivebar_at_reach(-gap)
    with pytest.raises(
        AssemblyError, match=rf"'leg1_base': {re.escape(repr(float(beyond[1])))}"
    ) as err:
        assemble(clm, beyond, m.q)
    # the max norm of a 3-vector of length gap is between gap / sqrt(3) and gap
    assert gap / np.sqrt(3) <= err.value.residual <= gap * (1 + 1e-6)


# ------------------------------------------------------------ branches near a singularity
def parallelogram(t: float) -> np.ndarray:
    """(crank, coupler, rocker) [rad] of the parallelogram branch of fourbar_chain([t])."""
    return np.array([t, -t, t])


def crossed(t: float) -> np.ndarray:
    """The other branch of fourbar_chain([t]): the coupler joint C reflected about the
    line from the crank tip B = 0.3 (cos t, sin t) to the rocker pivot D = (0.2, 0) (the
    two circles |C - B| = 0.2, |C - D| = 0.3 meet at C and at its mirror image)."""
    B, D = 0.3 * np.array([np.cos(t), np.sin(t)]), np.array([0.2, 0.0])
    v, u = np.array([0.2, 0.0]), (D - B) / np.linalg.norm(D - B)  # C - B, parallelogram
    C = B + 2 * (v @ u) * u - v
    return np.array([t, np.arctan2(C[1] - B[1], C[0] - B[0]) - t, np.arctan2(C[1], C[0] - 0.2)])


@pytest.mark.parametrize("solve", [assemble, assemble_within_limits])
@pytest.mark.parametrize("branch", [parallelogram, crossed])
def test_a_sweep_keeps_its_branch_across_the_change_point(solve, branch):
    """The parallelogram four-bar (crank 0.3 m, coupler 0.2 m, rocker 0.3 m, pivots 0.2 m
    apart) has two branches that cross at crank 0. A sweep in steps of 0.05 rad, each
    point from the last, stays on the branch it starts on. Near crank 0 the first
    Gauss-Newton step of each solve was large (0.33 rad from the parallelogram at -0.1
    rad to -0.05 rad, the passive Jacobian nearly singular): the parallelogram jumped to
    the crossed branch at -0.025 rad, the crossed one to the parallelogram at 0.025 rad."""
    clm, _, _ = fourbar_chain([0.0])
    q = branch(-0.525)
    for t in np.linspace(-0.475, 0.475, 20):
        q = solve(clm, [t], q).q
        np.testing.assert_allclose(q, branch(t), rtol=0, atol=ATOL_BRANCH)


def test_the_command_line_s_drive_keeps_the_branch():
    """assemble_connected (``--actuated``, a map's first point) drives the input in steps;
    from the parallelogram at -0.5 rad it ended on the crossed branch at -0.05 rad."""
    clm, _, _ = fourbar_chain([0.0])
    got = assemble_connected(clm, [-0.05], parallelogram(-0.5)).q
    np.testing.assert_allclose(got, parallelogram(-0.05), rtol=0, atol=ATOL_BRANCH)


def test_a_start_at_the_change_point_closes_on_a_branch():
    """From the singular configuration itself (both branches meet, the passive Jacobian
    has rank 1) the loop closes, on one of the two branches."""
    clm, q, _ = fourbar_chain([0.0])
    a = assemble(clm, [0.1], q)
    assert closure_gap(clm, a.q) <= GAP_TOL * clm.length
    off = min(np.abs(a.q - parallelogram(0.1)).max(), np.abs(a.q - crossed(0.1)).max())
    assert off <= ATOL_BRANCH


# ------------------------------------------------------------ size of the mechanism
@pytest.mark.parametrize("s", [1e-3, 1e3])
def test_the_closure_tolerance_scales_with_the_mechanism(s):
    """The four-bar at 1 mm and at 1 km of its bundled size: the same iterations, the
    same angles, lengths and residual in proportion (the tolerance is ASSEMBLY_TOL L)."""
    unit, q1, _ = scaled_fourbar(1.0)
    clm, q, _ = scaled_fourbar(s)
    a1, a = assemble(unit, [1.7], q1), assemble(clm, [1.7], q)
    assert a.iterations == a1.iterations
    assert closure_gap(clm, a.q) <= GAP_TOL * clm.length
    scale = np.where(clm.linear_coordinates, s, 1.0)  # one coordinate per joint: nq = nv
    # the same iterates up to rounding, amplified by the loop's conditioning
    np.testing.assert_allclose(a.q / scale, a1.q, rtol=0, atol=ATOL_BRANCH)


# ------------------------------------------------------------ ball joints
ARM = """<robot name="arm">
  <link name="base"/>
  <link name="upper"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01"
    ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="lower"/>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="lower"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1"
    velocity="1"/></joint>
  <transmission name="elbow_transmission"><type>SimpleTransmission</type>
    <joint name="elbow"><hardwareInterface>EffortJointInterface</hardwareInterface></joint>
    <actuator name="elbow_motor"><mechanicalReduction>1</mechanicalReduction></actuator>
  </transmission>
</robot>
"""


def test_a_ball_named_by_a_transmission_is_a_ball(tmp_path):
    """A URDF <transmission> names its joint in a <joint> element of its own; that element
    was taken for the joint, which stayed revolute (and its ball springs were refused)."""
    (tmp_path / "arm.urdf").write_text(ARM)
    (tmp_path / "arm.yaml").write_text(
        "name_mot: [shoulder]\nsprings: {shoulder: 100.0, elbow: 40.0}\nballs: [elbow]\n"
    )
    arm = cl.load_model(tmp_path / "arm.urdf", tmp_path / "arm.yaml")
    assert arm.model.joints[arm.joint_id("elbow")].shortname() == "JointModelFreeFlyer"
    np.testing.assert_array_equal(arm.stiffness[arm.joint_v_slice("elbow")],
                                  [np.inf] * 3 + [40.0] * 3)  # fmt: skip


#: R-S-S-R loop: crank about z (0.1 m), a ball at its tip carrying the coupler, whose end
#: (0.3, 0, 0.05) m in its frame is closed to the tip of a rocker (0.15 m along its z)
#: turning about x at D = (0.25, 0.2, 0) m. The coupler's spin about its ball-to-ball line
#: is an internal mobility; the frame ``tip`` is on the rocker.
RSSR = """<robot name="rssr">
  <link name="base"/>
  <link name="crank"><inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4"
    ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="coupler"><inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4"
    izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="rocker"><inertial><mass value="0.1"/><inertia ixx="1e-4" iyy="1e-4"
    izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="C_coupler"/><link name="C_rocker"/><link name="tip"/>
  <joint name="crank" type="revolute"><parent link="base"/><child link="crank"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="ball" type="fixed"><parent link="crank"/><child link="coupler"/>
    <origin xyz="0.1 0 0"/></joint>
  <joint name="coupler_end" type="fixed"><parent link="coupler"/><child link="C_coupler"/>
    <origin xyz="0.3 0 0.05"/></joint>
  <joint name="rocker" type="revolute"><parent link="base"/><child link="rocker"/>
    <origin xyz="0.25 0.2 0"/><axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="1"
    velocity="1"/></joint>
  <joint name="rocker_end" type="fixed"><parent link="rocker"/><child link="C_rocker"/>
    <origin xyz="0 0 0.15"/></joint>
  <joint name="rocker_tip" type="fixed"><parent link="rocker"/><child link="tip"/>
    <origin xyz="0 0.05 0.15"/></joint>
</robot>
"""
#: Rocker angles against their closed form [rad]: the closure tolerance (4e-13 m, L = 0.4
#: m) over the rocker's 0.15 m lever, with room for the conditioning of the loop.
ATOL_ROCKER = 1e-10


def rocker_angle(t: float) -> float:
    """Rocker angle phi [rad] at crank angle t, branch |phi| < pi/2.

    B = 0.1 (cos t, sin t, 0), C = D + 0.15 (0, -sin phi, cos phi), |C - B|^2 = 0.3^2 +
    0.05^2 = 0.0925 m^2; expanded, the equation is linear in sin phi:
    (0.25 - 0.1 cos t)^2 + (0.2 - 0.1 sin t)^2 + 0.0225 - 0.3 (0.2 - 0.1 sin t) sin phi
    = 0.0925.
    """
    a, b = 0.25 - 0.1 * np.cos(t), 0.2 - 0.1 * np.sin(t)
    return float(np.arcsin((a * a + b * b + 0.0225 - 0.0925) / (0.3 * b)))


@pytest.fixture(scope="module")
def rssr(tmp_path_factory):
    """(model, q): the R-S-S-R loop assembled at crank 0.4 rad, from crank 0."""
    folder = tmp_path_factory.mktemp("rssr")
    (folder / "rssr.urdf").write_text(RSSR)
    (folder / "rssr.yaml").write_text(
        "closed_loop: [[C_coupler, C_rocker]]\ntype: ['3d']\nname_mot: [crank]\n"
        "springs: {crank: 50.0}\nballs: [ball]\n"
    )
    clm = cl.load_model(folder / "rssr.urdf", folder / "rssr.yaml")
    q0 = pin.neutral(clm.model)
    q0[clm.model.joints[clm.joint_id("rocker")].idx_q] = rocker_angle(0.0)
    return clm, assemble(clm, [0.4], assemble(clm, [0.0], q0).q).q


def quaternion_of(clm: cl.ClosedLoopModel, name: str = "ball") -> slice:
    """Where q holds the quaternion (x, y, z, w) of ball joint ``name`` (after its three
    locked translations)."""
    i = clm.model.joints[clm.joint_id(name)].idx_q + 3
    return slice(i, i + 4)


def test_a_loop_through_a_ball_assembles_to_its_closed_form(rssr):
    """The rocker angle against the closed form; the ball's translations stay locked at 0;
    the closure holds in the world."""
    clm, q = rssr
    rocker = clm.model.joints[clm.joint_id("rocker")].idx_q
    translations = slice(quaternion_of(clm).start - 3, quaternion_of(clm).start)
    for t in (0.4, 0.45, -0.6):
        a = assemble(clm, [t], q)
        assert closure_gap(clm, a.q) <= GAP_TOL * clm.length
        assert abs(a.q[rocker] - rocker_angle(t)) <= ATOL_ROCKER
        np.testing.assert_array_equal(a.q[translations], 0.0)


def test_a_ball_quaternion_and_its_negative_give_the_same_answers(rssr):
    """q and -q are the same rotation: the same compliance, equilibrium and assembly, to
    rounding; a quaternion of norm 1 + 1e-7 (within UNIT_NORM_TOL) is normalised."""
    clm, q = rssr
    flipped, long = q.copy(), q.copy()
    flipped[quaternion_of(clm)] *= -1.0
    long[quaternion_of(clm)] *= 1.0 + 1e-7
    C = cl.compliance(clm, q, "tip").C
    for other in (flipped, long):
        assert_close_in_norm(cl.compliance(clm, other, "tip").C, C, RTOL_SAME)
    w = np.array([1.0, -2.0, 3.0, 0.1, 0.2, -0.3])
    e, f = cl.solve_equilibrium(clm, q, "tip", w), cl.solve_equilibrium(clm, flipped, "tip", w)
    np.testing.assert_allclose(pin.difference(clm.model, e.q, f.q), 0.0, rtol=0, atol=ATOL_SAME_Q)
    assert_close_in_norm(cl.preloaded_compliance(clm, f).C, cl.preloaded_compliance(clm, e).C,
                         RTOL_SAME)  # fmt: skip
    a, b = assemble(clm, [0.45], q), assemble(clm, [0.45], flipped)
    np.testing.assert_allclose(pin.difference(clm.model, a.q, b.q), 0.0, rtol=0, atol=ATOL_SAME_Q)


@pytest.mark.parametrize("factor", [0.5, 2.0, 0.0, np.nan])
def test_a_ball_quaternion_off_norm_one_is_refused(rssr, factor):
    """A quaternion scaled by 0.5, 2, 0 or NaN: InvalidInputError naming the joint (or
    the non-finite values) in the assembly, the compliance (single and stacked), the
    statics and the tangent terms (they answered for the unnormalised quaternion: the
    loop curvature off by 23 beside a largest entry of 8.7), never the answer of another
    rotation."""
    clm, q = rssr
    bad = q.copy()
    bad[quaternion_of(clm)] *= factor
    finite = r"q of joint 'ball' \(JointModelFreeFlyer\) is .*not of norm 1"
    match = "non-finite" if np.isnan(factor) else finite
    queries = (
        lambda: assemble(clm, [0.45], bad),
        lambda: assemble_within_limits(clm, [0.45], bad),
        lambda: cl.compliance(clm, bad, "tip"),
        lambda: cl.compliances(clm, bad[None], "tip"),
        lambda: cl.solve_equilibrium(clm, bad, "tip", np.zeros(6)),
        lambda: cl.geometric_stiffness(clm, bad, "tip", np.ones(6)),
        lambda: cl.closure_curvature(clm, bad, np.ones(clm.n_constraints)),
        lambda: cl.tangent_stiffness(clm, bad, q, "tip", np.ones(6), np.ones(clm.n_constraints)),
        lambda: cl.tangent_stiffness(clm, q, bad, "tip", np.ones(6), np.ones(clm.n_constraints)),
    )
    for query in queries:
        with pytest.raises(InvalidInputError, match=match):
            query()
