"""CaHyMan (Cassino Hybrid Manipulator) on top of :mod:`closedloop`.

Main entry points: :class:`CaHyManParams` (dimensions and springs, SI),
:class:`CaHyManModel` (Pinocchio model with loop closures: assembly, pose, inverse
kinematics) and :func:`stiffness` (6x6 stiffness and compliance at the arm extremity M).

The names are imported on first use (module-level ``__getattr__``): ``cahyman --help`` or
``import cahyman_pin.params`` does not load Pinocchio.
"""

import importlib
from typing import TYPE_CHECKING

#: Public name -> the module that defines it.
_EXPORTS = {
    **dict.fromkeys(("CaHyManStiffness", "Deflection", "stiffness"), "cahyman_pin.api"),
    **dict.fromkeys(("backend_names", "register_backend"), "cahyman_pin.backends.registry"),
    **dict.fromkeys(("CaHyManModel", "CaHyManPose", "cahyman_model"), "cahyman_pin.model"),
    **dict.fromkeys(("DEFAULT_PARAMS", "CaHyManParams"), "cahyman_pin.params"),
}

if TYPE_CHECKING:  # the names as static analysis sees them
    from cahyman_pin.api import CaHyManStiffness, Deflection, stiffness
    from cahyman_pin.backends.registry import backend_names, register_backend
    from cahyman_pin.model import CaHyManModel, CaHyManPose, cahyman_model
    from cahyman_pin.params import DEFAULT_PARAMS, CaHyManParams


def __getattr__(name: str):
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_EXPORTS[name]), name)
    globals()[name] = value  # once: later lookups do not come here
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})


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
