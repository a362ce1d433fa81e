"""The ``dtd`` command line: every setting of :class:`dtd.config.TrainConfig` is an option."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import tyro

from dtd.config import TrainConfig
from dtd.errors import DtdError


def train(
    config: tyro.conf.OmitArgPrefixes[TrainConfig],
    run_dir: Path | None = None,
    resume: Path | None = None,
    force: bool = False,
    progress: bool = True,
) -> None:
    """Train an agent; results land in the run directory.

    Examples:
      dtd train --env FetchPush-v4 --algo her --seed 0 --epochs 50 --run-dir runs/push-her-0
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
) -> None:
    """Evaluate a trained run with deterministic actions; print one JSON line of figures.

    Args:
        run_dir: The run directory to evaluate.
        episodes: Number of evaluation episodes.
        checkpoint: latest, best, or a path to a checkpoint file of this run.
        seed: Seed of the evaluation episodes (apart from training's).
    """
    from dtd.runs import evaluate_run

    print(json.dumps(evaluate_run(run_dir, episodes, checkpoint, seed)))


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``dtd`` command."""
    try:
        tyro.extras.subcommand_cli_from_dict(
            {"train": train, "eval": evaluate},
            prog="dtd",
            description="Dot-to-Dot: train and explain goal-conditioned agents (DDPG, HER).",
            args=argv,
        )
    except DtdError as exc:
        print(f"dtd: error: {exc}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("dtd: interrupted; continue with dtd train --resume RUN_DIR", file=sys.stderr)
        sys.exit(130)


if __name__ == "__main__":
    main()
