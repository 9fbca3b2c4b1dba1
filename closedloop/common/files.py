"""Output files written whole or not at all."""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import stat
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

from closedloop.exceptions import InvalidInputError


def output_folder(out: str | Path) -> Path:
    """The folder ``out``, made with its parents if missing.

    Raises:
        InvalidInputError: ``out`` cannot be made or is not a folder (the message names it
            and the system's reason).
    """
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise InvalidInputError(f"cannot write to {str(out)!r}: {e.strerror}") from None
    return out


def write_atomically(
    path: str | Path, write: Callable[[IO[Any]], object], *, text: bool = False,
    newline: str | None = None,
) -> Path:  # fmt: skip
    """Write ``path`` through ``write(f)`` so that it is either complete or unchanged.

    ``write`` gets an open file (binary, or UTF-8 text with ``text``; ``newline`` as for
    ``open()``): a hidden temporary file (``.NAME.<random>.tmp``) in the folder of
    ``path``, flushed to the disk and moved onto ``path`` with ``os.replace`` once
    ``write`` has returned. On any error (a full disk, an exception of ``write``,
    Ctrl-C) the temporary file is removed and the error raised again, with ``path`` as
    its file name where it named the temporary file; an existing file ``path`` is then left
    as it was. The new file gets the permissions of the file it replaces, or else
    ``0o666`` less the umask, as ``open()`` would give; a symbolic link ``path`` is
    followed (its target is replaced). A file that the user may not write is refused
    (:class:`PermissionError`, as by ``open()``); a target that is not a regular file
    (a device such as ``/dev/null``, a pipe such as ``/dev/stdout``) is written into
    directly. Returns ``path``.
    """
    path = Path(path)
    try:
        special = not stat.S_ISREG(os.stat(path).st_mode)  # the file a link leads to
    except FileNotFoundError:
        special = False
    mode, encoding = ("w", "utf-8") if text else ("wb", None)
    if special:  # a device, a pipe (/dev/stdout, whose link names no file): written into
        with open(path, mode, encoding=encoding, newline=newline) as f:
            write(f)
        return path
    target = Path(os.path.realpath(path))
    if target.exists() and not os.access(target, os.W_OK):  # as open() would refuse it
        raise PermissionError(errno.EACCES, "Permission denied", str(path))
    tmp = target.with_name(f".{target.name[:100]}.{secrets.token_hex(4)}.tmp")
    try:
        flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
        fd = os.open(tmp, flags, 0o666)  # the umask applies (tempfile would give 0o600)
        with os.fdopen(fd, mode, encoding=encoding, newline=newline) as f:
            with contextlib.suppress(OSError):  # no old file, or no permissions here
                os.chmod(tmp, stat.S_IMODE(os.stat(target).st_mode))
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException as e:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if isinstance(e, OSError) and e.filename == str(tmp):
            e.filename = str(path)
        raise
    return path


def save_figure(fig, path: str | Path, **kwargs) -> Path:
    """``fig.savefig(path, **kwargs)`` through :func:`write_atomically`, in the format of
    the suffix of ``path`` (matplotlib's default format without one), then the figure
    closed (saved or not); returns ``path``."""
    import matplotlib.pyplot as plt  # the caller's figure: pyplot is loaded already

    fmt = Path(path).suffix[1:] or None
    try:
        return write_atomically(path, lambda f: fig.savefig(f, format=fmt, **kwargs))
    finally:
        plt.close(fig)
