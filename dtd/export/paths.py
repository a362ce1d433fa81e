"""A trained agent's deterministic acting paths as torch modules, each with the clipping and
normalisation of its inputs and the scaling of its outputs inside: what the ONNX files hold.

Each module calls the learner's own code (:meth:`GoalLearner.action_of` and
:meth:`GoalLearner.value_of`), so an exported model computes what the agent computes; the
normalisers' statistics become constants of the model when it is traced.
"""

from __future__ import annotations

import torch
from torch import nn

from dtd.agents.goal_learner import GoalLearner
from dtd.agents.segments import high_level_input


class _LearnerPath(nn.Module):
    def __init__(self, learner: GoalLearner) -> None:
        super().__init__()
        # Registered so that the traced model holds their parameters (and head's buffers).
        self.actor, self.critic, self.head = learner.actor, learner.critic, learner.head
        self.learner = learner


class PolicyPath(_LearnerPath):
    """(observation, goal) -> action: a flat agent's policy, or dtd's low level, whose goal
    is the sub-goal in force."""

    def forward(self, observation: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        return self.learner.action_of(observation, goal)


class SubgoalPath(_LearnerPath):
    """(observation, achieved goal, goal) -> sub-goal: dtd's high level, its sub-goals kept in
    the goal box (with a unit quaternion on the Hand tasks)."""

    def forward(
        self, observation: torch.Tensor, achieved_goal: torch.Tensor, goal: torch.Tensor
    ) -> torch.Tensor:
        return self.learner.action_of(high_level_input(observation, achieved_goal), goal)


class SubgoalValuePath(_LearnerPath):
    """(observation, achieved goal, goal, sub-goal) -> value: the high level's critic Q1 of a
    candidate sub-goal, row by row (``DotToDotAgent.subgoal_values``)."""

    def forward(
        self,
        observation: torch.Tensor,
        achieved_goal: torch.Tensor,
        goal: torch.Tensor,
        subgoal: torch.Tensor,
    ) -> torch.Tensor:
        return self.learner.value_of(high_level_input(observation, achieved_goal), goal, subgoal)
