"""Command-line front end: ``closedloop stiffness MODEL --frame NAME ...``.

``closedloop view MODEL --frame NAME [--force ...] [--html FILE]`` shows the deflection
under a wrench in a meshcat viewer (see :mod:`closedloop.viewer.viewer`); ``closedloop deflect``
prints it (:mod:`closedloop.cli.deflect`), ``closedloop info MODEL`` lists what a model
holds (:mod:`closedloop.cli.info`), ``closedloop modes MODEL ...`` gives the natural
frequencies (:mod:`closedloop.cli.modes`), ``closedloop design PROBLEM.yaml`` optimises a
parametric model (:mod:`closedloop.cli.design`), ``closedloop path MODEL ...`` follows a path
under a process load and compensates its deflection (:mod:`closedloop.cli.path`).

MODEL is a robot file, a bundled model by name (``fourbar``, ``stewart``, ... with its
closure file; ``fourbar_mjcf``, ... the MJCF: :data:`closedloop.io.data.BUNDLED_MODELS`) or an
example-robot-data robot by name (``ur5``, ``panda``, ...; see :mod:`closedloop.io.data`).
A configuration outside the joints' limits is bad input (``--no-limits`` takes it).

Exit codes (the same for ``cahyman``; :func:`closedloop.exceptions.exit_status`):

* ``0`` - the stiffness K exists; K and C printed.
* ``1`` - the analysis succeeded but C is rank deficient: the frame is rigid along some
  directions, K does not exist. C and the rigid directions are printed (JSON: ``"K": null``).
  This is an answer, not an error, hence not 2; it differs from 0 so that scripts notice.
* ``2`` - bad input (missing file, unknown frame or joint, malformed closure file, wrong
  number of values, NaN, negative stiffness, joints outside their limits, an output
  path that cannot be written, a ``--q`` that does not close the loops): one line
  ``closedloop: error: <message>`` on stderr, a command-line syntax error included
  (:class:`closedloop.cli.parser.UsageError`); ``closedloop`` alone prints its help, the
  list of commands, before that line.
* ``3`` - the computation failed on valid input (loops that cannot be closed for these
  actuated values, no static equilibrium, a singular configuration or a mechanism, a result
  that is not finite): one line on stderr.
* ``141`` - standard output was closed early (``| head``); nothing more is written.

Start-up: a command imports only what it runs. The parser of the command named on the
command line is the only one built in full (:func:`build_parser`); the others stand in by
their help line (the command-line reference documents the parser with all of them in full,
:func:`reference_parser`). A subcommand lives in a module of its own with ``add_parser(subparsers,
arguments)`` and its function, listed in :data:`SUBCOMMAND_MODULES` (imported only when
it runs: :func:`closedloop.cli.common.add_subcommands`); ``stiffness`` and ``view``, built
here, import their modules when they run too. Below the command, heavy readers are imported
where a file needs them (:mod:`closedloop.io.loader`: the MJCF and SDF readers, beam
theory, balls and elastic closures). ``python -X importtime -m closedloop ...`` lists what
a command loads; ``tests/test_package.py`` checks it for ``stiffness`` and ``info``.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from closedloop import __version__
from closedloop.cli.common import EXIT_HELP, add_subcommands, command_of, run_main
from closedloop.cli.options import (
    PROG,
    add_model_arguments,
    add_preload_arguments,
    add_source_arguments,
)
from closedloop.cli.parser import Parser, finite_float

EPILOG = """\
Configuration: --q gives every coordinate of the model (nq values, SI: rad, m); --actuated
gives the actuated joints' values, driven there from the start in small steps while the
passive joints close the loops, on the start's assembly mode (start: the model's reference
configuration: its closure file's start:, MJCF qpos0, the springs' rest, else neutral;
--start Q or --near JOINT=VALUE: another start, another mode). Without either: the start,
assembled. The output names the passive joints' values of the mode used.
A configuration outside the joints' position limits is refused (angles in degrees are);
--no-limits takes it as it is.
A --q of a model with loops must close them to 1e-6 (metres per size of the mechanism, rad).

Springs: --joint-stiffness K gives stiffness K [N m/rad or N/m] to every actuated joint
that has no spring in the closure file (inf locks them; 1e999 is refused, not taken for
inf); --springs FILE is a YAML mapping joint -> stiffness
merged over the closure file's springs (.inf locks a joint). Actuated joints without a
spring are rigid. A URDF without closure file is a serial robot: the joints of its main
chain are actuated, joints beyond a branching (gripper fingers) are locked.

Output: C is the twist (dx dy dz [m], rx ry rz [rad]) per wrench (fx fy fz [N], nx ny nz
[N m]) at the frame origin, in world-aligned axes (--axes world) or the frame's own axes
(--axes local); K = C^-1, from a square-root factor of C. The rank and the condition
number are unit-free: lengths are divided by the size L of the mechanism. Above a scaled
condition number of 1e8 the result is flagged ill-conditioned (near a singular pose); below
an eigenvalue ratio of 1e-14 C is rank deficient.

