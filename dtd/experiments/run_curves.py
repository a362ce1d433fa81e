"""Runs found on disk with their learning curves and final successes: grouped by environment and
algorithm, and cut at an env-step budget to compare runs of different lengths."""

from __future__ import annotations

import dataclasses
import functools
import json
import warnings
from collections.abc import Sequence
from pathlib import Path

from dtd.config import Collection, Preset, TrainConfig, flat_items, with_algorithm_defaults
from dtd.errors import ConfigError, RunDirError
from dtd.experiments.curves import Curve, read_curve
from dtd.training.run_dir import RunDir, read_config


class UnreadableRun(UserWarning):
    """A run left out of the figures because its files cannot be read."""


@dataclasses.dataclass(frozen=True)
class RunCurve:
    """One run found on disk: where it is, what it trained, and its curve."""

    run_dir: Path
    env: str
    label: str
    """The algorithm, with `` (preset)`` where the preset is not the tuned default, and the
    settings (``name=value``) in which the run differs from others of its task, algorithm and
    preset found with it (a sweep's grid)."""
    curve: Curve
    test_episodes: int = 10
    """Evaluation episodes behind each epoch's eval success."""


@dataclasses.dataclass(frozen=True)
class FinalSuccess:
    """A run's final success and what it was measured on."""

    value: float
    episodes: int
    """Evaluation episodes behind it."""
    env_steps: float
    """Env steps of the run's last epoch."""
    saved: bool
    """Whether it is the saved evaluation of the last checkpoint (RUN/eval-latest.json) rather
    than the last epoch's eval success in metrics.csv."""


def final_success(run: RunCurve) -> FinalSuccess:
    """A run's final success: the saved evaluation of its latest checkpoint when that is of the
    last epoch in its curve (``dtd eval RUN --episodes 100 --save``, ``dtd sweep
    --final-episodes``), else the last epoch's eval success (over ``test_episodes``, noisier)."""
    last_epoch, env_steps = int(run.curve.epoch[-1]), float(run.curve.env_steps[-1])
    saved = RunDir(run.run_dir).final_evaluation
    evaluation = _saved_evaluation(saved, saved.stat().st_mtime_ns) if saved.is_file() else None
    if evaluation is not None and evaluation[0] == last_epoch:
        return FinalSuccess(evaluation[1], evaluation[2], env_steps, True)
    return FinalSuccess(run.curve.final_success, run.test_episodes, env_steps, False)


