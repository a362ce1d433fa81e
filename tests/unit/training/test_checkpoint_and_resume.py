"""Checkpoint files that cannot be read; what a resumed run keeps and may change; the thread
count and collector chosen for the machine."""

import dataclasses
from pathlib import Path
from typing import Annotated

import pytest
import torch
import tyro

from dtd.cli.options import (
    REQUIRED_ENV_UNLESS_RESUMED,
    deferred,
    parse_command,
    settings_given,
    settings_registry,
)
from dtd.config import (
    Algo,
    Collection,
    Device,
    LearnerKind,
    Precision,
    Preset,
    TrainConfig,
    preset_config,
    read_settings,
    with_settings,
)
from dtd.envs.spec import EnvSpec
from dtd.errors import CheckpointError, ConfigError
from dtd.training import components
from dtd.training.checkpoint import FORMAT_VERSION, Checkpoint, TrainState, load_checkpoint, save_atomic
from dtd.training.lifecycle import plan_start, resumed_config

VALID = TrainConfig(env="FetchReach-v4")
VALID_PATH = Path("run/checkpoints/latest.pt")


def test_checkpoint_round_trip_and_errors(tmp_path):
    path = tmp_path / "c.pt"
    save_atomic(path, {"x": torch.arange(3), "n": 5})
    state = load_checkpoint(path)
    assert state["n"] == 5 and state["format_version"] == FORMAT_VERSION
    assert [p.name for p in tmp_path.iterdir()] == ["c.pt"]  # no temporary file left

    with pytest.raises(CheckpointError, match="no checkpoint"):
        load_checkpoint(tmp_path / "missing.pt")
    path.write_bytes(path.read_bytes()[:50])
    with pytest.raises(CheckpointError, match="corrupt"):
        load_checkpoint(path)
    torch.save({"format_version": 99}, path)
    with pytest.raises(CheckpointError, match="format version 99"):
        load_checkpoint(path)


def whole_checkpoint(**changes) -> Checkpoint:
    fields = dict(
        env_id="FetchReach-v4",
        algo="her",
        spec={"obs_dim": 10, "goal_dim": 3, "action_dim": 4, "horizon": 50},
        counters=dataclasses.asdict(TrainState(epoch=2, env_steps=200, history=[{"eval_success": 0.5}])),
        agent={"learner": {"actor": torch.ones(2)}, "buffer": {"size": 3}},
        config=VALID.to_dict(),
        rng={"numpy": {}, "torch": torch.zeros(1), "collector": {}, "eval_envs": []},
        worker=1,
    )
    return Checkpoint(**{**fields, **changes})


def test_a_checkpoint_record_is_written_and_read_back_as_it_was(tmp_path):
    written = whole_checkpoint()
    written.save(tmp_path / "c.pt")
    read = Checkpoint.read(tmp_path / "c.pt")
    assert read.whole and read.epoch == 2 and read.env_steps == 200 and read.eval_success == 0.5
    assert read.worker == 1 and read.format_version == FORMAT_VERSION and read.config == VALID.to_dict()
    assert read.train_state() == TrainState(epoch=2, env_steps=200, history=[{"eval_success": 0.5}])
    assert torch.equal(read.agent["learner"]["actor"], torch.ones(2))
    assert read.acting_agent_state().keys() == {"learner"}  # the replay left out
    # The file's keys are those every earlier version wrote.
    assert set(load_checkpoint(tmp_path / "c.pt")) == {
        "format_version", "env_id", "algo", "spec", "state", "agent", "config", "worker", "rng",
    }  # fmt: skip


def test_an_agent_only_snapshot_is_no_whole_checkpoint_and_cannot_be_resumed(tmp_path):
    snapshot = whole_checkpoint(
        counters={"epoch": 3, "env_steps": 300, "eval_success": 0.25}, config=None, rng=None
    )
    snapshot.save(tmp_path / "s.pt")
    read = Checkpoint.read(tmp_path / "s.pt")
    assert not read.whole and read.epoch == 3 and read.eval_success == 0.25
    assert set(load_checkpoint(tmp_path / "s.pt")) == {
        "format_version",
        "env_id",
        "algo",
        "spec",
        "state",
        "agent",
    }
    with pytest.raises(CheckpointError, match="agent-only snapshot"):
        read.check_resumable(tmp_path / "s.pt")
    with pytest.raises(CheckpointError, match="older dtd"):
        whole_checkpoint(format_version=2).check_resumable(tmp_path / "c.pt")
    whole_checkpoint().check_resumable(tmp_path / "c.pt")


