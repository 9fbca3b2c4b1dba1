"""Compliance and stiffness about an unloaded configuration: the method, the result type
and how it is made (the kernel: :mod:`closedloop.elastostatics.query`).

Method (the Jacobian method K = J^-T K_q J^-1 generalised to loops). Let N (nv, d) span
the tangent motions dq that keep every closure and locked joint (``J_c N = 0``), K_q the
joint stiffness (0 for passive joints; diagonal, or block diagonal with the coupled
springs of multi-dof joints, ``ClosedLoopModel.spring_blocks``) and J (6, nv) the frame
Jacobian. With dq = N y, the potential energy of the springs is 1/2 y^T (N^T K_q N) y
and a wrench w at the frame does the work w^T J N y, so at equilibrium

    K_r y = N^T J^T w,   K_r = N^T K_q N   (d, d)
    dq = G w,            G = N K_r^+ N^T J^T   (nv, 6)
    C = J G = (J N) K_r^+ (J N)^T   (6, 6)

Passive joints and redundant closure rows need no special case: they only shape N.
A null direction z of K_r is a motion without any restoring spring. If it moves the
frame (J N z != 0) there is no equilibrium (:class:`~closedloop.MechanismError`); if not, it is an
internal mobility (e.g. a link spinning about its own axis) and is left out.

Numerics (:mod:`closedloop.common.conditioning`). Everything is computed in unit-free
coordinates: lengths divided by the characteristic length L of the configuration, in
joint space (prismatic coordinates dq / L, their springs k L^2 [N m]) as in Cartesian
space. K_r is never formed: the SVD of its square-root factor S = R N (K_q = R^T R; R is
sqrt(k), or the transposed Cholesky factor of a block) gives K_r = V diag(sigma^2) V^T to
the precision of S. A motion is spring-free when the sprung rows of N see it less than
``RANK_RTOL`` times the motion they see most (the rule of the rank of C, on the
kinematics: the springs' values, however far apart, do not decide it).
C = B B^T with B = J N V diag(1/sigma), and K comes from the SVD of B, never from
inv(C), which would lose cond(C) = cond(J)^2 digits.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import OnFirstRead, ReadOnlyArrays, check_wrench, frozen, readonly
from closedloop.common.conditioning import (
    FINITE_BOUND,
    ILL_CONDITIONED,
    RANK_RTOL,
    Spectrum,
    stiffness_from_factor,
    twist_scaling,
)
from closedloop.elastostatics.springs import SpringFactor
from closedloop.exceptions import (
    InvalidInputError,
    RigidDirectionsError,
    SingularConfigurationError,
)
from closedloop.kinematics.configuration import Configuration
from closedloop.model.closed_loop import ClosedLoopModel

#: Labels of the twist / wrench coordinates, in order.
TWIST_LABELS = ("dx", "dy", "dz", "rx", "ry", "rz")
UNITS = {
    "twist": "dx, dy, dz [m]; rx, ry, rz [rad] (small rotation vector)",
    "wrench": "fx, fy, fz [N]; nx, ny, nz [N m]",
    "C": "m/N, m/(N m) = rad/N, rad/(N m)",
    "K": "N/m, N/rad, N m/m, N m/rad",
    "length": "m",
    "condition_number": "1 (scaled stiffness K_s, twists (d/L, r), wrenches (f L, n))",
}


@dataclass(frozen=True)
class ComplianceResult(ReadOnlyArrays):
    """Compliance of a mechanism at one frame and configuration (arrays read-only).

    A result of the serial or partitioned path computes its ``stiffness_matrix`` (and, on
    the serial path with one spring a coordinate, ``G``) on their first read, from the
    factors its query kept, by the arithmetic the query would have used: the same values
    to the last bit, read-only, computed once (a read in any thread then returns the same
    array; :class:`closedloop.common.arrays.OnFirstRead`), kept by a pickled copy.

    Attributes:
        C: (6, 6) compliance [SI], twist (dx, dy, dz, rx, ry, rz) per wrench
            (fx, fy, fz, nx, ny, nz), both at ``point``, in ``axes``.
        frame: name of the loaded frame.
        axes: ``"world"`` (world-aligned) or ``"local"`` (the frame's own axes).
        point: (3,) reference point [m], world frame: the frame origin.
        q: (nq,) configuration.
        rank: rank of C (unit-free rule of :mod:`closedloop.common.conditioning`).
        rigid_directions: (6, 6 - rank) orthonormal basis of the twists that no wrench
            produces (empty when C is full rank).
        closure_residual: infinity norm of the loop-closure residual at q [m, rad].
        mobility: dimension d of the admissible motions (closures and locks kept).
        internal_mobilities: spring-free motions that do not move the frame.
        G: (nv, 6) map from wrench to joint deflection dq (tangent of q) [rad or m per N, N m].
        length: characteristic length L [m] of the unit-free scaling.
        condition_number: cond(K_s) of the scaled stiffness over the rank of C,
            dimensionless; above ``ILL_CONDITIONED`` (1e8) the result is ill-conditioned.
        stiffness_matrix: (6, 6) K [SI] from the square-root factor when rank is 6, else
            None; read it as :attr:`K`, which explains a missing K.
        path: how the admissible motions were found (:class:`SpringFactor`):
            ``"serial"``, ``"partitioned"`` or ``"null-space"``.
        note: why C = 0 when no wrench moves the frame (:func:`spring_note`), else "".
    """

    C: np.ndarray
    frame: str
    axes: str
    point: np.ndarray
    q: np.ndarray
    rank: int
    rigid_directions: np.ndarray
    closure_residual: float
    mobility: int
    internal_mobilities: int
    G: np.ndarray = field(repr=False)
    length: float = field(kw_only=True)
    condition_number: float = field(kw_only=True)
    stiffness_matrix: np.ndarray | None = field(kw_only=True, repr=False)
    path: str = field(kw_only=True, default="null-space")
    note: str = field(kw_only=True, default="", repr=False)

    @property
    def is_full_rank(self) -> bool:
        """True when C is invertible (the stiffness exists)."""
        return self.rank == 6

    @property
    def ill_conditioned(self) -> bool:
        """True when cond(K_s) exceeds ``ILL_CONDITIONED``: near a singular configuration,
        the stiffest direction of K is known to about 1e-16 sqrt(cond) relative."""
        return self.condition_number > ILL_CONDITIONED

    @property
    def K(self) -> np.ndarray:
        """(6, 6) stiffness C^-1 [SI], same point and axes as C.

        Raises:
            RigidDirectionsError: C is rank deficient; the error lists the rigid directions.
        """
        if not self.is_full_rank or self.stiffness_matrix is None:
            raise RigidDirectionsError(
                f"compliance at frame {self.frame!r} has rank {self.rank} < 6: the stiffness "
                f"is infinite along {describe_directions(self.rigid_directions)}"
                + (f"; {self.note}" if self.note else ""),
                self.rigid_directions,
            )
        return self.stiffness_matrix

    def deflection(self, wrench: np.ndarray) -> np.ndarray:
        """(6,) twist (dx, dy, dz [m], rx, ry, rz [rad]) of the frame under ``wrench`` (6,)."""
        w = check_wrench(wrench)
        return finite_product(lambda: self.C @ w, "deflection", wrench)

    def joint_deflection(self, wrench: np.ndarray) -> np.ndarray:
        """(nv,) joint deflection dq (tangent of q) [rad or m] under ``wrench`` (6,)."""
        w = check_wrench(wrench)
        return finite_product(lambda: self.G @ w, "joint deflection", wrench)

    def to_dict(self) -> dict:
        """JSON-ready summary: K (or None), C, frame, axes, point, rank, conditioning, units."""
        return {
            "K": self.K.tolist() if self.is_full_rank else None,
            "C": self.C.tolist(),
            "frame": self.frame,
            "axes": self.axes,
            "point": self.point.tolist(),
            "order": list(TWIST_LABELS),
            "rank": self.rank,
            "rigid_directions": self.rigid_directions.T.tolist(),
            "condition_number": self.condition_number,
            "ill_conditioned": self.ill_conditioned,
            "length": self.length,
            "closure_residual": self.closure_residual,
            "mobility": self.mobility,
            "internal_mobilities": self.internal_mobilities,
            "path": self.path,
            "note": self.note,
            "units": UNITS,
        }


# computed on first read by the results of the fast paths (fast_result)
ComplianceResult.G = OnFirstRead("G")
ComplianceResult.stiffness_matrix = OnFirstRead("stiffness_matrix")


def result_fields(result: ComplianceResult) -> dict:
    """Field name -> value of every field of a :class:`ComplianceResult` (those computed
    on first read included), as its constructor takes them."""
    return {f.name: getattr(result, f.name) for f in dataclasses.fields(ComplianceResult)}


def finite_product(product, what: str, wrench) -> np.ndarray:
    """``product()`` (a map applied to the wrench), read-only, or :class:`InvalidInputError`
    if it overflows (the message names ``what`` and the wrench)."""
    with np.errstate(over="ignore", invalid="ignore"):
        x = product()
    if not np.isfinite(x).all():
        raise InvalidInputError(
            f"the {what} under wrench {np.asarray(wrench).tolist()} overflows the floating "
            "point range; give a smaller load"
        )
    return readonly(x)


def describe_directions(V: np.ndarray) -> str:
    """Readable list of twist directions, e.g. ``[+0.71 dx +0.71 rz]``."""
    parts = []
    for v in np.asarray(V).T:
        v = v * np.sign(v[np.argmax(np.abs(v))])
        terms = [f"{c:+.2f} {lab}" for c, lab in zip(v, TWIST_LABELS, strict=True) if abs(c) > 5e-3]
        parts.append("[" + " ".join(terms) + "]")
    return ", ".join(parts)


def compliance_result(
    state: Configuration,
    frame: str,
    axes: str,
    C: np.ndarray,
    G: np.ndarray,
    f: SpringFactor,
    spectrum: Spectrum,
    cls: type[ComplianceResult] | None = None,
    **extra,
) -> ComplianceResult:
    """A checked :class:`ComplianceResult` (or subclass, with ``extra`` fields) of the
    general path's factor ``f`` (:func:`closedloop.elastostatics.springs.spring_factor`).

    Raises:
        SingularConfigurationError: C, G or K are not finite (overflow).
    """
    _require_finite(state.model, frame, C, G, spectrum.K)
    fid, mobility, internal = state.model.frame_id(frame), f.N.shape[1], f.n_internal
    return _result(
        state, frame, axes, C, G, spectrum, fid, mobility, internal, "null-space", cls, **extra
    )


class FastFields:
    """What the results of a fast path take from the plan of a frame, axes and length:
    the fields that do not depend on q (frame, axes, length, path, mobility: every
    admissible motion has a spring, no internal one), the frame's index ``fid``, the
    scales (d, outer(d, d)) at the length L and max(1, L), max(1, 1/L) of
    :func:`fast_result`'s bounds."""

    __slots__ = ("b_scale", "fid", "fields", "frame", "k_scale", "scales")

    def __init__(self, frame, axes, length, path, mobility, fid, scales):
        self.fields = {"frame": frame, "axes": axes, "length": length, "path": path,
                       "mobility": mobility, "internal_mobilities": 0, "note": ""}  # fmt: skip
        self.frame, self.fid, self.scales = frame, fid, scales
        self.b_scale, self.k_scale = max(1.0, length), max(1.0, 1.0 / length)


def fast_result(
    plan: FastFields,
    model: ClosedLoopModel,
    data: pin.Data,
    q: np.ndarray,
    residual: float,
    C: np.ndarray,
    G: np.ndarray | tuple,
    g_scale: float | None,
    spectrum: tuple,
) -> ComplianceResult:
    """A checked :class:`ComplianceResult` of a fast path (``"serial"`` or
    ``"partitioned"``: the plan's), with C = B B^T, at q (nq,) checked, whose kinematics
    are in ``data`` and the infinity norm of whose closure residual is ``residual``.

    ``spectrum``: the rank, rigid directions, condition number, U, beta, top and bottom of
    :func:`closedloop.common.conditioning.factor_rank` on the scaled factor B_s = D B.
    ``g_scale`` bounds ``|G_kj|`` / ``|B_jk|``, G being then a tuple (function,
    arguments...) whose call computes G; None: G is given.

    C, G and K are finite when bounds of their entries are: ``top`` and ``bottom``, the
    largest and smallest kept singular values of B_s, bound ``|B_jk|`` <= max(1, L) top,
    ``|C_ij|`` <= ``|B|^2`` and ``|K_ij|`` <= (max(1, 1/L) / bottom)^2; G's entries are
    bounded by ``g_scale`` or summed. Rounding adds less than a factor 1 + 1e-12 to any of
    these; beyond :data:`FINITE_BOUND`, or NaN, every entry is computed and looked at.
    Within it, K (from U and beta,
    :func:`closedloop.common.conditioning.stiffness_from_factor`) and a G given as a call
    are computed on their first read, by the same arithmetic
    (:class:`closedloop.common.arrays.OnFirstRead`).

    Raises:
        SingularConfigurationError: C, G or K are not finite (overflow).
    """
    rank, rigid, cond, U, beta, top, bottom = spectrum
    b = plan.b_scale * top
    k = plan.k_scale / bottom
    C.setflags(False)  # write=False (positional: half the cost)
    values = plan.fields.copy()
    if (  # a NaN fails each test
        b * b < FINITE_BOUND
        and (rank < 6 or k * k < FINITE_BOUND)
        and (g_scale * b < FINITE_BOUND if g_scale is not None else _finite(G))
    ):
        later = {}
        if g_scale is None:
            G.setflags(False)
            values["G"] = G
        else:
            later["G"] = G
        if rank == 6:
            later["stiffness_matrix"] = (stiffness_from_factor, U, beta, *plan.scales)
        else:
            values["stiffness_matrix"] = None
        values["_on_first_read"] = later
    else:  # every entry computed (an overflow without numpy's warnings) and looked at
        with np.errstate(over="ignore", invalid="ignore"):
            G = G[0](*G[1:]) if g_scale is not None else frozen(G)
            K = stiffness_from_factor(U, beta, *plan.scales) if rank == 6 else None
        _require_finite(model, plan.frame, C, G, K)
        values["G"], values["stiffness_matrix"] = G, K
    values["C"] = C
    values["point"] = _point(model, data, plan.fid)
    values["q"] = q
    values["rank"] = rank
    values["rigid_directions"] = rigid
    values["closure_residual"] = residual
    values["condition_number"] = cond
    if rank == 0:
        values["note"] = spring_note(model)
    result = object.__new__(ComplianceResult)
    object.__setattr__(result, "__dict__", values)
    return result


def _point(model: ClosedLoopModel, data: pin.Data, fid: int) -> np.ndarray:
    """(3,) read-only position [m] of frame ``fid`` in the world, from the joint placements
    in ``data`` (computed again: faster than reading it through data.oMf)."""
    point = pin.updateFramePlacement(model.model, data, fid).translation.copy()
    point.setflags(False)
    return point


def _finite(a: np.ndarray) -> bool:
    """No NaN nor inf in ``a`` (its sum is finite, or, when that overflows, each entry;
    called where numpy's overflow warnings are off)."""
    return math.isfinite(np.add.reduce(a, None)) or bool(np.isfinite(a).all())


@np.errstate(over="ignore", invalid="ignore")
def _require_finite(model: ClosedLoopModel, frame: str, C, G, K) -> None:
    """:class:`SingularConfigurationError` unless C, G and K (or None) are finite."""
    if _finite(C) and _finite(G) and (K is None or _finite(K)):
        return
    k = model.stiffness
    k = k[(k > 0) & np.isfinite(k)]
    springs = f"springs from {k.min():.3g} to {k.max():.3g} [SI]" if k.size else "no spring"
    raise SingularConfigurationError(
        f"the compliance or stiffness at frame {frame!r} of {model.name!r} overflows "
        f"the floating point range ({springs}; expected springs well within 1e-300..1e300, "
        "away from a singular configuration)"
    )


def _result(
    state: Configuration,
    frame: str,
    axes: str,
    C: np.ndarray,
    G: np.ndarray,
    spectrum: Spectrum,
    fid: int,
    mobility: int,
    n_internal: int,
    path: str,
    cls: type[ComplianceResult] | None = None,
    **extra,
) -> ComplianceResult:
    """:func:`compliance_result` from the numbers of the spring factor (``fid``: the
    frame's index), C, G and K checked finite."""
    C.setflags(write=False)
    G.setflags(write=False)
    fields = {
        "C": C,
        "frame": frame,
        "axes": axes,
        "point": _point(state.model, state.data, fid),
        "q": state.q,
        "rank": spectrum.rank,
        "rigid_directions": spectrum.rigid_directions,
        "closure_residual": state.residual_norm,
        "mobility": mobility,
        "internal_mobilities": n_internal,
        "G": G,
        "length": spectrum.length,
        "condition_number": spectrum.condition_number,
        "stiffness_matrix": spectrum.K,
        "path": path,
        "note": spring_note(state.model) if spectrum.rank == 0 else "",
    }
    if cls is None:  # every field given, checked: set without the dataclass __init__
        result = object.__new__(ComplianceResult)
        result.__dict__.update(fields)
        return result
    return cls(**fields, **extra)


#: How to give springs, in every API and command-line message that finds none.
HOW_TO_GIVE_SPRINGS = (
    "give springs: command line --joint-stiffness K (every actuated joint) or --springs FILE "
    "(joint -> stiffness), Python load_model(..., joint_stiffness=K) or springs={...}"
)


def spring_note(clm: ClosedLoopModel) -> str:
    """Why no wrench moves a frame (C = 0) of ``clm``: the model has no spring at all (no
    joint, beam or closure: every actuated joint without one is rigid), or none of its
    springs moves the frame; with :data:`HOW_TO_GIVE_SPRINGS` in the first case."""
    k = clm.stiffness
    if not np.any((k > 0) & np.isfinite(k)):
        return (
            "no joint, beam or closure of the model has a spring (an actuated joint without "
            "one is rigid), so nothing deflects; " + HOW_TO_GIVE_SPRINGS
        )
    return "none of the model's springs moves this frame (the frame is not beyond them)"


def energy_shares(clm: ClosedLoopModel, result: ComplianceResult, wrench) -> dict[str, float]:
    """Share of the deflection energy under ``wrench`` stored in each spring and each beam:
    "which element limits the stiffness at this frame for this load?".

    The joint deflection dq = G w stores 1/2 dq_j^T K_j dq_j in the spring of joint j (a
    number per coordinate or a block; a beam's is its virtual joint ``<link>_beam``,
    :mod:`closedloop.model.beams`); at equilibrium the energies sum to the work 1/2 w^T C w, so
    the shares sum to 1. For the unloaded compliance only: a preloaded one adds the
    preload's own energy terms, which are not split (InvalidInputError).

    Args:
        clm: the model of ``result``.
        result: a compliance of ``clm`` (:func:`closedloop.elastostatics.compliance.compliance`).
        wrench: (6,) (f [N], n [N m]) at the result's point, in its axes.

    Returns:
        joint name -> share (dimensionless, >= 0), every joint with a finite spring, in
        the model's order; empty when the wrench does no work: a zero wrench, or one along
        the rigid directions, whose work w^T C w is rounding (in the scaled coordinates of
        the rank rule, at most ``RANK_RTOL**2 * norm(C_s) * norm(w_s)**2``, Frobenius norm:
        about the most that a wrench along a direction the rank leaves out could do).
    """
    if hasattr(result, "equilibrium"):  # a PreloadedCompliance
        raise InvalidInputError(
            "energy_shares splits the energy of an unloaded compliance; this one is under a "
            "preload, whose own energy terms are not split (compute the shares without it)"
        )
    w = check_wrench(wrench)
    size = float(np.max(np.abs(w)))
    if size == 0.0:
        return {}
    w = w / size  # the shares do not depend on the size of the load: no overflow
    total = float(w @ result.C @ w)
    d = twist_scaling(result.length)  # scaled twists D t, scaled wrenches D^-1 w
    with np.errstate(over="ignore", invalid="ignore"):
        C_s, w_s = result.C * d[:, None] * d, w / d
        rounding = RANK_RTOL**2 * np.linalg.norm(C_s) * float(w_s @ w_s)  # |C_s|_F >= |C_s|_2
    if total <= (rounding if math.isfinite(rounding) else 0.0):  # C_s may overflow: then w^T C w
        return {}
    dq = result.G @ w
    f = clm.spring_forces(dq)
    out = {}
    k = clm.stiffness
    for j in range(1, clm.model.njoints):
        jm = clm.model.joints[j]
        v = slice(jm.idx_v, jm.idx_v + jm.nv)
        if jm.nv and np.any((k[v] > 0) & np.isfinite(k[v])):
            out[clm.model.names[j]] = float(dq[v] @ f[v])
    return {n: e / total for n, e in out.items()}
