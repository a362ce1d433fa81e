"""The Dot-to-Dot agent: a high level that places sub-goals ("dots") and a low level that
reaches them, both the same learner, both trained with hindsight relabelling."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from dtd.agents import subgoal_report
from dtd.agents.buffer import EpisodeBuffer
from dtd.agents.exploration import ActionNoise
from dtd.agents.goal_learner import GoalLearner
from dtd.agents.her import GoalStrategy, HindsightSampling, relabel_probability
from dtd.agents.interface import mean_metrics
from dtd.agents.networks import SubgoalHead
from dtd.agents.records import Batch, Episodes
from dtd.agents.rotations import multiply, random_rotations
from dtd.agents.segments import (
    high_level_input,
    sample_segment_transitions,
    segment_bounds,
    segment_window_end,
    segments_begun,
)
from dtd.config import DotToDotConfig, HighTarget, RelabelWindow
from dtd.envs.goals import GoalFunctions


@dataclasses.dataclass(frozen=True)
class HandOverSchedule:
    """Probability of a perturbation sub-goal instead of the high level's: linear from
    ``start`` to ``floor`` over ``decay_epochs`` epochs of episodes, then constant."""

    start: float
    floor: float
    decay_epochs: float
    episodes_per_epoch: int

    def eps(self, episodes_seen: int) -> float:
        """The probability after ``episodes_seen`` training episodes."""
        if self.decay_epochs <= 0:
            return self.floor
        progress = min(1.0, episodes_seen / (self.decay_epochs * self.episodes_per_epoch))
        return self.start + (self.floor - self.start) * progress


@dataclasses.dataclass(frozen=True)
class SubgoalExploration:
    """How training episodes choose their sub-goals."""

    schedule: HandOverSchedule
    sigma: float
    """Std of the perturbation of the achieved goal."""
    noise: float
    """Std of the noise on the high level's sub-goals."""
    rotation_angle: float = 0.0
    """For goals with a rotation: where above 0, a perturbation sub-goal's rotation is the
    achieved one turned by a random angle up to this (radians) about a random axis, rather
    than the Gaussian perturbation of its quaternion's entries."""


