"""Command line ``cahyman``: stiffness and deflection of CaHyMan at a pose.

Inputs are in the paper's units (degrees, millimetres); outputs are SI (JSON with
``--json``) with the paper's units beside them in the readable print. Examples::

    cahyman stiffness --alpha 45 60 75 --alpha4 45 --s4 0 --json
    cahyman deflect --force 1 1 1 --torque 0 0 0

Subcommands: every module named in :data:`SUBCOMMAND_MODULES` provides
``add_parser(subparsers)``, which adds its parser and sets ``func`` (``args -> int``) as
its default; :func:`~cahyman_pin.cli.options.add_pose_arguments` and
:func:`~cahyman_pin.cli.options.stiffness_from_args` are shared. Only
the module of the subcommand that runs is imported (the others stand in by their help
line), so that ``cahyman stiffness`` does not pay for matplotlib or the sweep machinery.

Exit status (as for ``closedloop``, :func:`closedloop.exceptions.exit_status`): 0 ok; 1 the
compliance is rank deficient (K does not exist); 2 bad input; 3 the computation failed on
valid input (an unreachable pose, a singular configuration); 141 standard output closed
early (``| head``). Errors are one line ``cahyman: error: ...`` on stderr. Parser, usage
error, number type, JSON writer and entry point are those of :mod:`closedloop.cli.common`.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from cahyman_pin.cli.stiffness import add_deflect, add_stiffness
from closedloop import __version__
from closedloop.cli.common import EXIT_HELP, add_subcommands, command_of, run_main
from closedloop.cli.parser import Parser

PROG = "cahyman"
#: Further subcommands: name -> (module defining ``add_parser(subparsers)``, help line).
SUBCOMMAND_MODULES: dict[str, tuple[str, str]] = {
    "report": ("cahyman_pin.cli.report", "write the comparison report against the paper"),
    "map": ("cahyman_pin.cli.map", "a stiffness index over swept inputs (NPZ, CSV, PNG)"),
    "view": ("cahyman_pin.cli.view", "meshcat view of the deflection under a wrench at M"),
    "modes": ("cahyman_pin.cli.modes", "natural frequencies at a pose (give the masses)"),
}


# ------------------------------------------------------------------ entry point
def build_parser(command: str | None = None, *, every: bool = False) -> argparse.ArgumentParser:
    """Parser with the built-in subcommands and those of :data:`SUBCOMMAND_MODULES`.

    Args:
        command: the subcommand that will run: only its module is imported; the other
            modules' subcommands are placeholders that carry their help line (enough for
            ``cahyman --help`` and for the list of choices of an unknown command).
        every: every subcommand built in full (:func:`reference_parser`).
    """
    parser = Parser(
        prog=PROG, description="Stiffness of CaHyMan (Cassino Hybrid Manipulator). " + EXIT_HELP
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    add_stiffness(subparsers)
    add_deflect(subparsers)
    add_subcommands(subparsers, SUBCOMMAND_MODULES, command, every=every)
    return parser


def reference_parser() -> argparse.ArgumentParser:
    """The parser with every subcommand built in full (options, description, epilog), for
    the command-line reference; it imports every subcommand's module, which the command
    itself never does."""
    return build_parser(every=True)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (see the module docstring)."""
    return run_main(PROG, lambda words: build_parser(command_of(words)), argv)


if __name__ == "__main__":
    raise SystemExit(main())
