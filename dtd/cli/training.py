"""The ``dtd`` command line: every setting of :class:`dtd.config.TrainConfig` is an option."""

from __future__ import annotations

import functools
import json
import sys
import warnings
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


def sweep(
    config: Annotated[TrainConfig, tyro.conf.arg(name="")],
    out: Path,
    algos: str = "ddpg,her,dtd",
    seeds: int = 5,
    workers: int = 0,
    ray: str | None = None,
    progress: bool = True,
) -> None:
    """Train every (algorithm, seed) pair of one configuration, each into OUT/<env>-<algo>-s<seed>.

    Run again on the same --out, finished trials are left alone and interrupted ones resume
    from their checkpoints. A failing trial is reported and does not stop the others. With
    --ray the trials are tasks of a Ray cluster: auto joins the cluster running here (or
    starts a local one for the sweep), local always starts one, anything else is a cluster's
    address (ray://host:10001); each task asks for as many CPUs as it has torch threads
    (--threads, 1 by default).

    Examples:
      dtd sweep --env FetchPush-v4 --algos ddpg,her,dtd --seeds 5 --epochs 50 --out runs/push-sweep
      dtd sweep --env FetchPush-v4 --preset paper --seeds 3 --out runs/push-sweep-paper
      dtd sweep --env FetchPush-v4 --seeds 5 --out /shared/push-sweep --ray auto
      dtd plot runs/push-sweep

    Args:
        config: Settings shared by every trial (--algo is replaced by --algos; --seed is the first seed).
        out: Directory of the trials' run directories (on a cluster: a path every node reaches).
        algos: Comma-separated algorithms, each trained with every seed.
        seeds: Seeds per algorithm: --seed, --seed + 1, ...
        workers: Local trials at once (0: one per core); they share the cores' torch threads.
        ray: Run on Ray instead: auto, local or a cluster address (needs pip install 'dtd[ray]').
        progress: Show a live progress bar.
    """
    from dtd.config import Algo
    from dtd.errors import ConfigError
    from dtd.plots import find_runs, summaries, summary_table
    from dtd.sweep import run_sweep, sweep_trials

    try:
        chosen = [Algo(name.strip()) for name in algos.split(",") if name.strip()]
    except ValueError as exc:
        raise ConfigError(f"--algos: {exc}; choose from {', '.join(a.value for a in Algo)}") from exc
    trials = sweep_trials(config, chosen, seeds, out)
    outcomes = run_sweep(trials, workers=workers, ray_address=ray, show_progress=progress)
    failed = [outcome for outcome in outcomes if not outcome.ok]
    for outcome in failed:
        print(f"{outcome.trial.name} failed:\n{outcome.error}", file=sys.stderr)
    runs = find_runs([trial.run_dir for trial in trials if trial.run_dir.is_dir()])
    if runs:
        print(summary_table(summaries(runs)))
    print(f"{len(outcomes) - len(failed)} of {len(outcomes)} trials finished in {out}")
    if failed:
        sys.exit(1)


