"""Stiffness maps of any robot over its workspace.

A map computes the compliance at a frame for many inputs (actuated values, SI), on the sweep engine
of :mod:`closedloop.analysis.map_engine` (path, chunks, kernel; executors in
:mod:`closedloop.analysis.tasks`), with the indices of each chunk's points at once
(:func:`closedloop.analysis.batch_indices.batch_indices`; det K and the condition numbers of a point
of cond(K_s) above 1e8 are its single query's,
:func:`closedloop.analysis.complete.resolve_ill_conditioned`): :func:`grid_points` makes the inputs,
:func:`stiffness_map` runs the map, :class:`StiffnessMap` holds it and writes its files (NPZ, CSV,
PNG; each whole or not at all: :func:`closedloop.common.files.write_atomically`).
"""

from __future__ import annotations

import csv
import json
import textwrap
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from closedloop.analysis.batch_indices import BATCH_INDICES
from closedloop.analysis.interrupts import Interrupted
from closedloop.analysis.map_engine import MapChunk, assemble_chunk, border_starts, path_order
from closedloop.analysis.map_results import OK, RANK_DEFICIENT, STATUS, PointData
from closedloop.analysis.model_source import ModelSource, model_of
from closedloop.analysis.tasks import CHUNK, gather, run_tasks_by_point
from closedloop.common.arrays import ReadOnlyArrays
from closedloop.common.figures import tidy_layout
from closedloop.common.files import output_folder, save_figure, write_atomically
from closedloop.elastostatics.compliance import UNITS
from closedloop.exceptions import InvalidInputError
from closedloop.model.closed_loop import ClosedLoopModel

#: Indices of a map and their units (SI; ``condition_number`` is the unit-free one of the
#: scaled K, ``condition_number_si`` that of the SI matrix).
INDICES = BATCH_INDICES
#: The index of ``stiffness_map(..., modes=True)``: the lowest nonzero natural frequency.
MODE_INDICES = {"lowest_frequency": "Hz"}
#: Every index a map may hold, and its unit.
ALL_INDICES = {**INDICES, **MODE_INDICES}
#: Largest map also written as CSV.
CSV_MAX_POINTS = 10_000
#: Names that ``numpy.savez`` takes as its own arguments, not as arrays.
NPZ_ARGUMENTS = ("file", "allow_pickle")


def column_name(name: str, unit: str) -> str:
    """A CSV column's name with its unit: ``det_K_N^6_per_rad^3``, ``crank_rad``,
    ``min_rotational_Nm_per_rad``; a dimensionless one (unit ``1 ...``) bare."""
    if unit.startswith("1"):
        return name
    return f"{name}_{unit.replace(' ', '').replace('/', '_per_')}"


