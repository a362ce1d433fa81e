"""What every learner shares: the inputs as the networks see them (clipped, normalised o || g),
the head that makes the actor's unit output an action, acting and valuing, one update (the TD
target, the critics' step, the actor's step, their order and delay, the precision they run in),
the Polyak targets, and the plain-data state. Each learner (DDPG, TD3, SAC, TQC) adds its
networks, its value of the next state, its critic loss and its actor loss."""

from __future__ import annotations

import contextlib
import copy
from typing import Any, NamedTuple

import numpy as np
import torch
from torch import nn

from dtd.agents.collective import ALONE, Collective
from dtd.agents.networks import ActionHead, xavier_initialise
from dtd.agents.normalizer import RunningNormalizer
from dtd.agents.records import Batch
from dtd.config import LearnerConfig
from dtd.envs.goals import SparseRewards, return_bounds


class StepTensors(NamedTuple):
    """A batch as tensors on the learner's device, with what every target needs resolved."""

    obs: torch.Tensor
    next_obs: torch.Tensor
    inputs: torch.Tensor
    next_inputs: torch.Tensor
    action: torch.Tensor
    reward: torch.Tensor
    discount: torch.Tensor
    """(N,) the discount of the value after each row: 0 where the row is terminal for its goal."""
    next_action: torch.Tensor | None
    """(N, action_dim) the action known to follow ``next_obs`` where ``next_action_given``."""
    next_action_given: torch.Tensor | None
    next_value: torch.Tensor | None
    """(N,) the value of ``next_obs`` known from what followed, where ``next_value_given``."""
    next_value_given: torch.Tensor | None
    actor_rows: torch.Tensor | None


