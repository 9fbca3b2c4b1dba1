"""What both command lines (``closedloop``, ``cahyman``) share, so that they follow one
convention: the parser (negative numbers in e-notation are values; a usage error is one
line, exit 2), the finite-number and positive-integer option types, output paths checked
before any work, the checks and summaries of a map (its size, its load, the range of its
index), one JSON writer (never a NaN), one-line errors, quiet closed pipes, a full stdout
as one line, the entry point that runs a parsed subcommand to its exit status
(:func:`closedloop.exceptions.exit_status`). The Dask executor of ``--scheduler`` is
:func:`closedloop.analysis.cluster.dask_executor` (lost workers and a run without workers end as
one line, never a hang)."""

from __future__ import annotations

import argparse
import contextlib
import importlib
import json
import math
import os
import re
import signal
import sys
import tempfile
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from closedloop.common.argtypes import (
    finite_float as finite_float,  # option types, shared below the CLI
)
from closedloop.common.argtypes import number as number
from closedloop.common.arrays import decimal
from closedloop.common.blas import single_threaded_blas
from closedloop.exceptions import (
    EXIT_BAD_INPUT,
    EXIT_FAILED,
    EXIT_OK,
    EXIT_RANK_DEFICIENT,
    ClosedLoopError,
    InvalidInputError,
    NumericalError,
    exit_status,
)

#: Exit status when standard output is closed early (128 + SIGPIPE, as a shell reports).
EXIT_PIPE = 141

#: The exit statuses, as the help of both command lines states them.
EXIT_HELP = (
    f"Exit status: {EXIT_OK} ok; {EXIT_RANK_DEFICIENT} rank deficient (K does not exist); "
    f"{EXIT_BAD_INPUT} bad input; {EXIT_FAILED} computation failed (loops that cannot be "
    f"closed, an unreachable pose, no equilibrium, a singular configuration); {EXIT_PIPE} "
    "output closed early. Errors are one line on stderr."
)


class UsageError(InvalidInputError):
    """A command-line error (unknown option, missing or malformed value): exit status 2."""


#: A command-line value that reads as a negative number (``-1e5``, ``-.5``, ``-inf``).
_NUMBER = r"(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|inf|infinity|nan"
#: An integer as a command line takes it: ASCII digits after an optional sign.
_INTEGER = re.compile(r"[-+]?[0-9]+")
#: A value that starts with a minus sign: a number, or a specification whose first number
#: is negative (``-90:90:3``, ``-1,0,1``), not an option.
NEGATIVE_NUMBER = re.compile(rf"^-({_NUMBER})([:,][-+.\w]*)*$", re.I | re.ASCII)


#: Options that may be given several times (each adds to a list, or counts).
_REPEATABLE = (argparse._AppendAction, argparse._CountAction, argparse._HelpAction,
               argparse._VersionAction)  # fmt: skip


class Parser(argparse.ArgumentParser):
    """An argument parser that takes ``-1e5``, ``-.5`` or ``-inf`` for values, not options
    (argparse's own rule knows only ``-1`` and ``-1.5``), refuses an option given twice
    (argparse keeps the last: ``--force 1 0 0 --force 0 0 1`` loaded one force) and
    abbreviated options (``--forc`` for ``--force``), and
    raises :class:`UsageError` instead of printing its usage block and exiting; its
    subparsers are of this class."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("allow_abbrev", False)  # --forc would escape the check of repeats
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER

    def error(self, message: str):
        raise UsageError(message)

    def parse_known_args(self, args=None, namespace=None):
        args = sys.argv[1:] if args is None else list(args)
        seen: dict = {}
        for token in args:
            if token == "--":
                break
            action = self._option_string_actions.get(token.split("=", 1)[0])
            if action is None or isinstance(action, _REPEATABLE):
                continue
            if action in seen:
                self.error(f"{seen[action]} given twice; expected it once")
            seen[action] = "/".join(action.option_strings)
        return super().parse_known_args(args, namespace)

    def _print_message(self, message: str, file=None) -> None:
        """argparse's writer of help and version, without swallowing an :class:`OSError`
        (``--help > /dev/full`` fails, as any other output)."""
        if message:
            (file or sys.stderr).write(message)


def path_text(text: str) -> str:
    """Option type: a file or folder path, as typed (an empty one, which would name the
    current folder or no file at all, is refused)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"{text!r} is an empty path; expected a file or folder")
    return text


