"""Goal-conditioned actor and critic over normalised inputs, and the heads that turn the
actor's output in [-1, 1] into an action of the level that uses it."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import torch
from torch import nn

from dtd.agents.normalizer import RunningNormalizer


def mlp(
    in_dim: int,
    hidden_sizes: Sequence[int],
    out_dim: int,
    layer_norm: bool = False,
    float32_output: bool = False,
) -> nn.Sequential:
    """ReLU perceptron with the given hidden widths and a linear output; with ``layer_norm``
    each hidden layer is normalised (LayerNorm) before its ReLU; with ``float32_output`` the
    output layer stays float32 under autocast (:class:`Float32Linear`)."""
    layers: list[nn.Module] = []
    width = in_dim
    for hidden in hidden_sizes:
        layers.append(nn.Linear(width, hidden))
        if layer_norm:
            layers.append(nn.LayerNorm(hidden))
        layers.append(nn.ReLU())
        width = hidden
    layers.append((Float32Linear if float32_output else nn.Linear)(width, out_dim))
    return nn.Sequential(*layers)


def outside_autocast(inputs: torch.Tensor, forward: Callable[[torch.Tensor], torch.Tensor]) -> torch.Tensor:
    """``forward(inputs)`` in float32 even where autocast lowers the precision around it."""
    device = inputs.device.type
    if not torch.is_autocast_enabled(device):
        return forward(inputs)
    with torch.autocast(device, enabled=False):
        return forward(inputs.float())


class Float32Linear(nn.Linear):
    """A linear layer computed in float32 under autocast: a critic's output. A value of about
    -15 is held by bfloat16 to steps of 1/16, as large as the TD errors late in training; the
    layer's product (hidden width x outputs) is a sliver of the network's cost."""

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        return outside_autocast(inputs, super().forward)


def xavier_initialise(module: nn.Module) -> None:
    """Glorot-uniform weights and zero biases in every linear layer of ``module``, as OpenAI
    baselines' HER initialises its networks (PyTorch's default is Kaiming-uniform)."""
    for layer in module.modules():
        if isinstance(layer, nn.Linear):
            nn.init.xavier_uniform_(layer.weight)
            nn.init.zeros_(layer.bias)
        elif isinstance(layer, EnsembleLinear):
            _, fan_in, fan_out = layer.weight.shape
            bound = math.sqrt(6.0 / (fan_in + fan_out))
            nn.init.uniform_(layer.weight, -bound, bound)
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
        self.body = mlp(input_dim + action_features, hidden_sizes, 1, layer_norm, float32_output=True)

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


class EnsembleLinear(nn.Module):
    """``members`` independent linear layers applied in one batched matmul: (N, B, in) to
    (N, B, out). Each member is initialised as ``nn.Linear`` initialises one layer."""

    def __init__(self, members: int, in_dim: int, out_dim: int, float32: bool = False) -> None:
        super().__init__()
        self.float32 = float32
        """Computed in float32 under autocast, as :class:`Float32Linear`."""
        self.weight = nn.Parameter(torch.empty(members, in_dim, out_dim))
        self.bias = nn.Parameter(torch.empty(members, 1, out_dim))
        bound = 1.0 / in_dim**0.5
        nn.init.uniform_(self.weight, -bound, bound)
        nn.init.uniform_(self.bias, -bound, bound)

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        if self.float32:
            return outside_autocast(inputs, self._product)
        return self._product(inputs)

    def _product(self, inputs: torch.Tensor) -> torch.Tensor:
        return torch.baddbmm(self.bias, inputs, self.weight)


class EnsembleLayerNorm(nn.Module):
    """LayerNorm over the last dimension with a gain and bias of each member's own."""

    def __init__(self, members: int, width: int) -> None:
        super().__init__()
        self.weight = nn.Parameter(torch.ones(members, 1, width))
        self.bias = nn.Parameter(torch.zeros(members, 1, width))

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        normal = nn.functional.layer_norm(inputs, inputs.shape[-1:])
        return normal * self.weight + self.bias


class CriticEnsemble(nn.Module):
    """N critics of the same shape held as one module: Z(o || g, a) with ``outputs`` values
    per critic (1: a Q-value; M: M quantiles of the return). Returns (B, N, outputs)."""

    def __init__(
        self,
        input_dim: int,
        action_features: int,
        hidden_sizes: Sequence[int],
        members: int,
        outputs: int = 1,
        layer_norm: bool = False,
    ) -> None:
        super().__init__()
        self.members = members
        layers: list[nn.Module] = []
        width = input_dim + action_features
        for hidden in hidden_sizes:
            layers.append(EnsembleLinear(members, width, hidden))
            if layer_norm:
                layers.append(EnsembleLayerNorm(members, hidden))
            layers.append(nn.ReLU())
            width = hidden
        layers.append(EnsembleLinear(members, width, outputs, float32=True))
        self.body = nn.Sequential(*layers)

    def forward(self, inputs: torch.Tensor, action_features: torch.Tensor) -> torch.Tensor:
        joint = torch.cat([inputs, action_features], dim=-1)
        shared = joint.unsqueeze(0).expand(self.members, *joint.shape)
        return self.body(shared).transpose(0, 1)


class GaussianActor(nn.Module):
    """A squashed Gaussian policy over o || g: unit = tanh(mean + std * noise), in [-1, 1]^d as
    :class:`Actor`'s output, so the same heads map it to an action."""

    LOG_STD_MIN = -5.0
    LOG_STD_MAX = 2.0

    def __init__(
        self, input_dim: int, output_dim: int, hidden_sizes: Sequence[int], layer_norm: bool = False
    ) -> None:
        super().__init__()
        self.output_dim = output_dim
        self.body = mlp(input_dim, hidden_sizes, 2 * output_dim, layer_norm)

    def distribution(self, inputs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The Gaussian's mean and log std before squashing."""
        mean, log_std = self.body(inputs).split(self.output_dim, dim=-1)
        # A smooth bound on the log std (rather than a clamp) keeps its gradient everywhere.
        log_std = self.LOG_STD_MIN + 0.5 * (self.LOG_STD_MAX - self.LOG_STD_MIN) * (torch.tanh(log_std) + 1)
        return mean, log_std

    def forward(self, inputs: torch.Tensor) -> torch.Tensor:
        """The deterministic unit action: tanh of the mean."""
        return torch.tanh(self.distribution(inputs)[0])

    def sample(self, inputs: torch.Tensor, noise: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """A unit action drawn with standard normal ``noise`` (reparameterised) and its log
        density, the tanh's change of volume included."""
        mean, log_std = self.distribution(inputs)
        pre_tanh = mean + log_std.exp() * noise
        unit = torch.tanh(pre_tanh)
        gaussian = -0.5 * noise.square() - log_std - 0.5 * math.log(2 * math.pi)
        # log(1 - tanh(x)^2) = 2 (log 2 - x - softplus(-2x)), stable for large |x|.
        squash = 2.0 * (math.log(2.0) - pre_tanh - nn.functional.softplus(-2.0 * pre_tanh))
        return unit, (gaussian - squash).sum(dim=-1)
