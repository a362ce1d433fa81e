"""Goal-conditioned SAC (Haarnoja et al., 2018) and TQC (Kuznetsov et al., 2020): a squashed
Gaussian actor that explores by its own samples, an entropy temperature tuned toward a target
entropy, and twin critics (SAC) or critics of quantiles whose highest atoms are dropped (TQC)."""

from __future__ import annotations

import math
from typing import Any

import torch
from torch import nn

from dtd.agents.goal_learner import GoalLearner, StepTensors
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
        # The lowest atoms, in no order: the loss takes them as a set.
        return torch.topk(atoms, kept, dim=1, largest=False, sorted=False).values

    def _critic_loss(self, values: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        return quantile_huber_loss(values, target)


def quantile_huber_loss(quantiles: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """The quantile Huber loss (kappa 1) of ``quantiles`` (N, critics, M), quantile i at the
    level (i + 1/2) / M, against the target atoms (N, K, no gradient), averaged over every pair."""
    return _QuantileHuber.apply(quantiles, target)


class _QuantileHuber(torch.autograd.Function):
    """The loss and its gradient without forming the (N, critics, M, K) pairs. Each quantile q
    splits its row's sorted targets t at q - 1, q and q + 1; in each part the weight is one
    number and clip(t - q) and Huber(t - q) are -1, t - q, (t - q)^2 / 2 or t - q - 1/2, so
    the sums over a part follow from running sums of t and t^2 (float64, about the row's mean:
    no cancellation). With the pairs formed one by one the loss took 5.9 ms of a 3x256 TQC
    update at batch 256 (benchmarks/updates.py)."""

    @staticmethod
    def forward(ctx: Any, quantiles: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        rows, critics, count = quantiles.shape
        centre = target.mean(dim=1, keepdim=True)
        sorted_atoms = torch.sort(target - centre, dim=1).values
        near = (quantiles.detach() - centre[:, :, None]).reshape(rows, critics * count)
        below = torch.searchsorted(sorted_atoms, near - 1.0)  # targets t < q - 1
        under = torch.searchsorted(sorted_atoms, near)  # t < q: weight 1 - tau, else tau
        within = torch.searchsorted(sorted_atoms, near + 1.0, right=True)  # t <= q + 1
        atoms, points = sorted_atoms.double(), near.double()
        levels = (torch.arange(count, device=quantiles.device, dtype=torch.float64) + 0.5) / count
        levels = levels.repeat(critics)
        # Running sums with a leading 0: sums[:, j] is the sum of the j lowest targets.
        zero = atoms.new_zeros(rows, 1)
        sums = torch.cat([zero, atoms.cumsum(dim=1)], dim=1)
        squares = torch.cat([zero, atoms.square().cumsum(dim=1)], dim=1)
        total = atoms.shape[1]

        def part(running: torch.Tensor, start: torch.Tensor, stop: torch.Tensor) -> torch.Tensor:
            return running.gather(1, stop) - running.gather(1, start)

        near_low, near_high = (under - below).double(), (within - under).double()
        sum_low, sum_high = part(sums, below, under), part(sums, under, within)
        square_low, square_high = part(squares, below, under), part(squares, under, within)
        far_low, far_high = below.double(), (total - within).double()
        sum_far_low = sums.gather(1, below)
        sum_far_high = sums[:, -1:] - sums.gather(1, within)
        # Sum over the targets of weight * clip(t - q): the gradient's.
        pulled = (1.0 - levels) * (sum_low - near_low * points - far_low) + levels * (
            sum_high - near_high * points + far_high
        )
        # Sum of weight * Huber(t - q).
        low_huber = far_low * (points - 0.5) - sum_far_low
        low_huber = low_huber + 0.5 * (square_low - 2.0 * points * sum_low + near_low * points.square())
        high_huber = sum_far_high - far_high * (points + 0.5)
        high_huber = high_huber + 0.5 * (square_high - 2.0 * points * sum_high + near_high * points.square())
        huber = (1.0 - levels) * low_huber + levels * high_huber
        pairs = quantiles.numel() * total
        ctx.save_for_backward(pulled.reshape(quantiles.shape).to(quantiles.dtype))
        ctx.pairs = pairs
        return (huber.sum() / pairs).to(quantiles.dtype)

    @staticmethod
    def backward(ctx: Any, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        # d loss / d quantile = -mean of weight * clip(t - q) over its targets (pairs counted
        # over the whole mean).
        (pulled,) = ctx.saved_tensors
        return -grad * pulled / ctx.pairs, None