def positive_int(text: str) -> int:
    """Option type: an integer >= 1 (a count of points, tasks or processes), in ASCII
    digits."""
    if not _INTEGER.fullmatch(text):
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer")
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected an integer >= 1")
    return value


def needs_gravity(option: str, gravity: bool) -> None:
    """Refuse a mass given without gravity (``option`` as typed, e.g. ``--mass m_M4=2``).

    Raises:
        UsageError: ``gravity`` is false.
    """
    if not gravity:
        raise UsageError(f"{option} weighs nothing without --gravity; give --gravity too")


#: Most points a map may have (a guard against typing one zero too many), both commands.
MAX_MAP_POINTS = 2_000_000


def check_map_size(n: int) -> None:
    """Refuse a map of more than :data:`MAX_MAP_POINTS` points, before any work.

    Raises:
        UsageError: too many points.
    """
    if n > MAX_MAP_POINTS:
        raise UsageError(f"{n} points is more than the {MAX_MAP_POINTS} a map may have")


def map_wrench(index: str, force, torque) -> np.ndarray | None:
    """(6,) wrench of a map's ``--force``/``--torque`` (a missing one is zero), or None.

    Raises:
        UsageError: a deflection index (``--index deflection_...``) without a load.
    """
    if force is None and torque is None:
        if index.startswith("deflection"):
            raise UsageError(f"--index {index} needs --force and/or --torque")
        return None
    return np.r_[force or (0.0, 0.0, 0.0), torque or (0.0, 0.0, 0.0)]


def index_line(name: str, values: np.ndarray, unit: str) -> str:
    """The summary of a map's plotted index: its range and the points without a value
    (``det_K: min 1, max 2 [N^6/rad^3] (3 points without a value)``)."""
    values = np.asarray(values, dtype=float).reshape(len(values), -1)
    finite = np.all(np.isfinite(values), axis=1)
    missing = int(np.count_nonzero(~finite))
    if not finite.any():
        return f"{name}: no value at any of the {len(values)} points (the plot is empty)"
    note = f" ({missing} points without a value)" if missing else ""
    if values.shape[1] != 1:  # a vector index: its range is not one number
        return f"{name}: values at {int(finite.sum())} points [{unit}]{note}"
    v = values[finite, 0]
    return f"{name}: min {v.min():.6g}, max {v.max():.6g} [{unit}]{note}"


class SpecError(argparse.ArgumentTypeError):
    """A value specification that cannot be read."""


#: Longest specification echoed whole in an error; a longer one is cut (its length said).
SHOWN_SPEC = 60


def quoted(text: str) -> str:
    """``text`` quoted for an error message, cut after :data:`SHOWN_SPEC` characters."""
    if len(text) <= SHOWN_SPEC:
        return repr(text)
    return f"{text[:SHOWN_SPEC]!r}... ({len(text)} characters)"


def parse_values(text: str) -> np.ndarray:
    """Values of a specification ``V``, ``START:STOP:NUM`` or ``V1,V2,...`` (no unit change).

    Raises:
        SpecError: the text does not follow one of the three forms (the message names the
            first value that is not a number, and cuts a long text).
    """
    if ":" in text:
        parts = text.split(":")
        try:
            start, stop, num = parts
            if not _INTEGER.fullmatch(num):
                raise ValueError(num)
            count = int(num)
        except ValueError:
            raise SpecError(
                f"{quoted(text)} is not START:STOP:NUM (numbers, NUM an integer)"
            ) from None
        if not 1 <= count <= MAX_MAP_POINTS:  # checked before any array is made
            raise SpecError(f"{quoted(text)}: NUM must be from 1 to {MAX_MAP_POINTS}")
        items = [start, stop]
    else:
        items = text.split(",")
    try:
        numbers = [decimal(v) for v in items]
    except ValueError:
        bad = next(v for v in items if not _is_number(v))
        where = "" if bad == text else f"{quoted(text)}: "
        raise SpecError(
            f"{where}{quoted(bad)} is not a number; expected a value, START:STOP:NUM or V1,V2,..."
        ) from None
    if ":" in text:
        with np.errstate(invalid="ignore", over="ignore"):  # refused below
            values = np.linspace(numbers[0], numbers[1], count)
    else:
        values = np.array(numbers)
    if not np.all(np.isfinite(values)):
        raise SpecError(f"{quoted(text)} has non-finite values")
    return values


