"""Dask clusters for the maps' ``--scheduler``: an executor that never hangs.

:func:`dask_executor` connects to a scheduler (an unreachable one is one typed error) and
yields a :class:`DaskExecutor`: the errors of Dask's machinery become a
:class:`~closedloop.exceptions.ClusterError` naming the scheduler (exit 3), a lost worker's
chunks are retried by Dask on the others, and a run without any worker for
``--worker-timeout`` seconds stops instead of waiting for ever.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import threading
import time
from concurrent.futures import CancelledError, Executor, Future, InvalidStateError

from closedloop.common.argtypes import finite_float
from closedloop.exceptions import ClusterError, InvalidInputError

#: Longest time [s] a Dask run waits with tasks pending and no worker connected (or the
#: scheduler lost) before it stops with one line (``--worker-timeout``).
WORKER_TIMEOUT = 30.0


def add_worker_timeout(parser: argparse.ArgumentParser) -> None:
    """Add ``--worker-timeout S`` (the bound of :class:`DaskExecutor`) to ``parser``."""
    parser.add_argument("--worker-timeout", type=finite_float, default=None,
                        metavar="S", help="with --scheduler: stop after S s without a "
                        f"worker (default {WORKER_TIMEOUT:g})")  # fmt: skip


def _is_dask_error(error: BaseException) -> bool:
    """An error of Dask's machinery (not of the task's own code): a class of the
    ``distributed`` package, a cancelled task, or an error raised in Dask's code
    (:func:`_raised_by_dask`)."""
    return _is_dask_class(error) or _raised_by_dask(error)


def _is_dask_class(error: BaseException) -> bool:
    """A cancelled task, or an error of a class of the ``distributed`` package
    (``KilledWorker``...)."""
    if isinstance(error, CancelledError):
        return True
    module = type(error).__module__
    return module == "distributed" or module.startswith("distributed.")


def _raised_by_dask(error: BaseException) -> bool:
    """True for an error raised by the ``distributed`` package's own code (the innermost
    frame of its traceback is there), not by the task: a task's error keeps the task's
    frames. Dask's executor reads a task's status after gathering its result; when the
    worker holding it is lost in between, the status is no longer "finished" and it takes
    the result for an error (``TypeError: cannot unpack non-iterable ...`` in
    ``distributed.cfexecutor``, distributed 2026.8): the task ran, its result was lost."""
    tb = error.__traceback__
    if tb is None:
        return False
    while tb.tb_next is not None:
        tb = tb.tb_next
    module = tb.tb_frame.f_globals.get("__name__", "")
    return module == "distributed" or module.startswith("distributed.")


class DaskExecutor(Executor):
    """The executor of a Dask client that never hangs and fails in one line.

    Each task's future is a future of its own, completed from Dask's: an error of Dask's
    machinery (e.g. ``KilledWorker`` once a task has lost ``allowed-failures`` workers)
    becomes a :class:`ClusterError` naming the scheduler; a task whose result Dask's
    executor lost with its worker (an error raised in Dask's own code) runs once more. A lost
    worker's tasks are retried by Dask on the others, so a map stays identical to the
    serial one. A watch thread checks every ``poll`` seconds that a worker is connected
    while tasks are pending; after ``worker_timeout`` seconds without one (or without the
    scheduler), the pending futures fail with a :class:`ClusterError`.

    Args:
        client: a ``distributed.Client`` (closed by the caller).
        address: the scheduler's address, for the messages.
        worker_timeout: seconds (> 0).
    """

    def __init__(self, client, address: str, worker_timeout: float):
        self._client, self._address, self._timeout = client, address, worker_timeout
        self._inner = client.get_executor()
        self._pending: set[Future] = set()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._watch = threading.Thread(target=self._watch_workers, daemon=True)
        self._watch.start()

    def submit(self, fn, /, *args, **kwargs) -> Future:
        """``fn(*args, **kwargs)`` on the cluster: a future of its own, completed from Dask's
        (an error of Dask's machinery as a :class:`ClusterError`)."""
        attempts = [self._inner.submit(fn, *args, **kwargs)]  # Dask's futures, the last current
        outer: Future = Future()
        with self._lock:
            self._pending.add(outer)
        outer.add_done_callback(lambda f: self._done(f, attempts[-1]))

        def again() -> None:  # the task once more, as Dask recomputes a lost result
            attempts.append(self._inner.submit(fn, *args, **kwargs))
            attempts[-1].add_done_callback(lambda f: self._forward(f, outer))

        attempts[0].add_done_callback(lambda f: self._forward(f, outer, again))
        return outer

    def _done(self, outer: Future, inner: Future) -> None:
        with self._lock:
            self._pending.discard(outer)
        if outer.cancelled():
            inner.cancel()

    def _forward(self, inner: Future, outer: Future, again=None) -> None:
        error = None if inner.cancelled() else inner.exception()
        lost = error is not None and _raised_by_dask(error) and not _is_dask_class(error)
        if lost and again is not None and not outer.done():
            try:  # a result lost with its worker (not the task's error): run it again
                again()
                return
            except RuntimeError:  # the executor is shut down: failed as a lost task below
                pass
        try:
            if inner.cancelled() or (error is not None and _is_dask_error(error)):
                what = (
                    "cancelled: the scheduler was lost, or the client closed"
                    if inner.cancelled()
                    else f"{type(error).__name__}: {error}"
                )
                outer.set_exception(ClusterError(
                    f"the Dask cluster at {self._address!r} lost a task ({what})"))  # fmt: skip
            elif error is not None:
                outer.set_exception(error)
            else:
                outer.set_result(inner.result())
        except InvalidStateError:  # already failed by the watch, or cancelled
            pass

    def _connected(self) -> bool:
        try:
            return self._client.status == "running" and bool(
                self._client.scheduler_info(n_workers=1)["workers"]
            )
        except Exception:  # the scheduler cannot answer: not connected
            return False

    def _watch_workers(self) -> None:
        poll = min(1.0, self._timeout / 4)
        since = None  # when tasks started waiting without a worker
        while not self._stop.wait(poll):
            with self._lock:
                waiting = bool(self._pending)
            if not waiting or self._connected():
                since = None
                continue
            since = time.monotonic() if since is None else since
            if time.monotonic() - since >= self._timeout:
                self._fail_pending()
                since = None

    def _fail_pending(self) -> None:
        error = ClusterError(
            f"no Dask worker connected to the scheduler {self._address!r} for "
            f"{self._timeout:g} s (--worker-timeout); stopped with tasks pending"
        )
        with self._lock:
            pending = list(self._pending)
        for future in pending:
            try:
                future.set_exception(error)
            except InvalidStateError:
                pass

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Stop the watch thread and shut Dask's executor down without waiting for it
        (the cluster is the user's); ``wait``: until the watch thread has ended.
        ``cancel_futures`` is accepted for :class:`concurrent.futures.Executor`'s
        signature and has no effect."""
        self._stop.set()
        self._inner.shutdown(wait=False)
        if wait:
            self._watch.join()


#: Dask's address schemes whose location is HOST:PORT.
HOST_PORT_SCHEMES = ("tcp", "tls", "ws", "wss")


def check_address(address: str) -> None:
    """Check a scheduler address with Dask's own parser, before any client exists.

    A ``Client`` whose constructor fails on a malformed address is left half started,
    and its clean-up when it is garbage collected can block (20 s, or for ever inside
    the start of the next client, with distributed 2026.8): so no client is built for
    an address that cannot be one.

    Raises:
        InvalidInputError: an unknown scheme, or a missing or non-numeric port.
    """
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.comm.registry import get_backend

    try:
        scheme, location = parse_address(address)
        get_backend(scheme)
        if scheme in HOST_PORT_SCHEMES:
            parse_host_port(location)
    except ValueError as e:
        raise InvalidInputError(
            f"--scheduler {address!r} is not a Dask address ({e}); expected e.g. tcp://HOST:8786"
        ) from None


@contextlib.contextmanager
def dask_executor(address: str | None, worker_timeout: float | None = None):
    """A :class:`DaskExecutor` on the scheduler at ``address`` (None for None), its client
    closed at the end. An unreachable scheduler or a missing Dask is one typed error.

    Raises:
        InvalidInputError: Dask is not installed, ``address`` is not an address (a
            missing port), the scheduler cannot be reached, or ``worker_timeout`` is not a
            positive number (None: ``WORKER_TIMEOUT``) or is given without ``address``.
    """
    if address is None:
        if worker_timeout is not None:
            raise InvalidInputError(
                f"--worker-timeout {worker_timeout:g} bounds a Dask run only; give --scheduler "
                "ADDRESS too, or leave it out"
            )
        yield None
        return
    worker_timeout = WORKER_TIMEOUT if worker_timeout is None else worker_timeout
    if not worker_timeout > 0:
        raise InvalidInputError(f"--worker-timeout must be > 0 s, got {worker_timeout!r}")
    try:
        from dask.distributed import Client
    except ImportError:
        raise InvalidInputError("--scheduler needs Dask: pip install '.[dask]'") from None
    check_address(address)
    with _quiet_dask_logs():
        try:
            client = Client(address, timeout="10s")
        except (OSError, TimeoutError) as e:
            raise InvalidInputError(f"cannot reach the Dask scheduler {address!r}: {e}") from None
        executor = DaskExecutor(client, address, worker_timeout)
        try:
            yield executor
        finally:
            executor.shutdown()
            _close(client)


def _close(client) -> None:
    """Close ``client``. With its scheduler lost, distributed's own reconnection may fail
    while it closes (a ``RuntimeError`` from its futures changing under iteration, a
    ``TimeoutError`` or ``OSError``); the run's outcome (its result, or the error that
    names the lost scheduler) is already decided, and is what the caller reports. The
    client is then marked closed, or its finaliser would try again (20 s, then a traceback
    on stderr at exit)."""
    try:
        client.close()
    except (RuntimeError, TimeoutError, OSError):
        client.status = "closed"


#: Loggers (with their children) muted while a Dask run lasts: Dask's own, and those of
#: the event loop its client runs on (tornado's ``tornado.application`` logs a callback's
#: ``CommClosedError`` with its traceback when the scheduler is lost mid-gather; asyncio
#: logs a task's exception that nobody retrieved).
DASK_LOGGERS = ("distributed", "tornado", "asyncio")


@contextlib.contextmanager
def _quiet_dask_logs():
    """The log records of :data:`DASK_LOGGERS` dropped while a run lasts, then the levels
    restored.

    A lost scheduler makes the client log its reconnection failures, and its event loop
    the failed callbacks, with their tracebacks on stderr; the run's outcome is already
    one :class:`ClusterError`. Each logger of these families that exists is muted (a
    child with a level of its own, such as ``tornado.application``, does not follow its
    parent); one created during the run inherits the muted level of its family's root.
    """
    manager = logging.Logger.manager
    children = tuple(f"{root}." for root in DASK_LOGGERS)
    names = [*DASK_LOGGERS, *(n for n in list(manager.loggerDict) if n.startswith(children))]
    loggers = [logging.getLogger(n) for n in names]
    levels = [logger.level for logger in loggers]
    for logger in loggers:
        logger.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for logger, level in zip(loggers, levels, strict=True):
            logger.setLevel(level)
