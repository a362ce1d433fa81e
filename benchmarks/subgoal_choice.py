"""Does the high level's actor choose the sub-goal its critic values most?

For each of ``--episodes`` evaluation starts of a trained dtd run (Fetch tasks: goals are
positions), compares pi1's deterministic first sub-goal with the best of a grid of candidate
sub-goals inside the box pi1 may choose from (the achieved goal +- ``subgoal_max_distance`` per
coordinate, within the goal box; a coordinate the box pins, such as FetchPush's table height,
stays pinned). Prints, per run, the median and 90th percentile of the distance between the two,
the critic's value at each (and the share of its value range the actor gives up), and how far
each lies along the way from the start to the goal (progress: 0 start, 1 goal).

The actor is trained to maximise Q1 minus ``--high.action-l2`` times its squared, scaled
output, a pull toward the achieved goal; a large gap says that pull (or an actor that lags its
critic) keeps the sub-goals from where the critic would put them.

    python benchmarks/subgoal_choice.py runs/push-dtd-0 --episodes 100
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from dtd.agents.dot_to_dot import DotToDotAgent
from dtd.agents.segments import subgoal_placement
from dtd.training.trained_run import load_run


def candidate_grid(
    achieved: np.ndarray, max_distance: float, low: np.ndarray, high: np.ndarray, points: int
) -> np.ndarray:
    """(K, G) candidates: per coordinate ``points`` values over the achieved goal +- max_distance
    within [low, high] (one value where the box pins the coordinate)."""
    axes = []
    for value, lo, hi in zip(achieved, low, high, strict=True):
        lo, hi = max(lo, value - max_distance), min(hi, value + max_distance)
        axes.append(np.array([lo]) if hi - lo < 1e-6 else np.linspace(lo, hi, points))
    return np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(axes))


def compare(run_dir: Path, episodes: int, points: int, checkpoint: str) -> dict[str, float]:
    loaded = load_run(run_dir, checkpoint)
    agent, env = loaded.agent, loaded.envs[0]
    if not isinstance(agent, DotToDotAgent) or loaded.spec.quaternion is not None:
        raise SystemExit(f"{run_dir}: needs a dtd run on a task whose goals are positions")
    head = agent.high.head
    low, high = head.low.numpy().astype(np.float64), head.high.numpy().astype(np.float64)
    max_distance = float(head.max_distance)
    gaps, value_lost, shares, actor_progress, best_progress = [], [], [], [], []
    for episode in range(episodes):
        observation, _ = env.reset(seed=loaded.config.seed + 1_000_000 + episode)
        start, goal = observation["achieved_goal"], observation["desired_goal"]
        chosen = agent.propose_subgoals(observation["observation"][None], start[None], goal[None])[0]
        candidates = candidate_grid(start, max_distance, low, high, points)
        values = agent.subgoal_values(observation, goal, np.concatenate([candidates, chosen[None]]))
        best = candidates[np.argmax(values[:-1])]
        gaps.append(np.linalg.norm(best - chosen))
        value_lost.append(values[:-1].max() - values[-1])
        shares.append(value_lost[-1] / max(values[:-1].max() - values[:-1].min(), 1e-9))
        progress, _ = subgoal_placement(start[None], np.stack([chosen, best])[None], goal[None])
        actor_progress.append(progress[0, 0])
        best_progress.append(progress[0, 1])
    loaded.close()
    return {
        "gap_median": float(np.median(gaps)),
        "gap_p90": float(np.percentile(gaps, 90)),
        "value_lost_median": float(np.median(value_lost)),
        "share_of_range_lost_median": float(np.median(shares)),
        "actor_progress_median": float(np.nanmedian(actor_progress)),
        "best_progress_median": float(np.nanmedian(best_progress)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--points", type=int, default=31, help="grid points per free coordinate")
    parser.add_argument("--checkpoint", default="latest")
    args = parser.parse_args()
    print("run  gap median / p90 (m)  value lost median (share of range)  progress actor / critic's best")
    for run in args.runs:
        f = compare(run, args.episodes, args.points, args.checkpoint)
        print(
            f"{run}  {f['gap_median']:.3f} / {f['gap_p90']:.3f}  {f['value_lost_median']:.4f} "
            f"({f['share_of_range_lost_median']:.2f})  "
            f"{f['actor_progress_median']:.2f} / {f['best_progress_median']:.2f}"
        )


if __name__ == "__main__":
    main()
