"""Sweep figures and summary from synthetic metrics.csv files with known values."""

import csv
import json
import re
import warnings

import numpy as np
import pytest

from dtd.config import Algo, Preset, TrainConfig, with_algorithm_defaults, with_settings
from dtd.errors import ConfigError, RunDirError
from dtd.experiments.curves import Curve, band, quantile
from dtd.experiments.plots import plot
from dtd.experiments.run_curves import UnreadableRun, find_runs
from dtd.experiments.summary import summaries
from dtd.training.run_dir import RunDir, write_config

# eval success per epoch; epochs hold 1,000 env steps and 10 s each.
HER = {
    0: [0.2, 0.6, 1.0, 1.0],  # smoothed 0.2 0.4 0.6 0.87: 0.5 at epoch 3, never 0.9
    1: [0.6, 0.9, 0.9, 1.0],  # smoothed 0.6 0.75 0.8 0.93: 0.5 at epoch 1, 0.9 at epoch 4
    2: [0.0, 0.3],  # stopped after 2 epochs; never 0.5
}


def write_run(root, algo, seed, success, preset=Preset.tuned, env="FetchPush-v4"):
    run = RunDir(root / f"{env}-{algo}-s{seed}")
    run.root.mkdir(parents=True)
    write_config(run, TrainConfig(env=env, algo=Algo(algo), seed=seed, preset=preset), {})
    rows = ["epoch,env_steps,wall_s,eval_success,train_success"]
    rows += [f"{e},{e * 1000},{e * 10.0},{s},0.0" for e, s in enumerate(success, start=1)]
    run.metrics.write_text("\n".join(rows) + "\n")


@pytest.fixture
def sweep_dir(tmp_path):
    for seed, success in HER.items():
        write_run(tmp_path / "sweep", "her", seed, success)
    write_run(tmp_path / "sweep", "dtd", 0, [0.5, 1.0, 1.0])
    write_run(tmp_path / "paper", "dtd", 0, [0.0, 0.0, 0.1], preset=Preset.paper)
    (tmp_path / "sweep" / "FetchPush-v4-ddpg-s0").mkdir()  # a trial that never started
    return tmp_path


def test_quantile_treats_inf_as_never_reached():
    assert quantile(np.array([1.0, 2.0, 3.0]), 0.5) == 2.0
    assert quantile(np.array([1.0, 2.0, 3.0, 4.0]), 0.25) == pytest.approx(1.75)
    assert quantile(np.array([1000.0, 3000.0, np.inf]), 0.25) == 2000.0
    assert quantile(np.array([1000.0, 3000.0, np.inf]), 0.75) == np.inf
    assert quantile(np.array([np.inf, np.inf]), 0.5) == np.inf


def test_band_counts_each_run_only_at_the_epochs_it_has():
    epochs = [np.arange(1.0, len(s) + 1) for s in HER.values()]
    curves = [Curve(e, e * 1000, e * 10, np.array(s)) for e, s in zip(epochs, HER.values(), strict=True)]
    stats = band(curves)
    np.testing.assert_array_equal(stats.runs, [3, 3, 2, 2])
    np.testing.assert_allclose(stats.mean, [0.8 / 3, 1.8 / 3, 0.95, 1.0])  # no padding of the short run
    np.testing.assert_allclose(stats.env_steps, [1000, 2000, 3000, 4000])
    np.testing.assert_allclose(stats.low[:2], [0.1, 0.45])  # 25th percentile of (0, .2, .6), (.3, .6, .9)
    np.testing.assert_allclose(stats.high[2:], [0.975, 1.0])


def test_summary_numbers(sweep_dir):
    rows = {row.label: row for row in summaries(find_runs([sweep_dir / "sweep", sweep_dir / "paper"]))}
    assert set(rows) == {"her", "dtd", "dtd (paper)"}
    her = rows["her"]
    assert (her.runs, her.epochs_min, her.epochs_max) == (3, 2, 4)
    final = her.final_success
    assert (final.median, final.q25, final.q75) == pytest.approx((1.0, 0.65, 1.0))
    assert her.reached == {0.5: 2, 0.9: 1}
    assert (her.steps_to[0.5].median, her.steps_to[0.5].q25, her.steps_to[0.5].q75) == (3000, 2000, np.inf)
    assert her.wall_to[0.5].median == 30.0
    assert her.steps_to[0.9].median == np.inf
    dtd = rows["dtd"]
    assert dtd.steps_to[0.5].median == 1000  # smoothed 0.5 0.75 0.83
    assert dtd.reached[0.9] == 0


