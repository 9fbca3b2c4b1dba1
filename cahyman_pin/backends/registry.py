"""The backends of :func:`cahyman_pin.api.stiffness`: what a backend returns, the registry
of backends by name, and the three built in.

Backends compute the matrices: ``"generic"`` (default) is the Pinocchio model of
:mod:`cahyman_pin.model` with :func:`closedloop.elastostatics.compliance.compliance`;
``"consistent"`` is the closed form of :mod:`cahyman_pin.backends.consistent`; ``"published"`` the
paper's matrices as printed (:mod:`cahyman_pin.backends.published`, its own coordinates, not
symmetric) with the parameters' K_s (``params.with_ks("printed")`` for the printed 0.697
N/m; every other damaged place as published). Another backend is a function
``f(params, alpha, alpha4, s4) -> BackendResult`` registered with
``register_backend("name", f)``.

A backend's C is at M (the arm extremity), in world axes, ordered (dx, dy, dz, rx, ry, rz)
for twists and (fx, fy, fz, nx, ny, nz) for wrenches, unless it says otherwise (``axes``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from cahyman_pin.model import CaHyManPose, cahyman_model, closed_form_pose
from cahyman_pin.params import CaHyManParams
from cahyman_pin.urdf_builder import FRAME_H, FRAME_M
from closedloop.common.arrays import readonly
from closedloop.elastostatics.compliance import compliance
from closedloop.exceptions import InvalidInputError
from closedloop.kinematics.configuration import Configuration


@dataclass(frozen=True)
class BackendResult:
    """What a backend returns.

    Attributes:
        C: (6, 6) compliance at M, world axes [SI] (see the module docstring).
        pose: plate and arm pose.
        C_platform: (6, 6) twist of the plate at H (world axes) per wrench at M, or None
            when the backend does not provide it.
        details: backend-specific extras (e.g. the configuration q); ``factor``, a
            square-root factor B (6, r) of C = B B^T [SI], when the backend has one: K and
            its indices then come from the SVD of B, not from C.
        axes: coordinates of C: ``"world"`` (twist at M, world axes) or a description of
            the backend's own coordinates.
    """

    C: np.ndarray
    pose: CaHyManPose
    C_platform: np.ndarray | None = None
    details: dict = field(default_factory=dict)
    axes: str = "world"


Backend = Callable[[CaHyManParams, np.ndarray, float, float], BackendResult]
_BACKENDS: dict[str, Backend] = {}


def register_backend(name: str, func: Backend) -> Backend:
    """Make ``func`` available as ``backend=name`` (returns ``func``)."""
    if not isinstance(name, str) or not name.isidentifier():
        raise InvalidInputError(f"backend name {name!r} must be an identifier")
    _BACKENDS[name] = func
    return func


def backend_names() -> tuple[str, ...]:
    """Names of the registered backends, sorted."""
    return tuple(sorted(_BACKENDS))


def get_backend(name: str) -> Backend:
    """The backend function called ``name``.

    Raises:
        InvalidInputError: unknown name (the message lists the choices).
    """
    if not isinstance(name, str) or name not in _BACKENDS:
        raise InvalidInputError(
            f"unknown backend {name!r}; expected one of {list(backend_names())}"
        )
    return _BACKENDS[name]


def generic_backend(
    params: CaHyManParams, alpha, alpha4: float, s4: float, *, weight: bool = False
) -> BackendResult:
    """Pinocchio model + closedloop compliance (the reference backend).

    With ``weight``, the assembled configuration is the springs' rest configuration: the
    machine settles under the weight of its masses (``params.m_*``, gravity
    ``params.gravity`` along -z) and the result is the tangent compliance there
    (:func:`closedloop.elastostatics.compliance.compliance` with ``gravity``); its ``sag`` is that
    of M.

    ``details`` holds ``q`` (nq,), the configuration of the result (the sagged one with
    ``weight``), and ``compliance``, the
    :class:`closedloop.elastostatics.compliance.ComplianceResult`.
    """
    model = cahyman_model(params)
    q = model.assemble(alpha, alpha4, s4)
    # q checked once, here; its limits in CaHyMan's words (not again by Configuration)
    state = Configuration(model.clm, q, length=params.length, check_limits=False)
    model.require_within_limits(state)
    gravity = (0.0, 0.0, -params.gravity) if weight else None
    result = compliance(state, FRAME_M, gravity=gravity)
    if weight:  # the plate Jacobian at the sagged configuration (its limits: the statics')
        state = Configuration(model.clm, result.q, length=params.length, check_limits=False)
    J_H = state.frame_jacobian(FRAME_H)
    return BackendResult(
        C=result.C,
        pose=model.pose_from(state.q, state.data),
        C_platform=readonly(J_H @ result.G),
        details={"q": result.q, "compliance": result},
    )


#: The backends that are the paper's closed forms: lumped springs, no masses, no beams.
CLOSED_FORMS = ("consistent", "published")


def check_closed_form(params: CaHyManParams, backend: str) -> None:
    """Refuse the parameters of a machine that a closed-form ``backend`` does not model
    (links as beams), rather than answer for another machine.

    Raises:
        InvalidInputError: ``params.links_as_beams`` with a backend of :data:`CLOSED_FORMS`.
    """
    if backend in CLOSED_FORMS and params.links_as_beams:
        raise InvalidInputError(
            f"links_as_beams needs the generic backend (the closed forms have the lumped "
            f"springs K_b, K_d, K_4, no beams), got backend {backend!r}"
        )


def consistent_backend(params: CaHyManParams, alpha, alpha4: float, s4: float) -> BackendResult:
    """The consistent closed form (pure numpy); ``details["breakdown"]`` has its parts and
    ``details["factor"]`` the square-root factor B (6, 12) of C, whose SVD gives K.

    The plate twist at H per wrench at M is C_H T^T (T^T carries the wrench from M to H).

    Raises:
        InvalidInputError: ``params.links_as_beams`` (:func:`check_closed_form`).
    """
    from cahyman_pin.backends.consistent import (  # on demand: start-up
        consistent_breakdown,
        factor_root_stiffness,
    )

    check_closed_form(params, "consistent")
    parts = consistent_breakdown(alpha, alpha4, s4, params)
    return BackendResult(
        C=parts.C,
        pose=closed_form_pose(alpha, alpha4, s4, params),
        C_platform=readonly(parts.C_H @ parts.T.T),
        details={
            "breakdown": parts,
            "factor": parts.B,
            "factor_roots": factor_root_stiffness(params),
        },
    )


#: The coordinates of the published backend's C (see :mod:`cahyman_pin.backends.published`).
PUBLISHED_AXES = (
    "paper: translations of H plus those of M, plate rotation vector (world) plus the arm "
    "angle about -y_p; not world axes at M"
)


def published_backend(params: CaHyManParams, alpha, alpha4: float, s4: float) -> BackendResult:
    """The paper's matrices as printed (see :mod:`cahyman_pin.backends.published`), with
    ``params.K_s`` (option ``ks="params"``; the paper prints 0.697 N/m:
    ``params.with_ks("printed")``).

    Its C is in the paper's own mixed coordinates (:data:`PUBLISHED_AXES`) and is not
    symmetric; C_platform is the plate term K_PAR^-1 of eq. (3) (displacement of H). No
    load is given, so the weight terms of eq. (11) are zero. ``details["result"]`` holds
    every matrix.

    Raises:
        InvalidInputError: ``params.links_as_beams`` (:func:`check_closed_form`).
    """
    from cahyman_pin.backends.published import PublishedOptions, published_stiffness

    check_closed_form(params, "published")
    r = published_stiffness(alpha, alpha4, s4, params, PublishedOptions(ks="params"))
    return BackendResult(
        C=r.C,
        pose=closed_form_pose(alpha, alpha4, s4, params),
        C_platform=r.C_PAR,
        details={"result": r},
        axes=PUBLISHED_AXES,
    )


register_backend("generic", generic_backend)
register_backend("consistent", consistent_backend)
register_backend("published", published_backend)
