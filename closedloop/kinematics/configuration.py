"""A configuration of a closed-loop model: the state every analysis works on.

In the manner of pink's and mink's ``Configuration``: one object a configuration, with
a Pinocchio Data of its own (never shared, so configurations can be used from several
threads at once; taken from the model's pool of workspaces and given back when the
configuration is gone), a read-only q, and the kinematics computed once at construction:
joint placements and Jacobians, frame placements, the closure residual (checked once
against :data:`CLOSURE_TOL`). Jacobians are computed on first use and kept.

The closure residual is judged unit-free: metres are divided by the characteristic
length L of the mechanism (:attr:`ClosedLoopModel.length`), radians are taken as they
are. It is judged only where the kinematics resolve it: Pinocchio places every joint from
the world origin, so the residual, a difference of two anchors so placed, is known to
about eps times their distance from the origin (:func:`residual_rounding`); coordinates
that put the joints so far away that this exceeds the tolerance close no loop (sliders
3e17 L out gave a residual of exactly 0 on a loop open by 0.65 L).
"""

from __future__ import annotations

import functools
import math
import operator

import numpy as np
import pinocchio as pin

from closedloop.common.arrays import frozen
from closedloop.common.conditioning import check_length
from closedloop.exceptions import InvalidInputError, OpenLoopError, OutsideLimitsError
from closedloop.kinematics.constraints import frame_jacobian_rows, jacobian_rows, residual_rows
from closedloop.kinematics.limits import degrees_hint, describe_limits, joints_outside_limits
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.closures import check_name

#: Largest scaled closure residual (infinity norm: metres / L, radians) at which a
#: configuration counts as closed: the tolerance of the compliance, the statics and the
#: command line alike. Values typed with 7 significant digits close a loop to about 1e-7
#: of its size; the first-order error of a compliance at such a configuration is of the
#: same relative size.
CLOSURE_TOL = 1e-6


def joint_reach(model: ClosedLoopModel, Q: np.ndarray) -> np.ndarray | float:
    """(...,) bound of the distance [m] of every joint origin and closure anchor from the
    world origin at the configurations Q (..., nq): the lengths of all joint placements,
    plus the largest anchor offset, plus the absolute values of the translational
    coordinates of q (prismatic joints, the position of a free flyer). A float for one q.
    """
    offset, translational = model.memo("joint_reach", _reach_terms, model)
    if Q.ndim == 1:  # one configuration (every query): Python floats, inf past the range
        return offset + sum(map(abs, Q[translational].tolist()))
    with np.errstate(over="ignore"):  # beyond the float range: inf, refused
        return offset + np.abs(Q[..., translational]).sum(axis=-1)


def _reach_terms(model: ClosedLoopModel) -> tuple[float, np.ndarray]:
    """(the placements' part of :func:`joint_reach` [m], the indices of the translational
    coordinates of q: per joint those of :attr:`ClosedLoopModel.linear_coordinates`, the
    leading ones of a joint with a quaternion or unit complex number, all of its q when
    they do not lead)."""
    pm = model.model
    anchors = [p for c in model.closures
               for p in (c.constraint.joint1_placement, c.constraint.joint2_placement)]  # fmt: skip
    offset = sum(np.linalg.norm(M.translation) for M in pm.jointPlacements)
    offset += max((np.linalg.norm(M.translation) for M in anchors), default=0.0)
    indices = []
    for j in range(1, pm.njoints):  # 0: the universe
        jm = pm.joints[j]
        linear = model.linear_coordinates[jm.idx_v : jm.idx_v + jm.nv]
        lead = int(np.cumprod(linear).sum())
        if jm.nq == jm.nv:
            indices += (jm.idx_q + np.flatnonzero(linear)).tolist()
        else:
            indices += range(jm.idx_q, jm.idx_q + (jm.nq if linear[lead:].any() else lead))
    return float(offset), frozen(np.array(indices, dtype=int))