def test_plot_writes_figures_and_summary(sweep_dir):
    result = plot([sweep_dir / "sweep", sweep_dir / "paper"], sweep_dir / "out")
    png, svg = result.figures
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert png.stat().st_size > 10_000
    assert "<svg" in svg.read_text()[:1000]
    with open(result.summary_csv, newline="") as file:
        rows = {row["algo"]: row for row in csv.DictReader(file)}
    her = rows["her"]
    assert her["runs"] == "3"
    assert her["final_success_q25"] == "0.650"
    assert her["env_steps_to_0.5_median"] == "3000"
    assert her["env_steps_to_0.5_q75"] == "inf"
    assert her["reached_0.9"] == "1"
    assert her["wall_s_to_0.9_median"] == "inf"
    assert "3000 [2000-not reached] (2/3)" in result.table
    assert "not reached (1/3)" in result.table  # 0.9: one run in three, the quartiles say no more


def test_a_saved_evaluation_of_the_last_epoch_is_the_summarys_final(sweep_dir):
    her_s0 = sweep_dir / "sweep" / "FetchPush-v4-her-s0"
    (her_s0 / "eval-latest.json").write_text(json.dumps({"epoch": 4, "episodes": 100, "success_rate": 0.42}))
    her = {row.label: row for row in summaries(find_runs([sweep_dir / "sweep"]))}["her"]
    assert (her.final_success.median, her.final_success.q25) == pytest.approx((0.42, 0.36))  # 0.3, 0.42, 1.0
    assert (her.final_episodes, her.final_env_steps) == ((10, 100), (2000, 4000))
    result = plot([sweep_dir / "sweep"], sweep_dir / "out")
    assert "0.42 [0.36-0.71]  10-100 episodes  2000-4000" in result.table
    rows = {row["algo"]: row for row in csv.DictReader(result.summary_csv.read_text().splitlines())}
    assert (rows["her"]["final_episodes_max"], rows["her"]["final_env_steps_min"]) == ("100", "2000")


def panel_texts(svg):
    """The texts matplotlib wrote into an SVG figure (each drawn as paths after a comment)."""
    return re.findall(r"<!-- (.+?) -->", svg.read_text())


def test_runs_of_several_tasks_are_also_drawn_side_by_side(sweep_dir):
    write_run(sweep_dir / "pick", "her", 0, [0.0, 0.1], env="FetchPickAndPlace-v4")
    write_run(sweep_dir / "pick", "dtd", 0, [0.1, 0.2, 0.4], env="FetchPickAndPlace-v4")
    result = plot([sweep_dir / "sweep", sweep_dir / "pick"], sweep_dir / "out")
    names = sorted(path.name for path in result.figures)
    assert names == sorted(
        f"{stem}.{ext}"
        for stem in ("FetchPush-v4", "FetchPickAndPlace-v4", "tasks")
        for ext in ("png", "svg")
    )
    texts = panel_texts(sweep_dir / "out" / "tasks.svg")
    # One panel per task, in the paper's order (FetchPush first); each titled, then its legend.
    push_title, pick_title = texts.index("FetchPush-v4"), texts.index("FetchPickAndPlace-v4")
    push, pick = texts[push_title:pick_title], texts[pick_title:]
    assert {"her (1 seed)", "dtd (1 seed)"} <= set(pick)
    assert {"her (3 seeds)", "dtd (1 seed)"} <= set(push) and "her (1 seed)" not in push
    assert texts.count("env steps") == 2 and "epoch" not in texts
    assert "faint: past the shortest run" in " ".join(texts)  # her's seed 2 stops early on FetchPush


def test_runs_compared_at_one_budget(sweep_dir):
    result = plot([sweep_dir / "sweep"], sweep_dir / "out", max_env_steps=2500)
    with open(result.summary_csv, newline="") as file:
        rows = {row["algo"]: row for row in csv.DictReader(file)}
    her = rows["her"]  # each seed's first 2 epochs: finals 0.6, 0.9, 0.3
    assert (her["epochs_min"], her["epochs_max"]) == ("2", "2")
    assert her["final_success_median"] == "0.600"
    assert her["reached_0.5"] == "1"  # seed 1 only (smoothed 0.6); seed 0 reaches it later
    assert her["env_steps_to_0.5_median"] == "inf"
    assert rows["dtd"]["final_success_median"] == "1.000"
    assert "as it was at 2,500 env steps" in result.table
    with pytest.raises(RunDirError, match="within 999 env steps"):
        plot([sweep_dir / "sweep"], sweep_dir / "out", max_env_steps=999)
    with pytest.raises(ConfigError, match="--max-env-steps must be a positive"):
        plot([sweep_dir / "sweep"], sweep_dir / "out", max_env_steps=0)


