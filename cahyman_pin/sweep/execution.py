"""Execution of CaHyMan sweeps: chunk kernels and executors.

A sweep is cut into chunks of points that are contiguous along its path (see
:mod:`cahyman_pin.sweep.engine`); each chunk is one task for a ``concurrent.futures.Executor``
and is computed by :func:`run_chunk`:

* ``"generic"``: per point, :meth:`CaHyManModel.assemble` then
  :func:`closedloop.compliance.compliance` at M, world axes (the code path of
  :func:`cahyman_pin.api.generic_backend`). The assembly starts (``start``) from the
  previous point's configuration, extrapolated along the path when the last two steps
  are equal (``"neighbour"``, the generic way), or from CaHyMan's closed-form geometry
  computed for the whole chunk at once (``"closed_form"``: exact, so the Gauss-Newton
  loop only checks it); a failed start is retried from the closed form;
* ``"consistent"``: the closed form on the whole chunk at once (one call, no loop over
  points); a failing batch is bisected to isolate the failing points;
* any other registered backend: its function, point by point.

A point that fails is recorded with a status and the error message; it never stops the
sweep. Programming errors (anything but :class:`ClosedLoopError` and
``numpy.linalg.LinAlgError``) do propagate.

The stiffness indices are computed afterwards, for all points at once
(:mod:`cahyman_pin.sweep.indices`).
"""

from __future__ import annotations

import os
import threading
from collections import OrderedDict
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from cahyman_pin.backends.consistent import consistent_compliance
from cahyman_pin.model import CaHyManModel, check_inputs
from cahyman_pin.params import CaHyManParams
from cahyman_pin.sweep.indices import FAILED, INVALID, OK, SINGULAR, UNREACHABLE
from cahyman_pin.urdf_builder import FRAME_M
from closedloop.blas import single_threaded_blas
from closedloop.compliance import compliance
from closedloop.exceptions import (
    AssemblyError,
    ClosedLoopError,
    InvalidInputError,
    MechanismError,
    RigidDirectionsError,
    SingularConfigurationError,
)
from closedloop.progress import progress

#: Starts of the generic assembly: the previous point's configuration (extrapolated),
#: or the closed-form geometry of CaHyMan, computed for a whole chunk at once.
STARTS = ("neighbour", "closed_form")
#: Exceptions recorded per point (anything else propagates).
POINT_ERRORS = (ClosedLoopError, np.linalg.LinAlgError)
#: Models kept per thread by the generic kernel (one per parameter set).
MODEL_CACHE_SIZE = 8
#: Relative tolerance on equal steps for extrapolating the warm start.
EQUAL_STEP_RTOL = 1e-9

_local = threading.local()


def status_code(error: Exception) -> int:
    """Status code of a point that raised ``error``."""
    if isinstance(error, InvalidInputError):
        return INVALID
    if isinstance(error, AssemblyError):
        return UNREACHABLE
    if isinstance(error, SingularConfigurationError | MechanismError | RigidDirectionsError):
        return SINGULAR
    return FAILED


def _message(error: Exception) -> str:
    return " ".join(str(error).split()) or type(error).__name__


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

    def __len__(self) -> int:
        return len(self.alpha4)


@dataclass
class ChunkResult:
    """What a chunk returns.

    Attributes:
        C: (c, 6, 6) compliance at M, world axes [SI]; NaN where the point failed.
        rank: (c,) rank of C from the generic solver, -1 otherwise (set later).
        status: (c,) status codes (:data:`cahyman_pin.sweep.indices.STATUS`).
        reasons: error message per failed point, by position in the chunk.
        iterations: (c,) Gauss-Newton iterations of the assembly (generic), else -1.
    """

    C: np.ndarray
    rank: np.ndarray
    status: np.ndarray
    reasons: dict[int, str] = field(default_factory=dict)
    iterations: np.ndarray | None = None

    @classmethod
    def empty(cls, n: int) -> ChunkResult:
        """Result for n points, all ``ok`` until recorded otherwise, C NaN."""
        return cls(
            C=np.full((n, 6, 6), np.nan),
            rank=np.full(n, -1, dtype=np.int8),
            status=np.zeros(n, dtype=np.int8),
            iterations=np.full(n, -1, dtype=np.int16),
        )

    def fail(self, i: int, error: Exception) -> None:
        """Record the failure of point i."""
        self.status[i] = status_code(error)
        self.reasons[i] = _message(error)


