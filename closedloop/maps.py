"""Stiffness maps of any robot over its workspace: a grid or a list of actuated inputs.

Each point is a vector of actuated values (the model's ``actuated`` joints, SI). The
loops are closed by :func:`closedloop.assembly.assemble`, started from the previous
point's configuration along the path (a grid is walked as a boustrophedon: one grid
step at a time, so that every start is a neighbour; the first point of a chunk starts
from the model's reference configuration), then the compliance at the frame is computed
and its indices (:data:`INDICES`). A point that fails is recorded (status and reason,
NaN in its indices), never the whole map lost.

The points are cut into chunks, contiguous along the path, one task each for a
``concurrent.futures.Executor`` (serial by default, local processes with ``workers``).
Tasks carry a :class:`ModelSource` (files and options, not the model: Pinocchio's
constraint models cannot be pickled), which each process loads once.
"""

from __future__ import annotations

import functools
import textwrap
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .assembly import assemble
from .blas import single_threaded_blas
from .compliance import compliance
from .exceptions import (
    AssemblyError,
    ClosedLoopError,
    InvalidInputError,
    MechanismError,
    RigidDirectionsError,
    SingularConfigurationError,
)
from .indices import StiffnessIndices
from .io import load_model, reference_configuration
from .model import ClosedLoopModel

#: Indices of a map and their units (SI; the condition number is that of the scaled K).
INDICES = {
    "det_K": "N^6/rad^3",
    "condition_number": "1 (scaled K: lengths per the mechanism size)",
    "min_translational": "N/m",
    "max_translational": "N/m",
    "min_rotational": "N m/rad",
    "max_rotational": "N m/rad",
    "deflection_translation": "m",
    "deflection_rotation": "rad",
}
#: Status of a point.
STATUS = ("ok", "rank_deficient", "unreachable", "singular", "failed")
#: Points per task when not given: enough to amortise the model load in each process.
CHUNK = 200
#: Largest map also written as CSV.
CSV_MAX_POINTS = 10_000


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
        C: (n, 6, 6) compliance at the frame [SI], NaN where the point failed.
        status: (n,) status names (:data:`STATUS`); reasons: n messages ("" when ok).
    """

    joints: tuple[str, ...]
    units: tuple[str, ...]
    inputs: np.ndarray
    shape: tuple[int, ...]
    swept: tuple[str, ...]
    frame: str
    wrench: np.ndarray | None
    indices: dict
    C: np.ndarray = field(repr=False)
    status: np.ndarray = field(repr=False)
    reasons: tuple[str, ...] = field(repr=False)

    @property
    def ok(self) -> np.ndarray:
        """(n,) bool: the compliance was computed (status ok or rank_deficient)."""
        return np.isin(self.status, ("ok", "rank_deficient"))

    def grid(self, name: str) -> np.ndarray:
        """Index ``name`` reshaped to the grid."""
        return self.indices[name].reshape(self.shape)

    def save(self, out: str | Path, index: str = "det_K") -> list[Path]:
        """Write ``map.npz`` (every index under its name, the inputs under the joint
        names, C, status, reasons), ``map.csv`` when at most :data:`CSV_MAX_POINTS`
        points, and ``map.png`` (curve or heat map of ``index``); returns the paths.

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
        np.savez(paths[0], **columns, **self.indices, C=self.C, status=self.status,
                 reasons=np.asarray(self.reasons), shape=np.asarray(self.shape))  # fmt: skip
        if len(self.status) <= CSV_MAX_POINTS:
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
        sweeps: swept joint -> its values [rad, m] (one or two joints).
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
    order = np.arange(points.shape[0]).reshape(shape)
    if len(shape) == 2:  # boustrophedon: every other row backwards
        order[1::2] = order[1::2, ::-1]
    return points, shape, order.reshape(-1)


