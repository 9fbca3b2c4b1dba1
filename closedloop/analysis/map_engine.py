"""The sweep engine of the maps: a path through many points, chunks, the kernel that computes one.

Five parts, shared by :mod:`closedloop.analysis.maps` and CaHyMan's maps (:mod:`cahyman_pin.sweep`):

* a **path** through the points (:func:`path_order`: a grid is walked by unit steps, a
  boustrophedon in two dimensions) cut into **chunks** of contiguous points;
* a **kernel**, any picklable callable ``kernel(task) -> ChunkResult`` computing one chunk
  (:class:`~closedloop.analysis.map_results.ChunkResult`: compliance, rank, status and reason
  per point; a point that fails is recorded, never the whole map lost);
* :func:`closedloop.analysis.tasks.run_tasks`: the chunks in this process, on local processes
  or on any ``concurrent.futures.Executor`` (e.g. Dask's ``Client.get_executor()``): the
  results do not depend on the executor;
* :func:`closedloop.analysis.complete.complete` (in each kernel, so in the workers): the rank
  and status from C and the stiffness indices of the chunk's points at once;
* :func:`closedloop.analysis.tasks.gather`: per-point arrays
  (:class:`~closedloop.analysis.map_results.PointData`).

A map stops at once on SIGINT (Ctrl-C) or SIGTERM (:mod:`closedloop.analysis.interrupts`).

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
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.analysis.complete import complete
from closedloop.analysis.map_results import OK, POINT_ERRORS, RANK_DEFICIENT, ChunkResult
from closedloop.analysis.model_source import ModelSource, model_of
from closedloop.common.conditioning import ILL_CONDITIONED
from closedloop.elastostatics.batch import STACK, answered
from closedloop.elastostatics.query import ComplianceQuery
from closedloop.kinematics.assembly import free_coordinates
from closedloop.kinematics.driving import (
    INPUT_STEP,
    assemble_connected,
    assemble_within_limits,
    input_scale,
)
from closedloop.model.closed_loop import ClosedLoopModel

#: Most points between two assemblies of the serial pass that computes the chunks' starts
#: (:func:`border_starts`; fewer where they span more than INPUT_STEP), and the stride of
#: that pass across a gap of failed points.
BORDER_STRIDE = 16
#: Relative tolerance on equal steps for extrapolating a warm start.
EQUAL_STEP_RTOL = 1e-9


def assemble_points(clm, frame, out, rows, solve, first=None, starts=None, axes="world",
                    length=None, inputs=None, check_limits=True):  # fmt: skip
    """Assemble the points ``rows`` of a chunk in order (warm-started), then query them.

    The compliances of the assembled points are computed together, :data:`STACK` at a
    time (:func:`closedloop.elastostatics.batch.stacked_compliances`); a point the stacked path
    leaves (near a singular pose, rank deficient...) gets the single query
    :func:`closedloop.elastostatics.compliance.compliance`, whose error, if any, is the point's. A
    point of cond(K_s) above ``ILL_CONDITIONED`` takes the single query's C, rank,
    condition number and K (``out.K``: from its square-root factor, which the formed C
    does not replace there; :func:`~closedloop.analysis.complete.resolve_ill_conditioned`).

    Args:
        clm: the :class:`ClosedLoopModel`.
        frame: the loaded frame.
        out: the :class:`~closedloop.analysis.map_results.ChunkResult` to fill.
        rows: positions in the chunk, in path order.
        solve: ``solve(i, q0) -> Assembly`` of the point at position i from ``q0`` (nq,).
        first: start of the first point, passed to ``solve`` (None too).
        starts: (len(rows), nq) start of every point (a start provider), or None: each
            point starts from the last assembled one.
        axes, length: as :func:`closedloop.elastostatics.compliance.compliance`.
        inputs: (c, m) inputs of the chunk's points, or None. Given, a point whose step
            from the last point repeats the step before (to :data:`EQUAL_STEP_RTOL`)
            starts from an extrapolation of the last points (linear after two equal steps
            in a row, quadratic after three, on the configuration manifold) instead of the
            last one (fewer Gauss-Newton iterations along a grid line).
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
    query = None
    for k in np.flatnonzero(ok & (cond > ILL_CONDITIONED)):  # the single query's K (and C)
        i = positions[k]
        try:
            if query is None:  # made once (one that cannot be made raises at each point)
                query = ComplianceQuery(clm, frame, axes, length=length, check_limits=check_limits)
            r = query(Q[k])
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
class MapChunk:
    """One task of :func:`assemble_chunk`: points contiguous along the path.

    Attributes:
        model: the model or its :class:`~closedloop.analysis.model_source.ModelSource`
            (Pinocchio's constraint models cannot be pickled: process executors need the
            source).
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
    """The kernel of :func:`~closedloop.analysis.maps.stiffness_map`: every point of
    ``chunk``, warm-started, and their indices. Each point starts from the last one
    assembled, and is driven there in steps of at most
    :data:`closedloop.kinematics.driving.INPUT_STEP` where it is further
    (:func:`closedloop.kinematics.driving.assemble_connected`); with a start provider, from
    its start in one solve."""
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


def path_start(clm: ClosedLoopModel, points: np.ndarray, check_limits: bool = True,
               q0: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
    """(nq,) start of a map's path: its first point assembled on the mode of q0 (nq,),
    default the model's reference configuration
    (:func:`closedloop.kinematics.driving.assemble_connected`), as ``closedloop stiffness
    --actuated`` assembles it; q0 where that fails (the point's own assembly then reports
    why)."""
    reference = clm.reference_configuration() if q0 is None else q0
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
                  check_limits: bool = True, q0: np.ndarray | None = None) -> list:  # fmt: skip
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
        q0: (nq,) the configuration the path starts from (:func:`path_start`).

    Returns:
        One (nq,) configuration per border, the first the path's start.
    """
    q = path_start(clm, points, check_limits, q0)
    first = q
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
    return [first, *(found.get(p) for p in firsts[1:])][: len(firsts)]


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
