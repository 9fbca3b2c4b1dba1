"""The tasks of a map run on an executor, and their results gathered into per-point arrays.

:func:`run_tasks` computes the chunks in this process, on local processes or on any
``concurrent.futures.Executor`` (e.g. Dask's ``Client.get_executor()``): the results do not
depend on the executor. :func:`gather` puts their results into a
:class:`~closedloop.analysis.map_results.PointData`; SIGINT and SIGTERM stop it
(:mod:`closedloop.analysis.interrupts`), the chunks not received marked ``not_computed``.
"""

from __future__ import annotations

import contextlib
import itertools
import multiprocessing
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool

import numpy as np

from closedloop.analysis.complete import complete
from closedloop.analysis.interrupts import (
    Interrupted,
    signals_blocked,
    start_worker,
    stop_on_signals,
)
from closedloop.analysis.map_results import NOT_COMPUTED, ChunkResult, PointData
from closedloop.common.progress import progress
from closedloop.exceptions import ClusterError, InvalidInputError

#: Points per task when not given: enough to amortise a task's overhead (pickling, the
#: model load in a fresh process), small enough for a few tasks per core.
CHUNK = 500


def _end_pool(pool: ProcessPoolExecutor, others: set) -> None:
    """End the processes of ``pool`` at once, their running tasks with them (the executor
    has no way to stop a running task: its processes are the children of this process
    started since it was made, ``multiprocessing.active_children()`` but ``others``), then
    its thread, which finds them gone and fails the pending tasks (none may be cancelled
    first: the thread of Python 3.11 raises on a cancelled one, with a traceback)."""
    processes = [p for p in multiprocessing.active_children() if p not in others]
    for process in processes:
        process.kill()
    for process in processes:
        process.join()
    pool.shutdown()


def run_tasks(
    kernel: Callable,
    tasks: Sequence,
    executor: Executor | None = None,
    workers: int | None = None,
) -> Iterator[tuple[int, ChunkResult]]:
    """Yield (task index, ``kernel(task)``) as the tasks finish.

    Stopped early (an exception, e.g. :class:`~closedloop.analysis.interrupts.Interrupted` or
    ``KeyboardInterrupt``, or the generator closed), the tasks not started are cancelled and
    the local processes ended at once, their running tasks lost; an executor's running tasks
    are left to it.

    Args:
        kernel: picklable callable (a module-level function) for process executors.
        tasks: the tasks (picklable for process executors).
        executor: any ``concurrent.futures.Executor``, used as given and left open.
        workers: without an executor, local processes (a pool ended at the end), at most
            one per task and per core (more would only wait); None or 1: this process.
            They ignore SIGINT and end with this process
            (:func:`~closedloop.analysis.interrupts.start_worker`).

    Raises:
        InvalidInputError: ``workers`` not a positive integer.
        ClusterError: a local process ended abruptly (killed) during a task.
    """
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise InvalidInputError(f"workers must be a positive integer, got {workers!r}")
    if executor is None and workers is not None:
        workers = min(workers, len(tasks), os.cpu_count() or 1)
    if executor is None and (workers or 1) == 1:
        for k, task in enumerate(tasks):
            yield k, kernel(task)
        return
    pool, futures, finished = executor, {}, False
    others = set(multiprocessing.active_children())  # not the pool's
    try:
        with signals_blocked():  # the processes are started here
            if executor is None:
                pool = ProcessPoolExecutor(workers, initializer=start_worker)
            futures = {pool.submit(kernel, task): k for k, task in enumerate(tasks)}
        for future in as_completed(futures):
            try:
                result = future.result()
            except BrokenProcessPool:
                raise ClusterError(
                    "a worker process of the map ended abruptly (killed, or out "
                    "of memory?); the map stopped, the others ended"
                ) from None
            yield futures[future], result
        finished = True
    finally:
        if executor is not None:
            for future in futures:
                future.cancel()
        elif pool is not None and finished:
            pool.shutdown()
        elif pool is not None:
            _end_pool(pool, others)


@contextlib.contextmanager
def local_processes(workers: int | None):
    """A pool of ``workers`` local processes kept for several :func:`run_tasks` (its
    ``executor``; an optimiser's generations), or None (this process) for None or 1.

    The processes start in :func:`run_tasks`, as its own do (signals blocked, then
    :func:`~closedloop.analysis.interrupts.start_worker`); the pool is shut down at the end
    of the block, or its processes ended at once, their running tasks with them, when the
    block ends by an exception (an interruption).

    Raises:
        InvalidInputError: ``workers`` not a positive integer.
    """
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise InvalidInputError(f"workers must be a positive integer, got {workers!r}")
    if (workers or 1) == 1:
        yield None
        return
    others = set(multiprocessing.active_children())  # not the pool's
    pool = ProcessPoolExecutor(min(workers, os.cpu_count() or 1), initializer=start_worker)
    try:
        yield pool
    except BaseException:
        _end_pool(pool, others)
        raise
    pool.shutdown()


