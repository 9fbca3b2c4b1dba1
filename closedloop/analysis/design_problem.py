"""Design problems: which values of a parametric model's arguments make it stiff enough,
light enough, everywhere in its workspace.

A problem is a YAML file or a dict of the same form (:func:`design_problem`)::

    model: leg.urdf.xacro            # a xacro file, or a URDF/MJCF/SDF whose closure file
    closures: leg.yaml               #   has ${...} placeholders (closedloop.io.expressions)
    frame: tip                       # the loaded frame
    parameters:                      # the arguments designed: name: [low, high] (SI)
      d: [0.005, 0.08]
    args: {L: 0.5}                   # optional: arguments held fixed
    workspace:                       # optional (default: the reference pose, assembled)
      sweep: {crank: "0.2:0.8:5"}    #   one or two joints, as closedloop map --sweep, with
      fixed: {}                      #   fixed: the other actuated joints; or
      # points: [[0.2], [0.5]]       #   actuated values, one row a point
    load: {force: [0, 0, -100], torque: [0, 0, 0]}  # optional: for the deflection indices
    objectives:
      - {index: mass, goal: minimize}
    constraints:
      - {index: min_translational, min: 2.0e+4}     # min and/or max, tolerance (relative,
    check_limits: true               # default 1e-6); false: points outside the joints'
                                     # limits are computed too (closedloop map --no-limits)

Relative paths are relative to the problem file (to the working folder for a dict). The
indices are those of a map (:data:`closedloop.analysis.maps.ALL_INDICES`), each at its worst
over the workspace (:data:`WORST`), and ``mass``
(:func:`closedloop.analysis.vibration.total_mass`). A design is evaluated by
:func:`closedloop.analysis.design_evaluation.evaluate_design`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from closedloop.analysis.maps import ALL_INDICES
from closedloop.analysis.model_source import ModelSource
from closedloop.common.argtypes import SpecError, parse_values
from closedloop.common.arrays import decimal
from closedloop.exceptions import InvalidInputError, ModelFileError
from closedloop.io.closure_file import read_yaml_mapping

#: Every index a problem may name, and its unit.
DESIGN_INDICES = {**ALL_INDICES, "mass": "kg"}
#: The worst value of each map index over the workspace: the smallest stiffness, frequency
#: or det K, the largest deflection or condition number.
WORST = {
    **dict.fromkeys(("det_K", "min_translational", "max_translational", "min_rotational",
                     "max_rotational", "lowest_frequency"), "min"),
    **dict.fromkeys(("condition_number", "condition_number_si", "deflection_translation",
                     "deflection_rotation"), "max"),
}  # fmt: skip
#: Default relative tolerance of a constraint: met when the value is within it of its bound.
CONSTRAINT_RTOL = 1e-6
GOALS = ("minimize", "maximize")
KEYS = ("model", "closures", "frame", "parameters", "args", "workspace", "load", "objectives",
        "constraints", "check_limits")  # fmt: skip


@dataclass(frozen=True)
class Objective:
    """An index to minimize or maximize (its worst value over the workspace)."""

    index: str
    goal: str = "minimize"

    @property
    def sign(self) -> float:
        """+1 to minimize, -1 to maximize: sign * value is minimized."""
        return 1.0 if self.goal == "minimize" else -1.0


@dataclass(frozen=True)
class Constraint:
    """Bounds on an index (its worst value over the workspace), met to ``tolerance``.

    Attributes:
        index: the index.
        min, max: its bounds (SI), one of them at least.
        tolerance: relative tolerance: ``min`` is met by a value >= min - tolerance abs(min)
            (an absolute ``tolerance`` for a bound of 0).
    """

    index: str
    min: float | None = None
    max: float | None = None
    tolerance: float = CONSTRAINT_RTOL

    def margins(self, value: float) -> list[float]:
        """Signed relative margin of each bound (>= 0 where met; NaN for a NaN value)."""
        out = []
        for bound, sign in ((self.min, 1.0), (self.max, -1.0)):
            if bound is not None:
                out.append(sign * (value - bound) / (abs(bound) or 1.0))
        return out

    def violation(self, value: float) -> float:
        """Relative violation beyond the tolerance (0 when met; inf for a NaN value)."""
        margins = self.margins(value)
        if any(math.isnan(m) for m in margins):
            return math.inf
        return sum(max(0.0, -m - self.tolerance) for m in margins)

    def describe(self) -> str:
        """``min_translational >= 20000``, ``0.1 <= mass <= 2``."""
        low = "" if self.min is None else f"{self.min:g} <= "
        high = "" if self.max is None else f" <= {self.max:g}"
        return f"{low}{self.index}{high}"


@dataclass(frozen=True)
class DesignProblem:
    """A design problem (module docstring), as :func:`design_problem` reads and checks it
    (one built field by field is taken as it is).

    Attributes:
        model, closures: the model's files (absolute paths; closures None without one).
        frame: the loaded frame.
        parameters: (name, low, high) of each argument designed [SI].
        objectives: one or more.
        constraints: the constraints (may be none).
        args: (name, value) of the arguments held fixed.
        sweeps, fixed: a grid workspace, (joint, values) and (joint, value) pairs; or
        points: the actuated values of each workspace point; all None: the reference pose.
        wrench: (fx, fy, fz [N], nx, ny, nz [N m]) of the deflection indices, or None.
        check_limits: False: workspace points outside the joints' limits are computed.
    """

    model: str
    closures: str | None
    frame: str
    parameters: tuple[tuple[str, float, float], ...]
    objectives: tuple[Objective, ...]
    constraints: tuple[Constraint, ...] = ()
    args: tuple[tuple[str, float], ...] = ()
    sweeps: tuple[tuple[str, tuple[float, ...]], ...] | None = None
    fixed: tuple[tuple[str, float], ...] = ()
    points: tuple[tuple[float, ...], ...] | None = None
    wrench: tuple[float, ...] | None = None
    check_limits: bool = True

    @property
    def names(self) -> tuple[str, ...]:
        """The parameters' names, in order."""
        return tuple(name for name, _, _ in self.parameters)

    @property
    def indices(self) -> tuple[str, ...]:
        """The indices the objectives and constraints need, each once."""
        found = [*(o.index for o in self.objectives), *(c.index for c in self.constraints)]
        return tuple(dict.fromkeys(found))

    def source(self, parameters: Mapping[str, float]) -> ModelSource:
        """The :class:`ModelSource` of the design with these parameter values."""
        args = {**dict(self.args), **{n: float(parameters[n]) for n in self.names}}
        return ModelSource(self.model, self.closures, args=tuple(sorted(args.items())))

    def to_dict(self) -> dict:
        """The problem as a JSON-ready dict of the file's form."""
        workspace = None
        if self.sweeps is not None:
            workspace = {"sweep": {n: list(v) for n, v in self.sweeps},
                         "fixed": dict(self.fixed)}  # fmt: skip
        elif self.points is not None:
            workspace = {"points": [list(p) for p in self.points]}
        return {
            "model": self.model, "closures": self.closures, "frame": self.frame,
            "parameters": {n: [lo, hi] for n, lo, hi in self.parameters},
            "args": dict(self.args), "workspace": workspace,
            "load": None if self.wrench is None else {"force": list(self.wrench[:3]),
                                                      "torque": list(self.wrench[3:])},
            "objectives": [{"index": o.index, "goal": o.goal} for o in self.objectives],
            "constraints": [{k: v for k, v in vars(c).items() if v is not None}
                            for c in self.constraints],
            "check_limits": self.check_limits,
        }  # fmt: skip


