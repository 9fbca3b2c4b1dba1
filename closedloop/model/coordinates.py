"""A model's coordinates: what its neutral configuration tells (which velocity
coordinates are translations, its characteristic length) and the check of a configuration
vector q (its shape, finite values, quaternions and unit complex numbers normalised), for
:class:`closedloop.model.closed_loop.ClosedLoopModel`.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import frozen, real_array
from closedloop.common.conditioning import characteristic_length
from closedloop.exceptions import InvalidInputError

#: The dtype of a configuration that needs no conversion (numpy's native float64).
_FLOAT64 = np.dtype(np.float64)
#: Largest change of a coordinate when the quaternions and unit complex numbers of q are
#: normalised: a q further from the configuration manifold is refused, a nearer one
#: normalised (7 typed digits are within it).
UNIT_NORM_TOL = 1e-6


def neutral_facts(model: pin.Model) -> tuple[np.ndarray, float]:
    """What a model's neutral configuration tells, from one forward kinematics:

    * (nv,) read-only mask of the translational velocity coordinates (prismatic, the
      linear part of a free flyer...), read off the joint motion subspaces: a coordinate
      is linear when it moves its joint without rotating it;
    * the characteristic length [m]: the diameter of the mechanism at the neutral
      configuration, the largest distance between two of its joint origins and frames
      (links, tools), not the world origin (the universe frame), so that moving the
      mechanism in the world leaves it unchanged
      (:func:`closedloop.common.conditioning.characteristic_length`).
    """
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    pin.updateFramePlacements(model, data)
    mask = np.zeros(model.nv, dtype=bool)
    for j in range(1, model.njoints):
        jm = model.joints[j]
        if jm.nv:
            S = np.asarray(data.joints[j].S).reshape(6, jm.nv)
            if not np.all(np.any(S != 0.0, axis=0)):
                raise InvalidInputError(
                    f"joint {model.names[j]!r} ({jm.shortname()}) has a coordinate that moves "
                    "nothing (a zero axis in the robot file?); expected an axis of non-zero length"
                )
            mask[jm.idx_v : jm.idx_v + jm.nv] = ~np.any(S[3:] != 0.0, axis=0)
    points = [data.oMi[j].translation for j in range(1, model.njoints)]
    points += [data.oMf[i].translation for i in range(1, model.nframes)]  # 0: the universe
    return frozen(mask), characteristic_length(points)


def checked_configuration(
    model: pin.Model, q: np.ndarray, nq: int, unit_coordinates: bool
) -> np.ndarray:
    """Validated copy of a configuration vector q (nq,) of ``model`` [rad, m], its
    quaternions and unit complex numbers normalised.

    Args:
        model: the kinematic tree.
        q: (nq,) the configuration.
        nq: ``model.nq``, read once by the caller (every query checks its q).
        unit_coordinates: whether ``model.nq != model.nv`` (quaternions or unit complex
            numbers), read once by the caller.

    Raises:
        InvalidInputError: q of another shape, with non-finite values, or with a
            quaternion or unit complex number off norm 1 by more than
            :data:`UNIT_NORM_TOL`.
    """
    if type(q) is np.ndarray and q.dtype is _FLOAT64 and q.ndim == 1:
        q = q.copy()  # the common case, without the conversions of real_array
    else:
        q = real_array(q, "q")
        if q.ndim > 1:  # a (1, nq) row or a stack of configurations is not one q
            raise InvalidInputError(
                f"q must be one configuration, shape (nq,) = ({model.nq},), got shape "
                f"{q.shape} (many configurations: closedloop.compliances)"
            )
        q = q.reshape(-1)
    if len(q) != nq:  # q is one-dimensional here
        raise InvalidInputError(f"q has {q.size} values; expected nq={nq}")
    # a sum of floats is finite when every one is (it may overflow: then look at each)
    if not math.isfinite(sum(q.tolist())) and not np.isfinite(q).all():
        raise InvalidInputError(f"q contains non-finite values: {q.tolist()}")
    if unit_coordinates:  # quaternions or unit complex numbers
        q = _normalised(model, q)
    return q


def _normalised(model: pin.Model, q: np.ndarray) -> np.ndarray:
    """q with its quaternions and unit complex numbers (free-flyer, spherical, planar,
    unbounded revolute joints) normalised, or :class:`InvalidInputError` naming the
    joint of one whose norm is off 1 by more than :data:`UNIT_NORM_TOL`."""
    if not pin.isNormalized(model, q, UNIT_NORM_TOL):
        for j, jm in enumerate(model.joints):  # the first joint whose part is off
            part = slice(jm.idx_q, jm.idx_q + jm.nq)
            alone = pin.neutral(model)
            alone[part] = q[part]
            if jm.nq != jm.nv and not pin.isNormalized(model, alone, UNIT_NORM_TOL):
                raise InvalidInputError(
                    f"q of joint {model.names[j]!r} ({jm.shortname()}) is "
                    f"{q[part].tolist()}: its quaternion or unit complex number is not of "
                    f"norm 1 (to {UNIT_NORM_TOL:g}); normalise it (pinocchio.normalize)"
                )
    return pin.normalize(model, q)