def _is_number(text: str) -> bool:
    try:
        decimal(text)
    except ValueError:
        return False
    return True


#: Output folders created by :func:`output_folder` for the running command: a command
#: that fails removes them again while they are empty (:func:`run_command`).
_CREATED: list[Path] = []


def output_folder(path: str | Path, option: str = "--out") -> Path:
    """Create the output folder ``path`` (and its parents) now, before any work; a
    command that fails afterwards leaves no empty folder of its own behind.

    Raises:
        InvalidInputError: ``path`` is a file, lies under a file, or cannot be created or
            written; the message names the option and the path.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InvalidInputError(f"{option} {str(path)!r} is a file; expected a folder")
    try:
        if not path.exists():
            path.mkdir(parents=True)
            _CREATED.append(path)
        tempfile.TemporaryFile(dir=path).close()
    except OSError as e:
        raise InvalidInputError(
            f"{option} {str(path)!r}: cannot create or write this folder ({e.strerror})"
        ) from None
    return path


def output_file(path: str | Path, option: str) -> Path:
    """Check, before any work, that the file ``path`` can be written in an existing folder.

    Raises:
        InvalidInputError: ``path`` is a folder or a file the user may not write, or its
            folder is missing, is a file or cannot be written; the message names the
            option and the path.
    """
    path = Path(path)
    parent = path.parent
    if path.is_dir():
        raise InvalidInputError(f"{option} {str(path)!r} is a folder; expected a file")
    if path.is_file() and not os.access(path, os.W_OK):  # refused by the writer, but late
        raise InvalidInputError(f"{option} {str(path)!r} is read-only; expected a writable file")
    if not parent.is_dir():
        what = "is not a folder" if parent.exists() else "does not exist"
        raise InvalidInputError(f"{option} {str(path)!r}: folder {str(parent)!r} {what}")
    try:
        tempfile.TemporaryFile(dir=parent).close()
    except OSError as e:
        raise InvalidInputError(
            f"{option} {str(path)!r}: cannot write in {str(parent)!r} ({e.strerror})"
        ) from None
    return path


def _non_finite(doc, where: str = "") -> str | None:
    """Where the first NaN or infinity of a JSON-ready ``doc`` is (``C[1][2]``), or None."""
    if isinstance(doc, float):
        return None if math.isfinite(doc) else where or "the value"
    if isinstance(doc, dict):
        items = [(f"{where}.{k}" if where else str(k), v) for k, v in doc.items()]
    elif isinstance(doc, list | tuple):
        items = [(f"{where}[{i}]", v) for i, v in enumerate(doc)]
    else:
        return None
    return next((found for path, v in items if (found := _non_finite(v, path))), None)


def check_finite(doc) -> None:
    """Refuse a JSON-ready ``doc`` (the results a command prints, as JSON or as text) that
    holds a NaN or an infinity.

    Raises:
        NumericalError: the message says where (``M.displacement_mm[2]``).
    """
    where = _non_finite(doc)
    if where is not None:
        raise NumericalError(f"the result is not finite at {where}; nothing written")


def print_json(doc) -> None:
    """Print ``doc`` as one JSON object (indented by 2), the one writer of both command lines.

    Raises:
        NumericalError: ``doc`` holds a NaN or an infinity (strict JSON has neither); the
            message says where (:func:`check_finite`). Nothing is printed.
    """
    try:
        text = json.dumps(doc, indent=2, allow_nan=False)
    except ValueError:
        check_finite(doc)
        raise
    print(text)


def _discard_stdout() -> None:
    """Send what is left of stdout to /dev/null, so that the interpreter's final flush of
    a closed or full stdout stays quiet."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # stdout without a file descriptor (captured in a test)
        return
    os.close(devnull)


