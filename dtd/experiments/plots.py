"""Training curves of many runs: one figure per environment and a summary table.

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

import numpy as np

from dtd.atomic import write_text_atomic
from dtd.config import Collection, Preset, TrainConfig
from dtd.curves import SMOOTHING, Curve, band, quantile, read_curve
from dtd.errors import ConfigError, RunDirError
from dtd.run_dir import RunDir, read_config

LEVELS = (0.5, 0.9)
"""Success levels the summary reports the env steps and wall time to."""

_COLOURS = {"ddpg": "tab:green", "her": "tab:blue", "dtd": "tab:red"}


@dataclasses.dataclass(frozen=True)
class RunCurve:
    """One run found on disk: where it is, what it trained, and its curve."""

    run_dir: Path
    env: str
    label: str
    """The algorithm, with `` (preset)`` where the preset is not the tuned default."""
    curve: Curve


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


def find_runs(directories: Sequence[Path]) -> list[RunCurve]:
    """Every run under ``directories`` that has finished at least one epoch, sorted by path.

    Two runs with the same settings but for the epoch budget (and where episodes are collected,
    a matter of speed only) are one trial found twice, say a copy of an unfinished run beside
    the run itself: the one with the most epochs counts, and a warning names the other.
    """
    run_dirs: set[Path] = set()
    for directory in map(Path, directories):
        if not directory.is_dir():
            raise RunDirError(f"{directory} is not a directory")
        run_dirs.update(path.resolve().parent for path in directory.rglob("config.json"))
    trials: dict[TrainConfig, RunCurve] = {}
    for run_dir in sorted(run_dirs):
        config = read_config(RunDir(run_dir))
        curve = read_curve(run_dir)
        if len(curve) == 0:
            continue
        label = config.algo.value
        if config.preset is not Preset.tuned:
            label += f" ({config.preset.value})"
        run = RunCurve(run_dir, config.env or "?", label, curve)
        trial = dataclasses.replace(config, epochs=0, collector=Collection.auto)
        if trial in trials:
            kept, dropped = sorted([trials[trial], run], key=lambda r: len(r.curve), reverse=True)
            warnings.warn(
                f"{dropped.run_dir} repeats the trial in {kept.run_dir} ({len(dropped.curve)} "
                f"against {len(kept.curve)} epochs); only the longer one counts",
                stacklevel=2,
            )
            run = kept
        trials[trial] = run
    return sorted(trials.values(), key=lambda run: run.run_dir)


def grouped(runs: Sequence[RunCurve]) -> dict[str, dict[str, list[Curve]]]:
    """Curves by environment, then by label (both in sorted order)."""
    groups: dict[str, dict[str, list[Curve]]] = {}
    for run in sorted(runs, key=lambda run: (run.env, _label_order(run.label), str(run.run_dir))):
        groups.setdefault(run.env, {}).setdefault(run.label, []).append(run.curve)
    return groups


def summarise(env: str, label: str, curves: Sequence[Curve]) -> GroupSummary:
    """The :class:`GroupSummary` of one group's curves. Levels are met when eval success
    averaged over :data:`dtd.curves.SMOOTHING` epochs first reaches them."""
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


def summary_csv(rows: Sequence[GroupSummary]) -> str:
    """The summary as CSV text: one row per group; ``inf`` where the median run (or a
    quartile) never reached the level."""
    header = ["env", "algo", "runs", "epochs_min", "epochs_max"]
    header += ["final_success_median", "final_success_q25", "final_success_q75"]
    for level in LEVELS:
        header += [f"reached_{level}"]
        header += [f"env_steps_to_{level}_{stat}" for stat in ("median", "q25", "q75")]
        header += [f"wall_s_to_{level}_{stat}" for stat in ("median", "q25", "q75")]
    lines = [",".join(header)]
    for row in rows:
        cells: list[object] = [row.env, row.label, row.runs, row.epochs_min, row.epochs_max]
        cells += _spread_cells(row.final_success, "{:.3f}")
        for level in LEVELS:
            cells.append(row.reached[level])
            cells += _spread_cells(row.steps_to[level], "{:.0f}")
            cells += _spread_cells(row.wall_to[level], "{:.1f}")
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


def draw(env: str, labels: dict[str, list[Curve]], path_stem: Path) -> list[Path]:
    """Draw one environment's curves against epochs and against env steps; write PNG and SVG
    beside ``path_stem``; return the files written."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(1, 2, figsize=(12, 4.5), sharey=True, layout="constrained")
    faint = False
    for label, curves in labels.items():
        stats = band(curves)
        algo = label.split(" ")[0]
        style = {"color": _COLOURS.get(algo), "linestyle": "--" if "(" in label else "-"}
        for axis, x in zip(axes, (stats.epoch, stats.env_steps), strict=True):
            complete = stats.runs == len(curves)
            name = f"{label} ({len(curves)} seed{'s' if len(curves) != 1 else ''})"
            colour = axis.plot(x[complete], stats.mean[complete], label=name, **style)[0].get_color()
            if not complete.all():  # past the shortest run: fewer seeds, drawn faint
                faint = True
                tail = np.flatnonzero(~complete)
                start = max(tail[0] - 1, 0)
                axis.plot(x[start:], stats.mean[start:], color=colour, ls=style["linestyle"], alpha=0.35)
            axis.fill_between(x, stats.low, stats.high, color=colour, alpha=0.2, linewidth=0)
    axes[0].set_xlabel("epoch")
    axes[1].set_xlabel("env steps")
    axes[0].set_ylabel("eval success rate")
    for axis in axes:
        axis.set_ylim(-0.02, 1.02)
        axis.grid(alpha=0.3)
    axes[0].legend(loc="upper left")
    note = " (faint: past the shortest run, over fewer seeds)" if faint else ""
    figure.suptitle(f"{env}: mean over seeds, band = 25th-75th percentile{note}")
    path_stem.parent.mkdir(parents=True, exist_ok=True)
    written = []
    for suffix in (".png", ".svg"):
        path = path_stem.with_suffix(suffix)
        figure.savefig(path, dpi=120)
        written.append(path)
    plt.close(figure)
    return written


