"""The training loop: epochs of (collect, store, update) cycles, evaluation, checkpoint, metrics.

Every collaborator is built elsewhere and passed in; the trainer is the only writer of files.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch

from dtd.agents.interface import Agent
from dtd.config import TrainConfig
from dtd.envs.spec import EnvSpec
from dtd.training.checkpoint import Checkpoint, TrainState, restoring
from dtd.training.collector import Collector, env_rng_states, restore_env_rng_states
from dtd.training.progress import TrainingProgress
from dtd.training.recorder import MetricsRecorder, Row
from dtd.training.rollout import concatenate, episode_figures, run_many
from dtd.training.run_dir import RunDir
from dtd.training.workers import WorkerGroup


class Trainer:
    """Runs epochs from a :class:`TrainState` to ``config.epochs``.

    As one of several data-parallel workers (``group``), it counts the env steps and episodes
    of all, reports figures averaged over all, and writes its own checkpoint shard; worker 0
    writes the run's files.
    """

    def __init__(
        self,
        config: TrainConfig,
        spec: EnvSpec,
        agent: Agent,
        collector: Collector,
        eval_envs: Sequence[gym.Env],
        rng: np.random.Generator,
        run: RunDir,
        recorder: MetricsRecorder | None,
        progress: TrainingProgress,
        group: WorkerGroup = WorkerGroup(),
    ) -> None:
        self.config = config
        self.spec = spec
        self.agent = agent
        self.collector = collector
        self.eval_envs = eval_envs
        self.rng = rng
        self.run = run
        self.recorder = recorder
        """Writes metrics.csv and TensorBoard (worker 0's; None on the others)."""
        self.progress = progress
        self.group = group

    def train(self, state: TrainState) -> TrainState:
        """Train until ``config.epochs`` epochs are finished; checkpoint after each one."""
        for epoch in range(state.epoch + 1, self.config.epochs + 1):
            row = self._epoch(state, epoch)
            state.history.append(row)
            self._save(state, improved=row["eval_success"] > state.best_eval_success)
            if self.recorder is not None:
                self.recorder.write_csv(state.history)
                self.recorder.log(row)
            if self.group.writes:
                self.progress.epoch_done(row)
        return state

    def _epoch(self, state: TrainState, epoch: int) -> Row:
        """Cycles of (collect, store, update), then evaluation; advances ``state``'s counters."""
        config = self.config
        start = time.perf_counter()
        sums: dict[str, float] = {}
        collected = []
        local_steps = 0
        self.collector.submit()
        for cycle in range(1, config.n_cycles + 1):
            episodes = self.collector.result()
            self.agent.store(episodes, self.rng)
            # The next cycle's episodes are collected while this cycle's updates run (in a
            # collecting process, at the same time; inline, just before them), or after them.
            if cycle < config.n_cycles and config.collect_ahead:
                self.collector.submit()
            for name, value in self.agent.train(config.updates_per_cycle, self.rng).items():
                sums[name] = sums.get(name, 0.0) + value
            if cycle < config.n_cycles and not config.collect_ahead:
                self.collector.submit()
            collected.append(episodes)
            # Episodes the task ended sooner than the time limit took fewer steps; the other
            # workers' are counted at the epoch's end, and shown meanwhile as this worker's.
            steps = int(np.sum(episodes.length))
            local_steps += steps
            state.episodes += episodes.count * self.group.workers
            state.updates += config.updates_per_cycle
            shown = steps * self.group.workers
            self.progress.advance(
                shown, epoch, local_steps * self.group.workers / (time.perf_counter() - start)
            )
        state.env_steps += self.group.total(local_steps)
        evaluation = run_many(self.eval_envs, self.agent, self.spec, config.test_episodes, False, self.rng)
        figures = self.group.mean(
            {
                **_prefixed("eval_", episode_figures(self.agent, evaluation)),
                **_prefixed("train_", episode_figures(self.agent, concatenate(collected))),
                **{name: total / config.n_cycles for name, total in sums.items()},
            }
        )
        state.wall_s += time.perf_counter() - start
        state.epoch = epoch
        return {
            "epoch": epoch,
            "env_steps": state.env_steps,
            "updates": state.updates,
            "episodes": state.episodes,
            "wall_s": round(state.wall_s, 3),
            **figures,
        }

    def _save(self, state: TrainState, improved: bool) -> None:
        if self.group.workers == 1:
            self._save_run(state, improved)
            return
        # Each worker's shard of the epoch first, then worker 0's checkpoint, which names the
        # epoch: a crash at any moment leaves a complete set for the epoch latest.pt holds.
        if not self.group.writes:
            shard = self.run.worker_shard(self.group.rank, state.epoch)
            self.snapshot(state, include_replay=True).save(shard)
        self.group.barrier()
        if self.group.writes:
            self._save_run(state, improved)
        self.group.barrier()
        if not self.group.writes:
            self.run.remove_worker_shards(self.group.rank, keep_epoch=state.epoch)

    def _save_run(self, state: TrainState, improved: bool) -> None:
        if improved:
            state.best_eval_success = state.history[-1]["eval_success"]
            self.snapshot(state, include_replay=False).save(self.run.best)
        if state.epoch == 1:  # kept to show what one epoch had learned (dtd heatmap)
            self.snapshot(state, include_replay=False).save(self.run.first)
        if keeps_epoch_snapshot(state.epoch, self.config):
            self.epoch_snapshot(state).save(self.run.epoch_snapshot(state.epoch))
        self.snapshot(state, include_replay=True).save(self.run.latest)

    def epoch_snapshot(self, state: TrainState) -> Checkpoint:
        """The agent alone after ``state``'s epoch, as ``dtd explore`` reads it."""
        return Checkpoint(
            env_id=self.spec.env_id,
            algo=self.config.algo.value,
            spec=dataclasses.asdict(self.spec),
            counters={
                "epoch": state.epoch,
                "env_steps": state.env_steps,
                "eval_success": state.history[-1]["eval_success"],
            },
            agent=self.agent.explaining_state(),
        )

    def snapshot(self, state: TrainState, include_replay: bool) -> Checkpoint:
        """Everything needed to continue exactly where ``state`` stands."""
        return Checkpoint(
            env_id=self.spec.env_id,
            algo=self.config.algo.value,
            spec=dataclasses.asdict(self.spec),
            counters=dataclasses.asdict(state),
            agent=self.agent.state_dict(include_replay=include_replay),
            config=self.config.to_dict(),
            rng={
                "numpy": self.rng.bit_generator.state,
                "torch": torch.get_rng_state(),
                "collector": self.collector.state_dict(),
                "eval_envs": env_rng_states(self.eval_envs),
            },
            worker=self.group.rank,
        )


def keeps_epoch_snapshot(epoch: int, config: TrainConfig) -> bool:
    """Whether a run keeps an agent-only snapshot after ``epoch``: every k-th epoch, with
    k = ceil(epochs / explore_snapshots), and the first and the last."""
    if config.explore_snapshots == 0:
        return False
    every = math.ceil(config.epochs / config.explore_snapshots)
    return epoch == 1 or epoch == config.epochs or epoch % every == 0


def restore(
    checkpoint: Checkpoint,
    agent: Agent,
    rng: np.random.Generator,
    collector: Collector,
    eval_envs: Sequence[gym.Env],
    path: Path,
) -> TrainState:
    """Load a whole :meth:`Trainer.snapshot` (with replay) read from ``path`` into the run's
    parts; return its counters."""
    checkpoint.check_resumable(path)
    assert checkpoint.rng is not None, "a whole checkpoint"
    with restoring(path):
        agent.load_state_dict(dict(checkpoint.agent))
        rng.bit_generator.state = checkpoint.rng["numpy"]
        torch.set_rng_state(checkpoint.rng["torch"])
        collector.load_state_dict(checkpoint.rng["collector"])
        restore_env_rng_states(eval_envs, checkpoint.rng["eval_envs"])
        return checkpoint.train_state()


def _prefixed(prefix: str, figures: dict[str, float]) -> dict[str, float]:
    return {prefix + name: value for name, value in figures.items()}
