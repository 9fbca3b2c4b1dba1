"""Output files are written whole or not at all: a write that fails midway (a full disk)
leaves no file and keeps the previous one."""

import errno
import os
import stat

import numpy as np
import numpy.lib.format
import pytest

import closedloop as cl
from cahyman_pin.sweep import SweepResult, pose_list, sweep
from closedloop.analysis.maps import stiffness_map
from closedloop.common.files import write_atomically


def disk_full():
    return OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


@pytest.mark.parametrize("error", [disk_full(), KeyboardInterrupt()])
def test_failed_write_leaves_no_file_and_keeps_the_old_one(tmp_path, error):
    from closedloop.common.files import write_atomically

    def write(f):
        f.write(b"new content, cut ")
        raise error

    with pytest.raises(type(error)):
        write_atomically(tmp_path / "new.npz", write)
    assert os.listdir(tmp_path) == []
    old = tmp_path / "old.npz"
    old.write_bytes(b"old content")
    with pytest.raises(type(error)):
        write_atomically(old, write)
    assert old.read_bytes() == b"old content" and os.listdir(tmp_path) == ["old.npz"]


def test_successful_write_replaces_the_old_content(tmp_path):
    from closedloop.common.files import write_atomically

    path = tmp_path / "m"
    path.write_text("old, and longer than the new")
    seen = []

    def write(f):
        seen.extend(os.listdir(tmp_path))
        np.savez(f, a=np.arange(3))  # a file object: no ".npz" appended

    assert write_atomically(path, write) == path
    assert sorted(os.listdir(tmp_path)) == ["m"]
    np.testing.assert_array_equal(np.load(path)["a"], np.arange(3))
    (tmp_in_folder,) = set(seen) - {"m"}  # hidden, beside the target
    assert tmp_in_folder.startswith(".m.") and tmp_in_folder.endswith(".tmp")
    write_atomically(path, lambda f: f.write("a,b\r\n1,2\n"), text=True, newline="")
    assert path.read_bytes() == b"a,b\r\n1,2\n"


def test_permissions_follow_the_umask_or_the_replaced_file(tmp_path, umask_022):
    from closedloop.common.files import write_atomically

    new = write_atomically(tmp_path / "new.csv", lambda f: f.write(b"x"))
    assert stat.S_IMODE(new.stat().st_mode) == 0o644  # 0o666 & ~0o022, not tempfile's 0o600
    os.umask(0o077)
    assert stat.S_IMODE(write_atomically(tmp_path / "private", lambda f: None).stat().st_mode) == (
        0o600
    )
    new.chmod(0o640)
    write_atomically(new, lambda f: f.write(b"y"))
    assert stat.S_IMODE(new.stat().st_mode) == 0o640 and new.read_bytes() == b"y"


def test_errors_name_the_file_asked_for(tmp_path):
    from closedloop.common.files import write_atomically

    with pytest.raises(FileNotFoundError) as info:
        write_atomically(tmp_path / "missing" / "map.npz", lambda f: None)
    assert info.value.filename == str(tmp_path / "missing" / "map.npz")


def fail_on_third_array(monkeypatch):
    """numpy's savez writes two arrays, part of the third, then finds the disk full."""
    real, calls = numpy.lib.format.write_array, []

    def write_array(fp, array, *args, **kwargs):
        calls.append(1)
        if len(calls) < 3:
            return real(fp, array, *args, **kwargs)
        fp.write(b"\x93NUMPY partial")
        raise disk_full()

    monkeypatch.setattr(numpy.lib.format, "write_array", write_array)


def test_map_save_that_fails_midway_keeps_the_previous_map(
    fourbar_urdf, fourbar_yaml, tmp_path, monkeypatch
):
    clm = cl.load_model(fourbar_urdf, fourbar_yaml)
    good = stiffness_map(clm, "P", sweeps={"crank": np.linspace(0.2, 2.8, 5)})
    good.save(tmp_path, index="min_translational")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    other = stiffness_map(clm, "P", sweeps={"crank": np.linspace(0.3, 2.7, 7)})
    fail_on_third_array(monkeypatch)
    with pytest.raises(OSError, match="No space left"):
        other.save(tmp_path, index="min_translational")
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before  # no temp file left
    with np.load(tmp_path / "map.npz") as data:
        np.testing.assert_array_equal(data["C"], good.C)


def test_sweep_save_that_fails_midway_keeps_the_previous_npz(tmp_path, monkeypatch):
    pts = pose_list(np.deg2rad([[60.0, 65.0, 70.0]] * 2), np.deg2rad([45.0, 30.0]), [0.01, 0.02])
    good = sweep(pts, backend="consistent", executor="serial")
    good.save_npz(tmp_path / "map.npz")
    fail_on_third_array(monkeypatch)
    with pytest.raises(OSError, match="No space left"):
        good.save_npz(tmp_path / "map.npz")
    assert os.listdir(tmp_path) == ["map.npz"]
    np.testing.assert_array_equal(SweepResult.load_npz(tmp_path / "map.npz").C, good.C)


def test_a_pipe_is_written_into_not_replaced(tmp_path):
    """`--html /dev/stdout` into a pipe, or `/dev/null`: the target is no regular file, so
    it is written into (the rename turned root's /dev/null into a regular file)."""
    import threading

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()))
    reader.start()
    write_atomically(fifo, lambda f: f.write(b"through the pipe"))
    reader.join(timeout=10)
    assert got == [b"through the pipe"] and stat.S_ISFIFO(os.stat(fifo).st_mode)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe"]  # no temporary left


def test_dev_stdout_into_a_pipe_is_written_into():
    """`--html /dev/stdout | ...`: the link leads to a pipe that has no file name; the
    writer failed with "No such file or directory"."""
    import subprocess
    import sys

    code = ("from closedloop.common.files import write_atomically; "
            "write_atomically('/dev/stdout', lambda f: f.write(b'through stdout'))")  # fmt: skip
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, check=True,
                          timeout=60)  # fmt: skip
    assert done.stdout == b"through stdout"


def test_a_file_the_user_may_not_write_is_refused(tmp_path, monkeypatch):
    """A read-only file is refused as open() refuses it (the rename only needs the folder's
    permission). Root may write any file: the check is os.access, patched here."""
    path = tmp_path / "protected.html"
    path.write_text("old")
    real = os.access
    monkeypatch.setattr(
        os, "access", lambda p, mode: False if str(p) == str(path) else real(p, mode)
    )
    with pytest.raises(PermissionError, match="Permission denied"):
        write_atomically(path, lambda f: f.write(b"new"))
    assert path.read_text() == "old"


def test_a_name_of_255_characters_is_written(tmp_path):
    """The temporary name is cut so that it stays within the file system's 255."""
    path = tmp_path / ("m" * 251 + ".npz")
    write_atomically(path, lambda f: f.write(b"data"))
    assert path.read_bytes() == b"data" and len(list(tmp_path.iterdir())) == 1
