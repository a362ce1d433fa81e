"""A run's parts built in one place from its configuration: environments seeded apart, the agent
its algorithm names, the collector of exploring episodes, and the thread count for the machine."""

from __future__ import annotations

import dataclasses
import functools
import os
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

from dtd.agents.buffer import EpisodeBuffer
from dtd.agents.collective import ALONE, Collective
from dtd.agents.dot_to_dot import DotToDotAgent
from dtd.agents.exploration import ActionNoise
from dtd.agents.flat import GoalConditionedAgent
from dtd.agents.her import GoalStrategy, HindsightSampling, relabel_probability
from dtd.agents.interface import Agent
from dtd.agents.learners import make_learner
from dtd.agents.networks import BoxActionHead, SubgoalHead
from dtd.config import (
    Algo,
    Collection,
    Device,
    HighTarget,
    LearnerKind,
    Precision,
    TrainConfig,
)
from dtd.envs.make import env_kwargs, make_envs
from dtd.envs.spec import EnvSpec, goal_functions
from dtd.errors import ConfigError
from dtd.training.collector import Collector, InlineCollector, ProcessCollector


def build_agent(config: TrainConfig, spec: EnvSpec, env: gym.Env, collective: Collective = ALONE) -> Agent:
    """The agent ``config.algo`` names, with fresh networks and an empty replay; its learners
    combine their updates with fellow workers through ``collective``."""
    learner = config.low_learner
    gamma = learner.gamma if learner.gamma is not None else spec.default_gamma()
    device = resolved_device(config.device)
    # A run records the precision it chose; ``auto`` here is a configuration never planned as a run.
    precision = UPDATE_DTYPES[resolved_precision(config, device)]
    low = make_learner(
        spec.obs_dim,
        spec.goal_dim,
        spec.action_dim,
        BoxActionHead(spec.action_max),
        learner,
        gamma,
        spec.sparse_rewards,
        collective,
        device,
        precision,
    )
    buffer = EpisodeBuffer.for_transitions(
        config.buffer_size, spec.horizon, spec.obs_dim, spec.goal_dim, spec.action_dim
    )
    # A stochastic policy explores by its own samples; random actions still replace some.
    noise_eps = 0.0 if low.stochastic else config.noise_eps
    noise = ActionNoise(noise_eps, config.random_eps, spec.action_max)
    goals = goal_functions(env, spec)
    # DDPG trains on the goals its episodes had; HER and dtd's low level relabel them.
    strategy = GoalStrategy.none if config.algo is Algo.ddpg else GoalStrategy.future
    sampling = HindsightSampling(
        relabel_probability(strategy, config.replay_k),
        goals.reward,
        low.gamma,
        goals.terminal,
        config.low_n_step,
        config.past_goal_share,
    )
    if config.algo is not Algo.dtd:
        return GoalConditionedAgent(low, buffer, goals, noise, sampling)

    settings = config.dtd
    if settings.segments > spec.horizon:
        raise ConfigError(f"--segments must be at most the horizon ({spec.horizon}), got {settings.segments}")
    # By default the high level discounts a segment as the low level discounts its steps.
    high_gamma = (
        settings.high.gamma
        if settings.high.gamma is not None
        else gamma ** (spec.horizon / settings.segments)
    )
    if settings.high_target is HighTarget.observed and not high_gamma < 1.0:
        raise ConfigError(f"--high-target observed needs a high-level discount below 1, got {high_gamma}")
    if settings.high_target is HighTarget.observed and spec.ends_on_goal:
        raise ConfigError(
            f"--high-target observed holds an episode's final reward for ever, and {spec.env_id} ends "
            "its episodes on reaching the goal; use --high-target bootstrap"
        )
    head = SubgoalHead(settings.subgoal_max_distance, spec.goal_low, spec.goal_high, spec.quaternion)
    high = make_learner(
        spec.obs_dim + spec.goal_dim,
        spec.goal_dim,
        spec.goal_dim,
        head,
        settings.high,
        high_gamma,
        spec.sparse_rewards,
        collective,
        device,
        precision,
    )
    return DotToDotAgent(
        low=low,
        high=high,
        buffer=buffer,
        goals=goals,
        horizon=spec.horizon,
        action_noise=noise,
        low_sampling=sampling,
        settings=settings,
        episodes_per_epoch=config.n_cycles * config.episodes_per_cycle,
    )


