"""Closure residual of the statics and the tangent stiffness of the equilibrium equations.

The static equilibrium of a mechanism with joint springs under a dead-load wrench w at a
frame (see :mod:`closedloop.elastostatics.statics`) solves

    F(q, lambda) = g(q) - J(q)^T w + J_c(q)^T lambda = 0,   c(q) = 0,

with g the spring forces, J (6, nv) the frame Jacobian (world-aligned axes, at the frame
origin) and c (m,) the stacked closure residuals of :func:`closure_gap`:

* a point closure (ball joint) contributes the **world gap** c = p2 - p1 [m] between its
  two anchor points, Jacobian J_p2 - J_p1 (point Jacobians, world axes). Unlike
  Pinocchio's ``R1^T (p2 - p1)`` (axes of side 1), it does not change when either body
  spins about an axis through the anchor, so the equations, hence Newton's iterates, do
  not depend on which body is written first; its multipliers lambda are world-axes forces
  [N] (the force that side 2 exerts on side 1 at the anchor);
* a weld, and a revolute, prismatic, cylindrical or universal closure, contributes its
  rows of :func:`closure_residual` [m, rad] (:mod:`closedloop.kinematics.constraints`),
  its multipliers the conjugate forces and moments [N, N m].

Linearising F along the admissible motions N (nv, d) gives the tangent stiffness

    K_t = K_q - K_G + sum_j lambda_j Hess c_j        (nv, nv), restricted as N^T K_t N,

(Chen and Kao's conservative congruence transformation, extended to loop closures) where

* ``K_G[i, k] = d(J^T w)_i / dq_k = sum_r w_r dJ[r, i]/dq_k`` is the geometric (load)
  stiffness, J with Pinocchio's LOCAL_WORLD_ALIGNED axes; it enters with a minus sign;
* ``Hess c_j`` is the second derivative of closure row j (the loop curvature), weighted by
  the internal force lambda_j of the loop. With redundant closure rows lambda is known
  only up to a self-stress mu (J_c^T mu = 0); differentiating c = 0 twice along the
  closure manifold gives mu^T Hess c [v, v] = 0 for every admissible v, so it does not
  matter on N.

Derivatives with respect to q are taken along ``pin.integrate(model, q, v)``. A
world-fixed moment is not conservative under finite rotations: its K_G, hence K_t, is
then not symmetric.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import check_wrench
from closedloop.common.derivatives import (
    DIFFERENCE_STEP,
    central_differences,
    pinocchio_second_order_exact,
)
from closedloop.elastostatics.point_closures import point_anchors, point_curvature, point_gap
from closedloop.exceptions import InvalidInputError
from closedloop.kinematics.constraints import (
    closure_jacobian,
    closure_residual,
    frame_jacobian,
    update_kinematics,
)
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.elastic import (
    beam_joints,
    deflection,
    deflection_jacobian,
    spring_law,
    spring_stiffness,
)
from closedloop.model.gravity import Load

#: Step [rad or m] of the central differences that give the curvature of the closures
#: other than points (and every second derivative where Pinocchio's are wrong,
#: :mod:`closedloop.common.derivatives`):
#: the error is ~1e-10 relative to the closure Jacobian for links of metre scale; that
#: curvature enters K_t multiplied by lambda, so its relative error in K_t stays ~1e-10.
WELD_CURVATURE_STEP = DIFFERENCE_STEP

#: Smallest singular value of the scaled tangent stiffness (1 without preload: the scale
#: of the springs) below which it counts as singular (critical preload). A stiffening
#: preload that makes it span more than the rank rule resolves (1 / RANK_RTOL^2) is
#: refused as such, not as a critical load.
CRITICAL_RTOL = 1e-12

#: A spring-free admissible motion counts as acted on by the preload (stiffened by the
#: weight, coupled to the sprung motions) when its rows of the scaled tangent stiffness
#: (:func:`settled_tangent`, on the scale of the stiffest spring) exceed this; below, the
#: preload terms are rounding (measured 1e-16 on the spinning rods of a Delta; the weld
#: curvature by central differences carries ~1e-10 of them).
SPRING_FREE_RTOL = 1e-9


def _hessian(raw: np.ndarray, nv: int) -> np.ndarray:
    """(6, nv, nv) tensor H[r, i, k] = dJ[r, i]/dq_k from a Pinocchio kinematic Hessian.

    Pinocchio returns the tensor with a memory layout that numpy reads transposed; the
    column-major reshape restores it (see the Pinocchio notes of the project).
    """
    return np.asarray(raw).ravel().reshape((6, nv, nv), order="F")


def closure_gap(
    clm: ClosedLoopModel, q: np.ndarray, *, update: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Closure residual c (m,) of the statics and its Jacobian (m, nv) at q.

    Point closures: the world gap p2 - p1 [m] between the anchor points of side 2 and
    side 1, world axes, Jacobian J_p2 - J_p1 [m/rad or m/m]; it is invariant under a spin
    of either body about an axis through its anchor. The other types (welds, revolute,
    prismatic, cylindrical, universal): their rows [m, rad] of
    :func:`closedloop.kinematics.constraints.closure_residual` and their Jacobian. Rows are
    stacked in the order of ``clm.closures``, ``Closure.size`` per closure.

    Args:
        clm: the model.
        q: (nq,) configuration.
        update: recompute the kinematics of q first (else they must be current).
    """
    if update:
        update_kinematics(clm, q)
    m, nv = clm.n_constraints, clm.model.nv
    c, A = np.zeros(m), np.zeros((m, nv))
    if any(cl.kind != "3d" for cl in clm.closures):
        c[:], A[:] = closure_residual(clm, q, update=False), closure_jacobian(clm, q, update=False)
    rows = point_anchors(clm).rows
    if rows.size:
        c[rows], A[rows] = point_gap(clm, q)
    return c, A


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
    if update:  # a q of the caller's: its quaternions checked and normalised
        q = clm.check_configuration(q)
    if not _exact_hessians(clm):
        K_G = central_differences(clm.model, q, lambda x: frame_jacobian(clm, x, frame).T @ w)
        update_kinematics(clm, q)
        return K_G
    if update:
        update_kinematics(clm, q)
    pin.computeJointKinematicHessians(clm.model, clm.data)
    raw = pin.getFrameKinematicHessian(clm.model, clm.data, fid, pin.LOCAL_WORLD_ALIGNED)
    return np.einsum("r,rik->ik", w, _hessian(raw, clm.model.nv))


