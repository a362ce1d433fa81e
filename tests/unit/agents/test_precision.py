"""bfloat16 updates: the networks' passes in bfloat16, what they learn against stays float32, and
an update's critic values and target stay close to a float32 copy's on the same batch."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest
import torch

from dtd.agents.learners import make_learner
from dtd.agents.networks import BoxActionHead
from dtd.agents.records import Batch
from dtd.config import LearnerConfig, LearnerKind

OBS, GOAL, ACT = 25, 3, 4
CONFIG = LearnerConfig(hidden_sizes=(256, 256, 256), batch_size=256)
# A value of about -15 (FetchPush's critics late in training) is held by bfloat16 to steps of
# 1/16; a float32 output layer keeps the error a hundred times smaller (measured: mean 3e-4).
VALUE_TOLERANCE = 0.005


def random_batch(rng: np.random.Generator, size: int = 256) -> Batch:
    return Batch(
        obs=rng.normal(size=(size, OBS)).astype(np.float32),
        goal=rng.normal(size=(size, GOAL)).astype(np.float32),
        action=rng.uniform(-1, 1, size=(size, ACT)).astype(np.float32),
        reward=-rng.integers(0, 2, size=size).astype(np.float32),
        next_obs=rng.normal(size=(size, OBS)).astype(np.float32),
    )


def twins(kind: LearnerKind):
    """A float32 learner, trained a little and its values moved to about -15, and a bfloat16
    copy of it (same parameters)."""
    torch.manual_seed(0)
    config = dataclasses.replace(CONFIG, learner=kind)
    full = make_learner(OBS, GOAL, ACT, BoxActionHead(1.0), config, 0.98, (-1.0, 0.0))
    rng = np.random.default_rng(0)
    full.update_normalizers(rng.normal(size=(1000, OBS)), rng.normal(size=(1000, GOAL)))
    for _ in range(5):
        full.update(random_batch(rng))
    with torch.no_grad():
        full.critic.body[-1].bias.add_(-15.0)
        full.critic_target.load_state_dict(full.critic.state_dict())
    lowered = copy.deepcopy(full)
    lowered.precision = torch.bfloat16
    return full, lowered, rng


@pytest.mark.parametrize("kind", [LearnerKind.ddpg, LearnerKind.td3, LearnerKind.tqc])
def test_a_bfloat16_updates_values_and_target_stay_near_float32s(kind):
    full, lowered, rng = twins(kind)
    batch = random_batch(rng)
    step_full, step_lowered = full.step_tensors(batch), lowered.step_tensors(batch)
    torch.manual_seed(1)  # the same target-policy noise or samples
    target_full = full.target(step_full)
    torch.manual_seed(1)
    target_lowered = lowered.target(step_lowered)
    assert target_lowered.dtype == torch.float32
    assert target_full.mean().item() < -10.0
    with torch.no_grad():
        values_full = full._critic_values(full.critic, step_full.inputs, step_full.action)
        with lowered._lowered():
            values_lowered = lowered._critic_values(lowered.critic, step_lowered.inputs, step_lowered.action)
    assert values_lowered.dtype == torch.float32  # the output layer is float32
    assert (target_lowered - target_full).abs().mean().item() < VALUE_TOLERANCE
    assert (values_lowered - values_full).abs().mean().item() < VALUE_TOLERANCE
    # bfloat16 it is: the hidden layers' rounding shows.
    assert not torch.equal(values_lowered, values_full)


def test_a_bfloat16_update_keeps_parameters_and_optimiser_state_float32_and_acts_in_float32():
    full, lowered, rng = twins(LearnerKind.ddpg)
    batch = random_batch(rng)
    metrics = lowered.update(batch)
    assert all(np.isfinite(value) for value in metrics.values())
    for net in (lowered.actor, lowered.critic, lowered.critic_target, lowered.actor_target):
        assert all(param.dtype == torch.float32 for param in net.parameters())
    for state in lowered.critic_optim.state.values():
        assert state["exp_avg"].dtype == torch.float32
    # Acting is float32 whatever the update's precision: the same parameters act alike.
    full.load_state_dict(lowered.state_dict())
    assert np.array_equal(full.act(batch.obs, batch.goal), lowered.act(batch.obs, batch.goal))


def test_a_bfloat16_step_moves_the_parameters_as_a_float32_step_does():
    full, lowered, rng = twins(LearnerKind.td3)
    before = [param.clone() for param in full.critic.parameters()]
    batch = random_batch(rng)
    full.update(batch)
    lowered.update(batch)
    steps_full = torch.cat([(p - b).flatten() for p, b in zip(full.critic.parameters(), before, strict=True)])
    steps_lowered = torch.cat(
        [(p - b).flatten() for p, b in zip(lowered.critic.parameters(), before, strict=True)]
    )
    # Adam's steps are about the learning rate each; their directions agree.
    cosine = torch.nn.functional.cosine_similarity(steps_full, steps_lowered, dim=0)
    assert cosine.item() > 0.9
