"""TD3, SAC and TQC: their targets and losses against values computed by hand on tiny batches,
the temperature's gradient, the squashed Gaussian's density, and what every learner promises
(parameters move, state round-trips to the same actions, terminal rows do not bootstrap)."""

from __future__ import annotations

import dataclasses
from copy import deepcopy

import numpy as np
import pytest
import torch
from torch import nn

from dtd.agents.learners import make_learner
from dtd.agents.networks import BoxActionHead, CriticEnsemble, GaussianActor
from dtd.agents.records import Batch
from dtd.agents.sac import SACLearner, TQCLearner, quantile_huber_loss
from dtd.agents.td3 import TD3Learner
from dtd.config import LearnerConfig, LearnerKind

OBS, GOAL, ACT = 5, 3, 2
GAMMA = 0.9
SMALL = LearnerConfig(hidden_sizes=(16, 16), batch_size=8)


def learner_of(kind: LearnerKind, seed: int = 0, **settings):
    torch.manual_seed(seed)
    config = dataclasses.replace(SMALL, learner=kind, **settings)
    return make_learner(OBS, GOAL, ACT, BoxActionHead(2.0), config, GAMMA, (-1.0, 0.0))


def random_batch(rng: np.random.Generator, size: int = 8, **fields) -> Batch:
    return Batch(
        obs=rng.normal(size=(size, OBS)).astype(np.float32),
        goal=rng.normal(size=(size, GOAL)).astype(np.float32),
        action=rng.uniform(-2, 2, size=(size, ACT)).astype(np.float32),
        reward=-rng.integers(0, 2, size=size).astype(np.float32),
        next_obs=rng.normal(size=(size, OBS)).astype(np.float32),
        **fields,
    )


def member_values(critic: CriticEnsemble, inputs: torch.Tensor, features: torch.Tensor) -> torch.Tensor:
    """(N, members, outputs) each critic's output, computed member by member as a plain MLP."""
    layers = [layer for layer in critic.body if not isinstance(layer, nn.ReLU)]
    outputs = []
    for member in range(critic.members):
        hidden = torch.cat([inputs, features], dim=-1)
        for index, layer in enumerate(layers):
            hidden = hidden @ layer.weight[member] + layer.bias[member]
            if index < len(layers) - 1:
                hidden = torch.relu(hidden)
        outputs.append(hidden)
    return torch.stack(outputs, dim=1)


def test_the_critic_ensemble_is_its_members_side_by_side():
    torch.manual_seed(0)
    critic = CriticEnsemble(4, 2, (8, 8), members=3, outputs=5)
    inputs, features = torch.randn(6, 4), torch.randn(6, 2)
    assert critic(inputs, features).shape == (6, 3, 5)
    torch.testing.assert_close(critic(inputs, features), member_values(critic, inputs, features))
    # The members start apart (each initialised as its own layer).
    assert not torch.allclose(critic.body[0].weight[0], critic.body[0].weight[1])


def test_td3_target_is_the_lower_twin_of_the_smoothed_target_action():
    learner = learner_of(LearnerKind.td3, target_noise=0.0)
    assert isinstance(learner, TD3Learner)
    rng = np.random.default_rng(0)
    batch = random_batch(rng)
    step = learner.step_tensors(batch)
    with torch.no_grad():
        next_action = 2.0 * learner.actor_target(step.next_inputs)
        values = member_values(learner.critic_target, step.next_inputs, next_action / 2.0)[..., 0]
        by_hand = step.reward + GAMMA * torch.minimum(values[:, 0], values[:, 1])
    torch.testing.assert_close(learner.target(step)[:, 0], torch.clamp(by_hand, -1 / (1 - GAMMA), 0.0))


def test_td3_target_noise_is_clipped_and_the_action_kept_in_bounds():
    learner = learner_of(LearnerKind.td3, target_noise=100.0, target_noise_clip=0.1)
    step = learner.step_tensors(random_batch(np.random.default_rng(1), size=256))
    seen = []

    def head(unit, obs):
        seen.append(unit)
        return 2.0 * unit

    learner.head.forward = head
    learner.target(step)
    with torch.no_grad():
        mean = learner.actor_target(step.next_inputs)
    assert torch.all((seen[0] - mean).abs() <= 0.1 + 1e-6)
    assert torch.all(seen[0].abs() <= 1.0)
    # Noise that large is at the clip almost everywhere not cut by the action's bound.
    inside = (mean.abs() < 0.85).flatten()
    assert torch.allclose((seen[0] - mean).abs().flatten()[inside], torch.tensor(0.1), atol=1e-6)


