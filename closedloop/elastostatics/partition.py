"""The fast paths to the admissible motions: the unit-free scaling of a model and the
partition of its coordinates into sprung and passive ones.

In the scaled coordinates (lengths per the characteristic length L), the passive joints
follow the sprung ones through the closures, dq_p = X dq_s with X = -J_p^+ J_s (one QR, or
one per independent loop block), when J_p is well conditioned (:func:`partition`); without
closures and passive joints the spring coordinates themselves are the admissible motions.
:mod:`closedloop.elastostatics.springs` holds the general path and the spring factor.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from closedloop.common import lapack
from closedloop.common.arrays import frozen, upper_triangular_inverses
from closedloop.common.conditioning import RANK_RTOL, svd, twist_scaling
from closedloop.kinematics.configuration import Configuration
from closedloop.kinematics.constraints import rigid_rows
from closedloop.model.closed_loop import ClosedLoopModel


class _Scaling(NamedTuple):
    """Unit-free scaling of a model at length L, and the index sets and factors of the fast
    paths (computed once per model and L)."""

    s_q: np.ndarray  # (nv,) dq = s_q * scaled dq: L for linear coordinates, 1 for angles
    row_scale: np.ndarray  # (m, 1) closure rows in metres divided by L
    locked_rows: np.ndarray  # (n_locked, nv) selection rows of the locked coordinates
    sprung: np.ndarray  # (s,) indices of the coordinates with a finite spring
    sqrt_k: np.ndarray  # (s,) sqrt of their scaled stiffness k s_q^2 [sqrt(N m)]
    passive: np.ndarray  # (p,) indices of the coordinates without spring (k = 0)
    # With spring blocks (else None): the scaled square root R_s (s, s) of the sprung
    # stiffness, diag(s_q) K_ss diag(s_q) = R_s^T R_s; its SVD R_s = U diag(sigma) V^T is
    # the spring factor of the fast paths on y = dq_s: K_r = V diag(sigma^2) V^T (W, sigma)
    root: np.ndarray | None
    order: np.ndarray  # (p + s,) the passive coordinates, then the sprung ones
    s_p: np.ndarray  # (p, 1) s_q of the passive coordinates
    # (m, p + s) scale of Jc[:, order]: [-J_p, J_s] scaled (rows per L, columns per s_q)
    scale_order: np.ndarray
    # (p + s, nv) when every closure row has one scale (else None): (gather Jc^T)^T is
    # Jc[:, order] * scale_order to the last bit (one product a column, the rest zeros), in
    # one matrix product, in Fortran order
    gather: np.ndarray | None
    upper: np.ndarray  # (m, p + s) 1 on and above the diagonal, 0 below; Fortran order, as
    # the QR that it masks (a product of two arrays of one order is a plain loop)
    d: np.ndarray  # (6,) twist scaling D = diag(1/L, 1/L, 1/L, 1, 1, 1)
    dd: np.ndarray  # (6, 6) outer(d, d): K = D K_s D entrywise
    d_rows: np.ndarray  # (6, s) d in every column: D B = B * d_rows (no broadcasting)
    scales: tuple  # (d, dd), the scales argument of spectrum_from_factor
    sigma: np.ndarray  # (s,) the spring factor's singular values on y = dq_s
    spread: float  # max(sigma) / min(sigma), 1 without springs
    W: np.ndarray | None  # (s, s) V diag(1 / sigma) with spring blocks, else None
    # (nv, s) the factor P = T W of the fast paths (T: dq = T y, y = dq_s / s_q) on the
    # sprung and locked rows (read-only): diag(s_q) W on the sprung ones, 0 elsewhere
    P0: np.ndarray
    passive_coef: np.ndarray | None  # (p, s) outer(s_p, 1 / sigma), diagonal springs only
    P_diagonal: np.ndarray | None  # (nv,) P0 = diag(s_q / sigma) when every coordinate has
    # a diagonal spring (a serial robot), else None
    P_rows: np.ndarray | None  # (6, nv) P_diagonal in every row (J P = J * P_rows), or None
    P_max: float  # the largest |entry| of P_diagonal, or inf
    # the blocks of loops of _loop_blocks, with BLOCK_PASSIVE passive coordinates or more,
    # else None
    loop_blocks: tuple | None

    @classmethod
    def of(cls, clm: ClosedLoopModel, L: float) -> _Scaling:
        s_q = np.where(clm.linear_coordinates, L, 1.0)
        k = clm.stiffness
        sprung = np.flatnonzero((k > 0.0) & np.isfinite(k))
        passive = np.flatnonzero(k == 0.0)
        sqrt_k = np.sqrt(k[sprung]) * s_q[sprung]
        root = W = None
        sigma = sqrt_k
        if clm.spring_blocks:
            root = clm.spring_root[np.ix_(sprung, sprung)] * s_q[sprung]
            _, sigma, Vt = np.linalg.svd(root)
            W = Vt.T / sigma
        row_scale = np.where(clm.linear_rows, 1.0 / L, 1.0)[:, None]
        d = twist_scaling(L)
        order = np.concatenate([passive, sprung])
        sign = np.where(np.arange(order.size) < passive.size, -1.0, 1.0)
        loops = (
            _loop_blocks(clm, passive, sprung, s_q, row_scale)
            if passive.size >= BLOCK_PASSIVE
            else None
        )
        P0 = np.zeros((k.size, sprung.size))
        if W is None:
            P0[sprung, np.arange(sprung.size)] = s_q[sprung] / sigma
            passive_coef = frozen(np.outer(s_q[passive], 1.0 / sigma))
        else:
            P0[sprung] = s_q[sprung, None] * W
            passive_coef = None
        frozen(P0)
        scale_order = row_scale * (sign * s_q[order])
        gather = None
        if passive.size and row_scale.size and np.all(row_scale == row_scale[0]):
            gather = np.zeros((order.size, k.size))
            gather[np.arange(order.size), order] = scale_order[0]
        dd = frozen(np.outer(d, d))
        P_diagonal = frozen(P0.diagonal().copy()) if W is None and sprung.size == k.size else None
        return cls(
            s_q,
            row_scale,
            rigid_rows(clm),
            sprung,
            sqrt_k,
            passive,
            root,
            order,
            s_q[passive, None],
            scale_order,
            gather,
            np.asfortranarray(np.triu(np.ones((row_scale.size, order.size)))),
            frozen(d),
            dd,
            frozen(np.repeat(d[:, None], sprung.size, axis=1)),
            (d, dd),
            sigma,
            float(sigma.max() / sigma.min()) if sigma.size else 1.0,
            W,
            P0,
            passive_coef,
            P_diagonal,
            None if P_diagonal is None else frozen(np.tile(P_diagonal, (6, 1))),
            float(abs(P_diagonal).max(initial=0.0)) if P_diagonal is not None else math.inf,
            loops,
        )


def scaling(state: Configuration) -> _Scaling:
    """The scaling of a configuration's model at its length (computed once per model and L)."""
    return model_scaling(state.model, state.length)


