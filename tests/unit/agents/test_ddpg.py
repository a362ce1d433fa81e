"""The DDPG learner: updates, targets, and save/load giving the same actions."""

import copy
import dataclasses

import numpy as np
import pytest
import torch

from dtd.agents.buffer import EpisodeBuffer
from dtd.agents.ddpg import DDPGLearner
from dtd.agents.exploration import ActionNoise
from dtd.agents.flat import GoalConditionedAgent
from dtd.agents.her import GoalStrategy, HindsightSampling, relabel_probability
from dtd.agents.networks import BoxActionHead
from dtd.agents.records import Batch, Episodes
from dtd.config import LearnerConfig
from dtd.training.checkpoint import load_checkpoint, save_atomic
from tests.helpers import sparse_goals

OBS, GOAL, ACT, T = 5, 3, 2, 6
SMALL = LearnerConfig(hidden_sizes=(32, 32), batch_size=16)


def make_learner(config: LearnerConfig = SMALL, seed: int = 0) -> DDPGLearner:
    torch.manual_seed(seed)
    return DDPGLearner(
        OBS, GOAL, ACT, BoxActionHead(2.0), config=config, gamma=0.9, sparse_rewards=(-1.0, 0.0)
    )


def random_batch(rng: np.random.Generator, size: int = 16) -> Batch:
    return Batch(
        obs=rng.normal(size=(size, OBS)).astype(np.float32),
        goal=rng.normal(size=(size, GOAL)).astype(np.float32),
        action=rng.uniform(-2, 2, size=(size, ACT)).astype(np.float32),
        reward=-rng.integers(0, 2, size=size).astype(np.float32),
        next_obs=rng.normal(size=(size, OBS)).astype(np.float32),
    )


def random_episodes(rng: np.random.Generator, count: int = 4) -> Episodes:
    return Episodes(
        obs=rng.normal(size=(count, T + 1, OBS)).astype(np.float32),
        achieved_goal=rng.normal(size=(count, T + 1, GOAL)).astype(np.float32),
        action=rng.uniform(-2, 2, size=(count, T, ACT)).astype(np.float32),
        step_goal=rng.normal(size=(count, T, GOAL)).astype(np.float32),
        desired_goal=rng.normal(size=(count, GOAL)).astype(np.float32),
        success=np.zeros(count, np.float32),
        length=np.full(count, T),
    )


def test_actions_are_bounded_by_the_action_scale():
    learner = make_learner()
    actions = learner.act(np.full((8, OBS), 1e3), np.full((8, GOAL), -1e3))
    assert actions.shape == (8, ACT)
    assert np.all(np.abs(actions) <= 2.0)


def test_an_update_changes_actor_and_critic_but_not_targets():
    learner = make_learner()
    before = {
        name: [p.clone() for p in net.parameters()]
        for name, net in vars(learner).items()
        if isinstance(net, torch.nn.Module)
    }
    metrics = learner.update(random_batch(np.random.default_rng(0)))
    assert set(metrics) == {"critic_loss", "actor_loss", "q_mean", "target_mean"}
    for name, params in before.items():
        changed = any(
            not torch.equal(a, b) for a, b in zip(params, getattr(learner, name).parameters(), strict=True)
        )
        assert changed == (name in ("actor", "critic")), name


def test_an_update_is_plain_ddpg_critic_step_then_actor_step():
    # Reference: the textbook update with backward() and the per-tensor Adam.
    learner = make_learner()
    batch = random_batch(np.random.default_rng(3))
    reference = copy.deepcopy(learner)
    actor_optim = torch.optim.Adam(reference.actor.parameters(), lr=SMALL.actor_lr, foreach=False)
    critic_optim = torch.optim.Adam(reference.critic.parameters(), lr=SMALL.critic_lr, foreach=False)
    obs, next_obs = torch.as_tensor(batch.obs), torch.as_tensor(batch.next_obs)
    inputs, next_inputs = reference.inputs(obs, batch.goal), reference.inputs(next_obs, batch.goal)
    with torch.no_grad():
        next_action = reference.head(reference.actor_target(next_inputs), next_obs)
        next_q = reference.critic_target(next_inputs, next_action / 2.0)
        target = torch.clamp(torch.as_tensor(batch.reward) + 0.9 * next_q, -10.0, 0.0)
    critic_loss = torch.mean((reference.critic(inputs, torch.as_tensor(batch.action) / 2.0) - target) ** 2)
    critic_optim.zero_grad()
    critic_loss.backward()
    critic_optim.step()
    unit = reference.actor(inputs)
    actor_loss = -reference.critic(inputs, unit).mean() + SMALL.action_l2 * torch.mean(unit**2)
    actor_optim.zero_grad()
    actor_loss.backward()
    actor_optim.step()

    metrics = learner.update(batch)
    assert metrics["critic_loss"] == pytest.approx(critic_loss.item(), rel=1e-5)
    assert metrics["actor_loss"] == pytest.approx(actor_loss.item(), rel=1e-5, abs=1e-6)
    for net in ("actor", "critic"):
        for ours, theirs in zip(
            getattr(learner, net).parameters(), getattr(reference, net).parameters(), strict=True
        ):
            assert torch.allclose(ours, theirs, atol=1e-6), net