@dataclass(frozen=True)
class StiffnessMap(ReadOnlyArrays):
    """A stiffness map (arrays read-only; point i is row i).

    Attributes:
        joints: names of the actuated joints, the columns of ``inputs``.
        units: their units, ``"rad"`` or ``"m"``.
        inputs: (n, n_act) actuated values [rad, m] of every point.
        shape: grid shape (sizes of the swept joints' axes, in sweep order), or (n,).
        swept: names of the swept joints (grid axes), or all joints for a list.
        frame: loaded frame.
        wrench: (6,) wrench of the deflection indices [N, N m], or None.
        indices: name -> (n,) values (units in :data:`ALL_INDICES`), NaN where not defined.
        data: the per-point arrays (C, rank, status and reason codes).
    """

    joints: tuple[str, ...]
    units: tuple[str, ...]
    inputs: np.ndarray
    shape: tuple[int, ...]
    swept: tuple[str, ...]
    frame: str
    wrench: np.ndarray | None
    indices: dict
    data: PointData = field(repr=False)

    @property
    def C(self) -> np.ndarray:
        """(n, 6, 6) compliance at the frame [SI], NaN where the point failed."""
        return self.data.C

    @property
    def status(self) -> np.ndarray:
        """(n,) status names (:data:`STATUS`)."""
        return np.asarray(STATUS)[self.data.codes]

    @property
    def reasons(self) -> tuple[str, ...]:
        """n messages ("" when ok), built on demand."""
        return tuple(np.asarray(self.data.reason_texts)[self.data.reason_codes].tolist())

    @property
    def ok(self) -> np.ndarray:
        """(n,) bool: the compliance was computed (status ok or rank_deficient)."""
        return np.isin(self.data.codes, (OK, RANK_DEFICIENT))

    def grid(self, name: str) -> np.ndarray:
        """Index ``name`` reshaped to the grid."""
        return self.indices[name].reshape(self.shape)

    def save(self, out: str | Path, index: str = "det_K") -> list[Path]:
        """Write ``map.npz`` (every index under its name, C, rank, status, reasons, shape,
        ``joints`` the actuated joints' names and ``inputs`` (n, n_act) their values, each
        joint's values under its name unless that name is one of these keys, and
        ``units``: a JSON object, key -> unit, ``inputs`` a list per column), ``map.csv``
        when at most :data:`CSV_MAX_POINTS` points (columns named with their units,
        :func:`column_name`; the status and reason of each point; an earlier map's
        ``map.csv`` is removed otherwise), and ``map.png`` (curve or heat map of
        ``index``); returns the paths.

        Raises:
            InvalidInputError: unknown index, or ``out`` not a writable folder.
        """
        if index not in self.indices:
            raise InvalidInputError(f"index {index!r}; expected one of {sorted(self.indices)}")
        out = output_folder(out)
        joint_units = dict(zip(self.joints, self.units, strict=True))
        units = {**joint_units, **{k: ALL_INDICES[k] for k in self.indices}, "C": UNITS["C"],
                 "inputs": list(self.units)}  # fmt: skip
        arrays = {**self.indices, "C": self.C, "rank": self.data.rank, "status": self.status,
                  "reasons": np.asarray(self.reasons), "shape": np.asarray(self.shape),
                  "joints": np.asarray(self.joints), "inputs": self.inputs}  # fmt: skip
        taken = {*arrays, *NPZ_ARGUMENTS, "units"}
        arrays.update({n: self.inputs[:, j] for j, n in enumerate(self.joints) if n not in taken})
        arrays["units"] = np.array(json.dumps({k: v for k, v in units.items() if k in arrays}))
        paths = [write_atomically(out / "map.npz", lambda f: np.savez(f, **arrays))]
        if len(self.inputs) <= CSV_MAX_POINTS:
            names = [*(column_name(n, u) for n, u in joint_units.items()),
                     *(column_name(k, ALL_INDICES[k]) for k in self.indices),
                     "status", "reason"]  # fmt: skip
            values = np.column_stack([self.inputs, *self.indices.values()]).tolist()

            def write(f) -> None:
                writer = csv.writer(f, lineterminator="\n")
                writer.writerow(names)
                for row, status, reason in zip(values, self.status, self.reasons, strict=True):
                    writer.writerow([*map(repr, row), status, reason])

            paths.append(write_atomically(out / "map.csv", write, text=True, newline=""))
        else:  # an earlier map's: it would disagree with the files beside it
            (out / "map.csv").unlink(missing_ok=True)
        paths.append(out / "map.png")
        plot_map(self, index, paths[-1])
        return paths

    def plotted(self) -> tuple[str, ...]:
        """The swept joints along the picture's axes: those of a grid with more than one
        value (the first when none has), or every joint of a list."""
        if len(self.shape) == 1:
            return self.swept
        long = tuple(n for n, size in zip(self.swept, self.shape, strict=True) if size > 1)
        return long or self.swept[:1]


def load_text(wrench: np.ndarray | None) -> str:
    """The load of a map's title, e.g. ``force (3, 0, -2) N, torque (0, 0.4, 0) N m`` (4
    significant digits, any magnitude), or "" without a wrench (6,) [N, N m]."""
    if wrench is None:
        return ""
    f, n = (", ".join(f"{x:.4g}" for x in part) for part in (wrench[:3], wrench[3:]))
    return f"force ({f}) N, torque ({n}) N m"


