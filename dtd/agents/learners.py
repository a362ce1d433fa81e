"""The learner a configuration names, built with fresh networks."""

from __future__ import annotations

import torch

from dtd.agents.collective import ALONE, Collective
from dtd.agents.ddpg import DDPGLearner
from dtd.agents.goal_learner import GoalLearner
from dtd.agents.networks import ActionHead
from dtd.agents.sac import SACLearner, TQCLearner
from dtd.agents.td3 import TD3Learner
from dtd.config import LearnerConfig, LearnerKind
from dtd.envs.goals import SparseRewards

LEARNERS: dict[LearnerKind, type[GoalLearner]] = {
    LearnerKind.ddpg: DDPGLearner,
    LearnerKind.td3: TD3Learner,
    LearnerKind.sac: SACLearner,
    LearnerKind.tqc: TQCLearner,
}


def make_learner(
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
) -> GoalLearner:
    """The ``config.learner`` learner of actions ``head`` makes from o || g, its updates'
    passes in ``precision`` (float32 or bfloat16)."""
    kind = LEARNERS[config.learner]
    return kind(
        obs_dim, goal_dim, action_dim, head, config, gamma, sparse_rewards, collective, device, precision
    )