def model_scaling(clm: ClosedLoopModel, L: float) -> _Scaling:
    """The scaling of a model at length L [m] (computed once per model and L)."""
    return clm.memo(("scaling", L), lambda: _Scaling.of(clm, L))


#: The partitioned path is taken when the passive part of the scaled closure Jacobian is
#: well conditioned (reciprocal 1-norm condition number above this, of its triangle R11
#: and the inverse of it that X needs, as the batch's): then both paths give C
#: to rounding (1e-12 and better on every test mechanism). Below it the null-space path
#: decides, with the rank rule.
PARTITION_RCOND = 1e-6
#: Largest residual ``|J_s + J_p X|_F`` of the partitioned closure equations, relative to
#: max ``|J_s|``, for the springs to move freely (else some spring coordinates are tied by
#: the loops).
PARTITION_RTOL = 1e-9


#: From this many passive coordinates on, the passive motion is solved loop by loop
#: (on the independent blocks of the closure Jacobian: loops that share no passive
#: coordinate are solved apart): the cost then grows with the number of loops, not its cube.
BLOCK_PASSIVE = 48


def passive_motion(Jc: np.ndarray, sc: _Scaling) -> np.ndarray | None:
    """X (p, s) = -J_p^+ J_s from the closure Jacobian Jc (m, nv), m >= p > 0 and s > 0
    (:func:`partition` calls it so: LAPACK called without the size checks), or None when
    J_p is ill conditioned or J_s + J_p X does not vanish (module constants).

    One QR of the scaled [-J_p, J_s] (LAPACK dgeqrf) = Q [[R11, R12], [0, R22]]:
    -J_p = Q1 R11, X = R11^-1 R12 (dtrtri: unlike dgels' triangular solve, it does not
    wake a multi-threaded BLAS on a small matrix), cond_1(R11) = ``|R11|_1`` ``|R11^-1|_1`` (dlantr)
    and ``|R22|_F`` = ``|J_s + J_p X|_F``. With many passive coordinates, one such QR per
    independent block of loops.
    """
    p = sc.passive.size
    if sc.loop_blocks is not None:
        return _passive_motion_by_blocks(Jc, sc)
    if sc.gather is not None:
        A = sc.gather.dot(Jc.T).T
    else:
        A = np.multiply(Jc[:, sc.order], sc.scale_order, order="F")
    scale = PARTITION_RTOL * np.maximum.reduce(abs(A[:, p:]), None)  # max |J_s|, scaled
    qr, _, _, info = lapack.unchecked.dgeqrf(A, overwrite_a=1)  # (sizes: partition's)
    R = qr * sc.upper  # the triangle (Householder vectors below it)
    residual = R[p:, p:]
    if info != 0 or np.vdot(residual, residual) > scale * scale:
        return None
    R11 = R[:p, :p]
    R_inv, info = lapack.unchecked.dtrtri(R11)  # a zero pivot: info > 0; near one, large
    norm_1 = lapack.unchecked.dlantr
    cond = norm_1(b"1", R11) * norm_1(b"1", R_inv) if info == 0 else math.inf
    if not cond * PARTITION_RCOND < 1.0:  # (an inverse with inf or NaN fails it too)
        return None
    return R_inv @ R[:p, p:]


