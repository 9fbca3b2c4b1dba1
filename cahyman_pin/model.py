"""CaHyMan as a :class:`closedloop.model.closed_loop.ClosedLoopModel`: build, assemble, read the
pose.

The model is built in memory from :mod:`cahyman_pin.urdf_builder` (URDF text parsed by
Pinocchio, closures and springs from the same builder), so a parameter sweep rebuilds it
without files. :func:`cahyman_model` caches one model per parameter set.

Inputs are alpha = (alpha_1, alpha_2, alpha_3) [rad] (leg cranks), alpha_4 [rad] (arm
elevation from x_p towards z_p) and s_4 [m] (telescope stroke, in [0, params.s4_max]).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from cahyman_pin import geometry
from cahyman_pin.params import DEFAULT_PARAMS, CaHyManParams
from cahyman_pin.urdf_builder import (
    FRAME_H,
    FRAME_M,
    LEGS,
    REVOLUTE_LIMIT,
    VIRTUAL_JOINTS,
    build_urdf,
    closed_form_values,
    closure_spec,
)
from closedloop.common.arrays import readonly, real_array
from closedloop.exceptions import InvalidInputError, OutsideLimitsError
from closedloop.kinematics.assembly import close_loops
from closedloop.kinematics.configuration import Configuration
from closedloop.kinematics.constraints import closure_residual, update_kinematics
from closedloop.kinematics.limits import describe_limits, joints_outside_limits
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.closures import closure_between_frames

#: Below this value of cos(phi) the plate normal is vertical and only theta + psi is
#: defined: :func:`paper_angles` then reports psi = 0 and theta = the yaw.
SINGULAR_COS_PHI = 1e-12


@dataclass(frozen=True)
class CaHyManPose:
    """Pose of the mobile plate and of the arm (arrays read-only, world frame, SI).

    Attributes:
        H: (3,) plate centre [m].
        R: (3, 3) plate orientation, world from plate (columns x_p, y_p, z_p).
        phi, theta, psi: the paper's angles [rad], R = Rz(theta) Ry(pi/2 - phi) Rz(psi);
            at phi = pi/2 (cos phi < ``SINGULAR_COS_PHI``) psi = 0 and theta is the yaw.
        s: (3,) strokes s_1..3 of the leg sliders [m].
        H_k: (3, 3) ball-joint centres, one leg per row [m].
        Q: (3,) arm pivot Q = H + HQ z_p [m].
        M: (3,) arm extremity M [m].
        R_M: (3, 3) orientation of the link carrying M (x axis along the arm direction w).
    """

    H: np.ndarray
    R: np.ndarray
    phi: float
    theta: float
    psi: float
    s: np.ndarray
    H_k: np.ndarray
    Q: np.ndarray
    M: np.ndarray
    R_M: np.ndarray

    def to_dict(self) -> dict:
        """JSON-ready dict (metres, radians)."""
        return {
            "H_m": self.H.tolist(),
            "R": self.R.tolist(),
            "phi_rad": self.phi,
            "theta_rad": self.theta,
            "psi_rad": self.psi,
            "s_m": self.s.tolist(),
            "M_m": self.M.tolist(),
        }


def paper_angles(R: np.ndarray) -> tuple[float, float, float]:
    """(phi, theta, psi) [rad] of a plate rotation R (3, 3) = Rz(theta) Ry(pi/2 - phi) Rz(psi).

    phi in [-pi/2, pi/2] (elevation of the plate normal), theta and psi in (-pi, pi].
    """
    cos_phi = float(np.hypot(R[0, 2], R[1, 2]))
    phi = float(np.arctan2(R[2, 2], cos_phi))
    if cos_phi < SINGULAR_COS_PHI:
        return phi, float(np.arctan2(R[1, 0], R[0, 0])), 0.0
    return phi, float(np.arctan2(R[1, 2], R[0, 2])), float(np.arctan2(R[2, 1], -R[2, 0]))


#: Overshoot of the stroke's ends, relative to s4_max, that is rounding of a computed stroke
#: (0.05 * 6 / 6 is one unit in the last place above 0.05): taken as the end itself.
STROKE_ROUNDING = 4.0 * np.finfo(float).eps


def check_inputs(alpha, alpha4, s4, p: CaHyManParams) -> tuple[np.ndarray, float, float]:
    """Validated (alpha (3,) [rad], alpha_4 [rad], s_4 [m]): finite, the angles within the
    joints' limits (+-``REVOLUTE_LIMIT``, one turn), the stroke within [0, s4_max] (a
    stroke beyond an end by rounding, ``STROKE_ROUNDING``, is that end).

    Raises:
        InvalidInputError: names the value and what was expected (an angle beyond one turn
            is most likely in degrees).
    """
    if (  # the common case, checked on Python floats without conversions (a comparison
        # with NaN is False, so NaN takes the general path, which names it)
        type(alpha) is np.ndarray
        and alpha.shape == (3,)
        and alpha.dtype == np.float64
        and isinstance(alpha4, float)
        and isinstance(s4, float)
        and abs(alpha4) <= REVOLUTE_LIMIT
        and 0.0 <= s4 <= p.s4_max
        and all(abs(a) <= REVOLUTE_LIMIT for a in alpha.tolist())  # False for NaN
    ):
        return alpha.copy(), float(alpha4), float(s4)
    alpha = np.array(alpha, dtype=float).reshape(-1)
    if alpha.shape != (3,) or not np.all(np.isfinite(alpha)):
        raise InvalidInputError(f"alpha must be 3 finite angles [rad], got {alpha.tolist()}")
    alpha4, s4 = np.asarray(alpha4, dtype=float), np.asarray(s4, dtype=float)
    if alpha4.size != 1 or not np.isfinite(alpha4).all():
        raise InvalidInputError(f"alpha_4 must be one finite angle [rad], got {alpha4.tolist()}")
    alpha4 = alpha4.reshape(())  # one value, given as [x] or x
    for name, value in (("alpha", alpha), ("alpha_4", alpha4)):
        if np.any(np.abs(value) > REVOLUTE_LIMIT):
            with np.errstate(over="ignore"):
                rad, deg = (
                    ", ".join(f"{v:.7g}" for v in np.ravel(x)) for x in (value, np.degrees(value))
                )
            raise InvalidInputError(
                f"{name} = ({rad}) rad = ({deg}) deg is beyond the joints' limits of one turn "
                "(+-2 pi rad, +-360 deg); the Python API takes radians, the command line degrees"
            )
    slack = STROKE_ROUNDING * p.s4_max
    if s4.size != 1 or not np.isfinite(s4).all():
        raise InvalidInputError(f"s_4 must be one finite stroke [m], got {s4.tolist()}")
    if not -slack <= s4.item() <= p.s4_max + slack:
        raise InvalidInputError(
            f"s_4 = {s4.item():.7g} m = {1e3 * s4.item():.7g} mm is outside the stroke "
            f"[0, {p.s4_max:.7g}] m = [0, {1e3 * p.s4_max:.7g}] mm (params.s4_max sets the "
            "stroke; the Python API takes metres, the command line millimetres)"
        )
    return alpha, float(alpha4), min(max(s4.item(), 0.0), p.s4_max)


def closed_form_pose(alpha, alpha4, s4, p: CaHyManParams = DEFAULT_PARAMS) -> CaHyManPose:
    """Pose from the closed-form geometry of :mod:`cahyman_pin.geometry` (no Pinocchio).

    Args:
        alpha: (3,) crank angles [rad]; alpha4: arm angle [rad]; s4: stroke [m].

    Raises:
        AssemblyError: the legs cannot carry the plate.
    """
    alpha, alpha4, s4 = check_inputs(alpha, alpha4, s4, p)
    pose = geometry.plate_pose(alpha, p)
    Q, M = geometry.extremity(pose, alpha4, s4, p)
    phi, theta, psi = paper_angles(pose.R)
    return CaHyManPose(
        H=readonly(pose.H),
        R=readonly(pose.R),
        phi=phi,
        theta=theta,
        psi=psi,
        s=readonly(pose.s),
        H_k=readonly(geometry.ball_centres(pose, p)),
        Q=readonly(Q),
        M=readonly(M),
        R_M=readonly(geometry.arm_rotation(pose.R, alpha4)),
    )


def build_closed_loop_model(p: CaHyManParams = DEFAULT_PARAMS) -> ClosedLoopModel:
    """ClosedLoopModel of CaHyMan for parameters ``p``, built in memory (no files); with
    ``p.links_as_beams`` the beams are inserted before the closures are built, so that the
    closure frames at their tips (coupler ends, H_k) follow the tips."""
    urdf = build_urdf(p)
    model = pin.buildModelFromXML(urdf)
    visual = pin.buildGeomFromUrdfString(model, urdf, pin.GeometryType.VISUAL)
    spec = closure_spec(p)
    springs, masses = spec.springs, {}
    if spec.beams:
        from closedloop.model.beams import apply_beams  # beam theory: with beams only

        model, (visual,), blocks, _, masses = apply_beams(model, [visual], spec.beams)
        springs = {**springs, **blocks}
    closures = [
        closure_between_frames(model, a, b, kind)
        for (a, b), kind in zip(spec.pairs, spec.types, strict=True)
    ]
    return ClosedLoopModel(
        model, closures, spec.actuated, springs, spec.locked, visual_model=visual,
        name="cahyman", beam_masses=masses,
    )  # fmt: skip


class CaHyManModel:
    """CaHyMan with Pinocchio: assembly, pose and inverse kinematics of the parallel base.

    Args:
        params: dimensions and springs (SI).

    Attributes:
        params: the parameters.
        clm: the :class:`ClosedLoopModel` (tree, 6 point closures, 5 actuated joints,
            12 springs).
    """

    def __init__(self, params: CaHyManParams = DEFAULT_PARAMS):
        if not isinstance(params, CaHyManParams):
            raise InvalidInputError(f"params must be a CaHyManParams, got {type(params).__name__}")
        self.params = params
        self.clm = build_closed_loop_model(params)
        self._q_index = {
            self.clm.model.names[j]: self.clm.model.joints[j].idx_q
            for j in range(1, self.clm.model.njoints)
        }
        # what the pose reads: frames H, M, Q, H_1..3 and the strokes s_1..3 in q
        names = (FRAME_H, FRAME_M, "Q", *(f"H_{k}" for k in LEGS))
        self._pose_frames = tuple(self.clm.frame_id(n) for n in names)
        self._stroke_index = np.array([self._q_index[f"s_{k}"] for k in LEGS])
        self._virtual_index = np.array([self._q_index[n] for n in VIRTUAL_JOINTS])

    def __repr__(self) -> str:
        return f"CaHyManModel({self.clm!r})"

    # --------------------------------------------------------------- configurations
    def initial_guess(self, alpha, alpha4, s4) -> np.ndarray:
        """(nq,) configuration from the closed-form geometry (undeformed springs).

        Raises:
            AssemblyError: the legs cannot carry the plate.
        """
        alpha, alpha4, s4 = check_inputs(alpha, alpha4, s4, self.params)
        return self.initial_guesses(alpha[None], np.array([alpha4]), np.array([s4]))[0]

    def initial_guesses(self, alpha, alpha4, s4) -> np.ndarray:
        """(n, nq) configurations from the closed-form geometry for n poses at once.

        Args:
            alpha: (n, 3) crank angles [rad]; alpha4: (n,) arm angles [rad]; s4: (n,)
                strokes [m]; checked by the caller (see :func:`check_inputs`).

        Raises:
            AssemblyError: the legs cannot carry the plate at some pose.
        """
        q = np.tile(pin.neutral(self.clm.model), (len(alpha), 1))
        for name, values in closed_form_values(alpha, alpha4, s4, self.params).items():
            i = self._q_index[name]
            q[:, i : i + values.shape[1]] = values
        return q

    def assemble(self, alpha, alpha4, s4, *, q0=None, full_output: bool = False,
                 jacobian: bool = False):  # fmt: skip
        """Assembled configuration for the inputs, springs at rest.

        Args:
            alpha: (3,) crank angles alpha_1..3 [rad].
            alpha4: arm angle [rad].
            s4: telescope stroke [m].
            q0: (nq,) warm start (e.g. a neighbouring pose); default: the closed-form
                guess, which picks the branch of the closed-form geometry.
            full_output: return the :class:`closedloop.kinematics.assembly.Assembly` (q, residual,
                iterations) instead of q.
            jacobian: with ``full_output``, the Assembly also holds the closure residuals
                and Jacobian at q (:attr:`closedloop.kinematics.assembly.Assembly.closure`).

        Returns:
            (nq,) read-only configuration q, or the Assembly.

        Raises:
            AssemblyError: unreachable inputs (message gives the residual reached).
            InvalidInputError: non-finite input, wrong count, s_4 outside its stroke.
        """
        alpha, alpha4, s4 = check_inputs(alpha, alpha4, s4, self.params)
        q0 = None if q0 is None else self.clm.check_configuration(q0)
        result = self.assemble_validated(np.array([*alpha.tolist(), alpha4, s4]), q0,
                                         jacobian=jacobian)  # fmt: skip
        return result if full_output else result.q

    def assemble_validated(self, inputs: np.ndarray, q0: np.ndarray | None = None, *,
                           jacobian: bool = False):  # fmt: skip
        """:meth:`assemble` (its :class:`closedloop.kinematics.assembly.Assembly`) of inputs and a
        start that the caller has checked: the sweeps validate a chunk's inputs at once.

        Args:
            inputs: (5,) alpha_1..3 [rad], alpha_4 [rad], s_4 [m], as :func:`check_inputs`
                accepts them.
            q0: (nq,) start, as
                :meth:`closedloop.model.closed_loop.ClosedLoopModel.check_configuration` returns it
                (finite, quaternion normalised; not modified), or None: the closed-form guess.
            jacobian: as :meth:`assemble`.

        Raises:
            AssemblyError: unreachable inputs.
        """
        if q0 is None:  # the guess of one pose, its inputs checked
            q = self.initial_guesses(inputs[None, :3], inputs[3:4], inputs[4:])[0]
        else:
            q = q0.copy()  # the start is the caller's
        q[self._virtual_index] = 0.0  # virtual springs at rest
        self.clm.set_actuated(q, inputs)
        return close_loops(self.clm, q, jacobian=jacobian)

    def require_within_limits(self, q) -> None:
        """:class:`OutsideLimitsError` when joints of an assembled configuration q (nq,),
        or of a :class:`closedloop.kinematics.configuration.Configuration` (its q checked
        already), are outside their limits
        (:func:`closedloop.kinematics.limits.joints_outside_limits`), in CaHyMan's words: its
        inputs are checked (:func:`check_inputs`) and the ``cahyman`` command has no way past
        the limits, hence no ``--no-limits`` hint.
        """
        q = q.q if isinstance(q, Configuration) else self.clm.check_configuration(q)
        bad = joints_outside_limits(self.clm, q)
        if bad:
            raise OutsideLimitsError(
                f"the pose assembles with joints outside their limits: {describe_limits(bad)}; "
                "CaHyMan is analysed within its joints' limits: choose another pose",
                bad,
            )

    def residual(self, q) -> float:
        """Infinity norm of the closure residual at q (nq,) [m]."""
        return float(np.max(np.abs(closure_residual(self.clm, self.clm.check_configuration(q)))))

    # ------------------------------------------------------------------------ pose
    def pose(self, q) -> CaHyManPose:
        """Plate and arm pose read from the assembled configuration q (nq,)."""
        q = self.clm.check_configuration(q)
        update_kinematics(self.clm, q)
        return self.pose_from(q, self.clm.data)

    def pose_from(self, q: np.ndarray, data: pin.Data) -> CaHyManPose:
        """:meth:`pose` from the frame placements of q (nq,) already in ``data`` (e.g. a
        :class:`closedloop.kinematics.configuration.Configuration`'s), without computing them
        again."""
        oMf, (plate, arm, pivot, *balls) = data.oMf, self._pose_frames
        plate, arm = oMf[plate], oMf[arm]
        R = readonly(plate.rotation)
        phi, theta, psi = paper_angles(R)
        return CaHyManPose(
            H=readonly(plate.translation),
            R=R,
            phi=phi,
            theta=theta,
            psi=psi,
            s=readonly(q[self._stroke_index]),
            H_k=readonly([oMf[k].translation for k in balls]),
            Q=readonly(oMf[pivot].translation),
            M=readonly(arm.translation),
            R_M=readonly(arm.rotation),
        )

    def inverse(self, z_H: float, phi: float, psi: float) -> np.ndarray:
        """Leg inputs for a plate height and tilt (closed form, the paper's branch).

        Args:
            z_H: plate-centre height [m]; phi: elevation of the plate normal [rad], in
                [0, pi/2] (pi/2 = level); psi: azimuth of the tilt [rad].

        Returns:
            (3,) crank angles alpha_1..3 [rad] in [-pi/2, pi/2].

        Raises:
            InvalidInputError: not three finite real numbers (strings, complex, None,
                sequences), phi outside [0, pi/2], psi beyond one turn (+-2 pi rad: most
                likely degrees).
            AssemblyError: a crank would have to reach beyond its length.
        """
        values = real_array([z_H, phi, psi], "z_H, phi, psi")
        if values.shape != (3,) or not np.all(np.isfinite(values)):
            raise InvalidInputError(
                f"z_H, phi, psi must be 3 finite numbers [m, rad, rad], got {values.tolist()}"
            )
        if not 0.0 <= values[1] <= 0.5 * np.pi:  # the closed form reads cos(phi) alone
            raise InvalidInputError(
                f"phi = {values[1]:.6g} rad = {np.rad2deg(values[1]):.6g} deg; expected the "
                "elevation of the plate normal in [0, pi/2] rad (pi/2: level; a tilt the "
                "other way is psi + pi)"
            )
        if abs(values[2]) > REVOLUTE_LIMIT:
            raise InvalidInputError(
                f"psi = {values[2]:.7g} rad = {np.rad2deg(values[2]):.7g} deg is beyond one turn "
                "(+-2 pi rad, +-360 deg); inverse() takes radians"
            )
        alpha = geometry.inverse_legs(*values, self.params)
        return readonly(alpha)


@functools.lru_cache(maxsize=32)
def cahyman_model(params: CaHyManParams = DEFAULT_PARAMS) -> CaHyManModel:
    """Cached :class:`CaHyManModel` for ``params`` (building a model costs milliseconds)."""
    return CaHyManModel(params)


__all__ = [
    "SINGULAR_COS_PHI",
    "CaHyManModel",
    "CaHyManPose",
    "build_closed_loop_model",
    "cahyman_model",
    "check_inputs",
    "closed_form_pose",
    "paper_angles",
]
