"""closedloop.common.progress: log lines off a terminal, a bar on one, nothing when disabled."""

import io
import sys
import time

import pytest

from closedloop.common import progress as progress_module
from closedloop.common.progress import progress


class Terminal(io.StringIO):
    """A text stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def run(items, **kw) -> tuple[list, str]:
    stream = kw.pop("stream", io.StringIO())
    seen = list(progress(items, stream=stream, **kw))
    return seen, stream.getvalue()


def slow(n: int, seconds: float):
    for i in range(n):
        time.sleep(seconds)
        yield i


def test_off_terminal_first_and_last_line_only_within_the_period(monkeypatch):
    monkeypatch.setattr(progress_module, "LOG_PERIOD", 3600.0)
    seen, text = run(slow(5, 0.15), total=5, label="sweep")
    assert seen == list(range(5))
    assert "\r" not in text and text.endswith("\n")
    lines = text.splitlines()
    # the estimate at the first item BURST = 0.1 s after the first, then the end
    assert len(lines) == 2, lines
    assert lines[0].startswith("sweep: 2/5, ") and "left" in lines[0]
    assert lines[1].startswith("sweep: 5/5, ")


def test_off_terminal_periodic_lines(monkeypatch):
    # 20 items of 20 ms at least (400 ms); a line falls due 50 ms after the last and is
    # written at the second item after (BURST = 0): lines at most 90 ms apart, so at least
    # 400/90 > 4 lines besides the last; a slower machine only adds lines.
    monkeypatch.setattr(progress_module, "LOG_PERIOD", 0.05)
    monkeypatch.setattr(progress_module, "BURST", 0.0)
    seen, text = run(slow(20, 0.02), total=20, label="map")
    assert seen == list(range(20))
    lines = text.splitlines()
    assert len(lines) >= 5, lines
    assert all(line.startswith("map: ") and "/20, " in line for line in lines)
    done = [int(line.split(": ")[1].split("/")[0]) for line in lines]
    assert done == sorted(set(done)) and done[0] == 2 and done[-1] == 20


def bursts(n: int, size: int, seconds: float):
    """n bursts of ``size`` items at once, ``seconds`` apart (a sweep's chunks)."""
    for k in range(n):
        time.sleep(seconds)
        yield from range(k * size, (k + 1) * size)


def test_off_terminal_first_estimate_counts_the_whole_first_burst(monkeypatch):
    # bursts 0.3 s apart, each over in far less than BURST = 0.1 s: the first line waits
    # for the first item of the second burst, so its rate is 101 items over about 0.6 s,
    # not 1 item over 0.3 s (a time left 100 times too long).
    monkeypatch.setattr(progress_module, "LOG_PERIOD", 3600.0)
    seen, text = run(bursts(3, 100, 0.3), total=300, label="sweep")
    assert seen == list(range(300))
    lines = text.splitlines()
    assert [line.split(",")[0] for line in lines] == ["sweep: 101/300", "sweep: 300/300"]


def test_unknown_total_shows_count_without_estimate():
    seen, text = run(iter(range(7)))
    assert seen == list(range(7))
    assert text.startswith("7, ") and text.count("\n") == 1
    assert "left" not in text


def test_terminal_draws_a_bar_in_place():
    seen, text = run(range(10), label="Fig. 6", stream=Terminal())
    assert seen == list(range(10))
    assert "\r" in text and "Fig. 6" in text and "10/10" in text
    assert text.endswith("\n")


@pytest.mark.parametrize("stream", [io.StringIO(), Terminal()])
def test_disabled_writes_nothing(stream):
    seen, text = run(range(5), stream=stream, enabled=False)
    assert seen == list(range(5)) and text == ""


def test_empty_run_writes_nothing():
    assert run([], label="sweep") == ([], "")


def test_stopping_early_ends_quietly(monkeypatch):
    monkeypatch.setattr(progress_module, "LOG_PERIOD", 3600.0)
    stream = io.StringIO()
    it = progress(range(100), label="sweep", stream=stream)
    assert [next(it) for _ in range(3)] == [0, 1, 2]
    it.close()
    assert stream.getvalue().splitlines()[-1].startswith("sweep: 2/100, ")


def interrupted(n: int, error: BaseException):
    """n items, then ``error`` raised (a signal's KeyboardInterrupt, or a failure)."""
    yield from range(n)
    raise error


@pytest.mark.parametrize(
    ("error", "last"), [(KeyboardInterrupt(), None), (ValueError("bad"), "sweep: 3/100, ")]
)
def test_an_interrupt_leaves_no_last_line_an_error_does(monkeypatch, error, last):
    monkeypatch.setattr(progress_module, "LOG_PERIOD", 3600.0)
    stream = io.StringIO()
    with pytest.raises(type(error)):
        for _ in progress(interrupted(3, error), total=100, label="sweep", stream=stream):
            pass
    if last is None:
        assert stream.getvalue() == ""  # the interruption's own line comes next
    else:
        assert stream.getvalue().splitlines()[-1].startswith(last)


def test_closed_while_interrupted_leaves_no_last_line(monkeypatch):
    """A consumer that closes the iteration on a KeyboardInterrupt (a map's gather)."""
    monkeypatch.setattr(progress_module, "LOG_PERIOD", 0.0)
    monkeypatch.setattr(progress_module, "BURST", 0.0)
    stream = io.StringIO()
    it = progress(range(100), label="sweep", stream=stream)
    assert [next(it) for _ in range(4)] == [0, 1, 2, 3]
    shown = stream.getvalue()
    assert shown.startswith("sweep: 2/100, ") and "3/100" not in shown  # lines while it ran
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt:
        it.close()
    assert stream.getvalue() == shown


def test_in_a_jupyter_kernel_tqdm_auto_draws_it(monkeypatch, capsys):
    # A kernel's stderr is no terminal; there tqdm.auto chooses (a widget with ipywidgets
    # in a notebook front end, else its text bar): here the text bar, on stderr.
    import types

    monkeypatch.setitem(sys.modules, "ipykernel", types.ModuleType("ipykernel"))
    assert list(progress(range(4), label="cells")) == [0, 1, 2, 3]
    err = capsys.readouterr().err
    assert "\r" in err and "cells" in err and "4/4" in err
