"""One design of a :class:`~closedloop.analysis.design_problem.DesignProblem` evaluated: its
model loaded with the design's arguments, its mass, a stiffness map over the workspace (the
stacked queries of :func:`closedloop.analysis.maps.stiffness_map`, in this process), each
index at its worst, and its feasibility.

A design is infeasible, with the reason kept, when its model cannot be built (a beam's wall
thicker than its radius, an expression without a value), a workspace point does not
assemble or fails, an index does not exist at a point (a rank-deficient compliance, no
natural frequency), or a constraint is not met to its tolerance.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from closedloop.analysis.design_problem import WORST, DesignProblem
from closedloop.analysis.map_results import OK, RANK_DEFICIENT
from closedloop.analysis.maps import StiffnessMap, stiffness_map
from closedloop.exceptions import ClosedLoopError
from closedloop.kinematics.assembly import assemble


@dataclass(frozen=True)
class DesignEvaluation:
    """A design and what it gives.

    Attributes:
        parameters: name -> value [SI] of the designed arguments.
        values: index -> its worst value over the workspace (``mass`` [kg]; units of
            :data:`closedloop.analysis.design_problem.DESIGN_INDICES`); NaN where not
            computed.
        feasible: every index computed at every point and every constraint met.
        reason: why it is infeasible ("" when feasible).
        violation: the constraints' summed relative violation beyond their tolerances (0
            when met; inf when an index could not be computed).
        worst: index -> the workspace point (its position in the workspace) of its worst value.
        seconds: time the evaluation took [s].
    """

    parameters: dict
    values: dict
    feasible: bool
    reason: str = ""
    violation: float = 0.0
    worst: dict = field(default_factory=dict)
    seconds: float = 0.0

    def to_dict(self) -> dict:
        """JSON-ready (NaN and infinity as None)."""
        return {
            "parameters": dict(self.parameters),
            "values": {k: _finite(v) for k, v in self.values.items()},
            "feasible": self.feasible,
            "reason": self.reason,
            "violation": _finite(self.violation),
            "worst_point": dict(self.worst),
            "seconds": self.seconds,
        }


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


@dataclass(frozen=True)
class DesignTask:
    """A design to evaluate, as an executor's task (picklable)."""

    problem: DesignProblem
    parameters: tuple[tuple[str, float], ...]


def evaluate_task(task: DesignTask) -> DesignEvaluation:
    """The kernel of the executors: :func:`evaluate_design` of a :class:`DesignTask`."""
    return evaluate_design(task.problem, dict(task.parameters))


def evaluate_design(
    problem: DesignProblem, parameters: Mapping[str, float], *, strict: bool = False
) -> DesignEvaluation:
    """Evaluate one design (module docstring).

    Args:
        problem: the problem.
        parameters: name -> value of every parameter [SI].
        strict: raise the errors of the model's loading and of the map instead of making
            the design infeasible (the check of a problem at its first design).

    Raises:
        ClosedLoopError: with ``strict`` only.
    """
    t0 = time.perf_counter()
    params = {n: float(parameters[n]) for n in problem.names}
    values = dict.fromkeys(problem.indices, math.nan)

    def result(reason: str, violation: float = math.inf, worst=None) -> DesignEvaluation:
        return DesignEvaluation(params, values, not reason, reason, violation, worst or {},
                                time.perf_counter() - t0)  # fmt: skip

    try:
        clm = problem.source(params).load()
        if "mass" in values:
            from closedloop.analysis.vibration import total_mass

            values["mass"] = total_mass(clm)
        smap = design_map(problem, clm)  # every point assembled, whatever the indices
    except ClosedLoopError as e:
        if strict:
            raise
        return result(f"{type(e).__name__}: {e}")
    mapped = [index for index in values if index != "mass"]
    failed = _failed_point(smap, mapped)
    if failed:
        return result(failed)
    worst = {}
    for index in mapped:
        v = smap.indices[index]
        k = int(np.argmin(v) if WORST[index] == "min" else np.argmax(v))
        values[index], worst[index] = float(v[k]), k
    broken = [c for c in problem.constraints if c.violation(values[c.index]) > 0]
    violation = math.fsum(c.violation(values[c.index]) for c in broken)
    reason = "; ".join(f"{c.describe()} not met: {c.index} = {values[c.index]:.6g}"
                       for c in broken)  # fmt: skip
    return result(reason, violation, worst)


def design_map(problem: DesignProblem, clm, *, modes: bool | None = None) -> StiffnessMap:
    """The stiffness map of a design's model ``clm`` over the problem's workspace (the
    reference pose, assembled, without one), in this process.

    Args:
        modes: also ``lowest_frequency`` (default: when the problem needs it).
    """
    modes = "lowest_frequency" in problem.indices if modes is None else modes
    options = {"wrench": problem.wrench, "modes": modes, "check_limits": problem.check_limits}
    if problem.sweeps is not None:
        return stiffness_map(clm, problem.frame, sweeps=dict(problem.sweeps),
                             fixed=dict(problem.fixed), **options)  # fmt: skip
    if problem.points is not None:
        points = np.array(problem.points, dtype=float)
    else:
        q = assemble(clm, None, clm.reference_configuration()).q
        points = clm.actuated_values(q)[None, :]
    return stiffness_map(clm, problem.frame, points=points, **options)


def _failed_point(smap: StiffnessMap, indices: list[str]) -> str:
    """Why the map does not give every index at every point ("" when it does): the first
    point that failed, or where an index does not exist."""
    computed = np.isin(smap.data.codes, (OK, RANK_DEFICIENT))
    missing = ~computed
    for index in indices:
        missing |= np.isnan(smap.indices[index])
    if not missing.any():
        return ""
    k = int(np.flatnonzero(missing)[0])
    point = ", ".join(f"{n} = {x:.6g}" for n, x in zip(smap.joints, smap.inputs[k], strict=True))
    where = f"workspace point {k}" + (f" ({point})" if point else "")
    if not computed[k]:
        return f"{where}: {smap.status[k]}: {smap.reasons[k]}"
    absent = [i for i in indices if np.isnan(smap.indices[i][k])]
    return f"{where}: {absent[0]} does not exist there (status {smap.status[k]})"
