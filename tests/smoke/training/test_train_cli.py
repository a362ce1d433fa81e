"""The command line end to end: the run directory, evaluation, determinism, help."""

from __future__ import annotations

import json
import re

import pytest

from dtd.config import TrainConfig, flat_items
from tests.helpers import TINY, dtd, read_metrics, without_times

pytestmark = pytest.mark.smoke


def test_train_fills_the_run_directory(reach_run):
    config = json.loads((reach_run / "config.json").read_text())
    assert config["config"]["env"] == "FetchReach-v4" and config["config"]["seed"] == 7
    assert config["config"]["learner"]["hidden_sizes"] == [32, 32]
    assert {"dtd", "torch", "mujoco", "gymnasium-robotics"} <= set(config["versions"])
    assert config["derived"]["spec"]["horizon"] == 50

    rows = read_metrics(reach_run)
    assert [int(r["epoch"]) for r in rows] == [1, 2, 3]
    assert [int(r["env_steps"]) for r in rows] == [200, 400, 600]
    assert [int(r["updates"]) for r in rows] == [10, 20, 30]
    for column in ("wall_s", "eval_success", "train_success", "critic_loss", "actor_loss", "q_mean",
                   "eval_final_distance"):  # fmt: skip
        assert all(r[column] != "" for r in rows), column
    assert all(0.0 <= float(r["eval_success"]) <= 1.0 for r in rows)

    assert (reach_run / "checkpoints" / "latest.pt").is_file()
    assert (reach_run / "checkpoints" / "best.pt").is_file()
    assert list((reach_run / "tensorboard").glob("events.out.tfevents.*"))


def test_tensorboard_holds_the_same_figures(reach_run):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(reach_run / "tensorboard"))
    events.Reload()
    success = events.Scalars("eval/success")
    rows = read_metrics(reach_run)
    assert [e.step for e in success] == [int(r["env_steps"]) for r in rows]
    assert [e.value for e in success] == pytest.approx([float(r["eval_success"]) for r in rows])


def test_eval_prints_one_json_line(reach_run):
    result = dtd("eval", reach_run, "--episodes", "4")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.strip().splitlines()
    assert len(lines) == 1
    figures = json.loads(lines[0])
    assert figures["episodes"] == 4 and figures["epoch"] == 3 and figures["env"] == "FetchReach-v4"
    assert figures["success_rate"] in (0.0, 0.25, 0.5, 0.75, 1.0)
    assert figures["mean_final_distance"] >= 0.0
    best = json.loads(dtd("eval", reach_run, "--episodes", "2", "--checkpoint", "best").stdout)
    assert best["checkpoint"].endswith("best.pt")


def test_same_seed_gives_the_same_metrics(reach_run, tmp_path):
    again = tmp_path / "again"
    result = dtd("train", "--env", "FetchReach-v4", "--epochs", "3", "--seed", "7", *TINY, "--run-dir", again)
    assert result.returncode == 0, result.stderr
    assert without_times(read_metrics(again)) == without_times(read_metrics(reach_run))
    other_seed = tmp_path / "other"
    dtd("train", "--env", "FetchReach-v4", "--epochs", "1", "--seed", "8", *TINY, "--run-dir", other_seed)
    assert read_metrics(other_seed)[0]["critic_loss"] != read_metrics(reach_run)[0]["critic_loss"]


def test_resume_extends_a_finished_run_like_a_longer_one(reach_run, tmp_path):
    short = tmp_path / "short"
    assert (
        dtd(
            "train", "--env", "FetchReach-v4", "--epochs", "2", "--seed", "7", *TINY, "--run-dir", short
        ).returncode
        == 0
    )
    result = dtd("train", "--resume", short, "--epochs", "3", "--no-progress")
    assert result.returncode == 0, result.stderr
    assert without_times(read_metrics(short)) == without_times(read_metrics(reach_run))


def test_help_documents_every_setting_with_its_default():
    text = dtd("train", "--help").stdout
    flat = re.sub(r"[│\s]+", " ", text)
    for name in flat_items(TrainConfig()):
        assert f"--{name.replace('_', '-')}" in flat, name
    for option in ("--run-dir", "--resume", "--force", "--threads"):
        assert option in flat
    assert flat.count("(default:") >= len(flat_items(TrainConfig()))
    assert "train" in dtd("--help").stdout and "eval" in dtd("--help").stdout