def plot(
    run_dirs: tyro.conf.Positional[tuple[Path, ...]],
    out: Path | None = None,
    max_env_steps: int | None = None,
) -> None:
    """Draw success against epochs and env steps per environment, and write summary.csv.

    Every run found under RUN_DIRS (any folder with a config.json) counts; runs are grouped
    by environment and algorithm (and preset, where not the default). Lines are the mean over
    seeds, bands the 25th-75th percentile.

    Examples:
      dtd plot runs/push-sweep
      dtd plot runs/push-sweep runs/push-sweep-paper --out docs/results/push
      dtd plot runs/pick-sweep --max-env-steps 400000 --out runs/pick-sweep/at-400k

    Args:
        run_dirs: Sweep or run directories to read.
        out: Where the figures (PNG and SVG per environment) and summary.csv go (default: the first RUN_DIR).
        max_env_steps: Compare runs at this budget: each curve ends at its last epoch within it (None: all).
    """
    from dtd.plots import plot as draw_plots

    if not run_dirs:
        raise DtdError("give at least one directory of runs")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = draw_plots(run_dirs, out if out is not None else run_dirs[0], max_env_steps)
    for warning in caught:
        print(f"warning: {warning.message}", file=sys.stderr)
    print(result.table)
    for path in [*result.figures, result.summary_csv]:
        print(f"wrote {path}")


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
        checkpoint: latest, best, first (after epoch 1), or a path to a checkpoint file of this run.
        seed: Seed of the evaluation episodes (apart from training's).
        show_subgoals: dtd runs: first print each episode's plan (start, sub-goals, reached, goal).
    """
    from dtd.runs import evaluate_run

    result = evaluate_run(run_dir, episodes, checkpoint, seed, show_subgoals)
    for number, plan in enumerate(result.pop("plans", []), start=1):
        print(format_plan(number, plan))
    print(json.dumps(result))


def render(
    run_dir: tyro.conf.Positional[Path],
    episodes: int = 3,
    out: Path | None = None,
    checkpoint: str = "latest",
    seed: int = 1_000_003,
    width: int = 480,
    height: int = 480,
) -> None:
    """Render deterministic episodes of a trained run, headless: an MP4 per episode, a PNG strip
    of key frames (start, each segment's end, final) and plans.json.

    The task's goal is a red dot; for dtd runs the current sub-goal is a green dot, changing
    exactly when the agent changes it (for the Hand task, a green ghost block beside the
    goal's ghost block shows the sub-goal's orientation).

    Examples:
      dtd render runs/push-dtd-0 --episodes 3 --out frames/

    Args:
        run_dir: The run directory.
        episodes: Episodes to render.
        out: Where the files go (default: RUN_DIR/render).
        checkpoint: latest, best, first (after epoch 1), or a path to a checkpoint file of this run.
        seed: Seed of the episodes.
        width: Frame width in pixels.
        height: Frame height in pixels.
    """
    from dtd.render import render_run

    target = out if out is not None else run_dir / "render"
    for number, files in enumerate(render_run(run_dir, episodes, target, checkpoint, seed, width, height), 1):
        outcome = "success" if files.plan["success"] else "failure"
        print(f"episode {number}: {outcome}  {files.video}  {files.strip}")
    print(f"plans: {target / 'plans.json'}")


def heatmap(
    run_dir: tyro.conf.Positional[Path],
    start: str = "1.15,0.55",
    goal: str = "1.45,0.95",
    out: Path | None = None,
    checkpoint: str = "first,latest",
    heights: str | None = None,
    resolution: int = 60,
) -> None:
    """Draw the high level's value of every sub-goal on a grid over the table (dtd runs on
    FetchPush or FetchPickAndPlace), with the block and the goal placed where asked.

    Examples:
      dtd heatmap runs/push-dtd-0 --out heat.png
      dtd heatmap runs/push-dtd-0 --start 1.15,0.55 --goal 1.45,0.95 --checkpoint latest

    Args:
        run_dir: A dtd run directory.
        start: The block's x,y on the table (world frame, metres).
        goal: The goal's x,y (or x,y,z).
        out: The image to write (PNG, or SVG by suffix; default: RUN_DIR/heatmap.png).
        checkpoint: Comma-separated checkpoints, a panel each: first (after epoch 1), latest, best, paths.
        heights: Comma-separated heights (z, m) of the slices (default: the table's; PickAndPlace: 4).
        resolution: Grid cells along each side of the table.
    """
    import numpy as np

    from dtd.heatmap import run_heatmaps

    levels = _numbers(heights, "--heights") if heights is not None else None
    names = [name.strip() for name in checkpoint.split(",") if name.strip()]
    target = out if out is not None else run_dir / "heatmap.png"
    path, columns = run_heatmaps(
        run_dir, target, names, _numbers(start, "--start"), _numbers(goal, "--goal"), levels, resolution
    )
    for label, slices in columns:
        for heat in slices:
            row, column = np.unravel_index(np.argmax(heat.values), heat.values.shape)
            chosen = ", ".join(f"{v:.3f}" for v in heat.subgoal)
            print(
                f"{label}, z {heat.z:.3f}: values {heat.values.min():.3f} to {heat.values.max():.3f}, "
                f"highest at ({heat.xs[column]:.3f}, {heat.ys[row]:.3f}); chosen sub-goal ({chosen})"
            )
    print(f"wrote {path}")


def report(
    run_dir: tyro.conf.Positional[Path],
    episodes: int = 3,
    checkpoint: str = "latest",
    seed: int = 1_000_003,
    resolution: int = 60,
) -> None:
    """Write RUN_DIR/report.html: configuration, training curves, heatmaps (dtd), key-frame
    strips, videos and each rendered episode's plan; it opens from disk with no server.

    Examples:
      dtd report runs/push-dtd-0

    Args:
        run_dir: The run directory.
        episodes: Episodes to render.
        checkpoint: The checkpoint shown (heatmaps also show the one after the first epoch).
        seed: Seed of the rendered episodes.
        resolution: Heatmap grid cells along each side of the table.
    """
    from dtd.report import write_report

    written = write_report(run_dir, episodes, checkpoint, seed, resolution)
    print(f"wrote {written.page} ({len(written.assets)} files beside it)")


def _numbers(text: str, option: str) -> list[float]:
    try:
        return [float(part) for part in text.split(",") if part.strip()]
    except ValueError as exc:
        raise DtdError(f"{option} takes comma-separated numbers, got {text!r}") from exc


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
    preset = preset_config(preset_named(args))
    commands = {
        "train": functools.partial(train, config=preset),
        "sweep": functools.partial(sweep, config=preset),
        "plot": plot,
        "eval": evaluate,
        "render": render,
        "heatmap": heatmap,
        "report": report,
    }
    try:
        if args[:1] == ["sweep"] and any(arg == "--algo" or arg.startswith("--algo=") for arg in args):
            raise DtdError("dtd sweep takes --algos (comma-separated), not --algo")
        tyro.extras.subcommand_cli_from_dict(
            commands,
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
