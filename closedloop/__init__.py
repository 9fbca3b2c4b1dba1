"""Stiffness analysis of robots with closed kinematic loops, on Pinocchio 4.

The whole workflow from one import::

    import closedloop as cl

    robot = cl.load_model("fourbar.urdf", "fourbar.yaml")   # tree + closures + springs
    state = cl.Configuration(robot, cl.assemble(robot, actuated=[0.3]).q)
    res = cl.compliance(state, "P")            # 6x6 C [SI] at the origin of frame P
    res.K, res.rank, res.condition_number, res.ill_conditioned
    cl.StiffnessIndices.from_result(res).min_translational_stiffness

The modules (``closedloop.compliance``, ``closedloop.assembly``, ...) stay importable.
"""

from __future__ import annotations

import importlib

from .assembly import Assembly, assemble
from .compliance import ComplianceResult, compliance
from .conditioning import ILL_CONDITIONED, RANK_RTOL
from .configuration import CLOSURE_TOL, Configuration
from .exceptions import (
    AssemblyError,
    ClosedLoopError,
    EquilibriumError,
    InvalidInputError,
    MechanismError,
    ModelFileError,
    NameNotFoundError,
    OpenLoopError,
    RigidDirectionsError,
    SingularConfigurationError,
)
from .indices import StiffnessIndices
from .io import load_model, robot_data_dir
from .model import ClosedLoopModel

__version__ = "0.2.0"

#: Names loaded on first use, and the module that defines each.
_LAZY = {
    "solve_equilibrium": "statics",
    "Equilibrium": "statics",
    "preloaded_compliance": "preload",
    "PreloadedCompliance": "preload",
    "tangent_stiffness": "preload",
    "geometric_stiffness": "preload",
    "closure_curvature": "preload",
}

__all__ = [
    "CLOSURE_TOL",
    "ILL_CONDITIONED",
    "RANK_RTOL",
    "Assembly",
    "AssemblyError",
    "ClosedLoopError",
    "ClosedLoopModel",
    "ComplianceResult",
    "Configuration",
    "EquilibriumError",
    "InvalidInputError",
    "MechanismError",
    "ModelFileError",
    "NameNotFoundError",
    "OpenLoopError",
    "RigidDirectionsError",
    "SingularConfigurationError",
    "StiffnessIndices",
    "assemble",
    "compliance",
    "load_model",
    "robot_data_dir",
    *_LAZY,
]


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'closedloop' has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
