"""Compliance under a finite dead-load preload.

A wrench w0 = (f [N], n [N m]) fixed in world axes and applied at the origin of a frame
deflects the mechanism to an equilibrium q
(:func:`closedloop.elastostatics.statics.solve_equilibrium`), with closure multipliers lambda. A
further wrench increment dw (also a dead load at the frame origin) moves it by dq = N y along the
admissible motions N (nv, d) (closures and locked joints kept), with

    K_t y = N^T J^T dw,   K_t = N^T (K_q - K_G + sum_j lambda_j Hess c_j) N   (d, d),

the tangent stiffness of :mod:`closedloop.elastostatics.tangent` (geometric stiffness of the preload
and loop curvature). The preloaded compliance at the frame is ``C = (J N) K_t^-1 (J N)^T``. A
world-fixed moment is not conservative under finite rotations: C is then not symmetric.

The second-order pieces used to live here; their names stay importable from this module
(``geometric_stiffness``, ``closure_curvature``, ``spring_hessian``, ``tangent_stiffness``,
``CRITICAL_RTOL``, ``WELD_CURVATURE_STEP``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from closedloop.common import lapack
from closedloop.common.arrays import check_wrench, readonly
from closedloop.common.conditioning import (
    RANK_RTOL,
    spectrum_from_factor,
    spectrum_of_matrix,
    twist_scaling,
)
from closedloop.elastostatics.equilibrium import Equilibrium
from closedloop.elastostatics.query import unloaded_compliance
from closedloop.elastostatics.springs import spring_factor
from closedloop.elastostatics.tangent import (
    CRITICAL_RTOL,
    WELD_CURVATURE_STEP,
    closure_curvature,
    geometric_stiffness,
    scaled_tangent,
    settled_tangent,
    spring_hessian,
    stability_margin,
    tangent_stiffness,
)
from closedloop.elastostatics.unloaded import ComplianceResult, compliance_result, result_fields
from closedloop.exceptions import EquilibriumError, SingularConfigurationError
from closedloop.kinematics.configuration import Configuration
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.elastic import deflection, spring_law

__all__ = [
    "CRITICAL_RTOL",
    "WELD_CURVATURE_STEP",
    "PreloadedCompliance",
    "closure_curvature",
    "geometric_stiffness",
    "preloaded_compliance",
    "require_stable",
    "spring_hessian",
    "tangent_stiffness",
]


@dataclass(frozen=True)
class PreloadedCompliance(ComplianceResult):
    """Compliance under a preload; the fields of :class:`ComplianceResult` plus the preload.

    ``C`` (6, 6) maps a wrench increment dw (dead load: fixed in world axes while the
    frame moves, at the frame origin, components in ``axes``) to the twist of the frame
    about its preloaded pose (dx, dy, dz [m], rx, ry, rz [rad]), at ``point``, the frame
    origin at the preloaded equilibrium ``q``. ``G`` (nv, 6) maps dw to the joint
    deflection. C is symmetric when the preload has no moment, not in general otherwise.

    Attributes:
        preload: (6,) preload wrench (f [N], n [N m]), world axes, at the frame origin.
        stability_margin: smallest eigenvalue of the symmetric part of K_t scaled by the
            unloaded spring stiffness (1 without preload, <= 0 past a static instability;
            for a non-conservative preload a divergence indicator only), the spring-free
            motions the preload acts on settled
            (:func:`closedloop.elastostatics.tangent.stability_margin`).
        equilibrium: the preloaded equilibrium (its rest configuration, the weight, the
            multipliers); ``q`` above is its configuration q_eq.
        spring_forces: (nv,) forces of the springs at q_eq, K_q dq [N m or N] (0 on
            passive and locked coordinates), dq = difference(q_rest, q_eq); on a beam's
            virtual joint the force [N] and moment [N m] at its tip, its rest axes, of
            :mod:`closedloop.model.elastic` (with the axial force's share of the bending).
    """

    preload: np.ndarray
    stability_margin: float
    equilibrium: Equilibrium | None = field(default=None, repr=False)
    spring_forces: np.ndarray | None = field(default=None, repr=False)

    # K: from a square-root factor when the preload is conservative and stable, else the
    # plain inverse of C (not symmetric under a preload moment); see ComplianceResult.K.

    @property
    def is_stable(self) -> bool:
        """True when the preloaded equilibrium is statically stable (margin > 0)."""
        return self.stability_margin > 0.0

    @property
    def sag(self) -> np.ndarray:
        """(6,) twist of the frame from the rest configuration to q_eq under the preload:
        (translation [m], rotation vector [rad]), world axes, at the frame origin."""
        return self.equilibrium.displacement

    def to_dict(self) -> dict:
        """JSON-ready summary: that of :class:`ComplianceResult` plus the preload: its
        description, the sag, q_eq, the stability margin."""
        out = super().to_dict()
        eq = self.equilibrium
        out["preload"] = self.preload.tolist()
        out["stability_margin"] = self.stability_margin
        if eq is not None:
            out.update(sag=eq.displacement.tolist(), q_eq=eq.q.tolist(), q_rest=eq.q_rest.tolist())
            out["weight"] = None if eq.gravity is None else eq.gravity.to_dict()
            out["spring_forces"] = self.spring_forces.tolist()
        return out


def require_stable(result: ComplianceResult) -> ComplianceResult:
    """``result``, unless it is a :class:`PreloadedCompliance` at an unstable equilibrium.

    There the tangent stiffness is indefinite: the mechanism does not stay on the
    equilibrium the load continuation followed (a bifurcation), and no deflection answers
    "how far does it deflect". The API returns such a result (``is_stable`` False, for a
    study of the instability); the command lines refuse it with this error.

    Raises:
        EquilibriumError: the stability margin is <= 0 (exit status 3 of the command lines).
    """
    if not isinstance(result, PreloadedCompliance) or result.is_stable:
        return result
    eq = result.equilibrium
    raise EquilibriumError(
        f"the equilibrium under the preload at frame {result.frame!r} is unstable (stability "
        f"margin {result.stability_margin:.3g} <= 0: the load or the weight exceeds what the "
        "springs hold there, and the tangent stiffness is indefinite); give a smaller load or "
        "mass, or stiffer springs",
        eq.closure_residual if eq is not None else 0.0,
        eq.force_residual if eq is not None else 0.0,
        1.0,
        limit_load=False,
        stability_margin=result.stability_margin,
    )


def preloaded_compliance(
    clm: ClosedLoopModel,
    equilibrium: Equilibrium,
    axes: str = "world",
    *,
    length: float | None = None,
) -> PreloadedCompliance:
    """Cartesian compliance at the loaded frame about a preloaded equilibrium.

    Args:
        clm: the model the equilibrium was solved with.
        equilibrium: result of :func:`closedloop.elastostatics.statics.solve_equilibrium` (its
            frame, preload wrench, configuration q, rest configuration and multipliers).
        axes: ``"world"`` (world-aligned, default) or ``"local"`` (the frame's own axes at
            the preloaded pose) for the increments dw and the twist.
        length: characteristic length L [m] of the unit-free rules and of the scaled
            condition number (default: the model's, as :class:`Configuration`).

    Returns:
        The compliance; when the preload terms vanish (zero wrench) it is exactly
        :func:`closedloop.elastostatics.compliance.compliance` at q. Spring-free motions that do not
        move the frame but that the preload acts on (a link hanging on a passive joint,
        stiffened by its weight and coupled to the sprung motions) settle with the
        increment (:func:`closedloop.elastostatics.tangent.settled_tangent`); the others (internal
        mobilities: a rod spinning about its axis) are left out, as there.

    Raises:
        MechanismError: a spring-free motion moves the frame.
        SingularConfigurationError: K_t is singular (critical preload: buckling or limit
            point).
    """
    eq = equilibrium
    frame, w0 = eq.frame, check_wrench(eq.wrench)
    # the statics flag or refuse an equilibrium outside the limits (JointLimitWarning)
    state = Configuration(clm, eq.q, length=length, check_limits=False)
    J = state.frame_jacobian(frame, axes)
    f = spring_factor(state, J, frame)
    Kt = tangent_stiffness(clm, state.q, eq.q_rest, frame, w0, eq.multipliers, gravity=eq.load)
    about = {"equilibrium": eq, "spring_forces": readonly(_spring_forces(clm, eq))}
    M, P, T = scaled_tangent(clm, Kt, f.N, f.V, f.sigma**2)  # P: preload part; T^T K_r T = I
    if not np.any(P):
        base = unloaded_compliance(state, frame, axes, "auto")
        return PreloadedCompliance(
            **result_fields(base), preload=readonly(w0), stability_margin=1.0, **about
        )
    s = T.shape[1]
    Z = f.Z / (f.sigma[0] if f.sigma.size else 1.0)  # on the scale of the stiffest spring
    M, T = settled_tangent(M, f.N.T @ Kt @ f.N, T, Z)
    s_M = np.linalg.svd(M, compute_uv=False)
    if s_M.size and s_M[-1] <= CRITICAL_RTOL:  # on the scale of the springs (1 unloaded)
        raise SingularConfigurationError(
            f"the tangent stiffness at frame {frame!r} is singular under preload "
            f"{w0.tolist()} (critical load: buckling or limit point)"
        )
    if s_M.size and s_M[-1] <= RANK_RTOL**2 * s_M[0]:  # a stiffening preload, too large
        raise SingularConfigurationError(
            f"the preload {w0.tolist()} at frame {frame!r} stiffens the mechanism "
            f"{s_M[0]:.3g} times beyond its springs: the tangent stiffness spans more than "
            f"{1 / RANK_RTOL**2:.0e} (the rank rule's resolution); give a smaller preload"
        )
    margin = stability_margin(M, s)
    B = J @ f.N @ T
    X = np.linalg.solve(M, B.T) if M.size else B.T
    C = B @ X
    conservative = not np.any(w0[3:])
    if conservative:  # K_t and C symmetric up to rounding
        C = 0.5 * (C + C.T)
    d = twist_scaling(state.length)[:, None]
    kinematic = d * (J @ f.NV)  # rank and rigid directions, as without preload
    if conservative and margin > 0.0:  # M = L L^T: C = (B L^-T) (B L^-T)^T
        F = lapack.dtrtrs(np.linalg.cholesky(M), B.T, lower=1)[0].T if M.size else B
        spectrum = spectrum_from_factor(d * F, state.length, kinematic, spread=np.inf)
    else:
        spectrum = spectrum_of_matrix(C, state.length, kinematic)
    return compliance_result(
        state,
        frame,
        axes,
        C,
        f.N @ T @ X,
        f,
        spectrum,
        cls=PreloadedCompliance,
        preload=readonly(w0),
        stability_margin=margin,
        **about,
    )


def _spring_forces(clm: ClosedLoopModel, eq: Equilibrium) -> np.ndarray:
    """(nv,) the springs' forces at the equilibrium
    (:func:`closedloop.model.elastic.spring_law`)."""
    return spring_law(clm, deflection(clm, eq.q_rest, eq.q))[0]
