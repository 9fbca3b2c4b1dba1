"""Progress of long sweeps on stderr, drawn by tqdm: a bar, log lines or a notebook widget.

* On a terminal: tqdm's bar, redrawn in place, with the rate and the time left.
* Elsewhere (logs, CI, a pipe): one plain line a :data:`LOG_PERIOD` seconds, the first as
  soon as the first items are done (the estimate of the whole run before it is well under
  way), and a last line at the end, unless the run was interrupted (a
  ``KeyboardInterrupt``, e.g. Ctrl-C or a map's SIGTERM, raised in the items or while the
  consumer closes the iteration): then the interruption has the last word. Never a
  carriage return. Items that come in bursts
  (a sweep's chunks) are counted a whole burst at a time: a line that falls due is written
  at the first item :data:`BURST` seconds later or more, so that the rate (items done over
  time elapsed) is not that of the first item of a burst.
* In a Jupyter kernel, writing to the default stream: ``tqdm.auto`` (a widget when
  ipywidgets is installed, text otherwise).
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Iterable, Iterator
from typing import TextIO, TypeVar

from tqdm import tqdm

#: The type of the items.
T = TypeVar("T")

#: Seconds between the lines written when the stream is not a terminal.
LOG_PERIOD = 5.0
#: Seconds a due line waits for the rest of a burst of items (see the module docstring).
BURST = 0.1

_LOG_FORMAT = "{desc}{n_fmt}/{total_fmt}, {elapsed} elapsed, about {remaining} left ({rate_fmt})"
_LOG_FORMAT_NO_TOTAL = "{desc}{n_fmt}, {elapsed} elapsed ({rate_fmt})"


class _LogLines(tqdm):
    """tqdm writing whole lines (no carriage return, no padding) for logs and pipes."""

    shown = 0
    #: The iteration was interrupted: no last line on closing.
    stopped = False

    def display(self, msg=None, pos=None):
        if msg is not None or self.n == 0:  # msg="": tqdm clearing the bar; n=0: no news
            return False
        self.fp.write(self.__str__() + "\n")
        self.fp.flush()
        self.shown = self.n
        return True

    def close(self):
        if not self.disable and self.n != self.shown and not self.stopped:
            self.display()  # the last line, unless the last one already showed it
        super().close()


def progress(
    items: Iterable[T],
    total: int | None = None,
    label: str = "",
    stream: TextIO | None = None,
    min_interval: float = 0.1,
    enabled: bool = True,
) -> Iterator[T]:
    """Yield ``items`` while showing how many are done on ``stream`` (default stderr).

    Args:
        items: any iterable; an item counts as done when the caller asks for the next.
        total: number of items (default ``len(items)`` if it has one; else unknown, and
            no time left is shown).
        label: what is counted, shown first.
        stream: where to write (default ``sys.stderr``).
        min_interval: seconds between redraws of the terminal bar.
        enabled: False to write nothing.
    """
    if not enabled:
        yield from items
        return
    if total is None and hasattr(items, "__len__"):
        total = len(items)
    total = total or None  # 0: unknown, as None
    out = sys.stderr if stream is None else stream
    if stream is None and "ipykernel" in sys.modules:
        from tqdm.auto import tqdm as auto

        bar = auto(total=total, desc=label, mininterval=min_interval)
    elif getattr(out, "isatty", lambda: False)():
        bar = tqdm(total=total, desc=label, file=out, mininterval=min_interval)
    else:
        yield from _log_lines(items, total, label, out)
        return
    with bar:
        for item in items:
            yield item
            bar.update()


def _log_lines(items: Iterable[T], total: int | None, label: str, out: TextIO) -> Iterator[T]:
    """:func:`progress` off a terminal: lines when due, once a burst of items is over."""
    bar = _LogLines(total=total, desc=f"{label}: " if label else "", file=out,
                    mininterval=math.inf, smoothing=0.0, leave=False,
                    bar_format=_LOG_FORMAT if total else _LOG_FORMAT_NO_TOTAL)  # fmt: skip
    due, pending = time.perf_counter(), None  # when a line falls due; since when it waits
    with bar:
        try:
            for item in items:
                yield item
                bar.update()  # counts only: mininterval=inf, the lines are drawn here
                now = time.perf_counter()
                if now < due:
                    continue
                if pending is None:
                    pending = now
                elif now - pending >= BURST:
                    bar.refresh()
                    due, pending = now + LOG_PERIOD, None
        except KeyboardInterrupt:  # raised in items
            bar.stopped = True
            raise
        except GeneratorExit as closing:  # closed at a yield: by a KeyboardInterrupt?
            bar.stopped = isinstance(closing.__context__, KeyboardInterrupt)
            raise
