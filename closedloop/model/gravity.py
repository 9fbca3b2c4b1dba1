"""Gravity of the model's own link inertias, and payloads, as a preload of the statics.

The weight of the links (URDF ``<inertial>``, MJCF masses) under a uniform acceleration
g (3,) [m/s^2] has the potential V(q) = -sum_b m_b g . c_b(q) (c_b the body centres of
mass); its generalised force is Pinocchio's generalised gravity G(q) = dV/dq
(``pin.computeGeneralizedGravity``: the joint torques that hold the robot still), and its
stiffness dG/dq (``pin.computeGeneralizedGravityDerivatives``), both along the tangent of
q. A payload is a point mass [kg] at a frame, with an offset [m] in the frame's axes; it
enters as one more body on the frame's joint, so that G and dG/dq include it.

In the equilibrium equations of :mod:`closedloop.elastostatics.tangent` the weight adds G(q) to the
spring forces and dG/dq to the tangent stiffness.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import check_wrench, readonly, real_array
from closedloop.common.derivatives import central_differences, pinocchio_second_order_exact
from closedloop.exceptions import InvalidInputError
from closedloop.model.closed_loop import ClosedLoopModel

#: Standard gravity along -z [m/s^2].
STANDARD_GRAVITY = (0.0, 0.0, -9.80665)


def _vector3(value, what: str) -> np.ndarray:
    v = real_array(value, what).reshape(-1)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        shown = np.asarray(value).tolist()
        raise InvalidInputError(f"{what} must be 3 finite numbers, got {shown}")
    return v


@dataclass(frozen=True)
class Payload:
    """A point mass carried by a frame.

    Attributes:
        mass: mass [kg], finite and >= 0.
        frame: name of the frame that carries it.
        offset: (3,) position of the mass [m] in the frame's axes, from its origin.
    """

    mass: float
    frame: str
    offset: np.ndarray = field(default_factory=lambda: readonly(np.zeros(3)))

    def __post_init__(self) -> None:
        number = isinstance(self.mass, int | float | np.integer | np.floating)
        try:  # an int beyond the float range (10**400) does not convert
            finite = number and math.isfinite(float(self.mass))
        except OverflowError:
            finite = False
        if isinstance(self.mass, bool | np.bool_) or not finite:
            raise InvalidInputError(f"payload mass must be a finite number [kg], got {self.mass!r}")
        if self.mass < 0.0:
            raise InvalidInputError(f"payload mass must be >= 0 [kg], got {self.mass}")
        if not isinstance(self.frame, str):
            raise InvalidInputError(f"payload frame must be a frame name, got {self.frame!r}")
        object.__setattr__(self, "offset", readonly(_vector3(self.offset, "payload offset")))

    def to_dict(self) -> dict:
        """JSON-ready description (SI)."""
        return {"mass_kg": float(self.mass), "frame": self.frame, "offset_m": self.offset.tolist()}


#: Largest weight moment m max|g_i| max(L, 1 m, the bodies' centres of mass in their joint
#: frames, payloads included) [N m] of a gravity load: its derivatives and the equilibrium
#: solver multiply it by the joint Jacobians and their squares.
WEIGHT_MAX = 1e150


class GravityLoad:
    """Weight of a model's links and payloads under the acceleration ``gravity``.

    Args:
        clm: the model (its inertias are used; it is not changed).
        gravity: (3,) acceleration [m/s^2], world axes (default :data:`STANDARD_GRAVITY`).
        payloads: point masses at frames.

    Raises:
        InvalidInputError: non-finite gravity, a bad payload, a nonzero gravity on a model
            whose inertias are not the robot file's
            (:meth:`closedloop.model.closed_loop.ClosedLoopModel.require_inertias`).
        NameNotFoundError: a payload frame that the model does not have.
    """

    def __init__(
        self,
        clm: ClosedLoopModel,
        gravity=STANDARD_GRAVITY,
        payloads: Sequence[Payload] = (),
    ):
        self.gravity = readonly(_vector3(gravity, "gravity [m/s^2]"))
        if self.gravity.any():  # the links' weight: their inertias are used
            clm.require_inertias("the weight of the links (gravity)")
        try:
            self.payloads = tuple(payloads)
        except TypeError:  # one Payload, or not a sequence
            raise InvalidInputError(
                f"payloads must be a sequence of Payload objects, got {payloads!r}"
            ) from None
        model = pin.Model(clm.model)  # a copy: the payloads become bodies of its own
        model.gravity = pin.Motion(np.r_[self.gravity, np.zeros(3)])
        for p in self.payloads:
            if not isinstance(p, Payload):
                raise InvalidInputError(f"payloads must be Payload objects, got {p!r}")
            f = model.frames[clm.frame_id(p.frame)]
            at = f.placement * pin.SE3(np.eye(3), p.offset)
            point_mass = pin.Inertia(float(p.mass), np.zeros(3), np.zeros((3, 3)))
            model.appendBodyToJoint(f.parentJoint, point_mass, at)
        reach = _checked_reach(model)
        self.model = model
        # the moving mass: the fixed base's (joint 0, the world) loads no spring
        self.mass = float(sum(model.inertias[j].mass for j in range(1, model.njoints)))
        lever = max(clm.length, 1.0, reach)
        weight = self.mass * float(np.max(np.abs(self.gravity))) * lever
        if not weight < WEIGHT_MAX:  # its moments, derivatives and the solver would overflow
            raise InvalidInputError(
                f"the weight under gravity {self.gravity.tolist()} m/s^2 of {self.mass:.6g} kg "
                f"(links and payloads) overflows the computation (about {weight:.3g} N m); "
                f"expected mass x |gravity| x size (or payload offset) well below "
                f"{WEIGHT_MAX:.0e}"
            )
        self._exact_derivatives = pinocchio_second_order_exact(model)
        self._local = threading.local()

    @property
    def data(self) -> pin.Data:
        """This thread's Data of :attr:`model`, made once (a Data costs more than the weight's
        computations: 0.2 s for a model of nv = 129, as CaHyMan's links as beams)."""
        try:
            return self._local.data
        except AttributeError:
            self._local.data = data = self.model.createData()
            return data

    def forces(self, q: np.ndarray, scale: float = 1.0) -> np.ndarray:
        """(nv,) generalised gravity scale G(q) [N m, N]: the weight's dV/dq."""
        return scale * pin.computeGeneralizedGravity(self.model, self.data, q)

    def stiffness(self, q: np.ndarray, scale: float = 1.0) -> np.ndarray:
        """(nv, nv) scale dG/dq [N m/rad, N/m, mixed]: the weight's part of K_t."""
        if not self._exact_derivatives:  # closedloop.common.derivatives
            return scale * central_differences(self.model, q, self.forces)
        return scale * pin.computeGeneralizedGravityDerivatives(self.model, self.data, q)

    def potential(self, q: np.ndarray) -> float:
        """Potential energy V(q) of the weight [J] (zero at the world origin)."""
        return float(pin.computePotentialEnergy(self.model, self.data, q))

    def to_dict(self) -> dict:
        """JSON-ready description: gravity [m/s^2], moving mass [kg] (links and payloads
        beyond the fixed base), payloads."""
        return {
            "gravity_m_s2": self.gravity.tolist(),
            "mass_kg": self.mass,
            "payloads": [p.to_dict() for p in self.payloads],
        }


