"""Rank, status and stiffness indices of a chunk's points, from their compliances.

:func:`complete` runs in each kernel, so in the workers of a map: the rank and status from C
(:func:`classify`) and the stiffness indices of the chunk's points at once; those that the
formed C does not resolve (an ill-conditioned point) as the single query computes them
(:func:`resolve_ill_conditioned`).
"""

from __future__ import annotations

import math

import numpy as np

from closedloop.analysis.batch_indices import batch_indices
from closedloop.analysis.indices import StiffnessIndices
from closedloop.analysis.map_results import FAILED, OK, RANK_DEFICIENT, ChunkResult
from closedloop.common.conditioning import (
    ILL_CONDITIONED,
    SCALED_TOL,
    Spectrum,
    batch_rank,
    scaled_asymmetry,
)
from closedloop.exceptions import RigidDirectionsError, SingularConfigurationError


def complete(out: ChunkResult, wrench: np.ndarray | None, relabel=None) -> None:
    """Rank, status and stiffness indices of a chunk's points, in place (in the kernel, so that the
    workers of a map compute them in parallel): :func:`classify`, then ``relabel(out, from_C)`` if
    given (a caller's own statuses; from_C (c,) bool: the rank came from C, not from the solver),
    then :func:`closedloop.analysis.batch_indices.batch_indices` into ``out.indices``, the
    ill-conditioned points' by :func:`resolve_ill_conditioned`."""
    from_C = out.rank < 0
    symmetric = classify(out)
    if relabel is not None:
        relabel(out, from_C)
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow fails its point, below
        out.indices = batch_indices(out.C, out.rank, out.length, wrench, symmetric, out.condition)
    resolve_ill_conditioned(out, symmetric)
    for name, values in out.indices.items():  # NaN: no value; inf: the index overflowed
        beyond = np.isinf(values) | ((values == 0.0) if name == "det_K" else False)  # det K
        # of a full-rank K is never 0: one that underflowed
        for i in np.flatnonzero(beyond & np.isin(out.status, (OK, RANK_DEFICIENT))):
            way = "overflows" if np.isinf(values[i]) else "underflows"
            out.status[i], out.C[i] = FAILED, np.nan
            reason = f"the index {name} {way} the floating point range (a load or spring"
            out.set_reason(i, reason + " far from the mechanism's scale; expected nearer)")
            for other in out.indices.values():
                other[i] = np.nan


def resolve_ill_conditioned(out: ChunkResult, symmetric: np.ndarray) -> None:
    """``det_K``, ``condition_number_si`` and ``condition_number`` of the full-rank
    symmetric points that the formed C does not resolve to rounding, as the single query
    computes them (:attr:`closedloop.analysis.indices.StiffnessIndices.determinant`,
    ``.condition_number``, ``.scaled_condition_number``), in ``out.indices`` (in place).

    Those are the points of cond(K_s) above ``ILL_CONDITIONED`` (1e8) or of an SI condition number
    that :func:`closedloop.analysis.batch_indices.batch_indices` leaves NaN (above its
    ``SI_RESOLVED``, 1e12). From the formed C, det K and the SI condition number err by
    about eps cond(K_s) relative (2e-8 at 1e8, 2e-4 at 1e12, nothing left at 1e16); from
    the solver's square-root factor, by about eps sqrt(cond(K_s)) (2e-8 at 1e16). K is the
    single query's where the kernel recorded it (``out.K``: every point above
    ``ILL_CONDITIONED`` of the project's kernels,
    :meth:`closedloop.analysis.map_results.ChunkResult.answer`); else (an SI
    condition number beyond ``SI_RESOLVED`` at a scaled one below 1e8, which a length unit
    alone makes so, or a kernel that records no K) from the eigen-decomposition of the
    scaled C (:meth:`~closedloop.analysis.indices.StiffnessIndices.from_compliance`: eps cond(K_s)
    relative). A det K beyond the float range becomes inf or 0 (its point fails in
    :func:`complete`, as a point of the batch); the indices of a point whose C has rank
    < 6 by that rule (a kernel without K, cond(K_s) near 1e14) are NaN.
    """
    names = ("det_K", "condition_number_si", "condition_number")
    det, cond_si, cond = (out.indices[name] for name in names)
    full = symmetric & (out.rank == 6)
    for i in np.flatnonzero(full & ~((cond <= ILL_CONDITIONED) & (cond_si >= 0.0))):
        C, K, L = out.C[i], out.K.get(i), float(out.length[i])
        try:
            if K is None:  # from C only
                s = StiffnessIndices.from_compliance(C, length=L)
            else:  # as StiffnessIndices.from_result of the single query
                spectrum = Spectrum(6, np.zeros((6, 0)), float(out.condition[i]), L, K)
                s = StiffnessIndices(C, 6, spectrum.rigid_directions, L, spectrum)
            cond_si[i], cond[i] = s.condition_number, s.scaled_condition_number
            det[i] = s.determinant
        except SingularConfigurationError:  # det K beyond the float range
            det[i] = math.inf if np.linalg.slogdet(s.K)[1] > 0.0 else 0.0
        except RigidDirectionsError:  # C of rank < 6 by the rule on C
            for name in names:
                out.indices[name][i] = np.nan


def classify(data: ChunkResult) -> np.ndarray:
    """Complete the rank and status of computed points from their compliance (in place).

    A symmetric C without a rank (not from the solver: a closed form) gets the rank of
    :func:`closedloop.common.conditioning.batch_rank`, and becomes ``failed`` if it is not
    positive semi-definite; a non-symmetric C counts as full rank (K = C^-1); a computed
    point of rank < 6 becomes ``rank_deficient``; C is NaN wherever the status is neither.

    Returns:
        (n,) bool: C is symmetric (and computed).
    """
    C, rank, codes = data.C, data.rank, data.status
    computed = (codes == OK) & np.all(np.isfinite(C), axis=(1, 2))
    symmetric = computed & (scaled_asymmetry(np.where(computed[:, None, None], C, 0.0),
                                             data.length) <= SCALED_TOL)  # fmt: skip
    unknown = symmetric & (rank < 0)
    if np.any(unknown):
        rank[unknown], _, psd = batch_rank(C[unknown], data.length[unknown])
        for i in np.flatnonzero(unknown)[~psd]:
            codes[i], symmetric[i] = FAILED, False
            data.set_reason(i, "compliance is not positive semi-definite")
    rank[computed & ~symmetric & (codes == OK)] = 6
    for i in np.flatnonzero((codes == OK) & (rank < 6)):
        codes[i] = RANK_DEFICIENT
        data.set_reason(i, f"compliance has rank {rank[i]} < 6: the stiffness does not exist")
    C[~np.isin(codes, (OK, RANK_DEFICIENT))] = np.nan
    return symmetric
