"""The prepared compliance query, and the kernel of the unloaded compliance it shares with
:func:`closedloop.compliance`.

A query of one frame repeated at many configurations (a path, a compensation loop, a
design optimisation, a fit) pays each time for what does not change between calls: the
frame's index and axes, the characteristic length L of the unit-free rules, the scaling
of the model at L with the partition of its coordinates into sprung, passive and locked
ones and the spring factor of the fast paths
(:func:`closedloop.elastostatics.partition.model_scaling`). :class:`ComplianceQuery`
resolves these once::

    query = cl.ComplianceQuery(robot, "tool0")
    results = [query(q) for q in path]      # each as cl.compliance(robot, q, "tool0")

and each call checks what protects its caller, once, at the boundary: q is made a
:class:`closedloop.kinematics.configuration.Configuration` (finite, quaternions of norm 1,
inside the joints' limits unless ``check_limits=False``, the closure residual judged
unit-free), the rank rule decides the rank, the result's arrays are read-only. Nothing
below it checks q again.

:func:`closedloop.elastostatics.compliance.compliance` is the same query made on the spot
on the model's plan of the frame, axes, path and length (:func:`query_plan`, kept by the
model): the two take the same path through the same operations, and give the same result to
the last bit.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from closedloop.common.conditioning import (
    FINITE_BOUND,
    check_length,
    factor_rank,
    spectrum_from_factor,
)
from closedloop.elastostatics.partition import (
    kinematic_factor,
    model_scaling,
    partition,
    passive_motion,
)
from closedloop.elastostatics.springs import check_path, spring_factor
from closedloop.elastostatics.unloaded import (
    ComplianceResult,
    FastFields,
    compliance_result,
    fast_result,
)
from closedloop.exceptions import InvalidInputError
from closedloop.kinematics.configuration import (
    CLOSURE_TOL,
    Configuration,
    checked_configuration,
    closure_state,
    joint_reach,
)
from closedloop.kinematics.constraints import jacobian_rows, reference_frame
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.closures import check_name


class ComplianceQuery:
    """The compliance of one frame of a model, prepared for many configurations.

    ``query(q)`` equals ``closedloop.compliance(model, q, frame, axes, length=length,
    path=path, check_limits=check_limits)`` to the last bit (module docstring); what does
    not depend on q is resolved when the query is made.

    A query holds no state of a call: each call computes in a workspace of its own (a
    :class:`closedloop.kinematics.configuration.Configuration`), so several threads may
    call one query, or queries of one model, at once.

    Args:
        model: the model with closures and springs.
        frame: name of the loaded frame; the reference point is its origin.
        axes: ``"world"`` (world-aligned axes, default) or ``"local"`` (the frame's own).
        length: characteristic length L [m] of the unit-free rules (default: the
            model's, :attr:`closedloop.model.closed_loop.ClosedLoopModel.length`).
        path: ``"auto"`` (default: the serial or partitioned fast path where it applies)
            or ``"null-space"`` (the general path); the path taken is in each result.
        check_limits: refuse a q outside the joints' position limits (default;
            :class:`closedloop.exceptions.OutsideLimitsError`); False takes q as it is.

    Raises:
        InvalidInputError: ``model`` is not a :class:`ClosedLoopModel`, the frame name not a
            str, bad axes, path or length, or a model without any moving joint (nv = 0).
        NameNotFoundError: unknown frame.
    """

    __slots__ = ("_check_limits", "_model", "_plan")

    def __init__(
        self,
        model: ClosedLoopModel,
        frame: str,
        axes: str = "world",
        *,
        length: float | None = None,
        path: str = "auto",
        check_limits: bool = True,
    ):
        if not isinstance(model, ClosedLoopModel):
            raise InvalidInputError(
                f"expected a ClosedLoopModel (closedloop.load_model), got {type(model).__name__}"
            )
        self._model, self._check_limits = model, check_limits
        self._plan = query_plan(model, frame, axes, path, length)

    # what was resolved, read-only
    model = property(lambda self: self._model, doc="The model.")
    frame = property(lambda self: self._plan.frame, doc="Name of the loaded frame.")
    axes = property(
        lambda self: self._plan.axes, doc='Axes of the results, ``"world"`` or ``"local"``.'
    )
    path = property(lambda self: self._plan.path, doc='``"auto"`` or ``"null-space"``.')
    length = property(
        lambda self: self._plan.length, doc="Characteristic length L [m] of the results."
    )
    check_limits = property(lambda self: self._check_limits, doc="Whether q's limits are checked.")

    def __call__(self, q) -> ComplianceResult:
        """The compliance of the frame at q.

        Args:
            q: (nq,) assembled configuration [rad, m; quaternions of norm 1]
                (:func:`closedloop.assemble`).

        Returns:
            The :class:`ComplianceResult` at the frame's origin, in the query's axes (the
            plain query's, :func:`closedloop.compliance`).

        Raises:
            InvalidInputError: q is not (nq,) finite real numbers (quaternions of norm 1).
            OutsideLimitsError: ``check_limits`` and joints of q outside their limits.
            OpenLoopError: q does not close the loops (tolerance ``CLOSURE_TOL``).
            MechanismError: a spring-free motion moves the frame (no static equilibrium).
            SingularConfigurationError: the compliance overflows; on the null-space path,
                springs too far apart (as :func:`closedloop.compliance`).
        """
        return self._plan.query(self._model, q, self._check_limits)

    def __repr__(self) -> str:
        return (
            f"ComplianceQuery({self.model.name!r}, {self.frame!r}, axes={self.axes!r}, "
            f"length={self.length:.4g} m, path={self.path!r}, check_limits={self.check_limits})"
        )


class _Plan:
    """What a compliance of one frame, axes, path and length resolves before any
    configuration (:func:`query_plan`), and the kernel that computes it at one: the frame's
    index and Pinocchio reference frame, the model's scaling at L
    (:func:`closedloop.elastostatics.partition.model_scaling`), whether the path is serial
    whatever the configuration, and whether that path can overflow. It holds no reference
    to the model (a model keeps its plans)."""

    __slots__ = (
        "_bounded", "_fid", "_fields", "_partitioned", "_reference", "_scaling", "_serial",
        "axes", "frame", "length", "path",
    )  # fmt: skip

    def __init__(self, model: ClosedLoopModel, frame: str, axes: str, path: str, length):
        check_name("frame", frame)
        check_path(path)
        self._reference = reference_frame(axes)
        self._fid = model.frame_id(frame)
        if model.model.nv == 0:  # pin.getFrameJacobian crashes the interpreter on nv = 0
            raise InvalidInputError(
                f"model {model.name!r} has no moving joint (nv = 0): frame {frame!r} cannot "
                "move, there is no compliance to compute; give the model joints (or springs)"
            )
        self.frame, self.axes, self.path = frame, axes, path
        self.length = model.length if length is None else check_length(length)
        sc = self._scaling = model_scaling(model, self.length)
        # neither closures nor passive joints: the serial path, whatever the configuration
        self._serial = path == "auto" and not model.closures and not sc.passive.size
        self._serial = self._serial and sc.sprung.size > 0
        self._bounded = self._serial and _bounded(model, self._fid, sc, self.length)
        # closures with as many rows as passive coordinates or more, and springs: the
        # partitioned path is tried first (partition)
        m = sum(c.size for c in model.closures)
        self._partitioned = path == "auto" and m >= sc.passive.size > 0 and sc.sprung.size > 0
        # what the fast paths' results take from the plan
        self._fields = {
            taken: FastFields(frame, axes, self.length, taken, sc.sigma.size, self._fid,
                              sc.scales)
            for taken in ("serial", "partitioned")
        }  # fmt: skip

    def query(self, model: ClosedLoopModel, q, check_limits: bool) -> ComplianceResult:
        """The compliance at q (nq,) of ``model`` (the plan's), q checked here, once
        (:class:`ComplianceQuery`).

        A serial robot's q is checked
        (:func:`closedloop.kinematics.configuration.checked_configuration`) and its
        kinematics computed in a workspace of the model's pool
        (:meth:`ClosedLoopModel.acquire_workspace`), without the closure residual, frame
        placements and Jacobians that a configuration keeps and the serial path does not
        read; so is a mechanism's on the partitioned path (:meth:`_partitioned_at`), with
        its closure residual judged as a configuration's. Otherwise (other models, loops
        that do not close, a partition that does not hold) q is made a
        :class:`Configuration`, which must close the loops.
        """
        if self._serial:
            q = checked_configuration(model, q, check_limits)
            workspace = model.acquire_workspace()
            try:
                pin.computeJointJacobians(model.model, workspace[0], q)
                return self._serial_at(model, workspace[0], q)
            finally:
                model.release_workspace(workspace)
        if self._partitioned:
            result = self._partitioned_at(model, checked_configuration(model, q, check_limits))
            if result is not None:
                return result
        state = Configuration(model, q, length=self.length, check_limits=check_limits)
        return self.at(state.require_closed())

    @np.errstate(over="ignore", invalid="ignore")  # overflows: the result's typed error
    def _partitioned_at(self, model: ClosedLoopModel, q: np.ndarray) -> ComplianceResult | None:
        """The partitioned path at q (nq,), checked, in a workspace of the model's pool:
        the kinematics, the closure residual and its rounding judged as a
        :class:`Configuration` judges them
        (:func:`closedloop.kinematics.configuration.closure_state`), the closure Jacobian
        and :func:`closedloop.elastostatics.partition.passive_motion`, the operations of
        :meth:`at` on the configuration. None when the loops do not close or the partition
        does not hold (the configuration then raises its error, or the null-space path
        decides)."""
        data, datas = workspace = model.acquire_workspace()
        try:
            pin.computeJointJacobians(model.model, data, q)
            _, norm, error, rounding = closure_state(model, data, datas, q, self.length)
            if not (error <= CLOSURE_TOL and rounding <= CLOSURE_TOL):
                return None
            X = passive_motion(jacobian_rows(model, data, datas, calc=False), self._scaling)
            if X is None:
                return None
            J = self._jacobian(model, data)
            return self._fast(model, data, q, norm, J, "partitioned", X)
        finally:
            model.release_workspace(workspace)

    def _jacobian(self, model: ClosedLoopModel, data: pin.Data) -> np.ndarray:
        """(6, nv) Jacobian of the frame, in the plan's axes, from the joint Jacobians in
        ``data``."""
        J = pin.getFrameJacobian(model.model, data, self._fid, self._reference)
        return J.reshape(6, 1) if J.ndim == 1 else J  # a one-dof model gives a (6,) vector

    def at(self, state: Configuration) -> ComplianceResult:
        """The compliance at a closed configuration of the model at the plan's length (not
        checked again: :class:`ComplianceQuery` and :func:`closedloop.compliance` make and
        check it)."""
        if self._serial:
            return self._serial_at(state.model, state.data, state.q)
        return self._guarded(state, self._jacobian(state.model, state.data))

    def _serial_at(self, model: ClosedLoopModel, data: pin.Data, q: np.ndarray):
        """The serial path at q (checked), whose joint Jacobians and placements are in
        ``data``."""
        J = self._jacobian(model, data)
        if self._bounded:  # nothing overflows: numpy's error state as it is
            return self._fast(model, data, q, 0.0, J, "serial", None)
        with np.errstate(over="ignore", invalid="ignore"):  # overflows: the typed error
            return self._fast(model, data, q, 0.0, J, "serial", None)

    @np.errstate(over="ignore", invalid="ignore")  # overflows: the result's typed error
    def _guarded(self, state: Configuration, J: np.ndarray) -> ComplianceResult:
        """:meth:`at` on a model with loops or passive joints (numpy's warnings off)."""
        fast = partition(state, self._scaling) if self.path == "auto" else None
        if fast is not None:
            return self._fast(state.model, state.data, state.q, state.residual_norm, J, *fast)
        return self._null_space(state, J, self._scaling)

    def _fast(self, model, data, q, residual: float, J: np.ndarray, path: str, X):
        """The serial and partitioned paths without forming N (nv, s), at q (nq,) with its
        kinematics in ``data`` and the infinity norm of its closure residual.

        In the scaled spring coordinates y = dq_s / s_q the joints move by dq = T y, with
        T = diag(s_q) on the sprung coordinates and s_p X on the passive ones
        (:func:`closedloop.elastostatics.partition.partition`), and K_r = W^-T W^-1
        (W = diag(1/sqrt_k), or V diag(1/sigma) with spring blocks). With P = T W (nv, s):
        C = B B^T, B = J P (6, s), and G = P B^T, the same factor as the null-space path's
        (:mod:`closedloop.elastostatics.unloaded`) on the same spectrum rule. The rank
        rule reads J on an orthonormal basis of the admissible motions, as the null-space
        path's J N V does: B diag(sigma) = J T V when T selects the sprung coordinates
        (serial), else :func:`closedloop.elastostatics.partition.kinematic_factor` (the
        singular values of J T V differ from those by up to cond(T), which would move the
        rank decision of a pose near the threshold; the spread of the full-rank test widens
        by cond(T) <= sqrt(1 + ``|X|_F^2``) for the same reason).
        """
        sc = self._scaling
        if sc.P_diagonal is not None:  # every coordinate sprung, diagonal P: by columns
            B = np.multiply(J, sc.P_rows, out=J)  # J is this call's own
            G, g_scale = (_transposed_product, B, sc.P_rows), sc.P_max  # on first read
        else:
            P = sc.P0.copy()
            if X is not None:  # dq_p = s_p X y
                P[sc.passive] = X * sc.passive_coef if sc.W is None else (X @ sc.W) * sc.s_p
            B = J.dot(P)
            G, g_scale = P.dot(B.T), None
        B_s = B * sc.d_rows
        if X is None:  # T selects the sprung coordinates: J T V is the orthonormal-basis factor
            kinematic, spread = (lambda: B_s * sc.sigma), sc.spread
        else:  # T = [I; X] is not orthonormal: cond(T) <= sqrt(1 + |X|_F^2) widens the spread
            cond_T = math.sqrt(1.0 + float(np.vdot(X, X)))
            kinematic = lambda: kinematic_factor(J, sc, X, B_s * sc.sigma, cond_T)  # noqa: E731
            spread = sc.spread * cond_T
        spectrum = factor_rank(B_s, kinematic, spread, sc.d)
        C = B.dot(B.T)
        return fast_result(self._fields[path], model, data, q, residual, C, G, g_scale, spectrum)

    def _null_space(self, state, J: np.ndarray, sc) -> ComplianceResult:
        """The general path: the admissible motions N and the spring factor
        (:func:`closedloop.elastostatics.springs.spring_factor`)."""
        f = spring_factor(state, J, self.frame)
        NV = f.NV
        JNV = (J @ NV) * sc.d[:, None]  # scaled, kinematic
        B_s = JNV / f.sigma  # C_s = B_s B_s^T
        spread = f.sigma.max() / f.sigma.min() if f.sigma.size else 1.0
        spectrum = spectrum_from_factor(B_s, self.length, JNV, spread, scales=sc.scales)
        P = NV / f.sigma
        B = J @ P  # C = B B^T
        return compliance_result(state, self.frame, self.axes, B @ B.T, P @ B.T, f, spectrum)


#: Joints whose motion is a rotation about their origin (Pinocchio's short names start so):
#: a frame Jacobian's column of one is at most the distance from the joint to the frame.
ROTATION_JOINTS = ("JointModelR", "JointModelSpherical", "JointModelUniversal")


def _transposed_product(B: np.ndarray, P_rows: np.ndarray) -> np.ndarray:
    """(nv, 6) read-only G = P B^T of the serial path with diagonal P, from B (6, nv) and
    P's diagonal in every row, P_rows (6, nv): ``|G_kj| = |B_jk| |P_k|``."""
    G = B * P_rows
    G.setflags(False)  # write=False; its transpose, a view, is then read-only too
    return G.T


def _bounded(model: ClosedLoopModel, fid: int, sc, L: float) -> bool:
    """True when the serial path with a spring on every coordinate cannot overflow at any
    configuration: every joint rotates about its origin (:data:`ROTATION_JOINTS`), so
    every entry of the frame Jacobian is at most j = max(1, 2 R + ``|frame offset|``) (R: the
    reach of the joint origins, :func:`closedloop.kinematics.configuration.joint_reach`,
    the same at every q), and with P the largest of P_diagonal ``|B|`` <= j P, ``|G|`` <= j P^2,
    ``|C|`` <= s (j P)^2, ``|D B diag(sigma)|`` <= j P max(1, 1/L) max(sigma), all below
    :data:`FINITE_BOUND` (the spring factor's own K is guarded where it is made,
    :func:`closedloop.elastostatics.unloaded.fast_result`)."""
    pm = model.model
    if sc.P_diagonal is None or not 0.0 < sc.P_max < math.inf:
        return False
    if not all(pm.joints[j].shortname().startswith(ROTATION_JOINTS) for j in range(1, pm.njoints)):
        return False
    offset = float(np.linalg.norm(pm.frames[fid].placement.translation))
    j = max(1.0, 2.0 * joint_reach(model, pin.neutral(pm)) + offset)
    P, s, big = sc.P_max, sc.sprung.size, FINITE_BOUND
    sigma = max(1.0, float(sc.sigma.max()))
    return j * P * max(s * j * P, P, max(1.0, 1.0 / L) * sigma) < big


def query_plan(
    model: ClosedLoopModel, frame: str, axes: str = "world", path: str = "auto", length=None
) -> _Plan:
    """The model's plan of a compliance of ``frame``, ``axes``, ``path`` and length L [m]
    (default: the model's), made (its arguments checked) on first use and kept
    (:meth:`closedloop.model.closed_loop.ClosedLoopModel.memo`).

    Raises:
        InvalidInputError, NameNotFoundError: as :class:`ComplianceQuery`.
    """
    L = model.length if length is None else length
    try:
        return model.memo(("query", frame, axes, path, L), _Plan, model, frame, axes, path, L)
    except TypeError:  # an unhashable argument, which the plan refuses
        return _Plan(model, frame, axes, path, L)


def unloaded_compliance(state: Configuration, frame: str, axes: str, path: str) -> ComplianceResult:
    """Compliance of a closed configuration without preload: the kernel of
    :func:`closedloop.elastostatics.compliance.compliance` without gravity, payloads or
    preload, on the model's plan (:func:`query_plan`).

    Args:
        state: a closed configuration.
        frame: name of the loaded frame.
        axes: ``"world"`` or ``"local"``.
        path: ``"auto"`` (the partitioned fast path where it applies) or ``"null-space"``.
    """
    return query_plan(state.model, frame, axes, path, state.length).at(state)
