"""Goal-conditioned TD3 (Fujimoto et al., 2018): twin critics and the lower of their targets,
a smoothed target policy, and an actor that steps less often than the critics."""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from dtd.agents.learner import GoalLearner, StepTensors
from dtd.agents.networks import Actor, CriticEnsemble
from dtd.agents.records import Batch


class TD3Learner(GoalLearner):
    """A deterministic actor, ``config.critics`` critics (two in the paper) whose lowest value
    is the target, noise on the target actor's action, and an actor step every
    ``config.actor_delay`` updates up the first critic. Explores by the agent's action noise."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.updates = 0
        """Critic updates so far: the actor steps on every ``actor_delay``-th."""

    def _networks(self, input_dim: int, action_dim: int) -> tuple[nn.Module, nn.Module]:
        config = self.config
        actor = Actor(input_dim, action_dim, config.hidden_sizes, config.layer_norm)
        critic = CriticEnsemble(
            input_dim, action_dim, config.hidden_sizes, config.critics, 1, config.layer_norm
        )
        return actor, critic

    def _values(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """(N, critics) each critic's value of ``action``."""
        return critic(inputs, self._features(action)).squeeze(-1)

    def _value(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self._values(critic, inputs, action)[:, 0]

    @torch.no_grad()
    def target(self, step: StepTensors) -> torch.Tensor:
        """(N,) r + discount * min_i Q_i'(o', g, mu'(o', g) + clipped noise), clipped to the
        return's range; a known next action or value replaces the target networks'."""
        nets = self._train_nets
        unit = nets["actor_target"](step.next_inputs)
        clip = self.config.target_noise_clip
        noise = torch.clamp(torch.randn_like(unit) * self.config.target_noise, -clip, clip)
        next_action = self.head(torch.clamp(unit + noise, -1.0, 1.0), step.next_obs)
        next_action = self._given_next_action(step, next_action)
        next_q = self._values(nets["critic_target"], step.next_inputs, next_action).min(dim=1).values
        if step.next_value is not None and step.next_value_given is not None:
            next_q = torch.where(step.next_value_given, step.next_value, next_q)
        return torch.clamp(step.reward + step.discount * next_q, *self.return_bounds)

    def update(self, batch: Batch) -> dict[str, float]:
        """One step of the critics; one of the actor on every ``actor_delay``-th call."""
        step = self.step_tensors(batch)
        target = self.target(step)
        q = self._values(self._train_nets["critic"], step.inputs, step.action)
        # Each critic's own mean squared error, summed: each learns at the rate of one alone.
        critic_loss = torch.square(q - target[:, None]).mean(dim=0).sum()
        actor_due = (self.updates + 1) % self.config.actor_delay == 0
        self.updates += 1
        if not self.config.actor_after_critic and actor_due:
            actor_loss = self._actor_step(step)
        self._step(self._critic_params, self.critic_optim, critic_loss)
        if self.config.actor_after_critic and actor_due:
            actor_loss = self._actor_step(step)
        metrics = {
            "critic_loss": critic_loss.item(),
            "q_mean": q.detach().mean().item(),
            "target_mean": target.mean().item(),
        }
        if actor_due:
            metrics["actor_loss"] = actor_loss
        return metrics

    def _actor_step(self, step: StepTensors) -> float:
        learning = self._actor_rows(step.inputs, step.obs, step.actor_rows)
        if learning is None:
            self._step(self._actor_params, self.actor_optim, None)
            return 0.0
        inputs, obs = learning
        action, unit = self._policy(self._train_nets["actor"], inputs, obs)
        loss = -self._value(self._train_nets["critic"], inputs, action).mean()
        loss = loss + self.config.action_l2 * torch.mean(torch.square(unit))
        self._step(self._actor_params, self.actor_optim, loss)
        return loss.item()

    def _training_state(self) -> dict[str, Any]:
        return {"updates": self.updates}

    def _load_training_state(self, state: dict[str, Any]) -> None:
        self.updates = int(state["updates"])
