"""The options of a map, both command lines: value specifications (``V``,
``START:STOP:NUM``, ``V1,V2,...``), its size checked before any work, its load, and the
summary of its plotted index, what the signals do to it.
"""

from __future__ import annotations

import argparse

import numpy as np

from closedloop.cli.parser import INTEGER, UsageError
from closedloop.common.arrays import decimal

#: What SIGINT and SIGTERM do to a map, both commands (the epilog of their help).
SIGNALS_EPILOG = """\
SIGINT (Ctrl-C) or SIGTERM while the map computes stops it at once, its workers with it,
writes the points computed (the others with status not_computed) and ends with one line,
exit 130 (SIGINT) or 143 (SIGTERM). Once every point is computed, a signal lets the files
be written whole and the output printed, then ends the same way ("wrote 400 of 400 points
to DIR"). A second signal meanwhile is ignored; no file is left half-written, nor a
temporary file.
"""
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
            if not INTEGER.fullmatch(num):
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
