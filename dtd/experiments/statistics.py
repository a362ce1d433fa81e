"""Aggregate statistics of final success over seeds, with confidence intervals, computed by
``rliable`` (Agarwal et al., 2021): per environment and algorithm the median of the runs, the
interquartile mean (IQM) and the mean with 95% stratified-bootstrap confidence intervals; the
probability that one algorithm's run beats another's; and performance profiles (the share of
runs whose final success exceeds each threshold).

A run's final success is :func:`dtd.experiments.run_curves.final_success`: its 100-episode
evaluation when one was saved for its last epoch (``dtd eval RUN --episodes 100 --save`` writes
``RUN/eval-latest.json``), else the last epoch's evaluation in metrics.csv (over
``--test-episodes`` episodes, noisier); each group says which it used, and at how many env
steps its runs' finals were reached, since groups trained to different budgets do not compare
like for like.
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from dtd.errors import DtdError
from dtd.experiments.run_curves import (
    FinalSuccess,
    RunCurve,
    env_order,
    final_success,
    label_colours,
    label_order,
)
from dtd.experiments.summary import span_text, steps_text
from dtd.figures import pyplot, save_figure

BOOTSTRAP_REPS = 10_000
"""Bootstrap replications of each confidence interval."""
CONFIDENCE = 0.95
SEED = 0
"""Seed of the bootstrap, so that the same runs give the same intervals."""
PROFILE_REPS = 2_000
"""Bootstrap replications of the performance profiles' bands."""
THRESHOLDS = np.linspace(0.0, 1.0, 51)
"""Success thresholds of the performance profiles."""
BASELINE = "her"
"""The algorithm others are compared with (probability of improvement), at the same preset."""


@dataclasses.dataclass(frozen=True)
class Interval:
    """A point estimate and its confidence interval."""

    estimate: float
    low: float
    high: float

    @property
    def has_interval(self) -> bool:
        """False for one run's value: one run has no spread to bootstrap."""
        return not (np.isnan(self.low) or np.isnan(self.high))

    def text(self) -> str:
        if not self.has_interval:
            return f"{self.estimate:.2f} [one run: none]"
        return f"{self.estimate:.2f} [{self.low:.2f}, {self.high:.2f}]"

    def cells(self) -> list[str]:
        """Estimate, low, high for a CSV (the bounds empty where there is no interval)."""
        bounds = [f"{self.low:.4f}", f"{self.high:.4f}"] if self.has_interval else ["", ""]
        return [f"{self.estimate:.4f}", *bounds]


@dataclasses.dataclass(frozen=True)
class GroupStatistics:
    """The statistics of one (environment, algorithm) group's final successes."""

    env: str
    label: str
    scores: np.ndarray
    """Each run's final success."""
    episodes: list[int]
    """How many evaluation episodes each run's final success counts."""
    env_steps: list[float]
    """The env steps of each run's last epoch."""
    median: Interval
    iqm: Interval
    mean: Interval
    improvement: dict[str, Interval]
    """P(a run of this group beats a run of the named group), for the baseline."""


def require_rliable() -> None:
    try:
        import rliable  # noqa: F401
    except ImportError as exc:
        raise DtdError("--stats needs rliable, which is not installed: pip install 'dtd[stats]'") from exc


def runs_per_group(runs: Sequence[RunCurve]) -> dict[tuple[str, str], list[RunCurve]]:
    """The runs of each (environment, label)."""
    groups: dict[tuple[str, str], list[RunCurve]] = {}
    for run in runs:
        groups.setdefault((run.env, run.label), []).append(run)
    return groups


def check_intervals_possible(runs: Sequence[RunCurve]) -> None:
    """A :class:`DtdError` where no (environment, algorithm) has two runs: no interval to give."""
    groups = runs_per_group(runs)
    if all(len(members) < 2 for members in groups.values()):
        raise DtdError(
            "--stats gives intervals over seeds, and each task and algorithm here has one run: "
            "train more seeds (dtd sweep --seeds N) or leave out --stats"
        )


