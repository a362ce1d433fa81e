"""Many training runs ("trials") side by side in local processes, each resumable.

A trial is a configuration, a budget of env steps and a run directory. Run again on the same
directories, finished trials are skipped and interrupted ones resume from their checkpoints
(:func:`dtd.runs.train_for_steps`). A failing trial is reported with its traceback and does
not stop the others.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import multiprocessing
import time
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path

from dtd.config import TrainConfig


@dataclasses.dataclass(frozen=True)
class Trial:
    """One training run of a sweep."""

    config: TrainConfig
    steps: int
    """Budget in env steps (rounded up to whole epochs)."""
    run_dir: Path

    @property
    def name(self) -> str:
        return self.run_dir.name


@dataclasses.dataclass(frozen=True)
class TrialOutcome:
    """How a trial ended: ``error`` holds the traceback of a failure, else None."""

    trial: Trial
    error: str | None
    wall_s: float
    """Seconds this call spent on the trial (0 for one finished before)."""

    @property
    def ok(self) -> bool:
        return self.error is None


def run_trial(trial: Trial) -> TrialOutcome:
    """Train ``trial`` to its budget (resuming, or skipping a finished run); never raises."""
    from dtd.runs import train_for_steps

    start = time.perf_counter()
    try:
        train_for_steps(trial.config, trial.steps, trial.run_dir)
    except Exception:
        return TrialOutcome(trial, traceback.format_exc(), time.perf_counter() - start)
    return TrialOutcome(trial, None, time.perf_counter() - start)


def run_local(
    trials: Sequence[Trial],
    workers: int,
    on_done: Callable[[TrialOutcome], None] | None = None,
) -> list[TrialOutcome]:
    """Run ``trials`` in a pool of ``workers`` processes; outcomes in the order of ``trials``.

    ``on_done`` is called in this process as each trial ends. With one worker the trials run
    here, one after the other.
    """
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    outcomes: dict[int, TrialOutcome] = {}
    if workers == 1:
        for index, trial in enumerate(trials):
            outcomes[index] = run_trial(trial)
            if on_done is not None:
                on_done(outcomes[index])
    else:
        context = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
            futures = {pool.submit(run_trial, trial): index for index, trial in enumerate(trials)}
            for future in concurrent.futures.as_completed(futures):
                index = futures[future]
                try:
                    outcomes[index] = future.result()
                except Exception:  # the worker process itself died
                    outcomes[index] = TrialOutcome(trials[index], traceback.format_exc(), 0.0)
                if on_done is not None:
                    on_done(outcomes[index])
    return [outcomes[index] for index in range(len(trials))]
