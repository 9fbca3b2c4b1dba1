"""Stiffness analysis of robots with closed kinematic loops, on Pinocchio 4.

The whole workflow from one import::

    import closedloop as cl

    robot = cl.load_model("fourbar.urdf", "fourbar.yaml")   # tree + closures + springs
    state = cl.Configuration(robot, cl.assemble(robot, actuated=[0.3]).q)
    res = cl.compliance(state, "P")            # 6x6 C [SI] at the origin of frame P
    res.K, res.rank, res.condition_number, res.ill_conditioned
    cl.compliances(robot, Q, "P").C            # (n, 6, 6) for n configurations Q (n, nq)
    cl.StiffnessIndices.from_result(res).min_translational_stiffness

The modules (``closedloop.compliance``, ``closedloop.assembly``, ...) stay importable.
"""

from __future__ import annotations

import importlib
import sys
from types import ModuleType
from typing import TYPE_CHECKING

#: Public name -> the module that defines it; imported on first use (module-level
#: ``__getattr__``), so that ``import closedloop.exceptions`` or a command line that needs a
#: few modules does not load scipy, yaml or every other module. The submodules among them:
#: :data:`_SUBMODULES`.
_EXPORTS = {
    "data": ".data",
    **dict.fromkeys(("Assembly", "assemble"), ".assembly"),
    **dict.fromkeys(("BatchCompliance", "compliances"), ".batch"),
    **dict.fromkeys(("ComplianceResult", "compliance"), ".compliance"),
    **dict.fromkeys(("ILL_CONDITIONED", "RANK_RTOL"), ".conditioning"),
    **dict.fromkeys(("CLOSURE_TOL", "Configuration"), ".configuration"),
    **dict.fromkeys(
        (
            "AssemblyError",
            "BeamError",
            "ClosedLoopError",
            "EquilibriumError",
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
            "ViewerError",
        ),
        ".exceptions",
    ),
    **dict.fromkeys(("STANDARD_GRAVITY", "GravityLoad", "Payload"), ".gravity"),
    "StiffnessIndices": ".indices",
    "load_model": ".io",
    "robot_data_dir": ".data",
    "ClosedLoopModel": ".model",
    **dict.fromkeys(("PreloadedCompliance", "preloaded_compliance"), ".preload"),
    **dict.fromkeys(("Equilibrium", "solve_equilibrium"), ".statics"),
    **dict.fromkeys(("closure_curvature", "geometric_stiffness", "tangent_stiffness"), ".tangent"),
    **dict.fromkeys(("ModesResult", "batch_modes", "modes"), ".vibration"),
}
_SUBMODULES = frozenset({"data"})

if TYPE_CHECKING:  # the names as static analysis sees them
    from . import data
    from .assembly import Assembly, assemble
    from .batch import BatchCompliance, compliances
    from .compliance import ComplianceResult, compliance
    from .conditioning import ILL_CONDITIONED, RANK_RTOL
    from .configuration import CLOSURE_TOL, Configuration
    from .data import robot_data_dir
    from .exceptions import (
        AssemblyError,
        BeamError,
        ClosedLoopError,
        EquilibriumError,
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
        ViewerError,
    )
    from .gravity import STANDARD_GRAVITY, GravityLoad, Payload
    from .indices import StiffnessIndices
    from .io import load_model
    from .model import ClosedLoopModel
    from .preload import PreloadedCompliance, preloaded_compliance
    from .statics import Equilibrium, solve_equilibrium
    from .tangent import closure_curvature, geometric_stiffness, tangent_stiffness
    from .vibration import ModesResult, batch_modes, modes


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    mod = importlib.import_module(module, __name__)
    value = mod if name in _SUBMODULES else getattr(mod, name)
    globals()[name] = value  # once: later lookups do not come here
    return value


class _Package(ModuleType):
    """The package, which keeps ``closedloop.compliance`` the function.

    Importing a submodule binds it to its name in the package: ``closedloop.compliance``
    would become the module once anything imported ``closedloop.compliance``. As when the
    package imported every name eagerly, the exported function of that name wins.
    """

    def __setattr__(self, name: str, value) -> None:
        if isinstance(value, ModuleType) and name in _EXPORTS and name not in _SUBMODULES:
            value = getattr(value, name)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package


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
    "ComplianceResult",
    "Configuration",
    "Equilibrium",
    "EquilibriumError",
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
    "Payload",
    "PreloadedCompliance",
    "RigidDirectionsError",
    "SingularConfigurationError",
    "StiffnessIndices",
    "ViewerError",
    "assemble",
    "batch_modes",
    "closure_curvature",
    "compliance",
    "compliances",
    "data",
    "geometric_stiffness",
    "load_model",
    "modes",
    "preloaded_compliance",
    "robot_data_dir",
    "solve_equilibrium",
    "tangent_stiffness",
]
