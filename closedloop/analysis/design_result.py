"""The result of :func:`closedloop.analysis.design_optimizer.optimize_design`: the best design,
the Pareto front, every evaluation and the history, and the files that show them
(:meth:`~closedloop.DesignResult.save`: ``design.json``, ``evaluations.csv``, ``convergence.png``,
``pareto.png`` with two objectives, and the stiffness map of the best design).
"""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from closedloop.analysis.design_evaluation import DesignEvaluation, design_map
from closedloop.analysis.design_problem import DESIGN_INDICES, DesignProblem
from closedloop.analysis.maps import StiffnessMap, column_name
from closedloop.analysis.nsga2 import nondominated_fronts
from closedloop.common.files import output_folder, save_figure, write_atomically


def pareto_set(
    problem: DesignProblem, evaluations: Sequence[DesignEvaluation]
) -> tuple[DesignEvaluation, ...]:
    """The feasible designs that no other feasible design dominates (on every objective at
    least as good, on one better), each once, in the order of the first objective."""
    unique = {tuple(e.parameters.values()): e for e in evaluations if e.feasible}
    feasible = list(unique.values())
    if not feasible:
        return ()
    F = _minimized(problem, feasible)
    front = nondominated_fronts(F, np.zeros(len(F)))[0]
    front = front[np.lexsort(F[front].T[::-1])]
    return tuple(feasible[i] for i in front)


def _minimized(problem: DesignProblem, evaluations) -> np.ndarray:
    """(m, k) objectives of evaluations, each signed to be minimized."""
    return np.array([[o.sign * e.values[o.index] for o in problem.objectives]
                     for e in evaluations]).reshape(len(evaluations), -1)  # fmt: skip


def best_design(problem: DesignProblem, pareto: Sequence[DesignEvaluation]):
    """The best design of a front: the best value with one objective; with several, the
    compromise, the design nearest to the ideal point once each objective is scaled to
    [0, 1] over the front (0 its best value on the front, 1 its worst); None without one."""
    if not pareto:
        return None
    F = _minimized(problem, pareto)
    low, high = F.min(axis=0), F.max(axis=0)
    scaled = (F - low) / np.where(high > low, high - low, 1.0)
    return pareto[int(np.argmin(np.linalg.norm(scaled, axis=1)))]


@dataclass(frozen=True)
class DesignResult:
    """What a design run found.

    Attributes:
        problem: the problem.
        best: the best feasible design (:func:`best_design`), or None when no design
            evaluated is feasible.
        pareto: the non-dominated feasible designs (:func:`pareto_set`; one objective: the
            best one).
        evaluations: every design evaluated, in order.
        history: after each batch of evaluations: ``{"evaluations": count, "best": {index:
            best feasible value so far, or None}}``.
        seed: the seed of the run (the same seed gives the same run).
        budget: the most evaluations the run could make.
        stopped: why it stopped: ``converged``, ``budget`` or ``interrupted by SIGINT``.
        timing: seconds: ``total``, ``evaluations`` (waiting for the batches),
            ``optimizer`` (the rest: the optimiser's own work), ``kernels`` (the
            evaluations' own times, summed over the processes).
    """

    problem: DesignProblem
    best: DesignEvaluation | None
    pareto: tuple[DesignEvaluation, ...]
    evaluations: tuple[DesignEvaluation, ...]
    history: tuple[dict, ...] = ()
    seed: int | None = None
    budget: int | None = None
    stopped: str = ""
    timing: dict = field(default_factory=dict)

    @classmethod
    def of(cls, problem: DesignProblem, evaluations, history=(), **fields) -> DesignResult:
        """The result of these evaluations (front and best computed)."""
        pareto = pareto_set(problem, evaluations)
        return cls(problem, best_design(problem, pareto), pareto, tuple(evaluations),
                   tuple(history), **fields)  # fmt: skip

    def to_dict(self) -> dict:
        """JSON-ready: the problem, ``best``, ``pareto``, ``evaluations``, the history, the
        seed, the budget, why it stopped, the timing (NaN and infinity as None)."""
        return {
            "problem": self.problem.to_dict(),
            "best": None if self.best is None else self.best.to_dict(),
            "pareto": [e.to_dict() for e in self.pareto],
            "evaluations": [e.to_dict() for e in self.evaluations],
            "history": list(self.history), "seed": self.seed, "budget": self.budget,
            "stopped": self.stopped, "timing": dict(self.timing),
            "units": {i: DESIGN_INDICES[i] for i in self.problem.indices},
        }  # fmt: skip

    def summary(self) -> list[str]:
        """Lines that say what was found."""
        feasible = sum(e.feasible for e in self.evaluations)
        lines = [f"{len(self.evaluations)} designs evaluated, {feasible} feasible "
                 f"(stopped: {self.stopped}; seed {self.seed})"]  # fmt: skip
        if self.best is None:
            reasons = [e.reason for e in self.evaluations if e.reason]
            common = max(set(reasons), key=reasons.count) if reasons else "none evaluated"
            return [*lines, f"no feasible design; most often: {common}"]
        best = ", ".join(f"{n} = {v:.6g}" for n, v in self.best.parameters.items())
        values = ", ".join(f"{i} = {v:.6g} {DESIGN_INDICES[i]}"
                           for i, v in self.best.values.items())  # fmt: skip
        lines += [f"best: {best}", f"  {values}"]
        if len(self.problem.objectives) > 1:
            lines.append(f"Pareto front: {len(self.pareto)} designs")
        return lines

    def best_map(self) -> StiffnessMap | None:
        """The stiffness map of the best design over the workspace (every index of the
        map; ``lowest_frequency`` when the problem needs it), or None without a best
        design."""
        if self.best is None:
            return None
        return design_map(self.problem, self.problem.source(self.best.parameters).load())

    def save(self, out: str | Path, best_map: bool = True) -> list[Path]:
        """Write ``design.json`` (:meth:`to_dict`), ``evaluations.csv`` (a row per design:
        parameters, index values with their units, feasible, violation, reason),
        ``convergence.png``, ``pareto.png`` (two objectives), and, with ``best_map``, a
        best design and a workspace (not the reference pose alone), its stiffness map in
        ``best_map/``
        (:meth:`~closedloop.analysis.maps.StiffnessMap.save`, the picture of the first map
        index of the objectives and constraints, else ``min_translational``); returns the
        paths.

        Raises:
            InvalidInputError: ``out`` is not a folder that can be written.
        """
        out = output_folder(out)
        text = json.dumps(self.to_dict(), indent=1, allow_nan=False)
        paths = [write_atomically(out / "design.json", lambda f: f.write(text), text=True)]
        paths.append(write_atomically(out / "evaluations.csv", self._write_csv, text=True,
                                      newline=""))  # fmt: skip
        paths.append(plot_convergence(self, out / "convergence.png"))
        if len(self.problem.objectives) == 2:
            paths.append(plot_pareto(self, out / "pareto.png"))
        workspace = self.problem.sweeps is not None or self.problem.points is not None
        if best_map and workspace and self.best is not None:
            maps = [i for i in self.problem.indices if i != "mass"]
            smap = self.best_map()
            paths += smap.save(out / "best_map", maps[0] if maps else "min_translational")
        return paths

    def _write_csv(self, f) -> None:
        indices = self.problem.indices
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(["evaluation", *self.problem.names,
                         *(column_name(i, DESIGN_INDICES[i]) for i in indices),
                         "feasible", "violation", "reason"])  # fmt: skip
        for k, e in enumerate(self.evaluations):
            writer.writerow([k, *map(repr, e.parameters.values()),
                             *(repr(e.values[i]) for i in indices), e.feasible,
                             repr(e.violation), e.reason])  # fmt: skip


