"""HER relabelling: which goals are drawn, from where, and the rewards that go with them."""

import numpy as np
import pytest

from dtd.agents.her import GoalStrategy, future_indices, relabel_probability, sample_transitions
from dtd.agents.records import Episodes

T = 10


def labelled_episodes(count: int = 3, horizon: int = T) -> Episodes:
    """Episodes whose every value encodes where it comes from: achieved goal = (episode, t, 0)."""
    ep = np.arange(count, dtype=np.float32)[:, None]
    steps = np.arange(horizon + 1, dtype=np.float32)[None, :]
    achieved = np.stack(
        [
            np.broadcast_to(ep, (count, horizon + 1)),
            np.broadcast_to(steps, (count, horizon + 1)),
            np.zeros((count, horizon + 1), np.float32),
        ],
        axis=-1,
    )
    obs = achieved.copy() * 10
    desired = np.stack([ep[:, 0], np.full(count, -1.0, np.float32), np.ones(count, np.float32)], axis=-1)
    return Episodes(
        obs=obs,
        achieved_goal=achieved,
        action=obs[:, :-1, :2].copy(),
        step_goal=np.repeat(desired[:, None], horizon, axis=1),
        desired_goal=desired,
        success=np.zeros(count, np.float32),
        length=np.full(count, horizon),
    )


def exact_reward(achieved: np.ndarray, goal: np.ndarray) -> np.ndarray:
    return -(np.linalg.norm(achieved - goal, axis=-1) > 1e-6).astype(np.float32)


def test_future_indices_lie_after_t_and_inside_the_window():
    rng = np.random.default_rng(0)
    t = rng.integers(0, T, size=10_000)
    future = future_indices(t, np.full_like(t, T), rng.random(t.size))
    assert np.all(future > t)
    assert np.all(future <= T)
    # Every future index is reachable, the last one (the final achieved goal) included.
    assert set(np.unique(future[t == 0])) == set(range(1, T + 1))


def test_future_indices_respect_a_shorter_window():
    t = np.array([0, 1, 4, 5, 9])
    window_end = np.array([5, 5, 5, 10, 10])
    for u in (0.0, 0.5, 0.999999):
        future = future_indices(t, window_end, np.full(t.size, u))
        assert np.all(future > t) and np.all(future <= window_end)
    assert np.all(future_indices(t, window_end, np.full(t.size, 0.999999)) == window_end)


def test_relabelled_goals_come_from_later_in_the_same_episode_and_rewards_are_recomputed():
    episodes = labelled_episodes()
    batch = sample_transitions(episodes, 5000, np.random.default_rng(1), 0.8, exact_reward)
    episode_of_obs = batch.obs[:, 0] / 10
    t_of_obs = batch.obs[:, 1] / 10
    relabelled = batch.goal[:, 2] == 0  # achieved goals have 0 there, desired goals 1
    assert 0.77 < relabelled.mean() < 0.83
    # Same episode, strictly later step, at most the episode's last achieved goal.
    assert np.all(batch.goal[relabelled, 0] == episode_of_obs[relabelled])
    assert np.all(batch.goal[relabelled, 1] > t_of_obs[relabelled])
    assert np.all(batch.goal[relabelled, 1] <= T)
    # next_obs is the step after obs in the same episode.
    assert np.all(batch.next_obs[:, 1] / 10 == t_of_obs + 1)
    assert np.all(batch.next_obs[:, 0] == batch.obs[:, 0])
    # Reward: 0 exactly when the relabelled goal is the next achieved goal (t + 1).
    expected = np.where(relabelled & (batch.goal[:, 1] == t_of_obs + 1), 0.0, -1.0)
    assert np.array_equal(batch.reward, expected)
    assert np.any(batch.reward == 0)


