"""A live progress display of training: epoch, env steps, eval success, steps/s, ETA."""

from __future__ import annotations

from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from dtd.training.recorder import Row


class TrainingProgress:
    """A rich progress bar over env steps (unless disabled), plus one line per finished epoch."""

    def __init__(self, total_steps: int, epochs: int, enabled: bool = True) -> None:
        self.epochs = epochs
        self.pending_note = ""
        self.console = Console(stderr=True)
        self.progress = Progress(
            TextColumn("[bold]epoch {task.fields[epoch]}/{task.fields[epochs]}"),
            BarColumn(),
            TextColumn("{task.completed:,.0f}/{task.total:,.0f} steps"),
            TextColumn("eval {task.fields[eval]}"),
            TextColumn("{task.fields[rate]} steps/s"),
            TimeRemainingColumn(),
            console=self.console,
            disable=not enabled,
        )
        self.task = self.progress.add_task(
            "train", total=total_steps, epoch=0, epochs=epochs, eval="-", rate="-"
        )

    def __enter__(self) -> TrainingProgress:
        self.progress.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.progress.stop()

    def note(self, text: str) -> None:
        """A word about the run, shown at the end of the first epoch's line (a start that fails
        before its first epoch ends in its error line alone)."""
        self.pending_note = text

    def start_at(self, steps: int) -> None:
        """Show ``steps`` env steps as already done (a resumed run)."""
        self.progress.update(self.task, completed=steps)

    def advance(self, steps: int, epoch: int, steps_per_s: float) -> None:
        """Count ``steps`` more env steps during ``epoch`` (1-based)."""
        self.progress.update(self.task, advance=steps, epoch=epoch, rate=f"{steps_per_s:,.0f}")

    def epoch_done(self, row: Row) -> None:
        """Show a finished epoch's figures; the total is estimated anew from the steps so far
        (episodes that a task ends on reaching its goal are shorter than the time limit)."""
        steps, epoch = int(row["env_steps"]), int(row["epoch"])
        total = round(steps * self.epochs / epoch) if epoch > 0 else None
        self.progress.update(self.task, eval=f"{row['eval_success']:.2f}", completed=steps, total=total)
        note = f"  ({self.pending_note})" if self.pending_note else ""
        self.pending_note = ""
        self.console.print(
            f"epoch {int(row['epoch'])}/{self.epochs}  steps {int(row['env_steps']):,}  "
            f"eval success {row['eval_success']:.3f}  train success {row['train_success']:.3f}  "
            f"final dist {row['eval_final_distance']:.3f}  wall {row['wall_s']:.0f}s{note}",
            soft_wrap=True,
        )
