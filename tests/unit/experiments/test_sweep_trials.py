"""Sweep trials: names, order, validation; how trials share the cores."""

import io
import sys

import pytest
from rich.console import Console

from dtd.config import Algo, Collection, LearnerKind, TrainConfig
from dtd.errors import ConfigError, DtdError
from dtd.experiments.sweep import SweepProgress, sweep_trials, trials_at_once
from dtd.experiments.trials import Trial, import_ray, sharing_cores


def test_trials_are_ordered_seed_by_seed_from_the_first_seed(tmp_path):
    trials = sweep_trials(TrainConfig(env="FetchPush-v4", seed=3), [Algo.her, Algo.dtd], 2, tmp_path / "out")
    assert [t.name for t in trials] == [
        "FetchPush-v4-her-s3", "FetchPush-v4-dtd-s3", "FetchPush-v4-her-s4", "FetchPush-v4-dtd-s4",
    ]  # fmt: skip
    assert [(t.config.algo, t.config.seed) for t in trials][1] == (Algo.dtd, 3)
    assert all(t.run_dir.is_absolute() and t.run_dir.parent == (tmp_path / "out").resolve() for t in trials)


@pytest.mark.parametrize(
    ("algos", "seeds", "message"),
    [([], 1, "no algorithm"), ([Algo.her, Algo.her], 1, "twice"), ([Algo.her], 0, "--seeds")],
)
def test_bad_sweeps_are_refused(tmp_path, algos, seeds, message):
    with pytest.raises(ConfigError, match=message):
        sweep_trials(TrainConfig(env="FetchPush-v4"), algos, seeds, tmp_path)
    with pytest.raises(ConfigError, match="--env"):
        sweep_trials(TrainConfig(), [Algo.her], 1, tmp_path)


def test_a_grid_trains_every_combination_of_its_settings_each_in_a_directory_named_by_them(tmp_path):
    grid = ["learner=ddpg,tqc", "hidden_sizes=[64, 64],[32]", "high.learner=sac"]
    trials = sweep_trials(TrainConfig(env="FetchPush-v4"), [Algo.dtd], 2, tmp_path, grid=grid)
    assert len(trials) == 2 * 2 * 2
    assert trials[0].name == "FetchPush-v4-dtd-learner=ddpg-hidden_sizes=64_64-high.learner=sac-s0"
    assert trials[3].name == "FetchPush-v4-dtd-learner=tqc-hidden_sizes=32-high.learner=sac-s0"
    settings = {(t.config.learner.learner, t.config.learner.hidden_sizes, t.config.seed) for t in trials}
    assert len(settings) == 8 and (LearnerKind.tqc, (64, 64), 1) in settings
    assert all(t.config.dtd.high.learner is LearnerKind.sac for t in trials)
    assert len({t.run_dir for t in trials}) == 8


@pytest.mark.parametrize(
    ("grid", "message"),
    [
        (["learner"], "NAME=VALUE"),
        (["learner=ddpg,,tqc"], "empty value"),
        (["learner=ddpg", "learner=tqc"], "twice"),
        (["learner=tqc,tqc"], "repeats"),
        (["seed=1,2"], "--seeds"),
        (["no_such=1,2"], "unknown setting"),
        (["learner=ddpg,qlearning"], "learner"),
    ],
)
def test_bad_grids_are_refused_in_one_line(tmp_path, grid, message):
    with pytest.raises(ConfigError, match=message):
        sweep_trials(TrainConfig(env="FetchPush-v4"), [Algo.her], 1, tmp_path, grid=grid)


def test_trials_running_together_share_the_cores():
    config = TrainConfig(env="FetchPush-v4")
    shared = sharing_cores(config, workers=2, cores=8)
    assert (shared.threads, shared.collector) == (4, Collection.inline)
    assert sharing_cores(config, workers=3, cores=2).threads == 1
    assert sharing_cores(config, workers=1, cores=8) == config  # one trial: chosen as for dtd train
    given = TrainConfig(env="FetchPush-v4", threads=3, collector=Collection.process)
    assert sharing_cores(given, workers=2, cores=8) == given  # what the user set is kept


