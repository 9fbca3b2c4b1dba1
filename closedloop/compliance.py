"""Cartesian compliance and stiffness of a closed-loop mechanism with joint springs.

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
frame (J N z != 0) there is no equilibrium (:class:`MechanismError`); if not, it is an
internal mobility (e.g. a link spinning about its own axis) and is left out.

Numerics (:mod:`closedloop.conditioning`). Everything is computed in unit-free
coordinates: lengths divided by the characteristic length L of the configuration, in
joint space (prismatic coordinates dq / L, their springs k L^2 [N m]) as in Cartesian
space. K_r is never formed: the SVD of its square-root factor S = R N (K_q = R^T R; R is
sqrt(k), or the transposed Cholesky factor of a block) gives K_r = V diag(sigma^2) V^T to
the precision of S, and a motion is spring-free when its sigma is below ``RANK_RTOL``
times the largest (the same rule as the rank of C, on the same square-root scale).
C = B B^T with B = J N V diag(1/sigma), and K comes from the SVD of B, never from
inv(C), which would lose cond(C) = cond(J)^2 digits.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import scipy.linalg

from .arrays import check_wrench, frozen, readonly
from .conditioning import (
    ILL_CONDITIONED,
    RANK_RTOL,
    Spectrum,
    spectrum_from_factor,
    split_factor,
    twist_scaling,
)
from .configuration import Configuration, as_configuration
from .exceptions import (
    InvalidInputError,
    MechanismError,
    RigidDirectionsError,
    SingularConfigurationError,
)
from .kinematics import nullspace, rigid_rows
from .model import ClosedLoopModel

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
class ComplianceResult:
    """Compliance of a mechanism at one frame and configuration (arrays read-only).

    Attributes:
        C: (6, 6) compliance [SI], twist (dx, dy, dz, rx, ry, rz) per wrench
            (fx, fy, fz, nx, ny, nz), both at ``point``, in ``axes``.
        frame: name of the loaded frame.
        axes: ``"world"`` (world-aligned) or ``"local"`` (the frame's own axes).
        point: (3,) reference point [m], world frame: the frame origin.
        q: (nq,) configuration.
        rank: rank of C (unit-free rule of :mod:`closedloop.conditioning`).
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
                f"is infinite along {describe_directions(self.rigid_directions)}",
                self.rigid_directions,
            )
        return self.stiffness_matrix

    def deflection(self, wrench: np.ndarray) -> np.ndarray:
        """(6,) twist (dx, dy, dz [m], rx, ry, rz [rad]) of the frame under ``wrench`` (6,)."""
        w = check_wrench(wrench)
        return _finite(lambda: self.C @ w, "deflection", wrench)

    def joint_deflection(self, wrench: np.ndarray) -> np.ndarray:
        """(nv,) joint deflection dq (tangent of q) [rad or m] under ``wrench`` (6,)."""
        w = check_wrench(wrench)
        return _finite(lambda: self.G @ w, "joint deflection", wrench)

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
            "units": UNITS,
        }


def _finite(product, what: str, wrench) -> np.ndarray:
    """``product()`` (a map applied to the wrench), or a typed error if it overflows."""
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


class SpringFactor(NamedTuple):
    """Admissible motions and the square-root factor of their spring stiffness.

    Attributes:
        N: (nv, d) basis of the admissible motions dq = N y (closures and locks kept),
            orthonormal in the scaled joint coordinates (prismatic ones divided by L).
        V: (d, s) orthonormal directions of y with a restoring spring.
        sigma: (s,) their singular values: K_r = N^T K_q N = V diag(sigma^2) V^T on them
            [sqrt(N m)].
        n_internal: number of spring-free motions that do not move the frame (left out).
        path: how N was found: ``"serial"`` (no closure, no passive joint: N selects the
            spring coordinates), ``"partitioned"`` (the passive joints follow the springs
            through the closures, dq_p = X dq_s) or ``"null-space"`` (the general path).
    """

    N: np.ndarray
    V: np.ndarray
    sigma: np.ndarray
    n_internal: int
    path: str = "null-space"
    identity_V: bool = False  # V is the identity (the fast paths without block springs)

    @property
    def NV(self) -> np.ndarray:
        """(nv, s) N V: the sprung admissible motions."""
        return self.N if self.identity_V else self.N @ self.V

    @property
    def P(self) -> np.ndarray:
        """(nv, s) N V diag(1/sigma): dq = P P^T J^T w, C = (J P) (J P)^T."""
        return self.NV / self.sigma