def _point_params(chunk: Chunk) -> Iterator[tuple[int, CaHyManParams | Exception]]:
    """(index, params) per point; params are rebuilt only where the design values change."""
    previous, params = None, chunk.params
    for i in range(len(chunk)):
        values = tuple(chunk.design[i].tolist())
        if values != previous:
            previous = values
            try:
                params = chunk.params.replace(**dict(zip(chunk.design_names, values, strict=True)))
            except InvalidInputError as e:
                params = e
        yield i, params


def _runs(chunk: Chunk, out: ChunkResult) -> Iterator[tuple[np.ndarray, CaHyManParams]]:
    """Runs of consecutive points sharing one parameter set (invalid sets recorded)."""
    start, current = 0, None
    items = [*_point_params(chunk), (len(chunk), None)]
    for i, params in items:
        if params is not current:
            if isinstance(current, CaHyManParams):
                yield np.arange(start, i), current
            elif current is not None:
                for j in range(start, i):
                    out.fail(j, current)
            start, current = i, params


def _prevalidate(chunk: Chunk, idx: np.ndarray, params: CaHyManParams, out: ChunkResult):
    """Points of ``idx`` whose inputs pass :func:`check_inputs` (others recorded)."""
    s4 = chunk.s4[idx]
    good = (
        np.all(np.isfinite(chunk.alpha[idx]), axis=1)
        & np.isfinite(chunk.alpha4[idx])
        & (s4 >= 0.0)
        & (s4 <= params.s4_max)
    )
    for i in idx[~good]:
        try:
            check_inputs(chunk.alpha[i], chunk.alpha4[i], chunk.s4[i], params)
        except InvalidInputError as e:
            out.fail(i, e)
    return idx[good]


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


def _warm_start(model: CaHyManModel, history: list, x: np.ndarray) -> np.ndarray | None:
    """Start configuration from the previous points: ``history`` holds (inputs, q) pairs.

    The previous q, or its linear extrapolation q1 + (q1 - q0) on the configuration
    manifold when the inputs x took the same step twice in a row.
    """
    if not history:
        return None
    x1, q1 = history[-1]
    if len(history) == 2:
        x0, q0 = history[0]
        step, last = x - x1, x1 - x0
        if np.max(np.abs(step - last)) <= EQUAL_STEP_RTOL * np.max(np.abs(last)):
            return pin.integrate(model.clm.model, q1, pin.difference(model.clm.model, q0, q1))
    return q1


def _assemble(model: CaHyManModel, alpha, alpha4: float, s4: float, q0):
    """Assembly from ``q0``; on failure, once more from the closed-form start."""
    try:
        return model.assemble(alpha, alpha4, s4, q0=q0, full_output=True)
    except AssemblyError:
        if q0 is None:
            raise
        return model.assemble(alpha, alpha4, s4, full_output=True)


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


def _closed_form_starts(chunk: Chunk, out: ChunkResult) -> dict[int, np.ndarray]:
    """Closed-form start configuration of every point, computed per run of parameters."""
    starts: dict[int, np.ndarray] = {}
    for idx, params in _runs(chunk, out):
        model = _model(params)

        def guesses(sub: np.ndarray, model=model) -> None:
            q = model.initial_guesses(chunk.alpha[sub], chunk.alpha4[sub], chunk.s4[sub])
            starts.update(zip(sub.tolist(), q, strict=True))

        _bisect(_prevalidate(chunk, idx, params, out), guesses, out)
    return starts


