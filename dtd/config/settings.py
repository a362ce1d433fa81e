"""The settings of a run as frozen dataclasses: every field's default, its bound, and its
docstring as the option's help text; read back from and written to plain JSON data."""

from __future__ import annotations

import dataclasses
from typing import Annotated, Any

import tyro

from dtd.config.choices import (
    Algo,
    Collection,
    Device,
    HighTarget,
    LearnerKind,
    Precision,
    Preset,
    RelabelWindow,
)
from dtd.config.plain import plain_data, typed_fields
from dtd.config.validation import (
    AT_LEAST_1,
    AT_LEAST_2,
    AUTOMATIC_OR_MORE,
    DISCOUNT,
    FINITE,
    GIVEN,
    HALF_TURN,
    NOT_NEGATIVE,
    POSITIVE,
    PROBABILITY,
    WIDTHS,
    ZERO_OR_MORE,
    validate,
)

EVAL_SEED = 1_000_003
"""Seed of evaluation episodes after training (dtd eval, render, heatmap, report, explore),
apart from every seed a run trains with."""


@dataclasses.dataclass(frozen=True)
class LearnerConfig:
    """Settings of one learner (actor, critics, their targets and input normalisers)."""

    learner: LearnerKind = LearnerKind.ddpg
    """The learner: ddpg, td3, sac or tqc."""
    hidden_sizes: Annotated[tuple[int, ...], WIDTHS] = (256, 256, 256)
    """Widths of the hidden ReLU layers of actor and critic."""
    layer_norm: bool = False
    """Normalise each hidden layer of actor and critic (LayerNorm before the ReLU)."""
    actor_lr: Annotated[float, POSITIVE] = 1e-3
    """Adam learning rate of the actor."""
    critic_lr: Annotated[float, POSITIVE] = 1e-3
    """Adam learning rate of the critic."""
    batch_size: Annotated[int | None, AT_LEAST_1] = 256
    """Transitions per update; unset (the low level's default): the algorithm's."""
    polyak: Annotated[float, PROBABILITY] = 0.95
    """Polyak coefficient of the target networks: target <- polyak * target + (1 - polyak) * online."""
    action_l2: Annotated[float, NOT_NEGATIVE] = 1.0
    """Weight of the actor's penalty on the squared (scaled) action."""
    gamma: Annotated[float | None, DISCOUNT] = None
    """Discount per step; None: 1 - 1/T, T being the episode's length in steps."""
    clip_return: bool = True
    """Clip the critic's target to the range of returns of the task's sparse reward, measured
    from the task (-1/0: [-1/(1-gamma), 0]; 0/1: [0, 1/(1-gamma)]); a dense reward is not
    clipped."""
    norm_clip: Annotated[float, POSITIVE] = 5.0
    """Normalised inputs are clipped to [-norm_clip, norm_clip]."""
    obs_clip: Annotated[float, POSITIVE] = 200.0
    """Raw observations and goals are clipped to [-obs_clip, obs_clip] before normalising."""
    norm_eps: Annotated[float, POSITIVE] = 0.01
    """Smallest standard deviation the running normalisers divide by."""
    xavier_init: bool = False
    """Initialise linear layers Glorot-uniform with zero biases, as OpenAI baselines' HER (off:
    PyTorch's default)."""
    actor_after_critic: bool = True
    """Step the actor against the critic its own step just updated (off: both gradients from
    the same parameters, as OpenAI baselines' HER)."""
    critics: Annotated[int, AT_LEAST_1] = 2
    """td3, sac, tqc: critics learned side by side (ddpg has one)."""
    actor_delay: Annotated[int, AT_LEAST_1] = 2
    """td3: the actor (and its penalty) steps once every this many critic updates."""
    target_noise: Annotated[float, NOT_NEGATIVE] = 0.2
    """td3: std of the Gaussian noise on the target actor's unit action (target-policy
    smoothing), as a fraction of the largest action."""
    target_noise_clip: Annotated[float, NOT_NEGATIVE] = 0.5
    """td3: that noise is clipped to [-this, this]."""
    quantiles: Annotated[int, AT_LEAST_1] = 25
    """tqc: quantiles of the return each critic learns."""
    dropped_quantiles: Annotated[int, ZERO_OR_MORE] = 2
    """tqc: the highest atoms dropped from the pooled target, per critic."""
    # FetchReach, her + sac, seed 0: from 1.0 the entropy bonus (about 2.6 a step) outweighed
    # the -1/0 reward and success stayed at 0-0.2 for 4 epochs; from 0.05, 0.7 after the first.
    initial_temperature: Annotated[float, POSITIVE] = 0.05
    """sac, tqc: the entropy temperature at the start."""
    target_entropy: Annotated[float | None, FINITE] = None
    """sac, tqc: the policy's entropy the temperature steers toward; None: minus the action's
    dimension (the high level's: the goal's)."""


