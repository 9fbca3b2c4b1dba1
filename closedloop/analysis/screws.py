"""The directional indices of a stiffness: principal stiffnesses and eigenscrews.

Eigenscrews (Lipkin and Patterson's decomposition of K): with the reciprocal product
matrix ``Delta = [[0, I], [I, 0]]`` (``x^T Delta w`` is the work of wrench w on twist x),
the symmetric-definite pencil ``K x = lambda Delta x`` has six real eigenpairs. The twist
x and the wrench ``K x = lambda Delta x`` then lie on the same screw: a rotation about the
screw axis with pitch h meets a force along the same axis with the same pitch. Every x has
a rotation part (``x^T K x = 2 lambda w.v > 0``), so each eigenscrew has a finite nonzero
pitch h (same sign as lambda) and an axis; ``K = sum_i k_i W_i W_i^T`` with ``W_i`` the
unit wrench on screw i and ``k_i = lambda_i / (2 h_i) > 0`` [N/m].

Their values are computed by :class:`closedloop.analysis.indices.StiffnessIndices`
(``min_translational_stiffness``..., ``eigenscrews``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from closedloop.common.arrays import readonly

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
