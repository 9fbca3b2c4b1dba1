"""A map stopped by SIGINT (Ctrl-C) or SIGTERM, and what the signals do in its workers.

Inside :func:`stop_on_signals` (in :func:`closedloop.analysis.tasks.gather`, and around the
whole of a map command) the first signal raises :class:`Interrupted` (a
``KeyboardInterrupt``), which carries what was computed; once a command's map is computed
and its files are being written, the signal is held until they are
(:meth:`SignalStop.hold`). The worker processes of
:func:`closedloop.analysis.tasks.run_tasks` are started with the signals blocked
(:func:`signals_blocked`) and ignore SIGINT themselves, ending with their parent
(:func:`start_worker`).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import sys
import threading
from collections.abc import Callable

import numpy as np

from closedloop.analysis.map_results import NOT_COMPUTED, PointData
from closedloop.common.blas import single_threaded_blas

#: Signals that stop a map (:func:`stop_on_signals`).
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: ``prctl`` option: the signal a process receives when its parent ends (Linux).
PR_SET_PDEATHSIG = 1


class Interrupted(KeyboardInterrupt):
    """A map stopped by SIGINT (Ctrl-C) or SIGTERM: its workers ended, what it computed kept.

    A ``KeyboardInterrupt``, so that code that catches Ctrl-C catches it.
    :func:`~closedloop.analysis.tasks.gather` raises it with ``data``;
    :func:`closedloop.analysis.maps.stiffness_map` and :func:`cahyman_pin.sweep.sweep` attach
    their result as ``partial`` and re-raise it.

    Attributes:
        signum: the signal (SIGINT, also for a plain ``KeyboardInterrupt``, or SIGTERM).
        data: the :class:`~closedloop.analysis.map_results.PointData` so far, or None
            (stopped outside a map): the points of the chunks not received have status
            ``not_computed`` and the reason :attr:`reason`, NaN values (none, for a signal
            held while a computed map's files were written: :meth:`SignalStop.hold`).
        partial: the map's result built on ``data`` (a
            :class:`~closedloop.analysis.maps.StiffnessMap` or a
            :class:`~cahyman_pin.sweep.SweepResult`), a design run's
            :class:`~closedloop.analysis.design_result.DesignResult` so far, or None.
        written: the folder ``partial`` was written to (:meth:`write`), or that of the
            files written while the signal was held, or None.
        progress: (points computed, points in all) of a run without ``data`` (a path,
            :func:`closedloop.analysis.paths.follow_path`), or None.
    """

    def __init__(self, signum: int = signal.SIGINT):
        super().__init__(signum)
        self.signum = signal.Signals(signum)
        self.data: PointData | None = None
        self.partial = None
        self.written = None
        self.progress: tuple[int, int] | None = None

    @property
    def reason(self) -> str:
        """The reason of the points not computed, e.g. ``interrupted by SIGINT``."""
        return f"interrupted by {self.signum.name}"

    def write(self, save: Callable, folder) -> None:
        """Write ``partial`` (if any) by ``save(partial)`` into ``folder``, and say so in
        the message."""
        if self.partial is not None:
            save(self.partial)
            self.written = folder

    def __str__(self) -> str:
        text = f"interrupted ({self.signum.name})"
        if self.written is None:
            return f"{text}; nothing written"
        counts = self.progress
        if self.data is not None:
            counts = (int(np.count_nonzero(self.data.codes != NOT_COMPUTED)), len(self.data.codes))
        if counts is None:  # neither a map nor a path (a design run): its results so far
            return f"{text}: wrote the results so far to {self.written}"
        return f"{text}: wrote {counts[0]} of {counts[1]} points to {self.written}"


class SignalStop:
    """What :func:`stop_on_signals` yields: the signal received in its block, and whether
    the block holds it (:meth:`hold`) instead of raising :class:`Interrupted` at once.

    Attributes:
        signum: the first SIGINT or SIGTERM received in the block, or None.
    """

    def __init__(self):
        self.signum: int | None = None
        self._raising = True  # the first signal raises at once (until held)
        self._raised = False
        self._data: PointData | None = None
        self._folder = None

    def hold(self, data: PointData | None, folder) -> None:
        """From now to the end of the block, a signal is held: the block goes on (the files
        of a map that is computed are written whole) and ends by raising
        :class:`Interrupted` with ``data`` (every point's outcome) and ``written`` the
        ``folder`` its body has written them to; without a signal, nothing is raised."""
        self._raising = False
        self._data, self._folder = data, folder

    def received(self, signum: int) -> None:
        """The block's signal handler: the first signal raises :class:`Interrupted` unless
        held; a later one is ignored."""
        if self.signum is not None:
            return
        self.signum = signum
        if self._raising:
            self._raised = True
            raise Interrupted(signum)

    def end(self) -> None:
        """The block has ended normally: raise the signal held, if any."""
        if self.signum is None or self._raised:
            return
        stop = Interrupted(self.signum)
        stop.data, stop.written = self._data, self._folder
        raise stop


@contextlib.contextmanager
def stop_on_signals(ignore_after: bool = False):
    """Inside the block, SIGINT and SIGTERM raise :class:`Interrupted`, once: a later one is
    ignored until the block ends, so that the clean-up after the first (workers ended, a
    partial map written) is not cut short; after :meth:`SignalStop.hold` (a map computed,
    its files being written), the first is held and raised when the block ends. Only in
    the main thread (where Python runs its signal handlers), and only for a signal whose
    handler is Python's default (SIGINT: ``KeyboardInterrupt``; SIGTERM: the end of the
    process): an ignored signal, a handler of the program's own or of an enclosing block
    stay as they are.

    Args:
        ignore_after: leave the signals the block handled ignored after it, instead of
            their default: a command line that ends its process then (a signal during the
            interpreter's exit, a few tenths of a second, finds nothing to stop and would
            otherwise kill the process without a word), never a library call.

    Yields:
        the block's :class:`SignalStop`.
    """
    stop = SignalStop()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return
    defaults = {signal.SIGINT: signal.default_int_handler, signal.SIGTERM: signal.SIG_DFL}

    def handler(signum, frame):
        stop.received(signum)

    previous = {s: signal.signal(s, handler) for s, h in defaults.items()
                if signal.getsignal(s) is h}  # fmt: skip
    try:
        yield stop
    finally:
        stop._raising = False  # a signal while the handlers are set back is held, not raised
        for s, h in previous.items():
            signal.signal(s, signal.SIG_IGN if ignore_after else h)
    stop.end()


def start_worker() -> None:
    """Initializer of a map's worker processes (started with SIGINT and SIGTERM blocked,
    :func:`~closedloop.analysis.tasks.run_tasks`): SIGINT ignored (a Ctrl-C reaches the whole
    process group; the parent ends the workers), SIGTERM ends the process, the process ends
    with its parent (Linux: even a parent killed by SIGKILL), one BLAS thread."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if sys.platform.startswith("linux"):
        parent = os.getppid()
        ctypes.CDLL(None).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
        if os.getppid() != parent:  # ended before prctl
            os._exit(1)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
    single_threaded_blas()


@contextlib.contextmanager
def signals_blocked():
    """SIGINT and SIGTERM blocked in this thread inside the block, and so in the processes
    it starts until their initializer (:func:`start_worker`) has set what the signals do
    there; a signal received meanwhile is handled at the end of the block. Nothing where
    Python cannot block signals (Windows)."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
