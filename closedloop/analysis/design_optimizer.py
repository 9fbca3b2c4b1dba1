"""The optimiser of design problems: :func:`~closedloop.optimize_design`.

One objective: scipy's ``differential_evolution`` (a population over the parameters' box,
each generation evaluated at once), then a bounded local polish from its best design
(SLSQP with the constraints, gradients by central differences evaluated at once), so that
an optimum on a constraint is found to the constraint's tolerance, not to the population's
spread. Differential evolution ranks the designs by Deb's rule: any design that meets the
constraints before any that does not, those by their violation, the others by their
objective. Two or more objectives: NSGA-II
(:mod:`closedloop.analysis.nsga2`); the Pareto front is the non-dominated set of every
design evaluated.

Designs are evaluated by :func:`closedloop.analysis.design_evaluation.evaluate_design` in this
process, on local processes (``workers``) or on a Dask cluster (``scheduler``), as the maps
are (:func:`closedloop.analysis.tasks.run_tasks`), every design once; the results do not
depend on where they ran. A seed makes a run reproducible. SIGINT and SIGTERM stop it with
the designs evaluated so far (:mod:`closedloop.analysis.interrupts`).
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from closedloop.analysis.design_evaluation import DesignEvaluation, DesignTask, evaluate_task
from closedloop.analysis.design_problem import DesignProblem, design_problem
from closedloop.analysis.design_result import DesignResult
from closedloop.analysis.interrupts import Interrupted, stop_on_signals
from closedloop.analysis.tasks import local_processes, run_tasks
from closedloop.common.progress import progress
from closedloop.exceptions import InvalidInputError

#: Evaluations a run may make per parameter, plus as many again, when no budget is given.
BUDGET_PER_PARAMETER = 100
#: Share of a one-objective budget left for the local polish, at most POLISH_STEPS steps.
POLISH_SHARE, POLISH_STEPS = 0.3, 30
#: Step of the central differences of the polish, in units of each parameter's range:
#: truncation error ~ h^2, that of the values' rounding (the assembly's tolerance, ~1e-12
#: relative) ~ 1e-12 / h; both below 1e-6 of the derivative at this h.
FD_STEP = 1e-5
#: Tolerance of SLSQP on the scaled objective and the constraints' relative margins.
POLISH_FTOL = 1e-12
#: Relative spread of the population's ranking values at which differential evolution stops.
DE_TOL = 1e-3
#: Smallest population of either method.
MIN_POPULATION = 10


class _BudgetSpent(Exception):
    """The budget of evaluations is spent: the run stops where it is."""


class _Evaluator:
    """Evaluates batches of designs (unit-box coordinates) on the executor, each design
    once, and keeps every evaluation, the convergence history and the time spent."""

    def __init__(self, problem: DesignProblem, executor, budget: int, show_progress: bool):
        self.problem, self.executor, self.budget = problem, executor, budget
        bounds = np.array([(lo, hi) for _, lo, hi in problem.parameters])
        self.low, self.span = bounds[:, 0], bounds[:, 1] - bounds[:, 0]
        self.cache: dict[tuple, DesignEvaluation] = {}
        self.evaluations: list[DesignEvaluation] = []
        self.history: list[dict] = []
        self.seconds = 0.0  # wall time inside the batches
        self.ticks = progress(itertools.count(), total=budget, label="designs",
                              enabled=show_progress)  # fmt: skip
        next(self.ticks)

    def parameters(self, u: np.ndarray) -> tuple[float, ...]:
        return tuple(float(x) for x in self.low + np.clip(u, 0.0, 1.0) * self.span)

    def __call__(self, U: np.ndarray) -> list[DesignEvaluation]:
        """The evaluations of the designs U (m, n) in [0, 1].

        Raises:
            _BudgetSpent: after evaluating what the budget allowed.
        """
        keys = [self.parameters(u) for u in np.atleast_2d(U)]
        new = list(dict.fromkeys(k for k in keys if k not in self.cache))
        left = self.budget - len(self.evaluations)
        todo = new[: max(left, 0)]
        if todo:
            t0 = time.perf_counter()
            tasks = [DesignTask(self.problem, tuple(zip(self.problem.names, k, strict=True)))
                     for k in todo]  # fmt: skip
            done: list = [None] * len(tasks)
            try:
                for i, evaluation in run_tasks(evaluate_task, tasks, self.executor):
                    done[i] = evaluation
                    next(self.ticks)
            finally:  # stopped too (an interruption): the designs evaluated are kept
                self.seconds += time.perf_counter() - t0
                for key, evaluation in zip(todo, done, strict=True):
                    if evaluation is not None:
                        self.cache[key] = evaluation
                        self.evaluations.append(evaluation)
                self.history.append(self._record())
        if len(todo) < len(new):
            raise _BudgetSpent
        return [self.cache[k] for k in keys]

    def _record(self) -> dict:
        """The state after a batch: evaluations so far and the best feasible value of each
        objective (None before any feasible design)."""
        feasible = [e for e in self.evaluations if e.feasible]
        best = {}
        for o in self.problem.objectives:
            values = [o.sign * e.values[o.index] for e in feasible]
            best[o.index] = o.sign * min(values) if values else None
        return {"evaluations": len(self.evaluations), "best": best}

    def objectives(self, evaluations) -> tuple[np.ndarray, np.ndarray]:
        """(m, k) minimized objectives and (m,) violations of evaluations."""
        F = np.array([[o.sign * e.values[o.index] for o in self.problem.objectives]
                      for e in evaluations])  # fmt: skip
        V = np.array([0.0 if e.feasible else e.violation for e in evaluations])
        return F, V


def optimize_design(
    problem: DesignProblem | Mapping | str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    seed: int | None = None,
    budget: int | None = None,
    show_progress: bool = False,
    worker_timeout: float | None = None,
) -> DesignResult:
    """Optimise a design problem (module docstring).

    Args:
        problem: a :class:`~closedloop.analysis.design_problem.DesignProblem`, a dict of its
            form or the path of its YAML file
            (:func:`~closedloop.analysis.design_problem.design_problem`).
        workers: local processes (default: this process).
        scheduler: the address of a Dask scheduler (``tcp://host:8786``) instead; the
            model files must be readable at the same paths on its workers.
        seed: makes the run reproducible (default: a fresh one, kept in the result).
        budget: most designs evaluated (default :data:`BUDGET_PER_PARAMETER` x (number of
            parameters + 1)).
        show_progress: the designs evaluated, on stderr.
        worker_timeout: with ``scheduler``: seconds without a worker before the run stops
            (:func:`closedloop.analysis.cluster.dask_executor`).

    Returns:
        The :class:`~closedloop.analysis.design_result.DesignResult`.

    Raises:
        InvalidInputError, ModelFileError, NameNotFoundError: a bad problem or option; the
            problem's first design (the middle of the parameters' box) is evaluated before
            the run, and an error of its model or workspace is raised, not recorded.
        ClusterError: a lost Dask cluster or local process.
        Interrupted: SIGINT or SIGTERM; its ``partial`` is the result so far.
    """
    from closedloop.analysis.cluster import dask_executor
    from closedloop.analysis.design_evaluation import evaluate_design

    problem = design_problem(problem)
    n = len(problem.names)
    if budget is None:
        budget = BUDGET_PER_PARAMETER * (n + 1)
    if isinstance(budget, bool) or not isinstance(budget, int) or budget < 2:
        raise InvalidInputError(f"budget {budget!r}; expected an integer >= 2 (evaluations)")
    if workers is not None and scheduler is not None:
        raise InvalidInputError("give workers or scheduler, not both")
    if seed is None:
        seed = int(np.random.SeedSequence().entropy % 2**63)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise InvalidInputError(f"seed {seed!r}; expected an integer >= 0")
    middle = {name: (lo + hi) / 2 for name, lo, hi in problem.parameters}
    evaluate_design(problem, middle, strict=True)  # the problem's own errors, raised here
    import scipy.optimize
    import scipy.stats  # noqa: F401

    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    stopped = "budget"
    with stop_on_signals():
        with dask_executor(scheduler, worker_timeout) as dask, local_processes(workers) as pool:
            evaluator = _Evaluator(problem, dask or pool, budget, show_progress)
            try:
                if len(problem.objectives) == 1:
                    stopped = _single_objective(evaluator, rng)
                else:
                    stopped = _many_objectives(evaluator, rng)
            except _BudgetSpent:
                stopped = "budget"
            except Interrupted as stop:
                stop.partial = _result(problem, evaluator, seed, budget, t0, stop.reason)
                raise
            finally:
                evaluator.ticks.close()
    return _result(problem, evaluator, seed, budget, t0, stopped)


def _result(problem, evaluator: _Evaluator, seed, budget, t0, stopped: str) -> DesignResult:
    total = time.perf_counter() - t0
    timing = {"total": total, "evaluations": evaluator.seconds,
              "optimizer": total - evaluator.seconds,
              "kernels": math.fsum(e.seconds for e in evaluator.evaluations)}  # fmt: skip
    return DesignResult.of(problem, tuple(evaluator.evaluations), tuple(evaluator.history),
                           seed=seed, budget=budget, stopped=stopped, timing=timing)  # fmt: skip


def _energies(evaluations, objective, scale: float) -> np.ndarray:
    """Values whose order is Deb's rule, for differential evolution (minimized): a
    feasible design's scaled objective x = sign f / scale mapped into (-1, 1) by x / (1 +
    ``|x|``) (monotone); an infeasible one's violation v into (1, 2) by 1 + v / (1 + v); one
    that failed (v infinite) 2."""
    out = np.empty(len(evaluations))
    for i, e in enumerate(evaluations):
        if e.feasible:
            x = objective.sign * e.values[objective.index] / scale
            out[i] = x / (1.0 + abs(x))
        else:
            v = e.violation
            out[i] = 2.0 if math.isinf(v) else 1.0 + v / (1.0 + v)
    return out


def _single_objective(ev: _Evaluator, rng) -> str:
    """Differential evolution, then the polish (module docstring); why it stopped."""
    from scipy.optimize import differential_evolution

    n, objective = len(ev.problem.names), ev.problem.objectives[0]
    polish = min(int(POLISH_SHARE * ev.budget), POLISH_STEPS * (2 * n + 1))
    global_budget = ev.budget - polish
    population = max(MIN_POPULATION, min(15 * n, global_budget // 5))
    scale: list[float] = []  # the objective's scale, from the first population

    def energies(U: np.ndarray) -> np.ndarray:  # U: (n, S), as scipy's vectorized call
        evaluations = ev(U.T)
        if not scale:
            values = [abs(e.values[objective.index]) for e in evaluations if e.feasible]
            scale.append(float(np.median(values)) if values and np.median(values) > 0 else 1.0)
        return _energies(evaluations, objective, scale[0])

    try:
        found = differential_evolution(
            energies, [(0.0, 1.0)] * n, popsize=math.ceil(population / n),
            maxiter=max(global_budget // population - 1, 0), tol=DE_TOL, polish=False,
            init="latinhypercube", updating="deferred", vectorized=True, rng=rng,
        )  # fmt: skip
        stopped = "converged" if found.success else "budget"
    except _BudgetSpent:
        stopped = "budget"
    rank = _energies(ev.evaluations, objective, scale[0] if scale else 1.0)
    best = ev.evaluations[int(np.argmin(rank))]
    u0 = (np.array([best.parameters[k] for k in ev.problem.names]) - ev.low) / ev.span
    try:
        return "converged" if _polish(ev, u0) else stopped
    except _BudgetSpent:
        return "budget"


class _Failed(Exception):
    """A design of the polish failed (no value): the polish stops there."""


def _polish(ev: _Evaluator, u0: np.ndarray) -> bool:
    """SLSQP from u0 on the unit box with the constraints' margins, gradients by central
    differences (one-sided at a bound) evaluated at once; stops at the first design that
    fails. Returns whether SLSQP converged.

    Raises:
        _BudgetSpent: the budget is spent.
    """
    from scipy.optimize import minimize

    problem = ev.problem
    objective, n = problem.objectives[0], len(u0)
    start = ev(u0[None])[0]
    if math.isinf(start.violation):
        return False
    scale = abs(start.values[objective.index]) or 1.0

    def values(e: DesignEvaluation) -> np.ndarray:
        if math.isinf(e.violation):
            raise _Failed
        margins = [m for c in problem.constraints for m in c.margins(e.values[c.index])]
        return np.array([objective.sign * e.values[objective.index] / scale, *margins])

    def gradient(u: np.ndarray) -> np.ndarray:
        up, down = np.minimum(u + FD_STEP, 1.0), np.maximum(u - FD_STEP, 0.0)
        steps = np.eye(n)
        points = np.vstack([u + (up - u)[:, None] * steps, u + (down - u)[:, None] * steps])
        G = np.array([values(e) for e in ev(points)])
        return ((G[:n] - G[n:]) / (up - down)[:, None]).T  # (1 + constraints, n)

    memo: dict = {}

    def at(u, what, rows):
        key = (what, u.tobytes())
        if key not in memo:
            memo[key] = values(ev(u[None])[0]) if what == "value" else gradient(u)
        return memo[key][rows].copy()  # SLSQP may write into what it is given

    constraints = []
    if problem.constraints:
        constraints = [{"type": "ineq", "fun": lambda u: at(u, "value", slice(1, None)),
                        "jac": lambda u: at(u, "gradient", slice(1, None))}]  # fmt: skip
    try:
        found = minimize(lambda u: at(u, "value", 0), u0, jac=lambda u: at(u, "gradient", 0),
                         method="SLSQP", bounds=[(0.0, 1.0)] * n, constraints=constraints,
                         options={"ftol": POLISH_FTOL, "maxiter": POLISH_STEPS})  # fmt: skip
    except _Failed:
        return False
    return bool(found.success)


def _many_objectives(ev: _Evaluator, rng) -> str:
    """NSGA-II over the whole budget; the front is taken from every evaluation."""
    from scipy.stats import qmc

    from closedloop.analysis.nsga2 import nsga2

    n = len(ev.problem.names)
    size = max(MIN_POPULATION, min(8 * n + 8, ev.budget // 5))
    start = qmc.LatinHypercube(d=n, rng=rng).random(size)
    nsga2(lambda U: ev.objectives(ev(U)), start, ev.budget // size, rng)
    return "budget"
