"""Admissible motions and the square-root factor of their spring stiffness.

At a configuration, N (nv, d) spans the tangent motions that keep every closure and
locked joint, and the springs' stiffness on them is K_r = N^T K_q N = V diag(sigma^2) V^T
on the motions with a restoring spring. Three ways to N, the result the same:

* ``"serial"``: no closure and no passive joint: N selects the spring coordinates;
* ``"partitioned"``: the passive joints follow the springs through the closures,
  dq_p = X dq_s with X = -J_p^+ J_s (one QR), when J_p is well conditioned;
* ``"null-space"``: the general path, a rank-revealing QR of the scaled closure and
  locked rows, then the SVD of the spring factor S = sqrt(K_q) N.

Everything is unit-free (lengths per the characteristic length L, prismatic coordinates
dq / L and their springs k L^2) and decided by the rank rule of
:mod:`closedloop.common.conditioning`; a motion with no restoring spring that moves the loaded
frame is a :class:`MechanismError`.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np

from closedloop.common import lapack
from closedloop.common.arrays import frozen, upper_triangular_inverses
from closedloop.common.conditioning import RANK_RTOL, rule_rank, split_factor, svd, twist_scaling
from closedloop.exceptions import InvalidInputError, MechanismError, SingularConfigurationError
from closedloop.kinematics.configuration import Configuration
from closedloop.kinematics.constraints import nullspace, rigid_rows
from closedloop.model.closed_loop import ClosedLoopModel


class SpringFactor(NamedTuple):
    """Admissible motions and the square-root factor of their spring stiffness.

    Attributes:
        N: (nv, d) basis of the admissible motions dq = N y (closures and locks kept),
            orthonormal in the scaled joint coordinates (prismatic ones divided by L).
        V: (d, s) orthonormal directions of y with a restoring spring.
        sigma: (s,) their singular values: K_r = N^T K_q N = V diag(sigma^2) V^T on them
            [sqrt(N m)].
        Z: (d, d - s) orthonormal spring-free directions of y (they do not move the frame:
            internal mobilities, left out of the compliance).
    """

    N: np.ndarray
    V: np.ndarray
    sigma: np.ndarray
    Z: np.ndarray

    @property
    def n_internal(self) -> int:
        """Number of spring-free motions (internal mobilities)."""
        return self.Z.shape[1]

    @property
    def NV(self) -> np.ndarray:
        """(nv, s) N V: the sprung admissible motions."""
        return self.N @ self.V

    @property
    def P(self) -> np.ndarray:
        """(nv, s) N V diag(1/sigma): dq = P P^T J^T w, C = (J P) (J P)^T."""
        return self.NV / self.sigma


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
    upper: np.ndarray  # (m, p + s) 1 on and above the diagonal, 0 below
    d: np.ndarray  # (6,) twist scaling D = diag(1/L, 1/L, 1/L, 1, 1, 1)
    dd: np.ndarray  # (6, 6) outer(d, d): K = D K_s D entrywise
    sigma: np.ndarray  # (s,) the spring factor's singular values on y = dq_s
    spread: float  # max(sigma) / min(sigma), 1 without springs
    W: np.ndarray | None  # (s, s) V diag(1 / sigma) with spring blocks, else None
    # (nv, s) the factor P = T W of the fast paths (T: dq = T y, y = dq_s / s_q) on the
    # sprung and locked rows (read-only): diag(s_q) W on the sprung ones, 0 elsewhere
    P0: np.ndarray
    passive_coef: np.ndarray | None  # (p, s) outer(s_p, 1 / sigma), diagonal springs only
    P_diagonal: np.ndarray | None  # (nv,) P0 = diag(s_q / sigma) when every coordinate has
    # a diagonal spring (a serial robot), else None
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
            row_scale * (sign * s_q[order]),
            np.triu(np.ones((row_scale.size, order.size))),
            d,
            np.outer(d, d),
            sigma,
            float(sigma.max() / sigma.min()) if sigma.size else 1.0,
            W,
            P0,
            passive_coef,
            frozen(P0.diagonal().copy()) if W is None and sprung.size == k.size else None,
            loops,
        )


def scaling(state: Configuration) -> _Scaling:
    """The scaling of a configuration's model at its length (computed once per model and L)."""
    return model_scaling(state.model, state.length)


def model_scaling(clm: ClosedLoopModel, L: float) -> _Scaling:
    """The scaling of a model at length L [m] (computed once per model and L)."""
    return clm.memo(("scaling", L), lambda: _Scaling.of(clm, L))