def run_tasks_by_point(
    kernel: Callable,
    tasks: Sequence,
    sizes: Sequence[int],
    executor: Executor | None = None,
    workers: int | None = None,
    *,
    label: str = "",
    show_progress: bool = False,
) -> Iterator[tuple[int, ChunkResult]]:
    """:func:`run_tasks`, its progress shown in points (task k holds ``sizes[k]`` points)
    by :func:`closedloop.common.progress.progress` on stderr when ``show_progress``; closed or
    stopped by an exception, it stops the tasks at once (:func:`run_tasks`)."""
    running = run_tasks(kernel, tasks, executor, workers)

    def by_point():
        for k, result in running:
            yield k, result
            yield from itertools.repeat(None, sizes[k] - 1)

    try:
        done = progress(by_point(), total=sum(sizes), label=label, enabled=show_progress)
        yield from (item for item in done if item is not None)
    finally:
        running.close()


def gather(
    n: int, pieces: Sequence[np.ndarray], results: Iterator, wrench=None, extra: Sequence = ()
) -> PointData:
    """Per-point arrays from the results of the chunks.

    SIGINT and SIGTERM stop it (:func:`~closedloop.analysis.interrupts.stop_on_signals`), as a
    ``KeyboardInterrupt`` does: ``results`` is closed (which ends the workers of
    :func:`run_tasks`) and :class:`~closedloop.analysis.interrupts.Interrupted` raised, its
    ``data`` the arrays so far, the points of the chunks not received ``not_computed``.

    Args:
        n: number of points.
        pieces: storage indices of each chunk's points, in chunk order.
        results: (chunk index, :class:`~closedloop.analysis.map_results.ChunkResult`) pairs
            in any order (e.g. :func:`run_tasks`).
        wrench: (6,) wrench of the chunks' deflection indices [N, N m], or None: the
            indices of a map whose chunks are all lost (their names).
        extra: names of the further indices the chunks give (``lowest_frequency``), NaN
            in a map whose chunks are all lost.

    Raises:
        Interrupted: by SIGINT (or a ``KeyboardInterrupt``) or SIGTERM.
    """
    data, received = None, np.zeros(len(pieces), dtype=bool)
    with stop_on_signals():
        try:
            data = _no_points(n)
            for k, r in results:
                p = pieces[k]
                for name, values in r.indices.items():
                    data.indices.setdefault(name, np.full(n, np.nan))[p] = values
                data.C[p], data.rank[p], data.codes[p] = r.C, r.rank, r.status
                data.condition[p] = r.condition
                data.length[p], data.iterations[p] = r.length, r.iterations
                for i, text in r.reasons.items():
                    data.set_reason(p[i], text)
                received[k] = True
        except KeyboardInterrupt as e:
            stop = e if isinstance(e, Interrupted) else Interrupted()
            getattr(results, "close", lambda: None)()
            data = _no_points(n) if data is None else data
            lost = [pieces[k] for k in np.flatnonzero(~received)]
            _not_computed(data, lost, wrench, extra, stop)
            if stop is e:
                raise
            raise stop from None
    return data


def _no_points(n: int) -> PointData:
    """The arrays of n points before any is received (status ``ok``, values NaN)."""
    return PointData(C=np.full((n, 6, 6), np.nan), rank=np.full(n, -1, dtype=np.int8),
                     condition=np.full(n, np.nan), codes=np.zeros(n, dtype=np.int8),
                     length=np.full(n, np.nan), iterations=np.full(n, -1, dtype=np.int16),
                     reason_codes=np.zeros(n, dtype=np.int32), reason_texts=[""])  # fmt: skip


def _not_computed(data: PointData, pieces: list, wrench, extra, stop: Interrupted) -> None:
    """Mark the points of ``pieces`` not computed (in place), attach ``data`` to ``stop``."""
    empty = ChunkResult.empty(0)
    complete(empty, wrench)
    for name in (*empty.indices, *extra):
        data.indices.setdefault(name, np.full(len(data.codes), np.nan))
    p = np.concatenate([np.zeros(0, dtype=np.intp), *pieces]).astype(np.intp)
    data.C[p], data.rank[p], data.condition[p], data.codes[p] = np.nan, -1, np.nan, NOT_COMPUTED
    data.length[p], data.iterations[p] = np.nan, -1
    for values in data.indices.values():
        values[p] = np.nan
    if p.size:
        data.set_reason(p[0], stop.reason)
        data.reason_codes[p] = data.reason_codes[p[0]]
    stop.data = data