def test_plot_of_nothing_says_so(tmp_path):
    with pytest.raises(RunDirError, match="no run"):
        plot([tmp_path], tmp_path / "out")
    with pytest.raises(RunDirError, match="not a directory"):
        plot([tmp_path / "missing"], tmp_path / "out")


def test_a_trial_found_twice_counts_once(sweep_dir):
    # A copy of her seed 0 stopped after 2 epochs (say, kept from an earlier session) and a
    # longer budget for the same trial: the same trial, counted once, the longer copy kept.
    write_run(sweep_dir / "copy", "her", 0, HER[0][:2])
    with pytest.warns(UserWarning, match=r"repeats the trial.*2 against 4 epochs"):
        runs = find_runs([sweep_dir / "sweep", sweep_dir / "copy"])
    her_seed_0 = [run for run in runs if run.label == "her" and run.run_dir.name.endswith("her-s0")]
    assert [run.run_dir.parent.name for run in her_seed_0] == ["sweep"]
    rows = {row.label: row for row in summaries(runs)}
    assert rows["her"].runs == 3
    # Another seed is another trial, not a repeat.
    write_run(sweep_dir / "more", "her", 3, [0.1])
    with pytest.warns(UserWarning):
        assert {row.label: row.runs for row in summaries(find_runs([sweep_dir]))}["her"] == 4


@pytest.mark.parametrize(
    ("damage", "reason"),
    [
        (lambda run: run.metrics.write_bytes(bytes(range(256)) * 8), "not a dtd metrics file"),
        (
            lambda run: run.metrics.write_text(run.metrics.read_text()[:-6]),
            "line 5 has 4 fields where the header has 5",
        ),
        (lambda run: run.metrics.write_text("epoch,wall_s\n1,2\n"), "no env_steps, eval_success column"),
        (lambda run: run.metrics.write_text(run.metrics.read_text().replace("0.6", "x")), "not a number"),
        (lambda run: run.config.write_text("{not json"), "config.json is unreadable"),
    ],
)
def test_an_unreadable_trial_is_left_out_with_a_warning_naming_it(sweep_dir, damage, reason):
    damaged = RunDir(sweep_dir / "sweep" / "FetchPush-v4-her-s0")
    damage(damaged)
    with pytest.warns(UnreadableRun, match=f"skipped {damaged.root}: .*{reason}"):
        result = plot([sweep_dir / "sweep"], sweep_dir / "out")
    with open(result.summary_csv, newline="") as file:
        rows = {row["algo"]: row for row in csv.DictReader(file)}
    assert rows["her"]["runs"] == "2" and rows["dtd"]["runs"] == "1"  # the others are all drawn


def test_a_grids_trials_are_grouped_and_labelled_by_the_settings_in_which_they_differ(tmp_path):
    for seed in (0, 1):
        for kind in ("ddpg", "tqc"):
            run = RunDir(tmp_path / f"FetchPush-v4-dtd-learner={kind}-s{seed}")
            run.root.mkdir(parents=True)
            config = with_settings(
                TrainConfig(env="FetchPush-v4", algo=Algo.dtd, seed=seed), [f"learner={kind}"]
            )
            write_config(run, config, {})
            run.metrics.write_text("epoch,env_steps,wall_s,eval_success,train_success\n1,1000,10.0,0.5,0.0\n")
    write_run(tmp_path, "her", 0, [0.1])
    rows = {row.label: row.runs for row in summaries(find_runs([tmp_path]))}
    # Settings that differ among the dtd runs name them; the seed never does; her stands alone.
    assert rows == {"dtd learner=ddpg": 2, "dtd learner=tqc": 2, "her": 1}
    plot([tmp_path], tmp_path / "figures")
    assert (tmp_path / "figures" / "FetchPush-v4.png").is_file()


def test_runs_that_recorded_their_algorithms_batch_and_runs_that_left_it_unset_are_one_group(tmp_path):
    for seed, recorded in ((0, True), (1, False)):
        run = RunDir(tmp_path / f"FetchPush-v4-her-s{seed}")
        run.root.mkdir(parents=True)
        config = TrainConfig(env="FetchPush-v4", algo=Algo.her, seed=seed)
        if recorded:  # as runs were written before the batch and n-step stayed unset
            config = with_algorithm_defaults(config)
        write_config(run, config, {})
        run.metrics.write_text("epoch,env_steps,wall_s,eval_success,train_success\n1,1000,10.0,0.5,0.0\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # neither is taken for a repeat of the other
        rows = {row.label: row.runs for row in summaries(find_runs([tmp_path]))}
    assert rows == {"her": 2}
