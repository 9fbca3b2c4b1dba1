"""The directional indices of a stiffness: principal stiffnesses and eigenscrews.

Eigenscrews (Lipkin and Patterson's decomposition of K): with the reciprocal product
matrix ``Delta = [[0, I], [I, 0]]`` (``x^T Delta w`` is the work of wrench w on twist x),
the symmetric-definite pencil ``K x = lambda Delta x`` has six real eigenpairs. The twist
x and the wrench ``K x = lambda Delta x`` then lie on the same screw: a rotation about the
screw axis with pitch h meets a force along the same axis with the same pitch. Every x has
a rotation part (``x^T K x = 2 lambda w.v > 0``), so each eigenscrew has a finite nonzero
pitch h (same sign as lambda) and an axis; ``K = sum_i k_i W_i W_i^T`` with ``W_i`` the
unit wrench on screw i and ``k_i = lambda_i / (2 h_i) > 0`` [N/m].

The eigenscrews are computed by :func:`eigenscrews`; the indices of
:class:`closedloop.analysis.indices.StiffnessIndices` (``min_translational_stiffness``...,
``eigenscrews``) give both.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from closedloop.analysis.spectra import ROUNDING_RTOL
from closedloop.common.arrays import readonly
from closedloop.exceptions import InvalidInputError

#: Reciprocal product matrix (6, 6): twist^T DELTA wrench = work [J].
DELTA = np.block([[np.zeros((3, 3)), np.eye(3)], [np.eye(3), np.zeros((3, 3))]])


def unit_direction(v: np.ndarray) -> np.ndarray:
    """v normalised, sign fixed so that its largest-magnitude component is positive."""
    v = v / np.linalg.norm(v)
    return readonly(v * np.sign(v[np.argmax(np.abs(v))]) + 0.0)


class PrincipalStiffness(NamedTuple):
    """A principal stiffness of a 3x3 block and its direction.

    Attributes:
        value: stiffness [N/m (translation) or N m/rad (rotation)].
        direction: (3,) unit vector (translation direction or rotation axis), in the axes
            of C; sign fixed so that its largest component is positive.
    """

    value: float
    direction: np.ndarray


@dataclass(frozen=True)
class Eigenscrew:
    """One eigenscrew of K (see the module docstring).

    Attributes:
        eigenvalue: lambda [N/rad], ``K twist = lambda Delta twist``; sign of the pitch.
        pitch: h [m/rad], nonzero.
        direction: (3,) unit axis direction, in the axes of C.
        point: (3,) [m] point of the axis nearest to the reference point, relative to it.
        spring: k = lambda / (2 h) [N/m] > 0, weight of the screw in ``K = sum k W W^T``.
    """

    eigenvalue: float
    pitch: float
    direction: np.ndarray
    point: np.ndarray
    spring: float

    @property
    def twist(self) -> np.ndarray:
        """(6,) unit rotation about the screw: (h u + p x u [m], u [rad]) at the point."""
        u, p = self.direction, self.point
        return np.concatenate([self.pitch * u + np.cross(p, u), u])

    @property
    def wrench(self) -> np.ndarray:
        """(6,) unit force on the screw: (u [N], h u + p x u [N m]); ``K twist = lambda wrench``."""
        return DELTA @ self.twist


def eigenscrews(C: np.ndarray, K: np.ndarray) -> tuple[Eigenscrew, ...]:
    """The six eigenscrews of K, by ascending eigenvalue (three negative pitches first).

    With factors K = F F^T and C = B B^T, ``F^T Delta F`` has the eigenvalues lambda
    (twist ``Delta F z``) and ``B^T Delta B`` their inverses (twist ``B z``): each screw is
    taken from the one that resolves it, the stiff ones from K and the soft ones from C
    (about eps sqrt(cond) relative, where a Cholesky factorisation of K loses the soft ones
    at eps cond, and fails near a singular pose).

    Args:
        C: (6, 6) symmetric compliance [m/N, rad/N, rad/(N m)], full rank.
        K: (6, 6) its inverse, the stiffness [N/m, N/rad, N m/rad]; both at one reference
            point and in one set of axes, those of the screws.

    Raises:
        InvalidInputError: K is not positive definite (an unstable preloaded equilibrium):
            the decomposition does not exist.
    """
    (mu, V), (kappa, U) = np.linalg.eigh(C), np.linalg.eigh(K)
    if mu[0] < -ROUNDING_RTOL * mu[-1] or kappa[0] < -ROUNDING_RTOL * kappa[-1]:
        raise InvalidInputError(
            f"the eigenscrews of K need a positive definite K; its eigenvalues run from "
            f"{kappa[0]:.3g} to {kappa[-1]:.3g} (an unstable preloaded equilibrium)"
        )
    F, B = U * np.sqrt(np.clip(kappa, 0.0, None)), V * np.sqrt(np.clip(mu, 0.0, None))
    lam_K, Z_K = np.linalg.eigh(F.T @ DELTA @ F)  # ascending: 3 negative, 3 positive
    nu, Z_C = np.linalg.eigh(B.T @ DELTA @ B)  # 1 / lambda, ascending
    # the lambda_K of the same screw: the inertia of Delta decides the positions
    pair = [2, 1, 0, 5, 4, 3]
    nu, Z_C = nu[pair], Z_C[:, pair]
    with np.errstate(divide="ignore"):
        lam_C = 1.0 / nu
    # soft screws (|lambda| below the geometric mean of the extremes) from C
    soft = np.abs(lam_C) <= np.sqrt(np.abs(lam_K).max() / np.abs(nu).max())
    lam = np.where(soft, lam_C, lam_K)
    X = np.where(soft, B @ Z_C, DELTA @ F @ Z_K)  # twists, each to a scale
    screws = []
    for i in np.argsort(lam, kind="stable"):
        v, w = X[:3, i], X[3:, i]
        n2 = float(w @ w)
        pitch, point = float(w @ v / n2), readonly(np.cross(w, v) / n2)
        lam_i = float(lam[i])
        screws.append(Eigenscrew(lam_i, pitch, unit_direction(w), point, lam_i / (2.0 * pitch)))
    return tuple(screws)
