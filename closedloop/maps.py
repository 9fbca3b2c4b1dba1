"""Stiffness maps of any robot over its workspace: the one sweep engine of the project.

A map computes the compliance at a frame for many inputs (actuated values, SI). The
engine, shared with CaHyMan's maps (:mod:`cahyman_pin.sweep`), has four parts:

* a **path** through the points (:func:`path_order`: a grid is walked by unit steps, a
  boustrophedon in two dimensions) cut into **chunks** of contiguous points;
* a **kernel**, any picklable callable ``kernel(task) -> ChunkResult`` computing one chunk
  (compliance, rank, status and reason per point; a point that fails is recorded, never
  the whole map lost);
* :func:`run_tasks`: the chunks in this process, on local processes or on any
  ``concurrent.futures.Executor`` (e.g. Dask's ``Client.get_executor()``): the results do
  not depend on the executor;
* :func:`gather`, :func:`classify` and :func:`closedloop.indices.batch_indices`: per-point
  arrays (no per-point Python objects: statuses and reasons are small integer codes), the
  rank and status from C, the indices of all points at once.

The kernel of this module (:func:`assemble_chunk`) works for any
:class:`~closedloop.model.ClosedLoopModel`: each point is assembled by
:func:`closedloop.assembly.assemble` from the previous point's configuration along the
path (or from a per-point start provider), then :func:`closedloop.compliance.compliance`
is queried. Every chunk carries the configuration its first point starts from, computed
serially along the path before the chunks are sent (:func:`border_starts`), so that a
chunk border does not restart from the reference configuration (which may lie on another
assembly mode).
"""

from __future__ import annotations

import functools
import textwrap
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin

from .assembly import assemble
from .blas import single_threaded_blas
from .compliance import compliance
from .conditioning import batch_rank
from .exceptions import (
    AssemblyError,
    ClosedLoopError,
    InvalidInputError,
    MechanismError,
    RigidDirectionsError,
    SingularConfigurationError,
)
from .indices import BATCH_INDICES, batch_indices
from .io import load_model, reference_configuration
from .model import ClosedLoopModel

