"""Stiffness indices of many compliances at once (a map's points), vectorised over the points.

The definitions are those of :class:`closedloop.analysis.indices.StiffnessIndices`;
:func:`batch_indices` computes the indices of :data:`BATCH_INDICES` for n compliances
(NaN where one does not exist).
"""

from __future__ import annotations

import numpy as np

from closedloop.common.conditioning import RANK_RTOL, batch_rank, twist_scalings

T, R = slice(0, 3), slice(3, 6)


#: Indices of many compliances at once (:func:`batch_indices`), and their units (SI).
BATCH_INDICES = {
    "det_K": "N^6/rad^3",
    "condition_number": "1 (cond of the scaled K_s: unit-free, see closedloop.common.conditioning)",
    "condition_number_si": "1 (cond of the SI matrix K: depends on the length unit)",
    "min_translational": "N/m",
    "max_translational": "N/m",
    "min_rotational": "N m/rad",
    "max_rotational": "N m/rad",
    "deflection_translation": "m",
    "deflection_rotation": "rad",
}


def block_spectrum(C: np.ndarray, block: slice, length) -> tuple[np.ndarray, ...]:
    """Eigenvalues c (n, 3) ascending and vectors V (n, 3, 3) of a 3x3 block of n
    compliances C (n, 6, 6) [SI], and which directions are rigid (n, 3): those whose
    scaled compliance is at most ``RANK_RTOL^2`` of the largest diagonal entry of the
    scaled C_s (lengths L (n,) or one [m]; the rank rule on eigenvalues, on the scale of
    C_s: its largest eigenvalue is 1 to 6 times that entry), so that a block of rounding
    beside a compliant other block is rigid (a Delta's rotations: 1e-32 beside 1e-4, read
    as stiffnesses of 1e31 N m/rad when judged on the block alone)."""
    c, V = np.linalg.eigh(C[:, block, block])
    d = twist_scalings(np.broadcast_to(np.asarray(length, dtype=float), (len(C),)))
    with np.errstate(over="ignore", invalid="ignore"):
        top = np.max(np.diagonal(C, axis1=1, axis2=2) * d**2, axis=1)
        rigid = c * d[:, block.start, None] ** 2 <= RANK_RTOL**2 * top[:, None]
    return c, V, rigid | (c <= RANK_RTOL**2 * np.maximum(c[:, -1:], 0.0))


def _block_extremes(C: np.ndarray, block: slice, length) -> tuple[np.ndarray, np.ndarray]:
    """(n,) min and max principal stiffness of a 3x3 block of symmetric compliances (the rule of
    :meth:`closedloop.analysis.indices.StiffnessIndices.min_translational_stiffness`: the minimum
    exists unless the block is rigid, the maximum only when no direction of it is), NaN else;
    lengths L (n,) or one [m] of the scaling (:func:`block_spectrum`)."""
    c, _, rigid = block_spectrum(C, block, length)
    with np.errstate(divide="ignore"):
        low = np.where(rigid.all(axis=1), np.nan, 1.0 / c[:, -1])
        high = np.where(rigid.any(axis=1), np.nan, 1.0 / c[:, 0])
    return low, high


#: Largest condition number of a formed C or C_s (n, 6, 6) whose eigenvalues (the SI
#: condition number) or determinant (det K, from C_s) are taken: they
#: err by about 1e-16 of the largest, so the smallest is known to 1e-4 relative at 1e12,
#: and not at all towards 1e16 (a map showed 1.5e17 where K's own was 3.8e16).
SI_RESOLVED = 1e12


