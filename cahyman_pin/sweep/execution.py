"""The kernel of CaHyMan's sweeps: one chunk of points, for
:func:`closedloop.analysis.tasks.run_tasks`.

A sweep is cut into chunks of points that are contiguous along its path (see
:mod:`cahyman_pin.sweep.engine`); each chunk is one task, computed by :func:`run_chunk`
per run of consecutive points that share one parameter set (a design sweep changes the
model, rebuilt once per run and cached per thread):

* ``"generic"``: per point, :meth:`CaHyManModel.assemble` then
  :func:`closedloop.elastostatics.compliance.compliance` at M, world axes (the code path of
  :func:`cahyman_pin.backends.registry.generic_backend`), by
  :func:`closedloop.analysis.map_engine.assemble_points`. The assembly starts (``start``) from
  CaHyMan's closed-form geometry, computed for the whole run at once (``"closed_form"``: exact, so
  the Gauss-Newton loop only checks it), or from the previous point's configuration
  (``"neighbour"``, the generic way: extrapolated along the path when the last two steps are equal;
  the first point of a chunk and a point after a failed start start from the closed form);
* ``"consistent"``: the closed form on the whole run at once (one call, no loop over
  points); a failing batch is bisected to isolate the failing points;
* any other registered backend: its function, point by point.

A point that fails is recorded with a status and the error message; it never stops the
sweep. The rank, the status from C and the indices are computed at the end of the chunk,
for all its points at once (:func:`closedloop.analysis.map_engine.complete`), and with
``modes`` (generic backend) the lowest natural frequency at each assembled configuration
(:func:`closedloop.analysis.vibration.lowest_frequencies`, as every map of the project). A
point whose scaled condition number exceeds ``ILL_CONDITIONED`` (1e8) takes its single
query's C and K (K from a square-root factor where the query has one: the formed C loses
cond(K_s) times the rounding): the generic kernel's in
:func:`closedloop.analysis.map_engine.assemble_points`, the others'
:func:`cahyman_pin.api.stiffness` (after the backend's kernel, for those points only), so
that its indices are that query's.
"""

from __future__ import annotations

import functools
import threading
from collections import OrderedDict
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from cahyman_pin.api import stiffness
from cahyman_pin.backends.consistent import consistent_compliance
from cahyman_pin.model import CaHyManModel, check_inputs
from cahyman_pin.params import CaHyManParams
from cahyman_pin.urdf_builder import FRAME_M, REVOLUTE_LIMIT
from closedloop.analysis.complete import complete
from closedloop.analysis.map_engine import assemble_points
from closedloop.analysis.map_results import OK, POINT_ERRORS, RANK_DEFICIENT, SINGULAR, ChunkResult
from closedloop.common.conditioning import ILL_CONDITIONED, SCALED_TOL, batch_rank, scaled_asymmetry
from closedloop.exceptions import AssemblyError, InvalidInputError

#: Starts of the generic assembly: the previous point's configuration, or the closed-form
#: geometry of CaHyMan, computed for a whole run of points at once.
STARTS = ("neighbour", "closed_form")
#: Models kept per thread by the generic kernel (one per parameter set).
MODEL_CACHE_SIZE = 8

_local = threading.local()


@dataclass(frozen=True)
class Chunk:
    """One task: points contiguous along the sweep path (SI).

    Attributes:
        backend: backend name.
        start: start of the generic assembly, one of :data:`STARTS`.
        func: the registered backend function (pickled by reference).
        params: parameters of the points, before the design values.
        design_names: names of the varying CaHyManParams fields.
        alpha: (c, 3) crank angles [rad]; alpha4: (c,) arm angle [rad]; s4: (c,) stroke [m].
        design: (c, len(design_names)) values of the design fields [SI].
        wrench: (6,) wrench at M of the deflection indices [N, N m], world axes, or None.
        modes: also the index ``lowest_frequency`` [Hz] of every point (generic backend;
            :func:`closedloop.analysis.vibration.lowest_frequencies`).
    """

    backend: str
    start: str
    func: Callable
    params: CaHyManParams
    design_names: tuple[str, ...]
    alpha: np.ndarray
    alpha4: np.ndarray
    s4: np.ndarray
    design: np.ndarray
    wrench: np.ndarray | None = None
    modes: bool = False

    def __len__(self) -> int:
        return len(self.alpha4)


