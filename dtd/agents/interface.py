"""What every agent offers the rollout and the trainer, what an agent that sets itself sub-goals
offers those who look inside it, and the mean of an agent's update diagnostics."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any, Protocol

import numpy as np

from dtd.agents.goal_learner import GoalLearner
from dtd.agents.records import Episodes


class Planner(Protocol):
    """An agent's high level, as explaining and exporting see it: where its segments begin,
    the sub-goals it proposes, their values, and the plans of played episodes."""

    bounds: np.ndarray
    """Steps at which the segments begin, and the horizon last."""
    high: GoalLearner
    """The high level's learner, whose actions are sub-goals (the export traces its paths)."""

    def propose_subgoals(
        self, obs: np.ndarray, achieved_goal: np.ndarray, desired_goal: np.ndarray
    ) -> np.ndarray:
        """The high level's deterministic sub-goals for a batch."""
        ...

    def subgoal_values(
        self, observation: Mapping[str, np.ndarray], goal: np.ndarray, candidates: np.ndarray
    ) -> np.ndarray:
        """The high level's value of each candidate sub-goal from one dict observation."""
        ...

    def plan(self, episodes: Episodes) -> list[dict[str, Any]]:
        """Each episode's start, sub-goals, segment ends and goal, in numbers."""
        ...

    def placement_by_distance(self, episodes: Episodes, groups: int = 3) -> list[dict[str, Any]]:
        """Where the sub-goals lay along the way, per group of goal distances."""
        ...


class Agent(Protocol):
    """What the rollout and the trainer need of an agent."""

    def planner(self) -> Planner | None:
        """Its high level, for an agent that sets itself sub-goals; None for a flat agent."""
        ...

    def motor_learner(self) -> GoalLearner:
        """The learner whose policy chooses the motor commands (a flat agent's only one; the
        low level of an agent that sets itself sub-goals)."""
        ...

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

    def explaining_state(self) -> dict[str, Any]:
        """Plain data of what acting and valuing need (actors, critics that judge, normalisers):
        a small snapshot to look at the agent later, not to train on."""
        ...

    def load_explaining_state(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`explaining_state` returned."""
        ...

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`state_dict` returned."""
        ...


def mean_metrics(per_update: Iterable[dict[str, float]]) -> dict[str, float]:
    """The mean of each diagnostic over the updates that report it (empty for no update)."""
    totals: dict[str, float] = {}
    counts: dict[str, int] = {}
    for metrics in per_update:
        for name, value in metrics.items():
            totals[name] = totals.get(name, 0.0) + value
            counts[name] = counts.get(name, 0) + 1
    return {name: total / counts[name] for name, total in totals.items()}
