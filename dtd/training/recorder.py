"""Metrics out: metrics.csv (rewritten whole and atomically) and TensorBoard scalars."""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence

from dtd.training.atomic import write_text_atomic
from dtd.training.run_dir import RunDir

# Columns every run has, in this order; others (losses, ...) follow alphabetically.
LEADING_COLUMNS = (
    "epoch",
    "env_steps",
    "updates",
    "episodes",
    "wall_s",
    "eval_success",
    "train_success",
    "eval_final_distance",
    "train_final_distance",
)

Row = dict[str, float]


def columns(rows: Sequence[Row]) -> list[str]:
    """The CSV header for ``rows``."""
    names = {name for row in rows for name in row}
    return [c for c in LEADING_COLUMNS if c in names] + sorted(names - set(LEADING_COLUMNS))


def metrics_csv(rows: Sequence[Row]) -> str:
    """All rows as CSV text."""
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=columns(rows), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return out.getvalue()


class MetricsRecorder:
    """Writes the history of epoch rows; the checkpoint holds the same history, so after a
    crash the files are rebuilt from it and never hold a row twice or miss one."""

    def __init__(self, run: RunDir, resume_step: int) -> None:
        from torch.utils.tensorboard import SummaryWriter  # slow import, only when training

        self.run = run
        # Events at or after resume_step came from an epoch that did not finish: drop them.
        self.writer = SummaryWriter(log_dir=str(run.tensorboard), purge_step=resume_step or None)

    def write_csv(self, history: Sequence[Row]) -> None:
        """Rewrite metrics.csv with ``history`` (nothing to write for an empty one)."""
        if history:
            write_text_atomic(self.run.metrics, metrics_csv(history))

    def log(self, row: Row) -> None:
        """Add one epoch's figures to TensorBoard, at its env step count."""
        step = int(row["env_steps"])
        for name, value in row.items():
            if name not in ("epoch", "env_steps"):
                self.writer.add_scalar(_tag(name), value, global_step=step)
        self.writer.flush()

    def close(self) -> None:
        """Flush and close the TensorBoard writer."""
        self.writer.close()


def _tag(name: str) -> str:
    for prefix in ("eval", "train"):
        if name.startswith(prefix + "_"):
            return f"{prefix}/{name[len(prefix) + 1 :]}"
    return f"progress/{name}" if name in LEADING_COLUMNS else f"learner/{name}"
