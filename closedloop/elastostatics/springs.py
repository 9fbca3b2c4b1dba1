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
from closedloop.common.arrays import frozen
from closedloop.common.conditioning import RANK_RTOL, rule_rank, split_factor, svd, twist_scaling
from closedloop.elastostatics.partition import model_scaling, scaling
from closedloop.exceptions import InvalidInputError, MechanismError, SingularConfigurationError
from closedloop.kinematics.configuration import Configuration
from closedloop.kinematics.constraints import nullspace
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


#: Values of the ``path`` argument of :func:`~closedloop.compliance`.
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
