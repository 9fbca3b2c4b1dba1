"""The one rank rule of the project: unit-free, decided on square-root factors.

A compliance C (6, 6) [SI] mixes m/N with rad/(N m); its eigenvalues, rank and condition
number in SI change with the length unit (m vs mm) and mean little. Every decision is
therefore taken on the **scaled** matrices, with a characteristic length L [m] of the
mechanism (:func:`characteristic_length`): twists (d / L, r) and wrenches (f L, n), so that

    C_s = D C D,   K_s = D^-1 K D^-1,   D = diag(1/L, 1/L, 1/L, 1, 1, 1),

are uniform in rad/(N m) and N m/rad. Multiplying every length by 1000 multiplies L by
1000 too and leaves C_s, hence every decision, unchanged.

Decisions are taken on a square-root factor B_s (C_s = B_s B_s^T, from the springs, see
:mod:`closedloop.elastostatics.compliance`), never on C_s itself: its singular values beta carry the
square roots of the eigenvalues of C_s, so an SVD resolves a 1e-16 eigenvalue ratio that
an eigen-decomposition of C_s (absolute error eps ``|C_s|``) would turn into noise or a
negative number. The same rule decides which motions have no restoring spring, on the
kinematics alone: the rows of the sprung coordinates of the orthonormal (scaled) basis N
of the admissible motions. A motion they see less than RANK_RTOL times the one they see
most is spring-free (a singular configuration), whatever the values of the springs: a
spring 1e20 times softer than the others is a spring, and its direction of C is known to
about the rounding of each spring, as the factor sqrt(K_q) N is a row scaling of N.

* **rank**: number of beta_i > :data:`RANK_RTOL` beta_max, i.e. eigenvalues of C_s above
  RANK_RTOL^2 = 1e-14 times the largest. Below that no double-precision computation of
  the kinematics tells a very stiff direction from a rigid one.
* **condition number**: cond(K_s) = (beta_max / beta_min)^2 over the rank, always
  finite; above :data:`ILL_CONDITIONED` the result is flagged ill-conditioned (close to a
  singular configuration: the stiffest direction of K is known to about
  eps sqrt(cond) relative, the softest one to eps).
* **K** = D K_s D with K_s = U diag(beta^-2) U^T from the SVD of B_s: positive definite
  by construction, never inv(C).

When only C is known (a closed-form backend, a user's matrix) the factor comes from the
eigen-decomposition of C_s (:func:`spectrum_from_compliance`); it resolves eigenvalue
ratios down to about 1e-16, a hundred times below the threshold.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from closedloop.common import lapack
from closedloop.common.arrays import frozen, readonly
from closedloop.exceptions import InvalidInputError

#: Relative threshold on the singular values of a scaled square-root factor (C_s = B B^T)
#: below which a direction counts as rigid: 1e-14 on the eigenvalues of C_s; and on those
#: of the sprung rows of the admissible motions, below which a motion is spring-free.
RANK_RTOL = 1e-7
#: Condition number of the scaled stiffness K_s above which a result is flagged
#: ill-conditioned (8 decades between the stiffest and the softest scaled direction).
ILL_CONDITIONED = 1e8
#: Tolerance on the scaled (dimensionless) compliance for symmetry and semi-definiteness.
SCALED_TOL = 1e-8
#: Bound of the entries of a computed matrix (C, G, K) below which it is finite without a
#: look at each entry, far enough below the largest float (1.8e308) for any rounding.
FINITE_BOUND = 1e300


#: Rows of the pairwise distances :func:`characteristic_length` forms at once (memory
#: rows x n x 3 doubles: 40 MB for n = 10^4 points).
DIAMETER_ROWS = 128


def characteristic_length(points: np.ndarray) -> float:
    """Size [m] of a mechanism: diameter of its points (n, 3) [m], the largest distance
    between two of them (unchanged when the points move rigidly, unlike the diagonal of a
    bounding box, which turns with the axes).

    Returns 1.0 when the points coincide (a mechanism of one point has no size) or when
    the diameter is not a finite float; this is the only case where the length unit can
    then matter.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    if len(p) < 2 or not np.all(np.isfinite(p)):
        return 1.0
    p = p - p[0]  # relative to a point of the set: translations far away cost no digits
    scale = float(np.max(np.abs(p)))
    if scale == 0.0:
        return 1.0
    p = p / scale  # squares of the scaled coordinates neither overflow nor underflow
    square = 0.0
    for start in range(0, len(p), DIAMETER_ROWS):  # (rows, n) distances at a time
        block = p[start : start + DIAMETER_ROWS]
        d2 = np.sum((block[:, None, :] - p[None, :, :]) ** 2, axis=2)
        square = max(square, float(d2.max()))
    size = math.sqrt(square) * scale
    return size if 0.0 < size < math.inf else 1.0