def test_a_file_lacking_a_part_of_a_checkpoint_is_refused_naming_it(tmp_path):
    save_atomic(tmp_path / "c.pt", {"env_id": "FetchReach-v4", "algo": "her", "agent": {}})
    with pytest.raises(CheckpointError, match=r"c\.pt lacks a part of a dtd checkpoint"):
        Checkpoint.read(tmp_path / "c.pt")


def test_a_checkpoint_of_another_task_or_algorithm_is_refused():
    spec = EnvSpec("FetchReach-v4", 10, 3, 4, 1.0, 50, (0.0,) * 3, (1.0,) * 3)
    config = dataclasses.replace(VALID, algo=Algo.her)
    whole_checkpoint().check_fits(config, spec, VALID_PATH)
    with pytest.raises(CheckpointError, match="belongs to a her run on FetchReach-v4, not to this dtd"):
        whole_checkpoint().check_fits(dataclasses.replace(config, algo=Algo.dtd), spec, VALID_PATH)
    with pytest.raises(CheckpointError, match="other dimensions"):
        whole_checkpoint(spec={**whole_checkpoint().spec, "goal_dim": 2}).check_fits(config, spec, VALID_PATH)


def test_resume_takes_the_stored_settings_and_allows_more_epochs():
    stored = dataclasses.replace(VALID, seed=3, n_cycles=7)
    given = TrainConfig(epochs=80)
    assert resumed_config(stored, given) == dataclasses.replace(stored, epochs=80)
    assert resumed_config(stored, TrainConfig(env="FetchReach-v4", seed=3)) == stored
    with pytest.raises(ConfigError, match="--seed cannot change"):
        resumed_config(stored, TrainConfig(seed=4))


def test_resuming_keeps_the_runs_preset():
    paper = preset_config(Preset.paper, env="FetchReach-v4")
    # `dtd train --resume RUN --epochs 80`: given = the tuned defaults with more epochs
    resumed = resumed_config(paper, dataclasses.replace(TrainConfig(), epochs=80))
    assert resumed == dataclasses.replace(paper, epochs=80)
    # `--resume RUN --preset paper --epochs 80` says the same
    assert resumed_config(paper, preset_config(Preset.paper, epochs=80)) == resumed
    with pytest.raises(ConfigError, match="--preset"):
        resumed_config(TrainConfig(env="FetchReach-v4"), preset_config(Preset.paper))


@pytest.mark.parametrize(
    ("cores", "threads", "collector", "expected"),
    [(1, 1, "auto", "inline"), (2, 1, "auto", "process"), (2, 2, "auto", "inline"),
     (16, 4, "auto", "process"), (8, 1, "inline", "inline"), (1, 1, "process", "process")],
)  # fmt: skip
def test_episodes_are_collected_beside_the_learner_where_a_core_is_free(
    monkeypatch, cores, threads, collector, expected
):
    monkeypatch.setattr(components, "usable_cores", lambda: cores)
    assert components.resolved_collection(Collection(collector), threads).value == expected


def test_one_torch_thread_unless_asked_for_more(monkeypatch):
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    # However many cores the process may use (as usable_cores asks the system).
    monkeypatch.setattr(components.os, "sched_getaffinity", lambda _: set(range(16)), raising=False)
    monkeypatch.setattr(components.os, "cpu_count", lambda: 16)
    assert components.usable_cores() == 16
    assert components.resolved_threads(0) == 1
    assert components.resolved_threads(3) == 3  # given threads are kept
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    assert components.resolved_threads(0) == 2  # the user's OpenMP setting is kept
    assert components.resolved_threads(3) == 3
    monkeypatch.setenv("OMP_NUM_THREADS", "many")
    assert components.resolved_threads(0) == 1


def test_resume_takes_what_the_command_line_gave_whatever_its_value():
    learner = dataclasses.replace(VALID.learner, learner=LearnerKind.tqc, hidden_sizes=(64, 64))
    stored = dataclasses.replace(VALID, algo=Algo.dtd, learner=learner, n_cycles=7, time_feature=True)
    # The options typed, read from the command line: the default value is given all the same.
    for args, option in [
        (["--learner", "ddpg"], "--learner"),
        (["--n-cycles", "50"], "--n-cycles"),
        (["--hidden-sizes", "256", "256", "256"], "--hidden-sizes"),
        (["--no-time-feature"], "--time-feature"),
        (["--algo", "her"], "--algo"),
        (["--preset", "paper"], "--preset"),
    ]:
        given = parsed_settings(args)
        with pytest.raises(ConfigError, match=f"{option} cannot change when resuming"):
            resumed_config(stored, given, settings_given(args))
    # The run's own values again, and what may change.
    own = ["--learner", "tqc", "--n-cycles", "7", "--time-feature", "--algo", "dtd", "--epochs", "80"]
    assert resumed_config(stored, parsed_settings(own), settings_given(own)) == dataclasses.replace(
        stored, epochs=80
    )


