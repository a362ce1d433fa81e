"""Data-parallel workers on torch.distributed: the same parameters on every worker, one worker
as a run of its own, a killed worker, resume, leaving the group, and bad input (2 workers of 1
thread each)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
import torch.distributed as dist

from tests.helpers import TINY, assert_same_figures, dtd, read_metrics

pytestmark = pytest.mark.smoke

DATA = Path(__file__).parents[2] / "data" / "before-workers"


def children(pid: int) -> list[int]:
    """The processes whose parent is ``pid``, oldest first."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (FileNotFoundError, ProcessLookupError):
            continue
        if int(fields[1]) == pid:
            found.append((int(fields[19]), int(stat.parent.name)))  # start time, pid
    return [child for _, child in sorted(found)]


def tensors_differing(first: object, second: object, path: str = "") -> list[str]:
    """Paths of the tensors that differ between two nested dicts of the same keys."""
    if isinstance(first, dict):
        assert isinstance(second, dict) and first.keys() == second.keys(), path
        return [name for key in first for name in tensors_differing(first[key], second[key], f"{path}/{key}")]
    if torch.is_tensor(first):
        return [] if torch.equal(first, second) else [path]
    return []


def test_two_workers_hold_the_same_parameters_and_statistics(tmp_path):
    # dtd: both of its learners (the one DDPG learner every algorithm uses) and its replay.
    run_dir = tmp_path / "run"
    result = dtd("train", "--env", "FetchPush-v4", "--algo", "dtd", "--seed", "2", "--epochs", "2", *TINY,
                 "--workers", "2", "--run-dir", run_dir)  # fmt: skip
    assert result.returncode == 0, result.stderr
    rows = read_metrics(run_dir)
    # An epoch is n_cycles cycles on every worker: 2 x 2 episodes x 2 workers.
    assert [int(row["env_steps"]) for row in rows] == [8 * 50, 16 * 50]
    assert [int(row["episodes"]) for row in rows] == [8, 16]
    first = torch.load(run_dir / "checkpoints" / "latest.pt", weights_only=True)
    shard = torch.load(run_dir / "checkpoints" / "workers" / "worker-1-epoch-2.pt", weights_only=True)
    assert (first["worker"], shard["worker"]) == (0, 1)
    for level in ("low", "high"):
        # Networks, targets, optimisers and normalisers: the same on both, bit for bit ...
        assert tensors_differing(first["agent"][level], shard["agent"][level]) == [], level
        # ... and the normalisers counted both workers' inputs.
        assert first["agent"][level]["obs_norm"]["count"] > 0
    # Each worker collected its own episodes.
    assert tensors_differing(first["agent"]["buffer"]["data"], shard["agent"]["buffer"]["data"])
    assert '"workers": 2' in (run_dir / "config.json").read_text()
    # A run of several workers is looked at like any other.
    result = dtd("eval", run_dir, "--episodes", "2")
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize("algo", ["her", "dtd"])
def test_one_worker_is_a_run_of_its_own(tmp_path, algo):
    # The reference was written by a run of its own before workers existed, with these settings,
    # on another machine, in float32: the same counts, and figures the same to float32 rounding.
    run_dir = tmp_path / "run"
    result = dtd("train", "--env", "FetchReach-v4", "--algo", algo, "--seed", "7", "--epochs", "2", *TINY,
                 "--workers", "1", "--precision", "float32", "--run-dir", run_dir)  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert_same_figures(read_metrics(run_dir), read_metrics(DATA / algo))