#: Smallest characteristic length [m]: the twist scaling 1 / L must be a finite float.
MIN_LENGTH = 1.0 / np.finfo(float).max


def check_length(length) -> float:
    """Validated characteristic length [m] (finite, >= :data:`MIN_LENGTH` = 5.6e-309)."""
    if type(length) is float and MIN_LENGTH <= length < math.inf:  # the common case
        return length
    if isinstance(length, bool) or not isinstance(length, int | float | np.integer | np.floating):
        raise InvalidInputError(
            f"characteristic length must be a real number [m], got {length!r} "
            f"({type(length).__name__})"
        )
    try:
        value = float(length)
    except OverflowError:  # an int beyond the float range
        value = math.inf
    if not (math.isfinite(value) and value > 0):
        raise InvalidInputError(f"characteristic length must be finite and > 0 [m], got {length}")
    if value < MIN_LENGTH:  # 1 / L would be inf
        raise InvalidInputError(
            f"characteristic length {length} m is below {MIN_LENGTH:.3g} m, where the twist "
            "scaling 1 / L leaves the float range; give a larger length"
        )
    return value


def twist_scaling(length: float) -> np.ndarray:
    """(6,) diagonal of D = diag(1/L, 1/L, 1/L, 1, 1, 1): scaled twist = D twist."""
    s = 1.0 / length
    return np.array((s, s, s, 1.0, 1.0, 1.0))


def scaled_asymmetry(C: np.ndarray, lengths) -> np.ndarray | float:
    """max ``|C_s - C_s^T|`` / max ``|C_s|`` of compliances C (..., 6, 6) [SI] scaled at the
    lengths L (...,) [m] (C_s = D C D, :func:`twist_scaling`), 0 for a zero C: the
    asymmetry that :data:`SCALED_TOL` bounds, unit-free, and blind to entries that vanish
    but for rounding (an entry-by-entry test takes them for an asymmetry)."""
    d = twist_scalings(np.atleast_1d(lengths)).reshape(*np.shape(lengths), 6)
    with np.errstate(over="ignore", invalid="ignore"):
        C_s = C * d[..., :, None] * d[..., None, :]
        top = np.abs(C_s).max(axis=(-2, -1))
        skew = np.abs(C_s - np.swapaxes(C_s, -1, -2)).max(axis=(-2, -1))
        out = np.where(top > 0.0, skew / np.where(top > 0.0, top, 1.0), 0.0)
    return float(out) if out.ndim == 0 else out


def twist_scalings(lengths: np.ndarray) -> np.ndarray:
    """(n, 6) diagonals of D (:func:`twist_scaling`) for the lengths L (n,) [m]."""
    return np.where(np.arange(6) < 3, 1.0 / np.asarray(lengths, dtype=float)[:, None], 1.0)


#: Size (the smaller side) up to which :func:`svd` calls ``dgesvd`` first: LAPACK's
#: divide and conquer ``dgesdd`` solves such a bidiagonal problem by the same QR iteration
#: (its SMLSIZ), after more set-up (10 % more time on a 6 x 6 matrix).
SMALL_SVD = 25
_FLOAT64 = np.dtype(np.float64)


