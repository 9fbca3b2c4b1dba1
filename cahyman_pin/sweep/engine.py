"""Stiffness maps and design sweeps of CaHyMan: many poses and parameter sets at once.

Example::

    import numpy as np
    from cahyman_pin.sweep import grid, sweep

    pts = grid({"alpha": np.deg2rad(np.linspace(30, 90, 61)), "b": np.linspace(0.04, 0.12, 9)},
               alpha4=np.deg2rad(60), s4=0.025)
    res = sweep(pts, wrench=[1, 1, 1, 0, 0, 0])     # generic backend, all cores
    res.grid_values("det_K")                          # (61, 9) [N^6/rad^3], NaN where failed
    res.save_npz("map.npz")

The points are a grid (:func:`grid`, any of the pose inputs alpha_1..3, alpha_4, s_4 and
any field of :class:`~cahyman_pin.params.CaHyManParams`) or a list (:func:`pose_list`).
Everything is SI: angles in rad, lengths in m, springs in N/m or N m/rad.

A grid is computed along a path that moves one grid step at a time (a boustrophedon:
rows alternate direction, design axes outermost so that the model changes rarely), so
that each generic assembly can start from its neighbour's configuration (``start=
"neighbour"``; by default it starts from the closed-form geometry). The path is cut
into chunks of contiguous points, one task each for a ``concurrent.futures.Executor``:
local processes by default, or any executor, e.g. Dask's ``Client.get_executor()``
(``pip install .[dask]``). Results do not depend on the executor. The path, the
chunks, the executors, the per-point arrays and the indices are those of every map of the
project (:mod:`closedloop.analysis.maps`,
:func:`closedloop.analysis.batch_indices.batch_indices`; at a point of cond(K_s) above 1e8,
det K and the condition numbers of :func:`cahyman_pin.api.stiffness`,
:func:`closedloop.analysis.complete.resolve_ill_conditioned`): the ``condition_number`` is the
unit-free one of the scaled K, ``condition_number_si`` that of the SI matrix
(:attr:`cahyman_pin.api.CaHyManStiffness.condition_number`). Only the kernels are
CaHyMan's (:mod:`cahyman_pin.sweep.execution`).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import os
import time
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cahyman_pin.backends.registry import check_closed_form, get_backend
from cahyman_pin.model import CaHyManModel
from cahyman_pin.params import WEIGHT_FIELDS, CaHyManParams
from cahyman_pin.sweep.execution import STARTS, Chunk, run_chunk
from cahyman_pin.sweep.points import (
    INPUT_UNITS,
    POSE_AXES,
    SweepPoints,
    grid,
    param_unit,
    pose_list,
)
from closedloop.analysis.interrupts import Interrupted
from closedloop.analysis.map_results import OK, RANK_DEFICIENT, STATUS, PointData
from closedloop.analysis.maps import ALL_INDICES, MODE_INDICES, column_name
from closedloop.analysis.tasks import gather, run_tasks_by_point
from closedloop.common.arrays import check_wrench, frozen, readonly
from closedloop.common.files import write_atomically
from closedloop.elastostatics.compliance import UNITS
from closedloop.exceptions import InvalidInputError

#: Largest sweep that :meth:`SweepResult.save` also writes as CSV.
CSV_MAX_POINTS = 20_000
#: Indices of a sweep and their units (SI), as every map of the project (``lowest_frequency``
#: with ``modes``); with a wrench, also ``deflection`` (n, 6), the twist of M [m, rad].
INDEX_UNITS = ALL_INDICES
#: Chunk size limits: long chunks amortise a task's overhead, many chunks balance the load.
MAX_CHUNK = {"consistent": 20_000}
#: Chunk size limit of a backend that :data:`MAX_CHUNK` does not name.
DEFAULT_MAX_CHUNK = 1_000
#: Chunks per worker by default: the last chunks, finishing alone, leave a core idle for
#: at most 1/16 of the run (a task costs about 1 ms of overhead).
CHUNKS_PER_WORKER = 16
#: Fewest points per task: a task costs about 1 ms, and each chunk's first point starts
#: afresh (from the closed form) with ``start="neighbour"``.
MIN_CHUNK = 64


@dataclass(frozen=True)
class SweepResult:
    """Stiffness indices over a sweep, in the storage order of ``points`` (read-only).

    Attributes:
        points: the inputs.
        backend: backend name.
        wrench: (6,) wrench at M for the deflection [N, N m], or None.
        indices: name -> (n,) value [SI] (units in :data:`INDEX_UNITS`), NaN where it does
            not exist; ``deflection`` (n, 6) when a wrench was given.
        data: the per-point arrays (:class:`closedloop.analysis.map_results.PointData`: C, rank,
            status and reason codes, assembly iterations).
        seconds: wall time of the computation [s].
    """

    points: SweepPoints
    backend: str
    wrench: np.ndarray | None
    indices: dict
    data: PointData
    seconds: float

    def __len__(self) -> int:
        return len(self.data.codes)

    @property
    def C(self) -> np.ndarray:
        """(n, 6, 6) compliance at M, world axes [SI]; NaN where the point failed."""
        return self.data.C

    @property
    def rank(self) -> np.ndarray:
        """(n,) rank of C (-1 where the point failed)."""
        return self.data.rank

    @property
    def status(self) -> np.ndarray:
        """(n,) status names (:data:`closedloop.analysis.map_results.STATUS`): ``ok``,
        ``rank_deficient`` (C exists, K does not), ``invalid``, ``unreachable``, ``singular``,
        ``failed``, ``not_computed`` (the sweep was interrupted first)."""
        return np.asarray(STATUS)[self.data.codes]

    @property
    def reasons(self) -> tuple[str, ...]:
        """(n,) error message per point ('' where ok), built on demand."""
        return tuple(np.asarray(self.data.reason_texts)[self.data.reason_codes].tolist())

    @property
    def iterations(self) -> np.ndarray:
        """(n,) Gauss-Newton iterations of each generic assembly (-1 otherwise)."""
        return self.data.iterations

    @property
    def ok(self) -> np.ndarray:
        """(n,) bool: the point was computed (status ``ok`` or ``rank_deficient``)."""
        return np.isin(self.data.codes, (OK, RANK_DEFICIENT))

    def grid_values(self, name: str) -> np.ndarray:
        """Index ``name`` reshaped to the grid shape (the trailing 6 of ``deflection`` kept)."""
        if name not in self.indices:
            raise InvalidInputError(f"unknown index {name!r}; expected one of {list(self.indices)}")
        v = self.indices[name]
        return v.reshape(*self.points.shape, *v.shape[1:])

    def failures(self) -> list[tuple[int, str, str]]:
        """(index, status, reason) of every point that was not computed."""
        texts = self.data.reason_texts
        return [(int(i), STATUS[self.data.codes[i]], texts[self.data.reason_codes[i]])
                for i in np.flatnonzero(~self.ok)]  # fmt: skip

    def summary(self) -> str:
        """One line: number of points, how many per status, wall time."""
        counts = np.bincount(self.data.codes, minlength=len(STATUS))
        parts = ", ".join(f"{c} {s}" for s, c in zip(STATUS, counts, strict=True) if c)
        return f"{len(self)} points ({parts}) in {self.seconds:.2f} s, backend {self.backend}"

    # ------------------------------------------------------------------ files
    def columns(self) -> dict[str, np.ndarray]:
        """Flat table: inputs, design values, status, indices (SI; names carry the unit,
        :func:`closedloop.analysis.maps.column_name`)."""
        p = self.points
        cols = {f"alpha{k + 1}_rad": p.alpha[:, k] for k in range(3)}
        cols.update(alpha4_rad=p.alpha4, s4_m=p.s4)
        cols.update({column_name(k, param_unit(k)): v for k, v in p.design.items()})
        cols.update(status=self.status, rank=self.rank)
        for name, v in self.indices.items():
            if v.ndim == 1:
                cols[column_name(name, INDEX_UNITS[name])] = v
        if "deflection" in self.indices:
            for j, lab in enumerate(("dx_m", "dy_m", "dz_m", "rx_rad", "ry_rad", "rz_rad")):
                cols[f"deflection_{lab}"] = self.indices["deflection"][:, j]
        cols["reason"] = np.asarray(self.reasons, dtype=object)
        return cols

    def save_csv(self, path) -> Path:
        """Write :meth:`columns` as CSV (one row per point); returns the path."""
        cols = self.columns()

        def write(f) -> None:
            writer = csv.writer(f)
            writer.writerow(list(cols))
            for row in zip(*(c.tolist() for c in cols.values()), strict=True):
                writer.writerow([repr(x) if isinstance(x, float) else x for x in row])

        return write_atomically(path, write, text=True, newline="")

    def save_parquet(self, path) -> Path:
        """Write :meth:`columns` as Parquet (needs pyarrow, which is not a dependency)."""
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError as err:
            raise InvalidInputError("Parquet needs pyarrow: pip install pyarrow") from err
        cols = {k: v.tolist() if v.dtype == object else v for k, v in self.columns().items()}
        table = pa.table(cols)
        return write_atomically(path, lambda f: pq.write_table(table, f))

    def save_npz(self, path) -> Path:
        """Write everything (inputs, C, indices, status, reasons, metadata) as NPZ."""
        p = self.points
        meta = {
            "backend": self.backend,
            "params": dataclasses.asdict(p.params),
            "shape": list(p.shape),
            "axes": [a for a, _ in p.axes],
            "design": list(p.design),
            "indices": list(self.indices),
            "seconds": self.seconds,
            "units": {
                **INPUT_UNITS,
                **{f"design_{k}": param_unit(k) for k in p.design},
                **INDEX_UNITS,
                "deflection": UNITS["twist"],
                "C": UNITS["C"],
                "wrench": UNITS["wrench"],
                "length": "m",
            },
        }
        arrays = {
            "alpha": p.alpha, "alpha4": p.alpha4, "s4": p.s4, "order": p.order, "C": self.C,
            "rank": self.rank, "status": self.status, "length": self.data.length,
            "reason_texts": np.asarray(self.data.reason_texts),
            "reason_codes": self.data.reason_codes, "iterations": self.iterations,
            "wrench": np.full(6, np.nan) if self.wrench is None else self.wrench,
            "meta": np.array(json.dumps(meta)),
        }  # fmt: skip
        arrays.update({f"design_{k}": v for k, v in p.design.items()})
        arrays.update({f"axis_{k}": v for k, v in p.axes})
        arrays.update({f"index_{k}": v for k, v in self.indices.items()})
        return write_atomically(path, lambda f: np.savez_compressed(f, **arrays))

    @classmethod
    def load_npz(cls, path) -> SweepResult:
        """Read a file written by :meth:`save_npz`."""
        with np.load(path, allow_pickle=False) as f:
            meta = json.loads(str(f["meta"]))
            points = SweepPoints(
                alpha=readonly(f["alpha"]), alpha4=readonly(f["alpha4"]), s4=readonly(f["s4"]),
                design={k: readonly(f[f"design_{k}"]) for k in meta["design"]},
                params=CaHyManParams(**meta["params"]), shape=tuple(meta["shape"]),
                axes=tuple((a, readonly(f[f"axis_{a}"])) for a in meta["axes"]),
                order=f["order"],
            )  # fmt: skip
            wrench = None if np.all(np.isnan(f["wrench"])) else readonly(f["wrench"])
            names, inverse = np.unique(f["status"], return_inverse=True)
            codes = np.array([STATUS.index(name) for name in names], dtype=np.int8)[inverse]
            data = PointData(
                C=readonly(f["C"]), rank=frozen(f["rank"]), codes=frozen(codes.reshape(-1)),
                condition=readonly(f["index_condition_number"]),
                length=readonly(f["length"]), iterations=frozen(f["iterations"]),
                reason_codes=frozen(f["reason_codes"]),
                reason_texts=f["reason_texts"].tolist(),
            )  # fmt: skip
            return cls(
                points=points, backend=meta["backend"], wrench=wrench,
                indices={k: readonly(f[f"index_{k}"]) for k in meta["indices"]},
                data=data, seconds=float(meta["seconds"]),
            )  # fmt: skip

    def save(self, directory, stem: str = "sweep") -> list[Path]:
        """NPZ always, CSV too when there are at most :data:`CSV_MAX_POINTS` points (else
        an earlier sweep's CSV of that name is removed: it would disagree with the NPZ)."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        paths = [self.save_npz(directory / f"{stem}.npz")]
        if len(self) <= CSV_MAX_POINTS:
            paths.append(self.save_csv(directory / f"{stem}.csv"))
        else:
            (directory / f"{stem}.csv").unlink(missing_ok=True)
        return paths


def _chunks(points: SweepPoints, backend: str, start: str, pieces: list, wrench,
            modes: bool) -> list[Chunk]:  # fmt: skip
    func = get_backend(backend)
    names = tuple(points.design)
    design = np.column_stack([points.design[k] for k in names]) if names else None
    return [
        Chunk(
            backend=backend,
            start=start,
            func=func,
            params=points.params,
            design_names=names,
            alpha=points.alpha[idx],
            alpha4=points.alpha4[idx],
            s4=points.s4[idx],
            design=np.zeros((idx.size, 0)) if design is None else design[idx],
            wrench=wrench,
            modes=modes,
        )
        for idx in pieces
    ]


def default_chunk_size(n: int, backend: str, workers: int) -> int:
    """Points per task: one task per :data:`DEFAULT_MAX_CHUNK` points serially (:data:`MAX_CHUNK`
    for the batched closed form), else about :data:`CHUNKS_PER_WORKER` tasks per worker
    of at least :data:`MIN_CHUNK` points."""
    limit = MAX_CHUNK.get(backend, DEFAULT_MAX_CHUNK)
    if workers <= 1:
        return limit
    return int(min(max(-(-n // (CHUNKS_PER_WORKER * workers)), MIN_CHUNK), limit))


def _executor(executor, workers: int | None) -> tuple[Executor | None, int]:
    """(executor, local processes) of :func:`closedloop.analysis.map_engine.run_tasks`."""
    if executor == "serial":
        return None, 1
    if executor == "processes":
        return None, workers or default_workers()
    if isinstance(executor, Executor):
        return executor, 1
    raise InvalidInputError(
        f"executor {executor!r}; expected 'processes', 'serial' or a concurrent.futures.Executor"
    )


def default_workers() -> int:
    """Number of worker processes by default: the usable cores."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def sweep(
    points: SweepPoints,
    *,
    backend: str = "generic",
    wrench=None,
    start: str = "closed_form",
    executor: Executor | str = "processes",
    workers: int | None = None,
    chunk_size: int | None = None,
    show_progress: bool = False,
    modes: bool = False,
) -> SweepResult:
    """Compliance and stiffness indices of CaHyMan at every point of a sweep.

    Args:
        points: from :func:`grid` or :func:`pose_list`.
        backend: ``"generic"`` (Pinocchio, warm-started along the path), ``"consistent"``
            (closed form, vectorised over each chunk), ``"published"`` or any registered
            backend (see :func:`cahyman_pin.backends.registry.backend_names`).
        wrench: (6,) wrench at M (fx, fy, fz [N], nx, ny, nz [N m]), world axes, for the
            ``deflection`` indices; None for none.
        start: generic backend only: where each assembly starts, ``"closed_form"``
            (default: CaHyMan's closed-form geometry, exact, computed per chunk at once;
            faster, and the same start as :func:`cahyman_pin.api.stiffness`) or
            ``"neighbour"`` (the previous point's configuration, extrapolated along
            equal steps; the first point of each chunk from the closed form). The two
            starts reach configurations within the assembly tolerance of each other; a
            point so near a singular pose that the rank rule decides on differences of
            that size may be answered from one start and refused from the other.
        executor: ``"processes"`` (local process pool, default), ``"serial"``, or any
            ``concurrent.futures.Executor`` (e.g. ``dask.distributed.Client.get_executor()``);
            tasks are pickled, so a registered backend must be importable by the workers.
        workers: processes of the local pool (default: every usable core).
        chunk_size: points per task (default :func:`default_chunk_size`); with
            ``start="neighbour"`` each chunk's first point starts from the closed form, so
            the results depend on it (within the assembly tolerance), not on the executor.
        show_progress: progress bar on stderr.
        modes: also the index ``lowest_frequency`` [Hz]: the lowest nonzero natural
            frequency at every point (:func:`closedloop.analysis.vibration.modes` at M's
            assembled configuration, rigid-body modes skipped; NaN where it has none),
            generic backend only; the masses are the parameters' ``m_*`` (give them: they
            are 0 by default).

    Raises:
        InvalidInputError: unknown backend or start, bad wrench or executor, links as
            beams with a closed-form backend (:func:`check_closed_form`),
            ``modes`` with another backend than ``"generic"``.
        ModesError: ``modes`` and no mass at any point.
            A point that cannot be computed does not raise: it is marked in ``status`` and
            ``reasons``.
        Interrupted: a ``KeyboardInterrupt`` (Ctrl-C, SIGINT) or SIGTERM during the sweep
            (:class:`closedloop.analysis.interrupts.Interrupted`, itself a ``KeyboardInterrupt``):
            the worker processes are ended at once (none is left), and the sweep so far is
            its ``partial``: a :class:`SweepResult` whose points not computed have status
            ``not_computed`` and reason ``interrupted by SIGINT`` (or ``SIGTERM``), values
            NaN. A SIGTERM handler is installed only while the sweep runs, in the main
            thread, where SIGTERM would end the process.
    """
    if not isinstance(points, SweepPoints):
        raise InvalidInputError(f"points must be SweepPoints, got {type(points).__name__}")
    w = None if wrench is None else readonly(check_wrench(wrench))
    if start not in STARTS:
        raise InvalidInputError(f"start {start!r}; expected one of {list(STARTS)}")
    check_closed_form(points.params, backend)
    if modes:
        _check_modes(points, backend)
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise InvalidInputError(f"workers must be a positive integer, got {workers!r}")
    pool, n_workers = _executor(executor, workers)
    size = default_chunk_size(len(points), backend, n_workers) if chunk_size is None else chunk_size
    if not isinstance(size, int) or size < 1:
        raise InvalidInputError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    t0 = time.perf_counter()
    n = len(points)
    pieces = [points.order[f : f + size] for f in range(0, n, size)]
    chunks = _chunks(points, backend, start, pieces, w, modes)

    results = run_tasks_by_point(run_chunk, chunks, [len(p) for p in pieces], pool, n_workers,
                                 label=f"{backend} sweep", show_progress=show_progress)  # fmt: skip
    try:
        data = gather(n, pieces, results, w, MODE_INDICES if modes else ())
    except Interrupted as stop:
        if stop.data is not None:  # else stopped before gather began
            stop.partial = _result(points, backend, w, stop.data, time.perf_counter() - t0)
        raise
    return _result(points, backend, w, data, time.perf_counter() - t0)


def _check_modes(points: SweepPoints, backend: str) -> None:
    """Refuse ``modes`` with a closed form (no masses) or a sweep without any mass."""
    if backend != "generic":
        raise InvalidInputError(
            f"the index lowest_frequency needs the generic backend (the closed forms have no "
            f"masses), got backend {backend!r}"
        )
    from closedloop.analysis.vibration import check_massive  # on demand, as the maps'

    swept = [points.design[k] for k in WEIGHT_FIELDS if k in points.design and k != "gravity"]
    if not any(np.any(values > 0.0) for values in swept):  # the masses: the fixed ones
        check_massive(CaHyManModel(points.params).clm)


def _result(points: SweepPoints, backend: str, w, data: PointData, seconds: float) -> SweepResult:
    """The :class:`SweepResult` of the arrays of :func:`sweep` (made read-only)."""
    indices = data.indices
    if w is not None:
        indices["deflection"] = data.C @ w
    arrays = (data.C, data.rank, data.codes, data.iterations, data.length, data.reason_codes)
    for a in (*arrays, *indices.values()):  # the indices are the data's, not copies
        a.flags.writeable = False
    return SweepResult(
        points=points, backend=backend, wrench=w, indices=indices, data=data, seconds=seconds
    )


__all__ = [
    "CSV_MAX_POINTS",
    "INDEX_UNITS",
    "POSE_AXES",
    "SweepPoints",
    "SweepResult",
    "default_chunk_size",
    "grid",
    "pose_list",
    "sweep",
]
