"""Commands that make runs and their figures: ``dtd train``, ``dtd sweep``, ``dtd plot``."""

from __future__ import annotations

import json
import signal
import sys
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import tyro

from dtd.cli.options import optional
from dtd.config import TrainConfig
from dtd.errors import DtdError
from dtd.training.launch import JobPlace

if TYPE_CHECKING:
    from dtd.training.lifecycle import StartPlan


def train(
    config: Annotated[TrainConfig, tyro.conf.arg(name="")],
    run_dir: Annotated[Path | None, optional("DIR", "runs/<env>-<algo>-s<seed>")] = None,
    resume: Annotated[Path | None, optional("DIR", "a new run")] = None,
    force: bool = False,
    progress: bool = True,
    oversubscribe: bool = False,
    place: JobPlace = JobPlace(),
    invocation: tuple[str, ...] = (),
) -> None:
    """Train an agent; results land in the run directory.

    With --workers N, N data-parallel workers (torch.distributed, gloo) train one agent: dtd
    starts them on this machine, or torchrun starts them on several (the run directory then
    on a filesystem every machine shares).

    Examples:
      dtd train --env FetchPush-v4 --algo her --seed 0 --epochs 50 --run-dir runs/push-her-0
      dtd train --env FetchPush-v4 --algo dtd --preset paper   # the paper's settings
      dtd train --resume runs/push-her-0
      dtd train --env FetchPush-v4 --algo dtd --preset paper --workers 19 --oversubscribe

    Args:
        config: The run's settings.
        run_dir: Where the run's files go.
        resume: Continue the run in this directory after its last finished epoch; --epochs may grow.
        force: Replace a run that already exists in --run-dir.
        progress: Show a live progress bar.
        oversubscribe: Start more workers than this machine has cores (each then runs slower).
        place: This process's place in a job of workers (the command line reads it).
        invocation: The command's arguments, which the workers started here are given.
    """
    from dtd.cli.options import settings_given
    from dtd.training.lifecycle import epochs_recorded, plan_start, train_planned

    plan = plan_start(config, run_dir, resume, force, place, given=settings_given(invocation[1:]))
    if not place.in_job and plan.workers > 1:
        _launch_workers(plan, oversubscribe, invocation)
        return
    before = epochs_recorded(plan.run.root) if plan.resuming else 0
    state = train_planned(plan, show_progress=progress, place=place)
    if not place.reports:
        return  # worker 0 reports for the job
    if resume is not None and state.epoch <= before:
        print(
            f"dtd: {resume} has already trained {state.epoch} epochs; nothing to do "
            f"(--epochs N with N > {state.epoch} trains it further)",
            file=sys.stderr,
        )
    last = state.history[-1] if state.history else {}
    print(
        json.dumps(
            {
                "epochs": state.epoch,
                "env_steps": state.env_steps,
                "eval_success": last.get("eval_success"),
                "best_eval_success": state.best_eval_success,
                "wall_s": round(state.wall_s, 1),
            }
        )
    )


