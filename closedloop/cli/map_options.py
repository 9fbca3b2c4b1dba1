"""The options of a map, both command lines: value specifications (``V``,
``START:STOP:NUM``, ``V1,V2,...``; :func:`closedloop.common.argtypes.parse_values`, read by
design problems too), its size checked before any work, its load, the summary of its
plotted index, and what the signals do to it.
"""

from __future__ import annotations

import numpy as np

from closedloop.cli.parser import UsageError
from closedloop.common.argtypes import MAX_MAP_POINTS, SHOWN_SPEC, SpecError, parse_values, quoted

#: What SIGINT and SIGTERM do to a map, both commands (the epilog of their help).
SIGNALS_EPILOG = """\
SIGINT (Ctrl-C) or SIGTERM while the map computes stops it at once, its workers with it,
writes the points computed (the others with status not_computed) and ends with one line,
exit 130 (SIGINT) or 143 (SIGTERM). Once every point is computed, a signal lets the files
be written whole and the output printed, then ends the same way ("wrote 400 of 400 points
to DIR"). A second signal meanwhile is ignored; no file is left half-written, nor a
temporary file.
"""

__all__ = ["MAX_MAP_POINTS", "SHOWN_SPEC", "SIGNALS_EPILOG", "SpecError", "check_map_size",
           "index_line", "map_wrench", "parse_values", "quoted"]  # fmt: skip


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