def require_within_limits(model: ClosedLoopModel, q: np.ndarray) -> None:
    """:class:`OutsideLimitsError` when joints of q (nq,) are outside their position limits,
    by the rule of :func:`closedloop.kinematics.limits.joints_outside_limits` (joints without
    limits, continuous joints and unbounded limits are never out; an angle that the assembly may
    wind, a revolute joint that is not actuated, counts by its placement). The message
    names each joint, its value and its limits, and asks "degrees?" when a revolute value
    exceeds 2 pi in magnitude.
    """
    # every coordinate within the model's limits as they are now (a comparison of Python
    # floats, cheaper than the rule's index sets for a few joints): inside by the rule
    lower, upper = model.memo("position_limits", _position_limits, model.model)
    lower, values, upper = lower.tolist(), q.tolist(), upper.tolist()
    if all(map(operator.le, lower, values)) and all(map(operator.le, values, upper)):
        return
    bad = joints_outside_limits(model, q)
    if not bad:
        return
    raise OutsideLimitsError(
        f"configuration of {model.name!r} outside the joint limits: {describe_limits(bad)}"
        f"{degrees_hint(model, bad, 'q is')}; to query it anyway: check_limits=False "
        "(command line: --no-limits)",
        bad,
    )


def checked_configuration(model: ClosedLoopModel, q, check_limits: bool = True) -> np.ndarray:
    """(nq,) read-only copy of q, checked (:meth:`ClosedLoopModel.check_configuration`:
    finite, quaternions normalised) and, with ``check_limits``, inside the joints'
    limits (:func:`require_within_limits`)."""
    q = model.check_configuration(q)
    q.setflags(False)  # write=False (positional: half the cost)
    if check_limits:
        require_within_limits(model, q)
    return q


def _position_limits(model: pin.Model) -> tuple[np.ndarray, np.ndarray]:
    """(nq,) views of the model's lower and upper position limits (a new value written
    into them is seen)."""
    return model.lowerPositionLimit, model.upperPositionLimit


#: The residual of a configuration without closures: (0,), read-only.
_NO_RESIDUAL = frozen(np.empty(0))


def residual_rounding(model: ClosedLoopModel, Q: np.ndarray, length: float) -> np.ndarray | float:
    """(...,) bound of the rounding of the scaled closure residual at the configurations Q
    (..., nq), at length L [m]: each joint placement composed from the world origin errs by
    eps times the distance (:func:`joint_reach`), and a chain has at most njoints of them.
    A float for one q."""
    factor = model.memo("reach_rounding", _rounding_factor, model.model)
    return factor * joint_reach(model, Q) / length


def _rounding_factor(model: pin.Model) -> float:
    """eps per joint placement composed from the world origin, njoints of them."""
    return model.njoints * float(np.finfo(float).eps)


def closure_state(
    model: ClosedLoopModel, data: pin.Data, constraint_datas, q: np.ndarray, length: float
) -> tuple[np.ndarray, float, float, float]:
    """The closure residual of a model with closures at q (nq,), checked, whose joint
    placements are in ``data`` (``constraint_datas``: its workspace's), at length L [m]:
    the (m,) read-only residual [m; m, rad], its infinity norm [m, rad], the scaled one
    (metres / L, radians: :attr:`Configuration.closure_error`) and the bound of its
    rounding (:func:`residual_rounding`). The loops are closed when both of the last two
    are within :data:`CLOSURE_TOL` (module docstring)."""
    r = frozen(residual_rows(model, data, constraint_datas))
    rounding = residual_rounding(model, q, length)
    values = r.tolist()  # a few rows: Python floats cost less than numpy's calls
    if math.isfinite(sum(values)):  # (a NaN would pass Python's max unseen)
        norm = max(map(abs, values))
    else:
        norm = float(abs(r).max())
    if model.memo("metre_rows", model.linear_rows.all):  # a factor keeps the maximum
        error = norm / length
    else:
        error = float((abs(r) * _row_scale(model, length)).max())
    return r, norm, error, rounding


def _row_scale(model: ClosedLoopModel, length: float) -> np.ndarray:
    """(m,) scale of the residual rows at length L [m]: 1 / L for metres, 1 for radians
    (once per model and L)."""
    rows = model.linear_rows
    return model.memo(("row_scale", length), lambda: np.where(rows, 1.0 / length, 1.0))


