"""Cartesian compliance and stiffness of a closed-loop mechanism with joint springs.

Method (the Jacobian method K = J^-T K_q J^-1 generalised to loops). Let N (nv, d) span
the tangent motions dq that keep every closure and locked joint (``J_c N = 0``), K_q the
diagonal joint stiffness (0 for passive joints) and J (6, nv) the frame Jacobian. With
dq = N y, the potential energy of the springs is 1/2 y^T (N^T K_q N) y and a wrench w at
the frame does the work w^T J N y, so at equilibrium

    K_r y = N^T J^T w,   K_r = N^T K_q N   (d, d)
    dq = G w,            G = N K_r^+ N^T J^T   (nv, 6)
    C = J G = (J N) K_r^+ (J N)^T   (6, 6)

Passive joints and redundant closure rows need no special case: they only shape N.
A null direction z of K_r is a motion without any restoring spring. If it moves the
frame (J N z != 0) there is no equilibrium (:class:`MechanismError`); if not, it is an
internal mobility (e.g. a link spinning about its own axis) and is left out.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .arrays import check_wrench, readonly
from .exceptions import MechanismError, RigidDirectionsError
from .kinematics import (
    RANK_RTOL,
    admissible_motions,
    closure_residual,
    frame_jacobian,
    nullspace,
    orthogonal_split,
    update_kinematics,
)
from .model import ClosedLoopModel

#: Labels of the twist / wrench coordinates, in order.
TWIST_LABELS = ("dx", "dy", "dz", "rx", "ry", "rz")
UNITS = {
    "twist": "dx, dy, dz [m]; rx, ry, rz [rad] (small rotation vector)",
    "wrench": "fx, fy, fz [N]; nx, ny, nz [N m]",
    "C": "m/N, m/(N m) = rad/N, rad/(N m)",
    "K": "N/m, N/rad, N m/m, N m/rad",
}


@dataclass(frozen=True)
class ComplianceResult:
    """Compliance of a mechanism at one frame and configuration (arrays read-only).

    Attributes:
        C: (6, 6) compliance [SI], twist (dx, dy, dz, rx, ry, rz) per wrench
            (fx, fy, fz, nx, ny, nz), both at ``point``, in ``axes``.
        frame: name of the loaded frame.
        axes: ``"world"`` (world-aligned) or ``"local"`` (the frame's own axes).
        point: (3,) reference point [m], world frame: the frame origin.
        q: (nq,) configuration.
        rank: rank of C.
        rigid_directions: (6, 6 - rank) orthonormal basis of the twists that no wrench
            produces (empty when C is full rank).
        closure_residual: infinity norm of the loop-closure residual at q [m, rad].
        mobility: dimension d of the admissible motions (closures and locks kept).
        internal_mobilities: spring-free motions that do not move the frame.
        G: (nv, 6) map from wrench to joint deflection dq (tangent of q) [rad or m per N, N m].
    """

    C: np.ndarray
    frame: str
    axes: str
    point: np.ndarray
    q: np.ndarray
    rank: int
    rigid_directions: np.ndarray
    closure_residual: float
    mobility: int
    internal_mobilities: int
    G: np.ndarray = field(repr=False)

    @property
    def is_full_rank(self) -> bool:
        """True when C is invertible (the stiffness exists)."""
        return self.rank == 6

    @property
    def K(self) -> np.ndarray:
        """(6, 6) stiffness C^-1 [SI], same point and axes as C.

        Raises:
            RigidDirectionsError: C is rank deficient; the error lists the rigid directions.
        """
        if not self.is_full_rank:
            raise RigidDirectionsError(
                f"compliance at frame {self.frame!r} has rank {self.rank} < 6: the stiffness "
                f"is infinite along {describe_directions(self.rigid_directions)}",
                self.rigid_directions,
            )
        K = np.linalg.inv(self.C)
        return readonly(0.5 * (K + K.T))

    def deflection(self, wrench: np.ndarray) -> np.ndarray:
        """(6,) twist (dx, dy, dz [m], rx, ry, rz [rad]) of the frame under ``wrench`` (6,)."""
        return self.C @ check_wrench(wrench)

    def joint_deflection(self, wrench: np.ndarray) -> np.ndarray:
        """(nv,) joint deflection dq (tangent of q) [rad or m] under ``wrench`` (6,)."""
        return self.G @ check_wrench(wrench)

    def to_dict(self) -> dict:
        """JSON-ready summary: K (or None), C, frame, axes, point, rank, units."""
        return {
            "K": self.K.tolist() if self.is_full_rank else None,
            "C": self.C.tolist(),
            "frame": self.frame,
            "axes": self.axes,
            "point": self.point.tolist(),
            "order": list(TWIST_LABELS),
            "rank": self.rank,
            "rigid_directions": self.rigid_directions.T.tolist(),
            "closure_residual": self.closure_residual,
            "units": UNITS,
        }


def describe_directions(V: np.ndarray) -> str:
    """Readable list of twist directions, e.g. ``[+0.71 dx +0.71 rz]``."""
    parts = []
    for v in np.asarray(V).T:
        v = v * np.sign(v[np.argmax(np.abs(v))])
        terms = [f"{c:+.2f} {lab}" for c, lab in zip(v, TWIST_LABELS, strict=True) if abs(c) > 5e-3]
        parts.append("[" + " ".join(terms) + "]")
    return ", ".join(parts)


def compliance(
    clm: ClosedLoopModel, q: np.ndarray, frame: str, axes: str = "world"
) -> ComplianceResult:
    """Cartesian compliance of ``frame`` at configuration q (see the module docstring).

    Args:
        clm: model with closures and springs.
        q: (nq,) assembled configuration (see :func:`closedloop.assembly.assemble`).
        frame: name of the loaded frame; the reference point is its origin.
        axes: ``"world"`` (world-aligned axes, default) or ``"local"``.

    Raises:
        NameNotFoundError: unknown frame.
        MechanismError: a spring-free motion moves the frame (no static equilibrium).
    """
    q = clm.check_configuration(q)
    update_kinematics(clm, q)
    J = frame_jacobian(clm, q, frame, axes, update=False)
    point = clm.data.oMf[clm.frame_id(frame)].translation
    residual = closure_residual(clm, q, update=False)
    N, Vs, ls, n_internal = spring_subspace(clm, q, J, frame)
    JN = J @ N
    B = JN @ (Vs / np.sqrt(ls))  # C = B B^T
    NV = N @ (Vs / ls)
    G = NV @ (JN @ Vs).T
    C = B @ B.T
    rigid, rank = nullspace(B.T)  # twists outside the range of C = B B^T
    return ComplianceResult(
        C=readonly(0.5 * (C + C.T)),
        frame=frame,
        axes=axes,
        point=readonly(point),
        q=readonly(q),
        rank=rank,
        rigid_directions=readonly(rigid),
        closure_residual=float(np.max(np.abs(residual), initial=0.0)),
        mobility=N.shape[1],
        internal_mobilities=n_internal,
        G=readonly(G),
    )


def spring_subspace(
    clm: ClosedLoopModel, q: np.ndarray, J: np.ndarray, frame: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Admissible motions and the eigen-decomposition of their spring stiffness K_r.

    Expects the kinematics of q to be up to date (:func:`update_kinematics`).

    Args:
        clm: model with closures and springs.
        q: (nq,) configuration.
        J: (6, nv) Jacobian of the loaded frame (any reference axes).
        frame: name of the loaded frame (for messages).

    Returns:
        N: (nv, d) orthonormal basis of the admissible motions (closures and locks kept).
        V: (d, s) orthonormal eigenvectors of K_r = N^T K_q N with a restoring spring.
        lam: (s,) their eigenvalues (> 0) [N m/rad, N/m, mixed per the joint units].
        n_internal: number of spring-free motions that do not move the frame (left out).

    Raises:
        MechanismError: a spring-free motion moves the frame (no static equilibrium).
    """
    N, _ = admissible_motions(clm, q, update=False)
    k = np.where(np.isinf(clm.stiffness), 0.0, clm.stiffness)
    # Spring-free motions are found kinematically (no spring coordinate moves: null space
    # of the spring rows of N), not by a threshold on the eigenvalues of K_r, which would
    # drop a spring more than 1/RANK_RTOL times softer than the stiffest one.
    W, Z, _ = orthogonal_split(N[k > 0.0])
    Kr = W.T @ ((N.T * k) @ N) @ W
    lam, V = np.linalg.eigh(0.5 * (Kr + Kr.T))
    V = W @ V
    JN = J @ N
    moves = np.zeros(Z.shape[1], dtype=bool)
    if Z.shape[1]:  # spring-free motions must not move the frame
        moves = np.linalg.norm(JN @ Z, axis=0) > RANK_RTOL * max(np.linalg.norm(JN), 1e-300)
    if np.any(moves):
        dq = N @ Z[:, moves]
        raise MechanismError(
            f"{clm.name!r} is still a mechanism at frame {frame!r}: {int(moves.sum())} motion(s) "
            f"with no restoring spring move it, driven mostly by {_main_joints(clm, dq)}; "
            "add springs or lock joints"
        )
    return N, V, lam, Z.shape[1]


def _main_joints(clm: ClosedLoopModel, dq: np.ndarray) -> str:
    weight = np.linalg.norm(np.atleast_2d(dq.T).T, axis=1)
    names = []
    for j in range(1, clm.model.njoints):
        jm = clm.model.joints[j]
        names.append((float(np.max(weight[jm.idx_v : jm.idx_v + jm.nv])), clm.model.names[j]))
    top = sorted(names, reverse=True)[:3]
    return ", ".join(repr(n) for w, n in top if w > 1e-6)
