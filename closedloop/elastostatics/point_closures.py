"""The point closures of a model, all at once: the world gap of their anchors, its Jacobian
and its curvature weighted by the closure forces (the rows of the point closures in
:func:`closedloop.elastostatics.tangent.closure_gap` and
:func:`~closedloop.elastostatics.tangent.closure_curvature`).

A point closure joins an anchor point fixed on the body of joint j1 (side 1) to one on the
body of joint j2 (side 2); its rows are the world gap c = p2 - p1 [m]. An anchor at p
(world) on joint j moves at J_p = V - [p]x W, with S = (V; W) (6, nv) the joint's spatial
Jacobian (WORLD): the columns S_a = (v_a; w_a) of Pinocchio's ``data.J`` on the joint's
support, zero elsewhere (what ``getJointJacobian(..., WORLD)`` returns). Along
``pin.integrate``, a coordinate b turns the axis of a coordinate a when it lies before it
on its chain (b != a, b of the same joint as a or of one of its ancestors):
dS_a/dq_b = S_b x S_a, the motion cross product (w_b x v_a + v_b x w_a; w_b x w_a), else
0 (Pinocchio's kinematic Hessian, ``computeJointKinematicHessians``, for joints whose
motion subspace is constant in their frame). With dp/dq_b = J_p[:, b], the curvature of
an anchor weighted by a force lambda (3,) [N], entry [a, b] = lambda . dJ_p[:, a]/dq_b, is

    (X - X^T + Y)[a, b] if b turns a, else 0;   minus (W^T [lambda]x J_p)[a, b],

with X = V^T [lambda]x W and Y = W^T [p x lambda]x W. Every anchor is handled in one pass:
positions and Jacobians as stacked arrays, each sum over the anchors one matrix product.

The anchors' kinematics at q are kept for the next call at the same q in the same thread
(:func:`anchor_kinematics`): the statics evaluate the gap and then the curvature at each
iterate, and their equations' residual and tangent read them once.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from closedloop.common.arrays import frozen
from closedloop.model.closed_loop import ClosedLoopModel


@dataclass(frozen=True)
class PointAnchors:
    """The anchors of a model's point closures (k closures, 2k anchors: the side-1 anchors
    in closure order, then the side-2 ones).

    Attributes:
        rows: (3k,) the rows of the point closures in the stacked closure residual.
        joints: (2k,) the joint of each anchor (0: the world).
        offsets: (2k, 3) each anchor in its joint's frame [m].
        support: (2k, nv) True on the coordinates that move the anchor's joint.
        turns: (nv, nv) True at [a, b] when coordinate b turns the axis of coordinate a
            (module docstring).
    """

    rows: np.ndarray
    joints: np.ndarray
    offsets: np.ndarray
    support: np.ndarray
    turns: np.ndarray


def point_anchors(clm: ClosedLoopModel) -> PointAnchors:
    """The anchors of the point closures of ``clm`` (once per model)."""

    def build():
        model, rows, row, sides = clm.model, [], 0, ([], [])
        for c in clm.closures:
            if c.kind == "3d":
                k = c.constraint
                rows.extend(range(row, row + 3))
                sides[0].append((k.joint1_id, k.joint1_placement.translation))
                sides[1].append((k.joint2_id, k.joint2_placement.translation))
            row += c.size
        anchors = sides[0] + sides[1]
        joints = np.array([j for j, _ in anchors], dtype=int)
        owner = np.zeros(model.nv, dtype=int)  # the joint of each coordinate
        for jm in model.joints[1:]:
            owner[jm.idx_v : jm.idx_v + jm.nv] = jm.id
        # [j, a]: coordinate a moves joint j (its joint is j or one of j's ancestors)
        coordinates = np.zeros((model.njoints, model.nv), dtype=bool)
        for j in range(1, model.njoints):
            coordinates[j] = np.isin(owner, list(model.supports[j][1:]))
        turns = coordinates[owner] & ~np.eye(model.nv, dtype=bool)
        return PointAnchors(
            rows=np.array(rows, dtype=int),
            joints=joints,
            offsets=np.array([t for _, t in anchors], dtype=float).reshape(-1, 3),
            support=coordinates[joints],
            turns=turns,
        )

    return clm.memo("point_anchors", build)


#: (3, 9) the cross product as a product: u (n, 3) @ _LEVI_CIVITA gives the rows of [u]x,
#: [u]x[i, j] = -epsilon[i, j, k] u_k.
_LEVI_CIVITA = np.array(
    [
        [0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0],
        [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    ]
)


def _skews(u: np.ndarray) -> np.ndarray:
    """(n, 3, 3) the matrices [u_i]x of the rows of u (n, 3): [u]x v = u x v."""
    return (u @ _LEVI_CIVITA).reshape(-1, 3, 3)


class _Last(threading.local):
    """This thread's last anchor kinematics: the workspace and anchors they were computed
    for (held, so that no other object takes their identity), the bits of q, the arrays."""

    data = anchors = bits = value = None


_last = _Last()


def anchor_kinematics(clm: ClosedLoopModel, q: np.ndarray):
    """(p, JW, Jp): the anchors' world positions (2k, 3) [m], their joints' spatial
    Jacobians (2k, 6, nv) and their point Jacobians (2k, 3, nv), world axes; read-only.

    Expects the joint Jacobians of q (nq,) in ``clm.data`` (this thread's workspace).
    Kept for the next call in this thread with the same workspace (so the same model) and
    a q of the same bits, which gets the same arrays without reading ``clm.data``.
    """
    data, anchors = clm.data, point_anchors(clm)
    bits = np.asarray(q, dtype=float).tobytes()
    last = _last
    if last.data is data and last.anchors is anchors and last.bits == bits:
        return last.value
    oMi = data.oMi  # one proxy for the anchors' joints
    H = np.array([oMi[j].homogeneous for j in anchors.joints.tolist()]).reshape(-1, 4, 4)
    p = (H[:, :3, :3] @ anchors.offsets[:, :, None])[:, :, 0] + H[:, :3, 3]
    JW = np.asarray(data.J)[None] * anchors.support[:, None, :]
    Jp = JW[:, :3] - _skews(p) @ JW[:, 3:]
    value = frozen(p), frozen(JW), frozen(Jp)
    last.data, last.anchors, last.bits, last.value = data, anchors, bits, value
    return value


def point_gap(clm: ClosedLoopModel, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(c, A): the world gaps p2 - p1 (3k,) [m] of the point closures, stacked in closure
    order, and their Jacobian (3k, nv) [m/rad or m/m]. Expects the joint Jacobians of q
    (nq,) in ``clm.data``."""
    p, _, Jp = anchor_kinematics(clm, q)
    k = p.shape[0] // 2
    return (p[k:] - p[:k]).reshape(-1), (Jp[k:] - Jp[:k]).reshape(-1, clm.model.nv)


def point_curvature(clm: ClosedLoopModel, q: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """(nv, nv) sum_r lam_r Hess c_r over the rows of the point closures (module
    docstring); entry [a, b] = d(A^T lam)_a / dq_b. Exact for joints whose motion subspace
    is constant in their frame (:func:`closedloop.common.derivatives.pinocchio_second_order_exact`).

    Args:
        clm: the model.
        q: (nq,) the configuration whose joint Jacobians are in ``clm.data``.
        lam: (3k,) the multipliers of the point closures' rows, world axes [N].
    """
    nv, anchors = clm.model.nv, point_anchors(clm)
    p, S, Jp = anchor_kinematics(clm, q)
    k = p.shape[0] // 2
    forces = np.concatenate([-lam.reshape(k, 3), lam.reshape(k, 3)])  # on side 1, side 2
    turn = _skews(forces)  # [lambda]x
    moment = _skews((turn @ p[:, :, None])[:, :, 0])  # [lambda x p]x = -[p x lambda]x
    V, W = S[:, :3].reshape(-1, nv), S[:, 3:]
    X = V.T @ (turn @ W).reshape(-1, nv)
    W = W.reshape(-1, nv)
    Y = W.T @ (moment @ S[:, 3:]).reshape(-1, nv)  # -W^T [p x lambda]x W
    return np.where(anchors.turns, X - X.T - Y, 0.0) - W.T @ (turn @ Jp).reshape(-1, nv)