def closed_pipe() -> int:
    """After a :class:`BrokenPipeError` on stdout: discard what is left and return
    :data:`EXIT_PIPE`."""
    _discard_stdout()
    return EXIT_PIPE


def output_failed(prog: str, error: OSError) -> int:
    """After an :class:`OSError` while writing (a full disk, ``> /dev/full``): one line on
    stderr, what is left of stdout discarded; returns :data:`EXIT_FAILED`."""
    what = f"{error.strerror or error}" + (f": {error.filename!r}" if error.filename else "")
    _discard_stdout()
    with contextlib.suppress(OSError):  # stderr full too: the exit status still says it
        print(error_line(prog, f"cannot write the output ({what})"), file=sys.stderr)
    return EXIT_FAILED


def check_html_options(args: argparse.Namespace) -> None:
    """With ``--html FILE``: the file can be written, and no ``--duration`` (which serves
    the live page; a page written to a file is not served). Checked before any work.

    Raises:
        InvalidInputError: the file cannot be written; ``--duration`` with ``--html``.
    """
    if not getattr(args, "html", None):
        return
    output_file(args.html, "--html")
    if getattr(args, "duration", None) is not None:
        raise UsageError(
            f"--duration {args.duration:g} serves the live page; with --html {args.html!r} "
            "the page is written and nothing is served (give one of them)"
        )


def error_line(prog: str, error: BaseException) -> str:
    """The one-line message of an error: ``prog: error: message`` (whitespace folded)."""
    return f"{prog}: error: {' '.join(str(error).split())}"


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
    (:func:`closedloop.exceptions.exit_status`; a :class:`ClusterError` is a failed
    computation, :data:`EXIT_FAILED`; so is output that cannot be written, ``> /dev/full``);
    a Ctrl-C, or a map stopped by a signal (:class:`closedloop.analysis.interrupts.Interrupted`),
    ends as ``prog: interrupted (SIGNAL)...`` and 128 + the signal's number (130, 143).
    Shared by both command lines."""
    _CREATED.clear()
    try:
        check_html_options(args)  # before any work
        with one_line_warnings(prog):
            status = int(args.func(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, not at the interpreter's exit
        return status
    except BrokenPipeError:
        return closed_pipe()
    except OSError as e:  # a full device; the typed errors name their own files
        _remove_empty_outputs()
        return output_failed(prog, e)
    except ClosedLoopError as e:
        _remove_empty_outputs()
        print(error_line(prog, e), file=sys.stderr)
        return exit_status(e)
    except np.linalg.LinAlgError as e:  # a LAPACK failure on valid input
        _remove_empty_outputs()
        print(error_line(prog, f"numerical failure: {e}"), file=sys.stderr)
        return EXIT_FAILED
    except KeyboardInterrupt as e:  # Ctrl-C; a map's SIGINT or SIGTERM: interrupts.Interrupted
        _remove_empty_outputs()
        print(f"{prog}: {str(e) or 'interrupted (SIGINT)'}", file=sys.stderr)
        return 128 + getattr(e, "signum", signal.SIGINT)


def _remove_empty_outputs() -> None:
    """Remove the folders :func:`output_folder` created for a command that failed, where
    they are still empty."""
    while _CREATED:
        with contextlib.suppress(OSError):  # not empty: kept
            _CREATED.pop().rmdir()


def command_of(argv: Sequence[str]) -> str | None:
    """The subcommand named by ``argv`` (its first word that is not an option), or None."""
    return next((a for a in argv if not a.startswith("-")), None)


def add_subcommands(subparsers, modules: dict[str, tuple[str, str]], command, *args) -> None:
    """Subcommands defined in modules (name -> (module with ``add_parser(subparsers,
    *args)``, help line)): only the module of ``command``, the one that will run, is
    imported; the others stand in by their help line (enough for ``--help`` and for the
    choices of an unknown command), so that a command does not pay for the others."""
    for name, (module, help_line) in modules.items():
        if command == name:
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
    return 0."""
    single_threaded_blas()  # small matrices: BLAS threads cost more than they give
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        try:
            args = parser_of(argv).parse_args(argv)
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
    return run_command(prog, args)
