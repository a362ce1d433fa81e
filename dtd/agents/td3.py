"""Goal-conditioned TD3 (Fujimoto et al., 2018): twin critics and the lower of their targets,
a smoothed target policy, and an actor that steps less often than the critics."""

from __future__ import annotations

import torch
from torch import nn

from dtd.agents.goal_learner import GoalLearner, StepTensors
from dtd.agents.networks import Actor, CriticEnsemble


class TD3Learner(GoalLearner):
    """A deterministic actor, ``config.critics`` critics (two in the paper) whose lowest value
    is the target, noise on the target actor's action, and an actor step every
    ``config.actor_delay`` updates up the first critic. Explores by the agent's action noise."""

    def _networks(self, input_dim: int, action_dim: int) -> tuple[nn.Module, nn.Module]:
        config = self.config
        actor = Actor(input_dim, action_dim, config.hidden_sizes, config.layer_norm)
        critic = CriticEnsemble(
            input_dim, action_dim, config.hidden_sizes, config.critics, 1, config.layer_norm
        )
        return actor, critic

    @property
    def actor_delay(self) -> int:
        return self.config.actor_delay

    def _critic_values(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """(N, critics) each critic's value of ``action``."""
        return critic(inputs, self._features(action)).squeeze(-1)

    def _value(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self._critic_values(critic, inputs, action)[:, 0]

    def _next_value(self, step: StepTensors) -> torch.Tensor:
        """min_i Q_i'(o', g, mu'(o', g) + clipped noise)."""
        assert self.actor_target is not None
        unit = self.actor_target(step.next_inputs)
        clip = self.config.target_noise_clip
        noise = torch.clamp(torch.randn_like(unit) * self.config.target_noise, -clip, clip)
        next_action = self.head(torch.clamp(unit + noise, -1.0, 1.0), step.next_obs)
        next_action = self._given_next_action(step, next_action)
        return (
            self._critic_values(self.critic_target, step.next_inputs, next_action)
            .min(dim=1, keepdim=True)
            .values
        )
