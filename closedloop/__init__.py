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

from . import data
from .assembly import Assembly, assemble
from .compliance import ComplianceResult, compliance
from .conditioning import ILL_CONDITIONED, RANK_RTOL
from .configuration import CLOSURE_TOL, Configuration
from .exceptions import (
    AssemblyError,
    BeamError,
    ClosedLoopError,
    EquilibriumError,
    InvalidInputError,
    JointLimitError,
    JointLimitWarning,
    MechanismError,
    ModelFileError,
    NameNotFoundError,
    OpenLoopError,
    RigidDirectionsError,
    SingularConfigurationError,
)
from .gravity import STANDARD_GRAVITY, GravityLoad, Payload
from .indices import StiffnessIndices
from .io import load_model, robot_data_dir
from .model import ClosedLoopModel
from .preload import PreloadedCompliance, preloaded_compliance
from .statics import Equilibrium, solve_equilibrium
from .tangent import closure_curvature, geometric_stiffness, tangent_stiffness

__version__ = "0.2.0"

__all__ = [
    "CLOSURE_TOL",
    "ILL_CONDITIONED",
    "RANK_RTOL",
    "STANDARD_GRAVITY",
    "Assembly",
    "AssemblyError",
    "BeamError",
    "ClosedLoopError",
    "ClosedLoopModel",
    "ComplianceResult",
    "Configuration",
    "Equilibrium",
    "EquilibriumError",
    "GravityLoad",
    "InvalidInputError",
    "JointLimitError",
    "JointLimitWarning",
    "MechanismError",
    "ModelFileError",
    "NameNotFoundError",
    "OpenLoopError",
    "Payload",
    "PreloadedCompliance",
    "RigidDirectionsError",
    "SingularConfigurationError",
    "StiffnessIndices",
    "assemble",
    "closure_curvature",
    "compliance",
    "data",
    "geometric_stiffness",
    "load_model",
    "preloaded_compliance",
    "robot_data_dir",
    "solve_equilibrium",
    "tangent_stiffness",
]
