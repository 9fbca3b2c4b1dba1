"""Benchmark CaHyMan: queries (the prepared one against its floor), sweeps, a 1e5-pose map,
closed form, the start-up of the command line."""

from __future__ import annotations

import resource
import statistics
import sys
import time
from functools import partial

import numpy as np
import pinocchio as pin
from benchtools import (
    START_MODES,
    Mode,
    Table,
    fmt_time,
    interleaved,
    load,
    parse_mode,
    wall_ratio,
)

from cahyman_pin.api import stiffness
from cahyman_pin.backends.consistent import consistent_compliance
from cahyman_pin.model import CaHyManModel, cahyman_model
from cahyman_pin.sweep import grid, sweep
from cahyman_pin.urdf_builder import FRAME_H, FRAME_M
from closedloop.analysis.indices import StiffnessIndices
from closedloop.common import lapack
from closedloop.elastostatics.batch import compliances
from closedloop.elastostatics.compliance import compliance
from closedloop.elastostatics.query import ComplianceQuery
from closedloop.kinematics.assembly import ASSEMBLY_TOL, free_coordinates, min_norm_solve
from closedloop.kinematics.configuration import Configuration
from closedloop.kinematics.constraints import jacobian_rows, residual_rows

#: Table 3's pose (alpha [rad], alpha_4 [rad], s_4 [m]), where single queries are timed.
POSE = (np.deg2rad([45.0, 60.0, 75.0]), np.deg2rad(45.0), 0.0)
#: The same pose on the command line (degrees, mm).
CLI_POSE = ["--alpha", "45", "60", "75", "--alpha4", "45", "--s4", "0", "--json"]
#: Leg-input range of the sweeps and maps [deg]; the arm is fixed at alpha_4 = 45 deg.
RANGE_DEG = (40.0, 80.0)
#: Grid sides of the serial sweeps; map grids (alpha_1, alpha_2, alpha_3 sides).
SWEEPS = (
    ("3a", "neighbour", "warm-started assembly + query in a sweep"),
    ("3b", "closed_form", "closed-form start + query in a sweep"),
)
SWEEP_SIDE = {"smoke": 3, "quick": 15, "full": 41}
MAP_SIDES = {"smoke": (6, 6, 1), "quick": (100, 100, 1), "full": (100, 100, 10)}
MAP_REPEATS = {"smoke": 1, "quick": 3, "full": 3}
#: No new map run after this many seconds of map runs [s].
MAP_BUDGET = {"smoke": 0.0, "quick": 20.0, "full": 120.0}
BATCH = {"smoke": 100, "quick": 10_000, "full": 10_000}
WORKERS = 2


def full_query(model: CaHyManModel, q: np.ndarray, path: str):
    """What ``api.stiffness`` computes once q is assembled: C, G, K, rank, residual (the
    compliance result), the plate twist J_H G, the pose and the stiffness indices."""
    length = model.params.length
    state = Configuration(model.clm, q, length=length)
    result = compliance(state, FRAME_M, path=path)
    return (
        result,
        state.frame_jacobian(FRAME_H) @ result.G,
        model.pose_from(state.q, state.data),
        StiffnessIndices.from_result(result, length=length),
    )


def leg_grid(sides: tuple[int, int, int]):
    """Grid of alpha_1 x alpha_2 x alpha_3 over RANGE_DEG (alpha_3 = 60 deg if one value)."""
    axes = {f"alpha{k + 1}": np.deg2rad(np.linspace(*RANGE_DEG, n))
            for k, n in enumerate(sides) if n > 1}  # fmt: skip
    alpha = None if len(axes) == 3 else np.deg2rad([60.0, 60.0, 60.0])
    return grid(axes, alpha=alpha, alpha4=POSE[1], s4=0.025)