def _passive_motion_by_blocks(Jc: np.ndarray, sc: _Scaling) -> np.ndarray | None:
    """:func:`passive_motion` on the blocks of :func:`_loop_blocks`, those of one shape
    at once, each gathered from the closure Jacobian Jc (m, nv) on its own rows and
    columns (scaled, the common ancestors' columns, rounding of a zero, set to 0). The
    QR of a block diagonal -J_p is block diagonal, and so are R and R^-1, whose 1-norms
    are the largest of the blocks' (the 1-norm condition of :func:`passive_motion`);
    the residual J_s + J_p X is checked on the blocks' spring columns, the others being
    zero."""
    X = np.zeros((sc.passive.size, sc.sprung.size))
    norm_R = norm_R_inv = top = residual2 = 0.0
    for rows, cols, springs, jc_cols, weight in sc.loop_blocks:
        k = cols.shape[1]
        block = Jc[rows[:, :, None], jc_cols] * weight  # (n, m_k, p_k + s_k), [-J_p, J_s]
        top = max(top, abs(block[:, :, k:]).max(initial=0.0))
        if k > rows.shape[1]:
            return None
        if k:
            R = np.linalg.qr(block, mode="r")  # (n, m_k, p_k + s_k), upper triangular
            with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
                R_inv = upper_triangular_inverses(R[:, :k, :k])
            if not np.isfinite(R_inv).all():  # a zero pivot: singular
                return None
            norm_R = max(norm_R, abs(R[:, :k, :k]).sum(axis=1).max())
            norm_R_inv = max(norm_R_inv, abs(R_inv).sum(axis=1).max())
            X[cols[:, :, None], springs[:, None, :]] = R_inv @ R[:, :k, k:]
            block = R[:, k:, k:]  # J_s + J_p X, rotated
        residual2 += np.vdot(block, block)
    scale = PARTITION_RTOL * top
    if not norm_R * norm_R_inv * PARTITION_RCOND < 1.0 or residual2 > scale * scale:
        return None
    return X


