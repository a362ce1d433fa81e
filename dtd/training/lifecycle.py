"""A run's life: start it, resume it after its last finished epoch, train it to an epoch or an
env-step budget."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import shutil
from collections.abc import Collection
from pathlib import Path
from typing import Any

from dtd.config import (
    Preset,
    TrainConfig,
    flat_items,
    preset_config,
    required_env,
    settings_apart,
    with_algorithm_defaults,
)
from dtd.config.settings import DOT_TO_DOT_FIELDS
from dtd.envs.make import env_kwargs
from dtd.envs.spec import EnvSpec
from dtd.errors import CheckpointError, ConfigError, RunDirError, WorkerLost
from dtd.training.atomic import remove_stale_temporaries
from dtd.training.checkpoint import Checkpoint, TrainState, restoring
from dtd.training.collector import ProcessCollector
from dtd.training.components import (
    Components,
    build,
    make_task_envs,
    resolved_device,
    resolved_precision,
    resolved_threads,
)
from dtd.training.launch import JobPlace
from dtd.training.progress import TrainingProgress
from dtd.training.recorder import MetricsRecorder
from dtd.training.run_dir import RunDir, read_config, write_config
from dtd.training.run_lock import holding
from dtd.training.trainer import Trainer, restore
from dtd.training.workers import WorkerGroup, join_group, leave_group

# Settings that may change when a run is resumed; any other must stay as the run began.
RESUMABLE_SETTINGS = frozenset({"epochs", "threads", "collector", "explore_snapshots", "device", "precision"})
_RESUMABLE_FLAGS = ", ".join("--" + name.replace("_", "-") for name in sorted(RESUMABLE_SETTINGS))
DOT_TO_DOT_SETTINGS = frozenset(DOT_TO_DOT_FIELDS)
"""Dot-to-Dot's settings (the high level's as ``high.<name>``), which only ``--algo dtd`` uses."""


def default_run_dir(config: TrainConfig) -> Path:
    """runs/<env>-<algo>-s<seed>."""
    env = (config.env or "env").split(":")[-1]
    return Path("runs") / f"{env}-{config.algo.value}-s{config.seed}"


def resumed_config(
    stored: TrainConfig, given: TrainConfig, named: Collection[str] | None = None
) -> TrainConfig:
    """The stored configuration, with the settings the user gave.

    ``named`` lists the settings given, by their names in :func:`flat_items` (the command line
    knows them from the options typed); None takes those of ``given`` that differ from its
    preset's defaults (``given`` built in Python, e.g. ``TrainConfig(epochs=80)``). A setting
    given at the run's own value (or, for the batch and n-step a run left to its algorithm, at
    what the algorithm chose) is accepted; another value only for RESUMABLE_SETTINGS, anything
    else is a :class:`ConfigError`.
    """
    given_flat = flat_items(given)
    if named is None:
        named = apart_from_defaults(given)
    stored_flat, chosen = flat_items(stored), flat_items(with_algorithm_defaults(stored))
    changes: dict[str, Any] = {}
    for name in sorted(named):
        value = given_flat[name]
        if _same_setting(name, value, stored_flat[name]) or _same_setting(name, value, chosen[name]):
            continue
        if name not in RESUMABLE_SETTINGS:
            raise ConfigError(
                f"--{name.replace('_', '-')} cannot change when resuming "
                f"(the run has {chosen[name]!r}); only {_RESUMABLE_FLAGS} can"
            )
        changes[name] = value
    # Typed as config.json is read (the flat values are plain: an enum's is its text).
    return TrainConfig.from_dict({**stored.to_dict(), **changes})


def apart_from_defaults(config: TrainConfig) -> set[str]:
    """The settings of ``config`` (by their names in :func:`flat_items`) that differ from its
    preset's defaults, and the preset where it is not the default one: what a configuration
    built in Python is taken to give."""
    named = settings_apart(config, preset_config(config.preset))
    return named | ({"preset"} if config.preset is not Preset.tuned else set())


def _same_setting(name: str, given: Any, stored: Any) -> bool:
    """Whether a setting given is the one stored: the environment's arguments as the values they
    are read as (in any order, ``False`` as ``false``), the others as they are."""
    if name == "env_kwargs":
        return env_kwargs(given) == env_kwargs(stored)
    return given == stored


def settings_out_of_place(config: TrainConfig, named: Collection[str]) -> list[str]:
    """The options among ``named`` (settings as :func:`flat_items` names them) that ``config``'s
    algorithm has no use for: Dot-to-Dot's, given to another algorithm."""
    if config.algo.sets_subgoals:
        return []
    unused = [name for name in sorted(named) if name.split(".")[0] in DOT_TO_DOT_SETTINGS]
    return ["--" + name.replace("_", "-") for name in unused]


