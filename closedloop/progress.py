"""A dependency-free text progress bar for long sweeps (written to stderr)."""

from __future__ import annotations

import sys
import time
from collections.abc import Iterable, Iterator
from typing import TextIO, TypeVar

T = TypeVar("T")


def progress(
    items: Iterable[T],
    total: int | None = None,
    label: str = "",
    stream: TextIO | None = None,
    min_interval: float = 0.1,
    enabled: bool = True,
) -> Iterator[T]:
    """Yield ``items`` while drawing ``label [#####.....] i/total  t s`` on ``stream``.

    On a terminal the bar is redrawn in place at most every ``min_interval`` seconds; on
    a non-terminal stream (logs, CI) only the final line is written.
    """
    stream = sys.stderr if stream is None else stream
    if total is None:
        total = len(items) if hasattr(items, "__len__") else 0
    live = enabled and hasattr(stream, "isatty") and stream.isatty()
    start = last = time.perf_counter()
    i = 0

    def draw(end: str) -> None:
        width = 30
        frac = i / total if total else 1.0
        filled = round(width * frac)
        bar = "#" * filled + "." * (width - filled)
        count = f"{i}/{total}" if total else f"{i}"
        stream.write(f"\r{label} [{bar}] {count} {time.perf_counter() - start:6.1f} s{end}")
        stream.flush()

    for item in items:
        yield item
        i += 1
        now = time.perf_counter()
        if live and now - last >= min_interval:
            draw("")
            last = now
    if enabled:
        draw("\n")
