"""The summary of groups of runs: per (environment, algorithm), the median and interquartile
range of final success and of the env steps and wall time to each success level; as CSV and as
an aligned table."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from dtd.experiments.curves import SMOOTHING, Curve, quantile
from dtd.experiments.run_curves import RunCurve, grouped

LEVELS = (0.5, 0.9)
"""Success levels the summary reports the env steps and wall time to."""


@dataclasses.dataclass(frozen=True)
class Spread:
    """Median and 25th / 75th percentiles over runs (``inf``: not reached)."""

    median: float
    q25: float
    q75: float

    @classmethod
    def of(cls, values: Sequence[float]) -> Spread:
        array = np.asarray(values, dtype=float)
        return cls(quantile(array, 0.5), quantile(array, 0.25), quantile(array, 0.75))


@dataclasses.dataclass(frozen=True)
class GroupSummary:
    """The figures of one (environment, algorithm) group of runs."""

    env: str
    label: str
    runs: int
    epochs_min: int
    epochs_max: int
    final_success: Spread
    """Each run's eval success at its last finished epoch."""
    reached: dict[float, int]
    """Per level, how many runs reached it."""
    steps_to: dict[float, Spread]
    wall_to: dict[float, Spread]


def summarise(env: str, label: str, curves: Sequence[Curve]) -> GroupSummary:
    """The :class:`GroupSummary` of one group's curves. Levels are met when eval success
    averaged over :data:`dtd.experiments.curves.SMOOTHING` epochs first reaches them."""
    steps_to, wall_to, reached = {}, {}, {}
    for level in LEVELS:
        hits = [curve.first_reaching(level) for curve in curves]
        steps_to[level] = Spread.of([hit[0] if hit else np.inf for hit in hits])
        wall_to[level] = Spread.of([hit[1] if hit else np.inf for hit in hits])
        reached[level] = sum(hit is not None for hit in hits)
    lengths = [len(curve) for curve in curves]
    return GroupSummary(
        env=env,
        label=label,
        runs=len(curves),
        epochs_min=min(lengths),
        epochs_max=max(lengths),
        final_success=Spread.of([curve.final_success for curve in curves]),
        reached=reached,
        steps_to=steps_to,
        wall_to=wall_to,
    )


def summaries(runs: Sequence[RunCurve]) -> list[GroupSummary]:
    return [
        summarise(env, label, curves)
        for env, labels in grouped(runs).items()
        for label, curves in labels.items()
    ]


def summary_csv(
    rows: Sequence[GroupSummary],
    extra: tuple[list[str], dict[tuple[str, str], list[str]]] | None = None,
) -> str:
    """The summary as CSV text: one row per group; ``inf`` where the median run (or a
    quartile) never reached the level. ``extra``: more columns (names, and cells per
    (environment, label)), e.g. the statistics of ``dtd plot --stats``."""
    header = ["env", "algo", "runs", "epochs_min", "epochs_max"]
    header += ["final_success_median", "final_success_q25", "final_success_q75"]
    for level in LEVELS:
        header += [f"reached_{level}"]
        header += [f"env_steps_to_{level}_{stat}" for stat in ("median", "q25", "q75")]
        header += [f"wall_s_to_{level}_{stat}" for stat in ("median", "q25", "q75")]
    if extra is not None:
        header += extra[0]
    lines = [",".join(header)]
    for row in rows:
        cells: list[object] = [row.env, row.label, row.runs, row.epochs_min, row.epochs_max]
        cells += _spread_cells(row.final_success, "{:.3f}")
        for level in LEVELS:
            cells.append(row.reached[level])
            cells += _spread_cells(row.steps_to[level], "{:.0f}")
            cells += _spread_cells(row.wall_to[level], "{:.1f}")
        if extra is not None:
            cells += extra[1].get((row.env, row.label), [""] * len(extra[0]))
        lines.append(",".join(map(str, cells)))
    return "\n".join(lines) + "\n"


def summary_table(rows: Sequence[GroupSummary]) -> str:
    """The summary as aligned text: median [25th-75th percentile] per figure."""
    heads = ["env", "algo", "runs", "epochs", "final success"]
    heads += [f"steps to {level}" for level in LEVELS] + [f"wall to {level}" for level in LEVELS]
    table = [heads]
    for row in rows:
        epochs = str(row.epochs_max)
        if row.epochs_min < row.epochs_max:
            epochs = f"{row.epochs_min}-{row.epochs_max}"
        cells = [row.env, row.label, str(row.runs), epochs, _spread_text(row.final_success, _plain)]
        for level in LEVELS:
            cells.append(_reached_text(row, level, row.steps_to[level], _steps))
        for level in LEVELS:
            cells.append(_reached_text(row, level, row.wall_to[level], _seconds))
        table.append(cells)
    widths = [max(len(line[column]) for line in table) for column in range(len(heads))]
    text = ["  ".join(cell.ljust(width) for cell, width in zip(line, widths, strict=True)) for line in table]
    text.append(
        f"median [25th-75th percentile] over runs; a level counts as reached when eval success "
        f"averaged over {SMOOTHING} epochs first meets it; final = eval success at each run's last epoch"
    )
    return "\n".join(text)


def _spread_cells(spread: Spread, form: str) -> list[str]:
    values = (spread.median, spread.q25, spread.q75)
    return ["inf" if np.isinf(value) else form.format(value) for value in values]


def _plain(value: float) -> str:
    return f"{value:.2f}"


def _steps(value: float) -> str:
    return f"{value / 1000:.0f}k" if value >= 10_000 else f"{value:.0f}"


def _seconds(value: float) -> str:
    return f"{value / 60:.0f} min" if value >= 600 else f"{value:.0f} s"


def _spread_text(spread: Spread, show) -> str:
    def one(value: float) -> str:
        return "not reached" if np.isinf(value) else show(value)

    return f"{one(spread.median)} [{one(spread.q25)}-{one(spread.q75)}]"


def _reached_text(row: GroupSummary, level: float, spread: Spread, show) -> str:
    if row.reached[level] == 0:
        return "not reached"
    if np.isinf(spread.median) and np.isinf(spread.q25):
        return f"not reached ({row.reached[level]}/{row.runs})"
    text = _spread_text(spread, show)
    return text if row.reached[level] == row.runs else f"{text} ({row.reached[level]}/{row.runs})"
