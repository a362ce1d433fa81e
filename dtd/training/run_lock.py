"""One trainer per run directory: an advisory lock held while a process trains the run.

The lock is ``flock`` on ``RUN/.trainer.lock``, a file that holds the trainer's PID and exists
only while it trains. The operating system releases the lock when its process ends in any way
(``kill -9`` included), so a lock file left behind by a killed trainer never blocks a later
one. Readers (``dtd eval``, ``plot``, ``report``, ``render``) take no lock.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Iterator
from pathlib import Path

from dtd.errors import MachineError, RunDirError
from dtd.training.atomic import machine_failure

LOCK_NAME = ".trainer.lock"


@contextlib.contextmanager
def holding(root: Path) -> Iterator[None]:
    """Hold the run directory ``root`` (made if missing) for this process, or raise
    :class:`RunDirError` naming the process that holds it, or why it cannot be written (a
    :class:`MachineError` where the disk is full).

    On leaving, the lock file is removed, and so are the folders made for it where the run
    wrote nothing (bad input found during set-up leaves the disk as it was).
    """
    root = Path(root)
    path = root / LOCK_NAME
    made = [folder for folder in (root, *root.parents) if not folder.exists()]
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RunDirError(f"cannot write to the run directory {root}: {exc.strerror or exc}") from exc
    fd = _locked(path)
    try:
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        except OSError as exc:  # a full disk, before the run has written anything
            raise MachineError(machine_failure(exc, path)) from exc
        yield
    finally:
        # Removed before it is unlocked: a trainer that opened it meanwhile sees it gone and
        # opens the next one (see _locked).
        with contextlib.suppress(OSError):
            path.unlink()
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)
        with contextlib.suppress(OSError):
            for folder in made:  # the run directory first, then the parents made for it
                folder.rmdir()


def _locked(path: Path) -> int:
    """A descriptor of the lock file at ``path``, locked by this process."""
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise RunDirError(
                f"cannot write to the run directory {path.parent}: {exc.strerror or exc}"
            ) from exc
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
            os.close(fd)
            raise RunDirError(
                f"{path.parent} is being trained by process {holder}; wait for it to end or stop it"
            ) from None
        try:
            current = os.stat(path).st_ino
        except FileNotFoundError:
            current = None
        if current == os.fstat(fd).st_ino:
            return fd
        os.close(fd)  # its holder removed the file as we opened it: lock the next one