def design_problem(problem: DesignProblem | Mapping | str | Path) -> DesignProblem:
    """A :class:`DesignProblem` from a YAML file, a dict of the same form or itself.

    Raises:
        ModelFileError: a file that is missing, not YAML or not of the form (the message
            names the file and the key).
        InvalidInputError: a dict not of the form (the message names the key).
    """
    if isinstance(problem, DesignProblem):
        return problem
    if isinstance(problem, str | Path):
        return _Reader(f"design problem {str(problem)!r}", ModelFileError).read_file(Path(problem))
    if not isinstance(problem, Mapping):
        raise InvalidInputError(
            f"design problem: expected a file path, a mapping or a DesignProblem, got "
            f"{type(problem).__name__}"
        )
    return _Reader("design problem", InvalidInputError).read(problem, Path.cwd())


class _Reader:
    """Reads a problem's mapping; errors of type ``error`` whose message starts ``where``."""

    def __init__(self, where: str, error: type[Exception]):
        self.where, self.error = where, error

    def fail(self, key: str, message: str):
        return self.error(f"{self.where}: {key}: {message}")

    def read_file(self, path: Path) -> DesignProblem:
        path, doc = read_yaml_mapping(path, "design problem")
        return self.read(doc, path.resolve().parent)

    def read(self, doc: Mapping, base: Path) -> DesignProblem:
        unknown = sorted(map(str, set(doc) - set(KEYS)))
        if unknown:
            raise self.error(f"{self.where}: unknown key(s) {unknown}; expected {', '.join(KEYS)}")
        for key in ("model", "frame", "parameters", "objectives"):
            if doc.get(key) is None:
                raise self.fail(key, "missing; expected it (model, frame, parameters, objectives)")
        parameters = self.parameters(doc["parameters"])
        args = tuple(
            (n, self.number(v, f"args: {n}")) for n, v in self.mapping(doc, "args").items()
        )
        clash = sorted({n for n, _ in args} & {n for n, _, _ in parameters})
        if clash:
            raise self.fail("args", f"{clash} are parameters too; expected each name once")
        objectives = self.objectives(doc["objectives"])
        constraints = self.constraints(doc.get("constraints") or [])
        wrench = self.load(doc.get("load"))
        deflections = [i for i in (*(o.index for o in objectives), *(c.index for c in constraints))
                       if i.startswith("deflection") and wrench is None]  # fmt: skip
        if deflections:
            raise self.fail(
                "load", f"missing; the index {deflections[0]!r} needs a force or torque"
            )
        check_limits = doc.get("check_limits", True)
        if not isinstance(check_limits, bool):
            raise self.fail("check_limits", f"{check_limits!r}; expected true or false")
        return DesignProblem(
            model=self.path(doc["model"], base, "model"),
            closures=None if doc.get("closures") is None else self.path(doc["closures"], base,
                                                                         "closures"),
            frame=self.text(doc["frame"], "frame"), parameters=parameters,
            objectives=objectives, constraints=constraints, args=args, wrench=wrench,
            check_limits=check_limits, **self.workspace(doc.get("workspace")),
        )  # fmt: skip

    def text(self, value, key: str) -> str:
        if not isinstance(value, str) or not value.strip():
            raise self.fail(key, f"{value!r}; expected a name")
        return value

    def path(self, value, base: Path, key: str) -> str:
        return str((base / self.text(value, key)).resolve())

    def number(self, value, key: str) -> float:
        if isinstance(value, str):  # YAML 1.1 reads 2e4 as a string
            try:
                value = decimal(value.strip())
            except ValueError:
                pass
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not math.isfinite(value)
        ):
            raise self.fail(key, f"{value!r}; expected a finite number")
        return float(value)

    def mapping(self, doc: Mapping, key: str) -> dict:
        value = doc.get(key) or {}
        if not isinstance(value, Mapping) or not all(isinstance(k, str) for k in value):
            raise self.fail(key, f"{value!r}; expected a mapping name -> value")
        return dict(value)

    def parameters(self, value) -> tuple[tuple[str, float, float], ...]:
        if not isinstance(value, Mapping) or not value:
            raise self.fail("parameters", f"{value!r}; expected a mapping name: [low, high]")
        out = []
        for name, bounds in value.items():
            key = f"parameters: {name}"
            if not isinstance(name, str) or not isinstance(bounds, list) or len(bounds) != 2:
                raise self.fail(key, f"{bounds!r}; expected [low, high]")
            low, high = (self.number(b, key) for b in bounds)
            if not low < high:
                raise self.fail(key, f"[{low:g}, {high:g}]; expected low < high")
            out.append((name, low, high))
        return tuple(out)

    def entries(self, value, key: str, allowed: tuple[str, ...]) -> list[dict]:
        if not isinstance(value, list) or not all(isinstance(e, Mapping) for e in value):
            raise self.fail(key, f"{value!r}; expected a list of mappings")
        for entry in value:
            unknown = sorted(map(str, set(entry) - set(allowed)))
            if unknown:
                raise self.fail(key, f"unknown key(s) {unknown}; expected {', '.join(allowed)}")
            index = entry.get("index")
            if index not in DESIGN_INDICES:
                raise self.fail(key, f"index {index!r}; expected one of {sorted(DESIGN_INDICES)}")
        return [dict(e) for e in value]

    def objectives(self, value) -> tuple[Objective, ...]:
        out = []
        for entry in self.entries(value, "objectives", ("index", "goal")):
            goal = entry.get("goal", "minimize")
            if goal not in GOALS:
                raise self.fail("objectives", f"goal {goal!r}; expected one of {list(GOALS)}")
            out.append(Objective(entry["index"], goal))
        if not out or len({o.index for o in out}) < len(out):
            raise self.fail("objectives", "expected one or more, each index once")
        return tuple(out)

    def constraints(self, value) -> tuple[Constraint, ...]:
        out = []
        for entry in self.entries(value, "constraints", ("index", "min", "max", "tolerance")):
            key = f"constraints: {entry['index']}"
            low, high = (None if entry.get(b) is None else self.number(entry[b], key)
                         for b in ("min", "max"))  # fmt: skip
            if (low is None and high is None) or (
                low is not None and high is not None and low > high
            ):
                raise self.fail(key, "expected min and/or max, min <= max")
            tolerance = self.number(entry.get("tolerance", CONSTRAINT_RTOL), key)
            if not 0.0 <= tolerance < 1.0:
                raise self.fail(key, f"tolerance {tolerance:g}; expected 0 <= tolerance < 1")
            out.append(Constraint(entry["index"], low, high, tolerance))
        return tuple(out)

    def load(self, value) -> tuple[float, ...] | None:
        if value is None:
            return None
        if not isinstance(value, Mapping) or not set(value) <= {"force", "torque"} or not value:
            raise self.fail("load", f"{value!r}; expected {{force: [fx, fy, fz], torque: [...]}}")
        out = []
        for part in ("force", "torque"):
            v = value.get(part, [0.0, 0.0, 0.0])
            if not isinstance(v, list) or len(v) != 3:
                raise self.fail(f"load: {part}", f"{v!r}; expected 3 numbers [N or N m]")
            out += [self.number(x, f"load: {part}") for x in v]
        return tuple(out)

    def workspace(self, value) -> dict:
        if value is None:
            return {}
        if not isinstance(value, Mapping) or not set(value) <= {"sweep", "fixed", "points"}:
            raise self.fail("workspace", f"{value!r}; expected sweep (with fixed) or points")
        if ("sweep" in value) == ("points" in value) or ("fixed" in value and "points" in value):
            raise self.fail("workspace", "expected either sweep (with fixed) or points")
        if "points" in value:
            rows = value["points"]
            if not isinstance(rows, list) or not rows or not all(isinstance(r, list) for r in rows):
                raise self.fail("workspace: points", "expected a list of rows of actuated values")
            return {"points": tuple(tuple(self.number(x, "workspace: points") for x in r)
                                    for r in rows)}  # fmt: skip
        sweeps = []
        for joint, spec in self.mapping(value, "sweep").items():
            key = f"workspace: sweep: {joint}"
            try:
                values = (parse_values(spec) if isinstance(spec, str)
                          else [self.number(x, key) for x in (spec if isinstance(spec, list)
                                                               else [spec])])  # fmt: skip
            except SpecError as e:
                raise self.fail(key, str(e)) from None
            sweeps.append((joint, tuple(float(x) for x in values)))
        fixed = tuple((j, self.number(v, f"workspace: fixed: {j}"))
                      for j, v in self.mapping(value, "fixed").items())  # fmt: skip
        return {"sweeps": tuple(sweeps), "fixed": fixed}
