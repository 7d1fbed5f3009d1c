"""An exclusive lock on a dataset directory for the length of one ``generate`` run.

Two runs on the same ``--out`` would overwrite each other's scene copy and shards (different
scenes) or repeat each other's work (the same scene). The lock is an ``fcntl.flock`` on
``DIR/.generate.lock``, held by world rank 0 from before the directory is touched until the
process ends; the kernel releases it when the process dies, so a killed run never leaves a
stale lock. The file records who holds it, for the error message.
"""

from __future__ import annotations

import fcntl
import os
import socket
import time
from pathlib import Path

LOCK_NAME = ".generate.lock"


class LockedError(RuntimeError):
    """Another process holds the directory's lock."""


class DirectoryLock:
    """``DirectoryLock(dir).acquire()`` or :class:`LockedError` naming the holder."""

    def __init__(self, directory: str | Path):
        self.path = Path(directory) / LOCK_NAME
        self._fh = None

    def acquire(self) -> DirectoryLock:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fh = open(self.path, "a+")
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.seek(0)
            holder = fh.read().strip() or "another process"
            fh.close()
            raise LockedError(f"{self.path.parent}: another generate run is using this "
                              f"directory ({holder}); wait for it to finish or use another "
                              "--out") from None
        fh.seek(0)
        fh.truncate()
        fh.write(f"pid {os.getpid()} on {socket.gethostname()} since "
                 f"{time.strftime('%Y-%m-%d %H:%M:%S')}\n")
        fh.flush()
        self._fh = fh
        return self

    def release(self) -> None:
        if self._fh is not None:
            fcntl.flock(self._fh.fileno(), fcntl.LOCK_UN)
            self._fh.close()
            self._fh = None
