"""Atomic file replacement: readers, and a crash at any moment, see the old file or the new one.

Every file dtd writes goes through here: one file by :func:`write_atomic` (a temporary renamed
over it), the files of one command's output folder by :func:`staged` (written into a temporary
folder beside it, moved in only when all are written). A command that fails or is interrupted
leaves no partial file and no part of its output; a full disk is one :class:`MachineError`.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

from dtd.errors import MachineError, RunDirError


def write_atomic(path: Path, write: Callable[[IO[bytes]], None]) -> None:
    """Let ``write`` fill a temporary file, fsync it, rename it over ``path``, fsync the folder.

    A failure of the machine (a full disk, an I/O error) raises :class:`MachineError` naming
    the operating system's reason and ``path``, even where the writer (``torch.save``) buries
    that reason in an error of its own; ``path`` is then left as it was.
    """
    tmp = temporary_beside(path)
    recorded = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open_for_writing(tmp) as raw:
            recorded = _RecordingWriter(raw)
            write(recorded)  # type: ignore[arg-type]
            raw.flush()
            os.fsync(raw.fileno())
        os.replace(tmp, path)
        fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
    except OSError as exc:
        raise MachineError(machine_failure(exc, path)) from exc
    except Exception as exc:
        if recorded is not None and recorded.error is not None:
            raise MachineError(machine_failure(recorded.error, path)) from exc
        raise
    finally:
        tmp.unlink(missing_ok=True)


def ensure_writable(folder: Path, what: str) -> None:
    """Make ``folder`` if missing and check that a file can be written in it, or raise
    :class:`RunDirError` saying that ``what`` cannot be written there and why: checked before
    work whose result would be lost."""
    probe = Path(folder) / f".write-check.{os.getpid()}.tmp"
    try:
        Path(folder).mkdir(parents=True, exist_ok=True)
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as exc:
        raise RunDirError(f"cannot write {what} into {folder}: {exc.strerror or exc}") from exc


def open_for_writing(path: Path) -> IO[bytes]:
    """The binary file every atomic write goes through (a seam for tests of a full disk)."""
    return open(path, "wb")


def machine_failure(error: OSError, path: Path) -> str:
    """'no space left on device writing PATH': the operating system's reason, then the file."""
    reason = (error.strerror or str(error)).rstrip(".")
    return f"{reason[:1].lower()}{reason[1:]} writing {path}"


class _RecordingWriter:
    """A file that remembers the operating system's error of a failed write, which a writer in
    C++ (``torch.save``) would otherwise replace with a message of its own."""

    def __init__(self, file: IO[bytes]) -> None:
        self.file = file
        self.error: OSError | None = None

    def write(self, data: Any) -> int:
        try:
            return self.file.write(data)
        except OSError as exc:
            self.error = exc
            raise

    def __getattr__(self, name: str) -> Any:
        return getattr(self.file, name)


def temporary_beside(path: Path) -> Path:
    """The name of ``path``'s temporary stand-in while this process writes it: hidden, beside
    it, naming the process (so that a killed writer's are known, :func:`remove_stale_temporaries`)."""
    return path.with_name(f".{path.name}.{os.getpid()}.tmp")


@contextlib.contextmanager
def staged(folder: Path, what: str) -> Iterator[Path]:
    """A temporary folder beside ``folder`` for the block to write ``what`` into; when the block
    ends without error its files move into ``folder`` (made where missing; a file of the same
    name replaced, others left), each by a rename. On an error or an interrupt nothing of it
    reaches ``folder``, and the temporary folder is removed. A failure of the machine (a full
    disk) is a :class:`MachineError` naming the operating system's reason; a folder that cannot
    be written a :class:`RunDirError`, before the block runs."""
    folder = Path(folder)
    with _staging(folder, what, lambda staging: staging) as staging:
        yield staging
        for path in sorted(staging.rglob("*")):
            if path.is_file():
                target = folder / path.relative_to(staging)
                target.parent.mkdir(parents=True, exist_ok=True)
                os.replace(path, target)


@contextlib.contextmanager
def staged_file(path: Path, what: str) -> Iterator[Path]:
    """:func:`staged` for one file: the block writes the path it is given, which replaces
    ``path`` when the block ends without error."""
    path = Path(path)
    with _staging(path, what, lambda staging: staging / path.name) as staging:
        yield staging / path.name
        os.replace(staging / path.name, path)


@contextlib.contextmanager
def _staging(target: Path, what: str, stand_in: Callable[[Path], Path]) -> Iterator[Path]:
    """A temporary folder beside ``target``, removed when the block ends; the machine's failures
    in the block as a :class:`MachineError` about ``target``, which ``stand_in(folder)`` stands
    for until then (a file written there is named by where it was going)."""
    staging = temporary_beside(target)
    try:
        ensure_writable(target.parent, what)
        staging.mkdir()
    except OSError as exc:
        raise RunDirError(f"cannot write {what} into {target.parent}: {exc.strerror or exc}") from exc
    try:
        yield staging
    except OSError as exc:
        raise MachineError(machine_failure(exc, target)) from exc
    except MachineError as exc:
        raise MachineError(str(exc).replace(str(stand_in(staging)), str(target))) from exc
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def remove_stale_temporaries(folder: Path) -> list[Path]:
    """Delete the temporary files and folders under ``folder`` that :func:`write_atomic` and
    :func:`staged` left behind when their process was killed (their process no longer exists);
    return them."""
    removed = []
    for tmp in list(folder.rglob(".*.tmp")):
        pid = tmp.name.rsplit(".", 2)[-2]
        if pid.isdigit() and not _process_exists(int(pid)):
            if tmp.is_dir():
                shutil.rmtree(tmp, ignore_errors=True)
            else:
                tmp.unlink(missing_ok=True)
            removed.append(tmp)
    return removed


def _process_exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process
    return True


def write_text_atomic(path: Path, text: str) -> None:
    """:func:`write_atomic` for UTF-8 text."""
    write_atomic(path, lambda file: file.write(text.encode()))
