"""Runs as a user sees them: start, resume and evaluate, with every piece built in one place."""

from __future__ import annotations

import dataclasses
import functools
import math
import os
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from dtd.agent import Agent, GoalConditionedAgent
from dtd.atomic import remove_stale_temporaries
from dtd.buffer import EpisodeBuffer
from dtd.checkpoint import FORMAT_VERSION, load_checkpoint, restoring
from dtd.collector import Collector, InlineCollector, ProcessCollector
from dtd.config import (
    Algo,
    Collection,
    Preset,
    RelabelWindow,
    TrainConfig,
    flat_items,
    preset_config,
    with_algorithm_batch,
)
from dtd.ddpg import DDPGLearner
from dtd.envs import EnvSpec, make_envs, reward_function
from dtd.errors import CheckpointError, ConfigError, RunDirError
from dtd.exploration import ActionNoise
from dtd.her import GoalStrategy, relabel_probability
from dtd.hierarchy import DotToDotAgent, HandOverSchedule, SubgoalExploration
from dtd.networks import BoxActionHead, SubgoalHead
from dtd.progress import TrainingProgress
from dtd.recorder import MetricsRecorder
from dtd.rollout import episode_figures, run_many
from dtd.run_dir import RunDir, read_config, write_config
from dtd.segments import segment_bounds, segment_window_end
from dtd.trainer import Trainer, TrainState, restore

# Settings that may change when a run is resumed; any other must stay as the run began.
RESUMABLE_SETTINGS = frozenset({"epochs", "threads", "collector"})
_RESUMABLE_FLAGS = ", ".join("--" + name for name in sorted(RESUMABLE_SETTINGS))


@dataclasses.dataclass
class Components:
    """Everything a run is made of, built from its configuration."""

    spec: EnvSpec
    agent: Agent
    collector: Collector
    """Exploring episodes of the training environments."""
    eval_envs: list[gym.Env]
    rng: np.random.Generator
    """Replay sampling (and anything else the learner draws)."""


def build_agent(config: TrainConfig, spec: EnvSpec, env: gym.Env) -> Agent:
    """The agent ``config.algo`` names, with fresh networks and an empty replay."""
    config = with_algorithm_batch(config)
    gamma = config.learner.gamma if config.learner.gamma is not None else spec.default_gamma()
    low = DDPGLearner(
        spec.obs_dim, spec.goal_dim, spec.action_dim, BoxActionHead(spec.action_max), config.learner, gamma
    )
    buffer = EpisodeBuffer.for_transitions(
        config.buffer_size, spec.horizon, spec.obs_dim, spec.goal_dim, spec.action_dim
    )
    noise = ActionNoise(config.noise_eps, config.random_eps, spec.action_max)
    reward_fn = reward_function(env)
    if config.algo is not Algo.dtd:
        strategy = GoalStrategy.future if config.algo is Algo.her else GoalStrategy.none
        return GoalConditionedAgent(
            low, buffer, reward_fn, noise, strategy, config.replay_k, config.past_goal_share
        )

    if config.segments > spec.horizon:
        raise ConfigError(f"--segments must be at most the horizon ({spec.horizon}), got {config.segments}")
    bounds = segment_bounds(spec.horizon, config.segments)
    # By default the high level discounts a segment as the low level discounts its steps.
    high_gamma = (
        config.high.gamma if config.high.gamma is not None else gamma ** (spec.horizon / config.segments)
    )
    head = SubgoalHead(config.subgoal_max_distance, spec.goal_low, spec.goal_high, spec.quaternion)
    high = DDPGLearner(
        spec.obs_dim + spec.goal_dim, spec.goal_dim, spec.goal_dim, head, config.high, high_gamma
    )
    schedule = HandOverSchedule(
        config.subgoal_eps_start,
        config.subgoal_eps_floor,
        config.subgoal_eps_decay_epochs,
        config.n_cycles * config.episodes_per_cycle,
    )
    window = segment_window_end(bounds) if config.low_relabel_window is RelabelWindow.segment else None
    return DotToDotAgent(
        low=low,
        high=high,
        buffer=buffer,
        reward_fn=reward_fn,
        bounds=bounds,
        action_noise=noise,
        exploration=SubgoalExploration(schedule, config.subgoal_sigma, config.subgoal_noise),
        low_relabel_prob=relabel_probability(GoalStrategy.future, config.replay_k),
        low_window_end=window,
        low_past_share=config.past_goal_share,
        high_relabel_prob=relabel_probability(GoalStrategy.future, config.high_replay_k),
        hindsight_action_prob=config.hindsight_action_prob,
        high_updates=config.high_updates_per_cycle,
    )


