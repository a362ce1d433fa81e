"""Goal-conditioned actor and critic over normalised inputs, and the heads that turn the
actor's output in [-1, 1] into an action of the level that uses it."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from dtd.agents.normalizer import RunningNormalizer


def mlp(in_dim: int, hidden_sizes: Sequence[int], out_dim: int, layer_norm: bool = False) -> nn.Sequential:
    """ReLU perceptron with the given hidden widths and a linear output; with ``layer_norm``
    each hidden layer is normalised (LayerNorm) before its ReLU."""
    layers: list[nn.Module] = []
    width = in_dim
    for hidden in hidden_sizes:
        layers.append(nn.Linear(width, hidden))
        if layer_norm:
            layers.append(nn.LayerNorm(hidden))
        layers.append(nn.ReLU())
        width = hidden
    layers.append(nn.Linear(width, out_dim))
    return nn.Sequential(*layers)


def xavier_initialise(module: nn.Module) -> None:
    """Glorot-uniform weights and zero biases in every linear layer of ``module``, as OpenAI
    baselines' HER initialises its networks (PyTorch's default is Kaiming-uniform)."""
    for layer in module.modules():
        if isinstance(layer, nn.Linear):
            nn.init.xavier_uniform_(layer.weight)
            nn.init.zeros_(layer.bias)


class Actor(nn.Module):
    """mu(o || g) as a unit vector in [-1, 1]^d; a head maps it to an action."""

    def __init__(
        self, input_dim: int, output_dim: int, hidden_sizes: Sequence[int], layer_norm: bool = False
    ) -> None:
        super().__init__()
        self.body = mlp(input_dim, hidden_sizes, output_dim, layer_norm)

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        return torch.tanh(self.body(inputs))


class Critic(nn.Module):
    """Q(o || g, a), given the action as the head encodes it for the critic."""

    def __init__(
        self, input_dim: int, action_features: int, hidden_sizes: Sequence[int], layer_norm: bool = False
    ) -> None:
        super().__init__()
        self.body = mlp(input_dim + action_features, hidden_sizes, 1, layer_norm)

    def forward(self, inputs: torch.Tensor, action_features: torch.Tensor) -> torch.Tensor:
        return self.body(torch.cat([inputs, action_features], dim=-1)).squeeze(-1)


class BoxActionHead(nn.Module):
    """Actions in [-action_max, action_max]; the critic sees them scaled back to [-1, 1]."""

    def __init__(self, action_max: float) -> None:
        super().__init__()
        self.register_buffer("action_max", torch.tensor(float(action_max)))

    def forward(self, unit: torch.Tensor, obs: torch.Tensor) -> torch.Tensor:
        return self.action_max * unit

    def critic_features(self, action: torch.Tensor, goal_norm: RunningNormalizer) -> torch.Tensor:
        return action / self.action_max


class SubgoalHead(nn.Module):
    """Sub-goals in absolute goal coordinates: achieved goal + max_distance * unit, kept in
    the goal box (and with a unit quaternion, for rotation goals).

    The achieved goal is read from the last ``goal_dim`` entries of the (raw) observation.
    The critic sees sub-goals normalised like goals, so it can be asked about any sub-goal.
    """

    def __init__(
        self,
        max_distance: float,
        low: Sequence[float],
        high: Sequence[float],
        quaternion: tuple[int, int] | None,
    ) -> None:
        super().__init__()
        self.register_buffer("max_distance", torch.tensor(float(max_distance)))
        self.register_buffer("low", torch.tensor(low, dtype=torch.float32))
        self.register_buffer("high", torch.tensor(high, dtype=torch.float32))
        self.quaternion = quaternion

    def forward(self, unit: torch.Tensor, obs: torch.Tensor) -> torch.Tensor:
        achieved = obs[..., -self.low.shape[0] :]
        return self.project(achieved + self.max_distance * unit)

    def project(self, subgoal: torch.Tensor) -> torch.Tensor:
        """Clip into the goal box; scale the rotation part to a unit quaternion (scaling, not
        clipping, keeps the rotation it points to)."""
        clipped = torch.maximum(torch.minimum(subgoal, self.high), self.low)
        if self.quaternion is None:
            return clipped
        start, stop = self.quaternion
        rotation = subgoal[..., start:stop]
        norm = torch.linalg.vector_norm(rotation, dim=-1, keepdim=True)
        # A rotation part of (almost) zero length has no direction: use the identity.
        identity = torch.zeros_like(rotation)
        identity[..., 0] = 1.0
        rotation = torch.where(norm > 1e-6, rotation / norm.clamp_min(1e-6), identity)
        return torch.cat([clipped[..., :start], rotation, clipped[..., stop:]], dim=-1)

    def critic_features(self, action: torch.Tensor, goal_norm: RunningNormalizer) -> torch.Tensor:
        return goal_norm.normalize(action)


ActionHead = BoxActionHead | SubgoalHead
