"""Exclusive ownership of a run directory by one process (an advisory `flock` on a lock file)."""

import fcntl
import os
from pathlib import Path

from ._checkpoint import CheckpointError

LOCK = ".run.lock"


class RunLock:
    """Holds an exclusive `fcntl.flock` on `directory/.run.lock` while a run writes into `directory`.

    A second process that wants the same directory (a second fresh run, or a resume while the first
    still runs) gets a [`CheckpointError`][] at once instead of overwriting the first run's
    checkpoints and log. The lock belongs to the open file: the operating system releases it when
    the process ends, however it ends (`kill -9` included), so a crashed run leaves no stale lock.
    The lock file itself stays (empty) in the directory.

    Use as a context manager, `with RunLock(directory): ...`, or `acquire()` / `release()`.
    """

    def __init__(self, directory):
        self.path = Path(directory) / LOCK
        self._fd = None

    def acquire(self) -> "RunLock":
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise CheckpointError(
                f"{self.path.parent} is in use by another run (another process holds {self.path}); wait for it to "
                "finish, or choose another directory."
            ) from None
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> "RunLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
