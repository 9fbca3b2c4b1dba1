"""Derivatives along the tangent of q by central differences, and where Pinocchio's own
second-order algorithms cannot be used.

Pinocchio's kinematic Hessians (``computeJointKinematicHessians``) and gravity
derivatives (``computeGeneralizedGravityDerivatives``) assume that each joint's motion
subspace S is constant in the joint frame. For joints whose S depends on q they are
wrong: measured against central differences of Pinocchio's own Jacobians and gravity
(pin 4.1), the universal joint 76 % and 39 % off, ZYX spherical 95 % and 8 %, the
ellipsoid 100 % and 54 % (relative to the largest entry). For models with such joints the
tangent stiffness (:mod:`closedloop.elastostatics.tangent`) and the weight's stiffness
(:mod:`closedloop.model.gravity`) are computed by central differences of the first-order
quantities instead, with :data:`DIFFERENCE_STEP`.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np
import pinocchio as pin

#: Step [rad or m] of the central differences. The error of a central difference is
#: h^2/6 ``|f'''|`` (truncation) + eps ``|f|`` / h (rounding), smallest near h = (3 eps)^(1/3) ~
#: 1e-5, where both are ~1e-10 relative to f for links of metre scale.
DIFFERENCE_STEP = 1e-5
#: Joints whose motion subspace depends on q (Pinocchio's second-order algorithms are
#: wrong for them, module docstring); composite and mimic joints are counted among them,
#: as their parts may be.
VARYING_SUBSPACE_JOINTS = frozenset(
    {
        "JointModelUniversal",
        "JointModelSphericalZYX",
        "JointModelEllipsoid",
        "JointModelComposite",
        "JointModelMimic",
    }
)


def pinocchio_second_order_exact(model: pin.Model) -> bool:
    """True when no joint of ``model`` is in :data:`VARYING_SUBSPACE_JOINTS`."""
    return not any(jm.shortname() in VARYING_SUBSPACE_JOINTS for jm in model.joints[1:])


def central_differences(
    model: pin.Model,
    q: np.ndarray,
    f: Callable[[np.ndarray], np.ndarray],
    columns: Iterable[int] | None = None,
    h: float = DIFFERENCE_STEP,
) -> np.ndarray:
    """(n, nv) derivative df/dq of f (n,) along the tangent of q (``pin.integrate``).

    Column b is (f(q + h e_b) - f(q - h e_b)) / 2h; only ``columns`` (default: all) are
    computed, the others are 0 (all of them when there is none: a model without degrees
    of freedom, or an empty ``columns``). Along a prismatic coordinate the Jacobians and
    gravity forces differentiated by the library are affine (the links beyond it translate
    rigidly): a step in metres then costs no truncation error whatever the mechanism's size.

    Args:
        model: the Pinocchio model of q.
        q: (nq,) configuration.
        f: function of a configuration (nq,) returning (n,) values.
        columns: tangent indices b to differentiate along.
        h: step [rad or m].
    """
    columns = range(model.nv) if columns is None else columns
    out = None
    for b in columns:
        e = np.zeros(model.nv)
        e[b] = h
        d = (f(pin.integrate(model, q, e)) - f(pin.integrate(model, q, -e))) / (2.0 * h)
        if out is None:
            out = np.zeros((d.size, model.nv))
        out[:, b] = d
    return np.zeros((np.asarray(f(q)).size, model.nv)) if out is None else out
