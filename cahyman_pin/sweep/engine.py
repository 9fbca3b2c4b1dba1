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
(``pip install .[dask]``). Results do not depend on the executor. Execution details
are in :mod:`cahyman_pin.sweep.execution`.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import time
from concurrent.futures import Executor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cahyman_pin.api import get_backend
from cahyman_pin.params import CaHyManParams
from cahyman_pin.sweep.execution import STARTS, Chunk, default_workers, run_chunks
from cahyman_pin.sweep.indices import INDEX_UNITS, STATUS, classify, stiffness_indices
from cahyman_pin.sweep.points import (
    INPUT_UNITS,
    POSE_AXES,
    SweepPoints,
    grid,
    param_unit,
    pose_list,
)
from closedloop.arrays import check_wrench, readonly
from closedloop.exceptions import InvalidInputError

#: Largest sweep that :meth:`SweepResult.save` also writes as CSV.
CSV_MAX_POINTS = 20_000
#: Chunk size limits: long chunks keep the warm start going, many chunks balance the load.
MAX_CHUNK = {"consistent": 20_000}
DEFAULT_MAX_CHUNK = 1_000


def _slug(unit: str) -> str:
    """A unit as part of a column name: 'N m/rad' -> 'Nm_per_rad'."""
    return unit.replace(" ", "").replace("/", "_per_")