def _runs(chunk: Chunk, out: ChunkResult) -> Iterator[tuple[np.ndarray, CaHyManParams]]:
    """(positions, params) of the runs of consecutive points sharing one parameter set;
    points with invalid parameters are recorded as such."""
    first, previous, params = 0, None, None
    for i in range(len(chunk) + 1):
        values = tuple(chunk.design[i].tolist()) if i < len(chunk) else None
        if i > 0 and values == previous:
            continue
        if isinstance(params, CaHyManParams):
            yield np.arange(first, i), params
        elif params is not None:
            for j in range(first, i):
                out.fail(j, params)
        if values is not None:
            try:
                named = dict(zip(chunk.design_names, values, strict=True))
                params = chunk.params.replace(**named) if named else chunk.params
            except InvalidInputError as e:
                params = e
        first, previous = i, values


def _prevalidate(chunk: Chunk, idx: np.ndarray, params: CaHyManParams, out: ChunkResult):
    """Points of ``idx`` whose inputs pass :func:`check_inputs` (others recorded)."""
    s4 = chunk.s4[idx]
    good = (
        np.all(np.abs(chunk.alpha[idx]) <= REVOLUTE_LIMIT, axis=1)  # False for NaN
        & (np.abs(chunk.alpha4[idx]) <= REVOLUTE_LIMIT)
        & (s4 >= 0.0)
        & (s4 <= params.s4_max)
    )
    for i in idx[~good]:
        try:
            check_inputs(chunk.alpha[i], chunk.alpha4[i], chunk.s4[i], params)
        except InvalidInputError as e:
            out.fail(i, e)
    return idx[good]


