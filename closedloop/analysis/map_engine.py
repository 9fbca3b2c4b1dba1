"""The sweep engine of the maps: a path through many points, chunks, kernels, executors.

Four parts, shared by :mod:`closedloop.analysis.maps` and CaHyMan's maps (:mod:`cahyman_pin.sweep`):

* a **path** through the points (:func:`path_order`: a grid is walked by unit steps, a
  boustrophedon in two dimensions) cut into **chunks** of contiguous points;
* a **kernel**, any picklable callable ``kernel(task) -> ChunkResult`` computing one chunk
  (compliance, rank, status and reason per point; a point that fails is recorded, never
  the whole map lost);
* :func:`run_tasks`: the chunks in this process, on local processes or on any
  ``concurrent.futures.Executor`` (e.g. Dask's ``Client.get_executor()``): the results do
  not depend on the executor;
* :func:`complete` (in each kernel, so in the workers): the rank and status from C
  (:func:`classify`) and the stiffness indices of the chunk's points at once; those that
  the formed C does not resolve (an ill-conditioned point) as the single query computes
  them (:func:`resolve_ill_conditioned`);
* :func:`gather`: per-point arrays (no per-point Python objects: statuses and reasons
  are small integer codes).

A map stops at once on SIGINT (Ctrl-C) or SIGTERM (:func:`stop_on_signals`, in
:func:`gather`): its worker processes are ended (they ignore SIGINT themselves, and end with
their parent), the chunks not received are marked ``not_computed``, and
:class:`Interrupted` (a ``KeyboardInterrupt``) carries what was computed.

The kernel for any :class:`~closedloop.model.closed_loop.ClosedLoopModel` is :func:`assemble_chunk`:
each point is assembled by :func:`closedloop.kinematics.assembly.assemble` from the previous point's
configuration along the path (or from a per-point start provider), then the chunk's
compliances are computed together (:mod:`closedloop.elastostatics.batch`, the single query
:func:`closedloop.elastostatics.compliance.compliance` where the stacked path does not answer).
Every chunk carries the configuration its first point starts from, computed serially along the
path before the chunks are sent (:func:`border_starts`), so that a chunk border does not
restart from the reference configuration (which may lie on another assembly mode).
"""

from __future__ import annotations

import bisect
import contextlib
import ctypes
import functools
import itertools
import math
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from closedloop.analysis.indices import StiffnessIndices, batch_indices
from closedloop.common.blas import single_threaded_blas
from closedloop.common.conditioning import (
    ILL_CONDITIONED,
    SCALED_TOL,
    Spectrum,
    batch_rank,
    scaled_asymmetry,
)
from closedloop.common.progress import progress
from closedloop.elastostatics.batch import QUERY_ERRORS, STACK, answered
from closedloop.elastostatics.compliance import compliance
from closedloop.exceptions import (
    AssemblyError,
    ClusterError,
    InvalidInputError,
    MechanismError,
    RigidDirectionsError,
    SingularConfigurationError,
)
from closedloop.io.loader import load_model, reference_configuration
from closedloop.kinematics.assembly import free_coordinates
from closedloop.kinematics.driving import (
    INPUT_STEP,
    assemble_connected,
    assemble_within_limits,
    input_scale,
)
from closedloop.model.closed_loop import ClosedLoopModel

#: Status of a point, by code (its index in this tuple); ``not_computed``: the map was
#: interrupted before the point's chunk was computed (:class:`Interrupted`).
STATUS = ("ok", "rank_deficient", "invalid", "unreachable", "singular", "failed", "not_computed")
OK, RANK_DEFICIENT, INVALID, UNREACHABLE, SINGULAR, FAILED, NOT_COMPUTED = range(len(STATUS))
#: Signals that stop a map (:func:`stop_on_signals`).
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: ``prctl`` option: the signal a process receives when its parent ends (Linux).
PR_SET_PDEATHSIG = 1
#: Exceptions recorded per point (anything else, a programming error, propagates).
POINT_ERRORS = QUERY_ERRORS
#: Points per task when not given: enough to amortise a task's overhead (pickling, the
#: model load in a fresh process), small enough for a few tasks per core.
CHUNK = 500
#: Most points between two assemblies of the serial pass that computes the chunks' starts
#: (:func:`border_starts`; fewer where they span more than INPUT_STEP), and the stride of
#: that pass across a gap of failed points.
BORDER_STRIDE = 16
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
        condition: (c,) scaled condition number cond(K_s) from the solver's factor, NaN
            where unknown (a closed form: then computed from C).
        status: (c,) status codes (:data:`STATUS`).
        length: (c,) characteristic length [m] of the scaled indices.
        iterations: (c,) Gauss-Newton iterations of the assembly, -1 if none.
        reasons: error message per failed point, by position in the chunk.
        indices: name -> (c,) stiffness indices (:func:`complete`; empty until then).
        K: position -> (6, 6) stiffness [SI] of the single query (from its square-root
            factor) at the points whose cond(K_s) exceeds ``ILL_CONDITIONED``
            (:meth:`answer`), for :func:`resolve_ill_conditioned`.
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


