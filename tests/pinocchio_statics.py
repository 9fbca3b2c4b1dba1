"""Checks of configurations and equilibria written from Pinocchio's kinematics alone, for the
tests of the inverse kinematics and of paths under a load (no closedloop kinematics or
statics code is used): the frame's placement, the point closures' world gaps, and the
static equilibrium K (q - q_rest) = J^T w - G(q) + J_c^T lambda with the closure Jacobian
J_c from central differences of the gaps.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
from helpers import tangent_differences

#: Step [rad, m] of the central differences of the closure gaps: their error, h^2 times
#: the third derivative (of the order of the links' size, 1 m), 1e-12 of the Jacobian,
#: with rounding eps / h = 2e-10 of the gaps' size.
GAP_STEP = 1e-6


def placement(model: pin.Model, q: np.ndarray, frame: str) -> pin.SE3:
    """World placement of ``frame`` at q (forward kinematics), a copy."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, q)
    return data.oMf[model.getFrameId(frame)].copy()


def gaps(clm, q: np.ndarray) -> np.ndarray:
    """(3 k,) world gaps p2 - p1 [m] of the model's point closures at q (every closure must
    be a point closure: this check knows no other)."""
    model, data = clm.model, clm.model.createData()
    pin.forwardKinematics(model, data, q)
    out = []
    for closure in clm.closures:
        assert closure.kind == "3d", closure.kind
        c = closure.constraint
        p1 = data.oMi[c.joint1_id].act(c.joint1_placement.translation)
        p2 = data.oMi[c.joint2_id].act(c.joint2_placement.translation)
        out.append(p2 - p1)
    return np.concatenate(out) if out else np.zeros(0)


def gap_jacobian(clm, q: np.ndarray) -> np.ndarray:
    """(3 k, nv) Jacobian of :func:`gaps` along ``pin.integrate``, central differences."""
    J = tangent_differences(clm.model, lambda x: gaps(clm, x), q, GAP_STEP)
    return J.reshape(-1, clm.model.nv)


def unbalance(clm, q, q_rest, frame: str, wrench, gravity=None) -> float:
    """The unbalanced generalised force at q (nq,), springs at rest at q_rest (nq,), under a
    dead-load ``wrench`` (6,) at the frame origin (world axes) and the links' weight under
    ``gravity`` (3,) (or none), relative to the largest of the spring, wrench and weight
    forces: the least-squares residual of K dq - J^T w + G(q) + J_c^T lambda = 0 over
    lambda, on the coordinates with a finite stiffness (the locked ones' reactions are
    free). Springs per coordinate on vector-space joints (dq = q - q_rest there)."""
    model = clm.model
    data = model.createData()
    k = np.where(np.isinf(clm.stiffness), 0.0, clm.stiffness)
    spring = k * pin.difference(model, q_rest, q)
    J = pin.computeFrameJacobian(model, data, q, model.getFrameId(frame), pin.LOCAL_WORLD_ALIGNED)
    load = J.T @ np.asarray(wrench, dtype=float)
    weight = np.zeros(model.nv)
    if gravity is not None:
        heavy = pin.Model(model)
        heavy.gravity = pin.Motion(np.r_[gravity, np.zeros(3)])
        weight = pin.computeGeneralizedGravity(heavy, heavy.createData(), q)
    free = np.isfinite(clm.stiffness)
    force = (spring - load + weight)[free]
    if clm.closures:
        A = gap_jacobian(clm, q)[:, free]
        lam = np.linalg.lstsq(A.T, -force, rcond=None)[0]
        force = force + A.T @ lam
    scale = max(np.abs(spring).max(), np.abs(load).max(), np.abs(weight).max())
    return float(np.abs(force).max() / scale)