#: Indices of a map and their units (SI; ``condition_number`` is the unit-free scaled one,
#: ``condition_number_si`` that of the SI matrix).
INDICES = BATCH_INDICES
#: Status of a point, by code (its index in this tuple).
STATUS = ("ok", "rank_deficient", "invalid", "unreachable", "singular", "failed")
OK, RANK_DEFICIENT, INVALID, UNREACHABLE, SINGULAR, FAILED = range(len(STATUS))
#: Exceptions recorded per point (anything else, a programming error, propagates).
POINT_ERRORS = (ClosedLoopError, np.linalg.LinAlgError)
#: Points per task when not given: enough to amortise a task's overhead (pickling, the
#: model load in a fresh process), small enough for a few tasks per core.
CHUNK = 500
#: Points between two assemblies of the serial pass that computes the chunks' starts:
#: a continuation step short enough to stay on one assembly mode.
BORDER_STRIDE = 16
#: Largest map also written as CSV.
CSV_MAX_POINTS = 10_000
#: Relative tolerance of the symmetry test of a compliance.
SYMMETRY_RTOL = 1e-9
#: Relative tolerance on equal steps for extrapolating a warm start.
EQUAL_STEP_RTOL = 1e-9


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
        rank: (c,) rank of C from the solver, -1 where unknown (set by :func:`classify`).
        status: (c,) status codes (:data:`STATUS`).
        length: (c,) characteristic length [m] of the scaled indices.
        iterations: (c,) Gauss-Newton iterations of the assembly, -1 if none.
        reasons: error message per failed point, by position in the chunk.
    """

    C: np.ndarray
    rank: np.ndarray
    status: np.ndarray
    length: np.ndarray
    iterations: np.ndarray
    reasons: dict[int, str] = field(default_factory=dict)

    @classmethod
    def empty(cls, n: int) -> ChunkResult:
        """n points, all ``ok`` until recorded otherwise, C NaN."""
        return cls(
            C=np.full((n, 6, 6), np.nan),
            rank=np.full(n, -1, dtype=np.int8),
            status=np.zeros(n, dtype=np.int8),
            length=np.full(n, np.nan),
            iterations=np.full(n, -1, dtype=np.int16),
        )

    def fail(self, i: int, error: Exception) -> None:
        """Record the failure of point i."""
        self.status[i] = status_code(error)
        self.reasons[int(i)] = " ".join(str(error).split()) or type(error).__name__


def assemble_points(clm, frame, out, rows, solve, first=None, starts=None, axes="world",
                    length=None, inputs=None):  # fmt: skip
    """Assemble and query the points ``rows`` of a chunk in order (warm-started).

    Args:
        clm: the :class:`ClosedLoopModel`.
        frame: the loaded frame.
        out: the :class:`ChunkResult` to fill.
        rows: positions in the chunk, in path order.
        solve: ``solve(i, q0) -> Assembly`` of the point at position i from ``q0`` (nq,).
        first: start of the first point, passed to ``solve`` (None too).
        starts: (len(rows), nq) start of every point (a start provider), or None: each
            point starts from the last assembled one.
        axes, length: as :func:`closedloop.compliance.compliance`.
        inputs: (c, m) inputs of the chunk's points, or None. Given, a point whose step
            from the last point repeats the step before (to :data:`EQUAL_STEP_RTOL`)
            starts from the linear extrapolation q1 + (q1 - q0) on the configuration
            manifold instead of q1 (fewer Gauss-Newton iterations along a grid line).
    """
    history: list = []  # (position, q) of the last two assembled points, in a row
    q_prev = first
    for k, i in enumerate(rows):
        q0 = q_prev if starts is None else starts[k]
        if starts is None and inputs is not None and len(history) == 2:
            q0 = _extrapolated(clm, inputs, history, i)
        try:
            a = solve(i, q0)
            c = compliance(clm, a.q, frame, axes, length=length)
        except POINT_ERRORS as e:
            out.fail(i, e)
            history = []
            continue
        out.C[i], out.rank[i], out.length[i] = c.C, c.rank, c.length
        out.iterations[i] = a.iterations
        q_prev, history = a.q, [*history[-1:], (i, a.q)]


def _extrapolated(clm, inputs: np.ndarray, history: list, i: int) -> np.ndarray:
    """q1 + (q1 - q0) when the inputs took the same step twice, else q1."""
    (i0, q0), (i1, q1) = history
    last, step = inputs[i1] - inputs[i0], inputs[i] - inputs[i1]
    if np.max(np.abs(step - last)) <= EQUAL_STEP_RTOL * np.max(np.abs(last)):
        return pin.integrate(clm.model, q1, pin.difference(clm.model, q0, q1))
    return q1


@dataclass(frozen=True)
class ModelSource:
    """Where a model comes from, so that worker processes can load it themselves.

    Attributes: the arguments of :func:`closedloop.io.load_model` (paths as strings).
    """

    path: str
    closures: str | None = None
    springs: tuple = ()
    joint_stiffness: float | None = None

    def load(self) -> ClosedLoopModel:
        """The model (loaded once per process)."""
        return _load(self)


@functools.lru_cache(maxsize=8)
def _load(source: ModelSource) -> ClosedLoopModel:
    springs = {k: list(v) if isinstance(v, tuple) else v for k, v in source.springs}
    return load_model(
        source.path,
        source.closures,
        springs=springs or None,
        joint_stiffness=source.joint_stiffness,
    )


def _model(model: ClosedLoopModel | ModelSource) -> ClosedLoopModel:
    return model.load() if isinstance(model, ModelSource) else model


@dataclass(frozen=True)
class MapChunk:
    """One task of :func:`assemble_chunk`: points contiguous along the path.

    Attributes:
        model: the model or its :class:`ModelSource` (Pinocchio's constraint models cannot
            be pickled: process executors need the source).
        frame: the loaded frame.
        points: (c, n_act) actuated values [rad, m], in path order.
        first: (nq,) configuration the first point starts from, or None (reference).
        start: start provider ``start(clm, points) -> (c, nq)`` or None (picklable).
    """

    model: ClosedLoopModel | ModelSource
    frame: str
    points: np.ndarray
    first: np.ndarray | None = None
    start: Callable | None = None

    def __len__(self) -> int:
        return len(self.points)


def assemble_chunk(chunk: MapChunk) -> ChunkResult:
    """The kernel of :func:`stiffness_map`: every point of ``chunk``, warm-started."""
    clm = _model(chunk.model)
    out = ChunkResult.empty(len(chunk))
    starts = None if chunk.start is None else chunk.start(clm, chunk.points)
    first = reference_configuration(clm) if chunk.first is None else chunk.first
    assemble_points(clm, chunk.frame, out, range(len(chunk)),
                    lambda i, q0: assemble(clm, chunk.points[i], q0), first, starts)  # fmt: skip
    return out


def border_starts(clm: ClosedLoopModel, points: np.ndarray, firsts: Sequence[int]) -> list:
    """Start configuration of each chunk, by a serial continuation along the path.

    The pass assembles every :data:`BORDER_STRIDE`-th point up to the last chunk border,
    each from the previous one (the first from the reference configuration), and keeps
    the configurations at the borders ``firsts``: the first point of a chunk then starts
    on the assembly mode the path followed, as in a serial run. A point that cannot be
    assembled is passed over (the continuation goes on from the last configuration).

    Args:
        points: (n, n_act) actuated values in path order [rad, m].
        firsts: path positions of the chunks' first points (ascending, from 0).

    Returns:
        One (nq,) configuration, or None for the first chunk (the reference), per border.
    """
    q = reference_configuration(clm)
    wanted = set(firsts[1:])
    visit = sorted(wanted | set(range(BORDER_STRIDE, max(wanted, default=0), BORDER_STRIDE)))
    found = {}
    for p in visit:
        try:
            q = assemble(clm, points[p], q).q
        except POINT_ERRORS:
            pass
        found[p] = q
    return [found.get(p) for p in firsts]


def run_tasks(
    kernel: Callable,
    tasks: Sequence,
    executor: Executor | None = None,
    workers: int | None = None,
) -> Iterator[tuple[int, ChunkResult]]:
    """Yield (task index, ``kernel(task)``) as the tasks finish.

    Args:
        kernel: picklable callable (a module-level function) for process executors.
        tasks: the tasks (picklable for process executors).
        executor: any ``concurrent.futures.Executor``, used as given and left open.
        workers: without an executor, local processes (a pool shut down at the end);
            None or 1: this process.

    Raises:
        InvalidInputError: ``workers`` not a positive integer.
    """
    if workers is not None and (not isinstance(workers, int) or workers < 1):
        raise InvalidInputError(f"workers must be a positive integer, got {workers!r}")
    if executor is None and (workers or 1) == 1:
        for k, task in enumerate(tasks):
            yield k, kernel(task)
        return
    pool = executor or ProcessPoolExecutor(workers, initializer=single_threaded_blas)
    futures = {pool.submit(kernel, task): k for k, task in enumerate(tasks)}
    try:
        for future in as_completed(futures):
            yield futures[future], future.result()
    finally:
        for future in futures:
            future.cancel()
        if executor is None:
            pool.shutdown()


@dataclass(frozen=True)
class PointData:
    """Per-point results of a map, in storage order (numpy arrays only).

    Attributes:
        C: (n, 6, 6) compliance [SI], NaN where the point failed.
        rank: (n,) int8 rank of C, -1 where unknown.
        codes: (n,) int8 status codes (:data:`STATUS`).
        length: (n,) characteristic length [m].
        iterations: (n,) int16 assembly iterations, -1 if none.
        reason_codes: (n,) int32 index of each point's reason in ``reason_texts``.
        reason_texts: distinct reasons, ``reason_texts[0] == ""`` (a failed point's
            message usually names its own numbers: one text per failed point).
    """

    C: np.ndarray
    rank: np.ndarray
    codes: np.ndarray
    length: np.ndarray
    iterations: np.ndarray
    reason_codes: np.ndarray
    reason_texts: list
    _codes: dict = field(default_factory=dict, repr=False, compare=False)

    def set_reason(self, i: int, text: str) -> None:
        """Record the reason of point i (while the data is being completed)."""
        if not self._codes:
            self._codes.update((t, k) for k, t in enumerate(self.reason_texts))
        if text not in self._codes:
            self._codes[text] = len(self.reason_texts)
            self.reason_texts.append(text)
        self.reason_codes[i] = self._codes[text]


def gather(n: int, pieces: Sequence[np.ndarray], results: Iterator) -> PointData:
    """Per-point arrays from the results of the chunks.

    Args:
        n: number of points.
        pieces: storage indices of each chunk's points, in chunk order.
        results: (chunk index, :class:`ChunkResult`) pairs in any order
            (e.g. :func:`run_tasks`).
    """
    data = PointData(C=np.full((n, 6, 6), np.nan), rank=np.full(n, -1, dtype=np.int8),
                     codes=np.zeros(n, dtype=np.int8), length=np.full(n, np.nan),
                     iterations=np.full(n, -1, dtype=np.int16),
                     reason_codes=np.zeros(n, dtype=np.int32), reason_texts=[""])  # fmt: skip
    for k, r in results:
        p = pieces[k]
        data.C[p], data.rank[p], data.codes[p] = r.C, r.rank, r.status
        data.length[p], data.iterations[p] = r.length, r.iterations
        for i, text in r.reasons.items():
            data.set_reason(p[i], text)
    return data


def classify(data: PointData) -> np.ndarray:
    """Complete the rank and status of computed points from their compliance (in place).

    A symmetric C without a rank (not from the solver: a closed form) gets the rank of
    :func:`closedloop.conditioning.batch_rank`, and becomes ``failed`` if it is not
    positive semi-definite; a non-symmetric C counts as full rank (K = C^-1); a computed
    point of rank < 6 becomes ``rank_deficient``; C is NaN wherever the status is neither.

    Returns:
        (n,) bool: C is symmetric (and computed).
    """
    C, rank, codes = data.C, data.rank, data.codes
    computed = (codes == OK) & np.all(np.isfinite(C), axis=(1, 2))
    Ct = C.swapaxes(1, 2)
    symmetric = computed & np.all(np.abs(C - Ct) <= SYMMETRY_RTOL * np.abs(Ct), axis=(1, 2))
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


def path_order(shape: tuple, outer: Sequence[int] = ()) -> np.ndarray:
    """Flat (C-order) indices of a grid along a path of unit steps.

    The path is the reflected mixed-radix Gray code: each axis runs backwards when the
    positions of the slower axes sum to an odd number, so consecutive points differ by
    one step along one axis (a boustrophedon in two dimensions).

    Args:
        shape: grid shape.
        outer: axes that vary slowest, slowest first (the others follow in grid order).

    Returns:
        (prod(shape),) read-only flat indices in path order.
    """
    perm = [*outer, *(a for a in range(len(shape)) if a not in outer)]
    pshape = [shape[a] for a in perm]
    idx = np.indices(pshape).reshape(len(pshape), -1)
    path, parity = np.empty_like(idx), np.zeros(idx.shape[1], dtype=np.int64)
    for j, size in enumerate(pshape):
        path[j] = np.where(parity % 2 == 1, size - 1 - idx[j], idx[j])
        parity += path[j]
    original = np.empty_like(path)
    original[perm] = path
    order = np.ravel_multi_index(tuple(original), shape)
    order.flags.writeable = False
    return order


@dataclass(frozen=True)
class StiffnessMap:
    """A stiffness map (arrays read-only; point i is row i).

    Attributes:
        joints: names of the actuated joints, the columns of ``inputs``.
        units: their units, ``"rad"`` or ``"m"``.
        inputs: (n, n_act) actuated values [rad, m] of every point.
        shape: grid shape (sizes of the swept joints' axes, in sweep order), or (n,).
        swept: names of the swept joints (grid axes), or all joints for a list.
        frame: loaded frame.
        wrench: (6,) wrench of the deflection indices [N, N m], or None.
        indices: name -> (n,) values (units in :data:`INDICES`), NaN where not defined.
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
        """Write ``map.npz`` (every index under its name, the inputs under the joint
        names, C, rank, status, reasons, shape), ``map.csv`` when at most
        :data:`CSV_MAX_POINTS` points, and ``map.png`` (curve or heat map of ``index``);
        returns the paths.

        Raises:
            InvalidInputError: unknown index, or ``out`` not a writable folder.
        """
        if index not in self.indices:
            raise InvalidInputError(f"index {index!r}; expected one of {sorted(self.indices)}")
        out = Path(out)
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise InvalidInputError(f"cannot write to {str(out)!r}: {e.strerror}") from None
        columns = {n: self.inputs[:, j] for j, n in enumerate(self.joints)}
        paths = [out / "map.npz"]
        np.savez(paths[0], **columns, **self.indices, C=self.C, rank=self.data.rank,
                 status=self.status, reasons=np.asarray(self.reasons),
                 shape=np.asarray(self.shape))  # fmt: skip
        if len(self.inputs) <= CSV_MAX_POINTS:
            paths.append(out / "map.csv")
            names = [*self.joints, *self.indices, "status"]
            rows = [[*map(repr, r), s] for r, s in zip(
                np.column_stack([self.inputs, *self.indices.values()]).tolist(), self.status,
                strict=True)]  # fmt: skip
            paths[-1].write_text("\n".join(",".join(r) for r in [names, *rows]) + "\n")
        paths.append(out / "map.png")
        plot_map(self, index, paths[-1])
        return paths


def plot_map(smap: StiffnessMap, index: str, path: Path) -> None:
    """PNG of ``index`` over the swept joints: a curve (one axis) or a heat map (two),
    with units, the fixed inputs and the load in the title; failed points left blank."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    unit = dict(zip(smap.joints, smap.units, strict=True))
    fixed = [f"{n} = {smap.inputs[0, j]:.4g} {unit[n]}" for j, n in enumerate(smap.joints)
             if n not in smap.swept]  # fmt: skip
    if smap.wrench is not None:
        fixed.append(f"wrench {np.round(smap.wrench, 4).tolist()} N, N m")
    title = "\n".join([f"{index} [{INDICES[index]}] at {smap.frame}",
                        *textwrap.wrap(", ".join(fixed), 80)])  # fmt: skip
    values = smap.grid(index)
    axes = [np.unique(smap.inputs[:, smap.joints.index(n)]) for n in smap.swept]
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=100)
    if len(smap.shape) == 1 or len(smap.swept) == 1:
        ax.plot(smap.inputs[:, smap.joints.index(smap.swept[0])], smap.indices[index], "o-")
        ax.set_xlabel(f"{smap.swept[0]} [{unit[smap.swept[0]]}]")
        ax.set_ylabel(f"{index} [{INDICES[index]}]")
    else:
        mesh = ax.pcolormesh(axes[1], axes[0], values, shading="nearest")
        fig.colorbar(mesh, ax=ax, label=f"{index} [{INDICES[index]}]")
        ax.set_xlabel(f"{smap.swept[1]} [{unit[smap.swept[1]]}]")
        ax.set_ylabel(f"{smap.swept[0]} [{unit[smap.swept[0]]}]")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def grid_points(
    clm: ClosedLoopModel, sweeps: Mapping[str, Sequence[float]], fixed: Mapping[str, float]
) -> tuple[np.ndarray, tuple[int, ...], np.ndarray]:
    """(n, n_act) points of a grid, its shape, and the path order (n,) through it.

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
    shape = tuple(a.size for a in axes)
    mesh = np.meshgrid(*axes, indexing="ij")
    points = np.empty((int(np.prod(shape)), len(act)))
    for j, name in enumerate(act):
        if name in sweeps:
            points[:, j] = mesh[list(sweeps).index(name)].reshape(-1)
        else:
            points[:, j] = float(fixed[name])
    return points, shape, path_order(shape)


def stiffness_map(
    model: ClosedLoopModel | ModelSource,
    frame: str,
    *,
    sweeps: Mapping[str, Sequence[float]] | None = None,
    fixed: Mapping[str, float] | None = None,
    points: np.ndarray | None = None,
    wrench: np.ndarray | None = None,
    start: Callable | None = None,
    workers: int | None = None,
    executor: Executor | None = None,
    chunk: int = CHUNK,
    progress: Callable[[int, int], None] | None = None,
) -> StiffnessMap:
    """Stiffness indices at many configurations (see the module docstring).

    Args:
        model: the model, or a :class:`ModelSource` (needed by process executors).
        frame: the loaded frame.
        sweeps, fixed: a grid (:func:`grid_points`); or
        points: (n, n_act) actuated values [rad, m] in the model's actuated order, a path.
        wrench: (6,) wrench [N, N m] at the frame for the deflection indices, or None.
        start: start provider ``start(clm, points (c, n_act)) -> (c, nq)``: every point
            starts from its own configuration (e.g. a closed-form guess) instead of the
            previous point's; picklable for process executors. Default None.
        workers: local processes (a :class:`ModelSource` is required), default serial.
        executor: any ``concurrent.futures.Executor`` (e.g. Dask's) instead.
        chunk: points per task; the results depend on it only within the assembly
            tolerance (each chunk's first point starts from the serial continuation of
            :func:`border_starts`), not on the executor.
        progress: called as ``progress(done, total)`` after each task (in the caller's
            thread).

    Raises:
        InvalidInputError: bad grid, points, wrench, workers or chunk.
        NameNotFoundError: unknown frame.
    """
    clm = _model(model)
    clm.frame_id(frame)
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
            raise InvalidInputError(
                f"points must be (n, {len(clm.actuated)}) finite actuated values "
                f"({list(clm.actuated)}), got shape {pts.shape}"
            )
        shape, order, swept = (len(pts),), np.arange(len(pts)), tuple(clm.actuated)
    if not isinstance(chunk, int) or chunk < 1:
        raise InvalidInputError(f"chunk must be a positive integer, got {chunk!r}")
    if (workers or 1) > 1 and executor is None and not isinstance(model, ModelSource):
        raise InvalidInputError("worker processes need a ModelSource (files), not a model")
    n = len(pts)
    firsts = list(range(0, n, chunk))
    pieces = [order[f : f + chunk] for f in firsts]
    borders = [None] * len(firsts) if start else border_starts(clm, pts[order], firsts)
    tasks = [MapChunk(model, frame, pts[p], q, start) for p, q in zip(pieces, borders, strict=True)]

    def reported() -> Iterator[tuple[int, ChunkResult]]:
        done = 0
        for k, result in run_tasks(assemble_chunk, tasks, executor, workers):
            done += len(pieces[k])
            if progress is not None:
                progress(done, n)
            yield k, result

    data = gather(n, pieces, reported())
    symmetric = classify(data)
    values = batch_indices(data.C, data.rank, data.length, w, symmetric)
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
        wrench=w,
        indices=values,
        data=data,
    )