LOW_LEVEL_BATCH: dict[Algo, int] = {Algo.her: 1024, Algo.ddpg: 1024, Algo.dtd: 256}
"""The batch of the learner of ``her`` and ``ddpg`` and of dtd's low level, when not given. The
reference batch of 256 was made for 19 workers averaging their gradients (an effective 4,864
per update); on one machine HER learned FetchPush far sooner with 1,024. Dot-to-Dot's low level
learned FetchPush as soon with 256 (0.5 at 145k against 140k, median of 3 seeds) in half the
wall time, and FetchPickAndPlace far sooner (docs/tuning.md)."""

LOW_LEVEL_N_STEP: dict[Algo, int] = {Algo.her: 1, Algo.ddpg: 1, Algo.dtd: 3}
"""Rewards summed per sampled transition of ``her`` and ``ddpg`` and of dtd's low level, when not
given. With 3, Dot-to-Dot's low level reached 0.9 eval success on FetchPush at 110k, 125k and
120k env steps (seeds 0-2) against 175k, 160k and 145k with one-step returns
(docs/tuning.md); ``her`` and ``ddpg`` keep one-step returns, as the reference."""

LOW_LEVEL_DEFAULTS = LearnerConfig(batch_size=None)
"""The learner of ``her``, ``ddpg`` and dtd's low level: the reference settings but the batch,
which depends on the algorithm (``LOW_LEVEL_BATCH``)."""

HIGH_LEVEL_DEFAULTS = LearnerConfig()
"""The high level's learner: the reference settings, as the low level's. Its action penalty keeps
sub-goals near the achieved goal until the critic says otherwise; without it (action_l2 = 0) the
sub-goals of FetchPush ran to the corners of the goal box and were never reached."""


@dataclasses.dataclass(frozen=True)
class DotToDotConfig:
    """Settings of Dot-to-Dot alone: the segments an episode is cut into, how sub-goals are
    explored, how the high level relabels, and the high level's learner."""

    segments: Annotated[int, AT_LEAST_2] = 2
    """dtd: segments an episode is cut into; one sub-goal each, the last one being the goal."""
    # With 0.1 FetchPush passed 0.9 success within 200k steps on three seeds of three (one of
    # three with the reference's 0.05), and FetchPickAndPlace reached 0.5 at 215k, not 270k.
    subgoal_sigma: Annotated[float, NOT_NEGATIVE] = 0.1
    """dtd: std of the Gaussian perturbation of the achieved goal proposed as a sub-goal (the
    paper: 0.05)."""
    subgoal_rotation_angle: Annotated[float, HALF_TURN] = 0.0
    """dtd, goals with a rotation (the Hand tasks): perturbation sub-goals turn the achieved
    rotation by a random angle of at most this many degrees about a random axis (0: Gaussian
    noise of std --subgoal-sigma on the quaternion's entries)."""
    subgoal_eps_start: Annotated[float, PROBABILITY] = 1.0
    """dtd: probability of a perturbation sub-goal (instead of the high level's) at the start."""
    subgoal_eps_floor: Annotated[float, PROBABILITY] = 0.1
    """dtd: the probability of a perturbation sub-goal after the decay."""
    subgoal_eps_decay_epochs: Annotated[float, NOT_NEGATIVE] = 30.0
    """dtd: epochs over which that probability falls linearly from start to floor."""
    subgoal_noise: Annotated[float, NOT_NEGATIVE] = 0.05
    """dtd: std of the Gaussian exploration noise added to the high level's sub-goals."""
    subgoal_max_distance: Annotated[float, POSITIVE] = 0.3
    """dtd: sub-goals lie within this distance (per coordinate) of the achieved goal, inside the goal box."""
    high_replay_k: Annotated[int, ZERO_OR_MORE] = 4
    """dtd: HER at the high level: goals replaced by later achieved goals in k/(k+1) of samples."""
    hindsight_action_prob: Annotated[float, PROBABILITY] = 0.0
    """dtd: probability of replacing a sampled sub-goal by the goal reached at its segment's end."""
    # On FetchPush the whole episode learned faster than the segment (0.95 against 0.86 at 300k).
    low_relabel_window: RelabelWindow = RelabelWindow.episode
    """dtd: where the low level's relabelled goals come from."""
    # It gets one transition per segment; with 10 FetchPush reached 0.97 success at 300k steps
    # (one seed), at a quarter of the high level's cost with 40.
    high_updates_per_cycle: Annotated[int, AT_LEAST_1] = 10
    """dtd: gradient updates of the high level per cycle, spread among the low level's."""
    high_target: HighTarget = HighTarget.bootstrap
    """dtd: where the value of the segment before the last comes from: ``bootstrap``, the
    target critic where the last segment starts with the goal as its sub-goal (the paper);
    ``observed``, what the episode went on to earn against the goal (the last segment's mean
    reward, then the final reward held for ever)."""
    high_actor_last_segment: bool = True
    """dtd: the high level's actor learns also from the states where the last segment starts,
    where the goal is the sub-goal and the actor never chooses (off: only from the states
    where it chooses)."""
    high: LearnerConfig = HIGH_LEVEL_DEFAULTS
    """dtd: settings of the high level's learner."""