def complete(out: ChunkResult, wrench: np.ndarray | None, relabel=None) -> None:
    """Rank, status and stiffness indices of a chunk's points, in place (in the kernel, so
    that the workers of a map compute them in parallel): :func:`classify`, then
    ``relabel(out, from_C)`` if given (a caller's own statuses; from_C (c,) bool: the
    rank came from C, not from the solver), then
    :func:`closedloop.analysis.indices.batch_indices` into ``out.indices``, the ill-conditioned
    points' by :func:`resolve_ill_conditioned`."""
    from_C = out.rank < 0
    symmetric = classify(out)
    if relabel is not None:
        relabel(out, from_C)
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow fails its point, below
        out.indices = batch_indices(out.C, out.rank, out.length, wrench, symmetric, out.condition)
    resolve_ill_conditioned(out, symmetric)
    for name, values in out.indices.items():  # NaN: no value; inf: the index overflowed
        beyond = np.isinf(values) | ((values == 0.0) if name == "det_K" else False)  # det K
        # of a full-rank K is never 0: one that underflowed
        for i in np.flatnonzero(beyond & np.isin(out.status, (OK, RANK_DEFICIENT))):
            way = "overflows" if np.isinf(values[i]) else "underflows"
            out.status[i], out.C[i] = FAILED, np.nan
            reason = f"the index {name} {way} the floating point range (a load or spring"
            out.set_reason(i, reason + " far from the mechanism's scale; expected nearer)")
            for other in out.indices.values():
                other[i] = np.nan


def resolve_ill_conditioned(out: ChunkResult, symmetric: np.ndarray) -> None:
    """``det_K``, ``condition_number_si`` and ``condition_number`` of the full-rank
    symmetric points that the formed C does not resolve to rounding, as the single query
    computes them (:attr:`closedloop.analysis.indices.StiffnessIndices.determinant`,
    ``.condition_number``, ``.scaled_condition_number``), in ``out.indices`` (in place).

    Those are the points of cond(K_s) above ``ILL_CONDITIONED`` (1e8) or of an SI
    condition number that :func:`closedloop.analysis.indices.batch_indices` leaves NaN (above its
    ``SI_RESOLVED``, 1e12). From the formed C, det K and the SI condition number err by
    about eps cond(K_s) relative (2e-8 at 1e8, 2e-4 at 1e12, nothing left at 1e16); from
    the solver's square-root factor, by about eps sqrt(cond(K_s)) (2e-8 at 1e16). K is the
    single query's where the kernel recorded it (``out.K``: every point above
    ``ILL_CONDITIONED`` of the project's kernels, :meth:`ChunkResult.answer`); else (an SI
    condition number beyond ``SI_RESOLVED`` at a scaled one below 1e8, which a length unit
    alone makes so, or a kernel that records no K) from the eigen-decomposition of the
    scaled C (:meth:`~closedloop.analysis.indices.StiffnessIndices.from_compliance`: eps cond(K_s)
    relative). A det K beyond the float range becomes inf or 0 (its point fails in
    :func:`complete`, as a point of the batch); the indices of a point whose C has rank
    < 6 by that rule (a kernel without K, cond(K_s) near 1e14) are NaN.
    """
    names = ("det_K", "condition_number_si", "condition_number")
    det, cond_si, cond = (out.indices[name] for name in names)
    full = symmetric & (out.rank == 6)
    for i in np.flatnonzero(full & ~((cond <= ILL_CONDITIONED) & (cond_si >= 0.0))):
        C, K, L = out.C[i], out.K.get(i), float(out.length[i])
        try:
            if K is None:  # from C only
                s = StiffnessIndices.from_compliance(C, length=L)
            else:  # as StiffnessIndices.from_result of the single query
                spectrum = Spectrum(6, np.zeros((6, 0)), float(out.condition[i]), L, K)
                s = StiffnessIndices(C, 6, spectrum.rigid_directions, L, spectrum)
            cond_si[i], cond[i] = s.condition_number, s.scaled_condition_number
            det[i] = s.determinant
        except SingularConfigurationError:  # det K beyond the float range
            det[i] = math.inf if np.linalg.slogdet(s.K)[1] > 0.0 else 0.0
        except RigidDirectionsError:  # C of rank < 6 by the rule on C
            for name in names:
                out.indices[name][i] = np.nan


