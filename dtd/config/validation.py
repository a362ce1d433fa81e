"""Checks of a configuration's values, each failing with the option's name and what it must be."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from dtd.errors import ConfigError

if TYPE_CHECKING:
    from dtd.config.settings import LearnerConfig, TrainConfig


def validate(config: TrainConfig) -> None:
    """Raise :class:`ConfigError` naming the first setting of ``config`` that cannot work."""
    checks: list[tuple[bool, str]] = [
        (config.env is not None and config.env.strip() != "", "--env is required"),
        (config.epochs >= 1, f"--epochs must be at least 1, got {config.epochs}"),
        (config.n_cycles >= 1, f"--n-cycles must be at least 1, got {config.n_cycles}"),
        (
            config.episodes_per_cycle >= 1,
            f"--episodes-per-cycle must be at least 1, got {config.episodes_per_cycle}",
        ),
        (
            config.updates_per_cycle >= 0,
            f"--updates-per-cycle must be 0 or more, got {config.updates_per_cycle}",
        ),
        (
            config.explore_snapshots >= 0,
            f"--explore-snapshots must be 0 or more, got {config.explore_snapshots}",
        ),
        (
            config.test_episodes >= 1,
            f"--test-episodes must be at least 1, got {config.test_episodes}",
        ),
        (config.buffer_size >= 1, f"--buffer-size must be at least 1, got {config.buffer_size}"),
        (config.replay_k >= 0, f"--replay-k must be 0 or more, got {config.replay_k}"),
        (
            _finite_in(config.past_goal_share, 0, 1),
            f"--past-goal-share must lie in [0, 1], got {config.past_goal_share}",
        ),
        (_finite_in(config.noise_eps, 0, math.inf), f"--noise-eps must be >= 0, got {config.noise_eps}"),
        (
            _finite_in(config.random_eps, 0, 1),
            f"--random-eps must lie in [0, 1], got {config.random_eps}",
        ),
        (config.threads >= 0, f"--threads must be 0 (automatic) or more, got {config.threads}"),
        (config.seed >= 0, f"--seed must be 0 or more, got {config.seed}"),
        (
            config.workers is None or config.workers >= 1,
            f"--workers must be at least 1, got {config.workers}",
        ),
        (config.dtd.segments >= 2, f"--segments must be at least 2, got {config.dtd.segments}"),
        (
            _finite_in(config.dtd.subgoal_sigma, 0, math.inf),
            f"--subgoal-sigma must be >= 0, got {config.dtd.subgoal_sigma}",
        ),
        (
            _finite_in(config.dtd.subgoal_rotation_angle, 0, 180),
            f"--subgoal-rotation-angle must lie in [0, 180] degrees, got {config.dtd.subgoal_rotation_angle}",
        ),
        (
            _finite_in(config.dtd.subgoal_eps_start, 0, 1) and _finite_in(config.dtd.subgoal_eps_floor, 0, 1),
            "--subgoal-eps-start and --subgoal-eps-floor must lie in [0, 1]",
        ),
        (
            _finite_in(config.dtd.subgoal_eps_decay_epochs, 0, math.inf),
            f"--subgoal-eps-decay-epochs must be >= 0, got {config.dtd.subgoal_eps_decay_epochs}",
        ),
        (
            _finite_in(config.dtd.subgoal_noise, 0, math.inf),
            f"--subgoal-noise must be >= 0, got {config.dtd.subgoal_noise}",
        ),
        (
            _positive(config.dtd.subgoal_max_distance),
            f"--subgoal-max-distance must be > 0, got {config.dtd.subgoal_max_distance}",
        ),
        (
            config.n_step is None or config.n_step >= 1,
            f"--n-step must be at least 1 (left out: the algorithm's), got {config.n_step}",
        ),
        (config.dtd.high_replay_k >= 0, f"--high-replay-k must be 0 or more, got {config.dtd.high_replay_k}"),
        (
            config.dtd.high_updates_per_cycle >= 1,
            f"--high-updates-per-cycle must be at least 1, got {config.dtd.high_updates_per_cycle}",
        ),
        (
            _finite_in(config.dtd.hindsight_action_prob, 0, 1),
            f"--hindsight-action-prob must lie in [0, 1], got {config.dtd.hindsight_action_prob}",
        ),
    ]
    # The low level's batch may be unset (None): its algorithm's.
    checks += _learner_checks(config.learner, "--", may_be_unset=True)
    checks += _learner_checks(config.dtd.high, "--high.", may_be_unset=False)
    for ok, message in checks:
        if not ok:
            raise ConfigError(message)


def _learner_checks(learner: LearnerConfig, prefix: str, may_be_unset: bool) -> list[tuple[bool, str]]:
    """The checks of one learner's settings; the low level's batch ``may_be_unset`` (the
    algorithm's)."""
    unset = " (left out: the algorithm's)" if may_be_unset else ""
    return [
        (
            len(learner.hidden_sizes) >= 1 and all(h >= 1 for h in learner.hidden_sizes),
            f"{prefix}hidden-sizes must be positive widths, got {learner.hidden_sizes}",
        ),
        (_positive(learner.actor_lr), f"{prefix}actor-lr must be > 0, got {learner.actor_lr}"),
        (_positive(learner.critic_lr), f"{prefix}critic-lr must be > 0, got {learner.critic_lr}"),
        (
            (learner.batch_size is None and may_be_unset) or (learner.batch_size or 0) >= 1,
            f"{prefix}batch-size must be at least 1{unset}, got {learner.batch_size}",
        ),
        (_finite_in(learner.polyak, 0, 1), f"{prefix}polyak must lie in [0, 1], got {learner.polyak}"),
        (
            _finite_in(learner.action_l2, 0, math.inf),
            f"{prefix}action-l2 must be >= 0, got {learner.action_l2}",
        ),
        (
            learner.gamma is None or (_finite_in(learner.gamma, 0, 1) and learner.gamma > 0),
            f"{prefix}gamma must lie in (0, 1], got {learner.gamma}",
        ),
        (_positive(learner.norm_clip), f"{prefix}norm-clip must be > 0, got {learner.norm_clip}"),
        (_positive(learner.obs_clip), f"{prefix}obs-clip must be > 0, got {learner.obs_clip}"),
        (_positive(learner.norm_eps), f"{prefix}norm-eps must be > 0, got {learner.norm_eps}"),
        (learner.critics >= 1, f"{prefix}critics must be at least 1, got {learner.critics}"),
        (learner.actor_delay >= 1, f"{prefix}actor-delay must be at least 1, got {learner.actor_delay}"),
        (
            _finite_in(learner.target_noise, 0, math.inf)
            and _finite_in(learner.target_noise_clip, 0, math.inf),
            f"{prefix}target-noise and {prefix}target-noise-clip must be >= 0",
        ),
        (learner.quantiles >= 1, f"{prefix}quantiles must be at least 1, got {learner.quantiles}"),
        (
            0 <= learner.dropped_quantiles < learner.quantiles,
            f"{prefix}dropped-quantiles must lie in [0, --quantiles), got {learner.dropped_quantiles}",
        ),
        (
            _positive(learner.initial_temperature),
            f"{prefix}initial-temperature must be > 0, got {learner.initial_temperature}",
        ),
        (
            learner.target_entropy is None or math.isfinite(learner.target_entropy),
            f"{prefix}target-entropy must be a finite number, got {learner.target_entropy}",
        ),
    ]


def _positive(x: float) -> bool:
    return math.isfinite(x) and x > 0


def _finite_in(x: float, low: float, high: float) -> bool:
    return math.isfinite(x) and low <= x <= high
