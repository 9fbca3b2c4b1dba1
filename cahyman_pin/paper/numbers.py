"""Numbers as the report prints them."""

from __future__ import annotations

import numpy as np

#: Table cells (mm, deg) below this magnitude are rounding noise of exact zeros.
ZERO_CELL = 1e-9


def fmt(v: float, digits: int = 4, sign: str = "") -> str:
    """A number for a table cell ('n/a' for NaN, 0 for rounding noise below ZERO_CELL)."""
    if not np.isfinite(v):
        return "n/a"
    return "0" if abs(v) < ZERO_CELL else f"{v:{sign}.{digits}g}"


def two_decimals(v: float) -> str:
    """The precision of the published tables (0.01 mm or deg); no negative zero."""
    return f"{round(v, 2) + 0.0:.2f}"
