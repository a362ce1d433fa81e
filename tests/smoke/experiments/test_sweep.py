"""dtd sweep: trials side by side, interrupted and run again (skip the finished, resume the
rest), failures that do not stop the others, the same trials on a local Ray."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dtd.config import Algo, LearnerConfig, TrainConfig
from dtd.experiments.sweep import run_sweep, sweep_trials
from dtd.experiments.trials import Trial, run_local
from dtd.training.lifecycle import epochs_recorded
from tests.helpers import TINY, dtd, read_metrics

pytestmark = pytest.mark.smoke

EPOCHS = 8
"""Enough that a trial killed after its first epoch cannot finish in the moment (up to a
quarter second) its worker takes to notice."""
SWEEP = ["sweep", "--env", "FetchReach-v4", "--algos", "her,dtd", "--seeds", "2", "--epochs", str(EPOCHS)]
SWEEP += TINY
NAMES = ["FetchReach-v4-her-s0", "FetchReach-v4-dtd-s0", "FetchReach-v4-her-s1", "FetchReach-v4-dtd-s1"]
"""The order a one-worker sweep runs its trials in."""
HER_SWEEP = [
    "sweep",
    "--env",
    "FetchReach-v4",
    "--algos",
    "her",
    "--seeds",
    "3",
    "--epochs",
    str(EPOCHS),
    *TINY,
]


def tiny_config(**settings) -> TrainConfig:
    """The TINY budget as a configuration: one epoch of FetchReach."""
    tiny = dict(env="FetchReach-v4", epochs=1, n_cycles=2, updates_per_cycle=5, test_episodes=2)
    tiny.update(buffer_size=20_000, threads=1, learner=LearnerConfig(hidden_sizes=(32, 32), batch_size=32))
    return TrainConfig(**{**tiny, **settings})


def children(pid: int) -> list[int]:
    """Processes whose parent is ``pid`` (Linux)."""
    found = []
    for entry in Path("/proc").iterdir():
        try:
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, ValueError, IndexError):
            continue
        if ppid == pid:
            found.append(int(entry.name))
    return found


def test_an_interrupted_sweep_run_again_skips_finished_trials_and_resumes_the_others(tmp_path):
    out = tmp_path / "sweep"
    process = subprocess.Popen(
        [sys.executable, "-m", "dtd", *SWEEP, "--parallel", "1", "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    first, second = (out / name for name in NAMES[:2])
    deadline = time.monotonic() + 240
    while not (epochs_recorded(first) == EPOCHS and epochs_recorded(second) >= 1):
        assert process.poll() is None, "the sweep ended before it could be interrupted"
        assert time.monotonic() < deadline
        time.sleep(0.01)
    workers = children(process.pid)
    assert workers, "the sweep runs its trial in a process of its own"
    os.kill(process.pid, signal.SIGKILL)  # the sweep alone: its worker must end with it
    process.wait()
    deadline = time.monotonic() + 15
    while any(Path(f"/proc/{pid}").exists() for pid in workers):
        assert time.monotonic() < deadline, "a trial went on training after its sweep was killed"
        time.sleep(0.1)
    interrupted_at = epochs_recorded(second)
    assert 1 <= interrupted_at < EPOCHS
    assert epochs_recorded(out / NAMES[2]) == 0
    finished = (first / "metrics.csv", first / "checkpoints" / "latest.pt")
    finished_files = {path: path.stat().st_mtime_ns for path in finished}
    rows_before = read_metrics(second)

    result = dtd(*SWEEP, "--parallel", "2", "--out", out)
    assert result.returncode == 0, result.stderr
    assert "4 of 4 trials finished" in result.stdout
    assert all(epochs_recorded(out / name) == EPOCHS for name in NAMES)
    # Nothing finished is redone, nothing done is lost.
    assert {path: path.stat().st_mtime_ns for path in finished_files} == finished_files
    assert read_metrics(second)[:interrupted_at] == rows_before
    # The summary table covers both algorithms, over both seeds.
    lines = [line.split() for line in result.stdout.splitlines()]
    assert ["FetchReach-v4", "her", "2", str(EPOCHS)] in [line[:4] for line in lines]
    assert ["FetchReach-v4", "dtd", "2", str(EPOCHS)] in [line[:4] for line in lines]

    again = dtd(*SWEEP, "--parallel", "2", "--out", out)
    assert again.returncode == 0, again.stderr
    assert [read_metrics(out / name)[-1]["epoch"] for name in NAMES] == [str(EPOCHS)] * 4


def start_sweep(out: Path, *extra: str) -> subprocess.Popen[str]:
    """A sweep of her on three seeds in a session of its own (its own process group, as a
    terminal's foreground job), caught once its first trial has finished an epoch."""
    process = subprocess.Popen(
        [sys.executable, "-m", "dtd", *HER_SWEEP, *extra, "--out", str(out)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        # A shell that started these tests in the background may have left SIGINT ignored.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 240  # a guard against a hang, not a measure of speed
    while epochs_recorded(out / "FetchReach-v4-her-s0") < 1:
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.05)
    return process


def stopped(process: subprocess.Popen[str], workers: list[int]) -> str:
    """``process``'s stderr once it and its ``workers`` have ended (guarded against a hang)."""
    _, stderr = process.communicate(timeout=60)
    deadline = time.monotonic() + 30
    while any(Path(f"/proc/{pid}").exists() for pid in workers):
        assert time.monotonic() < deadline, "a trial went on after its sweep ended"
        time.sleep(0.1)
    return stderr


def test_ctrl_c_stops_the_running_trial_and_starts_no_queued_one(tmp_path):
    out = tmp_path / "sweep"
    process = start_sweep(out, "--parallel", "1")
    workers = children(process.pid)
    os.killpg(process.pid, signal.SIGINT)  # Ctrl-C as a terminal sends it: to the whole group
    stderr = stopped(process, workers)
    assert process.returncode == 130, stderr
    assert stderr.strip() == "dtd: interrupted; run the same dtd sweep again to continue"
    interrupted_at = epochs_recorded(out / "FetchReach-v4-her-s0")
    assert 1 <= interrupted_at < EPOCHS
    assert [epochs_recorded(out / f"FetchReach-v4-her-s{seed}") for seed in (1, 2)] == [0, 0]
    rows_before = read_metrics(out / "FetchReach-v4-her-s0")

    result = dtd(*HER_SWEEP, "--parallel", "2", "--out", out)
    assert result.returncode == 0, result.stderr
    assert [epochs_recorded(out / f"FetchReach-v4-her-s{seed}") for seed in range(3)] == [EPOCHS] * 3
    assert read_metrics(out / "FetchReach-v4-her-s0")[:interrupted_at] == rows_before


@pytest.mark.parametrize("runner", [["--parallel", "2"], ["--ray", "local"]], ids=["processes", "ray"])
def test_sigterm_to_the_sweep_alone_stops_its_trials_too(tmp_path, runner):
    if "--ray" in runner:
        pytest.importorskip("ray")
    out = tmp_path / "sweep"
    process = start_sweep(out, *runner)
    workers = children(process.pid)
    process.send_signal(signal.SIGTERM)
    stderr = stopped(process, workers)
    assert process.returncode == 130, stderr
    assert "run the same dtd sweep again to continue" in stderr
    assert epochs_recorded(out / "FetchReach-v4-her-s0") < EPOCHS
    assert epochs_recorded(out / "FetchReach-v4-her-s2") == 0


def test_a_sweep_run_again_refuses_a_setting_typed_at_its_default_that_its_trial_began_without(tmp_path):
    out = tmp_path / "sweep"
    sweep = ["sweep", "--env", "FetchReach-v4", "--algos", "her", "--seeds", "1", "--parallel", "1"]
    assert dtd(*sweep, "--epochs", "1", *TINY, "--out", out).returncode == 0
    assert TINY[:2] == ["--n-cycles", "2"]
    run = out / "FetchReach-v4-her-s0"
    before = {path: path.read_bytes() for path in run.rglob("*") if path.is_file()}
    changed = dtd(*sweep, "--epochs", "2", "--n-cycles", "50", *TINY[2:], "--out", out)  # 50: the default
    assert changed.returncode == 1, changed.stderr
    assert "--n-cycles cannot change when resuming (the run has 2)" in changed.stderr
    assert {path: path.read_bytes() for path in run.rglob("*") if path.is_file()} == before  # left as it was
    # The same command as the trial began with trains it on.
    assert dtd(*sweep, "--epochs", "2", *TINY, "--out", out).returncode == 0
    assert epochs_recorded(out / "FetchReach-v4-her-s0") == 2


def test_a_failing_trial_is_reported_and_the_others_finish(tmp_path):
    good = Trial(tiny_config(algo=Algo.her), tmp_path / "good")
    bad = Trial(tiny_config(algo=Algo.her, env="NoSuchTask-v0"), tmp_path / "bad")
    seen = []
    outcomes = run_local([bad, good], workers=2, on_done=lambda outcome: seen.append(outcome.trial.name))
    assert sorted(seen) == ["bad", "good"]
    assert not outcomes[0].ok and "NoSuchTask-v0" in outcomes[0].error
    assert outcomes[1].ok and epochs_recorded(good.run_dir) == 1


def test_sweep_refuses_algo_and_unknown_algos(tmp_path):
    result = dtd(*SWEEP, "--algo", "her", "--out", tmp_path)
    assert result.returncode == 2 and "--algos" in result.stderr
    result = dtd(*SWEEP, "--workers", "2", "--out", tmp_path / "never")
    assert result.returncode == 2 and "--workers" in result.stderr and not (tmp_path / "never").exists()
    result = dtd(*SWEEP[:4], "her,sac", "--out", tmp_path)
    assert result.returncode == 2 and "sac" in result.stderr


def test_the_same_trials_run_as_ray_tasks(tmp_path):
    ray = pytest.importorskip("ray")
    trials = sweep_trials(tiny_config(), [Algo.her, Algo.dtd], 1, tmp_path / "ray-sweep")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        outcomes = run_sweep(trials, ray_address="auto", show_progress=False)
    finally:
        ray.shutdown()
    assert [outcome.error for outcome in outcomes] == [None, None]
    assert all(epochs_recorded(trial.run_dir) == 1 for trial in trials)
    assert Path(trials[0].run_dir, "train.log").read_text().count("epoch 1/1") == 1


def test_trials_are_evaluated_once_trained_and_not_again(tmp_path):
    trial = Trial(tiny_config(algo=Algo.her), tmp_path / "evaluated", final_episodes=3)
    (outcome,) = run_local([trial], workers=1)
    assert outcome.ok, outcome.error
    saved = trial.run_dir / "eval-latest.json"
    evaluation = json.loads(saved.read_text())
    assert evaluation["episodes"] == 3 and evaluation["epoch"] == 1 and 0 <= evaluation["success_rate"] <= 1
    written = saved.stat().st_mtime_ns
    (outcome,) = run_local([trial], workers=1)
    assert outcome.ok and saved.stat().st_mtime_ns == written
    result = dtd(*SWEEP, "--final-episodes", "-1", "--out", tmp_path / "refused")
    assert result.returncode == 2 and "--final-episodes" in result.stderr