def _bisect(idx: np.ndarray, func: Callable[[np.ndarray], None], out: ChunkResult) -> None:
    """Run ``func`` on the batch ``idx``; where it raises, bisect to record the failing points."""
    if idx.size == 0:
        return
    try:
        func(idx)
    except POINT_ERRORS as e:
        if idx.size == 1:
            out.fail(int(idx[0]), e)
        else:
            _bisect(idx[: idx.size // 2], func, out)
            _bisect(idx[idx.size // 2 :], func, out)


# ------------------------------------------------------------------ generic kernel
def _model(params: CaHyManParams) -> CaHyManModel:
    """This thread's model for ``params`` (Pinocchio data is not shared between threads)."""
    cache = getattr(_local, "models", None)
    if cache is None:
        cache = _local.models = OrderedDict()
    if params in cache:
        cache.move_to_end(params)
        return cache[params]
    model = cache[params] = CaHyManModel(params)
    if len(cache) > MODEL_CACHE_SIZE:
        cache.popitem(last=False)
    return model


def _generic(chunk: Chunk, idx: np.ndarray, params: CaHyManParams, out: ChunkResult):
    """The generic kernel on the run ``idx``; returns (its model, {position: q} of the
    points assembled)."""
    model = _model(params)
    configurations: dict[int, np.ndarray] = {}
    starts: dict[int, np.ndarray] = {}
    if chunk.start == "closed_form":

        def guesses(sub: np.ndarray) -> None:
            q = model.initial_guesses(chunk.alpha[sub], chunk.alpha4[sub], chunk.s4[sub])
            starts.update(zip(sub.tolist(), q, strict=True))

        _bisect(idx, guesses, out)
        idx = np.array(sorted(starts), dtype=int)

    inputs = np.column_stack([chunk.alpha, chunk.alpha4, chunk.s4])  # validated above

    def solve(i: int, q0):
        """Assembly from ``q0`` (None: the closed form); a failed warm start once more
        from the closed form."""
        try:
            a = model.assemble_validated(inputs[i], q0, jacobian=True)
        except AssemblyError:
            if q0 is None:
                raise
            a = model.assemble_validated(inputs[i], jacobian=True)
        configurations[i] = a.q
        return a

    # neighbour start: the first point of the run from the closed form (q0 None)
    per_point = [starts[i] for i in idx] if chunk.start == "closed_form" else None
    assemble_points(model.clm, FRAME_M, out, idx, solve, starts=per_point, length=params.length,
                    inputs=inputs)  # fmt: skip
    return model.clm, configurations


# ------------------------------------------------------------------ other kernels
def _consistent(chunk: Chunk, idx: np.ndarray, params: CaHyManParams, out: ChunkResult) -> None:
    def batch(sub: np.ndarray) -> None:
        out.C[sub] = consistent_compliance(chunk.alpha[sub], chunk.alpha4[sub], chunk.s4[sub],
                                           params)  # fmt: skip

    _bisect(idx, batch, out)


def _pointwise(chunk: Chunk, idx: np.ndarray, params: CaHyManParams, out: ChunkResult) -> None:
    for i in idx:
        try:
            out.C[i] = chunk.func(params, chunk.alpha[i], chunk.alpha4[i], chunk.s4[i]).C
        except POINT_ERRORS as e:
            out.fail(int(i), e)


def _single_queries(chunk: Chunk, idx: np.ndarray, params: CaHyManParams, out: ChunkResult):
    """The single query :func:`cahyman_pin.api.stiffness` at the points ``idx`` of a
    closed form whose compliance is symmetric and ill-conditioned (cond(K_s) above
    ``ILL_CONDITIONED`` or rank < 6 by the eigenvalues of C,
    :func:`closedloop.common.conditioning.batch_rank`):
    its C, rank, condition number and K (from the backend's square-root factor where it
    has one) into ``out``; its error, if any, is the point's (at a point of rank < 6 by
    C, the refusal of that rank in :func:`closedloop.analysis.map_engine.complete`). (The backend
    must be registered in the process, as for :func:`cahyman_pin.api.stiffness`.)"""
    idx = idx[(out.status[idx] == OK) & np.isfinite(out.C[idx]).all(axis=(1, 2))]
    idx = idx[scaled_asymmetry(out.C[idx], params.length) <= SCALED_TOL]
    rank, condition, _ = batch_rank(out.C[idx], params.length)
    # rank < 6 by the rule on C: the query's rule (on B's kinematic part) may answer
    for k in np.flatnonzero((condition > ILL_CONDITIONED) | (rank < 6)):
        i = idx[k]
        try:
            r = stiffness(chunk.alpha[i], chunk.alpha4[i], chunk.s4[i], params=params,
                          backend=chunk.backend)  # fmt: skip
        except POINT_ERRORS as e:
            if rank[k] == 6:  # else refused as the rule on C says (complete), the same way
                out.fail(int(i), e)
            continue
        s = r.indices
        out.answer(i, r.C, s.rank, s.scaled_condition_number, s.K if s.is_full_rank else None)


_KERNELS = {"generic": _generic, "consistent": _consistent}


def run_chunk(chunk: Chunk) -> ChunkResult:
    """Compliance of every point of ``chunk`` and their indices (the task sent to an
    executor)."""
    out = ChunkResult.empty(len(chunk))
    kernel = _KERNELS.get(chunk.backend, _pointwise)
    assembled = []  # the generic kernel's (model, {position: q}) of each run
    for idx, params in _runs(chunk, out):
        out.length[idx] = params.length
        ran = kernel(chunk, _prevalidate(chunk, idx, params, out), params, out)
        if kernel is _generic:
            assembled.append(ran)
        else:
            _single_queries(chunk, idx, params, out)
    complete(out, chunk.wrench, functools.partial(_singular_poses, chunk.backend))
    if chunk.modes:  # the vibration module on demand
        from closedloop.analysis.vibration import lowest_frequencies

        done = np.isin(out.status, (OK, RANK_DEFICIENT))
        frequencies = np.full(len(chunk), np.nan)
        for clm, configurations in assembled:
            rows = list(configurations)
            frequencies[rows] = lowest_frequencies(clm, configurations, done)[rows]
        out.indices["lowest_frequency"] = frequencies
    return out


def _singular_poses(backend: str, out: ChunkResult, from_C: np.ndarray) -> None:
    """As :func:`cahyman_pin.api.stiffness`: a closed form's compliance of rank < 6 (the
    rank from C) is a singular pose, where one direction is almost free, not rigidity."""
    for i in np.flatnonzero(from_C & (out.status == RANK_DEFICIENT)):
        out.status[i] = SINGULAR
        out.set_reason(i, f"the {backend} compliance at M has numerical rank {out.rank[i]} "
                       "< 6: a singular pose, where one direction is almost free")  # fmt: skip
        out.C[i] = np.nan


__all__ = ["STARTS", "Chunk", "run_chunk"]