def svd(A: np.ndarray, full_matrices: bool = True):
    """SVD A = U diag(s) Vt of a small matrix (m, n), straight from LAPACK.

    ``dgesvd`` up to :data:`SMALL_SVD`, else ``dgesdd`` (each a fraction of
    ``numpy.linalg.svd``'s call cost on 6x6 matrices), with the other as the fall-back when
    it does not converge.

    Raises:
        numpy.linalg.LinAlgError: neither converges (non-finite input), or A is empty.
    """
    if type(A) is not np.ndarray or A.dtype is not _FLOAT64:
        A = np.asarray(A, dtype=float)
    m, n = A.shape
    if m == 0 or n == 0:  # which LAPACK refuses (closedloop.common.lapack)
        raise np.linalg.LinAlgError(f"svd called with an empty array of shape {A.shape}")
    first, then = _SMALL_FIRST if m <= SMALL_SVD or n <= SMALL_SVD else _LARGE_FIRST
    U, s, Vt, info = first(A, 1, full_matrices)  # compute_uv, full_matrices
    if info > 0:
        U, s, Vt, info = then(A, 1, full_matrices)
    if info != 0:
        raise np.linalg.LinAlgError(f"SVD did not converge (LAPACK info {info})")
    return U, s, Vt


#: The SVD routines of :func:`svd`, in the order it tries them: LAPACK's own, the arrays'
#: sizes checked there (:data:`closedloop.common.lapack.unchecked`).
_SMALL_FIRST = (lapack.unchecked.dgesvd, lapack.unchecked.dgesdd)
_LARGE_FIRST = _SMALL_FIRST[::-1]


@dataclass(frozen=True)
class Spectrum:
    """Rank, rigid directions, conditioning and stiffness of one compliance (module rule).

    Attributes:
        rank: rank of C (0..6).
        rigid_directions: (6, 6 - rank) orthonormal basis of the twists that no wrench
            produces (SI twist coordinates dx, dy, dz, rx, ry, rz), null space of C.
        condition_number: cond(K_s) of the scaled matrix over its rank (1.0 for rank 0),
            dimensionless, finite.
        length: characteristic length L [m] of the scaling.
        K: (6, 6) stiffness [SI] when rank is 6, else None.
    """

    rank: int
    rigid_directions: np.ndarray
    condition_number: float
    length: float
    K: np.ndarray | None

    @property
    def ill_conditioned(self) -> bool:
        """True when cond(K_s) exceeds :data:`ILL_CONDITIONED`."""
        return self.condition_number > ILL_CONDITIONED


def split_factor(S: np.ndarray, rtol: float = RANK_RTOL):
    """SVD split of a factor S (m, n): kept singular values and vectors, and the rest.

    Returns:
        sigma: (r,) singular values above ``rtol`` times the largest, descending.
        V: (n, r) right singular vectors of ``sigma``; Z: (n, n - r) orthonormal basis of
        the remaining directions (S Z ~ 0 on the scale of the rule).
        U: (m, m) left singular vectors (all of them).
    """
    m, n = S.shape
    if m == 0 or n == 0:
        return np.zeros(0), np.zeros((n, 0)), np.eye(n), np.eye(m)
    U, s, Vt = svd(S)
    r = rule_rank(s, rtol)
    return s[:r], Vt[:r].T, Vt[r:].T, U


def rule_rank(s: np.ndarray, rtol: float = RANK_RTOL) -> int:
    """Number of singular values s (descending) above ``rtol`` times the largest."""
    return int(np.count_nonzero(s > rtol * s[0])) if s.size and s[0] > 0.0 else 0


_NO_DIRECTIONS = readonly(np.zeros((6, 0)))


def _rigid_directions(U: np.ndarray, rank: int, d: np.ndarray) -> np.ndarray:
    """(6, 6 - rank) orthonormal null space of C from the left singular vectors U (6, 6)
    of a scaled factor: null(C) = D null(C_s), signed and ordered."""
    if rank == 6:
        return _NO_DIRECTIONS
    rigid = U[:, rank:] * d[:, None]
    return readonly(_signed(np.linalg.qr(rigid)[0] if rigid.shape[1] else rigid))


def _signed(basis: np.ndarray) -> np.ndarray:
    """Columns with their largest-magnitude entry positive, ordered by the coordinate of
    that entry (stable output)."""
    if not basis.shape[1]:
        return basis
    top = np.argmax(np.abs(basis), axis=0)
    signs = np.sign(basis[top, np.arange(basis.shape[1])])
    return (basis * signs + 0.0)[:, np.argsort(top, kind="stable")]


