"""``closedloop view``: the deflection under a wrench in a meshcat viewer (its options are
shared with ``cahyman view``).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from closedloop.cli.options import PROG, add_wrench_arguments, mode_line, model_from_args
from closedloop.cli.parser import finite_float, path_text
from closedloop.exceptions import EXIT_OK
from closedloop.model.closed_loop import ClosedLoopModel


def add_view_arguments(p: argparse.ArgumentParser) -> None:
    """Options of a deflection view: wrench, amplification, output (SI)."""
    add_wrench_arguments(p)
    p.add_argument(
        "--scale",
        type=finite_float,
        metavar="S",
        help="amplification of the deflection (default: automatic, the largest "
        "point displacement shown as at most 10%% of the model size and the largest link "
        "rotation as at most 20 deg)",
    )
    p.add_argument(
        "--nonlinear", action="store_true", help="nonlinear static equilibrium along the load ramp"
    )
    p.add_argument(
        "--close-loops",
        action="store_true",
        help="draw the amplified joint deflection with its loops re-closed by the passive "
        "joints, instead of each link moved along its own twist",
    )
    p.add_argument(
        "--rotational", action="store_true", help="also the rotational compliance ellipsoid"
    )
    p.add_argument(
        "--html", type=path_text, metavar="FILE", help="write a self-contained HTML page"
    )
    p.add_argument(
        "--duration",
        type=finite_float,
        metavar="SECONDS",
        help="without --html: serve for this long (default: until Ctrl-C)",
    )
    p.add_argument(
        "--autoplay",
        action="store_true",
        help="play the load ramp (looping) once the page has loaded",
    )
    p.add_argument("--no-legend", action="store_true", help="no HTML legend on the page")


def view_from_args(
    clm: ClosedLoopModel,
    q: np.ndarray,
    frame: str,
    args,
    out=print,
    pose=None,
    prog=PROG,
    check_limits: bool = True,
):
    """Run :func:`closedloop.viewer.viewer.run_view` with :func:`add_view_arguments`' options.

    Warnings (a view without load) go to stderr, one line each, prefixed by ``prog``.
    ``pose``: the pose as the page's legend writes it (default q). ``check_limits``: refuse
    a q outside the joints' limits (False: ``--no-limits``, or the file's own
    configuration, as :func:`closedloop.cli.options.configuration`).
    """
    from closedloop.viewer.viewer import run_view  # meshcat is imported only for a view

    def warn(line: str) -> None:
        print(f"{prog}: warning: {line}", file=sys.stderr)

    return run_view(
        clm,
        q,
        frame,
        np.r_[args.force, args.torque],
        scale=args.scale,
        nonlinear=args.nonlinear,
        close_loops=args.close_loops,
        rotational=args.rotational,
        html=args.html,
        duration=args.duration,
        autoplay=args.autoplay,
        legend=not args.no_legend,
        pose=pose,
        out=out,
        warn=warn,
        check_limits=check_limits,
    )


def view(args: argparse.Namespace) -> int:
    """Run ``closedloop view``; returns the exit code (0)."""
    clm, state = model_from_args(args, geometry=True)
    given = args.q is not None or args.actuated is not None  # else the file's configuration
    mode = [line for line in [mode_line(clm, state.q)] if line]

    def out(line: str) -> None:  # the assembly mode first, once the view is computed
        if mode:
            print(mode.pop())
        print(line)

    view_from_args(clm, state.q, args.frame, args, out=out,
                   check_limits=given and not args.no_limits)  # fmt: skip
    return EXIT_OK
