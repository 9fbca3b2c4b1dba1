"""Shared helpers of the benchmark scripts: modes, interleaved timing, environment, table."""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Mode:
    """How hard to measure: repeats (medians over them) and the length of one batch [s]."""

    name: str
    repeats: int
    batch_seconds: float

    @property
    def smoke(self) -> bool:
        return self.name == "smoke"


MODES = {
    "smoke": Mode("smoke", 1, 0.0),  # one call of everything: checks that rows print
    "quick": Mode("quick", 5, 0.01),
    "full": Mode("full", 9, 0.04),
}


#: Environment variables that set the number of BLAS / LAPACK threads.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def parse_mode(doc: str, argv: Sequence[str] | None = None) -> Mode:
    """--quick / --smoke / (default) full, from the command line.

    ``--blas-threads N`` runs the script again with N BLAS threads (the variables must be
    set before numpy is loaded); the sweep workers inherit them.
    """
    parser = argparse.ArgumentParser(description=doc)
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--quick", action="store_true", help="short run (< 60 s)")
    group.add_argument("--smoke", action="store_true", help="one iteration of each row")
    parser.add_argument(
        "--blas-threads", type=int, metavar="N", help="BLAS threads per process (default: all)"
    )
    args = parser.parse_args(argv)
    if args.blas_threads is not None and argv is None:
        wanted = str(args.blas_threads)
        if any(os.environ.get(k) != wanted for k in BLAS_THREAD_VARIABLES):
            os.environ.update(dict.fromkeys(BLAS_THREAD_VARIABLES, wanted))
            os.execv(sys.executable, [sys.executable, *sys.argv])
    return MODES["smoke" if args.smoke else "quick" if args.quick else "full"]


#: Shortest batch of unit calls [s] (also in a smoke run: a single call is too noisy).
UNIT_BATCH_SECONDS = 0.002
#: Shortest unit batch as a share of the row's batch: the speed of a machine whose load
#: changes drifts within a long row (a sweep of 0.3 s), which 2 ms of unit calls on one
#: side of it do not sample (units 1.7 and 2.7 us within one run were seen so).
UNIT_SHARE = 0.1


@dataclass(frozen=True)
class Timing:
    """Medians over repeats: time of one call [s], of one unit call [s], and their ratio
    (command lines: also the ratio of their CPU times)."""

    seconds: float
    unit: float
    ratio: float
    repeats: int = 1
    cpu_ratio: float = math.nan


#: The clock of the timed batches: the CPU time of this process (its BLAS threads
#: included), so that the time it waits for a core of a loaded machine (shared with others)
#: does not count; what the other processes do to the caches still does, which the
#: alternating batches share out.
clock = time.process_time


def _calls(func: Callable[[], object], seconds: float) -> int:
    """Calls per batch so that a batch lasts about ``seconds`` (after one warm-up call)."""
    start = clock()
    func()
    one = clock() - start
    return max(1, int(seconds / max(one, 1e-9)))


def _batch(func: Callable[[], object], calls: int) -> float:
    start = clock()
    for _ in range(calls):
        func()
    return (clock() - start) / calls


def interleaved(
    func: Callable[[], object],
    unit: Callable[[], object],
    mode: Mode,
    per: int = 1,
    once: bool = False,
    budget: float = float("inf"),
) -> Timing:
    """Time ``func`` against ``unit`` in alternating batches (unit, func, unit, func...).

    Each batch of ``func`` is bracketed by two unit batches, each lasting at least
    :data:`UNIT_SHARE` of it, and its ratio uses their mean; ``per`` divides the time of
    one ``func`` call (e.g. the number of poses of a sweep); ``once``: one call of ``func``
    per repeat and no warm-up (long runs), and no new repeat once the repeats have taken
    ``budget`` seconds.
    """
    n_func = 1 if once else _calls(func, mode.batch_seconds)
    n_unit = _calls(unit, max(mode.batch_seconds, UNIT_BATCH_SECONDS))
    times, units, ratios = [], [], []
    start = clock()
    after = _batch(unit, n_unit)
    for _ in range(mode.repeats):
        if times and clock() - start > budget:
            break
        before = after
        call = _batch(func, n_func)
        after = _batch(unit, n_unit)
        u = 0.5 * (before + after)
        times.append(call / per)
        units.append(u)
        ratios.append(call / per / u)
        if UNIT_SHARE * call * n_func > n_unit * u:  # longer unit batches from now on
            n_unit = int(UNIT_SHARE * call * n_func / u) + 1
            after = _batch(unit, n_unit)
    return Timing(
        statistics.median(times), statistics.median(units), statistics.median(ratios), len(times)
    )