def lean_query(model, data, closures, q, passive, sprung, root_compliance, fid):
    """The least the partitioned query computes: Pinocchio's kinematics, the closure
    Jacobians (welds without Jlog6, the identity at closure), the passive motion
    X = -J_p^+ J_s by the normal equations, B = (J_s + J_p X) K_s^-1/2, C = B B^T and the
    SVD of B for the rank (index sets given; no check, no scaling, no G, no K, no result)."""
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    for c, cd in closures:
        c.calc(model, data, cd)
    Jc = np.concatenate([c.jacobian(model, data, cd) for c, cd in closures])
    Jp = Jc[:, passive]
    X = np.linalg.solve(Jp.T @ Jp, -(Jp.T @ Jc[:, sprung]))
    J = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)
    B = (J[:, sprung] + J[:, passive] @ X) * root_compliance
    return B @ B.T, lapack.dgesdd(B)


def lean_floor(clm, q):
    """:func:`lean_query` at q with its index sets and constraint data made once."""
    k = clm.stiffness
    passive, sprung = np.flatnonzero(k == 0.0), np.flatnonzero(np.isfinite(k) & (k > 0.0))
    closures = [(c.constraint, c.constraint.createData()) for c in clm.closures]
    fid = clm.model.getFrameId(FRAME_M)
    return partial(lean_query, clm.model, clm.model.createData(), closures, q, passive, sprung,
                   1.0 / np.sqrt(k[sprung]), fid)  # fmt: skip


def bench_queries(table: Table, mode: Mode, model: CaHyManModel, q, unit) -> None:
    for p, key in (("auto", "1a"), ("null-space", "1b")):
        taken = compliance(model.clm, q, FRAME_M, path=p).path
        t = interleaved(lambda p=p: full_query(model, q, p), unit, mode)
        table.units(key, "CaHyMan generic query at an assembled pose, like for like (C, G, K, "
                    f"rank, residual, J_H G, pose, indices), path={p!r} -> {taken}",
                    "<= 50 units" if p == "auto" else "-", t)  # fmt: skip
    for p, key in (("auto", "1c"), ("null-space", "1d")):
        t = interleaved(lambda p=p: compliance(model.clm, q, FRAME_M, path=p), unit, mode)
        table.units(key, f"CaHyMan `closedloop.compliance` alone, path={p!r}", "-", t)
    floor = lean_floor(model.clm, q)
    t_floor = interleaved(floor, unit, mode)
    table.units("1h", "CaHyMan floor: C and the rank rule written out without any check "
                "(scripts/bench_cahyman.py lean_query: the kinematics, the six closure "
                "Jacobians, the partition given, the passive motion by the normal equations, "
                "C = B B^T, the SVD of B)", "-", t_floor)  # fmt: skip
    query = ComplianceQuery(model.clm, FRAME_M)
    t = interleaved(lambda: query(q), unit, mode)
    t_vs_floor = interleaved(lambda: query(q), floor, mode)
    table.row("1g", f"CaHyMan prepared `ComplianceQuery(clm, 'M')(q)` -> {query(q).path}",
              "<= 90 units (1.5x floor)", f"{t.ratio:.1f} units",
              f"{fmt_time(t.seconds)} = {t_vs_floor.ratio:.2f}x floor (timed against it); "
              f"unit {fmt_time(t.unit)}")  # fmt: skip
    t = interleaved(lambda: stiffness(*POSE), unit, mode)
    table.units("1e", "`cahyman_pin.api.stiffness` whole call (closed-form start, assembly, "
                "query)", "-", t)  # fmt: skip
    points = leg_grid((10, 10, 1))
    Q = np.array(
        [
            model.assemble(a, a4, s4)
            for a, a4, s4 in zip(points.alpha, points.alpha4, points.s4, strict=True)
        ]
    )
    t = interleaved(lambda: compliances(model.clm, Q, FRAME_M), unit, mode, per=len(Q))
    table.units("1f", f"CaHyMan `closedloop.compliances`, {len(Q)} assembled poses at once "
                "(C, G, rank)", "-", t, " per pose")  # fmt: skip


def bench_sweeps(table: Table, mode: Mode, unit) -> None:
    side = SWEEP_SIDE[mode.name]
    points = leg_grid((side, side, 1))
    n = len(points)
    step = (RANGE_DEG[1] - RANGE_DEG[0]) / (side - 1)
    for key, start, name in SWEEPS:
        run = partial(sweep, points, executor="serial", chunk_size=n, start=start)
        t = interleaved(run, unit, mode, per=n)
        iterations = np.bincount(run().iterations.clip(0)).tolist()
        table.units(key, f"{name} ({n} poses, {step:g} deg steps, serial, indices included)",
                    "<= 100 units", t, " per pose")  # fmt: skip
        table.note(f"{key}: Gauss-Newton iterations per assembly (count of 0, 1, 2...): "
                   f"{iterations}")  # fmt: skip