def test_without_relabelling_goals_are_the_episode_goals():
    episodes = labelled_episodes()
    p = relabel_probability(GoalStrategy.none, 4)
    batch = sample_transitions(episodes, 1000, np.random.default_rng(2), p, exact_reward)
    assert p == 0.0
    assert np.all(batch.goal == episodes.desired_goal[batch.obs[:, 0].astype(int) // 10])
    assert np.all(batch.reward == -1.0)


def test_window_bounds_relabelled_goals():
    episodes = labelled_episodes()
    window_end = np.where(np.arange(T) < 5, 5, T)
    batch = sample_transitions(episodes, 4000, np.random.default_rng(3), 1.0, exact_reward, window_end)
    t = batch.obs[:, 1] / 10
    first_half = t < 5
    assert np.all(batch.goal[first_half, 1] <= 5)
    assert np.any(batch.goal[~first_half, 1] > 5)


def test_a_share_of_relabelled_goals_are_goals_given_in_any_stored_episode():
    count = 20
    episodes = labelled_episodes(count)
    batch = sample_transitions(episodes, 20_000, np.random.default_rng(4), 0.8, exact_reward, past_share=0.5)
    episode_of_obs = batch.obs[:, 0] / 10
    given = batch.goal[:, 2] == 1  # a desired goal, of this episode or of another
    future = ~given
    assert 0.38 < future.mean() < 0.42
    # Every given goal is one stored, of the episode it names.
    assert np.array_equal(batch.goal[given], episodes.desired_goal[batch.goal[given, 0].astype(int)])
    # 0.2 keep their own goal; 0.4 take a random episode's, another's in 19 cases of 20.
    other = given & (batch.goal[:, 0] != episode_of_obs)
    assert 0.36 < other.mean() < 0.40
    # Future goals still come from later in the same episode.
    assert np.all(batch.goal[future, 0] == episode_of_obs[future])
    assert np.all(batch.goal[future, 1] > batch.obs[future, 1] / 10)


def test_without_a_past_share_the_samples_are_those_of_plain_her():
    episodes = labelled_episodes()
    plain = sample_transitions(episodes, 500, np.random.default_rng(5), 0.8, exact_reward)
    zero = sample_transitions(episodes, 500, np.random.default_rng(5), 0.8, exact_reward, past_share=0.0)
    assert np.array_equal(plain.goal, zero.goal) and np.array_equal(plain.obs, zero.obs)


@pytest.mark.parametrize(("k", "p"), [(4, 0.8), (1, 0.5), (0, 0.0)])
def test_future_probability(k, p):
    assert relabel_probability(GoalStrategy.future, k) == pytest.approx(p)


def test_n_step_transitions_sum_discounted_rewards_up_to_the_episode_end():
    gamma, n = 0.5, 3
    batch = sample_transitions(
        labelled_episodes(), 4000, np.random.default_rng(7), 1.0, exact_reward, n_step=n, gamma=gamma
    )
    t = batch.obs[:, 1] / 10
    f = batch.goal[:, 1]  # relabelled goal (e, f, 0): only the step reaching t + 1 = f earns 0
    steps = np.minimum(n, T - t)
    reached_at = f - t - 1  # offset of the step that reaches the goal
    hit = (reached_at >= 0) & (reached_at < steps)
    expected = -np.sum([gamma**i * (i < steps) for i in range(n)], axis=0) + np.where(
        hit, gamma**reached_at, 0
    )
    assert np.allclose(batch.reward, expected)
    assert np.array_equal(batch.next_obs[:, 1] / 10, t + steps)
    assert np.allclose(batch.discount, gamma**steps)
    assert set(np.unique(steps)) == {1, 2, 3}  # cut at the episode's end
    one_step = sample_transitions(labelled_episodes(), 50, np.random.default_rng(7), 1.0, exact_reward)
    assert one_step.discount is None


def cut(episodes: Episodes, lengths: list[int]) -> Episodes:
    """``episodes`` ended after ``lengths`` steps, padded as the rollout pads them (the end
    repeated): values past an episode's end are marked 99 in obs, to catch padding drawn."""
    obs, achieved = episodes.obs.copy(), episodes.achieved_goal.copy()
    for i, end in enumerate(lengths):
        achieved[i, end + 1 :] = achieved[i, end]
        obs[i, end + 1 :] = 99.0
    return episodes._replace(obs=obs, achieved_goal=achieved, length=np.asarray(lengths))


def reached_exactly(achieved: np.ndarray, goal: np.ndarray) -> np.ndarray:
    return np.linalg.norm(achieved - goal, axis=-1) <= 1e-6


def test_steps_of_mixed_lengths_are_drawn_uniformly_and_never_padding():
    episodes = cut(labelled_episodes(3), [10, 2, 5])
    batch = sample_transitions(episodes, 17_000, np.random.default_rng(0), 0.8, exact_reward)
    episode, t = batch.obs[:, 0].astype(int) // 10, batch.obs[:, 1].astype(int) // 10
    assert np.all(t < np.array([10, 2, 5])[episode])  # no step past an episode's end
    assert not np.any(batch.next_obs == 99.0)
    # Uniform over the 17 stored steps: each episode in proportion to its length.
    shares = np.bincount(episode, minlength=3) / len(episode)
    assert shares == pytest.approx([10 / 17, 2 / 17, 5 / 17], abs=0.01)
    # Relabelled goals come from the episode's own steps, up to its end and not beyond.
    relabelled = batch.goal[:, 2] == 0.0
    assert np.all(batch.goal[relabelled, 0] == episode[relabelled])
    future = batch.goal[relabelled, 1]
    assert np.all(future > t[relabelled]) and np.all(future <= np.array([10, 2, 5])[episode[relabelled]])


def test_full_episodes_are_drawn_as_before_episodes_could_end():
    # Every episode at the time limit: an episode, then a step, as runs written before drew them.
    episodes = labelled_episodes(4)
    batch = sample_transitions(episodes, 64, np.random.default_rng(3), 0.8, exact_reward)
    rng = np.random.default_rng(3)
    episode, t = rng.integers(0, 4, size=64), rng.integers(0, T, size=64)
    assert np.array_equal(batch.obs, episodes.obs[episode, t])


def test_a_transition_is_terminal_exactly_where_its_goal_ends_the_episode():
    episodes = cut(labelled_episodes(2), [10, 4])
    batch = sample_transitions(
        episodes, 4000, np.random.default_rng(1), 0.8, exact_reward, terminal_fn=reached_exactly
    )
    assert batch.terminal is not None
    # For every goal, relabelled or the episode's own: terminal where the next achieved goal is it.
    next_achieved = batch.next_obs[:, :3] / 10
    assert np.array_equal(batch.terminal == 1.0, reached_exactly(next_achieved, batch.goal))
    assert np.array_equal(batch.reward == 0.0, batch.terminal == 1.0)
    # The cut episode's last transition toward a goal not reached there is a truncation.
    last = (batch.obs[:, 0] == 10.0) & (batch.obs[:, 1] == 30.0)  # episode 1, t = 3
    assert np.any(last & (batch.terminal == 0.0)) and np.any(last & (batch.terminal == 1.0))
    # Without a terminal verdict (a task that runs on), nothing is terminal.
    assert sample_transitions(episodes, 10, np.random.default_rng(1), 0.8, exact_reward).terminal is None


def test_n_step_sums_stop_at_the_terminal_step_and_at_the_episode_end():
    episodes = cut(labelled_episodes(1), [5])
    # Goal (0, 2, 0), reached by step 1: from t = 0 the sum covers steps 0 and 1, then ends.
    goal = np.array([[0.0, 2.0, 0.0]], np.float32)
    episodes = episodes._replace(step_goal=np.repeat(goal[:, None], T, axis=1))
    batch = sample_transitions(
        episodes,
        400,
        np.random.default_rng(2),
        0.0,
        exact_reward,
        n_step=3,
        gamma=0.5,
        terminal_fn=reached_exactly,
    )
    t = batch.obs[:, 1].astype(int) // 10
    from_zero, from_one = t == 0, t == 1
    assert np.all(batch.terminal[from_zero | from_one] == 1.0)
    assert batch.reward[from_zero] == pytest.approx(-1.0)  # -1, then 0 at the goal; nothing after
    assert batch.reward[from_one] == pytest.approx(0.0)
    # From t = 3 of 5 steps: two rewards, then the episode's end, which bootstraps.
    from_three = t == 3
    assert np.all(batch.terminal[from_three] == 0.0)
    assert batch.reward[from_three] == pytest.approx(-1.5) and batch.discount[from_three] == pytest.approx(
        0.25
    )
    assert np.all(batch.next_obs[from_three, 1] == 50.0)


def test_a_reward_that_reaches_no_goal_is_refused():
    from dtd.envs.goals import measure_rewards

    class Constant:
        unwrapped = None

        def reset(self, seed=None):
            return {"achieved_goal": np.zeros(2), "desired_goal": np.ones(2)}, {}

        def compute_reward(self, achieved, goal, info):
            return np.zeros(len(goal))

    env = Constant()
    env.unwrapped = env
    with pytest.raises(Exception, match="same reward"):
        measure_rewards(env, np.zeros(2), np.ones(2), None, "constant")
