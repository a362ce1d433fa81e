"""Goal-conditioned DDPG: the paper's learner, at both levels of ``--preset paper``."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from dtd.agents.learner import GoalLearner
from dtd.agents.networks import Actor, Critic
from dtd.agents.records import Batch


class DDPGLearner(GoalLearner):
    """DDPG: a deterministic actor mu(o, g) and one critic Q(o, g, a), with Polyak targets.
    Explores by the noise the agent adds to its actions."""

    def _networks(self, input_dim: int, action_dim: int) -> tuple[nn.Module, nn.Module]:
        config = self.config
        actor = Actor(input_dim, action_dim, config.hidden_sizes, config.layer_norm)
        critic = Critic(input_dim, action_dim, config.hidden_sizes, config.layer_norm)
        return actor, critic

    def _q(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return critic(inputs, self.head.critic_features(action, self.goal_norm))

    _value = _q

    def update(self, batch: Batch) -> dict[str, float]:
        """One gradient step of critic and actor (the actor's against the critic after its step,
        or with ``actor_after_critic`` off against the same critic as the critic's own, as
        baselines' HER does); returns diagnostics."""
        obs = self.tensor(batch.obs)
        next_obs = self.tensor(batch.next_obs)
        inputs = self.inputs(obs, batch.goal)
        next_inputs = self.inputs(next_obs, batch.goal)
        action = self.tensor(batch.action)
        reward = self.tensor(batch.reward)

        nets = self._train_nets
        with torch.no_grad():
            next_action = self._policy(nets["actor_target"], next_inputs, next_obs)[0]
            if batch.next_action is not None and batch.next_action_given is not None:
                given = torch.as_tensor(batch.next_action_given, device=self.device)[:, None]
                next_action = torch.where(given, self.tensor(batch.next_action), next_action)
            next_q = self._q(nets["critic_target"], next_inputs, next_action)
            if batch.next_value is not None and batch.next_value_given is not None:
                known = torch.as_tensor(batch.next_value_given, device=self.device)
                next_q = torch.where(known, self.tensor(batch.next_value), next_q)
            # A transition bootstraps unless the task ended the episode there for its goal: the
            # time limit (and an episode ended for another goal) cuts an episode, not its value.
            discount = self.gamma if batch.discount is None else self.tensor(batch.discount)
            if batch.terminal is not None:
                discount = discount * (1.0 - self.tensor(batch.terminal))
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
        chosen = None if rows is None else torch.as_tensor(rows, device=self.device)
        learning = self._actor_rows(inputs, obs, chosen)
        if learning is None:
            self._step(self._actor_params, self.actor_optim, None)
            return torch.zeros(())
        inputs, obs = learning
        policy_action, unit = self._policy(nets["actor"], inputs, obs)
        action_penalty = torch.mean(torch.square(unit))
        actor_loss = (
            -self._q(nets["critic"], inputs, policy_action).mean() + self.config.action_l2 * action_penalty
        )
        self._step(self._actor_params, self.actor_optim, actor_loss)
        return actor_loss
