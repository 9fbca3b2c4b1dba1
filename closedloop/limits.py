"""Joint position limits: which joints of a configuration are outside them, and the
assembly of actuated values that the limits allow (a map's points, the command line's
``--actuated``).

Limits are Pinocchio's ``model.lowerPositionLimit`` / ``upperPositionLimit`` of the
revolute and prismatic joints (one coordinate); the statics flag or refuse an equilibrium
outside them (:mod:`closedloop.statics`), a map marks a point ``invalid``.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from .assembly import INPUT_STEP, Assembly, check_actuated, close_loops, coordinate_scale
from .exceptions import AssemblyError, InvalidInputError, SingularConfigurationError
from .model import ClosedLoopModel

#: Excursion beyond a joint limit [m or rad] that counts as a violation: above the accuracy
#: of an equilibrium (1e-12), so that a rest configuration on a limit is not flagged for
#: rounding, and far below any mechanical clearance.
LIMIT_TOL = 1e-9
#: Limits at or beyond this magnitude [m, rad] are Pinocchio's "unbounded" defaults.
UNBOUNDED_LIMIT = 1e100


def joints_outside_limits(clm: ClosedLoopModel, q: np.ndarray) -> dict[str, tuple]:
    """Revolute and prismatic joints whose coordinate in q (nq,) is outside its limits.

    A bound counts when it is finite and below :data:`UNBOUNDED_LIMIT` in magnitude;
    a joint whose lower limit is not below its upper one (URDF ``<limit>`` without
    ``lower``/``upper`` reads as [0, 0]) has none. The angle of a revolute joint that is
    not actuated comes from the assembly, which may wind it by whole turns (11.13 rad for
    limits [-6.3, 6.3], the placement of 11.13 - 2 pi = 4.85 rad): it counts as inside
    when an angle that differs from it by whole turns is (so one bound alone never holds
    it: some whole turn brings it within). An actuated angle is the value
    the robot is driven to, and counts as it is. Returns name ->
    (value, lower, upper) [rad or m] for every coordinate more than :data:`LIMIT_TOL`
    outside, in joint order.
    """
    model, (names, i, wound) = clm.model, _limited_coordinates(clm)
    # the limits are read each time (a model's may be set after loading); a loop over
    # Python floats: a few joints, where numpy's calls cost more than the arithmetic
    lower, upper = model.lowerPositionLimit[i].tolist(), model.upperPositionLimit[i].tolist()
    out = {}
    for name, lo, hi, x, turns in zip(names, lower, upper, q[i].tolist(), wound, strict=True):
        if not lo < hi:
            continue
        low, high, y = abs(lo) < UNBOUNDED_LIMIT, abs(hi) < UNBOUNDED_LIMIT, x
        if turns and not (low and high):  # whole turns reach within one bound: never out
            continue
        if turns:
            y = lo + (x - lo) % _TURN  # the angle in the turn that starts at the lower limit
            if y > lo + _TURN - LIMIT_TOL:  # within the tolerance below it
                y -= _TURN
        if (low and y < lo - LIMIT_TOL) or (high and y > hi + LIMIT_TOL):
            out[name] = (x, lo, hi)
    return out


_TURN = 2.0 * math.pi


def _limited_coordinates(clm: ClosedLoopModel) -> tuple[list[str], np.ndarray, list[bool]]:
    """(names, q indices (k,), wound) of the one-coordinate revolute and prismatic joints,
    in joint order; ``wound``: revolute and not actuated. Once per model."""

    def build():
        model, rows = clm.model, []
        for j in range(1, model.njoints):
            jm = model.joints[j]
            kind = jm.shortname()
            if jm.nq == 1 and kind.startswith(("JointModelR", "JointModelP")):
                turns = kind.startswith("JointModelR") and model.names[j] not in clm.actuated
                rows.append((model.names[j], jm.idx_q, turns))
        names, idx, wound = zip(*rows, strict=True) if rows else ((), (), ())
        return list(names), np.array(idx, dtype=int), list(wound)

    return clm.memo("limited_coordinates", build)


def describe_limits(bad: dict[str, tuple]) -> str:
    """``name = value (limits [lower, upper])`` of each joint of :func:`joints_outside_limits`."""
    return ", ".join(
        f"{n} = {x:.12g} (limits [{lo:.6g}, {hi:.6g}])" for n, (x, lo, hi) in bad.items()
    )


def assemble_within_limits(
    clm: ClosedLoopModel,
    actuated: np.ndarray,
    q0: np.ndarray | None = None,
    *,
    jacobian: bool = True,
) -> Assembly:
    """:func:`closedloop.assembly.assemble` of actuated values (n_act,) [rad, m] inside the
    position limits of their joints (the rule of :func:`joints_outside_limits`), from q0
    (nq,; default: neutral, as ``assemble``); ``jacobian`` as for ``assemble``.

    Raises:
        InvalidInputError: bad ``actuated`` or ``q0`` (as for ``assemble``), or an
            actuated value outside its joint's limits (an ``invalid`` point of a map: the
            robot cannot be driven there).
        AssemblyError: the loops cannot be closed.
        SingularConfigurationError: they close at a singular configuration only.
    """
    q = clm.check_configuration(pin.neutral(clm.model) if q0 is None else q0)
    origin = None if q0 is None else q.copy()  # an assembled q0: its branch is followed
    clm.set_actuated(q, check_actuated(clm, actuated))
    bad = {n: v for n, v in joints_outside_limits(clm, q).items() if n in clm.actuated}
    if bad:
        raise InvalidInputError(f"actuated joints outside their limits: {describe_limits(bad)}")
    return close_loops(clm, q, jacobian=jacobian, origin=origin)


#: Most steps of :func:`assemble_connected` (a longer way takes longer steps).
MAX_INPUT_STEPS = 1000


def input_scale(clm: ClosedLoopModel) -> np.ndarray:
    """(n_act,) the unit of each actuated value in :data:`INPUT_STEP` (the largest change
    of an actuated value per step of :func:`assemble_connected`): L [m] for a length, 1 for
    an angle (once per model)."""
    return clm.memo("input_scale", lambda: coordinate_scale(clm)[clm.actuated_v_indices])


def assemble_connected(
    clm: ClosedLoopModel,
    actuated: np.ndarray,
    q0: np.ndarray | None = None,
    *,
    jacobian: bool = True,
) -> Assembly:
    """:func:`assemble_within_limits` on the assembly mode of q0 (default: neutral): the
    actuated values go from q0's to ``actuated`` (n_act,) [rad, m] in steps of at most
    :data:`INPUT_STEP`, each assembled from the last, as the robot is driven there.

    One Gauss-Newton solve from far away may land on another mode: the bundled four-bar
    solved at once from crank 0 is on the other mode at crank 1.0, not at 1.5. Where a step
    cannot be assembled (q0's mode ends on the way, at a singular position, or the way
    leaves the limits), the direct assembly from q0 is taken. A model without loops has
    its actuated values set (:func:`closedloop.assembly.assemble`).

    Raises:
        As :func:`assemble_within_limits`.
    """
    q = clm.check_configuration(pin.neutral(clm.model) if q0 is None else q0)
    target = check_actuated(clm, actuated)
    start = clm.actuated_values(q)
    with np.errstate(over="ignore"):  # inputs near the float range: one step, refused there
        steps = float(np.max(np.abs(target - start) / input_scale(clm), initial=0)) / INPUT_STEP
    n = min(MAX_INPUT_STEPS, math.ceil(steps)) if math.isfinite(steps) else 1
    path = q
    try:
        for k in range(1, n):
            path = assemble_within_limits(clm, start + k / n * (target - start), path,
                                          jacobian=False).q  # fmt: skip
    except (AssemblyError, InvalidInputError, SingularConfigurationError):
        path = q
    return assemble_within_limits(clm, target, path, jacobian=jacobian)