def build(
    config: TrainConfig,
    eval_seed: int | None = None,
    eval_envs: int | None = None,
    collection: Collection | None = None,
) -> Components:
    """Environments, agent, collector and random generators for ``config``, all seeded from
    ``config.seed``.

    ``eval_seed`` seeds the evaluation environments apart from training (``dtd eval``);
    ``collection`` overrides ``config.collector``.
    """
    config.validate()
    assert config.env is not None
    collection = collection or config.collector
    torch.set_num_threads(resolved_threads(config.threads, collection))
    torch.manual_seed(config.seed)
    train_seq, eval_seq, rng_seq, explore_seq = np.random.SeedSequence(config.seed).spawn(4)
    if eval_seed is not None:
        eval_seq = np.random.SeedSequence([eval_seed, 1])
    n_eval = eval_envs or min(config.test_episodes, config.episodes_per_cycle)
    evaluation, spec = seeded_envs(config.env, n_eval, eval_seq)
    if config.buffer_size < spec.horizon:
        close_envs(evaluation)
        raise ConfigError(
            f"--buffer-size must hold one episode ({spec.horizon} steps), got {config.buffer_size}"
        )
    agent = build_agent(config, spec, evaluation[0])
    exploring_side = functools.partial(_exploring_side, config, train_seq, explore_seq)
    try:
        if resolved_collection(collection) is Collection.process:
            collector: Collector = ProcessCollector(exploring_side, agent)
        else:
            train, _, _, explore_rng = exploring_side(agent)
            collector = InlineCollector(train, agent, spec, explore_rng)
    except BaseException:
        close_envs(evaluation)
        raise
    return Components(spec, agent, collector, evaluation, np.random.default_rng(rng_seq))


MAX_AUTO_THREADS = 4
"""Most torch threads chosen automatically: updates of batch 256 gain little beyond."""


def resolved_collection(collection: Collection) -> Collection:
    """``auto`` made concrete: a collecting process when this process may use three cores or
    more. On two cores a second torch thread for the learner gains more (FetchPush, her:
    3.21 s per 1k env steps inline with 2 threads, 3.60 with a collecting process and 1)."""
    if collection is not Collection.auto:
        return collection
    return Collection.process if usable_cores() >= 3 else Collection.inline


def resolved_threads(threads: int, collection: Collection) -> int:
    """``threads``, or for 0 the usable cores less one for a collecting process, at most
    :data:`MAX_AUTO_THREADS`."""
    if threads > 0:
        return threads
    spare = 1 if resolved_collection(collection) is Collection.process else 0
    return max(1, min(usable_cores() - spare, MAX_AUTO_THREADS))