def group_statistics(runs: Sequence[RunCurve]) -> list[GroupStatistics]:
    """Statistics per (environment, algorithm) of the runs' final successes; a group of one run
    has its value without an interval, and no probability of improvement."""
    require_rliable()
    groups = runs_per_group(runs)
    finals = {key: [final_success(run) for run in members] for key, members in groups.items()}
    with warnings.catch_warnings():
        # arch (rliable's bootstrap) announces a change of its own default generator.
        warnings.simplefilter("ignore", FutureWarning)
        result = [
            GroupStatistics(
                env,
                label,
                _scores(values),
                [final.episodes for final in values],
                [final.env_steps for final in values],
                *_aggregates(label, _scores(values)),
                _improvement(label, _scores(values), finals.get((env, baseline_of(label)))),
            )
            for (env, label), values in finals.items()
        ]
    return sorted(result, key=lambda group: (env_order(group.env), label_order(group.label)))


def baseline_of(label: str) -> str:
    """The label ``label`` is compared with: :data:`BASELINE` of the same preset (``dtd`` with
    ``her``, ``dtd (paper)`` with ``her (paper)``)."""
    _, _, preset = label.partition(" ")
    return f"{BASELINE} {preset}" if preset else BASELINE


def _scores(finals: Sequence[FinalSuccess]) -> np.ndarray:
    return np.array([final.value for final in finals])


def _aggregates(label: str, scores: np.ndarray) -> list[Interval]:
    """Median, IQM and mean of ``scores`` with their intervals (NaN bounds for one run)."""
    from rliable import library, metrics

    if len(scores) < 2:
        return [Interval(float(scores[0]), np.nan, np.nan)] * 3

    def estimates(matrix: np.ndarray) -> np.ndarray:
        # The median of the runs' finals: rliable's aggregate median is one over tasks of the
        # tasks' means, which for one task per environment is the mean.
        return np.array([np.median(matrix), metrics.aggregate_iqm(matrix), metrics.aggregate_mean(matrix)])

    points, intervals = library.get_interval_estimates(
        {label: scores[:, None]}, estimates, reps=BOOTSTRAP_REPS, random_state=np.random.RandomState(SEED)
    )
    return [
        Interval(float(points[label][i]), float(intervals[label][0, i]), float(intervals[label][1, i]))
        for i in range(3)
    ]


def _improvement(
    label: str, scores: np.ndarray, baseline: Sequence[FinalSuccess] | None
) -> dict[str, Interval]:
    """P(a run of ``label`` beats one of its baseline, :func:`baseline_of`), where there is one
    to beat; keyed by :data:`BASELINE`."""
    from rliable import library, metrics

    if baseline is None or baseline_of(label) == label or min(len(scores), len(baseline)) < 2:
        return {}
    pair = f"{label},{BASELINE}"
    points, intervals = library.get_interval_estimates(
        {pair: (scores[:, None], _scores(baseline)[:, None])},
        metrics.probability_of_improvement,
        reps=BOOTSTRAP_REPS,
        random_state=np.random.RandomState(SEED),
    )
    estimate = float(np.ravel(points[pair])[0])
    return {BASELINE: Interval(estimate, float(intervals[pair][0, 0]), float(intervals[pair][1, 0]))}


