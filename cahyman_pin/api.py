"""One-call stiffness queries of CaHyMan at an arbitrary pose (SI in, SI out).

Example::

    from cahyman_pin.api import stiffness
    r = stiffness([1.0, 1.1, 1.2], 0.5, 0.02)   # alpha [rad], alpha_4 [rad], s_4 [m]
    r.K, r.C, r.det_K                            # at M, world axes
    r.deflection([1, 1, 1, 0, 0, 0]).M           # twist of M under 1 N along x, y, z

Matrices are 6x6 at the reference point M (the arm extremity), in world axes, ordered
(dx, dy, dz, rx, ry, rz) for twists and (fx, fy, fz, nx, ny, nz) for wrenches; a rotation
is the small rotation vector of the arm link that carries M.

Backends compute the matrices: ``"generic"`` (default, the Pinocchio model), the closed
forms ``"consistent"`` and ``"published"``, or another registered with
:func:`~cahyman_pin.backends.registry.register_backend`
(:mod:`cahyman_pin.backends.registry`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from cahyman_pin.backends.registry import BackendResult, generic_backend, get_backend
from cahyman_pin.model import CaHyManPose, check_inputs
from cahyman_pin.params import DEFAULT_PARAMS, SPRING_FIELDS, CaHyManParams
from closedloop.analysis.indices import StiffnessIndices
from closedloop.analysis.spectra import lu_determinant
from closedloop.common.arrays import ReadOnlyArrays, check_wrench, readonly, real_array
from closedloop.common.conditioning import (
    SCALED_TOL,
    scaled_asymmetry,
    spectrum_from_factor,
    twist_scaling,
)
from closedloop.elastostatics.compliance import TWIST_LABELS, UNITS, finite_product
from closedloop.exceptions import InvalidInputError, SingularConfigurationError


@dataclass(frozen=True)
class Deflection:
    """Small displacement under a wrench at M (arrays read-only, world axes, SI).

    Attributes:
        wrench: (6,) (fx, fy, fz [N], nx, ny, nz [N m]) applied at M.
        M: (6,) twist of M: (dx, dy, dz [m], rx, ry, rz [rad]), rotation of the arm link.
        H: (6,) twist of the plate at H, or None if the backend does not give it.
    """

    wrench: np.ndarray
    M: np.ndarray
    H: np.ndarray | None

    def to_dict(self) -> dict:
        """JSON-ready dict (SI)."""
        return {
            "wrench": self.wrench.tolist(),
            "M": self.M.tolist(),
            "H": None if self.H is None else self.H.tolist(),
        }


@dataclass(frozen=True)
class CaHyManStiffness(ReadOnlyArrays):
    """Stiffness of CaHyMan at one pose (arrays read-only).

    Attributes:
        alpha: (3,) crank angles alpha_1..3 [rad].
        alpha4: arm angle [rad].
        s4: telescope stroke [m].
        params: parameters used.
        backend: name of the backend.
        C: (6, 6) compliance at M, world axes [m/N, m/(N m) = rad/N, rad/(N m)].
        C_platform: (6, 6) twist of the plate at H per wrench at M, or None.
        pose: plate and arm pose.
        indices: :class:`closedloop.analysis.indices.StiffnessIndices` of C, or None when C is not
            symmetric (the published backend): K, det_K, eigenvalues and condition
            number are then those of the plain inverse of C.
        details: backend extras (generic: ``q``, ``compliance``).
        axes: coordinates of C and K: ``"world"`` (at M, world axes) or the backend's own
            (the published backend:
            :data:`cahyman_pin.backends.registry.PUBLISHED_AXES`).
    """

    alpha: np.ndarray
    alpha4: float
    s4: float
    params: CaHyManParams
    backend: str
    C: np.ndarray
    C_platform: np.ndarray | None
    pose: CaHyManPose
    indices: StiffnessIndices | None
    details: dict = field(default_factory=dict, repr=False)
    axes: str = "world"

    @property
    def K(self) -> np.ndarray:
        """(6, 6) stiffness C^-1 at M, world axes [N/m, N/rad, N m/m, N m/rad].

        Raises:
            RigidDirectionsError: C is rank deficient.
        """
        return readonly(np.linalg.inv(self.C)) if self.indices is None else self.indices.K

    @property
    def det_K(self) -> float:
        """det K [N^6/rad^3] (the paper's performance index).

        Raises:
            SingularConfigurationError: det K is beyond the floating point range.
        """
        return lu_determinant(self.K) if self.indices is None else self.indices.determinant

    @property
    def eigenvalues(self) -> np.ndarray:
        """(6,) eigenvalues of K in SI (mixed units), ascending (real part first)."""
        if self.indices is None:
            ev = np.linalg.eigvals(self.K)
            return ev[np.lexsort((ev.imag, ev.real))]
        return self.indices.eigenvalues

    @property
    def condition_number(self) -> float:
        """Condition number of K in SI (depends on the length unit and the point)."""
        return (
            float(np.linalg.cond(self.K)) if self.indices is None else self.indices.condition_number
        )

    @property
    def sag_M(self) -> np.ndarray | None:
        """(6,) sag of M under the weight (``weight=True``): the twist from the rest pose to
        the sagged one, (translation [m], rotation vector [rad]), at M, world axes; None
        without weight."""
        result = self.details.get("compliance")
        return result.sag if hasattr(result, "sag") else None

    @property
    def is_full_rank(self) -> bool:
        """True when K exists."""
        return True if self.indices is None else self.indices.is_full_rank

    def deflection(self, wrench) -> Deflection:
        """Twists of M and of the plate under ``wrench`` (6,) at M [N, N m], world axes."""
        w = check_wrench(wrench)
        M = finite_product(lambda: self.C @ w, "deflection of M", w)
        H = (
            None
            if self.C_platform is None
            else finite_product(lambda: self.C_platform @ w, "deflection of the platform", w)
        )
        return Deflection(wrench=readonly(w), M=M, H=H)

    def to_dict(self) -> dict:
        """JSON-ready summary (SI): K, C, det_K, eigenvalues, platform, inputs, units."""
        full = self.is_full_rank
        ev = self.eigenvalues if full else None
        missing = {}
        try:
            det = self.det_K if full else None
        except SingularConfigurationError as e:
            det, missing["det_K"] = None, str(e)
        return {
            "K": self.K.tolist() if full else None,
            "C": self.C.tolist(),
            "det_K": det,
            "eigenvalues_K": None if ev is None else _real_or_pairs(ev),
            "condition_number_K": self.condition_number if full else None,
            "condition_number_scaled": (
                None if self.indices is None else self.indices.scaled_condition_number
            ),
            "ill_conditioned": None if self.indices is None else self.indices.ill_conditioned,
            "rank": 6 if self.indices is None else self.indices.rank,
            "reference_point": "M",
            "M_m": self.pose.M.tolist(),
            "axes": self.axes,
            "order": list(TWIST_LABELS),
            "platform": self.pose.to_dict(),
            "inputs": {
                "alpha_rad": self.alpha.tolist(),
                "alpha4_rad": self.alpha4,
                "s4_m": self.s4,
                "K_s_N_per_m": self.params.K_s,
            },
            "backend": self.backend,
            "sag_M": None if self.sag_M is None else self.sag_M.tolist(),
            "missing": missing,
            "units": {**UNITS, "det_K": "N^6/rad^3"},
        }


def _read_only(a) -> np.ndarray:
    """``a`` itself when it is a read-only float array owning its data (a generic result's),
    else a read-only copy."""
    if type(a) is np.ndarray and a.dtype == np.float64 and a.base is None:
        if not a.flags.writeable:
            return a
    return readonly(a)


def _real_or_pairs(ev: np.ndarray) -> list:
    """Eigenvalues as JSON: reals, or [real, imaginary] pairs when some are complex."""
    ev = np.real_if_close(ev)
    return ev.tolist() if np.isrealobj(ev) else [[float(e.real), float(e.imag)] for e in ev]


def _indices(result: BackendResult, params: CaHyManParams, backend: str, inputs: tuple):
    """Indices by the one rank rule at the machine's length (the generic solver's own
    decision, taken on its square-root factor, is kept; a backend's ``factor`` B gives
    K and the condition number from its SVD, as the generic solver's does, and the rank
    from its kinematic part B diag(sqrt k) when it gives ``factor_roots`` sqrt(k): springs
    however far apart are springs, as in the generic backend).

    Raises:
        SingularConfigurationError: a closed-form C of numerical rank < 6. CaHyMan's
            springs reach all six directions of M at every regular pose, so that rank
            deficiency is not rigidity but a singular pose: a crank near its coupler (the
            generic backend refuses the same poses as a mechanism: its spring-free rule
            works on the motions of the sprung joints), or, for a backend that gives C
            alone, springs many orders apart, whose compliances C cannot tell from
            rigidity by the rank rule. The message says which (the pose, if C is still
            rank deficient with the paper's springs; else the spread of the springs).
    """
    if "compliance" in result.details:
        return StiffnessIndices.from_result(result.details["compliance"], length=params.length)
    if "factor" in result.details:
        B_s = twist_scaling(params.length)[:, None] * result.details["factor"]
        roots = result.details.get("factor_roots")  # sqrt(k) of B's columns: the rank on
        # the kinematic part B diag(sqrt k), as the generic backend's (springs far apart
        # are springs; a singular pose is not)
        spectrum = (
            spectrum_from_factor(B_s, params.length)
            if roots is None
            else spectrum_from_factor(
                B_s, params.length, lambda: B_s * roots, float(roots.max() / roots.min())
            )
        )
        indices = StiffnessIndices(
            readonly(result.C), spectrum.rank, spectrum.rigid_directions, params.length, spectrum
        )
    elif scaled_asymmetry(result.C, params.length) > SCALED_TOL:
        return None
    else:
        indices = StiffnessIndices.from_compliance(result.C, length=params.length)
    if not indices.is_full_rank:
        raise SingularConfigurationError(
            f"the {backend} compliance at M has numerical rank {indices.rank} < 6 (scaled "
            f"eigenvalue ratio below 1e-14): {_rank_deficiency_reason(params, backend, inputs)}"
        )
    return indices


def _rank_deficiency_reason(params: CaHyManParams, backend: str, inputs: tuple) -> str:
    """Why a closed form's C is rank deficient: the pose (still so with the paper's
    springs) or the spread of ``params``' springs (full rank with the paper's)."""
    paper = {name: getattr(DEFAULT_PARAMS, name) for name in SPRING_FIELDS}
    given = {name: getattr(params, name) for name in SPRING_FIELDS}
    if given != paper:
        try:
            C = get_backend(backend)(params.replace(**paper), *inputs).C
            full = StiffnessIndices.from_compliance(C, length=params.length).is_full_rank
        except SingularConfigurationError:
            full = False
        if full:
            springs = ", ".join(f"{name}={value:g}" for name, value in given.items())
            return (
                f"the springs ({springs}) are too many orders apart for the closed form, "
                "which sums their compliances (the pose is regular); the generic backend "
                "resolves them"
            )
    return "a singular pose, where one direction is almost free; move the inputs away from it"


def stiffness(
    alpha,
    alpha4: float,
    s4: float,
    *,
    params: CaHyManParams = DEFAULT_PARAMS,
    backend: str = "generic",
    weight: bool = False,
) -> CaHyManStiffness:
    """Stiffness and compliance of CaHyMan at M for the given inputs.

    Args:
        alpha: (3,) crank angles alpha_1..3 [rad].
        alpha4: arm angle [rad] (from x_p towards z_p).
        s4: telescope stroke [m], in [0, params.s4_max].
        params: parameters (e.g. ``DEFAULT_PARAMS.with_ks("printed")``).
        backend: name of the backend (see :func:`cahyman_pin.backend_names`).
        weight: the machine under the weight of its masses (``params.m_*``), generic
            backend only (:func:`generic_backend`): the tangent compliance at the sagged
            pose, and ``details["compliance"].sag`` the sag of M.

    Raises:
        InvalidInputError: bad input or unknown backend.
        AssemblyError: unreachable pose.
    """
    if not isinstance(params, CaHyManParams):
        raise InvalidInputError(f"params must be a CaHyManParams, got {type(params).__name__}")
    # refuse what is not real numbers (strings, complex...); float arrays and floats are
    if not (type(alpha) is np.ndarray and alpha.dtype == np.float64):
        alpha = real_array(alpha, "alpha")
    alpha4 = alpha4 if isinstance(alpha4, float) else real_array(alpha4, "alpha4")
    s4 = s4 if isinstance(s4, float) else real_array(s4, "s4")
    alpha, alpha4, s4 = check_inputs(alpha, alpha4, s4, params)
    if weight and backend != "generic":
        raise InvalidInputError(
            f"the weight needs the generic backend (the closed forms have no masses), got "
            f"backend {backend!r}"
        )
    solve = get_backend(backend)
    result = (
        generic_backend(params, alpha, alpha4, s4, weight=True)
        if weight
        else solve(params, alpha, alpha4, s4)
    )
    return CaHyManStiffness(
        alpha=readonly(alpha),
        alpha4=alpha4,
        s4=s4,
        params=params,
        backend=backend,
        C=_read_only(result.C),
        C_platform=None if result.C_platform is None else _read_only(result.C_platform),
        pose=result.pose,
        indices=_indices(result, params, backend, (alpha, alpha4, s4)),
        details=result.details,
        axes=result.axes,
    )
