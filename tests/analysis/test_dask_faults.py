"""``--scheduler`` under faults: a lost worker is a retried chunk (the map stays the serial
one), a chunk lost with too many workers or a run without workers is one line, exit 3."""

import asyncio
import contextlib
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from concurrent.futures import Future

import dask
import numpy as np
import pytest
from dask.distributed import Client, LocalCluster
from helpers import REPO

from closedloop.analysis.cluster import DaskExecutor, _quiet_dask_logs
from closedloop.cli.app import main

#: Worker timeout of the tests [s]: small, so that a run without workers ends in seconds.
TIMEOUT = 3.0
#: Slack on the timeout [s]: the watch polls every min(1, TIMEOUT / 4) s, and a loaded
#: 2-core machine delays threads; a hang would exceed any such bound.
SLACK = 10.0
#: A map of many small chunks, so that a worker dies with chunks queued on it.
MAP = ["map", "fourbar", "--frame", "P", "--sweep", "crank=0.2:1.4:1500", "--chunk", "15"]
#: A map that outlasts closing the workers (seconds of chunks on two workers).
LONG_MAP = [*MAP[:-3], "crank=0.2:1.4:6000", "--chunk", "15"]


def _cluster(n_workers: int):
    return LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                        host="127.0.0.1", dashboard_address=None,
                        silence_logs=logging.CRITICAL)  # fmt: skip


def _kill_a_busy_worker(cluster, killed: list) -> threading.Thread:
    """A thread that kills (SIGKILL) the first worker process seen running a task and
    appends the worker's address to ``killed``."""

    def kill():
        with Client(cluster.scheduler_address, timeout="10s") as client:
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                busy = [w for w, keys in client.processing().items() if keys]
                for nanny in cluster.workers.values():
                    if nanny.worker_address in busy:
                        os.kill(nanny.process.pid, signal.SIGKILL)
                        killed.append(nanny.worker_address)
                        return
                time.sleep(0.005)

    thread = threading.Thread(target=kill, daemon=True)
    thread.start()
    return thread


def _last_line(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err, err
    return err.strip().splitlines()[-1]


def test_a_killed_worker_is_a_retried_chunk(tmp_path, capsys):
    """One of two workers killed mid-run: Dask retries its chunks on the other (and the
    restarted one); the NPZ arrays equal the serial map's exactly."""
    assert main([*MAP, "--out", str(tmp_path / "serial")]) == 0
    killed: list = []
    with _cluster(2) as cluster:
        thread = _kill_a_busy_worker(cluster, killed)
        status = main([*MAP, "--scheduler", cluster.scheduler_address,
                       "--out", str(tmp_path / "dask")])  # fmt: skip
        thread.join(60)
    assert status == 0, capsys.readouterr().err
    assert len(killed) == 1  # a worker died while it held chunks
    a, b = np.load(tmp_path / "serial/map.npz"), np.load(tmp_path / "dask/map.npz")
    for key in a.files:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_a_chunk_lost_with_its_workers_is_one_line(tmp_path, capsys):
    """With ``allowed-failures`` 0, the first worker killed with a chunk loses it for good
    (``KilledWorker``): one line naming the scheduler, exit 3."""
    killed: list = []
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}), _cluster(2) as cluster:
        thread = _kill_a_busy_worker(cluster, killed)
        status = main([*MAP, "--scheduler", cluster.scheduler_address,
                       "--out", str(tmp_path / "dask")])  # fmt: skip
        thread.join(60)
        address = cluster.scheduler_address
    line = _last_line(capsys)
    assert killed and status == 3, line
    assert line.startswith("closedloop: error: the Dask cluster at") and address in line
    assert "KilledWorker" in line


