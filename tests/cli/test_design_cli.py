"""``closedloop design``: its files, the same run on two processes, Ctrl-C with the results so
far written, one-line errors."""

from __future__ import annotations

import csv
import json
import logging
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import psutil
import pytest
import yaml
from dask.distributed import LocalCluster
from helpers import REPO

from closedloop.cli.app import main

DATA = REPO / "tests" / "data"
two_cores = pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="needs 2 cores for 2 workers")
#: Seconds the command may take to start evaluating, then to end after SIGINT (a batch of
#: designs of the four-bar is well under a second; the files about a second).
START_TIMEOUT, STOP_TIMEOUT = 60.0, 20.0


def problem_file(tmp_path: Path, **changes) -> Path:
    """The four-bar with tubes of diameter d: lightest and stiffest over four crank angles."""
    problem = {
        "model": str(REPO / "urdf" / "fourbar.urdf"),
        "closures": str(DATA / "xacro" / "fourbar_beams.yaml"), "frame": "P",
        "parameters": {"d": [0.005, 0.04]},
        "workspace": {"sweep": {"crank": "0.2:1.1:4"}},
        "objectives": [{"index": "mass", "goal": "minimize"},
                       {"index": "min_translational", "goal": "maximize"}],
        "constraints": [{"index": "min_translational", "min": 1000.0}],
        **changes,
    }  # fmt: skip
    path = tmp_path / "problem.yaml"
    path.write_text(yaml.safe_dump(problem))
    return path


def test_design_writes_its_files(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["design", str(problem_file(tmp_path)), "--seed", "1", "--budget", "12",
                 "--out", str(out)]) == 0  # fmt: skip
    printed = capsys.readouterr().out
    assert "12 designs evaluated" in printed and "Pareto front:" in printed
    doc = json.loads((out / "design.json").read_text())
    assert len(doc["evaluations"]) == 12 and doc["seed"] == 1 and doc["budget"] == 12
    assert doc["best"] in doc["pareto"] and doc["best"]["feasible"]
    assert doc["units"] == {"mass": "kg", "min_translational": "N/m"}
    with open(out / "evaluations.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["evaluation", "d", "mass_kg", "min_translational_N_per_m", "feasible",
                       "violation", "reason"]  # fmt: skip
    assert len(rows) == 13 and float(rows[1][1]) == doc["evaluations"][0]["parameters"]["d"]
    for name in ("convergence.png", "pareto.png", "best_map/map.png", "best_map/map.npz"):
        assert (out / name).stat().st_size > 0, name


def run_evaluations(tmp_path: Path, name: str, *extra: str) -> list:
    """The (parameters, values) of each design of a run with seed 4 and budget 8."""
    assert main(["design", str(problem_file(tmp_path)), "--seed", "4", "--budget", "8",
                 "--out", str(tmp_path / name), *extra]) == 0  # fmt: skip
    doc = json.loads((tmp_path / name / "design.json").read_text())
    return [(e["parameters"], e["values"]) for e in doc["evaluations"]]


@two_cores
def test_two_processes_and_dask_give_the_same_run(tmp_path, capsys):
    serial = run_evaluations(tmp_path, "one")
    me = psutil.Process()
    before = {p.pid for p in me.children(recursive=True)}  # earlier tests' helpers, if any
    assert run_evaluations(tmp_path, "two", "--workers", "2") == serial
    left = [p for p in me.children(recursive=True) if p.pid not in before]
    assert not left  # the pool ended with the run
    # a worker thread in this process: Dask's executor as a cluster's, without its start-up
    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                           dashboard_address=None, silence_logs=logging.CRITICAL)  # fmt: skip
    with cluster:
        assert run_evaluations(tmp_path, "dask", "--scheduler", cluster.scheduler_address) == serial


def test_no_feasible_design_exits_3(tmp_path, capsys):
    path = problem_file(tmp_path, constraints=[{"index": "min_translational", "min": 1.0e12}])
    assert main(["design", str(path), "--budget", "8", "--out", str(tmp_path / "o")]) == 3
    out, err = capsys.readouterr()
    assert "no feasible design; most often: 1e+12 <= min_translational not met" in out
    assert err.splitlines()[-1] == "closedloop: no design evaluated meets the constraints"
    assert json.loads((tmp_path / "o" / "design.json").read_text())["best"] is None


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (["missing.yaml"], "design problem 'missing.yaml' does not exist or is not a file"),
        (["{problem}", "--seed", "-3"], "argument --seed: '-3': expected an integer >= 0"),
        (["{problem}", "--workers", "2", "--scheduler", "tcp://h:1"], "not allowed with"),
    ],
)
def test_errors_are_one_line(tmp_path, capsys, args, match):
    problem = str(problem_file(tmp_path))
    assert main(["design", *(a.format(problem=problem) for a in args)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and match in err, err


def _lines(stream, into: queue.Queue) -> None:
    for line in stream:
        into.put(line.rstrip("\n"))
    into.put(None)


@two_cores
def test_ctrl_c_writes_the_results_so_far(tmp_path):
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "closedloop", "design", str(problem_file(tmp_path)),
         "--workers", "2", "--budget", "4000", "--seed", "0", "--out", str(out)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=REPO,
        start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )  # fmt: skip
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=_lines, args=(proc.stderr, lines), daemon=True).start()
    try:
        deadline, seen = time.monotonic() + START_TIMEOUT, []
        while not any(line.startswith("designs: ") for line in seen):  # the first progress
            line = lines.get(timeout=max(0.0, deadline - time.monotonic()))
            assert line is not None, f"ended before evaluating: {seen}"
            seen.append(line)
        workers = psutil.Process(proc.pid).children(recursive=True)
        assert len(workers) >= 2, workers
        os.killpg(proc.pid, signal.SIGINT)  # as Ctrl-C: the whole process group
        code = proc.wait(timeout=STOP_TIMEOUT)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    after = []
    while (line := lines.get(timeout=5)) is not None:
        after.append(line)
    assert code == 130
    assert after[-1] == f"closedloop: interrupted (SIGINT): wrote the results so far to {out}"
    doc = json.loads((out / "design.json").read_text())
    assert doc["stopped"] == "interrupted by SIGINT" and 0 < len(doc["evaluations"]) < 4000
    assert doc["best"] is not None and (out / "evaluations.csv").exists()
    _, alive = psutil.wait_procs(workers, timeout=3)
    assert not alive
