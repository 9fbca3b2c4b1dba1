"""Rounding noise in printed numbers: a component far below its vector's size is shown as 0.

A twist or a deflection computed in floating point carries, in components that are 0 in
exact arithmetic, rounding of about eps times the vector's size (2e-19 deg next to 90 deg).
Text output shows such components as 0; JSON output keeps the raw values.
"""

from __future__ import annotations

import numpy as np

#: A component below this fraction of its vector's largest component (in magnitude) is
#: rounding: about 1e4 eps, above the error of the few operations that compute a printed
#: vector, below any physically meaningful ratio of its components.
ROUNDING_RTOL = 1e-12


def without_rounding(v, rtol: float = ROUNDING_RTOL) -> np.ndarray:
    """A copy of v (n,) [any units, one vector] with every component whose magnitude is
    at most ``rtol`` times the largest magnitude set to 0 (NaN and infinities kept)."""
    v = np.array(v, dtype=float)
    finite = np.isfinite(v)
    size = float(np.max(np.abs(v[finite]), initial=0.0))
    v[finite & (np.abs(v) <= rtol * size)] = 0.0
    return v
