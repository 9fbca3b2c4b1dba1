"""Option types of command-line arguments that modules below the command lines also add
to a parser (the Dask executor's ``--worker-timeout``), so that they need not import
:mod:`closedloop.cli.parser`."""

from __future__ import annotations

import argparse
import math

from closedloop.common.arrays import decimal, overflowing


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