#: How a command line is started in :func:`wall_ratio`: as an installed package runs, its
#: bytecode cached (``PYTHONDONTWRITEBYTECODE`` left out, a first run writes the cache), or
#: compiled from its source at every run (a copy of the packages without bytecode, with
#: ``PYTHONDONTWRITEBYTECODE=1``; the libraries underneath as installed).
START_MODES = ("bytecode cached", "compiled from source")
#: The packages and data a command line needs, copied for a start from source.
SOURCE_TREE = ("closedloop", "cahyman_pin", "urdf")


@contextlib.contextmanager
def source_copy():
    """A folder with a copy of :data:`SOURCE_TREE` (no ``__pycache__``), for
    ``PYTHONPATH``; removed afterwards."""
    repo = Path(__file__).resolve().parent.parent
    with tempfile.TemporaryDirectory() as folder:
        for name in SOURCE_TREE:
            shutil.copytree(repo / name, Path(folder, name),
                            ignore=shutil.ignore_patterns("__pycache__"))  # fmt: skip
        yield folder


def wall_ratio(
    command: Sequence[str], reference: Sequence[str], mode: Mode, start: str = START_MODES[0]
) -> Timing:
    """Median wall time of a command and of a reference command, run alternately (``start``:
    one of :data:`START_MODES`); the ratio is the median of the pairs' ratios. The medians
    of their CPU times (user + system, children's accounting) are in ``cpu_ratio``."""
    runs = 1 if mode.smoke else 5 if mode.name == "quick" else 9
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}

    def run(cmd: Sequence[str], env: dict) -> tuple[float, float]:
        before, start_time = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=env)
        wall, after = time.perf_counter() - start_time, resource.getrusage(resource.RUSAGE_CHILDREN)
        return wall, (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)

    def pairs(env: dict) -> list[tuple]:
        run(command, env)  # warm the file cache (and write the bytecode when cached)
        return [(run(reference, env), run(command, env)) for _ in range(runs)]

    if start == START_MODES[0]:
        measured = pairs(env)
    else:
        with source_copy() as folder:
            path = os.pathsep.join([folder, *filter(None, [env.get("PYTHONPATH")])])
            measured = pairs({**env, "PYTHONPATH": path, "PYTHONDONTWRITEBYTECODE": "1"})
    ratios = [c[0] / r[0] for r, c in measured]
    cpu = statistics.median(c[1] / r[1] for r, c in measured if r[1] > 0)
    return Timing(statistics.median(c[0] for _, c in measured),
                  statistics.median(r[0] for r, _ in measured),
                  statistics.median(ratios), runs, cpu)  # fmt: skip