def usable_cores() -> int:
    """Cores this process may run on (all of the machine's where that cannot be asked)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def seeded_envs(env_id: str, count: int, seeds: np.random.SeedSequence) -> tuple[list[gym.Env], EnvSpec]:
    """``count`` environments of ``env_id``, each reset once with its own seed from ``seeds``."""
    envs, spec = make_envs(env_id, count)
    for env, seed in zip(envs, seeds.generate_state(count), strict=True):
        env.reset(seed=int(seed))
    return envs, spec


def _exploring_side(
    config: TrainConfig,
    train_seq: np.random.SeedSequence,
    explore_seq: np.random.SeedSequence,
    agent: Agent | None = None,
) -> tuple[list[gym.Env], Agent, EnvSpec, np.random.Generator]:
    """The training environments and exploration generator; with no ``agent``, also a copy
    that only acts (in a collecting process: it holds no replay)."""
    assert config.env is not None
    train, spec = seeded_envs(config.env, config.episodes_per_cycle, train_seq)
    if agent is None:
        agent = build_agent(dataclasses.replace(config, buffer_size=spec.horizon), spec, train[0])
    return train, agent, spec, np.random.default_rng(explore_seq)


def default_run_dir(config: TrainConfig) -> Path:
    """runs/<env>-<algo>-s<seed>."""
    env = (config.env or "env").split(":")[-1]
    return Path("runs") / f"{env}-{config.algo.value}-s{config.seed}"


def check_checkpoint(snapshot: dict[str, Any], config: TrainConfig, spec: EnvSpec, path: Path) -> None:
    """Refuse a checkpoint written for another environment or agent."""
    if snapshot.get("env_id") != config.env or snapshot.get("algo") != config.algo.value:
        raise CheckpointError(
            f"checkpoint {path} belongs to a {snapshot.get('algo')} run on {snapshot.get('env_id')}, "
            f"not to this {config.algo.value} run on {config.env}"
        )
    dims = ("obs_dim", "goal_dim", "action_dim", "horizon")
    stored = snapshot.get("spec") or {}
    if any(stored.get(name) != getattr(spec, name) for name in dims):
        raise CheckpointError(f"checkpoint {path} was written for an environment of other dimensions")


def resumed_config(stored: TrainConfig, given: TrainConfig) -> TrainConfig:
    """The stored configuration, with the settings the user changed on the command line.

    A setting counts as given when it differs from the default of the preset given; only
    RESUMABLE_SETTINGS may differ from the stored run.
    """
    if given.preset is not Preset.tuned and given.preset is not stored.preset:
        raise ConfigError(
            f"--preset cannot change when resuming (the run has {stored.preset.value!r}); "
            f"only {_RESUMABLE_FLAGS} can"
        )
    defaults = flat_items(preset_config(given.preset))
    stored_flat, given_flat = flat_items(stored), flat_items(given)
    changes: dict[str, Any] = {}
    for name, value in given_flat.items():
        if value == defaults[name] or value == stored_flat[name]:
            continue
        if name not in RESUMABLE_SETTINGS:
            raise ConfigError(
                f"--{name.replace('_', '-')} cannot change when resuming "
                f"(the run has {stored_flat[name]!r}); only {_RESUMABLE_FLAGS} can"
            )
        changes[name] = value
    return dataclasses.replace(stored, **changes)


def train(
    config: TrainConfig,
    run_dir: Path | None = None,
    resume: Path | None = None,
    force: bool = False,
    show_progress: bool = True,
) -> TrainState:
    """Start a run (or, with ``resume``, continue one) and train it to the end."""
    if resume is not None:
        run = RunDir(resume)
        if run_dir is not None and Path(run_dir).resolve() != run.root.resolve():
            raise ConfigError("give the run directory once: --resume DIR (without --run-dir)")
        config = resumed_config(read_config(run), config)
        config.validate()
        remove_stale_temporaries(run.root)  # half-written files of the process that was killed
        # A run killed during its first epoch has no checkpoint yet: it starts again.
        snapshot = load_checkpoint(run.latest) if run.latest.exists() else None
        components = build(config)
        state = TrainState()
        if snapshot is not None:
            try:
                check_checkpoint(snapshot, config, components.spec, run.latest)
                if snapshot["format_version"] != FORMAT_VERSION:
                    raise CheckpointError(
                        f"checkpoint {run.latest} was written by an older dtd (format "
                        f"{snapshot['format_version']}); it can be evaluated but not resumed"
                    )
                state = restore(
                    snapshot,
                    components.agent,
                    components.rng,
                    components.collector,
                    components.eval_envs,
                    run.latest,
                )
            except CheckpointError:
                close_all(components)
                raise
    else:
        config.validate()
        # The thread count is part of what makes a run repeatable: the run records it, and the
        # batch its algorithm chose.
        config = dataclasses.replace(config, threads=resolved_threads(config.threads, config.collector))
        config = with_algorithm_batch(config)
        run = RunDir(Path(run_dir) if run_dir is not None else default_run_dir(config))
        if run.holds_run() and not force:
            raise RunDirError(
                f"{run.root} already holds a run; continue it with --resume {run.root} "
                "or replace it with --force"
            )
        components = build(config)
        state = TrainState()
        if force:
            run.clear()

    write_config(run, config, {"spec": dataclasses.asdict(components.spec)})
    # TensorBoard events past the checkpoint came from an epoch that did not finish.
    recorder = MetricsRecorder(run, resume_step=state.env_steps + 1 if state.epoch else 0)
    total_steps = config.epochs * config.n_cycles * config.episodes_per_cycle * components.spec.horizon
    try:
        with TrainingProgress(total_steps, config.epochs, enabled=show_progress) as progress:
            trainer = Trainer(
                config,
                components.spec,
                components.agent,
                components.collector,
                components.eval_envs,
                components.rng,
                run,
                recorder,
                progress,
            )
            # metrics.csv is rebuilt from the checkpoint: rows of an unfinished epoch vanish.
            recorder.write_csv(state.history)
            progress.start_at(state.env_steps)
            return trainer.train(state)
    finally:
        recorder.close()
        close_all(components)


def train_to_end(config: TrainConfig, run_dir: Path) -> TrainState:
    """Bring the run in ``run_dir`` to ``config.epochs``: start it, resume it from its last
    checkpoint, or leave it as it is when it has already trained that far."""
    run = RunDir(Path(run_dir))
    if run.config.exists():
        recorded = epochs_recorded(run.root)
        if recorded >= config.epochs:
            return TrainState(epoch=recorded)  # nothing left to train
        return train(config, resume=run.root, show_progress=False)
    return train(config, run_dir=run.root, show_progress=False)


def train_for_steps(config: TrainConfig, steps: int, run_dir: Path) -> TrainState:
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
    assert config.env is not None
    envs, spec = make_envs(config.env, 1)
    envs[0].close()
    return spec


@dataclasses.dataclass
class LoadedRun:
    """A trained run brought back: its settings, checkpoint and rebuilt components."""

    run: RunDir
    config: TrainConfig
    checkpoint: Path
    snapshot: dict[str, Any]
    components: Components


def load_run(run_dir: Path, checkpoint: str = "latest", seed: int = 1_000_003, envs: int = 1) -> LoadedRun:
    """Rebuild a run's agent from a checkpoint, with ``envs`` evaluation environments seeded
    by ``seed``; raises :class:`DtdError` subclasses for missing or foreign files."""
    run = RunDir(Path(run_dir))
    config = read_config(run)
    path = run.checkpoint(checkpoint)
    snapshot = load_checkpoint(path)
    components = build(config, eval_seed=seed, eval_envs=envs, collection=Collection.inline)
    try:
        check_checkpoint(snapshot, config, components.spec, path)
        with restoring(path):
            components.agent.load_state_dict({k: v for k, v in snapshot["agent"].items() if k != "buffer"})
    except BaseException:
        close_all(components)
        raise
    return LoadedRun(run, config, path, snapshot, components)


def load_agent(run_dir: Path | str, checkpoint: str = "latest") -> tuple[Agent, gym.Env]:
    """A trained agent and an environment of its task, e.g. to query ``subgoal_values``."""
    loaded = load_run(Path(run_dir), checkpoint)
    loaded.components.collector.close()
    return loaded.components.agent, loaded.components.eval_envs[0]


def evaluate_run(
    run_dir: Path, episodes: int, checkpoint: str, seed: int, show_subgoals: bool = False
) -> dict[str, Any]:
    """Deterministic episodes of a trained agent; the figures as a dict (with ``plans``, the
    high level's sub-goals per episode, when ``show_subgoals``)."""
    if episodes < 1:
        raise ConfigError(f"--episodes must be at least 1, got {episodes}")
    config = read_config(RunDir(Path(run_dir)))
    if show_subgoals and config.algo is not Algo.dtd:
        raise ConfigError(f"--show-subgoals needs a dtd run; {run_dir} is a {config.algo.value} run")
    loaded = load_run(run_dir, checkpoint, seed, envs=min(episodes, 10))
    components = loaded.components
    try:
        played = run_many(
            components.eval_envs,
            components.agent,
            components.spec,
            episodes,
            explore=False,
            rng=components.rng,
        )
    finally:
        close_all(components)
    figures = episode_figures(components.agent, played)
    result: dict[str, Any] = {
        "run_dir": str(loaded.run.root),
        "checkpoint": str(loaded.checkpoint),
        "env": config.env,
        "algo": config.algo.value,
        "epoch": loaded.snapshot["state"]["epoch"],
        "env_steps": loaded.snapshot["state"]["env_steps"],
        "episodes": episodes,
        "seed": seed,
        "success_rate": figures.pop("success"),
        "mean_final_distance": figures.pop("final_distance"),
        **figures,
    }
    if show_subgoals:
        assert isinstance(components.agent, DotToDotAgent)
        result["plans"] = components.agent.plan(played)
    return result


def close_all(components: Components) -> None:
    """Close every environment (and the collecting process) of ``components``."""
    components.collector.close()
    close_envs(components.eval_envs)


def close_envs(envs: list[gym.Env]) -> None:
    """Close each of ``envs``."""
    for env in envs:
        env.close()
