"""CaHyMan (Cassino Hybrid Manipulator) on top of :mod:`closedloop`.

Main entry points: :class:`CaHyManParams` (dimensions and springs, SI),
:class:`CaHyManModel` (Pinocchio model with loop closures: assembly, pose, inverse
kinematics) and :func:`stiffness` (6x6 stiffness and compliance at the arm extremity M).
"""

from cahyman_pin.api import CaHyManStiffness, Deflection, backend_names, register_backend, stiffness
from cahyman_pin.model import CaHyManModel, CaHyManPose, cahyman_model
from cahyman_pin.params import DEFAULT_PARAMS, CaHyManParams

__all__ = [
    "DEFAULT_PARAMS",
    "CaHyManModel",
    "CaHyManParams",
    "CaHyManPose",
    "CaHyManStiffness",
    "Deflection",
    "backend_names",
    "cahyman_model",
    "register_backend",
    "stiffness",
]