@functools.cache
def _saved_evaluation(path: Path, modified_ns: int) -> tuple[int, float, int] | None:
    """Epoch, success rate and episodes of a saved evaluation; None, with a warning (once per
    version of the file), where it cannot be read."""
    try:
        evaluation = json.loads(path.read_text())
        return int(evaluation["epoch"]), float(evaluation["success_rate"]), int(evaluation["episodes"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        reason = f"{type(exc).__name__}: {exc}"[:200]
        warnings.warn(
            f"{path} is unreadable ({reason}); the run's final is its last epoch's evaluation", stacklevel=3
        )
        return None


def find_runs(directories: Sequence[Path]) -> list[RunCurve]:
    """Every run under ``directories`` that has finished at least one epoch, sorted by path.

    Two runs with the same settings but for the epoch budget (and where episodes are collected,
    a matter of speed only) are one trial found twice, say a copy of an unfinished run beside
    the run itself: the one with the most epochs counts, and a warning names the other. A run
    whose config.json or metrics.csv cannot be read is left out with an
    :class:`UnreadableRun` warning naming it and why.
    """
    run_dirs: set[Path] = set()
    for directory in map(Path, directories):
        if not directory.is_dir():
            raise RunDirError(f"{directory} is not a directory")
        run_dirs.update(path.resolve().parent for path in directory.rglob("config.json"))
    trials: dict[TrainConfig, RunCurve] = {}
    configs: dict[Path, TrainConfig] = {}
    for run_dir in sorted(run_dirs):
        try:
            config = read_config(RunDir(run_dir))
            curve = read_curve(run_dir)
        except RunDirError as exc:
            warnings.warn(UnreadableRun(f"skipped {run_dir}: {exc}"), stacklevel=2)
            continue
        if len(curve) == 0:
            continue
        run = RunCurve(run_dir, config.env or "?", config.algo.value, curve, config.test_episodes)
        # What the algorithm chose counts as given: runs that recorded it and runs that left it
        # to the algorithm are the same trial, and are labelled alike.
        config = with_algorithm_defaults(config)
        trial = dataclasses.replace(config, epochs=1, collector=Collection.auto)
        if trial in trials:
            kept, dropped = sorted([trials[trial], run], key=lambda r: len(r.curve), reverse=True)
            warnings.warn(
                f"{dropped.run_dir} repeats the trial in {kept.run_dir} ({len(dropped.curve)} "
                f"against {len(kept.curve)} epochs); only the longer one counts",
                stacklevel=2,
            )
            run = kept
        trials[trial] = run
        configs[run.run_dir] = config
    runs = sorted(trials.values(), key=lambda run: run.run_dir)
    labels = setting_labels([configs[run.run_dir] for run in runs])
    return [dataclasses.replace(run, label=label) for run, label in zip(runs, labels, strict=True)]


LABEL_IGNORES = frozenset(
    {"seed", "epochs", "collector", "threads", "workers", "device", "explore_snapshots", "test_episodes"}
)
"""Settings that never name a group of runs: the seed, the budget, and matters of speed or of
what a run keeps for later."""


def setting_labels(configs: Sequence[TrainConfig]) -> list[str]:
    """Each configuration's label (its algorithm's choices made concrete): its algorithm,
    `` (preset)`` where not the tuned default, then the settings in which it differs from the
    others of its task, algorithm and preset, as ``name=value`` in option names (``learner=tqc
    high.learner=tqc``)."""
    flats = [
        {name: value for name, value in flat_items(config).items() if name not in LABEL_IGNORES}
        for config in configs
    ]
    kin: dict[tuple[str, str, str], list[int]] = {}
    for index, config in enumerate(configs):
        kin.setdefault((config.env or "?", config.algo.value, config.preset.value), []).append(index)
    labels = []
    for index, config in enumerate(configs):
        label = config.algo.value
        if config.preset is not Preset.tuned:
            label += f" ({config.preset.value})"
        group = kin[(config.env or "?", config.algo.value, config.preset.value)]
        mine = flats[index]
        differing = [name for name, value in mine.items() if any(flats[i].get(name) != value for i in group)]
        labels.append(" ".join([label, *(f"{name}={_compact(mine[name])}" for name in differing)]))
    return labels


def _compact(value: object) -> str:
    if isinstance(value, list):
        return "[" + ",".join(map(str, value)) + "]"
    return str(value)


def grouped_runs(runs: Sequence[RunCurve]) -> dict[str, dict[str, list[RunCurve]]]:
    """Runs by environment (:func:`env_order`), then by label (:func:`label_order`)."""
    groups: dict[str, dict[str, list[RunCurve]]] = {}
    for run in sorted(runs, key=lambda run: (env_order(run.env), label_order(run.label), str(run.run_dir))):
        groups.setdefault(run.env, {}).setdefault(run.label, []).append(run)
    return groups


def grouped(runs: Sequence[RunCurve]) -> dict[str, dict[str, list[Curve]]]:
    """Curves by environment, then by label, in the order of :func:`grouped_runs`."""
    return {
        env: {label: [run.curve for run in members] for label, members in labels.items()}
        for env, labels in grouped_runs(runs).items()
    }


def cut_at(runs: Sequence[RunCurve], env_steps: float) -> list[RunCurve]:
    """``runs`` as they were at ``env_steps``, to compare them at one budget; a run with no
    epoch that early is left out."""
    if not env_steps > 0:
        raise ConfigError(f"--max-env-steps must be a positive number of env steps, got {env_steps}")
    cut = [dataclasses.replace(run, curve=run.curve.up_to(env_steps)) for run in runs]
    return [run for run in cut if len(run.curve) > 0]


_COLOURS = {"ddpg": "tab:green", "her": "tab:blue", "dtd": "tab:red"}


def colour_of(label: str) -> str | None:
    """The colour of an algorithm's label in every figure, its presets' included; None (the
    figure's next colour) for a label that names settings, one of several of its algorithm."""
    if "=" in label:
        return None
    return _COLOURS.get(label.split(" ")[0])


_PAPER_TASKS = ("FetchPush", "FetchPickAndPlace", "HandManipulateBlock")


_OTHER_COLOURS = ("tab:purple", "tab:orange", "tab:brown", "tab:pink", "tab:olive", "tab:cyan", "tab:gray")


def label_colours(labels: Sequence[str]) -> dict[str, str]:
    """A colour per label, the same in every panel of a figure: an algorithm's own where the label
    is the algorithm's alone (or a preset's), else the next of a fixed list."""
    colours: dict[str, str] = {}
    others = iter(_OTHER_COLOURS * (len(labels) // len(_OTHER_COLOURS) + 1))
    for label in labels:
        colours[label] = colour_of(label) or next(others)
    return colours


def env_order(env: str) -> tuple[int, str]:
    """The paper's tasks in its order (FetchPush, FetchPickAndPlace, HandManipulateBlock, each
    in any version or variant), then any other environment by name."""
    name = env.split(":")[-1].split("-v")[0]
    rank = next((rank for rank, task in enumerate(_PAPER_TASKS) if name.startswith(task)), len(_PAPER_TASKS))
    return rank, env


def label_order(label: str) -> tuple[int, str]:
    """ddpg, her, dtd, then any other label; presets after the tuned default."""
    order = {"ddpg": 0, "her": 1, "dtd": 2}
    return order.get(label.split(" ")[0], 3), label