class Configuration:
    """Configuration q of a :class:`ClosedLoopModel`, kinematics computed once.

    Args:
        model: the model with closures and springs.
        q: (nq,) configuration [rad, m; quaternions for spherical and free-flyer joints,
            of norm 1 to ``closedloop.model.coordinates.UNIT_NORM_TOL`` (1e-6; InvalidInputError
            beyond)].
        length: characteristic length L [m] (default: ``model.length``, the diameter of
            the joint origins and frames at the neutral configuration).
        check_limits: refuse a q with joints outside their position limits
            (:func:`require_within_limits`, :class:`OutsideLimitsError`; an angle typed in
            degrees is the usual cause). False: take q as it is (a pose the robot is meant
            to be analysed at beyond its stops, a deflected equilibrium).

    Raises:
        OutsideLimitsError: ``check_limits`` and joints of q outside their limits.
        InvalidInputError: q not (nq,) finite, quaternions not of norm 1, bad length.

    Attributes:
        model: the :class:`ClosedLoopModel`.
        q: (nq,) read-only configuration, its quaternions and unit complex numbers
            normalised.
        data: this configuration's own :class:`pinocchio.Data` (kinematics of q), valid
            while the configuration lives (it then goes back to the model's pool).
        length: characteristic length L [m].
        residual: (m,) read-only closure residual [m for points; m, rad for welds], in the
            axes of each closure's side-1 anchor (Pinocchio's convention).
        residual_norm: infinity norm of :attr:`residual` [m, rad].
        closure_error: scaled residual, infinity norm (metres / L, radians).
    """

    def __init__(
        self,
        model: ClosedLoopModel,
        q,
        *,
        length: float | None = None,
        check_limits: bool = True,
    ):
        if not isinstance(model, ClosedLoopModel):
            raise InvalidInputError(
                f"expected a ClosedLoopModel (closedloop.load_model), got {type(model).__name__}"
            )
        self.model = model
        self.q = q = checked_configuration(model, q, check_limits)
        pm = model.model
        self.data, self._constraint_datas = data, datas = model.acquire_workspace()
        pin.computeJointJacobians(pm, data, q)
        pin.updateFramePlacements(pm, data)
        self.length = model.length if length is None else check_length(length)
        if model.closures:  # the residual, its norms and the bound of its rounding
            closure = closure_state(model, data, datas, q, self.length)
            self.residual, self.residual_norm, self.closure_error, self._rounding = closure
        else:  # a serial robot closes no loop: no residual, no rounding of it
            self.residual, self.residual_norm, self.closure_error = _NO_RESIDUAL, 0.0, 0.0
            self._rounding = 0.0

    _closure_jacobian: np.ndarray | None = None  # computed on first use (per configuration)
    _frame_jacobians: dict | None = None

    def __copy__(self) -> Configuration:
        """A new configuration of the same model and q, with a workspace of its own (two
        configurations never share a pinocchio Data)."""
        return Configuration(self.model, self.q, length=self.length, check_limits=False)

    def __deepcopy__(self, memo: dict) -> Configuration:
        """As :meth:`__copy__`: the model is shared, not copied (it is not changed by a
        configuration), and q is copied."""
        return self.__copy__()

    def __del__(self) -> None:
        # the workspace goes back to the model's pool (not shared while this one lives)
        data = self.__dict__.get("data")
        if data is not None:
            self.model.release_workspace((data, self._constraint_datas))

    @property
    def is_closed(self) -> bool:
        """True when :attr:`closure_error` is within :data:`CLOSURE_TOL` (and resolved to
        it: the rounding of the residual is within it too, module docstring)."""
        return self.closure_error <= CLOSURE_TOL and self._rounding <= CLOSURE_TOL

    def require_closed(self) -> Configuration:
        """This configuration, or :class:`OpenLoopError` if it does not close the loops (or
        its residual is not resolved to :data:`CLOSURE_TOL`: the error's ``residual`` is
        then the bound of its rounding, :func:`residual_rounding`)."""
        if not self.closure_error <= CLOSURE_TOL:
            worst = self._closure_of_row(int(np.argmax(np.abs(self._scaled_residual()))))
            raise OpenLoopError(
                f"configuration does not close the loops of {self.model.name!r}: scaled "
                f"residual {self.closure_error:.3e} at closure {worst!r} (metres per "
                f"characteristic length L = {self.length:.4g} m, radians) exceeds "
                f"{CLOSURE_TOL:g}; assemble it first (closedloop.assemble)",
                self.closure_error,
                CLOSURE_TOL,
            )
        if self._rounding > CLOSURE_TOL:
            reach = float(joint_reach(self.model, self.q))
            raise OpenLoopError(
                f"configuration of {self.model.name!r} places its joints up to {reach:.3g} m "
                f"from the world origin (q's translational coordinates): there the closure "
                f"residual is known to {self._rounding:.1e} only (metres per characteristic "
                f"length L = {self.length:.4g} m), above {CLOSURE_TOL:g}; expected joints "
                f"within {reach * CLOSURE_TOL / self._rounding:.3g} m of the origin",
                self._rounding,
                CLOSURE_TOL,
            )
        return self

    def _row_scale(self) -> np.ndarray:
        """(m,) scale of the residual rows: 1 / L for metres, 1 for radians."""
        return _row_scale(self.model, self.length)

    def _scaled_residual(self) -> np.ndarray:
        """(m,) residual with its metres divided by the length L (radians as they are)."""
        return self.residual * self._row_scale()

    def _closure_of_row(self, row: int) -> str:
        for c in self.model.closures:
            if row < c.size:
                return c.name
            row -= c.size
        raise IndexError(row)

    def closure_jacobian(self) -> np.ndarray:
        """(m, nv) read-only Jacobian of :attr:`residual` with respect to the tangent of q."""
        if self._closure_jacobian is None:
            Jc = jacobian_rows(self.model, self.data, self._constraint_datas, calc=False)
            self._closure_jacobian = frozen(Jc)
        return self._closure_jacobian

    def frame_jacobian(self, frame: str, axes: str = "world") -> np.ndarray:
        """(6, nv) read-only Jacobian of ``frame``: twist (v [m/s], w [rad/s]) at its origin.

        Args:
            frame: frame name.
            axes: ``"world"`` (world-aligned axes) or ``"local"`` (the frame's own axes).
        """
        check_name("frame", frame)  # before the cache, which hashes it
        key = (frame, axes)
        if self._frame_jacobians is None:
            self._frame_jacobians = {}
        if key not in self._frame_jacobians:
            self._frame_jacobians[key] = frozen(
                frame_jacobian_rows(self.model, self.data, frame, axes)
            )
        return self._frame_jacobians[key]

    def frame_placement(self, frame: str) -> pin.SE3:
        """Placement (copy) of ``frame`` in the world at q."""
        return self.data.oMf[self.model.frame_id(frame)].copy()

    def __repr__(self) -> str:
        return (
            f"Configuration({self.model.name!r}, nq={self.q.size}, "
            f"closure_error={self.closure_error:.2e}, length={self.length:.4g} m)"
        )


def as_configuration(
    model, q=None, *, length: float | None = None, check_limits: bool = True
) -> Configuration:
    """A :class:`Configuration` from a configuration, or from a model and q (nq,)
    (``check_limits`` as for :class:`Configuration`, with a model).

    Raises:
        InvalidInputError: q or ``length`` given with a configuration (it has its own), or
            no q with a model.
    """
    if isinstance(model, Configuration):
        if q is not None or length is not None:
            raise InvalidInputError(
                "q and length belong to the Configuration; give them to Configuration(...)"
            )
        return model
    if q is None:
        raise InvalidInputError("a configuration q (nq,) is needed with a ClosedLoopModel")
    return Configuration(model, q, length=length, check_limits=check_limits)


def accepts_configuration(func):
    """Let ``func(model, q, *args)`` also be called as ``func(state, *args)``.

    A :class:`Configuration` in first place is replaced by its model and its q, so that
    every function written for ``(model, q)`` works on the state object.
    """

    @functools.wraps(func)
    def wrapper(model, *args, **kwargs):
        if isinstance(model, Configuration):
            return func(model.model, model.q, *args, **kwargs)
        return func(model, *args, **kwargs)

    return wrapper
