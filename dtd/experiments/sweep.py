"""A sweep: every (algorithm, seed) trial of one configuration, or of each combination of a grid
of settings, each in its own run directory.

Locally the trials share this machine's cores through a pool of processes; with a Ray address
they become tasks of a Ray cluster. Either way, a sweep run again on the same directory leaves
finished trials alone and resumes interrupted ones (:mod:`dtd.experiments.trials`).
"""

from __future__ import annotations

import dataclasses
import itertools
import re
import time
from collections.abc import Sequence
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from dtd.config import Algo, TrainConfig, required_env, with_settings
from dtd.errors import ConfigError
from dtd.experiments.trials import Trial, TrialOutcome, run_local, run_ray, sharing_cores, trials_root
from dtd.training.components import usable_cores
from dtd.training.lifecycle import epochs_recorded


def trial_name(config: TrainConfig, settings: Sequence[str] = ()) -> str:
    """<env>-<algo>[-<name>=<value>...]-s<seed>, the run directory's name inside the sweep's
    directory: the grid's ``settings`` of the trial, each value with what a path should not
    hold replaced (``hidden_sizes=[512, 512]`` becomes ``hidden_sizes=512_512``)."""
    env = (config.env or "env").split(":")[-1]
    parts = [env, config.algo.value]
    for setting in settings:
        name, _, value = setting.partition("=")
        parts.append(f"{name}={re.sub(r'[^A-Za-z0-9.+_]+', '_', value).strip('_')}")
    return "-".join([*parts, f"s{config.seed}"])


def grid_points(grid: Sequence[str]) -> list[list[str]]:
    """Every combination of the grid's settings, each given as ``NAME=V1,V2,...`` (a value may
    be a JSON list, its commas inside brackets); ``[[]]`` for no grid. NAME is a setting's name
    as ``dtd sweep --set`` takes it: a field of the configuration, ``learner.<name>`` or
    ``high.<name>`` for a learner's."""
    axes: list[list[str]] = []
    names: set[str] = set()
    for entry in grid:
        name, equals, values = entry.partition("=")
        name = name.strip().lstrip("-").replace("-", "_")
        if not equals or not name or not values.strip():
            raise ConfigError(f"--grid takes NAME=VALUE,VALUE,..., got {entry!r}")
        if name in names:
            raise ConfigError(f"--grid names {name} twice")
        names.add(name)
        choices = _split_values(values)
        if len(set(choices)) != len(choices):
            raise ConfigError(f"--grid {name} repeats a value: {values}")
        axes.append([f"{name}={choice}" for choice in choices])
    return [list(point) for point in itertools.product(*axes)]


def _split_values(values: str) -> list[str]:
    """``values`` split at the commas outside brackets."""
    parts, depth, current = [], 0, ""
    for char in values:
        depth += char in "[{"
        depth -= char in "]}"
        if char == "," and depth == 0:
            parts.append(current.strip())
            current = ""
        else:
            current += char
    parts.append(current.strip())
    if any(not part for part in parts):
        raise ConfigError(f"--grid has an empty value in {values!r}")
    return parts


def sweep_trials(
    base: TrainConfig,
    algos: Sequence[Algo],
    seeds: int,
    out: Path,
    final_episodes: int = 0,
    grid: Sequence[str] = (),
    given: frozenset[str] | None = None,
) -> list[Trial]:
    """Trials of ``base`` for each algorithm, each point of the ``grid`` (:func:`grid_points`)
    and ``seeds`` seeds from ``base.seed``; ordered seed by seed, so that the first results hold
    every algorithm and setting. With ``final_episodes``, each trial's last checkpoint is
    evaluated over that many episodes once it is trained. ``given`` names the settings of
    ``base`` the user gave (:attr:`Trial.given`); the grid's count as given too."""
    required_env(base.env)
    if not algos:
        raise ConfigError("--algos names no algorithm")
    if len(set(algos)) != len(algos):
        raise ConfigError(f"--algos names an algorithm twice: {','.join(a.value for a in algos)}")
    if seeds < 1:
        raise ConfigError(f"--seeds must be at least 1, got {seeds}")
    if final_episodes < 0:
        raise ConfigError(f"--final-episodes must be 0 (none) or more, got {final_episodes}")
    points = grid_points(grid)
    for point in points:
        for setting in point:
            if setting.partition("=")[0] in ("algo", "seed"):
                raise ConfigError("--grid cannot set algo or seed: give --algos and --seeds")
    root = trials_root(out)
    trials = []
    for seed in range(base.seed, base.seed + seeds):
        for point in points:
            for algo in algos:
                try:  # every value as its option is checked, before any trial starts
                    config = with_settings(dataclasses.replace(base, algo=algo, seed=seed), point)
                except ConfigError as exc:
                    if not point:
                        raise
                    raise ConfigError(f"--grid {' '.join(point)}: {exc}") from exc
                ungridded = dataclasses.replace(base, algo=algo, seed=seed)
                trial = Trial(ungridded, root / trial_name(config, point), final_episodes, given)
                trials.append(trial.with_config(config))  # the grid's settings count as given
    return trials


