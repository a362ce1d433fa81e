"""Episodes cut into segments, and the high level's transitions: pure, vectorised functions.

Segment n covers steps ``bounds[n] .. bounds[n+1] - 1``; it starts from observation
``bounds[n]`` and ends at observation ``bounds[n+1]``, or at the episode's end where the task
ended the episode inside it (segments after that were never begun). One sub-goal is pursued per
segment, the last segment's being the task's goal.
"""

from __future__ import annotations

from typing import Any, TypeVar

import numpy as np
import torch

from dtd.agents.her import future_indices, sample_steps, window_rewards
from dtd.agents.records import Batch, Episodes
from dtd.agents.rotations import angle_between, rotation_placement
from dtd.envs.goals import GoalTest, RewardFn

Quaternion = tuple[int, int] | None
"""Goal entries [start, stop) that hold a unit quaternion (a rotation), if any."""


def segment_bounds(horizon: int, segments: int) -> np.ndarray:
    """(segments + 1,) step indices where segments start, then the horizon; lengths differ
    by at most one."""
    if not 1 <= segments <= horizon:
        raise ValueError(f"cannot cut {horizon} steps into {segments} segments")
    return np.round(np.linspace(0, horizon, segments + 1)).astype(np.int64)


def segment_of_step(bounds: np.ndarray) -> np.ndarray:
    """(T,) the segment each step belongs to."""
    return np.searchsorted(bounds, np.arange(bounds[-1]), side="right") - 1


def segment_window_end(bounds: np.ndarray) -> np.ndarray:
    """(T,) for each step, the index of the achieved goal that ends its segment."""
    return bounds[segment_of_step(bounds) + 1]


def segment_mean_reward(
    achieved_goal: np.ndarray,
    episode: np.ndarray,
    start: np.ndarray,
    stop: np.ndarray,
    goal: np.ndarray,
    reward_fn: RewardFn,
) -> np.ndarray:
    """Mean over steps t = start .. stop-1 of reward_fn(achieved_goal[episode, t + 1], goal)."""
    rewards, inside, _ = window_rewards(achieved_goal, episode, start, stop, goal, reward_fn)
    return np.sum(rewards * inside, axis=1) / (stop - start)


def segments_begun(bounds: np.ndarray, length: np.ndarray) -> np.ndarray:
    """(B,) how many segments each episode of ``length`` steps began (all, where it ran to the
    time limit)."""
    return np.searchsorted(bounds[:-1], length, side="left")


Layout = TypeVar("Layout", np.ndarray, torch.Tensor)


def high_level_input(obs: Layout, achieved_goal: Layout) -> Layout:
    """The high level observes o || ag: it places sub-goals relative to the achieved goal. The
    one definition of that layout, for arrays (acting, replay) and tensors (the export) alike."""
    if isinstance(obs, torch.Tensor):
        return torch.cat([obs, achieved_goal], dim=-1)
    return np.concatenate([obs, achieved_goal], axis=-1)


def high_level_obs(episodes: Episodes, episode: np.ndarray, step: np.ndarray) -> np.ndarray:
    """:func:`high_level_input` at stored steps."""
    return high_level_input(episodes.obs[episode, step], episodes.achieved_goal[episode, step])


def sample_segment_transitions(
    episodes: Episodes,
    bounds: np.ndarray,
    batch_size: int,
    rng: np.random.Generator,
    relabel_prob: float,
    hindsight_action_prob: float,
    reward_fn: RewardFn,
    observed_gamma: float | None = None,
    terminal_fn: GoalTest | None = None,
) -> Batch:
    """High-level transitions, one per (episode, segment begun), with HER on the task's goal.

    A transition is (o||ag at the segment's start, g, sub-goal, mean reward over the segment
    against g, o||ag at its end), all from the same episode. With ``relabel_prob``, g is
    replaced by a goal achieved later in the episode and the reward recomputed from the
    stored achieved goals. With ``hindsight_action_prob``, a non-final segment's sub-goal is
    replaced by the goal it actually reached. When the next segment is the last, its
    sub-goal is the goal itself, so that is the next action to bootstrap from; or, with
    ``observed_gamma`` (the high level's discount), the segment before the last of an episode
    that ran to the time limit takes the value of its end from what the episode went on to do
    against g instead: the last segment's mean reward, then the final achieved goal's reward
    held for ever. The actor learns only from the segments where it chooses (``actor_rows``:
    all but the last).

    With ``terminal_fn`` (a task that ends an episode on reaching its goal), a segment in which
    an achieved goal ends the episode for g, relabelled or not, is terminal: its reward is the
    mean over its steps up to that one. A segment cut short by the episode's end otherwise is
    a truncation: it bootstraps from the episode's last observation.
    """
    segments = len(bounds) - 1
    horizon = int(bounds[-1])
    episode, segment = sample_steps(segments_begun(bounds, episodes.length), segments, batch_size, rng)
    relabel = rng.random(batch_size) < relabel_prob
    uniform = rng.random(batch_size)
    hindsight = (rng.random(batch_size) < hindsight_action_prob) & (segment < segments - 1)

    length = episodes.length[episode]
    start, stop = bounds[segment], np.minimum(bounds[segment + 1], length)
    goal = episodes.desired_goal[episode].copy()
    future = future_indices(start, length, uniform)
    goal[relabel] = episodes.achieved_goal[episode[relabel], future[relabel]]

    subgoal = episodes.step_goal[episode, start].copy()
    subgoal[hindsight] = episodes.achieved_goal[episode[hindsight], stop[hindsight]]
    rewards, inside, ends = window_rewards(
        episodes.achieved_goal, episode, start, stop, goal, reward_fn, terminal_fn
    )
    # The mean over the segment's steps, up to the one that ended the episode for g.
    reward = np.sum(rewards * inside, axis=1) / np.sum(inside, axis=1)
    terminal = None if ends is None else ends.astype(np.float32)
    next_value, next_value_given = None, None
    if observed_gamma is not None:
        next_value_given = (segment == segments - 2) & (length == horizon)
        next_value = np.zeros(batch_size, dtype=np.float32)
        rows = np.flatnonzero(next_value_given)
        if len(rows):
            last, end = np.full(len(rows), bounds[-2]), np.full(len(rows), horizon)
            last_segment = segment_mean_reward(
                episodes.achieved_goal, episode[rows], last, end, goal[rows], reward_fn
            )
            final = reward_fn(episodes.achieved_goal[episode[rows], horizon], goal[rows])
            next_value[rows] = last_segment + observed_gamma * final / (1.0 - observed_gamma)
    return Batch(
        obs=high_level_obs(episodes, episode, start),
        goal=goal,
        action=subgoal,
        reward=reward,
        next_obs=high_level_obs(episodes, episode, stop),
        next_action=goal,
        next_action_given=segment + 1 >= segments - 1,
        next_value=next_value,
        next_value_given=next_value_given,
        terminal=terminal,
        actor_rows=segment < segments - 1,
    )


