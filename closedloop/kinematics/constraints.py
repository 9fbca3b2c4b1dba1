"""Constrained kinematics: closure residuals and Jacobians, null spaces, closed-loop Jacobians."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from closedloop.common import lapack
from closedloop.common.conditioning import RANK_RTOL as _RANK_RTOL
from closedloop.exceptions import InvalidInputError, SingularConfigurationError
from closedloop.model.closed_loop import ClosedLoopModel

#: Relative threshold (singular values, or pivots of a rank-revealing QR) below which a
#: direction counts as rank deficient: the project's one rule (:mod:`.conditioning`).
RANK_RTOL = _RANK_RTOL

#: Pinocchio's reference frame of each ``axes`` value: world axes at the frame's origin, or
#: the frame's own axes.
REFERENCE_FRAMES = {"world": pin.LOCAL_WORLD_ALIGNED, "local": pin.LOCAL}


def reference_frame(axes: str) -> pin.ReferenceFrame:
    """Pinocchio's reference frame of the ``axes`` of a Jacobian (:data:`REFERENCE_FRAMES`).

    Raises:
        InvalidInputError: unknown ``axes``.
    """
    if not isinstance(axes, str) or axes not in REFERENCE_FRAMES:
        raise InvalidInputError(f"axes {axes!r}; expected one of {sorted(REFERENCE_FRAMES)}")
    return REFERENCE_FRAMES[axes]


def update_kinematics(clm: ClosedLoopModel, q: np.ndarray) -> None:
    """Forward kinematics, joint Jacobians and frame placements at q (nq,), in ``clm.data``.

    ``clm.data`` is this thread's workspace of the model; a
    :class:`closedloop.kinematics.configuration.Configuration` has a Data of its own instead.
    """
    pin.computeJointJacobians(clm.model, clm.data, q)
    pin.updateFramePlacements(clm.model, clm.data)


def _closures(clm: ClosedLoopModel) -> tuple[tuple, tuple[str, ...], bool]:
    """(the constraints of the closures, their types, whether all are point closures of a
    model with more than one coordinate: residuals and Jacobians stacked as Pinocchio gives
    them), once per model."""
    return clm.memo("closures", _closure_kinds, clm)


def _closure_kinds(clm: ClosedLoopModel) -> tuple[tuple, tuple[str, ...], bool]:
    closures = clm.closures
    points = clm.model.nv > 1 and all(c.kind == "3d" for c in closures)
    return tuple(c.constraint for c in closures), tuple(c.kind for c in closures), points


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def typed_residual(kind: str, c1Mc2: pin.SE3) -> np.ndarray:
    """Residual rows of a joint-type closure from the placement of B in A (``c1Mc2``).

    With R = R_A^T R_B, t = R_A^T (p_B - p_A) (B's origin in A's axes) [m] and z = R e_z
    (B's z axis in A's axes):

    * ``revolute``: (t, z_x, z_y) [m, m, m, rad, rad];
    * ``prismatic``: (log3 R, t_x, t_y) [rad x 3, m, m];
    * ``cylindrical``: (z_x, z_y, t_x, t_y) [rad, rad, m, m];
    * ``universal``: (t, z_z) [m x 3, rad] (z_z = z_A . z_B).

    The z rows of ``revolute`` and ``cylindrical`` also vanish with the z axes opposite:
    :func:`flipped_closures` tells that branch apart.
    """
    R, t = c1Mc2.rotation, c1Mc2.translation
    z = R[:, 2]
    if kind == "revolute":
        return np.concatenate([t, z[:2]])
    if kind == "prismatic":
        return np.concatenate([pin.log3(R), t[:2]])
    if kind == "cylindrical":
        return np.concatenate([z[:2], t[:2]])
    return np.concatenate([t, z[2:]])  # universal


def typed_jacobian(kind: str, model: pin.Model, data: pin.Data, constraint, cd) -> np.ndarray:
    """(n, nv) Jacobian of :func:`typed_residual` from the joint Jacobians in ``data`` and
    the evaluated constraint data ``cd`` (frames A = side 1, B = side 2).

    From the spatial (WORLD) Jacobians of the two joints, D = J_2 - J_1 [v0; w] is the
    relative spatial velocity: t moves at R_A^T (D_v - [p_B]x D_w) and B turns relative to A
    at W = R_A^T D_w (A's axes), so that dR = [W]x R, dz = W x z and
    d log3 R = Jlog3(R) R^T W.
    """
    nv = model.nv
    J1 = np.asarray(pin.getJointJacobian(model, data, constraint.joint1_id, pin.WORLD))
    J2 = np.asarray(pin.getJointJacobian(model, data, constraint.joint2_id, pin.WORLD))
    D = J2.reshape(6, nv) - J1.reshape(6, nv)
    RA, pB = cd.oMc1.rotation, cd.oMc2.translation
    T = RA.T @ (D[:3] - _skew(pB) @ D[3:])
    W = RA.T @ D[3:]
    R = cd.c1Mc2.rotation
    Z = -_skew(R[:, 2]) @ W
    if kind == "revolute":
        return np.vstack([T, Z[:2]])
    if kind == "prismatic":
        return np.vstack([pin.Jlog3(R) @ R.T @ W, T[:2]])
    if kind == "cylindrical":
        return np.vstack([Z[:2], T[:2]])
    return np.vstack([T, Z[2:]])  # universal


def residual_rows(clm: ClosedLoopModel, data: pin.Data, constraint_datas) -> np.ndarray:
    """(m,) stacked closure residuals from current kinematics in ``data`` [m; m, rad]:
    Pinocchio's for points (R_A^T (p_B - p_A)) and welds (log6 of B in A), those of
    :func:`typed_residual` for the joint types."""
    model = clm.model
    constraints, kinds, points = _closures(clm)
    if not constraints:
        return np.empty(0)
    if points:  # Pinocchio's residuals as they are
        for c, cd in zip(constraints, constraint_datas, strict=True):
            c.calc(model, data, cd)
        return np.concatenate([cd.constraint_position_error for cd in constraint_datas])
    parts = []
    for c, cd, kind in zip(constraints, constraint_datas, kinds, strict=True):
        c.calc(model, data, cd)
        parts.append(
            cd.constraint_position_error if kind in ("3d", "6d") else typed_residual(kind, cd.c1Mc2)
        )
    return np.concatenate(parts)


def jacobian_rows(
    clm: ClosedLoopModel, data: pin.Data, constraint_datas, *, calc: bool = True
) -> np.ndarray:
    """(m, nv) Jacobian of :func:`residual_rows` from current kinematics in ``data``
    (joint Jacobians included).

    Args:
        calc: evaluate the constraints first (False when :func:`residual_rows` has just
            done it with the same datas).
    """
    model = clm.model
    constraints, kinds, points = _closures(clm)
    if not constraints:
        return np.empty((0, model.nv))
    if calc:
        residual_rows(clm, data, constraint_datas)
    if points:  # each (3, nv) as it is
        pairs = zip(constraints, constraint_datas, strict=True)
        return np.concatenate([c.jacobian(model, data, cd) for c, cd in pairs])
    parts = []
    for c, cd, kind in zip(constraints, constraint_datas, kinds, strict=True):
        if kind == "3d":
            parts.append(c.jacobian(model, data, cd))
        elif kind == "6d":  # the derivative of log6 of the relative placement
            parts.append(pin.Jlog6(cd.c1Mc2.inverse()) @ c.jacobian(model, data, cd))
        else:
            parts.append(typed_jacobian(kind, model, data, c, cd))
    out = np.concatenate([np.asarray(p).reshape(-1, model.nv) for p in parts])
    return out


def flipped_closures(clm: ClosedLoopModel, constraint_datas) -> list[str]:
    """Names of the revolute and cylindrical closures whose z axes point opposite ways
    (z_A . z_B <= 0) in the evaluated ``constraint_datas``: their rows vanish there too,
    on a branch that is not the joint."""
    out = []
    for cl, cd in zip(clm.closures, constraint_datas, strict=True):
        if cl.kind in ("revolute", "cylindrical") and cd.c1Mc2.rotation[2, 2] <= 0.0:
            out.append(cl.name)
    return out


def frame_jacobian_rows(clm: ClosedLoopModel, data: pin.Data, frame: str, axes: str) -> np.ndarray:
    """(6, nv) Jacobian of ``frame`` from current joint Jacobians in ``data``.

    Raises:
        InvalidInputError: unknown ``axes``, or a model without any moving joint (nv = 0).
        NameNotFoundError: unknown frame.
    """
    reference = reference_frame(axes)
    fid = clm.frame_id(frame)
    if clm.model.nv == 0:  # pin.getFrameJacobian crashes the interpreter on nv = 0
        raise InvalidInputError(
            f"model {clm.name!r} has no moving joint (nv = 0): frame {frame!r} cannot move, "
            "there is no compliance to compute; give the model joints (or springs)"
        )
    J = pin.getFrameJacobian(clm.model, data, fid, reference)
    return np.asarray(J).reshape(6, clm.model.nv)  # a one-dof model gives a (6,) vector


def closure_residual(clm: ClosedLoopModel, q: np.ndarray, *, update: bool = True) -> np.ndarray:
    """Stacked closure residuals (m,) at q [m; m, rad] (:func:`residual_rows`)."""
    if update:
        update_kinematics(clm, q)
    return residual_rows(clm, *clm.workspace())


def closure_jacobian(clm: ClosedLoopModel, q: np.ndarray, *, update: bool = True) -> np.ndarray:
    """(m, nv) Jacobian of :func:`closure_residual` with respect to the tangent of q.

    For a weld the anchor Jacobian maps velocities to the relative twist; it is composed
    with the Jacobian of log6 so that the result is the derivative of the residual also
    away from closure (where the two coincide).
    """
    if update:
        update_kinematics(clm, q)
    return jacobian_rows(clm, *clm.workspace())


def frame_jacobian(
    clm: ClosedLoopModel, q: np.ndarray, frame: str, axes: str = "world", *, update: bool = True
) -> np.ndarray:
    """(6, nv) Jacobian of frame ``frame``: twist (v [m/s], w [rad/s]) at the frame origin.

    Args:
        axes: ``"world"`` (world-aligned axes) or ``"local"`` (the frame's own axes).
    """
    if update:
        update_kinematics(clm, q)
    return frame_jacobian_rows(clm, clm.data, frame, axes)


def orthogonal_split(A: np.ndarray, rtol: float = RANK_RTOL) -> tuple[np.ndarray, np.ndarray, int]:
    """Orthonormal bases of the row space and of the null space of A (m, n), and its rank.

    Rank-revealing QR of A^T with column pivoting (LAPACK ``dgeqp3``): A^T P = Q R with
    ``|R_ii|`` non-increasing; the rank counts the ``|R_ii|`` above ``rtol`` times the largest.
    On matrices this small it is several times faster than an SVD, and the rank decision
    agrees with the singular values except within a small factor of the threshold.

    Returns:
        W: (n, rank) row-space basis; Z: (n, n - rank) null-space basis, A Z ~ 0; together
        they form an orthogonal matrix.
        rank: rank of A.
    """
    m, n = A.shape
    if m == 0 or n == 0:
        return np.zeros((n, 0)), np.eye(n), 0
    qr, _, tau, _, info = lapack.dgeqp3(np.asarray(A, dtype=float).T)
    if info != 0:
        raise np.linalg.LinAlgError(f"dgeqp3 failed (info={info})")
    d = np.abs(qr.diagonal())
    rank = int(np.count_nonzero(d > rtol * d[0])) if d[0] > 0.0 else 0
    if tau.size < n:  # fewer reflectors than columns: pad to build the square Q
        qr = np.hstack([qr[:, : tau.size], np.zeros((n, n - tau.size))])
        tau = np.hstack([tau, np.zeros(n - tau.size)])
    Q = lapack.dorgqr(qr[:, :n], tau, overwrite_a=1)[0]
    return Q[:, :rank], Q[:, rank:], rank


def nullspace(A: np.ndarray, rtol: float = RANK_RTOL) -> tuple[np.ndarray, int]:
    """Orthonormal null-space basis of A (m, n), and the rank of A (:func:`orthogonal_split`).

    Returns:
        N: (n, n - rank) with A N ~ 0 and N^T N = I.
        rank: number of pivots of the rank-revealing QR above ``rtol`` times the largest.
    """
    _, N, rank = orthogonal_split(A, rtol)
    return N, rank


def rigid_rows(clm: ClosedLoopModel) -> np.ndarray:
    """(n_locked, nv) selection rows of the locked coordinates (stiffness = inf)."""
    idx = np.flatnonzero(np.isinf(clm.stiffness))
    E = np.zeros((idx.size, clm.model.nv))
    E[np.arange(idx.size), idx] = 1.0
    return E


def admissible_motions(clm: ClosedLoopModel, q: np.ndarray, *, update: bool = True):
    """Basis N (nv, d) of the tangent motions that keep every closure and locked joint.

    Returns:
        N: (nv, d) orthonormal basis, closure Jacobian and locked rows times N ~ 0.
        rank: rank of the stacked closure + locked rows (redundant rows removed).
    """
    A, locked = closure_jacobian(clm, q, update=update), rigid_rows(clm)
    return nullspace(np.vstack([A, locked]) if len(locked) else A)


def closed_loop_jacobian(
    clm: ClosedLoopModel, q: np.ndarray, frame: str, inputs: np.ndarray, axes: str = "world"
) -> np.ndarray:
    """(6, n_in) Jacobian of frame ``frame`` with respect to the coordinates ``inputs``.

    The other coordinates follow: the passive ones (stiffness 0) as the closures require,
    every other one held still. Rows: twist (v [m/s], w [rad/s]) at the frame origin, in
    ``axes``; columns: the tangent coordinates ``inputs`` (indices into v).

    Raises:
        SingularConfigurationError: the inputs do not determine the passive coordinates
            (the passive joints alone form a mobility) or violate the closures.
    """
    update_kinematics(clm, q)
    Jc = closure_jacobian(clm, q, update=False)
    Jf = frame_jacobian(clm, q, frame, axes, update=False)
    inputs = np.asarray(inputs, dtype=int)
    passive = np.flatnonzero(clm.stiffness == 0.0)
    passive = np.setdiff1d(passive, inputs)
    Jp, Ja = Jc[:, passive], Jc[:, inputs]
    Np, _ = nullspace(Jp)
    if Np.shape[1]:
        raise SingularConfigurationError(
            f"the passive joints form a {Np.shape[1]}-dof mobility at this configuration: "
            "the inputs do not determine the configuration"
        )
    X, *_ = np.linalg.lstsq(Jp, -Ja, rcond=None)
    gap = np.linalg.norm(Jp @ X + Ja) / max(1.0, np.linalg.norm(Ja))
    if gap > 1e-8:
        raise SingularConfigurationError(
            f"the inputs cannot move while the closures hold (relative gap {gap:.2e})"
        )
    return Jf[:, inputs] + Jf[:, passive] @ X
