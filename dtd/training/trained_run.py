"""A trained run brought back from its directory: its agent restored from a checkpoint, and
deterministic evaluation episodes of it."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import gymnasium as gym

from dtd.agents.interface import Agent
from dtd.config import EVAL_SEED, Device, TrainConfig
from dtd.errors import ConfigError
from dtd.training.atomic import write_text_atomic
from dtd.training.checkpoint import Checkpoint
from dtd.training.components import Acting, build_acting
from dtd.training.rollout import episode_figures, run_many
from dtd.training.run_dir import CHECKPOINT_NAMES, RunDir, read_config


@dataclasses.dataclass
class LoadedRun(Acting):
    """A trained run brought back: its agent, restored from one checkpoint, acting on seeded
    evaluation environments (close them with :meth:`close`, or use it in ``with``), and its
    settings and checkpoint."""

    run: RunDir
    config: TrainConfig
    path: Path
    """The checkpoint file it was loaded from."""
    checkpoint: Checkpoint

    def __enter__(self) -> LoadedRun:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def on_the_cpu(config: TrainConfig) -> TrainConfig:
    """A run's settings for acting: looking at a trained agent needs no GPU, wherever it was
    trained."""
    return dataclasses.replace(config, device=Device.cpu)


def load_run(
    run_dir: Path | str, checkpoint: str = "latest", seed: int = EVAL_SEED, envs: int = 1
) -> LoadedRun:
    """A run's agent restored from a checkpoint (without its replay), on ``envs`` evaluation
    environments seeded by ``seed``; raises :class:`DtdError` subclasses for missing or
    foreign files."""
    run = RunDir(Path(run_dir))
    config = read_config(run)
    path = run.checkpoint(checkpoint)
    stored = Checkpoint.read(path)
    acting = build_acting(on_the_cpu(config), eval_seed=seed, eval_envs=envs)
    try:
        stored.check_fits(config, acting.spec, path)
        stored.load_agent(acting.agent, path)
    except BaseException:
        acting.close()
        raise
    return LoadedRun(acting.spec, acting.agent, acting.envs, acting.rng, run, config, path, stored)


def load_agent(run_dir: Path | str, checkpoint: str = "latest") -> tuple[Agent, gym.Env]:
    """A trained agent and an environment of its task, e.g. to query ``subgoal_values``."""
    loaded = load_run(Path(run_dir), checkpoint)
    return loaded.agent, loaded.envs[0]


def evaluate_run(
    run_dir: Path | str,
    episodes: int = 100,
    checkpoint: str = "latest",
    seed: int = EVAL_SEED,
    show_subgoals: bool = False,
) -> dict[str, Any]:
    """Deterministic episodes of a trained agent; the figures as a dict. For a dtd run also
    ``subgoal_placement``, where the sub-goals lay along the way by the goal's distance (see
    :meth:`Planner.placement_by_distance`), and with ``show_subgoals`` ``plans``, the
    high level's sub-goals per episode."""
    if episodes < 1:
        raise ConfigError(f"--episodes must be at least 1, got {episodes}")
    config = read_config(RunDir(Path(run_dir)))
    if show_subgoals and not config.algo.sets_subgoals:
        raise ConfigError(f"--show-subgoals needs a dtd run; {run_dir} is a {config.algo.value} run")
    with load_run(run_dir, checkpoint, seed, envs=min(episodes, 10)) as loaded:
        played = run_many(loaded.envs, loaded.agent, loaded.spec, episodes, explore=False, rng=loaded.rng)
    figures = episode_figures(loaded.agent, played)
    result: dict[str, Any] = {
        "run_dir": str(loaded.run.root),
        "checkpoint": str(loaded.path),
        "env": config.env,
        "algo": config.algo.value,
        "epoch": loaded.checkpoint.epoch,
        "env_steps": loaded.checkpoint.env_steps,
        "episodes": episodes,
        "seed": seed,
        "success_rate": figures.pop("success"),
        "mean_final_distance": figures.pop("final_distance"),
        **figures,
    }
    planner = loaded.agent.planner()
    if planner is not None:
        result["subgoal_placement"] = planner.placement_by_distance(played)
        if show_subgoals:
            result["plans"] = planner.plan(played)
    return result


def saved_evaluation_path(run_dir: Path | str, checkpoint: str = "latest") -> Path:
    """Where ``dtd eval --save`` keeps the evaluation of ``checkpoint``: RUN/eval-NAME.json."""
    name = checkpoint if checkpoint in CHECKPOINT_NAMES else Path(checkpoint).stem
    return Path(run_dir) / f"eval-{name}.json"


def save_evaluation(result: dict[str, Any], run_dir: Path | str, checkpoint: str = "latest") -> Path:
    """Write an :func:`evaluate_run` result (without its plans) beside the run, atomically;
    the checkpoint named relative to the run (the file lies in it, so it names no run
    directory), so that the run reads the same when copied elsewhere."""
    path = saved_evaluation_path(run_dir, checkpoint)
    run = RunDir(Path(run_dir))
    kept = {key: value for key, value in result.items() if key not in ("plans", "run_dir")}
    kept["checkpoint"] = run.named(result["checkpoint"])
    write_text_atomic(path, json.dumps(kept, indent=1) + "\n")
    return path


def final_evaluation(run_dir: Path | str, episodes: int) -> Path:
    """The run's latest checkpoint evaluated over ``episodes`` episodes and saved, unless an
    evaluation of that epoch over at least as many episodes is saved already."""
    path = saved_evaluation_path(run_dir)
    epoch = Checkpoint.read(RunDir(Path(run_dir)).latest).epoch
    if path.is_file():
        try:
            saved = json.loads(path.read_text())
            if saved.get("epoch") == epoch and saved.get("episodes", 0) >= episodes:
                return path
        except ValueError:
            pass
    return save_evaluation(evaluate_run(run_dir, episodes), run_dir)
