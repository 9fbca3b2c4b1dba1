"""What both command lines share: number parsing, output paths checked before any work,
one-line errors, quiet closed pipes, and running a parsed subcommand to its exit status
(:func:`closedloop.exceptions.exit_status`)."""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

from .exceptions import EXIT_FAILED, ClosedLoopError, InvalidInputError, exit_status

#: Exit status when standard output is closed early (128 + SIGPIPE, as a shell reports).
EXIT_PIPE = 141


#: A command-line value that reads as a negative number (``-1e5``, ``-.5``, ``-inf``).
NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$", re.I)


class Parser(argparse.ArgumentParser):
    """An argument parser that takes ``-1e5``, ``-.5`` or ``-inf`` for values, not options
    (argparse's own rule knows only ``-1`` and ``-1.5``); its subparsers are of this class."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE_NUMBER


def output_folder(path: str | Path, option: str = "--out") -> Path:
    """Create the output folder ``path`` (and its parents) now, before any work.

    Raises:
        InvalidInputError: ``path`` is a file, lies under a file, or cannot be created or
            written; the message names the option and the path.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InvalidInputError(f"{option} {str(path)!r} is a file; expected a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=path).close()
    except OSError as e:
        raise InvalidInputError(
            f"{option} {str(path)!r}: cannot create or write this folder ({e.strerror})"
        ) from None
    return path


def output_file(path: str | Path, option: str) -> Path:
    """Check, before any work, that the file ``path`` can be written in an existing folder.

    Raises:
        InvalidInputError: ``path`` is a folder, or its folder is missing, is a file or
            cannot be written; the message names the option and the path.
    """
    path = Path(path)
    parent = path.parent
    if path.is_dir():
        raise InvalidInputError(f"{option} {str(path)!r} is a folder; expected a file")
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


def closed_pipe() -> int:
    """After a :class:`BrokenPipeError` on stdout: send what is left to /dev/null (so that
    the interpreter's final flush stays quiet) and return :data:`EXIT_PIPE`."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # stdout without a file descriptor (captured in a test)
        return EXIT_PIPE
    os.close(devnull)
    return EXIT_PIPE


def error_line(prog: str, error: BaseException) -> str:
    """The one-line message of an error: ``prog: error: message`` (whitespace folded)."""
    return f"{prog}: error: {' '.join(str(error).split())}"


def run_command(prog: str, args: argparse.Namespace) -> int:
    """Run a parsed subcommand ``args.func(args)`` and return its exit status; a closed
    pipe, a typed error or a LAPACK failure end as one line and the documented status
    (:func:`closedloop.exceptions.exit_status`). Shared by both command lines."""
    try:
        if getattr(args, "html", None):
            output_file(args.html, "--html")  # before any work
        status = int(args.func(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, not at the interpreter's exit
        return status
    except BrokenPipeError:
        return closed_pipe()
    except ClosedLoopError as e:
        print(error_line(prog, e), file=sys.stderr)
        return exit_status(e)
    except np.linalg.LinAlgError as e:  # a LAPACK failure on valid input
        print(error_line(prog, f"numerical failure: {e}"), file=sys.stderr)
        return EXIT_FAILED


def dask_client(address: str | None):
    """A Dask distributed client of the scheduler at ``address`` (None for None); the
    caller closes it. An unreachable scheduler or a missing Dask is one typed error."""
    if address is None:
        return None
    try:
        from dask.distributed import Client
    except ImportError:
        raise InvalidInputError("--scheduler needs Dask: pip install '.[dask]'") from None
    try:
        return Client(address, timeout="10s")
    except (OSError, TimeoutError) as e:
        raise InvalidInputError(f"cannot reach the Dask scheduler {address!r}: {e}") from None