def closure_curvature(
    clm: ClosedLoopModel, q: np.ndarray, multipliers: np.ndarray, *, update: bool = True
) -> np.ndarray:
    """(nv, nv) loop curvature sum_j lambda_j Hess c_j of the rows of :func:`closure_gap`.

    Entry [a, b] = d(J_c^T lambda)_a / dq_b [N m/rad, N/m...]. Point closures: exact,
    sum_r lambda_r (H_p2 - H_p1)[r] from Pinocchio's kinematic Hessians of the two anchor
    joints. The other types (welds, revolute, prismatic, cylindrical, universal): central
    differences of their exact Jacobian rows with step :data:`WELD_CURVATURE_STEP` (error
    ~1e-10 relative).

    Args:
        clm: the model.
        q: (nq,) configuration.
        multipliers: (m,) lambda, one per closure row, in the units conjugate to the rows:
            world-axes forces [N] for point rows, N and N m for the others'.
        update: recompute the kinematics of q first (else they must be current).
    """
    model = clm.model
    lam = np.asarray(multipliers, dtype=float).reshape(-1)
    if lam.shape != (clm.n_constraints,):
        raise InvalidInputError(
            f"{lam.size} multipliers given; expected one per closure row ({clm.n_constraints})"
        )
    if not np.all(np.isfinite(lam)):
        raise InvalidInputError(f"multipliers must be finite, got {lam.tolist()}")
    if not np.any(lam):
        return np.zeros((model.nv, model.nv))
    if update:  # a q of the caller's: its quaternions checked and normalised
        q = clm.check_configuration(q)
    if not _exact_hessians(clm):
        out = central_differences(model, q, lambda x: closure_gap(clm, x)[1].T @ lam)
        update_kinematics(clm, q)
        return out
    if update:
        update_kinematics(clm, q)
    rows = point_anchors(clm).rows
    lam_p = lam[rows]
    out = point_curvature(clm, q, lam_p) if np.any(lam_p) else np.zeros((model.nv, model.nv))
    if rows.size < lam.size:  # rows of other closures
        lam_w = lam.copy()
        lam_w[rows] = 0.0
        if np.any(lam_w):
            out += central_differences(model, q, lambda x: closure_jacobian(clm, x).T @ lam_w)
            update_kinematics(clm, q)
    return out


