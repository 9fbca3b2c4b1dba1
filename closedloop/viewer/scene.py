"""What the deflection viewer draws, computed without any viewer: poses, scale, ellipsoids.

A wrench w = (f [N], n [N m]) acts at the origin of a frame, world axes. The joint
deflection dq (nv,) (tangent of q) is the linear one, ``G w`` of
:func:`closedloop.elastostatics.compliance.compliance`, or, with ``nonlinear=True``, the finite one
``difference(q, q_eq)`` of the static equilibrium q_eq of
:func:`closedloop.elastostatics.statics.solve_equilibrium` (a dead load followed from zero). The
deflected pose is drawn amplified:

    q_s = integrate(q, s dq)

A loop closure holds q_s only to first order in s dq: a large s visibly opens the loops.
With ``close_loops=True`` each amplified pose is re-assembled instead
(:func:`closedloop.kinematics.assembly.assemble` from q_s): the spring and locked coordinates keep
their amplified values and the passive joints close the loops.

Amplification (``scale=None``): the first-order displacement of a point p under dq is
``J_p dq`` (J_p the translational rows of its Jacobian, world axes); over the origins of all
joints (the link frames) and of the loaded frame, the largest one, d_max [m], is made
``AUTO_FRACTION`` of the model size L [m], the diagonal of the bounding box of the origins
of all joints and frames at q:

    s = AUTO_FRACTION * L / d_max     (s = 1 when d_max = 0: nothing deflects)

Compliance ellipsoids, centred at the loaded frame origin at q, world axes. With C_tt,
C_rr the (3, 3) translational and rotational diagonal blocks of the compliance C (world
axes, at the frame origin), eigenvalues lambda_i and unit eigenvectors v_i:

* translation: semi-axes ``s F lambda_i`` [m] along v_i, F = |f| [N] (|n| / L when f = 0):
  the set {s C_tt u : |u| = F}, the amplified displacements of the frame origin under all
  forces of the applied magnitude. Under a pure force the amplified first-order
  displacement ``s C_tt f`` of the frame origin lies on its surface.
* rotation (on request): semi-axes ``rho s N mu_i`` [m] along v_i, N = |n| [N m]
  (|f| rho when n = 0), mu_i the eigenvalues of C_rr [rad/(N m)], rho = ``LEVER_FRACTION``
  L (the length of the drawn arrows): the amplified rotations under all moments of the
  applied magnitude, drawn as the arc length [m] they give at radius rho.

No ellipsoid is drawn for a zero wrench. An ellipsoid larger than the model is drawn
shrunk: its radii times ``shrink`` = min(1, ``ELLIPSOID_MAX_FRACTION`` L / largest radius)
(:attr:`Ellipsoid.drawn_radii`; the viewer's legend shows the factor).

Flexible links (the beams of :mod:`closedloop.model.beams`) are drawn bent: the link's mesh
stays rigid with the beam's clamped start and its ``end`` rides on the tip, and between
them the beam's axis is the cubic Hermite curve of :func:`beam_curves` from the start
(the link frame origin, tangent along the undeflected beam) to the tip (the virtual
joint's origin, tangent along the undeflected beam turned by the tip's rotation), both
tangents of the beam's length L. To first order in the tip's deflection this is the
Euler-Bernoulli deflection line of a clamped beam loaded at its tip (a cubic: it has the
tip's displacement and slope), e.g. 5 F L^3 / (48 E I) at mid-length under a tip force F;
an unloaded beam is the straight segment from start to tip.

Norms are taken without under- or overflow: a load of any finite magnitude gives the same
automatic picture; one whose deflection or ellipsoid is not a finite number (``--force
1.7e308 1.7e308 0``) is refused (InvalidInputError), and so is a given scale s that draws
s d_max larger than ``MAX_SHOWN_FRACTION`` L (``--scale 1e200``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.analysis.batch_indices import row_norms
from closedloop.common.arrays import check_wrench, readonly
from closedloop.elastostatics.compliance import ComplianceResult, compliance
from closedloop.elastostatics.equilibrium import Equilibrium
from closedloop.elastostatics.statics import solve_equilibrium
from closedloop.exceptions import InvalidInputError
from closedloop.kinematics.assembly import assemble
from closedloop.kinematics.configuration import accepts_configuration
from closedloop.kinematics.constraints import frame_jacobian, update_kinematics
from closedloop.model.beams import inserted_beams
from closedloop.model.closed_loop import ClosedLoopModel

#: Largest amplified first-order point displacement, as a fraction of the model size.
AUTO_FRACTION = 0.1
#: Lever arm rho of the rotational ellipsoid (and arrow length), per model size L.
LEVER_FRACTION = 0.25
#: Number of poses of the load-ramp animation (load fractions 0 .. 1, evenly spaced).
ANIMATION_FRAMES = 25
#: Largest drawn ellipsoid semi-axis, per model size L.
ELLIPSOID_MAX_FRACTION = 0.25
#: Largest amplified point displacement s d_max a given scale may draw, per model size L
#: (the automatic one draws AUTO_FRACTION): beyond, the picture is of nothing, and the
#: drawing (float32 in the page) overflows.
MAX_SHOWN_FRACTION = 100.0
#: Points of each drawn beam curve, start and tip included (evenly spaced parameter).
BEAM_POINTS = 13


@dataclass(frozen=True)
class BeamCurve:
    """A flexible link's axis as drawn: ``name`` its virtual joint, ``points`` (n, 3) [m],
    world frame, from the clamped start to the tip (the curve of :func:`beam_curves`)."""

    name: str
    points: np.ndarray


def beam_curves(clm: ClosedLoopModel, q: np.ndarray, n: int = BEAM_POINTS) -> tuple:
    """The beams of ``clm`` at q (nq,) as :class:`BeamCurve` of n points: the cubic Hermite
    curve p(u) = h00 p0 + h10 d0 + h01 p1 + h11 d1, u in [0, 1] (module docstring), with
    p0, p1 the start and tip [m] and d0, d1 the tangents [m] (world frame)."""
    update_kinematics(clm, clm.check_configuration(q))
    u = np.linspace(0.0, 1.0, n)[:, None]
    h00, h10, h01, h11 = (
        2 * u**3 - 3 * u**2 + 1,
        u**3 - 2 * u**2 + u,
        3 * u**2 - 2 * u**3,
        u**3 - u**2,
    )
    out = []
    for b in inserted_beams(clm.model):
        start, tip = clm.data.oMf[b.link_frame], clm.data.oMi[b.joint]
        d0 = start.rotation @ b.rest.translation
        d1 = tip.rotation @ (b.rest.rotation.T @ b.rest.translation)
        p = h00 * start.translation + h10 * d0 + h01 * tip.translation + h11 * d1
        out.append(BeamCurve(b.name, readonly(p)))
    return tuple(out)


@dataclass(frozen=True)
class Ellipsoid:
    """An ellipsoid to draw (arrays read-only).

    Attributes:
        kind: ``"translation"`` or ``"rotation"``.
        centre: (3,) centre [m], world frame.
        radii: (3,) semi-axes [m] (see the module docstring), ascending.
        axes: (3, 3) unit directions of the semi-axes (columns), world axes.
        shrink: factor (0, 1] of the drawn radii (module docstring).
    """

    kind: str
    centre: np.ndarray
    radii: np.ndarray
    axes: np.ndarray
    shrink: float = 1.0

    @property
    def drawn_radii(self) -> np.ndarray:
        """(3,) semi-axes drawn [m]: ``shrink * radii``."""
        return self.shrink * self.radii


@dataclass(frozen=True)
class DeflectionScene:
    """The nominal and the amplified deflected pose under a wrench (arrays read-only).

    Attributes:
        frame: name of the loaded frame.
        q: (nq,) nominal (unloaded, assembled) configuration.
        wrench: (6,) (fx, fy, fz [N], nx, ny, nz [N m]), world axes, at the frame origin.
        dq: (nv,) joint deflection (tangent of q) [rad or m], not amplified.
        scale: amplification s (dimensionless).
        auto_scaled: True when s was chosen by :func:`auto_scale`.
        size: model size L [m] (:func:`model_size`).
        max_displacement: d_max [m], largest first-order point displacement under dq
            (origins of the joints and of the loaded frame), not amplified.
        q_deflected: (nq,) integrate(q, s dq).
        point: (3,) loaded frame origin at q [m], world frame.
        point_deflected: (3,) loaded frame origin at q_deflected [m], world frame.
        frame_twist: (6,) displacement of the loaded frame (translation of its origin [m],
            rotation vector [rad]), world axes, not amplified: the first-order J dq = C w if
            linear, the finite ``equilibrium.displacement`` if nonlinear.
        compliance: compliance at the loaded frame, world axes, at q.
        ellipsoids: translational (and, on request, rotational) compliance ellipsoids.
        ramp: (n,) load fractions of the animation, 0 .. 1.
        ramp_q: (n, nq) amplified configurations integrate(q, s dq(t)) for each fraction t.
        equilibrium: the nonlinear equilibrium under the full wrench, or None (linear).
        beams: the flexible links at q_deflected (:func:`beam_curves`; () without beams).
        mode: for a natural mode (:func:`mode_scene`; then no wrench, no compliance):
            {"number": its rank from the lowest (1), "frequency_hz": its frequency}; None
            for a deflection.
    """

    frame: str
    q: np.ndarray
    wrench: np.ndarray
    dq: np.ndarray
    scale: float
    auto_scaled: bool
    size: float
    max_displacement: float
    q_deflected: np.ndarray
    point: np.ndarray
    point_deflected: np.ndarray
    frame_twist: np.ndarray
    compliance: ComplianceResult
    ellipsoids: tuple[Ellipsoid, ...]
    ramp: np.ndarray
    ramp_q: np.ndarray
    equilibrium: Equilibrium | None
    beams: tuple[BeamCurve, ...] = ()
    mode: dict | None = None

    @property
    def nonlinear(self) -> bool:
        """True when dq is the finite deflection of the nonlinear equilibrium."""
        return self.equilibrium is not None

    def summary(self) -> str:
        """One line: amplification, largest displacement and model size."""
        how = "automatic" if self.auto_scaled else "given"
        kind = "nonlinear" if self.nonlinear else "linear"
        return (
            f"deflection amplified x{self.scale:.4g} ({how}; {kind} deflection): largest "
            f"point displacement {self.max_displacement:.3e} m, shown as "
            f"{self.scale * self.max_displacement:.3e} m; model size {self.size:.3g} m"
        )

    def to_dict(self) -> dict:
        """JSON-ready summary (SI): ``point_deflected_m`` is the frame origin displaced by
        the deflection (not amplified: first order if linear), ``point_shown_m`` where the
        amplified view draws it (:attr:`point_deflected`)."""
        return {
            "frame": self.frame,
            "scale": self.scale,
            "auto_scaled": self.auto_scaled,
            "nonlinear": self.nonlinear,
            "model_size_m": self.size,
            "max_displacement_m": self.max_displacement,
            "wrench": self.wrench.tolist(),
            "point_m": self.point.tolist(),
            # the origin moved by the deflection itself; the drawn, amplified one apart
            "point_deflected_m": (self.point + self.frame_twist[:3]).tolist(),
            "point_shown_m": self.point_deflected.tolist(),
            "frame_twist": self.frame_twist.tolist(),
            "ellipsoids": [
                {
                    "kind": e.kind,
                    "radii_m": e.radii.tolist(),
                    "axes": e.axes.T.tolist(),
                    "shrink": e.shrink,
                }
                for e in self.ellipsoids
            ],
        }


def _origins(clm: ClosedLoopModel) -> np.ndarray:
    """(njoints - 1 + nframes, 3) origins of joints and frames from the current kinematics."""
    joints = [clm.data.oMi[j].translation for j in range(1, clm.model.njoints)]
    frames = [f.translation for f in clm.data.oMf]
    return np.array(joints + frames).reshape(-1, 3)


def bounding_box(clm: ClosedLoopModel, q: np.ndarray) -> np.ndarray:
    """(2, 3) lowest and highest corner [m], world frame, of all joint and frame origins at q."""
    update_kinematics(clm, clm.check_configuration(q))
    p = _origins(clm)
    return np.array([p.min(axis=0), p.max(axis=0)])


def model_size(clm: ClosedLoopModel, q: np.ndarray) -> float:
    """Model size L [m]: diagonal of :func:`bounding_box` at q (1 m if it is a point)."""
    lo, hi = bounding_box(clm, q)
    size = float(np.linalg.norm(hi - lo))
    return size if size > 0.0 else 1.0


def joint_jacobian(model: pin.Model, data: pin.Data, joint: int) -> np.ndarray:
    """(6, nv) Jacobian of ``joint``'s origin (velocity [m], angular velocity [rad]), world
    axes (LOCAL_WORLD_ALIGNED), from the joint Jacobians already computed in ``data``
    (Pinocchio gives a one-dof model's as a (6,) vector)."""
    J = pin.getJointJacobian(model, data, joint, pin.LOCAL_WORLD_ALIGNED)
    return np.asarray(J).reshape(6, model.nv)


def point_displacements(
    clm: ClosedLoopModel, q: np.ndarray, frame: str, dq: np.ndarray
) -> np.ndarray:
    """First-order displacements J_p dq [m] of the origins of the joints and of ``frame``.

    Args:
        q: (nq,) configuration.
        frame: name of the loaded frame.
        dq: (nv,) joint deflection (tangent of q) [rad or m].

    Returns:
        (njoints - 1 + 1, 3) displacements, world axes: joints 1..njoints-1, then the frame.
    """
    q = clm.check_configuration(q)
    dq = np.asarray(dq, dtype=float).reshape(-1)
    if dq.shape != (clm.model.nv,) or not np.all(np.isfinite(dq)):
        raise InvalidInputError(f"dq must be {clm.model.nv} finite values, got {dq.size}")
    J_f = frame_jacobian(clm, q, frame, "world")  # also the joint Jacobians of q
    rows = [joint_jacobian(clm.model, clm.data, j)[:3] @ dq for j in range(1, clm.model.njoints)]
    return np.array([*rows, J_f[:3] @ dq]).reshape(-1, 3)


def largest_displacement(clm: ClosedLoopModel, q: np.ndarray, frame: str, dq: np.ndarray) -> float:
    """d_max [m]: largest norm of :func:`point_displacements` (without under- or overflow
    of the squares: a load of any magnitude gives the same picture; NaN when one is
    not finite)."""
    return float(np.max(row_norms(point_displacements(clm, q, frame, dq))))


def auto_scale(
    clm: ClosedLoopModel,
    q: np.ndarray,
    frame: str,
    dq: np.ndarray,
    fraction: float = AUTO_FRACTION,
) -> float:
    """Amplification s = fraction L / d_max (module docstring); 1 when nothing deflects."""
    d_max = largest_displacement(clm, q, frame, dq)
    return fraction * model_size(clm, q) / d_max if d_max > 0.0 else 1.0


def compliance_ellipsoid(
    block: np.ndarray, magnitude: float, length: float, centre: np.ndarray, kind: str
) -> Ellipsoid:
    """Ellipsoid {length * magnitude * block u : |u| = 1} of a symmetric (3, 3) block.

    Args:
        block: (3, 3) symmetric positive semi-definite compliance block [SI].
        magnitude: load magnitude [N or N m].
        length: factor turning the block's output into metres (s, or s L for rotations).
        centre: (3,) centre [m], world frame.
        kind: ``"translation"`` or ``"rotation"``.
    """
    lam, V = np.linalg.eigh(0.5 * (block + block.T))
    with np.errstate(over="ignore", invalid="ignore"):
        radii = length * magnitude * np.clip(lam, 0.0, None)  # rounding may leave -1e-20
    return Ellipsoid(kind, readonly(centre), readonly(radii), readonly(V))


def capped(e: Ellipsoid, size: float, fraction: float = ELLIPSOID_MAX_FRACTION) -> Ellipsoid:
    """``e`` with ``shrink`` so that its largest drawn radius is at most fraction * size."""
    largest = float(np.max(e.radii))
    shrink = min(1.0, fraction * size / largest) if largest > 0.0 else 1.0
    return Ellipsoid(e.kind, e.centre, e.radii, e.axes, shrink)


def _ellipsoids(res: ComplianceResult, w: np.ndarray, s: float, size: float, rotational: bool):
    f, n = vector_norm(w[:3]), vector_norm(w[3:])
    if f == 0.0 and n == 0.0:
        return ()
    force = f if f > 0.0 else n / size
    out = [compliance_ellipsoid(res.C[:3, :3], force, s, res.point, "translation")]
    if rotational:
        rho = LEVER_FRACTION * size
        moment = n if n > 0.0 else f * rho
        out.append(compliance_ellipsoid(res.C[3:, 3:], moment, s * rho, res.point, "rotation"))
    return tuple(capped(e, size) for e in out)


def vector_norm(v: np.ndarray) -> float:
    """Euclidean norm of v (k,) at any magnitude (:func:`closedloop.analysis.indices.row_norms`)."""
    return float(row_norms(np.asarray(v, dtype=float)[None])[0])


def unit_vector(v: np.ndarray) -> np.ndarray:
    """v (k,) nonzero, finite, divided by its norm, at any magnitude (a load's direction)."""
    v = np.asarray(v, dtype=float)
    m = np.max(np.abs(v))
    return (v / m) / np.linalg.norm(v / m)


def _check_finite(w: np.ndarray, **values) -> None:
    for name, value in values.items():
        if not np.all(np.isfinite(value)):
            raise InvalidInputError(
                f"load {w.tolist()} too large: the {name.replace('_', ' ')} overflows "
                "(not a finite number); give a smaller wrench"
            )


@accepts_configuration
def deflection_scene(
    clm: ClosedLoopModel,
    q: np.ndarray,
    frame: str,
    wrench: np.ndarray,
    *,
    scale: float | None = None,
    nonlinear: bool = False,
    close_loops: bool = False,
    rotational: bool = False,
    frames: int = ANIMATION_FRAMES,
    check_limits: bool = True,
) -> DeflectionScene:
    """Poses, amplification, ellipsoids and load ramp for a wrench at ``frame``.

    Args:
        clm: model with closures and springs (or a :class:`Configuration`, then no q).
        q: (nq,) assembled configuration (the unloaded pose, rest of the springs).
        frame: name of the loaded frame.
        wrench: (6,) (fx, fy, fz [N], nx, ny, nz [N m]), world axes, at the frame origin.
        scale: amplification s >= 0; None chooses it (:func:`auto_scale`).
        nonlinear: solve the static equilibrium at each load fraction
            (:func:`closedloop.elastostatics.statics.solve_equilibrium`) instead of the linear map.
        close_loops: re-assemble each amplified pose (module docstring).
        rotational: also the rotational compliance ellipsoid.
        frames: number of poses of the load ramp (>= 2).
        check_limits: refuse a q outside the joints' limits (as
            :func:`closedloop.elastostatics.compliance.compliance`; False draws it as it is).

    Raises:
        InvalidInputError: bad wrench, scale or frame count; a wrench whose deflection
            overflows; a scale that draws the deflection larger than
            ``MAX_SHOWN_FRACTION`` model sizes.
        NameNotFoundError: unknown frame.
        MechanismError: a spring-free motion moves the frame.
        EquilibriumError: (nonlinear) no equilibrium on the branch of q.
        AssemblyError: (close_loops) the amplified spring deflections cannot be closed
            (a smaller scale can).
    """
    w = check_wrench(wrench)
    if scale is not None and not (np.isfinite(scale) and scale >= 0.0):
        raise InvalidInputError(f"scale must be a finite number >= 0, got {scale!r}")
    if int(frames) != frames or frames < 2:
        raise InvalidInputError(f"frames must be an integer >= 2, got {frames!r}")
    res = compliance(clm, q, frame, "world", check_limits=check_limits)
    q = res.q
    ramp = np.linspace(0.0, 1.0, int(frames))
    if nonlinear:  # the whole wrench first: an EquilibriumError names it, not a fraction
        equilibrium = solve_equilibrium(clm, q, frame, w)
        equilibria = [solve_equilibrium(clm, q, frame, t * w) for t in ramp[1:-1]]
        steps = [np.zeros(clm.model.nv), *(e.joint_deflection for e in equilibria)]
        steps.append(equilibrium.joint_deflection)
    else:
        dq_lin = res.joint_deflection(w)
        steps, equilibrium = [t * dq_lin for t in ramp], None
    dq = steps[-1]
    size = model_size(clm, q)
    with np.errstate(over="ignore", invalid="ignore"):
        twist = frame_jacobian(clm, q, frame, "world") @ dq
        if equilibrium is not None:  # the finite displacement, not the first-order one
            twist = equilibrium.displacement
        d_max = largest_displacement(clm, q, frame, dq)
    _check_finite(w, joint_deflection=dq, frame_displacement=twist, largest_displacement=d_max)
    s = auto_scale(clm, q, frame, dq) if scale is None else float(scale)
    if s * d_max > MAX_SHOWN_FRACTION * size:
        raise InvalidInputError(
            f"--scale {s:g} draws the largest point displacement {d_max:.3g} m as "
            f"{s * d_max:.3g} m, more than {MAX_SHOWN_FRACTION:g} model sizes ({size:.3g} m); "
            f"expected a scale of at most {MAX_SHOWN_FRACTION * size / d_max:.3g} (or none: "
            "automatic)"
        )
    ramp_q = [pin.integrate(clm.model, q, s * v) for v in steps]
    if close_loops and clm.closures:
        ramp_q = [assemble(clm, None, q_s).q for q_s in ramp_q]
    ramp_q = np.array(ramp_q)
    update_kinematics(clm, ramp_q[-1])
    point_deflected = clm.data.oMf[clm.frame_id(frame)].translation.copy()
    beams = beam_curves(clm, ramp_q[-1])
    update_kinematics(clm, q)
    ellipsoids = _ellipsoids(res, w, s, size, rotational)
    _check_finite(w, compliance_ellipsoid=[e.radii for e in ellipsoids])
    return DeflectionScene(
        frame=frame,
        q=q,
        wrench=readonly(w),
        dq=readonly(dq),
        scale=s,
        auto_scaled=scale is None,
        size=size,
        max_displacement=d_max,
        q_deflected=readonly(ramp_q[-1]),
        point=res.point,
        point_deflected=readonly(point_deflected),
        frame_twist=readonly(twist),
        compliance=res,
        ellipsoids=ellipsoids,
        ramp=readonly(ramp),
        ramp_q=readonly(ramp_q),
        equilibrium=equilibrium,
        beams=beams,
    )


def mode_scene(
    clm: ClosedLoopModel,
    q: np.ndarray,
    shape: np.ndarray,
    frequency: float,
    number: int,
    frame: str,
    *,
    scale: float | None = None,
    frames: int = ANIMATION_FRAMES,
) -> DeflectionScene:
    """A natural mode as a scene: the pose swinging harmonically between -s shape and
    +s shape (the animation, played back and forth), drawn at +s shape.

    Args:
        clm: the model; q: (nq,) the configuration of the modes
            (:attr:`closedloop.analysis.vibration.ModesResult.q`).
        shape: (nv,) the mode shape (joint deflections per unit modal amplitude).
        frequency: its natural frequency [Hz], for the legend; number: its rank (1: the
            lowest).
        frame: the frame whose origin counts among the displaced points.
        scale: amplification s >= 0 of the shape; None chooses it (:func:`auto_scale`).
        frames: number of poses of the swing (>= 2).

    Raises:
        InvalidInputError: bad scale or frame count, a shape that is not (nv,) finite.
    """
    if scale is not None and not (np.isfinite(scale) and scale >= 0.0):
        raise InvalidInputError(f"scale must be a finite number >= 0, got {scale!r}")
    if int(frames) != frames or frames < 2:
        raise InvalidInputError(f"frames must be an integer >= 2, got {frames!r}")
    dq = np.asarray(shape, dtype=float)
    if dq.shape != (clm.model.nv,) or not np.all(np.isfinite(dq)):
        raise InvalidInputError(f"mode shape of shape {dq.shape}; expected ({clm.model.nv},)")
    q = clm.check_configuration(q)
    size = model_size(clm, q)
    d_max = largest_displacement(clm, q, frame, dq)
    s = auto_scale(clm, q, frame, dq) if scale is None else float(scale)
    ramp = np.sin(np.linspace(-0.5 * np.pi, 0.5 * np.pi, int(frames)))  # harmonic
    ramp_q = np.array([pin.integrate(clm.model, q, s * t * dq) for t in ramp])
    update_kinematics(clm, ramp_q[-1])
    point_deflected = clm.data.oMf[clm.frame_id(frame)].translation.copy()
    beams = beam_curves(clm, ramp_q[-1])
    update_kinematics(clm, q)
    point = clm.data.oMf[clm.frame_id(frame)].translation.copy()
    return DeflectionScene(
        frame=frame,
        q=readonly(q),
        wrench=readonly(np.zeros(6)),
        dq=readonly(dq),
        scale=s,
        auto_scaled=scale is None,
        size=size,
        max_displacement=d_max,
        q_deflected=readonly(ramp_q[-1]),
        point=readonly(point),
        point_deflected=readonly(point_deflected),
        frame_twist=readonly(frame_jacobian(clm, q, frame, "world") @ dq),
        compliance=None,
        ellipsoids=(),
        ramp=readonly(ramp),
        ramp_q=readonly(ramp_q),
        equilibrium=None,
        beams=beams,
        mode={"number": int(number), "frequency_hz": float(frequency)},
    )
