"""The one goal-conditioned DDPG learner, used for every agent and at every level."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np
import torch
from torch import nn

from dtd.agents.collective import ALONE, Collective
from dtd.agents.networks import ActionHead, Actor, Critic, xavier_initialise
from dtd.agents.normalizer import RunningNormalizer
from dtd.agents.records import Batch
from dtd.config import LearnerConfig
from dtd.envs.goals import SparseRewards, return_bounds


class DDPGLearner:
    """Actor mu(o, g), critic Q(o, g, a), their Polyak targets and the input normalisers.

    The ``head`` decides what an action is: a motor command (the low level) or a sub-goal
    (the high level). Learns from batches it is given; acting with exploration, collecting
    and relabelling are the caller's concern. With fellow data-parallel workers
    (``collective``), each update's gradients and the normalisers' statistics are theirs
    combined, so every worker's parameters stay the same.
    """

    def __init__(
        self,
        obs_dim: int,
        goal_dim: int,
        action_dim: int,
        head: ActionHead,
        config: LearnerConfig,
        gamma: float,
        sparse_rewards: SparseRewards,
        collective: Collective = ALONE,
    ) -> None:
        self.config = config
        self.collective = collective
        self.gamma = gamma
        # A sparse reward bounds the return (-1/0 per step: to [-1/(1-gamma), 0]); a dense one is
        # not clipped, rather than clipped to a range it does not have.
        bounds = return_bounds(sparse_rewards, gamma) if config.clip_return else None
        self.return_bounds = bounds or (-np.inf, np.inf)
        self.obs_norm = RunningNormalizer(obs_dim, config.norm_eps, config.norm_clip, collective)
        self.goal_norm = RunningNormalizer(goal_dim, config.norm_eps, config.norm_clip, collective)
        input_dim = obs_dim + goal_dim
        self.head = head
        self.actor = Actor(input_dim, action_dim, config.hidden_sizes, config.layer_norm)
        self.critic = Critic(input_dim, action_dim, config.hidden_sizes, config.layer_norm)
        if config.xavier_init:
            xavier_initialise(self.actor)
            xavier_initialise(self.critic)
        self.actor_target = _frozen_copy(self.actor)
        self.critic_target = _frozen_copy(self.critic)
        # The fused kernel does Adam's whole step in one pass (the default on CPU is a loop of
        # small per-tensor operations).
        self.actor_optim = torch.optim.Adam(self.actor.parameters(), lr=config.actor_lr, fused=True)
        self.critic_optim = torch.optim.Adam(self.critic.parameters(), lr=config.critic_lr, fused=True)
        self._actor_params = list(self.actor.parameters())
        self._critic_params = list(self.critic.parameters())
        # What update() runs: the networks themselves, or compiled views of them (compile()).
        self._train_nets: dict[str, nn.Module] = {
            "actor": self.actor,
            "critic": self.critic,
            "actor_target": self.actor_target,
            "critic_target": self.critic_target,
        }

    def compile(self) -> None:
        """Make :meth:`update` run ``torch.compile``d networks (same parameters; acting stays
        eager). The first updates then take about a minute to compile, once per process."""
        self._train_nets = {name: torch.compile(net) for name, net in self._train_nets.items()}

    def inputs(self, obs: np.ndarray | torch.Tensor, goal: np.ndarray | torch.Tensor) -> torch.Tensor:
        """Clipped, normalised o || g as the networks see it."""
        clip = self.config.obs_clip
        obs_t = torch.clamp(_float_tensor(obs), -clip, clip)
        goal_t = torch.clamp(_float_tensor(goal), -clip, clip)
        return torch.cat([self.obs_norm.normalize(obs_t), self.goal_norm.normalize(goal_t)], dim=-1)

    def _policy(
        self, actor: nn.Module, inputs: torch.Tensor, obs: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        unit = actor(inputs)
        return self.head(unit, obs), unit

    def _q(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return critic(inputs, self.head.critic_features(action, self.goal_norm))

    def action_of(self, obs: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """Deterministic actions mu(o, g) of raw (unnormalised) float32 tensors, inputs clipped
        and normalised and the action scaled as in acting (e.g. to trace the acting path)."""
        return self._policy(self.actor, self.inputs(obs, goal), obs)[0]

    def value_of(self, obs: torch.Tensor, goal: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """Q(o, g, a) of raw float32 tensors, as :meth:`q_values` computes it."""
        return self._q(self.critic, self.inputs(obs, goal), action)

    @torch.no_grad()
    def act(self, obs: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Deterministic actions mu(o, g) for a batch."""
        obs_t = torch.as_tensor(obs, dtype=torch.float32)
        return self.action_of(obs_t, torch.as_tensor(goal, dtype=torch.float32)).numpy()

    @torch.no_grad()
    def q_values(self, obs: np.ndarray, goal: np.ndarray, action: np.ndarray) -> np.ndarray:
        """Q(o, g, a) for a batch."""
        obs_t, goal_t, action_t = (torch.as_tensor(x, dtype=torch.float32) for x in (obs, goal, action))
        return self.value_of(obs_t, goal_t, action_t).numpy()

    def update_normalizers(self, obs: np.ndarray, goal: np.ndarray) -> None:
        """Add observations and goals to the running statistics of the inputs."""
        clip = self.config.obs_clip
        self.obs_norm.update(np.clip(obs, -clip, clip))
        self.goal_norm.update(np.clip(goal, -clip, clip))

    def update(self, batch: Batch) -> dict[str, float]:
        """One gradient step of critic and actor (the actor's against the critic after its step,
        or with ``actor_after_critic`` off against the same critic as the critic's own, as
        baselines' HER does); returns diagnostics."""
        obs = torch.as_tensor(batch.obs, dtype=torch.float32)
        next_obs = torch.as_tensor(batch.next_obs, dtype=torch.float32)
        inputs = self.inputs(obs, batch.goal)
        next_inputs = self.inputs(next_obs, batch.goal)
        action = torch.as_tensor(batch.action, dtype=torch.float32)
        reward = torch.as_tensor(batch.reward, dtype=torch.float32)

        nets = self._train_nets
        with torch.no_grad():
            next_action = self._policy(nets["actor_target"], next_inputs, next_obs)[0]
            if batch.next_action is not None and batch.next_action_given is not None:
                given = torch.as_tensor(batch.next_action_given)[:, None]
                next_action = torch.where(
                    given, torch.as_tensor(batch.next_action, dtype=torch.float32), next_action
                )
            next_q = self._q(nets["critic_target"], next_inputs, next_action)
            if batch.next_value is not None and batch.next_value_given is not None:
                known = torch.as_tensor(batch.next_value_given)
                next_q = torch.where(known, torch.as_tensor(batch.next_value, dtype=torch.float32), next_q)
            # A transition bootstraps unless the task ended the episode there for its goal: the
            # time limit (and an episode ended for another goal) cuts an episode, not its value.
            discount = self.gamma if batch.discount is None else torch.as_tensor(batch.discount)
            if batch.terminal is not None:
                discount = discount * (1.0 - torch.as_tensor(batch.terminal, dtype=torch.float32))
            target = torch.clamp(reward + discount * next_q, *self.return_bounds)
        q = self._q(nets["critic"], inputs, action)
        critic_loss = torch.mean(torch.square(q - target))
        self.critic_optim.zero_grad(set_to_none=True)
        critic_loss.backward()
        self.collective.average_gradients(self._critic_params)
        if self.config.actor_after_critic:
            self.critic_optim.step()
        actor_loss = self._actor_step(nets, inputs, obs, batch.actor_rows)
        if not self.config.actor_after_critic:  # both gradients came from the same parameters
            self.critic_optim.step()

        return {
            "critic_loss": critic_loss.item(),
            "actor_loss": actor_loss.item(),
            "q_mean": q.detach().mean().item(),
            "target_mean": target.mean().item(),
        }

    def _actor_step(
        self,
        nets: dict[str, nn.Module],
        inputs: torch.Tensor,
        obs: torch.Tensor,
        rows: np.ndarray | None = None,
    ) -> torch.Tensor:
        """One step of the actor up the critic's value, less its action penalty, on ``rows``
        of the batch (all without them); the loss (no step, and loss 0, without any row)."""
        if rows is not None:
            chosen = torch.as_tensor(rows)
            if not bool(chosen.any()):
                if self.collective.workers == 1:
                    return torch.zeros(())
                # The others step with their gradients: this worker adds zeros to the mean.
                for param in self._actor_params:
                    param.grad = torch.zeros_like(param)
                self.collective.average_gradients(self._actor_params)
                self.actor_optim.step()
                return torch.zeros(())
            inputs, obs = inputs[chosen], obs[chosen]
        policy_action, unit = self._policy(nets["actor"], inputs, obs)
        action_penalty = torch.mean(torch.square(unit))
        actor_loss = (
            -self._q(nets["critic"], inputs, policy_action).mean() + self.config.action_l2 * action_penalty
        )
        # Gradients for the actor's parameters only: the critic's weight gradients, which a
        # plain backward() would also compute here, are never used.
        grads = torch.autograd.grad(actor_loss, self._actor_params)
        for param, grad in zip(self._actor_params, grads, strict=True):
            param.grad = grad
        self.collective.average_gradients(self._actor_params)
        self.actor_optim.step()
        return actor_loss

    @torch.no_grad()
    def update_target(self) -> None:
        """Move the target networks toward the online ones by 1 - polyak."""
        weight = 1.0 - self.config.polyak
        for target, online in ((self.actor_target, self.actor), (self.critic_target, self.critic)):
            torch._foreach_lerp_(list(target.parameters()), list(online.parameters()), weight)

    def acting_state(self) -> dict[str, Any]:
        """What :meth:`act` needs (head, actor, normalisers), for a copy that only acts."""
        return {
            "head": self.head.state_dict(),
            "actor": self.actor.state_dict(),
            "obs_norm": self.obs_norm.state_dict(),
            "goal_norm": self.goal_norm.state_dict(),
        }

    def load_acting_state(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`acting_state` returned."""
        self.head.load_state_dict(state["head"])
        self.actor.load_state_dict(state["actor"])
        self.obs_norm.load_state_dict(state["obs_norm"])
        self.goal_norm.load_state_dict(state["goal_norm"])

    def explaining_state(self) -> dict[str, Any]:
        """The acting state and the critic: what acting and valuing need, nothing to train on."""
        return {**self.acting_state(), "critic": self.critic.state_dict()}

    def load_explaining_state(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`explaining_state` returned."""
        self.load_acting_state(state)
        self.critic.load_state_dict(state["critic"])

    def state_dict(self) -> dict[str, Any]:
        """Plain data: the acting state plus critic, target networks and optimisers."""
        return {
            **self.acting_state(),
            "critic": self.critic.state_dict(),
            "actor_target": self.actor_target.state_dict(),
            "critic_target": self.critic_target.state_dict(),
            "actor_optim": self.actor_optim.state_dict(),
            "critic_optim": self.critic_optim.state_dict(),
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`state_dict` returned."""
        self.load_acting_state(state)
        self.critic.load_state_dict(state["critic"])
        self.actor_target.load_state_dict(state["actor_target"])
        self.critic_target.load_state_dict(state["critic_target"])
        self.actor_optim.load_state_dict(state["actor_optim"])
        self.critic_optim.load_state_dict(state["critic_optim"])


def _float_tensor(values: np.ndarray | torch.Tensor) -> torch.Tensor:
    # A tensor passes through untouched, so that tracing the acting path (ONNX export) keeps
    # it an input rather than a constant.
    return values if isinstance(values, torch.Tensor) else torch.as_tensor(values, dtype=torch.float32)


def _frozen_copy(module: nn.Module) -> nn.Module:
    target = copy.deepcopy(module)
    for param in target.parameters():
        param.requires_grad_(False)
    return target