def subgoal_placement(
    start: np.ndarray, subgoals: np.ndarray, goal: np.ndarray, quaternion: Quaternion = None
) -> tuple[np.ndarray, np.ndarray]:
    """Where sub-goals lie along the way from the start to the goal.

    ``start`` and ``goal`` (B, G), ``subgoals`` (B, K, G). Returns ``progress`` (B, K), the
    projection of each sub-goal onto the start-to-goal line as a fraction of that line (0 at
    the start, 1 at the goal, below 0 behind the start), and ``off_line`` (B, K), its distance
    from that line. Both are NaN for an episode whose goal is its start. Goals with a rotation
    (``quaternion``) are placed along the rotation from the start's to the goal's, off the
    line in degrees (:func:`dtd.agents.rotations.rotation_placement`).
    """
    if quaternion is not None:
        first, stop = quaternion
        progress, off_line = rotation_placement(
            start[:, first:stop], subgoals[..., first:stop], goal[:, first:stop]
        )
        return progress, np.degrees(off_line)
    line = goal - start  # (B, G)
    length_sq = np.sum(line * line, axis=-1)  # (B,)
    offset = subgoals - start[:, None]  # (B, K, G)
    with np.errstate(divide="ignore", invalid="ignore"):
        progress = np.einsum("bkg,bg->bk", offset, line) / length_sq[:, None]
    off_line = np.linalg.norm(offset - progress[..., None] * line[:, None], axis=-1)
    undefined = length_sq <= 0.0
    progress[undefined] = np.nan
    off_line[undefined] = np.nan
    return progress, off_line


def goal_separation(
    first: np.ndarray, second: np.ndarray, quaternion: Quaternion = None
) -> dict[str, np.ndarray]:
    """How far apart goals are: ``distance``, the Euclidean distance of their positions (every
    entry outside the rotation), and for goals with a rotation ``angle``, the angle in degrees
    of the rotation from one to the other."""
    if quaternion is None:
        return {"distance": np.linalg.norm(second - first, axis=-1)}
    begin, stop = quaternion
    position = np.r_[0:begin, stop : first.shape[-1]]
    return {
        "distance": np.linalg.norm(second[..., position] - first[..., position], axis=-1),
        "angle": np.degrees(angle_between(first[..., begin:stop], second[..., begin:stop])),
    }


def episode_plan(
    episodes: Episodes,
    index: int,
    bounds: np.ndarray | None,
    reached_fn: GoalTest | None = None,
    quaternion: Quaternion = None,
) -> dict[str, Any]:
    """Episode ``index``'s plan: the start; each segment's sub-goal, the achieved goal at the
    segment's end and whether that reached the sub-goal by the task's own measure (none without
    ``bounds``, only the segments the episode began; no verdicts without ``reached_fn``); the
    goal, the final achieved goal, success and the steps the episode ran.
    For goals with a rotation, ``angles`` (degrees): from the start to each sub-goal, from each
    segment's end to its sub-goal, from each sub-goal to the goal, from the start and from the
    final achieved goal to the goal."""
    achieved = episodes.achieved_goal[index]
    goal = episodes.desired_goal[index]
    length = int(episodes.length[index])
    subgoals = np.zeros((0, achieved.shape[-1]))
    ends = np.zeros_like(subgoals)
    if bounds is not None:
        begun = int(segments_begun(bounds, episodes.length[index : index + 1])[0])
        subgoals = episodes.step_goal[index, bounds[:begun]]
        ends = achieved[np.minimum(bounds[1 : begun + 1], length)]
    reached = [] if reached_fn is None or bounds is None else reached_fn(ends, subgoals).tolist()
    plan: dict[str, Any] = {
        "start": achieved[0].tolist(),
        "subgoals": subgoals.tolist(),
        "segment_ends": ends.tolist(),
        "reached": reached,
        "goal": goal.tolist(),
        "final": achieved[-1].tolist(),
        "success": bool(episodes.success[index]),
        "steps": length,
    }
    if quaternion is not None:

        def angles(first: np.ndarray, second: np.ndarray) -> list[float]:
            return np.round(goal_separation(first, second, quaternion)["angle"], 1).reshape(-1).tolist()

        plan["angles"] = {
            "start_to_subgoal": angles(achieved[None, 0], subgoals),
            "segment_end_to_subgoal": angles(ends, subgoals),
            "subgoal_to_goal": angles(subgoals, goal[None]),
            "start_to_goal": angles(achieved[None, 0], goal[None])[0],
            "final_to_goal": angles(achieved[None, -1], goal[None])[0],
        }
    return plan
