"""The flat goal-conditioned agents, DDPG and HER: one learner acting toward the task's goal."""

from __future__ import annotations

from typing import Any

import numpy as np

from dtd.agents.buffer import EpisodeBuffer
from dtd.agents.exploration import ActionNoise
from dtd.agents.goal_learner import GoalLearner
from dtd.agents.her import HindsightSampling
from dtd.agents.interface import mean_metrics
from dtd.agents.records import Episodes
from dtd.envs.goals import GoalFunctions


class GoalConditionedAgent:
    """DDPG (its sampling relabels no goal) or DDPG + HER (goals relabelled as HER does) toward
    the task's goal."""

    def __init__(
        self,
        learner: GoalLearner,
        buffer: EpisodeBuffer,
        goals: GoalFunctions,
        noise: ActionNoise,
        sampling: HindsightSampling,
    ) -> None:
        self.learner = learner
        self.buffer = buffer
        self.goals = goals
        """The task's reward and where it ends an episode for a goal."""
        self.noise = noise
        self.sampling = sampling
        """How transitions are drawn from replay (no relabelling for DDPG, HER's for HER)."""

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
        action = self.learner.act(obs, goal, rng if explore else None)
        return self.noise(action, rng) if explore else action

    def store(self, episodes: Episodes, rng: np.random.Generator) -> None:
        self.buffer.add(episodes)
        # Normalise with the goals the learner will be trained on, relabelled ones included.
        sample = self.sampling.sample(episodes, int(np.sum(episodes.length)), rng)
        self.learner.update_normalizers(sample.obs, sample.goal)

    def train(self, updates: int, rng: np.random.Generator) -> dict[str, float]:
        stored = self.buffer.stored()
        size = self.learner.config.batch_size
        metrics = mean_metrics(
            self.learner.update(self.sampling.sample(stored, size, rng)) for _ in range(updates)
        )
        self.learner.update_target()
        return metrics

    def planner(self) -> None:
        """None: a flat agent sets itself no sub-goals."""
        return None

    def motor_learner(self) -> GoalLearner:
        return self.learner

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

    def explaining_state(self) -> dict[str, Any]:
        return {"learner": self.learner.explaining_state()}

    def load_explaining_state(self, state: dict[str, Any]) -> None:
        self.learner.load_explaining_state(state["learner"])

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.learner.load_state_dict(state["learner"])
        if "buffer" in state:
            self.buffer.load_state_dict(state["buffer"])
