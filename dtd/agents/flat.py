"""The flat goal-conditioned agents, DDPG and HER: one learner acting toward the task's goal."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, Protocol

import numpy as np

from dtd.buffer import EpisodeBuffer
from dtd.ddpg import DDPGLearner
from dtd.envs import RewardFn
from dtd.exploration import ActionNoise
from dtd.her import GoalStrategy, relabel_probability, sample_transitions
from dtd.records import Batch, Episodes


class Agent(Protocol):
    """What the rollout and the trainer need of an agent."""

    def step_goal(
        self,
        obs: np.ndarray,
        achieved_goal: np.ndarray,
        desired_goal: np.ndarray,
        t: int,
        explore: bool,
        rng: np.random.Generator,
    ) -> np.ndarray:
        """The goal the acting policy pursues at step t (a batch)."""
        ...

    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: np.random.Generator) -> np.ndarray:
        """Actions for a batch, with exploration when ``explore``."""
        ...

    def store(self, episodes: Episodes, rng: np.random.Generator) -> None:
        """Keep collected episodes for learning."""
        ...

    def train(self, updates: int, rng: np.random.Generator) -> dict[str, float]:
        """Run ``updates`` gradient steps (then move the targets) and return mean diagnostics."""
        ...

    def episode_metrics(self, episodes: Episodes) -> dict[str, float]:
        """Figures of collected episodes that only this kind of agent has (may be empty)."""
        ...

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        """Plain data of everything the agent learned (and, optionally, its replay)."""
        ...

    def acting_state(self) -> dict[str, Any]:
        """Plain data of what exploring episodes need: a copy given it acts as this agent."""
        ...

    def load_acting_state(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`acting_state` returned."""
        ...

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`state_dict` returned."""
        ...


def mean_metrics(per_update: Iterable[dict[str, float]]) -> dict[str, float]:
    """The mean of each diagnostic over a series of updates (empty for no update)."""
    totals: dict[str, float] = {}
    count = 0
    for metrics in per_update:
        count += 1
        for name, value in metrics.items():
            totals[name] = totals.get(name, 0.0) + value
    return {name: total / count for name, total in totals.items()}


class GoalConditionedAgent:
    """DDPG (``GoalStrategy.none``) or DDPG + HER (``GoalStrategy.future``) toward the task's goal."""

    def __init__(
        self,
        learner: DDPGLearner,
        buffer: EpisodeBuffer,
        reward_fn: RewardFn,
        noise: ActionNoise,
        strategy: GoalStrategy,
        replay_k: int,
        past_share: float = 0.0,
    ) -> None:
        self.learner = learner
        self.buffer = buffer
        self.reward_fn = reward_fn
        self.noise = noise
        self.relabel_prob = relabel_probability(strategy, replay_k)
        self.past_share = past_share

    def step_goal(
        self,
        obs: np.ndarray,
        achieved_goal: np.ndarray,
        desired_goal: np.ndarray,
        t: int,
        explore: bool,
        rng: np.random.Generator,
    ) -> np.ndarray:
        return desired_goal

    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: np.random.Generator) -> np.ndarray:
        action = self.learner.act(obs, goal)
        return self.noise(action, rng) if explore else action

    def store(self, episodes: Episodes, rng: np.random.Generator) -> None:
        self.buffer.add(episodes)
        # Normalise with the goals the learner will be trained on, relabelled ones included.
        sample = self._batch(episodes, episodes.action.size // episodes.action.shape[-1], rng)
        self.learner.update_normalizers(sample.obs, sample.goal)

    def train(self, updates: int, rng: np.random.Generator) -> dict[str, float]:
        stored = self.buffer.stored()
        size = self.learner.config.batch_size
        metrics = mean_metrics(self.learner.update(self._batch(stored, size, rng)) for _ in range(updates))
        self.learner.update_target()
        return metrics

    def _batch(self, episodes: Episodes, size: int, rng: np.random.Generator) -> Batch:
        return sample_transitions(
            episodes, size, rng, self.relabel_prob, self.reward_fn, past_share=self.past_share
        )

    def episode_metrics(self, episodes: Episodes) -> dict[str, float]:
        return {}

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        state: dict[str, Any] = {"learner": self.learner.state_dict()}
        if include_replay:
            state["buffer"] = self.buffer.state_dict()
        return state

    def acting_state(self) -> dict[str, Any]:
        return {"learner": self.learner.acting_state()}

    def load_acting_state(self, state: dict[str, Any]) -> None:
        self.learner.load_acting_state(state["learner"])

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.learner.load_state_dict(state["learner"])
        if "buffer" in state:
            self.buffer.load_state_dict(state["buffer"])