class DotToDotAgent:
    """Two levels over one episode buffer.

    Each episode is cut at ``bounds``; at each segment's start the agent picks a sub-goal
    (the task's goal for the last segment) and the low level pursues it for the whole
    segment, reached or not. ``step_goal`` is that sub-goal at every step.
    """

    def __init__(
        self,
        low: GoalLearner,
        high: GoalLearner,
        buffer: EpisodeBuffer,
        goals: GoalFunctions,
        horizon: int,
        action_noise: ActionNoise,
        low_sampling: HindsightSampling,
        settings: DotToDotConfig,
        episodes_per_epoch: int,
    ) -> None:
        """``low_sampling`` is how a flat HER agent would draw the low level's transitions;
        ``settings`` cut the episodes of ``horizon`` steps into segments, and say how sub-goals
        are explored (the hand-over schedule counted in epochs of ``episodes_per_epoch``) and
        how the high level learns."""
        if not isinstance(high.head, SubgoalHead):
            raise TypeError("the high level's learner must propose sub-goals (a SubgoalHead)")
        self.low = low
        self.high = high
        self.buffer = buffer
        self.goals = goals
        """The task's reward, its verdict on reaching a goal and where it ends an episode."""
        self.settings = settings
        self.bounds = segment_bounds(horizon, settings.segments)
        self.segment_starts = {int(start): n for n, start in enumerate(self.bounds[:-1])}
        self.action_noise = action_noise
        self.exploration = SubgoalExploration(
            HandOverSchedule(
                settings.subgoal_eps_start,
                settings.subgoal_eps_floor,
                settings.subgoal_eps_decay_epochs,
                episodes_per_epoch,
            ),
            settings.subgoal_sigma,
            settings.subgoal_noise,
            math.radians(settings.subgoal_rotation_angle),
        )
        within_segment = settings.low_relabel_window is RelabelWindow.segment
        self.low_sampling = dataclasses.replace(
            low_sampling, window_end=segment_window_end(self.bounds) if within_segment else None
        )
        """How the low level draws its transitions: HER's, its relabelled goals within a window."""
        self.high_relabel_prob = relabel_probability(GoalStrategy.future, settings.high_replay_k)
        self.high_observed_gamma = high.gamma if settings.high_target is HighTarget.observed else None
        """Where given, the segment before the last learns the value of its end from what the
        episode did next (see :func:`sample_segment_transitions`), discounted by it."""
        self.high_actor_all_segments = settings.high_actor_last_segment
        """Whether the high level's actor learns also where the last segment starts."""
        self._subgoal: np.ndarray | None = None

    @property
    def segments(self) -> int:
        return len(self.bounds) - 1

    @property
    def eps(self) -> float:
        """The current probability of a perturbation sub-goal in training episodes."""
        return self.exploration.schedule.eps(self.buffer.episodes_added)

    def planner(self) -> DotToDotAgent:
        """Itself: what explaining and exporting ask of a high level it answers."""
        return self

    def motor_learner(self) -> GoalLearner:
        return self.low

    def propose_subgoals(
        self, obs: np.ndarray, achieved_goal: np.ndarray, desired_goal: np.ndarray
    ) -> np.ndarray:
        """The high level's deterministic sub-goals pi1(o || ag, g) for a batch."""
        return self.high.act(high_level_input(obs, achieved_goal), desired_goal)

    def subgoal_values(
        self, observation: Mapping[str, np.ndarray], goal: np.ndarray, candidates: np.ndarray
    ) -> np.ndarray:
        """Q1(o, g, sg) of the high level for each candidate sub-goal (absolute coordinates).

        ``observation`` is the environment's dict observation (``observation`` and
        ``achieved_goal`` are read), ``goal`` the task's goal, ``candidates`` (K, goal_dim).
        Returns (K,) values.
        """
        candidates = np.asarray(candidates, dtype=np.float32).reshape(-1, self.high.goal_norm.size)
        count = candidates.shape[0]
        high_obs = high_level_input(
            np.ravel(observation["observation"]), np.ravel(observation["achieved_goal"])
        ).astype(np.float32)
        goals = np.ravel(goal).astype(np.float32)
        return self.high.q_values(np.tile(high_obs, (count, 1)), np.tile(goals, (count, 1)), candidates)

    def step_goal(
        self,
        obs: np.ndarray,
        achieved_goal: np.ndarray,
        desired_goal: np.ndarray,
        t: int,
        explore: bool,
        rng: np.random.Generator,
    ) -> np.ndarray:
        segment = self.segment_starts.get(t)
        if segment is None:
            assert self._subgoal is not None, "episodes are stepped from t = 0"
            return self._subgoal
        if segment == self.segments - 1:
            self._subgoal = desired_goal.copy()
        elif not explore:
            self._subgoal = self.propose_subgoals(obs, achieved_goal, desired_goal)
        else:
            self._subgoal = self._explore_subgoals(obs, achieved_goal, desired_goal, rng)
        return self._subgoal

    def _explore_subgoals(
        self, obs: np.ndarray, achieved_goal: np.ndarray, desired_goal: np.ndarray, rng: np.random.Generator
    ) -> np.ndarray:
        count, goal_dim = desired_goal.shape
        explore = self.exploration
        perturbed = achieved_goal + explore.sigma * rng.standard_normal((count, goal_dim))
        proposed = self.high.act(high_level_input(obs, achieved_goal), desired_goal, rng)
        if not self.high.stochastic:  # a stochastic high level explores by its own samples
            proposed = proposed + explore.noise * rng.standard_normal((count, goal_dim))
        take_perturbed = rng.random(count) < self.eps
        if explore.rotation_angle > 0.0 and self.quaternion is not None:
            first, stop = self.quaternion
            turns = random_rotations(rng, count, explore.rotation_angle)
            perturbed[:, first:stop] = multiply(achieved_goal[:, first:stop], turns)
        chosen = np.where(take_perturbed[:, None], perturbed, proposed)
        return self.high.head.project(self.high.tensor(chosen)).cpu().numpy()

    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: np.random.Generator) -> np.ndarray:
        action = self.low.act(obs, goal, rng if explore else None)
        return self.action_noise(action, rng) if explore else action

    def _high_batch(self, episodes: Episodes, size: int, rng: np.random.Generator) -> Batch:
        batch = sample_segment_transitions(
            episodes,
            self.bounds,
            size,
            rng,
            self.high_relabel_prob,
            self.settings.hindsight_action_prob,
            self.goals.reward,
            self.high_observed_gamma,
            self.goals.terminal,
        )
        return batch._replace(actor_rows=None) if self.high_actor_all_segments else batch

    def store(self, episodes: Episodes, rng: np.random.Generator) -> None:
        self.buffer.add(episodes)
        # Each level normalises with the goals it will be trained on, relabelled ones included.
        low = self.low_sampling.sample(episodes, int(np.sum(episodes.length)), rng)
        self.low.update_normalizers(low.obs, low.goal)
        high = self._high_batch(episodes, int(np.sum(segments_begun(self.bounds, episodes.length))), rng)
        self.high.update_normalizers(high.obs, high.goal)

    def train(self, updates: int, rng: np.random.Generator) -> dict[str, float]:
        """``updates`` low-level updates with the high level's ``high_updates_per_cycle`` spread
        evenly among them (Algorithm 1 of the paper: both levels learn in the same phase)."""
        stored = self.buffer.stored()
        low_metrics, high_metrics = [], []
        for i in range(updates):
            low_metrics.append(
                self.low.update(self.low_sampling.sample(stored, self.low.config.batch_size, rng))
            )
            high_updates = self.settings.high_updates_per_cycle
            for _ in range((i + 1) * high_updates // updates - i * high_updates // updates):
                batch = self._high_batch(stored, self.high.config.batch_size, rng)
                high_metrics.append(self.high.update(batch))
        self.low.update_target()
        self.high.update_target()
        metrics = mean_metrics(low_metrics)
        metrics.update({"high_" + name: value for name, value in mean_metrics(high_metrics).items()})
        metrics["subgoal_eps"] = self.eps
        return metrics

    @property
    def quaternion(self) -> tuple[int, int] | None:
        """Goal entries holding a rotation (the Hand tasks), if any."""
        return self.high.head.quaternion

    def episode_metrics(self, episodes: Episodes) -> dict[str, float]:
        """How the sub-goals of these episodes went (:func:`subgoal_report.subgoal_metrics`)."""
        return subgoal_report.subgoal_metrics(episodes, self.bounds, self.goals.reached, self.quaternion)

    def placement_by_distance(self, episodes: Episodes, groups: int = 3) -> list[dict[str, Any]]:
        """Where the sub-goals lay along the way per group of goal distances
        (:func:`subgoal_report.placement_by_distance`)."""
        return subgoal_report.placement_by_distance(
            episodes, self.bounds, self.goals.reached, self.quaternion, groups
        )

    def plan(self, episodes: Episodes) -> list[dict[str, Any]]:
        """Per episode: the start, each segment's sub-goal, where the segment ended and whether
        it reached the sub-goal, the goal."""
        return subgoal_report.plans(episodes, self.bounds, self.goals.reached, self.quaternion)

    def state_dict(self, include_replay: bool = True) -> dict[str, Any]:
        state: dict[str, Any] = {"low": self.low.state_dict(), "high": self.high.state_dict()}
        if include_replay:
            state["buffer"] = self.buffer.state_dict()
        return state

    def acting_state(self) -> dict[str, Any]:
        # The episodes seen set the hand-over schedule's eps.
        return {
            "low": self.low.acting_state(),
            "high": self.high.acting_state(),
            "episodes_added": self.buffer.episodes_added,
        }

    def load_acting_state(self, state: dict[str, Any]) -> None:
        self.low.load_acting_state(state["low"])
        self.high.load_acting_state(state["high"])
        self.buffer.episodes_added = int(state["episodes_added"])

    def explaining_state(self) -> dict[str, Any]:
        # The low level only acts; the high level's critic values sub-goals (subgoal_values).
        return {**self.acting_state(), "high": self.high.explaining_state()}

    def load_explaining_state(self, state: dict[str, Any]) -> None:
        self.low.load_acting_state(state["low"])
        self.high.load_explaining_state(state["high"])
        self.buffer.episodes_added = int(state["episodes_added"])

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.low.load_state_dict(state["low"])
        self.high.load_state_dict(state["high"])
        if "buffer" in state:
            self.buffer.load_state_dict(state["buffer"])