@dataclasses.dataclass(frozen=True)
class PlotResult:
    figures: list[Path]
    summary_csv: Path
    table: str


def cut_at(runs: Sequence[RunCurve], env_steps: float) -> list[RunCurve]:
    """``runs`` as they were at ``env_steps``, to compare them at one budget; a run with no
    epoch that early is left out."""
    if not env_steps > 0:
        raise ConfigError(f"--max-env-steps must be a positive number of env steps, got {env_steps}")
    cut = [dataclasses.replace(run, curve=run.curve.up_to(env_steps)) for run in runs]
    return [run for run in cut if len(run.curve) > 0]


def plot(directories: Sequence[Path], out: Path, max_env_steps: float | None = None) -> PlotResult:
    """Find the runs under ``directories``; write a figure per environment and summary.csv
    into ``out``. With ``max_env_steps``, every run is taken as it was at that budget
    (:func:`cut_at`), so that runs of different lengths are compared at one."""
    runs = find_runs(directories)
    if max_env_steps is not None:
        runs = cut_at(runs, max_env_steps)
    if not runs:
        budget = f" within {max_env_steps:,.0f} env steps" if max_env_steps is not None else ""
        raise RunDirError(
            f"no run with a finished epoch{budget} under "
            + ", ".join(str(directory) for directory in directories)
        )
    figures = []
    for env, labels in grouped(runs).items():
        figures += draw(env, labels, Path(out) / env.split(":")[-1])
    rows = summaries(runs)
    csv_path = Path(out) / "summary.csv"
    write_text_atomic(csv_path, summary_csv(rows))
    table = summary_table(rows)
    if max_env_steps is not None:
        table += f"\nevery run as it was at {max_env_steps:,.0f} env steps (--max-env-steps)"
    return PlotResult(figures, csv_path, table)


def _label_order(label: str) -> tuple[int, str]:
    order = {"ddpg": 0, "her": 1, "dtd": 2}
    return order.get(label.split(" ")[0], 3), label


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
