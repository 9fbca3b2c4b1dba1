"""Compliance ellipsoids as the viewer draws them, centred at the loaded frame origin.

With C_tt, C_rr the (3, 3) translational and rotational diagonal blocks of the compliance
C (world axes, at the frame origin), eigenvalues lambda_i and unit eigenvectors v_i:

* translation: semi-axes ``s F lambda_i`` [m] along v_i, F = ``|f|`` [N] (``|n|`` / L when f = 0):
  the set {s C_tt u : ``|u|`` = F}, the amplified displacements of the frame origin under all
  forces of the applied magnitude. Under a pure force the amplified first-order
  displacement ``s C_tt f`` of the frame origin lies on its surface.
* rotation (on request): semi-axes ``rho s N mu_i`` [m] along v_i, N = ``|n|`` [N m]
  (``|f|`` rho when n = 0), mu_i the eigenvalues of C_rr [rad/(N m)], rho = ``LEVER_FRACTION``
  L (the length of the drawn arrows): the amplified rotations under all moments of the
  applied magnitude, drawn as the arc length [m] they give at radius rho.

s is the amplification, L the model size [m]. No ellipsoid is drawn for a zero wrench. An
ellipsoid larger than the model is drawn shrunk: its radii times ``shrink`` = min(1,
``ELLIPSOID_MAX_FRACTION`` L / largest radius) (:attr:`Ellipsoid.drawn_radii`; the
viewer's legend shows the factor).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from closedloop.analysis.batch_indices import row_norms
from closedloop.common.arrays import readonly
from closedloop.elastostatics.compliance import ComplianceResult

#: Lever arm rho of the rotational ellipsoid (and arrow length), per model size L.
LEVER_FRACTION = 0.25
#: Largest drawn ellipsoid semi-axis, per model size L.
ELLIPSOID_MAX_FRACTION = 0.25


@dataclass(frozen=True)
class Ellipsoid:
    """An ellipsoid to draw (arrays read-only).

    Attributes:
        kind: ``"translation"`` or ``"rotation"``.
        centre: (3,) centre [m], world frame.
        radii: (3,) semi-axes [m] (see the module docstring), ascending.
        axes: (3, 3) unit directions of the semi-axes (columns), world axes.
        shrink: factor (0, 1] of the drawn radii (module docstring).
    """

    kind: str
    centre: np.ndarray
    radii: np.ndarray
    axes: np.ndarray
    shrink: float = 1.0

    @property
    def drawn_radii(self) -> np.ndarray:
        """(3,) semi-axes drawn [m]: ``shrink * radii``."""
        return self.shrink * self.radii


def vector_norm(v: np.ndarray) -> float:
    """Euclidean norm of v (k,) at any magnitude
    (:func:`closedloop.analysis.batch_indices.row_norms`)."""
    return float(row_norms(np.asarray(v, dtype=float)[None])[0])


def unit_vector(v: np.ndarray) -> np.ndarray:
    """v (k,) nonzero, finite, divided by its norm, at any magnitude (a load's direction)."""
    v = np.asarray(v, dtype=float)
    m = np.max(np.abs(v))
    return (v / m) / np.linalg.norm(v / m)


def compliance_ellipsoid(
    block: np.ndarray, magnitude: float, length: float, centre: np.ndarray, kind: str
) -> Ellipsoid:
    """Ellipsoid {length * magnitude * block u : ``|u|`` = 1} of a symmetric (3, 3) block.

    Args:
        block: (3, 3) symmetric positive semi-definite compliance block [SI].
        magnitude: load magnitude [N or N m].
        length: factor turning the block's output into metres (s, or s L for rotations).
        centre: (3,) centre [m], world frame.
        kind: ``"translation"`` or ``"rotation"``.
    """
    lam, V = np.linalg.eigh(0.5 * (block + block.T))
    with np.errstate(over="ignore", invalid="ignore"):
        radii = length * magnitude * np.clip(lam, 0.0, None)  # rounding may leave -1e-20
    return Ellipsoid(kind, readonly(centre), readonly(radii), readonly(V))


def capped(e: Ellipsoid, size: float, fraction: float = ELLIPSOID_MAX_FRACTION) -> Ellipsoid:
    """``e`` with ``shrink`` so that its largest drawn radius is at most fraction * size."""
    largest = float(np.max(e.radii))
    shrink = min(1.0, fraction * size / largest) if largest > 0.0 else 1.0
    return Ellipsoid(e.kind, e.centre, e.radii, e.axes, shrink)


def wrench_ellipsoids(
    res: ComplianceResult, w: np.ndarray, s: float, size: float, rotational: bool
) -> tuple[Ellipsoid, ...]:
    """The ellipsoids (module docstring) of the compliance ``res`` under the wrench w (6,)
    [N, N m], amplification s, model size L = ``size`` [m]; () for a zero wrench."""
    f, n = vector_norm(w[:3]), vector_norm(w[3:])
    if f == 0.0 and n == 0.0:
        return ()
    force = f if f > 0.0 else n / size
    out = [compliance_ellipsoid(res.C[:3, :3], force, s, res.point, "translation")]
    if rotational:
        rho = LEVER_FRACTION * size
        moment = n if n > 0.0 else f * rho
        out.append(compliance_ellipsoid(res.C[3:, 3:], moment, s * rho, res.point, "rotation"))
    return tuple(capped(e, size) for e in out)
