"""What both command lines (``closedloop``, ``cahyman``) share to run, so that they follow one
convention: the entry point that parses the command line (:mod:`closedloop.cli.parser`) and
runs a parsed subcommand to its exit status (:func:`closedloop.exceptions.exit_status`),
one-line warnings and errors (:mod:`closedloop.cli.outputs`), the subcommands imported only
when they run. The Dask executor of ``--scheduler`` is
:func:`closedloop.analysis.cluster.dask_executor` (lost workers and a run without workers end
as one line, never a hang)."""

from __future__ import annotations

import argparse
import contextlib
import importlib
import signal
import sys
import warnings
from collections.abc import Callable, Sequence

import numpy as np

from closedloop.cli.outputs import (
    CREATED,
    EXIT_PIPE,
    check_html_options,
    closed_pipe,
    error_line,
    output_failed,
    remove_empty_outputs,
)
from closedloop.cli.parser import UsageError
from closedloop.common.blas import single_threaded_blas
from closedloop.exceptions import (
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_OK,
    EXIT_RANK_DEFICIENT,
    ClosedLoopError,
    exit_status,
)

#: The exit statuses, as the help of both command lines states them.
EXIT_HELP = (
    f"Exit status: {EXIT_OK} ok; {EXIT_RANK_DEFICIENT} rank deficient (K does not exist); "
    f"{EXIT_BAD_INPUT} bad input; {EXIT_FAILED} computation failed (loops that cannot be "
    f"closed, an unreachable pose, no equilibrium, a singular configuration); {EXIT_PIPE} "
    "output closed early. Errors are one line on stderr."
)


#: Warnings from one place of the code printed in full; the others are counted.
WARNINGS_PER_PLACE = 3


@contextlib.contextmanager
def one_line_warnings(prog: str):
    """Python warnings raised inside, printed as ``prog: warning: message`` (one line on
    stderr) instead of Python's two lines with the source file and line; filtered as
    Python does by default for code outside ``__main__`` (once per message and place;
    deprecations of the libraries underneath, import and resource warnings not shown),
    whatever the filters of the caller (a test runner shows them all). Of different
    messages from one place (one per load step of a nonlinear view), the first
    :data:`WARNINGS_PER_PLACE` are printed and the others counted in one line."""
    places: dict = {}

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        n = places[filename, lineno] = places.get((filename, lineno), 0) + 1
        if n <= WARNINGS_PER_PLACE:
            print(f"{prog}: warning: {' '.join(str(message).split())}", file=sys.stderr)

    with warnings.catch_warnings():
        warnings.simplefilter("default")
        for category in (DeprecationWarning, PendingDeprecationWarning, ImportWarning,
                         ResourceWarning):  # fmt: skip
            warnings.simplefilter("ignore", category)
        warnings.showwarning = show
        try:
            yield
        finally:
            more = sum(n - WARNINGS_PER_PLACE for n in places.values() if n > WARNINGS_PER_PLACE)
            if more:
                print(f"{prog}: warning: {more} more warnings like those above", file=sys.stderr)


def run_command(prog: str, args: argparse.Namespace) -> int:
    """Run a parsed subcommand ``args.func(args)`` and return its exit status; a closed
    pipe, a typed error or a LAPACK failure end as one line and the documented status
    (:func:`closedloop.exceptions.exit_status`; a
    :class:`~closedloop.exceptions.ClusterError` is a failed computation,
    :data:`EXIT_FAILED`; so is output that cannot be written, ``> /dev/full``);
    a Ctrl-C, or a map stopped by a signal (:class:`closedloop.analysis.interrupts.Interrupted`),
    ends as ``prog: interrupted (SIGNAL)...`` and 128 + the signal's number (130, 143).
    Shared by both command lines."""
    CREATED.clear()
    try:
        check_html_options(args)  # before any work
        with one_line_warnings(prog):
            status = int(args.func(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, not at the interpreter's exit
        return status
    except BrokenPipeError:
        return closed_pipe()
    except OSError as e:  # a full device; the typed errors name their own files
        remove_empty_outputs()
        return output_failed(prog, e)
    except ClosedLoopError as e:
        remove_empty_outputs()
        print(error_line(prog, e), file=sys.stderr)
        return exit_status(e)
    except np.linalg.LinAlgError as e:  # a LAPACK failure on valid input
        remove_empty_outputs()
        print(error_line(prog, f"numerical failure: {e}"), file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt as e:  # Ctrl-C; a map's SIGINT or SIGTERM: interrupts.Interrupted
        remove_empty_outputs()
        print(f"{prog}: {str(e) or 'interrupted (SIGINT)'}", file=sys.stderr)
        return 128 + getattr(e, "signum", signal.SIGINT)


def command_of(argv: Sequence[str]) -> str | None:
    """The subcommand named by ``argv`` (its first word that is not an option), or None."""
    return next((a for a in argv if not a.startswith("-")), None)


def add_subcommands(
    subparsers, modules: dict[str, tuple[str, str]], command, *args, every: bool = False
) -> None:
    """Subcommands defined in modules (name -> (module with ``add_parser(subparsers,
    *args)``, help line)): only the module of ``command``, the one that will run, is
    imported; the others stand in by their help line (enough for ``--help`` and for the
    choices of an unknown command), so that a command does not pay for the others.
    ``every``: all of them built in full (the command-line reference)."""
    for name, (module, help_line) in modules.items():
        if every or command == name:
            importlib.import_module(module).add_parser(subparsers, *args)
        else:
            subparsers.add_parser(name, help=help_line, add_help=False)


def run_main(
    prog: str,
    parser_of: Callable[[list[str]], argparse.ArgumentParser],
    argv: Sequence[str] | None = None,
) -> int:
    """The entry point of a command line: parse ``argv`` (default ``sys.argv[1:]``) with
    ``parser_of(argv)`` and run the subcommand; returns the exit status. A usage error is
    one line ``prog: error: ...`` and :data:`EXIT_BAD_INPUT`; ``--help`` and ``--version``
    return 0. No arguments at all: the help, which lists the commands, on stderr, then
    the usage error's line "give a COMMAND" and :data:`EXIT_BAD_INPUT` (argparse's status
    for a missing argument: a script that runs the bare command has failed). Without
    ``argv`` (the process's own command line, which ends with the command) the subcommand
    gets ``args.program = True``: a map then leaves SIGINT and SIGTERM ignored once it has
    ended (:func:`closedloop.analysis.interrupts.stop_on_signals`)."""
    single_threaded_blas()  # small matrices: BLAS threads cost more than they give
    program = argv is None
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        try:
            parser = parser_of(argv)
            if not argv:  # the commands listed; a usage error still, as argparse makes it
                parser.print_help(sys.stderr)
                raise UsageError(f"give a COMMAND, one of those above ({prog} COMMAND --help "
                                 "describes it)")  # fmt: skip
            args = parser.parse_args(argv)
        except SystemExit as e:  # --help, --version
            sys.stdout.flush()  # a closed or full stdout shows here
            return e.code if isinstance(e.code, int) else EXIT_OK
    except UsageError as e:
        print(error_line(prog, e), file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # --help | head
        return closed_pipe()
    except OSError as e:  # --help > /dev/full
        return output_failed(prog, e)
    args.program = program
    return run_command(prog, args)