def warm_starts(model: CaHyManModel, side: int) -> list[tuple]:
    """(alpha, alpha_4, s_4, q0) of every point of the side x side grid of row 3a after
    the first three of its row: the start of its assembly there (the quadratic
    extrapolation of the last three assembled configurations,
    :func:`closedloop.analysis.map_engine.assemble_points`)."""
    clm, points = model.clm, leg_grid((side, side, 1))
    inputs = list(zip(points.alpha, points.alpha4, points.s4, strict=True))
    out = []
    for row in range(side):
        line = inputs[row * side : (row + 1) * side]
        Q = [model.assemble(*p) for p in line]
        for k in range(3, len(line)):
            q0 = pin.normalize(clm.model, 3.0 * Q[k - 1] - 3.0 * Q[k - 2] + Q[k - 3])
            out.append((*line[k], q0))
    return out


def lean_assembly(clm, actuated: np.ndarray, q0: np.ndarray, free: np.ndarray) -> int:
    """The floor of :func:`closedloop.kinematics.assembly.assemble` as row 3a calls it: its
    Gauss-Newton loop on the same pieces (closure rows, minimum-norm solve), and the
    closure Jacobian at the solution handed to the query, without any check, copy or
    result object; returns the iterations."""
    model, data, datas = clm.model, clm.data, clm.constraint_datas
    q = q0.copy()
    q[clm.actuated_q_indices] = actuated
    pin.computeJointJacobians(model, data, q)
    r, it = residual_rows(clm, data, datas), 0
    while abs(r).max() > ASSEMBLY_TOL * clm.length:  # point closures: metres / L
        step = np.zeros(model.nv)
        step[free] = -min_norm_solve(jacobian_rows(clm, data, datas, calc=False)[:, free], r)
        q = pin.integrate(model, q, step)
        pin.computeJointJacobians(model, data, q)
        r, it = residual_rows(clm, data, datas), it + 1
    jacobian_rows(clm, data, datas, calc=False)
    return it


def bench_assembly_floor(table: Table, mode: Mode, model: CaHyManModel, unit) -> None:
    """Row 3c: the assembly of row 3a alone, on its own warm starts, against its floor."""
    starts = warm_starts(model, max(SWEEP_SIDE[mode.name], 5))  # smoke: 2 starts a row
    free, clm = free_coordinates(model.clm), model.clm
    actuated = [np.concatenate([a, [a4, s4]]) for a, a4, s4, _ in starts]

    def library() -> list[int]:
        return [model.assemble(a, a4, s4, q0=q0, full_output=True, jacobian=True).iterations
                for a, a4, s4, q0 in starts]  # fmt: skip

    def lean() -> list[int]:
        return [lean_assembly(clm, x, s[3], free) for x, s in zip(actuated, starts, strict=True)]

    n = len(starts)
    t_lib = interleaved(library, unit, mode, per=n)
    t_lean = interleaved(lean, unit, mode, per=n)
    table.units("3c", f"assembly of row 3a alone, `CaHyManModel.assemble` from the same warm "
                f"starts ({n} poses)", "-", t_lib, " per pose")  # fmt: skip
    table.note(f"3c: a Gauss-Newton loop on the same pieces without any check (scripts/"
               f"bench_cahyman.py lean_assembly) {t_lean.ratio:.1f} units = "
               f"{fmt_time(t_lean.seconds)} per pose; iterations per pose, library "
               f"{np.mean(library()):.2f}, lean {np.mean(lean()):.2f}")  # fmt: skip


def cpu_seconds() -> float:
    """CPU time [s] of this process and of its reaped children (the sweep workers)."""
    me, children = (resource.getrusage(w) for w in (resource.RUSAGE_SELF,
                                                    resource.RUSAGE_CHILDREN))  # fmt: skip
    return me.ru_utime + me.ru_stime + children.ru_utime + children.ru_stime