def assemble_points(clm, frame, out, rows, solve, first=None, starts=None, axes="world",
                    length=None, inputs=None, check_limits=True):  # fmt: skip
    """Assemble the points ``rows`` of a chunk in order (warm-started), then query them.

    The compliances of the assembled points are computed together, :data:`STACK` at a
    time (:func:`closedloop.elastostatics.batch.stacked_compliances`); a point the stacked path
    leaves (near a singular pose, rank deficient...) gets the single query
    :func:`closedloop.elastostatics.compliance.compliance`, whose error, if any, is the point's. A
    point of cond(K_s) above ``ILL_CONDITIONED`` takes the single query's C, rank,
    condition number and K (``out.K``: from its square-root factor, which the formed C
    does not replace there; :func:`resolve_ill_conditioned`).

    Args:
        clm: the :class:`ClosedLoopModel`.
        frame: the loaded frame.
        out: the :class:`ChunkResult` to fill.
        rows: positions in the chunk, in path order.
        solve: ``solve(i, q0) -> Assembly`` of the point at position i from ``q0`` (nq,).
        first: start of the first point, passed to ``solve`` (None too).
        starts: (len(rows), nq) start of every point (a start provider), or None: each
            point starts from the last assembled one.
        axes, length: as :func:`closedloop.elastostatics.compliance.compliance`.
        inputs: (c, m) inputs of the chunk's points, or None. Given, a point whose step
            from the last point repeats the step before (to :data:`EQUAL_STEP_RTOL`)
            starts from an extrapolation of the last points (:func:`_extrapolated`)
            instead of the last one (fewer Gauss-Newton iterations along a grid line).
        check_limits: as for :func:`closedloop.elastostatics.compliance.compliance`.
    """
    history: list = []  # q of the last three assembled points, in a row
    q_prev, assembled = first, []
    repeated = _repeated_steps(inputs, rows) if starts is None and inputs is not None else None
    for k, i in enumerate(rows):
        q0 = q_prev if starts is None else starts[k]
        if repeated is not None and len(history) >= 2 and repeated[k]:
            q0 = _extrapolated(clm, history, quadratic=len(history) == 3 and repeated[k - 1])
        try:
            a = solve(i, q0)
        except POINT_ERRORS as e:
            out.fail(i, e)
            history = []
            continue
        assembled.append((i, a))
        q_prev, history = a.q, [*history[-2:], a.q]
        if len(assembled) == STACK:  # queried a stack at a time: the closure Jacobians
            _query_points(clm, frame, out, assembled, axes, length, check_limits)  # they hold
            assembled = []  # are let go
    _query_points(clm, frame, out, assembled, axes, length, check_limits)


def _query_points(clm, frame, out, assembled: list, axes: str, length, check_limits) -> None:
    """The compliance of each assembled point ``(position, Assembly)`` into ``out``."""
    if not assembled:
        return
    Q = np.array([a.q for _, a in assembled])
    positions = np.array([i for i, _ in assembled])
    closure = None
    if all(a.closure is not None for _, a in assembled):  # evaluated by the assemblies
        closure = tuple(np.array(c) for c in zip(*(a.closure for _, a in assembled), strict=True))
    C, _, rank, cond, _, errors, L = answered(clm, Q, frame, axes, length, POINT_ERRORS,
                                              closure=closure,
                                              check_limits=check_limits)  # fmt: skip
    ok = rank >= 0
    done = positions[ok]
    out.C[done], out.rank[done], out.condition[done], out.length[done] = (
        C[ok],
        rank[ok],
        cond[ok],
        L,
    )
    out.iterations[done] = [a.iterations for (_, a), s in zip(assembled, ok, strict=True) if s]
    for k, e in errors.items():
        out.fail(positions[k], e)
    for k in np.flatnonzero(ok & (cond > ILL_CONDITIONED)):  # the single query's K (and C)
        i = positions[k]
        try:
            r = compliance(clm, Q[k], frame, axes, length=length, check_limits=check_limits)
        except POINT_ERRORS as e:
            out.fail(i, e)
            continue
        out.answer(i, r.C, r.rank, r.condition_number, r.stiffness_matrix)


