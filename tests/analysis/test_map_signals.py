"""Maps stopped by SIGINT (Ctrl-C) or SIGTERM: the workers end at once, the points computed
are written, the rest marked ``not_computed``; one line on stderr, exit 128 + the signal."""

from __future__ import annotations

import csv
import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import psutil
import pytest
from helpers import REPO, default_sigint, map_argv

from closedloop.analysis.interrupts import Interrupted, stop_on_signals
from closedloop.analysis.map_results import STATUS, ChunkResult
from closedloop.analysis.maps import StiffnessMap, stiffness_map
from closedloop.analysis.model_source import ModelSource
from closedloop.analysis.tasks import gather, run_tasks

#: The tests of worker processes: a map's pool has at most one process a core.
two_cores = pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="needs 2 cores for 2 workers")
#: Seconds a command may take to start computing (imports, the estimate, the border pass).
START_TIMEOUT = 60.0
#: Seconds from the signal to the end of the command (1-3 s seen on a loaded machine:
#: the map ended, its files written, the figure about a second), well under what the rest
#: of the map takes on two workers (5-16 s, more on a loaded machine).
STOP_TIMEOUT = 10.0
#: Seconds the workers may take to be gone after the command has ended.
REAP_TIMEOUT = 3.0

#: ``closedloop map`` of 8100 points (the delta robot, 1-2 ms a point; CSV written) and
#: ``cahyman map`` of 19600 (generic backend from the neighbour, about 0.3 ms a point).
COMMANDS = {
    "closedloop": ([*map_argv("closedloop", 90), "--chunk", "20"], "map points: "),
    "cahyman": ([*map_argv("cahyman", 140), "--start", "neighbour", "--chunk-size", "20"],
                "generic sweep: "),
}  # fmt: skip


def _lines(stream, into: queue.Queue) -> None:
    for line in stream:
        into.put(line.rstrip("\n"))
    into.put(None)


def _left(processes: list) -> list:
    """The processes still alive :data:`REAP_TIMEOUT` seconds on (killed, not to outlive
    a failed test)."""
    _, alive = psutil.wait_procs(processes, timeout=REAP_TIMEOUT)
    for process in alive:
        process.kill()
    return alive