def bench_map(table: Table, mode: Mode, unit) -> None:
    """Row 4, and the parallel efficiency: the same map serially and on WORKERS processes,
    in alternating pairs (a change of load hits both)."""
    points = leg_grid(MAP_SIDES[mode.name])
    n = len(points)
    pairs, result, before = [], {}, load()
    start = time.perf_counter()
    for _ in range(MAP_REPEATS[mode.name]):
        if pairs and time.perf_counter() - start > MAP_BUDGET[mode.name]:
            break
        t0, c0 = time.perf_counter(), cpu_seconds()
        sweep(points, executor="serial")
        t1, c1 = time.perf_counter(), cpu_seconds()
        result["r"] = sweep(points, workers=WORKERS)  # its pool is shut down: children reaped
        pairs.append((t1 - t0, time.perf_counter() - t1, c1 - c0, cpu_seconds() - c1))
    medians = (statistics.median(x) for x in zip(*pairs, strict=True))
    serial, parallel, serial_cpu, parallel_cpu = medians
    per_core = parallel * WORKERS / n
    u = interleaved(unit, unit, mode).seconds
    label = {"smoke": " (smoke run: a tiny map)", "quick": " (--quick: 1e4 poses, not 1e5)",
             "full": ""}[mode.name]  # fmt: skip
    table.row("4", f"{n}-pose generic map, {WORKERS} processes, start='closed_form'{label}",
              "<= 10 s (1e5 poses)", f"{parallel:.2f} s",
              f"{per_core * 1e6:.0f} us = {per_core / u:.0f} units per pose per core "
              f"(median of {len(pairs)})")  # fmt: skip
    table.note(f"4 (last run): {result['r'].summary()}")
    table.note(f"parallel efficiency on {WORKERS} processes: {serial / (WORKERS * parallel):.2f} "
               f"(target >= 0.8; {n} poses: serial {serial:.2f} s, {WORKERS} processes "
               f"{parallel:.2f} s, medians of {len(pairs)} alternating pairs; load average "
               f"{before} before, {load()} after); CPU time of the parallel run over the "
               f"serial one {parallel_cpu / serial_cpu:.2f} (the work the pool adds, whatever "
               "the load)")  # fmt: skip


def bench_closed_form(table: Table, mode: Mode, unit) -> None:
    rng = np.random.default_rng(0)
    n = BATCH[mode.name]
    alpha = np.deg2rad(rng.uniform(*RANGE_DEG, (n, 3)))
    alpha4, s4 = np.deg2rad(rng.uniform(0.0, 90.0, n)), rng.uniform(0.0, 0.05, n)
    t = interleaved(lambda: consistent_compliance(alpha, alpha4, s4), unit, mode, per=n)
    table.row("5", f"consistent closed form, batched ({n} poses)", "<= 5 us/pose",
              f"{t.seconds * 1e6:.2f} us/pose", f"{t.ratio:.1f} units per pose")  # fmt: skip


def bench_cli(table: Table, mode: Mode) -> None:
    """``cahyman stiffness --json`` (``python -m cahyman_pin``) against ``python -c "import
    pinocchio"``, its bytecode cached and compiled from source."""
    command = [sys.executable, "-m", "cahyman_pin", "stiffness", *CLI_POSE]
    reference = [sys.executable, "-c", "import pinocchio"]
    for start, key in zip(START_MODES, ("7", "7s"), strict=True):
        t = wall_ratio(command, reference, mode, start)
        table.command(key, "`cahyman stiffness --json` wall vs `python -c 'import pinocchio'`",
                      "<= 1.5x", t, start)  # fmt: skip


def main() -> None:
    mode = parse_mode(__doc__)
    table = Table("CaHyMan benchmarks", mode)
    model = cahyman_model()
    q = model.assemble(*POSE)
    unit = partial(pin.computeJointJacobians, model.clm.model, model.clm.model.createData(), q)
    bench_queries(table, mode, model, q, unit)
    bench_sweeps(table, mode, unit)
    bench_assembly_floor(table, mode, model, unit)
    bench_map(table, mode, unit)
    bench_closed_form(table, mode, unit)
    bench_cli(table, mode)
    table.close()


if __name__ == "__main__":
    main()