def _launch_workers(plan: StartPlan, oversubscribe: bool, invocation: tuple[str, ...]) -> None:
    """Start the planned run's workers here, and report how the job ended in one line."""
    from dtd.errors import ConfigError, MachineError
    from dtd.training.components import usable_cores
    from dtd.training.launch import INTERRUPTED_EXIT, LOST_WORKER_EXIT, launch_local

    run, workers = plan.run, plan.workers
    cores = usable_cores()
    if workers > cores and not oversubscribe:
        raise ConfigError(
            f"--workers {workers} is more than the {cores} cores this process may use; "
            "--oversubscribe starts them anyway (each then runs slower)"
        )
    # The cores are shared out: each worker's torch threads (where --threads leaves it open).
    threads = max(1, cores // workers)
    try:
        ends = launch_local(invocation, workers, threads)
    except KeyboardInterrupt as interrupt:
        interrupt.run_dir = run.root  # type: ignore[attr-defined]
        raise
    first = ends[0]
    if first.returncode == 0:
        return
    how = f"continue from its last finished epoch with dtd train --resume {run.root}"
    if first.returncode == INTERRUPTED_EXIT or first.returncode == -signal.SIGINT:
        print(f"dtd: interrupted; {how}", file=sys.stderr)
        sys.exit(INTERRUPTED_EXIT)
    if first.returncode < 0 or first.returncode == LOST_WORKER_EXIT:
        raise MachineError(f"{first.describe()}; the job stopped: {how}")
    sys.exit(first.returncode)  # the worker said why


def sweep(
    config: Annotated[TrainConfig, tyro.conf.arg(name="")],
    out: Path,
    algos: str = "ddpg,her,dtd",
    seeds: int = 5,
    parallel: int = 0,
    ray: Annotated[str | None, optional("ADDRESS", "local processes")] = None,
    progress: bool = True,
    final_episodes: int = 0,
    grid: Annotated[tuple[str, ...], tyro.conf.UseAppendAction, optional("NAME=V1,V2", "none")] = (),
    invocation: tuple[str, ...] = (),
) -> None:
    """Train every (algorithm, seed) pair of one configuration, each into OUT/<env>-<algo>-s<seed>;
    with --grid, every combination of the grid's settings too, each into
    OUT/<env>-<algo>-<name>=<value>...-s<seed>.

    Run again on the same --out, finished trials are left alone and interrupted ones resume
    from their checkpoints. A failing trial is reported and does not stop the others. With
    --ray the trials are tasks of a Ray cluster: auto joins the cluster running here (or
    starts a local one for the sweep), local always starts one, anything else is a cluster's
    address (ray://host:10001); each task asks for as many CPUs as it has torch threads
    (--threads, 1 by default).

    Examples:
      dtd sweep --env FetchPush-v4 --algos ddpg,her,dtd --seeds 5 --epochs 50 --out runs/push-sweep
      dtd sweep --env FetchPush-v4 --preset paper --seeds 3 --out runs/push-sweep-paper
      dtd sweep --env FetchPush-v4 --seeds 5 --out /shared/push-sweep --ray auto
      dtd sweep --env FetchPush-v4 --seed 100 --seeds 5 --final-episodes 100 --out runs/record/push
      dtd sweep --env FetchPush-v4 --algos dtd --grid learner=ddpg,tqc --grid updates_per_cycle=40,100 --out g
      dtd plot runs/push-sweep

    Args:
        config: Settings shared by every trial (--algo is replaced by --algos; --seed is the first seed).
        out: Directory of the trials' run directories (on a cluster: a path every node reaches).
        algos: Comma-separated algorithms, each trained with every seed.
        seeds: Seeds per algorithm: --seed, --seed + 1, ...
        parallel: Local trials at once (0: one per core); they share the cores' torch threads.
        ray: Run on Ray instead: auto, local or a cluster address (needs pip install 'dtd[ray]').
        progress: Show a live progress bar.
        final_episodes: Once a trial is trained, evaluate its last checkpoint over this many
            episodes and save it (RUN/eval-latest.json, the final dtd plot --stats takes);
            0: none. Run again, a saved evaluation of the last epoch is kept.
        grid: A setting and its values to train each trial with, NAME=V1,V2 (a value read as
            JSON, else as text; a list's commas inside its brackets); given again for another
            setting, trials cover every combination. NAME as the option without dashes
            (learner, updates_per_cycle, high.learner, hidden_sizes). dtd plot labels the
            trials by the settings in which they differ.
        invocation: The command's arguments, from which the settings given are read.
    """
    from dtd.cli.options import settings_given
    from dtd.config import Algo
    from dtd.errors import ConfigError
    from dtd.experiments.run_curves import find_runs
    from dtd.experiments.summary import summaries, summary_table
    from dtd.experiments.sweep import run_sweep, sweep_trials, trials_at_once
    from dtd.training.atomic import ensure_writable

    try:
        chosen = [Algo(name.strip()) for name in algos.split(",") if name.strip()]
    except ValueError as exc:
        raise ConfigError(f"--algos: {exc}; choose from {', '.join(a.value for a in Algo)}") from exc
    trials = sweep_trials(config, chosen, seeds, out, final_episodes, grid, settings_given(invocation[1:]))
    trials_at_once(trials, parallel)  # refused before anything is written
    ensure_writable(out, "the sweep's runs")
    outcomes = run_sweep(trials, parallel=parallel, ray_address=ray, show_progress=progress)
    failed = [outcome for outcome in outcomes if not outcome.ok]
    for outcome in failed:
        print(f"{outcome.trial.name} failed:\n{outcome.error}", file=sys.stderr)
    runs = find_runs([trial.run_dir for trial in trials if trial.run_dir.is_dir()])
    if runs:
        print(summary_table(summaries(runs)))
    print(f"{len(outcomes) - len(failed)} of {len(outcomes)} trials finished in {out}")
    if failed:
        sys.exit(1)


def plot(
    run_dirs: tyro.conf.Positional[tuple[Path, ...]],
    out: Annotated[Path | None, optional("DIR", "the first RUN_DIR")] = None,
    max_env_steps: Annotated[int | None, optional("STEPS", "every epoch")] = None,
    strict: bool = False,
    stats: bool = False,
) -> None:
    """Draw success against epochs and env steps per environment, and write summary.csv.

    Every run found under RUN_DIRS (any folder with a config.json) counts; runs are grouped
    by environment and algorithm (and preset, where not the default). Lines are the mean over
    seeds, bands the 25th-75th percentile. Runs of two or more environments are also drawn
    side by side in tasks.png (the paper's layout: a panel per task, the paper's tasks first
    in its order, success against env steps). A run whose files cannot be read is left out
    with a warning naming it; the others are drawn.

    Examples:
      dtd plot runs/push-sweep
      dtd plot runs/push-sweep runs/push-sweep-paper --out docs/results/push
      dtd plot runs/pick-sweep --max-env-steps 400000 --out runs/pick-sweep/at-400k
      dtd plot runs/record --stats

    Args:
        run_dirs: Sweep or run directories to read.
        out: Where the figures (PNG and SVG per environment, and tasks) and summary.csv go.
        max_env_steps: Compare runs at this budget: each curve ends at its last epoch within it.
        strict: Exit with status 1 when a run was left out because its files cannot be read.
        stats: Also the statistics of final success over seeds (needs dtd[stats]): median,
            interquartile mean and mean with 95% stratified-bootstrap confidence intervals,
            the probability that a run beats one of her at its preset, and performance
            profiles (rliable); a figure per environment (ENV-stats.png) and columns of
            summary.csv. A run's final is its saved 100-episode evaluation (dtd eval RUN
            --episodes 100 --save) where there is one for its last epoch.
    """
    from dtd.experiments.plots import plot as draw_plots
    from dtd.experiments.run_curves import UnreadableRun

    if not run_dirs:
        raise DtdError("give at least one directory of runs")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = draw_plots(run_dirs, out if out is not None else run_dirs[0], max_env_steps, stats)
    for warning in caught:
        print(f"warning: {warning.message}", file=sys.stderr)
    print(result.table)
    for path in [*result.figures, result.summary_csv]:
        print(f"wrote {path}")
    if strict and any(issubclass(warning.category, UnreadableRun) for warning in caught):
        sys.exit(1)