def test_target_moves_by_one_minus_polyak():
    learner = make_learner(dataclasses.replace(SMALL, polyak=0.75))
    learner.update(random_batch(np.random.default_rng(0)))
    online = [p.clone() for p in learner.critic.parameters()]
    target = [p.clone() for p in learner.critic_target.parameters()]
    learner.update_target()
    for o, t, new in zip(online, target, learner.critic_target.parameters(), strict=True):
        assert torch.allclose(new, 0.75 * t + 0.25 * o, atol=1e-6)


def test_layer_norm_normalises_every_hidden_layer_of_both_networks():
    learner = make_learner(dataclasses.replace(SMALL, layer_norm=True))
    for net in (learner.actor, learner.critic, learner.actor_target, learner.critic_target):
        norms = [m for m in net.modules() if isinstance(m, torch.nn.LayerNorm)]
        assert [n.normalized_shape for n in norms] == [(32,), (32,)]
    hidden = {}
    learner.critic.body[1].register_forward_hook(lambda m, i, out: hidden.update(out=out.detach()))
    rng = np.random.default_rng(0)
    batch = random_batch(rng)
    learner.critic(torch.from_numpy(np.hstack([batch.obs, batch.goal])), torch.from_numpy(batch.action / 2))
    assert torch.allclose(hidden["out"].mean(-1), torch.zeros(16), atol=1e-5)
    before = [p.clone() for p in learner.critic.parameters()]
    metrics = learner.update(batch)
    assert np.isfinite(metrics["critic_loss"])
    assert any(not torch.equal(b, p) for b, p in zip(before, learner.critic.parameters(), strict=True))
    assert not any(isinstance(m, torch.nn.LayerNorm) for m in make_learner().critic.modules())


def test_critic_targets_stay_in_the_return_range():
    learner = make_learner()
    with torch.no_grad():  # a critic that wildly overestimates
        learner.critic_target.body[-1].bias.fill_(1e3)
    metrics = learner.update(random_batch(np.random.default_rng(0)))
    assert -1 / (1 - 0.9) <= metrics["target_mean"] <= 0.0


@pytest.mark.parametrize("strategy", list(GoalStrategy))
def test_agent_checkpoint_round_trip_gives_the_same_actions(tmp_path, strategy):
    rng = np.random.default_rng(0)

    def agent(seed: int) -> GoalConditionedAgent:
        learner = make_learner(seed=seed)
        buffer = EpisodeBuffer(10, T, OBS, GOAL, ACT)
        noise = ActionNoise(0.2, 0.3, 2.0)
        goals = sparse_goals(lambda a, g: -np.ones(len(a), np.float32))
        sampling = HindsightSampling(relabel_probability(strategy, 4), goals.reward, learner.gamma)
        return GoalConditionedAgent(learner, buffer, goals, noise, sampling)

    trained = agent(seed=0)
    trained.store(random_episodes(rng), rng)
    trained.train(5, rng)
    save_atomic(tmp_path / "agent.pt", trained.state_dict())
    restored = agent(seed=1)
    restored.load_state_dict(load_checkpoint(tmp_path / "agent.pt"))

    obs, goal = rng.normal(size=(7, OBS)), rng.normal(size=(7, GOAL))
    assert not np.array_equal(agent(seed=1).act(obs, goal, False, rng), trained.act(obs, goal, False, rng))
    assert np.array_equal(restored.act(obs, goal, False, rng), trained.act(obs, goal, False, rng))
    # Training goes on identically from the restored state.
    rng_a, rng_b = np.random.default_rng(5), np.random.default_rng(5)
    assert trained.train(3, rng_a) == restored.train(3, rng_b)
    assert np.array_equal(restored.act(obs, goal, False, rng), trained.act(obs, goal, False, rng))