def trials_at_once(trials: Sequence[Trial], parallel: int) -> int:
    """``parallel``, or for 0 one per usable core (never more than there are trials)."""
    if parallel < 0:
        raise ConfigError(f"--parallel must be 0 (one per core) or more, got {parallel}")
    return parallel or max(1, min(len(trials), usable_cores()))


LOG_LINE_EVERY_S = 60.0
"""Without a terminal (output sent to a log file) a status line replaces the bar, at most this
often and only when epochs were added."""


class SweepProgress:
    """A progress bar over all the sweep's epochs, read from the run directories, and a line
    per trial as it ends; without a terminal, a plain status line now and then instead of the
    bar."""

    def __init__(
        self,
        trials: Sequence[Trial],
        enabled: bool,
        console: Console | None = None,
        log_every_s: float = LOG_LINE_EVERY_S,
    ) -> None:
        self.trials = trials
        self.console = console or Console(stderr=True)
        self.log_lines = enabled and not self.console.is_terminal
        self.log_every_s = log_every_s
        self.started = time.monotonic()
        self.last_line = (-float("inf"), 0)
        self.progress = Progress(
            TextColumn("[bold]sweep"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("epochs, {task.fields[done]} of {task.fields[trials]} trials ended"),
            TimeElapsedColumn(),
            console=self.console,
            disable=not enabled or self.log_lines,
        )
        self.total = sum(trial.config.epochs for trial in trials)
        self.task = self.progress.add_task("sweep", total=self.total, done=0, trials=len(trials))
        self.ended = 0

    def __enter__(self) -> SweepProgress:
        self.progress.start()
        self.refresh()
        return self

    def __exit__(self, *exc: object) -> None:
        self.refresh()
        self.progress.stop()

    def refresh(self) -> None:
        epochs = sum(min(epochs_recorded(t.run_dir), t.config.epochs) for t in self.trials)
        self.progress.update(self.task, completed=epochs, done=self.ended)
        now = time.monotonic()
        if self.log_lines and epochs > self.last_line[1] and now - self.last_line[0] >= self.log_every_s:
            self.last_line = (now, epochs)
            minutes = (now - self.started) / 60
            self.console.print(
                f"sweep: {epochs}/{self.total} epochs, {self.ended} of {len(self.trials)} trials ended, "
                f"{minutes:.0f} min",
                highlight=False,
            )

    def trial_ended(self, outcome: TrialOutcome) -> None:
        self.ended += 1
        epochs = epochs_recorded(outcome.trial.run_dir)
        if outcome.ok:
            self.console.print(f"{outcome.trial.name}: {epochs} epochs ({outcome.wall_s:.0f} s)")
        else:
            last_line = outcome.error.strip().splitlines()[-1] if outcome.error else "?"
            self.console.print(f"[red]{outcome.trial.name}: FAILED after {epochs} epochs: {last_line}")
        self.refresh()


def run_sweep(
    trials: Sequence[Trial],
    parallel: int = 0,
    ray_address: str | None = None,
    show_progress: bool = True,
) -> list[TrialOutcome]:
    """Run ``trials`` locally (``parallel`` at once, each in a process; 0 = one per core) or on
    Ray; return the outcomes in the order of ``trials``."""
    if ray_address is None:
        count = trials_at_once(trials, parallel)
        trials = [t.with_config(sharing_cores(t.config, count, usable_cores())) for t in trials]
    else:
        # On a cluster each trial keeps to its torch threads (1 unless --threads says more), and
        # Ray gives it as many CPUs: a node then runs as many trials as it has cores.
        trials = [t.with_config(dataclasses.replace(t.config, threads=t.config.threads or 1)) for t in trials]
    with SweepProgress(trials, show_progress) as progress:
        if ray_address is None:
            return run_local(trials, count, progress.trial_ended, progress.refresh)
        return run_ray(trials, ray_address, progress.trial_ended, progress.refresh)