@dataclasses.dataclass(frozen=True)
class StartPlan:
    """What :func:`train` starts or resumes, resolved once before anything is built."""

    config: TrainConfig
    """The settings, as the run records them and training uses them: as given for a new run
    (its thread count, precision and workers made concrete), a resumed run's own with the
    changes it allows."""
    run: RunDir
    resuming: bool
    force: bool = False
    """Replace a run already in ``run``."""

    @property
    def workers(self) -> int:
        return self.config.workers or 1

    def derived(self, spec: EnvSpec) -> dict[str, Any]:
        """What follows from the settings and the task, as config.json records it beside them:
        among them what the algorithm chose where a setting was left to it."""
        return {
            "spec": dataclasses.asdict(spec),
            "batch_size": self.config.low_learner.batch_size,
            "n_step": self.config.low_n_step,
        }


def plan_start(
    config: TrainConfig,
    run_dir: Path | str | None = None,
    resume: Path | str | None = None,
    force: bool = False,
    place: JobPlace = JobPlace(),
    given: Collection[str] | None = None,
) -> StartPlan:
    """What :func:`train` would start or resume, checked before anything is built: the
    settings (a resumed run's read from its directory once) and the run directory; a
    :class:`ConfigError` or :class:`RunDirError` where it cannot. ``given`` names the settings
    the user gave (:func:`resumed_config`); a new run refuses Dot-to-Dot's among them for
    another algorithm."""
    if resume is not None:
        if run_dir is not None and Path(run_dir).resolve() != Path(resume).resolve():
            raise ConfigError("give the run directory once: --resume DIR (without --run-dir)")
        run = RunDir(Path(resume))
        # A missing or unreadable run is refused here.
        resumed = _chosen_precision(resumed_config(read_config(run), config, given))
        return StartPlan(resumed, run, resuming=True)
    required_env(config.env)
    unused = settings_out_of_place(config, given or ())
    if unused:
        raise ConfigError(
            f"{', '.join(unused)}: Dot-to-Dot's settings, which --algo {config.algo.value} does not use; "
            "leave them out or train --algo dtd"
        )
    # The thread count and precision are part of what makes a run repeatable: the run records
    # them. Under torchrun the workers are the job's size.
    config = dataclasses.replace(
        _chosen_precision(config),
        threads=resolved_threads(config.threads),
        workers=config.workers or place.workers or 1,
    )
    run = RunDir(Path(run_dir) if run_dir is not None else default_run_dir(config))
    if run.holds_run() and not force:
        raise RunDirError(
            f"{run.root} already holds a run; continue it with --resume {run.root} or replace it with --force"
        )
    return StartPlan(config, run, resuming=False, force=force)


def _chosen_precision(config: TrainConfig) -> TrainConfig:
    """``config`` with the precision ``auto`` chooses on this machine made concrete: a run keeps
    the number format it began with wherever it resumes."""
    return dataclasses.replace(config, precision=resolved_precision(config, resolved_device(config.device)))


def train(
    config: TrainConfig,
    run_dir: Path | str | None = None,
    resume: Path | str | None = None,
    force: bool = False,
    show_progress: bool = True,
    place: JobPlace = JobPlace(),
    given: Collection[str] | None = None,
) -> TrainState:
    """Start a run in ``run_dir`` (default: runs/<env>-<algo>-s<seed>) or, with ``resume``,
    continue the run in that directory after its last finished epoch; train it to
    ``config.epochs`` and return its counters and metrics history. ``given`` names the
    settings of ``config`` the caller gives (:func:`plan_start`).

    The run directory is held by this process while it trains (a second trainer is refused,
    :mod:`dtd.training.run_lock`); that it can be written is known before anything is built.
    In a job of data-parallel workers (started by torchrun or ``dtd train --workers N``), this
    process is the one at ``place`` (:meth:`JobPlace.from_environment`).
    """
    return train_planned(plan_start(config, run_dir, resume, force, place, given), show_progress, place)


def train_planned(plan: StartPlan, show_progress: bool = True, place: JobPlace = JobPlace()) -> TrainState:
    """Carry out ``plan`` (:func:`plan_start`) as the process at ``place``: hold and open the run
    directory, build the run (restored from a stopped run's last checkpoint), train it."""
    if not place.in_job and plan.workers > 1:
        raise ConfigError(
            f"a run of {plan.workers} workers is started by dtd train --workers {plan.workers} or by torchrun"
        )
    group = join_group(plan.workers, place) if place.in_job else WorkerGroup()
    run, config = plan.run, plan.config
    try:
        # Every worker has looked at the run directory before any of them writes to it.
        group.barrier()
        starting = group.writes and not plan.resuming
        with (
            holding(run.root) if group.writes else contextlib.nullcontext(),
            run.starting(replace=plan.force) if starting else contextlib.nullcontext(),
        ):
            latest = _latest_checkpoint(plan, group) if plan.resuming else None
            state = TrainState()
            if latest is not None:
                with restoring(run.latest):
                    state = latest.train_state()
            # A run trained to its end already is left as it is: nothing is built or written.
            if state.epoch < config.epochs:
                components = build(
                    config,
                    worker=group.rank,
                    collective=group.collective,
                    local_workers=place.local_workers,
                )
                if latest is not None:
                    state = _restored(latest, plan, components, state, group)
                state = _train_built(plan, components, state, show_progress, group)
            group.barrier()  # every worker is done before any leaves the group
            return state
    except (KeyboardInterrupt, WorkerLost) as stop:
        stop.run_dir = run.root  # type: ignore[union-attr]  # how to continue, for the CLI
        raise
    finally:
        if group.workers > 1:
            leave_group()


