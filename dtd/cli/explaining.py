"""Commands that look at a trained run: ``dtd eval``, ``dtd render``, ``dtd heatmap``, ``dtd report``,
``dtd explore``, ``dtd export``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import tyro

from dtd.cli.options import optional
from dtd.config import EVAL_SEED
from dtd.errors import DtdError

RunDirArgument = Annotated[Path, tyro.conf.Positional, tyro.conf.arg(metavar="RUN_DIR")]


def evaluate(
    run_dir: RunDirArgument,
    episodes: int = 100,
    checkpoint: str = "latest",
    seed: int = EVAL_SEED,
    show_subgoals: bool = False,
    save: bool = False,
) -> None:
    """Evaluate a trained run with deterministic actions; print one JSON line of figures.

    Args:
        run_dir: The run directory to evaluate.
        episodes: Number of evaluation episodes.
        checkpoint: latest, best (the epoch of the highest eval success, a noisy pick that
            flatters), first (after epoch 1), or the path of a checkpoint file of this run.
        seed: Seed of the evaluation episodes (apart from training's).
        show_subgoals: dtd runs: first print each episode's plan, then where the sub-goals lay.
        save: Also write the JSON line to RUN_DIR/eval-CHECKPOINT.json (eval-latest.json is
            the final that dtd plot --stats takes for the run's last epoch).
    """
    from dtd.training.trained_run import evaluate_run, save_evaluation

    result = evaluate_run(run_dir, episodes, checkpoint, seed, show_subgoals)
    if save:
        save_evaluation(result, run_dir, checkpoint)
    for number, plan in enumerate(result.pop("plans", []), start=1):
        print(format_plan(number, plan))
    if show_subgoals:
        print(format_placement(result["subgoal_placement"]))
    print(json.dumps(result))


def render(
    run_dir: RunDirArgument,
    episodes: int = 3,
    out: Annotated[Path | None, optional("DIR", "RUN_DIR/render")] = None,
    checkpoint: str = "latest",
    seed: int = EVAL_SEED,
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
        out: Where the files go.
        checkpoint: latest, best (the epoch of the highest eval success, a noisy pick that
            flatters), first (after epoch 1), or the path of a checkpoint file of this run.
        seed: Seed of the episodes.
        width: Frame width in pixels.
        height: Frame height in pixels.
    """
    from dtd.explain.render import render_run

    target = out if out is not None else run_dir / "render"
    for number, files in enumerate(render_run(run_dir, episodes, target, checkpoint, seed, width, height), 1):
        outcome = "success" if files.plan["success"] else "failure"
        print(f"episode {number}: {outcome}  {files.video}  {files.strip}")
    print(f"plans: {target / 'plans.json'}")


def heatmap(
    run_dir: RunDirArgument,
    start: Annotated[str | None, optional("X,Y", "1.15,0.55")] = None,
    goal: Annotated[str | None, optional("X,Y[,Z]", "1.45,0.95")] = None,
    out: Annotated[Path | None, optional("FILE", "RUN_DIR/heatmap.png")] = None,
    checkpoint: str = "first,latest",
    heights: Annotated[
        str | None, optional("Z,...", "the table's; on FetchPickAndPlace also 0.1, 0.2, 0.3 m above")
    ] = None,
    resolution: int = 60,
    seed: int = 0,
) -> None:
    """Draw the high level's value of every sub-goal on a grid over the table (dtd runs on
    FetchPush or FetchPickAndPlace), with the block and the goal placed where asked; or, for a
    task whose goals are points on a plane (the mazes), over its goal box from its own start
    and goal.

    Examples:
      dtd heatmap runs/push-dtd-0 --out heat.png
      dtd heatmap runs/push-dtd-0 --start 1.15,0.55 --goal 1.45,0.95 --checkpoint latest

    Args:
        run_dir: A dtd run directory.
        start: The block's x,y on the table (world frame, metres; Fetch tasks).
        goal: The goal's x,y (or x,y,z; Fetch tasks).
        out: The image to write (PNG, or SVG by suffix).
        checkpoint: Comma-separated checkpoints, a panel each: first (after epoch 1), latest, best, paths.
        heights: Comma-separated heights (z, m) of the slices.
        resolution: Grid cells along each side of the table.
        seed: Seed of the reset that gives a planar task's start and goal.
    """
    import numpy as np

    from dtd.explain.heatmap import run_heatmaps

    levels = _numbers(heights, "--heights") if heights is not None else None
    names = [name.strip() for name in checkpoint.split(",") if name.strip()]
    target = out if out is not None else run_dir / "heatmap.png"
    placed = [
        _numbers(text, name) if text is not None else None
        for text, name in ((start, "--start"), (goal, "--goal"))
    ]
    path, columns = run_heatmaps(run_dir, target, names, *placed, levels, resolution, seed)
    for label, slices in columns:
        for heat in slices:
            row, column = np.unravel_index(np.argmax(heat.values), heat.values.shape)
            chosen = ", ".join(f"{v:.3f}" for v in heat.subgoal)
            where = f", z {heat.z:.3f}" if heat.z is not None else ""
            print(
                f"{label}{where}: values {heat.values.min():.3f} to {heat.values.max():.3f}, "
                f"highest at ({heat.xs[column]:.3f}, {heat.ys[row]:.3f}); chosen sub-goal ({chosen})"
            )
    print(f"wrote {path}")


def report(
    run_dir: RunDirArgument,
    episodes: int = 3,
    checkpoint: str = "latest",
    seed: int = EVAL_SEED,
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
    from dtd.explain.report import write_report

    written = write_report(run_dir, episodes, checkpoint, seed, resolution)
    print(f"wrote {written.page} ({len(written.assets)} files beside it)")


def explore(
    run_dir: RunDirArgument,
    host: str = "127.0.0.1",
    port: int = 8765,
    threads: int = 1,
) -> None:
    """Open a local web page to question a run: for dtd runs on FetchPush or FetchPickAndPlace,
    drag the block and the goal and see the high level's value of every sub-goal and the one
    it would choose, after any epoch kept; play episodes from that placement and watch them.
    Works on a run that is still training. Ctrl-C stops it.

    Examples:
      dtd explore runs/push-dtd-0
      dtd explore runs/push-dtd-0 --port 0

    Args:
        run_dir: The run directory.
        host: The address to listen on; anything but this machine's own (127.0.0.1) lets
            others reach the page, which has no login.
        port: The port to listen on (0: any free one).
        threads: Torch threads for the value maps.
    """
    import contextlib
    import sys
    import tempfile

    import torch

    try:
        from dtd.explain.explore.server import is_loopback, serve
    except ImportError as exc:
        raise DtdError(
            f"dtd explore needs its web server ({exc.name} is missing): pip install 'dtd[explore]'"
        ) from exc

    if threads < 1:
        raise DtdError(f"--threads must be at least 1, got {threads}")
    if not 0 <= port <= 65535:
        raise DtdError(f"--port must lie in 0..65535 (0: any free one), got {port}")
    torch.set_num_threads(threads)

    def ready(url: str) -> None:
        if not is_loopback(host):
            print(
                f"dtd explore: warning: listening on {host}: anyone who can reach it can use the page "
                "(there is no login) and have episodes rendered on this machine",
                file=sys.stderr,
            )
        print(f"dtd explore: {run_dir} at {url}  (Ctrl-C stops it)", flush=True)

    # The server stops on Ctrl-C and passes the interrupt on: here it is the way to stop.
    with tempfile.TemporaryDirectory(prefix="dtd-explore-") as videos, contextlib.suppress(KeyboardInterrupt):
        serve(run_dir, host, port, Path(videos), ready)
    print("dtd explore: stopped", flush=True)


def export(
    run_dir: RunDirArgument,
    checkpoint: str = "latest",
    out: Annotated[Path | None, optional("DIR", "RUN_DIR/export")] = None,
    force: bool = False,
) -> None:
    """Export a trained agent as ONNX models that run without dtd or torch (ONNX Runtime, a C++
    controller, a ROS node): her/ddpg one policy (observation, goal) -> action; dtd its low
    level (observation, sub-goal) -> action, its high level (observation, achieved goal, goal)
    -> sub-goal and the high level's critic. Input normalisation, clipping and action scaling
    are inside. Also writes policy.json (dimensions, when to ask for a sub-goal, versions) and
    a README.md with an example.

    Examples:
      dtd export runs/push-dtd-0 --out push-dtd-onnx/

    Args:
        run_dir: The run directory.
        checkpoint: latest, best, first, or the path of a checkpoint file of this run.
        out: Where the files go.
        force: Replace the models in an --out that already holds files.
    """
    from dtd.export.onnx_files import export_run

    target = out if out is not None else run_dir / "export"
    exported = export_run(run_dir, target, checkpoint, force)
    for path in exported.files:
        print(f"{path}  ({path.stat().st_size:,} bytes)")
    source = exported.policy["checkpoint"]
    print(
        f"epoch {source['epoch']}, {source['env_steps']:,} env steps; ONNX opset {exported.policy['opset']}; "
        f"largest difference from the torch agent {exported.largest_difference:.1e}"
    )


def _numbers(text: str, option: str) -> list[float]:
    try:
        return [float(part) for part in text.split(",") if part.strip()]
    except ValueError as exc:
        raise DtdError(f"{option} takes comma-separated numbers, got {text!r}") from exc


def format_plan(number: int, plan: dict) -> str:
    """One episode's plan as readable lines (for goals with a rotation, with its angles)."""

    def point(values: list[float]) -> str:
        return "(" + ", ".join(f"{v:.3f}" for v in values) + ")"

    angles = plan.get("angles")
    steps = f" after {plan['steps']} steps" if "steps" in plan else ""
    lines = [
        f"episode {number}: {'success' if plan['success'] else 'failure'}{steps}",
        f"  start    {point(plan['start'])}",
    ]
    # No verdicts where the task's reward does not tell a goal reached (a dense reward).
    verdicts = plan["reached"] or [None] * len(plan["subgoals"])
    for segment, (subgoal, end, reached) in enumerate(
        zip(plan["subgoals"], plan["segment_ends"], verdicts, strict=True)
    ):
        verdict = "unknown" if reached is None else "yes" if reached else "no"
        lines.append(
            f"  segment {segment}: sub-goal {point(subgoal)}  reached: {verdict}, ended at {point(end)}"
        )
        if angles:
            lines.append(
                f"    turned {angles['start_to_subgoal'][segment]:.0f} deg from the start, "
                f"{angles['subgoal_to_goal'][segment]:.0f} deg from the goal; "
                f"ended {angles['segment_end_to_subgoal'][segment]:.0f} deg from it"
            )
    lines.append(f"  goal     {point(plan['goal'])}")
    if angles:
        lines.append(
            f"    {angles['start_to_goal']:.0f} deg from the start; "
            f"the episode ended {angles['final_to_goal']:.0f} deg from it"
        )
    return "\n".join(lines)


def format_placement(groups: list[dict]) -> str:
    """Where the sub-goals lay along the way, per group of goal distances (or, for goals with a
    rotation, goal angles), as a table."""
    rotation = bool(groups) and "goal_angle" in groups[0]
    if rotation:
        lines = [
            "sub-goal rotations along the turn from the start to the goal (progress: 0 at the start,",
            "1 at the goal; off line: degrees from the shortest turn)",
            "  goal angle (deg)  episodes  success  progress per sub-goal  off line per sub-goal",
        ]
    else:
        lines = [
            "sub-goals along the way (progress: 0 at the start, 1 at the goal; off line: distance from it)",
            "  goal distance    episodes  success  progress per sub-goal  off line per sub-goal",
        ]
    for group in groups:
        low, high = group["goal_angle"] if rotation else group["goal_distance"]
        progress = " ".join(f"{value:.2f}" for value in group["progress"])
        off_line = " ".join(f"{value:.{1 if rotation else 3}f}" for value in group["off_line"])
        counts = f"{group['episodes']:>8}  {group['success']:>7.2f}"
        span = f"{low:5.1f} - {high:5.1f}    " if rotation else f"{low:.3f} - {high:.3f}"
        lines.append(f"  {span}  {counts}  {progress:<21}  {off_line}")
    if not groups:
        lines.append("  (every goal was met at its episode's start)")
    return "\n".join(lines)
