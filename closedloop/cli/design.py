"""``closedloop design``: the dimensions, sections or springs of a parametric model that make
it stiff enough, light enough everywhere in its workspace.

    closedloop design PROBLEM.yaml [--workers N | --scheduler ADDRESS [--worker-timeout S]]
        [--seed S] [--budget N] [--out DIR]

PROBLEM.yaml names the model (a xacro file, or a robot file whose closure file has ${...}
placeholders), the parameters and their bounds, the workspace, the load, the objectives and
the constraints (closedloop.analysis.design_problem). One objective: differential evolution,
then a local polish onto the constraints; two or more: a Pareto front. Written in --out:
design.json (best, pareto, evaluations), evaluations.csv, convergence.png, pareto.png (two
objectives) and best_map/ (the stiffness map of the best design over the workspace). The
same --seed gives the same run, on any number of workers. SIGINT (Ctrl-C) or SIGTERM stops
the run and writes what it found so far (exit 130 or 143). Exit 3 when no design evaluated
meets the constraints.
"""

from __future__ import annotations

import argparse
import sys

from closedloop.analysis.cluster import add_worker_timeout
from closedloop.cli.outputs import output_folder
from closedloop.cli.parser import path_text, positive_int
from closedloop.exceptions import EXIT_FAILED


def _seed(text: str) -> int:
    """Option type of ``--seed``: an integer >= 0."""
    if not text.isascii() or not text.isdigit():
        raise argparse.ArgumentTypeError(f"{text!r}: expected an integer >= 0")
    return int(text)


def add_parser(sub, parent_arguments) -> None:
    """The ``design`` subparser (the model is the problem file's: ``parent_arguments``,
    the options of a model, are not added)."""
    p = sub.add_parser(
        "design",
        help="optimise a parametric model over its workspace (a problem file)",
        description=__doc__.split("\n\n", 1)[1],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("problem", type=path_text, metavar="PROBLEM.yaml", help="design problem")
    run = p.add_mutually_exclusive_group()
    run.add_argument("--workers", type=positive_int, metavar="N", help="local processes")
    run.add_argument("--scheduler", metavar="ADDRESS", help="Dask scheduler, e.g. tcp://h:8786")
    add_worker_timeout(p)
    p.add_argument("--seed", type=_seed, metavar="S", help="seed of the run (default: new)")
    p.add_argument("--budget", type=positive_int, metavar="N",
                   help="most designs evaluated (default 100 x (parameters + 1))")  # fmt: skip
    p.add_argument("--out", type=path_text, default="closedloop-design", metavar="DIR",
                   help="output folder (default: ./%(default)s)")  # fmt: skip
    p.set_defaults(func=run_design)


def run_design(args) -> int:
    """Run ``closedloop design``; returns the exit status (0, or 3 without a feasible
    design)."""
    from closedloop.analysis.design_optimizer import optimize_design
    from closedloop.analysis.design_problem import design_problem
    from closedloop.analysis.interrupts import Interrupted, stop_on_signals

    problem = design_problem(args.problem)
    out = output_folder(args.out)  # before any computation
    with stop_on_signals():
        try:
            result = optimize_design(problem, workers=args.workers, scheduler=args.scheduler,
                                     seed=args.seed, budget=args.budget, show_progress=True,
                                     worker_timeout=args.worker_timeout)  # fmt: skip
        except Interrupted as stop:  # what was found, written before the one line
            stop.write(lambda partial: partial.save(out, best_map=False), out)
            raise
    paths = result.save(out)
    print("\n".join(result.summary()))
    for path in paths:
        print(f"wrote {path}")
    if result.best is None:
        print("closedloop: no design evaluated meets the constraints", file=sys.stderr)
        return EXIT_FAILED
    return 0