def _latest_checkpoint(plan: StartPlan, group: WorkerGroup) -> Checkpoint | None:
    """A stopped run's last checkpoint, after the leftovers of the process that stopped are
    cleared; None for a run killed during its first epoch (it starts again)."""
    run = plan.run
    if group.writes:
        remove_stale_temporaries(run.root)  # half-written files of the process that was killed
        # A run set aside by a forced start that was killed before its first epoch: resuming
        # the new run gives it up.
        shutil.rmtree(run.set_aside, ignore_errors=True)
    return Checkpoint.read(run.latest) if run.latest.exists() else None


def _restored(
    latest: Checkpoint, plan: StartPlan, components: Components, trained: TrainState, group: WorkerGroup
) -> TrainState:
    """The counters of a stopped run, its agent, random state, collector and environments put
    back as ``latest`` holds them (a data-parallel worker k > 0: from its shard of that epoch)."""
    run = plan.run
    path = run.latest if group.writes else run.worker_shard(group.rank, trained.epoch)
    try:
        checkpoint = latest if group.writes else Checkpoint.read(path)
        checkpoint.check_fits(plan.config, components.spec, path)
        parts = (components.agent, components.rng, components.collector, components.envs)
        return restore(checkpoint, *parts, path)
    except CheckpointError:
        components.close()
        raise


def _train_built(
    plan: StartPlan,
    components: Components,
    state: TrainState,
    show_progress: bool,
    group: WorkerGroup = WorkerGroup(),
) -> TrainState:
    """Record the configuration, then train from ``state`` to ``config.epochs`` (worker 0 of
    data-parallel workers records and shows progress; the others only train)."""
    run, config = plan.run, plan.config
    recorder = None
    if group.writes:
        write_config(run, plan.config, plan.derived(components.spec))
        # TensorBoard events past the checkpoint came from an epoch that did not finish.
        recorder = MetricsRecorder(run, resume_step=state.env_steps + 1 if state.epoch else 0)
    total_steps = (
        config.epochs * config.n_cycles * config.episodes_per_cycle * components.spec.horizon * group.workers
    )
    try:
        with TrainingProgress(total_steps, config.epochs, enabled=show_progress and group.writes) as progress:
            trainer = Trainer(
                config,
                components.spec,
                components.agent,
                components.collector,
                components.envs,
                components.rng,
                run,
                recorder,
                progress,
                group,
            )
            # metrics.csv is rebuilt from the checkpoint: rows of an unfinished epoch vanish.
            if recorder is not None:
                recorder.write_csv(state.history)
            progress.start_at(state.env_steps)
            progress.note(
                f"updates in {config.precision.value} on {resolved_device(config.device)}, "
                f"{resolved_threads(config.threads)} torch thread(s), collecting {_collecting(components)}"
            )
            return trainer.train(state)
    finally:
        if recorder is not None:
            recorder.close()
        components.close()


def _collecting(components: Components) -> str:
    return "in a process" if isinstance(components.collector, ProcessCollector) else "inline"


def train_to_end(
    config: TrainConfig, run_dir: Path | str, given: Collection[str] | None = None
) -> TrainState:
    """Bring the run in ``run_dir`` to ``config.epochs``: start it, resume it from its last
    checkpoint, or leave it as it is when it has already trained that far. Resumed, the run
    takes the settings ``given`` names (None: those of ``config`` apart from its preset's
    defaults, :func:`resumed_config`) and ``config.epochs`` however it was given."""
    run = RunDir(Path(run_dir))
    if run.config.exists():
        recorded = epochs_recorded(run.root)
        if recorded >= config.epochs:
            return TrainState(epoch=recorded)  # nothing left to train
        named = {*(apart_from_defaults(config) if given is None else given), "epochs"}
        return train(config, resume=run.root, show_progress=False, given=named)
    return train(config, run_dir=run.root, show_progress=False)


def train_for_steps(config: TrainConfig, steps: int, run_dir: Path | str) -> TrainState:
    """Train until at least ``steps`` env steps, resuming a run already in ``run_dir``."""
    return train_to_end(dataclasses.replace(config, epochs=epochs_for_steps(config, steps)), run_dir)


def epochs_for_steps(config: TrainConfig, steps: int) -> int:
    """Whole epochs of ``config`` that hold at least ``steps`` env steps."""
    horizon = env_spec_of(config).horizon
    return math.ceil(steps / (config.n_cycles * config.episodes_per_cycle * horizon))


def epochs_recorded(run_dir: Path) -> int:
    """Epochs the run in ``run_dir`` has finished: the rows of its metrics.csv (0 if none)."""
    metrics = RunDir(Path(run_dir)).metrics
    if not metrics.exists():
        return 0
    with open(metrics) as file:
        return max(0, sum(1 for line in file if line.strip()) - 1)


def env_spec_of(config: TrainConfig) -> EnvSpec:
    """The spec of ``config.env``, from a throw-away instance."""
    envs, spec = make_task_envs(config, 1)
    envs[0].close()
    return spec
