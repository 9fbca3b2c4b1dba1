"""The reference configuration of a model: the start of an assembly that is given none,
which picks its assembly mode (:func:`closedloop.kinematics.assembly.assemble`).

A model keeps named configurations in Pinocchio's ``model.referenceConfigurations``; the
reference configuration is the first there of :data:`REFERENCE_KEYS` (a closure file's
``start:``, the MJCF ``qpos0``, the springs' rest configuration), else the neutral one.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

#: Name of the rest configuration in ``model.referenceConfigurations`` (springs at rest).
REST = "spring_rest"
#: Name of the start configuration that a closure file's ``start:`` gives (the joints it
#: names at their values, the others as in the file's own reference configuration).
START = "start"
#: Keys of ``model.referenceConfigurations`` taken as the reference configuration, first
#: found first (:meth:`closedloop.model.closed_loop.ClosedLoopModel.reference_configuration`).
REFERENCE_KEYS = (START, "qpos0", REST)


def reference_key(model: pin.Model) -> str | None:
    """The first of :data:`REFERENCE_KEYS` in ``model.referenceConfigurations``, or None."""
    return next((k for k in REFERENCE_KEYS if k in model.referenceConfigurations), None)


def reference_of(model: pin.Model) -> np.ndarray:
    """(nq,) new array: the reference configuration of ``model``, the first it has of a
    closure file's ``start:`` (:data:`START`), the MJCF ``qpos0`` and the rest
    configuration (:data:`REST`: springs at their SDF ``spring_reference``, or the URDF's
    drawing with the cut's joints of elastic closures), else neutral."""
    key = reference_key(model)
    return np.array(model.referenceConfigurations[key] if key else pin.neutral(model), float)
