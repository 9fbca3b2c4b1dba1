"""The results of a map's points: their status codes, a chunk's results, a map's arrays.

A kernel of :mod:`closedloop.analysis.map_engine` returns a :class:`ChunkResult` for its chunk
(a point that fails is recorded with its status and reason, never the whole map lost);
:func:`closedloop.analysis.tasks.gather` puts the chunks' results into one :class:`PointData`
(no per-point Python objects: statuses and reasons are small integer codes).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from closedloop.elastostatics.batch import QUERY_ERRORS
from closedloop.exceptions import (
    AssemblyError,
    InvalidInputError,
    MechanismError,
    RigidDirectionsError,
    SingularConfigurationError,
)

#: Status of a point, by code (its index in this tuple); ``not_computed``: the map was
#: interrupted before the point's chunk was computed
#: (:class:`~closedloop.analysis.interrupts.Interrupted`).
STATUS = ("ok", "rank_deficient", "invalid", "unreachable", "singular", "failed", "not_computed")
OK, RANK_DEFICIENT, INVALID, UNREACHABLE, SINGULAR, FAILED, NOT_COMPUTED = range(len(STATUS))


#: Exceptions recorded per point (anything else, a programming error, propagates).
POINT_ERRORS = QUERY_ERRORS


def status_code(error: Exception) -> int:
    """Status code (index in :data:`STATUS`) of a point that raised ``error``."""
    if isinstance(error, InvalidInputError):
        return INVALID
    if isinstance(error, AssemblyError):
        return UNREACHABLE
    if isinstance(error, SingularConfigurationError | MechanismError | RigidDirectionsError):
        return SINGULAR
    return FAILED


@dataclass
class ChunkResult:
    """What a kernel returns for c points (SI).

    Attributes:
        C: (c, 6, 6) compliance at the frame [SI], NaN where the point failed.
        rank: (c,) rank of C from the solver, -1 where unknown (set by
            :func:`~closedloop.analysis.complete.classify`).
        condition: (c,) scaled condition number cond(K_s) from the solver's factor, NaN
            where unknown (a closed form: then computed from C).
        status: (c,) status codes (:data:`STATUS`).
        length: (c,) characteristic length [m] of the scaled indices.
        iterations: (c,) Gauss-Newton iterations of the assembly, -1 if none.
        reasons: error message per failed point, by position in the chunk.
        indices: name -> (c,) stiffness indices
            (:func:`~closedloop.analysis.complete.complete`; empty until then).
        K: position -> (6, 6) stiffness [SI] of the single query (from its square-root
            factor) at the points whose cond(K_s) exceeds ``ILL_CONDITIONED``
            (:meth:`answer`), for :func:`~closedloop.analysis.complete.resolve_ill_conditioned`.
    """

    C: np.ndarray
    rank: np.ndarray
    condition: np.ndarray
    status: np.ndarray
    length: np.ndarray
    iterations: np.ndarray
    reasons: dict[int, str] = field(default_factory=dict)
    indices: dict[str, np.ndarray] = field(default_factory=dict)
    K: dict[int, np.ndarray] = field(default_factory=dict)

    @classmethod
    def empty(cls, n: int) -> ChunkResult:
        """n points, all ``ok`` until recorded otherwise, C NaN."""
        return cls(
            C=np.full((n, 6, 6), np.nan),
            rank=np.full(n, -1, dtype=np.int8),
            condition=np.full(n, np.nan),
            status=np.zeros(n, dtype=np.int8),
            length=np.full(n, np.nan),
            iterations=np.full(n, -1, dtype=np.int16),
        )

    def fail(self, i: int, error: Exception) -> None:
        """Record the failure of point i."""
        self.status[i] = status_code(error)
        self.set_reason(i, " ".join(str(error).split()) or type(error).__name__)

    def set_reason(self, i: int, text: str) -> None:
        """Record the reason of point i's status."""
        self.reasons[int(i)] = text

    def answer(self, i: int, C: np.ndarray, rank: int, condition: float, K) -> None:
        """Point i as its single query answered it: C (6, 6), rank, cond(K_s) and K (6, 6)
        [SI] from the query's square-root factor (None: rank < 6)."""
        self.C[i], self.rank[i], self.condition[i] = C, rank, condition
        if K is not None:
            self.K[int(i)] = K


@dataclass(frozen=True)
class PointData:
    """Per-point results of a map, in storage order (numpy arrays only).

    Attributes:
        C: (n, 6, 6) compliance [SI], NaN where the point failed.
        rank: (n,) int8 rank of C, -1 where unknown.
        condition: (n,) scaled condition number from the solver, NaN where unknown.
        codes: (n,) int8 status codes (:data:`STATUS`).
        length: (n,) characteristic length [m].
        iterations: (n,) int16 assembly iterations, -1 if none.
        reason_codes: (n,) int32 index of each point's reason in ``reason_texts``.
        reason_texts: distinct reasons, ``reason_texts[0] == ""`` (a failed point's
            message usually names its own numbers: one text per failed point).
        indices: name -> (n,) stiffness indices of the chunks
            (:func:`~closedloop.analysis.complete.complete`).
    """

    C: np.ndarray
    rank: np.ndarray
    condition: np.ndarray
    codes: np.ndarray
    length: np.ndarray
    iterations: np.ndarray
    reason_codes: np.ndarray
    reason_texts: list
    indices: dict = field(default_factory=dict)
    _codes: dict = field(default_factory=dict, repr=False, compare=False)

    def set_reason(self, i: int, text: str) -> None:
        """Record the reason of point i (while the data is being completed)."""
        if not self._codes:
            self._codes.update((t, k) for k, t in enumerate(self.reason_texts))
        if text not in self._codes:
            self._codes[text] = len(self.reason_texts)
            self.reason_texts.append(text)
        self.reason_codes[i] = self._codes[text]
