"""The ``dtd`` command line: every setting of :class:`dtd.config.TrainConfig` is an option."""

from __future__ import annotations

import functools
import json
import sys
from pathlib import Path
from typing import Annotated

import tyro

from dtd.config import Preset, TrainConfig, preset_config
from dtd.errors import DtdError


def train(
    config: Annotated[TrainConfig, tyro.conf.arg(name="")],
    run_dir: Path | None = None,
    resume: Path | None = None,
    force: bool = False,
    progress: bool = True,
) -> None:
    """Train an agent; results land in the run directory.

    Examples:
      dtd train --env FetchPush-v4 --algo her --seed 0 --epochs 50 --run-dir runs/push-her-0
      dtd train --env FetchPush-v4 --algo dtd --preset paper   # the paper's settings
      dtd train --resume runs/push-her-0

    Args:
        config: The run's settings.
        run_dir: Where the run's files go (default: runs/<env>-<algo>-s<seed>).
        resume: Continue the run in this directory after its last finished epoch; --epochs may grow.
        force: Replace a run that already exists in --run-dir.
        progress: Show a live progress bar.
    """
    from dtd.runs import train as train_run

    state = train_run(config, run_dir=run_dir, resume=resume, force=force, show_progress=progress)
    last = state.history[-1] if state.history else {}
    print(
        json.dumps(
            {
                "epochs": state.epoch,
                "env_steps": state.env_steps,
                "eval_success": last.get("eval_success"),
                "best_eval_success": state.best_eval_success,
                "wall_s": round(state.wall_s, 1),
            }
        )
    )


def evaluate(
    run_dir: tyro.conf.Positional[Path],
    episodes: int = 100,
    checkpoint: str = "latest",
    seed: int = 1_000_003,
    show_subgoals: bool = False,
) -> None:
    """Evaluate a trained run with deterministic actions; print one JSON line of figures.

    Args:
        run_dir: The run directory to evaluate.
        episodes: Number of evaluation episodes.
        checkpoint: latest, best, or a path to a checkpoint file of this run.
        seed: Seed of the evaluation episodes (apart from training's).
        show_subgoals: dtd runs: first print each episode's plan (start, sub-goals, reached, goal).
    """
    from dtd.runs import evaluate_run

    result = evaluate_run(run_dir, episodes, checkpoint, seed, show_subgoals)
    for number, plan in enumerate(result.pop("plans", []), start=1):
        print(format_plan(number, plan))
    print(json.dumps(result))


def format_plan(number: int, plan: dict) -> str:
    """One episode's plan as readable lines."""

    def point(values: list[float]) -> str:
        return "(" + ", ".join(f"{v:.3f}" for v in values) + ")"

    lines = [
        f"episode {number}: {'success' if plan['success'] else 'failure'}",
        f"  start    {point(plan['start'])}",
    ]
    for segment, (subgoal, reached) in enumerate(zip(plan["subgoals"], plan["reached"], strict=True)):
        lines.append(f"  segment {segment}: sub-goal {point(subgoal)}  reached {point(reached)}")
    lines.append(f"  goal     {point(plan['goal'])}")
    return "\n".join(lines)


def preset_named(argv: list[str]) -> Preset:
    """The ``--preset`` given in ``argv`` (the last one), else ``tuned``; a name that is not a
    preset is left for the parser to report."""
    preset = Preset.tuned
    for index, arg in enumerate(argv):
        name, _, value = arg.partition("=")
        if name != "--preset":
            continue
        value = value or (argv[index + 1] if index + 1 < len(argv) else "")
        if value in Preset.__members__:
            preset = Preset(value)
    return preset


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``dtd`` command."""
    args = sys.argv[1:] if argv is None else argv
    # The preset supplies the defaults the other options override, so it is read first.
    train_command = functools.partial(train, config=preset_config(preset_named(args)))
    try:
        tyro.extras.subcommand_cli_from_dict(
            {"train": train_command, "eval": evaluate},
            prog="dtd",
            description="Dot-to-Dot: train and explain goal-conditioned agents (DDPG, HER, DtD).",
            args=args,
        )
    except DtdError as exc:
        print(f"dtd: error: {exc}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("dtd: interrupted; continue with dtd train --resume RUN_DIR", file=sys.stderr)
        sys.exit(130)


if __name__ == "__main__":
    main()
