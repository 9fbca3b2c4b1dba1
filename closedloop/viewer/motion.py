"""How the viewer amplifies a deflection: each link moves rigidly along its own twist.

A finite-element post-processor amplifies the nodal displacements, not the rotations that
produced them. Here likewise: the deflection dq (nv,) (tangent of q) gives each joint body
(link) i a twist, the world-frame spatial motion of the link (pin.WORLD):

    xi_i = (v_i, w_i) = J_i(q) dq

v_i [m] the displacement of the link's point at the world origin and w_i [rad] its rotation
vector, world axes (for a finite deflection, the nonlinear equilibrium q_eq, xi_i =
log6(oMi(q_eq) oMi(q)^-1), the link's finite displacement). Amplified by a, the link is
drawn at

    oMi_drawn = exp6(a xi_i) oMi(q)

a rigid motion of the link. Two links that share a joint point p move it by the same
first-order displacement (v_i + w_i x p), so the joint stays together, and a closed loop
stays closed, to first order in a, however deep the chain (the gap is of second order).
Amplifying the joint deflection instead, integrate(q, a dq), turns a small rotation near
the root into a large one, which swings every link beyond it; here each link turns by a
times its own rotation, which the cap below keeps readable.

Amplification (``scale=None``): the largest of the first-order displacements ``|J_p dq|`` of
the joint origins and the loaded frame's origin, d_max [m], drawn at most
``AUTO_FRACTION`` of the model size L [m], and the largest link rotation ``|w_i|``, w_max
[rad], drawn at most ``ROTATION_CAP``:

    a = min(AUTO_FRACTION L / d_max, ROTATION_CAP / w_max)   (a = 1 when nothing deflects)
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from closedloop.analysis.batch_indices import row_norms
from closedloop.exceptions import InvalidInputError
from closedloop.kinematics.constraints import frame_jacobian, update_kinematics
from closedloop.model.closed_loop import ClosedLoopModel

#: Largest amplified first-order point displacement, as a fraction of the model size.
AUTO_FRACTION = 0.1
#: Largest amplified link rotation [rad] (20 deg, 0.349 rad): beyond, the first-order
#: drawing of a link's rotation stops being readable (a rotation of a rad moves a point
#: by 2 sin(a/2) instead of a: 0.5 % shorter at 0.35 rad).
ROTATION_CAP = float(np.deg2rad(20.0))


def joint_jacobian(model: pin.Model, data: pin.Data, joint: int, reference=None) -> np.ndarray:
    """(6, nv) Jacobian of ``joint`` (velocity [m], angular velocity [rad]), world axes,
    from the joint Jacobians already computed in ``data``: of its origin
    (LOCAL_WORLD_ALIGNED, the default) or the spatial one (pin.WORLD: the velocity of the
    body's point at the world origin). Pinocchio gives a one-dof model's as a (6,) vector."""
    frame = pin.LOCAL_WORLD_ALIGNED if reference is None else reference
    J = pin.getJointJacobian(model, data, joint, frame)
    return np.asarray(J).reshape(6, model.nv)


def link_twists(clm: ClosedLoopModel, q: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """(njoints, 6) first-order twists xi_i = J_i(q) dq of the joint bodies (module
    docstring): (v [m], w [rad]), world axes, v of the body's point at the world origin;
    row 0 (the world) is zero."""
    q = clm.check_configuration(q)
    pin.computeJointJacobians(clm.model, clm.data, q)
    rows = [np.zeros(6)]
    for j in range(1, clm.model.njoints):
        rows.append(joint_jacobian(clm.model, clm.data, j, pin.WORLD) @ dq)
    return np.array(rows)


def finite_twists(poses: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """(njoints, 6) twists xi_i = log6(moved_i poses_i^-1) of the finite motions of the
    joint bodies from ``poses`` to ``moved`` (both (njoints, 4, 4), world frame)."""
    return np.array(
        [
            pin.log6(pin.SE3(M) * pin.SE3(P).inverse()).vector
            for P, M in zip(poses, moved, strict=True)
        ]
    )


def drawn_poses(poses: np.ndarray, twists: np.ndarray, a: float) -> np.ndarray:
    """(njoints, 4, 4) placements exp6(a xi_i) oMi of the links moved along their twists.

    Args:
        poses: (njoints, 4, 4) nominal joint placements oMi, world frame.
        twists: (njoints, 6) twists xi_i (v [m], w [rad]), world axes, at the world origin.
        a: amplification (dimensionless).
    """
    return np.array([pin.exp6(a * xi).homogeneous @ P for P, xi in zip(poses, twists, strict=True)])


def frame_pose(model: pin.Model, poses: np.ndarray, frame_id: int) -> np.ndarray:
    """(4, 4) world placement of a frame carried by its parent joint's drawn placement."""
    f = model.frames[frame_id]
    return poses[f.parentJoint] @ f.placement.homogeneous


def point_displacements(
    clm: ClosedLoopModel, q: np.ndarray, frame: str, dq: np.ndarray
) -> np.ndarray:
    """First-order displacements J_p dq [m] of the origins of the joints and of ``frame``.

    Args:
        q: (nq,) configuration.
        frame: name of the loaded frame.
        dq: (nv,) joint deflection (tangent of q) [rad or m].

    Returns:
        (njoints - 1 + 1, 3) displacements, world axes: joints 1..njoints-1, then the frame.
    """
    q = clm.check_configuration(q)
    dq = np.asarray(dq, dtype=float).reshape(-1)
    if dq.shape != (clm.model.nv,) or not np.all(np.isfinite(dq)):
        raise InvalidInputError(f"dq must be {clm.model.nv} finite values, got {dq.size}")
    J_f = frame_jacobian(clm, q, frame, "world")  # also the joint Jacobians of q
    rows = [joint_jacobian(clm.model, clm.data, j)[:3] @ dq for j in range(1, clm.model.njoints)]
    return np.array([*rows, J_f[:3] @ dq]).reshape(-1, 3)


def largest_displacement(clm: ClosedLoopModel, q: np.ndarray, frame: str, dq: np.ndarray) -> float:
    """d_max [m]: largest norm of :func:`point_displacements` (without under- or overflow
    of the squares: a load of any magnitude gives the same picture; NaN when one is
    not finite)."""
    return float(np.max(row_norms(point_displacements(clm, q, frame, dq))))


def largest_rotation(twists: np.ndarray) -> float:
    """w_max [rad]: largest link rotation ``|w_i|`` of ``twists`` (njoints, 6)."""
    return float(np.max(row_norms(np.asarray(twists)[:, 3:])))


def auto_scale(size: float, d_max: float, w_max: float, fraction: float = AUTO_FRACTION) -> float:
    """Amplification a = min(fraction L / d_max, ROTATION_CAP / w_max) (module
    docstring), L = ``size`` [m]; 1 when nothing deflects."""
    bounds = []
    if d_max > 0.0:
        bounds.append(fraction * size / d_max)
    if w_max > 0.0:
        bounds.append(ROTATION_CAP / w_max)
    return min(bounds) if bounds else 1.0


def model_poses(clm: ClosedLoopModel, q: np.ndarray) -> np.ndarray:
    """(njoints, 4, 4) world placements oMi of the joints of ``clm`` at q (index 0: the
    world), from its own data, which is updated to q."""
    update_kinematics(clm, clm.check_configuration(q))
    return np.array([M.homogeneous for M in clm.data.oMi])
