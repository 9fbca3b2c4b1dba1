"""The stiffest posture along a path: where the task leaves the frame's pose free in part, the
free coordinates chosen for the least deflection under each point's load.

The *default path* is the task's inverse kinematics continued from point to point (what
:func:`closedloop.analysis.paths.follow_path` does without the search). A candidate posture
turns the default pose of a point by the free coordinates z and solves the whole pose there
(:func:`closedloop.kinematics.inverse.reach`, continued from a neighbouring candidate, within
the joints' limits: a posture outside them, singular, or one the way does not reach, is
not a candidate). Its cost is the translational deflection of the frame, ``|(J dq)_xyz|`` [m],
of the linear model at that unloaded configuration under the point's load (the wrench and
the weight, :func:`closedloop.elastostatics.compensation.linear_deflection`; ``|(C w)_xyz|``
for a wrench alone).

* ``"tool-axis"``: z is the angle [rad] about the tool's z axis, from the default posture.
  Every point's candidates are a grid of angles over the whole turn (a step of at most
  :data:`GRID_STEP` that divides ``max_change``), walked both ways from the default posture,
  each from the last; dynamic programming then picks the sequence of least total deflection
  whose neighbouring angles differ by at most ``max_change`` (default :data:`MAX_CHANGE`:
  the bounded change that keeps the path continuous; the default path, z = 0 throughout,
  is one such sequence, so the choice deflects no more in all), and each angle is refined
  within its grid step by bounded Brent (``scipy.optimize.minimize_scalar``, to
  :data:`ANGLE_TOL`), still within ``max_change`` of the last.
* ``"position"``: z is the rotation vector [rad], world axes, from the posture continued
  from the last chosen one; point after point, Powell's method within the box of
  ``max_change`` about it (``scipy.optimize.minimize``, at most
  :data:`POWELL_EVALUATIONS` postures): a local search, from the default orientation at the
  first point.

The gain is measured against the default path, point by point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from closedloop.analysis.path_points import placement
from closedloop.common.arrays import ReadOnlyArrays, check_positive
from closedloop.common.progress import progress
from closedloop.elastostatics.compensation import linear_deflection
from closedloop.exceptions import ClosedLoopError, InvalidInputError
from closedloop.kinematics.constraints import frame_jacobian
from closedloop.kinematics.frame_task import FrameTask
from closedloop.kinematics.inverse import reach
from closedloop.model.closed_loop import ClosedLoopModel
from closedloop.model.gravity import GravityLoad, Load

#: Free coordinates of a task.
FREE_SIZE = {"tool-axis": 1, "position": 3}
#: Largest change of each free coordinate between neighbouring points [rad].
MAX_CHANGE = 0.1
#: Largest step of the grid of angles about the tool axis [rad] (5 degrees): the step
#: divides max_change, so that a change of max_change is a whole number of steps.
GRID_STEP = math.radians(5.0)
#: Most evaluations of Powell's search at a point (a ``"position"`` task).
POWELL_EVALUATIONS = 300
#: Resolution of the refined angle [rad], and of Powell's search.
ANGLE_TOL = 1e-6
#: Actuated joints needed to turn the frame about its free axes (the whole pose).
WHOLE_POSE_ACTUATORS = 6


def check_freedom(clm: ClosedLoopModel, task: str) -> None:
    """Refuse the stiffest posture for a task that leaves no freedom (``"pose"``) or a model
    whose actuators do not control the whole pose (InvalidInputError)."""
    if task not in FREE_SIZE:
        raise InvalidInputError(
            f"the stiffest posture needs a task that leaves the frame's pose free in part "
            f"({' or '.join(FREE_SIZE)}), got task {task!r}"
        )
    if len(clm.actuated) < WHOLE_POSE_ACTUATORS:
        raise InvalidInputError(
            f"the stiffest posture turns the frame about its free axes, which needs "
            f"{WHOLE_POSE_ACTUATORS} actuated joints or more; {clm.name!r} has "
            f"{len(clm.actuated)} ({list(clm.actuated)}): task {task!r} leaves it no freedom"
        )


def turned(base: pin.SE3, task: str, z: np.ndarray) -> pin.SE3:
    """The pose ``base`` turned by the free coordinates z: about its own z axis by z[0]
    (``"tool-axis"``), or by the rotation vector z (3,) in world axes (``"position"``)."""
    if task == "tool-axis":
        return pin.SE3(base.rotation @ pin.exp3(np.array([0.0, 0.0, z[0]])), base.translation)
    return pin.SE3(pin.exp3(np.asarray(z, dtype=float)) @ base.rotation, base.translation)


def free_coordinates(task: str, default: pin.SE3, chosen: pin.SE3) -> np.ndarray:
    """(d,) the free coordinates of the pose ``chosen`` from the pose ``default`` (the
    inverse of :func:`turned`)."""
    if task == "tool-axis":
        return pin.log3(default.rotation.T @ chosen.rotation)[2:]
    return pin.log3(chosen.rotation @ default.rotation.T)


@dataclass(frozen=True)
class StiffestChoice(ReadOnlyArrays):
    """The free coordinates chosen along a path (arrays read-only, one row a point).

    Attributes:
        free: (n, d) the chosen free coordinates from the default path's posture [rad]
            (the angle about the tool axis, or the rotation vector R R_default^T, world
            axes).
        deflection: (n,) translational deflection of the linear model at the chosen
            posture under the point's load [m].
        default_deflection: (n,) the same at the default path's posture [m].
        max_change: the bound on the change of each free coordinate between neighbouring
            points [rad].
    """

    free: np.ndarray
    deflection: np.ndarray
    default_deflection: np.ndarray
    max_change: float

    @property
    def gain(self) -> np.ndarray:
        """(n,) default_deflection / deflection: how many times less the chosen posture
        deflects (1: no gain)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.default_deflection / self.deflection