def _repeated_steps(inputs: np.ndarray, rows) -> np.ndarray:
    """(len(rows),) bool: the step of the inputs into ``rows[k]`` repeats the step into
    ``rows[k - 1]`` (to :data:`EQUAL_STEP_RTOL`)."""
    steps = np.diff(inputs[np.asarray(rows, dtype=int)], axis=0)  # steps[k - 1]: into k
    repeated = np.zeros(len(steps) + 1, dtype=bool)
    before, step = steps[:-1], steps[1:]
    tol = EQUAL_STEP_RTOL * np.max(abs(before), axis=1, initial=0.0)
    repeated[2:] = np.max(abs(step - before), axis=1, initial=0.0) <= tol
    return repeated


def _extrapolated(clm, history: list, quadratic: bool) -> np.ndarray:
    """The warm start after a repeated input step, from the last assembled points.

    With q1, q2, q3 the last three (q1 the last): after the same step three times in a
    row (``quadratic``), the extrapolation 3 q1 - 3 q2 + q3 of the coordinates,
    normalised onto the configuration manifold (quaternions and unit complex numbers), an
    error of third order in the step; after twice, q1 + (q1 - q2) on the manifold (second
    order).
    """
    q1, q2 = history[-1], history[-2]
    if quadratic:
        q = q1 - q2
        q *= 3.0
        q += history[-3]
        return pin.normalize(clm.model, q)
    return pin.integrate(clm.model, q1, pin.difference(clm.model, q2, q1))


@dataclass(frozen=True)
class ModelSource:
    """Where a model comes from, so that worker processes can load it themselves.

    Attributes: the arguments of :func:`closedloop.io.loader.load_model` (paths as strings).
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


def model_of(model: ClosedLoopModel | ModelSource) -> ClosedLoopModel:
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
        wrench: (6,) wrench of the deflection indices [N, N m] at the frame, or None.
        modes: also the index ``lowest_frequency`` [Hz] of every point
            (:func:`closedloop.analysis.vibration.lowest_frequencies`).
        check_limits: False: points outside the joints' limits are computed too.
    """

    model: ClosedLoopModel | ModelSource
    frame: str
    points: np.ndarray
    first: np.ndarray | None = None
    start: Callable | None = None
    wrench: np.ndarray | None = None
    modes: bool = False
    check_limits: bool = True

    def __len__(self) -> int:
        return len(self.points)


def assemble_chunk(chunk: MapChunk) -> ChunkResult:
    """The kernel of :func:`stiffness_map`: every point of ``chunk``, warm-started, and
    their indices. Each point starts from the last one assembled, and is driven there in
    steps of at most :data:`closedloop.kinematics.driving.INPUT_STEP` where it is further
    (:func:`closedloop.kinematics.driving.assemble_connected`); with a start provider, from its
    start in one solve."""
    clm = model_of(chunk.model)
    out = ChunkResult.empty(len(chunk))
    starts = None if chunk.start is None else chunk.start(clm, chunk.points)
    first = chunk.first
    if first is None and starts is None:  # the path's first chunk (a start provider: unused)
        first = path_start(clm, chunk.points, chunk.check_limits)
    last = [None]  # the inputs of the last point assembled (q0: its configuration)
    configurations = {}  # position -> q of the assembled points

    def solve(i: int, q0):
        a = drive(clm, chunk.points[i], q0, last[0] if starts is None else None,
                  check_limits=chunk.check_limits)  # fmt: skip
        last[0] = chunk.points[i]
        configurations[i] = a.q
        return a

    assemble_points(clm, chunk.frame, out, range(len(chunk)), solve, first, starts,
                    check_limits=chunk.check_limits)  # fmt: skip
    complete(out, chunk.wrench)
    if chunk.modes:  # the vibration module on demand
        from closedloop.analysis.vibration import lowest_frequencies

        done = np.isin(out.status, (OK, RANK_DEFICIENT))
        out.indices["lowest_frequency"] = lowest_frequencies(clm, configurations, done)
    return out


