"""The commands that read a run and write files, under faults: a full disk (a real small
filesystem), SIGTERM (a scheduler's stop), input a heatmap cannot draw, a run whose files are
damaged. Each is one line (exit 1 for the machine, 2 for the input, 130 for a stop) and leaves
no partial output: nothing of what the command was writing, no temporary file."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.helpers import dtd, small_disk
from tests.smoke.training.test_faults import one_error_line

pytestmark = pytest.mark.smoke


def everything_under(folder: Path) -> list[str]:
    """Every file and folder under ``folder``, hidden ones too."""
    return sorted(path.relative_to(folder).as_posix() for path in folder.rglob("*"))


def copied_run(run: Path, into: Path) -> Path:
    """The files of ``run`` a reader needs, copied into ``into``/run."""
    copy = into / "run"
    (copy / "checkpoints").mkdir(parents=True)
    for name in ("config.json", "metrics.csv", "checkpoints/latest.pt", "checkpoints/first.pt"):
        shutil.copy(run / name, copy / name)
    return copy


@pytest.mark.parametrize(
    ("command", "disk_bytes"),
    [("render", 64 << 10), ("plot", 64 << 10), ("export", 8 << 10)],
)
def test_a_full_disk_is_one_line_and_leaves_no_partial_output(reach_run, tmp_path, command, disk_bytes):
    with small_disk(tmp_path / "disk", disk_bytes) as disk:
        extra = ["--episodes", "1"] if command == "render" else []
        result = dtd(command, reach_run, *extra, "--out", disk / "out")
        one_error_line(result, 1, "no space left on device writing")
        assert everything_under(disk) == []
        if command == "export":  # and so the next try is not refused as having been made
            shutil.rmtree(disk / "out", ignore_errors=True)


def test_a_report_on_a_full_disk_is_one_line_and_leaves_the_run_as_it_was(reach_run, tmp_path):
    needed = sum(path.stat().st_size for path in reach_run.rglob("*") if path.is_file())
    with small_disk(tmp_path / "disk", needed + (48 << 10)) as disk:
        run = copied_run(reach_run, disk)
        before = everything_under(run)
        one_error_line(dtd("report", run, "--episodes", "1"), 1, "no space left on device writing")
        assert everything_under(run) == before


@pytest.mark.parametrize("damage", ["a truncated latest.pt", "metrics.csv cut mid-line"])
def test_a_refused_report_writes_nothing(reach_run, tmp_path, damage):
    run = copied_run(reach_run, tmp_path)
    if damage == "a truncated latest.pt":
        latest = run / "checkpoints" / "latest.pt"
        latest.write_bytes(latest.read_bytes()[: latest.stat().st_size // 2])
    else:
        metrics = run / "metrics.csv"
        metrics.write_text(metrics.read_text()[:-25])
    before = everything_under(run)
    one_error_line(dtd("report", run, "--episodes", "1"), 2, "corrupt" if "latest" in damage else "truncated")
    assert everything_under(run) == before


@pytest.mark.parametrize(
    ("damage", "reason"),
    [("config.json", "config.json is unreadable"), ("metrics.csv", "a truncated or malformed row")],
)
def test_plot_of_a_run_it_cannot_read_says_why(reach_run, tmp_path, damage, reason):
    run = copied_run(reach_run, tmp_path)
    path = run / damage
    path.write_text("{not json" if damage == "config.json" else path.read_text()[:-25])
    one_error_line(dtd("plot", run, "--out", tmp_path / "figures"), 2, "no run with a finished epoch", reason)
    assert not (tmp_path / "figures").exists()


def test_a_corrupt_saved_evaluation_is_said_once_and_the_last_epoch_counts(reach_run, tmp_path):
    run = copied_run(reach_run, tmp_path)
    (run / "eval-latest.json").write_text("{broken")
    result = dtd("plot", run, "--out", tmp_path / "figures")
    assert result.returncode == 0, result.stderr
    warnings = [line for line in result.stderr.splitlines() if "eval-latest.json is unreadable" in line]
    assert len(warnings) == 1, result.stderr


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--start", "1.2"], "--start takes the block's x,y (2 numbers), got 1"),
        (["--start", "1.1,0.6,0.4,0.5"], "--start takes the block's x,y (2 numbers), got 4"),
        (["--goal", "1.3"], "--goal takes x,y or x,y,z"),
        (["--resolution", "100000"], "--resolution must lie in 2..200"),
        (["--heights", "-5"], "--heights -5.000 lies outside"),
        (["--goal", "1.3,0.7,3"], "--goal's z 3.000 lies outside"),
    ],
)
def test_heatmap_input_it_cannot_draw_is_one_line(push_dtd_run, tmp_path, args, needle):
    out = tmp_path / "heat.png"
    coarse = [] if "--resolution" in args else ["--resolution", "4"]
    one_error_line(dtd("heatmap", push_dtd_run, *args, *coarse, "--out", out), 2, needle)
    assert everything_under(tmp_path) == []


def started(args: list[str], environment: dict[str, str] | None = None) -> subprocess.Popen[str]:
    """``dtd ARGS`` in a fresh interpreter, once it has loaded torch: inside its command."""
    process = subprocess.Popen(
        [sys.executable, "-m", "dtd", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, **(environment or {})},
    )
    deadline = time.monotonic() + 120  # a guard against a hang, not a measure of speed
    while "libtorch" not in Path(f"/proc/{process.pid}/maps").read_text():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline, "the command did not load torch in time"
        time.sleep(0.05)
    return process


@pytest.mark.parametrize("command", ["eval", "render", "export"])
def test_sigterm_stops_a_command_as_ctrl_c_does_and_leaves_nothing(reach_run, tmp_path, command):
    args = {
        "eval": ["eval", str(reach_run), "--episodes", "100000"],
        "render": ["render", str(reach_run), "--episodes", "200", "--out", str(tmp_path / "out")],
        "export": ["export", str(reach_run), "--out", str(tmp_path / "out")],
    }[command]
    process = started(args)
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr
    assert stderr.strip().splitlines() == ["dtd: interrupted"], stderr
    assert everything_under(tmp_path) == []


def test_sigterm_stops_the_explorer_as_ctrl_c_does(push_dtd_run, tmp_path):
    temporary = tmp_path / "tmp"
    temporary.mkdir()
    process = started(["explore", str(push_dtd_run), "--port", "0"], {"TMPDIR": str(temporary)})
    assert process.stdout is not None
    deadline = time.monotonic() + 120
    line = ""
    while " at http://" not in line:
        line = process.stdout.readline()
        assert line or process.poll() is None, process.communicate()
        assert time.monotonic() < deadline
    process.send_signal(signal.SIGTERM)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == 0, stderr
    assert stdout.strip().splitlines() == ["dtd explore: stopped"] and "Traceback" not in stderr
    assert list(temporary.glob("dtd-explore-*")) == []  # its videos' folder is gone
