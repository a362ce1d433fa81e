import os
import subprocess
import sys

from dtd.training.atomic import remove_stale_temporaries, write_text_atomic


def test_write_text_atomic_leaves_only_the_file(tmp_path):
    path = tmp_path / "sub" / "config.json"
    write_text_atomic(path, "{}")
    write_text_atomic(path, '{"a": 1}')
    assert path.read_text() == '{"a": 1}'
    assert [p.name for p in path.parent.iterdir()] == ["config.json"]


def test_stale_temporaries_of_dead_processes_are_removed(tmp_path):
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True
    )
    dead_pid = int(dead.stdout)  # that process has exited
    stale = tmp_path / "checkpoints" / f".latest.pt.{dead_pid}.tmp"
    live = tmp_path / "checkpoints" / f".best.pt.{os.getpid()}.tmp"  # a writer still at work
    stale.parent.mkdir()
    stale.write_bytes(b"half")
    live.write_bytes(b"half")
    (tmp_path / "notes.tmp").write_text("not ours")
    assert remove_stale_temporaries(tmp_path) == [stale]
    assert not stale.exists() and live.exists() and (tmp_path / "notes.tmp").exists()
