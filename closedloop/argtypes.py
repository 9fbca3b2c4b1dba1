"""Option types of command-line arguments that modules below the command lines also add
to a parser (the Dask executor's ``--worker-timeout``), so that they need not import
:mod:`closedloop.cli_common`."""

from __future__ import annotations

import argparse
import math


def finite_float(text: str) -> float:
    """Option type: a finite number (``nan``, ``inf`` and overflowing values are refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value
