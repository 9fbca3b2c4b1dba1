"""Stiffness indices of many compliances at once (no loop over points).

The formulas are those of :class:`closedloop.indices.StiffnessIndices` for a symmetric
compliance and of :class:`cahyman_pin.api.CaHyManStiffness` for a non-symmetric one (the
published backend), applied to a stack of matrices, so that a sweep reproduces
point-by-point :func:`cahyman_pin.api.stiffness` queries. Arrays are SI: C (n, 6, 6) at
M in world axes, twists (dx, dy, dz [m], rx, ry, rz [rad]), wrenches (fx, fy, fz [N],
nx, ny, nz [N m]).
"""

from __future__ import annotations

import numpy as np

from closedloop.conditioning import RANK_RTOL, batch_rank

#: Status of a point, by code (index in this tuple).
STATUS = ("ok", "rank_deficient", "invalid", "unreachable", "singular", "failed")
OK, RANK_DEFICIENT, INVALID, UNREACHABLE, SINGULAR, FAILED = range(len(STATUS))
#: Relative tolerance of the symmetry test (as :func:`cahyman_pin.api.stiffness`).
SYMMETRY_RTOL = 1e-9


#: Indices of :func:`stiffness_indices` and their units (SI).
INDEX_UNITS = {
    "det_K": "N^6/rad^3",
    "condition_number": "1 (SI matrix, depends on the length unit)",
    "min_translational": "N/m",
    "max_translational": "N/m",
    "min_rotational": "N m/rad",
    "max_rotational": "N m/rad",
    "deflection_translation": "m",
    "deflection_rotation": "rad",
}


def compliance_rank(C: np.ndarray, length) -> tuple[np.ndarray, np.ndarray]:
    """Rank of symmetric compliances by the one rule of :mod:`closedloop.conditioning`.

    Args:
        C: (n, 6, 6) symmetric compliances [SI].
        length: (n,) characteristic lengths of the machines [m] (``params.length``).

    Returns:
        rank: (n,) int; psd: (n,) bool, False where C is not positive semi-definite.
    """
    rank, _, psd = batch_rank(C, length)
    return rank, psd


def _block_extremes(C: np.ndarray, block: slice) -> tuple[np.ndarray, np.ndarray]:
    """Min and max principal stiffness of a 3x3 block of C (rotations or forces free).

    As ``StiffnessIndices.min_/max_..._stiffness``: the minimum exists unless the block is
    zero, the maximum only when no direction of the block is rigid.
    """
    c = np.linalg.eigvalsh(C[:, block, block])
    rigid = c <= RANK_RTOL**2 * np.maximum(c[:, -1:], 0.0)  # the rule, on eigenvalues
    with np.errstate(divide="ignore"):
        low = np.where(rigid.all(axis=1), np.nan, 1.0 / c[:, -1])
        high = np.where(rigid.any(axis=1), np.nan, 1.0 / c[:, 0])
    return low, high


def stiffness_indices(
    C: np.ndarray, full_rank: np.ndarray, symmetric: np.ndarray, wrench: np.ndarray | None
) -> dict[str, np.ndarray]:
    """Stiffness indices of many compliances at once (NaN where an index does not exist).

    Symmetric C: the formulas of :class:`closedloop.indices.StiffnessIndices`
    (det K = 1 / det C, condition number from the eigenvalues of K = C^-1, extreme
    principal stiffnesses from the 3x3 blocks of C). Non-symmetric C (published backend):
    those of :class:`cahyman_pin.api.CaHyManStiffness` (K the plain inverse, det K and
    the 2-norm condition number of K); the principal stiffnesses are NaN.

    Args:
        C: (n, 6, 6) compliances at M, world axes [SI]; rows not to evaluate may be NaN.
        full_rank: (n,) bool, K exists (the others get NaN for every index that needs K).
        symmetric: (n,) bool.
        wrench: (6,) wrench at M [N, N m] for the deflection, or None.

    Returns:
        name -> (n,) array, names and units in :data:`INDEX_UNITS`; with a wrench also
        ``"deflection"``: (n, 6) twist of M (dx, dy, dz [m], rx, ry, rz [rad]).
    """
    n = len(C)
    out = {name: np.full(n, np.nan) for name in INDEX_UNITS}
    sym = symmetric & full_rank
    if np.any(sym):
        Cs = C[sym]
        K = np.linalg.inv(Cs)
        lam = np.linalg.eigvalsh(0.5 * (K + K.swapaxes(1, 2)))
        out["det_K"][sym] = 1.0 / np.linalg.det(Cs)
        out["condition_number"][sym] = lam[:, -1] / lam[:, 0]
    asym = ~symmetric & full_rank
    if np.any(asym):
        K = np.linalg.inv(C[asym])
        out["det_K"][asym] = np.linalg.det(K)
        out["condition_number"][asym] = np.linalg.cond(K)
    defined = symmetric & np.all(np.isfinite(C), axis=(1, 2))
    if np.any(defined):
        for kind, block in (("translational", slice(0, 3)), ("rotational", slice(3, 6))):
            low, high = _block_extremes(C[defined], block)
            out[f"min_{kind}"][defined], out[f"max_{kind}"][defined] = low, high
    if wrench is None:
        del out["deflection_translation"], out["deflection_rotation"]
        return out
    twist = C @ np.asarray(wrench, dtype=float)
    out["deflection"] = twist
    out["deflection_translation"] = np.linalg.norm(twist[:, :3], axis=1)
    out["deflection_rotation"] = np.linalg.norm(twist[:, 3:], axis=1)
    return out


def classify(
    C: np.ndarray, rank: np.ndarray, status: np.ndarray, reasons: list, length: np.ndarray
) -> np.ndarray:
    """Complete rank and status of computed points from their compliance (in place).

    Symmetric C without a rank (not from the generic solver) gets the rank of
    :func:`compliance_rank`; a symmetric C that is not positive semi-definite becomes
    ``failed`` (C set to NaN); a non-symmetric C counts as full rank (K = C^-1, as
    published); a computed point of rank < 6 becomes ``rank_deficient``.

    Args:
        C: (n, 6, 6) compliances [SI], NaN where not computed; modified.
        rank: (n,) ranks, -1 where unknown; modified.
        status: (n,) status codes, OK where computed; modified.
        reasons: n messages; modified.
        length: (n,) characteristic length of the machine at each point [m].

    Returns:
        (n,) bool: C is symmetric (and computed).
    """
    computed = status == OK
    symmetric = computed & np.all(
        np.abs(C - C.swapaxes(1, 2)) <= SYMMETRY_RTOL * np.abs(C.swapaxes(1, 2)), axis=(1, 2)
    )
    unknown = symmetric & (rank < 0)
    if np.any(unknown):
        rank[unknown], psd = compliance_rank(C[unknown], length[unknown])
        for i in np.flatnonzero(unknown)[~psd]:
            status[i], C[i], symmetric[i] = FAILED, np.nan, False
            reasons[i] = "compliance is not positive semi-definite"
    rank[computed & ~symmetric & (status == OK)] = 6
    for i in np.flatnonzero((status == OK) & (rank < 6)):
        status[i] = RANK_DEFICIENT
        reasons[i] = f"compliance has rank {rank[i]} < 6: the stiffness does not exist"
    return symmetric


__all__ = [
    "INDEX_UNITS",
    "STATUS",
    "SYMMETRY_RTOL",
    "classify",
    "compliance_rank",
    "stiffness_indices",
]
