"""Small array helpers shared by the packages: read-only copies and input checks."""

from __future__ import annotations

import numpy as np

from .exceptions import InvalidInputError


def readonly(a) -> np.ndarray:
    """Read-only float copy of ``a``."""
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


def frozen(a: np.ndarray) -> np.ndarray:
    """``a`` made read-only in place (for an array the caller has just created)."""
    a.flags.writeable = False
    return a


def check_wrench(w) -> np.ndarray:
    """(6,) validated wrench (fx, fy, fz [N], nx, ny, nz [N m]); raises InvalidInputError."""
    w = np.asarray(w, dtype=float).reshape(-1)
    if w.shape != (6,) or not np.all(np.isfinite(w)):
        raise InvalidInputError(
            f"wrench must be 6 finite values (fx fy fz [N], nx ny nz [N m]), got {w.tolist()}"
        )
    return w