#: The partitioned path is taken when the passive part of the scaled closure Jacobian is
#: well conditioned (reciprocal condition estimate above this): then both paths give C
#: to rounding (1e-12 and better on every test mechanism). Below it the null-space path
#: decides, with the rank rule.
PARTITION_RCOND = 1e-6
#: Largest residual |J_s + J_p X|_F of the partitioned closure equations, relative to
#: max |J_s|, for the springs to move freely (else some spring coordinates are tied by
#: the loops).
PARTITION_RTOL = 1e-9


#: From this many passive coordinates on, the passive motion is solved loop by loop
#: (:func:`_loop_blocks`): the cost then grows with the number of loops, not its cube.
BLOCK_PASSIVE = 48


def _passive_motion(Jc: np.ndarray, sc: _Scaling) -> np.ndarray | None:
    """X (p, s) = -J_p^+ J_s from the closure Jacobian Jc (m, nv), m >= p, or None when
    J_p is ill conditioned or J_s + J_p X does not vanish (module constants).

    One QR of the scaled [-J_p, J_s] (LAPACK dgeqrf) = Q [[R11, R12], [0, R22]]:
    -J_p = Q1 R11, X = R11^-1 R12 (dtrtri: unlike dgels' triangular solve, it does not
    wake a multi-threaded BLAS on a small matrix) and |R22|_F = |J_s + J_p X|_F. With
    many passive coordinates, one such QR per independent block of loops.
    """
    p = sc.passive.size
    if sc.loop_blocks is not None:
        return _passive_motion_by_blocks(Jc, sc)
    A = np.multiply(Jc[:, sc.order], sc.scale_order, order="F")
    scale = PARTITION_RTOL * abs(A[:, p:]).max()
    qr, _, _, info = lapack.dgeqrf(A, overwrite_a=1)
    R = qr * sc.upper  # the triangle (Householder vectors below it)
    if info != 0 or lapack.dtrcon(R[:p, :p])[0] <= PARTITION_RCOND:
        return None
    residual = R[p:, p:]
    if np.vdot(residual, residual) > scale * scale:
        return None
    R_inv, info = lapack.dtrtri(R[:p, :p], overwrite_c=1)
    return R_inv @ R[:p, p:] if info == 0 else None


