"""``closedloop map``: a stiffness index over a grid of actuated inputs, as data and a figure.

    closedloop map MODEL [--closures F] --frame NAME --sweep JOINT=START:STOP:NUM
        [--sweep ...] [--fixed JOINT=VALUE ...] | --points FILE
        [--start Q ... | --near JOINT=VALUE ...]
        [--index NAME] [--force FX FY FZ] [--torque NX NY NZ]
        [--workers N | --scheduler ADDRESS [--worker-timeout S]] [--no-limits] [--out DIR]

Values are SI (rad, m). ``--points`` reads a text file of actuated values, one point a row
(whitespace or comma separated, the model's actuated order). A point whose actuated values
are outside their joints' limits has the status ``invalid``; ``--no-limits`` computes it
as any other. The path's first point is driven there from the model's reference
configuration, on its assembly mode, and each point from the last (``--start`` or
``--near``: from that start instead, on its mode; so a sprung passive joint gets its rest
value). The files are written by ``closedloop.analysis.maps.StiffnessMap.save``.
``--scheduler`` runs the chunks on a Dask distributed cluster (``pip install .[dask]``;
start one with ``dask scheduler`` and ``dask worker ADDRESS``): a lost worker's chunks are
retried on the others, a chunk lost with too many workers or a run without any worker for
``--worker-timeout`` seconds stops with one line (exit 3). SIGINT and SIGTERM: the epilog
of the help, :data:`closedloop.cli.map_options.SIGNALS_EPILOG`.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from closedloop.analysis.cluster import add_worker_timeout, dask_executor
from closedloop.analysis.interrupts import Interrupted, SignalStop, stop_on_signals
from closedloop.analysis.maps import ALL_INDICES, stiffness_map
from closedloop.analysis.model_source import ModelSource
from closedloop.analysis.tasks import CHUNK
from closedloop.cli.map_options import (
    SIGNALS_EPILOG,
    SpecError,
    check_map_size,
    index_line,
    map_wrench,
    parse_values,
    quoted,
)
from closedloop.cli.options import add_start_arguments, start_from_args
from closedloop.cli.outputs import output_folder
from closedloop.cli.parser import UsageError, finite_float, path_text, positive_int
from closedloop.common.arrays import decimal
from closedloop.common.input_files import read_text
from closedloop.exceptions import InvalidInputError

#: Points timed first for the estimate of a long map, and the time [s] the probe aims at
#: (ten times more points while it takes less; see _time_per_point).
PROBE, PROBE_SECONDS = 3, 0.1


def _sweep(text: str) -> tuple[str, np.ndarray]:
    name, sep, spec = text.partition("=")
    if not sep or not name:
        raise SpecError(f"{quoted(text)}: expected JOINT=START:STOP:NUM or JOINT=V1,V2,... (SI)")
    return name, parse_values(spec)


def _fixed(text: str) -> tuple[str, float]:
    name, sep, value = text.partition("=")
    if not sep or not name:
        raise SpecError(f"{quoted(text)}: expected JOINT=VALUE (SI)")
    return name, finite_float(value)


def add_parser(sub, parent_arguments) -> None:
    """The ``map`` subparser; ``parent_arguments(p)`` adds MODEL, --closures, --frame and
    the springs options."""
    p = sub.add_parser(
        "map",
        help="a stiffness index over a grid of actuated inputs (NPZ, CSV, PNG)",
        description=__doc__.split("\n\n", 1)[1].rsplit(" SIGINT and SIGTERM", 1)[0],
        epilog=SIGNALS_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parent_arguments(p)
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument(
        "--sweep",
        type=_sweep,
        action="append",
        metavar="JOINT=START:STOP:NUM",
        help="a swept joint: NUM values from START to STOP, or V1,V2,... (SI)",
    )
    what.add_argument("--points", metavar="FILE", help="actuated values, one point a row")
    p.add_argument("--fixed", type=_fixed, action="append", default=[], metavar="JOINT=VALUE")
    add_start_arguments(p)
    p.add_argument("--index", choices=sorted(ALL_INDICES), default="det_K", help="index to plot")
    for name, unit in (("--force", "N"), ("--torque", "N m")):
        p.add_argument(name, nargs=3, type=finite_float, metavar=("X", "Y", "Z"),
                       help=f"load of the deflection indices, world axes [{unit}]")  # fmt: skip
    run = p.add_mutually_exclusive_group()
    run.add_argument("--workers", type=positive_int, metavar="N", help="local processes")
    run.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler, e.g. tcp://h:8786")
    add_worker_timeout(p)
    p.add_argument("--chunk", type=positive_int, default=CHUNK, metavar="N", help="points per task")
    p.add_argument("--no-limits", action="store_true",
                   help="compute the points outside the joints' position limits too (invalid "
                   "by default)")  # fmt: skip
    p.add_argument("--out", type=path_text, default="closedloop-map", metavar="DIR",
                   help="output folder (default: ./%(default)s)")  # fmt: skip
    p.set_defaults(func=run_map)


def _points(path: str) -> np.ndarray:
    text = read_text(path, f"--points {path!r}", "CSV").replace(",", " ")
    try:
        rows = [[decimal(x) for x in line.split()] for line in text.splitlines() if line.strip()]
        points = np.array(rows, dtype=float)
    except ValueError:
        raise InvalidInputError(f"--points {path!r}: expected rows of numbers") from None
    if not rows:
        raise InvalidInputError(f"--points {path!r} has no points; expected rows of numbers")
    return points


def _grid(args) -> dict:
    """The grid of ``--sweep``/``--fixed`` or the points of ``--points``, checked: one
    ``--sweep`` and at most one ``--fixed`` a joint, no ``--fixed`` of a swept joint or
    with ``--points``."""
    fixed = [f"{name}={value:g}" for name, value in args.fixed]
    if args.points is not None:
        if fixed:
            raise UsageError(f"--fixed {fixed[0]} with --points: the file gives every actuated "
                             "value; give one of them")  # fmt: skip
        return {"points": _points(args.points)}
    swept = [name for name, _ in args.sweep]
    for name in swept:
        if swept.count(name) > 1:
            raise UsageError(f"--sweep {name}=... given {swept.count(name)} times; expected "
                             "one --sweep a joint")  # fmt: skip
    for (name, _), text in zip(args.fixed, fixed, strict=True):
        if name in swept:
            raise UsageError(f"--fixed {text}: joint {name!r} is swept (--sweep {name}=...); "
                             "give one of them")  # fmt: skip
        if [n for n, _ in args.fixed].count(name) > 1:
            raise UsageError(f"--fixed {name}=... given more than once; expected one a joint")
    return {"sweeps": dict(args.sweep), "fixed": dict(args.fixed)}


def model_source(args) -> ModelSource:
    """The :class:`ModelSource` of the MODEL, --closures, springs and --arg options."""
    from closedloop.cli.options import model_arguments
    from closedloop.io.data import resolve
    from closedloop.io.loader import read_springs_file

    robot, closures = resolve(args.model, args.closures)
    springs = read_springs_file(args.springs) if args.springs else {}
    frozen = tuple(sorted((k, tuple(v) if isinstance(v, list) else v) for k, v in springs.items()))
    values = tuple(sorted((model_arguments(args) or {}).items()))
    return ModelSource(str(robot), None if closures is None else str(closures), frozen,
                       args.joint_stiffness, values)  # fmt: skip


def run_map(args) -> int:
    """Run ``closedloop map``; returns the exit code (0). SIGINT and SIGTERM are handled from
    here to the last line of output (see the module docstring)."""
    with stop_on_signals(ignore_after=getattr(args, "program", False)) as signals:
        return _run_map(args, signals)


def _run_map(args, signals: SignalStop) -> int:
    wrench = map_wrench(args.index, args.force, args.torque)
    grid = _grid(args)
    sizes = [len(grid["points"])] if "points" in grid else [v.size for v in grid["sweeps"].values()]
    n = math.prod(sizes)
    check_map_size(n)
    source = model_source(args)
    clm = source.load()
    clm.frame_id(args.frame)
    out = output_folder(args.out)  # before any computation
    options = {"frame": args.frame, "wrench": wrench, "chunk": args.chunk,
               "modes": args.index == "lowest_frequency",
               "check_limits": not args.no_limits, "q0": start_from_args(clm, args)}  # fmt: skip
    with dask_executor(args.scheduler, args.worker_timeout) as executor:
        if n > PROBE:  # an estimate before a long run, from a few points computed here
            per_point = _time_per_point(clm, grid, n, options)
            share = max(1, args.workers or 1)
            print(f"closedloop map: {n} points, about {per_point * n / share:.3g} s "
                  f"({1e3 * per_point:.3g} ms a point)", file=sys.stderr)  # fmt: skip
        try:
            result = stiffness_map(
                source if (args.workers or args.scheduler) else clm,
                workers=args.workers,
                executor=executor,
                show_progress=True,
                **options,
                **grid,
            )
        except Interrupted as stop:  # the points computed, written before the one line
            stop.write(lambda partial: partial.save(out, args.index), out)
            raise
        signals.hold(result.data, out)  # every point computed: a signal lets the files be written
    paths = result.save(out, args.index)
    counts = {s: int(np.sum(result.status == s)) for s in np.unique(result.status)}
    print(f"{n} points: " + ", ".join(f"{c} {s}" for s, c in counts.items()))
    print(index_line(args.index, result.indices[args.index], ALL_INDICES[args.index]))
    for path in paths:
        print(f"wrote {path}")
    sys.stdout.flush()  # while a signal is held
    return 0


def _first(clm, grid, k: int) -> np.ndarray:
    """The first ``k`` points of the grid or the points (storage order), without building
    the whole grid: its leading axis cut to the rows that hold them."""
    from closedloop.analysis.maps import grid_points

    if "points" in grid:
        return grid["points"][:k]
    sweeps = dict(grid["sweeps"])
    lead = next(iter(sweeps))
    rest = math.prod(v.size for v in sweeps.values()) // sweeps[lead].size
    sweeps[lead] = sweeps[lead][: -(-k // rest)]
    return grid_points(clm, sweeps, grid["fixed"])[0][:k]


def _time_per_point(clm, grid, n: int, options: dict) -> float:
    """Seconds a point, timed on the first points: PROBE of them, ten times more while
    they take less than PROBE_SECONDS in all (a map call's fixed cost, about a
    millisecond, then weighs little) and stay at most a tenth of the map."""
    k = PROBE
    while True:
        t0 = time.perf_counter()
        stiffness_map(clm, **options, points=_first(clm, grid, k))
        elapsed = time.perf_counter() - t0
        if elapsed >= PROBE_SECONDS or 10 * k > n // 10:
            return elapsed / k
        k *= 10