def growth_exponent(nv: Sequence[int], seconds: Sequence[float]) -> float:
    """Slope of log(time) against log(nv), least squares on the upper half of the sizes."""
    order = np.argsort(nv)
    upper = order[len(order) // 2 :]
    x, y = np.log(np.asarray(nv, float)[upper]), np.log(np.asarray(seconds, float)[upper])
    return float(np.polyfit(x, y, 1)[0])


def fmt_time(seconds: float) -> str:
    """A time with a readable unit (ns, us, ms, s)."""
    if not math.isfinite(seconds):
        return str(seconds)
    for scale, name in ((1.0, "s"), (1e-3, "ms"), (1e-6, "us")):
        if seconds >= scale:
            return f"{seconds / scale:.3g} {name}"
    return f"{seconds * 1e9:.3g} ns"


def cores() -> tuple[int, int]:
    """(cores of the machine, cores usable by this process)."""
    total = os.cpu_count() or 1
    try:
        return total, len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return total, total


def lapack_probe() -> str:
    """Time of a small least-squares solve (dgels, 27 x 15, 12 right-hand sides): a few us
    single-threaded; 10-100x more when a multi-threaded BLAS fights a loaded machine."""
    import scipy.linalg

    rng = np.random.default_rng(0)
    A, B = rng.standard_normal((27, 15)), rng.standard_normal((27, 12))
    t = interleaved(lambda: scipy.linalg.lapack.dgels(A, B), lambda: None, MODES["quick"])
    setting = ", ".join(f"{k}={os.environ.get(k, 'unset')}" for k in BLAS_THREAD_VARIABLES)
    return f"LAPACK probe: dgels 27x15 {fmt_time(t.seconds)} ({setting})"


def load() -> str:
    """The load average (1, 5, 15 min) as text."""
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


class Table:
    """A Markdown table of rows (id, row, target, measured, absolute), printed as it grows.

    The environment (versions, cores, load average) comes before it, the notes and the
    load average at the end after it.
    """

    HEADER = ("id", "row", "target", "measured", "absolute")

    def __init__(self, title: str, mode: Mode):
        import pinocchio as pin

        total, usable = cores()
        print(f"# {title} ({mode.name} run: medians of {mode.repeats} repeats)")
        print(f"python {platform.python_version()}, pin {pin.__version__}, numpy {np.__version__}"
              f"; {total} cores ({usable} usable); load average at start: {load()}")  # fmt: skip
        print(lapack_probe())
        print("unit = one pinocchio.computeJointJacobians call on the same model, timed in "
              "alternating batches with the row; times: CPU time of the benchmark's process "
              "(command lines: wall time)\n")  # fmt: skip
        print("| " + " | ".join(self.HEADER) + " |")
        print("|" + " --- |" * len(self.HEADER), flush=True)
        self.notes: list[str] = []

    def row(self, key: str, name: str, target: str, measured: str, absolute: str) -> None:
        print(f"| {key} | {name} | {target} | {measured} | {absolute} |", flush=True)

    def units(self, key: str, name: str, target: str, t: Timing, what: str = "") -> None:
        """A row measured in units of the computeJointJacobians call."""
        unit = f"unit {fmt_time(t.unit)}"
        self.row(key, name, target, f"{t.ratio:.1f} units", f"{fmt_time(t.seconds)}{what}; {unit}")

    def against_floor(self, key: str, name: str, target: str, floor: Timing, t: Timing) -> None:
        """A row measured against its floor ``floor`` (the floor's timing in units): ``t``
        timed in alternating batches with the floor's numbers, its ratio to them."""
        units = t.ratio * floor.ratio
        absolute = f"{fmt_time(t.seconds)} = {units:.1f} units; floor {fmt_time(t.unit)}"
        self.row(key, name, target, f"{t.ratio:.2f}x floor", absolute)

    def command(self, key: str, name: str, target: str, t: Timing, start: str) -> None:
        """A command line's wall time against a reference command's (``start``: how both
        were started, one of :data:`START_MODES`)."""
        absolute = f"{fmt_time(t.seconds)} vs {fmt_time(t.unit)}; CPU {t.cpu_ratio:.2f}x"
        self.row(key, f"{name} ({start})", target, f"{t.ratio:.2f}x", absolute)

    def note(self, text: str) -> None:
        self.notes.append(text)

    def close(self) -> None:
        print()
        for text in self.notes:
            print(f"* {text}")
        print(f"* load average at end: {load()}", flush=True)
        sys.stdout.flush()