def _passive_motion_by_blocks(Jc: np.ndarray, sc: _Scaling) -> np.ndarray | None:
    """:func:`_passive_motion` on the blocks of :func:`_loop_blocks`, those of one shape
    at once, each gathered from the closure Jacobian Jc (m, nv) on its own rows and
    columns (scaled, the common ancestors' columns, rounding of a zero, set to 0). The
    QR of a block diagonal -J_p is block diagonal, and so are R and R^-1, whose 1-norms
    are the largest of the blocks' (the exact 1-norm condition, which dtrcon estimates);
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
        X = _passive_motion(state.closure_jacobian(), sc)
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


#: Largest spread of the scaled springs (stiffest / softest; k L^2 for prismatic joints)
#: that the general path and the statics accept. The general path's C keeps the soft
#: springs to rounding at any spread (:func:`spring_split`; 2e-14 of its largest unit-free
#: entry at worst on five test mechanisms up to 1e20, 6e-15 at 1e50 with this limit
#: lifted). What only the stiff springs carry is not resolved: the basis N mixes the
#: coordinates, so a soft motion's part on a stiff coordinate, about 1/sqrt(spread) of it,
#: is known to eps of the soft motion only, and the stiff springs' deflections (rows of G)
#: and the compliance of directions that only stiff springs resist (a Delta's platform
#: turning on stiff rods) err by up to eps spread of their own size (0.7 on CaHyMan's leg
#: motors at 1.1e17, 5 on a Delta at 1e20). The fast paths scale by the springs exactly,
#: at any spread.
SPREAD_RESOLVED = 1e20


def check_spread(clm: ClosedLoopModel, L: float, what: str = "the general path") -> None:
    """Refuse springs further apart than :data:`SPREAD_RESOLVED` (scaled at length L [m])
    with a SingularConfigurationError naming the spread and the softest and stiffest
    springs (with spring blocks: the stiffness of the softest and stiffest direction of
    the spring factor, on the joint it moves most); ``what`` is what refuses them."""
    sc = model_scaling(clm, L)
    if not sc.spread > math.sqrt(SPREAD_RESOLVED):  # sc.spread: of the square roots
        return
    directions = np.eye(sc.sigma.size) if sc.W is None else sc.W * sc.sigma  # (s, s)

    def spring(i: int) -> str:
        c = sc.sprung[np.argmax(np.abs(directions[:, i]))]
        unit = "N/m" if clm.linear_coordinates[c] else "N m/rad"
        k = float(sc.sigma[i] / sc.s_q[c]) ** 2 if sc.sigma[i] < 1e154 * sc.s_q[c] else math.inf
        return f"{k:.3g} {unit} on {clm.coordinate_joint(int(c))!r}"

    spread = sc.spread * sc.spread  # inf beyond the float range, not an OverflowError
    raise SingularConfigurationError(
        f"the springs of {clm.name!r} span {spread:.1e} (scaled: k L^2 for prismatic joints, "
        f"L = {L:.3g} m), from {spring(int(np.argmin(sc.sigma)))} to "
        f"{spring(int(np.argmax(sc.sigma)))}, beyond the {SPREAD_RESOLVED:.0e} that {what} "
        "resolves in double precision; lock the stiffest joints (a spring of inf) or bring "
        f"the springs within {SPREAD_RESOLVED:.0e} of each other"
    )


#: Values of the ``path`` argument of :func:`compliance`.
PATHS = ("auto", "null-space")


def check_path(path: str) -> None:
    """Refuse a ``path`` argument that is not one of :data:`PATHS` (InvalidInputError)."""
    if path not in PATHS:
        raise InvalidInputError(f"path {path!r}; expected one of {list(PATHS)}")


#: QR steps of the spring factor's triangle before its SVD in :func:`spring_split`, when
#: its diagonal spans more than GRADED_RATIO (springs far apart; below it the steps change
#: nothing measurable). C against mpmath, relative to its largest unit-free entry, over
#: 428 spring sets of five test mechanisms at scaled spreads of 1e4 to 1e20: 9e-8 at worst
#: without steps, 2e-8 with one, 5e-11 with three (a Delta whose rods are far stiffer than
#: its arms), 2e-14 with five.
GRADED_QR_STEPS = 5
GRADED_RATIO = 1e2


@functools.cache
def _upper(r: int) -> np.ndarray:
    """(r, r) read-only mask, 1 on and above the diagonal and 0 below (a triangle from
    LAPACK's QR in a product, faster than numpy.triu)."""
    return frozen(np.triu(np.ones((r, r))))


def spring_split(rows: np.ndarray, root: np.ndarray):
    """The admissible motions y split by the springs: those the springs see, with the SVD
    of their spring factor, and the spring-free ones.

    The motions a spring sees are decided on the kinematics alone: the rows of the sprung
    coordinates of an orthonormal, unit-free basis of the admissible motions, by the rank
    rule (the rest move no sprung coordinate, whatever the springs' values); on them the
    factor is S = root rows (K_r = S^T S), whose SVD gives sigma and V.

    Args:
        rows: (s, d) the sprung coordinates' rows of the basis (unit-free).
        root: (s,) the square roots of the springs, or (m, s) a square-root factor R of
            their stiffness (R^T R), in the units of ``rows``.

    Returns:
        V: (d, r) orthonormal directions with a restoring spring; sigma: (r,) their
        singular values [sqrt(N m)]; Z: (d, d - r) orthonormal spring-free directions.
    """
    n, d = rows.shape
    full = False
    if n >= d > 0:  # the rank alone tells whether every motion moves a sprung coordinate
        _, s, _, info = lapack.dgesdd(rows, compute_uv=0)
        full = info == 0 and rule_rank(s) == d
    if full:  # nothing to split off
        V_k, Z, seen = np.eye(d), np.zeros((d, 0)), rows
    else:
        _, V_k, Z, _ = split_factor(rows)
        seen = rows @ V_k
    S = root[:, None] * seen if root.ndim == 1 else root @ seen
    if not S.size:
        return V_k, np.zeros(0), Z
    # The rows of S are graded by the springs; the SVD of S itself resolves a soft spring
    # only to eps of the stiffest (eps sqrt(spread) relative). A QR with the rows in
    # decreasing norm and column pivoting, S P = Q R, is row-wise stable (each row's error
    # is eps of its own norm, so a soft spring keeps its digits beside a stiff one); without
    # the pivoting, a leading column that the stiff rows do not move reflects them into the
    # soft rows, whose digits then cancel (eps sqrt(spread) again). R is graded down its
    # rows but not along them, which the SVD of R does not resolve either; QRs of the
    # transposed triangle (R^T = Q_1 R_1, R_1^T = Q_2 R_2, ...: steps of the unshifted QR
    # iteration, each column-wise stable) grade it both ways and shrink the coupling of
    # stiff and soft, until the SVD of the last triangle resolves the soft singular values
    # (LAPACK's dgejsv preconditions so, then ends with a Jacobi SVD). The right factors
    # are those of the even steps: R = Q_2 R_3^T Q_3^T Q_1^T after three, and
    # R_3^T = U diag(sigma) W^T gives V = P Q_1 Q_3 W.
    r = S.shape[1]
    upper = _upper(r)
    qr, jpvt, _, _, info = lapack.dgeqp3(S[np.argsort(-np.einsum("ij,ij->i", S, S))])
    R, V = qr[:r] * upper, np.eye(r)
    steps = GRADED_QR_STEPS if abs(R[0, 0]) > GRADED_RATIO * abs(R[-1, -1]) else 0
    for step in range(steps):
        qr, tau, _, step_info = lapack.dgeqrf(R.T)
        info, R = info or step_info, qr * upper
        if step % 2 == 0:
            V = V @ lapack.dorgqr(qr, tau, overwrite_a=1)[0]
    if info != 0:
        raise np.linalg.LinAlgError(f"QR of the spring factor failed (LAPACK info {info})")
    _, sigma, Wt = svd(R.T if steps % 2 else R, False)
    V[jpvt - 1] = V @ Wt.T
    return V_k @ V, sigma, Z


def spring_factor(state: Configuration, J: np.ndarray, frame: str) -> SpringFactor:
    """Admissible motions and spring factor at a configuration (module docstring), on the
    general (null-space) path: N orthonormal in the scaled coordinates, what the rank rule
    of a preloaded compliance reads (the fast paths of :func:`closedloop.compliance` do
    not form N).

    Args:
        state: the configuration.
        J: (6, nv) Jacobian of the loaded frame (any reference axes) [m/rad, 1].
        frame: name of the loaded frame (for messages).

    Raises:
        MechanismError: a spring-free motion moves the frame (no static equilibrium):
            a joint without spring, or a singular configuration where an admissible motion
            moves the sprung coordinates less than ``RANK_RTOL`` (1e-7) times the motion
            that moves them most (scaled, unit-free; the springs' values do not enter).
        SingularConfigurationError: springs further apart than ``SPREAD_RESOLVED``.
    """
    clm, L, sc = state.model, state.length, scaling(state)
    check_spread(clm, L)
    Jc = state.closure_jacobian() * sc.row_scale
    A = np.vstack([Jc, sc.locked_rows]) if len(sc.locked_rows) else Jc
    N_s, _ = nullspace(A * sc.s_q)
    V, sigma, Z = spring_split(N_s[sc.sprung], sc.sqrt_k if sc.root is None else sc.root)
    N = N_s * sc.s_q[:, None]
    if Z.shape[1]:  # spring-free motions must not move the frame
        JN_s = (J * twist_scaling(L)[:, None]) @ N
        moves = np.linalg.norm(JN_s @ Z, axis=0) > RANK_RTOL * max(np.linalg.norm(JN_s), 1e-300)
        if np.any(moves):
            raise MechanismError(
                f"{clm.name!r} is still a mechanism at frame {frame!r}: {int(moves.sum())} "
                "motion(s) with no restoring spring (no spring moves, or they move 1e-7 "
                "times less than in another motion: a singular configuration) move it, "
                "driven mostly by "
                f"{_main_joints(clm, N @ Z[:, moves])}; add springs, lock joints or move away "
                "from the singularity"
            )
    return SpringFactor(N, V, sigma, Z)


def spring_subspace(
    clm: ClosedLoopModel, q: np.ndarray, J: np.ndarray, frame: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Admissible motions and the eigen-decomposition of their spring stiffness K_r.

    The form of :func:`spring_factor` for a model and q (first release).

    Returns:
        N: (nv, d) basis of the admissible motions (closures and locks kept).
        V: (d, s) orthonormal eigenvectors of K_r = N^T K_q N with a restoring spring.
        lam: (s,) their eigenvalues sigma^2 (> 0).
        n_internal: number of spring-free motions that do not move the frame (left out).

    Raises:
        MechanismError: a spring-free motion moves the frame (no static equilibrium).
    """
    f = spring_factor(Configuration(clm, q, check_limits=False), J, frame)
    return f.N, f.V, f.sigma**2, f.n_internal


def _main_joints(clm: ClosedLoopModel, dq: np.ndarray) -> str:
    weight = np.linalg.norm(np.atleast_2d(dq.T).T, axis=1)
    names = []
    for j in range(1, clm.model.njoints):
        jm = clm.model.joints[j]
        names.append((float(np.max(weight[jm.idx_v : jm.idx_v + jm.nv])), clm.model.names[j]))
    top = sorted(names, reverse=True)[:3]
    return ", ".join(repr(n) for w, n in top if w > 1e-6)
