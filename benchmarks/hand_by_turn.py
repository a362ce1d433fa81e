"""A trained Hand rotation run by how far its goal is turned from the block's start: success per
group, and for a dtd run what its high level does there: where the first sub-goal lies along the
shortest turn from the start to the goal (progress: 0 at the start, 1 at the goal), how far off
that turn (degrees), and how many sub-goals the low level reached. Deterministic episodes of the
run's latest checkpoint, the evaluation seed that ``dtd eval`` uses (so every run meets the same
goals), in three groups of equal size by the goal's turn.

    python benchmarks/hand_by_turn.py runs/record/hand/HandManipulateBlockRotateZ-v1-dtd-s100 --episodes 100
    python benchmarks/hand_by_turn.py runs/record/hand/HandManipulateBlockRotateZ-v1-her-s100 --episodes 100
"""

from __future__ import annotations

import argparse

import numpy as np

from dtd.agents.segments import goal_separation
from dtd.agents.subgoal_report import goal_away
from dtd.training.rollout import run_many
from dtd.training.trained_run import load_run

GROUPS = 3


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("run_dir")
    parser.add_argument("--episodes", type=int, default=100)
    args = parser.parse_args()
    with load_run(args.run_dir, envs=10) as loaded:
        if loaded.spec.quaternion is None:
            raise SystemExit(f"{args.run_dir}: needs a run on a task whose goals have a rotation")
        planner = loaded.agent.planner()
        episodes = run_many(loaded.envs, loaded.agent, loaded.spec, args.episodes, False, loaded.rng)
        # The episodes whose goal is not met at their start, in order of the goal's turn, split
        # in equal parts: the groups of the high level's placement_by_distance.
        away = np.flatnonzero(goal_away(episodes, loaded.agent.goals.reached))
        turn = goal_separation(
            episodes.achieved_goal[away, 0], episodes.desired_goal[away], loaded.spec.quaternion
        )["angle"]
        order = np.argsort(turn, kind="stable")
        members = np.array_split(away[order], GROUPS)
        angles = np.array_split(turn[order], GROUPS)
        plans = planner.plan(episodes) if planner is not None else None
        groups = planner.placement_by_distance(episodes, GROUPS) if planner is not None else None
    summary = f"{args.run_dir}: {args.episodes} episodes, success {episodes.success.mean():.2f}"
    header = "| goal's turn (degrees) | episodes | success |"
    if plans is not None:
        # The intermediate sub-goals' verdicts (the last segment's sub-goal is the task's goal).
        verdicts = [plan["reached"][:-1] for plan in plans]
        reached = np.array([np.mean(shown) if shown else np.nan for shown in verdicts])
        summary += f", sub-goals reached {np.nanmean(reached):.2f}"
        header += " first sub-goal: progress along the turn | off the turn (degrees) | sub-goals reached |"
    print(summary)
    print(header)
    print("|---" * header.count(" |") + "|")
    for number, (rows, turned) in enumerate(zip(members, angles, strict=True)):
        success = episodes.success[rows].mean()
        line = f"| {turned.min():.0f} - {turned.max():.0f} | {len(rows)} | {success:.2f} |"
        if groups is not None:
            first = f"{groups[number]['progress'][0]:.2f} | {groups[number]['off_line'][0]:.1f}"
            line += f" {first} | {np.nanmean(reached[rows]):.2f} |"
        print(line)


if __name__ == "__main__":
    main()
