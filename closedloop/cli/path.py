"""``closedloop path``: a path under a process load, its deflection and its compensation.

    closedloop path MODEL --frame NAME --path FILE.csv
        [--force FX FY FZ] [--torque NX NY NZ] | [--wrenches FILE.csv]
        [--gravity [GX GY GZ]] [--payload MASS [X Y Z]]
        [--task pose|tool-axis|position] [--stiffest [--max-change RAD]]
        [--q Q ... | --actuated A ...] [--no-limits]
        [--workers N | --scheduler ADDRESS [--worker-timeout S]] [--chunk N]
        [--out DIR] [--json] [--html FILE]

``--path``: a CSV file with a header naming the columns x,y,z,qx,qy,qz,qw (the frame's
target poses: position [m], unit quaternion, world axes; one row a point; other columns are
ignored). The load: a constant --force/--torque [N, N m] or ``--wrenches``, a CSV file with
the columns fx,fy,fz,nx,ny,nz, one row a point, at the frame origin, world axes, dead
loads; --gravity weighs the links with it. The path starts on the branch of the --q or
--actuated configuration (default: the model's own, assembled). The task: ``pose`` (the
target's position and orientation), ``tool-axis`` (its position and z axis: the rotation
about the tool axis is free), ``position``; --stiffest chooses the free rotation for the
least deflection, at most --max-change rad from one point to the next.

Written to --out (default ./closedloop-path): path.csv and path.npz (per point: the error
under the load, the first-order and the exact compensation's residuals, the commands),
path_error.png (the error along the path, mm and mrad, before and after compensation) and
path_3d.png (the path and its deflection, amplified); --html FILE a meshcat page of the
robot at the point of largest deflection with the path and the deflected path. A point that
cannot be computed (out of reach, a singular pose, a joint limit, a limit load) ends the
run with one line naming it (exit 3, or 2 for a joint limit of the inverse kinematics),
the points before it written. SIGINT (Ctrl-C) or SIGTERM stops the run and writes the
points computed (exit 130 or 143). Long paths run their statics on --workers processes or
a Dask --scheduler, once every configuration is found here (each continuing the last).
"""

from __future__ import annotations

import argparse

from closedloop.analysis.cluster import add_worker_timeout
from closedloop.cli.parser import UsageError, finite_float, path_text, positive_int

#: The columns of a --path file and of a --wrenches file.
PATH_COLUMNS = ("x", "y", "z", "qx", "qy", "qz", "qw")
WRENCH_COLUMNS = ("fx", "fy", "fz", "nx", "ny", "nz")