def _exact_hessians(clm: ClosedLoopModel) -> bool:
    """Whether Pinocchio's kinematic Hessians hold for the model (once per model)."""
    return clm.memo("exact_hessians", lambda: pinocchio_second_order_exact(clm.model))


def spring_hessian(clm: ClosedLoopModel, q: np.ndarray, q_rest: np.ndarray) -> np.ndarray:
    """(nv, nv) stiffness of the springs' energy at q (:mod:`closedloop.model.elastic`).

    ``Je^T K_e Je + sum_i (f_e)_i Hess e_i`` with e the springs' deflection (dq =
    difference(q_rest, q), a beam's tip displacement and rotation), Je = de/dq (
    ``pin.dDifference``, ARG1, for the ordinary joints), f_e the springs' forces and K_e
    their stiffness (``clm.spring_matrix``: diag(k), or a block for the coupled spring of
    a multi-dof joint; on a beam with its geometric stiffness). For 1-dof joints
    (revolute, prismatic) and the other vector-space joints Je is constant and the second
    term vanishes; for a sprung joint on a Lie group (free flyer, spherical, planar:
    nq != nv) it is the derivative of Je^T f_e at fixed f_e, by central differences with
    step :data:`WELD_CURVATURE_STEP` (error ~1e-10 of ``|f_e|``), zero at zero deflection.
    Locked coordinates (k = inf) get 0. Units: N m/rad or N/m on the diagonal.
    """
    model = clm.model
    Jd, e = deflection_jacobian(clm, q_rest, q), deflection(clm, q_rest, q)
    if clm.spring_blocks or beam_joints(clm):
        H = Jd.T @ spring_stiffness(clm, e) @ Jd
    else:
        k = np.where(np.isinf(clm.stiffness), 0.0, clm.stiffness)
        H = (Jd.T * k) @ Jd
    curved = clm.memo("lie_group_springs", lambda: _lie_group_springs(clm))
    if curved.size:
        f = spring_law(clm, e)[0]
        if np.any(f[curved]):
            H += central_differences(
                model, q, lambda x: deflection_jacobian(clm, q_rest, x).T @ f, curved
            )
    return H


def _lie_group_springs(clm: ClosedLoopModel) -> np.ndarray:
    """Velocity indices of the sprung coordinates of joints with nq != nv (Lie groups)."""
    k, out = clm.stiffness, []
    for jm in clm.model.joints[1:]:
        v = slice(jm.idx_v, jm.idx_v + jm.nv)
        if jm.nq != jm.nv and np.any((k[v] > 0) & np.isfinite(k[v])):
            out.extend(range(v.start, v.stop))
    return np.array(out, dtype=int)


def tangent_stiffness(
    clm: ClosedLoopModel,
    q: np.ndarray,
    q_rest: np.ndarray,
    frame: str,
    wrench: np.ndarray,
    multipliers: np.ndarray,
    *,
    gravity: Load | None = None,
    update: bool = True,
) -> np.ndarray:
    """(nv, nv) tangent stiffness in joint space, K_q - K_G(w) + sum_j lambda_j Hess c_j
    (+ dG/dq of the weight).

    Entry [a, b] is the derivative of equilibrium equation a (generalised force on
    coordinate a [N m or N]) with respect to coordinate b of q [rad or m]. Locked
    coordinates have zero spring terms; restrict the matrix to the admissible motions.

    Args:
        clm: the model.
        q: (nq,) configuration (an equilibrium).
        q_rest: (nq,) rest configuration of the springs.
        frame: name of the loaded frame.
        wrench: (6,) dead-load wrench (f [N], n [N m]), world axes, at the frame origin.
        multipliers: (m,) closure multipliers lambda at q, conjugate to the rows of
            :func:`closure_gap` (``Equilibrium.multipliers``).
        gravity: a :class:`closedloop.model.gravity.Load` whose weight (scaled) adds dG/dq.
        update: recompute the kinematics of q first (else they must be current).
    """
    if update:  # a q of the caller's: its quaternions checked and normalised
        q, q_rest = clm.check_configuration(q), clm.check_configuration(q_rest)
        update_kinematics(clm, q)
    K = spring_hessian(clm, q, q_rest)
    K -= geometric_stiffness(clm, q, frame, wrench, update=False)
    K += closure_curvature(clm, q, multipliers, update=False)
    if gravity is not None:
        K += gravity.stiffness(q, clm.model.nv)
    return K