@pytest.mark.parametrize(
    ("env_id", "obs_dim", "algo"),
    [
        ("FetchPush-v4", 25, "her"),
        ("FetchPickAndPlace-v4", 25, "her"),
        ("FetchSlide-v4", 25, "her"),
        ("HandManipulateBlock-v1", 61, "her"),
        ("gymnasium_robotics:FetchReach-v4", 10, "ddpg"),
        ("FetchReach-v4", 10, "dtd"),
        ("FetchPush-v4", 25, "dtd"),
        ("FetchPickAndPlace-v4", 25, "dtd"),
        ("HandManipulateBlock-v1", 61, "dtd"),
    ],
)
def test_every_task_of_the_paper_trains(tmp_path, env_id, obs_dim, algo):
    run_dir = tmp_path / "run"
    args = ["--n-cycles", "1", "--updates-per-cycle", "2", "--batch-size", "16", "--hidden-sizes", "16",
            "--test-episodes", "1", "--episodes-per-cycle", "1", "--buffer-size", "1000",
            "--collector", "inline", "--no-progress"]  # fmt: skip
    result = dtd("train", "--env", env_id, "--algo", algo, "--epochs", "1", *args, "--run-dir", run_dir)
    assert result.returncode == 0, result.stderr
    assert json.loads((run_dir / "config.json").read_text())["derived"]["spec"]["obs_dim"] == obs_dim
    assert len(read_metrics(run_dir)) == 1


def test_train_for_steps_resumes_up_to_a_larger_budget(tmp_path):
    from dtd.config import LearnerConfig
    from dtd.training.lifecycle import train_for_steps

    config = TrainConfig(
        env="FetchReach-v4", n_cycles=2, updates_per_cycle=2, test_episodes=1, buffer_size=5000,
        learner=LearnerConfig(hidden_sizes=(16,), batch_size=16),
    )  # fmt: skip
    assert train_for_steps(config, 200, tmp_path / "run").env_steps == 200
    state = train_for_steps(config, 450, tmp_path / "run")  # 2.25 epochs of 200 steps: 3 epochs
    assert state.env_steps == 600
    assert [int(r["epoch"]) for r in read_metrics(tmp_path / "run")] == [1, 2, 3]


def test_the_paper_preset_gives_the_defaults_and_options_beside_it_win(tmp_path):
    run_dir = tmp_path / "paper"
    result = dtd("train", "--env", "FetchReach-v4", "--algo", "dtd", "--preset", "paper", "--epochs", "1",
                 "--low-relabel-window", "episode", *TINY, "--run-dir", run_dir)  # fmt: skip
    assert result.returncode == 0, result.stderr
    config = json.loads((run_dir / "config.json").read_text())["config"]
    assert config["preset"] == "paper" and config["dtd"]["low_relabel_window"] == "episode"
    assert config["dtd"]["high_updates_per_cycle"] == 40 and config["updates_per_cycle"] == 5


def test_a_run_records_the_batch_its_algorithm_chose_beside_its_settings(tmp_path):
    at = TINY.index("--batch-size")
    small = [*TINY[:at], *TINY[at + 2 :], "--epochs", "1"]
    for algo, batch, n_step in (("dtd", 256, 3), ("her", 1024, 1)):
        run_dir = tmp_path / algo
        result = dtd("train", "--env", "FetchReach-v4", "--algo", algo, *small, "--run-dir", run_dir)
        assert result.returncode == 0, result.stderr
        written = json.loads((run_dir / "config.json").read_text())
        # The settings as given (left to the algorithm), what it chose among the derived facts.
        assert written["config"]["learner"]["batch_size"] is None and written["config"]["n_step"] is None
        assert (written["derived"]["batch_size"], written["derived"]["n_step"]) == (batch, n_step)
        # Resuming with the default, or with what the algorithm chose, keeps them.
        for given in ([], ["--batch-size", str(batch), "--n-step", str(n_step)]):
            result = dtd("train", "--resume", run_dir, "--epochs", "2", "--no-progress", *given)
            assert result.returncode == 0, result.stderr
            now = json.loads((run_dir / "config.json").read_text())
            assert now["derived"] == written["derived"]
            assert now["config"] == written["config"] | {"epochs": 2}
        result = dtd("train", "--resume", run_dir, "--epochs", "3", "--batch-size", "64")
        assert (
            result.returncode == 2
            and f"--batch-size cannot change when resuming (the run has {batch})" in (result.stderr)
        )


def test_collecting_after_the_updates_is_the_same_inline_or_in_a_process(reach_run, tmp_path):
    runs = {}
    for collector in ("inline", "process"):
        runs[collector] = tmp_path / collector
        options = ["--no-collect-ahead", "--collector", collector, "--run-dir", runs[collector]]
        result = dtd("train", "--env", "FetchReach-v4", "--epochs", "3", "--seed", "7", *TINY, *options)
        assert result.returncode == 0, result.stderr
    after = without_times(read_metrics(runs["inline"]))
    assert after == without_times(read_metrics(runs["process"]))
    # Collected with the policy after the cycle's updates: other episodes than collecting ahead.
    assert after != without_times(read_metrics(reach_run))
    config = json.loads((runs["inline"] / "config.json").read_text())["config"]
    assert config["collect_ahead"] is False