def test_a_trial_resumed_takes_the_settings_typed_those_of_its_grid_point_and_its_share_of_cores(tmp_path):
    base = TrainConfig(env="FetchPush-v4", n_cycles=50)
    typed = frozenset({"env", "n_cycles"})  # --n-cycles 50 typed at its default
    trials = sweep_trials(base, [Algo.her, Algo.dtd], 1, tmp_path, grid=["learner=ddpg,tqc"], given=typed)
    assert trials[0].given == typed  # ddpg: the grid's value is the default, nothing changes
    assert trials[2].given == typed | {"learner"}
    shared = trials[2].with_config(sharing_cores(trials[2].config, workers=2, cores=8))
    assert shared.given == typed | {"learner", "threads", "collector"}
    # Built in Python, a trial's settings given are guessed when it resumes (resumed_config).
    assert all(t.given is None for t in sweep_trials(base, [Algo.her], 1, tmp_path))


def test_workers_default_to_one_per_core_but_no_more_than_trials(tmp_path, monkeypatch):
    monkeypatch.setattr("dtd.experiments.sweep.usable_cores", lambda: 4)
    trials = [Trial(TrainConfig(env="FetchReach-v4"), tmp_path / str(n)) for n in range(3)]
    assert trials_at_once(trials, 0) == 3
    assert trials_at_once(trials * 2, 0) == 4
    assert trials_at_once(trials, 2) == 2
    with pytest.raises(ConfigError):
        trials_at_once(trials, -1)


def test_without_ray_the_error_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)
    with pytest.raises(DtdError, match=r"pip install 'dtd\[ray\]'"):
        import_ray()


def test_without_a_terminal_a_status_line_replaces_the_bar(tmp_path, monkeypatch):
    recorded = {}
    monkeypatch.setattr("dtd.experiments.sweep.epochs_recorded", lambda run_dir: recorded.get(run_dir, 0))
    trials = [Trial(TrainConfig(env="FetchReach-v4", epochs=4), tmp_path / str(n)) for n in range(2)]
    log = io.StringIO()
    progress = SweepProgress(
        trials, enabled=True, console=Console(file=log, force_terminal=False), log_every_s=0
    )
    with progress:
        recorded[trials[0].run_dir] = 3
        progress.refresh()
        progress.refresh()  # nothing new: no second line
        recorded[trials[1].run_dir] = 9  # more than the trial asks for counts as its 4
        progress.refresh()
    lines = log.getvalue().splitlines()
    assert lines == [
        "sweep: 3/8 epochs, 0 of 2 trials ended, 0 min",
        "sweep: 7/8 epochs, 0 of 2 trials ended, 0 min",
    ]

    terminal = io.StringIO()
    with SweepProgress(trials, enabled=True, console=Console(file=terminal, force_terminal=True)) as bar:
        bar.refresh()
    assert "sweep:" not in terminal.getvalue()


@pytest.mark.parametrize(
    ("grid", "message"),
    [
        ("batch_size=0,32", "--grid batch_size=0: --batch-size must be at least 1"),
        ("high.batch_size=0,32", "--high.batch-size must be at least 1"),
        ("n_step=0", "--n-step must be at least 1"),
        ("epochs=-1", "--epochs must be at least 1"),
        ("batch_size=abc", "batch_size must be an integer"),
    ],
)
def test_every_grid_value_is_checked_as_its_option_before_any_trial(tmp_path, grid, message):
    with pytest.raises(ConfigError, match=message):
        sweep_trials(TrainConfig(env="FetchPush-v4"), [Algo.her, Algo.dtd], 1, tmp_path, grid=[grid])
    assert not (tmp_path / "FetchPush-v4-her-batch_size=0-s0").exists()