def _loop_blocks(clm: ClosedLoopModel, passive: np.ndarray, sprung: np.ndarray, s_q, row_scale):
    """Independent blocks of loops of the passive part J_p (m, p) of the closure Jacobian.

    A closure's residual, the placement of one anchor seen from the other, does not change
    when a common ancestor of its two joints moves (both anchors move together): its
    Jacobian vanishes on those columns (Pinocchio returns rounding there). On the other
    columns (the joints between the anchors) rows and passive columns that share no entry
    form separate blocks: the connected components of that pattern. A block's spring
    columns are those between the anchors of one of its rows.

    Returns:
        per shape (m_k, p_k, s_k) of block, for its n blocks: rows (n, m_k), passive
        columns (n, p_k) and spring columns (n, s_k) (indices into the passive and the
        sprung coordinates), the columns of the block [-J_p, J_s] in Jc (n, 1, p_k + s_k)
        and its weight (n, m_k, p_k + s_k): the scaling (sign,
        rows per L, columns per s_q) times 1 between the anchors and 0 on the common
        ancestors (a block may have rows and no passive column).
    """
    import scipy.sparse
    import scipy.sparse.csgraph

    model = clm.model
    between = []
    for c in clm.closures:
        a, b = (set(model.supports[j]) for j in (c.constraint.joint1_id, c.constraint.joint2_id))
        row = np.zeros(model.nv)
        for j in (a ^ b) - {0}:
            row[model.joints[j].idx_v : model.joints[j].idx_v + model.joints[j].nv] = 1.0
        between += [row] * c.size
    between = np.array(between).reshape(-1, model.nv)
    mask = between[:, passive]
    m, p = mask.shape
    rows, cols = np.nonzero(mask)
    graph = scipy.sparse.coo_matrix((np.ones(rows.size), (rows, cols + m)), shape=(m + p,) * 2)
    n, labels = scipy.sparse.csgraph.connected_components(graph, directed=False)
    order = np.argsort(labels, kind="stable")
    shapes: dict[tuple[int, int, int], list] = {}
    for members in np.split(order, np.cumsum(np.bincount(labels, minlength=n))[:-1]):
        r, k = members[members < m], members[members >= m] - m
        springs = np.flatnonzero(between[np.ix_(r, sprung)].any(axis=0))
        shapes.setdefault((r.size, k.size, springs.size), []).append((r, k, springs))
    blocks = []
    for (m_k, p_k, s_k), members in shapes.items():
        r, k, sp = (np.array([b[i] for b in members], dtype=int).reshape(len(members), size)
                    for i, size in enumerate((m_k, p_k, s_k)))  # fmt: skip
        jc_cols = np.hstack([passive[k], sprung[sp]])[:, None, :]  # (n, 1, p_k + s_k)
        sign = np.where(np.arange(p_k + s_k) < p_k, -1.0, 1.0)
        weight = row_scale[r] * (sign * s_q[jc_cols]) * between[r[:, :, None], jc_cols]
        blocks.append((r, k, sp, jc_cols, weight))
    return tuple(blocks)


def partition(state: Configuration, sc: _Scaling) -> tuple[str, np.ndarray | None] | None:
    """The fast path at a configuration: ``("serial", None)``, ``("partitioned", X)`` or
    None (the null-space path then decides).

    With the closure rows J_c dq = J_s dq_s + J_p dq_p = 0 (scaled, locked coordinates
    still), a passive part J_p of full column rank fixes dq_p = X dq_s, X = -J_p^+ J_s
    (p, s), for every spring motion dq_s when J_s + J_p X = 0; the admissible motions are
    then N = [I; X] in the scaled spring coordinates, where K_r = diag(k s_q^2) is already
    diagonal (with spring blocks: K_r = R_s^T R_s, whose SVD is computed once per model).
    Without closures nor passive joints N selects the spring coordinates (serial).
    """
    p, m = sc.passive.size, state.residual.size
    X = None
    if not sc.sprung.size:
        return None
    if p:
        if m < p:
            return None
        X = passive_motion(state.closure_jacobian(), sc)
        if X is None:
            return None
    elif m:
        return None  # loops without passive joints tie the springs together
    return ("partitioned", X) if m else ("serial", None)


def kinematic_factor(
    J: np.ndarray, sc: _Scaling, X: np.ndarray, JT: np.ndarray, cond_T: float
) -> np.ndarray:
    """(6, s) the factor whose singular values the rank rule reads on the partitioned path:
    the scaled frame Jacobian on an orthonormal basis of the admissible motions, as the
    null-space path's D J N V.

    On T = [I; X] = Q R (thin QR) that is D J diag(s_q) Q, whose singular values are
    those of ``JT`` = D J diag(s_q) T V (V orthogonal) to within cond(T): ``JT`` is
    returned when no singular value of it lies within that factor of the rule's
    threshold (the same rank; a planar mechanism's rigid directions lie far below it),
    else the QR is computed (near the threshold only).

    Args:
        J: (6, nv) frame Jacobian [m/rad, 1]; X: (p, s) passive motion per scaled spring
            motion (:func:`partition`); JT: (6, s) the factor on T; cond_T: an upper
            bound of cond(T), >= 1.
    """
    s_k = svd(JT, False)[1]
    if not s_k.size or s_k[0] == 0.0:  # nothing moves the frame: rank 0 on every basis
        return JT
    ratio = s_k / (RANK_RTOL * s_k[0])
    if np.all((ratio > cond_T) | (ratio < 1.0 / cond_T)):
        return JT
    T = np.zeros((sc.s_q.size, sc.sprung.size))
    T[sc.sprung, np.arange(sc.sprung.size)] = 1.0
    T[sc.passive] = X
    Q = np.linalg.qr(T)[0]
    return ((J * sc.s_q) @ Q) * sc.d[:, None]
