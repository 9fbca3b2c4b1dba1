"""Option types of command-line arguments that modules below the command lines also add
to a parser (the Dask executor's ``--worker-timeout``) or read from a file (the value
specifications ``V``, ``START:STOP:NUM``, ``V1,V2,...`` of a map's ``--sweep`` and of a
design problem's workspace), so that they need not import :mod:`closedloop.cli.parser`."""

from __future__ import annotations

import argparse
import math
import re

from closedloop.common.arrays import decimal, overflowing

#: An integer as a command line takes it: ASCII digits after an optional sign.
INTEGER = re.compile(r"[-+]?[0-9]+")
#: Most points a map may have (a guard against typing one zero too many), both commands.
MAX_MAP_POINTS = 2_000_000


def number(text: str) -> float:
    """Option type: a number in ASCII decimal notation (:func:`closedloop.common.arrays.decimal`:
    not ``0_3`` nor other scripts' digits), ``inf`` and ``nan`` included; ``1e999``, beyond
    the double range, is refused, not taken for ``inf``."""
    try:
        return decimal(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(
            str(e)
            if overflowing(text)
            else f"{text!r} is not a number; expected ASCII decimal notation (e.g. -1.5e3)"
        ) from None


def finite_float(text: str) -> float:
    """Option type: a finite number in ASCII decimal notation (:func:`number`; ``nan``,
    ``inf`` and overflowing values are refused)."""
    value = number(text)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


class SpecError(argparse.ArgumentTypeError):
    """A value specification that cannot be read."""


#: Longest specification echoed whole in an error; a longer one is cut (its length said).
SHOWN_SPEC = 60


def quoted(text: str) -> str:
    """``text`` quoted for an error message, cut after :data:`SHOWN_SPEC` characters."""
    if len(text) <= SHOWN_SPEC:
        return repr(text)
    return f"{text[:SHOWN_SPEC]!r}... ({len(text)} characters)"


def parse_values(text: str):
    """(n,) values of a specification ``V``, ``START:STOP:NUM`` or ``V1,V2,...`` (a numpy
    array, no unit change; numpy imported on demand, not with the command lines' parser).

    Raises:
        SpecError: the text does not follow one of the three forms (the message names the
            first value that is not a number, and cuts a long text).
    """
    import numpy as np

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