class _Scaling(NamedTuple):
    """Unit-free scaling of a model at length L (computed once per model and L)."""

    s_q: np.ndarray  # (nv,) dq = s_q * scaled dq: L for linear coordinates, 1 for angles
    row_scale: np.ndarray  # (m, 1) closure rows in metres divided by L
    locked_rows: np.ndarray  # (n_locked, nv) selection rows of the locked coordinates
    sprung: np.ndarray  # (s,) indices of the coordinates with a finite spring
    sqrt_k: np.ndarray  # (s,) sqrt of their scaled stiffness k s_q^2 [sqrt(N m)]
    passive: np.ndarray  # (p,) indices of the coordinates without spring (k = 0)
    # With spring blocks (else None): the scaled square root R_s (s, s) of the sprung
    # stiffness, diag(s_q) K_ss diag(s_q) = R_s^T R_s, and its SVD R_s = U diag(sigma) V^T,
    # which is the spring factor of the fast paths on y = dq_s: K_r = V diag(sigma^2) V^T.
    root: np.ndarray | None = None
    root_V: np.ndarray | None = None
    root_sigma: np.ndarray | None = None

    @classmethod
    def of(cls, clm: ClosedLoopModel, L: float) -> _Scaling:
        s_q = np.where(clm.linear_coordinates, L, 1.0)
        k = clm.stiffness
        sprung = np.flatnonzero((k > 0.0) & np.isfinite(k))
        root = root_V = root_sigma = None
        if clm.spring_blocks:
            root = clm.spring_root[np.ix_(sprung, sprung)] * s_q[sprung]
            _, root_sigma, Vt = np.linalg.svd(root)
            root_V = Vt.T
        return cls(
            s_q,
            np.where(clm.linear_rows, 1.0 / L, 1.0)[:, None],
            rigid_rows(clm),
            sprung,
            np.sqrt(k[sprung]) * s_q[sprung],
            np.flatnonzero(k == 0.0),
            root,
            root_V,
            root_sigma,
        )

    @property
    def fast_factor(self) -> tuple[np.ndarray | None, np.ndarray]:
        """(V (s, s) or None for the identity, sigma (s,)): the spring factor on y = dq_s."""
        return (None, self.sqrt_k) if self.root is None else (self.root_V, self.root_sigma)


#: The partitioned path is taken when the passive part of the scaled closure Jacobian is
#: well conditioned (reciprocal condition estimate above this): then both paths give C
#: to rounding (1e-12 and better on every test mechanism). Below it the null-space path
#: decides, with the rank rule.
PARTITION_RCOND = 1e-6
#: Largest residual |J_s + J_p X| of the partitioned closure equations, relative to |J_s|,
#: for the springs to move freely (else some spring coordinates are tied by the loops).
PARTITION_RTOL = 1e-9