def path_start(clm: ClosedLoopModel, points: np.ndarray, check_limits: bool = True) -> np.ndarray:
    """(nq,) start of a map's path: its first point assembled on the mode of the file's
    configuration (:func:`closedloop.kinematics.driving.assemble_connected`), as ``closedloop
    stiffness --actuated`` assembles it; the file's configuration where that fails (the
    point's own assembly then reports why)."""
    reference = reference_configuration(clm)
    if not len(points):
        return reference
    try:
        return np.array(assemble_connected(clm, points[0], reference, jacobian=False,
                                           check_limits=check_limits).q)  # fmt: skip
    except POINT_ERRORS:
        return reference


def drive(clm: ClosedLoopModel, actuated: np.ndarray, q0, start: np.ndarray | None, *,
          jacobian: bool = True, check_limits: bool = True):  # fmt: skip
    """:func:`closedloop.kinematics.driving.assemble_within_limits` of ``actuated`` (n_act,) from q0
    (nq,), whose inputs are ``start`` (None: unknown, solved at once); driven there in
    steps of at most INPUT_STEP (:func:`closedloop.kinematics.driving.assemble_connected`) where it
    is further than that and the assembly moves a coordinate (a passive joint)."""
    far = start is not None and (
        np.max(np.abs(actuated - start) / input_scale(clm), initial=0.0) > INPUT_STEP
    )
    if far and _free(clm):
        return assemble_connected(clm, actuated, q0, jacobian=jacobian, check_limits=check_limits)
    return assemble_within_limits(clm, actuated, q0, jacobian=jacobian, check_limits=check_limits)


def _free(clm: ClosedLoopModel) -> bool:
    """Whether the assembly moves any coordinate (once per model)."""
    return bool(clm.memo("free_coordinates", lambda: free_coordinates(clm)).size)


def border_starts(clm: ClosedLoopModel, points: np.ndarray, firsts: Sequence[int],
                  check_limits: bool = True) -> list:  # fmt: skip
    """Start configuration of each chunk, by a serial continuation along the path.

    The pass assembles the points of :func:`continuation_points` (steps of at most
    :data:`closedloop.kinematics.driving.INPUT_STEP` along the path, as :func:`path_start` is
    reached, and at most :data:`BORDER_STRIDE` points) and the chunk borders ``firsts``, each from
    the previous one (the first from :func:`path_start`), and keeps the configurations at
    the borders: the first point of a chunk then starts on the assembly mode the path
    followed, as in a serial run. (A jump of 16 points, checked against two half jumps,
    left the mode: the four-bar over a whole crank turn in 40 points, chunks of 16, had 16
    points on the other mode, C up to 51 % off; both half jumps landed there too.) Where a
    point fails, the pass walks again point by point from the last assembled one, past the
    failure to the next point that assembles, as a serial run does: across a gap of failed
    points the continuation jumps from the same configuration to the same point whatever
    the chunks (a failed border keeps the last assembled configuration, as a serial run).
    A gap of :data:`BORDER_STRIDE` failed points or more is crossed :data:`BORDER_STRIDE`
    points at a time (the pass stays a small share of the map, failed points being the
    costliest): after it, the branch may depend on the chunks.

    Args:
        points: (n, n_act) actuated values in path order [rad, m].
        firsts: path positions of the chunks' first points (ascending, from 0).

    Returns:
        One (nq,) configuration, or None for the first chunk (the reference), per border.
    """
    q = path_start(clm, points, check_limits)
    wanted = set(firsts[1:])
    last = max(wanted, default=-1)
    visit = sorted(wanted | set(continuation_points(clm, points[: last + 1])))
    crossing = sorted(wanted | set(range(0, last, BORDER_STRIDE)))  # in a long gap
    found: dict = {}
    p, done, failed = 0, -1, None  # done: position of the last assembled point
    while p <= last:
        try:
            start = points[done] if done >= 0 else None  # q's inputs, as the kernel's
            q = drive(clm, points[p], q, start, jacobian=False, check_limits=check_limits).q
            ok = True
        except POINT_ERRORS:
            ok = False
        found[p] = q
        if ok:
            done = p
        if failed is None and not ok and p - done <= BORDER_STRIDE:  # walk again from the
            failed, p = p, done + 1  # last assembled point (not in a long gap: crossed)
            continue
        if failed is not None:  # point by point, to the first success after the failure
            if not (ok and p >= failed) and p - done < BORDER_STRIDE:
                p += 1
                continue
            failed = None  # found, or a long gap: crossed BORDER_STRIDE points at a time
        ahead = visit if ok else crossing
        k = bisect.bisect_right(ahead, p)
        p = ahead[k] if k < len(ahead) else last + 1
    return [None, *(found.get(p) for p in firsts[1:])][: len(firsts)]


