"""The summary of groups of runs: per (environment, algorithm), the median and interquartile
range of final success (each run's saved evaluation of its last checkpoint where there is one)
and of the env steps and wall time to each success level; as CSV and as an aligned table."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from dtd.experiments.curves import SMOOTHING, quantile
from dtd.experiments.run_curves import RunCurve, final_success, grouped_runs

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
    """Of each run's :func:`dtd.experiments.run_curves.final_success`."""
    final_episodes: tuple[int, int]
    """Fewest and most evaluation episodes behind a run's final success."""
    final_env_steps: tuple[float, float]
    """Fewest and most env steps of a run's last epoch: the budgets the finals were reached in."""
    reached: dict[float, int]
    """Per level, how many runs reached it."""
    steps_to: dict[float, Spread]
    wall_to: dict[float, Spread]


def summarise(env: str, label: str, runs: Sequence[RunCurve]) -> GroupSummary:
    """The :class:`GroupSummary` of one group's runs. Levels are met when eval success
    averaged over :data:`dtd.experiments.curves.SMOOTHING` epochs first reaches them."""
    curves = [run.curve for run in runs]
    finals = [final_success(run) for run in runs]
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
        final_success=Spread.of([final.value for final in finals]),
        final_episodes=(min(final.episodes for final in finals), max(final.episodes for final in finals)),
        final_env_steps=(min(final.env_steps for final in finals), max(final.env_steps for final in finals)),
        reached=reached,
        steps_to=steps_to,
        wall_to=wall_to,
    )


def summaries(runs: Sequence[RunCurve]) -> list[GroupSummary]:
    return [
        summarise(env, label, members)
        for env, labels in grouped_runs(runs).items()
        for label, members in labels.items()
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
    header += ["final_episodes_min", "final_episodes_max", "final_env_steps_min", "final_env_steps_max"]
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
        cells += [*row.final_episodes, *(f"{steps:.0f}" for steps in row.final_env_steps)]
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
    heads = ["env", "algo", "runs", "epochs", "final success", "final over", "final at"]
    heads += [f"steps to {level}" for level in LEVELS] + [f"wall to {level}" for level in LEVELS]
    table = [heads]
    for row in rows:
        epochs = str(row.epochs_max)
        if row.epochs_min < row.epochs_max:
            epochs = f"{row.epochs_min}-{row.epochs_max}"
        cells = [row.env, row.label, str(row.runs), epochs, _spread_text(row.final_success, _two_decimals)]
        cells.append(f"{span_text(row.final_episodes, str)} episodes")
        cells.append(span_text(row.final_env_steps, steps_text))
        for level in LEVELS:
            cells.append(_reached_text(row, level, row.steps_to[level], steps_text))
        for level in LEVELS:
            cells.append(_reached_text(row, level, row.wall_to[level], _seconds))
        table.append(cells)
    widths = [max(len(line[column]) for line in table) for column in range(len(heads))]
    text = ["  ".join(cell.ljust(width) for cell, width in zip(line, widths, strict=True)) for line in table]
    text.append(
        f"median [25th-75th percentile] over runs; a level counts as reached when eval success "
        f"averaged over {SMOOTHING} epochs first meets it"
    )
    text.append(
        "final = each run's saved evaluation of its last checkpoint (dtd eval --save, dtd sweep "
        "--final-episodes) where there is one, else its last epoch's eval success; final over: the "
        "episodes behind it; final at: the env steps of the runs' last epochs"
    )
    return "\n".join(text)


def span_text(bounds: tuple[float, float], show) -> str:
    """``low-high`` shown by ``show``, or one value where they are equal."""
    low, high = bounds
    return show(low) if low == high else f"{show(low)}-{show(high)}"


def _spread_cells(spread: Spread, form: str) -> list[str]:
    values = (spread.median, spread.q25, spread.q75)
    return ["inf" if np.isinf(value) else form.format(value) for value in values]


def _two_decimals(value: float) -> str:
    return f"{value:.2f}"


def steps_text(value: float) -> str:
    """Env steps, short: 950, 20k, 1.74M."""
    if value >= 1_000_000:
        return f"{value / 1_000_000:.3g}M"
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