@pytest.mark.parametrize("prog", ["closedloop", "cahyman"])
def test_a_run_without_workers_stops_after_the_timeout(prog, tmp_path, capsys):
    """A scheduler without any worker: one line, exit 3, after the timeout, not a hang."""
    from cahyman_pin.cli import main as cahyman_main

    with _cluster(0) as cluster:
        address = cluster.scheduler_address
        t0 = time.monotonic()
        if prog == "closedloop":
            status = main([*MAP, "--scheduler", address, "--worker-timeout", str(TIMEOUT),
                           "--out", str(tmp_path / "x")])  # fmt: skip
        else:
            status = cahyman_main(["map", "--alpha", "30:90:7", "--scheduler", address,
                                   "--worker-timeout", str(TIMEOUT),
                                   "--out", str(tmp_path / "x")])  # fmt: skip
        elapsed = time.monotonic() - t0
    line = _last_line(capsys)
    assert status == 3, line
    assert line.startswith(f"{prog}: error: no Dask worker connected to the scheduler")
    assert address in line and f"for {TIMEOUT:g} s" in line
    assert TIMEOUT <= elapsed < TIMEOUT + SLACK, elapsed


def test_the_worker_timeout_must_be_positive(tmp_path, capsys):
    with _cluster(0) as cluster:
        status = main([*MAP, "--scheduler", cluster.scheduler_address, "--worker-timeout", "0",
                       "--out", str(tmp_path / "x")])  # fmt: skip
    assert status == 2
    assert "--worker-timeout must be > 0 s, got 0.0" in _last_line(capsys)


def test_all_workers_lost_mid_run_stops_after_the_timeout(tmp_path, capsys):
    """Both workers closed while chunks are running: one line, exit 3, after the timeout."""
    with _cluster(2) as cluster:
        address = cluster.scheduler_address

        def close_all():
            with Client(address, timeout="10s") as client:
                while not any(client.processing().values()):
                    time.sleep(0.005)
            t_lost.append(time.monotonic())
            cluster.scale(0)

        t_lost: list = []
        thread = threading.Thread(target=close_all, daemon=True)
        thread.start()
        status = main([*LONG_MAP, "--scheduler", address, "--worker-timeout", str(TIMEOUT),
                       "--out", str(tmp_path / "x")])  # fmt: skip
        t_end = time.monotonic()
        thread.join(60)
    line = _last_line(capsys)
    assert status == 3, line
    assert line.startswith("closedloop: error: no Dask worker connected to the scheduler")
    assert t_lost and TIMEOUT <= t_end - t_lost[0] < TIMEOUT + SLACK, t_end - t_lost[0]


class _DaskFuture:
    """A Dask future as distributed's executor reads it once done: ``status``, and the
    value of ``_result(raiseit=False)``, the task's result or its error triple."""

    def __init__(self, status: str, value):
        self.status, self.value = status, value

    async def _result(self, raiseit=True):
        return self.value


class _Client:
    """A client whose executor completes each task's future with distributed's own
    ``_cascade_future``: the first submission with ``status`` ("lost": a result gathered,
    then its worker lost, so that the status is no longer "finished" when read, the race
    of the test above, which failed once under load with ``TypeError: cannot unpack
    non-iterable ChunkResult``), the next ones as finished (or failed) tasks."""

    def __init__(self, status: str):
        self.first, self.calls = status, 0
        self.status = "running"

    def scheduler_info(self, n_workers=1):
        return {"workers": {"tcp://127.0.0.1:1": {}}}

    def get_executor(self):
        client = self

        class Inner:
            def submit(self, fn, *args):
                client.calls += 1
                try:
                    value, status = fn(*args), "finished"
                except Exception:
                    value, status = sys.exc_info(), "error"
                if client.calls == 1 and client.first == "lost":
                    status = "lost"
                future = Future()
                asyncio.run(_cascade(_DaskFuture(status, value), future))
                return future

            def shutdown(self, wait=True):
                pass

        return Inner()


async def _cascade(dask_future: _DaskFuture, future: Future) -> None:
    """distributed's executor completing ``future`` from ``dask_future`` (on a loop)."""
    from distributed.cfexecutor import _cascade_future

    await _cascade_future(dask_future, future)