def continuation_points(clm: ClosedLoopModel, points: np.ndarray) -> list[int]:
    """Path positions the border pass assembles between the chunk borders (ascending,
    from 0; the same whatever the chunks).

    From each, the next is the farthest point along the path within
    :data:`closedloop.kinematics.driving.INPUT_STEP` of path length (the largest change of an
    actuated value, lengths in units of the characteristic length L, summed over the path's steps:
    the step of :func:`closedloop.kinematics.driving.assemble_connected`), at most
    :data:`BORDER_STRIDE` points on and at least the next point (a step longer than
    INPUT_STEP is driven in steps of INPUT_STEP, as a chunk drives it). A model whose
    assembly moves no coordinate (no passive joint) has one configuration per point,
    whatever the start: only the first position, the borders being enough.

    Args:
        points: (n, n_act) actuated values in path order [rad, m].
    """
    n = len(points)
    if n < 2 or not _free(clm):
        return [0]
    steps = np.max(np.abs(np.diff(points, axis=0)) / input_scale(clm), axis=1)
    arc = np.concatenate(([0.0], np.cumsum(steps)))  # path length up to each point
    out, v = [0], 0
    while v < n - 1:
        j = int(np.searchsorted(arc, arc[v] + INPUT_STEP, side="right")) - 1
        v = min(max(j, v + 1), v + BORDER_STRIDE, n - 1)
        out.append(v)
    return out


class Interrupted(KeyboardInterrupt):
    """A map stopped by SIGINT (Ctrl-C) or SIGTERM: its workers ended, what it computed kept.

    A ``KeyboardInterrupt``, so that code that catches Ctrl-C catches it. :func:`gather`
    raises it with ``data``; :func:`closedloop.analysis.maps.stiffness_map` and
    :func:`cahyman_pin.sweep.sweep` attach their result as ``partial`` and re-raise it.

    Attributes:
        signum: the signal (SIGINT, also for a plain ``KeyboardInterrupt``, or SIGTERM).
        data: the :class:`PointData` so far, or None (stopped outside a map): the points of
            the chunks not received have status ``not_computed`` and the reason
            :attr:`reason`, NaN values.
        partial: the map's result built on ``data`` (a
            :class:`~closedloop.analysis.maps.StiffnessMap` or a
            :class:`~cahyman_pin.sweep.SweepResult`), or None.
        written: the folder ``partial`` was written to (:meth:`write`), or None.
    """

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(signum)
        self.signum = signal.Signals(signum)
        self.data: PointData | None = None
        self.partial = None
        self.written = None

    @property
    def reason(self) -> str:
        """The reason of the points not computed, e.g. ``interrupted by SIGINT``."""
        return f"interrupted by {self.signum.name}"

    def write(self, save: Callable, folder) -> None:
        """Write ``partial`` (if any) by ``save(partial)`` into ``folder``, and say so in
        the message."""
        if self.partial is not None:
            save(self.partial)
            self.written = folder

    def __str__(self) -> str:
        text = f"interrupted ({self.signum.name})"
        if self.data is None or self.written is None:
            return f"{text}; nothing written"
        done = int(np.count_nonzero(self.data.codes != NOT_COMPUTED))
        return f"{text}: wrote {done} of {len(self.data.codes)} points to {self.written}"


@contextlib.contextmanager
def stop_on_signals():
    """Inside the block, SIGINT and SIGTERM raise :class:`Interrupted`, once: a later one is
    ignored until the block ends, so that the clean-up after the first (workers ended, a
    partial map written) is not cut short. Only in the main thread (where Python runs its
    signal handlers), and only for a signal whose handler is Python's default (SIGINT:
    ``KeyboardInterrupt``; SIGTERM: the end of the process): an ignored signal, a
    handler of the program's own or of an enclosing block stay as they are."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    defaults = {signal.SIGINT: signal.default_int_handler, signal.SIGTERM: signal.SIG_DFL}
    received: list[int] = []

    def stop(signum, frame):
        if not received:
            received.append(signum)
            raise Interrupted(signum)

    previous = {s: signal.signal(s, stop) for s, h in defaults.items() if signal.getsignal(s) is h}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def _start_worker() -> None:
    """Initializer of a map's worker processes (started with SIGINT and SIGTERM blocked,
    :func:`run_tasks`): SIGINT ignored (a Ctrl-C reaches the whole process group; the
    parent ends the workers), SIGTERM ends the process, the process ends with its parent
    (Linux: even a parent killed by SIGKILL), one BLAS thread."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        parent = os.getppid()
        ctypes.CDLL(None).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
        if os.getppid() != parent:  # ended before prctl
            os._exit(1)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
    single_threaded_blas()