class GoalLearner:
    """Actor and critic(s) over o || g, their targets and the input normalisers.

    The ``head`` decides what an action is: a motor command (the low level) or a sub-goal
    (the high level). Learns from batches it is given; collecting and relabelling are the
    caller's concern. With fellow data-parallel workers (``collective``), each update's
    gradients and the normalisers' statistics are theirs combined, so every worker's
    parameters stay the same. Networks, optimisers and batches live on ``device``; what
    :meth:`act` and :meth:`q_values` return is on the CPU. With ``precision`` bfloat16 the
    networks' passes of an update run in bfloat16 (see :meth:`update`); acting is float32.
    """

    stochastic = False
    """Whether the policy explores by sampling itself (else by noise the agent adds)."""

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
        device: torch.device | str = "cpu",
        precision: torch.dtype = torch.float32,
    ) -> None:
        self.config = config
        self.collective = collective
        self.gamma = gamma
        self.device = torch.device(device)
        self.precision = precision
        """The dtype of the networks' passes in an update: float32, or bfloat16 (autocast)."""
        self.action_dim = action_dim
        # A sparse reward bounds the return (-1/0 per step: to [-1/(1-gamma), 0]); a dense one is
        # not clipped, rather than clipped to a range it does not have.
        bounds = return_bounds(sparse_rewards, gamma) if config.clip_return else None
        self.return_bounds = bounds or (-np.inf, np.inf)
        norm = (config.norm_eps, config.norm_clip, collective, self.device)
        self.obs_norm = RunningNormalizer(obs_dim, *norm)
        self.goal_norm = RunningNormalizer(goal_dim, *norm)
        self.head = head.to(self.device)
        self.actor, self.critic = self._networks(obs_dim + goal_dim, action_dim)
        if config.xavier_init:
            xavier_initialise(self.actor)
            xavier_initialise(self.critic)
        self.actor.to(self.device)
        self.critic.to(self.device)
        self.actor_target = _frozen_copy(self.actor) if self._uses_actor_target() else None
        self.critic_target = _frozen_copy(self.critic)
        # The fused kernel does Adam's whole step in one pass (the default on CPU is a loop of
        # small per-tensor operations).
        self.actor_optim = torch.optim.Adam(self.actor.parameters(), lr=config.actor_lr, fused=True)
        self.critic_optim = torch.optim.Adam(self.critic.parameters(), lr=config.critic_lr, fused=True)
        self._actor_params = list(self.actor.parameters())
        self._critic_params = list(self.critic.parameters())
        self.updates = 0
        """Updates so far: the actor steps on every ``actor_delay``-th."""

    # What each learner supplies.

    def _networks(self, input_dim: int, action_dim: int) -> tuple[nn.Module, nn.Module]:
        """The actor and the critic (or critics, as one module) of this learner."""
        raise NotImplementedError

    def _uses_actor_target(self) -> bool:
        return True

    @property
    def actor_delay(self) -> int:
        """The actor steps once every this many updates (of the critics)."""
        return 1

    def _value(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """(N,) the value of ``action`` the actor climbs, from ``critic``'s output."""
        raise NotImplementedError

    def _critic_values(self, critic: nn.Module, inputs: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """(N, critics, ...) what ``critic`` says of ``action``: each critic's value (or atoms)."""
        raise NotImplementedError

    def _next_value(self, step: StepTensors) -> torch.Tensor:
        """(N, K) what the target bootstraps from at the next state: the target networks' value of
        the next action (a known one where the batch gives it), K atoms of it for a distributional
        critic, an entropy bonus included for a stochastic policy."""
        raise NotImplementedError

    def _critic_loss(self, values: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """The critics' loss of ``values`` (:meth:`_critic_values`) against ``target`` (N, K)."""
        # Each critic's own mean squared error, summed: each learns at the rate of one alone.
        return torch.square(values.flatten(1) - target).mean(dim=0).sum()

    def _actor_objective(
        self, inputs: torch.Tensor, obs: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """(N,) what the actor minimises per row before its action penalty, the unit actions it
        chose and their log density (None for a deterministic actor): minus the critic's value."""
        action, unit = self._policy(self.actor, inputs, obs)
        return -self._value(self.critic, inputs, action), unit, None

    def _after_actor_step(self, log_prob: torch.Tensor | None) -> dict[str, float]:
        """Anything that steps with the actor (e.g. a temperature); ``None``: this worker had no
        row for the actor. Returns its diagnostics."""
        return {}

    # One update, the same for every learner.

    def update(self, batch: Batch) -> dict[str, float]:
        """One step of the critic(s) toward the TD target and, on every ``actor_delay``-th update,
        one of the actor up the critic (the critic after its own step; with ``actor_after_critic``
        off the same critic as the critic's step saw, as baselines' HER); returns diagnostics.

        In bfloat16 precision the networks' forward and backward passes run in bfloat16; the
        parameters, Adam's state, the normalised inputs, the target, its clip and the losses stay
        float32."""
        step = self.step_tensors(batch)
        target = self.target(step)
        with self._lowered():
            values = self._critic_values(self.critic, step.inputs, step.action).float()
        critic_loss = self._critic_loss(values, target)
        self.updates += 1
        actor_due = self.updates % self.actor_delay == 0
        actor_metrics: dict[str, float] = {}
        if actor_due and not self.config.actor_after_critic:
            actor_metrics = self._actor_step(step)
        self._step(self._critic_params, self.critic_optim, critic_loss)
        if actor_due and self.config.actor_after_critic:
            actor_metrics = self._actor_step(step)
        return {
            "critic_loss": critic_loss.item(),
            "q_mean": values.detach().mean().item(),
            "target_mean": target.mean().item(),
            **actor_metrics,
        }

    @torch.no_grad()
    def target(self, step: StepTensors) -> torch.Tensor:
        """(N, K) r + discount * the next state's value (a known value where the batch gives
        it), clipped to the return's range."""
        with self._lowered():
            next_value = self._next_value(step).float()
        if step.next_value is not None and step.next_value_given is not None:
            next_value = torch.where(step.next_value_given[:, None], step.next_value[:, None], next_value)
        target = step.reward[:, None] + step.discount[:, None] * next_value
        return torch.clamp(target, *self.return_bounds)

    def _actor_step(self, step: StepTensors) -> dict[str, float]:
        """One step of the actor on its rows of the batch (all without ``actor_rows``): its
        objective plus the penalty on its squared unit action."""
        learning = self._actor_rows(step.inputs, step.obs, step.actor_rows)
        if learning is None:
            self._step(self._actor_params, self.actor_optim, None)
            return self._after_actor_step(None)
        # A context of its own: autocast's bfloat16 copies of the critic are not those of before
        # its step.
        with self._lowered():
            objective, unit, log_prob = self._actor_objective(*learning)
        penalty = torch.mean(torch.square(unit.float()))
        loss = objective.float().mean() + self.config.action_l2 * penalty
        self._step(self._actor_params, self.actor_optim, loss)
        return {"actor_loss": loss.item(), **self._after_actor_step(log_prob)}

    def _lowered(self) -> contextlib.AbstractContextManager:
        """Where the networks run in the update's precision (nothing to do for float32)."""
        if self.precision == torch.float32:
            return contextlib.nullcontext()
        return torch.autocast(self.device.type, dtype=self.precision)

    def tensor(self, values: np.ndarray | torch.Tensor) -> torch.Tensor:
        """``values`` as a float32 tensor on the learner's device (a tensor there passes through
        untouched, so that tracing the acting path keeps it an input rather than a constant)."""
        if isinstance(values, torch.Tensor) and values.device == self.device:
            return values
        return torch.as_tensor(values, dtype=torch.float32, device=self.device)

    def inputs(self, obs: np.ndarray | torch.Tensor, goal: np.ndarray | torch.Tensor) -> torch.Tensor:
        """Clipped, normalised o || g as the networks see it."""
        clip = self.config.obs_clip
        obs_t = torch.clamp(self.tensor(obs), -clip, clip)
        goal_t = torch.clamp(self.tensor(goal), -clip, clip)
        return torch.cat([self.obs_norm.normalize(obs_t), self.goal_norm.normalize(goal_t)], dim=-1)

    def _policy(
        self, actor: nn.Module, inputs: torch.Tensor, obs: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        unit = actor(inputs)
        return self.head(unit, obs), unit

    def _features(self, action: torch.Tensor) -> torch.Tensor:
        return self.head.critic_features(action, self.goal_norm)

    def action_of(self, obs: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """Deterministic actions of raw (unnormalised) float32 tensors, inputs clipped and
        normalised and the action scaled as in acting (e.g. to trace the acting path)."""
        return self._policy(self.actor, self.inputs(obs, goal), self.tensor(obs))[0]

    def value_of(self, obs: torch.Tensor, goal: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """The value of ``action`` from raw float32 tensors, as :meth:`q_values` computes it."""
        return self._value(self.critic, self.inputs(obs, goal), self.tensor(action))

    @torch.no_grad()
    def act(self, obs: np.ndarray, goal: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """Actions for a batch: the deterministic policy's, or with ``rng`` a draw from a
        stochastic policy (a deterministic learner ignores it; its exploration is the agent's)."""
        obs_t = self.tensor(obs)
        goal_t = self.tensor(goal)
        if rng is None or not self.stochastic:
            return self.action_of(obs_t, goal_t).cpu().numpy()
        noise = self.tensor(rng.standard_normal((obs_t.shape[0], self.action_dim)))
        unit, _ = self.actor.sample(self.inputs(obs_t, goal_t), noise)
        return self.head(unit, obs_t).cpu().numpy()

    @torch.no_grad()
    def q_values(self, obs: np.ndarray, goal: np.ndarray, action: np.ndarray) -> np.ndarray:
        """The value of each (o, g, a) of a batch."""
        return self.value_of(self.tensor(obs), self.tensor(goal), self.tensor(action)).cpu().numpy()

    def update_normalizers(self, obs: np.ndarray, goal: np.ndarray) -> None:
        """Add observations and goals to the running statistics of the inputs."""
        clip = self.config.obs_clip
        self.obs_norm.update(np.clip(obs, -clip, clip))
        self.goal_norm.update(np.clip(goal, -clip, clip))

    def step_tensors(self, batch: Batch) -> StepTensors:
        """``batch`` on the device, each row's discount resolved (n-step, terminal)."""
        obs = self.tensor(batch.obs)
        next_obs = self.tensor(batch.next_obs)
        discount = (
            torch.full((obs.shape[0],), self.gamma, device=self.device)
            if batch.discount is None
            else self.tensor(batch.discount)
        )
        # A transition bootstraps unless the task ended the episode there for its goal: the
        # time limit (and an episode ended for another goal) cuts an episode, not its value.
        if batch.terminal is not None:
            discount = discount * (1.0 - self.tensor(batch.terminal))

        def optional(values: np.ndarray | None, kind: torch.dtype = torch.float32) -> torch.Tensor | None:
            return None if values is None else torch.as_tensor(values, dtype=kind, device=self.device)

        given_action = batch.next_action is not None and batch.next_action_given is not None
        given_value = batch.next_value is not None and batch.next_value_given is not None
        return StepTensors(
            obs=obs,
            next_obs=next_obs,
            inputs=self.inputs(obs, batch.goal),
            next_inputs=self.inputs(next_obs, batch.goal),
            action=self.tensor(batch.action),
            reward=self.tensor(batch.reward),
            discount=discount,
            next_action=optional(batch.next_action) if given_action else None,
            next_action_given=optional(batch.next_action_given, torch.bool) if given_action else None,
            next_value=optional(batch.next_value) if given_value else None,
            next_value_given=optional(batch.next_value_given, torch.bool) if given_value else None,
            actor_rows=optional(batch.actor_rows, torch.bool),
        )

    @staticmethod
    def _actor_rows(
        inputs: torch.Tensor, obs: torch.Tensor, rows: torch.Tensor | None
    ) -> tuple[torch.Tensor, torch.Tensor] | None:
        """``inputs`` and ``obs`` of the rows the actor learns from (all, without ``rows``); None
        where the batch holds none of them."""
        if rows is None:
            return inputs, obs
        if not bool(rows.any()):
            return None
        return inputs[rows], obs[rows]

    def _given_next_action(self, step: StepTensors, next_action: torch.Tensor) -> torch.Tensor:
        """The target's next action, the known one where the batch gives it."""
        if step.next_action is None or step.next_action_given is None:
            return next_action
        return torch.where(step.next_action_given[:, None], step.next_action, next_action)

    def _step(
        self, params: list[torch.Tensor], optim: torch.optim.Optimizer, loss: torch.Tensor | None
    ) -> None:
        """One optimiser step on ``loss`` (its gradients for ``params`` only), averaged with the
        fellow workers; ``None``: this worker has no row to learn from, and adds zeros to the
        others' mean (alone, no step at all)."""
        if loss is None:
            if self.collective.workers == 1:
                return
            for param in params:
                param.grad = torch.zeros_like(param)
        else:
            # Gradients for these parameters only: e.g. the critic's weight gradients, which a
            # plain backward() of the actor's loss would also compute, are never used.
            grads = torch.autograd.grad(loss, params)
            for param, grad in zip(params, grads, strict=True):
                param.grad = grad
        self.collective.average_gradients(params)
        optim.step()

    @torch.no_grad()
    def update_target(self) -> None:
        """Move the target networks toward the online ones by 1 - polyak."""
        weight = 1.0 - self.config.polyak
        pairs = [(self.critic_target, self.critic)]
        if self.actor_target is not None:
            pairs.insert(0, (self.actor_target, self.actor))
        for target, online in pairs:
            torch._foreach_lerp_(list(target.parameters()), list(online.parameters()), weight)

    def acting_state(self) -> dict[str, Any]:
        """What :meth:`act` needs (head, actor, normalisers), for a copy that only acts (on the
        CPU, in another process, wherever this learner is)."""
        return {
            "head": _on_cpu(self.head.state_dict()),
            "actor": _on_cpu(self.actor.state_dict()),
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

    def _training_state(self) -> dict[str, Any]:
        """What only training needs beside targets and optimisers: the count of updates (and
        e.g. a temperature)."""
        return {"updates": self.updates}

    def _load_training_state(self, state: dict[str, Any]) -> None:
        # A checkpoint of a learner without an actor delay may have no count.
        self.updates = int(state.get("updates", 0))

    def state_dict(self) -> dict[str, Any]:
        """Plain data: the acting state plus critic, target networks and optimisers."""
        state = {**self.acting_state(), "critic": self.critic.state_dict()}
        if self.actor_target is not None:
            state["actor_target"] = self.actor_target.state_dict()
        state["critic_target"] = self.critic_target.state_dict()
        state["actor_optim"] = self.actor_optim.state_dict()
        state["critic_optim"] = self.critic_optim.state_dict()
        return {**state, **self._training_state()}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore what :meth:`state_dict` returned."""
        self.load_acting_state(state)
        self.critic.load_state_dict(state["critic"])
        if self.actor_target is not None:
            self.actor_target.load_state_dict(state["actor_target"])
        self.critic_target.load_state_dict(state["critic_target"])
        self.actor_optim.load_state_dict(state["actor_optim"])
        self.critic_optim.load_state_dict(state["critic_optim"])
        self._load_training_state(state)


def _on_cpu(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    # On the CPU this is the same dict of the same tensors.
    return {name: tensor.cpu() for name, tensor in state.items()}


def _frozen_copy(module: nn.Module) -> nn.Module:
    target = copy.deepcopy(module)
    for param in target.parameters():
        param.requires_grad_(False)
    return target