def test_a_result_lost_with_its_worker_is_computed_again():
    """distributed's executor takes a result whose worker was lost after the gather for
    an error triple and fails the task with the TypeError of unpacking it (raised in its
    own code, not the task's): the task runs again, as Dask recomputes lost results,
    instead of the TypeError ending the map."""
    client = _Client("lost")
    executor = DaskExecutor(client, "tcp://127.0.0.1:1", worker_timeout=5.0)
    try:
        assert executor.submit(pow, 7, 2).result(timeout=10) == 49  # not iterable
    finally:
        executor.shutdown()
    assert client.calls == 2


def _fails(x):
    return x + "2"  # TypeError in the task's own frame


def test_a_task_s_own_type_error_is_not_run_again():
    """A TypeError of the task itself (the task's frame innermost in its traceback) is
    the task's error, run once."""
    client = _Client("finished")
    executor = DaskExecutor(client, "tcp://127.0.0.1:1", worker_timeout=5.0)
    try:
        with pytest.raises(TypeError, match="unsupported operand"):
            executor.submit(_fails, 7).result(timeout=10)
    finally:
        executor.shutdown()
    assert client.calls == 1


@contextlib.contextmanager
def _external_cluster(n_workers: int):
    """A scheduler and workers in processes of their own (as on a real cluster, and unlike
    LocalCluster, whose silenced logs live in the test's process); yields the scheduler's
    process and address, and kills what is left at the end."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    address = f"tcp://127.0.0.1:{port}"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler",
                                  "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                                 **quiet)  # fmt: skip
    workers = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address,
                                "--nworkers", str(n_workers), "--nthreads", "1",
                                "--no-dashboard"], **quiet)  # fmt: skip
    try:
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(n_workers, timeout=60)
        yield scheduler, address
    finally:
        for process in (workers, scheduler):
            process.kill()
            process.wait(30)


def test_a_scheduler_lost_mid_run_is_one_line(tmp_path):
    """The scheduler killed (SIGKILL) while chunks run: one line naming it, exit 3, soon.
    The client logged its failed reconnections with tracebacks on stderr before the line.
    The command runs in a process of its own, as a user runs it (Dask's log handler holds
    the stderr of the process that imported it)."""
    argv = [*LONG_MAP, "--worker-timeout", str(TIMEOUT), "--out", str(tmp_path / "x")]
    with _external_cluster(2) as (scheduler, address):
        env = {**os.environ, "PYTHONPATH": str(REPO)}
        command = subprocess.Popen([sys.executable, "-m", "closedloop", *argv, "--scheduler",
                                    address], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                   text=True, cwd=REPO, env=env)  # fmt: skip
        with Client(address, timeout="10s") as client:
            while not any(client.processing().values()) and command.poll() is None:
                time.sleep(0.005)
        t_lost = time.monotonic()
        os.kill(scheduler.pid, signal.SIGKILL)
        _, err = command.communicate(timeout=TIMEOUT + SLACK + 60)
        t_end = time.monotonic()
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("closedloop map: ")]
    assert command.returncode == 3 and len(lines) == 1, err
    assert lines[0].startswith(f"closedloop: error: the Dask cluster at {address!r} lost a task")
    assert t_end - t_lost < TIMEOUT + SLACK, t_end - t_lost


@pytest.mark.parametrize("name", ["tornado.application", "asyncio", "distributed.client"])
def test_the_logs_of_dask_and_its_event_loop_are_muted_while_a_run_lasts(name):
    """A scheduler lost mid-gather makes tornado log the failed callback's CommClosedError
    with its traceback (``tornado.application``, at the level ERROR that Dask's logging
    configuration gives it) and asyncio an exception nobody retrieved; only distributed's
    loggers were muted, and a lost scheduler printed 50 lines of traceback before the
    one-line error in 2 runs of 3. Records of these loggers, and of a child created during
    the run, are dropped while a run lasts; the levels are restored after it."""
    logger, records = logging.getLogger(name), []
    handler = logging.Handler()
    handler.emit = records.append
    level = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.ERROR)
    try:
        with _quiet_dask_logs():
            logger.error("during the run")
            logging.getLogger(f"{name}.made_during_the_run").error("during the run")
        assert logger.level == logging.ERROR
        logger.error("after the run")
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)
    assert [r.getMessage() for r in records] == ["after the run"]
