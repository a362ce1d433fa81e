"""Running the ``dtd`` command as a user would, on tiny budgets."""

from __future__ import annotations

import atexit
import contextlib
import csv
import json
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from dtd.envs.goals import GoalFunctions, RewardFn

# A budget that exercises every part of training in about a second per epoch (episodes collected
# inline: a collecting process would take longer to start than such a run takes to train).
TINY = [
    "--n-cycles", "2", "--updates-per-cycle", "5", "--batch-size", "32", "--hidden-sizes", "32", "32",
    "--test-episodes", "2", "--buffer-size", "20000", "--threads", "1", "--collector", "inline",
    "--no-progress",
]  # fmt: skip


def dtd(*args: str | Path, cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    """Run ``python -m dtd ARGS`` in a process of its own and capture its output.

    The process is a fork of a server that has already imported torch, MuJoCo,
    Gymnasium-Robotics and matplotlib (:mod:`tests.cli_server`), so that each command starts in
    well under a second; with ``DTD_TESTS_FRESH_INTERPRETERS=1``, or an environment changed since the
    server started, it is a fresh interpreter instead."""
    command = [sys.executable, "-m", "dtd", *map(str, args)]
    server = _server()
    if server is None:
        return subprocess.run(command, capture_output=True, text=True, timeout=timeout, cwd=cwd)
    return server.run(command, cwd, timeout)


class _CommandServer:
    """The client side of one :mod:`tests.cli_server` process."""

    def __init__(self) -> None:
        self.env = _environment()
        self.process = subprocess.Popen(
            [sys.executable, "-m", "tests.cli_server"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            bufsize=0,
            cwd=Path(__file__).resolve().parents[1],
        )
        self.folder = Path(tempfile.mkdtemp(prefix="dtd-tests-output-"))

    def usable(self) -> bool:
        return self.process.poll() is None and _environment() == self.env

    def run(self, command: list[str], cwd: Path | None, timeout: float) -> subprocess.CompletedProcess[str]:
        stdout, stderr = self.folder / "stdout", self.folder / "stderr"
        stdout.write_bytes(b"")
        stderr.write_bytes(b"")
        request = {
            "args": command[3:],
            "cwd": str(Path(cwd) if cwd is not None else Path.cwd()),
            "env": dict(os.environ),
            "stdout": str(stdout),
            "stderr": str(stderr),
        }
        assert self.process.stdin is not None and self.process.stdout is not None
        message = (json.dumps(request) + "\n").encode()
        while message:
            message = message[self.process.stdin.write(message) :]
        replies = self.process.stdout.fileno()
        pid = int(_read_line(replies, timeout=60))
        try:
            returncode = int(_read_line(replies, timeout))
        except TimeoutError:
            os.kill(pid, signal.SIGKILL)
            _read_line(replies, timeout=60)
            output = stdout.read_text(), stderr.read_text()
            raise subprocess.TimeoutExpired(command, timeout, *output) from None
        return subprocess.CompletedProcess(command, returncode, stdout.read_text(), stderr.read_text())

    def close(self) -> None:
        if self.process.stdin is not None:
            self.process.stdin.close()
        self.process.wait(timeout=30)
        shutil.rmtree(self.folder, ignore_errors=True)


_servers: list[_CommandServer] = []


def _server() -> _CommandServer | None:
    """This test process's command server, started on first use; None where commands must
    run in fresh interpreters."""
    if os.environ.get("DTD_TESTS_FRESH_INTERPRETERS", "") not in ("", "0"):
        return None
    if _servers and _servers[-1].usable():
        return _servers[-1]
    if _servers and _servers[-1].process.poll() is None:
        return None  # the environment changed since the server started: a fresh interpreter
    _servers.append(_CommandServer())
    if len(_servers) == 1:
        atexit.register(lambda: [server.close() for server in _servers])
    return _servers[-1]


def _read_line(fd: int, timeout: float) -> str:
    """One line from the unbuffered pipe ``fd`` (read a byte at a time, so that nothing past
    the line is taken from the pipe); TimeoutError after ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    line = b""
    while not line.endswith(b"\n"):
        ready, _, _ = select.select([fd], [], [], max(0.0, deadline - time.monotonic()))
        if not ready:
            raise TimeoutError
        byte = os.read(fd, 1)
        if not byte:
            raise RuntimeError("the dtd command server of the tests ended")
        line += byte
    return line.decode()


def _environment() -> dict[str, str]:
    """The environment a command would get, but for the variable naming pytest's current test."""
    return {name: value for name, value in os.environ.items() if name != "PYTEST_CURRENT_TEST"}


def sparse_goals(reward: RewardFn) -> GoalFunctions:
    """The verdicts of a -1/0 task that runs to its time limit, from its reward."""
    return GoalFunctions(reward=reward, reached=lambda a, g: reward(a, g) == 0.0, terminal=None)


def read_metrics(run_dir: Path) -> list[dict[str, str]]:
    """metrics.csv as a list of rows."""
    with open(run_dir / "metrics.csv") as file:
        return list(csv.DictReader(file))


def without_times(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    """Rows minus the wall-clock column, for comparing runs."""
    return [{k: v for k, v in row.items() if k != "wall_s"} for row in rows]


# Figures of a run written on another machine agree with this machine's to float32 rounding, not
# bit for bit: torch picks kernels for the CPU's instruction set (AVX2, AVX-512), whose sums round
# differently. After 2 tiny epochs the losses differ by 1e-8 to 1e-5 of their value, and the eval
# figures, whose episodes carry the difference through the simulator, by up to 4e-4; a changed
# seed or a changed order of random draws moves them by tenths.
ANOTHER_MACHINE = {"rel": 1e-2, "abs": 1e-5}


def assert_same_figures(rows: list[dict[str, str]], expected: list[dict[str, str]]) -> None:
    """``rows`` of metrics.csv are ``expected``, written on another machine: the same columns,
    the same counts (epochs, steps, updates, episodes) and blanks, and each figure the same to
    :data:`ANOTHER_MACHINE`'s tolerance."""
    rows, expected = without_times(rows), without_times(expected)
    assert [list(row) for row in rows] == [list(row) for row in expected]
    for epoch, (row, want) in enumerate(zip(rows, expected, strict=True), start=1):
        exact = {name for name, value in want.items() if not value or value.lstrip("-").isdigit()}
        assert {name: row[name] for name in exact} == {name: want[name] for name in exact}, epoch
        figures = {name: float(row[name]) for name in want.keys() - exact}
        wanted = {name: float(want[name]) for name in figures}
        assert figures == pytest.approx(wanted, **ANOTHER_MACHINE), epoch


@contextlib.contextmanager
def read_only(folder: Path) -> Iterator[None]:
    """Make ``folder`` read-only for this process while inside: a read-only bind mount where we
    are root (whom file modes do not stop), else file modes."""
    if os.geteuid() != 0:
        modes = {path: path.stat().st_mode for path in [folder, *folder.rglob("*")]}
        for path in modes:
            path.chmod(modes[path] & ~0o222)
        try:
            yield
        finally:
            for path, mode in modes.items():
                path.chmod(mode)
        return
    mounted = subprocess.run(["mount", "--bind", str(folder), str(folder)], capture_output=True, text=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot make {folder} read-only here: {mounted.stderr.strip()}")
    try:
        remounted = subprocess.run(
            ["mount", "-o", "remount,bind,ro", str(folder)], capture_output=True, text=True
        )
        if remounted.returncode != 0:
            pytest.skip(f"cannot make {folder} read-only here: {remounted.stderr.strip()}")
        yield
    finally:
        subprocess.run(["umount", str(folder)], check=True)


@contextlib.contextmanager
def small_disk(folder: Path, size_bytes: int) -> Iterator[Path]:
    """``folder`` as a filesystem of its own of ``size_bytes`` (a tmpfs), which a writer fills
    with a real "no space left on device"; skipped where this process cannot mount one."""
    folder.mkdir(parents=True, exist_ok=True)
    size = f"size={max(4096, size_bytes // 4096 * 4096)}"
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", size, "tmpfs", str(folder)], capture_output=True, text=True
    )
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a small filesystem at {folder} here: {mounted.stderr.strip()}")
    try:
        yield folder
    finally:
        subprocess.run(["umount", "--lazy", str(folder)], check=True)