def performance_profiles(groups: Sequence[GroupStatistics]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per label, the share of runs whose final success exceeds each of :data:`THRESHOLDS`
    and its confidence band (2 x thresholds); for one environment's groups."""
    from rliable import library

    scores = {group.label: group.scores[:, None] for group in groups}
    saved = np.random.get_state()
    np.random.seed(SEED)  # create_performance_profile bootstraps with numpy's global generator
    try:
        profiles, bands = library.create_performance_profile(scores, THRESHOLDS, reps=PROFILE_REPS)
    finally:
        np.random.set_state(saved)
    return {label: (profiles[label], bands[label]) for label in profiles}


def statistics_columns(
    groups: Sequence[GroupStatistics],
) -> tuple[list[str], dict[tuple[str, str], list[str]]]:
    """Columns for summary.csv: their names, and per (environment, label) their cells."""
    header = ["final_success_per_run"]
    for name in ("median", "iqm", "mean"):
        header += [f"final_{name}", f"final_{name}_ci_low", f"final_{name}_ci_high"]
    header += [f"p_improvement_over_{BASELINE}", "p_improvement_ci_low", "p_improvement_ci_high"]
    cells = {}
    for group in groups:
        row = [" ".join(f"{score:.3f}" for score in group.scores)]
        for interval in (group.median, group.iqm, group.mean):
            row += interval.cells()
        poi = group.improvement.get(BASELINE)
        row += poi.cells() if poi else ["", "", ""]
        cells[(group.env, group.label)] = row
    return header, cells


def statistics_table(groups: Sequence[GroupStatistics]) -> str:
    """The statistics as aligned text."""
    heads = ["env", "algo", "runs", "final from", "final at", "median", "IQM", "mean"]
    heads.append(f"P(better than {BASELINE})")
    table = [heads]
    for group in groups:
        source = span_text((min(group.episodes), max(group.episodes)), str) + " episodes"
        poi = group.improvement.get(BASELINE)
        table.append(
            [group.env, group.label, str(len(group.scores)), source, _budget(group)]
            + [interval.text() for interval in (group.median, group.iqm, group.mean)]
            + [poi.text() if poi else "-"]
        )
    widths = [max(len(line[column]) for line in table) for column in range(len(heads))]
    text = ["  ".join(cell.ljust(width) for cell, width in zip(line, widths, strict=True)) for line in table]
    text.append(
        f"final success over seeds: estimate [{CONFIDENCE:.0%} stratified-bootstrap CI, {BOOTSTRAP_REPS:,} "
        "replications] (rliable); final from: the episodes of the evaluation each run's final comes "
        "from; final at: the env steps of the runs' last epochs"
    )
    text += unequal_budgets(groups)
    return "\n".join(text)


def unequal_budgets(groups: Sequence[GroupStatistics]) -> list[str]:
    """A warning per environment whose runs' finals were reached at different env steps: their
    finals, and the probability of improvement, do not compare like for like."""
    warnings_ = []
    for env in sorted({group.env for group in groups}, key=env_order):
        in_env = [group for group in groups if group.env == env]
        if len({steps for group in in_env for steps in group.env_steps}) > 1:
            budgets = ", ".join(f"{group.label} {_budget(group)}" for group in in_env)
            warnings_.append(
                f"note: {env}'s finals were reached at different env steps ({budgets}); "
                "dtd plot --max-env-steps compares every run at one budget"
            )
    return warnings_


def _budget(group: GroupStatistics) -> str:
    """The env steps of the group's runs' last epochs, short."""
    return span_text((min(group.env_steps), max(group.env_steps)), steps_text)


def draw_statistics(env: str, groups: Sequence[GroupStatistics], path_stem: Path) -> list[Path]:
    """One environment's aggregates with their intervals and its performance profiles, as PNG
    and SVG beside ``path_stem``."""
    plt = pyplot()

    figure, axes = plt.subplots(1, 4, figsize=(16, 3.8), layout="constrained")
    colours = label_colours([group.label for group in groups])
    for axis, name in zip(axes[:3], ("median", "iqm", "mean"), strict=True):
        for row, group in enumerate(groups):
            interval = getattr(group, name)
            colour = colours[group.label]
            if interval.has_interval:
                axis.barh(
                    row, interval.high - interval.low, left=interval.low, height=0.6, color=colour, alpha=0.5
                )
            axis.plot([interval.estimate] * 2, [row - 0.3, row + 0.3], color=colour, linewidth=2)
        axis.set_yticks(range(len(groups)), [f"{g.label} ({len(g.scores)})" for g in groups])
        axis.set_xlim(-0.02, 1.02)
        axis.set_title({"iqm": "IQM"}.get(name, name))
        axis.set_xlabel("final success")
        axis.grid(axis="x", alpha=0.3)
    profiles = performance_profiles(groups)
    for group in groups:
        profile, band = profiles[group.label]
        colour = colours[group.label]
        axes[3].plot(THRESHOLDS, profile, color=colour, label=group.label)
        axes[3].fill_between(THRESHOLDS, band[0], band[1], color=colour, alpha=0.2, linewidth=0)
    axes[3].set_xlabel("final success threshold")
    axes[3].set_ylabel("share of runs above it")
    axes[3].set_title("performance profile")
    # Below the panel: a grid's labels are longer than the panel is wide.
    axes[3].legend(loc="upper center", bbox_to_anchor=(0.5, -0.22), fontsize="small")
    axes[3].grid(alpha=0.3)
    figure.suptitle(f"{env}: final success over seeds, {CONFIDENCE:.0%} stratified-bootstrap CIs (rliable)")
    return save_figure(figure, path_stem)
