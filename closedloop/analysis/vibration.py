"""Natural frequencies and mode shapes of a compliant mechanism at a configuration.

Small oscillations about a configuration q. On the admissible motions dq = N y (closures
and locked joints kept, N (nv, d) orthonormal in the scaled coordinates, as for the
compliance: :mod:`closedloop.elastostatics.springs`) the kinetic energy is 1/2 y'^T M_r y' and the
potential energy 1/2 y^T K_r y with

    M_r = N^T M(q) N,   K_r = N^T K N   (d, d),

M(q) (nv, nv) the joint-space mass matrix of the tree's inertias (Pinocchio's composite
rigid body algorithm, :func:`pinocchio.crba`), payloads as point masses on their frames'
joints, plus the beams' own mass, and K the stiffness of every spring, beam and elastic
closure (K_q), or with ``gravity`` the tangent stiffness at the equilibrium under the
weight (springs, gravity's dG/dq and the closures' curvature,
:func:`closedloop.elastostatics.tangent.tangent_stiffness`). The modes solve the generalised
symmetric eigenproblem K_r y = omega^2 M_r y.

Beams' own mass (a ``density:`` key [kg/m^3] in a beam's entry, or the model-wide
``density`` of :func:`modes`; on top of the link's own inertia, which stays at the beam's
start). A beam is a rigid link with a 6-dof virtual joint at its tip
(:mod:`closedloop.model.beams`): its distributed mass is the consistent mass matrix of the
Euler-Bernoulli frame element on its two ends' twists, M_e (12, 12) in the beam axes
(axial rho A L / 6 [[2, 1], [1, 2]], torsion rho Ip L / 6 [[2, 1], [1, 2]], bending the
Hermite cubics' rho A L / 420 [[156, 22 L, 54, -13 L], ...]), the start's twist that of
the link frame and the tip's that of the virtual joint, both by their Jacobians J_e (12,
nv) at q: M += J_e^T M_e J_e. The cubics hold every rigid motion exactly (the beam's mass,
centre and second moment as a slender rod) and with one element a clamped beam's first
bending frequency comes out 0.48 % high (3.533 instead of 1.8751^2 = 3.516 times
sqrt(EI / (rho A L^4))); split into N elements (the beam entry's ``elements: N``) it
converges as h^4 (the cubic element's rate). The section's own rotary inertia in
bending is left out (slender beams).

Numerics. M_r is never inverted. Its eigendecomposition M_r = U diag(mu) U^T splits the
motions into massive ones (mu above :data:`MASSLESS_RTOL` times the largest) and massless
ones b (a virtual spring between two massless bodies, a massless passive link): those
carry no inertia, so they follow the massive ones statically, K_bb b = -K_ba a, and are
condensed out (Guyan's static condensation, exact for massless motions): K_c = K_aa -
K_ab K_bb^+ K_ba. The massless motions that no spring sees either (K_bb's null space, by
the same relative rule as the rank of the compliance) carry neither energy and are left
out (internal mobilities). On the massive motions, a = diag(mu_a)^-1/2 c turns the
problem into the standard symmetric one diag(mu_a)^-1/2 K_c diag(mu_a)^-1/2 c =
omega^2 c (LAPACK's dsyevd), whose conditioning is bounded by the kept mass range (at
most 1 / MASSLESS_RTOL). A mode with omega^2 at or below :data:`RIGID_RTOL` times the
largest ``|omega^2|`` (the rank rule of :mod:`closedloop.common.conditioning`, RANK_RTOL on the
square-root factor, read on omega^2) is a rigid-body mode: a mechanism's motion with no
restoring spring, reported with frequency exactly 0. A mode below minus that bound is an
unstable equilibrium (a weight that overturns its springs): refused.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import frozen, readonly
from closedloop.common.conditioning import RANK_RTOL, twist_scaling
from closedloop.elastostatics.partition import scaling
from closedloop.exceptions import ClosedLoopError, InvalidInputError, ModesError
from closedloop.kinematics.configuration import Configuration, as_configuration
from closedloop.kinematics.constraints import nullspace
from closedloop.model.beam_joints import inserted_beams
from closedloop.model.beam_section import beam_axes
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.closures import check_name
from closedloop.model.gravity import GravityLoad, Payload

#: Eigenvalues of the reduced mass matrix at or below this fraction of the largest are
#: massless motions, condensed statically: the rounding of M_r is about 1e-16 of its
#: largest eigenvalue, and a real mass this far below the heaviest would vibrate 1e6 times
#: faster than the rest (beyond any model's validity), so it is better taken as massless.
MASSLESS_RTOL = 1e-12
#: omega^2 at or below this fraction of the largest ``|omega^2|`` is a rigid-body mode
#: (frequency 0): the rank rule RANK_RTOL (1e-7) of the compliance on the square-root
#: factor of the stiffness, here on omega, squared.
RIGID_RTOL = RANK_RTOL**2


@dataclass(frozen=True)
class ModesResult:
    """Natural frequencies and mode shapes at a configuration (arrays read-only).

    Attributes:
        frequencies: (n,) natural frequencies [Hz], ascending; rigid-body modes are
            exactly 0.
        eigenvalues: (n,) omega^2 [rad^2/s^2], ascending (0 for the rigid-body modes).
        shapes: (nv, n) mode shapes as joint deflections (tangent of q [rad, m]) per unit
            modal amplitude, mass-normalised: shapes.T @ M @ shapes = I (the modal
            amplitude eta in sqrt(kg) m: kinetic energy 1/2 eta'^2 [J]).
        q: (nq,) the configuration of the modes (the equilibrium under gravity if given).
        frame: name of the frame of ``twists`` and ``effective_masses``, or None.
        axes: ``"world"`` or ``"local"``: the axes of ``twists``.
        point: (3,) the frame origin [m], world axes (zeros without a frame).
        twists: (6, n) twist of the frame along each mode shape (dx, dy, dz [m], rx, ry,
            rz [rad] per unit modal coordinate), at its origin, in ``axes``; None without
            a frame.
        effective_masses: (6, n) effective mass of each mode at the frame, per twist
            component: 1 / twists^2 [kg for translations, kg m^2 for rotations], the mass
            of the one-dof oscillator (stiffness omega^2 m) that the mode is when seen
            along that component at the frame; inf where the mode does not move it (the
            component, translations per the length L, at most RANK_RTOL times the mode's
            largest: rounding). None without a frame.
        n_rigid: number of rigid-body modes among the returned ones (frequency 0).
        mobility: d, the number of admissible motions.
        n_massless: massless admissible motions condensed statically.
        n_internal: massless motions that no spring sees either, left out.
        n_modes: number of modes of the model at q (d - n_massless).
        mass_condition: largest / smallest eigenvalue of M_r on the kept massive motions
            (scaled coordinates): the conditioning of the eigenproblem.
    """

    frequencies: np.ndarray
    eigenvalues: np.ndarray
    shapes: np.ndarray
    q: np.ndarray
    frame: str | None
    axes: str
    point: np.ndarray
    twists: np.ndarray | None
    effective_masses: np.ndarray | None
    n_rigid: int
    mobility: int
    n_massless: int
    n_internal: int
    n_modes: int
    mass_condition: float

    @property
    def lowest_elastic_frequency(self) -> float:
        """Lowest nonzero frequency [Hz] among the returned ones (nan if all are rigid)."""
        elastic = self.frequencies[self.frequencies > 0.0]
        return float(elastic[0]) if elastic.size else math.nan

    def to_dict(self) -> dict:
        """JSON-ready summary (SI): frequencies [Hz] ascending, shapes, twists, masses."""

        def listed(a):
            return None if a is None else np.where(np.isfinite(a), a, None).tolist()

        return {
            "frequencies": self.frequencies.tolist(),
            "eigenvalues": self.eigenvalues.tolist(),
            "shapes": self.shapes.T.tolist(),
            "frame": self.frame,
            "axes": self.axes,
            "point": self.point.tolist(),
            "twists": None if self.twists is None else self.twists.T.tolist(),
            "effective_masses": listed(None if self.twists is None else self.effective_masses.T),
            "n_rigid": self.n_rigid,
            "mobility": self.mobility,
            "n_massless": self.n_massless,
            "n_internal": self.n_internal,
            "n_modes": self.n_modes,
            "mass_condition": self.mass_condition,
            "units": {
                "frequencies": "Hz",
                "eigenvalues": "rad^2/s^2",
                "twists": "m, rad per unit modal coordinate",
                "effective_masses": "kg (translations), kg m^2 (rotations)",
            },
        }


def mass_matrix(
    state: Configuration, payloads: Sequence[Payload] = (), density: float | None = None
) -> np.ndarray:
    """(nv, nv) joint-space mass matrix M(q) [kg, kg m, kg m^2] of the tree's inertias,
    ``payloads`` (point masses on their frames' joints) and the beams' own mass (module
    docstring; ``density`` [kg/m^3] for the beams without a ``density:`` key),
    symmetric."""
    clm = state.model
    if payloads:
        load = GravityLoad(clm, (0.0, 0.0, 0.0), payloads)
        M = pin.crba(load.model, load.data, state.q)
    else:  # the configuration's own Data, at its q: the kinematics it holds stay the same
        M = pin.crba(clm.model, state.data, state.q).copy()
    M = np.triu(M) + np.triu(M, 1).T  # CRBA fills the upper triangle
    for link, tip, axes, length, section in _beam_sites(clm):
        rho = section.density or density
        if rho is None:
            continue
        ends = []
        for frame, R in zip((link, tip), axes, strict=True):
            J = pin.getFrameJacobian(clm.model, state.data, frame, pin.LOCAL)
            ends += [R.T @ J[:3], R.T @ J[3:]]
        J_e = np.vstack(ends)  # (12, nv): the two ends' twists in the beam axes
        M += J_e.T @ consistent_mass(length, rho * section.A, rho * section.Ip) @ J_e
    return M


def total_mass(clm: ClosedLoopModel, density: float | None = None) -> float:
    """Total mass of a model [kg]: every body's inertia (the links welded to the world too,
    which Pinocchio merges into the universe's inertia) and each beam's own mass rho A L
    (its ``density:`` key, else ``density`` [kg/m^3]; a beam without either weighs
    nothing besides its link's inertia), the masses :func:`mass_matrix` moves.

    Raises:
        InvalidInputError: a body whose inertia is not the robot file's
            (:meth:`ClosedLoopModel.require_inertias`).
    """
    clm.require_inertias("the total mass")
    bodies = math.fsum(inertia.mass for inertia in clm.model.inertias)
    beams = math.fsum((s.density or density or 0.0) * s.A * length
                      for _, _, _, length, s in _beam_sites(clm))  # fmt: skip
    return bodies + beams


def _beam_sites(clm: ClosedLoopModel) -> tuple:
    """Per beam with a section: (link frame, tip frame (the virtual joint's), (the beam
    axes in the link frame, in the tip frame at rest), length [m], its BeamMass); once a
    model."""

    def sites():
        out = []
        for beam in inserted_beams(clm.model) if clm.beam_masses else ():
            section = clm.beam_masses.get(beam.name)
            if section is None:
                continue
            tip = beam.rest.translation
            R_LB = beam_axes(beam.name, tip, None, axisymmetric=True)  # x along the beam, Ip only
            frame = clm.model.getFrameId(beam.name, pin.JOINT)
            axes = (R_LB, beam.rest.rotation.T @ R_LB)
            out.append((beam.link_frame, frame, axes, float(np.linalg.norm(tip)), section))
        return tuple(out)

    return clm.memo("beam_sites", sites)


def consistent_mass(length: float, mass_per_length: float, polar_per_length: float):
    """(12, 12) consistent mass matrix [kg, kg m, kg m^2] of a straight Euler-Bernoulli
    frame element of ``length`` L [m], rho A [kg/m] and rho Ip [kg m], on the twists (v,
    w) of its start, then its end, in the beam axes (x along the beam)."""
    L, m = length, mass_per_length * length
    M = np.zeros((12, 12))
    rod = np.array([[2.0, 1.0], [1.0, 2.0]]) / 6.0
    M[np.ix_([0, 6], [0, 6])] = m * rod  # axial
    M[np.ix_([3, 9], [3, 9])] = polar_per_length * L * rod  # torsion
    bending = (
        m
        / 420.0
        * np.array(
            [
                [156.0, 22.0 * L, 54.0, -13.0 * L],
                [22.0 * L, 4.0 * L * L, 13.0 * L, -3.0 * L * L],
                [54.0, 13.0 * L, 156.0, -22.0 * L],
                [-13.0 * L, -3.0 * L * L, -22.0 * L, 4.0 * L * L],
            ]
        )
    )
    M[np.ix_([1, 5, 7, 11], [1, 5, 7, 11])] = bending  # v, rz: rz = dv/dx
    flip = np.array([1.0, -1.0, 1.0, -1.0])  # w, ry: ry = -dw/dx
    M[np.ix_([2, 4, 8, 10], [2, 4, 8, 10])] = flip[:, None] * bending * flip
    return M


def modes(
    model: ClosedLoopModel | Configuration,
    q: np.ndarray | None = None,
    *,
    n: int | None = None,
    frame: str | None = None,
    axes: str = "world",
    length: float | None = None,
    gravity=None,
    payloads: Sequence[Payload] = (),
    density: float | None = None,
) -> ModesResult:
    """Natural frequencies and mode shapes at a configuration (module docstring).

    Call as ``modes(state)`` with a :class:`Configuration`, or ``modes(model, q)``.

    Args:
        model: a configuration, or a model with closures and springs.
        q: (nq,) assembled configuration, with a model.
        n: number of lowest modes to return (default: all of them), 1 <= n <= n_modes.
        frame: a frame whose twist and effective masses along each mode are reported.
        axes: ``"world"`` (default) or ``"local"``: the axes of the frame's twists.
        length: characteristic length [m] of the scaled coordinates, with a model.
        gravity: (3,) acceleration [m/s^2], world axes: q is then the springs' rest
            configuration, the mechanism settles under the weight of its links and
            payloads (:func:`closedloop.elastostatics.statics.solve_equilibrium`) and the modes are
            those about that equilibrium, with gravity's tangent stiffness.
        payloads: point masses at frames (:class:`closedloop.model.gravity.Payload`): they add
            to the mass matrix (and to the weight, with ``gravity``).
        density: density [kg/m^3] of the beams whose entry has no ``density:`` key (a
            finite number > 0); None: those beams add no mass of their own.

    Raises:
        OpenLoopError: q does not close the loops.
        ModesError: no admissible motion (a rigid model), no mass on any admissible
            motion, or an unstable equilibrium (a negative omega^2).
        InvalidInputError: a bad n, frame, axes, gravity, payload or density (not a
            finite number > 0, or given to a model without a beam section); a model whose
            link inertias are not the robot file's
            (:meth:`closedloop.model.closed_loop.ClosedLoopModel.require_inertias`).
        NameNotFoundError: an unknown frame.
    """
    if frame is not None:
        check_name("frame", frame)
    if axes not in ("world", "local"):
        raise InvalidInputError(f"axes {axes!r}; expected 'world' or 'local'")
    state = as_configuration(model, q, length=length)
    state.require_closed()
    clm = state.model
    clm.require_inertias("the natural frequencies")
    if frame is not None:
        clm.frame_id(frame)  # an unknown frame: before any work
    if density is not None:
        _check_density(clm, density)
    K = clm.spring_matrix
    if gravity is not None:
        state, K = _settled(state, gravity, payloads)
    N = _admissible(state)
    d = N.shape[1]
    if d == 0:
        raise ModesError(
            f"{clm.name!r} has no admissible motion at this configuration (every joint "
            "locked or held by the closures): a rigid model has no natural frequency"
        )
    M_r = N.T @ mass_matrix(state, payloads, density) @ N
    K_r = N.T @ K @ N
    lam, Y, info = _eigen(0.5 * (M_r + M_r.T), 0.5 * (K_r + K_r.T), clm.name)
    n_all = lam.size
    if n is None:
        n = n_all
    elif isinstance(n, bool) or not isinstance(n, int | np.integer) or not 1 <= n <= n_all:
        raise InvalidInputError(f"n = {n!r}; expected an integer from 1 to {n_all} (the modes)")
    lam, shapes = lam[:n], N @ Y[:, :n]
    twists = masses = None
    point = np.zeros(3)
    if frame is not None:
        twists = state.frame_jacobian(frame, axes) @ shapes
        point = state.data.oMf[clm.frame_id(frame)].translation
        scaled = np.abs(twists) * twist_scaling(state.length)[:, None]  # unit-free
        moved = scaled > RANK_RTOL * scaled.max(axis=0, initial=0.0)  # beyond rounding
        with np.errstate(divide="ignore"):
            masses = np.where(moved, 1.0 / np.where(moved, twists, 1.0) ** 2, np.inf)
    return ModesResult(
        frequencies=frozen(np.sqrt(lam) / (2.0 * math.pi)),
        eigenvalues=frozen(lam),
        shapes=frozen(shapes),
        q=state.q,
        frame=frame,
        axes=axes,
        point=readonly(point),
        twists=None if twists is None else frozen(twists),
        effective_masses=None if masses is None else frozen(masses),
        n_rigid=int(np.count_nonzero(lam == 0.0)),
        mobility=d,
        n_massless=info[0],
        n_internal=info[1],
        n_modes=n_all,
        mass_condition=info[2],
    )


def lowest_frequencies(clm: ClosedLoopModel, configurations: dict, done: np.ndarray):
    """(len(done),) the lowest nonzero natural frequency [Hz] (rigid-body modes skipped)
    at the configurations {position: q (nq,)} of the positions where ``done`` (bool); NaN
    elsewhere and where :func:`modes` raises or every mode is rigid (a map's index
    ``lowest_frequency``)."""
    out = np.full(len(done), np.nan)
    for i, q in configurations.items():
        if done[i]:
            try:
                out[i] = modes(clm, q).lowest_elastic_frequency
            except ClosedLoopError:
                pass  # no value at this point: NaN, as the other indices
    return out


def check_massive(clm: ClosedLoopModel, density: float | None = None) -> None:
    """Refuse a model without any mass (ModesError): no link inertia, no beam density; or
    whose inertias are not the robot file's (InvalidInputError,
    :meth:`closedloop.model.closed_loop.ClosedLoopModel.require_inertias`)."""
    clm.require_inertias("the natural frequencies")
    weighed = any(s.density or density for s in clm.beam_masses.values())
    if not weighed and not any(inertia.mass > 0.0 for inertia in clm.model.inertias):
        raise ModesError(
            f"{clm.name!r} has no mass (no link inertia, no beam density): it has no natural "
            "frequency; give the links inertias (masses) or the beams' density"
        )


def _check_density(clm: ClosedLoopModel, density) -> None:
    number = isinstance(density, int | float | np.integer | np.floating)
    if isinstance(density, bool) or not number or not 0.0 < density < math.inf:
        raise InvalidInputError(f"density {density!r}; expected a finite number > 0 [kg/m^3]")
    if not clm.beam_masses:
        raise InvalidInputError(
            f"density {density} kg/m^3 given, but {clm.name!r} has no beam with a section "
            "(beams: with E, G and section) to weigh"
        )


def _settled(state: Configuration, gravity, payloads) -> tuple[Configuration, np.ndarray]:
    """The equilibrium under the weight (rest configuration ``state``) and the tangent
    stiffness there (nv, nv)."""
    from closedloop.elastostatics.statics import solve_equilibrium
    from closedloop.elastostatics.tangent import tangent_stiffness

    clm, frame = state.model, state.model.model.frames[0].name  # the world: no load on it
    eq = solve_equilibrium(clm, state.q, frame, np.zeros(6), gravity=gravity, payloads=payloads)
    K = tangent_stiffness(clm, eq.q, eq.q_rest, frame, np.zeros(6), eq.multipliers, gravity=eq.load)
    return Configuration(clm, eq.q, length=state.length), K


def _admissible(state: Configuration) -> np.ndarray:
    """(nv, d) the admissible motions, orthonormal in the scaled coordinates, as the
    compliance's general path (:func:`closedloop.elastostatics.springs.spring_factor`)."""
    sc = scaling(state)
    Jc = state.closure_jacobian() * sc.row_scale
    A = np.vstack([Jc, sc.locked_rows]) if len(sc.locked_rows) else Jc
    N_s, _ = nullspace(A * sc.s_q)
    return N_s * sc.s_q[:, None]


def _eigen(M: np.ndarray, K: np.ndarray, name: str):
    """omega^2 (r,) ascending and mass-normalised shapes Y (d, r) of K y = omega^2 M y on
    (d, d) symmetric M (semi-definite) and K, with the massless motions condensed (module
    docstring); and (condensed, left out, mass condition)."""
    mu, U = np.linalg.eigh(M)
    top = mu[-1] if mu.size else 0.0
    heavy = mu > MASSLESS_RTOL * top
    if not top > 0.0:
        raise ModesError(
            f"{name!r} has no mass on its admissible motions (no link inertia moves, no "
            "payload, no beam density): it has no natural frequency; give the links "
            "inertias (masses), a payload or the beams' density"
        )
    Ua, Ub = U[:, heavy], U[:, ~heavy]
    Ka = Ua.T @ K @ Ua
    B, left_out = Ua, 0
    if Ub.shape[1]:  # massless motions follow statically: K_bb b = -K_ba a
        Kba = Ub.T @ K @ Ua
        kb, Wb = np.linalg.eigh(Ub.T @ K @ Ub)
        scale = max(float(np.max(np.abs(np.linalg.eigvalsh(K)))), 0.0)
        seen = np.abs(kb) > RIGID_RTOL * scale
        left_out = int(np.count_nonzero(~seen))
        W = Wb[:, seen]
        T = -(W / kb[seen]) @ (W.T @ Kba)  # b = T a
        Ka = Ka + Kba.T @ T
        B = Ua + Ub @ T
    s = 1.0 / np.sqrt(mu[heavy])
    A = s[:, None] * Ka * s
    lam, C = np.linalg.eigh(0.5 * (A + A.T))
    bound = RIGID_RTOL * float(np.max(np.abs(lam)))
    if lam[0] < -bound:
        raise ModesError(
            f"the equilibrium of {name!r} is unstable: omega^2 = {lam[0]:.4g} rad^2/s^2 < 0 "
            "(the weight overturns the springs); there is no vibration about it"
        )
    lam = np.where(lam <= bound, 0.0, lam)
    Y = B @ (s[:, None] * C)
    return lam, Y, (Ub.shape[1] - left_out, left_out, float(mu[-1] / mu[heavy][0]))


def batch_modes(
    model: ClosedLoopModel,
    Q: np.ndarray,
    *,
    n: int | None = None,
    **options,
) -> np.ndarray:
    """(m, n) natural frequencies [Hz], ascending, at the configurations Q (m, nq).

    Args:
        model: a model with closures and springs.
        Q: (m, nq) assembled configurations.
        n: number of lowest modes per configuration (default: the number of modes at the
            first one, which every configuration must then have).
        options: the keyword arguments of :func:`modes` (``length``, ``gravity``,
            ``payloads``).

    Raises:
        the errors of :func:`modes`, at the first configuration that raises.
    """
    Q = np.atleast_2d(np.asarray(Q, dtype=float))
    if Q.ndim != 2 or Q.shape[0] == 0:
        raise InvalidInputError(f"Q must be (m, nq) configurations, got shape {Q.shape}")
    rows = []
    for q in Q:
        rows.append(modes(model, q, n=n, **options).frequencies)
        n = rows[0].size
    return frozen(np.array(rows))