def add_parser(sub, source_arguments) -> None:
    """The ``path`` subparser, with the model and start options of ``stiffness``."""
    from closedloop.cli.options import (
        add_model_arguments,
        add_preload_arguments,
        add_wrench_arguments,
    )

    p = sub.add_parser(
        "path",
        help="a path under a process load: its deflection and compensation (CSV, NPZ, PNG)",
        description=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_model_arguments(p)
    p.add_argument("--path", required=True, type=path_text, metavar="FILE",
                   help="CSV of target poses, columns x,y,z,qx,qy,qz,qw")  # fmt: skip
    add_wrench_arguments(p)
    p.add_argument("--wrenches", type=path_text, metavar="FILE",
                   help="CSV of one wrench a point, columns fx,fy,fz,nx,ny,nz "
                   "(instead of --force/--torque)")  # fmt: skip
    add_preload_arguments(
        p, "MASS [kg] [X Y Z]: a point mass at the frame, offset in its axes [m] (needs "
        "--gravity)", preload=False,
    )  # fmt: skip
    p.add_argument("--task", choices=("pose", "tool-axis", "position"), default="pose",
                   help="what the frame meets at each point (default: pose)")  # fmt: skip
    p.add_argument("--stiffest", action="store_true",
                   help="choose the task's free rotation for the least deflection")  # fmt: skip
    p.add_argument("--max-change", type=finite_float, metavar="RAD",
                   help="with --stiffest: largest change of the free rotation between "
                   "neighbouring points [rad] (default 0.1)")  # fmt: skip
    run = p.add_mutually_exclusive_group()
    run.add_argument("--workers", type=positive_int, metavar="N", help="local processes")
    run.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler, e.g. tcp://h:8786")
    add_worker_timeout(p)
    p.add_argument("--chunk", type=positive_int, metavar="N",
                   help="points per task of the workers (default 500)")  # fmt: skip
    p.add_argument("--out", type=path_text, default="closedloop-path", metavar="DIR",
                   help="output folder (default: ./%(default)s)")  # fmt: skip
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.add_argument("--html", type=path_text, metavar="FILE",
                   help="a meshcat page of the robot, the path and its deflection")  # fmt: skip
    p.set_defaults(func=run_path)


def read_columns(path: str, option: str, columns: tuple[str, ...]):
    """(n, k) the named ``columns`` of a CSV file with a header (other columns ignored).

    Raises:
        InvalidInputError: the file cannot be read, lacks a column, has no rows, or holds a
            value that is not a number (the message names the option, the line and the
            value).
    """
    import csv
    from pathlib import Path

    import numpy as np

    from closedloop.common.arrays import decimal
    from closedloop.exceptions import InvalidInputError

    try:
        lines = Path(path).read_text(encoding="utf-8").splitlines()
    except OSError as e:
        raise InvalidInputError(f"{option} {path!r}: {e.strerror}") from None
    except UnicodeDecodeError:
        raise InvalidInputError(f"{option} {path!r}: not a text file (UTF-8)") from None
    rows = [row for row in csv.reader(lines) if any(cell.strip() for cell in row)]
    header = [h.strip() for h in rows[0]] if rows else []
    missing = [c for c in columns if c not in header]
    if missing:
        raise InvalidInputError(
            f"{option} {path!r}: header {header} lacks {missing}; expected a first line "
            f"naming the columns {','.join(columns)}"
        )
    if len(rows) < 2:
        raise InvalidInputError(f"{option} {path!r} has no rows below its header")
    index = [header.index(c) for c in columns]
    values = np.empty((len(rows) - 1, len(columns)))
    for i, row in enumerate(rows[1:]):
        for j, k in enumerate(index):
            cell = row[k].strip() if k < len(row) else ""
            try:
                values[i, j] = decimal(cell)
            except ValueError:
                raise InvalidInputError(
                    f"{option} {path!r}: row {i + 1} column {columns[j]!r} is {cell!r}; "
                    "expected a number"
                ) from None
    return values


def _wrenches(args, count: int):
    """The wrenches (n, 6) of --force/--torque or --wrenches, for ``count`` points."""
    import numpy as np

    from closedloop.exceptions import InvalidInputError

    if args.wrenches is None:
        return np.r_[args.force, args.torque]
    if any(args.force) or any(args.torque):
        raise UsageError("--wrenches with --force/--torque: give one of them")
    w = read_columns(args.wrenches, "--wrenches", WRENCH_COLUMNS)
    if len(w) != count:
        raise InvalidInputError(
            f"--wrenches {args.wrenches!r} has {len(w)} rows; expected one a point of "
            f"--path ({count})"
        )
    return w


def run_path(args) -> int:
    """Run ``closedloop path``; returns the exit code (0)."""
    from closedloop.analysis.cluster import dask_executor
    from closedloop.analysis.interrupts import Interrupted
    from closedloop.analysis.paths import follow_path
    from closedloop.analysis.tasks import CHUNK
    from closedloop.cli.options import model_from_args, preload_from_args
    from closedloop.cli.outputs import output_folder, print_json
    from closedloop.exceptions import ClosedLoopError

    if args.max_change is not None and not args.stiffest:
        raise UsageError(f"--max-change {args.max_change:g} without --stiffest")
    path = read_columns(args.path, "--path", PATH_COLUMNS)
    wrench = _wrenches(args, len(path))
    preload = preload_from_args(args)
    clm, state = model_from_args(args, geometry=args.html is not None)
    out = output_folder(args.out)  # before any computation
    model = clm
    if args.workers or args.scheduler:
        from closedloop.cli.map import model_source

        model = model_source(args)
    options = {"task": args.task, "stiffest": args.stiffest, "q0": state.q,
               "check_limits": not args.no_limits, "workers": args.workers,
               "chunk": args.chunk or CHUNK, "show_progress": True, **preload}  # fmt: skip
    if args.max_change is not None:
        options["max_change"] = args.max_change
    with dask_executor(args.scheduler, args.worker_timeout) as executor:
        try:
            result = follow_path(model, args.frame, path, wrench=wrench, executor=executor,
                                 **options)  # fmt: skip
        except Interrupted as stop:  # the points computed, written before the one line
            stop.write(lambda partial: partial.save(out), out)
            raise
        except ClosedLoopError as e:
            partial = getattr(e, "partial", None)
            if partial is not None and partial.n:
                partial.save(out)
                e.args = (f"{e}; the {partial.n} points before it written to {out}",)
            raise
    paths = result.save(out)
    summary = result.summary()
    if args.html is not None:
        from closedloop.viewer.path_view import run_path_view

        lines = []  # the page's summary: after the path's
        run_path_view(clm, result, html=args.html, out=lines.append)
        paths.append(args.html)
    if args.json:
        print_json({**summary, "written": [str(p) for p in paths]})
        return 0
    for line in summary_lines(summary):
        print(line)
    if args.html is not None:
        print(lines[0])
    for p in paths:
        print(f"wrote {p}")
    return 0


def summary_lines(summary: dict) -> list[str]:
    """The text of a path's summary (:meth:`~closedloop.PathResult.summary`): points, and
    the largest error without compensation, with the first-order and with the exact one
    (mm, mrad)."""
    lines = [
        f"{summary['points']} points, frame {summary['frame']!r}, task {summary['task']} "
        f"(compensated: {summary['compensated']})"
    ]
    for key, name in (("error", "without compensation"),
                      ("residual_first_order", "first-order compensation"),
                      ("residual", "exact compensation")):  # fmt: skip
        e = summary[key]
        lines.append(
            f"{name:>26}: largest error {1e3 * e['translation_m']:.4g} mm (point "
            f"{e['at_point']}), {summary['rotation']} {1e3 * e['rotation_rad']:.4g} mrad "
            f"(point {e['rotation_at_point']})"
        )
    if "stiffest" in summary:
        s = summary["stiffest"]
        lines.append(
            f"stiffest posture: deflection {s['gain_median']:.4g} times smaller than the "
            f"default posture's (median; {s['gain_min']:.4g} to {s['gain_max']:.4g})"
        )
    return lines
