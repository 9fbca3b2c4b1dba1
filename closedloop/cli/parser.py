"""The parser of both command lines (``closedloop``, ``cahyman``) and their option types:
negative numbers in e-notation are values, an option given twice or abbreviated is refused,
a usage error is one line (:class:`~closedloop.cli.parser.UsageError`, exit 2).
"""

from __future__ import annotations

import argparse
import re
import sys

from closedloop.common.argtypes import INTEGER as INTEGER  # option types, shared below the CLI
from closedloop.common.argtypes import (
    finite_float as finite_float,
)
from closedloop.common.argtypes import number as number
from closedloop.exceptions import InvalidInputError


class UsageError(InvalidInputError):
    """A command-line error (unknown option, missing or malformed value): exit status 2."""


#: A command-line value that reads as a negative number (``-1e5``, ``-.5``, ``-inf``).
_NUMBER = r"(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?|inf|infinity|nan"
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
        """Raise :class:`UsageError` (argparse's prints the usage block and exits)."""
        raise UsageError(message)

    def parse_known_args(self, args=None, namespace=None):
        """argparse's, once no option is given twice (a :class:`UsageError` otherwise)."""
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
    if not INTEGER.fullmatch(text):
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