def batch_indices(
    C: np.ndarray,
    rank: np.ndarray,
    length,
    wrench: np.ndarray | None = None,
    symmetric: np.ndarray | None = None,
    condition: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """The indices of :data:`BATCH_INDICES` for n compliances at once (NaN where one does
    not exist), by the definitions of :class:`~closedloop.analysis.indices.StiffnessIndices`.

    * ``det_K``: det K = 1 / det C, full rank only, from the scaled C_s: NaN where its
      condition number exceeds :data:`SI_RESOLVED`.
    * ``condition_number``: cond(K_s) of the scaled stiffness over the rank, at the characteristic
      length L (as :attr:`~closedloop.analysis.indices.StiffnessIndices.scaled_condition_number`):
      unit-free, the one to compare. ``condition`` where given (the solver's, from the square-root
      factor), else from the eigenvalues of C (:func:`closedloop.common.conditioning.batch_rank`),
      which resolve it up to about 1e12.
    * ``condition_number_si``: cond(K) of the SI matrix, full rank only (as
      :attr:`~closedloop.analysis.indices.StiffnessIndices.condition_number`): changes with the
      length unit. From the eigenvalues of C: NaN above :data:`SI_RESOLVED`, where they do not
      resolve it.
    * ``min/max_translational``, ``min/max_rotational``: extreme principal stiffnesses of
      the 3x3 blocks of C [N/m, N m/rad].
    * ``deflection_translation``, ``deflection_rotation``: ``|d|`` [m], ``|r|`` [rad] of the twist
      C w under ``wrench`` (only with a wrench).

    A non-symmetric C (a closed form in its own coordinates, e.g. CaHyMan's published
    matrices) has K = C^-1, det K = det(C^-1), the 2-norm condition numbers of K and of
    K_s = D^-1 K D^-1, and no principal stiffnesses.

    Args:
        C: (n, 6, 6) compliances [SI] at one reference point; rows with a NaN are skipped.
        rank: (n,) rank of each C (6: K exists).
        length: characteristic length L [m], one or (n,).
        wrench: (6,) (fx, fy, fz [N], nx, ny, nz [N m]) at the same point, or None.
        symmetric: (n,) bool, which C are symmetric (default: all).
        condition: (n,) cond(K_s) from the solver, NaN where unknown (or None).

    Returns:
        name -> (n,) array (units in :data:`BATCH_INDICES`; no deflections without wrench).
    """
    n = len(C)
    L = np.broadcast_to(np.asarray(length, dtype=float), (n,))
    out = {name: np.full(n, np.nan) for name in BATCH_INDICES}
    finite = np.all(np.isfinite(C), axis=(1, 2))
    sym = finite if symmetric is None else finite & symmetric
    full = finite & (np.asarray(rank) == 6)
    known = np.zeros(n, dtype=bool)
    if condition is not None:
        known = finite & np.isfinite(condition)
        out["condition_number"][known] = condition[known]
    rest = sym & ~known  # from the eigenvalues of C only where the solver's is not known
    if np.any(rest):
        _, out["condition_number"][rest], _ = batch_rank(C[rest], L[rest])
    if np.any(sym):
        for kind, block in (("translational", T), ("rotational", R)):
            out[f"min_{kind}"][sym], out[f"max_{kind}"][sym] = _block_extremes(
                C[sym], block, L[sym]
            )
    both = sym & full
    if np.any(both):
        c = np.abs(np.linalg.eigvalsh(C[both]))  # an indefinite C (unstable preload) too
        with np.errstate(divide="ignore", over="ignore"):
            cond_si = c.max(axis=1) / c.min(axis=1)
        cond_si[~(cond_si <= SI_RESOLVED)] = np.nan
        out["condition_number_si"][both] = cond_si
        cond_s = out["condition_number"][both]
        out["det_K"][both] = _scaled_determinants(C[both], L[both], cond_s)
    other = ~sym & full
    if np.any(other):
        K = np.linalg.inv(C[other])
        d = twist_scalings(L[other])
        out["det_K"][other] = np.linalg.det(K)
        out["condition_number_si"][other] = np.linalg.cond(K)
        out["condition_number"][other] = np.linalg.cond(K / d[:, :, None] / d[:, None, :])
    if wrench is None:
        del out["deflection_translation"], out["deflection_rotation"]
        return out
    w = np.asarray(wrench, dtype=float)
    scale = np.max(np.abs(w))  # C (w / s) then times s: no overflow or underflow of |C w|
    twist = C[finite] @ (w / scale) if scale > 0 else np.zeros((int(finite.sum()), 6))
    out["deflection_translation"][finite] = scale * row_norms(twist[:, :3])
    out["deflection_rotation"][finite] = scale * row_norms(twist[:, 3:])
    return out


def _scaled_determinants(C: np.ndarray, L: np.ndarray, condition: np.ndarray) -> np.ndarray:
    """(n,) det K = det(D)^2 / det(C_s) [N^6/rad^3] of symmetric compliances C (n, 6, 6)
    from the LU factors of the scaled C_s = D C D (D = diag(1/L, 1/L, 1/L, 1, 1, 1), L
    (n,) [m]), logarithms against under- and overflow; NaN where ``condition`` (n,)
    (cond(K_s)) exceeds :data:`SI_RESOLVED`. Unlike 1 / det(C), the error follows the
    scaled condition, not the SI one, which a length unit alone makes large (a mechanism
    of 1e-4 m has an SI condition number 1e8 times its scaled one)."""
    d = twist_scalings(L)
    sign, log_det = np.linalg.slogdet(C * d[:, :, None] * d[:, None, :])
    with np.errstate(over="ignore", invalid="ignore"):
        det = sign * np.exp(-log_det - 6.0 * np.log(L))
    return np.where(condition <= SI_RESOLVED, det, np.nan)


def row_norms(v: np.ndarray) -> np.ndarray:
    """(n,) Euclidean norms of the rows of v (n, k), without overflow or underflow of the
    squares (inf only where a norm exceeds 1.8e308, NaN where a row is not finite)."""
    big = np.max(np.abs(v), axis=1)
    safe = np.where(big > 0, big, 1.0)
    with np.errstate(invalid="ignore", over="ignore"):
        return big * np.linalg.norm(v / safe[:, None], axis=1)
