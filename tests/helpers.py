"""Running the ``dtd`` command as a user would, on tiny budgets."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

# A budget that exercises every part of training in about a second per epoch.
TINY = [
    "--n-cycles", "2", "--updates-per-cycle", "5", "--batch-size", "32", "--hidden-sizes", "32", "32",
    "--test-episodes", "2", "--buffer-size", "20000", "--threads", "1", "--no-progress",
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