@dataclass(frozen=True)
class SweepResult:
    """Stiffness indices over a sweep, in the storage order of ``points`` (read-only).

    Attributes:
        points: the inputs.
        backend: backend name.
        wrench: (6,) wrench at M for the deflection [N, N m], or None.
        C: (n, 6, 6) compliance at M, world axes [SI]; NaN where the point failed.
        rank: (n,) rank of C (-1 where the point failed).
        status: (n,) status names (see :data:`cahyman_pin.sweep.execution.STATUS`): ``ok``,
            ``rank_deficient`` (C exists, K does not), ``invalid``, ``unreachable``,
            ``singular``, ``failed``.
        reasons: (n,) error message per point ('' where ok).
        indices: name -> (n,) value [SI] (units in :data:`INDEX_UNITS`), NaN where it does
            not exist; ``deflection`` (n, 6) when a wrench was given.
        iterations: (n,) Gauss-Newton iterations of each generic assembly (-1 otherwise).
        seconds: wall time of the computation [s].
    """

    points: SweepPoints
    backend: str
    wrench: np.ndarray | None
    C: np.ndarray
    rank: np.ndarray
    status: np.ndarray
    reasons: tuple
    indices: dict
    iterations: np.ndarray
    seconds: float

    def __len__(self) -> int:
        return len(self.rank)

    @property
    def ok(self) -> np.ndarray:
        """(n,) bool: the point was computed (status ``ok`` or ``rank_deficient``)."""
        return np.isin(self.status, ("ok", "rank_deficient"))

    def grid_values(self, name: str) -> np.ndarray:
        """Index ``name`` reshaped to the grid shape (the trailing 6 of ``deflection`` kept)."""
        if name not in self.indices:
            raise InvalidInputError(f"unknown index {name!r}; expected one of {list(self.indices)}")
        v = self.indices[name]
        return v.reshape(*self.points.shape, *v.shape[1:])

    def failures(self) -> list[tuple[int, str, str]]:
        """(index, status, reason) of every point that was not computed."""
        return [(int(i), str(self.status[i]), self.reasons[i]) for i in np.flatnonzero(~self.ok)]

    def summary(self) -> str:
        """One line: number of points, how many per status, wall time."""
        names, counts = np.unique(self.status, return_counts=True)
        parts = ", ".join(f"{c} {s}" for s, c in zip(names, counts, strict=True))
        return f"{len(self)} points ({parts}) in {self.seconds:.2f} s, backend {self.backend}"

    # ------------------------------------------------------------------ files
    def columns(self) -> dict[str, np.ndarray]:
        """Flat table: inputs, design values, status, indices (SI; names carry the unit)."""
        p = self.points
        cols = {f"alpha{k + 1}_rad": p.alpha[:, k] for k in range(3)}
        cols.update(alpha4_rad=p.alpha4, s4_m=p.s4)
        cols.update({f"{k}_{_slug(param_unit(k))}": v for k, v in p.design.items()})
        cols.update(status=self.status, rank=self.rank)
        for name, v in self.indices.items():
            if v.ndim == 1:
                cols[name] = v
        if "deflection" in self.indices:
            for j, lab in enumerate(("dx_m", "dy_m", "dz_m", "rx_rad", "ry_rad", "rz_rad")):
                cols[f"deflection_{lab}"] = self.indices["deflection"][:, j]
        cols["reason"] = np.asarray(self.reasons, dtype=object)
        return cols

    def save_csv(self, path) -> Path:
        """Write :meth:`columns` as CSV (one row per point); returns the path."""
        path = Path(path)
        cols = self.columns()
        with path.open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(list(cols))
            for row in zip(*(c.tolist() for c in cols.values()), strict=True):
                writer.writerow([repr(x) if isinstance(x, float) else x for x in row])
        return path

    def save_parquet(self, path) -> Path:
        """Write :meth:`columns` as Parquet (needs pyarrow, which is not a dependency)."""
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError as err:
            raise InvalidInputError("Parquet needs pyarrow: pip install pyarrow") from err
        cols = {k: v.tolist() if v.dtype == object else v for k, v in self.columns().items()}
        pq.write_table(pa.table(cols), str(path))
        return Path(path)

    def save_npz(self, path) -> Path:
        """Write everything (inputs, C, indices, status, reasons, metadata) as NPZ."""
        p = self.points
        texts, codes = np.unique(np.asarray(self.reasons, dtype=str), return_inverse=True)
        meta = {
            "backend": self.backend,
            "params": dataclasses.asdict(p.params),
            "shape": list(p.shape),
            "axes": [a for a, _ in p.axes],
            "design": list(p.design),
            "indices": list(self.indices),
            "seconds": self.seconds,
            "units": {**INPUT_UNITS, **INDEX_UNITS, "C": "m/N, rad/N, m/(N m), rad/(N m)"},
        }
        arrays = {
            "alpha": p.alpha, "alpha4": p.alpha4, "s4": p.s4, "order": p.order, "C": self.C,
            "rank": self.rank, "status": self.status, "reason_texts": texts,
            "reason_codes": codes.astype(np.int32), "iterations": self.iterations,
            "wrench": np.full(6, np.nan) if self.wrench is None else self.wrench,
            "meta": np.array(json.dumps(meta)),
        }  # fmt: skip
        arrays.update({f"design_{k}": v for k, v in p.design.items()})
        arrays.update({f"axis_{k}": v for k, v in p.axes})
        arrays.update({f"index_{k}": v for k, v in self.indices.items()})
        path = Path(path)
        np.savez_compressed(path, **arrays)
        return path

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
            return cls(
                points=points, backend=meta["backend"], wrench=wrench, C=readonly(f["C"]),
                rank=f["rank"], status=f["status"],
                reasons=tuple(f["reason_texts"][f["reason_codes"]].tolist()),
                indices={k: readonly(f[f"index_{k}"]) for k in meta["indices"]},
                iterations=f["iterations"], seconds=float(meta["seconds"]),
            )  # fmt: skip

    def save(self, directory, stem: str = "sweep") -> list[Path]:
        """NPZ always, CSV too when there are at most :data:`CSV_MAX_POINTS` points."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        paths = [self.save_npz(directory / f"{stem}.npz")]
        if len(self) <= CSV_MAX_POINTS:
            paths.append(self.save_csv(directory / f"{stem}.csv"))
        return paths


def _chunks(points: SweepPoints, backend: str, start: str, chunk_size: int) -> list[Chunk]:
    func = get_backend(backend)
    names = tuple(points.design)
    design = np.column_stack([points.design[k] for k in names]) if names else None
    out = []
    for first in range(0, len(points), chunk_size):
        idx = points.order[first : first + chunk_size]
        out.append(
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
            )
        )
    return out


def default_chunk_size(n: int, backend: str, workers: int) -> int:
    """About four chunks per worker, at most 1000 points (20000 for the closed form)."""
    limit = MAX_CHUNK.get(backend, DEFAULT_MAX_CHUNK)
    return int(min(max(-(-n // (4 * max(workers, 1))), 1), limit))


def _lengths(points: SweepPoints) -> np.ndarray:
    """(n,) characteristic length [m] of the machine at each point (``params.length``),
    computed once per distinct design; invalid designs (failed points) get the base one."""
    n, base = len(points), points.params.length
    if not points.design:
        return np.full(n, base)
    names = list(points.design)
    rows, inverse = np.unique(
        np.column_stack([points.design[k] for k in names]), axis=0, return_inverse=True
    )
    values = []
    for row in rows:
        try:
            values.append(
                points.params.replace(**dict(zip(names, row.tolist(), strict=True))).length
            )
        except InvalidInputError:
            values.append(base)
    return np.asarray(values)[inverse.reshape(-1)]


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
) -> SweepResult:
    """Compliance and stiffness indices of CaHyMan at every point of a sweep.

    Args:
        points: from :func:`grid` or :func:`pose_list`.
        backend: ``"generic"`` (Pinocchio, warm-started along the path), ``"consistent"``
            (closed form, vectorised over each chunk), ``"published"`` or any registered
            backend (see :func:`cahyman_pin.api.backend_names`).
        wrench: (6,) wrench at M (fx, fy, fz [N], nx, ny, nz [N m]), world axes, for the
            ``deflection`` indices; None for none.
        start: generic backend only: where each assembly starts, ``"closed_form"``
            (default: CaHyMan's closed-form geometry, exact, computed per chunk at once;
            faster, and the same start as :func:`cahyman_pin.api.stiffness`) or
            ``"neighbour"`` (the previous point's configuration, extrapolated along the
            path: for variants of the machine without a closed form).
        executor: ``"processes"`` (local process pool, default), ``"serial"``, or any
            ``concurrent.futures.Executor`` (e.g. ``dask.distributed.Client.get_executor()``);
            tasks are pickled, so a registered backend must be importable by the workers.
        workers: processes of the local pool (default: every usable core).
        chunk_size: points per task (default :func:`default_chunk_size`); each chunk
            starts cold, so the results depend on it (slightly: within the assembly
            tolerance), not on the executor.
        show_progress: progress bar on stderr.

    Raises:
        InvalidInputError: unknown backend or start, bad wrench or executor. A point that
            cannot be computed does not raise: it is marked in ``status`` and ``reasons``.
    """
    if not isinstance(points, SweepPoints):
        raise InvalidInputError(f"points must be SweepPoints, got {type(points).__name__}")
    w = None if wrench is None else readonly(check_wrench(wrench))
    if start not in STARTS:
        raise InvalidInputError(f"start {start!r}; expected one of {list(STARTS)}")
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise InvalidInputError(f"workers must be a positive integer, got {workers!r}")
    n_workers = workers or (1 if executor == "serial" else default_workers())
    size = chunk_size or default_chunk_size(len(points), backend, n_workers)
    if not isinstance(size, int) or size < 1:
        raise InvalidInputError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    t0 = time.perf_counter()
    chunks = _chunks(points, backend, start, size)
    results = run_chunks(chunks, executor, workers, show_progress, f"{backend} sweep")
    n = len(points)
    C, rank = np.full((n, 6, 6), np.nan), np.full(n, -1, dtype=np.int8)
    codes, iterations = np.zeros(n, dtype=np.int8), np.full(n, -1, dtype=np.int16)
    reasons = [""] * n
    offset = 0
    for r in results:
        idx = points.order[offset : offset + len(r.rank)]
        C[idx], rank[idx], codes[idx], iterations[idx] = r.C, r.rank, r.status, r.iterations
        for i, text in r.reasons.items():
            reasons[idx[i]] = text
        offset += len(r.rank)
    symmetric = classify(C, rank, codes, reasons, _lengths(points))
    indices = stiffness_indices(C, codes == STATUS.index("ok"), symmetric, w)
    return SweepResult(
        points=points,
        backend=backend,
        wrench=w,
        C=readonly(C),
        rank=rank,
        status=np.asarray(STATUS)[codes],
        reasons=tuple(reasons),
        indices={k: readonly(v) for k, v in indices.items()},
        iterations=iterations,
        seconds=time.perf_counter() - t0,
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
