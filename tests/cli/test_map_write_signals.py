"""A signal while a map writes its files, once every point is computed (``closedloop map``,
``cahyman map``): the files are written whole, then one line on stderr and exit 128 + the
signal; a signal once the command is over leaves its exit status as it was. Never a
process killed by the signal, a half-written file or a temporary file left."""

from __future__ import annotations

import csv
import fcntl
import io
import os
import re
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest
from helpers import REPO, default_sigint, map_argv

#: Seconds a command may take from its start to its last line.
RUN_TIMEOUT = 120.0
#: The signals sent after the last point are spread over this many seconds: the writing
#: of the files (0.5-1.5 s seen, the figure most of it) and the exit of the interpreter
#: (0.15-0.4 s seen) that follows.
WINDOW = 1.5
#: Runs with a signal per command (SIGINT and SIGTERM in turn; 2-6 s each on a loaded
#: machine). Run k sends its signal at a random moment of the k-th of RUNS equal slices of
#: the window, so that the moments cover the window from the writing's start to the exit
#: (the first slice, 0-0.375 s, falls in the writing on any machine) without depending on luck.
RUNS = 4
#: Bytes a pipe holds while the command writes into it (Linux's least, a page).
PIPE_SIZE = 4096

#: A 10 x 10 map of each command, serial: (argv, its last progress line, its files).
COMMANDS = {
    "closedloop": ([*map_argv("closedloop", 10), "--index", "min_translational"],
                   "map points: 100/100", ("map.npz", "map.csv", "map.png")),
    "cahyman": ([*map_argv("cahyman", 10), "--workers", "1"],
                "generic sweep: 100/100", ("map.npz", "map.csv", "map_det_K.png")),
}  # fmt: skip
POINTS = 100


def _start(prog: str, out: Path) -> subprocess.Popen:
    argv = COMMANDS[prog][0]
    return subprocess.Popen(
        [sys.executable, *argv, "--out", str(out)], stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True, cwd=REPO, start_new_session=True,
        preexec_fn=default_sigint,
    )  # fmt: skip


def _until_computed(proc: subprocess.Popen, prog: str) -> None:
    """Read stderr up to the command's last progress line: every point is computed."""
    label = COMMANDS[prog][1]
    deadline = time.monotonic() + RUN_TIMEOUT
    seen = []
    while not (seen and seen[-1].startswith(label)):
        line = proc.stderr.readline()
        assert line and time.monotonic() < deadline, f"ended before its last point: {seen}"
        seen.append(line)


def _finish(proc: subprocess.Popen) -> tuple[int, str, list[str]]:
    """(exit code, stdout, stderr lines from here on) of the command, killed on a timeout."""
    try:
        stdout, stderr = proc.communicate(timeout=RUN_TIMEOUT)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return proc.returncode, stdout, stderr.splitlines()


def _whole(name: str, data: bytes) -> None:
    """``data`` is a complete file ``name``: its NPZ arrays, CSV rows or PNG pixels all read."""
    if name.endswith(".npz"):
        with np.load(io.BytesIO(data)) as f:
            arrays = {k: f[k] for k in f.files}
        assert arrays["status"].shape == (POINTS,) and arrays["C"].shape == (POINTS, 6, 6)
    elif name.endswith(".csv"):
        rows = list(csv.DictReader(io.StringIO(data.decode("utf-8"))))
        assert len(rows) == POINTS and all(r["status"] for r in rows)
    else:
        pixels = matplotlib.image.imread(io.BytesIO(data), format="png")
        assert pixels.ndim == 3 and min(pixels.shape[:2]) > 100