def test_resume_reads_the_environments_arguments_as_their_values():
    stored = dataclasses.replace(VALID, env_kwargs=("continuing_task=false", "reward_type=sparse"))
    again = ["--env-kwargs", "reward_type=sparse", "continuing_task=False"]
    assert resumed_config(stored, parsed_settings(again), settings_given(again)) == stored
    other = ["--env-kwargs", "reward_type=dense", "continuing_task=False"]
    with pytest.raises(ConfigError, match="--env-kwargs cannot change"):
        resumed_config(stored, parsed_settings(other), settings_given(other))


def test_the_settings_given_are_read_from_the_options_typed():
    args = [
        "--n-cycles=50",
        "--no-time-feature",
        "--high.no-layer-norm",
        "--learner",
        "ddpg",
        "--resume",
        "r",
    ]
    assert settings_given([*args, "--no-progress", "--force"]) == {
        "n_cycles", "time_feature", "high.layer_norm", "learner"
    }  # fmt: skip


def parsed_settings(args: list[str]) -> TrainConfig:
    """The settings ``dtd train`` parses from ``args`` (without its own options)."""
    settings = [arg for arg in args if arg not in ("--resume", "r")]
    commands = {"train": deferred(_settings_of, TrainConfig()), "plot": deferred(_settings_of)}
    registry = {"train": settings_registry(hints=REQUIRED_ENV_UNLESS_RESUMED)}
    return parse_command(commands, "", ["train", "--env", "FetchReach-v4", *settings], registry)()


def _settings_of(config: Annotated[TrainConfig, tyro.conf.arg(name="")]) -> TrainConfig:
    """The settings parsed."""
    return config


def test_auto_precision_is_bfloat16_only_where_native_and_shown_equal(monkeypatch):
    cpu = torch.device("cpu")
    dtd = dataclasses.replace(VALID, algo=Algo.dtd)
    for precision in (Precision.float32, Precision.bfloat16):
        assert components.resolved_precision(dataclasses.replace(dtd, precision=precision), cpu) is precision
    monkeypatch.setattr(components, "cpu_features", lambda: frozenset({"avx512f", "avx512_bf16"}))
    assert components.resolved_precision(dtd, cpu) is Precision.bfloat16
    monkeypatch.setattr(components, "cpu_features", lambda: frozenset({"avx512f", "amx_bf16"}))
    assert components.resolved_precision(dtd, cpu) is Precision.bfloat16
    # Learning not shown equal: HER, another learner at either level.
    for other in (
        dataclasses.replace(dtd, algo=Algo.her),
        with_settings(dtd, ["learner=tqc"]),
        with_settings(dtd, ["high.learner=td3"]),
    ):
        assert components.resolved_precision(other, cpu) is Precision.float32
    monkeypatch.setattr(components, "cpu_features", lambda: frozenset({"avx2"}))
    assert components.resolved_precision(dtd, cpu) is Precision.float32


def test_a_run_records_the_precision_chosen_and_keeps_it_on_resume(monkeypatch, tmp_path):
    monkeypatch.setattr(components, "cpu_features", lambda: frozenset({"avx512_bf16"}))
    plan = plan_start(dataclasses.replace(VALID, algo=Algo.dtd, device=Device.cpu), tmp_path / "run")
    assert plan.config.precision is Precision.bfloat16
    assert preset_config(Preset.paper).precision is Precision.float32
    # A config.json written before the setting existed was float32's.
    data = VALID.to_dict()
    del data["precision"]
    assert read_settings(data, 1).precision is Precision.float32
    # On resume the run's own is kept, and may be changed.
    stored = dataclasses.replace(VALID, precision=Precision.bfloat16)
    assert resumed_config(stored, TrainConfig(epochs=80)).precision is Precision.bfloat16
    args = ["--precision", "float32"]
    changed = resumed_config(stored, parsed_settings(args), settings_given(args))
    assert changed == dataclasses.replace(stored, precision=Precision.float32)