def test_td3_actor_steps_on_every_delay_th_update_only():
    learner = learner_of(LearnerKind.td3, actor_delay=3)
    rng = np.random.default_rng(2)
    before = [p.clone() for p in learner.actor.parameters()]
    reported = []
    for update in range(6):
        reported.append("actor_loss" in learner.update(random_batch(rng)))
        moved = any(not torch.equal(b, p) for b, p in zip(before, learner.actor.parameters(), strict=True))
        assert moved == (update >= 2)
    assert reported == [False, False, True, False, False, True]


def test_tqc_target_pools_every_critics_atoms_and_drops_the_highest():
    learner = learner_of(LearnerKind.tqc, critics=2, quantiles=3, dropped_quantiles=1)
    assert isinstance(learner, TQCLearner)
    atoms = torch.tensor([[[5.0, -1.0, 2.0], [0.5, 9.0, -3.0]], [[1.0, 1.0, 1.0], [0.0, -2.0, 4.0]]])
    learner.critic_target = lambda inputs, features: atoms
    log_prob = torch.tensor([0.5, -1.0])
    learner._sample = lambda inputs: (torch.zeros(2, ACT), log_prob)
    batch = Batch(
        obs=np.zeros((2, OBS), np.float32),
        goal=np.zeros((2, GOAL), np.float32),
        action=np.zeros((2, ACT), np.float32),
        reward=np.array([-1.0, 0.0], np.float32),
        next_obs=np.zeros((2, OBS), np.float32),
    )
    alpha = learner.temperature.item()
    # Pooled: row 0 [-3, -1, 0.5, 2, 5, 9], row 1 [-2, 0, 1, 1, 1, 4]; the top 2 of 6 dropped
    # (one per critic); the kept atoms are a set, in no order.
    kept = torch.tensor([[-3.0, -1.0, 0.5, 2.0], [-2.0, 0.0, 1.0, 1.0]])
    by_hand = torch.tensor([[-1.0], [0.0]]) + GAMMA * (kept - alpha * log_prob[:, None])
    target = torch.sort(learner.target(learner.step_tensors(batch)), dim=1).values
    torch.testing.assert_close(target, torch.clamp(by_hand, -1 / (1 - GAMMA), 0.0))


def test_sac_target_is_the_lower_twin_less_the_entropy_term_and_a_given_action_has_none():
    learner = learner_of(LearnerKind.sac, critics=2)
    assert isinstance(learner, SACLearner)
    values = torch.tensor([[[-2.0], [-3.0]], [[-1.0], [-0.5]]])
    learner.critic_target = lambda inputs, features: values
    learner._sample = lambda inputs: (torch.zeros(2, ACT), torch.tensor([2.0, 2.0]))
    batch = Batch(
        obs=np.zeros((2, OBS), np.float32),
        goal=np.zeros((2, GOAL), np.float32),
        action=np.zeros((2, ACT), np.float32),
        reward=np.array([-1.0, -1.0], np.float32),
        next_obs=np.zeros((2, OBS), np.float32),
        next_action=np.zeros((2, ACT), np.float32),
        next_action_given=np.array([False, True]),
    )
    alpha = learner.temperature.item()
    expected = torch.tensor([[-1.0 + GAMMA * (-3.0 - alpha * 2.0)], [-1.0 + GAMMA * -1.0]])
    torch.testing.assert_close(learner.target(learner.step_tensors(batch)), expected)


def test_quantile_huber_loss_by_hand():
    # Quantiles 0 and 1 at levels 1/4 and 3/4 against atoms 0.5 and 3: deltas 0.5, 3, -0.5, 2.
    # Huber: 0.125, 2.5, 0.125, 1.5; weights |tau - [delta < 0]|: 1/4, 1/4, 1/4, 3/4.
    quantiles = torch.tensor([[[0.0, 1.0]]])
    target = torch.tensor([[0.5, 3.0]])
    by_hand = (0.25 * 0.125 + 0.25 * 2.5 + 0.25 * 0.125 + 0.75 * 1.5) / 4
    assert quantile_huber_loss(quantiles, target).item() == pytest.approx(by_hand)


