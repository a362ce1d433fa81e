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
        if planner is None:
            print(f"{args.run_dir}: {args.episodes} episodes, success {episodes.success.mean():.2f}")
            print("| goal's turn (degrees) | episodes | success |")
            print("|---|---|---|")
            for rows, turned in zip(members, angles, strict=True):
                print(
                    f"| {turned.min():.0f} - {turned.max():.0f} | {len(rows)} "
                    f"| {episodes.success[rows].mean():.2f} |"
                )
            return
        plans = planner.plan(episodes)
        groups = planner.placement_by_distance(episodes, GROUPS)
    # The intermediate sub-goals' verdicts (the last segment's sub-goal is the task's goal).
    reached = np.array([np.mean(plan["reached"][:-1]) if plan["reached"][:-1] else np.nan for plan in plans])
    print(
        f"{args.run_dir}: {args.episodes} episodes, success {episodes.success.mean():.2f}, "
        f"sub-goals reached {np.nanmean(reached):.2f}"
    )
    print(
        "| goal's turn (degrees) | episodes | success | first sub-goal: progress along the turn "
        "| off the turn (degrees) | sub-goals reached |"
    )
    print("|---|---|---|---|---|---|")
    for group, rows in zip(groups, members, strict=True):
        low, high = group["goal_angle"]
        print(
            f"| {low:.0f} - {high:.0f} | {group['episodes']} | {group['success']:.2f} "
            f"| {group['progress'][0]:.2f} | {group['off_line'][0]:.1f} "
            f"| {np.nanmean(reached[rows]):.2f} |"
        )


if __name__ == "__main__":
    main()