def spectrum_from_factor(
    B_s: np.ndarray,
    length: float,
    range_factor: np.ndarray | Callable[[], np.ndarray] | None = None,
    spread: float = 1.0,
    scales: tuple[np.ndarray, np.ndarray] | None = None,
) -> Spectrum:
    """Spectrum of C = D^-1 B_s B_s^T D^-1 from its scaled square-root factor B_s (6, r).

    Args:
        B_s: (6, r) scaled factor [rad/sqrt(N m)]: C_s = B_s B_s^T.
        length: characteristic length L [m] of the scaling D.
        range_factor: (6, r) matrix A with B_s = A W, W (r, r) invertible, whose singular
            values decide the rank and the rigid directions (default: B_s itself). The
            compliance passes the kinematic part J N V of B_s = J N V diag(1/sigma), so
            that one enormous compliance (a near-singular pose) is not mistaken for
            rigidity of the other directions; the condition number and K come from B_s.
            A function returning A is called only when the rank is not decided without it.
        spread: cond(W). The singular values of A and B_s differ by at most this factor,
            so A is full rank without being looked at when beta_6 > RANK_RTOL spread
            beta_1.
        scales: (d (6,), outer(d, d) (6, 6)) of :func:`twist_scaling` at ``length``, when
            the caller has them.
    """
    d, dd = scales if scales is not None else (twist_scaling(length), None)
    if not (isinstance(B_s, np.ndarray) and B_s.ndim == 2):
        B_s = np.asarray(B_s, dtype=float).reshape(6, -1)
    rank, rigid, cond, U, beta, _, bottom = factor_rank(B_s, range_factor, spread, d)
    K = None
    if rank == 6:
        entry = max(1.0, 1.0 / length) / bottom  # |K_ij| <= entry^2
        if entry * entry < FINITE_BOUND:
            K = stiffness_from_factor(U, beta, d, dd)
        else:
            with np.errstate(over="ignore", invalid="ignore"):  # an overflow: the caller's error
                K = stiffness_from_factor(U, beta, d, dd)
    return _spectrum(rank, rigid, cond, float(length), K)


def factor_rank(
    B_s: np.ndarray,
    range_factor: np.ndarray | Callable[[], np.ndarray] | None,
    spread: float,
    d: np.ndarray,
) -> tuple:
    """The rule of :func:`spectrum_from_factor` on B_s (6, r) without K (``d``: the twist
    scaling at the length, :func:`twist_scaling`).

    Returns:
        rank, rigid directions (6, 6 - rank) read-only, cond(K_s), the left singular
        vectors U (6, 6) and the singular values beta (descending) of B_s, the largest and
        the smallest kept of them (0.0 and 1.0 without any): K = D U diag(beta^-2) U^T D
        when the rank is 6 (:func:`stiffness_from_factor`).
    """
    # the left singular vectors U (6, 6) are all needed (rigid directions): the thin SVD
    # has them when r >= 6
    U, beta, _ = svd(B_s, B_s.shape[1] < 6) if B_s.size else (np.eye(6), np.zeros(0), None)
    b = beta.tolist()  # Python floats: the tests below on a few numbers
    if len(b) >= 6 and b[5] > RANK_RTOL * spread * b[0]:
        rank, basis = 6, U  # full rank, and so is the range factor (spread >= 1)
    else:
        rank, basis = rule_rank(beta), U
        if range_factor is not None:
            A = range_factor() if callable(range_factor) else range_factor
            if A.size:
                basis, s_k, _ = svd(A, A.shape[1] < 6)
                rank = rule_rank(s_k)
            else:  # no compliant coordinate at all: every direction is rigid
                basis, rank = np.eye(6), 0
    top, bottom = (b[0], b[rank - 1]) if rank else (0.0, 1.0)
    ratio = top / bottom
    # (a float's ** 2 raises OverflowError where the product is inf)
    cond = ratio * ratio if rank else 1.0
    return rank, _rigid_directions(basis, rank, d), cond, U, beta, top, bottom


def stiffness_from_factor(U: np.ndarray, beta: np.ndarray, d: np.ndarray, dd) -> np.ndarray:
    """(6, 6) read-only K = D K_s D [SI], K_s = U diag(beta^-2) U^T, from the SVD of a scaled
    factor of full rank (:func:`factor_rank`; ``dd``: outer(d, d) or None)."""
    Ub = U / beta
    K = Ub.dot(Ub.T)
    K *= np.outer(d, d) if dd is None else dd
    K.setflags(False)  # write=False (positional: half the cost)
    return K


