"""Stiffness analysis of robots with closed kinematic loops, on Pinocchio 4.

The whole workflow from one import::

    import closedloop as cl

    robot = cl.load_model("fourbar.urdf", "fourbar.yaml")   # tree + closures + springs
    state = cl.Configuration(robot, cl.assemble(robot, actuated=[0.3]).q)  # mode of its start
    cl.assembly_modes(robot, [0.3])            # the assembly modes found there
    res = cl.compliance(state, "P")            # 6x6 C [SI] at the origin of frame P
    query = cl.ComplianceQuery(robot, "P")     # prepared: query(q) at many configurations
    res.K, res.rank, res.condition_number, res.ill_conditioned
    cl.compliances(robot, Q, "P").C            # (n, 6, 6) for n configurations Q (n, nq)
    cl.StiffnessIndices.from_result(res).min_translational_stiffness
    cl.follow_path(robot, "P", path, wrench=w).residual   # a path: error, compensation

The package is laid out in layers, each importing only those below it:
:mod:`closedloop.common` (shared utilities) -> :mod:`closedloop.model` (the closed-loop
model, beams, gravity) -> :mod:`closedloop.io` (model files) and
:mod:`closedloop.kinematics` (configurations, assembly, limits) ->
:mod:`closedloop.elastostatics` (compliance, statics) -> :mod:`closedloop.analysis`
(indices, identification, maps, natural frequencies, design) -> :mod:`closedloop.viewer` ->
:mod:`closedloop.cli`.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

#: Public name -> the module that defines it; imported on first use (module-level
#: ``__getattr__``), so that ``import closedloop.exceptions`` or a command line that needs a
#: few modules does not load scipy, yaml or every other module. The submodules among them:
#: :data:`_SUBMODULES`.
_EXPORTS = {
    "data": ".io.data",
    **dict.fromkeys(("Assembly", "assemble"), ".kinematics.assembly"),
    "assembly_modes": ".kinematics.assembly_modes",
    **dict.fromkeys(("BatchCompliance", "compliances"), ".elastostatics.batch"),
    **dict.fromkeys(("ComplianceResult", "compliance"), ".elastostatics.compliance"),
    "ComplianceQuery": ".elastostatics.query",
    **dict.fromkeys(("ILL_CONDITIONED", "RANK_RTOL"), ".common.conditioning"),
    **dict.fromkeys(("CLOSURE_TOL", "Configuration"), ".kinematics.configuration"),
    **dict.fromkeys(
        (
            "AssemblyError",
            "BeamError",
            "ClosedLoopError",
            "EquilibriumError",
            "ExpressionError",
            "IgnoredFeatureWarning",
            "InvalidInputError",
            "JointLimitError",
            "JointLimitWarning",
            "MechanismError",
            "ModelFileError",
            "ModelMisfitWarning",
            "ModesError",
            "NameNotFoundError",
            "NumericalError",
            "OpenLoopError",
            "OutsideLimitsError",
            "RigidDirectionsError",
            "SingularConfigurationError",
            "UnreachableError",
            "ViewerError",
        ),
        ".exceptions",
    ),
    **dict.fromkeys(("STANDARD_GRAVITY", "GravityLoad", "Payload"), ".model.gravity"),
    "StiffnessIndices": ".analysis.indices",
    "load_model": ".io.loader",
    "robot_data_dir": ".io.data",
    "ClosedLoopModel": ".model.closed_loop",
    **dict.fromkeys(("PreloadedCompliance", "preloaded_compliance"), ".elastostatics.preload"),
    "Equilibrium": ".elastostatics.equilibrium",
    "solve_equilibrium": ".elastostatics.statics",
    **dict.fromkeys(
        ("closure_curvature", "geometric_stiffness", "tangent_stiffness"), ".elastostatics.tangent"
    ),
    **dict.fromkeys(("ModesResult", "batch_modes", "modes"), ".analysis.vibration"),
    **dict.fromkeys(("DesignProblem", "design_problem"), ".analysis.design_problem"),
    "DesignEvaluation": ".analysis.design_evaluation",
    "DesignResult": ".analysis.design_result",
    "optimize_design": ".analysis.design_optimizer",
    "inverse_kinematics": ".kinematics.inverse",
    "follow_path": ".analysis.paths",
    "PathResult": ".analysis.path_results",
}
_SUBMODULES = frozenset({"data"})

if TYPE_CHECKING:  # the names as static analysis sees them
    from closedloop.analysis.design_evaluation import DesignEvaluation
    from closedloop.analysis.design_optimizer import optimize_design
    from closedloop.analysis.design_problem import DesignProblem, design_problem
    from closedloop.analysis.design_result import DesignResult
    from closedloop.analysis.indices import StiffnessIndices
    from closedloop.analysis.path_results import PathResult
    from closedloop.analysis.paths import follow_path
    from closedloop.analysis.vibration import ModesResult, batch_modes, modes
    from closedloop.common.conditioning import ILL_CONDITIONED, RANK_RTOL
    from closedloop.elastostatics.batch import BatchCompliance, compliances
    from closedloop.elastostatics.compliance import ComplianceResult, compliance
    from closedloop.elastostatics.equilibrium import Equilibrium
    from closedloop.elastostatics.preload import PreloadedCompliance, preloaded_compliance
    from closedloop.elastostatics.query import ComplianceQuery
    from closedloop.elastostatics.statics import solve_equilibrium
    from closedloop.elastostatics.tangent import (
        closure_curvature,
        geometric_stiffness,
        tangent_stiffness,
    )
    from closedloop.exceptions import (
        AssemblyError,
        BeamError,
        ClosedLoopError,
        EquilibriumError,
        ExpressionError,
        IgnoredFeatureWarning,
        InvalidInputError,
        JointLimitError,
        JointLimitWarning,
        MechanismError,
        ModelFileError,
        ModelMisfitWarning,
        ModesError,
        NameNotFoundError,
        NumericalError,
        OpenLoopError,
        OutsideLimitsError,
        RigidDirectionsError,
        SingularConfigurationError,
        UnreachableError,
        ViewerError,
    )
    from closedloop.io import data
    from closedloop.io.data import robot_data_dir
    from closedloop.io.loader import load_model
    from closedloop.kinematics.assembly import Assembly, assemble
    from closedloop.kinematics.assembly_modes import assembly_modes
    from closedloop.kinematics.configuration import CLOSURE_TOL, Configuration
    from closedloop.kinematics.inverse import inverse_kinematics
    from closedloop.model.closed_loop import ClosedLoopModel
    from closedloop.model.gravity import STANDARD_GRAVITY, GravityLoad, Payload


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    mod = importlib.import_module(module, __name__)
    value = mod if name in _SUBMODULES else getattr(mod, name)
    globals()[name] = value  # once: later lookups do not come here
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})


__version__ = "0.2.0"

__all__ = [
    "CLOSURE_TOL",
    "ILL_CONDITIONED",
    "RANK_RTOL",
    "STANDARD_GRAVITY",
    "Assembly",
    "AssemblyError",
    "BatchCompliance",
    "BeamError",
    "ClosedLoopError",
    "ClosedLoopModel",
    "ComplianceQuery",
    "ComplianceResult",
    "Configuration",
    "DesignEvaluation",
    "DesignProblem",
    "DesignResult",
    "Equilibrium",
    "EquilibriumError",
    "ExpressionError",
    "GravityLoad",
    "IgnoredFeatureWarning",
    "InvalidInputError",
    "JointLimitError",
    "JointLimitWarning",
    "MechanismError",
    "ModelFileError",
    "ModelMisfitWarning",
    "ModesError",
    "ModesResult",
    "NameNotFoundError",
    "NumericalError",
    "OpenLoopError",
    "OutsideLimitsError",
    "PathResult",
    "Payload",
    "PreloadedCompliance",
    "RigidDirectionsError",
    "SingularConfigurationError",
    "StiffnessIndices",
    "UnreachableError",
    "ViewerError",
    "assemble",
    "assembly_modes",
    "batch_modes",
    "closure_curvature",
    "compliance",
    "compliances",
    "data",
    "design_problem",
    "follow_path",
    "geometric_stiffness",
    "inverse_kinematics",
    "load_model",
    "modes",
    "optimize_design",
    "preloaded_compliance",
    "robot_data_dir",
    "solve_equilibrium",
    "tangent_stiffness",
]