def _partitioned_factor(state: Configuration, sc: _Scaling) -> SpringFactor | None:
    """Spring factor without a null space, when the springs determine everything.

    With the closure rows J_c dq = J_s dq_s + J_p dq_p = 0 (scaled, locked coordinates
    still), a passive part J_p of full column rank fixes dq_p = X dq_s, X = -J_p^+ J_s,
    for every spring motion dq_s when J_s + J_p X = 0; the admissible motions are then
    N = [I; X] in the spring coordinates, where K_r = diag(k s_q^2) is already diagonal
    (with spring blocks: K_r = R_s^T R_s, whose SVD is computed once per model).
    Returns None when this does not apply (the null-space path then decides).
    """
    nv, s, p = state.model.model.nv, sc.sprung, sc.passive
    T = np.zeros((nv, s.size))
    T[s, np.arange(s.size)] = 1.0
    Jc = state.closure_jacobian()
    if p.size:
        if Jc.shape[0] < p.size:
            return None
        Jc = Jc * sc.row_scale
        J_s = Jc[:, s] * sc.s_q[s]
        # least squares min |J_p X + J_s| by QR (LAPACK dgels): R in qr[:p, :p], the
        # residual's components in x[p:]
        qr, x, info = scipy.linalg.lapack.dgels(Jc[:, p] * sc.s_q[p], -J_s)
        if info != 0 or scipy.linalg.lapack.dtrcon(qr[: p.size, : p.size])[0] <= PARTITION_RCOND:
            return None
        scale = np.max(np.abs(J_s), initial=0.0)
        if np.max(np.abs(x[p.size :]), initial=0.0) > PARTITION_RTOL * scale:
            return None
        T[p] = x[: p.size]
    elif Jc.shape[0]:
        return None  # loops without passive joints tie the springs together
    # the same spring-free rule as the null-space path, which would find singular values
    # of the spring factor between min(sigma) / |T| and max(sigma)
    V, sigma = sc.fast_factor
    if sigma.size and sigma.min() <= RANK_RTOL * sigma.max() * np.linalg.norm(T):
        return None
    path = "partitioned" if Jc.shape[0] else "serial"
    if V is None:  # diagonal springs: y = dq_s already diagonalises K_r
        return SpringFactor(T * sc.s_q[:, None], np.eye(s.size), sigma, 0, path, True)
    return SpringFactor(T * sc.s_q[:, None], V, sigma, 0, path)


#: Values of the ``path`` argument of :func:`compliance`.
PATHS = ("auto", "null-space")


def spring_factor(
    state: Configuration, J: np.ndarray, frame: str, path: str = "auto"
) -> SpringFactor:
    """Admissible motions and spring factor at a configuration (module docstring).

    Args:
        state: the configuration.
        J: (6, nv) Jacobian of the loaded frame (any reference axes) [m/rad, 1].
        frame: name of the loaded frame (for messages).
        path: ``"auto"`` (the serial or partitioned path where it applies, else the null
            space) or ``"null-space"`` (always the general path).

    Raises:
        MechanismError: a spring-free motion moves the frame (no static equilibrium):
            a joint without spring, or a singular configuration where the springs resist
            a motion RANK_RTOL^2 = 1e-14 times less than the stiffest one.
    """
    clm, L = state.model, state.length
    sc = clm.memo(("scaling", L), lambda: _Scaling.of(clm, L))
    if path not in PATHS:
        raise InvalidInputError(f"path {path!r}; expected one of {list(PATHS)}")
    fast = _partitioned_factor(state, sc) if path == "auto" else None
    if fast is not None:
        return fast
    Jc = state.closure_jacobian() * sc.row_scale
    A = np.vstack([Jc, sc.locked_rows]) if len(sc.locked_rows) else Jc
    N_s, _ = nullspace(A * sc.s_q)
    if sc.root is None:
        S = sc.sqrt_k[:, None] * N_s[sc.sprung]
    else:  # spring blocks: S^T S = N_s^T diag(s_q) K_q diag(s_q) N_s
        S = sc.root @ N_s[sc.sprung]
    sigma, V, Z, _ = split_factor(S)
    N = N_s * sc.s_q[:, None]
    if Z.shape[1]:  # spring-free motions must not move the frame
        JN_s = (J * twist_scaling(L)[:, None]) @ N
        moves = np.linalg.norm(JN_s @ Z, axis=0) > RANK_RTOL * max(np.linalg.norm(JN_s), 1e-300)
        if np.any(moves):
            raise MechanismError(
                f"{clm.name!r} is still a mechanism at frame {frame!r}: {int(moves.sum())} "
                "motion(s) with no restoring spring (or one below 1e-14 of the stiffest, a "
                f"singular configuration) move it, driven mostly by "
                f"{_main_joints(clm, N @ Z[:, moves])}; add springs, lock joints or move away "
                "from the singularity"
            )
    return SpringFactor(N, V, sigma, Z.shape[1])