def _spectrum(rank: int, rigid: np.ndarray, cond: float, length: float, K) -> Spectrum:
    """A :class:`Spectrum` of checked fields, set without the frozen dataclass's
    ``__init__`` (a field at a time through ``object.__setattr__``: a tenth of a query of
    a serial robot)."""
    spectrum = object.__new__(Spectrum)
    spectrum.__dict__.update(
        {"rank": rank, "rigid_directions": rigid, "condition_number": cond, "length": length,
         "K": K}
    )  # fmt: skip
    return spectrum


def spectrum_of_matrix(C: np.ndarray, length: float, range_factor: np.ndarray) -> Spectrum:
    """Spectrum of a compliance C (6, 6) [SI] without a symmetric square-root factor.

    For a C that is not symmetric (a preload moment) or not definite (an unstable
    preloaded equilibrium): rank and rigid directions from ``range_factor`` (as in
    :func:`spectrum_from_factor`), K = C^-1 by an LU solve of the scaled matrix, and the
    2-norm condition number of the scaled K.
    """
    d = twist_scaling(length)
    basis, s_k, _ = svd(range_factor)
    rank = rule_rank(s_k)
    Cs = C * np.outer(d, d)
    s_C = svd(Cs)[1]
    cond = float(s_C[0] / s_C[rank - 1]) if rank else 1.0
    K = frozen(np.linalg.solve(Cs, np.eye(6)) * np.outer(d, d)) if rank == 6 else None
    return Spectrum(rank, _rigid_directions(basis, rank, d), cond, float(length), K)


def scaled_compliance_factor(C: np.ndarray, length: float) -> np.ndarray:
    """(6, 6) square-root factor B_s of C_s = D C D from its eigen-decomposition.

    Raises:
        InvalidInputError: C is not symmetric positive semi-definite (scaled tolerance
            :data:`SCALED_TOL`).
    """
    d = twist_scaling(length)
    Cs = C * np.outer(d, d)
    top = np.max(np.abs(Cs))
    if top > 0.0 and np.max(np.abs(Cs - Cs.T)) > SCALED_TOL * top:
        raise InvalidInputError("compliance is not symmetric")
    mu, U = np.linalg.eigh(0.5 * (Cs + Cs.T))
    if top > 0.0 and mu[0] < -SCALED_TOL * mu[-1]:
        raise InvalidInputError(
            f"compliance is not positive semi-definite (scaled eigenvalue ratio "
            f"{mu[0] / mu[-1]:.2e})"
        )
    return U * np.sqrt(np.clip(mu, 0.0, None))


def spectrum_from_compliance(C: np.ndarray, length: float) -> Spectrum:
    """Spectrum of a symmetric PSD compliance C (6, 6) [SI] given as a matrix.

    Raises:
        InvalidInputError: C is not symmetric positive semi-definite.
    """
    return spectrum_from_factor(scaled_compliance_factor(C, length), length)


def batch_rank(C: np.ndarray, length) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rank, condition number and PSD flag of many symmetric compliances (n, 6, 6) [SI].

    The rule of :func:`spectrum_from_compliance`, vectorised over the stack.

    Args:
        C: (n, 6, 6) symmetric compliances [SI].
        length: characteristic length [m], one for all or (n,) one per matrix.

    Returns:
        rank: (n,) int; condition: (n,) cond(K_s) over the rank; psd: (n,) bool.
    """
    L = np.broadcast_to(np.asarray(length, dtype=float), (len(C),))
    d = twist_scalings(L)
    Cs = C * d[:, :, None] * d[:, None, :]
    mu = np.linalg.eigvalsh(0.5 * (Cs + np.swapaxes(Cs, 1, 2)))
    top = mu[:, -1:]
    keep = mu > RANK_RTOL**2 * np.maximum(top, 0.0)
    rank = np.count_nonzero(keep, axis=1)
    low = np.min(np.where(keep, mu, np.inf), axis=1)
    condition = np.where(rank > 0, top[:, 0] / np.where(rank > 0, low, 1.0), 1.0)
    psd = mu[:, 0] >= -SCALED_TOL * np.maximum(top[:, 0], 0.0)
    return rank, condition, psd
