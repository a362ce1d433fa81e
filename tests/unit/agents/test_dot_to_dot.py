"""Dot-to-Dot on hand-made episodes: segments, high-level transitions and relabelling,
sub-goal choice, the hand-over schedule, sub-goal bounds and rotations."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from dtd.agents.buffer import EpisodeBuffer
from dtd.agents.ddpg import DDPGLearner
from dtd.agents.dot_to_dot import DotToDotAgent, HandOverSchedule
from dtd.agents.exploration import ActionNoise
from dtd.agents.her import HindsightSampling
from dtd.agents.networks import BoxActionHead, SubgoalHead
from dtd.agents.records import Episodes
from dtd.agents.rotations import angle_between, from_rotation_vector
from dtd.agents.segments import (
    sample_segment_transitions,
    segment_bounds,
    segment_mean_reward,
    segment_of_step,
    segment_window_end,
    segments_begun,
    subgoal_placement,
)
from dtd.config import DotToDotConfig, LearnerConfig, RelabelWindow
from dtd.envs.make import make_envs
from dtd.training.checkpoint import load_checkpoint, save_atomic
from tests.helpers import sparse_goals

T, OBS, GOAL, ACT = 10, 4, 3, 2


def labelled_episodes(count: int = 3) -> Episodes:
    """Achieved goal of episode e at step t is (e, t, 0); obs is (e, t, 0, 0) * 10;
    the goal is (e, -1, 1); sub-goals are (e, t, 2) at each step."""
    e = np.arange(count, dtype=np.float32)[:, None] * np.ones((1, T + 1), np.float32)
    t = np.ones((count, 1), np.float32) * np.arange(T + 1, dtype=np.float32)[None]
    achieved = np.stack([e, t, np.zeros_like(e)], axis=-1)
    obs = np.concatenate([achieved, np.zeros((count, T + 1, 1), np.float32)], axis=-1) * 10
    goal = np.stack([e[:, 0], -np.ones(count, np.float32), np.ones(count, np.float32)], axis=-1)
    step_goal = np.stack([e[:, :T], t[:, :T], np.full((count, T), 2.0, np.float32)], axis=-1)
    return Episodes(
        obs,
        achieved,
        obs[:, :T, :ACT].copy(),
        step_goal,
        goal,
        np.zeros(count, np.float32),
        np.full(count, T),
    )


def reached_reward(achieved: np.ndarray, goal: np.ndarray) -> np.ndarray:
    return -(np.linalg.norm(achieved - goal, axis=-1) > 1e-6).astype(np.float32)


def test_segment_bounds_cover_the_episode_in_near_equal_parts():
    assert segment_bounds(50, 2).tolist() == [0, 25, 50]
    bounds = segment_bounds(10, 3)
    assert bounds[0] == 0 and bounds[-1] == 10 and set(np.diff(bounds)) <= {3, 4}
    assert segment_of_step(np.array([0, 5, 10])).tolist() == [0] * 5 + [1] * 5
    # A step's relabelling window ends where its segment ends (not one step early or late).
    assert segment_window_end(np.array([0, 5, 10])).tolist() == [5] * 5 + [10] * 5
    with pytest.raises(ValueError):
        segment_bounds(3, 4)


def test_high_level_transitions_stay_in_their_episode():
    episodes = labelled_episodes()
    bounds = segment_bounds(T, 2)
    batch = sample_segment_transitions(
        episodes, bounds, 500, np.random.default_rng(0), 0.0, 0.0, reached_reward
    )
    episode, start = batch.obs[:, 0] / 10, batch.obs[:, 1] / 10
    assert set(np.unique(start)) == {0, 5}
    # o || ag at the segment's start; the next observation at its end, same episode.
    assert np.array_equal(batch.obs[:, OBS:], np.stack([episode, start, 0 * start], axis=-1))
    assert np.array_equal(batch.next_obs[:, 0] / 10, episode)
    assert np.array_equal(batch.next_obs[:, 1] / 10, start + 5)
    assert np.array_equal(batch.next_obs[:, OBS:], batch.next_obs[:, :3] / 10)
    # The action is the sub-goal pursued in that segment; the goal is the episode's.
    assert np.array_equal(batch.action, np.stack([episode, start, np.full_like(start, 2)], axis=-1))
    assert np.array_equal(batch.goal, episodes.desired_goal[episode.astype(int)])
    assert np.all(batch.reward == -1.0)  # the goal (e, -1, 1) is never reached
    # With two segments, every next segment is the last: its sub-goal is the goal.
    assert np.all(batch.next_action_given) and np.array_equal(batch.next_action, batch.goal)


def test_next_action_is_only_given_for_the_last_segment():
    bounds = segment_bounds(T, 3)
    batch = sample_segment_transitions(
        labelled_episodes(), bounds, 500, np.random.default_rng(1), 0.0, 0.0, reached_reward
    )
    start = batch.obs[:, 1] / 10
    assert np.array_equal(batch.next_action_given, start >= bounds[1])


def test_high_level_her_replaces_the_goal_by_a_later_achieved_goal_and_recomputes_the_reward():
    episodes = labelled_episodes()
    bounds = segment_bounds(T, 2)
    batch = sample_segment_transitions(
        episodes, bounds, 4000, np.random.default_rng(2), 0.8, 0.0, reached_reward
    )
    episode, start = batch.obs[:, 0] / 10, batch.obs[:, 1] / 10
    relabelled = batch.goal[:, 1] >= 0  # achieved goals have t >= 0, the task's goal -1
    assert 0.75 < relabelled.mean() < 0.85
    assert np.all(batch.goal[relabelled, 0] == episode[relabelled])
    assert np.all(batch.goal[relabelled, 1] > start[relabelled])
    assert np.all(batch.goal[relabelled, 1] <= T)
    # Mean over the segment's 5 steps: one step (the one reaching goal t) earns 0, if inside it.
    inside = relabelled & (batch.goal[:, 1] <= start + 5)
    expected = np.where(inside, -4 / 5, -1.0)
    assert np.allclose(batch.reward, expected)
    assert np.array_equal(batch.next_action, batch.goal)


def test_segment_mean_reward_matches_a_loop():
    rng = np.random.default_rng(3)
    achieved = rng.integers(0, 2, size=(2, T + 1, 1)).astype(np.float32)
    episode, start, stop = np.array([0, 1, 1]), np.array([0, 3, 7]), np.array([3, 7, 10])
    goal = np.ones((3, 1), np.float32)
    got = segment_mean_reward(achieved, episode, start, stop, goal, reached_reward)
    for i in range(3):
        steps = range(start[i], stop[i])
        want = np.mean([reached_reward(achieved[episode[i], t + 1][None], goal[i][None])[0] for t in steps])
        assert got[i] == pytest.approx(want)


def test_hindsight_actions_replace_non_final_sub_goals_by_what_was_reached():
    episodes = labelled_episodes()
    bounds = segment_bounds(T, 2)
    batch = sample_segment_transitions(
        episodes, bounds, 500, np.random.default_rng(4), 0.0, 1.0, reached_reward
    )
    start = batch.obs[:, 1] / 10
    first = start == 0
    assert np.array_equal(batch.action[first], batch.next_obs[first, OBS:])  # reached at t = 5
    assert np.all(batch.action[~first, 2] == 2.0)  # the last segment keeps its sub-goal


def test_hand_over_schedule():
    schedule = HandOverSchedule(start=1.0, floor=0.1, decay_epochs=10, episodes_per_epoch=100)
    assert schedule.eps(0) == 1.0
    assert schedule.eps(500) == pytest.approx(0.55)
    assert schedule.eps(1000) == pytest.approx(0.1)
    assert schedule.eps(10**6) == pytest.approx(0.1)
    assert HandOverSchedule(1.0, 0.2, 0, 100).eps(0) == 0.2


def test_sub_goals_stay_in_the_box_and_rotations_are_unit_quaternions():
    low, high = (0, 0, 0, -1, -1, -1, -1), (1, 1, 1, 1, 1, 1, 1)
    head = SubgoalHead(0.5, low, high, quaternion=(3, 7))
    raw = torch.tensor([[5.0, -5.0, 0.5, 3.0, 0.0, 4.0, 0.0], [0.2, 0.2, 0.2, 0.0, 0.0, 0.0, 0.0]])
    projected = head.project(raw)
    assert torch.all(projected >= torch.tensor(low)) and torch.all(projected <= torch.tensor(high))
    assert torch.allclose(torch.linalg.vector_norm(projected[:, 3:], dim=-1), torch.ones(2))
    assert torch.allclose(projected[0, 3:], torch.tensor([0.6, 0.0, 0.8, 0.0]))  # clipped, then normalised
    assert torch.equal(projected[1, 3:], torch.tensor([1.0, 0.0, 0.0, 0.0]))  # no direction: identity
    # The head adds at most max_distance to the achieved goal (the last 7 obs entries).
    obs = torch.cat([torch.zeros(2, 4), torch.full((2, 3), 0.5), torch.tensor([[1.0, 0, 0, 0]] * 2)], dim=-1)
    out = head(torch.tensor([[1.0] * 7, [-1.0] * 7]), obs)
    assert torch.allclose(out[:, :3], torch.tensor([[1.0] * 3, [0.0] * 3]))


def test_goal_box_pins_the_coordinates_no_goal_varies():
    # FetchPush's goals and blocks all lie at table height: a sub-goal above or below it could
    # never be reached, so the box leaves no room there; x and y get a margin beyond the goals.
    envs, spec = make_envs("FetchPush-v4", 1)
    low, high = np.array(spec.goal_low), np.array(spec.goal_high)
    assert high[2] - low[2] < 1e-6 and low[2] == pytest.approx(0.4249, abs=1e-3)
    goals = []
    for seed in range(100, 120):
        first, _ = envs[0].reset(seed=seed)
        goals += [first["desired_goal"], first["achieved_goal"]]
    assert np.all(np.array(goals)[:, :2] > low[:2]) and np.all(np.array(goals)[:, :2] < high[:2])
    assert np.all(high[:2] - low[:2] < 0.5)


def test_goal_box_stops_at_the_height_where_the_object_rests():
    # FetchPickAndPlace's block starts on the table and its goals lie on it or in the air: the
    # box's floor is the table, its ceiling above the highest goal.
    envs, spec = make_envs("FetchPickAndPlace-v4", 1)
    low, high = np.array(spec.goal_low), np.array(spec.goal_high)
    first, _ = envs[0].reset(seed=7)
    assert low[2] == pytest.approx(first["achieved_goal"][2], abs=1e-6)
    assert high[2] > 0.85 and np.all(high[:2] - low[:2] > 0.3)
    # FetchReach's gripper also starts at one place, but its goals lie below it: a margin there.
    envs, spec = make_envs("FetchReach-v4", 1)
    first, _ = envs[0].reset(seed=7)
    assert spec.goal_low[2] < first["achieved_goal"][2] - 0.1


def make_agent(seed: int = 0, eps: float = 1.0, high_updates: int = 4, segments: int = 2) -> DotToDotAgent:
    torch.manual_seed(seed)
    config = LearnerConfig(hidden_sizes=(16,), batch_size=8)
    low = DDPGLearner(OBS, GOAL, ACT, BoxActionHead(1.0), config, 0.9, (-1.0, 0.0))
    head = SubgoalHead(0.3, (-1.0,) * GOAL, (60.0,) * GOAL, None)
    high = DDPGLearner(OBS + GOAL, GOAL, GOAL, head, config, 0.5, (-1.0, 0.0))
    goals = sparse_goals(reached_reward)
    settings = DotToDotConfig(
        segments=segments,
        subgoal_eps_start=eps,
        subgoal_eps_floor=eps,
        subgoal_eps_decay_epochs=0,
        subgoal_sigma=0.1,
        subgoal_noise=0.1,
        low_relabel_window=RelabelWindow.segment,
        high_updates_per_cycle=high_updates,
    )
    return DotToDotAgent(
        low=low,
        high=high,
        buffer=EpisodeBuffer(20, T, OBS, GOAL, ACT),
        goals=goals,
        horizon=T,
        action_noise=ActionNoise(0.2, 0.3, 1.0),
        low_sampling=HindsightSampling(0.8, goals.reward, low.gamma),
        settings=settings,
        episodes_per_epoch=1,
    )


@pytest.mark.parametrize("explore", [False, True])
def test_sub_goals_change_at_segment_starts_only_and_the_last_is_the_goal(explore):
    agent = make_agent(eps=0.5)
    rng = np.random.default_rng(0)
    obs, achieved = rng.normal(size=(4, OBS)), rng.normal(size=(4, GOAL))
    goal = rng.normal(size=(4, GOAL))
    chosen = [agent.step_goal(obs + t, achieved + t, goal, t, explore, rng).copy() for t in range(T)]
    for t in range(1, 5):
        assert np.array_equal(chosen[t], chosen[0])
    assert not np.allclose(chosen[0], goal)
    for t in range(5, T):
        assert np.array_equal(chosen[t], goal)
    if not explore:
        assert np.allclose(chosen[0], agent.propose_subgoals(obs, achieved, goal))


def test_perturbation_sub_goals_lie_around_the_achieved_goal():
    agent = make_agent(eps=1.0)
    rng = np.random.default_rng(1)
    achieved = np.full((2000, GOAL), 10.0)
    subgoal = agent.step_goal(np.zeros((2000, OBS)), achieved, np.zeros((2000, GOAL)), 0, True, rng)
    assert np.allclose(subgoal.mean(axis=0), 10.0, atol=0.01)
    assert np.allclose(subgoal.std(axis=0), 0.1, atol=0.01)


def test_subgoal_values_are_the_high_level_critic_at_each_candidate():
    agent = make_agent()
    rng = np.random.default_rng(2)
    agent.store(labelled_episodes(), rng)
    agent.train(3, rng)
    observation = {"observation": rng.normal(size=OBS), "achieved_goal": rng.normal(size=GOAL)}
    goal, candidates = rng.normal(size=GOAL), rng.normal(size=(6, GOAL))
    values = agent.subgoal_values(observation, goal, candidates)
    high_obs = np.concatenate([observation["observation"], observation["achieved_goal"]])
    for k in range(6):
        direct = agent.high.q_values(high_obs[None], goal[None], candidates[k][None])[0]
        assert values[k] == pytest.approx(direct, rel=1e-6)
    assert len(set(np.round(values, 6))) > 1


def test_training_reports_both_levels_and_checkpoints_round_trip(tmp_path):
    agent = make_agent()
    rng = np.random.default_rng(3)
    agent.store(labelled_episodes(), rng)
    metrics = agent.train(4, rng)
    assert {"critic_loss", "high_critic_loss", "high_q_mean", "subgoal_eps"} <= set(metrics)
    figures = agent.episode_metrics(labelled_episodes())
    assert figures["subgoal_reached"] == 0.0  # sub-goals (e, t, 2) are never reached
    assert figures["subgoal_from_start"] == pytest.approx(2.0)  # (e, 0, 2) vs (e, 0, 0)
    # From (e, 0, 0) toward the goal (e, -1, 1) the sub-goal (e, 0, 2) is as far along the line
    # as the goal, and (0, 1, 1) off it.
    assert figures["subgoal_progress"] == pytest.approx(1.0)
    assert figures["subgoal_off_line"] == pytest.approx(np.sqrt(2.0))
    save_atomic(tmp_path / "a.pt", agent.state_dict())
    restored = make_agent(seed=9)
    restored.load_state_dict(load_checkpoint(tmp_path / "a.pt"))
    obs, achieved, goal = rng.normal(size=(3, OBS)), rng.normal(size=(3, GOAL)), rng.normal(size=(3, GOAL))
    assert np.array_equal(
        restored.propose_subgoals(obs, achieved, goal), agent.propose_subgoals(obs, achieved, goal)
    )
    assert np.array_equal(restored.act(obs, goal, False, rng), agent.act(obs, goal, False, rng))


@pytest.mark.parametrize(("updates", "high_updates"), [(10, 2), (10, 10), (3, 7)])
def test_the_high_level_makes_its_own_number_of_updates_spread_among_the_low_levels(updates, high_updates):
    agent = make_agent(high_updates=high_updates)
    calls: list[str] = []
    for name, learner in (("low", agent.low), ("high", agent.high)):
        learner.update = lambda batch, name=name: calls.append(name) or {"critic_loss": 0.0}  # type: ignore[method-assign]
    rng = np.random.default_rng(0)
    agent.store(labelled_episodes(), rng)
    agent.train(updates, rng)
    assert calls.count("low") == updates and calls.count("high") == high_updates
    # Evenly spread: before the i-th low update at most ceil(i * high / low) high ones ran.
    highs_before = [calls[:index].count("high") for index, name in enumerate(calls) if name == "low"]
    assert all(h <= -(-i * high_updates // updates) for i, h in enumerate(highs_before))
    assert calls[-1] == "high"


def test_subgoal_placement_is_progress_along_the_start_to_goal_line_and_distance_off_it():
    start = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    goal = np.array([[2.0, 0.0, 0.0], [1.0, 1.0, 1.0]])  # the second episode's goal is its start
    subgoals = np.array(
        [
            [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [4.0, 0.0, 3.0]],
            [[0.0, 0.0, 0.0]] * 4,
        ]
    )
    progress, off_line = subgoal_placement(start, subgoals, goal)
    assert progress[0].tolist() == [0.5, 0.5, -0.5, 2.0]
    assert off_line[0].tolist() == [0.0, 1.0, 0.0, 3.0]
    assert np.all(np.isnan(progress[1])) and np.all(np.isnan(off_line[1]))


def test_placement_by_distance_groups_episodes_by_how_far_their_goal_is():
    agent = make_agent(segments=3)
    episodes = labelled_episodes(count=4)
    goal = episodes.desired_goal.copy()
    goal[:, 1] = [-1.0, -4.0, -2.0, 0.0]  # distances from (e, 0, 0): sqrt 2, sqrt 17, sqrt 5, 1
    goal[3] = episodes.achieved_goal[3, 0]  # met at the start: left out
    episodes = episodes._replace(desired_goal=goal, success=np.array([1.0, 0.0, 1.0, 1.0], np.float32))
    groups = agent.placement_by_distance(episodes, groups=2)
    assert [group["episodes"] for group in groups] == [2, 1]
    assert groups[0]["goal_distance"] == pytest.approx([np.sqrt(2.0), np.sqrt(5.0)], abs=1e-4)
    assert groups[0]["success"] == 1.0 and groups[1]["success"] == 0.0
    assert len(groups[0]["progress"]) == 2  # two intermediate sub-goals of three segments
    # Sub-goal (e, t, 2) against the line from (e, 0, 0) to (e, -4, 1): (-4t + 2) / 17 along it.
    assert groups[1]["progress"] == pytest.approx([2 / 17, (-4 * 3 + 2) / 17], abs=1e-3)
    assert agent.placement_by_distance(episodes._replace(desired_goal=episodes.achieved_goal[:, 0])) == []


def test_observed_values_end_the_segment_before_the_last_with_what_the_episode_did_next():
    bounds = segment_bounds(T, 3)  # [0, 3, 7, 10]
    gamma = 0.5
    batch = sample_segment_transitions(
        labelled_episodes(), bounds, 2000, np.random.default_rng(5), 1.0, 0.0, reached_reward, gamma
    )
    start = batch.obs[:, 1] / 10
    before_last = start == 3
    assert np.array_equal(batch.next_value_given, before_last)
    # Relabelled goal (e, f, 0): in the last segment (steps 7-9, reaching t = 8..10) one step
    # earns 0 when 8 <= f <= 10; the final achieved goal (t = 10) meets it only when f = 10.
    f = batch.goal[before_last, 1]
    last_segment = np.where(f >= 8, -2 / 3, -1.0)
    final = np.where(f == 10, 0.0, -1.0)
    assert np.allclose(batch.next_value[before_last], last_segment + gamma * final / (1 - gamma))
    # The actor learns where it chooses: every segment but the last.
    assert np.array_equal(batch.actor_rows, start < 7)
    bootstrapped = sample_segment_transitions(
        labelled_episodes(), bounds, 50, np.random.default_rng(5), 1.0, 0.0, reached_reward
    )
    assert bootstrapped.next_value is None and bootstrapped.next_value_given is None


def test_the_agent_passes_its_high_level_choices_to_the_batch():
    agent = make_agent()
    batch = agent._high_batch(labelled_episodes(), 64, np.random.default_rng(6))
    assert batch.actor_rows is None and batch.next_value is None
    agent.high_actor_all_segments, agent.high_observed_gamma = False, 0.5
    batch = agent._high_batch(labelled_episodes(), 64, np.random.default_rng(6))
    assert batch.actor_rows is not None and batch.next_value_given is not None


def make_pose_agent(rotation_angle: float) -> DotToDotAgent:
    """An agent whose goals are poses: a position, then a unit quaternion (the Hand tasks)."""
    torch.manual_seed(0)
    goal_dim = 7
    config = LearnerConfig(hidden_sizes=(16,), batch_size=8)
    low = DDPGLearner(OBS, goal_dim, ACT, BoxActionHead(1.0), config, 0.9, (-1.0, 0.0))
    head = SubgoalHead(0.3, (-5.0,) * 3 + (-1.0,) * 4, (5.0,) * 3 + (1.0,) * 4, (3, 7))
    high = DDPGLearner(OBS + goal_dim, goal_dim, goal_dim, head, config, 0.5, (-1.0, 0.0))

    def within_a_tenth(achieved: np.ndarray, goal: np.ndarray) -> np.ndarray:
        return -(angle_between(achieved[..., 3:], goal[..., 3:]) > 0.1).astype(np.float32)

    settings = DotToDotConfig(
        subgoal_eps_start=1.0,
        subgoal_eps_floor=1.0,
        subgoal_eps_decay_epochs=0,
        subgoal_sigma=0.1,
        subgoal_noise=0.1,
        subgoal_rotation_angle=math.degrees(rotation_angle),
        high_updates_per_cycle=1,
    )
    return DotToDotAgent(
        low=low,
        high=high,
        buffer=EpisodeBuffer(20, T, OBS, goal_dim, ACT),
        goals=sparse_goals(within_a_tenth),
        horizon=T,
        action_noise=ActionNoise(0.2, 0.3, 1.0),
        low_sampling=HindsightSampling(0.8, within_a_tenth, low.gamma),
        settings=settings,
        episodes_per_epoch=1,
    )


@pytest.mark.parametrize("rotation_angle", [0.0, 0.5])
def test_perturbation_sub_goals_are_poses_turned_from_the_achieved_rotation(rotation_angle):
    agent = make_pose_agent(rotation_angle)
    rng = np.random.default_rng(3)
    achieved = np.tile([0.5, 0.5, 0.5, np.cos(0.4), 0.0, 0.0, np.sin(0.4)], (2000, 1))
    subgoal = agent.step_goal(np.zeros((2000, OBS)), achieved, np.zeros((2000, 7)), 0, True, rng)
    assert np.allclose(np.linalg.norm(subgoal[:, 3:], axis=-1), 1.0, atol=1e-5)
    assert np.allclose(subgoal[:, :3].std(axis=0), 0.1, atol=0.01)  # positions: Gaussian
    turned = angle_between(achieved[:, 3:], subgoal[:, 3:])
    if rotation_angle:
        assert turned.max() <= rotation_angle + 1e-5 and turned.mean() == pytest.approx(0.25, abs=0.01)
    else:  # Gaussian noise on the entries, then scaled back to unit length: no bound
        assert turned.max() > 0.5


def test_pose_sub_goals_are_reported_as_angles_along_the_rotation_to_the_goal():
    agent = make_pose_agent(0.0)
    count = 2
    identity, quarter = [1.0, 0, 0, 0], from_rotation_vector(np.array([0, 0, np.pi / 2])).tolist()
    eighth = from_rotation_vector(np.array([0, 0, np.pi / 4])).tolist()
    achieved = np.tile(np.array([0.0, 0.0, 0.0, *identity], np.float32), (count, T + 1, 1))
    achieved[:, -1, 3:] = quarter  # the goal's rotation reached at the end
    step_goal = np.tile(np.array([1.0, 0.0, 0.0, *eighth], np.float32), (count, T, 1))
    goal = np.tile(np.array([0.0, 0.0, 0.0, *quarter], np.float32), (count, 1))
    step_goal[:, T // 2 :] = goal[:, None]
    obs = np.zeros((count, T + 1, OBS), np.float32)
    actions = np.zeros((count, T, ACT), np.float32)
    episodes = Episodes(obs, achieved, actions, step_goal, goal, np.ones(count), np.full(count, T))
    metrics = agent.episode_metrics(episodes)
    assert metrics["subgoal_from_start"] == pytest.approx(1.0)  # positions
    assert metrics["subgoal_angle_from_start"] == pytest.approx(45.0, abs=1e-3)
    assert metrics["subgoal_angle_from_goal"] == pytest.approx(45.0, abs=1e-3)
    assert metrics["subgoal_progress"] == pytest.approx(0.5, abs=1e-5)
    assert metrics["subgoal_off_line"] == pytest.approx(0.0, abs=1e-3)
    plan = agent.plan(episodes)[0]
    assert plan["angles"]["start_to_subgoal"] == [45.0, 90.0]  # the last segment's is the goal
    assert plan["angles"]["subgoal_to_goal"][0] == 45.0 and plan["angles"]["final_to_goal"] == 0.0
    assert plan["reached"] == [False, True]
    assert agent.placement_by_distance(episodes)[0]["goal_angle"] == [90.0, 90.0]  # degrees


def test_segments_of_episodes_ended_inside_a_segment():
    # T = 10, three segments at 0, 3, 7 (bounds rounded): one episode full, one ended at step 5
    # (inside the second segment), one at step 2 (inside the first).
    bounds = segment_bounds(T, 3)
    assert bounds.tolist() == [0, 3, 7, 10]
    episodes = labelled_episodes(3)
    lengths = np.array([10, 5, 2])
    achieved = episodes.achieved_goal.copy()
    for i, end in enumerate(lengths):
        achieved[i, end + 1 :] = achieved[i, end]
    episodes = episodes._replace(achieved_goal=achieved, length=lengths)
    assert segments_begun(bounds, lengths).tolist() == [3, 2, 1]
    batch = sample_segment_transitions(
        episodes, bounds, 6000, np.random.default_rng(0), 0.0, 0.0, reached_reward
    )
    episode, start = batch.obs[:, 0].astype(int) // 10, batch.obs[:, 1].astype(int) // 10
    ends = (batch.next_obs[:, 1] / 10).astype(int)
    # Only segments begun: uniform over the six (episode, segment) pairs.
    pairs = set(zip(episode.tolist(), start.tolist(), strict=True))
    assert pairs == {(0, 0), (0, 3), (0, 7), (1, 0), (1, 3), (2, 0)}
    # A segment the episode's end cut short ends there.
    assert np.all(ends[(episode == 1) & (start == 3)] == 5)
    assert np.all(ends[(episode == 2) & (start == 0)] == 2)
    assert np.all(ends[(episode == 0) & (start == 3)] == 7)


def test_a_segment_is_terminal_where_its_goal_ends_the_episode_and_averages_until_then():
    bounds = segment_bounds(T, 2)
    episodes = labelled_episodes(1)
    episodes = episodes._replace(length=np.array([8]))

    def reached(achieved: np.ndarray, goal: np.ndarray) -> np.ndarray:
        return np.linalg.norm(achieved - goal, axis=-1) <= 1e-6

    # Relabelled goals are achieved goals: one of step t' ends the episode for it at t' - 1.
    batch = sample_segment_transitions(
        episodes, bounds, 3000, np.random.default_rng(1), 1.0, 0.0, reached_reward, terminal_fn=reached
    )
    start, goal_step = batch.obs[:, 1].astype(int) // 10, batch.goal[:, 1].astype(int)
    in_segment = goal_step <= np.minimum(start + 5, 8)
    assert np.array_equal(batch.terminal == 1.0, in_segment)
    # Mean reward over the steps up to the goal's: -1 for each step before, 0 at it.
    steps = goal_step - start
    want = np.where(in_segment, -(steps - 1) / steps, -1.0)
    assert batch.reward == pytest.approx(want)
