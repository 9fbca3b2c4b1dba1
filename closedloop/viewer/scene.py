"""What the deflection viewer draws, computed without any viewer: poses, scale, ellipsoids.

A wrench w = (f [N], n [N m]) acts at the origin of a frame, world axes. The joint
deflection dq (nv,) (tangent of q) is the linear one, ``G w`` of
:func:`closedloop.elastostatics.compliance.compliance`, or, with ``nonlinear=True``, the finite one
``difference(q, q_eq)`` of the static equilibrium q_eq of
:func:`closedloop.elastostatics.statics.solve_equilibrium` (a dead load followed from zero).

The deflected pose is drawn amplified link by link (:mod:`closedloop.viewer.motion`): each
joint body moves rigidly along its own twist xi_i = J_i dq amplified by s (the finite
displacement of the link for a nonlinear deflection), exp6(s xi_i) oMi(q), so that joints
stay together and closed loops stay closed to first order; the automatic s keeps the
largest drawn point displacement at most ``AUTO_FRACTION`` of the model size L and the
largest drawn link rotation at most ``ROTATION_CAP``. The model size L [m] is the diagonal
of the bounding box of the origins of all joints and frames at q.

With ``close_loops=True`` the amplified configuration integrate(q, s dq) is re-assembled
instead (:func:`closedloop.kinematics.assembly.assemble`: the spring and locked coordinates
keep their amplified values and the passive joints close the loops) and drawn by forward
kinematics: the loops close exactly, but a small rotation near the root is amplified at
every link beyond it.

Compliance ellipsoids: :mod:`closedloop.viewer.ellipsoids`; flexible links drawn bent:
:mod:`closedloop.viewer.beam_curves`.

Norms are taken without under- or overflow: a load of any finite magnitude gives the same
automatic picture; one whose deflection or ellipsoid is not a finite number (``--force
1.7e308 1.7e308 0``) is refused (InvalidInputError), and so is a given scale s that draws
s d_max larger than ``MAX_SHOWN_FRACTION`` L (``--scale 1e200``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import check_wrench, readonly
from closedloop.elastostatics.compliance import ComplianceResult
from closedloop.elastostatics.equilibrium import Equilibrium
from closedloop.elastostatics.query import ComplianceQuery
from closedloop.elastostatics.statics import solve_equilibrium
from closedloop.exceptions import InvalidInputError
from closedloop.kinematics.assembly import assemble
from closedloop.kinematics.configuration import accepts_configuration
from closedloop.kinematics.constraints import frame_jacobian, update_kinematics
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.viewer.beam_curves import BeamCurve, beam_curves
from closedloop.viewer.ellipsoids import Ellipsoid, wrench_ellipsoids
from closedloop.viewer.motion import (
    ROTATION_CAP,
    auto_scale,
    drawn_poses,
    finite_twists,
    frame_pose,
    largest_displacement,
    largest_rotation,
    link_twists,
    model_poses,
)

#: Number of poses of the load-ramp animation (load fractions 0 .. 1, evenly spaced).
ANIMATION_FRAMES = 25
#: Largest amplified point displacement s d_max a given scale may draw, per model size L
#: (the automatic one draws at most AUTO_FRACTION): beyond, the picture is of nothing, and
#: the drawing (float32 in the page) overflows.
MAX_SHOWN_FRACTION = 100.0


@dataclass(frozen=True)
class DeflectionScene:
    """The nominal and the amplified deflected pose under a wrench (arrays read-only).

    Attributes:
        frame: name of the loaded frame.
        q: (nq,) nominal (unloaded, assembled) configuration.
        wrench: (6,) (fx, fy, fz [N], nx, ny, nz [N m]), world axes, at the frame origin.
        dq: (nv,) joint deflection (tangent of q) [rad or m], not amplified.
        scale: amplification s (dimensionless).
        auto_scaled: True when s was chosen by :func:`closedloop.viewer.motion.auto_scale`.
        size: model size L [m] (:func:`model_size`).
        max_displacement: d_max [m], largest first-order point displacement under dq
            (origins of the joints and of the loaded frame), not amplified.
        max_rotation: w_max [rad], largest link rotation ``|w_i|`` of :attr:`twists`, not
            amplified.
        poses: (njoints, 4, 4) nominal joint placements oMi(q), world frame (0: the world).
        twists: (njoints, 6) twist xi_i of each joint body (v [m] of its point at the world
            origin, rotation vector w [rad]), world axes, not amplified
            (:mod:`closedloop.viewer.motion`).
        ramp_poses: (n, njoints, 4, 4) drawn joint placements for each load fraction t:
            exp6(s xi_i(t)) oMi(q) (with ``close_loops``: the forward kinematics of
            :attr:`ramp_q`).
        q_deflected: (nq,) integrate(q, s dq), the amplified configuration (re-assembled
            with ``close_loops``); drawn only with ``close_loops``.
        point: (3,) loaded frame origin at q [m], world frame.
        point_deflected: (3,) loaded frame origin as drawn at the full load [m], world frame.
        frame_twist: (6,) displacement of the loaded frame (translation of its origin [m],
            rotation vector [rad]), world axes, not amplified: the first-order J dq = C w if
            linear, the finite ``equilibrium.displacement`` if nonlinear.
        compliance: compliance at the loaded frame, world axes, at q.
        ellipsoids: translational (and, on request, rotational) compliance ellipsoids.
        ramp: (n,) load fractions of the animation, 0 .. 1.
        ramp_q: (n, nq) amplified configurations integrate(q, s dq(t)) for each fraction t.
        equilibrium: the nonlinear equilibrium under the full wrench, or None (linear).
        beams: the flexible links as drawn at the full load (:func:`beam_curves`; () without
            beams).
        mode: for a natural mode (:func:`mode_scene`; then no wrench, no compliance):
            {"number": its rank from the lowest (1), "frequency_hz": its frequency}; None
            for a deflection.
        reassembled: True when the drawn poses are the re-assembled :attr:`ramp_q`
            (``close_loops``), False when each link moves along its twist.
    """

    frame: str
    q: np.ndarray
    wrench: np.ndarray
    dq: np.ndarray
    scale: float
    auto_scaled: bool
    size: float
    max_displacement: float
    max_rotation: float
    poses: np.ndarray
    twists: np.ndarray
    ramp_poses: np.ndarray
    q_deflected: np.ndarray
    point: np.ndarray
    point_deflected: np.ndarray
    frame_twist: np.ndarray
    compliance: ComplianceResult | None
    ellipsoids: tuple[Ellipsoid, ...]
    ramp: np.ndarray
    ramp_q: np.ndarray
    equilibrium: Equilibrium | None
    beams: tuple[BeamCurve, ...] = ()
    mode: dict | None = None
    reassembled: bool = False

    @property
    def nonlinear(self) -> bool:
        """True when dq is the finite deflection of the nonlinear equilibrium."""
        return self.equilibrium is not None

    @property
    def poses_deflected(self) -> np.ndarray:
        """(njoints, 4, 4) drawn joint placements at the full load, world frame."""
        return self.ramp_poses[-1]

    def summary(self) -> str:
        """One line: amplification, largest displacement and rotation, model size."""
        how = "automatic" if self.auto_scaled else "given"
        kind = "nonlinear" if self.nonlinear else "linear"
        w_deg = np.rad2deg(self.max_rotation)
        return (
            f"deflection amplified x{self.scale:.4g} ({how}; {kind} deflection): largest "
            f"point displacement {self.max_displacement:.3e} m, shown as "
            f"{self.scale * self.max_displacement:.3e} m; largest link rotation "
            f"{w_deg:.3e} deg, shown as {self.scale * w_deg:.3g} deg (at most "
            f"{np.rad2deg(ROTATION_CAP):.3g} deg when automatic); model size {self.size:.3g} m"
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
            "max_rotation_rad": self.max_rotation,
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


def _check_finite(w: np.ndarray, **values) -> None:
    for name, value in values.items():
        if not np.all(np.isfinite(value)):
            raise InvalidInputError(
                f"load {w.tolist()} too large: the {name.replace('_', ' ')} overflows "
                "(not a finite number); give a smaller wrench"
            )


def _check_counts(scale, frames) -> None:
    if scale is not None and not (np.isfinite(scale) and scale >= 0.0):
        raise InvalidInputError(f"scale must be a finite number >= 0, got {scale!r}")
    if int(frames) != frames or frames < 2:
        raise InvalidInputError(f"frames must be an integer >= 2, got {frames!r}")


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
    query: ComplianceQuery | None = None,
) -> DeflectionScene:
    """Poses, amplification, ellipsoids and load ramp for a wrench at ``frame``.

    Args:
        clm: model with closures and springs (or a :class:`~closedloop.Configuration`, then no q).
        q: (nq,) assembled configuration (the unloaded pose, rest of the springs).
        frame: name of the loaded frame.
        wrench: (6,) (fx, fy, fz [N], nx, ny, nz [N m]), world axes, at the frame origin.
        scale: amplification s >= 0; None chooses it
            (:func:`closedloop.viewer.motion.auto_scale`).
        nonlinear: solve the static equilibrium at each load fraction
            (:func:`closedloop.elastostatics.statics.solve_equilibrium`) instead of the linear map.
        close_loops: draw the re-assembled amplified configurations (module docstring).
        rotational: also the rotational compliance ellipsoid.
        frames: number of poses of the load ramp (>= 2).
        check_limits: refuse a q outside the joints' limits (as
            :func:`closedloop.elastostatics.compliance.compliance`; False draws it as it is).
        query: the compliance of ``frame`` in world axes on ``clm`` with ``check_limits``,
            prepared once by a caller that draws many scenes of the frame
            (:class:`closedloop.elastostatics.query.ComplianceQuery`); default: made here.

    Raises:
        InvalidInputError: bad wrench, scale or frame count; a wrench whose deflection
            overflows; a scale that draws the deflection larger than
            ``MAX_SHOWN_FRACTION`` model sizes; a ``query`` of another model, frame, axes
            or limits rule.
        NameNotFoundError: unknown frame.
        MechanismError: a spring-free motion moves the frame.
        EquilibriumError: (nonlinear) no equilibrium on the branch of q.
        AssemblyError: (close_loops) the amplified spring deflections cannot be closed
            (a smaller scale can).
    """
    w = check_wrench(wrench)
    _check_counts(scale, frames)
    if query is None:
        query = ComplianceQuery(clm, frame, "world", check_limits=check_limits)
    elif (query.model, query.frame, query.axes) != (clm, frame, "world") or (
        query.check_limits != check_limits
    ):
        raise InvalidInputError(
            f"query {query!r} does not ask for frame {frame!r} of {clm.name!r} in world axes "
            f"with check_limits={check_limits}; expected the query of this scene"
        )
    res = query(q)
    q = res.q
    poses = model_poses(clm, q)
    ramp = np.linspace(0.0, 1.0, int(frames))
    if nonlinear:  # the whole wrench first: an EquilibriumError names it, not a fraction
        equilibrium = solve_equilibrium(clm, q, frame, w)
        solved = [solve_equilibrium(clm, q, frame, t * w) for t in ramp[1:-1]]
        solved = [*solved, equilibrium]
        steps = [np.zeros(clm.model.nv), *(e.joint_deflection for e in solved)]
        ramp_twists = [np.zeros((clm.model.njoints, 6))]
        ramp_twists += [finite_twists(poses, model_poses(clm, e.q)) for e in solved]
    else:
        dq_lin = res.joint_deflection(w)
        steps, equilibrium = [t * dq_lin for t in ramp], None
        with np.errstate(over="ignore", invalid="ignore"):
            xi = link_twists(clm, q, dq_lin)
        ramp_twists = [t * xi for t in ramp]
    dq, twists = steps[-1], ramp_twists[-1]
    size = model_size(clm, q)
    with np.errstate(over="ignore", invalid="ignore"):
        twist = frame_jacobian(clm, q, frame, "world") @ dq
        if equilibrium is not None:  # the finite displacement, not the first-order one
            twist = equilibrium.displacement
        d_max = largest_displacement(clm, q, frame, dq)
    _check_finite(w, joint_deflection=dq, frame_displacement=twist, largest_displacement=d_max)
    w_max = largest_rotation(twists)
    s = auto_scale(size, d_max, w_max) if scale is None else float(scale)
    if s * d_max > MAX_SHOWN_FRACTION * size:
        raise InvalidInputError(
            f"--scale {s:g} draws the largest point displacement {d_max:.3g} m as "
            f"{s * d_max:.3g} m, more than {MAX_SHOWN_FRACTION:g} model sizes ({size:.3g} m); "
            f"expected a scale of at most {MAX_SHOWN_FRACTION * size / d_max:.3g} (or none: "
            "automatic)"
        )
    ramp_q = [pin.integrate(clm.model, q, s * v) for v in steps]
    reassembled = bool(close_loops and clm.closures)
    if reassembled:
        ramp_q = [assemble(clm, None, q_s).q for q_s in ramp_q]
        ramp_poses = [model_poses(clm, q_s) for q_s in ramp_q]
    else:
        ramp_poses = [drawn_poses(poses, xi, s) for xi in ramp_twists]
    update_kinematics(clm, q)
    ellipsoids = wrench_ellipsoids(res, w, s, size, rotational)
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
        max_rotation=w_max,
        poses=readonly(poses),
        twists=readonly(twists),
        ramp_poses=readonly(np.array(ramp_poses)),
        q_deflected=readonly(ramp_q[-1]),
        point=res.point,
        point_deflected=readonly(_frame_origin(clm, ramp_poses[-1], frame)),
        frame_twist=readonly(twist),
        compliance=res,
        ellipsoids=ellipsoids,
        ramp=readonly(ramp),
        ramp_q=readonly(np.array(ramp_q)),
        equilibrium=equilibrium,
        beams=beam_curves(clm.model, ramp_poses[-1]),
        reassembled=reassembled,
    )


def _frame_origin(clm: ClosedLoopModel, poses: np.ndarray, frame: str) -> np.ndarray:
    """(3,) origin [m], world frame, of ``frame`` with the joints at ``poses``."""
    return frame_pose(clm.model, poses, clm.frame_id(frame))[:3, 3].copy()


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
    """A natural mode as a scene: each link swinging harmonically along its twist between
    -s and +s times the shape's (the animation, played back and forth), drawn at +s.

    Args:
        clm: the model; q: (nq,) the configuration of the modes
            (:attr:`closedloop.analysis.vibration.ModesResult.q`).
        shape: (nv,) the mode shape (joint deflections per unit modal amplitude).
        frequency: its natural frequency [Hz], for the legend; number: its rank (1: the
            lowest).
        frame: the frame whose origin counts among the displaced points.
        scale: amplification s >= 0 of the shape; None chooses it
            (:func:`closedloop.viewer.motion.auto_scale`).
        frames: number of poses of the swing (>= 2).

    Raises:
        InvalidInputError: bad scale or frame count, a shape that is not (nv,) finite.
    """
    _check_counts(scale, frames)
    dq = np.asarray(shape, dtype=float)
    if dq.shape != (clm.model.nv,) or not np.all(np.isfinite(dq)):
        raise InvalidInputError(f"mode shape of shape {dq.shape}; expected ({clm.model.nv},)")
    q = clm.check_configuration(q)
    size = model_size(clm, q)
    poses, twists = model_poses(clm, q), link_twists(clm, q, dq)
    d_max, w_max = largest_displacement(clm, q, frame, dq), largest_rotation(twists)
    s = auto_scale(size, d_max, w_max) if scale is None else float(scale)
    ramp = np.sin(np.linspace(-0.5 * np.pi, 0.5 * np.pi, int(frames)))  # harmonic
    ramp_q = np.array([pin.integrate(clm.model, q, s * t * dq) for t in ramp])
    ramp_poses = np.array([drawn_poses(poses, twists, s * t) for t in ramp])
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
        max_rotation=w_max,
        poses=readonly(poses),
        twists=readonly(twists),
        ramp_poses=readonly(ramp_poses),
        q_deflected=readonly(ramp_q[-1]),
        point=readonly(point),
        point_deflected=readonly(_frame_origin(clm, ramp_poses[-1], frame)),
        frame_twist=readonly(frame_jacobian(clm, q, frame, "world") @ dq),
        compliance=None,
        ellipsoids=(),
        ramp=readonly(ramp),
        ramp_q=readonly(ramp_q),
        equilibrium=None,
        beams=beam_curves(clm.model, ramp_poses[-1]),
        mode={"number": int(number), "frequency_hz": float(frequency)},
    )