def pairwise_quantile_huber(quantiles: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """The loss as its definition reads: every quantile against every target atom."""
    count = quantiles.shape[-1]
    levels = (torch.arange(count, dtype=quantiles.dtype) + 0.5) / count
    delta = target[:, None, None, :] - quantiles[..., None]
    weight = torch.abs(levels[:, None] - (delta < 0).float())
    huber = torch.where(delta.abs() <= 1.0, 0.5 * delta.square(), delta.abs() - 0.5)
    return torch.mean(weight * huber)


@pytest.mark.parametrize(("scale", "shift"), [(0.3, 0.0), (2.0, -15.0), (10.0, -30.0)])
def test_the_quantile_huber_loss_and_its_gradient_are_the_pairwise_ones(scale, shift):
    generator = torch.Generator().manual_seed(0)
    quantiles = (torch.randn(64, 2, 25, generator=generator) * scale + shift).requires_grad_()
    target = torch.randn(64, 46, generator=generator) * scale + shift  # in no order
    target[:3, 10] = quantiles[:3, 0, 0].detach()  # ties
    target[:3, 11] = quantiles[:3, 0, 1].detach() + 1.0  # at the Huber's kink
    target[5] = target[5, :1]  # one value throughout (a known next value)
    ours = quantile_huber_loss(quantiles, target)
    (ours_grad,) = torch.autograd.grad(ours, quantiles)
    theirs = pairwise_quantile_huber(quantiles, target)
    (theirs_grad,) = torch.autograd.grad(theirs, quantiles)
    torch.testing.assert_close(ours, theirs, rtol=1e-5, atol=1e-7)
    torch.testing.assert_close(ours_grad, theirs_grad, rtol=1e-4, atol=1e-9)


def test_quantiles_learn_the_quantiles_of_their_targets():
    quantiles = torch.zeros(1, 1, 4, requires_grad=True)
    optimiser = torch.optim.Adam([quantiles], lr=0.5)
    samples = torch.linspace(0.0, 100.0, 401)[None]
    for _ in range(3000):
        optimiser.zero_grad()
        quantile_huber_loss(quantiles, samples).backward()
        optimiser.step()
    # Levels 1/8, 3/8, 5/8, 7/8 of a uniform on [0, 100] (the Huber's kink at 1 moves them by
    # about 0.3 on this grid; a squared loss would bring all four to the mean, 50).
    torch.testing.assert_close(
        quantiles.detach().flatten(), torch.tensor([12.5, 37.5, 62.5, 87.5]), atol=0.5, rtol=0
    )


def test_the_squashed_gaussian_density_is_torchs():
    torch.manual_seed(0)
    actor = GaussianActor(4, 3, (8,))
    inputs, noise = torch.randn(10, 4), torch.randn(10, 3)
    unit, log_prob = actor.sample(inputs, noise)
    mean, log_std = actor.distribution(inputs)
    squashed = torch.distributions.TransformedDistribution(
        torch.distributions.Normal(mean, log_std.exp()), [torch.distributions.TanhTransform()]
    )
    torch.testing.assert_close(unit, torch.tanh(mean + log_std.exp() * noise))
    torch.testing.assert_close(log_prob, squashed.log_prob(unit).sum(-1), atol=1e-3, rtol=1e-4)
    assert torch.all(log_std >= GaussianActor.LOG_STD_MIN) and torch.all(log_std <= GaussianActor.LOG_STD_MAX)


def test_the_temperature_gradient_is_minus_the_entropy_gap():
    learner = learner_of(LearnerKind.sac, initial_temperature=0.5)
    log_prob = torch.tensor([1.0, -3.0, 0.5, 0.0])
    sample = learner._sample

    def fixed(inputs):
        unit, _ = sample(inputs)
        return unit, log_prob + 0.0 * unit.sum()

    learner._sample = fixed
    grads = []
    learner.temperature_optim.step = lambda: grads.append(learner.log_temperature.grad.clone())
    rng = np.random.default_rng(3)
    learner.update(random_batch(rng, size=4))
    # loss = -log(alpha) * mean(log pi + target entropy); target entropy -|A| = -2.
    assert grads[0].item() == pytest.approx(-(log_prob.mean().item() - 2.0))


def test_the_temperature_falls_while_the_policy_is_more_random_than_its_target():
    learner = learner_of(LearnerKind.sac, target_entropy=-50.0)
    rng = np.random.default_rng(4)
    start = learner.temperature.item()
    metrics = [learner.update(random_batch(rng)) for _ in range(20)]
    assert learner.temperature.item() < start
    assert metrics[-1]["temperature"] == pytest.approx(learner.temperature.item(), rel=0.05)


@pytest.mark.parametrize("kind", [LearnerKind.td3, LearnerKind.sac, LearnerKind.tqc])
def test_terminal_rows_target_the_reward_alone(kind):
    learner = learner_of(kind)
    rng = np.random.default_rng(5)
    batch = random_batch(rng, terminal=np.ones(8, np.float32))
    target = learner.target(learner.step_tensors(batch)).reshape(8, -1)
    reward = torch.as_tensor(batch.reward)[:, None]
    torch.testing.assert_close(target, reward.expand_as(target))


@pytest.mark.parametrize("kind", [LearnerKind.td3, LearnerKind.sac, LearnerKind.tqc])
def test_a_known_next_value_replaces_the_critics(kind):
    learner = learner_of(kind)
    rng = np.random.default_rng(6)
    batch = random_batch(
        rng, next_value=np.full(8, -2.0, np.float32), next_value_given=np.array([True] * 4 + [False] * 4)
    )
    target = learner.target(learner.step_tensors(batch)).reshape(8, -1)
    expected = torch.as_tensor(batch.reward[:4])[:, None] + GAMMA * -2.0
    torch.testing.assert_close(target[:4], expected.expand_as(target[:4]))


@pytest.mark.parametrize("kind", list(LearnerKind))
def test_every_learner_moves_its_networks_and_round_trips_its_state(kind):
    learner = learner_of(kind, actor_delay=1)
    rng = np.random.default_rng(7)
    learner.update_normalizers(rng.normal(size=(64, OBS)), rng.normal(size=(64, GOAL)))
    actor = [p.clone() for p in learner.actor.parameters()]
    critic = [p.clone() for p in learner.critic.parameters()]
    for _ in range(3):
        metrics = learner.update(random_batch(rng))
    learner.update_target()
    assert all(np.isfinite(value) for value in metrics.values())
    assert any(not torch.equal(b, p) for b, p in zip(actor, learner.actor.parameters(), strict=True))
    assert any(not torch.equal(b, p) for b, p in zip(critic, learner.critic.parameters(), strict=True))
    copy = learner_of(kind, seed=1, actor_delay=1)
    # A deep copy, as a checkpoint file gives: an optimiser loads tensors on its device as they are.
    copy.load_state_dict(deepcopy(learner.state_dict()))
    obs, goal = rng.normal(size=(6, OBS)), rng.normal(size=(6, GOAL))
    np.testing.assert_array_equal(copy.act(obs, goal), learner.act(obs, goal))
    batch = random_batch(rng)
    torch.manual_seed(9)
    after = learner.update(batch)
    torch.manual_seed(9)
    assert copy.update(batch) == after


@pytest.mark.parametrize("kind", [LearnerKind.sac, LearnerKind.tqc])
def test_a_stochastic_learner_explores_by_its_own_samples_drawn_from_the_generator(kind):
    learner = learner_of(kind)
    rng = np.random.default_rng(8)
    obs, goal = rng.normal(size=(200, OBS)), rng.normal(size=(200, GOAL))
    first = learner.act(obs, goal, np.random.default_rng(1))
    again = learner.act(obs, goal, np.random.default_rng(1))
    np.testing.assert_array_equal(first, again)
    deterministic = learner.act(obs, goal)
    assert not np.allclose(first, deterministic)
    assert np.all(np.abs(first) <= 2.0)


def test_a_deterministic_learner_ignores_the_generator():
    learner = learner_of(LearnerKind.td3)
    rng = np.random.default_rng(9)
    obs, goal = rng.normal(size=(5, OBS)), rng.normal(size=(5, GOAL))
    np.testing.assert_array_equal(learner.act(obs, goal, np.random.default_rng(0)), learner.act(obs, goal))


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA GPU on this machine")
@pytest.mark.parametrize("kind", list(LearnerKind))
def test_learners_train_on_a_gpu_and_their_state_loads_on_the_cpu(kind):
    torch.manual_seed(0)
    config = dataclasses.replace(SMALL, learner=kind)
    learner = make_learner(OBS, GOAL, ACT, BoxActionHead(2.0), config, GAMMA, (-1.0, 0.0), device="cuda")
    rng = np.random.default_rng(10)
    learner.update_normalizers(rng.normal(size=(64, OBS)), rng.normal(size=(64, GOAL)))
    for _ in range(5):
        learner.update(random_batch(rng))
    learner.update_target()
    assert next(learner.critic.parameters()).is_cuda
    obs, goal = rng.normal(size=(4, OBS)), rng.normal(size=(4, GOAL))
    on_gpu = learner.act(obs, goal)
    cpu = make_learner(OBS, GOAL, ACT, BoxActionHead(2.0), config, GAMMA, (-1.0, 0.0))
    cpu.load_state_dict(learner.state_dict())
    np.testing.assert_allclose(cpu.act(obs, goal), on_gpu, atol=1e-5)
