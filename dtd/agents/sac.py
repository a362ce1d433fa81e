"""Goal-conditioned SAC (Haarnoja et al., 2018) and TQC (Kuznetsov et al., 2020): a squashed
Gaussian actor that explores by its own samples, an entropy temperature tuned toward a target
entropy, and twin critics (SAC) or critics of quantiles whose highest atoms are dropped (TQC)."""

from __future__ import annotations

import math
from typing import Any

import torch
from torch import nn

from dtd.agents.learner import GoalLearner, StepTensors
from dtd.agents.networks import CriticEnsemble, GaussianActor


class SACLearner(GoalLearner):
    """SAC: ``config.critics`` critics (two in the paper) whose lowest value the actor climbs
    and the target bootstraps from, less the temperature times the log density of the action
    sampled at the next state."""

    stochastic = True

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        config = self.config
        self.target_entropy = (
            config.target_entropy if config.target_entropy is not None else -float(self.action_dim)
        )
        """The policy's entropy (per action) the temperature steers toward."""
        self.log_temperature = torch.tensor(
            math.log(config.initial_temperature), device=self.device, requires_grad=True
        )
        self.temperature_optim = torch.optim.Adam([self.log_temperature], lr=config.actor_lr)

    def _uses_actor_target(self) -> bool:
        return False

    def _networks(self, input_dim: int, action_dim: int) -> tuple[nn.Module, nn.Module]:
        config = self.config
        actor = GaussianActor(input_dim, action_dim, config.hidden_sizes, config.layer_norm)
        critic = CriticEnsemble(
            input_dim, action_dim, config.hidden_sizes, config.critics, self._outputs(), config.layer_norm
        )
        return actor, critic

    def _outputs(self) -> int:
        """Values each critic gives of an action (1: its Q-value)."""
        return 1

    def _critic_values(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """(N, critics, outputs) each critic's value (or quantiles) of ``action``."""
        return critic(inputs, self._features(action))

    def _value(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self._critic_values(critic, inputs, action).squeeze(-1).min(dim=1).values

    def _next_atoms(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """(N, K) what the target bootstraps from at the next state: SAC's lowest critic (K = 1)."""
        return self._value(critic, inputs, action)[:, None]

    @property
    def temperature(self) -> torch.Tensor:
        """The entropy temperature alpha (no gradient)."""
        return self.log_temperature.detach().exp()

    def _sample(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        noise = torch.randn(inputs.shape[0], self.action_dim, device=self.device)
        return self.actor.sample(inputs, noise)

    def _next_value(self, step: StepTensors) -> torch.Tensor:
        """The atoms at the next state less alpha * log pi(a'|o', g). A known next action
        replaces the sampled one and has no entropy term: no policy chose it."""
        unit, log_prob = self._sample(step.next_inputs)
        next_action = self._given_next_action(step, self.head(unit, step.next_obs))
        if step.next_action_given is not None:
            log_prob = torch.where(step.next_action_given, torch.zeros_like(log_prob), log_prob)
        atoms = self._next_atoms(self.critic_target, step.next_inputs, next_action)
        return atoms - self.temperature * log_prob[:, None]

    def _actor_objective(
        self, inputs: torch.Tensor, obs: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """alpha * log pi(a|o, g) - the critics' value of a sampled action a."""
        unit, log_prob = self._sample(inputs)
        value = self._value(self.critic, inputs, self.head(unit, obs))
        return self.temperature * log_prob - value, unit, log_prob

    def _after_actor_step(self, log_prob: torch.Tensor | None) -> dict[str, float]:
        """One step of the temperature toward the target entropy."""
        if log_prob is None:
            self._step([self.log_temperature], self.temperature_optim, None)
            return {}
        # d/d(log alpha) of -log alpha * (log pi + target entropy): alpha falls while the policy's
        # entropy is above the target, and rises when below.
        entropy_gap = log_prob.detach().float() + self.target_entropy
        temperature_loss = -torch.mean(self.log_temperature * entropy_gap)
        self._step([self.log_temperature], self.temperature_optim, temperature_loss)
        entropy = -log_prob.detach().float().mean().item()
        return {"entropy": entropy, "temperature": self.temperature.item()}

    def _training_state(self) -> dict[str, Any]:
        return {
            "log_temperature": self.log_temperature.detach().clone(),
            "temperature_optim": self.temperature_optim.state_dict(),
        }

    def _load_training_state(self, state: dict[str, Any]) -> None:
        with torch.no_grad():
            self.log_temperature.copy_(state["log_temperature"])
        self.temperature_optim.load_state_dict(state["temperature_optim"])


class TQCLearner(SACLearner):
    """TQC: SAC's actor and temperature over ``config.critics`` critics of ``config.quantiles``
    quantiles each. The target pools every critic's atoms at the next state, drops the highest
    ``config.dropped_quantiles`` per critic (the overestimation), and each critic's quantiles
    learn them by the quantile Huber loss; the actor climbs the mean of all atoms."""

    def _outputs(self) -> int:
        return self.config.quantiles

    def _value(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self._critic_values(critic, inputs, action).mean(dim=(1, 2))

    def _next_atoms(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        atoms = self._critic_values(critic, inputs, action).flatten(1)
        kept = atoms.shape[1] - self.config.dropped_quantiles * self.config.critics
        return torch.sort(atoms, dim=1).values[:, :kept]

    def _critic_loss(self, values: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        return quantile_huber_loss(values, target)


def quantile_huber_loss(quantiles: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """The quantile Huber loss (kappa 1) of ``quantiles`` (N, critics, M), quantile i at the
    level (i + 1/2) / M, against the target atoms (N, K, no gradient), averaged over every pair."""
    return _QuantileHuber.apply(quantiles, target)


class _QuantileHuber(torch.autograd.Function):
    """The loss and its gradient in one pass over the (N, critics, M, K) pairs: with autograd
    tracking each elementwise step, the loss took 15 ms of a 3x256 TQC update at batch 256,
    computed this way 2.6 ms (benchmarks/updates.py)."""

    @staticmethod
    def forward(ctx: Any, quantiles: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        count = quantiles.shape[-1]
        levels = (torch.arange(count, device=quantiles.device, dtype=quantiles.dtype) + 0.5) / count
        delta = target[:, None, None, :] - quantiles[..., None]
        # The weight |tau - [delta < 0]|, and Huber(delta) = c (delta - c / 2), c = clip(delta, -1, 1).
        weight = torch.where(delta < 0, 1.0 - levels[:, None], levels[:, None])
        clipped = delta.clamp(-1.0, 1.0)
        weighted = weight * clipped
        ctx.save_for_backward(weighted.sum(dim=-1))
        ctx.pairs = delta.numel()
        return torch.mean(weighted * (delta - 0.5 * clipped))

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        # d loss / d quantile = -mean of weight * clip(delta) over its targets (pairs counted
        # over the whole mean).
        (weighted_sum,) = ctx.saved_tensors
        return -grad * weighted_sum / ctx.pairs, None