DOT_TO_DOT_FIELDS = tuple(field.name for field in dataclasses.fields(DotToDotConfig))


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """A whole training run. Defaults are the ``tuned`` preset: the reference settings of OpenAI
    baselines' HER except where docs/tuning.md measured better (``PAPER`` in presets.py holds the
    reference)."""

    env: Annotated[str | None, GIVEN] = None
    """Gymnasium id of a goal-conditioned environment, e.g. FetchPush-v4, or module:EnvId."""
    env_kwargs: tuple[str, ...] = ()
    """Keyword arguments of the environment's constructor (and of gym.make, e.g.
    max_episode_steps), each KEY=VALUE with VALUE read as JSON or Python (false, False, 3, 0.5,
    [1, 2]) or else as text, e.g. --env-kwargs continuing_task=False reward_type=sparse; kept in
    config.json for resume, eval, render, explore and export."""
    time_feature: bool = False
    """Append the fraction of the episode left, 1 - t/T, to the observation the networks see
    (as RL Zoo's TimeFeatureWrapper for the Fetch tasks); needs a time limit."""
    algo: Algo = Algo.her
    """Agent to train."""
    preset: Preset = Preset.tuned
    """Defaults of every other setting: ``tuned`` (docs/tuning.md) or ``paper`` (the reference
    settings of HER and the paper); the options given beside it override them."""
    seed: Annotated[int, ZERO_OR_MORE] = 0
    """Seed of networks, environments, exploration and replay sampling."""
    epochs: Annotated[int, AT_LEAST_1] = 50
    """Number of epochs; each ends with an evaluation and a checkpoint."""
    n_cycles: Annotated[int, AT_LEAST_1] = 50
    """Cycles per epoch; a cycle collects episodes, then updates the learner."""
    episodes_per_cycle: Annotated[int, AT_LEAST_1] = 2
    """Episodes collected per cycle, one per training environment, stepped together."""
    updates_per_cycle: Annotated[int, ZERO_OR_MORE] = 40
    """Gradient updates per cycle; the target networks move once after them."""
    explore_snapshots: Annotated[int, ZERO_OR_MORE] = 100
    """About how many agent-only snapshots (no replay, no optimiser) a run keeps in
    checkpoints/epochs/ for ``dtd explore``: one after every k-th epoch, k = ceil(epochs /
    this), and after the first and the last (every epoch when there are at most this many);
    0 keeps none."""
    test_episodes: Annotated[int, AT_LEAST_1] = 10
    """Deterministic evaluation episodes at the end of every epoch."""
    buffer_size: Annotated[int, AT_LEAST_1] = 1_000_000
    """Replay capacity in transitions (whole episodes are kept)."""
    replay_k: Annotated[int, ZERO_OR_MORE] = 4
    """HER: relabelled goals per original one; a fraction k/(k+1) of samples is relabelled."""
    past_goal_share: Annotated[float, PROBABILITY] = 0.0
    """HER: share of the relabelled goals that are goals given before (of a random stored
    step, any episode) instead of goals achieved later in the episode."""
    n_step: Annotated[int | None, AT_LEAST_1] = None
    """Rewards summed per sampled transition before bootstrapping (n-step returns; dtd: the
    low level's), cut at the episode's end; 1 is one-step DDPG; unset: the algorithm's."""
    noise_eps: Annotated[float, NOT_NEGATIVE] = 0.2
    """Exploration: std of Gaussian action noise, as a fraction of the largest action."""
    random_eps: Annotated[float, PROBABILITY] = 0.3
    """Exploration: probability of taking a uniformly random action instead."""
    # One thread by default: two OpenMP threads beside any other busy process wait for each
    # other and ran 2.5 to 4 times slower than one (benchmarks/contention.py, docs/results/speed.md).
    threads: Annotated[int, AUTOMATIC_OR_MORE] = 0
    """Torch threads of the learner; 0: OMP_NUM_THREADS where it is set, else one. A run records
    the number in its config.json; runs with the same number on one machine are the same bit
    for bit. More than one is faster only on a machine nothing else is using."""
    collector: Collection = Collection.auto
    """Where training episodes are collected; a matter of speed only: at the same thread count
    the run is the same."""
    collect_ahead: bool = True
    """Collect a cycle's episodes while the previous cycle's updates run, with the policy from
    before them (off: after them, as OpenAI baselines' HER; slower with a collecting process)."""
    device: Device = Device.auto
    """Where the learners' networks, optimisers and batches live: cpu, cuda, or auto, cuda where
    torch finds a GPU; replay and the collecting process's acting stay on the CPU. A run's
    checkpoints load on either (--resume RUN --device cpu moves a GPU run to the CPU)."""
    precision: Precision = Precision.auto
    """Number format of the networks' passes in an update, at both levels: float32, bfloat16,
    or auto (bfloat16 where the device computes it natively and it learned as float32 did, else
    float32); a new run records the one chosen, and keeps it on resume unless given."""
    workers: Annotated[int | None, AT_LEAST_1] = None
    """Data-parallel workers (torch.distributed): each collects its own episodes into its own
    replay; every update's gradients are averaged over all and the input statistics summed.
    An epoch is n_cycles cycles on every worker. Unset: 1 for a new run (under torchrun, its
    job's size); a resumed run's own, which another number cannot change."""
    learner: tyro.conf.OmitArgPrefixes[LearnerConfig] = LOW_LEVEL_DEFAULTS
    """Settings of the learner (of the low level, for dtd)."""
    dtd: Annotated[DotToDotConfig, tyro.conf.arg(name="")] = DotToDotConfig()
    """Dot-to-Dot's segments, sub-goal exploration, high-level relabelling and high level's
    learner (options without a prefix, but ``--high.<name>``); given to another algorithm,
    they are refused."""

    def __post_init__(self) -> None:
        """Every setting within its bound, checked where the settings are made (parsed, read
        from a run, replaced): a :class:`ConfigError` naming the first that is not."""
        validate(self)

    @property
    def low_learner(self) -> LearnerConfig:
        """The learner of ``her``, ``ddpg`` and dtd's low level as training uses it: an unset
        batch is the algorithm's (``LOW_LEVEL_BATCH``). A run records ``learner`` as given, and
        this batch among the facts derived from it."""
        if self.learner.batch_size is not None:
            return self.learner
        return dataclasses.replace(self.learner, batch_size=LOW_LEVEL_BATCH[self.algo])

    @property
    def low_n_step(self) -> int:
        """The rewards summed per sampled transition of the low level as training uses them: an
        unset ``n_step`` is the algorithm's (``LOW_LEVEL_N_STEP``)."""
        return self.n_step if self.n_step is not None else LOW_LEVEL_N_STEP[self.algo]

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready data (enums as their values)."""
        return plain_data(dataclasses.asdict(self))

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:
        """Inverse of :meth:`to_dict`, every value taken as it is; unknown keys and values of the
        wrong type are a :class:`ConfigError` naming the setting, missing keys take their
        defaults. Settings a run stored in an earlier format: :func:`read_settings`."""
        return cls(**typed_fields(cls, data, ""))