def _point(clm, frame, actuated, q0, wrench):
    """(C, indices, status, reason, q) of one point."""
    nan = dict.fromkeys(INDICES, np.nan)
    try:
        q = assemble(clm, actuated, q0).q
    except AssemblyError as e:
        return None, nan, "unreachable", str(e), None
    try:
        res = compliance(clm, q, frame)
    except (MechanismError, SingularConfigurationError) as e:
        return None, nan, "singular", str(e), q
    except ClosedLoopError as e:
        return None, nan, "failed", str(e), q
    s, out = StiffnessIndices.from_result(res), dict(nan)
    for name, get in (
        ("det_K", lambda: s.determinant),
        ("condition_number", lambda: s.scaled_condition_number),
        ("min_translational", lambda: s.min_translational_stiffness.value),
        ("max_translational", lambda: s.max_translational_stiffness.value),
        ("min_rotational", lambda: s.min_rotational_stiffness.value),
        ("max_rotational", lambda: s.max_rotational_stiffness.value),
    ):
        try:
            out[name] = get()
        except RigidDirectionsError:
            pass
    if wrench is not None:
        d = res.deflection(wrench)
        out["deflection_translation"] = float(np.linalg.norm(d[:3]))
        out["deflection_rotation"] = float(np.linalg.norm(d[3:]))
    status = "ok" if res.is_full_rank else "rank_deficient"
    return res.C, out, status, "" if status == "ok" else f"rank {res.rank} < 6", q


def _chunk(model, frame, points: np.ndarray, wrench) -> tuple:
    """Indices, C, status, reasons of consecutive points, warm-started along them."""
    clm = model.load() if isinstance(model, ModelSource) else model
    n = len(points)
    C, status, reasons = np.full((n, 6, 6), np.nan), [], []
    values = {name: np.full(n, np.nan) for name in INDICES}
    q_prev = reference_configuration(clm)
    for i, actuated in enumerate(points):
        c, idx, st, why, q = _point(clm, frame, actuated, q_prev, wrench)
        if c is not None:
            C[i] = c
        for name, v in idx.items():
            values[name][i] = v
        status.append(st)
        reasons.append(why)
        q_prev = q if q is not None else reference_configuration(clm)
    return values, C, status, reasons


def stiffness_map(
    model: ClosedLoopModel | ModelSource,
    frame: str,
    *,
    sweeps: Mapping[str, Sequence[float]] | None = None,
    fixed: Mapping[str, float] | None = None,
    points: np.ndarray | None = None,
    wrench: np.ndarray | None = None,
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
        points: (n, n_act) actuated values [rad, m] in the model's actuated order.
        wrench: (6,) wrench [N, N m] at the frame for the deflection indices, or None.
        workers: local processes (a :class:`ModelSource` is required), default serial.
        executor: any ``concurrent.futures.Executor`` (e.g. Dask's) instead.
        chunk: points per task.
        progress: called as ``progress(done, total)`` after each task (in the caller's
            thread).

    Raises:
        InvalidInputError: bad grid, points, wrench, workers or chunk.
        NameNotFoundError: unknown frame.
    """
    clm = model.load() if isinstance(model, ModelSource) else model
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
    if workers is not None and executor is None:
        if not isinstance(model, ModelSource):
            raise InvalidInputError("worker processes need a ModelSource (files), not a model")
        executor = ProcessPoolExecutor(workers, initializer=single_threaded_blas)
    pieces = [order[i : i + chunk] for i in range(0, len(order), chunk)]
    tasks = [(model, frame, pts[p], w) for p in pieces]
    results: list = [None] * len(tasks)
    done = 0

    def finished(k: int, result) -> None:
        nonlocal done
        results[k], done = result, done + len(pieces[k])
        if progress is not None:
            progress(done, len(pts))

    if executor is None:
        for k, t in enumerate(tasks):
            finished(k, _chunk(*t))
    else:
        with executor if workers is not None else _NoClose(executor) as ex:
            futures = {ex.submit(_chunk, *t): k for k, t in enumerate(tasks)}
            for f in as_completed(futures):
                finished(futures[f], f.result())
    n = len(pts)
    C, status, reasons = np.full((n, 6, 6), np.nan), np.empty(n, dtype=object), [""] * n
    values = {name: np.full(n, np.nan) for name in INDICES}
    for p, (vals, c, st, why) in zip(pieces, results, strict=True):
        C[p], status[p] = c, st
        for name in INDICES:
            values[name][p] = vals[name]
        for i, text in zip(p, why, strict=True):
            reasons[i] = text
    if w is None:
        for name in ("deflection_translation", "deflection_rotation"):
            del values[name]
    for a in (pts, C, *values.values()):
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
        C=C,
        status=status.astype(str),
        reasons=tuple(reasons),
    )


class _NoClose:
    """Context manager that leaves a caller's executor open."""

    def __init__(self, executor: Executor):
        self.executor = executor

    def __enter__(self) -> Executor:
        return self.executor

    def __exit__(self, *exc) -> None:
        return None
