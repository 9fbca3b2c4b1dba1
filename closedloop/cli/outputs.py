"""What a command writes, both command lines: output paths checked before any work (and the
empty folders of a failed command removed), one JSON writer (never a NaN), one-line errors,
quiet closed pipes and a full stdout as one line.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
from pathlib import Path

from closedloop.cli.parser import UsageError
from closedloop.exceptions import EXIT_FAILED, InvalidInputError, NumericalError

#: Exit status when standard output is closed early (128 + SIGPIPE, as a shell reports).
EXIT_PIPE = 141


#: Output folders created by :func:`output_folder` for the running command: a command
#: that fails removes them again while they are empty (:func:`closedloop.cli.common.run_command`).
CREATED: list[Path] = []


def output_folder(path: str | Path, option: str = "--out") -> Path:
    """Create the output folder ``path`` (and its parents) now, before any work; a
    command that fails afterwards leaves no empty folder of its own behind.

    Raises:
        InvalidInputError: ``path`` is a file, lies under a file, or cannot be created or
            written; the message names the option and the path.
    """
    import tempfile  # on demand: with shutil, bz2, lzma (a command without files)

    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InvalidInputError(f"{option} {str(path)!r} is a file; expected a folder")
    try:
        if not path.exists():
            path.mkdir(parents=True)
            CREATED.append(path)
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
    import tempfile

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


def remove_empty_outputs() -> None:
    """Remove the folders :func:`output_folder` created for a command that failed, where
    they are still empty."""
    while CREATED:
        with contextlib.suppress(OSError):  # not empty: kept
            CREATED.pop().rmdir()
