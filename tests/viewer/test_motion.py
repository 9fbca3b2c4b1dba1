"""The drawn deflection: each link a rigid motion along its own twist (closedloop.viewer.motion).

Independent checks of the picture, from the drawn joint placements alone: a joint shared
by two links and a loop closure stay together to second order in the amplification a
(the gap quarters when a halves), the automatic amplification keeps every drawn link
rotation within ROTATION_CAP and every drawn joint displacement within AUTO_FRACTION of
the model size, and CaHyMan's drawn plates keep apart (coal's distance between the discs).
"""

from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest
from helpers import UR5_Q

from cahyman_pin.model import cahyman_model
from closedloop.io.loader import load_model
from closedloop.viewer.motion import AUTO_FRACTION, ROTATION_CAP, drawn_poses, link_twists
from closedloop.viewer.scene import deflection_scene

#: A gap of second order quarters when a halves; the third-order term changes the ratio by
#: about a |xi| relative, at most ROTATION_CAP / 4 < 0.09 at the scales used (a quarter of
#: the automatic one): 4 within 10 %.
RATIO_RTOL = 0.1
#: Gaps below this, per model size, are rounding (of the nominal closure, ~1e-12, and of
#: the placements): not compared.
GAP_FLOOR = 1e-10
#: Drawn rotations and displacements against their caps: rounding of log3 and exp6.
CAP_RTOL = 1e-9
#: Joint types whose origin is a point of both the parent's and the child's body.
FIXED_ORIGIN = ("JointModelR", "JointModelSpherical")
UR5_WRENCH = [10.0, -5.0, -40.0, 0.0, 0.0, 2.0]  # at tool0
FOURBAR_WRENCH = [3.0, 0.0, -20.0, 0.0, 0.0, 0.0]  # at P
#: CaHyMan: the guide's example (pose, torque) and the CLI's default pose under a force.
CAHYMAN_CASES = {
    "guide_torque": (([45.0, 60.0, 75.0], 45.0, 0.05), [0.0, 0.0, 0.0, 0.0, 0.0, 5.0]),
    "default_force": (([90.0, 90.0, 90.0], 90.0, 0.05), [10.0, 0.0, -20.0, 0.0, 0.0, 0.0]),
    "default_moment": (([90.0, 90.0, 90.0], 90.0, 0.05), [0.0, 0.0, 0.0, 5.0, 0.0, 0.0]),
}


@pytest.fixture(scope="module")
def ur5(ur5_urdf):
    return load_model(ur5_urdf, joint_stiffness=1e4, geometry=True), np.array(UR5_Q)


@pytest.fixture(scope="module")
def cahyman_poses():
    model = cahyman_model()
    return model.clm, {
        name: (model.assemble(np.deg2rad(alpha), np.deg2rad(alpha4), s4), w)
        for name, ((alpha, alpha4, s4), w) in CAHYMAN_CASES.items()
    }


def joint_gaps(model: pin.Model, poses: np.ndarray) -> np.ndarray:
    """Distance [m] between the drawn origin of each joint with a fixed origin (revolute,
    spherical) and the same point carried by its parent's drawn placement."""
    gaps = []
    for j in range(1, model.njoints):
        p = model.parents[j]
        if p == 0 or not model.joints[j].shortname().startswith(FIXED_ORIGIN):
            continue
        carried = poses[p] @ model.jointPlacements[j].homogeneous
        gaps.append(np.linalg.norm(poses[j][:3, 3] - carried[:3, 3]))
    return np.array(gaps)


def closure_gaps(clm, poses: np.ndarray) -> np.ndarray:
    """Distance [m] between the two drawn points of each loop closure."""
    gaps = []
    for c in clm.closures:
        k = c.constraint
        a = poses[k.joint1_id] @ k.joint1_placement.homogeneous
        b = poses[k.joint2_id] @ k.joint2_placement.homogeneous
        gaps.append(np.linalg.norm(a[:3, 3] - b[:3, 3]))
    return np.array(gaps)


def second_order(gaps_of_scale, a: float, size: float) -> None:
    """The gaps quarter when the amplification a halves, and some are above rounding."""
    full, half = gaps_of_scale(a), gaps_of_scale(0.5 * a)
    assert np.max(full) > 1e3 * GAP_FLOOR * size  # something to compare
    compared = full > GAP_FLOOR * size
    np.testing.assert_allclose(full[compared] / half[compared], 4.0, rtol=RATIO_RTOL)


@pytest.mark.parametrize(
    "robot, frame, wrench", [("ur5", "tool0", UR5_WRENCH), ("fourbar", "P", FOURBAR_WRENCH)]
)
def test_a_joint_shared_by_two_links_stays_together_to_second_order(robot, frame, wrench, request):
    """(CaHyMan's few revolute joints on a moving parent show gaps of rounding only, 1e-17
    m: nothing to compare; its loops are checked below.)"""
    clm, q = request.getfixturevalue(robot)
    auto = deflection_scene(clm, q, frame, wrench)

    def gaps(a):
        return joint_gaps(
            clm.model, deflection_scene(clm, q, frame, wrench, scale=a).poses_deflected
        )

    second_order(gaps, 0.25 * auto.scale, auto.size)


