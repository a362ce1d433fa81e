"""The named choices among a run's settings: algorithms, learners, devices, number formats,
presets and the ways of Dot-to-Dot's relabelling and collection."""

from __future__ import annotations

import enum


class Algo(enum.Enum):
    """The agents this package trains."""

    ddpg = "ddpg"
    """Goal-conditioned DDPG, no relabelling."""
    her = "her"
    """DDPG with Hindsight Experience Replay (``future`` strategy)."""
    dtd = "dtd"
    """Dot-to-Dot: a high-level sub-goal policy over a low-level HER agent, HER at both levels."""

    @property
    def sets_subgoals(self) -> bool:
        """Whether the agent has a high level that sets it sub-goals (plans, maps, sub-goal
        figures)."""
        return self is Algo.dtd


class RelabelWindow(enum.Enum):
    """How far ahead the low level of Dot-to-Dot draws its relabelled goals from."""

    segment = "segment"
    """Only from the segment of the transition: near goals, like the sub-goals it is given."""
    episode = "episode"
    """From anywhere later in the episode, as in plain HER."""


class HighTarget(enum.Enum):
    """What the high level of Dot-to-Dot learns the value of the segment before the last from."""

    bootstrap = "bootstrap"
    """Its reward plus the target critic where the last segment starts, with the goal as that
    segment's sub-goal: Q1'(o', g, g), as the paper."""
    observed = "observed"
    """Its reward plus what the episode went on to earn against the goal: the last segment's
    mean reward, then the final achieved goal's reward held for ever; no critic, so a
    relabelled goal needs no value of Q1 where the sub-goal is the goal."""


class Collection(enum.Enum):
    """Where training episodes are collected. At the same ``--threads`` the run is the same
    either way, step for step (with ``--collect-ahead`` or without); only the wall time
    differs."""

    auto = "auto"
    """``process`` where a core is left beside the learner's torch threads, else ``inline``."""
    inline = "inline"
    """In the learner's process, between its updates."""
    process = "process"
    """In a process of its own beside the learner, during the learner's updates."""


class LearnerKind(enum.Enum):
    """The off-policy learners every agent (and each level of Dot-to-Dot) can be built on."""

    ddpg = "ddpg"
    """DDPG: a deterministic actor and one critic, exploring by the action noise settings."""
    td3 = "td3"
    """TD3: twin critics and the lower of their targets, target-policy smoothing, an actor
    that steps every ``--actor-delay`` updates (Fujimoto et al., 2018)."""
    sac = "sac"
    """SAC: a squashed Gaussian actor exploring by its own samples, twin critics, an entropy
    temperature tuned toward ``--target-entropy`` (Haarnoja et al., 2018)."""
    tqc = "tqc"
    """TQC: SAC's actor over ``--critics`` critics of ``--quantiles`` quantiles each, the top
    ``--dropped-quantiles`` of each critic dropped from the pooled target (Kuznetsov et al.,
    2020)."""


class Device(enum.Enum):
    """Where the learners' networks, optimisers and batches live."""

    cpu = "cpu"
    """The CPU."""
    cuda = "cuda"
    """The first CUDA GPU; an error where there is none."""
    auto = "auto"
    """CUDA where torch finds a GPU, else the CPU."""


class Precision(enum.Enum):
    """The number format of the networks' passes in an update."""

    auto = "auto"
    """bfloat16 where the device computes it natively and the algorithm's learning was shown equal
    to float32's (``dtd`` with DDPG at both levels: ``BFLOAT16_SHOWN_EQUAL``), else float32; a
    run records which it chose."""
    float32 = "float32"
    """Every pass in float32."""
    bfloat16 = "bfloat16"
    """Forward and backward passes in bfloat16 (autocast); parameters, Adam's state, the
    normalisers, the target and the losses in float32; acting and evaluation in float32."""


class Preset(enum.Enum):
    """The defaults every setting starts from; options given beside it override them."""

    tuned = "tuned"
    """This library's defaults, measured on one machine (docs/tuning.md)."""
    paper = "paper"
    """The reference settings of HER and of the Dot-to-Dot paper, exactly."""