def _computing_map(out: Path) -> tuple[subprocess.Popen, list]:
    """``closedloop map --workers 2`` in a session of its own, once its first progress line
    is out: (the process, its worker processes)."""
    argv, label = COMMANDS["closedloop"]
    proc = subprocess.Popen(
        [sys.executable, *argv, "--workers", "2", "--out", str(out)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=REPO,
        start_new_session=True,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + START_TIMEOUT
        while not proc.stderr.readline().startswith(label):
            assert time.monotonic() < deadline and proc.poll() is None
        return proc, psutil.Process(proc.pid).children(recursive=True)
    except BaseException:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        raise


def _interrupted_run(prog: str, sig: signal.Signals, out: Path):
    """Start ``prog map --workers 2``, wait for its first progress line, send ``sig`` (SIGINT
    to the process group, as Ctrl-C; SIGTERM to the main process only), and return
    (exit code, stderr lines after the signal, the workers, seconds to the exit)."""
    argv, progress_label = COMMANDS[prog]
    proc = subprocess.Popen(
        [sys.executable, *argv, "--workers", "2", "--out", str(out)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, cwd=REPO,
        start_new_session=True, preexec_fn=default_sigint,
    )  # fmt: skip
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=_lines, args=(proc.stderr, lines), daemon=True).start()
    try:
        deadline = time.monotonic() + START_TIMEOUT
        seen = []
        while not any(line.startswith(progress_label) for line in seen):
            line = lines.get(timeout=max(0.0, deadline - time.monotonic()))
            assert line is not None, f"ended before computing: {seen}"
            seen.append(line)
        workers = psutil.Process(proc.pid).children(recursive=True)
        assert len(workers) >= 2, workers
        t0 = time.monotonic()
        if sig == signal.SIGINT:
            os.killpg(proc.pid, sig)
        else:
            proc.send_signal(sig)
        code = proc.wait(timeout=STOP_TIMEOUT)
        elapsed = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    after = []
    while (line := lines.get(timeout=5.0)) is not None:
        after.append(line)
    return code, after, workers, elapsed, progress_label


@two_cores
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize("prog", list(COMMANDS))
def test_a_signal_stops_the_map_and_writes_what_it_computed(tmp_path, prog, sig):
    out = tmp_path / "map"
    code, after, workers, elapsed, _ = _interrupted_run(prog, sig, out)
    assert not _left(workers), "workers left"
    assert code == 128 + sig, after
    assert elapsed < STOP_TIMEOUT, elapsed
    # what the signal prints: one line, the only one (the progress display closes without
    # its last count line)
    assert len(after) == 1, after
    found = re.fullmatch(rf"{prog}: interrupted \({sig.name}\): wrote (\d+) of (\d+) points to "
                         rf"{re.escape(str(out))}", after[0])  # fmt: skip
    assert found, after
    done, total = int(found[1]), int(found[2])
    assert 0 < done < total
    with np.load(out / "map.npz") as data:
        status = data["status"]
        if "reasons" in data:  # closedloop's
            reasons = data["reasons"]
        else:  # cahyman's: the distinct texts and a code a point
            reasons = data["reason_texts"][data["reason_codes"]]
        C = data["C"]
    assert len(status) == total
    lost = status == "not_computed"
    assert np.count_nonzero(~lost) == done
    assert set(reasons[lost]) == {f"interrupted by {sig.name}"}
    assert np.all(np.isnan(C[lost]))
    computed = np.isin(status, ("ok", "rank_deficient"))
    assert computed.any() and np.all(np.isfinite(C[computed]))
    with open(out / "map.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == total
    assert [r["status"] for r in rows] == status.tolist()
    assert {r["reason"] for r in rows if r["status"] == "not_computed"} == {
        f"interrupted by {sig.name}"
    }


@two_cores
def test_a_keyboard_interrupt_in_python_ends_the_workers_and_keeps_the_partial_map():
    """stiffness_map(workers=2) interrupted (SIGINT to this process, as Ctrl-C once the
    workers run): Interrupted, a KeyboardInterrupt, with the map so far; no worker left."""
    source = ModelSource(str(REPO / "urdf/delta.urdf"), str(REPO / "urdf/delta.yaml"))
    me = psutil.Process()
    before = {p.pid for p in me.children(recursive=True)}
    workers: list = []

    def interrupt_when_computing():
        deadline = time.monotonic() + START_TIMEOUT
        while time.monotonic() < deadline:
            new = [p for p in me.children(recursive=True) if p.pid not in before]
            if len(new) >= 2:
                workers.extend(new)
                time.sleep(0.3)  # chunks under way
                os.kill(os.getpid(), signal.SIGINT)
                return
            time.sleep(0.02)

    thread = threading.Thread(target=interrupt_when_computing, daemon=True)
    thread.start()
    values = np.linspace(-0.3, 0.3, 50)
    with pytest.raises(KeyboardInterrupt) as caught:
        stiffness_map(source, "platform", sweeps={"arm0": values, "arm1": values},
                      fixed={"arm2": 0.0}, workers=2, chunk=20)  # fmt: skip
    thread.join()
    stop = caught.value
    assert isinstance(stop, Interrupted) and stop.signum == signal.SIGINT
    assert workers and not _left(workers)
    partial = stop.partial
    assert isinstance(partial, StiffnessMap) and partial.inputs.shape == (2500, 3)
    lost = partial.status == "not_computed"
    assert lost.any()
    assert {partial.reasons[i] for i in np.flatnonzero(lost)} == {"interrupted by SIGINT"}
    assert np.all(np.isnan(partial.C[lost]))
    assert np.all(np.isnan(partial.indices["min_translational"][lost]))
    assert str(stop) == "interrupted (SIGINT); nothing written"


@two_cores
def test_a_worker_ends_with_its_parent_killed_by_sigkill(tmp_path):
    """A parent that cannot clean up (SIGKILL) takes its workers with it (Linux)."""
    if not sys.platform.startswith("linux"):
        pytest.skip("the parent-death signal is Linux's")
    proc, workers = _computing_map(tmp_path)
    try:
        assert len(workers) >= 2
        proc.kill()
        proc.wait()
        assert not _left(workers)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


@two_cores
def test_a_worker_killed_mid_map_stops_the_command_in_one_line(tmp_path):
    """A worker killed by SIGKILL while computing: the command does not hang; one line,
    exit 3 (a failed computation), no process left."""
    proc, workers = _computing_map(tmp_path)
    try:
        workers[0].kill()
        code = proc.wait(timeout=STOP_TIMEOUT)
        err = proc.stderr.read().splitlines()
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert not _left(workers)
    assert code == 3
    own = [line for line in err if not line.startswith(COMMANDS["closedloop"][1])]
    assert own == ["closedloop: error: a worker process of the map ended abruptly (killed, or "
                   "out of memory?); the map stopped, the others ended"]  # fmt: skip


def _computed(n: int):
    """The data of a map of ``n`` points, every one computed (gathered from one chunk)."""
    chunk = ChunkResult.empty(n)
    chunk.C[:] = np.eye(6)
    return gather(n, [np.arange(n)], iter([(0, chunk)]))


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_once_the_map_is_held_is_raised_when_the_block_ends(sig):
    """Held (its files being written), the first signal lets the block run to its end, a
    second is ignored; then Interrupted, with the map and the folder written; the handlers
    are set back."""
    defaults = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    data = _computed(3)
    done = []
    with pytest.raises(Interrupted) as caught:
        with stop_on_signals() as signals:
            signals.hold(data, "out")
            os.kill(os.getpid(), sig)  # its handler runs before os.kill returns
            done.append("written")
            os.kill(os.getpid(), signal.SIGINT)
            done.append("printed")
    assert done == ["written", "printed"]
    stop = caught.value
    assert stop.signum == sig and stop.data is data
    assert str(stop) == f"interrupted ({sig.name}): wrote 3 of 3 points to out"
    assert {s: signal.getsignal(s) for s in defaults} == defaults


def test_a_signal_before_the_hold_stops_the_block_at_once():
    with pytest.raises(Interrupted) as caught:
        with stop_on_signals():
            os.kill(os.getpid(), signal.SIGTERM)
            pytest.fail("not stopped")
    assert caught.value.signum == signal.SIGTERM
    assert str(caught.value) == "interrupted (SIGTERM); nothing written"


def test_a_block_that_ends_its_process_leaves_the_signals_ignored():
    """``ignore_after``: a signal after the block (the process exiting) is ignored; a block
    without a signal raises nothing."""
    defaults = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    assert defaults == {signal.SIGINT: signal.default_int_handler, signal.SIGTERM: signal.SIG_DFL}
    try:
        with stop_on_signals(ignore_after=True) as signals:
            signals.hold(_computed(2), "out")
        assert all(signal.getsignal(s) == signal.SIG_IGN for s in defaults)
        os.kill(os.getpid(), signal.SIGTERM)  # ignored: this test goes on
    finally:
        for s, handler in defaults.items():
            signal.signal(s, handler)


@pytest.mark.parametrize("received", [0, 1])
def test_gather_keeps_the_chunks_received_before_a_keyboard_interrupt(received):
    """Chunks received are kept as they came; the others' points are not_computed, NaN,
    under every index of the map (its deflections too: a wrench), whatever was received."""
    pieces = [np.array([4, 0]), np.array([1, 3]), np.array([2])]
    first = ChunkResult.empty(2)
    first.C[:] = np.eye(6)
    first.rank[:] = 6
    first.indices = {"det_K": np.array([1.0, 2.0])}
    closed = []

    def results():
        try:
            yield from [(0, first)][:received]
            raise KeyboardInterrupt
        finally:
            closed.append(True)

    with pytest.raises(Interrupted) as caught:
        gather(5, pieces, results(), wrench=np.ones(6))
    data = caught.value.data
    assert closed and caught.value.signum == signal.SIGINT
    lost = np.array([1, 2, 3] if received else [0, 1, 2, 3, 4])
    kept = np.setdiff1d(np.arange(5), lost)
    assert (data.codes[lost] == STATUS.index("not_computed")).all()
    assert (data.codes[kept] == STATUS.index("ok")).all()
    assert {data.reason_texts[c] for c in data.reason_codes[lost]} == {"interrupted by SIGINT"}
    assert np.isnan(data.C[lost]).all() and (data.rank[lost] == -1).all()
    np.testing.assert_array_equal(data.C[kept], np.broadcast_to(np.eye(6), (len(kept), 6, 6)))
    assert {"det_K", "deflection_translation", "deflection_rotation"} <= set(data.indices)
    assert all(np.isnan(v[lost]).all() for v in data.indices.values())
    np.testing.assert_array_equal(data.indices["det_K"][kept], [2.0, 1.0][: len(kept)])


def test_gather_interrupted_before_any_chunk_keeps_the_extra_indices():
    """A map of natural frequencies stopped before its first chunk still has that index
    (NaN everywhere), so that its partial files hold the index the command plots."""

    def results():
        raise KeyboardInterrupt
        yield

    with pytest.raises(Interrupted) as caught:
        gather(3, [np.arange(3)], results(), extra=("lowest_frequency",))
    values = caught.value.data.indices["lowest_frequency"]
    assert values.shape == (3,) and np.isnan(values).all()


def test_a_failing_task_ends_the_pool_at_once():
    """An error in one task ends the other running tasks' processes at once, instead of
    waiting for them (the pool is ended, not shut down)."""
    t0 = time.monotonic()
    with pytest.raises(ZeroDivisionError):
        for _ in run_tasks(_slow_or_failing, [0, 30, 30], workers=2):
            pass
    assert time.monotonic() - t0 < 20.0  # not the 30 s of the running task


def _slow_or_failing(seconds: float) -> float:
    if seconds == 0:
        time.sleep(0.5)
        return 1 / 0
    time.sleep(seconds)
    return seconds