def _checked_reach(model: pin.Model) -> float:
    """Largest ``|coordinate|`` [m] of the moving bodies' centres of mass in their joint frames
    (the lever of their weight), once each body is checked: InvalidInputError for a mass
    that is not finite or is negative, or a centre of mass that is not finite (a model
    file's ``<inertial>``; the payloads are checked as they are made)."""
    reach = 0.0
    for j in range(1, model.njoints):
        inertia = model.inertias[j]
        mass, com = float(inertia.mass), np.asarray(inertia.lever)
        if not (math.isfinite(mass) and mass >= 0.0 and np.all(np.isfinite(com))):
            raise InvalidInputError(
                f"the body on joint {model.names[j]!r} has mass {mass:g} kg at centre of mass "
                f"{com.tolist()} m; expected a finite mass >= 0 [kg] at a finite point [m] to "
                "weigh it under gravity"
            )
        reach = max(reach, float(np.max(np.abs(com))))
    return reach


@dataclass(frozen=True)
class Load:
    """What the statics follow from zero: a dead-load wrench at a frame, and the weight.

    ``t * load`` is the load at fraction t of the continuation (both scaled).

    Attributes:
        wrench: (6,) (f [N], n [N m]), world axes, at the loaded frame's origin.
        gravity: the weight, or None.
        scale: fraction of the weight applied (1 for the full load).
    """

    wrench: np.ndarray
    gravity: GravityLoad | None = None
    scale: float = 1.0

    def __rmul__(self, t: float) -> Load:
        return Load(t * self.wrench, self.gravity, t * self.scale)

    def any(self) -> bool:
        """True when something is applied."""
        weight = self.gravity is not None and self.scale != 0.0 and self.gravity.mass > 0.0
        return bool(np.any(self.wrench)) or (weight and bool(np.any(self.gravity.gravity)))

    def forces(self, q: np.ndarray, nv: int) -> np.ndarray:
        """(nv,) generalised weight scale G(q) (zero without gravity) [N m, N]."""
        return np.zeros(nv) if self.gravity is None else self.gravity.forces(q, self.scale)

    def stiffness(self, q: np.ndarray, nv: int) -> np.ndarray:
        """(nv, nv) the weight's stiffness scale dG/dq (zero without gravity)."""
        if self.gravity is None:
            return np.zeros((nv, nv))
        return self.gravity.stiffness(q, self.scale)


def as_load(w) -> Load:
    """A :class:`Load` from a Load or a wrench (6,) (fx, fy, fz [N], nx, ny, nz [N m])."""
    return w if isinstance(w, Load) else Load(check_wrench(w))