def scaled_tangent(
    clm: ClosedLoopModel, Kt: np.ndarray, N: np.ndarray, V: np.ndarray, ls: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Tangent stiffness on the sprung admissible motions, scaled by the springs.

    Args:
        clm: the model.
        Kt: (nv, nv) tangent stiffness (:func:`tangent_stiffness`).
        N: (nv, d) admissible motions; V (d, s), ls (s,): eigenvectors and eigenvalues of
            their spring stiffness N^T K_q N with a restoring spring
            (:func:`closedloop.elastostatics.compliance.spring_subspace`).

    Returns:
        (M, P, T): M (s, s) ``I + T^T P T`` with T = V / sqrt(ls) (T^T N^T K_q N T = I),
        dimensionless: the identity without preload, singular at a critical load; P (d, d)
        the preload part N^T (K_t - K_q) N of the restricted tangent stiffness; T (d, s)
        the scaling V / sqrt(ls) [sqrt(rad / (N m)), per the joint units].
    """
    P = N.T @ (Kt - clm.spring_matrix) @ N
    T = V / np.sqrt(ls)
    return np.eye(T.shape[1]) + T.T @ P @ T, P, T


def settled_tangent(
    M: np.ndarray, H: np.ndarray, T: np.ndarray, Z: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The scaled tangent stiffness extended to the spring-free motions the preload acts on.

    A spring-free admissible motion that does not move the loaded frame (a link hanging
    on a passive joint, a rod spinning about its axis) has no spring; the preload may
    still stiffen it (the weight of the hanging link) or couple it to the sprung motions.
    Those it acts on settle with them, and enter the compliance and the stability
    margin; the others (every row of theirs below :data:`SPRING_FREE_RTOL`) are internal
    mobilities, left out.

    Args:
        M: (s, s) T^T H T (:func:`scaled_tangent`).
        H: (d, d) the tangent stiffness on the admissible motions (any coordinates).
        T: (d, s) the sprung motions, T^T K_r T = I.
        Z: (d, z) the spring-free motions, orthonormal (unit-free) and divided by the
            square root of the stiffest spring (so that their rows of M are on its scale).

    Returns:
        (M, T) extended: M (s + a, s + a) on the motions T (d, s + a), the sprung ones
        first, then the a spring-free ones the preload acts on (unchanged when a = 0).
    """
    if not Z.shape[1]:
        return M, T
    HZ = H @ Z
    Mtz, Mzt, Mzz = T.T @ HZ, Z.T @ H @ T, Z.T @ HZ
    U, sv, _ = np.linalg.svd(np.hstack([Mzt, Mzz, Mtz.T, Mzz.T]), full_matrices=False)
    W = U[:, : int(np.count_nonzero(sv > SPRING_FREE_RTOL))]
    if not W.shape[1]:
        return M, T
    extended = np.block([[M, Mtz @ W], [W.T @ Mzt, W.T @ Mzz @ W]])
    return extended, np.hstack([T, Z @ W])


def stability_margin(M: np.ndarray, sprung: int | None = None) -> float:
    """Smallest eigenvalue of the symmetric part of M (:func:`scaled_tangent`); 1 if empty
    (no sprung motion: the unloaded value). Above 1 when the preload stiffens every motion
    (a hanging weight, tension).

    With ``sprung`` < M's size (:func:`settled_tangent`: the spring-free motions the
    preload acts on come last), those settle at each sprung motion: the margin is that
    of the Schur complement of their block S_zz in the symmetric part S, still 1
    unloaded and 0 where K_t turns singular; the smallest eigenvalue of S_zz (<= 0, on the
    scale of the stiffest spring) when the preload leaves one of them unstable or neutral
    (a link balanced upright on a passive joint).
    """
    if not M.size:
        return 1.0
    S = 0.5 * (M + M.T)
    s = S.shape[0] if sprung is None else sprung
    if s < S.shape[0]:
        low = float(np.linalg.eigvalsh(S[s:, s:])[0])
        if low <= 0.0 or s == 0:
            return low
        S = S[:s, :s] - S[:s, s:] @ np.linalg.solve(S[s:, s:], S[s:, :s])
    return float(np.linalg.eigvalsh(S)[0])
