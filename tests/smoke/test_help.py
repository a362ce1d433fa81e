"""The command line's help and its parse errors, as a user reads them."""

from __future__ import annotations

import itertools
import os
import re
import subprocess
import sys

import pytest

pytestmark = pytest.mark.smoke

COMMANDS = ("train", "sweep", "plot", "eval", "render", "heatmap", "report", "explore", "export")


def run(*args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "COLUMNS": "100"}
    return subprocess.run([sys.executable, "-m", "dtd", *args], capture_output=True, text=True, env=env)


def entries(help_text: str) -> list[list[str]]:
    """Each option of a help page: the text of its lines inside the box, in order."""
    found: list[list[str]] = []
    current: list[str] | None = None
    for line in help_text.splitlines():
        if not line.startswith("│") or not line.rstrip().endswith("│"):
            current = None  # a box's edge: the next lines are a new box's description
            continue
        inner = line[1:-1]
        if re.match(r"^\s?(-|[A-Z_]+\s)", inner):  # an option or positional starts an entry
            current = [inner]
            found.append(current)
        elif current is not None and inner.strip():
            current.append(inner)
    return found


@pytest.fixture(scope="module")
def pages() -> dict[str, str]:
    pages = {}
    for command in COMMANDS:
        result = run(command, "--help")
        assert result.returncode == 0, result.stderr
        # The checks below read the entries: a page whose layout they cannot read fails here.
        assert len(entries(result.stdout)) >= 2, (command, result.stdout)
        pages[command] = result.stdout
    return pages


def test_help_names_no_internals_and_one_default_each(pages):
    for command, page in pages.items():
        assert not re.search(r"\bdtd\.[a-z_]+\.", page), command
        assert "LOW_LEVEL" not in page and "``" not in page, command
        for entry in entries(page):
            text = " ".join(part.strip() for part in entry)
            assert text.count("(default:") <= 1, (command, text)
            assert "(default: None)" not in text, (command, text)
            assert "{None}" not in text, (command, text)


def test_help_keeps_sentences_whole(pages):
    # A description line is broken early when the next word would have fitted on it.
    for command, page in pages.items():
        for entry in entries(page):
            if len(entry) < 2:
                continue
            width = len(entry[0])
            described = re.match(r"^\s*\S.*?\s{2,}\S", entry[0]) is not None
            lines = entry if described else entry[1:]
            for line, following in itertools.pairwise(lines):
                next_word = following.split()[0]
                assert len(line.rstrip()) + 1 + len(next_word) > width - 1, (command, line)


def test_required_and_missing_options_are_marked(pages):
    env = next(" ".join(e) for e in entries(pages["train"]) if e[0].strip().startswith("--env"))
    assert "(required" in env
    sweep_options = [entry[0].split()[0] for entry in entries(pages["sweep"])]
    assert "--algos" in sweep_options and "--algo" not in sweep_options
    assert "--high.batch-size" in pages["train"]
    high_batch = next(" ".join(e) for e in entries(pages["train"]) if "--high.batch-size" in e[0])
    assert "high level" in high_batch and "1024" not in high_batch


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["train", "--epochs", "abc"], "Error parsing --epochs: invalid literal for int()"),
        (["train", "--algo", "foo"], "invalid choice 'foo' for argument '--algo'"),
        (["eval"], "RUN_DIR"),
        (["train", "--no-such-option", "1"], "--no-such-option"),
        (["nonsense"], "unknown command 'nonsense'"),
        (["sweep", "--algo", "her", "--env", "FetchReach-v4", "--out", "x"], "perhaps you meant --algos"),
        (["sweep", "--workers", "2", "--env", "FetchReach-v4", "--out", "x"], "Unrecognized options"),
    ],
)
def test_parse_errors_are_one_line(args, needle):
    result = run(*args)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("dtd: error: "), result.stderr
    assert needle in lines[0] and "│" not in lines[0]