@pytest.mark.parametrize("robot", ["fourbar", "cahyman"])
def test_a_closed_loop_stays_closed_to_second_order(robot, request):
    if robot == "fourbar":
        clm, q = request.getfixturevalue("fourbar")
        loads = [(q, "P", FOURBAR_WRENCH)]
    else:
        clm, poses = request.getfixturevalue("cahyman_poses")
        loads = [(q, "M", w) for q, w in poses.values()]
    for q, frame, w in loads:
        auto = deflection_scene(clm, q, frame, w)
        # the nominal pose is closed (to the assembly's tolerance, below GAP_FLOOR L)
        assert np.max(closure_gaps(clm, auto.poses)) < GAP_FLOOR * auto.size

        def gaps(a, q=q, frame=frame, w=w):
            return closure_gaps(clm, deflection_scene(clm, q, frame, w, scale=a).poses_deflected)

        second_order(gaps, 0.25 * auto.scale, auto.size)


def test_twists_drawn_at_zero_amplification_are_the_nominal_pose(fourbar):
    clm, q = fourbar
    dq = np.linspace(-1.0, 1.0, clm.model.nv)
    scene = deflection_scene(clm, q, "P", FOURBAR_WRENCH)
    np.testing.assert_array_equal(
        drawn_poses(scene.poses, link_twists(clm, q, dq), 0.0), scene.poses
    )


@pytest.mark.parametrize("case", list(CAHYMAN_CASES))
def test_automatic_amplification_keeps_drawn_rotations_and_displacements_within_the_caps(
    cahyman_poses, case
):
    """Measured on the drawn placements: the angle of each link's drawn rotation from its
    nominal one (log3) and the drawn displacement of each joint origin; one cap is met."""
    clm, poses = cahyman_poses
    q, w = poses[case]
    scene = deflection_scene(clm, q, "M", w)
    angles = [
        np.linalg.norm(pin.log3(P[:3, :3] @ N[:3, :3].T))
        for P, N in zip(scene.poses_deflected, scene.poses, strict=True)
    ]
    moved = np.linalg.norm(scene.poses_deflected[:, :3, 3] - scene.poses[:, :3, 3], axis=1)
    assert max(angles) <= ROTATION_CAP * (1 + CAP_RTOL)
    # the first-order displacement is capped; the drawn one is the chord of the arc
    assert np.max(moved) <= AUTO_FRACTION * scene.size * (1 + CAP_RTOL)
    met = [max(angles) / ROTATION_CAP, scene.scale * scene.max_displacement / (
        AUTO_FRACTION * scene.size)]  # fmt: skip
    assert max(met) == pytest.approx(1.0, rel=1e-6)


def plate_distance(clm, poses_a, name_a, poses_b, name_b) -> float:
    """coal's distance [m] between two geometry objects carried by drawn joint placements
    (negative when they intersect)."""
    objects = {g.name: g for g in clm.visual_model.geometryObjects}
    placed = []
    for poses, name in ((poses_a, name_a), (poses_b, name_b)):
        g = objects[name]
        T = poses[g.parentJoint] @ g.placement.homogeneous
        placed.append((g.geometry, coal.Transform3s(T[:3, :3], T[:3, 3])))
    (ga, ta), (gb, tb) = placed
    return coal.distance(ga, ta, gb, tb, coal.DistanceRequest(), coal.DistanceResult())


@pytest.mark.parametrize("case", list(CAHYMAN_CASES))
def test_cahyman_plates_do_not_pass_through_each_other_or_the_ghost(cahyman_poses, case):
    """The drawn mobile plate keeps clear of the fixed plate and of the ghost's fixed
    plate, and stays near its own ghost (a plate turned at most ROTATION_CAP)."""
    clm, poses = cahyman_poses
    q, w = poses[case]
    scene = deflection_scene(clm, q, "M", w)
    nominal, drawn = scene.poses, scene.poses_deflected
    gap = plate_distance(clm, nominal, "mobile_plate_0", nominal, "fixed_plate_0")
    assert gap > 0.05  # [m] the nominal pose: the plates apart
    for fixed in (drawn, nominal):  # the deflected fixed plate and its ghost
        assert plate_distance(clm, drawn, "mobile_plate_0", fixed, "fixed_plate_0") > 0.5 * gap
    plate = clm.model.getJointId("plate")
    turn = pin.log3(drawn[plate][:3, :3] @ nominal[plate][:3, :3].T)
    assert np.linalg.norm(turn) <= ROTATION_CAP * (1 + CAP_RTOL)


def test_a_finite_deflection_drawn_at_unit_scale_is_the_equilibrium(fourbar):
    """--nonlinear: each link's twist is its finite motion, log6(oMi(q_eq) oMi(q)^-1), so
    at s = 1 the drawn placements are the equilibrium's forward kinematics."""
    clm, q = fourbar
    w = [0.0, 0.0, -200.0, 0.0, 0.0, 0.0]
    scene = deflection_scene(clm, q, "P", w, nonlinear=True, scale=1.0, frames=2)
    data = clm.model.createData()
    pin.forwardKinematics(clm.model, data, scene.equilibrium.q)
    expected = np.array([M.homogeneous for M in data.oMi])
    np.testing.assert_allclose(scene.poses_deflected, expected, rtol=0, atol=1e-12)
    assert not scene.reassembled


def test_close_loops_draws_the_reassembled_configuration(fourbar):
    clm, q = fourbar
    scene = deflection_scene(clm, q, "P", FOURBAR_WRENCH, scale=150.0, close_loops=True)
    data = clm.model.createData()
    pin.forwardKinematics(clm.model, data, scene.q_deflected)
    expected = np.array([M.homogeneous for M in data.oMi])
    np.testing.assert_allclose(scene.poses_deflected, expected, rtol=0, atol=1e-12)
    assert scene.reassembled