Exit status: 0 K exists; 1 C is rank deficient (the rigid directions are named, K does
not exist, JSON "K": null); 2 bad input; 3 the computation failed (loops that cannot be
closed, no equilibrium, a singular configuration); 141 output closed early; errors are one
line on stderr.

Examples:
  closedloop stiffness ur5 --frame tool0 --q 0 -1.0 1.5 -0.5 1.2 0.3 --joint-stiffness 1e4
  closedloop stiffness fourbar --frame P --actuated 0.3
"""


#: Further subcommands: name -> (module defining ``add_parser(subparsers, arguments)``,
#: help line); imported only when they run (the map's imports Dask's and tqdm's code).
SUBCOMMAND_MODULES: dict[str, tuple[str, str]] = {
    "map": (
        "closedloop.cli.map",
        "a stiffness index over a grid of actuated inputs (NPZ, CSV, PNG)",
    ),
    "identify": ("closedloop.cli.identify", "fit spring stiffnesses to measured deflections"),
    "modes": ("closedloop.cli.modes", "natural frequencies and mode shapes at a pose"),
    "info": ("closedloop.cli.info", "joints, frames, closures, springs and sizes of a model"),
    "deflect": ("closedloop.cli.deflect", "twist of a frame and joint deflections under a load"),
    "design": ("closedloop.cli.design", "optimise a parametric model over its workspace"),
    "path": (
        "closedloop.cli.path",
        "a path under a process load: its deflection and compensation (CSV, NPZ, PNG)",
    ),
}


#: Help lines of the subcommands built here.
STIFFNESS_HELP = "Cartesian stiffness K and compliance C of a frame"
VIEW_HELP = "meshcat view of the deflection under a wrench"


def _add_stiffness(sub) -> None:
    """The parser of ``closedloop stiffness``."""
    p = sub.add_parser(
        "stiffness",
        help=STIFFNESS_HELP,
        description="Cartesian stiffness K and compliance C of a frame (SI units).",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_model_arguments(p)
    p.add_argument("--axes", choices=("world", "local"), default="world", help="axes of K and C")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument(
        "--wrench", nargs=6, type=finite_float, metavar="W",
        help="fx fy fz [N] nx ny nz [N m] at the frame (in --axes): print the share of the "
        "deflection energy stored in each spring and beam (none when the wrench does no "
        "work)",
    )  # fmt: skip
    add_preload_arguments(p)
    p.set_defaults(func=_stiffness)


def _stiffness(args: argparse.Namespace) -> int:
    from closedloop.cli.stiffness import stiffness  # the query's modules, when it runs

    return stiffness(args)


def _add_view(sub) -> None:
    """The parser of ``closedloop view``."""
    from closedloop.cli.view import add_view_arguments, view

    v = sub.add_parser(
        "view",
        help=VIEW_HELP,
        description="Nominal pose (translucent ghost), amplified deflected pose, wrench arrows,\n"
        "compliance ellipsoids and an HTML legend (load, amplification, real displacements\n"
        "in mm and deg, colour key) in a meshcat viewer. --html writes a self-contained\n"
        "page; without it the viewer is served on 127.0.0.1 until Ctrl-C or SIGTERM.",
        epilog=EPILOG.split("\n\nOutput:")[0],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_model_arguments(v)
    add_view_arguments(v)
    v.set_defaults(func=view)


def build_parser(command: str | None = None, *, every: bool = False) -> argparse.ArgumentParser:
    """Argument parser of the ``closedloop`` command; only ``command``'s parser is built
    in full, only its module imported (module docstring); ``every``: all of them
    (:func:`reference_parser`)."""
    parser = Parser(
        prog=PROG,
        description="Stiffness and compliance of robots with closed loops. " + EXIT_HELP,
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (add, help_line) in {"stiffness": (_add_stiffness, STIFFNESS_HELP),
                                   "view": (_add_view, VIEW_HELP)}.items():  # fmt: skip
        if every or command == name:
            add(sub)
        else:  # its help line (as add_subcommands)
            sub.add_parser(name, help=help_line, add_help=False)
    add_subcommands(sub, SUBCOMMAND_MODULES, command, add_source_arguments, every=every)
    return parser


def reference_parser() -> argparse.ArgumentParser:
    """The parser with every subcommand built in full (options, description, epilog), for
    the command-line reference; it imports every subcommand's module, which the command
    itself never does."""
    return build_parser(every=True)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``closedloop`` command; returns the exit code (see module doc)."""
    return run_main(PROG, lambda words: build_parser(command_of(words)), argv)


if __name__ == "__main__":
    sys.exit(main())
