"""Running the ``dtd`` command as a user would, on tiny budgets."""

from __future__ import annotations

import contextlib
import csv
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

# A budget that exercises every part of training in about a second per epoch (episodes collected
# inline: a collecting process would take longer to start than such a run takes to train).
TINY = [
    "--n-cycles", "2", "--updates-per-cycle", "5", "--batch-size", "32", "--hidden-sizes", "32", "32",
    "--test-episodes", "2", "--buffer-size", "20000", "--threads", "1", "--collector", "inline",
    "--no-progress",
]  # fmt: skip


def dtd(*args: str | Path, cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    """Run ``python -m dtd ARGS`` and capture its output."""
    return subprocess.run(
        [sys.executable, "-m", "dtd", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=cwd,
    )


def read_metrics(run_dir: Path) -> list[dict[str, str]]:
    """metrics.csv as a list of rows."""
    with open(run_dir / "metrics.csv") as file:
        return list(csv.DictReader(file))


def without_times(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    """Rows minus the wall-clock column, for comparing runs."""
    return [{k: v for k, v in row.items() if k != "wall_s"} for row in rows]


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
