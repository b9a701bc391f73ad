"""One run per run directory: an OS file lock on ``<run>/.lock``.

``fcntl.flock`` (advisory, exclusive, non-blocking) is released by the kernel when the process
ends however it ends (kill -9 included), so a stale lock never blocks the next run. The holder
writes its pid into the file so that a second run can name it.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
from collections.abc import Iterator
from pathlib import Path

from pipeline.core.errors import PipelineError

LOCK_NAME = ".lock"


class RunLockedError(PipelineError):
    """Another process is running on the same run directory."""


def _holder(path: Path) -> str:
    try:
        text = path.read_text(encoding="utf-8").strip()
    except OSError:
        return "another process"
    return f"process {text}" if text.isdigit() else "another process"


@contextlib.contextmanager
def run_lock(run_dir: Path) -> Iterator[int | None]:
    """Hold the lock of ``run_dir`` (yields its file descriptor).

    Raises :class:`RunLockedError` naming the holder's pid when another process holds it.
    Yields None (no lock) when the directory is read-only: nothing can be written there then,
    so a concurrent run cannot mix files into it either.
    """
    path = Path(run_dir) / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError as exc:
        if exc.errno in (errno.EROFS, errno.EACCES, errno.EPERM):
            yield None
            return
        raise
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise RunLockedError(run_dir, None, f"{_holder(path)} is running on this run directory; "
                                 "wait for it to finish or choose another name/--out") from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        yield fd
    finally:
        os.close(fd)               # releases the lock