def _generic(chunk: Chunk, out: ChunkResult) -> None:
    starts = _closed_form_starts(chunk, out) if chunk.start == "closed_form" else None
    history: list = []
    x_all = np.column_stack([chunk.alpha, chunk.alpha4, chunk.s4, chunk.design])
    model = None
    for i, params in _point_params(chunk):
        if isinstance(params, Exception):
            out.fail(i, params)
        if out.status[i] != OK:  # invalid parameters or inputs, or no closed-form start
            history = []
            continue
        if model is None or model.params is not params:
            model = _model(params)
        try:
            q0 = _warm_start(model, history, x_all[i]) if starts is None else starts[i]
            result = _assemble(model, chunk.alpha[i], chunk.alpha4[i], chunk.s4[i], q0)
            c = compliance(model.clm, result.q, FRAME_M, "world", length=params.length)
        except POINT_ERRORS as e:
            out.fail(i, e)
            history = []
            continue
        out.C[i], out.rank[i], out.iterations[i] = c.C, c.rank, result.iterations
        history = [*history[-1:], (x_all[i], result.q)]


# ------------------------------------------------------------------ other kernels
def _consistent(chunk: Chunk, out: ChunkResult) -> None:
    for idx, params in _runs(chunk, out):

        def batch(sub: np.ndarray, params=params) -> None:
            out.C[sub] = consistent_compliance(
                chunk.alpha[sub], chunk.alpha4[sub], chunk.s4[sub], params
            )

        _bisect(_prevalidate(chunk, idx, params, out), batch, out)


def _pointwise(chunk: Chunk, out: ChunkResult) -> None:
    for idx, params in _runs(chunk, out):
        for i in _prevalidate(chunk, idx, params, out):
            try:
                out.C[i] = chunk.func(params, chunk.alpha[i], chunk.alpha4[i], chunk.s4[i]).C
            except POINT_ERRORS as e:
                out.fail(int(i), e)


_KERNELS = {"generic": _generic, "consistent": _consistent}


def run_chunk(chunk: Chunk) -> ChunkResult:
    """Compliance of every point of ``chunk`` (the task sent to an executor)."""
    out = ChunkResult.empty(len(chunk))
    _KERNELS.get(chunk.backend, _pointwise)(chunk, out)
    return out


# ------------------------------------------------------------------ executors
def default_workers() -> int:
    """Number of worker processes by default: the usable cores."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def run_chunks(
    chunks: Sequence[Chunk],
    executor: Executor | str = "processes",
    workers: int | None = None,
    show_progress: bool = False,
    label: str = "sweep",
) -> list[ChunkResult]:
    """Run every chunk and return the results in the order of ``chunks``.

    Args:
        chunks: the tasks.
        executor: ``"processes"`` (a local ``ProcessPoolExecutor`` with ``workers``
            processes, shut down at the end), ``"serial"`` (this process, no executor), or
            any ``concurrent.futures.Executor`` (e.g. a Dask ``Client.get_executor()``),
            used as given and left open.
        workers: processes of the ``"processes"`` pool (default: :func:`default_workers`).
        show_progress: draw a progress bar (points done) on stderr.
        label: label of the progress bar.
    """
    total = sum(len(c) for c in chunks)
    results: list[ChunkResult | None] = [None] * len(chunks)

    def serial() -> Iterator[None]:
        for k, chunk in enumerate(chunks):
            results[k] = run_chunk(chunk)
            yield from range(len(chunk))

    def pooled(ex: Executor) -> Iterator[None]:
        futures: dict[Future, int] = {ex.submit(run_chunk, c): k for k, c in enumerate(chunks)}
        try:
            for future in as_completed(futures):
                k = futures[future]
                results[k] = future.result()
                yield from range(len(chunks[k]))
        finally:
            for future in futures:
                future.cancel()

    def points() -> Iterator[None]:
        if executor == "serial":
            yield from serial()
        elif executor == "processes":
            pool = ProcessPoolExecutor(
                workers or default_workers(), initializer=single_threaded_blas
            )
            with pool as ex:
                yield from pooled(ex)
        elif isinstance(executor, Executor):
            yield from pooled(executor)
        else:
            raise InvalidInputError(
                f"executor {executor!r}; expected 'processes', 'serial' or a "
                "concurrent.futures.Executor"
            )

    for _ in progress(points(), total=total, label=label, enabled=show_progress):
        pass
    return results  # type: ignore[return-value]


# ------------------------------------------------------------------ indices


__all__ = [
    "POINT_ERRORS",
    "STARTS",
    "Chunk",
    "ChunkResult",
    "default_workers",
    "run_chunk",
    "run_chunks",
    "status_code",
]
