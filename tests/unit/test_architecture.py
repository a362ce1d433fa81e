"""The package's architecture: imports point down the wings, and the public API at the top."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import dtd

PACKAGE = Path(dtd.__file__).parent

WINGS = ("envs", "agents", "training", "experiments", "explain", "export", "cli")
"""The package's parts from the bottom up: each may import the ones before it, never one after."""

BASE = ("config", "errors", "figures")
"""Imported by every wing; they import nothing of dtd but each other."""


def part_of(module: str) -> str:
    """The wing (or base module) a dotted module name of dtd belongs to; ``dtd`` for the
    package itself and ``__main__``."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] != "__main__" else "dtd"


def module_name(path: Path, root: Path) -> str:
    relative = path.relative_to(root.parent).with_suffix("")
    parts = list(relative.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imported_modules(source: str, module: str, is_package: bool) -> list[tuple[int, str]]:
    """(line, module) of every import of dtd in ``source``, at any depth (inside functions
    and ``TYPE_CHECKING`` blocks too), relative imports resolved."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = module.split(".")
                anchor = anchor[: len(anchor) - node.level + (1 if is_package else 0)]
                base = ".".join([*anchor, node.module] if node.module else anchor)
            else:
                base = node.module or ""
            if base == "dtd":  # `from dtd import x`: x may be a module of the package
                found += [(node.lineno, f"dtd.{alias.name}") for alias in node.names]
            else:
                found.append((node.lineno, base))
    return [(line, name) for line, name in found if name == "dtd" or name.startswith("dtd.")]


def upward_imports(sources: dict[str, tuple[str, bool]]) -> list[str]:
    """Each import among ``sources`` (module name -> (source, is package)) that points up or
    sideways out of its wing, as 'module:line imports target'."""
    problems = []
    for module, (source, is_package) in sorted(sources.items()):
        here = part_of(module)
        for line, target in imported_modules(source, module, is_package):
            there = part_of(target)
            if there not in (*WINGS, *BASE):
                there = "dtd"  # a name of the public API (`from dtd import train`)
            if here == "dtd" or there == here:
                continue  # the package's public API may name anything; a wing uses itself
            if there == "dtd":
                allowed = False  # the public API is for users, not for the package's own parts
            elif here in BASE:
                allowed = there in BASE
            elif there in BASE:
                allowed = True
            else:
                allowed = WINGS.index(there) < WINGS.index(here)
            if not allowed:
                problems.append(f"{module}:{line} imports {target}")
    return problems


def package_sources() -> dict[str, tuple[str, bool]]:
    return {
        module_name(path, PACKAGE): (path.read_text(), path.name == "__init__.py")
        for path in PACKAGE.rglob("*.py")
    }


def test_every_module_lies_in_a_wing_or_at_the_top():
    parts = {part_of(module) for module in package_sources()}
    assert parts <= {*WINGS, *BASE, "dtd"}, parts - {*WINGS, *BASE, "dtd"}


def test_imports_only_point_down():
    assert upward_imports(package_sources()) == []


def test_agents_know_of_environments_only_their_spec_and_goal_verdicts():
    sources = package_sources()
    used = {
        target
        for module, (source, is_package) in sources.items()
        if part_of(module) == "agents"
        for _, target in imported_modules(source, module, is_package)
        if part_of(target) == "envs"
    }
    assert used <= {"dtd.envs.spec", "dtd.envs.goals"}, used


@pytest.mark.parametrize(
    ("module", "source", "points_up"),
    [
        ("dtd.agents.ddpg", "from dtd.training.trainer import Trainer", True),
        ("dtd.envs.spec", "import dtd.agents.records", True),
        ("dtd.training.trainer", "def f():\n    from dtd.explain.render import render_run", True),
        ("dtd.experiments.plots", "from dtd.explain import report", True),
        ("dtd.explain.report", "from dtd.cli.training import plot", True),
        ("dtd.config.settings", "from dtd.envs.spec import EnvSpec", True),
        ("dtd.agents.flat", "from dtd import train", True),
        ("dtd.agents.flat", "from ..training import trainer", True),
        ("dtd.explain.report", "from dtd.experiments.curves import read_curve", False),
        ("dtd.agents.ddpg", "from dtd.config import LearnerConfig", False),
        ("dtd.agents.flat", "from .records import Batch", False),
        ("dtd.cli", "from dtd.explain.render import render_run", False),
        ("dtd", "from dtd.training.lifecycle import train", False),
    ],
)
def test_the_check_finds_an_import_that_points_up(module, source, points_up):
    assert bool(upward_imports({module: (source, False)})) is points_up


def test_the_public_api_is_small_and_loads_on_first_use():
    from dtd import TrainConfig, evaluate_run, load_agent, train
    from dtd.config import TrainConfig as ConfigTrainConfig
    from dtd.training.lifecycle import train as lifecycle_train
    from dtd.training.trained_run import evaluate_run as trained_evaluate_run
    from dtd.training.trained_run import load_agent as trained_load_agent

    assert TrainConfig is ConfigTrainConfig and train is lifecycle_train
    assert evaluate_run is trained_evaluate_run and load_agent is trained_load_agent
    assert set(dtd.__all__) <= set(dir(dtd))
    assert all(getattr(dtd, name) is not None for name in dtd.__all__)
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        _ = dtd.nothing
    # `import dtd` (and so `dtd --help`) loads neither torch nor MuJoCo.
    probe = "import sys, dtd, dtd.cli; print(sorted({'torch', 'mujoco'} & set(sys.modules)))"
    loaded = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert loaded.stdout.strip() == "[]"
