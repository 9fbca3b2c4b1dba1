"""Tangent stiffness and compliance under a finite dead-load preload.

A wrench w0 = (f [N], n [N m]) fixed in world axes and applied at the origin of a frame
deflects the mechanism to an equilibrium q (see :func:`closedloop.statics.solve_equilibrium`)
where, with multipliers lambda of the closure rows c(q) = 0,

    F(q, lambda) = g(q) - J(q)^T w0 + J_c(q)^T lambda = 0,   g = K_q dq (spring forces).

A further wrench increment dw (also a dead load at the frame origin) moves it by dq = N y
along the admissible motions N (nv, d) (closures and locked joints kept), with

    K_t y = N^T J^T dw,   K_t = N^T (K_q - K_G + sum_j lambda_j Hess c_j) N   (d, d)

(Chen and Kao's conservative congruence transformation, extended to loop closures), where

* ``K_G[i, k] = d(J^T w0)_i / dq_k = sum_r w0_r dJ[r, i]/dq_k`` is the geometric (load)
  stiffness of the preload, J the (6, nv) frame Jacobian with world-aligned axes at the
  frame origin (Pinocchio LOCAL_WORLD_ALIGNED); it enters with a minus sign;
* ``Hess c_j`` is the second derivative of closure row j: the loop curvature, weighted by
  the internal force lambda_j that the preload creates in the loop. With redundant
  closure rows, lambda is known only up to a self-stress mu (J_c^T mu = 0), which the
  solver sets to zero; it does not matter here, because differentiating c = 0 twice
  along the closure manifold gives mu^T Hess c [v, v] = 0 for every admissible v.

Derivatives with respect to q are taken along ``pin.integrate(model, q, v)``. The
preloaded compliance at the frame is ``C = (J N) K_t^-1 (J N)^T``. A world-fixed moment is
not conservative under finite rotations: its K_G, hence K_t and C, is then not symmetric.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from .arrays import check_wrench, readonly
from .compliance import ComplianceResult, compliance, spring_subspace
from .exceptions import InvalidInputError, SingularConfigurationError
from .kinematics import (
    closure_jacobian,
    closure_residual,
    frame_jacobian,
    nullspace,
    update_kinematics,
)
from .model import ClosedLoopModel

if TYPE_CHECKING:
    from .statics import Equilibrium

#: Step [rad or m] of the central differences that give the curvature of weld closures.
#: The error of a central difference is h^2/6 |c'''| (truncation) + eps |J_c| / h (rounding),
#: smallest near h = (3 eps)^(1/3) ~ 1e-5, where both are ~1e-10 relative to the closure
#: Jacobian for links of metre scale; that curvature enters K_t multiplied by lambda, so
#: its relative error in K_t stays ~1e-10.
WELD_CURVATURE_STEP = 1e-5

#: Smallest singular value of the scaled tangent stiffness (1 without preload), relative
#: to max(1, its largest), below which it counts as singular (critical preload).
CRITICAL_RTOL = 1e-12


def _hessian(raw: np.ndarray, nv: int) -> np.ndarray:
    """(6, nv, nv) tensor H[r, i, k] = dJ[r, i]/dq_k from a Pinocchio kinematic Hessian.

    Pinocchio returns the tensor with a memory layout that numpy reads transposed; the
    column-major reshape restores it (see the Pinocchio notes of the project).
    """
    return np.asarray(raw).ravel().reshape((6, nv, nv), order="F")


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def geometric_stiffness(
    clm: ClosedLoopModel, q: np.ndarray, frame: str, wrench: np.ndarray, *, update: bool = True
) -> np.ndarray:
    """(nv, nv) geometric stiffness K_G of a dead-load wrench at a frame.

    ``K_G[i, k] = d(J^T w)_i / dq_k`` with J (6, nv) the Jacobian of ``frame`` (twist at the
    frame origin, world-aligned axes) and w held fixed in world axes. Units: N m per rad or
    N per m, per the units of coordinates i and k. It enters the tangent stiffness with a
    minus sign; it is symmetric when w has no moment.

    Args:
        clm: the model.
        q: (nq,) configuration.
        frame: name of the loaded frame.
        wrench: (6,) (fx, fy, fz [N], nx, ny, nz [N m]), world axes, at the frame origin.
        update: recompute the kinematics of q first (else they must be current).
    """
    w = check_wrench(wrench)
    fid = clm.frame_id(frame)
    if update:
        update_kinematics(clm, q)
    pin.computeJointKinematicHessians(clm.model, clm.data)
    raw = pin.getFrameKinematicHessian(clm.model, clm.data, fid, pin.LOCAL_WORLD_ALIGNED)
    return np.einsum("r,rik->ik", w, _hessian(raw, clm.model.nv))


def _point_jacobians(clm: ClosedLoopModel, joint: int, placement: pin.SE3):
    """Position (3,), rotation (3, 3), point Jacobian (3, nv), angular Jacobian (3, nv) and
    their derivatives (3, nv, nv) of an anchor frame fixed on ``joint`` (world axes).

    From the spatial (WORLD) Jacobian [v0; w] of the joint, the point p moves at
    v0 + w x p, so J_p = J_v - [p]x J_w and dJ_p[:, a]/dq_b = H_v - [p]x H_w - [J_p b]x J_w a.
    """
    model, data = clm.model, clm.data
    oM = data.oMi[joint] * placement
    p = oM.translation
    JW = pin.getJointJacobian(model, data, joint, pin.WORLD)
    HW = _hessian(pin.getJointKinematicHessian(model, data, joint, pin.WORLD), model.nv)
    Jp = JW[:3] - _skew(p) @ JW[3:]
    Hp = HW[:3] - np.einsum("ij,jab->iab", _skew(p), HW[3:])
    Hp -= np.cross(Jp.T[None, :, :], JW[3:].T[:, None, :]).transpose(2, 0, 1)
    return p, oM.rotation, Jp, JW[3:], Hp, HW[3:]


def _point_curvature(clm: ClosedLoopModel, constraint, lam: np.ndarray) -> np.ndarray:
    """(nv, nv) Hessian of lam . c for a point closure c = R1^T (p2 - p1).

    With mu = R1 lam (world) and d = p2 - p1 the gradient is
    ``D^T mu + W1^T (mu x d)`` (D = J_p2 - J_p1, W1 the angular Jacobian of side 1); the
    Hessian differentiates it with d mu/dq_b = w1_b x mu and d d/dq_b = D_b.
    """
    p1, R1, J1, W1, H1, HW1 = _point_jacobians(
        clm, constraint.joint1_id, constraint.joint1_placement
    )
    p2, _, J2, _, H2, _ = _point_jacobians(clm, constraint.joint2_id, constraint.joint2_placement)
    mu, d = R1 @ lam, p2 - p1
    D, HD = J2 - J1, H2 - H1
    X = np.cross(W1.T, mu)  # (nv, 3): row b is w1_b x mu
    Y = np.cross(X, d) + np.cross(mu, D.T)  # row b: d(mu x d)/dq_b
    return (
        D.T @ X.T
        + np.einsum("r,rab->ab", mu, HD)
        + W1.T @ Y.T
        + np.einsum("r,rab->ab", np.cross(mu, d), HW1)
    )


def closure_curvature(
    clm: ClosedLoopModel, q: np.ndarray, multipliers: np.ndarray, *, update: bool = True
) -> np.ndarray:
    """(nv, nv) loop curvature sum_j lambda_j Hess c_j (entry [a, b] = d(J_c^T lambda)_a/dq_b).

    Point closures: exact, from Pinocchio's kinematic Hessians of the two anchor joints
    (:func:`_point_curvature`). Weld closures (log6 residual): central differences of the
    exact closure Jacobian with step :data:`WELD_CURVATURE_STEP` (error ~1e-10 relative).

    Args:
        clm: the model.
        q: (nq,) configuration.
        multipliers: (m,) lambda, one per closure row, in the units conjugate to the rows
            (N for point rows [m]; N and N m for weld rows [m, rad]).
        update: recompute the kinematics of q first (else they must be current).
    """
    model = clm.model
    lam = np.asarray(multipliers, dtype=float).reshape(-1)
    if lam.shape != (clm.n_constraints,):
        raise InvalidInputError(
            f"{lam.size} multipliers given; expected one per closure row ({clm.n_constraints})"
        )
    if update:
        update_kinematics(clm, q)
    out = np.zeros((model.nv, model.nv))
    if not np.any(lam):
        return out
    pin.computeJointKinematicHessians(model, clm.data)
    weld_rows = np.zeros(clm.n_constraints, dtype=bool)
    row = 0
    for c in clm.closures:
        lam_j = lam[row : row + c.size]
        if c.kind == "3d" and np.any(lam_j):
            out += _point_curvature(clm, c.constraint, lam_j)
        elif c.kind == "6d":
            weld_rows[row : row + c.size] = True
        row += c.size
    lam_w = np.where(weld_rows, lam, 0.0)
    if np.any(lam_w):
        h = WELD_CURVATURE_STEP
        for b in range(model.nv):
            e = np.zeros(model.nv)
            e[b] = h
            plus = closure_jacobian(clm, pin.integrate(model, q, e)).T @ lam_w
            minus = closure_jacobian(clm, pin.integrate(model, q, -e)).T @ lam_w
            out[:, b] += (plus - minus) / (2.0 * h)
        update_kinematics(clm, q)
    return out


def spring_hessian(clm: ClosedLoopModel, q: np.ndarray, q_rest: np.ndarray) -> np.ndarray:
    """(nv, nv) stiffness of the springs 1/2 sum k_i dq_i^2, dq = difference(q_rest, q).

    ``Jd^T diag(k) Jd`` with Jd = d dq / dq (``pin.dDifference``, ARG1): exact for 1-dof
    joints (revolute, prismatic), where Jd = 1; for a multi-dof joint carrying a spring it
    omits the derivative of Jd, exact at zero deflection of that joint. Locked coordinates
    (k = inf) get 0. Units: N m/rad or N/m on the diagonal.
    """
    Jd = pin.dDifference(clm.model, q_rest, q, pin.ARG1)
    k = np.where(np.isinf(clm.stiffness), 0.0, clm.stiffness)
    return (Jd.T * k) @ Jd


def tangent_stiffness(
    clm: ClosedLoopModel,
    q: np.ndarray,
    q_rest: np.ndarray,
    frame: str,
    wrench: np.ndarray,
    multipliers: np.ndarray,
    *,
    update: bool = True,
) -> np.ndarray:
    """(nv, nv) tangent stiffness in joint space, K_q - K_G(w) + sum_j lambda_j Hess c_j.

    Entry [a, b] is the derivative of equilibrium equation a (generalised force on
    coordinate a [N m or N]) with respect to coordinate b of q [rad or m]. Locked
    coordinates have zero spring terms; restrict the matrix to the admissible motions.

    Args:
        clm: the model.
        q: (nq,) configuration (an equilibrium).
        q_rest: (nq,) rest configuration of the springs.
        frame: name of the loaded frame.
        wrench: (6,) dead-load wrench (f [N], n [N m]), world axes, at the frame origin.
        multipliers: (m,) closure multipliers lambda at q (see :class:`Equilibrium`).
        update: recompute the kinematics of q first (else they must be current).
    """
    if update:
        update_kinematics(clm, q)
    K = spring_hessian(clm, q, q_rest)
    K -= geometric_stiffness(clm, q, frame, wrench, update=False)
    K += closure_curvature(clm, q, multipliers, update=False)
    return K


@dataclass(frozen=True)
class PreloadedCompliance(ComplianceResult):
    """Compliance under a preload; the fields of :class:`ComplianceResult` plus the preload.

    ``C`` (6, 6) maps a wrench increment dw (dead load: fixed in world axes while the
    frame moves, at the frame origin, components in ``axes``) to the twist of the frame
    about its preloaded pose (dx, dy, dz [m], rx, ry, rz [rad]), at ``point``, the frame
    origin at the preloaded equilibrium ``q``. ``G`` (nv, 6) maps dw to the joint
    deflection. C is symmetric when the preload has no moment, not in general otherwise.

    Attributes:
        preload: (6,) preload wrench (f [N], n [N m]), world axes, at the frame origin.
        stability_margin: smallest eigenvalue of the symmetric part of K_t scaled by the
            unloaded spring stiffness (1 without preload, <= 0 past a static instability;
            for a non-conservative preload a divergence indicator only).
    """

    preload: np.ndarray
    stability_margin: float

    @property
    def is_stable(self) -> bool:
        """True when the preloaded equilibrium is statically stable (margin > 0)."""
        return self.stability_margin > 0.0

    @property
    def K(self) -> np.ndarray:
        """(6, 6) stiffness C^-1 [SI]; symmetrised only when C is symmetric."""
        if not self.is_full_rank or np.array_equal(self.C, self.C.T):
            return super().K  # symmetric, or raises RigidDirectionsError
        return readonly(np.linalg.inv(self.C))

    def to_dict(self) -> dict:
        """JSON-ready summary: that of :class:`ComplianceResult` plus the preload."""
        out = super().to_dict()
        out["preload"] = self.preload.tolist()
        out["stability_margin"] = self.stability_margin
        return out


def preloaded_compliance(
    clm: ClosedLoopModel, equilibrium: Equilibrium, axes: str = "world"
) -> PreloadedCompliance:
    """Cartesian compliance at the loaded frame about a preloaded equilibrium.

    Args:
        clm: the model the equilibrium was solved with.
        equilibrium: result of :func:`closedloop.statics.solve_equilibrium` (its frame,
            preload wrench, configuration q, rest configuration and multipliers).
        axes: ``"world"`` (world-aligned, default) or ``"local"`` (the frame's own axes at
            the preloaded pose) for the increments dw and the twist.

    Returns:
        The compliance; when the preload terms vanish (zero wrench) it is exactly
        :func:`closedloop.compliance.compliance` at q. As there, spring-free motions that
        do not move the frame (internal mobilities) are left out; any coupling of the
        preload into them is neglected.

    Raises:
        MechanismError: a spring-free motion moves the frame.
        SingularConfigurationError: K_t is singular (critical preload: buckling or limit
            point).
    """
    eq = equilibrium
    q, frame, w0 = eq.q, eq.frame, check_wrench(eq.wrench)
    update_kinematics(clm, q)
    J = frame_jacobian(clm, q, frame, axes, update=False)
    N, Vs, ls, n_internal = spring_subspace(clm, q, J, frame)
    Kt = tangent_stiffness(clm, q, eq.q_rest, frame, w0, eq.multipliers, update=False)
    k = np.where(np.isinf(clm.stiffness), 0.0, clm.stiffness)
    P = N.T @ (Kt - np.diag(k)) @ N  # preload part of K_t (d, d)
    if not np.any(P):
        base = compliance(clm, q, frame, axes)
        return PreloadedCompliance(**base.__dict__, preload=readonly(w0), stability_margin=1.0)
    T = Vs / np.sqrt(ls)  # T^T K_r T = I on the sprung motions
    M = np.eye(T.shape[1]) + T.T @ P @ T
    s_M = np.linalg.svd(M, compute_uv=False)
    if s_M.size and s_M[-1] <= CRITICAL_RTOL * max(1.0, s_M[0]):
        raise SingularConfigurationError(
            f"the tangent stiffness at frame {frame!r} is singular under preload "
            f"{w0.tolist()} (critical load: buckling or limit point)"
        )
    margin = float(np.min(np.linalg.eigvalsh(0.5 * (M + M.T)), initial=1.0))
    B = J @ N @ T
    X = np.linalg.solve(M, B.T) if M.size else B.T
    C = B @ X
    if not np.any(w0[3:]):  # conservative preload: K_t and C symmetric up to rounding
        C = 0.5 * (C + C.T)
    rigid, rank = nullspace(B.T)  # twists outside the range of C
    residual = closure_residual(clm, q)  # also restores the kinematics of q
    return PreloadedCompliance(
        C=readonly(C),
        frame=frame,
        axes=axes,
        point=readonly(clm.data.oMf[clm.frame_id(frame)].translation),
        q=readonly(q),
        rank=rank,
        rigid_directions=readonly(rigid),
        closure_residual=float(np.max(np.abs(residual), initial=0.0)),
        mobility=N.shape[1],
        internal_mobilities=n_internal,
        G=readonly(N @ T @ X),
        preload=readonly(w0),
        stability_margin=margin,
    )