def map_title(smap: StiffnessMap, index: str) -> str:
    """Title of the picture of ``index``: the index and its unit, the frame, the fixed
    inputs with their units and the load (lines of at most 80 characters)."""
    plotted = smap.plotted()
    fixed = [f"{n} = {smap.inputs[0, j]:.6g} {u}"
             for j, (n, u) in enumerate(zip(smap.joints, smap.units, strict=True))
             if n not in plotted]  # fmt: skip
    parts = [*fixed, load_text(smap.wrench)] if smap.wrench is not None else fixed
    return "\n".join([f"{index} [{ALL_INDICES[index]}] at {smap.frame}",
                      *textwrap.wrap(", ".join(parts), 80)])  # fmt: skip


def plot_map(smap: StiffnessMap, index: str, path: Path) -> None:
    """Write the PNG ``path`` of :func:`map_figure`."""
    save_figure(map_figure(smap, index), path)


def map_figure(smap: StiffnessMap, index: str):
    """The figure of ``index`` over the swept joints (a ``matplotlib.figure.Figure`` of
    pyplot, Agg): a curve (one axis with more than one value, or a list) or a heat map
    (two), with units, the fixed inputs, the load and the number of points without a value
    in the title; failed points left blank."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    unit = dict(zip(smap.joints, smap.units, strict=True))
    axes = smap.plotted()
    label = f"{index} [{ALL_INDICES[index]}]"
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=100)
    if len(axes) == 1 or len(smap.shape) == 1:  # the curve along its first input
        x = smap.inputs[:, smap.joints.index(axes[0])]
        listed = len(smap.shape) == 1 and len(smap.swept) > 1  # a list: its own order
        order = slice(None) if listed else np.argsort(x, kind="stable")
        ax.plot(x[order], smap.indices[index][order], "o-")
        ax.set_xlabel(f"{axes[0]} [{unit[axes[0]]}]")
        ax.set_ylabel(label)
    else:  # the grid's axes sorted for the picture (a sweep may list its values in any order)
        grid = smap.inputs.reshape(*smap.shape, -1)
        y = grid[:, 0, smap.joints.index(axes[0])]
        x = grid[0, :, smap.joints.index(axes[1])]
        iy, ix = np.argsort(y), np.argsort(x)
        values = smap.grid(index)[np.ix_(iy, ix)]
        mesh = ax.pcolormesh(x[ix], y[iy], values, shading="nearest")
        fig.colorbar(mesh, ax=ax, label=label)
        ax.set_xlabel(f"{axes[1]} [{unit[axes[1]]}]")
        ax.set_ylabel(f"{axes[0]} [{unit[axes[0]]}]")
    missing = int(np.count_nonzero(np.isnan(smap.indices[index])))
    note = f" ({missing} points without a value)" if missing else ""
    ax.set_title(map_title(smap, index) + note, fontsize=9)
    tidy_layout(fig)  # tight, no tick labels on one another
    return fig


def grid_points(
    clm: ClosedLoopModel, sweeps: Mapping[str, Sequence[float]], fixed: Mapping[str, float]
) -> tuple[np.ndarray, tuple[int, ...], np.ndarray]:
    """(n, n_act) points of a grid, its shape, and the path order (n,) through it.

    The points are in the order the sweeps list their values (C order over the axes); the
    path (:func:`closedloop.analysis.map_engine.path_order`) walks each axis by its values in
    ascending order, whatever their listed order, so that each step goes to a neighbouring
    value and a map does not depend on the listed order (a four-bar's crank listed in a
    shuffled order had 19 of 40 points on the other assembly mode).

    Args:
        clm: the model (its actuated joints are the inputs).
        sweeps: swept joint -> its values [rad, m].
        fixed: value of every other actuated joint [rad, m].

    Raises:
        InvalidInputError: a swept or fixed name that is not an actuated joint, a missing
            value, non-finite values.
    """
    act = list(clm.actuated)
    for name in (*sweeps, *fixed):
        if name not in act:
            raise InvalidInputError(f"{name!r} is not an actuated joint; expected one of {act}")
    missing = [n for n in act if n not in sweeps and n not in fixed]
    if missing:
        raise InvalidInputError(f"give a value (fixed or swept) to the actuated joints {missing}")
    axes = [np.asarray(v, dtype=float).reshape(-1) for v in sweeps.values()]
    if not axes or not all(a.size and np.all(np.isfinite(a)) for a in axes):
        raise InvalidInputError("every swept joint needs finite values")
    if len(axes) > 2:
        raise InvalidInputError(f"sweep one or two joints, got {list(sweeps)}")
    for name, a in zip(sweeps, axes, strict=True):
        if np.unique(a).size < a.size:
            raise InvalidInputError(f"the values of swept joint {name!r} must be distinct, "
                                    f"got {a.tolist()}")  # fmt: skip
    shape = tuple(a.size for a in axes)
    mesh = np.meshgrid(*axes, indexing="ij")
    points = np.empty((int(np.prod(shape)), len(act)))
    for j, name in enumerate(act):
        if name in sweeps:
            points[:, j] = mesh[list(sweeps).index(name)].reshape(-1)
        else:
            points[:, j] = float(fixed[name])
    ranks = [np.argsort(a, kind="stable") for a in axes]  # sorted position -> listed one
    walk = np.unravel_index(path_order(shape), shape)  # positions in the sorted grid
    order = np.ravel_multi_index(tuple(r[w] for r, w in zip(ranks, walk, strict=True)), shape)
    order.flags.writeable = False
    return points, shape, order


def stiffness_map(
    model: ClosedLoopModel | ModelSource,
    frame: str,
    *,
    sweeps: Mapping[str, Sequence[float]] | None = None,
    fixed: Mapping[str, float] | None = None,
    points: np.ndarray | None = None,
    wrench: np.ndarray | None = None,
    start: Callable | None = None,
    q0: np.ndarray | None = None,
    workers: int | None = None,
    executor: Executor | None = None,
    chunk: int = CHUNK,
    show_progress: bool = False,
    modes: bool = False,
    check_limits: bool = True,
) -> StiffnessMap:
    """Stiffness indices at many configurations (see the module docstring).

    Args:
        model: the model, or a :class:`ModelSource` (needed by process executors).
        frame: the loaded frame.
        sweeps, fixed: a grid (:func:`grid_points`; each swept joint's values in any
            order, walked in ascending order, the results in the listed order); or
        points: (n, n_act) actuated values [rad, m] in the model's actuated order, a path.
        wrench: (6,) wrench [N, N m] at the frame for the deflection indices, or None.
        start: start provider ``start(clm, points (c, n_act)) -> (c, nq)``: every point
            starts from its own configuration (e.g. a closed-form guess) instead of the
            previous point's; picklable for process executors. Default None.
        q0: (nq,) the configuration the path starts from: its first point is driven
            there from q0, on q0's assembly mode (default: the model's reference
            configuration, as :func:`closedloop.kinematics.assembly.assemble`); not with
            ``start``.
        workers: local processes (a :class:`ModelSource` is required), default serial.
        executor: any ``concurrent.futures.Executor`` (e.g. Dask's) instead.
        chunk: points per task; the results depend on it only within the assembly
            tolerance (each chunk's first point starts from the serial continuation of
            :func:`border_starts`), except after a gap of
            :data:`~closedloop.analysis.map_engine.BORDER_STRIDE` or more failed points; not on the
            executor.
        show_progress: progress on stderr (:mod:`closedloop.common.progress`), in points.
        modes: also the index ``lowest_frequency`` [Hz]: the lowest nonzero natural
            frequency of every point (:func:`closedloop.analysis.vibration.modes`, rigid-body modes
            skipped; NaN where it has none).
        check_limits: a point whose actuated values are outside their joints' limits is
            ``invalid`` (the robot cannot be driven there); False: computed as any other
            (the command line's ``--no-limits``).

    Raises:
        InvalidInputError: bad grid, points, wrench, q0, workers or chunk; ``modes`` on a model
            whose link inertias are not the robot file's
            (:meth:`closedloop.model.closed_loop.ClosedLoopModel.require_inertias`).
        NameNotFoundError: unknown frame.
        ModesError: ``modes`` on a model without any mass.
        Interrupted: a ``KeyboardInterrupt`` (Ctrl-C, SIGINT) or SIGTERM during the map
            (:class:`closedloop.analysis.interrupts.Interrupted`, itself a ``KeyboardInterrupt``):
            the worker processes are ended at once (none is left), and the map so far is
            its ``partial``: a :class:`StiffnessMap` whose points not computed (their
            chunk not finished) have status ``not_computed`` and reason ``interrupted by
            SIGINT`` (or ``SIGTERM``), values NaN. A SIGTERM handler is installed only
            while the map runs, in the main thread, where SIGTERM would end the process.
    """
    clm = model_of(model)
    clm.frame_id(frame)
    if modes:
        from closedloop.analysis.vibration import check_massive

        check_massive(clm)
    w = None if wrench is None else np.asarray(wrench, dtype=float)
    if w is not None and (w.shape != (6,) or not np.all(np.isfinite(w))):
        raise InvalidInputError(f"wrench must be 6 finite values, got {np.asarray(wrench)}")
    if (sweeps is None) == (points is None):
        raise InvalidInputError("give either sweeps (with fixed) or points")
    if sweeps is not None:
        pts, shape, order = grid_points(clm, sweeps, fixed or {})
        swept = tuple(sweeps)
    else:
        pts = np.asarray(points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != len(clm.actuated) or not np.all(np.isfinite(pts)):
            bad = np.flatnonzero(~np.all(np.isfinite(pts), axis=-1)) if pts.ndim == 2 else []
            got = f"row {bad[0]} is {pts[bad[0]].tolist()}" if len(bad) else f"shape {pts.shape}"
            raise InvalidInputError(
                f"points must be (n, {len(clm.actuated)}) finite actuated values "
                f"({list(clm.actuated)}), got {got}"
            )
        shape, order, swept = (len(pts),), np.arange(len(pts)), tuple(clm.actuated)
    if q0 is not None:
        if start is not None:
            raise InvalidInputError("give a start provider (start) or q0, not both")
        q0 = clm.check_configuration(q0)
    if not isinstance(chunk, int) or chunk < 1:
        raise InvalidInputError(f"chunk must be a positive integer, got {chunk!r}")
    if (workers or 1) > 1 and executor is None and not isinstance(model, ModelSource):
        raise InvalidInputError("worker processes need a ModelSource (files), not a model")
    n = len(pts)
    firsts = list(range(0, n, chunk))
    pieces = [order[f : f + chunk] for f in firsts]

    def results():
        borders = ([None] * len(firsts) if start
                   else border_starts(clm, pts[order], firsts, check_limits, q0))  # fmt: skip
        tasks = [MapChunk(model, frame, pts[p], q, start, w, modes, check_limits)
                 for p, q in zip(pieces, borders, strict=True)]  # fmt: skip
        sizes = [len(piece) for piece in pieces]
        yield from run_tasks_by_point(assemble_chunk, tasks, sizes, executor, workers,
                                      label="map points", show_progress=show_progress)  # fmt: skip

    try:
        data = gather(n, pieces, results(), w, MODE_INDICES if modes else ())
    except Interrupted as stop:
        if stop.data is not None:  # else stopped before gather began
            stop.partial = _stiffness_map(clm, pts, shape, swept, frame, w, stop.data)
        raise
    return _stiffness_map(clm, pts, shape, swept, frame, w, data)


def _stiffness_map(clm, pts, shape, swept, frame, wrench, data: PointData) -> StiffnessMap:
    """The :class:`StiffnessMap` of the arrays of :func:`stiffness_map` (made read-only)."""
    values = data.indices
    for a in (pts, data.C, data.rank, data.codes, *values.values()):
        a.flags.writeable = False
    return StiffnessMap(
        joints=tuple(clm.actuated),
        units=tuple(
            "m" if lin else "rad" for lin in clm.linear_coordinates[clm.actuated_v_indices]
        ),
        inputs=pts,
        shape=shape,
        swept=swept,
        frame=frame,
        wrench=wrench,
        indices=values,
        data=data,
    )
