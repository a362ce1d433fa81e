"""Hindsight Experience Replay as pure, vectorised sampling functions over stored episodes."""

from __future__ import annotations

import dataclasses
import enum

import numpy as np

from dtd.agents.records import Batch, Episodes
from dtd.envs.goals import GoalTest, RewardFn


class GoalStrategy(enum.Enum):
    """Which goals sampled transitions are trained on."""

    none = "none"
    """The goal the episode was collected with (plain DDPG)."""
    future = "future"
    """With probability k/(k+1), a goal achieved later in the same episode."""


def relabel_probability(strategy: GoalStrategy, replay_k: int) -> float:
    """Fraction of sampled transitions whose goal is replaced."""
    if strategy is GoalStrategy.none:
        return 0.0
    return replay_k / (replay_k + 1.0)


def future_indices(t: np.ndarray, window_end: np.ndarray, uniform: np.ndarray) -> np.ndarray:
    """Indices into achieved goals, uniform over t+1 .. window_end (inclusive).

    ``achieved_goal[:, t + 1]`` is what step t reached, so the earliest future goal is
    that one, and ``window_end`` (T for the whole episode) the last.
    """
    span = window_end - t
    return t + 1 + np.minimum((uniform * span).astype(np.int64), span - 1)


def sample_steps(
    length: np.ndarray, horizon: int, batch_size: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """(episode, t) of ``batch_size`` steps drawn uniformly over the stored steps, episode b
    holding steps 0 .. length[b]-1 (padding is never drawn). Where every episode ran the whole
    ``horizon`` this is an episode, then a step (the draws of such tasks' runs always)."""
    count = len(length)
    if np.all(length == horizon):
        return rng.integers(0, count, size=batch_size), rng.integers(0, horizon, size=batch_size)
    ends = np.cumsum(length)
    flat = rng.integers(0, ends[-1], size=batch_size)
    episode = np.searchsorted(ends, flat, side="right")
    return episode, flat - (ends[episode] - length[episode])


def window_rewards(
    achieved_goal: np.ndarray,
    episode: np.ndarray,
    start: np.ndarray,
    stop: np.ndarray,
    goal: np.ndarray,
    reward_fn: RewardFn,
    terminal_fn: GoalTest | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Rewards of steps t = start .. stop-1 of each row's episode against its goal,
    reward_fn(achieved_goal[episode, t + 1], goal), as (B, L) for the longest window L, and the
    (B, L) mask of the steps inside each row's window (the rest are padding).

    With ``terminal_fn`` the mask stops at (and includes) the first step whose achieved goal
    ends the episode for the row's goal, and the third value is (B,) whether there is such a
    step: the task would have ended the episode there (None without ``terminal_fn``).
    """
    longest = int(np.max(stop - start))
    offsets = np.arange(longest)[None, :]
    inside = offsets < (stop - start)[:, None]
    reached = np.minimum(start[:, None] + 1 + offsets, stop[:, None])  # padding repeats the last
    batch, goal_dim = goal.shape
    achieved = achieved_goal[episode[:, None], reached].reshape(-1, goal_dim)
    goals = np.repeat(goal, longest, axis=0)
    rewards = reward_fn(achieved, goals).reshape(batch, longest)
    if terminal_fn is None:
        return rewards, inside, None
    ends = terminal_fn(achieved, goals).reshape(batch, longest) & inside
    terminal = ends.any(axis=1)
    first = np.where(terminal, ends.argmax(axis=1), longest)
    return rewards, inside & (offsets <= first[:, None]), terminal


def sample_transitions(
    episodes: Episodes,
    batch_size: int,
    rng: np.random.Generator,
    relabel_prob: float,
    reward_fn: RewardFn,
    window_end: np.ndarray | None = None,
    past_share: float = 0.0,
    n_step: int = 1,
    gamma: float = 1.0,
    terminal_fn: GoalTest | None = None,
) -> Batch:
    """Sample transitions uniformly over stored steps, relabel goals, recompute rewards.

    ``window_end[t]`` bounds how far ahead the relabelled goal of step t may come from
    (default: the episode's end). A share ``past_share`` of the relabelled transitions takes
    instead the goal of a random stored step, of any episode: a goal given before, a likely
    goal of the task (mrl's ``actual`` goals).

    With ``n_step`` > 1 the reward is the ``gamma``-discounted sum of the rewards of steps
    t .. t+n-1 against the (relabelled) goal, cut at the episode's end, and the transition
    leads to the observation after them, with ``discount`` gamma to the power of the steps
    summed.

    With ``terminal_fn`` (a task that ends an episode on reaching its goal), a transition is
    terminal where its achieved goal ends the episode for its goal, relabelled or not; an n-step
    sum stops at that step. The episode's own end is a truncation for every other goal: those
    transitions bootstrap from the last observation.
    """
    horizon = episodes.action.shape[1]
    length = episodes.length
    episode, t = sample_steps(length, horizon, batch_size, rng)
    relabel = rng.random(batch_size) < relabel_prob
    uniform = rng.random(batch_size)

    end = np.full(batch_size, horizon) if window_end is None else np.asarray(window_end)[t]
    end = np.minimum(end, length[episode])
    future = future_indices(t, end, uniform)
    goal = episodes.step_goal[episode, t].copy()
    goal[relabel] = episodes.achieved_goal[episode[relabel], future[relabel]]
    if past_share > 0.0:
        past = relabel & (rng.random(batch_size) < past_share)
        past_episode, past_t = sample_steps(length, horizon, batch_size, rng)
        goal[past] = episodes.step_goal[past_episode[past], past_t[past]]
    # The reward of step t is earned by the goal it reached: the next achieved goal.
    discount, terminal = None, None
    if n_step == 1:
        reached, next_t = episodes.achieved_goal[episode, t + 1], t + 1
        reward = reward_fn(reached, goal)
        if terminal_fn is not None:
            terminal = terminal_fn(reached, goal).astype(np.float32)
    else:
        next_t = np.minimum(t + n_step, length[episode])
        rewards, inside, ends = window_rewards(
            episodes.achieved_goal, episode, t, next_t, goal, reward_fn, terminal_fn
        )
        terminal = None if ends is None else ends.astype(np.float32)
        discounts = gamma ** np.arange(rewards.shape[1], dtype=np.float64)
        reward = np.sum(rewards * discounts * inside, axis=1).astype(np.float32)
        discount = (gamma ** (next_t - t).astype(np.float64)).astype(np.float32)
    return Batch(
        obs=episodes.obs[episode, t],
        goal=goal,
        action=episodes.action[episode, t],
        reward=reward,
        next_obs=episodes.obs[episode, next_t],
        terminal=terminal,
        discount=discount,
    )


@dataclasses.dataclass(frozen=True)
class HindsightSampling:
    """How one level draws its training transitions from stored episodes
    (:func:`sample_transitions` with these settings): the share of relabelled goals, the task's
    reward and end of episodes, and the returns' steps and discount (the learner's)."""

    relabel_prob: float
    reward_fn: RewardFn
    gamma: float
    terminal_fn: GoalTest | None = None
    n_step: int = 1
    past_share: float = 0.0
    window_end: np.ndarray | None = None
    """How far ahead a relabelled goal may come from (None: the episode's end)."""

    def sample(self, episodes: Episodes, batch_size: int, rng: np.random.Generator) -> Batch:
        return sample_transitions(
            episodes,
            batch_size,
            rng,
            self.relabel_prob,
            self.reward_fn,
            self.window_end,
            self.past_share,
            self.n_step,
            self.gamma,
            self.terminal_fn,
        )