def compliance(
    model: ClosedLoopModel | Configuration,
    q: np.ndarray | str | None = None,
    frame: str | None = None,
    axes: str = "world",
    *,
    length: float | None = None,
    path: str = "auto",
    gravity=None,
    payloads=(),
    preload=None,
) -> ComplianceResult:
    """Cartesian compliance of ``frame`` at a configuration (see the module docstring).

    Call as ``compliance(state, frame)`` with a :class:`Configuration`, or as
    ``compliance(model, q, frame)``.

    Args:
        model: a configuration, or a model with closures and springs.
        q: (nq,) assembled configuration with a model (:func:`closedloop.assemble`); with a
            configuration, the frame may be given here.
        frame: name of the loaded frame; the reference point is its origin.
        axes: ``"world"`` (world-aligned axes, default) or ``"local"``.
        length: characteristic length [m] of the unit-free rules, with a model (default:
            that of the configuration, the size of its joint origins).
        path: ``"auto"`` (default: the serial or partitioned fast path where it applies)
            or ``"null-space"`` (the general path, e.g. to cross-check); the path taken is
            in the result.
        gravity: (3,) acceleration [m/s^2], world axes, weighing the model's link inertias
            (and ``payloads``, :class:`closedloop.gravity.Payload`); with it, or with
            ``preload`` (6,) (a dead-load wrench at the frame origin [N, N m], world
            axes), q is the springs' rest configuration, the mechanism settles under the
            preload (:func:`closedloop.statics.solve_equilibrium`) and the result is the
            tangent compliance there (:class:`closedloop.preload.PreloadedCompliance`,
            with the sag of the frame, q_eq and the spring forces).

    Raises:
        NameNotFoundError: unknown frame.
        OpenLoopError: q does not close the loops (tolerance ``CLOSURE_TOL``).
        MechanismError: a spring-free motion moves the frame (no static equilibrium).
        SingularConfigurationError: the compliance overflows (springs near 1e-308).
    """
    if isinstance(model, Configuration) and isinstance(q, str):  # compliance(state, frame, ...)
        q, frame, axes = None, q, axes if frame is None else frame
    if frame is None:
        raise TypeError("compliance() needs the name of the loaded frame")
    state = as_configuration(model, q, length=length)
    state.require_closed()
    if gravity is not None or payloads or preload is not None:
        # the preloaded compliance builds on this module: imported here, on demand
        from .preload import preloaded_compliance
        from .statics import solve_equilibrium

        w0 = np.zeros(6) if preload is None else preload
        eq = solve_equilibrium(state, frame, w0, gravity=gravity, payloads=payloads)
        return preloaded_compliance(state.model, eq, axes)
    J = state.frame_jacobian(frame, axes)
    f = spring_factor(state, J, frame, path)
    NV = f.NV
    JNV = (J @ NV) * twist_scaling(state.length)[:, None]  # scaled, kinematic
    B_s = JNV / f.sigma  # C_s = B_s B_s^T
    spread = f.sigma.max() / f.sigma.min() if f.sigma.size else 1.0
    spectrum = spectrum_from_factor(B_s, state.length, range_factor=JNV, spread=spread)
    P = NV / f.sigma
    B = J @ P  # C = B B^T
    C = B @ B.T
    return compliance_result(state, frame, axes, 0.5 * (C + C.T), P @ B.T, f, spectrum)


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
    """A checked :class:`ComplianceResult` (or subclass, with ``extra`` fields).

    Raises:
        SingularConfigurationError: C, G or K are not finite (overflow).
    """
    total = C.sum() + G.sum() + (0.0 if spectrum.K is None else spectrum.K.sum())
    if not np.isfinite(total):  # a NaN or inf anywhere (or entries near 1e308)
        raise SingularConfigurationError(
            f"the compliance at frame {frame!r} of {state.model.name!r} overflows the "
            "floating point range (springs near 1e-308, or a singular configuration)"
        )
    return (cls or ComplianceResult)(
        C=frozen(C),
        frame=frame,
        axes=axes,
        point=readonly(state.data.oMf[state.model.frame_id(frame)].translation),
        q=state.q,
        rank=spectrum.rank,
        rigid_directions=spectrum.rigid_directions,
        closure_residual=float(np.max(np.abs(state.residual), initial=0.0)),
        mobility=f.N.shape[1],
        internal_mobilities=f.n_internal,
        G=frozen(G),
        length=spectrum.length,
        condition_number=spectrum.condition_number,
        stiffness_matrix=spectrum.K,
        path=f.path,
        **extra,
    )


