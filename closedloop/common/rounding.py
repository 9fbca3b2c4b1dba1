"""Rounding noise in printed numbers: a component far below its vector's size is shown as 0.

A twist, a deflection or a pose computed in floating point carries, in components that
are 0 in exact arithmetic, rounding of about eps times the vector's size (2e-19 deg next
to 90 deg). Text output shows such components as 0; JSON output keeps the raw values.
Matrices are printed as computed: in an ill-conditioned compliance an entry 1e-13 of the
largest may be a true stiff direction, not rounding.
A vector of mixed units (a twist: m and rad) is compared unit-free, each component times
its scale (1/L for lengths, :func:`closedloop.common.conditioning.twist_scaling`).
"""

from __future__ import annotations

import numpy as np

#: A component whose magnitude (scaled) is at most this fraction of the largest one's is
#: rounding: about 5e3 eps, above the error of the few operations that compute a printed
#: vector, below any physically meaningful ratio of its components.
ROUNDING_RTOL = 1e-12


def without_rounding(v, scale=None, rtol: float = ROUNDING_RTOL) -> np.ndarray:
    """A copy of v (n,) [any units, one vector] with every component whose magnitude,
    times ``scale`` (n,) [1 / its unit; default 1], is at most ``rtol`` times the largest
    such magnitude set to 0 (NaN and infinities kept)."""
    v = np.array(v, dtype=float)
    size = np.abs(v) * (1.0 if scale is None else np.asarray(scale, dtype=float))
    finite = np.isfinite(size)
    largest = float(np.max(size[finite], initial=0.0))
    v[finite & (size <= rtol * largest)] = 0.0
    return v