@dataclasses.dataclass
class Acting:
    """An agent on seeded evaluation environments of its task, with no training environments
    and no collector: what evaluating, rendering, explaining and exporting a run need."""

    spec: EnvSpec
    agent: Agent
    envs: list[gym.Env]
    rng: np.random.Generator
    """Replay sampling (and anything else the learner draws)."""

    def close(self) -> None:
        close_envs(self.envs)


@dataclasses.dataclass
class Components(Acting):
    """Everything a run is made of, built from its configuration: the agent on its evaluation
    environments, and the collector of its exploring episodes."""

    collector: Collector
    """Exploring episodes of the training environments."""

    def close(self) -> None:
        """Close every environment (and the collecting process)."""
        self.collector.close()
        super().close()


def build_acting(
    config: TrainConfig,
    eval_seed: int | None = None,
    eval_envs: int | None = None,
    worker: int = 0,
    collective: Collective = ALONE,
) -> Acting:
    """The agent ``config`` describes (fresh networks, empty replay) on its evaluation
    environments, all seeded from ``config.seed`` as :func:`build` seeds them; ``eval_seed``
    seeds the environments apart from training (``dtd eval``); the task-dependent bounds
    (a replay of one episode at least, segments within the horizon) are checked here."""
    torch.set_num_threads(resolved_threads(config.threads))
    torch.manual_seed(config.seed)
    seeds = _run_seeds(config, worker)
    eval_seq = np.random.SeedSequence([eval_seed, 1]) if eval_seed is not None else seeds.evaluation
    n_eval = eval_envs or min(config.test_episodes, config.episodes_per_cycle)
    evaluation, spec = seeded_envs(config, n_eval, eval_seq)
    if config.buffer_size < spec.horizon:
        close_envs(evaluation)
        raise ConfigError(
            f"--buffer-size must hold one episode ({spec.horizon} steps), got {config.buffer_size}"
        )
    try:
        agent = build_agent(config, spec, evaluation[0], collective)
    except BaseException:
        close_envs(evaluation)
        raise
    return Acting(spec, agent, evaluation, np.random.default_rng(seeds.replay))


def build(
    config: TrainConfig,
    collection: Collection | None = None,
    worker: int = 0,
    collective: Collective = ALONE,
    local_workers: int = 1,
) -> Components:
    """Environments, agent, collector and random generators for ``config``, all seeded from
    ``config.seed``.

    ``collection`` overrides ``config.collector``. Data-parallel ``worker`` k > 0 of a run
    seeds its environments, exploration and replay sampling apart from worker 0 (whose
    seeds are a run of its own's) and combines its updates through ``collective``; the
    networks start the same on every worker; ``local_workers`` of the run share this machine.
    """
    acting = build_acting(config, worker=worker, collective=collective)
    seeds = _run_seeds(config, worker)
    collection = collection or config.collector
    exploring_side = functools.partial(_exploring_side, config, seeds.training, seeds.exploration)
    try:
        threads = resolved_threads(config.threads)
        if resolved_collection(collection, threads, local_workers) is Collection.process:
            collector: Collector = ProcessCollector(exploring_side, acting.agent)
        else:
            train, _, _, explore_rng = exploring_side(acting.agent)
            collector = InlineCollector(train, acting.agent, acting.spec, explore_rng)
    except BaseException:
        acting.close()
        raise
    return Components(acting.spec, acting.agent, acting.envs, acting.rng, collector)


@dataclasses.dataclass(frozen=True)
class _RunSeeds:
    training: np.random.SeedSequence
    evaluation: np.random.SeedSequence
    replay: np.random.SeedSequence
    exploration: np.random.SeedSequence


def _run_seeds(config: TrainConfig, worker: int) -> _RunSeeds:
    """The seeds of a run's parts, from ``config.seed`` (worker k > 0: apart from worker 0)."""
    seeds = np.random.SeedSequence(config.seed if worker == 0 else [config.seed, worker])
    return _RunSeeds(*seeds.spawn(4))


def resolved_device(device: Device) -> torch.device:
    """Where the learners live: ``auto`` made concrete (CUDA where torch finds a GPU, else the
    CPU); ``cuda`` on a machine without one is a :class:`ConfigError`."""
    available = torch.cuda.is_available()
    if device is Device.auto:
        return torch.device("cuda" if available else "cpu")
    if device is Device.cuda and not available:
        raise ConfigError("--device cuda: torch finds no CUDA GPU on this machine; use --device cpu or auto")
    return torch.device(device.value)