def energy_shares(clm: ClosedLoopModel, result: ComplianceResult, wrench) -> dict[str, float]:
    """Share of the deflection energy under ``wrench`` stored in each spring and each beam:
    "which element limits the stiffness at this frame for this load?".

    The joint deflection dq = G w stores 1/2 dq_j^T K_j dq_j in the spring of joint j (a
    number per coordinate or a block; a beam's is its virtual joint ``<link>_beam``,
    :mod:`closedloop.beams`); at equilibrium the energies sum to the work 1/2 w^T C w, so
    the shares sum to 1. For the unloaded compliance (a preloaded one adds the preload's
    own energy terms, which are not split).

    Args:
        clm: the model of ``result``.
        result: a compliance of ``clm`` (:func:`compliance`).
        wrench: (6,) (f [N], n [N m]) at the result's point, in its axes.

    Returns:
        joint name -> share (dimensionless, >= 0), every joint with a finite spring, in
        the model's order; empty when the wrench does no work (w^T C w = 0).
    """
    w = check_wrench(wrench)
    dq = result.G @ w
    f = clm.spring_forces(dq)
    total = float(w @ result.C @ w)
    out = {}
    k = clm.stiffness
    for j in range(1, clm.model.njoints):
        jm = clm.model.joints[j]
        v = slice(jm.idx_v, jm.idx_v + jm.nv)
        if jm.nv and np.any((k[v] > 0) & np.isfinite(k[v])):
            out[clm.model.names[j]] = float(dq[v] @ f[v])
    if total <= 0.0:
        return {}
    return {n: e / total for n, e in out.items()}


def spring_subspace(
    clm: ClosedLoopModel, q: np.ndarray, J: np.ndarray, frame: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Admissible motions and the eigen-decomposition of their spring stiffness K_r.

    The form of :func:`spring_factor` for a model and q (first release).

    Returns:
        N: (nv, d) basis of the admissible motions (closures and locks kept).
        V: (d, s) orthonormal eigenvectors of K_r = N^T K_q N with a restoring spring.
        lam: (s,) their eigenvalues sigma^2 (> 0).
        n_internal: number of spring-free motions that do not move the frame (left out).

    Raises:
        MechanismError: a spring-free motion moves the frame (no static equilibrium).
    """
    f = spring_factor(Configuration(clm, q), J, frame)
    return f.N, f.V, f.sigma**2, f.n_internal


def _main_joints(clm: ClosedLoopModel, dq: np.ndarray) -> str:
    weight = np.linalg.norm(np.atleast_2d(dq.T).T, axis=1)
    names = []
    for j in range(1, clm.model.njoints):
        jm = clm.model.joints[j]
        names.append((float(np.max(weight[jm.idx_v : jm.idx_v + jm.nv])), clm.model.names[j]))
    top = sorted(names, reverse=True)[:3]
    return ", ".join(repr(n) for w, n in top if w > 1e-6)
