"""Joint position limits: which joints of a configuration are outside them (the assembly
of actuated values that the limits allow: :mod:`closedloop.kinematics.driving`).

Limits are Pinocchio's ``model.lowerPositionLimit`` / ``upperPositionLimit`` of the
revolute and prismatic joints (one coordinate); the statics flag or refuse an equilibrium
outside them (:mod:`closedloop.elastostatics.statics`), a map marks a point ``invalid``.
"""

from __future__ import annotations

import math
import operator

import numpy as np

from closedloop.model.closed_loop import ClosedLoopModel

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
    names, i, wound, lower, upper = _limited_coordinates(clm)  # the limits' values read now
    if i is not None:
        lower, q, upper = lower[i], q[i], upper[i]
    # Python floats: a few joints, where numpy's calls cost more than the arithmetic
    lower, values, upper = lower.tolist(), q.tolist(), upper.tolist()
    if all(map(operator.le, lower, values)) and all(map(operator.le, values, upper)):
        return {}  # every value within its limits: none out, whatever the rule below
    out = {}
    for name, lo, hi, x, turns in zip(names, lower, upper, values, wound, strict=True):
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


def _limited_coordinates(clm: ClosedLoopModel) -> tuple:
    """(names, q indices (k,), wound, lower, upper) of the one-coordinate revolute and
    prismatic joints, in joint order; ``wound``: revolute and not actuated; the indices None
    when they are all of q in order (a serial robot's); lower and upper (nq,) views of the
    Pinocchio model's own limits (a new value is written into them: these views see it).
    Once per model."""
    return clm.memo("limited_coordinates", _find_limited, clm)


def _find_limited(clm: ClosedLoopModel) -> tuple:
    model, rows = clm.model, []
    for j in range(1, model.njoints):
        jm = model.joints[j]
        kind = jm.shortname()
        if jm.nq == 1 and kind.startswith(("JointModelR", "JointModelP")):
            turns = kind.startswith("JointModelR") and model.names[j] not in clm.actuated
            rows.append((model.names[j], jm.idx_q, turns))
    names, idx, wound = zip(*rows, strict=True) if rows else ((), (), ())
    idx = np.array(idx, dtype=int)
    every = np.array_equal(idx, np.arange(model.nq))
    limits = model.lowerPositionLimit, model.upperPositionLimit
    return list(names), None if every else idx, list(wound), *limits


def describe_limits(bad: dict[str, tuple]) -> str:
    """``name = value (limits [lower, upper])`` of each joint of :func:`joints_outside_limits`."""
    return ", ".join(
        f"{n} = {x:.12g} (limits [{lo:.6g}, {hi:.6g}])" for n, (x, lo, hi) in bad.items()
    )


def degrees_hint(clm: ClosedLoopModel, bad: dict[str, tuple], values: str) -> str:
    """``"; crank beyond 2 pi: degrees? <values> in radians (numpy.radians)"`` for the
    revolute joints of ``bad`` (:func:`joints_outside_limits`) whose value exceeds 2 pi in
    magnitude, the usual cause of an angle outside its limits; ``""`` when none does.
    ``values``: what holds the angles (``"q is"``, ``"actuated values are"``)."""
    joints = clm.model.joints
    turned = [n for n, (x, _, _) in bad.items() if abs(x) > _TURN
              and joints[clm.joint_id(n)].shortname().startswith("JointModelR")]  # fmt: skip
    if not turned:
        return ""
    return f"; {', '.join(turned)} beyond 2 pi: degrees? {values} in radians (numpy.radians)"
