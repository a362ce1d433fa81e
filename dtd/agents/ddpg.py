"""Goal-conditioned DDPG: the paper's learner, at both levels of ``--preset paper``."""

from __future__ import annotations

import torch
from torch import nn

from dtd.agents.goal_learner import GoalLearner, StepTensors
from dtd.agents.networks import Actor, Critic


class DDPGLearner(GoalLearner):
    """DDPG: a deterministic actor mu(o, g) and one critic Q(o, g, a), with Polyak targets.
    Explores by the noise the agent adds to its actions."""

    def _networks(self, input_dim: int, action_dim: int) -> tuple[nn.Module, nn.Module]:
        config = self.config
        actor = Actor(input_dim, action_dim, config.hidden_sizes, config.layer_norm)
        critic = Critic(input_dim, action_dim, config.hidden_sizes, config.layer_norm)
        return actor, critic

    def _value(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return critic(inputs, self._features(action))

    def _critic_values(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self._value(critic, inputs, action)[:, None]

    def _next_value(self, step: StepTensors) -> torch.Tensor:
        """Q'(o', g, mu'(o', g))."""
        assert self.actor_target is not None
        next_action = self._policy(self.actor_target, step.next_inputs, step.next_obs)[0]
        next_action = self._given_next_action(step, next_action)
        return self._value(self.critic_target, step.next_inputs, next_action)[:, None]
