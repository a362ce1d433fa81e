"""Learning curves read back from runs' ``metrics.csv``, and the figures taken from them."""

from __future__ import annotations

import csv
import dataclasses
from pathlib import Path

import numpy as np

from dtd.errors import RunDirError
from dtd.training.run_dir import RunDir

SMOOTHING = 3
"""Epochs whose eval success is averaged when a curve is asked when it first reached a level:
one epoch's 10 evaluation episodes reach 0.5 by chance long before the policy does."""


LEVEL_TOLERANCE = 1e-9
"""A level counts as met by a mean that rounding put just below it (success rates are
multiples of one over the number of test episodes)."""


@dataclasses.dataclass(frozen=True)
class Curve:
    """One run's per-epoch figures, in epoch order."""

    epoch: np.ndarray
    env_steps: np.ndarray
    wall_s: np.ndarray
    eval_success: np.ndarray

    def __len__(self) -> int:
        return len(self.epoch)

    @property
    def final_success(self) -> float:
        return float(self.eval_success[-1]) if len(self) else float("nan")

    def up_to(self, env_steps: float) -> Curve:
        """The curve cut after its last epoch at or before ``env_steps``: the run as it was at
        that budget (the whole curve if it stopped earlier)."""
        keep = self.env_steps <= env_steps
        return Curve(self.epoch[keep], self.env_steps[keep], self.wall_s[keep], self.eval_success[keep])

    def smoothed(self, window: int = SMOOTHING) -> np.ndarray:
        """Eval success averaged over each epoch and the ``window - 1`` before it (fewer at
        the start)."""
        if window < 1:
            raise ValueError(f"window must be at least 1, got {window}")
        # Each window summed on its own: a running sum's differences drift (0.9 became 0.8999...).
        values = self.eval_success
        return np.array([values[max(end - window, 0) : end].mean() for end in range(1, len(self) + 1)])

    def first_reaching(self, level: float, window: int = SMOOTHING) -> tuple[int, float] | None:
        """(env steps, wall seconds) at the first epoch whose smoothed eval success is at
        least ``level``; None if it never is."""
        reached = np.flatnonzero(self.smoothed(window) >= level - LEVEL_TOLERANCE)
        if len(reached) == 0:
            return None
        first = reached[0]
        return int(self.env_steps[first]), float(self.wall_s[first])


def read_curve(run_dir: Path) -> Curve:
    """The curve of the run in ``run_dir`` (empty if it has not finished an epoch); a
    metrics.csv that is not text, lacks a column or holds a truncated or malformed row is a
    :class:`RunDirError` naming the file and the line."""
    run = RunDir(Path(run_dir))
    if not run.metrics.exists():
        if not run.config.exists():
            raise RunDirError(f"{run.root} holds no run (no config.json)")
        return Curve(*(np.zeros(0) for _ in range(4)))
    columns = ("epoch", "env_steps", "wall_s", "eval_success")
    try:
        with open(run.metrics, newline="", encoding="utf-8") as file:
            reader = csv.DictReader(file)
            missing = [name for name in columns if name not in (reader.fieldnames or [])]
            if missing:
                raise RunDirError(f"{run.metrics} is not a dtd metrics file (no {', '.join(missing)} column)")
            values: list[list[float]] = []
            for row in reader:
                if None in row or None in row.values():
                    fields = sum(value is not None for key, value in row.items() if key is not None)
                    fields += len(row.get(None) or [])  # type: ignore[call-overload]
                    raise RunDirError(
                        f"{run.metrics} line {reader.line_num} has {fields} fields where the header "
                        f"has {len(reader.fieldnames or [])} (a truncated or malformed row)"
                    )
                values.append([float(row[name]) for name in columns])
    except (UnicodeDecodeError, csv.Error) as exc:
        raise RunDirError(f"{run.metrics} is not a dtd metrics file ({exc})") from exc
    except ValueError as exc:
        raise RunDirError(
            f"{run.metrics} line {reader.line_num} holds a value that is not a number ({exc})"
        ) from exc
    table = np.array(values, dtype=float).reshape(-1, len(columns))
    return Curve(*(table[:, column] for column in range(len(columns))))


def quantile(values: np.ndarray, q: float) -> float:
    """The ``q`` quantile of ``values`` (linear between order statistics), where ``inf`` stands
    for "never reached": any interpolation toward an ``inf`` is ``inf`` (NumPy's would be NaN)."""
    ordered = np.sort(np.asarray(values, dtype=float))
    if len(ordered) == 0:
        return float("nan")
    position = q * (len(ordered) - 1)
    low, high = int(np.floor(position)), int(np.ceil(position))
    if low == high or ordered[low] == ordered[high]:
        return float(ordered[low])
    if np.isinf(ordered[high]):
        return float("inf")
    return float(ordered[low] + (position - low) * (ordered[high] - ordered[low]))


@dataclasses.dataclass(frozen=True)
class Band:
    """Eval success over several runs, epoch by epoch: the mean and the 25th-75th percentile
    band. A run that stopped earlier counts only at the epochs it has; ``runs`` says how many
    runs each point is over (never padded)."""

    epoch: np.ndarray
    env_steps: np.ndarray
    mean: np.ndarray
    low: np.ndarray
    high: np.ndarray
    runs: np.ndarray


def band(curves: list[Curve]) -> Band:
    """The :class:`Band` of ``curves`` (of runs whose epochs hold the same env steps)."""
    length = max((len(curve) for curve in curves), default=0)
    columns: dict[str, list[float]] = {name: [] for name in ("epoch", "env_steps", "mean", "low", "high")}
    runs = []
    for index in range(length):
        present = [curve for curve in curves if len(curve) > index]
        values = np.array([curve.eval_success[index] for curve in present])
        columns["epoch"].append(float(np.median([curve.epoch[index] for curve in present])))
        columns["env_steps"].append(float(np.median([curve.env_steps[index] for curve in present])))
        columns["mean"].append(float(values.mean()))
        columns["low"].append(quantile(values, 0.25))
        columns["high"].append(quantile(values, 0.75))
        runs.append(len(present))
    arrays = {name: np.array(column) for name, column in columns.items()}
    return Band(**arrays, runs=np.array(runs, dtype=int))
