"""A static equilibrium under a dead-load wrench, and what is measured on one: the frame's
displacement and, for a pure force, the potential energy (an independent check of
:func:`closedloop.elastostatics.statics.solve_equilibrium`: the equilibrium is a stationary
point of it on the closure manifold).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import ReadOnlyArrays, real_array
from closedloop.exceptions import InvalidInputError
from closedloop.kinematics.constraints import update_kinematics
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.elastic import deflection, spring_law
from closedloop.model.gravity import GravityLoad, Load


@dataclass(frozen=True)
class Equilibrium(ReadOnlyArrays):
    """A static equilibrium under a dead-load wrench (arrays read-only).

    Attributes:
        q: (nq,) equilibrium configuration.
        q_rest: (nq,) rest configuration of the springs (unloaded, assembled).
        frame: name of the loaded frame.
        wrench: (6,) applied wrench (fx, fy, fz [N], nx, ny, nz [N m]), world axes, at the
            frame origin.
        translation: (3,) displacement of the frame origin from its unloaded position [m],
            world axes.
        rotation: (3,) rotation vector of the frame from its unloaded orientation [rad],
            world axes: R = exp(rotation) R_rest.
        joint_deflection: (nv,) difference(q_rest, q) [rad or m].
        multipliers: (m,) closure multipliers lambda, one per row of
            :func:`closedloop.elastostatics.tangent.closure_gap`; for a point closure, the force [N]
            that side 2 exerts on side 1 at the anchor, in world axes; for a weld, the wrench
            [N, N m] conjugate to its log6 residual rows. Minimum-norm when closure rows
            are redundant (no self-stress).
        closure_residual: infinity norm of the closure residual at q [m, rad].
        force_residual: infinity norm of the unbalanced generalised force
            (g - J^T w + J_c^T lambda on the free coordinates) [N m, N].
        iterations: Newton iterations, all load increments together.
        load_steps: load increments used (1 when the full load converged at once).
        limits_violated: names of the joints outside their position limits at q (see
            :func:`closedloop.kinematics.limits.joints_outside_limits`); empty when every limit
            holds.
        gravity: the weight of the links and payloads that acts with the wrench
            (:class:`closedloop.model.gravity.GravityLoad`), or None.
    """

    q: np.ndarray
    q_rest: np.ndarray
    frame: str
    wrench: np.ndarray
    translation: np.ndarray
    rotation: np.ndarray
    joint_deflection: np.ndarray
    multipliers: np.ndarray
    closure_residual: float
    force_residual: float
    iterations: int
    load_steps: int
    limits_violated: tuple[str, ...] = ()
    gravity: GravityLoad | None = None

    @property
    def displacement(self) -> np.ndarray:
        """(6,) (translation [m], rotation vector [rad]) of the frame, world axes."""
        return np.concatenate([self.translation, self.rotation])

    @property
    def load(self) -> Load:
        """The full load: the wrench and the weight."""
        return Load(self.wrench, self.gravity)


def frame_displacement(
    clm: ClosedLoopModel, q: np.ndarray, q_ref: np.ndarray, frame: str
) -> np.ndarray:
    """(6,) displacement of ``frame`` from its pose at q_ref to its pose at q, world axes.

    Translation p(q) - p(q_ref) [m] of the frame origin, then the rotation vector
    log3(R(q) R(q_ref)^T) [rad]; to first order the frame twist J dq.
    """
    fid = clm.frame_id(frame)
    update_kinematics(clm, q_ref)
    ref = clm.data.oMf[fid].copy()
    update_kinematics(clm, q)
    cur = clm.data.oMf[fid]
    return np.concatenate(
        [cur.translation - ref.translation, pin.log3(cur.rotation @ ref.rotation.T)]
    )


def potential_energy(
    clm: ClosedLoopModel,
    q: np.ndarray,
    q_rest: np.ndarray,
    frame: str,
    force: np.ndarray,
    gravity: GravityLoad | None = None,
) -> float:
    """Potential energy [J] of the springs, a dead-load force at a frame origin, the weight.

    ``1/2 dq^T K_q dq - f . (p(q) - p(q_rest)) + V_g(q) - V_g(q_rest)`` over the spring
    coordinates (0 < k < inf; K_q = ``clm.spring_matrix``, diag(k) or with blocks),
    dq = difference(q_rest, q); a beam's energy is that of :mod:`closedloop.model.elastic`
    (its tip displacement and rotation, with the shortening of the bent beam). A
    world-fixed moment has no potential.

    Args:
        force: (3,) force [N], world axes, at the origin of ``frame``.
        gravity: the weight (:class:`closedloop.model.gravity.GravityLoad`), or None.
    """
    f = real_array(force, "force").reshape(-1)
    if f.shape != (3,) or not np.isfinite(f).all():
        raise InvalidInputError(f"force must be 3 finite values (fx fy fz) [N], got {f.tolist()}")
    springs = spring_law(clm, deflection(clm, q_rest, q))[1]
    dp = frame_displacement(clm, q, q_rest, frame)[:3]
    weight = 0.0 if gravity is None else gravity.potential(q) - gravity.potential(q_rest)
    return float(springs - f @ dp + weight)
