"""Aggregate statistics of final success (rliable) from synthetic runs with known finals."""

import csv
import json

import numpy as np
import pytest

from dtd.config import Preset
from dtd.errors import DtdError
from dtd.experiments.plots import plot
from dtd.experiments.run_curves import find_runs
from dtd.experiments.statistics import group_statistics
from tests.unit.experiments.test_plots import write_run

pytest.importorskip("rliable", reason="dtd plot --stats needs the [stats] extra")

HER_FINALS = [0.2, 0.4, 0.5, 0.6, 0.9]
DTD_FINALS = [0.7, 0.8, 0.8, 0.9, 1.0]


@pytest.fixture(autouse=True)
def fewer_replications(monkeypatch):
    """Intervals of 1,000 replications: a few times faster, and as good a check."""
    monkeypatch.setattr("dtd.experiments.statistics.BOOTSTRAP_REPS", 1_000)
    monkeypatch.setattr("dtd.experiments.statistics.PROFILE_REPS", 200)


@pytest.fixture
def record(tmp_path):
    for seed, (her, dtd) in enumerate(zip(HER_FINALS, DTD_FINALS, strict=True), start=100):
        write_run(tmp_path, "her", seed, [0.0, her])
        write_run(tmp_path, "dtd", seed, [0.1, dtd])
    return tmp_path


def test_estimates_are_the_runs_median_iqm_and_mean_and_dtds_probability_of_improvement(record):
    her, dtd = group_statistics(find_runs([record]))
    assert (her.label, dtd.label) == ("her", "dtd")
    assert her.median.estimate == pytest.approx(0.5)
    assert her.iqm.estimate == pytest.approx(np.mean([0.4, 0.5, 0.6]))  # the middle half of 5
    assert her.mean.estimate == pytest.approx(np.mean(HER_FINALS))
    for interval in (her.median, her.iqm, her.mean, dtd.iqm):
        assert interval.low <= interval.estimate <= interval.high
        assert interval.high - interval.low > 0.05  # five seeds leave real uncertainty
    # P(dtd run > her run), ties counting half: 21.5 of 25 pairs.
    assert dtd.improvement["her"].estimate == pytest.approx(21.5 / 25)
    assert dtd.improvement["her"].high <= 1.0 and "her" not in her.improvement
    assert her.episodes == [10] * 5  # the last epoch's 10-episode evaluation


def test_each_preset_is_compared_with_her_of_the_same_preset(record):
    for seed, (her, dtd) in enumerate([(0.1, 0.2), (0.1, 0.3), (0.2, 0.1)], start=100):
        write_run(record / "paper", "her", seed, [0.0, her], preset=Preset.paper)
        write_run(record / "paper", "dtd", seed, [0.0, dtd], preset=Preset.paper)
    groups = {group.label: group for group in group_statistics(find_runs([record]))}
    assert groups["dtd"].improvement["her"].estimate == pytest.approx(21.5 / 25)
    # P(dtd (paper) run > her (paper) run), ties counting half: 6.5 of 9 pairs.
    assert groups["dtd (paper)"].improvement["her"].estimate == pytest.approx(6.5 / 9)
    assert "her" not in groups["her (paper)"].improvement


def test_a_saved_100_episode_evaluation_of_the_last_epoch_is_the_final(record):
    run = record / "FetchPush-v4-her-s100"
    (run / "eval-latest.json").write_text(json.dumps({"epoch": 2, "episodes": 100, "success_rate": 0.33}))
    (record / "FetchPush-v4-her-s101" / "eval-latest.json").write_text(
        json.dumps({"epoch": 1, "episodes": 100, "success_rate": 0.99})  # of an earlier epoch: not taken
    )
    her = group_statistics(find_runs([record]))[0]
    np.testing.assert_allclose(her.scores, [0.33, 0.4, 0.5, 0.6, 0.9])
    assert her.episodes == [100, 10, 10, 10, 10]


def test_plot_stats_writes_a_figure_columns_and_a_table(record, tmp_path):
    result = plot([record], tmp_path / "out", stats=True)
    assert (tmp_path / "out" / "FetchPush-v4-stats.png").is_file()
    rows = {row["algo"]: row for row in csv.DictReader(result.summary_csv.read_text().splitlines())}
    assert float(rows["her"]["final_median"]) == pytest.approx(0.5)
    assert float(rows["dtd"]["p_improvement_over_her"]) == pytest.approx(0.86)
    assert rows["her"]["p_improvement_over_her"] == ""
    assert "P(better than her)" in result.table and "0.86 [" in result.table
    assert "different env steps" not in result.table


def test_finals_at_different_budgets_are_said_to_be(record, tmp_path):
    write_run(record, "her", 105, [0.0, 0.5, 0.6, 0.7])
    result = plot([record], tmp_path / "out", stats=True)
    budgets = "FetchPush-v4's finals were reached at different env steps (her 2000-4000, dtd 2000)"
    assert budgets in result.table
    (her,) = [group for group in group_statistics(find_runs([record])) if group.label == "her"]
    assert her.env_steps == [2000.0] * 5 + [4000.0]


def test_a_group_of_one_run_has_its_value_and_no_interval(record, tmp_path):
    write_run(record / "paper", "dtd", 100, [0.0, 0.7], preset=Preset.paper)
    result = plot([record], tmp_path / "out", stats=True)
    (alone,) = [group for group in group_statistics(find_runs([record])) if group.label == "dtd (paper)"]
    assert alone.median.estimate == pytest.approx(0.7) and not alone.median.has_interval
    assert alone.improvement == {}
    assert "0.70 [one run: none]" in result.table and "0.70 [0.70, 0.70]" not in result.table
    rows = {row["algo"]: row for row in csv.DictReader(result.summary_csv.read_text().splitlines())}
    alone_row = rows["dtd (paper)"]
    assert alone_row["final_median"] == "0.7000" and alone_row["final_median_ci_low"] == ""


def test_stats_over_runs_of_one_seed_each_are_refused_before_anything_is_written(tmp_path):
    write_run(tmp_path / "runs", "her", 100, [0.0, 0.5])
    write_run(tmp_path / "runs", "dtd", 100, [0.0, 0.7])
    with pytest.raises(DtdError, match="one run"):
        plot([tmp_path / "runs"], tmp_path / "out", stats=True)
    assert not (tmp_path / "out").exists()