def _check(prog: str, sig: signal.Signals, out: Path, code: int, stdout: str, after: list,
           read: dict | None = None) -> bool:  # fmt: skip
    """The outcome of a map signalled after its last point is one of two: ended by the
    signal (exit 128 + the signal, one line that says what it wrote: every point, or
    nothing) or over before it (exit 0, nothing on stderr); every file whole, or absent
    when nothing was written; no temporary file. ``read``: the files read from a pipe.
    Returns whether the signal ended the command."""
    files = COMMANDS[prog][2]
    assert code in (0, 128 + sig), (code, after)
    assert not [p.name for p in out.iterdir() if p.name.endswith(".tmp")]
    read = read or {}
    contents = {n: read[n] if n in read else (out / n).read_bytes() for n in files
                if n in read or (out / n).is_file()}  # fmt: skip
    if code == 0:
        assert after == []
        written = True
    else:
        assert len(after) == 1, after
        said = rf"(: wrote (\d+) of (\d+) points to {re.escape(str(out))}|; nothing written)"
        found = re.fullmatch(rf"{prog}: interrupted \({sig.name}\){said}", after[0])
        assert found, after
        written = found[2] is not None
        if written:
            assert int(found[2]) == int(found[3]) == POINTS
    if written:
        assert sorted(contents) == sorted(files)
        assert all(str(out / n) in stdout for n in files), stdout
    else:  # stopped before the map was whole: no file of it
        assert contents == {}
    for name, data in contents.items():
        _whole(name, data)
    return code != 0


@pytest.mark.parametrize("prog", list(COMMANDS))
def test_a_signal_at_any_moment_of_the_writing_ends_in_whole_files_and_one_line(tmp_path, prog):
    """Signals at random moments from the last point to past the exit, one in each slice of
    the window: every run ends by the signal with its files written and one line, or was
    over before it."""
    rng = np.random.default_rng(45)
    stopped = 0
    for k in range(RUNS):
        sig = (signal.SIGINT, signal.SIGTERM)[k % 2]
        out = tmp_path / f"run{k}"
        proc = _start(prog, out)
        _until_computed(proc, prog)
        time.sleep(WINDOW * (k + rng.uniform()) / RUNS)
        proc.send_signal(sig)
        code, stdout, after = _finish(proc)
        stopped += _check(prog, sig, out, code, stdout, after)
    assert stopped, "no signal came while the files were written: the test missed the phase"


def _read_paused(fd: int, proc: subprocess.Popen, sig: signal.Signals) -> tuple[bytes, int]:
    """Read the pipe ``fd`` the command writes a file into: a first part, then ``sig`` to
    the command while it waits for the pipe to be read further, then the rest. Returns
    (the file's bytes, how many had been read when the signal was sent)."""
    deadline = time.monotonic() + RUN_TIMEOUT
    chunks: list[bytes] = []
    signalled = None
    while True:
        assert time.monotonic() < deadline, "the command did not write the file"
        if not select.select([fd], [], [], 0.1)[0]:
            assert chunks or proc.poll() is None, "the command ended before the file"
            continue
        chunk = os.read(fd, PIPE_SIZE)
        if not chunk:  # the command closed the file
            return b"".join(chunks), signalled
        chunks.append(chunk)
        if signalled is None:
            signalled = len(chunk)
            proc.send_signal(sig)


@pytest.mark.parametrize("k", [0, 1, 2])
@pytest.mark.parametrize("prog", list(COMMANDS))
def test_a_signal_while_each_file_is_written_lets_it_be_written_whole(tmp_path, prog, k):
    """The file ``k`` is a pipe that the test reads (the writer writes into it directly, as
    into a device): the command is signalled while it waits to write the rest of that file;
    the file comes whole, the files after it are written, then one line, exit 128 + the
    signal."""
    name = COMMANDS[prog][2][k]
    sig = (signal.SIGTERM, signal.SIGINT)[(k + (prog == "cahyman")) % 2]
    out = tmp_path / "map"
    out.mkdir()
    os.mkfifo(out / name)
    fd = os.open(out / name, os.O_RDONLY | os.O_NONBLOCK)
    try:
        size = fcntl.fcntl(fd, fcntl.F_SETPIPE_SZ, PIPE_SIZE)
        proc = _start(prog, out)
        try:
            _until_computed(proc, prog)
            data, before = _read_paused(fd, proc, sig)
        except BaseException:
            os.killpg(proc.pid, signal.SIGKILL)
            raise
        finally:
            code, stdout, after = _finish(proc)
    finally:
        os.close(fd)
    assert _check(prog, sig, out, code, stdout, after, read={name: data})
    # the signal came while the command had this file's rest to write
    assert len(data) > before + size, (len(data), before, size)
