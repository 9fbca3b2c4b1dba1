"""det K and the eigenvalues of one stiffness K = C^-1 from formed matrices, to the precision
they resolve: the rounding tolerances of a formed matrix, the determinant from LU logarithms,
the eigenvalues from the inverse pair (C, K).
"""

from __future__ import annotations

import numpy as np

from closedloop.common.conditioning import SCALED_TOL
from closedloop.exceptions import SingularConfigurationError


def lu_determinant(K: np.ndarray) -> float:
    """det K [N^6/rad^3] of a (6, 6) stiffness from its LU factors (logarithms: no overflow
    on the way), or :func:`finite_determinant`'s error."""
    sign, log_det = np.linalg.slogdet(K)
    with np.errstate(over="ignore", under="ignore"):
        return finite_determinant(sign * np.exp(log_det), log_det / np.log(10.0))


def finite_determinant(det: float, log10: float) -> float:
    """``det`` [N^6/rad^3] when it is a finite non-zero float (K is full rank here).

    Raises:
        SingularConfigurationError: it overflowed or underflowed; the message gives its
            size 10^``log10``.
    """
    if det != 0.0 and np.isfinite(det):
        return float(det)
    raise SingularConfigurationError(
        f"det K = 1e{log10:.1f} N^6/rad^3 is beyond the floating point range (1e-308 to "
        "1e308); the other indices stand (springs far from 1 N/m or N m/rad make it so: "
        "each enters at the power of its directions)"
    )


#: Smallest eigenvalue of a formed scaled stiffness, relative to its largest, that it
#: resolves (a few eps): below, rounding decides whether it is positive.
RESOLVED_RTOL = 1e-15
#: Largest negative eigenvalue, relative to the largest, that rounding gives a formed
#: symmetric positive definite 6x6 matrix (a few eps; 1e-13 leaves a factor of 100).
ROUNDING_RTOL = 1e-13


def inverse_pair_eigenvalues(C: np.ndarray, K: np.ndarray) -> np.ndarray | None:
    """(6,) eigenvalues of K = C^-1 ascending, from C and K (6, 6) both formed, or None
    when C is not symmetric (to SCALED_TOL) or K not positive definite.

    An eigenvalue of a formed symmetric matrix is known to about eps times its largest
    one; so 1/mu, mu an eigenvalue of C, is taken from C where mu >= sqrt(mu_min mu_max)
    and from K below (mu_min = 1 / kappa_max, from K): each to about eps sqrt(cond)
    relative, where the eigenvalues of K alone lose its smallest ones at eps cond.
    """
    if np.max(np.abs(C - C.T)) > SCALED_TOL * np.max(np.abs(C)):
        return None
    mu, kappa = np.linalg.eigvalsh(0.5 * (C + C.T)), np.linalg.eigvalsh(K)  # ascending
    # indefinite (an unstable preloaded equilibrium): an eigenvalue negative beyond the
    # rounding of a formed matrix (a positive definite one may show -eps times its largest)
    if mu[0] < -ROUNDING_RTOL * mu[-1] or kappa[0] < -ROUNDING_RTOL * kappa[-1]:
        return None
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        lam = np.where(mu >= np.sqrt(mu[-1] / kappa[-1]), 1.0 / mu, kappa[::-1])
    return np.sort(lam) if np.all(lam > 0.0) else None
