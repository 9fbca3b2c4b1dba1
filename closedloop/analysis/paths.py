"""A path under a process load: the inverse kinematics point to point, the deflection under
the load, its exact and first-order compensation, and the stiffest posture
(:func:`~closedloop.follow_path`).

Every point is first given its unloaded configuration, the inverse kinematics of its target
continued from the last point's (:func:`closedloop.kinematics.inverse.reach`; with
``stiffest``, the search of :mod:`closedloop.analysis.stiffest`), then its statics
(:mod:`closedloop.analysis.path_points`), warm-started from the last point's. A point that
fails (a target out of reach, a singular pose, a joint limit, a limit load) ends the path
with its error, which names it and keeps the points before it (``partial``); SIGINT and
SIGTERM stop it as they stop a map (:mod:`closedloop.analysis.interrupts`), the points
computed kept.

With ``stiffest`` every point's configuration is found first (the search weighs the whole
path), then the statics. A path longer than a chunk runs its statics on the map's workers
(``workers``, or an ``executor`` such as Dask's; :func:`closedloop.analysis.tasks.run_tasks`)
once the configurations are known: they are computed first, in this process, one after the
other (each continues the last). Each chunk's first point solves its equilibrium by the
load continuation from rest, the others from the last: the results agree with the serial
run's to the statics' tolerance.
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np

from closedloop.analysis.interrupts import Interrupted, stop_on_signals
from closedloop.analysis.model_source import ModelSource, model_of
from closedloop.analysis.path_points import (
    PathStatics,
    PointStatics,
    compensated_rows,
    placement,
)
from closedloop.analysis.path_results import ARRAYS, PathResult
from closedloop.analysis.stiffest import (
    FREE_SIZE,
    MAX_CHANGE,
    StiffestChoice,
    StiffestSearch,
    check_freedom,
)
from closedloop.analysis.tasks import CHUNK, run_tasks_by_point
from closedloop.common.arrays import real_array
from closedloop.common.progress import progress
from closedloop.exceptions import ClosedLoopError, InvalidInputError
from closedloop.kinematics.assembly import close_loops
from closedloop.kinematics.frame_task import FrameTask, check_task, target_placement, xyzquat
from closedloop.kinematics.inverse import reach
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.gravity import GravityLoad, Payload


def check_path(path) -> np.ndarray:
    """(n, 7) the path's XYZQUAT rows (x, y, z [m], qx, qy, qz, qw), quaternions normalised.

    Raises:
        InvalidInputError: not an (n, 7) array of finite numbers with n >= 1, or a row whose
            quaternion is not of norm 1 (the message names the row).
    """
    rows = real_array(path, "path")
    if rows.ndim != 2 or rows.shape[1] != 7 or not len(rows):
        raise InvalidInputError(
            f"path must be (n, 7) rows x y z [m] qx qy qz qw (XYZQUAT, world axes), n >= 1, "
            f"got shape {rows.shape}"
        )
    return np.array([xyzquat(target_placement(x, f"path row {i}")) for i, x in enumerate(rows)])


def check_wrenches(wrench, n: int) -> np.ndarray:
    """(n, 6) the process wrench of every point [N, N m] from None (no wrench), one (6,) for
    all or (n, 6).

    Raises:
        InvalidInputError: another shape, or values that are not finite.
    """
    if wrench is None:
        return np.zeros((n, 6))
    w = real_array(wrench, "wrench")
    if w.shape == (6,):
        w = np.tile(w, (n, 1))
    if w.shape != (n, 6) or not np.isfinite(w).all():
        raise InvalidInputError(
            f"wrench must be 6 finite values (fx fy fz [N], nx ny nz [N m]) or one row of 6 "
            f"a point, ({n}, 6); got shape {w.shape}"
        )
    return w


def follow_path(
    model: ClosedLoopModel | ModelSource,
    frame: str,
    path,
    *,
    wrench=None,
    gravity=None,
    payloads: Sequence[Payload] = (),
    task: str = "pose",
    stiffest: bool = False,
    q0: np.ndarray | None = None,
    check_limits: bool = True,
    max_change: float = MAX_CHANGE,
    workers: int | None = None,
    executor: Executor | None = None,
    chunk: int = CHUNK,
    show_progress: bool = False,
) -> PathResult:
    """A path followed by ``frame`` under a load (module docstring; the result's arrays:
    :class:`~closedloop.analysis.path_results.PathResult`).

    Args:
        model: the model, or a :class:`ModelSource` (needed by process workers).
        frame: the frame that follows the path and carries the wrench.
        path: (n, 7) targets, XYZQUAT rows (x, y, z [m], qx, qy, qz, qw), world axes.
        wrench: the process load at the frame origin, world axes, a dead load: (6,) for
            every point or (n, 6), (fx, fy, fz [N], nx, ny, nz [N m]); None: none.
        gravity: (3,) acceleration [m/s^2] weighing the links (and ``payloads``) with the
            wrench, as in :func:`closedloop.elastostatics.statics.solve_equilibrium`.
        payloads: point masses (:class:`closedloop.model.gravity.Payload`), with gravity.
        task: ``"pose"``, ``"tool-axis"`` or ``"position"``
            (:func:`closedloop.kinematics.inverse.inverse_kinematics`).
        stiffest: choose the task's free coordinates for the least deflection
            (:mod:`closedloop.analysis.stiffest`); needs a task with freedom and six
            actuated joints or more.
        q0: (nq,) start whose branch the path follows (default: the model's reference
            configuration), assembled first.
        check_limits: refuse configurations, equilibria and commands outside the joints'
            position limits.
        max_change: with ``stiffest``, the largest change of a free coordinate between
            neighbouring points [rad] (> 0).
        workers, executor, chunk: the statics of a path longer than ``chunk`` on local
            processes (a :class:`ModelSource` is needed) or an executor, ``chunk`` points a
            task.
        show_progress: progress on stderr, in points.

    Raises:
        UnreachableError, SingularConfigurationError, OutsideLimitsError: a point's
            inverse kinematics fails. EquilibriumError (a limit load, or a compensation
            that does not converge), JointLimitError (an equilibrium or commands beyond the
            limits), MechanismError: a point's statics fail. The error of the first point
            that fails has a message that starts with "path point i of n" and the
            attributes ``point`` (i) and ``partial`` (a :class:`PathResult` of the points
            before it).
        InvalidInputError, NameNotFoundError: bad arguments (before any point).
        AssemblyError: q0 cannot be assembled.
        Interrupted: SIGINT or SIGTERM; its ``partial`` the points computed.
    """
    clm = model_of(model)
    clm.frame_id(frame)
    targets = check_path(path)
    n = len(targets)
    wrenches = check_wrenches(wrench, n)
    kind = check_task(task)
    if payloads and gravity is None:
        raise InvalidInputError("payloads weigh nothing without gravity: give gravity (3,)")
    weight = None if gravity is None else GravityLoad(clm, gravity, payloads)
    search = None
    if stiffest:
        check_freedom(clm, kind)
        search = StiffestSearch(clm, frame, kind, weight, check_limits, max_change)
    if not isinstance(chunk, int) or isinstance(chunk, bool) or chunk < 1:
        raise InvalidInputError(f"chunk must be a positive integer, got {chunk!r}")
    parallel = (workers or 1) > 1 or executor is not None
    if (workers or 1) > 1 and executor is None and not isinstance(model, ModelSource):
        raise InvalidInputError("worker processes need a ModelSource (files), not a model")
    start = clm.reference_configuration() if q0 is None else q0
    q = np.array(close_loops(clm, clm.check_configuration(start)).q)
    held = compensated_rows(clm, kind)
    run = _Run(clm, frame, kind, held, targets, wrenches, weight, search, check_limits)
    with stop_on_signals():
        try:
            if parallel and n > chunk:
                run.parallel(q, model, workers, executor, chunk, gravity, payloads, show_progress)
            else:
                run.serial(q, show_progress)
        except KeyboardInterrupt as e:
            stop = e if isinstance(e, Interrupted) else Interrupted()
            stop.partial = run.result()
            stop.progress = (stop.partial.n, n)
            if stop is e:
                raise
            raise stop from None
    if run.failure is not None:
        i, error = run.failure
        partial = run.result()
        error.args = (f"path point {i} of {n} (target {targets[i].tolist()}): {error}",)
        error.point, error.partial = i, partial
        raise error
    return run.result()


class _Run:
    """The points of one path, computed in order; ``failure``: (point, error) of the first
    point that failed, or None."""

    def __init__(self, clm, frame, task, held, targets, wrenches, weight, search, check_limits):
        self.clm, self.frame, self.task, self.held = clm, frame, task, held
        self.targets, self.wrenches, self.weight, self.search = targets, wrenches, weight, search
        self.check_limits = check_limits
        self.q_target: list[np.ndarray] = []
        self.chosen: list[tuple] = []  # with a search: (free, deflection, default) a point
        self.statics: dict[int, PointStatics] = {}
        self.failure: tuple[int, ClosedLoopError] | None = None

    def fail(self, i: int, error: ClosedLoopError) -> None:
        """Record the failure of point i, unless an earlier point failed."""
        if self.failure is None or i < self.failure[0]:
            self.failure = (i, error)

    def posture(self, i: int, q_prev: np.ndarray) -> np.ndarray:
        """The unloaded configuration of point i, the task continued from q_prev (nq,)."""
        goal = FrameTask(self.task, target_placement(self.targets[i]))
        return np.array(reach(self.clm, self.frame, goal, q_prev,
                              check_limits=self.check_limits).q)  # fmt: skip

    def postures(self, q: np.ndarray, show_progress: bool) -> None:
        """Every point's configuration first: the stiffest posture's search, or the task
        continued point to point (up to the first point that fails)."""
        if self.search is not None:
            targets = [target_placement(t) for t in self.targets]
            rows, failure = self.search.postures(q, targets, self.wrenches, show_progress)
            self.q_target = [row[0] for row in rows]
            self.chosen = [row[1:] for row in rows]
            if failure is not None:
                self.fail(*failure)
            return
        for i in range(len(self.targets)):
            try:
                q = self.posture(i, q)
            except ClosedLoopError as e:
                self.fail(i, e)
                return
            self.q_target.append(q)

    def serial(self, q: np.ndarray, show_progress: bool) -> None:
        """In this process: each point's posture then its statics, point after point (with
        a search, every posture first)."""
        statics = PathStatics(self.clm, self.frame, self.held, self.weight, self.check_limits)
        if self.search is not None:
            self.postures(q, show_progress)
        n = len(self.q_target) if self.search is not None else len(self.targets)
        for i in progress(range(n), total=n, label="path points", enabled=show_progress):
            try:
                if self.search is None:
                    q = self.posture(i, q)
                    self.q_target.append(q)
                point = statics.solve(self.q_target[i], self.wrenches[i])
            except ClosedLoopError as e:
                self.fail(i, e)
                return
            self.statics[i] = point

    def parallel(self, q, model, workers, executor, chunk, gravity, payloads, show_progress):
        """Every posture here first, then the statics by chunks on the workers."""
        self.postures(q, show_progress)
        k = len(self.q_target)
        firsts = list(range(0, k, chunk))
        tasks = [
            PathChunk(model, self.frame, self.held, np.array(self.q_target[f : f + chunk]),
                      self.wrenches[f : f + chunk], gravity, tuple(payloads), self.check_limits)
            for f in firsts
        ]  # fmt: skip
        sizes = [len(t.q_target) for t in tasks]
        running = run_tasks_by_point(path_chunk, tasks, sizes, executor, workers,
                                     label="path points", show_progress=show_progress)  # fmt: skip
        with contextlib.closing(running):  # stopped early, the workers end with it
            for c, (points, failure) in running:
                for j, point in enumerate(points):
                    self.statics[firsts[c] + j] = point
                if failure is not None:
                    self.fail(firsts[c] + failure[0], restored(failure[1]))

    def result(self) -> PathResult:
        """The points computed so far that follow one another from the first (those before
        the first failure, or before the first point not computed)."""
        m = 0
        while m in self.statics and m < len(self.q_target):
            m += 1
        if self.failure is not None:
            m = min(m, self.failure[0])
        clm, points = self.clm, [self.statics[i] for i in range(m)]
        nq, n_act = clm.model.nq, len(clm.actuated)

        def stack(name: str, width: int) -> np.ndarray:
            return np.array([getattr(p, name) for p in points]).reshape(m, width)

        poses = [xyzquat(placement(clm, q, self.frame)) for q in self.q_target[:m]]
        arrays = {
            "targets": self.targets[:m],
            "wrenches": self.wrenches[:m],
            "poses": np.array(poses).reshape(m, 7),
            "q_target": np.array(self.q_target[:m]).reshape(m, nq),
            **{k: stack(k, nq) for k in ("q_loaded", "q_compensated")},
            **{k: stack(k, n_act) for k in ("commands", "commands_first_order")},
            **{k: stack(k, 6) for k in ("error", "residual", "deflection_first_order",
                                          "residual_first_order")},
        }  # fmt: skip
        for name in ARRAYS:
            arrays[name] = np.array(arrays[name], dtype=float)
            arrays[name].flags.writeable = False
        choice = None
        if self.search is not None:
            d = FREE_SIZE[self.task]
            rows = self.chosen[:m]
            free = np.array([r[0] for r in rows]).reshape(m, d)
            deflection = np.array([r[1] for r in rows]).reshape(m)
            default = np.array([r[2] for r in rows]).reshape(m)
            for a in (free, deflection, default):
                a.flags.writeable = False
            choice = StiffestChoice(free, deflection, default, self.search.max_change)
        units = tuple("m" if lin else "rad"
                      for lin in clm.linear_coordinates[clm.actuated_v_indices])  # fmt: skip
        return PathResult(
            frame=self.frame, task=self.task, held=self.held, joints=tuple(clm.actuated),
            joint_units=units, gravity=self.weight, stiffest=choice, length=clm.length,
            **arrays,
        )  # fmt: skip


@dataclass(frozen=True)
class PathChunk:
    """The statics of consecutive points of a path, sent to a worker (picklable).

    Attributes:
        model: a :class:`ModelSource` (process workers) or the model (this process).
        frame, held: the loaded frame and the compensated task.
        q_target: (c, nq) the points' unloaded configurations.
        wrenches: (c, 6) their wrenches [N, N m].
        gravity: (3,) [m/s^2] or None; payloads: the payloads.
        check_limits: as :func:`follow_path`.
    """

    model: ClosedLoopModel | ModelSource
    frame: str
    held: str
    q_target: np.ndarray
    wrenches: np.ndarray
    gravity: object
    payloads: tuple
    check_limits: bool


def path_chunk(chunk: PathChunk):
    """(list of :class:`PointStatics`, failure) of a chunk's points in order: failure is
    None, or (position in the chunk, :func:`carried` error) of the first that failed (the
    chunk stops there)."""
    clm = model_of(chunk.model)
    weight = None if chunk.gravity is None else GravityLoad(clm, chunk.gravity, chunk.payloads)
    statics = PathStatics(clm, chunk.frame, chunk.held, weight, chunk.check_limits)
    points = []
    for j, (q, w) in enumerate(zip(chunk.q_target, chunk.wrenches, strict=True)):
        try:
            points.append(statics.solve(q, w))
        except ClosedLoopError as e:
            return points, (j, carried(e))
    return points, None


def carried(error: ClosedLoopError) -> tuple:
    """An error as picklable parts (its class, args and attributes): the errors of the
    project take more than a message to make, which pickle cannot give them back."""
    return type(error), error.args, dict(error.__dict__)


def restored(parts: tuple) -> ClosedLoopError:
    """The error of :func:`carried`'s parts."""
    cls, args, attributes = parts
    error = cls.__new__(cls)
    error.args = args
    error.__dict__.update(attributes)
    return error