def job_after_its_first_epoch(run_dir: Path, epochs: int) -> subprocess.Popen[str]:
    """``dtd train --workers 2`` of a tiny FetchReach her run, in a session of its own (a
    terminal's Ctrl-C reaches its whole process group), once its first epoch has finished."""
    args = ["--env", "FetchReach-v4", "--algo", "her", "--seed", "4", "--epochs", str(epochs), *TINY]
    launcher = subprocess.Popen(
        [sys.executable, "-m", "dtd", "train", *args, "--workers", "2", "--run-dir", str(run_dir)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        # A test runner in the background may have left SIGINT ignored for its children.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 240
    while not (run_dir / "metrics.csv").exists():
        assert launcher.poll() is None, launcher.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.05)
    return launcher


def test_a_killed_worker_stops_the_job_in_one_line_and_resume_finishes(tmp_path):
    run_dir = tmp_path / "run"
    launcher = job_after_its_first_epoch(run_dir, epochs=4)  # kill within the next epoch
    workers = children(launcher.pid)
    assert len(workers) == 2
    killed = workers[1]
    os.kill(killed, signal.SIGKILL)
    started = time.monotonic()
    _, stderr = launcher.communicate(timeout=60)
    assert time.monotonic() - started < 60
    assert launcher.returncode == 1
    lines = [line for line in stderr.splitlines() if line.startswith("dtd:")]
    assert len(lines) == 1, stderr
    assert f"(pid {killed}) was killed by SIGKILL" in lines[0] and f"--resume {run_dir}" in lines[0]
    assert "Traceback" not in stderr
    result = dtd("train", "--resume", run_dir)
    assert result.returncode == 0, result.stderr
    assert [int(row["epoch"]) for row in read_metrics(run_dir)] == [1, 2, 3, 4]
    assert sorted(path.name for path in (run_dir / "checkpoints" / "workers").iterdir()) == [
        "worker-1-epoch-4.pt"
    ]


@pytest.mark.parametrize("stop", ["ctrl-c", "sigterm"])
def test_an_interrupted_job_stops_every_worker_in_one_line_and_resumes(tmp_path, stop):
    run_dir = tmp_path / "run"
    launcher = job_after_its_first_epoch(run_dir, epochs=3)
    workers = children(launcher.pid)
    assert len(workers) == 2
    if stop == "ctrl-c":
        os.killpg(launcher.pid, signal.SIGINT)
    else:
        launcher.terminate()  # the launcher alone, as a scheduler stops a job
    _, stderr = launcher.communicate(timeout=60)
    assert launcher.returncode == 130, stderr
    lines = [line for line in stderr.splitlines() if not line.startswith("epoch ")]  # progress
    assert lines == [f"dtd: interrupted; continue with dtd train --resume {run_dir}"], stderr
    for worker in workers:  # none left behind
        assert (
            not Path(f"/proc/{worker}").exists() or "Z" in Path(f"/proc/{worker}/stat").read_text().split()[2]
        )
    result = dtd("train", "--resume", run_dir)
    assert result.returncode == 0, result.stderr
    assert [int(row["epoch"]) for row in read_metrics(run_dir)] == [1, 2, 3]


def test_workers_whose_launcher_is_killed_stop_in_one_line_and_resume_finishes(tmp_path):
    run_dir = tmp_path / "run"
    launcher = job_after_its_first_epoch(run_dir, epochs=10_000)  # would train for a long time
    workers = children(launcher.pid)
    assert len(workers) == 2
    os.kill(launcher.pid, signal.SIGKILL)
    # The workers still hold the launcher's stderr: it ends when both have ended.
    _, stderr = launcher.communicate(timeout=120)
    deadline = time.monotonic() + 120  # a guard against a hang, not a measure of speed
    while any(Path(f"/proc/{worker}").exists() for worker in workers):
        assert time.monotonic() < deadline, f"workers {workers} outlived their launcher"
        time.sleep(0.1)
    lines = [line for line in stderr.splitlines() if not line.startswith("epoch ")]  # progress
    assert lines == [
        f"dtd: the launcher of this run's workers (pid {launcher.pid}) ended, so its workers stopped; "
        f"continue with dtd train --resume {run_dir}"
    ], stderr
    trained = len(read_metrics(run_dir))
    result = dtd("train", "--resume", run_dir, "--epochs", str(trained + 1))
    assert result.returncode == 0, result.stderr
    assert [int(row["epoch"]) for row in read_metrics(run_dir)] == list(range(1, trained + 2))


LEAVING_WORKER = """
import os
import torch
from dtd.training.launch import JobPlace
from dtd.training.workers import join_group, leave_group

def gloo_threads():
    names = (open(f"/proc/self/task/{task}/comm").read().strip() for task in os.listdir("/proc/self/task"))
    return [name for name in names if "gloo" in name]

group = join_group(2, JobPlace.from_environment())
joined = len(gloo_threads())
# A learner's optimiser, made once the group exists, imports torch._dynamo on first use.
torch.optim.Adam([torch.nn.Parameter(torch.zeros(1))])
group.barrier()
leave_group()
print(joined, len(gloo_threads()))
"""


def test_a_worker_that_leaves_the_group_has_no_gloo_threads_left():
    # gloo threads still running when the interpreter exits can abort it (SIGABRT) after the
    # run has finished: leaving the group must end them.
    store = dist.TCPStore("127.0.0.1", 0, is_master=True, wait_for_workers=False)
    # What torchrun's agent sets for each worker of a one-machine job, less the rank, with the
    # store held here, as the agent holds it.
    job = {
        "WORLD_SIZE": "2",
        "LOCAL_WORLD_SIZE": "2",
        "MASTER_ADDR": "127.0.0.1",
        "MASTER_PORT": str(store.port),
        "TORCHELASTIC_USE_AGENT_STORE": "True",
        "OMP_NUM_THREADS": "1",
    }
    workers = [
        subprocess.Popen(
            [sys.executable, "-c", LEAVING_WORKER],
            env={**os.environ, **job, "RANK": str(rank)},
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        for rank in range(2)
    ]
    for worker in workers:
        stdout, stderr = worker.communicate(timeout=180)
        assert worker.returncode == 0, stderr
        joined, left = map(int, stdout.split())
        assert joined > 0  # the group's threads are seen while it is joined
        assert left == 0


def test_bad_worker_input_is_one_line(tmp_path):
    base = ["train", "--env", "FetchReach-v4", *TINY]
    for args, message in [
        (["--workers", "0"], "--workers must be at least 1, got 0"),
        (["--workers", str((os.cpu_count() or 2) + 1)], "--oversubscribe starts them anyway"),
    ]:
        result = dtd(*base, *args, "--run-dir", tmp_path / "never")
        assert result.returncode == 2 and message in result.stderr, result.stderr
        assert len(result.stderr.strip().splitlines()) == 1
        assert not (tmp_path / "never").exists()
    run_dir = tmp_path / "two"
    result = dtd(*base, "--epochs", "1", "--workers", "2", "--run-dir", run_dir)
    assert result.returncode == 0, result.stderr
    for other in ("3", "1"):  # 1 too, though it is a new run's default
        result = dtd("train", "--resume", run_dir, "--epochs", "2", "--workers", other)
        assert result.returncode == 2
        assert "--workers cannot change when resuming (the run has 2)" in result.stderr
        assert len(result.stderr.strip().splitlines()) == 1
    assert len(read_metrics(run_dir)) == 1
