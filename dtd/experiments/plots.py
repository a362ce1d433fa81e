"""Training curves of many runs: one figure per environment, one of every environment side by
side (the paper's layout), and a summary table.

Runs are found under the given directories (any folder holding a config.json), grouped by
environment and then by algorithm (with the preset, where it is not the tuned default), and
drawn as the mean eval success over seeds with the 25th-75th percentile band, against epochs
and against env steps. The summary gives, per group, the median and interquartile range of
final success and of the env steps and wall time to reach each success level.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dtd.errors import RunDirError
from dtd.experiments.curves import Curve, band
from dtd.experiments.run_curves import UnreadableRun, cut_at, env_order, find_runs, grouped, label_colours
from dtd.experiments.statistics import (
    check_intervals_possible,
    draw_statistics,
    group_statistics,
    require_rliable,
    statistics_columns,
    statistics_table,
)
from dtd.experiments.summary import summaries, summary_csv, summary_table
from dtd.figures import pyplot, save_figure
from dtd.training.atomic import staged

TASKS_FIGURE = "tasks"
"""The stem of the figure of every environment side by side (written for runs of two or more)."""


def draw(env: str, labels: dict[str, list[Curve]], path_stem: Path) -> list[Path]:
    """Draw one environment's curves against epochs and against env steps; write PNG and SVG
    beside ``path_stem``; return the files written."""
    plt = pyplot()
    from matplotlib import ticker

    figure, axes = plt.subplots(1, 2, figsize=(12, 4.5), sharey=True, layout="constrained")
    faint = False
    colours = label_colours(list(labels))
    for label, curves in labels.items():
        faint |= _draw_label(axes, ("epoch", "env_steps"), label, curves, colours[label])
    axes[0].set_xlabel("epoch")
    axes[0].xaxis.set_major_locator(ticker.MaxNLocator(integer=True))
    axes[1].set_xlabel("env steps")
    axes[0].set_ylabel("eval success rate")
    _finish_axes(axes)
    axes[0].legend(loc="upper left")
    figure.suptitle(f"{env}: mean over seeds, band = 25th-75th percentile{_faint_note(faint)}")
    return save_figure(figure, path_stem)


def draw_tasks(groups: dict[str, dict[str, list[Curve]]], path_stem: Path) -> list[Path]:
    """The paper's layout: one panel per environment, eval success against env steps, every
    algorithm's mean over seeds and 25th-75th percentile band, in the colours of every other
    figure; write PNG and SVG beside ``path_stem``; return the files written."""
    plt = pyplot()
    from matplotlib import ticker

    figure, axes = plt.subplots(
        1, len(groups), figsize=(4.6 * len(groups), 4.2), sharey=True, layout="constrained", squeeze=False
    )
    faint = False
    colours = label_colours(list(dict.fromkeys(label for labels in groups.values() for label in labels)))
    for axis, (env, labels) in zip(axes[0], groups.items(), strict=True):
        for label, curves in labels.items():
            faint |= _draw_label([axis], ("env_steps",), label, curves, colours[label])
        axis.set_title(env.split(":")[-1])
        axis.set_xlabel("env steps")
        axis.xaxis.set_major_formatter(ticker.EngFormatter(sep=""))
        axis.legend(loc="upper left", fontsize="small")
    axes[0][0].set_ylabel("eval success rate")
    _finish_axes(axes[0])
    figure.suptitle(f"Mean over seeds, band = 25th-75th percentile{_faint_note(faint)}")
    return save_figure(figure, path_stem)


def _draw_label(
    axes: Sequence[Any], against: Sequence[str], label: str, curves: list[Curve], colour: str
) -> bool:
    """Draw ``label``'s mean over seeds and band on each axis, against the :class:`Band` field
    named beside it ("epoch" or "env_steps"); return whether part of it is past the shortest
    run (drawn faint, as it is over fewer seeds)."""
    stats = band(curves)
    # A preset's line is dashed; a label's settings may hold brackets of their own.
    style = {"color": colour, "linestyle": "--" if " (" in label.split("=")[0] else "-"}
    complete = stats.runs == len(curves)
    name = f"{label} ({len(curves)} seed{'s' if len(curves) != 1 else ''})"
    for axis, field in zip(axes, against, strict=True):
        x = getattr(stats, field)
        axis.plot(x[complete], stats.mean[complete], label=name, **style)
        if not complete.all():
            start = max(np.flatnonzero(~complete)[0] - 1, 0)
            axis.plot(x[start:], stats.mean[start:], color=colour, ls=style["linestyle"], alpha=0.35)
        axis.fill_between(x, stats.low, stats.high, color=colour, alpha=0.2, linewidth=0)
    return not complete.all()


def _finish_axes(axes: Sequence[Any]) -> None:
    for axis in axes:
        axis.set_ylim(-0.02, 1.02)
        axis.grid(alpha=0.3)


def _faint_note(faint: bool) -> str:
    return " (faint: past the shortest run, over fewer seeds)" if faint else ""


@dataclasses.dataclass(frozen=True)
class PlotResult:
    figures: list[Path]
    summary_csv: Path
    table: str


def plot(
    directories: Sequence[Path], out: Path, max_env_steps: float | None = None, stats: bool = False
) -> PlotResult:
    """Find the runs under ``directories``; write a figure per environment and summary.csv
    into ``out``, and where the runs span two or more environments the paper's layout of them
    side by side (:func:`draw_tasks`, ``tasks.png``). With ``max_env_steps``, every run is
    taken as it was at that budget (:func:`cut_at`), so that runs of different lengths are
    compared at one. With ``stats``, also the aggregate statistics of final success
    (:mod:`dtd.experiments.statistics`): a figure per environment (ENV-stats), columns of
    summary.csv and a table."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        runs = find_runs(directories)
    unreadable = [str(warning.message) for warning in caught if issubclass(warning.category, UnreadableRun)]
    if max_env_steps is not None:
        runs = cut_at(runs, max_env_steps)
    if not runs:
        budget = f" within {max_env_steps:,.0f} env steps" if max_env_steps is not None else ""
        reasons = f" ({'; '.join(unreadable)})" if unreadable else ""
        raise RunDirError(
            f"no run with a finished epoch{budget} under "
            + ", ".join(str(directory) for directory in directories)
            + reasons
        )
    for warning in caught:  # passed on, now that the runs left out are not the whole answer
        warnings.warn_explicit(warning.message, warning.category, warning.filename, warning.lineno)
    if stats:
        require_rliable()
        check_intervals_possible(runs)
    groups = grouped(runs)
    rows = summaries(runs)
    statistics = group_statistics(runs) if stats else []
    drawn: list[Path] = []
    # Every figure and summary.csv at once: a full disk or an interrupt leaves --out as it was.
    with staged(Path(out), "the figures") as folder:
        for env, labels in groups.items():
            drawn += draw(env, labels, folder / env.split(":")[-1])
        if len(groups) > 1:
            drawn += draw_tasks(groups, folder / TASKS_FIGURE)
        extra = None
        if statistics:
            extra = statistics_columns(statistics)
            for env in sorted({group.env for group in statistics}, key=env_order):
                in_env = [group for group in statistics if group.env == env]
                drawn += draw_statistics(env, in_env, folder / f"{env.split(':')[-1]}-stats")
        (folder / "summary.csv").write_text(summary_csv(rows, extra))
    figures = [Path(out) / path.relative_to(folder) for path in drawn]
    csv_path = Path(out) / "summary.csv"
    table = summary_table(rows)
    if statistics:
        table += "\n\n" + statistics_table(statistics)
    if max_env_steps is not None:
        table += f"\nevery run as it was at {max_env_steps:,.0f} env steps (--max-env-steps)"
    return PlotResult(figures, csv_path, table)
