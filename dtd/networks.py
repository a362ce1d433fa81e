"""Goal-conditioned actor and critic: multilayer perceptrons over normalised inputs."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn


def mlp(in_dim: int, hidden_sizes: Sequence[int], out_dim: int) -> nn.Sequential:
    """ReLU perceptron with the given hidden widths and a linear output."""
    layers: list[nn.Module] = []
    width = in_dim
    for hidden in hidden_sizes:
        layers += [nn.Linear(width, hidden), nn.ReLU()]
        width = hidden
    layers.append(nn.Linear(width, out_dim))
    return nn.Sequential(*layers)


class Actor(nn.Module):
    """mu(o || g) in [-action_max, action_max]; the scale is saved with the weights."""

    def __init__(self, input_dim: int, action_dim: int, hidden_sizes: Sequence[int], action_max: float):
        super().__init__()
        self.body = mlp(input_dim, hidden_sizes, action_dim)
        self.register_buffer("action_max", torch.tensor(float(action_max)))

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        return self.action_max * torch.tanh(self.body(inputs))


class Critic(nn.Module):
    """Q(o || g, a), with the action scaled to [-1, 1] like the other inputs."""

    def __init__(self, input_dim: int, action_dim: int, hidden_sizes: Sequence[int], action_max: float):
        super().__init__()
        self.body = mlp(input_dim + action_dim, hidden_sizes, 1)
        self.register_buffer("action_max", torch.tensor(float(action_max)))

    def forward(self, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.body(torch.cat([inputs, action / self.action_max], dim=-1)).squeeze(-1)