def test_exploration_noise_stays_in_bounds_and_takes_random_actions():
    noise = ActionNoise(noise_eps=0.2, random_eps=0.3, action_max=2.0)
    rng = np.random.default_rng(0)
    actions = np.full((10_000, ACT), 1.9, np.float32)
    noisy = noise(actions, rng)
    assert np.all(np.abs(noisy) <= 2.0)
    far = np.abs(noisy - 1.9).max(axis=1) > 1.5  # only a random action lands that far
    assert 0.2 < far.mean() < 0.3


def test_the_reference_update_order_steps_the_actor_against_the_critic_before_its_step():
    rng = np.random.default_rng(3)
    batch = random_batch(rng)
    together = make_learner(dataclasses.replace(SMALL, actor_after_critic=False))
    in_turn = make_learner(SMALL)
    still_critic = make_learner(dataclasses.replace(SMALL, critic_lr=1e-30))
    for learner in (together, in_turn, still_critic):
        learner.update(batch)

    def same(a: torch.nn.Module, b: torch.nn.Module) -> bool:
        return all(torch.allclose(x, y) for x, y in zip(a.parameters(), b.parameters(), strict=True))

    assert same(together.critic, in_turn.critic)  # the critic's step is the same either way
    assert same(together.actor, still_critic.actor)  # the actor saw the critic before its step
    assert not same(together.actor, in_turn.actor)


def test_glorot_initialisation_has_zero_biases_and_its_bounds():
    learner = make_learner(dataclasses.replace(SMALL, xavier_init=True))
    for net in (learner.actor, learner.critic):
        for layer in (m for m in net.modules() if isinstance(m, torch.nn.Linear)):
            fan_out, fan_in = layer.weight.shape
            bound = (6.0 / (fan_in + fan_out)) ** 0.5
            assert torch.all(layer.bias == 0) and layer.weight.abs().max() <= bound
            assert layer.weight.abs().max() > 0.8 * bound  # uniform up to the bound, not narrower
    default = make_learner(SMALL)
    assert any(torch.any(m.bias != 0) for m in default.actor.modules() if isinstance(m, torch.nn.Linear))


def test_known_next_values_replace_the_target_critics_estimate():
    learner = make_learner()
    rng = np.random.default_rng(4)
    batch = random_batch(rng)
    known = np.arange(16) % 2 == 0
    batch = batch._replace(next_value=np.full(16, -3.0, np.float32), next_value_given=known)
    with torch.no_grad():  # a target critic that says 0 everywhere
        for param in learner.critic_target.parameters():
            param.zero_()
    metrics = learner.update(batch)
    expected = np.where(known, batch.reward + 0.9 * -3.0, batch.reward)
    assert metrics["target_mean"] == pytest.approx(float(expected.mean()), rel=1e-6)


def test_the_actor_learns_only_from_its_rows():
    rng = np.random.default_rng(5)
    batch = random_batch(rng)
    rows = np.arange(16) < 5
    masked = make_learner()
    masked.update(batch._replace(actor_rows=rows))
    without_rows = make_learner()
    without_rows.update(batch._replace(actor_rows=np.zeros(16, bool)))  # a critic step only
    for unchanged, start in zip(
        without_rows.actor.parameters(), make_learner().actor.parameters(), strict=True
    ):
        assert torch.equal(unchanged, start)
    # The actor's step equals one taken on those 5 rows alone, against the same critic.
    subset = make_learner()
    subset.critic.load_state_dict(masked.critic.state_dict())
    inputs = subset.inputs(torch.as_tensor(batch.obs[rows]), batch.goal[rows])
    step = subset.step_tensors(batch)._replace(inputs=inputs, obs=torch.as_tensor(batch.obs[rows]))
    loss = subset._actor_step(step)["actor_loss"]
    for ours, theirs in zip(masked.actor.parameters(), subset.actor.parameters(), strict=True):
        assert torch.allclose(ours, theirs, atol=1e-6)
    assert np.isfinite(loss)


def test_a_per_row_discount_replaces_gamma():
    learner = make_learner()
    batch = random_batch(np.random.default_rng(6))
    with torch.no_grad():  # a target critic that says -1 everywhere
        for param in learner.critic_target.parameters():
            param.zero_()
        learner.critic_target.body[-1].bias.fill_(-1.0)
    discount = np.linspace(0.0, 0.8, 16).astype(np.float32)
    metrics = learner.update(batch._replace(discount=discount))
    assert metrics["target_mean"] == pytest.approx(float(np.mean(batch.reward - discount)), rel=1e-6)