def _key(z) -> tuple[float, ...]:
    """The free coordinates z as a key of the candidates tried."""
    return tuple(np.round(np.atleast_1d(np.asarray(z, dtype=float)), 15).tolist())


class StiffestSearch:
    """The search of the module docstring.

    Args:
        clm, frame: the model and the loaded frame.
        task: ``"tool-axis"`` or ``"position"`` (:func:`check_freedom`).
        weight: the weight of links and payloads, or None.
        check_limits: candidates outside the joints' limits are refused.
        max_change: :data:`MAX_CHANGE` or another bound > 0 [rad].
    """

    def __init__(self, clm, frame, task, weight: GravityLoad | None, check_limits, max_change):
        check_positive("max_change", max_change, "rad")
        self.clm, self.frame, self.task = clm, frame, task
        self.weight, self.check_limits, self.max_change = weight, check_limits, float(max_change)

    def deflection(self, q: np.ndarray, load: Load) -> float:
        """``|(J dq)_xyz|`` [m] of the linear model at q (nq,) under ``load``."""
        clm, frame = self.clm, self.frame
        twist = frame_jacobian(clm, q, frame) @ linear_deflection(clm, q, frame, load)
        return float(np.linalg.norm(twist[:3]))

    def postures(self, q: np.ndarray, targets, wrenches, show_progress: bool = False):
        """(rows, failure) of a path from the assembled start q (nq,), its targets (SE3)
        and wrenches (n, 6): rows[i] = (configuration (nq,), free coordinates (d,),
        deflection [m], default deflection [m]) of the points before the first whose
        default posture cannot be reached; failure = (that point, its error) or None."""
        clm, frame, task = self.clm, self.frame, self.task
        defaults, failure = [], None
        for i, target in enumerate(targets):
            try:
                q = reach(clm, frame, FrameTask(task, target), q, check_limits=self.check_limits).q
            except ClosedLoopError as e:
                failure = (i, e)
                break
            defaults.append(np.array(q))
        loads = [Load(np.asarray(w, dtype=float), self.weight) for w in wrenches[: len(defaults)]]
        bases = [placement(clm, q, frame) for q in defaults]
        if task == "tool-axis":
            return self._angles(defaults, bases, loads, show_progress), failure
        return self._rotations(defaults, bases, loads), failure

    def _pose(self, base: pin.SE3, z, start: np.ndarray) -> np.ndarray:
        """The configuration, continued from ``start``, at the pose ``base`` turned by z."""
        pose = FrameTask("pose", turned(base, self.task, np.atleast_1d(z)))
        return np.array(reach(self.clm, self.frame, pose, start, check_limits=self.check_limits).q)

    def _angles(self, defaults, bases, loads, show_progress) -> list[tuple]:
        """Dynamic programming over a grid of angles about the tool axis (module
        docstring), then each angle refined within its grid step."""
        n, delta = len(defaults), self.max_change
        h = delta / math.ceil(delta / GRID_STEP)  # the grid's step divides max_change
        m, K = round(delta / h), int(math.pi / h)
        offsets = np.arange(-K, K + 1) * h
        cost = np.full((n, 2 * K + 1), math.inf)
        configs: list[dict] = [{} for _ in range(n)]
        for i in progress(range(n), total=n, label="stiffest posture", enabled=show_progress):
            cost[i, K], configs[i][K] = self.deflection(defaults[i], loads[i]), defaults[i]
            for sign in (1, -1):  # walked both ways from the default posture, each from the last
                start = defaults[i]
                for k in range(1, K + 1):
                    g = K + sign * k
                    try:
                        q = self._pose(bases[i], offsets[g], start)
                        cost[i, g] = self.deflection(q, loads[i])
                    except ClosedLoopError:  # unreachable, singular, outside the limits
                        break
                    configs[i][g] = start = q
        # least total deflection over sequences whose neighbours are at most m steps apart
        total, back = cost[0].copy(), np.zeros((n, 2 * K + 1), dtype=int)
        for i in range(1, n):
            best = np.full(2 * K + 1, math.inf)
            for g in range(2 * K + 1):
                lo = max(0, g - m)
                j = lo + int(np.argmin(total[lo : g + m + 1]))
                best[g], back[i, g] = cost[i, g] + total[j], j
            total = best
        chosen = [int(np.argmin(total))]
        for i in range(n - 1, 0, -1):
            chosen.append(back[i, chosen[-1]])
        chosen.reverse()
        rows, previous = [], None
        for i, g in enumerate(chosen):
            lo, hi = offsets[g] - h, offsets[g] + h
            if previous is not None:  # within max_change of the last angle, refined
                lo, hi = max(lo, previous - delta), min(hi, previous + delta)
            z, q, value = self._refined(bases[i], loads[i], configs[i][g], offsets[g],
                                        cost[i, g], (lo, hi))  # fmt: skip
            rows.append((q, np.array([z]), value, cost[i, K]))
            previous = z
        return rows

    def _refined(self, base, load, q, z, value, bounds):
        """(angle, configuration, deflection): the grid's angle z (its configuration q and
        deflection) refined by bounded Brent within ``bounds``."""
        from scipy.optimize import minimize_scalar

        best = [value, z, q]

        def cost(x: float) -> float:
            try:
                qx = self._pose(base, x, q)
                v = self.deflection(qx, load)
            except ClosedLoopError:
                return math.inf
            if v < best[0]:
                best[:] = [v, x, qx]
            return v

        lo, hi = bounds
        if hi > lo:
            minimize_scalar(cost, bounds=(lo, hi), method="bounded", options={"xatol": ANGLE_TOL})
        return best[1], best[2], best[0]

    def _rotations(self, defaults, bases, loads) -> list[tuple]:
        """Powell's search of the orientation at each point, within max_change of the
        posture continued from the last chosen one (module docstring)."""
        clm, frame, rows, q_prev = self.clm, self.frame, [], defaults[0]
        for default, target, load in zip(defaults, bases, loads, strict=True):
            goal = FrameTask("position", target)
            base = np.array(reach(clm, frame, goal, q_prev, check_limits=self.check_limits).q)
            value, q = self._rotation(base, load, self.max_change)
            free = free_coordinates("position", placement(clm, default, frame),
                                    placement(clm, q, frame))  # fmt: skip
            rows.append((q, free, value, self.deflection(default, load)))
            q_prev = q
        return rows

    def _rotation(self, base: np.ndarray, load: Load, bound: float) -> tuple[float, np.ndarray]:
        """(deflection, configuration) of the least deflection found by Powell's method
        over the rotation vectors within +-bound of the pose at ``base`` (nq,)."""
        from scipy.optimize import minimize

        M = placement(self.clm, base, self.frame)
        tried = {_key(np.zeros(3)): (self.deflection(base, load), base)}

        def cost(z) -> float:
            key = _key(z)
            if key not in tried:
                try:
                    qz = self._pose(M, z, base)
                    tried[key] = (self.deflection(qz, load), qz)
                except ClosedLoopError:
                    tried[key] = (math.inf, None)
            return tried[key][0]

        minimize(cost, np.zeros(3), method="Powell", bounds=[(-bound, bound)] * 3,
                 options={"xtol": ANGLE_TOL, "ftol": 1e-12,
                          "maxfev": POWELL_EVALUATIONS})  # fmt: skip
        return min(tried.values(), key=lambda t: t[0])