BFLOAT16_SHOWN_EQUAL = frozenset({Algo.dtd})
"""The algorithms whose bfloat16 updates learned as their float32 updates did on the tuning seeds,
with DDPG at every level: where ``--precision auto`` chooses bfloat16 on a device that computes it
natively. Dot-to-Dot on FetchPush (median 3-epoch 0.9 at 120k both) and FetchPickAndPlace (0.5 at
225-240k both); not ``her``, whose FetchPush success over 100k-200k was 0.14 against float32's
0.28 (seeds 0-2), nor the learners not compared (docs/results/precision.md)."""

UPDATE_DTYPES = {Precision.float32: torch.float32, Precision.bfloat16: torch.bfloat16}


def resolved_precision(config: TrainConfig, device: torch.device) -> Precision:
    """``config.precision`` made concrete for ``device``: ``auto`` is bfloat16 where it is native
    there and the algorithm, with DDPG at every level, is one of :data:`BFLOAT16_SHOWN_EQUAL`;
    else float32."""
    if config.precision is not Precision.auto:
        return config.precision
    learners = {config.learner.learner}
    if config.algo is Algo.dtd:
        learners.add(config.dtd.high.learner)
    shown_equal = config.algo in BFLOAT16_SHOWN_EQUAL and learners == {LearnerKind.ddpg}
    return Precision.bfloat16 if shown_equal and native_bfloat16(device) else Precision.float32


def native_bfloat16(device: torch.device) -> bool:
    """Whether ``device`` does bfloat16 matrix products in hardware: a CUDA GPU that supports
    them, a CPU with AVX-512 BF16 or AMX (where it lists its features, as Linux does)."""
    if device.type == "cuda":
        return torch.cuda.is_bf16_supported()
    return bool({"avx512_bf16", "amx_bf16"} & cpu_features())


@functools.cache
def cpu_features() -> frozenset[str]:
    """The CPU's feature flags as /proc/cpuinfo lists them (none where there is no such file)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return frozenset()
    flags = next((line for line in text.splitlines() if line.startswith("flags")), "")
    return frozenset(flags.partition(":")[2].split())


def resolved_collection(collection: Collection, threads: int, local_workers: int = 1) -> Collection:
    """``auto`` made concrete for a learner of ``threads`` torch threads: a collecting process
    where a core of this worker's share of the machine is left for it, else inline (a process
    beside threads on every core would only take turns with them)."""
    if collection is not Collection.auto:
        return collection
    return Collection.process if usable_cores() // local_workers > threads else Collection.inline


def resolved_threads(threads: int) -> int:
    """``threads``, or for 0 the OMP_NUM_THREADS the user set, else one. Two OpenMP threads
    beside any other busy process wait for each other: an update took 2.5 to 4 times as long
    as with one thread (benchmarks/contention.py); more threads are for a machine the run has
    to itself, given by --threads."""
    if threads > 0:
        return threads
    return omp_num_threads() or 1


def omp_num_threads() -> int | None:
    """OMP_NUM_THREADS as a positive number of threads, where it is set to one."""
    value = os.environ.get("OMP_NUM_THREADS", "").strip()
    return int(value) if value.isdigit() and int(value) > 0 else None


def usable_cores() -> int:
    """Cores this process may run on (all of the machine's where that cannot be asked)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def seeded_envs(
    config: TrainConfig, count: int, seeds: np.random.SeedSequence
) -> tuple[list[gym.Env], EnvSpec]:
    """``count`` environments of ``config``'s task, each reset once with its own seed from
    ``seeds``."""
    envs, spec = make_task_envs(config, count)
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
    train, spec = seeded_envs(config, config.episodes_per_cycle, train_seq)
    if agent is None:
        # It only acts, between the learner's updates: on the CPU, wherever the learner is.
        acting_config = dataclasses.replace(config, buffer_size=spec.horizon, device=Device.cpu)
        agent = build_agent(acting_config, spec, train[0])
    return train, agent, spec, np.random.default_rng(explore_seq)


def make_task_envs(config: TrainConfig, count: int) -> tuple[list[gym.Env], EnvSpec]:
    """``count`` environments of ``config.env`` made with ``config.env_kwargs``, and the spec."""
    assert config.env is not None
    return make_envs(config.env, count, env_kwargs(config.env_kwargs), config.time_feature)


def close_envs(envs: list[gym.Env]) -> None:
    """Close each of ``envs``."""
    for env in envs:
        env.close()
