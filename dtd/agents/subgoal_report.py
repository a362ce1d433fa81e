"""What the sub-goals of played episodes did, in numbers: reached or not, how far from the start
and the goal, where along the way, and each episode's plan. Pure functions of the episodes, the
segments' bounds and the task's verdict on goals; the Dot-to-Dot agent reports through them."""

from __future__ import annotations

from typing import Any

import numpy as np

from dtd.agents.records import Episodes
from dtd.agents.segments import episode_plan, goal_separation, segments_begun, subgoal_placement
from dtd.envs.goals import GoalTest

Quaternion = tuple[int, int] | None
"""Goal entries holding a rotation (the Hand tasks), if any."""


def subgoal_metrics(
    episodes: Episodes, bounds: np.ndarray, reached_fn: GoalTest | None, quaternion: Quaternion
) -> dict[str, float]:
    """How the sub-goals of these episodes went: reached at their segment's end, how far
    they lay from the start and from the goal, and where along the way (progress along
    the start-to-goal line and distance off it, over episodes whose goal is not met at
    their start; NaN where every goal is). Intermediate sub-goals only, of the segments an
    episode began; reached is NaN where the task's reward does not tell (``reached_fn`` None).
    For goals with a rotation, distances are of the positions, ``*_angle_*`` the rotations'
    angles in degrees, and the way is the rotation's (off it in degrees)."""
    starts = bounds[:-2]
    ends = np.minimum(bounds[1:-1][None, :], episodes.length[:, None])  # (B, N-1)
    begun = intermediate_begun(episodes, bounds)
    subgoals = episodes.step_goal[:, starts]  # (B, N-1, G)
    reached_goals = np.take_along_axis(episodes.achieved_goal, ends[..., None], axis=1)
    goal_dim = subgoals.shape[-1]
    reached = float("nan")
    if reached_fn is not None:
        verdicts = reached_fn(reached_goals.reshape(-1, goal_dim), subgoals.reshape(-1, goal_dim))
        reached = _mean(verdicts.reshape(begun.shape)[begun])
    from_start = goal_separation(episodes.achieved_goal[:, :1], subgoals, quaternion)
    from_goal = goal_separation(episodes.desired_goal[:, None], subgoals, quaternion)
    away = goal_away(episodes, reached_fn)
    progress, off_line = _placement(episodes, bounds, away, quaternion)
    metrics = {
        "subgoal_reached": reached,
        "subgoal_from_start": _mean(from_start["distance"][begun]),
        "subgoal_from_goal": _mean(from_goal["distance"][begun]),
    }
    if "angle" in from_start:
        metrics["subgoal_angle_from_start"] = _mean(from_start["angle"][begun])
        metrics["subgoal_angle_from_goal"] = _mean(from_goal["angle"][begun])
    metrics["subgoal_progress"] = _mean(progress[begun[away]])
    metrics["subgoal_off_line"] = _mean(off_line[begun[away]])
    return metrics


def placement_by_distance(
    episodes: Episodes,
    bounds: np.ndarray,
    reached_fn: GoalTest | None,
    quaternion: Quaternion,
    groups: int = 3,
) -> list[dict[str, Any]]:
    """Where the intermediate sub-goals lay along the way, for ``groups`` groups of
    episodes of equal size by the distance from the start to the goal (nearest first;
    episodes whose goal is met at their start left out): per group its distance range,
    episodes, success, and per sub-goal the mean progress along the start-to-goal line
    (0 start, 1 goal) and mean distance off it (over the episodes that began its segment)."""
    away = goal_away(episodes, reached_fn)
    separation = goal_separation(episodes.achieved_goal[:, 0], episodes.desired_goal, quaternion)
    separation_key = "goal_angle" if "angle" in separation else "goal_distance"
    distance = separation.get("angle", separation["distance"])[away]
    progress, off_line = _placement(episodes, bounds, away, quaternion)
    begun = intermediate_begun(episodes, bounds)[away]
    progress, off_line = np.where(begun, progress, np.nan), np.where(begun, off_line, np.nan)
    order = np.argsort(distance, kind="stable")
    summary: list[dict[str, Any]] = []
    if not len(order):
        return summary
    for members in np.array_split(order, min(groups, len(order))):
        summary.append(
            {
                separation_key: [round(float(distance[members][i]), 4) for i in (0, -1)],
                "episodes": len(members),
                "success": float(np.mean(episodes.success[away][members])),
                "progress": [round(float(v), 3) for v in _column_means(progress[members])],
                "off_line": [round(float(v), 4) for v in _column_means(off_line[members])],
            }
        )
    return summary


def plans(
    episodes: Episodes, bounds: np.ndarray, reached_fn: GoalTest | None, quaternion: Quaternion
) -> list[dict[str, Any]]:
    """Per episode: the start, each segment's sub-goal, where the segment ended and whether
    it reached the sub-goal, the goal (:func:`dtd.agents.segments.episode_plan`)."""
    return [episode_plan(episodes, index, bounds, reached_fn, quaternion) for index in range(episodes.count)]


def intermediate_begun(episodes: Episodes, bounds: np.ndarray) -> np.ndarray:
    """(B, N-1) whether each episode began each intermediate segment."""
    begun = segments_begun(bounds, episodes.length)
    return np.arange(len(bounds) - 2)[None, :] < begun[:, None]


def goal_away(episodes: Episodes, reached_fn: GoalTest | None) -> np.ndarray:
    """(B,) whether an episode's goal is not already met at its start (every episode where
    the task's reward does not tell)."""
    if reached_fn is None:
        return np.ones(episodes.count, dtype=bool)
    return ~reached_fn(episodes.achieved_goal[:, 0], episodes.desired_goal)


def _placement(
    episodes: Episodes, bounds: np.ndarray, away: np.ndarray, quaternion: Quaternion
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`subgoal_placement` of the intermediate sub-goals, over the episodes ``away``
    (those whose goal is not met at their start): (B', N-1) each."""
    return subgoal_placement(
        episodes.achieved_goal[away, 0],
        episodes.step_goal[away][:, bounds[:-2]],
        episodes.desired_goal[away],
        quaternion,
    )


def _mean(values: np.ndarray) -> float:
    """The mean of ``values`` (NaN for none)."""
    return float(np.mean(values)) if values.size else float("nan")


def _column_means(values: np.ndarray) -> np.ndarray:
    """Each column's mean over its rows that are not NaN (NaN where none is)."""
    if not np.isnan(values).any():
        return np.mean(values, axis=0)
    counts = np.sum(~np.isnan(values), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, np.nansum(values, axis=0) / np.maximum(counts, 1), np.nan)