def _label(problem: DesignProblem, index: str) -> str:
    goal = next((o.goal for o in problem.objectives if o.index == index), "")
    return f"{index} [{DESIGN_INDICES[index]}]" + (f" ({goal})" if goal else "")


def plot_convergence(result: DesignResult, path: Path) -> Path:
    """PNG: each objective of every feasible design against the evaluation count, and the
    best value so far."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    objectives = result.problem.objectives
    fig, axes = plt.subplots(len(objectives), 1, figsize=(6.4, 2.4 + 2.2 * len(objectives)),
                             dpi=100, squeeze=False, sharex=True)  # fmt: skip
    feasible = [(k, e) for k, e in enumerate(result.evaluations) if e.feasible]
    for ax, o in zip(axes[:, 0], objectives, strict=True):
        ax.plot([k for k, _ in feasible], [e.values[o.index] for _, e in feasible], ".",
                color="0.7", label="feasible designs")  # fmt: skip
        steps = [(h["evaluations"], h["best"][o.index]) for h in result.history
                 if h["best"].get(o.index) is not None]  # fmt: skip
        if steps:
            ax.step(*zip(*steps, strict=True), where="post", color="C0", label="best so far")
        ax.set_ylabel(_label(result.problem, o.index), fontsize=8)
        ax.legend(fontsize=8)
    axes[-1, 0].set_xlabel("designs evaluated")
    infeasible = len(result.evaluations) - len(feasible)
    axes[0, 0].set_title(f"convergence: {len(result.evaluations)} designs, {infeasible} "
                         f"infeasible (stopped: {result.stopped})", fontsize=9)  # fmt: skip
    fig.tight_layout()
    return save_figure(fig, path)


def plot_pareto(result: DesignResult, path: Path) -> Path:
    """PNG of a two-objective run: every design (feasible grey, infeasible red crosses where
    their values exist), the Pareto front and the best design (a star)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a, b = (o.index for o in result.problem.objectives)
    fig, ax = plt.subplots(figsize=(6.4, 4.8), dpi=100)
    for feasible, style in ((True, {"marker": ".", "color": "0.7"}),
                            (False, {"marker": "x", "color": "C3", "alpha": 0.4})):  # fmt: skip
        points = [(e.values[a], e.values[b]) for e in result.evaluations
                  if e.feasible == feasible and math.isfinite(e.values[a])
                  and math.isfinite(e.values[b])]  # fmt: skip
        if points:
            label = "feasible designs" if feasible else "infeasible designs"
            ax.plot(*zip(*points, strict=True), linestyle="none", label=label, **style)
    if result.pareto:
        front = sorted((e.values[a], e.values[b]) for e in result.pareto)
        ax.plot(*zip(*front, strict=True), "o-", color="C0", ms=4, label="Pareto front")
    if result.best is not None:
        ax.plot(result.best.values[a], result.best.values[b], "*", color="C1", ms=16,
                label="best (compromise)")  # fmt: skip
    ax.set_xlabel(_label(result.problem, a))
    ax.set_ylabel(_label(result.problem, b))
    ax.set_title(f"Pareto front: {len(result.pareto)} of {len(result.evaluations)} designs",
                 fontsize=9)  # fmt: skip
    ax.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)