@contextlib.contextmanager
def _signals_blocked():
    """SIGINT and SIGTERM blocked in this thread inside the block, and so in the processes
    it starts until their initializer (:func:`_start_worker`) has set what the signals do
    there; a signal received meanwhile is handled at the end of the block. Nothing where
    Python cannot block signals (Windows)."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)


def _end_pool(pool: ProcessPoolExecutor) -> None:
    """End the processes of ``pool`` at once, their running tasks with them (the executor
    has no public way to stop a running task: its processes are its ``_processes``), then
    its thread, which finds them gone and fails the pending tasks (none may be cancelled
    first: the thread of Python 3.11 raises on a cancelled one, with a traceback)."""
    processes = list((pool._processes or {}).values())
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

    Stopped early (an exception, e.g. :class:`Interrupted` or ``KeyboardInterrupt``, or
    the generator closed), the tasks not started are cancelled and the local processes
    ended at once, their running tasks lost; an executor's running tasks are left to it.

    Args:
        kernel: picklable callable (a module-level function) for process executors.
        tasks: the tasks (picklable for process executors).
        executor: any ``concurrent.futures.Executor``, used as given and left open.
        workers: without an executor, local processes (a pool ended at the end), at most
            one per task and per core (more would only wait); None or 1: this process.
            They ignore SIGINT and end with this process (:func:`_start_worker`).

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
    try:
        with _signals_blocked():  # the processes are started here
            if executor is None:
                pool = ProcessPoolExecutor(workers, initializer=_start_worker)
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
            _end_pool(pool)


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
        indices: name -> (n,) stiffness indices of the chunks (:func:`complete`).
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


def gather(n: int, pieces: Sequence[np.ndarray], results: Iterator, wrench=None) -> PointData:
    """Per-point arrays from the results of the chunks.

    SIGINT and SIGTERM stop it (:func:`stop_on_signals`), as a ``KeyboardInterrupt`` does:
    ``results`` is closed (which ends the workers of :func:`run_tasks`) and
    :class:`Interrupted` raised, its ``data`` the arrays so far, the points of the chunks
    not received ``not_computed``.

    Args:
        n: number of points.
        pieces: storage indices of each chunk's points, in chunk order.
        results: (chunk index, :class:`ChunkResult`) pairs in any order
            (e.g. :func:`run_tasks`).
        wrench: (6,) wrench of the chunks' deflection indices [N, N m], or None: the
            indices of a map whose chunks are all lost (their names).

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
            _not_computed(data, [pieces[k] for k in np.flatnonzero(~received)], wrench, stop)
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


def _not_computed(data: PointData, pieces: list, wrench, stop: Interrupted) -> None:
    """Mark the points of ``pieces`` not computed (in place), attach ``data`` to ``stop``."""
    empty = ChunkResult.empty(0)
    complete(empty, wrench)
    for name in empty.indices:
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


def classify(data: ChunkResult) -> np.ndarray:
    """Complete the rank and status of computed points from their compliance (in place).

    A symmetric C without a rank (not from the solver: a closed form) gets the rank of
    :func:`closedloop.common.conditioning.batch_rank`, and becomes ``failed`` if it is not
    positive semi-definite; a non-symmetric C counts as full rank (K = C^-1); a computed
    point of rank < 6 becomes ``rank_deficient``; C is NaN wherever the status is neither.

    Returns:
        (n,) bool: C is symmetric (and computed).
    """
    C, rank, codes = data.C, data.rank, data.status
    computed = (codes == OK) & np.all(np.isfinite(C), axis=(1, 2))
    symmetric = computed & (scaled_asymmetry(np.where(computed[:, None, None], C, 0.0),
                                             data.length) <= SCALED_TOL)  # fmt: skip
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
