"""Opening a record file for writing: one run at a time per file."""

from __future__ import annotations

import fcntl
import os
from pathlib import Path
from typing import IO

from netsetest.records.errors import RecordError


def open_locked(path: str | Path) -> IO[bytes]:
    """The record file for writing, emptied, held under an exclusive lock until it is closed: a second run
    writing the same file fails at once (RecordError) instead of interleaving its lines into this one's."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise RecordError(f"{path}: another run is writing this record") from None
    os.ftruncate(fd, 0)  # only now: the other run's record is never emptied
    return os.fdopen(fd, "wb")


def being_written(path: str | Path) -> bool:
    """Whether a run holds ``path`` under :func:`open_locked` now: checked before a run starts any role, so
    that the second of two runs sharing a record is refused at once, not by its collector mid-start."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:  # no such file (or none readable): nothing writes it that could be refused here
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)  # closing releases a lock taken here
    return False
